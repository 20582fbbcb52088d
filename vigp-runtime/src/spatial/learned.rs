//! The learned integrator in space (paper eq. 7 and 8, maximal
//! coordinates): a Gaussian process learns the velocity map
//! z_k ↦ ν_{k+1} = (v_i, ω_i)_{k+1} on top of a prior (the nominal
//! Lie-group variational step, or a constant mean); the prediction is then
//! projected onto the joint constraints of the next configuration. The
//! configuration update x_{k+1} = x_k + Δt·v_k, q_{k+1} = q_k ⊗ exp(Δt·ω_k)
//! is exact and never learned, so the unit quaternions stay unit to
//! rounding whatever the GP predicts, and the projection keeps every joint
//! to solver tolerance.
//!
//! # GP inputs: which rotation representation
//!
//! Per link: the centre of mass x, the orientation, v and ω (body frame).
//! The orientation enters as the nine entries of its rotation matrix
//! ([`Rotation::Matrix`], the default): a continuous, one-to-one image of
//! the rotation group, so that physically equal states are equal GP inputs
//! and nearby rotations are nearby inputs, which is what a stationary
//! kernel assumes. The alternative, the quaternion's four components
//! ([`Rotation::Quaternion`]), double-covers the rotations: q and −q are
//! the same orientation but far apart as inputs, and a link that turns
//! once about an axis comes back as −q. A GP trained on q then knows
//! nothing at −q and falls back to its prior there; canonicalising the
//! sign (w ≥ 0) instead makes the input jump at half turns.
//! `tests/learn/spatial_learned.rs` measures the difference.
//!
//! # Under inputs
//!
//! An actuated mechanism's model learns under the inputs its data were
//! logged with ([`forced_transitions`], [`LearnedSpatial::train_forced`]):
//! the GP input is the encoded state followed by the previous and the
//! current input, (enc(z), u_prev, u) — the next discrete velocities depend
//! on the input that produced z's velocities as well as on the one held
//! over the step (the planar `vigp::learned`, "Under inputs", explains
//! why) — and the prior is the nominal forced step under u
//! ([`LieStepper::step_forced`]). Such a model steps with
//! [`LearnedSpatial::step_mean_forced_in`] (previous input explicit) or
//! [`Integrator::rollout_forced`](crate::Integrator::rollout_forced) (step k after `inputs[k − 1]`, the
//! first after `inputs[0]`: the input taken as held across the start); its
//! plain step, without inputs, is a typed error
//! ([`LearnSpatialError::Inputs`]), never a silent u = 0.

use crate::StepError;
use crate::gp::{TrainOptions, TrainReport, Workspace};
use crate::learned::transition::{held_inputs, without_inputs};
use crate::learned::{
    ForcedTransition, InputLayout, LearnError, LearnedIntegrator, NominalStep, Prior, Row, Space,
    Transition,
};
use nalgebra::{SVector, UnitQuaternion, Vector3};
use vigp_core::spatial::maximal::{pack, unpack};
use vigp_core::spatial::{LieStepper, Spatial, SpatialState};

/// How an orientation is presented to the GP.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Rotation {
    /// The nine entries of the rotation matrix (row-major).
    Matrix,
    /// The quaternion (w, x, y, z) as the state carries it.
    Quaternion,
}

impl Rotation {
    /// Input dimensions per orientation.
    pub fn dim(self) -> usize {
        match self {
            Rotation::Matrix => 9,
            Rotation::Quaternion => 4,
        }
    }

    /// GP input dimension for `B` links: per link x (3), the orientation,
    /// v (3) and ω (3).
    pub fn input_dim(self, links: usize) -> usize {
        links * (9 + self.dim())
    }

    /// Write the GP input of `z` into `out` (length [`Rotation::input_dim`]).
    pub fn encode<const B: usize>(self, z: &SpatialState<B>, out: &mut [f64]) {
        let mut k = 0;
        let mut put = |x: f64| {
            out[k] = x;
            k += 1;
        };
        for i in 0..B {
            z.x[i].iter().for_each(|x| put(*x));
            match self {
                Rotation::Matrix => {
                    let r = z.q[i].to_rotation_matrix();
                    for a in 0..3 {
                        for b in 0..3 {
                            put(r[(a, b)]);
                        }
                    }
                }
                Rotation::Quaternion => {
                    let q = z.q[i].quaternion();
                    [q.w, q.i, q.j, q.k].iter().for_each(|x| put(*x));
                }
            }
            z.v[i].iter().for_each(|x| put(*x));
            z.w[i].iter().for_each(|x| put(*x));
        }
    }
}

/// A sampled configuration: centres of mass and orientations of every link.
pub type Configuration<const B: usize> = ([Vector3<f64>; B], [UnitQuaternion<f64>; B]);

