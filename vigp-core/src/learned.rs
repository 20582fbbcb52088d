//! The learned step on fixed-size data (paper eq. 7–8), `no_std` and
//! without allocation: the nominal variational step of a [`Dynamics`]
//! model as prior, a GP mean exported from the std runtime as correction, and for
//! mechanisms with loops the projection of the velocity onto the
//! constraints.
//!
//! The std runtime writes a trained `Learned` model as Rust source
//! (`Learned::to_embedded_source`, or `vigp export` on the command line):
//! static arrays for the GPs and one [`LearnedModel`] that names the
//! mechanism, its parameter values, Δt, the encoding, the prior and the
//! inputs. [`LearnedStepper::new`] checks that model against the mechanism
//! type and sets the parameters; [`LearnedStepper::step`] is then
//!
//! ```text
//! x₁ = x₀ + Δt·v₀
//! v_u = v̄(z₀) + μ(enc(z₀))      (v̄: nominal VI step, or 0 for a constant prior)
//! v₁  = argmin ‖v − v_u‖²  s.t. g(x₁ + Δt·v) = 0      (loops only)
//! ```
//!
//! # Inputs
//!
//! A model trained with inputs on an actuated mechanism (the std runtime's
//! `Learned::train_forced`) takes them in [`LearnedStepper::step_forced`]
//! and [`LearnedStepper::rollout_forced_into`]: the GP input is the encoded
//! state followed by the previous and the current input,
//! (enc(z₀), u_prev, u), and the nominal prior is the nominal forced step
//! [`Stepper::step_forced`] under u, as in the std runtime:
//!
//! ```text
//! v_u = v̄(z₀, u) + μ(enc(z₀), u_prev, u)
//! ```
//!
//! Here u is held over [t₁, t₂], the interval of the velocity the step
//! predicts, and u_prev over [t₀, t₁], the interval of z₀'s velocity: under
//! a zero-order-held input the true next discrete velocity depends on both
//! (the std runtime's `vigp::learned`, "Under inputs"). A step takes u_prev
//! explicitly; a rollout takes the input that produced z₀'s velocity and
//! then runs step k under `inputs[k]` after `inputs[k − 1]`. A model
//! exported with the GP input (enc(z₀), u) (from a model file without
//! `previous_input`) has `D` = encoding + inputs instead of encoding +
//! 2·inputs; [`LearnedStepper::new`] tells the two apart by `D`, and such a
//! model ignores u_prev ([`LearnedStepper::takes_previous_input`]).
//!
//! The input count is a type-level fact: `U` must equal
//! [`Dynamics::INPUTS`], or be 0 for no input (u = 0, as
//! [`Stepper::step_forced`] takes it) — the bound `M: Inputs<U>`
//! ([`crate::Inputs`]), so a wrong-length input is a compile error at the
//! call; NaN or ±∞ in u is [`StepError::NonFiniteInput { step: None }`].
//! [`LearnedStepper::step`] (no input) of a model with inputs is the forced
//! step under u = 0, as the std runtime's unforced step of such a model. A
//! model trained without inputs takes only u = 0 in `step_forced` (which is
//! then `step`); any other input is [`LearnedError::NoInputs`].
//!
//! Cost per step: one nominal [`Stepper`] step (with a nominal prior), N·D
//! subtract-multiply-adds and N exponentials per velocity component for the
//! GP means (N training points, D encoded inputs), and for loops a few
//! Newton iterations on the (N+C)-dimensional KKT system of the projection.
//! Stack only.

mod derivatives;

pub(crate) use derivatives::buffer_length;
pub use derivatives::{VelocityDerivatives, chain_rollout, chain_step};

use crate::dynamics::Dynamics;
use crate::forced::{InputJacobian, RolloutDerivativeBuffers, StepDerivatives};
use crate::gp::{ExportedGp, GpError};
use crate::params::Parameters;
use crate::projection::project_velocity;
use crate::real::Real;
use crate::state::{CoordinateKind, State};
use crate::step::{StepError, StepOptions, Stepper};
use nalgebra::SVector;

