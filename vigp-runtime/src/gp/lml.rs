//! Gram matrix, Cholesky with jitter escalation, log marginal likelihood and
//! its analytic gradient.
//!
//! Cost per evaluation: O(N²d) to build K, N³/3 flops for the Cholesky and
//! (gradient only) about 2N³/3 more for (K+σ²I)⁻¹, plus O(N²d) for the
//! gradient contractions. Memory: three N×N matrices.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Mat, Par};

use super::error::GpError;
use super::kernel::Hyperparameters;

/// Jitter ladder: first try relative jitter `JITTER_START` (times the
/// diagonal σ_f² + σ_n²), multiply by 10 until `JITTER_MAX`.
const JITTER_START: f64 = 1e-12;
const JITTER_MAX: f64 = 1e-3;

/// A factorised training Gram matrix A = K + (σ_n² + jitter)·I = L·Lᵀ.
pub(crate) struct Factor {
    /// Lower-triangular Cholesky factor (upper part is garbage, never read).
    pub l: Mat<f64>,
    /// Absolute jitter added to the diagonal (0 if none was needed).
    pub jitter: f64,
    /// The noise-free kernel matrix K_f (lower triangle), kept for gradients.
    pub kf: Option<Mat<f64>>,
}

/// x scaled by the length scales: xs[i, j] = x[i, j] / ℓ_j (row-major).
pub(crate) fn scale_inputs(x: &[f64], d: usize, ls: &[f64]) -> Vec<f64> {
    let mut xs = x.to_vec();
    for row in xs.chunks_exact_mut(d) {
        for (v, l) in row.iter_mut().zip(ls) {
            *v /= l;
        }
    }
    xs
}

#[inline]
pub(crate) fn sqdist(a: &[f64], b: &[f64]) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        let u = x - y;
        s += u * u;
    }
    s
}

/// Noise-free kernel matrix K_f (lower triangle incl. diagonal) from scaled inputs.
fn kernel_lower(xs: &[f64], n: usize, d: usize, sf2: f64) -> Mat<f64> {
    let mut k = Mat::<f64>::zeros(n, n);
    for b in 0..n {
        let xb = &xs[b * d..(b + 1) * d];
        let col = k
            .col_mut(b)
            .try_as_col_major_mut()
            .expect("Mat columns are contiguous");
        let col = col.as_slice_mut();
        col[b] = sf2;
        for a in b + 1..n {
            col[a] = sf2 * (-0.5 * sqdist(&xs[a * d..(a + 1) * d], xb)).exp();
        }
    }
    k
}

/// Cholesky of K_f + (σ_n² + jitter)·I, escalating the jitter from
/// `start_jitter` (absolute; 0 = try without first) until it succeeds.
pub(crate) fn factorise(
    xs: &[f64],
    n: usize,
    d: usize,
    hp: &Hyperparameters,
    start_jitter: f64,
    keep_kf: bool,
    par: Par,
) -> Result<Factor, GpError> {
    let kf = kernel_lower(xs, n, d, hp.signal_variance);
    let diag_scale = hp.signal_variance + hp.noise_variance;
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        n,
        par,
        Default::default(),
    ));
    let mut jitter = start_jitter;
    loop {
        let mut a = kf.clone();
        for i in 0..n {
            a[(i, i)] += hp.noise_variance + jitter;
        }
        let ok = llt::factor::cholesky_in_place(
            a.as_mut(),
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .is_ok()
            && (0..n).all(|i| a[(i, i)].is_finite() && a[(i, i)] > 0.0);
        if ok {
            return Ok(Factor {
                l: a,
                jitter,
                kf: keep_kf.then_some(kf),
            });
        }
        jitter = if jitter <= 0.0 {
            JITTER_START * diag_scale
        } else {
            jitter * 10.0
        };
        if jitter > JITTER_MAX * diag_scale * 1.000_001 {
            return Err(GpError::NotPositiveDefinite {
                jitter: jitter / 10.0,
            });
        }
    }
}

/// Solves L·v = b in place (forward substitution, column-oriented).
#[inline]
pub(crate) fn forward_solve(l: &Mat<f64>, v: &mut [f64]) {
    let n = v.len();
    for j in 0..n {
        let col = l.col(j).try_as_col_major().expect("contiguous").as_slice();
        let vj = v[j] / col[j];
        v[j] = vj;
        if vj != 0.0 {
            for (vi, lij) in v[j + 1..].iter_mut().zip(&col[j + 1..]) {
                *vi -= lij * vj;
            }
        }
    }
}