/// Transitions of a trajectory of configurations sampled every Δt (K
/// configurations give K − 2 transitions): the discrete velocities are
/// (x_{k+1} − x_k)/Δt and log(q_k⁻¹ q_{k+1})/Δt, so that the configuration
/// update is exact and the GP learns only the velocity map. The next
/// velocities stack every link's (v, ω) as [`pack`] does: N = 6B, checked
/// at compile time.
pub fn transitions<const B: usize, const N: usize>(
    configurations: &[Configuration<B>],
    dt: f64,
) -> Vec<Transition<N, SpatialState<B>>> {
    const { assert!(N == 6 * B, "N must be 6 times the number of links") };
    configurations
        .windows(3)
        .map(|w| {
            let next = between(&w[1], &w[2], dt);
            Transition {
                z: between(&w[0], &w[1], dt),
                v_next: pack(&next.v, &next.w),
            }
        })
        .collect()
}

/// The discrete state at configuration `a` whose configuration Δt later
/// is `b` ([`SpatialState::from_configurations`]).
pub(crate) fn between<const B: usize>(
    a: &Configuration<B>,
    b: &Configuration<B>,
    dt: f64,
) -> SpatialState<B> {
    SpatialState::from_configurations(&a.0, &a.1, &b.0, &b.1, dt)
}

/// Transitions of a trajectory of configurations sampled every Δt with the
/// input logged at each sample and held until the next (zero-order hold):
/// transition k, from configurations k, k+1, k+2, is driven by
/// `inputs[k + 1]`, the input held over [t_{k+1}, t_{k+2}], after
/// `inputs[k]` (its `u_prev`) — the convention of
/// [`crate::learned::forced_transitions`]. K configurations give
/// K − 2 transitions; `inputs` must be as long as `configurations`
/// (shorter: fewer transitions).
pub fn forced_transitions<const B: usize, const N: usize, const U: usize>(
    configurations: &[Configuration<B>],
    inputs: &[SVector<f64, U>],
    dt: f64,
) -> Vec<ForcedTransition<N, U, SpatialState<B>>> {
    held_inputs(transitions(configurations, dt), inputs)
}

/// Why training or prediction of a learned spatial integrator failed: the
/// one error of the learned family ([`LearnError`]), whose
/// [`LearnError::NotUnit`], [`LearnError::IdentifiedPrior`] and
/// [`LearnError::Inputs`] arise here.
pub type LearnSpatialError = LearnError;

/// A mean prediction with the GP's latent standard deviations along it.
pub(crate) struct Trace<const B: usize, const N: usize> {
    /// z₀, …, z_K.
    pub states: Vec<SpatialState<B>>,
    /// σ at z₀, …, z_{K−1}: the uncertainty of each step's velocities.
    pub std_devs: Vec<SVector<f64, N>>,
}

/// A learned spatial integrator: prior + GP velocity map, projected onto
/// the joint constraints (when the mechanism has any and projection is
/// on), the [`LearnedIntegrator`] over the nominal Lie-group step.
///
/// Cost per step: the nominal Lie-group step (with [`Prior::Nominal`]), the
/// GP mean (O(N·d) per output: N samples, d inputs, 6B outputs) and the
/// velocity projection (a few Newton iterations on a (6B + C) KKT system).
pub type LearnedSpatial<S, const B: usize, const J: usize, const N: usize, const C: usize> =
    LearnedIntegrator<LieStepper<S, B, J, N, C>, N>;

