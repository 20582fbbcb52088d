//! One learned integrator over every configuration space.
//!
//! A learned integrator is a nominal model, a GP and a rule: the state
//! z_k is configuration k and the velocities of the step to k + 1; the GP
//! learns the next velocities ν_{k+1} on top of the nominal step's (the
//! prior, eq. 7), from the encoded state and the inputs, (enc(z), u_prev,
//! u); the configuration update is exact, and the predicted velocities are
//! projected onto the constraints of the next configuration (eq. 8).
//!
//! What differs between configuration spaces is what a [`Space`] says:
//! how a state is encoded, checked and advanced, where the nominal prior
//! of a noisy state is evaluated, the space's error type and whether a
//! model trained with inputs predicts without them. Its prior step is a
//! [`NominalStep`]. Minimal coordinates in ℝⁿ
//! ([`Variational`](crate::Variational), `vigp::learned::Learned`) and
//! bodies in ℝ³ × SO(3) ([`LieStepper`](vigp_core::spatial::LieStepper),
//! `vigp::spatial::learned::LearnedSpatial`) are the one type
//! [`LearnedIntegrator`], whose training, velocity prediction
//! (`predict_velocity`, `predict_mean_velocity`), step (`step_in`,
//! `step_mean_in`), their forced forms and accessors are written once
//! here. What only one space has stays with it: exact derivatives and
//! model files in minimal coordinates, the spatial conformal bound's
//! pose errors.

use super::{LearnError, LearnedStepInfo, Prior, distinct_rows};
use crate::gp::{Gp, PriorMean, TrainOptions, TrainReport, Workspace};
use crate::integrator::{Integrator, check_inputs_cover, roll};
use crate::newton::StepError;
use nalgebra::SVector;

/// A configuration space with its nominal model, as a learned integrator
/// sees it: the nominal [`Integrator`] of the space (its state, mechanism,
/// time step and error are the learned integrator's too) with what
/// learning adds. `N` is the number of velocity coordinates (the GP's
/// outputs).
pub trait Space<const N: usize>:
    Integrator<Error: From<<Self as Space<N>>::PredictionError>>
{
    /// How a state enters the GP.
    type Encoding: Copy + core::fmt::Debug + PartialEq;

    /// Whether the model has constraints to project onto.
    fn constrained(&self) -> bool;

    /// The length of an encoded state.
    fn encoded_dim(&self, encoding: Self::Encoding) -> usize;

    /// Writes the encoded state into `out` (length
    /// [`Space::encoded_dim`]).
    fn encode(&self, encoding: Self::Encoding, z: &Self::State, out: &mut [f64]);

    /// The error of this space's learned predictions and steps; the
    /// integrator's error ([`Integrator::Error`]) converts from it.
    type PredictionError;

    /// A learned step's error as this space's error.
    fn error(e: LearnError) -> Self::PredictionError;

    /// Whether predictions under `given` inputs fit a model trained with
    /// `trained` ([`LearnError::Inputs`] or
    /// [`StepError::InputsNotSupported`] otherwise; module docs of the
    /// space's learned integrator).
    fn check_inputs(trained: usize, given: usize) -> Result<(), LearnError>;

    /// The velocities ν of a state.
    fn velocities(z: &Self::State) -> SVector<f64, N>;

    /// Whether every number of the state is finite.
    fn is_finite(z: &Self::State) -> bool;

    /// A state a step may start from, as the nominal step checks it: by
    /// default a finite one ([`StepError::NonFiniteState`] otherwise); a
    /// space with more to check (unit quaternions) says so.
    fn check(z: &Self::State) -> Result<(), StepError> {
        if Self::is_finite(z) {
            Ok(())
        } else {
            Err(StepError::NonFiniteState { step: None })
        }
    }

    /// What training asks of a finite state beyond finiteness (transition
    /// `i`; e.g. unit quaternions). Nothing by default.
    fn check_training(_i: usize, _z: &Self::State) -> Result<(), LearnError> {
        Ok(())
    }

    /// The consistent state nearest to `z` (only asked of a constrained
    /// model): where the nominal prior of a noisy training state is
    /// evaluated, as it is at prediction time, where predictions are
    /// projected.
    fn consistent(&self, z: &Self::State) -> Result<Self::State, StepError>;

    /// The exact configuration update of `z` with the next velocities
    /// `nu`, projected onto the constraints of the next configuration when
    /// `project` (and the model has constraints).
    fn advance(
        &self,
        z: &Self::State,
        nu: &SVector<f64, N>,
        project: bool,
    ) -> Result<Self::State, StepError>;
}

