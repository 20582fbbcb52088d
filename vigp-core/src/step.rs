//! The first-order variational step (paper eq. 5–6, α = 0 rule of the std
//! runtime's `Variational::new`) on fixed-size data, without allocation.
//!
//! With x₁ = x₀ + Δt·v₀ the unknowns are v₁ and the multipliers λ:
//!
//! ```text
//! d(v₁, λ) = p₀ + Δt·(½[v₁ᵀ ∂M/∂q_i v₁]_i − ∇V − D v₁) − M v₁ − G(x₁)ᵀλ = 0
//! c(v₁)    = g(x₁ + Δt·v₁) = 0,                p₀ = M(x₀) v₀
//! ```
//!
//! (all terms at x₁). Because x₁ is fixed, M, ∂M/∂q, ∇V and D are computed
//! once per step by one [`Jet2`](crate::Jet2) pass of the kinematics
//! ([`terms`]); each Newton iteration is then `O(N³)` arithmetic on small
//! matrices (plus one [`Jet1`](crate::Jet1) pass of the loop constraints for
//! closed chains). A rollout carries p₁ = M(x₁)v₁ to the next step, so it
//! costs one kinematics pass per step.
//!
//! Numerical caveats: the Newton matrix is Δt(Q − D) − M (Q_ij = (∂M/∂q_i v)_j),
//! solved by LU with complete pivoting; for loops the KKT system is solved by
//! its Schur complement G A⁻¹Gᵀ with complete pivoting, so where G loses
//! rank only the deficient multiplier is dropped (convergence there may
//! still fail: [`StepError::LineSearchFailed`]).

use crate::linalg::{solve_kkt, solve_partial};
use crate::model::{Model, constraints_and_jacobian, mass_matrix, terms};
use crate::state::{CoordinateKind, State};
use nalgebra::{SMatrix, SVector};

/// Options of the Newton solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOptions {
    /// Convergence when the scaled residual max-norm is below this
    /// (momentum residual relative to |p₀|∞ + the largest diagonal entry of
    /// M, constraint residual relative to 1 + the largest length
    /// coordinate). Default 1e-12, as the std runtime.
    pub tolerance: f64,
    /// Iteration cap (default 25).
    pub max_iterations: usize,
    /// Smallest line-search step before the step fails (default 1/256).
    pub min_step: f64,
}

impl Default for StepOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-12,
            max_iterations: 25,
            min_step: 1.0 / 256.0,
        }
    }
}

/// Why a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepError {
    /// Δt is not finite or not positive.
    InvalidTimeStep {
        /// The offending Δt.
        dt: f64,
    },
    /// Options that cannot work.
    InvalidOptions(&'static str),
    /// Model parameters that cannot describe a mechanism: a negative or
    /// non-finite mass, inertia or damping coefficient, or non-finite
    /// gravity.
    InvalidModel(&'static str),
    /// The state (or the momentum) holds NaN or ±∞.
    NonFiniteState,
    /// The residual became NaN or ±∞.
    NonFiniteResidual {
        /// Newton iteration.
        iteration: usize,
    },
    /// The Newton (or Schur) matrix is singular.
    SingularJacobian {
        /// Newton iteration.
        iteration: usize,
    },
    /// The line search found no decrease down to `min_step`.
    LineSearchFailed {
        /// Newton iteration.
        iteration: usize,
        /// Scaled residual reached.
        residual: f64,
    },
    /// The iteration cap was reached before the tolerance.
    NotConverged {
        /// Iterations used.
        iterations: usize,
        /// Scaled residual reached.
        residual: f64,
    },
}

impl core::fmt::Display for StepError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidTimeStep { dt } => {
                write!(f, "invalid time step dt = {dt} (must be finite and > 0)")
            }
            Self::InvalidOptions(why) => write!(f, "invalid step options: {why}"),
            Self::InvalidModel(why) => write!(f, "invalid model parameters: {why}"),
            Self::NonFiniteState => write!(f, "non-finite state or momentum"),
            Self::NonFiniteResidual { iteration } => {
                write!(f, "non-finite residual at Newton iteration {iteration}")
            }
            Self::SingularJacobian { iteration } => {
                write!(f, "singular Newton matrix at iteration {iteration}")
            }
            Self::LineSearchFailed {
                iteration,
                residual,
            } => write!(
                f,
                "line search failed at Newton iteration {iteration}, residual {residual:.3e}"
            ),
            Self::NotConverged {
                iterations,
                residual,
            } => write!(
                f,
                "Newton did not converge: {iterations} iterations, residual {residual:.3e}"
            ),
        }
    }
}

