//! Newton solver options, diagnostics, the step error type, and the
//! regularised KKT solve of the Newton steps.

/// Options of the Newton solves inside implicit steps (the core
/// [`vigp_core::StepOptions`]): tolerance on the scaled residual (default
/// 1e-12), iteration cap (25), smallest line-search step (1/256), and the
/// stall tolerance (1e-10) under which a step that cannot decrease its
/// residual further (a loop at a configuration where its constraint
/// Jacobian loses rank) is accepted.
pub type NewtonOptions = vigp_core::StepOptions;

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
    /// The bend |Δt·(v₁ − v₀)|∞ of the step's discrete path (the core's
    /// [`vigp_core::StepReport::continuation`]; 0 where not measured).
    pub continuation: f64,
    /// How often the step halved its sub-step before it converged (0: at
    /// once; see [`crate::Variational::max_subdivision`]).
    pub subdivisions: u32,
}

pub use vigp_core::linalg::solve_kkt_regularised;

/// Why a step failed. `step` is filled in by rollouts with the index of the
/// failing step.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    /// Δt is not finite, not positive, or so large or small that Δt² is
    /// not a normal f64.
    #[error("invalid time step dt = {dt:e} (must be finite and > 0, with dt² a normal number)")]
    InvalidTimeStep {
        /// The offending Δt.
        dt: f64,
    },
    /// Solver options that cannot work.
    #[error("invalid solver options: {0}")]
    InvalidOptions(&'static str),
    /// Run-time parameters that cannot describe a mechanism (a negative or
    /// non-finite mass, inertia or damping coefficient, a non-positive
    /// length, non-finite gravity; the message names the parameter).
    #[error("invalid model parameters: {0}")]
    InvalidModel(&'static str),
    /// The input (or produced) state contains NaN or ±∞.
    #[error("non-finite state{}", at(step))]
    NonFiniteState {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// An input (actuator torque or force) is NaN or ±∞, or the input
    /// sequence is shorter than the rollout.
    #[error("non-finite or missing input{}", at(step))]
    NonFiniteInput {
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A spatial state's quaternion is not of unit norm (the core's
    /// [`vigp_core::StepError::NonUnitQuaternion`]).
    #[error(
        "the quaternion of link {link} has norm {norm} (must be 1 to 1e-9: normalise it, e.g. UnitQuaternion::new_normalize, \
         or start from a consistent state, vigp::projection::consistent_state){}",
        at(step)
    )]
    NonUnitQuaternion {
        /// The link, in declaration order.
        link: usize,
        /// Its quaternion's norm.
        norm: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// Non-zero inputs given to an integrator that cannot take them (the
    /// default of [`crate::Integrator::step_forced`]).
    #[error("this integrator does not take inputs")]
    InputsNotSupported,
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
    /// No decrease of the residual along the exact Newton direction, above
    /// the stall tolerance: the discrete equations have no root near the
    /// start (often a step too large for the motion; see
    /// `Variational::substeps`).
    #[error(
        "Newton stalled at iteration {iteration}: residual {residual:.3e} cannot be decreased along the Newton direction{} \
         (no root near the start: often a step too large for the motion; try a smaller dt, `substeps`, or the midpoint rule)",
        at(step)
    )]
    LineSearchFailed {
        /// Newton iteration.
        iteration: usize,
        /// Scaled residual reached.
        residual: f64,
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
    /// Newton converged to a root that is not the continuation of the
    /// motion (the core's [`vigp_core::StepError::NotContinuation`]; see
    /// `Variational::continuation_bound`).
    #[error(
        "{}: it bends the path by {ratio:.3e} rad > bound {bound:e}{}; {}",
        vigp_core::step::NOT_CONTINUATION_TEXT,
        at(step),
        vigp_core::step::NOT_CONTINUATION_REMEDY
    )]
    NotContinuation {
        /// The bend |Δt·(v₁ − v₀)|∞ of the step (radians, or scaled
        /// lengths).
        ratio: f64,
        /// The bound in force.
        bound: f64,
        /// Rollout step index, if in a rollout.
        step: Option<usize>,
    },
    /// A step that failed (no root near the start, or a root that is not
    /// the continuation of the motion) and still failed after halving its
    /// sub-step `depth` times ([`crate::Variational::max_subdivision`]).
    #[error(
        "no sub-step converged: halved {depth} times down to dt = {substep_dt:e}, the step still \
         failed (residual {residual:e}){}; the motion is too fast for this dt, or the model \
         has no solution here",
        at(step)
    )]
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
    /// A rollout of `steps` steps whose states cannot be stored (checked
    /// before anything is allocated: [`trajectory_buffer`]).
    #[error("{} ({steps} steps)", vigp_core::step::TOO_MANY_STEPS_TEXT)]
    TooManySteps {
        /// The step count asked for.
        steps: usize,
    },
    /// A link whose mass or rotational inertia is negligible against the
    /// mechanism's: `LieStepper` refuses it at construction (the core's
    /// [`vigp_core::StepError::NegligibleInertia`]).
    #[error(
        "link `{link}`: {what} {value:.3e} {} {bound:.3e}); {}",
        vigp_core::step::NEGLIGIBLE_INERTIA_TEXT,
        vigp_core::step::NEGLIGIBLE_INERTIA_REMEDY
    )]
    NegligibleInertia {
        /// The link's name.
        link: &'static str,
        /// `"mass"` (kg) or `"smallest principal moment of inertia"` (kg·m²).
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
    #[error(
        "the loop cannot close: no configuration satisfies the loop equations \
         (smallest scaled residual |g(q)| found: {residual:.3e}); check the link lengths and the joints' anchor points"
    )]
    LoopCannotClose {
        /// The smallest scaled residual found.
        residual: f64,
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

impl From<vigp_core::StepError> for StepError {
    /// The core's errors in the std runtime's form (no rollout step yet;
    /// `NotConverged` carries no tolerance in the core and reports NaN
    /// here: use [`StepError::with_tolerance`] where it is known).
    fn from(e: vigp_core::StepError) -> Self {
        use vigp_core::StepError as E;
        match e {
            E::InvalidTimeStep { dt } => StepError::InvalidTimeStep { dt },
            E::InvalidOptions(why) => StepError::InvalidOptions(why),
            E::InvalidModel(why) => StepError::InvalidModel(why),
            E::NonFiniteState => StepError::NonFiniteState { step: None },
            E::NonFiniteInput => StepError::NonFiniteInput { step: None },
            E::NonUnitQuaternion { link, norm } => StepError::NonUnitQuaternion {
                link,
                norm,
                step: None,
            },
            E::NonFiniteResidual { iteration } => StepError::NonFiniteResidual {
                iteration,
                step: None,
            },
            E::SingularJacobian { iteration } => StepError::SingularJacobian {
                iteration,
                step: None,
            },
            E::LineSearchFailed {
                iteration,
                residual,
            } => StepError::LineSearchFailed {
                iteration,
                residual,
                step: None,
            },
            E::NotConverged {
                iterations,
                residual,
            } => StepError::NotConverged {
                iterations,
                residual,
                tolerance: f64::NAN,
                step: None,
            },
            E::NotContinuation { ratio, bound } => StepError::NotContinuation {
                ratio,
                bound,
                step: None,
            },
            E::TooManySteps { steps } => StepError::TooManySteps { steps },
            E::NegligibleInertia {
                link,
                what,
                value,
                bound,
            } => StepError::NegligibleInertia {
                link,
                what,
                value,
                bound,
            },
        }
    }
}

/// A trajectory of `steps + 1` copies of `first`, the storage of a
/// rollout of `steps` steps, allocated only after the length is checked
/// ([`vigp_core::step::check_step_count`]) and with a fallible
/// reservation: `usize::MAX`, `usize::MAX / 2` or a count the allocator
/// refuses is [`StepError::TooManySteps`], not a panic. Every allocating
/// rollout of vigp should take its buffer from here.
pub fn trajectory_buffer<T: Clone>(first: T, steps: usize) -> Result<Vec<T>, StepError> {
    let len = vigp_core::step::check_step_count::<T>(steps)?;
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| StepError::TooManySteps { steps })?;
    v.resize(len, first);
    Ok(v)
}

impl StepError {
    /// Fill in the tolerance of a [`StepError::NotConverged`].
    pub fn with_tolerance(mut self, tol: f64) -> Self {
        if let StepError::NotConverged { tolerance, .. } = &mut self {
            *tolerance = tol;
        }
        self
    }
}

impl StepInfo {
    /// Diagnostics of a core step.
    pub fn from_report(r: &vigp_core::StepReport) -> Self {
        StepInfo {
            iterations: r.iterations,
            residual: r.residual,
            stalled: r.stalled,
            regularised: r.regularised,
            restarted: false,
            continuation: r.continuation,
            subdivisions: 0,
        }
    }
}
