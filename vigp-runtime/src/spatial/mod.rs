//! Spatial (3-D) mechanisms: the `no_std` core (`vigp_core::spatial`:
//! description, minimal coordinates, the Lie-group variational integrator
//! in maximal coordinates) re-exported, plus the std conveniences: a
//! typed error, rollouts into a `Vec`, run summaries and the learned
//! integrator in space ([`learned`]) and its conformal error bounds
//! ([`bound`]).
//!
//! A `mechanism!` with `gravity: [gx, gy, gz]` generates a parameter type
//! `Name` implementing [`Spatial`], with `Name::minimal()` (a
//! [`Mechanism`](crate::Mechanism): every planar integrator, the learned
//! integrator and the projections work on it unchanged) and
//! `Name::maximal()` (a [`Maximal`] view for [`LieStepper`]).

#[cfg(feature = "alloc")]
pub mod bound;
#[cfg(feature = "alloc")]
pub mod learned;

pub use vigp_core::spatial::*;
pub use vigp_core::{RolloutError, StepOptions};

use crate::StepError;
use crate::integrator::{Integrator, StepFailure};

/// Why a spatial computation failed.
#[derive(Debug, thiserror::Error)]
pub enum SpatialError {
    /// A step failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// A step inside a rollout failed (the index names it).
    #[error(transparent)]
    Rollout(#[from] RolloutError),
    /// The description cannot be integrated.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A learned integrator's GP failed.
    #[cfg(feature = "alloc")]
    #[error(transparent)]
    Learn(Box<learned::LearnSpatialError>),
}

#[cfg(feature = "alloc")]
impl From<learned::LearnSpatialError> for SpatialError {
    fn from(e: learned::LearnSpatialError) -> Self {
        match e {
            learned::LearnSpatialError::Step(s) => SpatialError::Step(s),
            other => SpatialError::Learn(Box::new(other)),
        }
    }
}

impl StepFailure for SpatialError {
    /// A step's error becomes [`SpatialError::Rollout`] at step `k`; the
    /// others stay as they are.
    fn at_step(self, k: usize) -> Self {
        match self {
            SpatialError::Step(error) => SpatialError::Rollout(RolloutError { step: k, error }),
            other => other,
        }
    }
}

/// The Lie-group variational integrator as an [`Integrator`] of spatial
/// states.
impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize> Integrator
    for LieStepper<S, B, J, N, C>
{
    type State = SpatialState<B>;
    type Error = SpatialError;
    type Mechanism = S;

    fn dt(&self) -> f64 {
        LieStepper::dt(self)
    }

    fn step(&self, z: &SpatialState<B>) -> Result<SpatialState<B>, SpatialError> {
        Ok(LieStepper::step(self, z)?)
    }

    /// Through [`LieStepper::rollout_into`] (extrapolated Newton starts;
    /// that inherent method fills a buffer that starts with z₀, this
    /// trait's [`Integrator::rollout_into`] one that starts with z₁).
    fn rollout(
        &self,
        z0: &SpatialState<B>,
        steps: usize,
    ) -> Result<Vec<SpatialState<B>>, SpatialError> {
        let mut out = crate::newton::trajectory_buffer(*z0, steps)?;
        LieStepper::rollout_into(self, z0, &mut out)?;
        Ok(out)
    }

    fn step_forced<const U: usize>(
        &self,
        z: &SpatialState<B>,
        u: &nalgebra::SVector<f64, U>,
    ) -> Result<SpatialState<B>, SpatialError>
    where
        S: vigp_core::Inputs<U>,
    {
        Ok(LieStepper::step_forced(self, z, u)?)
    }

    /// Through [`LieStepper::rollout_forced_into`].
    fn rollout_forced<const U: usize>(
        &self,
        z0: &SpatialState<B>,
        inputs: &[nalgebra::SVector<f64, U>],
    ) -> Result<Vec<SpatialState<B>>, SpatialError>
    where
        S: vigp_core::Inputs<U>,
    {
        let mut out = crate::newton::trajectory_buffer(*z0, inputs.len())?;
        LieStepper::rollout_forced_into(self, z0, inputs, &mut out)?;
        Ok(out)
    }
}

/// What a run did to the invariants: energy error, constraint violation
/// and quaternion norms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialSummary {
    /// max_k |E_k − E_0|.
    pub max_energy_error: f64,
    /// max |E_k − E_0| over the first tenth of the run.
    pub first_tenth: f64,
    /// max |E_k − E_0| over the last tenth of the run.
    pub last_tenth: f64,
    /// max_k |g(x_k, q_k)|, from step 1 on (z₀ may be inconsistent).
    pub max_violation: f64,
    /// max_k max_i |‖q_i‖ − 1|.
    pub max_norm_error: f64,
}

/// Summarise a trajectory of `stepper`.
pub fn summarize<
    S: Spatial<B, J>,
    const B: usize,
    const J: usize,
    const N: usize,
    const C: usize,
>(
    stepper: &LieStepper<S, B, J, N, C>,
    traj: &[SpatialState<B>],
) -> SpatialSummary {
    let e0 = traj.first().map_or(0.0, |z| stepper.energy(z));
    let n = traj.len();
    let tenth = (n / 10).max(1);
    let mut s = SpatialSummary {
        max_energy_error: 0.0,
        first_tenth: 0.0,
        last_tenth: 0.0,
        max_violation: 0.0,
        max_norm_error: 0.0,
    };
    for (k, z) in traj.iter().enumerate() {
        let de = (stepper.energy(z) - e0).abs();
        s.max_energy_error = s.max_energy_error.max(de);
        if k < tenth {
            s.first_tenth = s.first_tenth.max(de);
        }
        if k + tenth >= n {
            s.last_tenth = s.last_tenth.max(de);
        }
        if k > 0 {
            s.max_violation = s.max_violation.max(stepper.constraint_violation(z));
        }
        s.max_norm_error = s.max_norm_error.max(z.norm_error());
    }
    s
}
