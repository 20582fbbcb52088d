//! Newton solver options, diagnostics, the step error type, and the
//! regularised KKT solve of the Newton steps.

use crate::linalg::solve_kkt;
use nalgebra::{SMatrix, SVector};

/// Options of the Newton solves inside implicit steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonOptions {
    /// Convergence when the scaled residual max-norm falls below this
    /// (momentum residual relative to 1 + |p₀|, constraint residual relative
    /// to 1 + the largest length coordinate, so effectively absolute in
    /// metres for mechanisms near the origin). Default 1e-12.
    pub tolerance: f64,
    /// Iteration cap (default 25).
    pub max_iterations: usize,
    /// Smallest line-search step tried before Newton is declared stalled
    /// (default 1/256).
    pub min_step: f64,
    /// A stalled Newton iteration (no decrease possible along the Newton
    /// direction, as at a configuration where a loop's constraint Jacobian
    /// loses rank) is accepted when both scaled residuals are below this
    /// (default 1e-10; reported as [`StepInfo::stalled`]). Set it equal to
    /// `tolerance` to refuse stalled steps.
    pub stall_tolerance: f64,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-12,
            max_iterations: 25,
            min_step: 1.0 / 256.0,
            stall_tolerance: 1e-10,
        }
    }
}

impl NewtonOptions {
    /// Reject options that cannot work.
    pub fn validate(&self) -> Result<(), StepError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(StepError::InvalidOptions(
                "tolerance must be finite and > 0",
            ));
        }
        if !(self.stall_tolerance.is_finite() && self.stall_tolerance >= self.tolerance) {
            return Err(StepError::InvalidOptions(
                "stall_tolerance must be finite and >= tolerance",
            ));
        }
        if !(self.min_step > 0.0 && self.min_step <= 1.0) {
            return Err(StepError::InvalidOptions("min_step must be in (0, 1]"));
        }
        Ok(())
    }
}

/// Diagnostics of a converged step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepInfo {
    /// Newton iterations used.
    pub iterations: usize,
    /// Final scaled residual (max-norm).
    pub residual: f64,
    /// `true` when the step was accepted as stalled (see
    /// [`NewtonOptions::stall_tolerance`]) rather than converged.
    pub stalled: bool,
    /// `true` when some Newton matrix was singular and the equivalent
    /// regularised KKT system was solved instead (see
    /// [`solve_kkt_regularised`]).
    pub regularised: bool,
    /// `true` when the first Newton run failed and the solve was restarted
    /// from a feasible point (the velocity projection from far off the
    /// manifold, see [`crate::projection::project_velocity`]).
    pub restarted: bool,
}

/// A KKT solution (x, y) of [`solve_kkt_regularised`].
pub type KktSolution<const N: usize, const C: usize> = (SVector<f64, N>, SVector<f64, C>);

/// Solve the KKT system of a Newton step,
///
/// ```text
/// [ J   B ] [x]   [r]
/// [ A   0 ] [y] = [c],
/// ```
///
/// by [`solve_kkt`] (Schur complement, J invertible); when J is singular but
/// the whole KKT matrix is not (a link without rotational inertia in
/// maximal coordinates, whose orientation the constraints fix), solve the
/// equivalent augmented system
///
/// ```text
/// (J + ρ·B·A) x + B y = r + ρ·B·c,   A x = c
/// ```
///
/// which has the same solution (add ρ·B times the second row to the first).
/// ρ = ±‖J‖/‖B·A‖ (max-norms) with the sign of tr(J)·tr(B·A), so that
/// ρ·B·A adds to J with J's own sign (J ≈ −M in the variational step,
/// +M in the acceleration solve, I in the projection). The augmented
/// solution is accepted only when it solves the original system to 1e-8
/// relative to ‖J‖‖x‖ + ‖B‖‖y‖ + ‖r‖ (rows of J) and ‖A‖‖x‖ + ‖c‖ (rows
/// of A): the augmentation multiplies the condition number by up to
/// ρ‖B·A‖/‖J‖ = 1, so round-off stays near ε·cond; otherwise, or when J is
/// singular and C = 0, `None`.
///
/// Returns the solution and whether the regularisation was needed.
pub fn solve_kkt_regularised<const N: usize, const C: usize>(
    j: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, C>,
    a: &SMatrix<f64, C, N>,
    r: &SVector<f64, N>,
    c: &SVector<f64, C>,
) -> Option<(KktSolution<N, C>, bool)> {
    if let Some(sol) = solve_kkt(j, b, a, r, c) {
        return Some((sol, false));
    }
    if C == 0 {
        return None;
    }
    let k = b * a;
    let (jn, kn) = (j.amax(), k.amax());
    if !(kn > 0.0 && kn.is_finite() && jn.is_finite()) {
        return None;
    }
    let sign = if j.trace() * k.trace() >= 0.0 {
        1.0
    } else {
        -1.0
    };
    let rho = sign * if jn > 0.0 { jn / kn } else { 1.0 / kn };
    let (x, y) = solve_kkt(&(j + k * rho), b, a, &(r + b * c * rho), c)?;
    // the augmented system is equivalent in exact arithmetic; check it
    let e1 = (j * x + b * y - r).amax();
    let e2 = (a * x - c).amax();
    let s1 = j.amax() * x.amax() + b.amax() * y.amax() + r.amax();
    let s2 = a.amax() * x.amax() + c.amax();
    let ok = e1 <= 1e-8 * s1.max(f64::MIN_POSITIVE) && e2 <= 1e-8 * s2.max(f64::MIN_POSITIVE);
    (ok && x.iter().chain(y.iter()).all(|v| v.is_finite())).then_some(((x, y), true))
}

