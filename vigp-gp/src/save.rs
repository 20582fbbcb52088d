//! Save and load trained models (serde).

use serde::{Deserialize, Serialize};

use crate::error::GpError;
use crate::kernel::Hyperparameters;
use crate::mean::{MeanFn, Resolved};
use crate::model::{Gp, check_dims, check_finite};
use crate::normalise::InputNormaliser;
use crate::train::Prepared;

/// Format version written by [`Gp::to_saved`]: 2 added the inducing
/// points of sparse GPs; version 1 files (exact GPs) still load.
const VERSION: u32 = 2;

/// Relative tolerance when checking that a re-attached mean function
/// reproduces its saved values at the training inputs: the function is
/// deterministic, so only JSON round-trip (exact for f64 in serde_json) or
/// a different build's floating-point contraction can differ.
const MEAN_TOL: f64 = 1e-9;

/// The serde form of a trained [`Gp`]: data, normalisation, prior mean,
/// hyperparameters and (sparse GPs) inducing points. The factors are not
/// stored; loading recomputes them (O(N³), or O(N·M²) for a sparse GP) with
/// the saved jitter as the first rung of the ladder.
///
/// A function prior mean cannot be serialised: its values at the training
/// inputs are stored instead, and [`Gp::from_saved`] must be given the
/// function again (it checks that it reproduces those values).
///
/// For a bit-identical round trip through JSON, enable serde_json's
/// `float_roundtrip` feature (its default parser may change the last bit of
/// an f64, which moves predictions of a nearly noise-free model by more).
///
/// ```
/// use vigp_gp::{Gp, PriorMean, SavedGp, TrainOptions};
/// let x = [0.0, 0.5, 1.0, 1.5];
/// let y = [0.1, 0.4, 0.8, 1.6];
/// let nominal = |x: &[f64], m: &mut [f64]| m[0] = x[0];
/// let opts = TrainOptions { mean: PriorMean::function(nominal), ..Default::default() };
/// let (gp, _) = Gp::train(&x, 1, &y, 1, &opts)?;
/// let saved: SavedGp = gp.to_saved();              // serialise with serde_json, bincode, …
/// let back = Gp::from_saved(&saved, Some(PriorMean::function(nominal)))?;
/// assert_eq!(back.predict(&[0.7])?, gp.predict(&[0.7])?);
/// # Ok::<(), vigp_gp::GpError>(())
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedGp {
    /// Format version (currently 2; 1 is read too).
    pub version: u32,
    /// Input dimension d.
    pub input_dim: usize,
    /// Output dimension p.
    pub output_dim: usize,
    /// Training inputs, row-major N × d, original units.
    pub inputs: Vec<f64>,
    /// Training targets, row-major N × p, original units.
    pub targets: Vec<f64>,
    /// Input standardisation.
    pub input_normaliser: InputNormaliser,
    /// The prior mean.
    pub mean: SavedMean,
    /// Per output: hyperparameters (normalised), output scale s_y and jitter.
    pub outputs: Vec<SavedOutput>,
    /// Inducing inputs of a sparse GP (normalised units, row-major M × d);
    /// `None` for an exact GP (and in version 1 files).
    #[serde(default)]
    pub inducing_normalised: Option<Vec<f64>>,
}

/// The prior mean of a saved model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SavedMean {
    /// m = 0.
    Zero,
    /// m = these constants (one per output).
    Constant(Vec<f64>),
    /// A user function, whose values at the training inputs (row-major N × p)
    /// are recorded so that a re-attached function can be checked.
    Function(Vec<f64>),
}

/// One output of a saved model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedOutput {
    /// Hyperparameters in normalised units.
    pub hyperparameters: Hyperparameters,
    /// Output scale s_y.
    pub output_scale: f64,
    /// Jitter (normalised units) that the trained model needed.
    pub jitter: f64,
}

fn bad(msg: impl Into<String>) -> GpError {
    GpError::InvalidModel(msg.into())
}

impl Gp {
    /// The serialisable form of this model.
    pub fn to_saved(&self) -> SavedGp {
        SavedGp {
            version: VERSION,
            input_dim: self.d,
            output_dim: self.p,
            inputs: self.inputs.clone(),
            targets: self.targets.clone(),
            input_normaliser: self.input_norm.clone(),
            mean: match &self.mean {
                Resolved::Zero => SavedMean::Zero,
                Resolved::Constant(c) => SavedMean::Constant(c.clone()),
                Resolved::Function(_) => SavedMean::Function(self.prior_at_inputs.clone()),
            },
            outputs: self
                .outputs
                .iter()
                .map(|o| SavedOutput {
                    hyperparameters: o.hp.clone(),
                    output_scale: o.output_scale,
                    jitter: o.jitter,
                })
                .collect(),
            inducing_normalised: self.inducing.clone(),
        }
    }

