//! Newton solver options, diagnostics, the step error type, and the
//! regularised KKT solve of the Newton steps.

/// Options of the Newton solves inside implicit steps (the core
/// [`vigp_core::StepOptions`]): tolerance on the scaled residual (default
/// 1e-12), iteration cap (25), smallest line-search step (1/256), and the
/// stall tolerance (1e-10) under which a step that cannot decrease its
/// residual further (a loop at a configuration where its constraint
/// Jacobian loses rank) is accepted.
pub use vigp_core::StepOptions;

/// Diagnostics of a converged step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepInfo {
    /// Newton iterations used.
    pub iterations: usize,
    /// Final scaled residual (max-norm).
    pub residual: f64,
    /// `true` when the step was accepted as stalled (see
    /// [`StepOptions::stall_tolerance`]) rather than converged.
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

pub use vigp_core::StepError;

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