/// Why a step failed. `step` is filled in by rollouts with the index of the
/// failing step.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    /// Δt is not finite or not positive.
    #[error("invalid time step dt = {dt} (must be finite and > 0)")]
    InvalidTimeStep {
        /// The offending Δt.
        dt: f64,
    },
    /// Solver options that cannot work.
    #[error("invalid solver options: {0}")]
    InvalidOptions(&'static str),
    /// The input (or produced) state contains NaN or ±∞.
    #[error("non-finite state{}", at(step))]
    NonFiniteState {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// The residual became NaN or ±∞ during Newton iterations.
    #[error("non-finite residual at Newton iteration {iteration}{}", at(step))]
    NonFiniteResidual {
        /// Newton iteration.
        iteration: usize,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// The Newton matrix is singular.
    #[error("singular Newton matrix at iteration {iteration}{}", at(step))]
    SingularJacobian {
        /// Newton iteration.
        iteration: usize,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A learned model's prediction failed or was not finite.
    #[error("learned prediction failed{}", at(step))]
    Prediction {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// The iteration cap was reached before the tolerance.
    #[error(
        "Newton did not converge: {iterations} iterations, residual {residual:.3e} > tolerance {tolerance:.1e}{}",
        at(step)
    )]
    NotConverged {
        /// Iterations used.
        iterations: usize,
        /// Scaled residual reached.
        residual: f64,
        /// Tolerance asked for.
        tolerance: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// Newton did not converge from a state whose configuration violates
    /// the constraints: the step had to close the gap |g(q)| at once. The
    /// remedy is a consistent initial state.
    #[error(
        "Newton did not converge from a state off the constraints (|g(q)| = {violation:.3e}, \
         residual {residual:.3e} after {iterations} iterations){}: start from a consistent state, \
         vigp::projection::consistent_state (or consistent_state_holding to keep chosen \
         coordinates, e.g. a crank angle, fixed)",
        at(step)
    )]
    OffConstraints {
        /// |g(q)| of the state the step started from (scaled like the
        /// constraint residual).
        violation: f64,
        /// Iterations used.
        iterations: usize,
        /// Scaled residual reached.
        residual: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
}

fn at(step: &Option<usize>) -> String {
    match step {
        Some(k) => format!(" (rollout step {k})"),
        None => String::new(),
    }
}

impl StepError {
    /// The same error, tagged with a rollout step index.
    pub fn at_step(mut self, k: usize) -> Self {
        match &mut self {
            StepError::NonFiniteState { step }
            | StepError::NonFiniteResidual { step, .. }
            | StepError::SingularJacobian { step, .. }
            | StepError::NotConverged { step, .. }
            | StepError::OffConstraints { step, .. }
            | StepError::Prediction { step } => *step = Some(k),
            StepError::InvalidTimeStep { .. } | StepError::InvalidOptions(_) => {}
        }
        self
    }
}
