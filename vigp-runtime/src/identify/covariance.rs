//! Noise level, covariance and 95 % intervals of the base parameters.
//!
//! The rows are weighted by 1/σ_j² (σ_j per row position within a
//! transition, from the residuals of the prior-free fit with r base
//! parameters: σ_j² = Σ e_i²/(n_j − r·n_j/n)); under independent rows the
//! posterior covariance of the base parameters θ = K·π is
//! (ÃᵀÃ + (K S² Kᵀ)⁻¹)⁻¹ with Ã the weighted (two-stage, with
//! instruments) rows, and the 95 % interval of θ_i is θ̂_i ± 1.96·√Σ_ii.
//!
//! The residuals of neighbouring transitions share samples, so under
//! position noise the rows are not independent (a moving average of order
//! two over transitions). [`position_noise`] models the row errors as
//! ε = J·n, n independent noise of variance σ_q² on every logged
//! coordinate and J the exact dependence of each residual on its three
//! samples ([`super::Regressor::noise_jacobian`]); σ_q² is estimated from
//! the residuals, E(e_i²) = σ_q²·|J_i|² (times (n − r)/n for the fitted
//! parameters), and the estimate θ̂ = H⁻¹(Ŵᵀ D b + P θ₀) with
//! H = ŴᵀŴ + P then has covariance H⁻¹(σ_q² Σ_s g_s g_sᵀ + P)H⁻¹,
//! g_s = Σ_i Ŵ_iᵀ D_i J_{i,s} over the rows i that sample s enters.

use super::estimate::Fit;
use nalgebra::{DMatrix, DVector};

/// σ_q and σ_q² Σ_s g_s g_sᵀ (module docs) of a fit, with `jacs[t]` the
/// noise Jacobian of transition t (rows × 3N) and `first[t]` the global
/// index of its first sample x_{k−1}.
pub fn position_noise(
    fit: &Fit,
    jacs: &[DMatrix<f64>],
    first: &[usize],
    coordinates: usize,
    rank: usize,
) -> (f64, DMatrix<f64>) {
    let n_rows = fit.residuals.len();
    let block = if jacs.is_empty() { 1 } else { jacs[0].nrows() };
    let mut num = 0.0;
    let mut den = 0.0;
    for (t, j) in jacs.iter().enumerate() {
        for a in 0..block {
            let i = t * block + a;
            let w = fit.row_scale[i] * fit.row_scale[i];
            num += w * fit.residuals[i] * fit.residuals[i];
            den += w * j.row(a).norm_squared();
        }
    }
    let dof = (n_rows as f64 - rank as f64).max(1.0) / n_rows as f64;
    let sq2 = if den > 0.0 { num / den / dof } else { 0.0 };
    // g per (sample, coordinate), accumulated over the rows it enters.
    let samples = first.iter().map(|f| f + 3).max().unwrap_or(0);
    let mut g = DMatrix::zeros(rank, samples * coordinates);
    for (t, j) in jacs.iter().enumerate() {
        for a in 0..block {
            let i = t * block + a;
            let wi = fit.fitted_rows.row(i).transpose() * fit.row_scale[i];
            for col in 0..3 * coordinates {
                let v = j[(a, col)];
                if v != 0.0 {
                    let s = (first[t] + col / coordinates) * coordinates + col % coordinates;
                    let mut gc = g.column_mut(s);
                    gc.axpy(v, &wi, 1.0);
                }
            }
        }
    }
    (sq2.sqrt(), &g * g.transpose() * sq2)
}

/// The two-sided 97.5 % quantile of the standard normal distribution.
pub const Z95: f64 = 1.959_963_984_540_054;

/// Half-widths of the 95 % intervals (1.96 standard deviations) of
/// estimates with covariance `cov`.
pub fn half_widths(cov: &DMatrix<f64>) -> Vec<f64> {
    (0..cov.nrows())
        .map(|i| Z95 * cov[(i, i)].max(0.0).sqrt())
        .collect()
}

/// Standard deviations of linear combinations K·π of estimates with
/// covariance `cov`.
pub fn combination_sd(k: &DMatrix<f64>, cov: &DMatrix<f64>) -> DVector<f64> {
    let c = k * cov * k.transpose();
    DVector::from_fn(c.nrows(), |i, _| c[(i, i)].max(0.0).sqrt())
}
