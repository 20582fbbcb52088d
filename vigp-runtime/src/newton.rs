//! Newton solver options, diagnostics and the step error type.

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
            | StepError::Prediction { step } => *step = Some(k),
            StepError::InvalidTimeStep { .. } | StepError::InvalidOptions(_) => {}
        }
        self
    }
}
