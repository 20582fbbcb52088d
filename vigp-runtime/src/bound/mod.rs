//! Error bounds of the learned integrators: three kinds behind one entry
//! point, [`Learned::error_bound`], whose result [`Learned::predict`] uses
//! so that every predicted state carries its bound.
//!
//! | kind | guarantee | assumptions | needs |
//! |---|---|---|---|
//! | [`BoundKind::Theorem1`] | w.p. ≥ 1 − δ, for all states whose GP input lies in a box X | the true velocity map is a sample of the fitted GP prior; the projection is L-Lipschitz (L estimated) | the trained model |
//! | [`BoundKind::Rkhs`] | w.p. ≥ 1 − δ, for all states | the true map lies in the fitted kernel's RKHS with norm ≤ B; sub-Gaussian noise | the trained model and a norm bound B |
//! | [`BoundKind::Conformal`] | P(error ≤ bound) ≥ 1 − δ for a new case exchangeable with the calibration cases | exchangeability only | held-out windows ([`Calibration`]) |
//!
//! * **Theorem 1** is the paper's bound (Brüdigam et al. 2022), built on the
//!   uniform error bound of Lederer, Umlauft & Hirche (NeurIPS 2019,
//!   Thm 3.1): per velocity component i (union bound, δ_i = δ/p)
//!   |f_i − μ_i| ≤ √β_i·σ_i + γ_i on X, and ‖v − v_true‖ ≤ L·Σ_i(√β_i σ_i + γ_i)
//!   with L the projection's Lipschitz constant (1 without constraints).
//!   τ is chosen to minimise the bound at the median σ of sample states
//!   ([`Tau::Optimise`]); σ's modulus of continuity is the feature-space
//!   one, σ_f·τ/ℓ_min, which does not depend on the noise
//!   ([`SigmaModulus`]); see [`Theorem1Settings`].
//! * **RKHS** (Fiedler, Scherer & Trimpe, AAAI 2021):
//!   |f_i − μ_i| ≤ β_i·σ_i for all inputs, β_i = B_i + (R_i/√λ_i)·√(ln det(…) − 2 ln δ_i),
//!   combined as ‖v − v_true‖ ≤ L·‖(β_i σ_i)_i‖₂; see [`RkhsSettings`].
//! * **Conformal** (split conformal prediction): the one-step velocity error
//!   normalised by the GP's predictive standard deviation, and the k-step
//!   position error directly, on held-out windows; see
//!   [`ConformalSettings`].
//!
//! Inputs: for a model trained with inputs ([`Learned::train_forced`]) the
//! GP input is the encoded state followed by the previous and the current
//! input, and the rigorous kinds bound the forced step the same way:
//! [`Learned::error_bound_forced`] estimates the constants at the training
//! inputs (states with their logged inputs), and
//! [`Learned::predict_forced`] predicts under planned inputs, after the
//! input that produced the start's velocity, with a bound at every state
//! (Theorem 1's box X includes the inputs' range). The conformal kind
//! calibrates on windows that carry their inputs and previous input
//! ([`Calibration::from_trajectories_forced`]).
//!
//! Multi-step: the conformal kind calibrates the k-step position error
//! itself. The rigorous kinds bound one step; over several steps
//! [`Learned::predict`] propagates them with the learned step's local
//! Jacobian norms at the predicted states ([`Learned::step_jacobian_norms`],
//! exact derivatives) (P_{k+1} = P_k + Δt·V_k,
//! V_{k+1} = ‖∂v′/∂q‖·P_k + ‖∂v′/∂v‖·V_k + b_k): a first-order estimate, not
//! part of the theorems.
//!
//! The derivations, the choice of τ, of the Lipschitz constants and of the
//! norm bound, and measured coverage and tightness are in `docs/bounds.md`.

pub(crate) mod conformal;
mod jacobian;
mod rkhs;
pub mod space;
mod uniform;
pub(crate) mod windows;

pub use conformal::{Calibration, ConformalParts, Region, Window};
pub use jacobian::projection_jacobian;
pub use rkhs::RkhsOutput;
pub use space::{BoundSpace, Planned};
pub use uniform::Theorem1Output;
pub use windows::{CalibrationOf, CalibrationWindow};

use crate::gp::{GpError, Workspace};
use crate::integrator::Integrator;
use crate::learned::{LearnError, Learned};
use crate::mechanism::{Mechanism, State};
use crate::newton::StepError;
use crate::variational::Variational;
use conformal::{position_scales, predictive_scale, score_scale};
use core::fmt;
use nalgebra::SVector;
use serde::{Deserialize, Serialize};