/// Bodies in ℝ³ × SO(3): the state is every link's centre of mass,
/// orientation and velocities (linear, and angular in the body frame), the
/// configuration update x₁ = x + Δt·v, q₁ = q ⊗ exp(Δt·ω) (exact: unit
/// quaternions stay unit), the encoding [`Rotation`], the projection
/// [`LieStepper::project_velocity`] onto the joints.
impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize> Space<N>
    for LieStepper<S, B, J, N, C>
{
    type Encoding = Rotation;
    type PredictionError = LearnError;

    fn error(e: LearnError) -> LearnError {
        e
    }

    /// Exactly the model's: a model trained with inputs refuses a
    /// prediction without them, never a silent u = 0 (module docs).
    fn check_inputs(trained: usize, given: usize) -> Result<(), LearnError> {
        if given == trained {
            Ok(())
        } else {
            Err(LearnError::Inputs { trained, given })
        }
    }

    fn velocities(z: &SpatialState<B>) -> SVector<f64, N> {
        pack(&z.v, &z.w)
    }

    fn constrained(&self) -> bool {
        C > 0
    }

    fn encoded_dim(&self, rotation: Rotation) -> usize {
        rotation.input_dim(B)
    }

    fn encode(&self, rotation: Rotation, z: &SpatialState<B>, out: &mut [f64]) {
        rotation.encode(z, out);
    }

    fn is_finite(z: &SpatialState<B>) -> bool {
        z.is_finite()
    }

    fn check(z: &SpatialState<B>) -> Result<(), StepError> {
        z.validate()
    }

    fn check_training(i: usize, z: &SpatialState<B>) -> Result<(), LearnError> {
        match z.non_unit() {
            Some((link, norm)) => Err(LearnError::NotUnit {
                transition: i,
                link,
                norm,
            }),
            None => Ok(()),
        }
    }

    fn consistent(&self, z: &SpatialState<B>) -> Result<SpatialState<B>, StepError> {
        self.consistent_state(z)
    }

    fn advance(
        &self,
        z: &SpatialState<B>,
        nu: &SVector<f64, N>,
        project: bool,
    ) -> Result<SpatialState<B>, StepError> {
        let (x1, q1) = z.advanced(self.dt());
        let nu = if project && C > 0 {
            self.project_velocity(&x1, &q1, nu)?
        } else {
            *nu
        };
        let (v, w) = unpack(&nu);
        Ok(SpatialState { x: x1, q: q1, v, w })
    }
}

/// The prior: the nominal Lie-group step (its velocities).
impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    NominalStep<N> for LieStepper<S, B, J, N, C>
{
    fn prior_velocity(&self, z: &SpatialState<B>) -> Result<SVector<f64, N>, StepError> {
        next_velocities(self.step(z))
    }

    fn prior_velocity_forced<const U: usize>(
        &self,
        z: &SpatialState<B>,
        u: &SVector<f64, U>,
    ) -> Result<SVector<f64, N>, StepError>
    where
        S: vigp_core::Inputs<U>,
    {
        next_velocities(self.step_forced(z, u))
    }
}

