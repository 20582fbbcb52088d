//! The paper's learned integrators (§3): a Gaussian process learns the
//! velocity map z_k ↦ v_{k+1} on top of a prior (the nominal variational
//! step, eq. 7, or a constant mean), and for constrained models the
//! prediction is projected onto the constraint manifold (eq. 8).
//!
//! Positions are never learned: x_{k+1} = x_k + Δt·v_k is exact for discrete
//! velocities, so training targets are v_{k+1} = (x_{k+2} − x_{k+1})/Δt from
//! positions sampled at Δt ([`transitions`]).
//!
//! # Under inputs
//!
//! An actuated mechanism's data carry a zero-order-held input per sample:
//! u_k acts over [t_k, t_{k+1}]. The discrete velocity v_{k+1} then depends
//! on the state z_k = (x_k, v_k) *and on two inputs*: the one held over
//! [t_k, t_{k+1}] (`u_prev`), which together with x_k and x_{k+1} fixes the
//! true velocity at t_{k+1} (a two-point boundary problem of the continuous
//! motion), and the one held over [t_{k+1}, t_{k+2}] (`u`), which carries
//! the motion on to x_{k+2}. So the velocity map that is exact in structure
//! for any truth (a continuous system, a higher-order integrator, a real
//! robot) is v_{k+1} = f(z_k, u_prev, u), and a forced model's GP input is
//! (enc(z_k), u_prev, u) ([`ForcedTransition`], [`Learned::train_forced`]).
//! Only vigp's own first-order VI carries no `u_prev` (its velocity is the
//! state), and the nominal prior is that VI's forced step under `u`.
//!
//! Every prediction of a forced model takes the previous input explicitly:
//! a step from z_k takes `u_prev` (the input that produced v_k) and `u`;
//! a rollout from z₀ takes the input that produced v₀ and the sequence
//! `inputs`, step k running under `inputs[k]` after `inputs[k − 1]`. The
//! [`Integrator`](crate::Integrator) trait's forced calls, which have no slot for it, take the
//! input as held across the start: `step_forced(z, u)` is the step with
//! `u_prev = u`, and `rollout_forced_into(z0, inputs, …)` starts with
//! `u_prev = inputs[0]`.

use crate::gp::{GpError, TrainOptions, TrainReport, Workspace};
use crate::mechanism::{Mechanism, State};
use crate::newton::{StepError, StepOptions};
use crate::projection::{consistent_state, project_velocity};
use crate::variational::Variational;
use nalgebra::SVector;

mod embedded;
mod export;
mod family;
mod file;
mod identified;
#[cfg(feature = "urdf")]
pub mod robot;
pub(crate) mod time_step;
pub(crate) mod transition;
pub use embedded::{EmbeddedExport, ExportSize};
pub(crate) use family::{InputLayout, Row};
pub use family::{LearnedIntegrator, NominalStep, Space};
pub use file::{LoadError, SavedKind, SavedLearned, SavedNewton};
pub use identified::{IdentifiedError, IdentifiedParameters, IdentifiedValue};
pub use transition::{ForcedTransition, Transition, forced_transitions, transitions};

pub use vigp_core::learned::Encoding;

