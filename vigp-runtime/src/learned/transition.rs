//! Training pairs of the learned family, one type over every configuration
//! space: a discrete state and the next discrete velocities, with or
//! without the inputs that drove them.
//!
//! The state type `Z` names the space: [`State<N>`] (the default) for
//! coordinates in ℝᴺ, [`SpatialState<B>`](vigp_core::spatial::SpatialState)
//! for bodies in ℝ³ × SO(3), whose next velocities are every link's linear
//! and body angular velocity stacked as
//! [`pack`](vigp_core::spatial::maximal::pack) stacks them (N = 6B).
//! The learned integrator ([`super::LearnedIntegrator`]) trains on these
//! pairs whatever the space.

use crate::mechanism::State;
use nalgebra::SVector;
use vigp_core::state::discrete_velocity;

/// One training pair: a discrete state z_k and the next discrete
/// velocities ν_{k+1} (module docs: `Z` is the space's state).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition<const N: usize, Z = State<N>> {
    /// z_k: configuration k and the velocities of the step to k+1, e.g.
    /// v_k = (x_{k+1} − x_k)/Δt in coordinates.
    pub z: Z,
    /// ν_{k+1}: the velocities of the step from k+1 to k+2, e.g.
    /// (x_{k+2} − x_{k+1})/Δt in coordinates.
    pub v_next: SVector<f64, N>,
}

/// One training pair of an actuated mechanism: a discrete state, the
/// input that produced its velocities, the input that drove the step from
/// it (held over the interval of the new discrete velocities,
/// `vigp_core::forced`) and the next discrete velocities (the module docs
/// of [`crate::learned`], "Under inputs": the GP input is
/// (enc(z), u_prev, u)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForcedTransition<const N: usize, const U: usize, Z = State<N>> {
    /// z_k: configuration k and the velocities of the step to k+1.
    pub z: Z,
    /// The input over [t_k, t_{k+1}] (the one that produced z_k's
    /// velocities).
    pub u_prev: SVector<f64, U>,
    /// The input over [t_{k+1}, t_{k+2}] (one per actuated joint, in
    /// declaration order).
    pub u: SVector<f64, U>,
    /// ν_{k+1}: the velocities of the step from k+1 to k+2.
    pub v_next: SVector<f64, N>,
}

impl<const N: usize, Z: Copy> Transition<N, Z> {
    /// This pair driven by `u` after `u_prev`.
    pub fn forced<const U: usize>(
        &self,
        u_prev: SVector<f64, U>,
        u: SVector<f64, U>,
    ) -> ForcedTransition<N, U, Z> {
        ForcedTransition {
            z: self.z,
            u_prev,
            u,
            v_next: self.v_next,
        }
    }
}

/// Transitions of a trajectory with the input logged at each sample and
/// held until the next (zero-order hold): transition k, from samples k,
/// k+1, k+2, is driven by `inputs[k + 1]` after `inputs[k]` (its
/// `u_prev`). `inputs` must be as long as the samples (shorter: fewer
/// transitions).
pub(crate) fn held_inputs<const N: usize, const U: usize, Z: Copy>(
    data: Vec<Transition<N, Z>>,
    inputs: &[SVector<f64, U>],
) -> Vec<ForcedTransition<N, U, Z>> {
    data.iter()
        .zip(inputs.windows(2))
        .map(|(t, u)| t.forced(u[0], u[1]))
        .collect()
}

/// Unforced pairs as forced ones without inputs (U = 0), the one form
/// training takes.
pub(crate) fn without_inputs<const N: usize, Z: Copy>(
    data: &[Transition<N, Z>],
) -> Vec<ForcedTransition<N, 0, Z>> {
    data.iter()
        .map(|t| t.forced(SVector::zeros(), SVector::zeros()))
        .collect()
}

/// Transitions of a trajectory of positions sampled every Δt (K positions
/// give K − 2 transitions), with the velocity convention of
/// [`State::from_positions`].
pub fn transitions<const N: usize>(positions: &[SVector<f64, N>], dt: f64) -> Vec<Transition<N>> {
    positions
        .windows(3)
        .map(|w| Transition {
            z: State::from_positions(w[0], &w[1], dt),
            v_next: discrete_velocity(&w[1], &w[2], dt),
        })
        .collect()
}

/// Transitions of a trajectory of positions sampled every Δt with the
/// input logged at each sample (held until the next): transition k is
/// driven by `inputs[k + 1]` (see `vigp::data::Run::step_input`) after
/// `inputs[k]` (its `u_prev`, the input that produced v_k). K positions
/// give K − 2 transitions; `inputs` must be as long as `positions`
/// (shorter: fewer transitions).
pub fn forced_transitions<const N: usize, const U: usize>(
    positions: &[SVector<f64, N>],
    inputs: &[SVector<f64, U>],
    dt: f64,
) -> Vec<ForcedTransition<N, U>> {
    held_inputs(transitions(positions, dt), inputs)
}
