//! The fourth-order variational integrator: a symmetric composition of the
//! midpoint rule ([`vigp_core::compose`]) behind the std [`Integrator`] trait.

use crate::mechanism::{Mechanism, State};
use crate::newton::{StepError, StepOptions};
use crate::variational::Integrator;
use vigp_core::Composition;

/// A fourth-order variational integrator: Suzuki's five-stage symmetric
/// composition of the midpoint rule ([`Variational4::new`]) or Yoshida's
/// triple jump ([`Variational4::triple_jump`]). Symplectic, with bounded
/// energy error and constraints held at position level every sub-step,
/// like the other variational integrators; fourth order like
/// [`crate::Rk4`]. For a model with a constant mass matrix, no constraints
/// and no damping the composed method is explicit Störmer–Verlet instead
/// of the midpoint rule (one force evaluation per stage, no Newton solve;
/// see [`vigp_core::compose`] and `Composition::is_explicit`).
///
/// **The state's velocity is the continuous q̇** (as for the classical
/// integrators), not a discrete one: start it from (q, q̇) with G(q)q̇ = 0
/// for loops. Construction never fails; invalid settings are reported by
/// `step`.
#[derive(Clone, Copy, Debug)]
pub struct Variational4<M: Mechanism<N, C>, const N: usize, const C: usize> {
    inner: Result<Composition<M, N, C>, StepError>,
    dt: f64,
}

impl<M: Mechanism<N, C>, const N: usize, const C: usize> Variational4<M, N, C> {
    /// Suzuki's five-stage composition.
    pub fn new(model: M, dt: f64) -> Self {
        Self {
            inner: Composition::new(model, dt),
            dt,
        }
    }

    /// Yoshida's triple jump (3 sub-steps; larger error constant).
    pub fn triple_jump(model: M, dt: f64) -> Self {
        Self {
            inner: Composition::triple_jump(model, dt),
            dt,
        }
    }

    /// Replace the Newton options of the sub-steps.
    pub fn with_options(mut self, options: StepOptions) -> Self {
        self.inner = self.inner.and_then(|c| c.options(options));
        self
    }

    /// The core integrator, or why the settings cannot work.
    pub fn composition(&self) -> Result<&Composition<M, N, C>, StepError> {
        self.inner.as_ref().map_err(|e| *e)
    }

    /// Energy ½ q̇ᵀM(q)q̇ + V(q) of a continuous state (NaN when the
    /// settings are invalid).
    pub fn energy(&self, z: &State<N>) -> f64 {
        self.inner.as_ref().map_or(f64::NAN, |c| c.energy(z))
    }
}

impl<M: Mechanism<N, C>, const N: usize, const C: usize> Integrator<N> for Variational4<M, N, C> {
    type Mechanism = M;

    fn dt(&self) -> f64 {
        self.dt
    }

    fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        self.composition()?.step(z)
    }

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
        self.composition()?.step_forced(z, u)
    }

    /// Carries the momentum between steps. No allocation.
    fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), StepError> {
        self.composition()?
            .steps_into(z0, out)
            .map_err(|e| e.error.at_step(e.step))
    }
}