/// Solves Lᵀ·x = v in place (backward substitution, column dot products).
pub(crate) fn backward_solve(l: &Mat<f64>, v: &mut [f64]) {
    let n = v.len();
    for j in (0..n).rev() {
        let col = l.col(j).try_as_col_major().expect("contiguous").as_slice();
        let s: f64 = v[j + 1..]
            .iter()
            .zip(&col[j + 1..])
            .map(|(a, b)| a * b)
            .sum();
        v[j] = (v[j] - s) / col[j];
    }
}

/// α = A⁻¹ y.
pub(crate) fn solve_alpha(l: &Mat<f64>, y: &[f64]) -> Vec<f64> {
    let mut a = y.to_vec();
    forward_solve(l, &mut a);
    backward_solve(l, &mut a);
    a
}

/// ln det A = 2 Σ ln L_ii.
pub(crate) fn log_det(l: &Mat<f64>) -> f64 {
    2.0 * (0..l.nrows()).map(|i| l[(i, i)].ln()).sum::<f64>()
}

/// Result of one likelihood evaluation.
pub(crate) struct LmlEval {
    pub value: f64,
    pub gradient: Vec<f64>,
}

/// log p(y | X, θ) = −½ yᵀα − ½ ln det A − (N/2) ln 2π, and (if `grad`) its
/// gradient w.r.t. θ = (ln ℓ, ln σ_f², ln σ_n²):
/// ∂/∂θ_k = ½ tr((ααᵀ − A⁻¹) ∂A/∂θ_k).
pub(crate) fn lml(
    x: &[f64],
    n: usize,
    d: usize,
    y: &[f64],
    log_params: &[f64],
    grad: bool,
    par: Par,
) -> Result<LmlEval, GpError> {
    let hp = Hyperparameters::from_log(log_params)?;
    let xs = scale_inputs(x, d, &hp.length_scales);
    let f = factorise(&xs, n, d, &hp, 0.0, grad, par)?;
    let alpha = solve_alpha(&f.l, y);
    let fit: f64 = y.iter().zip(&alpha).map(|(a, b)| a * b).sum();
    let value =
        -0.5 * fit - 0.5 * log_det(&f.l) - 0.5 * n as f64 * (2.0 * core::f64::consts::PI).ln();
    if !value.is_finite() {
        return Err(GpError::NotPositiveDefinite { jitter: f.jitter });
    }
    let mut gradient = Vec::new();
    if grad {
        let kf = f.kf.as_ref().expect("kept for gradient");
        let mut ainv = Mat::<f64>::zeros(n, n);
        let mut mem = MemBuffer::new(llt::inverse::inverse_scratch::<f64>(n, par));
        llt::inverse::inverse(ainv.as_mut(), f.l.as_ref(), par, MemStack::new(&mut mem));
        let mut gl = vec![0.0; d];
        let mut g_off = 0.0; // Σ_{a>b} W_ab K_ab
        let mut w_diag = 0.0; // Σ_a W_aa
        for b in 0..n {
            let ac = ainv
                .col(b)
                .try_as_col_major()
                .expect("contiguous")
                .as_slice();
            let kc = kf.col(b).try_as_col_major().expect("contiguous").as_slice();
            let xb = &xs[b * d..(b + 1) * d];
            let ab = alpha[b];
            w_diag += ab * ab - ac[b];
            for a in b + 1..n {
                let kw = (alpha[a] * ab - ac[a]) * kc[a];
                g_off += kw;
                let xa = &xs[a * d..(a + 1) * d];
                for ((g, p), q) in gl.iter_mut().zip(xa).zip(xb) {
                    let u = p - q;
                    *g += kw * u * u;
                }
            }
        }
        gradient.extend_from_slice(&gl);
        gradient.push(g_off + 0.5 * hp.signal_variance * w_diag);
        gradient.push(0.5 * hp.noise_variance * w_diag);
        if gradient.iter().any(|g| !g.is_finite()) {
            return Err(GpError::NotPositiveDefinite { jitter: f.jitter });
        }
    }
    Ok(LmlEval { value, gradient })
}