/// Why a bound could not be computed or used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BoundError {
    /// The identified parameters of an identified prior do not fit the
    /// mechanism.
    #[error("identified prior: {0}")]
    Identified(crate::learned::IdentifiedError),
    /// A setting is out of its domain (NaN, ∞, negative, δ ∉ (0, 1), …).
    #[error("invalid bound setting {what}: {value}")]
    InvalidSetting {
        /// Which setting, with its domain.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A setting or an input has the wrong number of values (one per GP
    /// output, per window or per trajectory: `what` says which).
    #[error("{what}: expected {expected} values, got {got}")]
    WrongLength {
        /// Which setting, with what its values count.
        what: &'static str,
        /// The number expected.
        expected: usize,
        /// The number given.
        got: usize,
    },
    /// Required data is missing.
    #[error("empty {0}")]
    Empty(&'static str),
    /// Too few calibration cases for δ: the conformal quantile would be
    /// infinite.
    #[error(
        "too few calibration windows for delta = {delta:e}: need at least {}, got {got}",
        windows(*needed)
    )]
    TooFewCalibration {
        /// The δ asked for.
        delta: f64,
        /// The least number of windows, ⌈1/δ − 1⌉ (`usize::MAX` when that
        /// does not fit).
        needed: usize,
        /// The number given.
        got: usize,
    },
    /// Calibration windows that start at training states: the conformal
    /// guarantee needs held-out data, and windows from the training runs
    /// score the model where it was fitted (coverage falls below 1 − δ).
    #[error(
        "{overlapping} of {total} calibration windows start at a training state (the first: window {first}): \
         calibrate on runs held out from training"
    )]
    CalibrationOverlapsTraining {
        /// Windows whose start is a training state.
        overlapping: usize,
        /// Windows in all.
        total: usize,
        /// The first such window.
        first: usize,
    },
    /// A calibration window is unusable.
    #[error("calibration window {index}: {reason}")]
    Calibration {
        /// Index of the window.
        index: usize,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A constant of the bound came out NaN or infinite.
    #[error("the bound's {what} is not finite ({value})")]
    NonFinite {
        /// Which constant.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// A variance-based bound (Theorem 1, RKHS) at a predicted state whose
    /// GP posterior variance came out 0: with a noise variance tiny against
    /// σ_f² (nearly noise-free data) σ_f² − kᵀ(K + σ_n²I)⁻¹k is lost to
    /// rounding, and the bound would be 0 (or its γ term alone) whatever
    /// the true error. A conformal bound, or a larger lower bound on the
    /// noise variance when training, gives a usable bound.
    #[error(
        "the GP variance of output {output} at step {step} was lost to rounding (0): \
         a variance-based bound would be 0; use a conformal bound or a larger noise lower bound \
         (TrainOptions::bounds, `vigp fit --noise-floor`)"
    )]
    VarianceLost {
        /// The GP output.
        output: usize,
        /// The step of the prediction (0 = from the start state).
        step: usize,
    },
    /// A conformal bound is asked for more steps than it was calibrated for.
    #[error(
        "prediction of {requested} steps, but the conformal bound was calibrated on windows of {calibrated}"
    )]
    HorizonTooLong {
        /// The calibration horizon K.
        calibrated: usize,
        /// The steps asked for.
        requested: usize,
    },
    /// A Theorem-1 or RKHS bound asked of a sparse GP (trained with
    /// [`Method::Sparse`](crate::gp::Method::Sparse)): both bound the
    /// distance to the *exact* posterior mean with the exact posterior
    /// variance, which a sparse model does not have. The conformal bound,
    /// calibrated on held-out runs, makes no such assumption.
    #[error(
        "the {kind} bound assumes the exact GP posterior, and this model is a sparse GP: \
         use the conformal bound (held-out calibration runs)"
    )]
    SparseModel {
        /// `"Theorem-1"` or `"RKHS"`.
        kind: &'static str,
    },
    /// The bound was computed for another model (output count or Δt), or
    /// the inputs do not fit the model.
    #[error("bound and model do not match: {0}")]
    Mismatch(&'static str),
    /// A bound was asked under a number of inputs other than the one the
    /// model was trained with (0: trained without inputs).
    #[error("the model was trained with {trained} inputs, and was given {given}")]
    Inputs {
        /// Inputs of the training data.
        trained: usize,
        /// Inputs given.
        given: usize,
    },
    /// A kind of bound this configuration space does not have (bodies in
    /// ℝ³ × SO(3) take the conformal kind only).
    #[error("no {kind} bound for {space}: use the conformal kind")]
    KindUnavailable {
        /// The kind asked for ([`BoundKind::name`]).
        kind: &'static str,
        /// The configuration space.
        space: &'static str,
    },
    /// A step, projection or nominal prior failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// The GP failed.
    #[error(transparent)]
    Gp(#[from] GpError),
    /// A learned robot's step failed ([`crate::learned::robot`]).
    #[error(transparent)]
    LearnedRobot(#[from] Box<crate::learned::robot::LearnedRobotError>),
}

/// A window count for messages: `usize::MAX` stands for "more than any
/// count" (⌈1/δ − 1⌉ saturates for δ near 0).
fn windows(n: usize) -> String {
    if n == usize::MAX {
        format!("{:e} (delta is far too small)", n as f64)
    } else {
        n.to_string()
    }
}

impl From<LearnError> for BoundError {
    fn from(e: LearnError) -> Self {
        match e {
            LearnError::Gp(g) => BoundError::Gp(g),
            LearnError::Step(s) => BoundError::Step(s),
            LearnError::Empty => BoundError::Empty("training data"),
            LearnError::InvalidSetting { what, value } => {
                BoundError::InvalidSetting { what, value }
            }
            LearnError::NonFinite(_) => BoundError::NonFinite {
                what: "training transition",
                value: f64::NAN,
            },
            LearnError::DtContradictsData { given, .. } => BoundError::InvalidSetting {
                what: "dt (contradicts the training transitions)",
                value: given,
            },
            LearnError::Identified(e) => BoundError::Identified(e),
            LearnError::NotUnit { norm, .. } => BoundError::NonFinite {
                what: "training quaternion norm (must be 1)",
                value: norm,
            },
            LearnError::IdentifiedPrior => BoundError::Mismatch(
                "an identified prior is not taken by a Lie-group stepper: train with Prior::Nominal on the identified mechanism",
            ),
            LearnError::Inputs { trained, given } => BoundError::Inputs { trained, given },
        }
    }
}

pub(crate) fn check_delta(delta: f64) -> Result<(), BoundError> {
    if delta > 0.0 && delta < 1.0 {
        Ok(())
    } else {
        Err(BoundError::InvalidSetting {
            what: "delta (must be in (0, 1))",
            value: delta,
        })
    }
}

/// How Theorem 1's grid constant τ is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Tau {
    /// Per output, the τ that minimises √β(τ)·σ̃ + γ(τ) at the median
    /// posterior standard deviation σ̃ of the sample states (a grid of 0.01
    /// decades from 1e-40). Any fixed τ > 0 gives a valid bound; this picks
    /// one from the model and the sample states only, never from errors.
    Optimise,
    /// τ = this value times the largest edge of the box X (normalised
    /// units); finite and > 0.
    Relative(f64),
}

/// The modulus of continuity ω_σ of the posterior standard deviation in
/// Theorem 1.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum SigmaModulus {
    /// ω_σ(τ) = σ_f·τ/ℓ_min: σ(x) = ‖A^{1/2}φ(x)‖ with 0 ⪯ A ⪯ I in the
    /// feature space, so |σ(x) − σ(x′)| ≤ ‖φ(x) − φ(x′)‖ =
    /// √(2σ_f²(1 − e^{−r²/2})) ≤ σ_f·r. Independent of the noise, so the
    /// bound stays finite when the fitted noise reaches its lower limit.
    FeatureSpace,
    /// Lederer et al. (2019): ω_σ(τ) = √(2τ·L_k·(1 + N·‖(K + σ_n²I)⁻¹‖·σ_f²)),
    /// which grows like 1/σ_n: as in the paper, and much wider with tiny noise.
    Lederer2019,
}

/// The Lipschitz constant L_f of the true velocity map in Theorem 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum LipschitzF {
    /// L_f = L_μ, the posterior mean's bound (an estimate: the true map is
    /// unknown). With the optimised τ the term (L_μ + L_f)·τ is small, so
    /// the choice matters little; the report shows it.
    FromMean,
    /// One constant per GP output (velocity component), in velocity units
    /// per unit of the GP's encoded input; finite and ≥ 0.
    Given(Vec<f64>),
}

/// Settings of the paper's Theorem-1 bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Theorem1Settings {
    /// Failure probability δ ∈ (0, 1) of the whole bound (union over
    /// outputs). Default 0.05.
    pub delta: f64,
    /// Choice of τ. Default [`Tau::Optimise`].
    pub tau: Tau,
    /// Modulus of continuity of σ. Default [`SigmaModulus::FeatureSpace`].
    pub sigma_modulus: SigmaModulus,
    /// Lipschitz constant of the true map. Default [`LipschitzF::FromMean`].
    pub lipschitz_f: LipschitzF,
    /// The box X: the training inputs' box widened on each side by this
    /// fraction of its edge (finite, ≥ 0). Default 0.5. β grows only with
    /// the logarithm of X's size; states outside X are flagged in
    /// [`BoundedPrediction::outside`].
    pub domain_margin: f64,
}

impl Default for Theorem1Settings {
    fn default() -> Self {
        Self {
            delta: 0.05,
            tau: Tau::Optimise,
            sigma_modulus: SigmaModulus::FeatureSpace,
            lipschitz_f: LipschitzF::FromMean,
            domain_margin: 0.5,
        }
    }
}