/// How a state z = (q, v) is presented to the GP (saved as `"raw"` or
/// `"sincos"` with the `serde` feature). The std runtime and the exported
/// `no_std` models encode with the same arithmetic (libm's sincos), so a
/// model and its export see the same GP inputs, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum Encoding {
    /// The model's own coordinates and velocities (minimal or maximal).
    Raw,
    /// Every angle coordinate θ replaced by (sin θ, cos θ); velocities as is.
    SinCos,
}

impl Encoding {
    /// Input dimension of the encoding for a model with coordinate `kinds`.
    pub fn dim(self, kinds: &[CoordinateKind]) -> usize {
        let angles = kinds
            .iter()
            .filter(|k| **k == CoordinateKind::Angle)
            .count();
        match self {
            Encoding::Raw => 2 * kinds.len(),
            Encoding::SinCos => 2 * kinds.len() + angles,
        }
    }

    /// Writes the encoding of `z` into `out` (length at least
    /// [`dim`](Self::dim)).
    pub fn encode<const N: usize>(
        self,
        kinds: &[CoordinateKind; N],
        z: &State<N>,
        out: &mut [f64],
    ) {
        self.encode_parts(kinds, z.q.as_slice(), z.v.as_slice(), out);
    }

    /// [`Encoding::encode`] of the state with coordinates `q` and
    /// velocities `v` (one of each per kind), for models whose size is
    /// known at run time.
    pub fn encode_parts(self, kinds: &[CoordinateKind], q: &[f64], v: &[f64], out: &mut [f64]) {
        let mut k = 0;
        for (i, kind) in kinds.iter().enumerate() {
            if self == Encoding::SinCos && *kind == CoordinateKind::Angle {
                let (s, c) = q[i].sincos();
                out[k] = s;
                out[k + 1] = c;
                k += 2;
            } else {
                out[k] = q[i];
                k += 1;
            }
        }
        out[k..k + v.len()].copy_from_slice(v);
    }

    /// The chain rule through the encoding: for a function whose gradient
    /// with respect to the encoded state (its first [`Encoding::dim`]
    /// entries) at coordinates `q` is `g`, calls `add(i, ∂/∂q_i)` and then
    /// `add(n + i, ∂/∂v_i)` for i = 0 … n − 1, n = `kinds.len()`
    /// (∂(sin θ, cos θ)/∂θ = (cos θ, −sin θ) under [`Encoding::SinCos`]).
    pub fn pull_back(
        self,
        kinds: &[CoordinateKind],
        q: &[f64],
        g: &[f64],
        mut add: impl FnMut(usize, f64),
    ) {
        let mut k = 0;
        for (i, kind) in kinds.iter().enumerate() {
            if self == Encoding::SinCos && *kind == CoordinateKind::Angle {
                let (sn, cs) = q[i].sincos();
                add(i, g[k] * cs - g[k + 1] * sn);
                k += 2;
            } else {
                add(i, g[k]);
                k += 1;
            }
        }
        for i in 0..kinds.len() {
            add(kinds.len() + i, g[k + i]);
        }
    }

    /// Inverse of [`Encoding::encode`]: the state whose encoding is `input`
    /// (length [`Encoding::dim`]). With [`Encoding::SinCos`] an angle comes
    /// back as atan2(sin, cos) ∈ (−π, π], i.e. modulo 2π.
    pub fn decode<const N: usize>(self, kinds: &[CoordinateKind; N], input: &[f64]) -> State<N> {
        let mut z = State {
            q: SVector::zeros(),
            v: SVector::zeros(),
        };
        let mut k = 0;
        for (i, kind) in kinds.iter().enumerate() {
            if self == Encoding::SinCos && *kind == CoordinateKind::Angle {
                z.q[i] = input[k].atan2(input[k + 1]);
                k += 2;
            } else {
                z.q[i] = input[k];
                k += 1;
            }
        }
        for i in 0..N {
            z.v[i] = input[k + i];
        }
        z
    }
}

