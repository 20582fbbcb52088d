//! A small projected L-BFGS for box-constrained minimisation.
//!
//! Why hand-written: `argmin` 0.11 has L-BFGS without bounds, and the pure-Rust
//! L-BFGS-B ports on crates.io are young single-author 0.1 releases. GP
//! hyperparameter problems have d + 2 ≤ a few dozen variables, where a
//! projected quasi-Newton method (Bertsekas 1982; Kim, Sra & Dhillon 2010) is
//! simple, deterministic and sufficient:
//!
//! * the active set holds the variables at a bound whose gradient pushes
//!   outwards; the L-BFGS two-loop direction is computed and then zeroed on
//!   the active set (steepest descent if that is not a descent direction);
//! * a backtracking Armijo search along the projected path
//!   P(x + t·d) keeps every iterate feasible; an evaluation that fails (e.g. a
//!   kernel matrix that is not positive definite) counts as +∞;
//! * curvature pairs with sᵀy ≤ 0 are skipped, so the inverse-Hessian
//!   approximation stays positive definite;
//! * stop when ‖P(x − g) − x‖∞ ≤ `pgtol`, or the relative decrease of f is
//!   below `ftol` (as scipy's L-BFGS-B `factr` test), or after `max_iters`.

use std::collections::VecDeque;

use super::error::GpError;

/// Options of [`minimise`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct LbfgsOptions {
    pub memory: usize,
    pub max_iters: usize,
    pub pgtol: f64,
    pub ftol: f64,
}

/// Outcome of [`minimise`].
#[derive(Clone, Debug)]
pub(crate) struct LbfgsResult {
    pub x: Vec<f64>,
    pub f: f64,
    pub iterations: usize,
    pub evaluations: usize,
    pub converged: bool,
}