/// The RKHS-norm bound B of the RKHS kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum NormBound {
    /// B_i = factor·‖μ_i‖_k (finite, > 0): a heuristic. The fitted mean's
    /// norm is what the data show of f; for noise-free data it is a lower
    /// bound on ‖f‖_k (the minimum-norm interpolant), so the factor must be
    /// ≥ 1 and buys room for what the data do not show.
    MeanTimes(f64),
    /// One bound per GP output, finite and ≥ 0 (the RKHS norm is unit free).
    Given(Vec<f64>),
}

/// The sub-Gaussian constant R of the noise in the RKHS kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum NoiseBound {
    /// R_i = the fitted noise standard deviation σ_n,i (Gaussian noise of
    /// standard deviation σ is σ-sub-Gaussian).
    Fitted,
    /// One R per GP output, in velocity units, finite and ≥ 0.
    Given(Vec<f64>),
}

/// Settings of the RKHS bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RkhsSettings {
    /// Failure probability δ ∈ (0, 1) (union over outputs). Default 0.05.
    pub delta: f64,
    /// Norm bound B. Default `MeanTimes(2.0)`.
    pub norm_bound: NormBound,
    /// Noise constant R. Default [`NoiseBound::Fitted`].
    pub noise: NoiseBound,
}

impl Default for RkhsSettings {
    fn default() -> Self {
        Self {
            delta: 0.05,
            norm_bound: NormBound::MeanTimes(2.0),
            noise: NoiseBound::Fitted,
        }
    }
}

/// The normalisation of conformal scores: the one-step error is divided by
/// a scale ũ of the start, the k-step position error by
/// u_k = Δt·Σ_{j<k} Σ_{i≤j} ũ_i along the prediction. Any choice keeps the
/// coverage guarantee; it decides where the bound is wide.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Score {
    /// ũ = the GP's predictive standard deviation √(Σ σ_i² + σ_n,i²), for
    /// a noisy observation: the bound widens where the GP is unsure.
    GpStd,
    /// ũ = the latent standard deviation √(Σ σ_i²) (floored at 1e-6 of the
    /// noise): for noise-free targets (simulated data), where the noise
    /// floor of [`Score::GpStd`] blurs the normalisation.
    LatentStd,
    /// ũ = 1: one constant bound per horizon (u_k = Δt·k(k+1)/2).
    Absolute,
    /// Choose among the three on the first fifth of the calibration windows
    /// (the one whose bounds are narrowest there, geometric mean of the
    /// one-step and K-step widths) and calibrate the choice on the other
    /// four fifths: the choice does not see the windows that calibrate it,
    /// so the guarantee holds. Falls back to [`Score::GpStd`] on all
    /// windows when either part is too small for δ.
    Auto,
}

/// How the k-step position quantiles are calibrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tube {
    /// One quantile per horizon k: each step's bound covers with
    /// probability ≥ 1 − δ.
    PerStep,
    /// One quantile of max_k(score_k): the whole tube covers all K steps at
    /// once with probability ≥ 1 − δ (wider).
    Simultaneous,
}

/// What the conformal bound does outside its calibrated [`Region`]: for a
/// state whose GP input lies outside the box of the calibration starts'
/// inputs, or farther (in the GP's normalised inputs) from every
/// calibration start than 99 % of the calibration starts are from their
/// nearest one of another run, or whose predictive standard deviation
/// exceeds every calibration start's. Such a case is unlike the
/// calibration cases, and the conformal guarantee does not apply to it. (A
/// heuristic detector: about 1 % of cases drawn like the calibration
/// starts are flagged by the distance test, about 2d/(n + 1) by the box.)
///
/// With a fallback, a flagged state's one-step bound is the larger of the
/// conformal and the fallback bound, and when the *start* z₀ is flagged the
/// position bounds of the whole prediction are too (the k-step calibration
/// is about windows from the calibration starts' distribution).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Fallback {
    /// Keep the conformal bound and only flag the states
    /// ([`BoundedPrediction::outside`]).
    None,
    /// Flag, and fall back to the RKHS bound (default settings, same δ),
    /// whose guarantee covers every input. (Where the GP variance is lost
    /// to rounding — a model trained on noise-free data, σ_n² at its floor
    /// — the RKHS bound would be 0: such a flagged state keeps its
    /// conformal bound and its flag, as with [`Fallback::None`]. A sparse
    /// GP has no RKHS or Theorem-1 bound, [`BoundError::SparseModel`]: its
    /// flagged states keep their conformal bound whatever the setting.)
    Rkhs,
    /// Flag, and fall back to the Theorem-1 bound (default settings, same δ).
    Theorem1,
}

/// Settings of the conformal bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConformalSettings {
    /// Miscoverage δ ∈ (0, 1). Needs at least ⌈1/δ − 1⌉ calibration
    /// windows. Default 0.05.
    pub delta: f64,
    /// Score normalisation. Default [`Score::Auto`].
    pub score: Score,
    /// Per-step or simultaneous tube. Default [`Tube::PerStep`].
    pub tube: Tube,
    /// Outside the calibrated region. Default [`Fallback::Rkhs`].
    pub fallback: Fallback,
}

impl Default for ConformalSettings {
    fn default() -> Self {
        Self {
            delta: 0.05,
            score: Score::Auto,
            tube: Tube::PerStep,
            fallback: Fallback::Rkhs,
        }
    }
}

/// Which bound to compute, with its settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum BoundKind {
    /// The paper's Theorem 1 (Lederer et al. 2019 per output, union bound,
    /// projection Lipschitz constant).
    Theorem1(Theorem1Settings),
    /// The RKHS-norm bound of Fiedler, Scherer & Trimpe (2021).
    Rkhs(RkhsSettings),
    /// Split conformal prediction on held-out windows.
    Conformal(ConformalSettings),
}

impl BoundKind {
    /// Theorem 1 with default settings and this δ.
    pub fn theorem1(delta: f64) -> Self {
        Self::Theorem1(Theorem1Settings {
            delta,
            ..Theorem1Settings::default()
        })
    }

    /// The RKHS bound with default settings and this δ.
    pub fn rkhs(delta: f64) -> Self {
        Self::Rkhs(RkhsSettings {
            delta,
            ..RkhsSettings::default()
        })
    }

    /// The conformal bound with default settings and this δ.
    pub fn conformal(delta: f64) -> Self {
        Self::Conformal(ConformalSettings {
            delta,
            ..ConformalSettings::default()
        })
    }

    /// `"theorem1"`, `"rkhs"` or `"conformal"` (as [`ErrorBound::kind_name`]).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Theorem1(_) => "theorem1",
            Self::Rkhs(_) => "rkhs",
            Self::Conformal(_) => "conformal",
        }
    }

    /// The δ of the settings.
    pub fn delta(&self) -> f64 {
        match self {
            Self::Theorem1(s) => s.delta,
            Self::Rkhs(s) => s.delta,
            Self::Conformal(s) => s.delta,
        }
    }
}

/// The constants of each kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum BoundParts {
    /// Theorem 1: per output, and the box X.
    Theorem1 {
        /// Per output.
        outputs: Vec<Theorem1Output>,
        /// Lower corner of X in the GP's encoded inputs (original units).
        domain_lower: Vec<f64>,
        /// Upper corner of X.
        domain_upper: Vec<f64>,
        /// The modulus of continuity used.
        sigma_modulus: SigmaModulus,
    },
    /// RKHS: per output.
    Rkhs {
        /// Per output.
        outputs: Vec<RkhsOutput>,
    },
    /// Conformal: the calibrated quantiles.
    Conformal(ConformalParts),
}