/// The nominal step of a [`Space`]: the prior of eq. 7 (a separate trait
/// because stepping may ask more of the mechanism, e.g. `Clone` to
/// subdivide, than its geometry does).
pub trait NominalStep<const N: usize>: Space<N> {
    /// The nominal step's next velocities from `z` (no inputs).
    fn prior_velocity(&self, z: &Self::State) -> Result<SVector<f64, N>, StepError>;

    /// The nominal forced step's next velocities from `z` under `u`.
    fn prior_velocity_forced<const U: usize>(
        &self,
        z: &Self::State,
        u: &SVector<f64, U>,
    ) -> Result<SVector<f64, N>, StepError>
    where
        Self::Mechanism: vigp_core::Inputs<U>;
}

/// One training row: a state, the input that produced its velocities, the
/// input held over the step (both empty without inputs), and the next
/// velocities.
pub(crate) struct Row<'a, Z, const N: usize> {
    /// z_k.
    pub z: &'a Z,
    /// The input over [t_k, t_{k+1}].
    pub u_prev: &'a [f64],
    /// The input over [t_{k+1}, t_{k+2}].
    pub u: &'a [f64],
    /// ν_{k+1}.
    pub next: SVector<f64, N>,
}

/// Where the inputs sit in a GP input, after the encoded state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct InputLayout {
    /// Inputs of the mechanism the GP takes (0: trained without inputs).
    pub inputs: usize,
    /// Whether u_prev precedes u (otherwise only u: a model file written
    /// before the previous input was learned).
    pub previous_input: bool,
}

/// A learned integrator over the configuration space of its nominal model
/// `S`: prior + GP velocity map, and the projection when the model has
/// constraints and projection is on (module docs).
///
/// Every user meets it under a name for its space: `Learned<M, N, C>` in
/// minimal coordinates, `LearnedSpatial<S, B, J, N, C>` for bodies in
/// space. Both are aliases of this type, so what is written here (the
/// accessors below, training and prediction) is one code path, and code
/// over the family is written once:
///
/// ```
/// use vigp_runtime::learned::{LearnedIntegrator, Space};
///
/// /// Training points and GP input width of any learned integrator,
/// /// planar or spatial.
/// fn size<S: Space<N>, const N: usize>(learned: &LearnedIntegrator<S, N>) -> (usize, usize) {
///     (learned.gp().n(), learned.gp().input_dim())
/// }
/// ```
#[derive(Clone, Debug)]
pub struct LearnedIntegrator<S: Space<N>, const N: usize> {
    /// The nominal model: the prior's step, Δt and the projection's
    /// constraints and options, held once.
    pub(crate) nominal: S,
    pub(crate) prior: Prior,
    pub(crate) encoding: S::Encoding,
    pub(crate) project: bool,
    pub(crate) gp: Gp,
    /// Number of inputs of the mechanism the GP takes (0: trained without
    /// inputs).
    pub(crate) inputs: usize,
    /// Whether the GP input carries the previous input before the current
    /// one, (enc(z), u_prev, u), or only the current one, (enc(z), u) (a
    /// model file without `previous_input`).
    pub(crate) previous_input: bool,
}

