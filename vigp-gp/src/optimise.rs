//! Box-constrained minimisation with the L-BFGS-B that trains the GPs
//! (Byrd, Lu, Nocedal & Zhu 1995, scipy's iteration with a Moré–Thuente
//! line search), for any smooth objective with a gradient.
//!
//! The objective returns `Some((f, ∇f))`, or `None` where it cannot be
//! evaluated (e.g. a simulation that fails): the optimiser then shrinks
//! the trial step towards the best point instead of stopping, except at
//! the start, which must evaluate.
//!
//! ```
//! use vigp_gp::optimise::{Options, minimise};
//! // (x − 3)² + 10(y + 1)² in the box [0, 2] × [−5, 5]: the minimum is
//! // on the bound x = 2, at y = −1.
//! let f = |p: &[f64]| {
//!     let (x, y) = (p[0], p[1]);
//!     let v = (x - 3.0).powi(2) + 10.0 * (y + 1.0).powi(2);
//!     Some((v, vec![2.0 * (x - 3.0), 20.0 * (y + 1.0)]))
//! };
//! let m = minimise(f, &[0.5, 2.0], &[0.0, -5.0], &[2.0, 5.0], &Options::default())?;
//! // x sits on its bound; y to the stopping tests (pgtol 1e-5 on 20(y + 1)).
//! assert!((m.x[0] - 2.0).abs() < 1e-12 && (m.x[1] + 1.0).abs() < 1e-4);
//! # Ok::<(), vigp_gp::optimise::OptimiseError>(())
//! ```

use std::cell::Cell;

use crate::error::GpError;
use crate::lbfgs::{self, LbfgsOptions};

/// Settings of [`minimise`] (scipy's defaults but for the iteration cap).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// Curvature pairs kept (scipy's `maxcor`, default 10; at least 1).
    pub memory: usize,
    /// Most iterations (accepted steps; default 200).
    pub max_iters: usize,
    /// Stop when the projected gradient's ∞-norm is at most this
    /// (default 1e-5).
    pub pgtol: f64,
    /// Stop when the relative decrease of an iteration is at most this
    /// (default 2.2e-9, scipy's `factr` = 1e7 times the machine epsilon).
    pub ftol: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            memory: 10,
            max_iters: 200,
            pgtol: 1e-5,
            ftol: 1e7 * f64::EPSILON,
        }
    }
}

/// The outcome of [`minimise`].
#[derive(Clone, Debug, PartialEq)]
pub struct Minimum {
    /// The best point reached.
    pub x: Vec<f64>,
    /// The objective there.
    pub f: f64,
    /// Iterations (accepted steps).
    pub iterations: usize,
    /// Evaluations of the objective (repeated points served from a cache
    /// are not counted).
    pub evaluations: usize,
    /// A stopping test (`pgtol` or `ftol`) was met, not `max_iters`.
    pub converged: bool,
}

/// What can go wrong in [`minimise`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OptimiseError {
    /// The start and the bounds do not have one length, or the gradient
    /// has another.
    #[error("{what}: expected {expected} entries, found {found}")]
    Dimension {
        /// Which vector.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Found length.
        found: usize,
    },
    /// A bound is NaN, or a lower bound exceeds its upper bound.
    #[error("bounds of variable {index}: [{lo}, {hi}]")]
    Bounds {
        /// The variable.
        index: usize,
        /// Its lower bound.
        lo: f64,
        /// Its upper bound.
        hi: f64,
    },
    /// The start is not finite.
    #[error("the start is not finite")]
    NonFinite,
    /// Options out of range (memory 0, a negative or NaN tolerance).
    #[error("options: {0}")]
    Options(&'static str),
    /// The objective could not be evaluated, or is not finite, at the
    /// start (projected into the box).
    #[error("the objective cannot be evaluated at the start")]
    Start,
}