/// The prior of the learned velocity map: what the GPs learn on top of.
///
/// `I` is what an identified prior carries: nothing on a target (the
/// default, [`Infallible`](core::convert::Infallible): an exported model
/// carries its identified parameters in its prior's mechanism and is
/// [`Prior::Nominal`]), the identified parameters and their covariance in
/// the std runtime (`vigp::learned::Prior`, which saves as `"nominal"`,
/// `"constant"` or `{"identified": {…}}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum Prior<I = core::convert::Infallible> {
    /// The nominal variational step v̄(z) (paper eq. 7): the GPs learn
    /// the residual v_{k+1} − v̄(z_k).
    Nominal,
    /// No prior model: the GP means (with their constant mean, the
    /// training targets' mean) are the velocity itself.
    Constant,
    /// The nominal variational step of the mechanism with identified
    /// physical parameters (written into it through its parameters; its
    /// other parameters as given): the GPs learn what the identified model
    /// leaves.
    Identified(I),
}

impl<I> Prior<I> {
    /// Whether the prior is a nominal variational step ([`Prior::Nominal`]
    /// or [`Prior::Identified`]), so that the GP mean is zero.
    pub fn uses_nominal_step(&self) -> bool {
        !matches!(self, Prior::Constant)
    }

    /// The identified parameters of [`Prior::Identified`].
    pub fn identified(&self) -> Option<&I> {
        match self {
            Prior::Identified(p) => Some(p),
            _ => None,
        }
    }
}

/// A learned model as exported data (normally a `static` in a generated
/// file). `N` coordinates, `D` GP inputs: the encoding's dimension plus
/// twice the number of control inputs (previous, then current; once for a
/// model with the GP input (enc(z), u), module docs "Inputs").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedModel<'a, const N: usize, const D: usize> {
    /// The mechanism's name (`Parameters::NAME`).
    pub mechanism: &'a str,
    /// The coordinate names the model was trained on (minimal view).
    pub coordinates: [&'a str; N],
    /// Names of the control inputs the GPs take after the encoded state
    /// (the actuated joints, in declaration order, as
    /// [`Dynamics::INPUT_NAMES`]; the GPs take the previous values, then
    /// the current ones); empty for a model trained without inputs.
    pub inputs: &'a [&'a str],
    /// Every parameter of the nominal model, by name.
    pub parameters: &'a [(&'a str, f64)],
    /// Time step Δt (s).
    pub dt: f64,
    /// GP input encoding.
    pub encoding: Encoding,
    /// Prior of the velocity map.
    pub prior: Prior,
    /// Project predictions onto the loop constraints (mechanisms with
    /// loops).
    pub project: bool,
    /// Options of the nominal step and of the projection's Newton solve.
    pub options: StepOptions,
    /// One GP per velocity component.
    pub gps: &'a [ExportedGp<'a, D>; N],
}