impl<S: Space<N>, const N: usize> LearnedIntegrator<S, N> {
    /// Trains the GP on `data` (one [`Row`] each, `row`) and returns the
    /// learned integrator over `nominal`: GP input (enc(z), u_prev, u) as
    /// `layout` says, target ν_{k+1} − prior, the prior's next velocities
    /// from `prior_velocity(nominal, z, t)` at the consistent state
    /// nearest to z (constrained models) or 0 for [`Prior::Constant`],
    /// whose constant is the GP's mean. A transition repeated exactly is
    /// trained on once ([`distinct_rows`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn fit<T>(
        nominal: S,
        data: &[T],
        row: impl Fn(&T) -> Row<'_, S::State, N>,
        layout: InputLayout,
        encoding: S::Encoding,
        prior: Prior,
        options: &TrainOptions,
        prior_velocity: impl Fn(&S, &S::State, &T) -> Result<SVector<f64, N>, StepError>,
    ) -> Result<(Self, TrainReport), LearnError> {
        if data.is_empty() {
            return Err(LearnError::Empty);
        }
        let e = nominal.encoded_dim(encoding);
        let d = e + layout.tail();
        let mut inputs = vec![0.0; data.len() * d];
        let mut targets = Vec::with_capacity(data.len() * N);
        for (i, t) in data.iter().enumerate() {
            let r = row(t);
            if !(S::is_finite(r.z)
                && r.next.iter().all(|x| x.is_finite())
                && r.u.iter().chain(r.u_prev).all(|x| x.is_finite()))
            {
                return Err(LearnError::NonFinite(i));
            }
            S::check_training(i, r.z)?;
            layout.write(
                &nominal,
                encoding,
                r.z,
                r.u_prev,
                r.u,
                &mut inputs[i * d..(i + 1) * d],
            );
            let base = if prior.uses_nominal_step() {
                if nominal.constrained() {
                    let z = nominal.consistent(r.z)?;
                    prior_velocity(&nominal, &z, t)?
                } else {
                    prior_velocity(&nominal, r.z, t)?
                }
            } else {
                SVector::zeros()
            };
            targets.extend((r.next - base).iter());
        }
        distinct_rows(&mut inputs, d, &mut targets, N);
        let mut opts = options.clone();
        opts.mean = if prior.uses_nominal_step() {
            PriorMean::Zero
        } else {
            PriorMean::Constant
        };
        let (gp, report) = Gp::train(&inputs, d, &targets, N, &opts)?;
        Ok((
            Self {
                project: nominal.constrained(),
                nominal,
                prior,
                encoding,
                gp,
                inputs: layout.inputs,
                previous_input: layout.previous_input,
            },
            report,
        ))
    }

    /// Where the inputs sit in this model's GP input.
    pub(crate) fn layout(&self) -> InputLayout {
        InputLayout {
            inputs: self.inputs,
            previous_input: self.previous_input,
        }
    }

    /// Writes the GP input of a step from `z` after `u_prev` under `u`
    /// into `out` (length `gp().input_dim()`): the encoded state, then
    /// u_prev (when the model takes it) and u; empty `u` (or a model
    /// without inputs) leaves zeros, the input u = 0.
    pub(crate) fn gp_input_into(&self, z: &S::State, u_prev: &[f64], u: &[f64], out: &mut [f64]) {
        self.layout()
            .write(&self.nominal, self.encoding, z, u_prev, u, out);
    }

    /// Passes the GP input of a step from `z` after `u_prev` under `u`
    /// ([`Self::gp_input_into`]) to `f`, on the stack (heap only above 128
    /// dimensions).
    pub(crate) fn with_gp_input<T, E>(
        &self,
        z: &S::State,
        u_prev: &[f64],
        u: &[f64],
        f: impl FnOnce(&[f64]) -> Result<T, E>,
    ) -> Result<T, E> {
        let d = self.nominal.encoded_dim(self.encoding) + self.layout().tail();
        let mut stack = [0.0f64; 128];
        let mut heap;
        let input: &mut [f64] = if d <= stack.len() {
            &mut stack[..d]
        } else {
            heap = vec![0.0; d];
            &mut heap
        };
        self.gp_input_into(z, u_prev, u, input);
        f(input)
    }

    /// The unprojected velocities ν_u = prior + μ at the GP input of a
    /// step from `z` after `u_prev` under `u` (empty: u = 0), the prior's
    /// next velocities from `prior_velocity(nominal, z)` (unused for
    /// [`Prior::Constant`]); the GP's latent variances into `var` when
    /// given (the mean is the same bits either way).
    pub(crate) fn velocity(
        &self,
        z: &S::State,
        u_prev: &[f64],
        u: &[f64],
        ws: &mut Workspace,
        var: Option<&mut SVector<f64, N>>,
        prior_velocity: impl FnOnce(&S, &S::State) -> Result<SVector<f64, N>, StepError>,
    ) -> Result<SVector<f64, N>, LearnError> {
        let mut mean = SVector::<f64, N>::zeros();
        self.with_gp_input(z, u_prev, u, |input| match var {
            Some(var) => self
                .gp
                .predict_into(input, mean.as_mut_slice(), var.as_mut_slice(), ws),
            None => self.gp.predict_mean_into(input, mean.as_mut_slice(), ws),
        })?;
        let prior = if self.prior.uses_nominal_step() {
            prior_velocity(&self.nominal, z)?
        } else {
            SVector::zeros()
        };
        let nu = prior + mean;
        if !nu.iter().all(|x| x.is_finite()) {
            return Err(StepError::Prediction { step: None }.into());
        }
        Ok(nu)
    }

    /// The next state from `z` and the unprojected velocities `nu`: the
    /// exact configuration update, and `nu` projected onto the
    /// constraints when the model projects ([`Space::advance`]).
    pub(crate) fn next_state(
        &self,
        z: &S::State,
        nu: &SVector<f64, N>,
    ) -> Result<S::State, StepError> {
        self.nominal.advance(z, nu, self.project)
    }

    /// Switch the projection off (eq. 7 even for a constrained model), e.g.
    /// to measure what the projection buys.
    pub fn without_projection(mut self) -> Self {
        self.project = false;
        self
    }

    /// `true` when predictions are projected onto the constraints.
    pub fn projects(&self) -> bool {
        self.project
    }

    /// The trained GP.
    pub fn gp(&self) -> &Gp {
        &self.gp
    }

    /// A GP workspace for the steps that take one (`step_in`, …).
    pub fn workspace(&self) -> Workspace {
        self.gp.workspace()
    }

    /// Whether the step with its variances may compute some velocity
    /// outputs' variances on a helper thread (see
    /// [`Gp::set_parallel_variance`]: default `false`, results
    /// bit-identical either way; when on, a second core busy-waits for
    /// 200 µs after each step).
    pub fn set_parallel_variance(&mut self, on: bool) {
        self.gp.set_parallel_variance(on);
    }

    /// The nominal model: the prior's step (for a prior of identified
    /// parameters, with those parameters), Δt and the constraints.
    pub fn nominal(&self) -> &S {
        &self.nominal
    }

    /// The encoding of the state in GP inputs.
    pub fn encoding(&self) -> S::Encoding {
        self.encoding
    }

    /// The prior (a copy; [`Self::identified`] borrows the identified
    /// parameters).
    pub fn prior(&self) -> Prior {
        self.prior.clone()
    }

    /// The identified parameters of a model trained with
    /// [`Prior::Identified`] (their values and covariance).
    pub fn identified(&self) -> Option<&super::IdentifiedParameters> {
        self.prior.identified()
    }

    /// Number of inputs the model was trained with (0: without inputs).
    pub fn inputs(&self) -> usize {
        self.inputs
    }

    /// Whether the GP takes the previous input, (enc(z), u_prev, u): `true`
    /// for every model trained with inputs; `false` without inputs, and
    /// for a model file written with the GP input (enc(z), u)
    /// ([`SavedLearned::previous_input`](super::SavedLearned::previous_input)),
    /// whose predictions ignore `u_prev`.
    pub fn takes_previous_input(&self) -> bool {
        self.previous_input
    }
}

