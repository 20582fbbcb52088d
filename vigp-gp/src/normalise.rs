//! Standardisation of inputs (per dimension) and scaling of outputs.

use serde::{Deserialize, Serialize};

/// Scales below this are treated as zero variance and replaced by 1, as in
/// scikit-learn's `_handle_zero_variance` (10 · machine epsilon).
const ZERO_SCALE: f64 = 10.0 * f64::EPSILON;

/// Affine map x_n = (x − shift) / scale per input dimension.
///
/// A dimension whose standard deviation is zero (a constant column) keeps
/// scale 1, so it never produces NaN.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputNormaliser {
    /// Subtracted from each input dimension (the training mean, or 0).
    pub shift: Vec<f64>,
    /// Divides each input dimension (the training standard deviation with
    /// divisor N, or 1).
    pub scale: Vec<f64>,
}

impl InputNormaliser {
    /// The identity map in `dim` dimensions.
    pub fn identity(dim: usize) -> Self {
        Self {
            shift: vec![0.0; dim],
            scale: vec![1.0; dim],
        }
    }

    /// Mean and standard deviation (divisor N) of each column of the
    /// row-major `n × dim` matrix `x`.
    pub fn fit(x: &[f64], dim: usize) -> Self {
        let n = x.len() / dim;
        // the plain mean: the stationary kernel sees only differences of
        // inputs, so a shift off by a few ulps changes only rounding (unlike the
        // targets' constant mean, `column_means`), and keeping it keeps
        // every trained model's bits
        let shift = plain_means(x, dim);
        let mut scale = vec![0.0; dim];
        for row in x.chunks_exact(dim) {
            for ((q, v), m) in scale.iter_mut().zip(row).zip(&shift) {
                *q += (v - m) * (v - m);
            }
        }
        for (j, q) in scale.iter_mut().enumerate() {
            *q = (*q / n as f64).sqrt();
            if q.is_infinite() {
                // the squares overflowed (inputs beyond ~1e154): the same
                // deviation as m·√(mean ((x − μ)/m)²), m = max |x − μ|
                let col = x.chunks_exact(dim).map(|row| row[j] - shift[j]);
                let m = col.clone().fold(0.0f64, |m, u| m.max(u.abs()));
                *q = m * (col.map(|u| (u / m) * (u / m)).sum::<f64>() / n as f64).sqrt();
            }
            if !q.is_finite() || *q < ZERO_SCALE {
                *q = 1.0;
            }
        }
        // A column of huge constant values: its deviation can be rounding
        // noise relative to the mean; treat it as constant too.
        for (q, m) in scale.iter_mut().zip(&shift) {
            if *q < ZERO_SCALE * m.abs() {
                *q = 1.0;
            }
        }
        Self { shift, scale }
    }

    /// Writes the normalised `x` into `out` (same length).
    #[inline]
    pub fn apply(&self, x: &[f64], out: &mut [f64]) {
        for (((o, v), m), s) in out.iter_mut().zip(x).zip(&self.shift).zip(&self.scale) {
            *o = (v - m) / s;
        }
    }
}

/// The plain mean Σx/N of each column of the row-major `n × dim` matrix
/// `x`; a sum that overflows (values near f64::MAX) falls back to Σ(x/N).
fn plain_means(x: &[f64], dim: usize) -> Vec<f64> {
    let n = (x.len() / dim) as f64;
    let mut mean = vec![0.0; dim];
    for row in x.chunks_exact(dim) {
        for (s, v) in mean.iter_mut().zip(row) {
            *s += v;
        }
    }
    mean.iter_mut().for_each(|s| *s /= n);
    if mean.iter().any(|s| !s.is_finite()) {
        mean.iter_mut().for_each(|s| *s = 0.0);
        for row in x.chunks_exact(dim) {
            for (s, v) in mean.iter_mut().zip(row) {
                *s += v / n;
            }
        }
    }
    mean
}

/// The mean of each column of the row-major `n × dim` matrix `x`, to
/// within a few ulps of the spread of the column rather than of its
/// magnitude: the plain mean m₀, then m₀ + Σ(x − m₀)/N (the corrected
/// two-pass algorithm). A plain running sum of 1e6 + 1e-3·f(x) loses
/// ~1e-9 of the signal per sample and shifts every normalised target.
pub(crate) fn column_means(x: &[f64], dim: usize) -> Vec<f64> {
    let n = (x.len() / dim) as f64;
    let mut mean = plain_means(x, dim);
    let mut correction = vec![0.0; dim];
    for row in x.chunks_exact(dim) {
        for ((c, v), m) in correction.iter_mut().zip(row).zip(&mean) {
            *c += (v - m) / n;
        }
    }
    for (m, c) in mean.iter_mut().zip(&correction) {
        if c.is_finite() {
            *m += c;
        }
    }
    mean
}

/// Output scale: the root mean square of the residual y − m(x), or 1 when
/// that is zero (or normalisation is off). With the constant prior mean the
/// residual has zero mean, so this is the standard deviation (divisor N),
/// exactly scikit-learn's `normalize_y=True` convention.
pub(crate) fn output_scale(residual: &[f64]) -> f64 {
    let n = residual.len() as f64;
    let mut s = (residual.iter().map(|r| r * r).sum::<f64>() / n).sqrt();
    if s.is_infinite() {
        // the squares overflowed (residuals beyond ~1e154): the same RMS as
        // m·√(mean (r/m)²), m = max |r|
        let m = residual.iter().fold(0.0f64, |m, r| m.max(r.abs()));
        s = m * (residual.iter().map(|r| (r / m) * (r / m)).sum::<f64>() / n).sqrt();
    }
    if s.is_finite() && s >= ZERO_SCALE {
        s
    } else {
        1.0
    }
}
