//! A rigorous frequentist bound under an RKHS-norm assumption: Fiedler,
//! Scherer & Trimpe (AAAI 2021, Thm 1), which refines Chowdhury & Gopalan
//! (ICML 2017, Thm 2) and Abbasi-Yadkori (2013) to any regularisation λ.
//!
//! Assumptions (per output, in the GP's normalised units):
//! * the true residual map f lies in the RKHS H_k of the fitted kernel k
//!   with ‖f‖_k ≤ B;
//! * the observation noise is conditionally R-sub-Gaussian (a martingale
//!   difference sequence; i.i.d. Gaussian noise of standard deviation R
//!   qualifies).
//!
//! Then, with μ and σ computed with regularisation λ (our GP: λ = σ_n² +
//! jitter), with probability ≥ 1 − δ, for all inputs x (no domain):
//!
//! ```text
//! |f(x) − μ(x)| ≤ β·σ(x),   β = B + (R/√λ)·√(ln det(λ̄/λ·K + λ̄·I) − 2·ln δ),   λ̄ = max(1, λ)
//! ```
//!
//! The RKHS norm is the same in original and normalised units (scaling the
//! kernel by s_y² scales the norm of s_y·f back by 1/s_y), so B is unit
//! free; R is in the units of the velocity.

use super::{BoundError, NoiseBound, NormBound, RkhsSettings, check_delta};
use crate::gp::Gp;
use serde::{Deserialize, Serialize};

/// The parts of one output's RKHS bound (normalised units unless stated).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RkhsOutput {
    /// ‖μ‖_k = √(αᵀKα): the RKHS norm of the fitted posterior mean.
    pub mean_norm: f64,
    /// B: the assumed bound on ‖f‖_k.
    pub norm_bound: f64,
    /// R: the sub-Gaussian constant of the noise (normalised units).
    pub noise_bound: f64,
    /// λ = σ_n² + jitter, the regularisation of μ and σ.
    pub regularisation: f64,
    /// ln det(λ̄/λ·K + λ̄·I), twice the information gain for λ ≤ 1.
    pub log_det: f64,
    /// β = B + (R/√λ)·√(ln det(…) − 2 ln(δ/p)): the σ-multiplier of this
    /// output (before the projection's L).
    pub beta: f64,
}

pub(super) fn compute(gp: &Gp, settings: &RkhsSettings) -> Result<Vec<RkhsOutput>, BoundError> {
    check_delta(settings.delta)?;
    let (n, p) = (gp.n(), gp.output_dim());
    let check_vec = |what: &'static str, v: &[f64]| -> Result<(), BoundError> {
        if v.len() != p {
            return Err(BoundError::WrongLength {
                what,
                expected: p,
                got: v.len(),
            });
        }
        match v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
            Some(bad) => Err(BoundError::InvalidSetting { what, value: *bad }),
            None => Ok(()),
        }
    };
    match &settings.norm_bound {
        NormBound::MeanTimes(c) => {
            if !(c.is_finite() && *c > 0.0) {
                return Err(BoundError::InvalidSetting {
                    what: "norm_bound factor (must be finite and > 0)",
                    value: *c,
                });
            }
        }
        NormBound::Given(v) => check_vec("norm_bound (finite, >= 0, one per output)", v)?,
    }
    if let NoiseBound::Given(v) = &settings.noise {
        check_vec("noise bound R (finite, >= 0, one per output)", v)?;
    }
    let ln_delta_i = (settings.delta / p as f64).ln();
    let mut out = Vec::with_capacity(p);
    for (i, o) in gp.outputs().iter().enumerate() {
        let lambda = o.regularisation_normalised();
        let alpha = o.alpha_normalised();
        let r = o.residual_normalised();
        // αᵀKα = αᵀ(K + λI)α − λ‖α‖² = αᵀr − λ‖α‖²
        let ar: f64 = alpha.iter().zip(r).map(|(a, y)| a * y).sum();
        let aa: f64 = alpha.iter().map(|a| a * a).sum();
        let mean_norm = (ar - lambda * aa).max(0.0).sqrt();
        let norm_bound = match &settings.norm_bound {
            NormBound::MeanTimes(c) => c * mean_norm,
            NormBound::Given(v) => v[i],
        };
        let noise_bound = match &settings.noise {
            NoiseBound::Fitted => o.hyperparameters().noise_variance.sqrt(),
            NoiseBound::Given(v) => v[i] / o.output_scale(),
        };
        let lbar = lambda.max(1.0);
        let log_det = n as f64 * (lbar / lambda).ln() + o.log_det_normalised()?;
        let beta =
            norm_bound + noise_bound / lambda.sqrt() * (log_det.max(0.0) - 2.0 * ln_delta_i).sqrt();
        for (what, value) in [
            ("RKHS mean norm", mean_norm),
            ("RKHS log det", log_det),
            ("RKHS beta", beta),
        ] {
            if !value.is_finite() {
                return Err(BoundError::NonFinite { what, value });
            }
        }
        out.push(RkhsOutput {
            mean_norm,
            norm_bound,
            noise_bound,
            regularisation: lambda,
            log_det,
            beta,
        });
    }
    Ok(out)
}