/// Why a learned model does not fit a mechanism, or a learned step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LearnedError {
    /// The model was trained for another mechanism.
    WrongMechanism,
    /// A parameter of the mechanism is missing from the model.
    MissingParameter(&'static str),
    /// The model has a parameter the mechanism does not (index into
    /// [`LearnedModel::parameters`]).
    UnknownParameter(usize),
    /// `D` is neither the encoding's dimension plus twice the model's
    /// inputs nor plus once.
    InputDimension {
        /// The encoding's dimension.
        expected: usize,
        /// `D`.
        got: usize,
    },
    /// The model takes a number of inputs other than the mechanism's
    /// [`Dynamics::INPUTS`] (a model trained with inputs must take all of
    /// them).
    InputCount {
        /// The mechanism's number of inputs.
        expected: usize,
        /// The model's ([`LearnedModel::inputs`]).
        got: usize,
    },
    /// Input `i` of the model ([`LearnedModel::inputs`]) is not the
    /// mechanism's input `i` ([`Dynamics::INPUT_NAMES`]).
    UnknownInput(usize),
    /// A nonzero input given to a model trained without inputs (it knows
    /// only u = 0).
    NoInputs,
    /// Projection asked for a mechanism without loops.
    NothingToProject,
    /// The nominal step or the projection failed.
    Step(StepError),
    /// A GP prediction failed.
    Gp(GpError),
    /// A learned robot's tree engine refused its bodies or failed a step
    /// ([`crate::tree::LearnedTreeStepper`]).
    Engine(crate::tree::EngineError),
    /// A caller-owned buffer of the wrong length
    /// ([`LearnedStepper::rollout_derivatives_into`]).
    BufferLength {
        /// Which buffer.
        name: &'static str,
        /// The length it must have.
        expected: usize,
        /// Its length.
        got: usize,
    },
}

impl From<StepError> for LearnedError {
    fn from(e: StepError) -> Self {
        Self::Step(e)
    }
}

impl From<GpError> for LearnedError {
    fn from(e: GpError) -> Self {
        Self::Gp(e)
    }
}

impl core::fmt::Display for LearnedError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WrongMechanism => f.write_str("the learned model belongs to another mechanism"),
            Self::MissingParameter(p) => {
                write!(f, "parameter {p} is missing from the learned model")
            }
            Self::UnknownParameter(i) => {
                write!(
                    f,
                    "parameter {i} of the learned model is not a parameter of this mechanism"
                )
            }
            Self::InputDimension { expected, got } => write!(
                f,
                "the GPs take {got} inputs, the encoded state and the model's control inputs have {expected}"
            ),
            Self::InputCount { expected, got } => write!(
                f,
                "the learned model takes {got} control inputs, the mechanism has {expected}"
            ),
            Self::UnknownInput(i) => write!(
                f,
                "control input {i} of the learned model is not this mechanism's input {i}"
            ),
            Self::NoInputs => {
                f.write_str("the learned model was trained without inputs: it takes only u = 0")
            }
            Self::NothingToProject => f.write_str("projection asked for a mechanism without loops"),
            Self::Step(e) => write!(f, "step failed: {e}"),
            Self::Gp(e) => write!(f, "GP prediction failed: {e}"),
            Self::Engine(e) => write!(f, "the tree engine: {e}"),
            Self::BufferLength {
                name,
                expected,
                got,
            } => write!(f, "buffer `{name}` holds {got} entries, {expected} needed"),
        }
    }
}

impl core::error::Error for LearnedError {}

/// The learned integrator on fixed-size data: nominal [`Stepper`] prior,
/// encoding, exported GP means, and the projection for loops. No
/// allocation; equal to the std runtime's `Learned` mean step to solver
/// tolerance (tested to 1e-12).
#[derive(Clone, Copy, Debug)]
pub struct LearnedStepper<'a, M: Dynamics<N, C>, const N: usize, const C: usize, const D: usize> {
    stepper: Stepper<M, N, C>,
    learned: &'a LearnedModel<'a, N, D>,
}