impl core::error::Error for StepError {}

/// A step error inside a rollout, with the index of the failing step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RolloutError {
    /// Index of the step that failed (0 = the step from the initial state).
    pub step: usize,
    /// What failed.
    pub error: StepError,
}

impl core::fmt::Display for RolloutError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "rollout step {}: {}", self.step, self.error)
    }
}

impl core::error::Error for RolloutError {}

/// Diagnostics of a converged step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// Newton iterations used.
    pub iterations: usize,
    /// Final scaled residual: evaluated, or, for a tree (`C = 0`) whose
    /// last Newton step was a full one, its quadratic remainder
    /// (Δt/2)[Δvᵀ ∂M/∂q_i Δv]_i (the residual is exactly quadratic in v, so
    /// this is the residual left by that step, up to rounding).
    pub residual: f64,
}

/// The first-order variational integrator of a [`Model`] with a fixed Δt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stepper<M, const N: usize, const C: usize> {
    model: M,
    dt: f64,
    options: StepOptions,
}

fn max_abs<const K: usize>(x: &SVector<f64, K>) -> f64 {
    x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

impl<M: Model<N, C>, const N: usize, const C: usize> Stepper<M, N, C> {
    /// A stepper with default options.
    pub fn new(model: M, dt: f64) -> Result<Self, StepError> {
        Self::with_options(model, dt, StepOptions::default())
    }

    /// A stepper with the given options.
    pub fn with_options(model: M, dt: f64, options: StepOptions) -> Result<Self, StepError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(StepError::InvalidTimeStep { dt });
        }
        if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
            return Err(StepError::InvalidOptions(
                "tolerance must be finite and > 0",
            ));
        }
        if !(options.min_step > 0.0 && options.min_step <= 1.0) {
            return Err(StepError::InvalidOptions("min_step must be in (0, 1]"));
        }
        validate(&model)?;
        Ok(Self { model, dt, options })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// Δt.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Discrete momentum p = M(q)v of a state (the p₀ of its step).
    pub fn momentum(&self, z: &State<N>) -> SVector<f64, N> {
        mass_matrix(&self.model, &z.q) * z.v
    }

    /// One step from `z`.
    pub fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        // `solve` refuses a non-finite z or p₀ with `NonFiniteState`.
        let p0 = self.momentum(z);
        self.solve(z, &p0, &z.v).map(|(z1, _, _)| z1)
    }

    /// One step from `z` with its momentum `p0` known (from the previous
    /// step); returns the new state, its momentum and diagnostics.
    pub fn step_with_momentum(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError> {
        self.solve(z, p0, &z.v)
    }

    /// The step from `z` with momentum `p0`, Newton started at `guess`.
    fn solve(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        guess: &SVector<f64, N>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError> {
        if !z.is_finite() || !p0.iter().all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteState);
        }
        self.solve_finite(z, p0, guess)
    }

    /// [`Self::solve`] for inputs known to be finite: a converged step's
    /// outputs are (its residual is finite), so rollouts check only z₀.
    fn solve_finite(
        &self,
        z: &State<N>,
        p0: &SVector<f64, N>,
        guess: &SVector<f64, N>,
    ) -> Result<(State<N>, SVector<f64, N>, StepReport), StepError> {
        let h = self.dt;
        let x1 = z.q + z.v * h;
        let t = terms(&self.model, &x1);
        // Momentum scale |p₀|∞ + m̄ (m̄ = largest diagonal entry of M, i.e.
        // one unit of velocity's momentum) so that convergence does not
        // depend on the mass unit; the std runtime scales the same way.
        let m_bar = (0..N).map(|i| t.mass[(i, i)].abs()).fold(0.0, f64::max);
        let p_scale = match max_abs(p0) + m_bar {
            0.0 => 1.0,
            s => s,
        };
        let mut l_scale = 1.0f64;
        for (x, kind) in x1.iter().zip(M::KINDS.iter()) {
            if *kind == CoordinateKind::Length {
                l_scale = l_scale.max(1.0 + x.abs());
            }
        }
        let g1 = if C > 0 {
            constraints_and_jacobian(&self.model, &x1).1
        } else {
            SMatrix::zeros()
        };
        // d(v) = b − M_h v + (Δt/2)[vᵀ ∂M/∂q_i v]_i with the v-independent
        // parts formed once: b = p₀ − Δt∇V, M_h = M + Δt·D.
        let b = p0 - t.dpotential * h;
        let m_h = if M::DISSIPATIVE {
            t.mass + t.damping * h
        } else {
            t.mass
        };
        let inv_p_scale = 1.0 / p_scale;
        let inv_l_scale = 1.0 / l_scale;
        let eval = |v: &SVector<f64, N>, lambda: &SVector<f64, C>| {
            let (d, q) = residual(&t.dmass, &m_h, &b, h, v);
            let d = d - g1.transpose() * lambda;
            let (c, g2) = if C > 0 {
                constraints_and_jacobian(&self.model, &(x1 + v * h))
            } else {
                (SVector::zeros(), SMatrix::zeros())
            };
            let err = (max_abs(&d) * inv_p_scale).max(max_abs(&c) * inv_l_scale);
            (d, q, c, g2, err)
        };
        let mut v = if guess.iter().all(|x| x.is_finite()) {
            *guess
        } else {
            z.v
        };
        let mut lambda = SVector::<f64, C>::zeros();
        let (mut d, mut q, mut c, mut g2, mut err) = eval(&v, &lambda);
        for iteration in 0..self.options.max_iterations {
            if !err.is_finite() {
                return Err(StepError::NonFiniteResidual { iteration });
            }
            if err <= self.options.tolerance {
                let z1 = State { q: x1, v };
                return Ok((
                    z1,
                    t.mass * v,
                    StepReport {
                        iterations: iteration,
                        residual: err,
                    },
                ));
            }
            // Newton matrix A = ∂d/∂v = ΔtQ − M_h, Q_ij = (∂M/∂q_i v)_j.
            let a = q * h - m_h;
            let singular = StepError::SingularJacobian { iteration };
            let (dv, dl) = if C == 0 {
                // A is a small perturbation of −M: partial pivoting suffices.
                let dv = solve_partial(&a, &(-d)).ok_or(singular)?;
                // With x₁ fixed, d is exactly quadratic in v, so after a full
                // Newton step the residual is the quadratic remainder
                // d(v + Δ) = (Δt/2)[Δᵀ ∂M/∂q_i Δ]_i, up to the O(ε·scale)
                // rounding of d(v) and of the solve. That costs N³
                // multiply-adds, less than evaluating d (which also forms Q
                // and M_h v). When it is within half the tolerance (the other
                // half covers the rounding, ~1e-16 relative) the step is
                // accepted without evaluating d again.
                let half_h = 0.5 * h;
                let bound = t
                    .dmass
                    .iter()
                    .map(|dm| (half_h * dv.dot(&(dm * dv))).abs())
                    .fold(0.0, f64::max)
                    * inv_p_scale;
                if bound <= 0.5 * self.options.tolerance {
                    let v1 = v + dv;
                    if v1.iter().all(|x| x.is_finite()) {
                        return Ok((
                            State { q: x1, v: v1 },
                            t.mass * v1,
                            StepReport {
                                iterations: iteration + 1,
                                residual: bound,
                            },
                        ));
                    }
                }
                (dv, SVector::zeros())
            } else {
                // A Δv − G₁ᵀΔλ = −d,  G₂ Δv = −c/Δt (Schur complement, complete
                // pivoting: a rank-deficient G loses only the deficient
                // multiplier).
                solve_kkt(&a, &(-g1.transpose()), &g2, &(-d), &(c / -h)).ok_or(singular)?
            };
            // Backtracking on the scaled residual.
            let mut alpha = 1.0;
            loop {
                let (vn, ln) = (v + dv * alpha, lambda + dl * alpha);
                let (dn, qn, cn, g2n, errn) = eval(&vn, &ln);
                if errn.is_finite() && (errn < err || errn <= self.options.tolerance) {
                    (v, lambda, d, q, c, g2, err) = (vn, ln, dn, qn, cn, g2n, errn);
                    break;
                }
                alpha *= 0.5;
                if alpha < self.options.min_step {
                    return Err(StepError::LineSearchFailed {
                        iteration,
                        residual: err,
                    });
                }
            }
        }
        if err <= self.options.tolerance {
            return Ok((
                State { q: x1, v },
                t.mass * v,
                StepReport {
                    iterations: self.options.max_iterations,
                    residual: err,
                },
            ));
        }
        Err(StepError::NotConverged {
            iterations: self.options.max_iterations,
            residual: err,
        })
    }

    /// Fills `out` with the trajectory from `z0`: `out[0] = z0`, then one
    /// step per entry. The momentum is carried from step to step, so each
    /// step costs one kinematics pass, and Newton starts from the linear
    /// extrapolation 2v_k − v_{k−1} (one iteration fewer on smooth motion;
    /// the converged step is the same to the solver tolerance). No
    /// allocation.
    pub fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), RolloutError> {
        let Some((first, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        if !z0.is_finite() {
            return Err(RolloutError {
                step: 0,
                error: StepError::NonFiniteState,
            });
        }
        *first = *z0;
        let (mut z, mut p, mut v_prev) = (*z0, self.momentum(z0), z0.v);
        if !p.iter().all(|x| x.is_finite()) {
            return Err(RolloutError {
                step: 0,
                error: StepError::NonFiniteState,
            });
        }
        for (k, slot) in rest.iter_mut().enumerate() {
            let guess = z.v * 2.0 - v_prev;
            let (z1, p1, _) = self
                .solve_finite(&z, &p, &guess)
                .map_err(|error| RolloutError { step: k, error })?;
            *slot = z1;
            v_prev = z.v;
            (z, p) = (z1, p1);
        }
        Ok(())
    }
}

/// Checks the run-time parameters a [`Model`] exposes: gravity finite,
/// every body's mass and inertia finite and ≥ 0 (zero is a massless link),
/// every damping coefficient finite and ≥ 0 (a negative one would inject
/// energy). Bodies and dampers are visited once at q = 0 (their parameters
/// do not depend on q).
fn validate<M: Model<N, C>, const N: usize, const C: usize>(model: &M) -> Result<(), StepError> {
    let ok = |x: f64| x.is_finite() && x >= 0.0;
    if !model.gravity().iter().all(|g| g.is_finite()) {
        return Err(StepError::InvalidModel("gravity must be finite"));
    }
    let q = SVector::<f64, N>::zeros();
    let mut err = None;
    model.for_each_body(&q, &mut |b| {
        if !ok(b.mass) {
            err = err.or(Some("a link mass is negative or not finite"));
        }
        if !ok(b.inertia) {
            err = err.or(Some("a link inertia is negative or not finite"));
        }
    });
    model.for_each_damper(&q, &mut |c, _| {
        if !ok(c) {
            err = err.or(Some("a damping coefficient is negative or not finite"));
        }
    });
    err.map_or(Ok(()), |why| Err(StepError::InvalidModel(why)))
}

/// d(v) without the multiplier term, b − M_h v + (Δt/2)[vᵀ∂M/∂q_i v]_i
/// (b = p₀ − Δt∇V, M_h = M + ΔtD), and Q (row i = (∂M/∂q_i v)ᵀ), which the
/// Newton matrix reuses.
fn residual<const N: usize>(
    dmass: &[SMatrix<f64, N, N>; N],
    m_h: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    h: f64,
    v: &SVector<f64, N>,
) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
    let mut d = b - m_h * v;
    let mut q = SMatrix::<f64, N, N>::zeros();
    let half_h = 0.5 * h;
    for (i, dm) in dmass.iter().enumerate() {
        let dmv = dm * v;
        d[i] += half_h * v.dot(&dmv);
        q.set_row(i, &dmv.transpose());
    }
    (d, q)
}