impl InputLayout {
    /// Number of GP input components after the encoded state.
    pub(crate) fn tail(self) -> usize {
        if self.previous_input {
            2 * self.inputs
        } else {
            self.inputs
        }
    }

    /// Writes enc(z), then u_prev (when taken) and u, into `out`; empty
    /// `u` or no inputs leave the tail zero.
    fn write<S: Space<N>, const N: usize>(
        self,
        space: &S,
        encoding: S::Encoding,
        z: &S::State,
        u_prev: &[f64],
        u: &[f64],
        out: &mut [f64],
    ) {
        let e = space.encoded_dim(encoding);
        space.encode(encoding, z, &mut out[..e]);
        out[e..].fill(0.0);
        let m = self.inputs;
        if u.is_empty() || m == 0 {
            return;
        }
        if self.previous_input {
            out[e..e + m].copy_from_slice(&u_prev[..m]);
            out[e + m..e + 2 * m].copy_from_slice(&u[..m]);
        } else {
            out[e..e + m].copy_from_slice(&u[..m]);
        }
    }
}

/// Prediction and steps, with the nominal step as the prior.
impl<S: NominalStep<N>, const N: usize> LearnedIntegrator<S, N> {
    /// The unprojected prediction ν_u = prior(z) + μ(z) (eq. 7) and the
    /// posterior standard deviations of the velocities, without inputs.
    /// Cost O(p·N·(d + N)) for the GP (the variance needs a triangular
    /// solve per output) plus the prior. A model trained with inputs is
    /// the space's to refuse or to predict under u = 0
    /// ([`Space::check_inputs`]).
    pub fn predict_velocity(
        &self,
        z: &S::State,
        ws: &mut Workspace,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>), S::PredictionError> {
        let mut var = SVector::<f64, N>::zeros();
        let nu = self
            .unforced_velocity(z, ws, Some(&mut var))
            .map_err(S::error)?;
        Ok((nu, std_dev(&var)))
    }