/// A computed bound: its constants, and what [`Learned::predict`] needs to
/// attach a bound to every predicted state. Made by
/// [`Learned::error_bound`]; serialisable with the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorBound {
    /// δ.
    pub delta: f64,
    /// Lipschitz constant L of the projection (1 without constraints and for
    /// the conformal kind, which needs none): the largest spectral norm of
    /// its Jacobian at the sample states.
    pub projection_lipschitz: f64,
    /// The kind's constants.
    pub parts: BoundParts,
    /// Sample states L and τ were estimated at.
    pub samples: usize,
    /// The rigorous bound a conformal bound falls back to outside its
    /// calibrated region ([`Fallback`]).
    pub fallback: Option<Box<ErrorBound>>,
    outputs: usize,
    dt: f64,
    /// Per output √(σ_n² + jitter) in velocity units: the noise floor of the
    /// conformal score's scale.
    noise_std: Vec<f64>,
}

impl ErrorBound {
    /// A conformal bound without a fallback (a learned robot's).
    pub(crate) fn conformal_alone(
        delta: f64,
        parts: ConformalParts,
        outputs: usize,
        dt: f64,
        noise_std: Vec<f64>,
    ) -> Self {
        ErrorBound {
            delta,
            projection_lipschitz: 1.0,
            parts: BoundParts::Conformal(parts),
            samples: 0,
            fallback: None,
            outputs,
            dt,
            noise_std,
        }
    }

    /// Number of GP outputs the bound was made for.
    pub fn outputs(&self) -> usize {
        self.outputs
    }

    /// The time step of the model the bound was made for.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Per output √(σ_n² + jitter) of the model, in velocity units.
    pub(crate) fn noise(&self) -> &[f64] {
        &self.noise_std
    }

    /// `"theorem1"`, `"rkhs"` or `"conformal"`.
    pub fn kind_name(&self) -> &'static str {
        match self.parts {
            BoundParts::Theorem1 { .. } => "theorem1",
            BoundParts::Rkhs { .. } => "rkhs",
            BoundParts::Conformal(_) => "conformal",
        }
    }

    /// The most steps [`Learned::predict`] may take with this bound: the
    /// calibration horizon for the conformal kind, `None` (no limit) for the
    /// rigorous kinds.
    pub fn horizon(&self) -> Option<usize> {
        match &self.parts {
            BoundParts::Conformal(c) => Some(c.position_quantiles.len()),
            _ => None,
        }
    }

    /// The σ-multiplier of each output: the factor of σ_i(z) in the bound
    /// (L·√β_i for Theorem 1, L·β_i for RKHS, q̂ for conformal, which
    /// multiplies the predictive standard deviation).
    pub fn sigma_multipliers(&self) -> Vec<f64> {
        let l = self.projection_lipschitz;
        match &self.parts {
            BoundParts::Theorem1 { outputs, .. } => {
                outputs.iter().map(|o| l * o.beta.sqrt()).collect()
            }
            BoundParts::Rkhs { outputs } => outputs.iter().map(|o| l * o.beta).collect(),
            BoundParts::Conformal(c) => vec![c.one_step_quantile; self.outputs],
        }
    }

    /// The one-step bound on ‖v_{k+1} − v_true‖ at a state whose GP
    /// posterior standard deviations (velocity units, one per output) are
    /// `std_dev`. Errors: wrong length, or a NaN, ∞ or negative entry.
    pub fn one_step(&self, std_dev: &[f64]) -> Result<f64, BoundError> {
        if std_dev.len() != self.outputs {
            return Err(BoundError::WrongLength {
                what: "std_dev (one per GP output)",
                expected: self.outputs,
                got: std_dev.len(),
            });
        }
        if let Some(bad) = std_dev.iter().find(|s| !(s.is_finite() && **s >= 0.0)) {
            return Err(BoundError::InvalidSetting {
                what: "std_dev (must be finite and >= 0)",
                value: *bad,
            });
        }
        let l = self.projection_lipschitz;
        let b = match &self.parts {
            BoundParts::Theorem1 { outputs, .. } => {
                l * std_dev
                    .iter()
                    .zip(outputs)
                    .map(|(s, o)| o.beta.sqrt() * s + o.gamma)
                    .sum::<f64>()
            }
            BoundParts::Rkhs { outputs } => {
                // ‖(β_i σ_i)‖₂, scaled by the largest term against overflow
                let terms = std_dev.iter().zip(outputs).map(|(s, o)| o.beta * s);
                let m = terms.clone().fold(0.0f64, f64::max);
                if m > 0.0 {
                    l * m * terms.map(|t| (t / m) * (t / m)).sum::<f64>().sqrt()
                } else {
                    0.0
                }
            }
            BoundParts::Conformal(c) => {
                c.one_step_quantile * score_scale(c.score, std_dev, &self.noise_std)
            }
        };
        if b.is_finite() && b >= 0.0 {
            Ok(b)
        } else {
            Err(BoundError::NonFinite {
                what: "one-step bound",
                value: b,
            })
        }
    }

    /// Whether a state with GP input `input` (`input_n` normalised) and
    /// predictive scale `scale` lies outside what the bound covers: outside
    /// the box X (Theorem 1); for the conformal kind, outside the box of the
    /// calibration starts, farther from every calibration start than their
    /// nearest-neighbour threshold, or beyond their largest scale. Never for
    /// the RKHS kind.
    fn outside(&self, input: &[f64], input_n: &[f64], scale: f64) -> bool {
        match &self.parts {
            BoundParts::Theorem1 {
                domain_lower,
                domain_upper,
                ..
            } => input
                .iter()
                .zip(domain_lower.iter().zip(domain_upper))
                .any(|(x, (lo, hi))| x < lo || x > hi),
            BoundParts::Rkhs { .. } => false,
            BoundParts::Conformal(c) => c.region.outside(input, input_n, scale),
        }
    }
}