/// Minimises `f` over the box [lo, hi] (entries may be ±∞) from `x0`
/// (projected into the box first); `f` returns the value and the gradient,
/// or `None` where it cannot be evaluated (module docs).
pub fn minimise<F>(
    mut f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    options: &Options,
) -> Result<Minimum, OptimiseError>
where
    F: FnMut(&[f64]) -> Option<(f64, Vec<f64>)>,
{
    let n = x0.len();
    for (what, v) in [("lower bounds", lo), ("upper bounds", hi)] {
        if v.len() != n {
            return Err(OptimiseError::Dimension {
                what,
                expected: n,
                found: v.len(),
            });
        }
    }
    if let Some(index) = (0..n).find(|&i| lo[i].is_nan() || hi[i].is_nan() || lo[i] > hi[i]) {
        return Err(OptimiseError::Bounds {
            index,
            lo: lo[index],
            hi: hi[index],
        });
    }
    if x0.iter().any(|v| !v.is_finite()) {
        return Err(OptimiseError::NonFinite);
    }
    if options.memory == 0 {
        return Err(OptimiseError::Options("memory must be at least 1"));
    }
    let tolerance = |t: f64| t >= 0.0 && t.is_finite();
    if !(tolerance(options.pgtol) && tolerance(options.ftol)) {
        return Err(OptimiseError::Options(
            "tolerances must be finite and non-negative",
        ));
    }
    let wrong_gradient = Cell::new(None);
    let objective = |x: &[f64]| -> Result<(f64, Vec<f64>), GpError> {
        match f(x) {
            Some((v, g)) if g.len() == n => Ok((v, g)),
            Some((_, g)) => {
                wrong_gradient.set(Some(g.len()));
                Err(GpError::DimensionMismatch {
                    what: "gradient",
                    expected: n,
                    got: g.len(),
                })
            }
            None => Err(GpError::OptimiserFailed {
                output: 0,
                reason: "objective not evaluated".into(),
            }),
        }
    };
    let opt = LbfgsOptions {
        memory: options.memory,
        max_iters: options.max_iters,
        pgtol: options.pgtol,
        ftol: options.ftol,
        unit_start: false,
    };
    let r = lbfgs::minimise(objective, x0, lo, hi, opt);
    if let Some(found) = wrong_gradient.get() {
        return Err(OptimiseError::Dimension {
            what: "gradient",
            expected: n,
            found,
        });
    }
    let r = r.map_err(|_| OptimiseError::Start)?;
    Ok(Minimum {
        x: r.x,
        f: r.f,
        iterations: r.iterations,
        evaluations: r.evaluations,
        converged: r.converged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A convex quadratic with its minimum outside the box: the optimum is
    /// the projection of the unconstrained minimum (closed form), reached
    /// to 1e-8 (pgtol 1e-10 on a problem with unit curvature).
    #[test]
    fn quadratic_in_a_box() {
        let c = [3.0, -0.2, -5.0];
        let f = |x: &[f64]| {
            let v: f64 = x.iter().zip(&c).map(|(a, b)| (a - b) * (a - b)).sum();
            Some((v, x.iter().zip(&c).map(|(a, b)| 2.0 * (a - b)).collect()))
        };
        let options = Options {
            pgtol: 1e-10,
            ..Options::default()
        };
        let m = minimise(
            f,
            &[0.0; 3],
            &[-1.0; 3],
            &[1.0, 1.0, f64::INFINITY],
            &options,
        )
        .unwrap();
        for (x, want) in m.x.iter().zip([1.0, -0.2, -1.0]) {
            assert!((x - want).abs() < 1e-8, "{:?}", m.x);
        }
        assert!(m.converged);
    }

    #[test]
    fn bad_input_is_an_error() {
        let f = |x: &[f64]| Some((x[0] * x[0], vec![2.0 * x[0]]));
        let o = Options::default();
        assert!(matches!(
            minimise(f, &[0.0], &[f64::NAN], &[1.0], &o),
            Err(OptimiseError::Bounds { .. })
        ));
        assert!(matches!(
            minimise(f, &[0.0], &[2.0], &[1.0], &o),
            Err(OptimiseError::Bounds { .. })
        ));
        assert!(matches!(
            minimise(f, &[f64::NAN], &[0.0], &[1.0], &o),
            Err(OptimiseError::NonFinite)
        ));
        assert!(matches!(
            minimise(f, &[0.0, 1.0], &[0.0], &[1.0], &o),
            Err(OptimiseError::Dimension { .. })
        ));
        let wrong = |_: &[f64]| Some((1.0, vec![0.0, 0.0]));
        assert!(matches!(
            minimise(wrong, &[0.0], &[0.0], &[1.0], &o),
            Err(OptimiseError::Dimension { .. })
        ));
        let none = |_: &[f64]| None;
        assert_eq!(
            minimise(none, &[0.0], &[0.0], &[1.0], &o),
            Err(OptimiseError::Start)
        );
        let zero = Options { memory: 0, ..o };
        assert!(matches!(
            minimise(f, &[0.0], &[0.0], &[1.0], &zero),
            Err(OptimiseError::Options(_))
        ));
    }
}