    /// ν_u = prior(z) + μ(z) without the variance: O(p·N·d) for the GP plus
    /// the prior. Equal bit for bit to the first component of
    /// [`Self::predict_velocity`].
    pub fn predict_mean_velocity(
        &self,
        z: &S::State,
        ws: &mut Workspace,
    ) -> Result<SVector<f64, N>, S::PredictionError> {
        self.unforced_velocity(z, ws, None).map_err(S::error)
    }

    /// [`Self::predict_velocity`] under inputs `u` after `u_prev` (the
    /// input that produced z's velocities): ν_u = forced prior(z, u) +
    /// μ(enc(z), u_prev, u) and the posterior standard deviations. `U` is
    /// the model's input count (or what [`Space::check_inputs`] admits);
    /// a NaN or ∞ in `u_prev` or `u` is [`StepError::NonFiniteInput`].
    pub fn predict_velocity_forced<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<(SVector<f64, N>, SVector<f64, N>), S::PredictionError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        let mut var = SVector::<f64, N>::zeros();
        let nu = self
            .forced_velocity(z, u_prev, u, ws, Some(&mut var))
            .map_err(S::error)?;
        Ok((nu, std_dev(&var)))
    }

    /// [`Self::predict_velocity_forced`] without the variance (the same
    /// mean, bit for bit).
    pub fn predict_mean_velocity_forced<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<SVector<f64, N>, S::PredictionError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        self.forced_velocity(z, u_prev, u, ws, None)
            .map_err(S::error)
    }

    /// One learned step with a caller-owned GP workspace: the exact
    /// configuration update, the velocities predicted (with their
    /// standard deviations) and projected; what the step reports. No
    /// allocation for GP inputs of up to 128 dimensions.
    pub fn step_in(
        &self,
        z: &S::State,
        ws: &mut Workspace,
    ) -> Result<(S::State, LearnedStepInfo<N>), S::PredictionError> {
        let mut var = SVector::<f64, N>::zeros();
        let (next, nu) = self
            .mean_step(z, |l| l.unforced_velocity(z, ws, Some(&mut var)))
            .map_err(S::error)?;
        Ok((next, info::<S, N>(&next, nu, std_dev(&var))))
    }

    /// One learned step using only the posterior mean (what a rollout
    /// needs): [`Self::step_in`]'s next state, bit for bit, at
    /// O(p·N·d) instead of O(p·N·(d + N)) for the GP.
    pub fn step_mean_in(
        &self,
        z: &S::State,
        ws: &mut Workspace,
    ) -> Result<S::State, S::PredictionError> {
        Ok(self.mean_step_parts(z, ws).map_err(S::error)?.0)
    }

    /// One learned mean step under inputs `u` (held over the step) after
    /// `u_prev` (the input that produced z's velocities), as
    /// [`Self::step_mean_in`].
    pub fn step_mean_forced_in<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<S::State, S::PredictionError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        Ok(self
            .mean_step_forced_parts(z, u_prev, u, ws)
            .map_err(S::error)?
            .0)
    }

    /// The next state of a mean step without inputs and ν_u.
    pub(crate) fn mean_step_parts(
        &self,
        z: &S::State,
        ws: &mut Workspace,
    ) -> Result<(S::State, SVector<f64, N>), LearnError> {
        self.mean_step(z, |l| l.unforced_velocity(z, ws, None))
    }

    /// The next state of a mean step under `u` after `u_prev` and ν_u.
    pub(crate) fn mean_step_forced_parts<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<(S::State, SVector<f64, N>), LearnError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        self.mean_step(z, |l| l.forced_velocity(z, u_prev, u, ws, None))
    }

    /// ν_u from `velocity` (which checks the state), and the next state.
    fn mean_step(
        &self,
        z: &S::State,
        velocity: impl FnOnce(&Self) -> Result<SVector<f64, N>, LearnError>,
    ) -> Result<(S::State, SVector<f64, N>), LearnError> {
        // the velocity checks the state
        let nu = velocity(self)?;
        Ok((self.next_state(z, &nu)?, nu))
    }

    /// ν_u without inputs (u = 0 in the GP input of a model with inputs,
    /// where the space admits it).
    pub(crate) fn unforced_velocity(
        &self,
        z: &S::State,
        ws: &mut Workspace,
        var: Option<&mut SVector<f64, N>>,
    ) -> Result<SVector<f64, N>, LearnError> {
        S::check(z)?;
        S::check_inputs(self.inputs, 0)?;
        self.velocity(z, &[], &[], ws, var, |s, z| s.prior_velocity(z))
    }

    /// ν_u under `u` after `u_prev`.
    pub(crate) fn forced_velocity<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
        var: Option<&mut SVector<f64, N>>,
    ) -> Result<SVector<f64, N>, LearnError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        S::check(z)?;
        S::check_inputs(self.inputs, U)?;
        if !u.iter().chain(u_prev.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None }.into());
        }
        self.velocity(z, u_prev.as_slice(), u.as_slice(), ws, var, |s, z| {
            s.prior_velocity_forced(z, u)
        })
    }
}