    /// Rebuilds a model from its saved form, validating every dimension and
    /// value. `mean` must be `Some(PriorMean::Function(f))` exactly when the
    /// model was trained with a function mean (pass the same function: its
    /// values at the training inputs are checked to 1e-9 relative); for zero
    /// and constant means pass `None`.
    pub fn from_saved(saved: &SavedGp, mean: Option<super::PriorMean>) -> Result<Self, GpError> {
        if saved.version != VERSION && saved.version != 1 {
            return Err(bad(format!("unsupported version {}", saved.version)));
        }
        let (d, p) = (saved.input_dim, saved.output_dim);
        let n = check_dims(&saved.inputs, d, &saved.targets, p)?;
        let norm = &saved.input_normaliser;
        if norm.shift.len() != d || norm.scale.len() != d {
            return Err(bad("input normaliser has the wrong dimension"));
        }
        check_finite("input normaliser", &norm.shift)?;
        check_finite("input normaliser", &norm.scale)?;
        if norm.scale.iter().any(|s| *s <= 0.0) {
            return Err(bad("input normaliser scale must be positive"));
        }
        if saved.outputs.len() != p {
            return Err(bad("number of saved outputs differs from output_dim"));
        }
        if let Some(z) = &saved.inducing_normalised {
            if saved.version < 2 {
                return Err(bad("inducing points need format version 2"));
            }
            if z.is_empty() || z.len() % d != 0 || z.len() / d > n {
                return Err(bad("inducing points: need 1..=N rows of d numbers"));
            }
            check_finite("inducing points", z)?;
        }
        let sparse = saved.inducing_normalised.is_some();
        for o in &saved.outputs {
            o.hyperparameters.validate(d)?;
            if !(o.output_scale.is_finite() && o.output_scale > 0.0) {
                return Err(bad("output scale must be positive and finite"));
            }
            if !(o.jitter.is_finite() && o.jitter >= 0.0) {
                return Err(bad("jitter must be finite and non-negative"));
            }
            let h = &o.hyperparameters;
            let diag = h.signal_variance + h.noise_variance;
            // Training never adds more than the jitter ladder's maximum; a
            // larger value would silently turn the model into its prior.
            let max = if sparse {
                super::sparse::KUU_JITTER_MAX * h.signal_variance
            } else {
                super::likelihood::JITTER_MAX * diag
            };
            if o.jitter > max * (1.0 + 1e-9) {
                return Err(bad(format!(
                    "jitter {:e} exceeds the largest jitter training adds ({:e} of σ_f² + σ_n²)",
                    o.jitter,
                    super::likelihood::JITTER_MAX
                )));
            }
        }
        let resolved = match (&saved.mean, mean) {
            (SavedMean::Zero, None) => Resolved::Zero,
            (SavedMean::Constant(c), None) => {
                if c.len() != p {
                    return Err(bad("constant mean has the wrong length"));
                }
                check_finite("constant mean", c)?;
                Resolved::Constant(c.clone())
            }
            (SavedMean::Function(_), None) => {
                return Err(GpError::PriorMean(
                    "model was trained with a function mean: pass it to from_saved".into(),
                ));
            }
            (SavedMean::Function(_), Some(super::PriorMean::Function(f))) => {
                Resolved::Function(f as MeanFn)
            }
            (_, Some(_)) => {
                return Err(GpError::PriorMean(
                    "a prior mean was given, but the saved model has no function mean".into(),
                ));
            }
        };
        let mut prior = vec![0.0; n * p];
        for (o, x) in prior.chunks_exact_mut(p).zip(saved.inputs.chunks_exact(d)) {
            resolved.eval(x, o);
        }
        check_finite("prior mean at the training inputs", &prior)?;
        if let SavedMean::Function(vals) = &saved.mean {
            if vals.len() != n * p {
                return Err(bad("saved function-mean values have the wrong length"));
            }
            for (a, b) in vals.iter().zip(&prior) {
                if (a - b).abs() > MEAN_TOL * a.abs().max(b.abs()).max(1.0) {
                    return Err(GpError::PriorMean(format!(
                        "the given mean function does not reproduce the saved values ({a} vs {b})"
                    )));
                }
            }
        }
        let mut xn = vec![0.0; n * d];
        for (o, x) in xn.chunks_exact_mut(d).zip(saved.inputs.chunks_exact(d)) {
            norm.apply(x, o);
        }
        let residuals = (0..p)
            .map(|j| {
                let s = saved.outputs[j].output_scale;
                let r: Vec<f64> = (0..n)
                    .map(|i| (saved.targets[i * p + j] - prior[i * p + j]) / s)
                    .collect();
                check_finite("residual y - m(x)", &r)?;
                Ok((r, s))
            })
            .collect::<Result<Vec<_>, GpError>>()?;
        let prep = Prepared {
            n,
            d,
            p,
            xn,
            norm: norm.clone(),
            mean: resolved,
            prior,
            residuals,
        };
        let hps: Vec<Hyperparameters> = saved
            .outputs
            .iter()
            .map(|o| o.hyperparameters.clone())
            .collect();
        // exact: absolute jitter; sparse: relative K_uu jitter ε = jitter/σ_f²
        let jit: Vec<f64> = saved
            .outputs
            .iter()
            .map(|o| {
                if sparse {
                    o.jitter / o.hyperparameters.signal_variance
                } else {
                    o.jitter
                }
            })
            .collect();
        Gp::from_prepared(
            &saved.inputs,
            &saved.targets,
            prep,
            &hps,
            Some(&jit),
            saved.inducing_normalised.clone(),
        )
    }
}