/// The prior mean of the learned velocity map (saved as `"nominal"`,
/// `"constant"` or `{"identified": {…}}`).
///
/// With [`Prior::Identified`] the prior is the nominal step of the
/// mechanism whose physical parameters were identified from logs
/// ([`crate::identify`]), and the GP learns what those parameters cannot
/// explain (Coulomb friction, backlash, unmodelled flexibility):
///
/// ```
/// use vigp_runtime::identify::{DelRegressor, Log, Options, identify};
/// use vigp_runtime::learned::{
///     Encoding, IdentifiedParameters, Learned, Prior, Transition,
/// };
/// use vigp_runtime::gp::TrainOptions;
/// use vigp_runtime::{Mechanism, Parameters};
/// # fn demo<M>(model: M, log: Log, data: &[Transition<1>])
/// #     -> Result<(), Box<dyn std::error::Error>>
/// # where M: Mechanism<1, 0> + Parameters + Copy {
/// // `model`: the mechanism as declared; `log`: positions every 10 ms.
/// let regressor = DelRegressor::midpoint(model, 0.01)?;
/// let id = identify(&regressor, &[log], &Options::default())?;
/// let params = IdentifiedParameters::from_identification::<M>(&id)?;
/// let prior = Prior::Identified(params);
/// let (learned, _) =
///     Learned::train(model, 0.01, data, Encoding::Raw, prior, &TrainOptions::default())?;
/// // the learned model's prior is the identified mechanism
/// assert!(learned.identified().is_some());
/// # Ok(()) }
/// ```
///
/// The model file ([`SavedLearned`]) records the identified standard
/// parameters and their covariance in its `prior`, and the mechanism's
/// parameters with the identified values in `parameters`.
///
/// One type with the target's [`vigp_core::learned::Prior`], whose
/// `Identified` carries the identified parameters here (an exported model
/// writes the identified parameters into its prior's mechanism instead).
pub type Prior = vigp_core::learned::Prior<IdentifiedParameters>;

/// Why training or prediction of a learned integrator failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// The GP could not be trained or evaluated.
    #[error(transparent)]
    Gp(#[from] GpError),
    /// A nominal step or a projection failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// No training data.
    #[error("no training transitions")]
    Empty,
    /// The identified parameters of [`Prior::Identified`] do not fit the
    /// mechanism.
    #[error("identified prior: {0}")]
    Identified(#[from] IdentifiedError),
    /// A setting is out of its domain.
    #[error("invalid setting {what}: {value}")]
    InvalidSetting {
        /// Which setting.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A training transition contains NaN or ±∞ (in the data, or
    /// velocities differenced with Δt = 0).
    #[error(
        "training transition {0} is not finite (NaN or ∞ in the data, or velocities from dt = 0)"
    )]
    NonFinite(usize),
    /// The Δt given to training is more than [`TRAIN_DT_TOLERANCE`] away
    /// (relative) from the one the transitions were formed with, estimated
    /// from consecutive transitions of one run (x_{k+1} = x_k + Δt·v_k).
    #[error(
        "dt = {given} contradicts the training transitions: transitions {first} and {} were \
         formed with dt ≈ {found:.6e}{hint}; train with the data's time step",
        first + 1
    )]
    DtContradictsData {
        /// The Δt given.
        given: f64,
        /// The median estimate from the transitions.
        found: f64,
        /// The first transition of the pair the median came from.
        first: usize,
        /// A hint when the two differ by a round factor.
        hint: &'static str,
    },
    /// A training transition's orientation is not a unit quaternion
    /// (|‖q‖ − 1| > [`UNIT_TOLERANCE`](vigp_core::spatial::maximal::UNIT_TOLERANCE):
    /// built with `UnitQuaternion::new_unchecked` from
    /// unnormalised data).
    #[error(
        "training transition {transition}: the quaternion of link {link} has norm {norm} (must be 1 to 1e-9: normalise it, e.g. UnitQuaternion::new_normalize)"
    )]
    NotUnit {
        /// The transition.
        transition: usize,
        /// The link.
        link: usize,
        /// ‖q‖.
        norm: f64,
    },
    /// [`Prior::Identified`] was given to a model that takes its
    /// parameters from its nominal stepper (a Lie-group stepper): build
    /// the stepper from the mechanism with the identified parameters
    /// ([`IdentifiedParameters::apply`]) and train with
    /// [`Prior::Nominal`].
    #[error(
        "an identified prior is not taken here: build the stepper from the mechanism with the \
         identified parameters (IdentifiedParameters::apply) and train with Prior::Nominal"
    )]
    IdentifiedPrior,
    /// A prediction was asked under a number of inputs other than the one
    /// the model was trained with (0: trained without inputs).
    #[error("the model was trained with {trained} inputs, and was given {given}")]
    Inputs {
        /// Inputs of the training data.
        trained: usize,
        /// Inputs given to the prediction.
        given: usize,
    },
}