/// Rollouts of the posterior mean under inputs.
impl<S: NominalStep<N>, const N: usize> LearnedIntegrator<S, N> {
    /// One mean step under `u` after `u_prev` as the integrator takes it:
    /// a model trained without inputs takes only u = 0 (its unforced step)
    /// and refuses other inputs with [`StepError::InputsNotSupported`].
    fn held_step_in<const U: usize>(
        &self,
        z: &S::State,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<S::State, <S as Integrator>::Error>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        if self.inputs == 0 {
            if !u.iter().all(|x| *x == 0.0) {
                return Err(StepError::InputsNotSupported.into());
            }
            return Ok(self.step_mean_in(z, ws)?);
        }
        Ok(self.step_mean_forced_in(z, u_prev, u, ws)?)
    }

    /// The states after 1, …, `out.len()` mean steps from `z0`, step k
    /// under `inputs[k]` after `inputs[k − 1]` and the first after `u_prev`
    /// (the input that produced z₀'s velocities): the states of
    /// [`Self::step_mean_forced_in`] step by step, with one workspace.
    /// `inputs` must be at least as long as `out` (shorter:
    /// [`StepError::NonFiniteInput`] at step `inputs.len()`, before any
    /// step). A model trained without inputs takes only zeros
    /// ([`Integrator::step_forced`]). Stops at the first error (which names
    /// the step).
    pub fn rollout_mean_forced_into<const U: usize>(
        &self,
        z0: &S::State,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        out: &mut [S::State],
    ) -> Result<(), <S as Integrator>::Error>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        check_inputs_cover(inputs.len(), out.len())?;
        let mut ws = self.gp.workspace();
        roll(z0, out, |k, z| {
            let up = if k == 0 { u_prev } else { &inputs[k - 1] };
            self.held_step_in(z, up, &inputs[k], &mut ws)
        })
    }
}