impl fmt::Display for ErrorBound {
    /// A human-readable report of the bound's parts.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} bound, delta = {}, projection Lipschitz L = {:.4} ({} sample states)",
            self.kind_name(),
            self.delta,
            self.projection_lipschitz,
            self.samples
        )?;
        match &self.parts {
            BoundParts::Theorem1 {
                outputs,
                sigma_modulus,
                ..
            } => {
                writeln!(
                    f,
                    "  |f_i - mu_i| <= sqrt(beta_i) sigma_i + gamma_i on X; omega_sigma: {sigma_modulus:?}; L_mu, L_f, L_sigma, tau in normalised units"
                )?;
                writeln!(
                    f,
                    "  output      beta    gamma        L_mu         L_f     L_sigma        tau  sigma-multiplier L*sqrt(beta)"
                )?;
                for (i, o) in outputs.iter().enumerate() {
                    writeln!(
                        f,
                        "  {i:>6} {:>9.2} {:>8.2e} {:>11.3e} {:>11.3e} {:>11.3e} {:>10.2e} {:>10.2}",
                        o.beta,
                        o.gamma,
                        o.lipschitz_mean,
                        o.lipschitz_f,
                        o.lipschitz_sigma,
                        o.tau,
                        self.projection_lipschitz * o.beta.sqrt()
                    )?;
                }
            }
            BoundParts::Rkhs { outputs } => {
                writeln!(
                    f,
                    "  |f_i - mu_i| <= beta_i sigma_i for all inputs, beta_i = B_i + R_i/sqrt(lambda_i) sqrt(ln det - 2 ln(delta/p))"
                )?;
                writeln!(
                    f,
                    "  output   ||mu||_k        B          R     lambda     ln det     beta  sigma-multiplier L*beta"
                )?;
                for (i, o) in outputs.iter().enumerate() {
                    writeln!(
                        f,
                        "  {i:>6} {:>10.3e} {:>8.3e} {:>10.3e} {:>10.3e} {:>10.2} {:>8.2} {:>10.2}",
                        o.mean_norm,
                        o.norm_bound,
                        o.noise_bound,
                        o.regularisation,
                        o.log_det,
                        o.beta,
                        self.projection_lipschitz * o.beta
                    )?;
                }
            }
            BoundParts::Conformal(c) => {
                writeln!(
                    f,
                    "  {} calibration windows ({} failed), score {:?}{}, tube {:?}",
                    c.calibration_size,
                    c.failed,
                    c.score,
                    if c.selection_size > 0 {
                        format!(" (chosen on {} more windows)", c.selection_size)
                    } else {
                        String::new()
                    },
                    c.tube
                )?;
                writeln!(
                    f,
                    "  one-step quantile {:.4}; position quantiles k = 1..{}: {:.3?}",
                    c.one_step_quantile,
                    c.position_quantiles.len(),
                    c.position_quantiles
                )?;
                match &self.fallback {
                    Some(b) => write!(
                        f,
                        "  outside the calibrated region it falls back to the {b}"
                    )?,
                    None => writeln!(f, "  outside the calibrated region: flagged only")?,
                }
            }
        }
        Ok(())
    }
}

/// A multi-step prediction in which every state carries its bound.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundedPrediction<const N: usize> {
    /// z_0, z_1, …, z_K.
    pub states: Vec<State<N>>,
    /// K values: for each step k, the bound on ‖v_{k+1} − v_true(z_k)‖, the
    /// error of the velocity predicted from z_k (holds with probability
    /// ≥ 1 − δ; for conformal, marginally).
    pub one_step_bounds: Vec<f64>,
    /// K + 1 values: the bound on ‖q_k − q_true,k‖, the position error at
    /// step k of the prediction against the true trajectory from z_0 (0 at
    /// k = 0). Conformal: calibrated directly; rigorous kinds: propagated
    /// (see the module docs).
    pub position_bounds: Vec<f64>,
    /// K values: the GP posterior standard deviations σ(z_k).
    pub std_devs: Vec<SVector<f64, N>>,
    /// K values: the size of each projection correction.
    pub corrections: Vec<f64>,
    /// K values: `true` where z_k lies outside what the bound covers
    /// (Theorem 1: its GP input is outside the box X; conformal: its GP
    /// input is outside the box of, or far from, the calibration starts, or
    /// its predictive standard deviation exceeds theirs: see [`Fallback`]).
    pub outside: Vec<bool>,
    /// `true` when a conformal bound left its calibrated region and some
    /// bounds are the larger of it and its [`Fallback`] (see there). The
    /// region is that of the calibration *starts*, and a prediction's later
    /// states often leave it even for an ordinary case (88 % of 10-step
    /// predictions in one check): this says a bound is the conservative
    /// fallback, not that the case is unusual; `outside[0]` is the test
    /// of the start.
    pub fell_back: bool,
}

/// Minimal coordinates in ℝⁿ: all three kinds ([`BoundKind`]; module
/// docs), one entry point for them.
///
/// `error_bound`: `calibration` holds held-out windows, required by the
/// conformal kind; the rigorous kinds also estimate L and pick τ at its
/// start states (besides the training states) and accept
/// [`Calibration::empty`]. Cost: the rigorous kinds predict σ and the
/// projection's Jacobian at up to 2·256 sample states (plus an O(N³)
/// eigenvalue problem per output for [`SigmaModulus::Lederer2019`]); the
/// conformal kind predicts every calibration window with variances (n·K
/// learned steps). Errors: invalid settings (NaN, ∞, negative, δ ∉ (0, 1),
/// wrong lengths), too few or malformed calibration windows, calibration
/// data with another Δt, a failed projection or prior step at a sample
/// state, a constant that comes out non-finite, or a rigorous kind asked of
/// a sparse GP ([`BoundError::SparseModel`]: a sparse model takes the
/// conformal kind, without a fallback). A model trained with inputs is
/// sampled under u = 0 by `error_bound`; the conformal kind on calibration
/// windows that carry inputs is a [`BoundError::Mismatch`] there.
///
/// `error_bound_forced`: the conformal kind predicts each calibration
/// window under its inputs (windows from
/// [`Calibration::from_trajectories_forced`] or [`Calibration::new_forced`]);
/// the GP inputs of its region test are the starts' with their first step's
/// input. The rigorous kinds estimate the projection's Lipschitz constant
/// and pick τ at the training inputs and the calibration starts, each state
/// with its input; Theorem 1's box X spans the GP inputs, the inputs' range
/// included. `U` other than the model's inputs (inputs for a model trained
/// without them, or none for one trained with them) is a
/// [`BoundError::Mismatch`].
///
/// `predict`: every state carries its bound, the one-step velocity bound of
/// each step and the position bound of each state ([`BoundedPrediction`]).
/// Cost: `steps` learned steps with variances, plus, for the rigorous kinds
/// (and a conformal bound that falls back), one mean step with its exact
/// gradient per step for the local Jacobian that propagates the bound
/// ([`Learned::step_jacobian_norms`]). A model trained with inputs predicts
/// under u = 0 there (as [`Learned::step_mean_in`]).
///
/// `predict_forced`: step k from the predicted z_k under `inputs[k]` (held
/// over [t_{k+1}, t_{k+2}], the interval of the velocity the step predicts,
/// as in [`crate::learned::ForcedTransition::u`]). The one-step bounds are
/// those of the GP at (z_k, u_{k−1}, u_k), and the rigorous kinds propagate
/// them to positions with the forced step's Jacobian norms there
/// ([`Learned::step_jacobian_norms_forced`]). Several bounds on one
/// prediction: [`Learned::predict_bounds`], [`Learned::predict_bounds_forced`].
impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> BoundSpace<N>
    for Variational<M, N, C>
{
    type Window = Window<N>;
    type Bound = ErrorBound;
    type Prediction = BoundedPrediction<N>;

    fn check_forced(learned: &Learned<M, N, C>, inputs: usize) -> Result<(), BoundError> {
        learned.check_forced_inputs(inputs)
    }

    fn error_bound<const U: usize>(
        learned: &Learned<M, N, C>,
        kind: &BoundKind,
        calibration: &Calibration<N>,
    ) -> Result<ErrorBound, BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        learned.error_bound_at::<U>(kind, calibration)
    }

    fn predict<const U: usize>(
        learned: &Learned<M, N, C>,
        z0: &State<N>,
        run: Planned<'_, U>,
        bound: &ErrorBound,
    ) -> Result<BoundedPrediction<N>, BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        let mut all = learned.predict_bounds_at(z0, run.steps, run.u_prev, run.inputs, &[bound])?;
        Ok(all.remove(0))
    }
}