/// Leaves out every training row of a GP that repeats an earlier row
/// exactly: the same input (`d` values) and the same target (`p` values),
/// bit for bit (−0 and +0 equal). Returns how many rows it left out; the
/// rows kept stay in their order, so data without repeats are untouched.
///
/// Why: the GP's noise model has independent noise on every observation,
/// under which two equal real-valued noisy observations have probability
/// zero. A repeated row is one measurement recorded twice (e.g. a sample
/// drawn twice from a pool), and kept twice it makes the marginal
/// likelihood unbounded: with σ_n² → 0 and length scales short enough that
/// distinct samples decorrelate, the kernel predicts each repeat exactly
/// from its twin, ½·ln(σ_f²/σ_n²) nats per repeat. On the paper's
/// cart-pole with an identified prior (256 samples drawn with replacement
/// from 2400, ~15 repeats, noise 1e-3 against a residual of the same
/// size) the evidence chose that corner (σ_n² at its lower bound) over
/// the fit of the residual, and the GP predicted nothing (`docs/identify.md`).
/// Replicates — equal inputs with different targets — are kept: they are
/// independent measurements.
pub fn distinct_rows(inputs: &mut Vec<f64>, d: usize, targets: &mut Vec<f64>, p: usize) -> usize {
    if p == 0 {
        return 0;
    }
    let n = targets.len() / p;
    let key = |i: usize| -> Vec<u64> {
        inputs[i * d..(i + 1) * d]
            .iter()
            .chain(&targets[i * p..(i + 1) * p])
            // + 0.0 maps −0 to +0
            .map(|x| (x + 0.0).to_bits())
            .collect()
    };
    let mut seen = std::collections::HashSet::with_capacity(n);
    let keep: Vec<bool> = (0..n).map(|i| seen.insert(key(i))).collect();
    let removed = keep.iter().filter(|k| !**k).count();
    if removed > 0 {
        let mut k = 0;
        for i in (0..n).filter(|&i| keep[i]) {
            inputs.copy_within(i * d..(i + 1) * d, k * d);
            targets.copy_within(i * p..(i + 1) * p, k * p);
            k += 1;
        }
        inputs.truncate(k * d);
        targets.truncate(k * p);
    }
    removed
}

/// Relative distance between the Δt given to [`Learned::train`] (and
/// `train_forced`) and the one its transitions were formed with beyond
/// which training refuses them ([`LearnError::DtContradictsData`]). Loose on
/// purpose: transitions whose velocities were measured rather than
/// differenced satisfy x_{k+1} = x_k + Δt·v_k only to O(Δt·|a|/|v|), while
/// the mistakes this catches (a factor of 2, milliseconds for seconds) are
/// 50 % or more. `vigp::data::check_transitions_dt` checks to any tolerance.
pub const TRAIN_DT_TOLERANCE: f64 = 0.25;

/// Diagnostics of one learned step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedStepInfo<const N: usize> {
    /// The unprojected prediction v_u (eq. 7).
    pub unprojected: SVector<f64, N>,
    /// Posterior standard deviation σ_i(z) of each velocity component.
    pub std_dev: SVector<f64, N>,
    /// Size ‖v − v_u‖ of the projection's correction (0 without constraints).
    pub correction: f64,
}

/// A learned integrator in minimal coordinates: prior + GP velocity map
/// (+ projection when the model has constraints and projection is on),
/// the [`LearnedIntegrator`] over the nominal [`Variational`] step.
///
/// Complexity per step: one nominal VI step (with [`Prior::Nominal`]),
/// O(N·d) per output for the GP mean (N training samples, d input
/// dimensions: N·d subtract-multiply-adds and N exponentials), O(N²) more
/// per output for the variance (only [`Learned::step_in`] and the error
/// bound need it; [`Integrator::step`](crate::Integrator::step) and rollouts use the mean), and a
/// Newton projection for constrained models.
pub type Learned<M, const N: usize, const C: usize> = LearnedIntegrator<Variational<M, N, C>, N>;