/// The learned integrator as an [`Integrator`] of its space: mean steps
/// (the GP's posterior mean), each call allocating a GP workspace (use
/// [`LearnedIntegrator::step_mean_in`] in loops); a rollout allocates one.
impl<S: NominalStep<N>, const N: usize> Integrator for LearnedIntegrator<S, N> {
    type State = S::State;
    type Error = <S as Integrator>::Error;
    type Mechanism = <S as Integrator>::Mechanism;

    fn dt(&self) -> f64 {
        self.nominal.dt()
    }

    /// One mean step ([`LearnedIntegrator::step_mean_in`]); a model
    /// trained with inputs steps under u = 0 or refuses, as its space says
    /// ([`Space::check_inputs`]).
    fn step(&self, z: &S::State) -> Result<S::State, <S as Integrator>::Error> {
        Ok(self.step_mean_in(z, &mut self.gp.workspace())?)
    }

    /// A model trained with inputs steps under them
    /// ([`LearnedIntegrator::step_mean_forced_in`]) with the input taken as
    /// held across the start, u_prev = u (the trait has no slot for the
    /// previous input; pass it to `step_mean_forced_in` where it differs);
    /// one trained without inputs takes only u = 0.
    fn step_forced<const U: usize>(
        &self,
        z: &S::State,
        u: &SVector<f64, U>,
    ) -> Result<S::State, <S as Integrator>::Error>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        self.held_step_in(z, u, u, &mut self.gp.workspace())
    }

    /// Mean steps with one workspace.
    fn rollout_into(
        &self,
        z0: &S::State,
        out: &mut [S::State],
    ) -> Result<(), <S as Integrator>::Error> {
        let mut ws = self.gp.workspace();
        roll(z0, out, |_, z| Ok(self.step_mean_in(z, &mut ws)?))
    }

    /// Step k under `inputs[k]` after `inputs[k − 1]`, the first after
    /// `inputs[0]` (the input taken as held across the start;
    /// [`LearnedIntegrator::rollout_mean_forced_into`] takes the previous
    /// input explicitly).
    fn rollout_forced_into<const U: usize>(
        &self,
        z0: &S::State,
        inputs: &[SVector<f64, U>],
        out: &mut [S::State],
    ) -> Result<(), <S as Integrator>::Error>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        match inputs.first() {
            Some(u0) => self.rollout_mean_forced_into(z0, u0, inputs, out),
            None if out.is_empty() => Ok(()),
            None => Err(StepError::NonFiniteInput { step: Some(0) }.into()),
        }
    }
}

/// Standard deviations from latent variances (negative rounding is 0).
fn std_dev<const N: usize>(var: &SVector<f64, N>) -> SVector<f64, N> {
    var.map(|v| v.max(0.0).sqrt())
}

/// What a step reports: ν_u, σ, and the size of the projection's
/// correction ‖ν − ν_u‖.
fn info<S: Space<N>, const N: usize>(
    next: &S::State,
    nu: SVector<f64, N>,
    std_dev: SVector<f64, N>,
) -> LearnedStepInfo<N> {
    LearnedStepInfo {
        unprojected: nu,
        std_dev,
        correction: (S::velocities(next) - nu).norm(),
    }
}
