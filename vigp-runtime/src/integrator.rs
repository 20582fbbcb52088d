//! [`Integrator`]: the one-step map z_k ↦ z_{k+1} that every integrator of
//! vigp implements, over any configuration space.
//!
//! The state is the integrator's: [`State<N>`](crate::State) in minimal
//! coordinates (the variational integrators, the classical ones, the
//! learned integrator), [`SpatialState<B>`](crate::spatial::SpatialState)
//! for bodies in ℝ³ × SO(3) (the Lie-group integrator and its learned
//! form). Code written against the trait serves both; a bound names the
//! state where the code needs it:
//!
//! ```
//! use vigp_runtime::{Integrator, State};
//!
//! /// The positions after `steps` steps of any integrator in minimal
//! /// coordinates.
//! fn final_positions<I: Integrator<State = State<2>>>(
//!     integrator: &I,
//!     z0: &State<2>,
//!     steps: usize,
//! ) -> Result<[f64; 2], I::Error> {
//!     let trajectory = integrator.rollout(z0, steps)?;
//!     Ok(trajectory[steps].q.into())
//! }
//! ```

use crate::newton::StepError;
use nalgebra::SVector;

/// What an integrator's step fails with: a [`StepError`] or a richer error
/// that holds one, placed at its step inside a rollout.
pub trait StepFailure: From<StepError> + core::fmt::Debug + core::fmt::Display {
    /// The same failure as the error of step `k` of a rollout.
    fn at_step(self, k: usize) -> Self;
}

impl StepFailure for StepError {
    fn at_step(self, k: usize) -> Self {
        StepError::at_step(self, k)
    }
}

/// A one-step map z_k ↦ z_{k+1} with a fixed time step.
///
/// Implemented by every integrator, planar or spatial, nominal or learned,
/// so a user swaps integrators in one line and writes a rollout, a
/// summary or a controller once (module docs).
pub trait Integrator {
    /// The discrete state it steps.
    type State: Copy + core::fmt::Debug + PartialEq;
    /// Why a step fails ([`StepError`] in minimal coordinates,
    /// [`SpatialError`](crate::spatial::SpatialError) in space).
    type Error: StepFailure;
    /// The mechanism this integrator steps: its forced steps take the input
    /// vectors it takes ([`vigp_core::Inputs`]), so a wrong input length is
    /// a compile error at the call.
    type Mechanism: ?Sized;

    /// The time step Δt in seconds.
    fn dt(&self) -> f64;

    /// One step. Never returns a non-finite state.
    fn step(&self, z: &Self::State) -> Result<Self::State, Self::Error>;

    /// One step under inputs `u` (one per actuated joint, in declaration
    /// order; `U` must equal the mechanism's number of inputs). Every
    /// integrator of vigp implements it; the default, for integrators that
    /// cannot take inputs, takes u = 0 as [`Integrator::step`] and refuses
    /// anything else with [`StepError::InputsNotSupported`].
    fn step_forced<const U: usize>(
        &self,
        z: &Self::State,
        u: &SVector<f64, U>,
    ) -> Result<Self::State, Self::Error>
    where
        Self: Sized,
        Self::Mechanism: vigp_core::Inputs<U>,
    {
        if u.iter().all(|x| *x == 0.0) {
            self.step(z)
        } else {
            Err(StepError::InputsNotSupported.into())
        }
    }

    /// Fill `out` with the states after 1, 2, …, `out.len()` steps from
    /// `z0`, without allocating. Stops at the first error (which names the
    /// step).
    fn rollout_into(&self, z0: &Self::State, out: &mut [Self::State]) -> Result<(), Self::Error> {
        roll(z0, out, |_, z| self.step(z))
    }

    /// The states after 1, …, `out.len()` steps from `z0`, step k under
    /// `inputs[k]` (which must be at least as long as `out`; shorter is
    /// [`StepError::NonFiniteInput`] at step `inputs.len()`, before any
    /// step). Stops at the first error (which names the step).
    fn rollout_forced_into<const U: usize>(
        &self,
        z0: &Self::State,
        inputs: &[SVector<f64, U>],
        out: &mut [Self::State],
    ) -> Result<(), Self::Error>
    where
        Self: Sized,
        Self::Mechanism: vigp_core::Inputs<U>,
    {
        check_inputs_cover(inputs.len(), out.len())?;
        roll(z0, out, |k, z| self.step_forced(z, &inputs[k]))
    }

    /// The trajectory z₀, z₁, …, z_steps (`steps + 1` states), through
    /// [`Integrator::rollout_into`].
    ///
    /// A `steps` whose trajectory cannot be stored (`usize::MAX`, a
    /// duration divided by Δt = 0) is [`StepError::TooManySteps`], checked
    /// before allocation ([`crate::newton::trajectory_buffer`]).
    #[cfg(feature = "alloc")]
    fn rollout(&self, z0: &Self::State, steps: usize) -> Result<Vec<Self::State>, Self::Error> {
        let mut trajectory = crate::newton::trajectory_buffer(*z0, steps)?;
        self.rollout_into(z0, &mut trajectory[1..])?;
        Ok(trajectory)
    }

    /// The forced trajectory z₀, z₁, …, z_K (K = `inputs.len()`), step k
    /// under `inputs[k]`, through [`Integrator::rollout_forced_into`].
    #[cfg(feature = "alloc")]
    fn rollout_forced<const U: usize>(
        &self,
        z0: &Self::State,
        inputs: &[SVector<f64, U>],
    ) -> Result<Vec<Self::State>, Self::Error>
    where
        Self: Sized,
        Self::Mechanism: vigp_core::Inputs<U>,
    {
        let mut trajectory = crate::newton::trajectory_buffer(*z0, inputs.len())?;
        self.rollout_forced_into(z0, inputs, &mut trajectory[1..])?;
        Ok(trajectory)
    }

    /// The energy of a state as this integrator defines it, when that is
    /// not the model's `energy(z)`: the midpoint VI's discrete velocity
    /// belongs to the interval's midpoint
    /// ([`Variational::energy`](crate::Variational::energy)). `None` (the
    /// default) means the model's energy; [`crate::summarize`] uses this.
    fn state_energy(&self, z: &Self::State) -> Option<f64> {
        let _ = z;
        None
    }
}

/// Fills `out` with the states after 1, …, `out.len()` steps from `z0`,
/// step k by `step(k, z_k)`; stops at the first error, placed at its step
/// ([`StepFailure::at_step`]). The loop of every rollout of the trait.
pub(crate) fn roll<Z: Copy, E: StepFailure>(
    z0: &Z,
    out: &mut [Z],
    mut step: impl FnMut(usize, &Z) -> Result<Z, E>,
) -> Result<(), E> {
    let mut z = *z0;
    for (k, slot) in out.iter_mut().enumerate() {
        z = step(k, &z).map_err(|e| e.at_step(k))?;
        *slot = z;
    }
    Ok(())
}

/// A forced rollout of `steps` states needs at least as many inputs:
/// [`StepError::NonFiniteInput`] at the first missing one otherwise.
pub(crate) fn check_inputs_cover(inputs: usize, steps: usize) -> Result<(), StepError> {
    if inputs < steps {
        Err(StepError::NonFiniteInput { step: Some(inputs) })
    } else {
        Ok(())
    }
}