fn project(x: &mut [f64], lo: &[f64], hi: &[f64]) {
    for ((v, l), h) in x.iter_mut().zip(lo).zip(hi) {
        *v = v.clamp(*l, *h);
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimises `f` (returning value and gradient) over the box [lo, hi] from x0.
pub(crate) fn minimise<F>(
    mut f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    opt: LbfgsOptions,
) -> Result<LbfgsResult, GpError>
where
    F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), GpError>,
{
    let n = x0.len();
    let mut x = x0.to_vec();
    project(&mut x, lo, hi);
    let (mut fx, mut g) = f(&x)?;
    let mut evaluations = 1;
    let mut mem: VecDeque<(Vec<f64>, Vec<f64>, f64)> = VecDeque::new();
    let mut converged = false;
    let mut iterations = 0;
    let mut x_new = vec![0.0; n];
    while iterations < opt.max_iters {
        // Projected-gradient test.
        let pg = (0..n)
            .map(|i| ((x[i] - g[i]).clamp(lo[i], hi[i]) - x[i]).abs())
            .fold(0.0, f64::max);
        if pg <= opt.pgtol {
            converged = true;
            break;
        }
        iterations += 1;
        let active: Vec<bool> = (0..n)
            .map(|i| (x[i] <= lo[i] && g[i] > 0.0) || (x[i] >= hi[i] && g[i] < 0.0))
            .collect();
        let mut accepted = None;
        for attempt in 0..2 {
            if attempt == 1 {
                if mem.is_empty() {
                    break;
                }
                mem.clear();
            }
            let d = direction(&g, &active, &mem);
            let slope = dot(&g, &d);
            let d = if slope < 0.0 {
                d
            } else {
                (0..n)
                    .map(|i| if active[i] { 0.0 } else { -g[i] })
                    .collect()
            };
            // First step of a fresh memory: move at most 1 in log space.
            let dmax = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if dmax == 0.0 {
                break;
            }
            let mut t = if mem.is_empty() {
                (1.0 / dmax).min(1.0)
            } else {
                1.0
            };
            for _ in 0..40 {
                for i in 0..n {
                    x_new[i] = x[i] + t * d[i];
                }
                project(&mut x_new, lo, hi);
                let step: Vec<f64> = (0..n).map(|i| x_new[i] - x[i]).collect();
                let decrease = dot(&g, &step);
                if step.iter().all(|s| *s == 0.0) {
                    break;
                }
                evaluations += 1;
                if let Ok((fn_, gn)) = f(&x_new)
                    && fn_.is_finite()
                    && fn_ <= fx + 1e-4 * decrease
                {
                    accepted = Some((fn_, gn, step));
                    break;
                }
                t *= 0.5;
            }
            if accepted.is_some() {
                break;
            }
        }
        let Some((fn_, gn, s)) = accepted else {
            // No progress possible along any direction: a (numerical) stationary point.
            converged = true;
            break;
        };
        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() && sy > 0.0 {
            if mem.len() == opt.memory {
                mem.pop_front();
            }
            mem.push_back((s, y, 1.0 / sy));
        }
        let f_old = fx;
        x.copy_from_slice(&x_new);
        fx = fn_;
        g = gn;
        if (f_old - fx) <= opt.ftol * f_old.abs().max(fx.abs()).max(1.0) {
            converged = true;
            break;
        }
    }
    Ok(LbfgsResult {
        x,
        f: fx,
        iterations,
        evaluations,
        converged,
    })
}

/// Two-loop recursion on the free variables: d = −H·g with active entries zeroed.
fn direction(g: &[f64], active: &[bool], mem: &VecDeque<(Vec<f64>, Vec<f64>, f64)>) -> Vec<f64> {
    let mut q: Vec<f64> = g
        .iter()
        .zip(active)
        .map(|(v, a)| if *a { 0.0 } else { *v })
        .collect();
    let mut alphas = Vec::with_capacity(mem.len());
    for (s, y, rho) in mem.iter().rev() {
        let a = rho * dot(s, &q);
        for (qi, yi) in q.iter_mut().zip(y) {
            *qi -= a * yi;
        }
        alphas.push(a);
    }
    if let Some((s, y, _)) = mem.back() {
        let gamma = dot(s, y) / dot(y, y);
        q.iter_mut().for_each(|v| *v *= gamma);
    }
    for ((s, y, rho), a) in mem.iter().zip(alphas.iter().rev()) {
        let b = rho * dot(y, &q);
        for (qi, si) in q.iter_mut().zip(s) {
            *qi += (a - b) * si;
        }
    }
    q.iter()
        .zip(active)
        .map(|(v, a)| if *a { 0.0 } else { -v })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> LbfgsOptions {
        LbfgsOptions {
            memory: 10,
            max_iters: 500,
            pgtol: 1e-9,
            ftol: 0.0,
        }
    }

    #[test]
    fn rosenbrock_unconstrained_interior() {
        let f = |x: &[f64]| {
            let (a, b) = (x[0], x[1]);
            let v = (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2);
            let g = vec![
                -2.0 * (1.0 - a) - 400.0 * a * (b - a * a),
                200.0 * (b - a * a),
            ];
            Ok((v, g))
        };
        let r = minimise(f, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], opts()).unwrap();
        assert!(r.converged);
        // Minimiser (1, 1); pgtol 1e-9 on a well-conditioned-near-optimum problem
        // gives ~1e-8 accuracy in x.
        assert!(
            (r.x[0] - 1.0).abs() < 1e-6 && (r.x[1] - 1.0).abs() < 1e-6,
            "{:?}",
            r.x
        );
    }

    #[test]
    fn quadratic_with_active_bound() {
        // min (x-3)² + (y+1)² on [0,2]×[0,2]: solution (2, 0), both bounds active.
        let f = |x: &[f64]| {
            Ok((
                (x[0] - 3.0).powi(2) + (x[1] + 1.0).powi(2),
                vec![2.0 * (x[0] - 3.0), 2.0 * (x[1] + 1.0)],
            ))
        };
        let r = minimise(f, &[1.0, 1.0], &[0.0, 0.0], &[2.0, 2.0], opts()).unwrap();
        assert!(r.converged);
        assert_eq!(r.x, vec![2.0, 0.0]);
    }
}
