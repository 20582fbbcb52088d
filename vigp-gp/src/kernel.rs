//! The ARD squared-exponential kernel and its hyperparameters.
//!
//! k(x, x') = σ_f² · exp(−½ Σ_j (x_j − x'_j)² / ℓ_j²)
//!
//! plus σ_n² on the diagonal of the training Gram matrix (the noise). The
//! optimiser works on θ = (ln ℓ_1, …, ln ℓ_d, ln σ_f², ln σ_n²): this order is
//! used by every `log_params` slice and gradient in this module tree.

use serde::{Deserialize, Serialize};

use crate::error::GpError;

/// Hyperparameters of one output's GP: ARD length scales ℓ_j, signal
/// variance σ_f² and noise variance σ_n².
///
/// Units depend on where the value comes from: inside a trained
/// [`Gp`](super::Gp) they are in *normalised* units (see
/// [`OutputGp::hyperparameters`](super::OutputGp::hyperparameters));
/// [`OutputGp::hyperparameters_original`](super::OutputGp::hyperparameters_original)
/// converts them to the units of the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    /// One length scale ℓ_j > 0 per input dimension.
    pub length_scales: Vec<f64>,
    /// Signal variance σ_f² > 0 (the prior variance of the latent function).
    pub signal_variance: f64,
    /// Noise variance σ_n² > 0 of the observations.
    pub noise_variance: f64,
}

impl Hyperparameters {
    /// Isotropic hyperparameters: every length scale equal to `length_scale`.
    pub fn isotropic(
        input_dim: usize,
        length_scale: f64,
        signal_variance: f64,
        noise_variance: f64,
    ) -> Self {
        Self {
            length_scales: vec![length_scale; input_dim],
            signal_variance,
            noise_variance,
        }
    }

    /// Number of hyperparameters, d + 2.
    pub fn len(&self) -> usize {
        self.length_scales.len() + 2
    }

    /// Always false: there are at least the two variances.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// θ = (ln ℓ_1, …, ln ℓ_d, ln σ_f², ln σ_n²).
    pub fn to_log(&self) -> Vec<f64> {
        let mut t: Vec<f64> = self.length_scales.iter().map(|l| l.ln()).collect();
        t.push(self.signal_variance.ln());
        t.push(self.noise_variance.ln());
        t
    }

    /// Inverse of [`to_log`](Self::to_log). `log_params` must have length d + 2 ≥ 2.
    pub fn from_log(log_params: &[f64]) -> Result<Self, GpError> {
        if log_params.len() < 3 {
            return Err(GpError::DimensionMismatch {
                what: "log_params (d + 2 with d >= 1)",
                expected: 3,
                got: log_params.len(),
            });
        }
        let d = log_params.len() - 2;
        let hp = Self {
            length_scales: log_params[..d].iter().map(|t| t.exp()).collect(),
            signal_variance: log_params[d].exp(),
            noise_variance: log_params[d + 1].exp(),
        };
        hp.validate(d)?;
        Ok(hp)
    }

    /// Check dimensions and that every value is finite, strictly positive
    /// and a normal f64 (not subnormal).
    pub fn validate(&self, input_dim: usize) -> Result<(), GpError> {
        if self.length_scales.len() != input_dim {
            return Err(GpError::DimensionMismatch {
                what: "length_scales",
                expected: input_dim,
                got: self.length_scales.len(),
            });
        }
        for &l in &self.length_scales {
            check_positive("length scale", l)?;
        }
        check_positive("signal variance", self.signal_variance)?;
        check_positive("noise variance", self.noise_variance)
    }

    /// Kernel value k(a, b) (no noise term), in the units of these hyperparameters.
    pub fn kernel(&self, a: &[f64], b: &[f64]) -> f64 {
        let r2: f64 = a
            .iter()
            .zip(b)
            .zip(&self.length_scales)
            .map(|((x, y), l)| {
                let u = (x - y) / l;
                u * u
            })
            .sum();
        self.signal_variance * (-0.5 * r2).exp()
    }

    /// Lipschitz constant of x ↦ k(x, x') in the Euclidean norm:
    /// L_k = σ_f² · e^{−1/2} / min_j ℓ_j (the maximum of r·e^{−r²/2} is at r = 1).
    pub fn kernel_lipschitz(&self) -> f64 {
        let lmin = self
            .length_scales
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        self.signal_variance * (-0.5f64).exp() / lmin
    }
}

pub(crate) fn check_positive(what: &'static str, value: f64) -> Result<(), GpError> {
    // normal, not only > 0: a subnormal length scale turns the scaled
    // inputs into ∞, a subnormal variance has no precision left
    if value.is_normal() && value > 0.0 {
        Ok(())
    } else {
        Err(GpError::InvalidHyperparameter { what, value })
    }
}

/// Normalised-unit hyperparameters in original units: ℓ_j·s_x,j,
/// σ_f²·s_y², σ_n²·s_y² (`input_scale` s_x, `output_scale` s_y).
pub(crate) fn original_units(
    hp: &Hyperparameters,
    input_scale: &[f64],
    output_scale: f64,
) -> Hyperparameters {
    let s2 = output_scale * output_scale;
    Hyperparameters {
        length_scales: hp
            .length_scales
            .iter()
            .zip(input_scale)
            .map(|(l, s)| l * s)
            .collect(),
        signal_variance: hp.signal_variance * s2,
        noise_variance: hp.noise_variance * s2,
    }
}