/// States, standard deviations and corrections of a learned prediction,
/// the inputs it was made under (empty: unforced, U = 0) and the input
/// before the first (that produced the start's velocity).
pub(crate) struct Trace<'a, const N: usize, const U: usize> {
    pub states: Vec<State<N>>,
    pub std_devs: Vec<SVector<f64, N>>,
    pub corrections: Vec<f64>,
    pub u_prev: SVector<f64, U>,
    pub inputs: &'a [SVector<f64, U>],
}

impl<const N: usize, const U: usize> Trace<'_, N, U> {
    /// The previous and the current input of step k (None: unforced).
    pub fn step_inputs(&self, k: usize) -> Option<(&SVector<f64, U>, &SVector<f64, U>)> {
        let u = self.inputs.get(k)?;
        Some((
            if k == 0 {
                &self.u_prev
            } else {
                &self.inputs[k - 1]
            },
            u,
        ))
    }
}

/// At most this many training and this many calibration states are used to
/// estimate L and pick τ (evenly strided).
const MAX_SAMPLES: usize = 256;

/// Refuses calibration windows that start at training states: a window
/// start (`starts`: each encoded as the GP's first `e` inputs) that equals
/// a GP training input's state part to 1e-12 relative (run contents, not
/// run names, are compared; held-out runs of a real system never repeat a
/// state to 12 digits, while windows cut from the training runs start
/// exactly at them).
pub(crate) fn check_held_out(
    gp: &crate::gp::Gp,
    e: usize,
    starts: impl Iterator<Item = Vec<f64>>,
) -> Result<(), BoundError> {
    let d = gp.input_dim();
    if e > d || e == 0 {
        return Ok(());
    }
    let train: Vec<&[f64]> = gp.inputs().chunks_exact(d).map(|x| &x[..e]).collect();
    // sort the training states by their first entry to look windows up
    let mut order: Vec<usize> = (0..train.len()).collect();
    order.sort_by(|&a, &b| train[a][0].total_cmp(&train[b][0]));
    let keys: Vec<f64> = order.iter().map(|&i| train[i][0]).collect();
    let (mut overlapping, mut first, mut total) = (0, 0, 0);
    for (wi, buf) in starts.enumerate() {
        total += 1;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()));
        let tol = 1e-12 * (1.0 + buf[0].abs());
        let lo = keys.partition_point(|k| *k < buf[0] - tol);
        let hit = keys[lo..]
            .iter()
            .zip(&order[lo..])
            .take_while(|(k, _)| **k <= buf[0] + tol)
            .any(|(_, &i)| train[i].iter().zip(&buf).all(|(a, b)| close(*a, *b)));
        if hit {
            if overlapping == 0 {
                first = wi;
            }
            overlapping += 1;
        }
    }
    if overlapping > 0 {
        return Err(BoundError::CalibrationOverlapsTraining {
            overlapping,
            total,
            first,
        });
    }
    Ok(())
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// `steps` learned steps with variances from `z0`: unforced when
    /// `U = 0`, else under `inputs` (one per step) after `u_prev`.
    pub(crate) fn trace<'a, const U: usize>(
        &self,
        z0: &State<N>,
        steps: usize,
        u_prev: &SVector<f64, U>,
        inputs: &'a [SVector<f64, U>],
        ws: &mut Workspace,
    ) -> Result<Trace<'a, N, U>, StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        // the count checked before anything is allocated (the rollout's
        // GP input buffer holds steps × d numbers)
        let d = self.gp().input_dim().max(1);
        vigp_core::step::check_step_count::<State<N>>(steps)?;
        if steps
            .checked_mul(d)
            .and_then(|n| n.checked_mul(core::mem::size_of::<f64>()))
            .is_none_or(|bytes| bytes > isize::MAX as usize)
        {
            return Err(StepError::TooManySteps { steps });
        }
        let mut t = Trace {
            states: Vec::with_capacity(steps + 1),
            std_devs: Vec::with_capacity(steps),
            corrections: Vec::with_capacity(steps),
            u_prev: *u_prev,
            inputs,
        };
        t.states.push(*z0);
        for (next, info) in self.rollout_info(z0, steps, u_prev, inputs, ws)? {
            t.std_devs.push(info.std_dev);
            t.corrections.push(info.correction);
            t.states.push(next);
        }
        Ok(t)
    }

    /// Per output √(σ_n² + jitter) in velocity units.
    fn noise_std(&self) -> Vec<f64> {
        self.gp().noise_std()
    }

    /// Training states (decoded from the GP inputs) and calibration starts,
    /// each evenly strided to at most [`MAX_SAMPLES`].
    fn sample_states(&self, calibration: &Calibration<N>) -> Vec<State<N>> {
        let gp = self.gp();
        let d = gp.input_dim();
        let stride = gp.n().div_ceil(MAX_SAMPLES).max(1);
        let mut out: Vec<State<N>> = gp
            .inputs()
            .chunks_exact(d)
            .step_by(stride)
            .map(|x| self.encoding().decode(&M::KINDS, x))
            .collect();
        let w = calibration.windows();
        let stride = w.len().div_ceil(MAX_SAMPLES).max(1);
        out.extend(w.iter().step_by(stride).map(|w| w.start));
        out
    }

    /// [`check_held_out`] on the encoded window starts.
    fn check_held_out(&self, calibration: &Calibration<N>) -> Result<(), BoundError> {
        let e = self.encoding().dim(&M::KINDS);
        let starts = calibration.windows().iter().map(|w| {
            let mut buf = vec![0.0; e];
            self.encoding().encode(&M::KINDS, &w.start, &mut buf);
            buf
        });
        check_held_out(self.gp(), e, starts)
    }

    /// Training states with their previous and current inputs (decoded
    /// from the GP inputs; a model without the previous input gets the
    /// current one twice) and the starts of calibration windows that carry
    /// `U` inputs (with their previous and first step's), each evenly
    /// strided to at most [`MAX_SAMPLES`].
    #[allow(clippy::type_complexity)]
    fn sample_forced<const U: usize>(
        &self,
        calibration: &Calibration<N>,
    ) -> Vec<(State<N>, SVector<f64, U>, SVector<f64, U>)>
    where
        M: vigp_core::Inputs<U>,
    {
        let gp = self.gp();
        let d = gp.input_dim();
        let e = self.encoding().dim(&M::KINDS);
        let at_u = if self.takes_previous_input() {
            e + U
        } else {
            e
        };
        let stride = gp.n().div_ceil(MAX_SAMPLES).max(1);
        let mut out: Vec<_> = gp
            .inputs()
            .chunks_exact(d)
            .step_by(stride)
            .map(|x| {
                (
                    self.encoding().decode(&M::KINDS, &x[..e]),
                    SVector::from_column_slice(&x[e..e + U]),
                    SVector::from_column_slice(&x[at_u..at_u + U]),
                )
            })
            .collect();
        let w = calibration.windows();
        let stride = w.len().div_ceil(MAX_SAMPLES).max(1);
        for (i, w) in w.iter().enumerate().step_by(stride) {
            if let Some(us) = calibration.window_inputs::<U>(i) {
                let prev = calibration.window_previous_input(i).unwrap_or(us[0]);
                out.push((w.start, prev, us[0]));
            }
        }
        out
    }

    /// `error_bound` (U = 0: unforced samples) or `error_bound_forced`.
    fn error_bound_at<const U: usize>(
        &self,
        kind: &BoundKind,
        calibration: &Calibration<N>,
    ) -> Result<ErrorBound, BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        let dt = Integrator::dt(self);
        if !calibration.is_empty() && (calibration.dt() - dt).abs() > 1e-12 * dt {
            return Err(BoundError::Mismatch(
                "the calibration windows have another dt than the model",
            ));
        }
        let gp = self.gp();
        let p = gp.output_dim();
        let noise_std = self.noise_std();
        let bound = |parts, projection_lipschitz, samples| ErrorBound {
            delta: kind.delta(),
            projection_lipschitz,
            parts,
            samples,
            fallback: None,
            outputs: p,
            dt,
            noise_std: noise_std.clone(),
        };
        if let BoundKind::Conformal(s) = kind {
            if calibration.is_empty() {
                return Err(BoundError::Empty(
                    "calibration windows (the conformal bound needs held-out data)",
                ));
            }
            if calibration.input_count() != U {
                return Err(BoundError::Mismatch(if U == 0 {
                    "the calibration windows carry inputs: bound predictions under inputs \
                     (error_bound_forced)"
                } else {
                    "the calibration windows carry no inputs (or other inputs): build them \
                     with Calibration::from_trajectories_forced or new_forced"
                }));
            }
            self.check_held_out(calibration)?;
            let parts = conformal::calibrate::<M, N, C, U>(self, s, calibration, &noise_std)?;
            let mut b = bound(BoundParts::Conformal(parts), 1.0, 0);
            let fallback = match s.fallback {
                // No rigorous bound covers a sparse GP: flag only.
                _ if gp.is_sparse() => None,
                Fallback::None => None,
                Fallback::Rkhs => Some(BoundKind::rkhs(s.delta)),
                Fallback::Theorem1 => Some(BoundKind::theorem1(s.delta)),
            };
            if let Some(kind) = fallback {
                b.fallback = Some(Box::new(self.error_bound_at::<U>(&kind, calibration)?));
            }
            return Ok(b);
        }
        check_delta(kind.delta())?;
        if gp.is_sparse() {
            return Err(BoundError::SparseModel {
                kind: match kind {
                    BoundKind::Rkhs(_) => "RKHS",
                    _ => "Theorem-1",
                },
            });
        }
        #[allow(clippy::type_complexity)]
        let samples: Vec<(State<N>, SVector<f64, U>, SVector<f64, U>)> = if U == 0 {
            let zero = SVector::zeros();
            let states = self.sample_states(calibration);
            states.into_iter().map(|z| (z, zero, zero)).collect()
        } else {
            self.sample_forced(calibration)
        };
        let mut ws = self.workspace();
        let mut sigma = vec![Vec::with_capacity(samples.len()); p];
        let mut lip = 1.0f64;
        for (z, u_prev, u) in &samples {
            let (vu, sd) = if U == 0 {
                self.predict_velocity(z, &mut ws)?
            } else {
                self.predict_velocity_forced(z, u_prev, u, &mut ws)?
            };
            for (i, o) in gp.outputs().iter().enumerate() {
                sigma[i].push(sd[i] / o.output_scale());
            }
            if self.projects() && C > 0 {
                let jac = projection_jacobian(self.model(), &(z.q + z.v * dt), &vu, dt)?;
                lip = lip.max(jacobian::spectral_norm(&jac));
            }
        }
        if !lip.is_finite() {
            return Err(BoundError::NonFinite {
                what: "projection Lipschitz constant",
                value: lip,
            });
        }
        let parts = match kind {
            BoundKind::Theorem1(s) => {
                let t = uniform::compute(gp, s, &sigma)?;
                BoundParts::Theorem1 {
                    outputs: t.outputs,
                    domain_lower: t.lower,
                    domain_upper: t.upper,
                    sigma_modulus: s.sigma_modulus,
                }
            }
            BoundKind::Rkhs(s) => BoundParts::Rkhs {
                outputs: rkhs::compute(gp, s)?,
            },
            BoundKind::Conformal(_) => unreachable!("handled above"),
        };
        Ok(bound(parts, lip, samples.len()))
    }

    /// [`Learned::predict_forced`] under several bounds at once, as
    /// [`Learned::predict_bounds`]: result `i` equals
    /// `predict_forced(z0, u_prev, inputs, bounds[i])` bit for bit.
    pub fn predict_bounds_forced<const U: usize>(
        &self,
        z0: &State<N>,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        bounds: &[&ErrorBound],
    ) -> Result<Vec<BoundedPrediction<N>>, BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        self.check_forced_inputs(U)?;
        self.predict_bounds_at(z0, inputs.len(), u_prev, inputs, bounds)
    }

    /// [`Learned::predict`] under several bounds at once (e.g. to compare
    /// kinds on the same prediction): the predicted states and their
    /// variances are computed once, and so is the learned step's Jacobian
    /// at each state, which every rigorous bound (and fallback) shares.
    /// Result `i` equals `predict(z0, steps, bounds[i])` bit for bit.
    ///
    /// Errors: as [`Learned::predict`] for any of the bounds; an empty
    /// list is [`BoundError::Empty`].
    pub fn predict_bounds(
        &self,
        z0: &State<N>,
        steps: usize,
        bounds: &[&ErrorBound],
    ) -> Result<Vec<BoundedPrediction<N>>, BoundError> {
        self.predict_bounds_at::<0>(z0, steps, &SVector::zeros(), &[], bounds)
    }

    /// `predict_bounds` (U = 0: unforced) or `predict_bounds_forced`.
    fn predict_bounds_at<const U: usize>(
        &self,
        z0: &State<N>,
        steps: usize,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        bounds: &[&ErrorBound],
    ) -> Result<Vec<BoundedPrediction<N>>, BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        if bounds.is_empty() {
            return Err(BoundError::Empty("list of bounds"));
        }
        for bound in bounds {
            self.check_bound(bound, steps)?;
            if let BoundParts::Conformal(c) = &bound.parts
                && c.inputs != U
            {
                return Err(BoundError::Mismatch(
                    "the conformal bound was calibrated under other inputs than the \
                     prediction's (error_bound_forced with forced windows bounds \
                     predict_forced)",
                ));
            }
        }
        let mut ws = self.workspace();
        let mut trace = self.trace(z0, steps, u_prev, inputs, &mut ws)?;
        let mut norms = vec![None; trace.states.len()];
        let parts = bounds
            .iter()
            .map(|bound| self.bounded(bound, &trace, &mut norms, &mut ws))
            .collect::<Result<Vec<_>, _>>()?;
        // the trace is cloned for all but the last result, which takes it
        let last = parts.len() - 1;
        Ok(parts
            .into_iter()
            .enumerate()
            .map(
                |(i, (one_step_bounds, position_bounds, outside, fell_back))| {
                    let (states, std_devs, corrections) = if i == last {
                        (
                            core::mem::take(&mut trace.states),
                            core::mem::take(&mut trace.std_devs),
                            core::mem::take(&mut trace.corrections),
                        )
                    } else {
                        (
                            trace.states.clone(),
                            trace.std_devs.clone(),
                            trace.corrections.clone(),
                        )
                    };
                    BoundedPrediction {
                        states,
                        one_step_bounds,
                        position_bounds,
                        std_devs,
                        corrections,
                        outside,
                        fell_back,
                    }
                },
            )
            .collect())
    }

    /// The check of the forced calls that `U` is the model's input count
    /// ([`BoundError::Mismatch`] otherwise).
    fn check_forced_inputs(&self, inputs: usize) -> Result<(), BoundError> {
        if inputs != self.inputs() {
            return Err(BoundError::Mismatch(
                "number of inputs (U must be the model's inputs)",
            ));
        }
        Ok(())
    }

    /// The checks of [`Learned::predict`] on one bound.
    fn check_bound(&self, bound: &ErrorBound, steps: usize) -> Result<(), BoundError> {
        let dt = Integrator::dt(self);
        if bound.outputs != self.gp().output_dim() {
            return Err(BoundError::Mismatch("number of GP outputs"));
        }
        if (bound.dt - dt).abs() > 1e-12 * dt {
            return Err(BoundError::Mismatch("time step dt"));
        }
        if let BoundParts::Theorem1 { domain_lower, .. } = &bound.parts
            && domain_lower.len() != self.gp().input_dim()
        {
            return Err(BoundError::Mismatch("GP input dimension"));
        }
        if let BoundParts::Conformal(c) = &bound.parts {
            c.region.check(self.gp().input_dim())?;
        }
        if let Some(h) = bound.horizon()
            && steps > h
        {
            return Err(BoundError::HorizonTooLong {
                calibrated: h,
                requested: steps,
            });
        }
        Ok(())
    }

    /// One-step bounds, position bounds, outside flags and whether the
    /// fallback was used, for `bound` (and its fallback where the trace
    /// leaves its domain) along `trace`; `norms` caches the step's Jacobian
    /// norms per state.
    #[allow(clippy::type_complexity)]
    fn bounded<const U: usize>(
        &self,
        bound: &ErrorBound,
        trace: &Trace<'_, N, U>,
        norms: &mut [Option<(f64, f64)>],
        ws: &mut Workspace,
    ) -> Result<(Vec<f64>, Vec<f64>, Vec<bool>, bool), BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        let (mut one_step, mut position, outside, _) =
            self.attach(bound, trace, norms, ws, true, false)?;
        let mut fell_back = false;
        if let Some(fb) = &bound.fallback
            && outside.iter().any(|o| *o)
        {
            // the fallback's position bounds (which cost a Jacobian per
            // step) only when the start itself is outside
            let start_outside = outside.first().copied().unwrap_or(false);
            // lenient: a state whose variance is lost to rounding has no
            // fallback bound (it would be 0); it keeps its conformal bound
            // and its flag
            let (one, pos, _, lost) = self.attach(fb, trace, norms, ws, start_outside, true)?;
            for (((a, b), o), l) in one_step.iter_mut().zip(one).zip(&outside).zip(&lost) {
                if *o && !*l {
                    *a = a.max(b);
                    fell_back = true;
                }
            }
            if start_outside && !lost.iter().any(|l| *l) {
                for (a, b) in position.iter_mut().zip(pos) {
                    *a = a.max(b);
                }
                fell_back = true;
            }
        }
        Ok((one_step, position, outside, fell_back))
    }

    /// One-step bounds, position bounds (only the initial 0 unless
    /// `positions`), outside flags of `bound` along a predicted trace, and
    /// the states where a variance-based bound's variance was lost to
    /// rounding (an error unless `lenient`; with `lenient` the one-step
    /// bounds there are meaningless, and the position bounds are not
    /// propagated when any state lost its variance).
    #[allow(clippy::type_complexity)]
    fn attach<const U: usize>(
        &self,
        bound: &ErrorBound,
        trace: &Trace<'_, N, U>,
        norms: &mut [Option<(f64, f64)>],
        ws: &mut Workspace,
        positions: bool,
        lenient: bool,
    ) -> Result<(Vec<f64>, Vec<f64>, Vec<bool>, Vec<bool>), BoundError>
    where
        M: vigp_core::Inputs<U>,
    {
        let dt = Integrator::dt(self);
        let steps = trace.std_devs.len();
        let mut input = vec![0.0; self.gp().input_dim()];
        let mut input_n = input.clone();
        let mut one_step = Vec::with_capacity(steps);
        let mut outside = Vec::with_capacity(steps);
        let mut scales = Vec::with_capacity(steps);
        let variance_based = matches!(
            bound.parts,
            BoundParts::Theorem1 { .. } | BoundParts::Rkhs { .. }
        );
        let mut lost = Vec::with_capacity(steps);
        for (step, (z, sd)) in trace.states.iter().zip(&trace.std_devs).enumerate() {
            let zero = sd.iter().position(|s| *s == 0.0);
            if variance_based
                && !lenient
                && let Some(output) = zero
            {
                return Err(BoundError::VarianceLost { output, step });
            }
            lost.push(variance_based && zero.is_some());
            one_step.push(bound.one_step(sd.as_slice())?);
            let s = predictive_scale(sd.as_slice(), &bound.noise_std);
            // the GP input: the encoded state, then the step's previous and
            // current inputs (a model with inputs predicting unforced keeps
            // them 0)
            match trace.step_inputs(step) {
                Some((up, u)) => self.gp_input_into(z, up.as_slice(), u.as_slice(), &mut input),
                None => self.gp_input_into(z, &[], &[], &mut input),
            }
            self.gp().input_normaliser().apply(&input, &mut input_n);
            outside.push(bound.outside(&input, &input_n, s));
            if let BoundParts::Conformal(c) = &bound.parts {
                scales.push(score_scale(c.score, sd.as_slice(), &bound.noise_std));
            }
        }
        let mut position = Vec::with_capacity(steps + 1);
        position.push(0.0);
        // (a lost variance leaves nothing to propagate: the caller drops
        // these position bounds, so their Jacobians are not formed)
        let positions = positions && !lost.iter().any(|l| *l);
        match &bound.parts {
            _ if !positions => {}
            BoundParts::Conformal(c) => {
                let u = position_scales(&scales, dt);
                for (q, u) in c.position_quantiles.iter().zip(u) {
                    position.push(q * u);
                }
            }
            _ => {
                let (mut pk, mut vk) = (0.0f64, 0.0f64);
                for (k, b) in one_step.iter().enumerate() {
                    let (a, c) = if k > 0 && k + 1 < steps {
                        match norms[k] {
                            Some(n) => n,
                            None => {
                                // the step's inputs (0 for an unforced trace)
                                let (up, u) = trace
                                    .step_inputs(k)
                                    .map_or((SVector::zeros(), SVector::zeros()), |(a, b)| {
                                        (*a, *b)
                                    });
                                let n =
                                    self.step_jacobian_norms_at(&trace.states[k], &up, &u, ws)?;
                                norms[k] = Some(n);
                                n
                            }
                        }
                    } else {
                        (0.0, 0.0)
                    };
                    let p_next = pk + dt * vk;
                    vk = a * pk + c * vk + b;
                    pk = p_next;
                    position.push(pk);
                }
            }
        }
        if let Some(bad) = position.iter().find(|b| !(b.is_finite() && **b >= 0.0)) {
            return Err(BoundError::NonFinite {
                what: "position bound",
                value: *bad,
            });
        }
        Ok((one_step, position, outside, lost))
    }
}