/// The next velocities of the nominal step from `z`.
fn next_velocities<const N: usize, const B: usize>(
    z1: Result<SpatialState<B>, StepError>,
) -> Result<SVector<f64, N>, StepError> {
    let z1 = z1?;
    Ok(pack(&z1.v, &z1.w))
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    LearnedSpatial<S, B, J, N, C>
{
    /// Train on transitions. `stepper` is the nominal model: the prior
    /// (for [`Prior::Nominal`]), Δt, and the constraints of the projection.
    /// With constraints, the prior of a (noisy, inconsistent) training state
    /// is evaluated at its consistent neighbour, as at prediction time.
    /// An actuated mechanism's model trained here predicts under u = 0;
    /// [`LearnedSpatial::train_forced`] learns under inputs. A transition
    /// that repeats an earlier one exactly is one measurement, trained on
    /// once ([`crate::learned::distinct_rows`]).
    pub fn train(
        stepper: LieStepper<S, B, J, N, C>,
        data: &[Transition<N, SpatialState<B>>],
        rotation: Rotation,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnSpatialError> {
        Self::train_inputs(
            stepper,
            &without_inputs(data),
            rotation,
            prior,
            options,
            |s, z, _| s.prior_velocity(z),
        )
    }

    /// [`LearnedSpatial::train`] for an actuated mechanism on transitions
    /// with their inputs ([`forced_transitions`]): the GP input is the
    /// encoded state followed by u_prev and u (module docs, "Under
    /// inputs"), and the nominal prior is the forced
    /// Lie-group step under u ([`LieStepper::step_forced`]). `U` must equal
    /// the mechanism's number of actuated joints (checked at compile time).
    /// Predict with [`LearnedSpatial::step_mean_forced_in`] or
    /// [`Integrator::rollout_forced`](crate::Integrator::rollout_forced).
    pub fn train_forced<const U: usize>(
        stepper: LieStepper<S, B, J, N, C>,
        data: &[ForcedTransition<N, U, SpatialState<B>>],
        rotation: Rotation,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnSpatialError>
    where
        S: vigp_core::Inputs<U>,
    {
        Self::train_inputs(stepper, data, rotation, prior, options, |s, z, u| {
            s.prior_velocity_forced(z, u)
        })
    }

    /// Training with the GP input = encoded state followed by u_prev and u
    /// (U values each, none for U = 0) and the prior's next velocities from
    /// `nominal(stepper, z, u)`.
    fn train_inputs<const U: usize>(
        stepper: LieStepper<S, B, J, N, C>,
        data: &[ForcedTransition<N, U, SpatialState<B>>],
        rotation: Rotation,
        prior: Prior,
        options: &TrainOptions,
        nominal: impl Fn(
            &LieStepper<S, B, J, N, C>,
            &SpatialState<B>,
            &SVector<f64, U>,
        ) -> Result<SVector<f64, N>, StepError>,
    ) -> Result<(Self, TrainReport), LearnSpatialError>
    where
        S: vigp_core::Inputs<U>,
    {
        if data.is_empty() {
            return Err(LearnSpatialError::Empty);
        }
        if let Prior::Identified(_) = prior {
            return Err(LearnSpatialError::IdentifiedPrior);
        }
        Self::fit(
            stepper,
            data,
            |t| Row {
                z: &t.z,
                u_prev: t.u_prev.as_slice(),
                u: t.u.as_slice(),
                next: t.v_next,
            },
            InputLayout {
                inputs: U,
                previous_input: U > 0,
            },
            rotation,
            prior,
            options,
            |s, z, t| nominal(s, z, &t.u),
        )
    }

    /// The nominal stepper.
    pub fn stepper(&self) -> &LieStepper<S, B, J, N, C> {
        &self.nominal
    }

    /// The rotation representation of the GP inputs.
    pub fn rotation(&self) -> Rotation {
        self.encoding
    }

    /// `given` inputs must be the training data's.
    pub(crate) fn check_inputs(&self, given: usize) -> Result<(), LearnSpatialError> {
        <LieStepper<S, B, J, N, C> as Space<N>>::check_inputs(self.inputs, given)
    }

    /// The GP input of a step from `z` after `u_prev` under `u` (both
    /// empty: unforced).
    pub(crate) fn gp_input(&self, z: &SpatialState<B>, u_prev: &[f64], u: &[f64], out: &mut [f64]) {
        self.gp_input_into(z, u_prev, u, out);
    }

    /// The mean prediction z₀, …, z_steps with the GP's latent standard
    /// deviations at z₀, …, z_{steps−1} (those of each step's velocities), a
    /// model trained without inputs.
    pub(crate) fn trace(
        &self,
        z0: &SpatialState<B>,
        steps: usize,
        ws: &mut Workspace,
    ) -> Result<Trace<B, N>, LearnSpatialError> {
        self.check_inputs(0)?;
        self.trace_with(z0, steps, ws, |_| (&[], &[]), |s, z, _| s.step(z))
    }

    /// [`Self::trace`] under `inputs` (one per step) after `u_prev`, a
    /// model from [`LearnedSpatial::train_forced`].
    pub(crate) fn trace_forced<const U: usize>(
        &self,
        z0: &SpatialState<B>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        ws: &mut Workspace,
    ) -> Result<Trace<B, N>, LearnSpatialError>
    where
        S: vigp_core::Inputs<U>,
    {
        self.check_inputs(U)?;
        if !inputs
            .iter()
            .chain([u_prev])
            .flatten()
            .all(|x| x.is_finite())
        {
            return Err(StepError::NonFiniteInput { step: None }.into());
        }
        self.trace_with(
            z0,
            inputs.len(),
            ws,
            |k| step_inputs(u_prev, inputs, k),
            |s, z, k| s.step_forced(z, &inputs[k]),
        )
    }

    fn trace_with<'u>(
        &self,
        z0: &SpatialState<B>,
        steps: usize,
        ws: &mut Workspace,
        input: impl Fn(usize) -> (&'u [f64], &'u [f64]),
        nominal: impl Fn(
            &LieStepper<S, B, J, N, C>,
            &SpatialState<B>,
            usize,
        ) -> Result<SpatialState<B>, StepError>,
    ) -> Result<Trace<B, N>, LearnSpatialError> {
        z0.validate()?;
        vigp_core::step::check_step_count::<SpatialState<B>>(steps)
            .map_err(LearnSpatialError::Step)?;
        let mut states = Vec::with_capacity(steps + 1);
        let mut std_devs = Vec::with_capacity(steps);
        states.push(*z0);
        let mut z = *z0;
        for k in 0..steps {
            let mut var = SVector::<f64, N>::zeros();
            let (up, u) = input(k);
            let nu = self.velocity(&z, up, u, ws, Some(&mut var), |s, z| {
                next_velocities(nominal(s, z, k))
            })?;
            z = self.next_state(&z, &nu)?;
            states.push(z);
            std_devs.push(var.map(|v| v.max(0.0).sqrt()));
        }
        Ok(Trace { states, std_devs })
    }
}

/// The previous and the current input of step k of a rollout after
/// `u_prev` under `inputs`.
pub(crate) fn step_inputs<'u, const U: usize>(
    u_prev: &'u SVector<f64, U>,
    inputs: &'u [SVector<f64, U>],
    k: usize,
) -> (&'u [f64], &'u [f64]) {
    let up = if k == 0 { u_prev } else { &inputs[k - 1] };
    (up.as_slice(), inputs[k].as_slice())
}
