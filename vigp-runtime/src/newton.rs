//! Newton solver options, diagnostics, the step error type, and the
//! regularised KKT solve of the Newton steps.

/// Options of the Newton solves inside implicit steps (the core
/// [`vigp_core::StepOptions`]): tolerance on the scaled residual (default
/// 1e-12), iteration cap (25), smallest line-search step (1/256), and the
/// stall tolerance (1e-10) under which a step that cannot decrease its
/// residual further (a loop at a configuration where its constraint
/// Jacobian loses rank) is accepted.
pub use vigp_core::StepOptions;

/// Diagnostics of a converged step, the core's: Newton iterations, final
/// scaled residual, whether it was accepted as stalled or needed the
/// regularised KKT solve ([`solve_kkt_regularised`]), the bend of its
/// discrete path, whether a velocity projection restarted
/// ([`crate::projection::project_velocity`]) and how often the step halved
/// its sub-step ([`crate::Variational::max_subdivision`]).
pub use vigp_core::StepReport;

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