/// Minimal coordinates in ℝⁿ: the state is (q, v), the configuration
/// update q₁ = q + Δt·v, the encoding [`Encoding`] over the mechanism's
/// coordinate kinds, the projection [`project_velocity`] onto
/// g(q₁ + Δt·v₁) = 0.
impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Space<N> for Variational<M, N, C> {
    type Encoding = Encoding;
    type PredictionError = StepError;

    fn error(e: LearnError) -> StepError {
        step_error(e)
    }

    /// The model's input count, or none: a model trained with inputs
    /// predicts under u = 0 without them (its `Integrator::step`).
    fn check_inputs(trained: usize, given: usize) -> Result<(), LearnError> {
        if given == 0 || given == trained {
            Ok(())
        } else {
            Err(StepError::InputsNotSupported.into())
        }
    }

    fn velocities(z: &State<N>) -> SVector<f64, N> {
        z.v
    }

    fn constrained(&self) -> bool {
        C > 0
    }

    fn encoded_dim(&self, encoding: Encoding) -> usize {
        encoding.dim(&M::KINDS)
    }

    fn encode(&self, encoding: Encoding, z: &State<N>, out: &mut [f64]) {
        encoding.encode(&M::KINDS, z, out);
    }

    fn is_finite(z: &State<N>) -> bool {
        z.is_finite()
    }

    fn consistent(&self, z: &State<N>) -> Result<State<N>, StepError> {
        consistent_state(self.model(), &z.q, &z.v, self.stepper().dt())
    }

    fn advance(
        &self,
        z: &State<N>,
        vu: &SVector<f64, N>,
        project: bool,
    ) -> Result<State<N>, StepError> {
        let dt = self.stepper().dt();
        let x1 = z.q + z.v * dt;
        let v = if project && C > 0 {
            project_velocity(self.model(), &x1, vu, dt, self.options())?.0
        } else {
            *vu
        };
        Ok(State { q: x1, v })
    }
}

/// The prior: the nominal variational step (its velocity).
impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> NominalStep<N>
    for Variational<M, N, C>
{
    fn prior_velocity(&self, z: &State<N>) -> Result<SVector<f64, N>, StepError> {
        Ok(self.step(z)?.v)
    }

    fn prior_velocity_forced<const U: usize>(
        &self,
        z: &State<N>,
        u: &SVector<f64, U>,
    ) -> Result<SVector<f64, N>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        Ok(self.step_forced(z, u)?.v)
    }
}

/// A learned step with its exact derivatives
/// ([`Learned::step_derivatives_forced`]): the next state, A = ∂z₁/∂z₀
/// and B = ∂z₁/∂u, and B_prev = ∂z₁/∂u_prev.
type StepWithDerivatives<const N: usize, const U: usize> = (
    State<N>,
    vigp_core::StepDerivatives<N, U>,
    vigp_core::InputJacobian<N, U>,
);