impl<'a, M, const N: usize, const C: usize, const D: usize> LearnedStepper<'a, M, N, C, D>
where
    M: Dynamics<N, C> + Parameters,
{
    /// A stepper for `model` (its parameters are set to the learned model's:
    /// they are the prior the GPs were trained on). Checks the mechanism's
    /// name, every parameter name, the control inputs (none, or exactly the
    /// mechanism's, by name and order), the GP input dimension (encoding
    /// plus twice the inputs, or plus once for a model without the
    /// previous input) and the options.
    pub fn new(mut model: M, learned: &'a LearnedModel<'a, N, D>) -> Result<Self, LearnedError> {
        if learned.mechanism != M::NAME {
            return Err(LearnedError::WrongMechanism);
        }
        for (i, name) in M::PARAMETER_NAMES.iter().enumerate() {
            let Some((_, value)) = learned.parameters.iter().find(|(n, _)| n == name) else {
                return Err(LearnedError::MissingParameter(name));
            };
            match model.parameter_mut(i) {
                Some(slot) => *slot = *value,
                None => return Err(LearnedError::MissingParameter(name)),
            }
        }
        if let Some(i) = learned
            .parameters
            .iter()
            .position(|(n, _)| M::parameter_index(n).is_none())
        {
            return Err(LearnedError::UnknownParameter(i));
        }
        if !learned.inputs.is_empty() {
            if learned.inputs.len() != M::INPUTS {
                return Err(LearnedError::InputCount {
                    expected: M::INPUTS,
                    got: learned.inputs.len(),
                });
            }
            if let Some(i) = learned
                .inputs
                .iter()
                .zip(M::INPUT_NAMES)
                .position(|(a, b)| a != b)
            {
                return Err(LearnedError::UnknownInput(i));
            }
        }
        let e = learned.encoding.dim(&M::KINDS);
        let m = learned.inputs.len();
        if D != e + 2 * m && D != e + m {
            return Err(LearnedError::InputDimension {
                expected: e + 2 * m,
                got: D,
            });
        }
        if learned.project && C == 0 {
            return Err(LearnedError::NothingToProject);
        }
        let stepper = Stepper::with_options(model, learned.dt, learned.options)?;
        Ok(Self { stepper, learned })
    }

    /// The nominal stepper (the prior).
    pub fn nominal(&self) -> &Stepper<M, N, C> {
        &self.stepper
    }

    /// The learned model.
    pub fn learned(&self) -> &LearnedModel<'a, N, D> {
        self.learned
    }

    /// Whether the GPs take the previous input, (enc(z), u_prev, u): a
    /// model with inputs whose `D` is the encoding's dimension plus twice
    /// the inputs. `false` without inputs and for a model exported with
    /// the GP input (enc(z), u), whose steps ignore u_prev.
    pub fn takes_previous_input(&self) -> bool {
        !self.learned.inputs.is_empty()
            && D == self.learned.encoding.dim(&M::KINDS) + 2 * self.learned.inputs.len()
    }

    /// The unprojected prediction v_u = v̄(z) + μ(enc(z)) of the next
    /// velocity (for a model with inputs: under u = 0).
    pub fn predict_velocity(&self, z: &State<N>) -> Result<SVector<f64, N>, LearnedError> {
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None }.into());
        }
        // (an exported model's identified parameters are in its mechanism)
        let prior = if self.learned.prior.uses_nominal_step() {
            self.stepper.step(z)?.v
        } else {
            SVector::zeros()
        };
        self.add_gp_mean(z, &[], &[], prior)
    }

    /// The unprojected prediction v_u = v̄(z, u) + μ(enc(z), u_prev, u) of
    /// the next velocity under inputs `u` after `u_prev`, the input that
    /// produced z's velocity (module docs, "Inputs"). `U` must equal
    /// [`Dynamics::INPUTS`], or be 0 for no input (then this is
    /// [`predict_velocity`](Self::predict_velocity)): the bound
    /// `M: Inputs<U>`, with a `const` assertion as a backstop against an
    /// `Inputs` implementation that contradicts [`Dynamics::INPUTS`].
    pub fn predict_velocity_forced<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> Result<SVector<f64, N>, LearnedError>
    where
        M: crate::Inputs<U>,
    {
        Self::check_call(z, u_prev, u)?;
        if U == 0 {
            // no input: u = 0, as `Stepper::step_forced` takes it
            return self.predict_velocity(z);
        }
        if self.learned.inputs.is_empty() {
            return if u.iter().all(|x| *x == 0.0) {
                self.predict_velocity(z)
            } else {
                Err(LearnedError::NoInputs)
            };
        }
        // (an exported model's identified parameters are in its mechanism)
        let prior = if self.learned.prior.uses_nominal_step() {
            self.stepper.step_forced(z, u)?.v
        } else {
            SVector::zeros()
        };
        self.add_gp_mean(z, u_prev.as_slice(), u.as_slice(), prior)
    }

    /// The checks of a forced call: `U` is the mechanism's input count or
    /// 0 (at compile time: the bound `M: Inputs<U>`, with a `const`
    /// assertion as a backstop against an `Inputs` implementation that
    /// contradicts [`Dynamics::INPUTS`]), the state and inputs finite.
    fn check_call<const U: usize>(
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> Result<(), LearnedError>
    where
        M: crate::Inputs<U>,
    {
        const { crate::dynamics::check_input_count(U, M::INPUTS) };
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None }.into());
        }
        if !u.iter().chain(u_prev.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteInput { step: None }.into());
        }
        Ok(())
    }

    /// v + μ(enc(z), u_prev, u): the GP input is the encoded state
    /// followed by `u_prev` (when the model takes it) and `u` (zeros where
    /// they are empty).
    fn add_gp_mean(
        &self,
        z: &State<N>,
        u_prev: &[f64],
        u: &[f64],
        mut v: SVector<f64, N>,
    ) -> Result<SVector<f64, N>, LearnedError> {
        let (x, _) = self.gp_input(z, u_prev, u);
        for (vi, gp) in v.iter_mut().zip(self.learned.gps.iter()) {
            *vi += gp.predict_mean(&x)?;
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err(GpError::NonFiniteOutput.into());
        }
        Ok(v)
    }

    /// The GP input (enc(z), then `u_prev` when the model takes it, then
    /// `u`; zeros where they are empty) and the encoding's dimension, where
    /// the inputs start.
    fn gp_input(&self, z: &State<N>, u_prev: &[f64], u: &[f64]) -> ([f64; D], usize) {
        let mut x = [0.0f64; D];
        let m = self.learned.inputs.len();
        let previous = self.takes_previous_input();
        // `new` checked D = encoding dimension + 2·inputs (or + inputs)
        let e = D.saturating_sub(if previous { 2 * m } else { m });
        let (state, inputs) = x.split_at_mut(e);
        self.learned.encoding.encode(&M::KINDS, z, state);
        let (before, current) = inputs.split_at_mut(if previous { m } else { 0 });
        for (xi, ui) in before.iter_mut().zip(u_prev) {
            *xi = *ui;
        }
        for (xi, ui) in current.iter_mut().zip(u) {
            *xi = *ui;
        }
        (x, e)
    }

    /// One learned step (that of [`step_forced`](Self::step_forced), bit
    /// for bit) with its exact derivatives: A = ∂z₁/∂z₀, B = ∂z₁/∂u and
    /// B_prev = ∂z₁/∂u_prev. They are the nominal step's
    /// ([`Stepper::step_with_derivatives`]; zero under a constant prior),
    /// plus the GP means' gradient ([`ExportedGp::predict_mean_gradient`])
    /// through the encoding, then for loops the projection differentiated
    /// through its KKT conditions ([`VelocityDerivatives::project`]). `U`
    /// as for `step_forced` (0: the step under u = 0, A alone; a model
    /// trained without inputs takes only U = 0 here,
    /// [`LearnedError::NoInputs`] otherwise). The same
    /// arithmetic as the std runtime's `Learned::step_derivatives_forced`
    /// on the model this one was exported from. No allocation: the
    /// nominal solver's workspace and N gradients of D numbers on the
    /// stack.
    #[allow(clippy::type_complexity)]
    pub fn step_derivatives<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> Result<(State<N>, StepDerivatives<N, U>, InputJacobian<N, U>), LearnedError>
    where
        M: crate::Inputs<U>,
    {
        Self::check_call(z, u_prev, u)?;
        let m = self.learned.inputs.len();
        if U > 0 && m == 0 {
            // no derivative in an input the model does not take
            return Err(LearnedError::NoInputs);
        }
        let (mut v, mut d) = if self.learned.prior.uses_nominal_step() {
            let (z1, d) = self.stepper.step_with_derivatives(z, u)?;
            (z1.v, VelocityDerivatives::of_step(&d))
        } else {
            (SVector::zeros(), VelocityDerivatives::zeros())
        };
        // U = 0: the GP input's input tail stays zero
        let (x, e) = self.gp_input(z, u_prev.as_slice(), u.as_slice());
        let mut grads = [[0.0f64; D]; N];
        for ((vi, gp), g) in v.iter_mut().zip(self.learned.gps.iter()).zip(&mut grads) {
            let (mean, grad) = gp.predict_mean_gradient(&x)?;
            *vi += mean;
            *g = grad;
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err(GpError::NonFiniteOutput.into());
        }
        // where u_prev and u sit in the GP input (U = 0: no input columns)
        let previous = self.takes_previous_input();
        let at_u = if previous { e + m } else { e };
        d.add_gp_gradient(
            self.learned.encoding,
            &M::KINDS,
            &z.q,
            previous.then_some(e),
            at_u,
            |j| &grads[j][..],
        );
        let h = self.learned.dt;
        let x1 = z.q + z.v * h;
        if self.learned.project && C > 0 {
            let k = self.stepper.constants();
            let vp = project_velocity(self.stepper.model(), k, &x1, &v, h, &self.learned.options)?;
            d.project(self.stepper.model(), k, &x1, &v, &vp, h)?;
            v = vp;
        }
        Ok(d.into_step(z, v, h))
    }

    /// The learned rollout of [`rollout_forced_into`](Self::rollout_forced_into)
    /// (step k under `inputs[k]` after `inputs[k − 1]`, the first after
    /// `u_prev`; K = `inputs.len()` steps) with the exact derivatives of
    /// every state with respect to z_0 and to every planned input, into
    /// caller-owned buffers: what a shooting MPC over the learned model
    /// needs on the target. Each step is
    /// [`step_derivatives`](Self::step_derivatives) (its state bit for bit
    /// that of `step_forced`), chained by [`chain_step`]: u_j reaches
    /// z_{j+1} through B_j and z_{j+2} through B_prev,(j+1). Buffers of
    /// the wrong length are [`LearnedError::BufferLength`], before any
    /// step; a failing step returns its index with the error. No
    /// allocation. Cost: K derivative steps plus K²/2 products of
    /// N × N by N × U blocks.
    pub fn rollout_derivatives_into<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        out: RolloutDerivativeBuffers<'_, N, U>,
    ) -> Result<(), (usize, LearnedError)>
    where
        M: crate::Inputs<U>,
    {
        chain_rollout(
            z0,
            u_prev,
            inputs,
            out,
            |z, up, u| self.step_derivatives(z, up, u),
            buffer_length,
        )
    }

    /// x₁ = x₀ + Δt·v₀ and the velocity `vu`, projected for loops.
    fn finish(&self, z: &State<N>, vu: SVector<f64, N>) -> Result<State<N>, LearnedError> {
        let x1 = z.q + z.v * self.learned.dt;
        let v = if self.learned.project && C > 0 {
            project_velocity(
                self.stepper.model(),
                self.stepper.constants(),
                &x1,
                &vu,
                self.learned.dt,
                &self.learned.options,
            )?
        } else {
            vu
        };
        Ok(State { q: x1, v })
    }

    /// One learned step from `z` (for a model with inputs: under u = 0,
    /// [`step_forced`](Self::step_forced) with zeros).
    pub fn step(&self, z: &State<N>) -> Result<State<N>, LearnedError> {
        let vu = self.predict_velocity(z)?;
        self.finish(z, vu)
    }

    /// One learned step from `z` under inputs `u` (one per actuated joint,
    /// in declaration order; `U` must equal [`Dynamics::INPUTS`], or 0 for
    /// no input, checked when the code is built) after `u_prev`, the input
    /// that produced z's velocity (module docs, "Inputs"): GP input
    /// (enc(z), u_prev, u), nominal prior the forced step
    /// [`Stepper::step_forced`], projection for loops. Equal to the std
    /// runtime's learned forced mean step to solver tolerance. NaN or ±∞
    /// in `u_prev` or `u` is [`StepError::NonFiniteInput { step: None }`]; a model trained
    /// without inputs takes only u = 0 ([`LearnedError::NoInputs`]).
    pub fn step_forced<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
    ) -> Result<State<N>, LearnedError>
    where
        M: crate::Inputs<U>,
    {
        let vu = self.predict_velocity_forced(z, u_prev, u)?;
        self.finish(z, vu)
    }

    /// The states after 1, 2, …, `out.len()` steps from `z0` (an MPC
    /// prediction), into a caller-owned slice: `out[k]` is the state after
    /// k + 1 steps, as in [`Stepper::steps_into`](crate::Stepper::steps_into)
    /// and the std `Integrator::rollout_into` (the nominal
    /// [`Stepper::rollout_into`](crate::Stepper::rollout_into) puts z₀ in
    /// `out[0]`). On failure returns the index of the failing step with the
    /// error.
    pub fn rollout_into(
        &self,
        z0: &State<N>,
        out: &mut [State<N>],
    ) -> Result<(), (usize, LearnedError)> {
        let mut z = *z0;
        for (k, slot) in out.iter_mut().enumerate() {
            z = self.step(&z).map_err(|e| (k, e))?;
            *slot = z;
        }
        Ok(())
    }

    /// The states after 1, 2, …, `out.len()` forced steps from `z0`, step k
    /// under `inputs[k]` after `inputs[k − 1]`, the first after `u_prev`
    /// (the input that produced z₀'s velocity; an MPC prediction along an
    /// input sequence), into a caller-owned slice; each step is
    /// [`step_forced`](Self::step_forced). `inputs` must be at least as
    /// long as `out`: a shorter one fails at step `inputs.len()` with
    /// [`StepError::NonFiniteInput { step: None }`], before any step. On failure returns
    /// the index of the failing step with the error. No allocation.
    pub fn rollout_forced_into<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        out: &mut [State<N>],
    ) -> Result<(), (usize, LearnedError)>
    where
        M: crate::Inputs<U>,
    {
        forced_rollout(z0, u_prev, inputs, out, |z, up, u| {
            self.step_forced(z, up, u)
        })
    }
}

/// The states after 1, 2, …, `out.len()` steps from `z0` of a step that
/// reads the previous input: step k is `step(z_k, u_{k−1}, u_k)`
/// (`u_prev` before the first). `inputs` shorter than `out` fails at step
/// `inputs.len()` with [`StepError::NonFiniteInput`], before any step; a
/// failing step returns its index with the error.
#[inline]
pub(crate) fn forced_rollout<const N: usize, const U: usize>(
    z0: &State<N>,
    u_prev: &SVector<f64, U>,
    inputs: &[SVector<f64, U>],
    out: &mut [State<N>],
    mut step: impl FnMut(
        &State<N>,
        &SVector<f64, U>,
        &SVector<f64, U>,
    ) -> Result<State<N>, LearnedError>,
) -> Result<(), (usize, LearnedError)> {
    if inputs.len() < out.len() {
        return Err((
            inputs.len(),
            StepError::NonFiniteInput { step: None }.into(),
        ));
    }
    let mut z = *z0;
    for (k, (slot, u)) in out.iter_mut().zip(inputs).enumerate() {
        let up = if k == 0 { u_prev } else { &inputs[k - 1] };
        z = step(&z, up, u).map_err(|e| (k, e))?;
        *slot = z;
    }
    Ok(())
}
