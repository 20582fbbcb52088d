//! The fourth-order variational integrator, [`vigp_core::Composition`] (a
//! symmetric composition of the midpoint rule, [`vigp_core::compose`]),
//! behind the std [`Integrator`] trait.
//!
//! Suzuki's five-stage composition ([`Composition::new`]) or Yoshida's
//! triple jump ([`Composition::triple_jump`]): symplectic, with bounded
//! energy error and constraints held at position level every sub-step,
//! like the other variational integrators; fourth order like
//! [`crate::Rk4`]. For a model with a constant mass matrix, no constraints
//! and no damping the composed method is explicit Störmer–Verlet instead
//! of the midpoint rule (one force evaluation per stage, no Newton solve;
//! `Composition::is_explicit`).
//!
//! **The state's velocity is the continuous q̇** (as for the classical
//! integrators), not a discrete one: start it from (q, q̇) with G(q)q̇ = 0
//! for loops. Construction checks Δt and the model's parameters, and
//! `Composition::options` the Newton options.

use crate::integrator::Integrator;
use crate::mechanism::{Mechanism, State};
use crate::newton::StepError;
pub use vigp_core::Composition;

impl<M: Mechanism<N, C>, const N: usize, const C: usize> Integrator for Composition<M, N, C> {
    type State = State<N>;
    type Error = StepError;
    type Mechanism = M;

    fn dt(&self) -> f64 {
        Composition::dt(self)
    }

    fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        Composition::step(self, z)
    }

    /// The energy ½ q̇ᵀM(q)q̇ + V(q) of a continuous state.
    fn state_energy(&self, z: &State<N>) -> Option<f64> {
        Some(self.energy(z))
    }

    /// Every midpoint stage forced by u (`vigp_core::Composition::step_forced`).
    fn step_forced<const U: usize>(
        &self,
        z: &State<N>,
        u: &nalgebra::SVector<f64, U>,
    ) -> Result<State<N>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        Composition::step_forced(self, z, u)
    }

    /// Carries the momentum between steps. No allocation.
    fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), StepError> {
        self.steps_into(z0, out)
            .map_err(|e| e.error.at_step(e.step))
    }
}