/// A learned step's error as a step error: the GP's failure is the
/// prediction's.
fn step_error(e: LearnError) -> StepError {
    match e {
        LearnError::Step(e) => e,
        _ => StepError::Prediction { step: None },
    }
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// Train on transitions. `model` supplies the prior (for
    /// [`Prior::Nominal`]; for [`Prior::Identified`] with the identified
    /// parameters written into it, which the learned model then keeps as
    /// [`Learned::model`]), the angle kinds for [`Encoding::SinCos`], and
    /// the constraints for the projection (on whenever C > 0). The GP
    /// options' `mean` is overridden by `prior`.
    ///
    /// A transition that repeats an earlier one exactly (the same state,
    /// inputs and next velocity, bit for bit) is one measurement recorded
    /// twice, and the GP trains on it once ([`distinct_rows`]): the
    /// learned model's `gp().n()` counts the distinct transitions.
    ///
    /// Errors: no or non-finite transitions, a Δt the transitions
    /// contradict, identified parameters that do not fit `model`
    /// ([`LearnError::Identified`]), a failed nominal step or GP training.
    pub fn train(
        model: M,
        dt: f64,
        data: &[Transition<N>],
        encoding: Encoding,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnError>
    where
        M: crate::Parameters,
    {
        let forced = transition::without_inputs(data);
        let nominal =
            |vi: &Variational<M, N, C>, z: &State<N>, _: &SVector<f64, 0>| vi.prior_velocity(z);
        Self::train_inputs(model, dt, &forced, encoding, prior, options, false, nominal)
    }

    /// [`Learned::train`] for an actuated mechanism on transitions with
    /// their inputs ([`forced_transitions`]): the GP input is the encoded
    /// state followed by the previous and the current input,
    /// (enc(z), u_prev, u) (module docs, "Under inputs"), and the nominal
    /// prior is the forced step under u. `U` must equal the mechanism's
    /// `Dynamics::INPUTS`.
    pub fn train_forced<const U: usize>(
        model: M,
        dt: f64,
        data: &[ForcedTransition<N, U>],
        encoding: Encoding,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnError>
    where
        M: vigp_core::Inputs<U> + crate::Parameters,
    {
        let nominal = |vi: &Variational<M, N, C>, z: &State<N>, u: &SVector<f64, U>| {
            vi.prior_velocity_forced(z, u)
        };
        Self::train_inputs(model, dt, data, encoding, prior, options, true, nominal)
    }

    /// Training with the GP input = encoded state (+ u_prev, u when
    /// `forced`) and
    /// the prior's next velocity `nominal(vi, z, u)` of the nominal
    /// first-order VI `vi` (default Newton options, built once here).
    #[allow(clippy::too_many_arguments)]
    fn train_inputs<const U: usize>(
        model: M,
        dt: f64,
        data: &[ForcedTransition<N, U>],
        encoding: Encoding,
        prior: Prior,
        options: &TrainOptions,
        forced: bool,
        nominal_velocity: impl Fn(
            &Variational<M, N, C>,
            &State<N>,
            &SVector<f64, U>,
        ) -> Result<SVector<f64, N>, StepError>,
    ) -> Result<(Self, TrainReport), LearnError>
    where
        M: vigp_core::Inputs<U> + crate::Parameters,
    {
        if data.is_empty() {
            return Err(LearnError::Empty);
        }
        // the identified prior's mechanism: the identified parameters
        // written into `model` (checked before any data)
        let model = match &prior {
            Prior::Identified(p) => p.model(&model)?,
            _ => model,
        };
        vigp_core::step::check_time_step(dt)?;
        if let Some((found, first)) = time_step::estimate(data.iter().map(|t| (&t.z, &t.v_next)))
            && (found - dt).abs() > TRAIN_DT_TOLERANCE * dt
        {
            return Err(LearnError::DtContradictsData {
                given: dt,
                found,
                first,
                hint: time_step::factor_hint(dt, found),
            });
        }
        let layout = InputLayout {
            inputs: if forced { U } else { 0 },
            previous_input: forced && U > 0,
        };
        // With constraints, a noisy state is off the manifold and the
        // nominal step would spend Δv ≈ |g|/Δt re-closing it: the prior is
        // evaluated at the nearest consistent state instead, as it is at
        // prediction time (predictions are projected).
        let (mut learned, report) = Self::fit(
            Variational::new(model, dt)?,
            data,
            |t| Row {
                z: &t.z,
                u_prev: if forced { t.u_prev.as_slice() } else { &[] },
                u: if forced { t.u.as_slice() } else { &[] },
                next: t.v_next,
            },
            layout,
            encoding,
            prior,
            options,
            |vi, z, t| nominal_velocity(vi, z, &t.u),
        )?;
        // near a folded loop the projection converges linearly
        let options = StepOptions {
            max_iterations: 100,
            ..StepOptions::default()
        };
        learned.nominal = learned.nominal.with_options(options)?;
        Ok((learned, report))
    }

    /// One learned mean step under inputs `u` after `u_prev` (as
    /// [`Learned::step_mean_forced_in`]; `U = 0` for no input, u = 0)
    /// with its exact derivatives A = ∂z₁/∂z₀, B = ∂z₁/∂u and
    /// B_prev = ∂z₁/∂u_prev (the third value; zero for a model that does
    /// not take the previous input): q₁ = q₀ + Δt·v₀, and
    /// v₁ = prior(z₀, u) + μ(enc(z₀), u_prev, u) differentiates into the
    /// nominal forced step's derivatives (`Variational::step_derivatives`;
    /// the prior does not depend on u_prev) plus the GP mean's gradient
    /// (`Gp::predict_mean_gradient_into`) through the encoding. The
    /// projection (constrained models: loops, maximal coordinates)
    /// differentiates implicitly through its KKT conditions at the
    /// projected velocity (multipliers and the constraints' second
    /// derivatives included).
    ///
    /// Numerical caveat for finite-difference checks: the GP mean
    /// μ = k(x)ᵀα sums terms much larger than itself when the trained noise
    /// variance sits on its lower bound (near noise-free data: |α| grows
    /// like 1/σ_n²), so the learned step carries rounding noise of about
    /// 1e-9–1e-7 in v₁. Central differences with ε = 1e-6 then show
    /// apparent errors of 1e-4 and more; use ε ≈ 1e-3 with a five-point
    /// stencil, or raise the noise floor (`TrainOptions::bounds`, e.g.
    /// `noise_variance: (1e-6, 10.0)` in the GP's normalised units), which
    /// also smooths the step for line searches. The exact derivatives returned here are not affected.
    pub fn step_derivatives_forced<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut Workspace,
    ) -> Result<StepWithDerivatives<N, U>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        use vigp_core::learned::VelocityDerivatives;
        self.check_input_count::<U>()?;
        <Variational<M, N, C> as Space<N>>::check(z)?;
        if !u.iter().chain(u_prev.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None });
        }
        let h = self.nominal.dt();
        // prior
        let (mut v, mut dv) = match self.prior {
            Prior::Nominal | Prior::Identified(_) => {
                let (z1, d) = self.nominal.step_derivatives(z, u)?;
                (z1.v, VelocityDerivatives::of_step(&d))
            }
            Prior::Constant => (SVector::zeros(), VelocityDerivatives::zeros()),
        };
        // GP mean and its gradient in the GP input
        let e = self.encoding.dim(&M::KINDS);
        let d = e + self.layout().tail();
        let mut mean = SVector::<f64, N>::zeros();
        let mut grad = vec![0.0; N * d];
        let gradient = |input: &[f64]| {
            self.gp
                .predict_mean_gradient_into(input, mean.as_mut_slice(), &mut grad, ws)
                .map_err(|_| StepError::Prediction { step: None })
        };
        // U = 0 on a model with inputs: u = 0 in the GP input
        self.with_gp_input(z, u_prev.as_slice(), u.as_slice(), gradient)?;
        // where u and u_prev sit in the GP input (U = 0: nowhere)
        let (at_prev, at_u) = if self.previous_input {
            (Some(e), e + U)
        } else {
            (None, e)
        };
        v += mean;
        dv.add_gp_gradient(self.encoding, &M::KINDS, &z.q, at_prev, at_u, |j| {
            &grad[j * d..(j + 1) * d]
        });
        if !v.iter().all(|x| x.is_finite()) {
            return Err(StepError::Prediction { step: None });
        }
        let x1 = z.q + z.v * h;
        if self.project && C > 0 {
            let model = self.nominal.model();
            let (vp, _) = project_velocity(model, &x1, &v, h, self.nominal.options())?;
            let k = model.constants()?;
            dv.project(model, &k, &x1, &v, &vp, h)?;
            v = vp;
        }
        Ok(dv.into_step(z, v, h))
    }

    /// The learned mean rollout under planned inputs (the states of
    /// [`Learned::rollout_mean_forced_into`], bit for bit: step k from z_k
    /// under `inputs[k]` after `inputs[k − 1]`, the first after `u_prev`)
    /// with the exact derivatives of every state with respect to z_0 and to
    /// every planned input: what a shooting MPC over the learned model
    /// needs. The learned step reads the previous input too
    /// ([`Learned::takes_previous_input`]), so u_j reaches z_{j+1} through
    /// B_j and z_{j+2} through B_prev,(j+1):
    ///
    /// ∂z_{k+1}/∂u_j = A_k ∂z_k/∂u_j + [j = k] B_k + [j = k − 1] B_prev,k,
    ///
    /// with A_k, B_k and B_prev,k from [`Learned::step_derivatives_forced`]
    /// at (z_k, u_{k−1}, u_k). `u_prev` is data, not a decision: its column
    /// is not returned. Cost: K derivative steps plus O(K²) products of
    /// N × N blocks. Errors are those of the steps, tagged with the step.
    pub fn rollout_derivatives_forced<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        ws: &mut Workspace,
    ) -> Result<crate::RolloutDerivatives<N, U>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        self.check_input_count::<U>()?;
        crate::RolloutDerivatives::fill(
            z0,
            inputs.len(),
            |buffers| {
                vigp_core::learned::chain_rollout(
                    z0,
                    u_prev,
                    inputs,
                    buffers,
                    |z, up, u| self.step_derivatives_forced(z, up, u, ws),
                    |_, _, _| StepError::InvalidOptions("rollout derivative buffers"),
                )
            },
            |e, _| e,
        )
    }

    /// The forced calls take `U` equal to the inputs the model was trained
    /// with, or `U = 0` (no input: u = 0, as every [`Integrator`](crate::Integrator) takes
    /// it). A `U` other than 0 and the mechanism's input count does not
    /// compile (the `Inputs<U>` bound on every forced call), so the only
    /// run-time refusal is the mechanism's input count on a model trained
    /// without inputs.
    fn check_input_count<const U: usize>(&self) -> Result<(), StepError> {
        <Variational<M, N, C> as Space<N>>::check_inputs(self.inputs, U).map_err(step_error)
    }

    /// [`Learned::rollout_with_info`] under planned inputs: step k goes from
    /// z_k under `inputs[k]` (u is held over the interval of the velocity
    /// the step predicts, [t_{k+1}, t_{k+2}], as in [`ForcedTransition::u`])
    /// after `inputs[k − 1]`, and after `u_prev` for k = 0 (the input that
    /// produced z₀'s velocity), so `inputs.len()` steps. The states equal
    /// those of [`Learned::step_mean_forced_in`] step by step, and the
    /// standard deviations are those at (z_k, u_{k−1}, u_k), from one
    /// batched [`Gp::predict`](crate::gp::Gp::predict) as in `rollout_with_info`.
    ///
    /// `U` is the model's input count, or 0 for no input (u = 0; a
    /// different `U` does not compile). Errors: the mechanism's input count
    /// on a model trained without inputs
    /// ([`StepError::InputsNotSupported`]), and those of the steps, tagged
    /// with the failing step.
    pub fn rollout_forced_with_info<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        ws: &mut Workspace,
    ) -> Result<Vec<(State<N>, LearnedStepInfo<N>)>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        self.check_input_count::<U>()?;
        self.rollout_info(z0, inputs.len(), u_prev, inputs, ws)
    }

    /// The model (prior and constraints): for [`Prior::Identified`] the
    /// mechanism with the identified parameters.
    pub fn model(&self) -> &M {
        self.nominal.model()
    }

    /// `steps` learned steps from `z0`, each with what
    /// [`step_in`](Self::step_in) reports (posterior standard deviations,
    /// unprojected velocity, projection correction): the states and infos
    /// equal those of `steps` calls of `step_in`, bit for bit. This is the
    /// multi-step prediction with uncertainty an MPC horizon needs.
    ///
    /// The steps run on the posterior mean ([`step_mean_in`](Self::step_mean_in),
    /// which gives the same next state), and the variances at all visited
    /// points come afterwards from one [`Gp::predict`](crate::gp::Gp::predict). For an exact GP with
    /// the stored inverse (the default) that shares each pass over an
    /// output's L⁻¹ between the points, so the variance of a step costs a
    /// fraction of `step_in`'s, which streams L⁻¹ (N²/2 values per output)
    /// once per step. Allocates the result and the batch's buffers.
    ///
    /// Errors: those of `step_in`, tagged with the failing step.
    pub fn rollout_with_info(
        &self,
        z0: &State<N>,
        steps: usize,
        ws: &mut Workspace,
    ) -> Result<Vec<(State<N>, LearnedStepInfo<N>)>, StepError> {
        self.rollout_info::<0>(z0, steps, &SVector::zeros(), &[], ws)
    }

    /// `steps` mean steps with their standard deviations: unforced (u = 0
    /// for a model with inputs) when `U = 0`, else under `inputs[k]` after
    /// `inputs[k − 1]` (`u_prev` for k = 0).
    pub(crate) fn rollout_info<const U: usize>(
        &self,
        z0: &State<N>,
        steps: usize,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        ws: &mut Workspace,
    ) -> Result<Vec<(State<N>, LearnedStepInfo<N>)>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        let d = self.gp.input_dim();
        if self.gp.output_dim() != N || d == 0 || (U > 0 && inputs.len() != steps) {
            return Err(StepError::Prediction { step: None });
        }
        // step counts are checked before anything is allocated
        vigp_core::step::check_step_count::<(State<N>, LearnedStepInfo<N>)>(steps)?;
        let len = steps
            .checked_mul(d)
            .ok_or(StepError::TooManySteps { steps })?;
        vigp_core::step::check_step_count::<f64>(len)?;
        let mut points = vec![0.0; len];
        let mut out = Vec::with_capacity(steps);
        let mut z = *z0;
        for (k, x) in points.chunks_exact_mut(d).enumerate() {
            let copy = |input: &[f64]| {
                if input.len() != x.len() {
                    return Err(StepError::Prediction { step: Some(k) });
                }
                x.copy_from_slice(input);
                Ok(())
            };
            let (next, vu) = if U == 0 {
                // the GP input of z, followed by u = 0 for a model with inputs
                self.with_gp_input(&z, &[], &[], copy)?;
                self.mean_step_parts(&z, ws)
            } else {
                let up = if k == 0 { u_prev } else { &inputs[k - 1] };
                self.with_gp_input(&z, up.as_slice(), inputs[k].as_slice(), copy)?;
                self.mean_step_forced_parts(&z, up, &inputs[k], ws)
            }
            .map_err(|e| step_error(e).at_step(k))?;
            out.push((
                next,
                LearnedStepInfo {
                    unprojected: vu,
                    std_dev: SVector::zeros(),
                    correction: (next.v - vu).norm(),
                },
            ));
            z = next;
        }
        let variance = match self.gp.predict(&points) {
            Ok(p) => p.variance,
            Err(_) => {
                // Name the step whose prediction fails, as step_in would.
                let mut z = *z0;
                for (k, (next, _)) in out.iter().enumerate() {
                    if U == 0 {
                        self.predict_velocity(&z, ws).map(|_| ())
                    } else {
                        let up = if k == 0 { u_prev } else { &inputs[k - 1] };
                        self.predict_velocity_forced(&z, up, &inputs[k], ws)
                            .map(|_| ())
                    }
                    .map_err(|e| e.at_step(k))?;
                    z = *next;
                }
                return Err(StepError::Prediction { step: None });
            }
        };
        for ((_, info), var) in out.iter_mut().zip(variance.chunks_exact(N)) {
            info.std_dev = SVector::from_iterator(var.iter().map(|s| s.max(0.0).sqrt()));
        }
        Ok(out)
    }
}
