//! Why a step failed: the one error type of every integrator in vigp, from
//! the `no_std` [`Stepper`](crate::Stepper) to the std runtime's learned
//! rollouts (which re-export it as `vigp::StepError`).
//!
//! Errors that can happen inside a rollout carry `step`: `None` from a
//! single step, the index of the failing step once a rollout has tagged it
//! ([`StepError::at_step`]).

use core::fmt;

/// Why a step failed. `step` is filled in by rollouts with the index of the
/// failing step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepError {
    /// Δt is not finite, not positive, or so large or small that Δt² is
    /// not a normal f64.
    InvalidTimeStep {
        /// The offending Δt.
        dt: f64,
    },
    /// Solver options that cannot work.
    InvalidOptions(&'static str),
    /// Run-time parameters that cannot describe a mechanism (a negative or
    /// non-finite mass, inertia or damping coefficient, a non-positive
    /// length, non-finite gravity; the message names the parameter).
    InvalidModel(&'static str),
    /// The state (or the momentum) holds NaN or ±∞.
    NonFiniteState {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// An input (actuator torque or force) is NaN or ±∞, or the input
    /// sequence is shorter than the rollout.
    NonFiniteInput {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A spatial state's orientation quaternion is not of unit norm (see
    /// [`crate::spatial::SpatialState::validate`]).
    NonUnitQuaternion {
        /// The link, in declaration order.
        link: usize,
        /// Its quaternion's norm ‖q‖.
        norm: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// Non-zero inputs given to an integrator that cannot take them (a
    /// learned model trained without inputs).
    InputsNotSupported,
    /// The residual became NaN or ±∞ during Newton iterations.
    NonFiniteResidual {
        /// Newton iteration.
        iteration: usize,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// The Newton (or KKT) matrix is singular.
    SingularJacobian {
        /// Newton iteration.
        iteration: usize,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A learned model's prediction failed or was not finite.
    Prediction {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// No decrease of the residual along the exact Newton direction down
    /// to the smallest line-search step, above the stall tolerance: the
    /// discrete equations have no root near the start (often a step too
    /// large for the motion).
    LineSearchFailed {
        /// Newton iteration.
        iteration: usize,
        /// Scaled residual reached.
        residual: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// The iteration cap was reached before the tolerance.
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
    /// Newton converged, but to a root that is not the continuation of the
    /// motion: the step bends the discrete path by |h·(v₁ − v₀)|∞ = `ratio`
    /// (radians, or scaled lengths), more than `bound`, and gains more
    /// energy than half the two energies' magnitudes (see
    /// [`Stepper::continuation_bound`](crate::Stepper::continuation_bound)).
    NotContinuation {
        /// The bend |h·(v₁ − v₀)|∞ of the step.
        ratio: f64,
        /// The bound in force.
        bound: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A step that failed (no root near the start, or a root that is not
    /// the continuation of the motion) and still failed after halving its
    /// sub-step `depth` times.
    NotResolved {
        /// Halvings tried.
        depth: u32,
        /// The smallest sub-step tried (s).
        substep_dt: f64,
        /// The residual (or bend) of the last failure.
        residual: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A rollout of this many steps whose states cannot be stored:
    /// (steps + 1)·(size of a state) exceeds the address space (a duration
    /// divided by Δt = 0 gives such a count). See
    /// [`check_step_count`](crate::step::check_step_count).
    TooManySteps {
        /// The step count asked for.
        steps: usize,
    },
    /// A link whose mass or rotational inertia is negligible against the
    /// mechanism's (below [`crate::spatial::maximal::NEGLIGIBLE_INERTIA`]
    /// of its scale): the maximal view's Newton matrix cannot resolve its
    /// motion, so [`crate::spatial::LieStepper`] refuses it at
    /// construction. A massless connector (a cross link between two
    /// revolute joints) is a joint: `universal`, or fold the link into
    /// its neighbour. The minimal view takes such links.
    NegligibleInertia {
        /// The link's name.
        link: &'static str,
        /// Which inertia: `"mass"` (kg) or `"smallest principal moment of
        /// inertia"` (kg·m²).
        what: &'static str,
        /// Its value.
        value: f64,
        /// The smallest value accepted for this mechanism.
        bound: f64,
    },
    /// A mechanism whose loop equations g(q) = 0 have no solution that
    /// Gauss–Newton finds from several starts (links too short or too long
    /// to close the loop): refused when the integrator is built, with the
    /// smallest scaled residual |g(q)|∞ / (1 + |q|∞) found.
    LoopCannotClose {
        /// The smallest scaled residual found.
        residual: f64,
    },
    /// Newton did not converge from a state whose configuration violates
    /// the constraints: the step had to close the gap |g(q)| at once. The
    /// remedy is a consistent initial state.
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

/// " (rollout step k)" after a message, or nothing outside a rollout.
struct At(Option<usize>);

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(k) => write!(f, " (rollout step {k})"),
            None => Ok(()),
        }
    }
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::InvalidTimeStep { dt } => write!(
                f,
                "invalid time step dt = {dt:e} (must be finite and > 0, with dt² a normal number)"
            ),
            Self::InvalidOptions(why) => write!(f, "invalid solver options: {why}"),
            Self::InvalidModel(why) => write!(f, "invalid model parameters: {why}"),
            Self::NonFiniteState { step } => write!(f, "non-finite state{}", At(step)),
            Self::NonFiniteInput { step } => {
                write!(f, "non-finite or missing input{}", At(step))
            }
            Self::NonUnitQuaternion { link, norm, step } => write!(
                f,
                "the quaternion of link {link} has norm {norm} (must be 1 to 1e-9: normalise it, e.g. \
                 UnitQuaternion::new_normalize, or start from a consistent state, \
                 vigp::projection::consistent_state){}",
                At(step)
            ),
            Self::InputsNotSupported => write!(f, "this integrator does not take inputs"),
            Self::NonFiniteResidual { iteration, step } => write!(
                f,
                "non-finite residual at Newton iteration {iteration}{}",
                At(step)
            ),
            Self::SingularJacobian { iteration, step } => write!(
                f,
                "singular Newton matrix at iteration {iteration}{}",
                At(step)
            ),
            Self::Prediction { step } => write!(f, "learned prediction failed{}", At(step)),
            Self::LineSearchFailed {
                iteration,
                residual,
                step,
            } => write!(
                f,
                "Newton stalled at iteration {iteration}: residual {residual:.3e} cannot be decreased along the \
                 Newton direction{} (no root near the start: often a step too large for the motion; try a \
                 smaller dt, `substeps`, or the midpoint rule)",
                At(step)
            ),
            Self::NotConverged {
                iterations,
                residual,
                tolerance,
                step,
            } => write!(
                f,
                "Newton did not converge: {iterations} iterations, residual {residual:.3e} > tolerance \
                 {tolerance:.1e}{}",
                At(step)
            ),
            Self::NotContinuation { ratio, bound, step } => write!(
                f,
                "Newton converged to a root that is not the continuation of the motion (the step does \
                 not resolve the motion: its velocity change Δt·|v₁ − v₀| moves the path by more than the \
                 bound and its energy jumps): it bends the path by {ratio:.3e} rad > bound {bound:e}{}; the \
                 step is too large for the motion: use a smaller dt or `substeps` (or turn the check off \
                 with `continuation_bound(f64::INFINITY)`)",
                At(step)
            ),
            Self::NotResolved {
                depth,
                substep_dt,
                residual,
                step,
            } => write!(
                f,
                "no sub-step converged: halved {depth} times down to dt = {substep_dt:e}, the step still \
                 failed (residual {residual:e}){}; the motion is too fast for this dt, or the model \
                 has no solution here",
                At(step)
            ),
            Self::TooManySteps { steps } => write!(
                f,
                "a rollout whose states do not fit in memory (a duration divided by a zero or tiny \
                 dt?) ({steps} steps)"
            ),
            Self::NegligibleInertia {
                link,
                what,
                value,
                bound,
            } => write!(
                f,
                "link `{link}`: {what} {value:.3e} is negligible against the mechanism's inertia (the \
                 maximal view's Newton matrix cannot resolve the link's motion below {bound:.3e}); a \
                 massless connector such as the cross of a Hooke joint is a joint, not a link: use \
                 `universal(parent, child) {{ axes: [..] }}`, or merge the link into its neighbour; the \
                 minimal view integrates such links"
            ),
            Self::LoopCannotClose { residual } => write!(
                f,
                "the loop cannot close: no configuration satisfies the loop equations (smallest scaled \
                 residual |g(q)| found: {residual:.3e}); check the link lengths and the joints' anchor points"
            ),
            Self::OffConstraints {
                violation,
                iterations,
                residual,
                step,
            } => write!(
                f,
                "Newton did not converge from a state off the constraints (|g(q)| = {violation:.3e}, \
                 residual {residual:.3e} after {iterations} iterations){}: start from a consistent state, \
                 vigp::projection::consistent_state (or consistent_state_holding to keep chosen \
                 coordinates, e.g. a crank angle, fixed)",
                At(step)
            ),
        }
    }
}

impl core::error::Error for StepError {}

impl StepError {
    /// [`StepError::NonFiniteResidual`] outside a rollout.
    #[inline]
    pub(crate) const fn non_finite_residual(iteration: usize) -> Self {
        StepError::NonFiniteResidual {
            iteration,
            step: None,
        }
    }

    /// [`StepError::SingularJacobian`] outside a rollout.
    #[inline]
    pub(crate) const fn singular(iteration: usize) -> Self {
        StepError::SingularJacobian {
            iteration,
            step: None,
        }
    }

    /// [`StepError::LineSearchFailed`] outside a rollout.
    #[inline]
    pub(crate) const fn line_search_failed(iteration: usize, residual: f64) -> Self {
        StepError::LineSearchFailed {
            iteration,
            residual,
            step: None,
        }
    }

    /// [`StepError::NotConverged`] outside a rollout.
    #[inline]
    pub(crate) const fn not_converged(iterations: usize, residual: f64, tolerance: f64) -> Self {
        StepError::NotConverged {
            iterations,
            residual,
            tolerance,
            step: None,
        }
    }

    /// The same error, tagged with a rollout step index (errors that cannot
    /// happen inside a rollout are returned as they are).
    pub fn at_step(mut self, k: usize) -> Self {
        match &mut self {
            StepError::NonFiniteState { step }
            | StepError::NonFiniteInput { step }
            | StepError::NonUnitQuaternion { step, .. }
            | StepError::NonFiniteResidual { step, .. }
            | StepError::SingularJacobian { step, .. }
            | StepError::NotConverged { step, .. }
            | StepError::LineSearchFailed { step, .. }
            | StepError::OffConstraints { step, .. }
            | StepError::NotContinuation { step, .. }
            | StepError::NotResolved { step, .. }
            | StepError::Prediction { step } => *step = Some(k),
            StepError::InvalidTimeStep { .. }
            | StepError::TooManySteps { .. }
            | StepError::NegligibleInertia { .. }
            | StepError::LoopCannotClose { .. }
            | StepError::InputsNotSupported
            | StepError::InvalidOptions(_)
            | StepError::InvalidModel(_) => {}
        }
        self
    }
}
