//! Prediction with a trained Gaussian process exported as Rust source:
//! `no_std`, no allocation, fixed input dimension.
//!
//! The std runtime (`vigp_runtime::gp::Gp`) trains the model and writes it
//! out as `static` arrays (`Gp::to_rust_source`); the generated file builds
//! one [`ExportedGp`] per output, which firmware-style code evaluates with
//! [`ExportedGp::predict_mean`] (mean) or [`ExportedGp::predict`] (mean and
//! latent variance, with a caller-provided scratch buffer).
//!
//! # Model and conventions
//!
//! One output of the std GP: with the input standardisation
//! x_n = (x − μ)/s_x, the length scales ℓ, signal variance σ_f² and weights
//! α = (K + (σ_n² + jitter)·I)⁻¹ r (all in normalised units), an output
//! scale s_y and a constant prior mean m,
//!
//! ```text
//! q_j     = ((x_j − μ_j) / s_x,j) / ℓ_j                  (scaled query)
//! r_i²    = Σ_j (X̃_ji − q_j)²                             (X̃: scaled training inputs)
//! k_i     = σ_f² · exp(−½ r_i²)   (0 if r_i² > 690)
//! mean    = m + s_y · Σ_i k_i·α_i
//! var     = s_y² · max(σ_f² − ‖L⁻¹k‖², 0)                 (latent f, no noise)
//! ```
//!
//! with L the lower Cholesky factor of K + (σ_n² + jitter)·I. These are the
//! same operations, in the same order, as the std GP's prediction, and both
//! use the kernel functions of this module ([`kernel_dot`], [`kernel_row`],
//! [`dot`]), so an exported model reproduces the std model's mean **bit for
//! bit** (tested in `tests/gp/gp_export.rs`).
//!
//! # Cost
//!
//! Mean: N·D subtract-multiply-adds, N exponentials and N multiply-adds,
//! i.e. O(N·D) time, O(1) memory (a 64-entry stack block). Variance:
//! O(N²) more (a triangular solve with the packed Cholesky factor), with an
//! N-entry scratch buffer from the caller. Nothing allocates.
//!
//! # The exponential and the cut-off
//!
//! The kernel uses its own branch-free exponential ([`kernel_exp`]) instead
//! of `libm::exp`: it vectorises (two lanes on baseline x86-64, more with
//! `-C target-cpu=native`), which `libm::exp` and the platform `exp` do not;
//! measured 4.8 ns against 15.6 ns (`libm::exp`) and 8.6 ns (glibc, through
//! `f64::exp`) per call in a loop on this 2-core machine under load. It is
//! within 1 ulp of the correctly rounded e^x on [−708, 0] (max 0.95 ulp
//! against a double-double reference, tested). Kernel values with
//! r² > [`R2_CUTOFF`] = 690 (below e^{−345}·σ_f² ≈ 1.4e-150·σ_f²) are 0, as
//! in the std GP's training kernel: far below rounding, and it keeps every
//! product out of the subnormal range.

/// Why an exported-GP prediction failed. Prediction never panics and never
/// returns a silent NaN.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GpError {
    /// The query holds NaN or ±∞.
    NonFiniteInput {
        /// Index of the first offending component.
        index: usize,
    },
    /// The model's arrays do not fit together (e.g. `inputs.len() != D·N`).
    InvalidModel(&'static str),
    /// A model value is NaN, ±∞ or (for scales) not positive
    /// ([`ExportedGp::validate`]).
    InvalidValue {
        /// Which array.
        what: &'static str,
        /// Index in it.
        index: usize,
    },
    /// The variance needs the Cholesky factor, and this export has none
    /// (export with the factor to get variances).
    NoCholesky,
    /// The caller's scratch buffer is shorter than N.
    ScratchTooSmall {
        /// Needed length (N).
        needed: usize,
        /// Length given.
        got: usize,
    },
    /// The result overflowed to ±∞ or NaN (weights of absurd size).
    NonFiniteOutput,
}

impl core::fmt::Display for GpError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NonFiniteInput { index } => {
                write!(f, "non-finite GP input at component {index}")
            }
            Self::InvalidModel(what) => write!(f, "inconsistent exported GP: {what}"),
            Self::InvalidValue { what, index } => {
                write!(
                    f,
                    "invalid value in exported GP array {what} at index {index}"
                )
            }
            Self::NoCholesky => f.write_str(
                "the exported GP has no Cholesky factor (export it with the factor for variances)",
            ),
            Self::ScratchTooSmall { needed, got } => {
                write!(f, "scratch buffer too small: need {needed}, got {got}")
            }
            Self::NonFiniteOutput => f.write_str("GP prediction is not finite"),
        }
    }
}

impl core::error::Error for GpError {}

/// One output of a trained GP as plain data (normally `static` arrays from
/// a generated file; see the module docs for the formulas).
///
/// All fields are public so that generated code can build it in a
/// `static`. Use [`validate`](Self::validate) once if the data does not
/// come from the exporter; prediction checks the array lengths on every
/// call (O(1)) and returns [`GpError::InvalidModel`] if they do not fit.
///
/// ```
/// use vigp_core::gp::ExportedGp;
/// // Two training points in one dimension, weights α, no normalisation.
/// static INPUTS: [f64; 2] = [-1.0, 1.0];
/// static WEIGHTS: [f64; 2] = [0.5, 0.5];
/// static GP: ExportedGp<'static, 1> = ExportedGp {
///     inputs: &INPUTS,
///     weights: &WEIGHTS,
///     length_scales: [1.0],
///     signal_variance: 2.0,
///     input_shift: [0.0],
///     input_scale: [1.0],
///     output_scale: 1.0,
///     prior_mean: 0.0,
///     cholesky: None,
/// };
/// let m = GP.predict_mean(&[0.0])?;
/// // σ_f²·(½e^{−½} + ½e^{−½}) = 2e^{−½}
/// assert!((m - 2.0 * (-0.5f64).exp()).abs() < 1e-15);
/// # Ok::<(), vigp_core::gp::GpError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExportedGp<'a, const D: usize> {
    /// Training inputs, standardised and divided by the length scales,
    /// **column-major** D × N: `inputs[j·N + i]` = ((x_ij − μ_j)/s_x,j)/ℓ_j.
    pub inputs: &'a [f64],
    /// Weights α = (K + (σ_n² + jitter)·I)⁻¹ r in normalised units (length N).
    pub weights: &'a [f64],
    /// Length scales ℓ_j (normalised units).
    pub length_scales: [f64; D],
    /// Signal variance σ_f² (normalised units).
    pub signal_variance: f64,
    /// Input standardisation shift μ_j (the training mean, or 0).
    pub input_shift: [f64; D],
    /// Input standardisation scale s_x,j (the training standard deviation, or 1).
    pub input_scale: [f64; D],
    /// Output scale s_y (1 if output normalisation was off).
    pub output_scale: f64,
    /// Constant prior mean m (0 for a zero prior).
    pub prior_mean: f64,
    /// Lower Cholesky factor L of K + (σ_n² + jitter)·I, packed column by
    /// column (column j holds L_jj, …, L_{N−1,j}), N(N+1)/2 numbers; only
    /// needed for [`predict`](Self::predict).
    pub cholesky: Option<&'a [f64]>,
}

impl<const D: usize> ExportedGp<'_, D> {
    /// Number of training points N.
    pub fn n(&self) -> usize {
        self.weights.len()
    }

    /// Checks every length and value: finite data, positive scales and
    /// variances, a Cholesky factor with positive diagonal. O(N) (O(N²)
    /// with the factor). Prediction does not need this; it is for data that
    /// did not come from the exporter.
    pub fn validate(&self) -> Result<(), GpError> {
        let n = self.check_lengths()?;
        finite("inputs", self.inputs)?;
        finite("weights", self.weights)?;
        finite("input_shift", &self.input_shift)?;
        positive("length_scales", &self.length_scales)?;
        positive("input_scale", &self.input_scale)?;
        positive("signal_variance", &[self.signal_variance])?;
        positive("output_scale", &[self.output_scale])?;
        finite("prior_mean", &[self.prior_mean])?;
        if let Some(l) = self.cholesky {
            finite("cholesky", l)?;
            let mut at = 0;
            for j in 0..n {
                if l[at] <= 0.0 {
                    return Err(GpError::InvalidValue {
                        what: "cholesky (diagonal)",
                        index: at,
                    });
                }
                at += n - j;
            }
        }
        Ok(())
    }

    /// N after checking that the arrays fit together (O(1)).
    fn check_lengths(&self) -> Result<usize, GpError> {
        let n = self.weights.len();
        if n == 0 || D == 0 {
            return Err(GpError::InvalidModel("no training points or D = 0"));
        }
        if n.checked_mul(D) != Some(self.inputs.len()) {
            return Err(GpError::InvalidModel("inputs.len() != D·N"));
        }
        if let Some(l) = self.cholesky {
            if n.checked_mul(n + 1).map(|m| m / 2) != Some(l.len()) {
                return Err(GpError::InvalidModel("cholesky.len() != N(N+1)/2"));
            }
        }
        Ok(n)
    }

    /// The scaled query q_j = ((x_j − μ_j)/s_x,j)/ℓ_j (the same two
    /// divisions as the std GP, so that q is bit-identical).
    fn scaled_query(&self, x: &[f64; D]) -> Result<[f64; D], GpError> {
        if let Some(index) = x.iter().position(|v| !v.is_finite()) {
            return Err(GpError::NonFiniteInput { index });
        }
        let mut q = [0.0; D];
        for j in 0..D {
            q[j] = ((x[j] - self.input_shift[j]) / self.input_scale[j]) / self.length_scales[j];
        }
        Ok(q)
    }

    /// Posterior mean at `x` (original input units), without allocating.
    ///
    /// Cost: N·D subtract-multiply-adds, N exponentials, N multiply-adds
    /// (O(N·D)); memory: a 64-entry stack block.
    ///
    /// Errors: [`GpError::NonFiniteInput`] for NaN/∞ in `x`,
    /// [`GpError::InvalidModel`] for inconsistent array lengths,
    /// [`GpError::NonFiniteOutput`] if the sum overflows.
    pub fn predict_mean(&self, x: &[f64; D]) -> Result<f64, GpError> {
        let n = self.check_lengths()?;
        let q = self.scaled_query(x)?;
        let s = kernel_dot(self.inputs, n, &q, self.signal_variance, self.weights)?;
        let mean = self.prior_mean + self.output_scale * s;
        if mean.is_finite() {
            Ok(mean)
        } else {
            Err(GpError::NonFiniteOutput)
        }
    }

    /// Posterior mean at `x` (bit for bit that of
    /// [`predict_mean`](Self::predict_mean)) and its gradient in `x`:
    /// ∂m/∂x_j = −s_y·Σ_i α_i k_i (q_j − X_ji) / (s_x,j ℓ_j), k_i the
    /// kernel values, X the scaled training inputs and q the scaled query
    /// (zero where the kernel is cut off, as the mean's terms are).
    /// O(N·D), no allocation. Errors as `predict_mean`.
    pub fn predict_mean_gradient(&self, x: &[f64; D]) -> Result<(f64, [f64; D]), GpError> {
        let mean = self.predict_mean(x)?;
        let n = self.check_lengths()?;
        let q = self.scaled_query(x)?;
        let mut g = [0.0; D];
        for (i, w) in self.weights.iter().enumerate() {
            let d = |j: usize| q[j] - self.inputs[j * n + i];
            let r2 = (0..D).fold(0.0, |r2, j| r2 + d(j) * d(j));
            let wk = w * kernel_value(self.signal_variance, r2);
            if wk != 0.0 {
                for (j, gj) in g.iter_mut().enumerate() {
                    *gj -= wk * d(j);
                }
            }
        }
        for ((gj, s), l) in g.iter_mut().zip(&self.input_scale).zip(&self.length_scales) {
            *gj *= self.output_scale / (s * l);
        }
        if g.iter().all(|x| x.is_finite()) {
            Ok((mean, g))
        } else {
            Err(GpError::NonFiniteOutput)
        }
    }

    /// Posterior mean and latent variance (of f(x), without observation
    /// noise) at `x`, without allocating: `scratch` must hold at least N
    /// numbers (its content on return is L⁻¹k).
    ///
    /// Cost: O(N·D) for the kernel and mean, N²/2 multiply-adds for the
    /// triangular solve. The mean equals [`predict_mean`](Self::predict_mean)
    /// bit for bit.
    ///
    /// Errors: those of `predict_mean`, plus [`GpError::NoCholesky`] and
    /// [`GpError::ScratchTooSmall`].
    pub fn predict(&self, x: &[f64; D], scratch: &mut [f64]) -> Result<(f64, f64), GpError> {
        let n = self.check_lengths()?;
        let chol = self.cholesky.ok_or(GpError::NoCholesky)?;
        if scratch.len() < n {
            return Err(GpError::ScratchTooSmall {
                needed: n,
                got: scratch.len(),
            });
        }
        let q = self.scaled_query(x)?;
        let k = &mut scratch[..n];
        kernel_row(self.inputs, n, &q, self.signal_variance, k)?;
        let s = dot(k, self.weights)?;
        forward_solve_packed(chol, k)?;
        let vv: f64 = k.iter().map(|v| v * v).sum();
        let sy = self.output_scale;
        let mean = self.prior_mean + sy * s;
        let var = sy * sy * (self.signal_variance - vv).max(0.0);
        if mean.is_finite() && var.is_finite() {
            Ok((mean, var))
        } else {
            Err(GpError::NonFiniteOutput)
        }
    }
}

/// Block length of the fused kernel loop (a stack buffer; a multiple of
/// [`LANES`]).
const BLOCK: usize = 64;

/// Independent partial sums of the dot products (lets the compiler keep
/// them in vector registers; fixes the summation order).
const LANES: usize = 8;

/// log2(e).
const LOG2E: f64 = core::f64::consts::LOG2_E;
/// ln 2 split as in fdlibm: `LN2_HI` has 21 trailing zero bits, so
/// k·`LN2_HI` is exact for |k| < 2²¹.
const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000); // 6.93147180369123816490e-1
const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76); // 1.90821492927058770002e-10
/// 1.5·2⁵²: adding it rounds a number of magnitude < 2⁵¹ to an integer.
const ROUND: f64 = 6_755_399_441_055_744.0;
/// Below this argument [`kernel_exp`] returns 0 (e^−708 ≈ 3.3e-308).
const EXP_MIN: f64 = -708.0;

/// Squared scaled distance beyond which the kernel value σ_f²·e^{−r²/2} is
/// taken as 0 (e^{−345} ≈ 1.4e-150: far below rounding relative to σ_f²,
/// far above the subnormal range, whose microcode assists would cost ~100
/// cycles per operation). The same cut-off as the std GP's training kernel.
pub const R2_CUTOFF: f64 = 690.0;

/// e^x for x ≤ 0, branch-free so that loops over it vectorise.
///
/// Accuracy: within 1 ulp of the correctly rounded e^x for x in
/// [−708, 0] (tested); 0 for x < −708 (and for −∞). Arguments above 0 are
/// outside its contract (the kernel only needs −½·r² ≤ 0): it returns
/// e^x for 0 < x < 709 with the same accuracy but is not tested there.
/// NaN in gives an unspecified finite value: callers check their inputs.
///
/// Method: x = k·ln 2 + r with k = round(x·log2 e) and |r| ≤ ln 2/2
/// (Cody–Waite, two-part ln 2); e^r = 1 + r + r²·Q(r) with Q the Taylor
/// polynomial of (e^r − 1 − r)/r² to degree 11 (truncation < 5e-18
/// relative), evaluated by Estrin's scheme (depth 4 instead of Horner's 12,
/// so that consecutive elements overlap in the pipeline); then the result
/// is scaled by 2^k built from its bits.
#[inline(always)]
pub fn kernel_exp(x: f64) -> f64 {
    exp_above(x, EXP_MIN)
}

/// Turns squared scaled distances r² into kernel values σ_f²·e^{−r²/2}
/// (0 where r² > [`R2_CUTOFF`]) in place: the last step of [`kernel_row`],
/// for callers that compute the distances themselves (e.g. several rows
/// at once). Elementwise, so the values are those of [`kernel_row`] bit
/// for bit. O(len).
#[inline(always)]
pub fn kernel_from_sqdist(signal_variance: f64, r2: &mut [f64]) {
    for v in r2.iter_mut() {
        *v = kernel_value(signal_variance, *v);
    }
}

/// σ_f²·e^{−r²/2}, or 0 when r² > [`R2_CUTOFF`].
#[inline(always)]
fn kernel_value(sf2: f64, r2: f64) -> f64 {
    sf2 * exp_above(-0.5 * r2, -0.5 * R2_CUTOFF)
}

/// e^x for `min` ≤ x ≤ 0 (`min` ≥ −708), 0 below `min`; see [`kernel_exp`].
#[inline(always)]
fn exp_above(x: f64, min: f64) -> f64 {
    // `if` forms (not f64::max) compile to plain max/compare-and-mask.
    let xc = if x < min { min } else { x };
    let t = xc * LOG2E + ROUND;
    let k = t - ROUND;
    let r = (xc - k * LN2_HI) - k * LN2_LO;
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    // Q(r) = Σ_{i=0}^{11} r^i/(i + 2)!
    let a0 = 1.0 / 2.0 + r * (1.0 / 6.0);
    let a1 = 1.0 / 24.0 + r * (1.0 / 120.0);
    let a2 = 1.0 / 720.0 + r * (1.0 / 5_040.0);
    let a3 = 1.0 / 40_320.0 + r * (1.0 / 362_880.0);
    let a4 = 1.0 / 3_628_800.0 + r * (1.0 / 39_916_800.0);
    let a5 = 1.0 / 479_001_600.0 + r * (1.0 / 6_227_020_800.0);
    let b0 = a0 + r2 * a1;
    let b1 = a2 + r2 * a3;
    let b2 = a4 + r2 * a5;
    let q = (b0 + r4 * b1) + r8 * b2;
    // e^r − 1 = r + r²·Q, then 1 + (e^r − 1): the small part is summed first.
    let er = 1.0 + (q * r2 + r);
    // k ∈ [−1022, 0] here: its integer value sits in the low bits of t.
    let ki = (t.to_bits() as i64).wrapping_sub(ROUND.to_bits() as i64);
    let scale = f64::from_bits(((ki + 1023) as u64) << 52);
    let y = er * scale;
    if x < min { 0.0 } else { y }
}

/// Checks the shapes shared by the kernel functions.
fn check_kernel(inputs: &[f64], n: usize, q: &[f64]) -> Result<(), GpError> {
    if n.checked_mul(q.len()) != Some(inputs.len()) {
        return Err(GpError::InvalidModel("inputs.len() != d·n"));
    }
    Ok(())
}

/// k_i = σ_f²·exp(−½ Σ_j (X̃_j,start+i − q_j)²) for one block `k`
/// (length ≤ [`BLOCK`]); the sum over j runs in ascending order from 0
/// whatever the specialisation, so every path gives the same bits.
#[inline(always)]
fn block_kernel(inputs: &[f64], n: usize, q: &[f64], sf2: f64, start: usize, k: &mut [f64]) {
    macro_rules! fixed {
        ($($d:literal)*) => {
            match q.len() {
                $($d => {
                    let q: &[f64; $d] = q.try_into().unwrap_or(&[0.0; $d]);
                    block_kernel_fixed::<$d>(inputs, n, q, sf2, start, k)
                })*
                _ => block_kernel_any(inputs, n, q, sf2, start, k),
            }
        };
    }
    fixed!(1 2 3 4 5 6 7 8)
}

/// [`block_kernel`] for a compile-time dimension: the D columns are read
/// side by side and each squared distance stays in a register.
#[inline(always)]
fn block_kernel_fixed<const D: usize>(
    inputs: &[f64],
    n: usize,
    q: &[f64; D],
    sf2: f64,
    start: usize,
    k: &mut [f64],
) {
    let len = k.len();
    let cols: [&[f64]; D] = core::array::from_fn(|j| &inputs[j * n + start..j * n + start + len]);
    for (i, ki) in k.iter_mut().enumerate() {
        let mut s = 0.0;
        for j in 0..D {
            let u = cols[j][i] - q[j];
            s += u * u;
        }
        *ki = s;
    }
    for v in k.iter_mut() {
        *v = kernel_value(sf2, *v);
    }
}

/// [`block_kernel`] for any dimension: one pass over the block per four
/// columns, each squared distance held in a register within a pass and
/// summed in column order (so the bits of the one-pass sum).
#[inline(always)]
fn block_kernel_any(inputs: &[f64], n: usize, q: &[f64], sf2: f64, start: usize, k: &mut [f64]) {
    let len = k.len();
    let col = |j: usize| &inputs[j * n + start..j * n + start + len];
    k.iter_mut().for_each(|v| *v = 0.0);
    let mut j = 0;
    while j + 4 <= q.len() {
        let (c0, c1, c2, c3) = (col(j), col(j + 1), col(j + 2), col(j + 3));
        let (q0, q1, q2, q3) = (q[j], q[j + 1], q[j + 2], q[j + 3]);
        for ((((s, x0), x1), x2), x3) in k.iter_mut().zip(c0).zip(c1).zip(c2).zip(c3) {
            let (u0, u1, u2, u3) = (x0 - q0, x1 - q1, x2 - q2, x3 - q3);
            *s = (((*s + u0 * u0) + u1 * u1) + u2 * u2) + u3 * u3;
        }
        j += 4;
    }
    for (qj, jj) in q[j..].iter().zip(j..) {
        for (s, x) in k.iter_mut().zip(col(jj)) {
            let u = x - qj;
            *s += u * u;
        }
    }
    for v in k.iter_mut() {
        *v = kernel_value(sf2, *v);
    }
}

/// k_i = σ_f²·exp(−½ r_i²), r_i² = Σ_j (X̃_ji − q_j)² (0 when
/// r_i² > [`R2_CUTOFF`]) for all i, written to `out` (length n), with X̃ the
/// column-major d × n scaled training inputs and q the scaled query
/// (d = `q.len()`). O(n·d); the std GP's variance path uses it too.
///
/// Errors: [`GpError::InvalidModel`] if `inputs.len() != d·n` or
/// `out.len() != n`.
///
/// Always inlined, so a caller compiled for a wider vector unit (e.g. the
/// std runtime's AVX2 dispatch) compiles it for that unit too; the values
/// are the same bits either way (elementwise arithmetic, no fused
/// multiply-adds).
#[inline(always)]
pub fn kernel_row(
    inputs: &[f64],
    n: usize,
    q: &[f64],
    signal_variance: f64,
    out: &mut [f64],
) -> Result<(), GpError> {
    check_kernel(inputs, n, q)?;
    if out.len() != n {
        return Err(GpError::InvalidModel("kernel row length != n"));
    }
    let mut start = 0;
    for block in out.chunks_mut(BLOCK) {
        block_kernel(inputs, n, q, signal_variance, start, block);
        start += BLOCK;
    }
    Ok(())
}

/// [`kernel_row`] for the consecutive points `start .. start + out.len()`
/// only: `out[i]` is the kernel value of point `start + i`, the same bits
/// as `kernel_row`'s entry `start + i`. O(`out.len()`·d). A training
/// Gram matrix's lower triangle is one call per column (`start` = column
/// + 1).
///
/// Errors: [`GpError::InvalidModel`] if `inputs.len() != d·n` or
/// `start + out.len() > n`.
///
/// Always inlined, as [`kernel_row`].
#[inline(always)]
pub fn kernel_row_range(
    inputs: &[f64],
    n: usize,
    q: &[f64],
    signal_variance: f64,
    start: usize,
    out: &mut [f64],
) -> Result<(), GpError> {
    check_kernel(inputs, n, q)?;
    if start.checked_add(out.len()).is_none_or(|end| end > n) {
        return Err(GpError::InvalidModel("kernel row range beyond n"));
    }
    let mut at = start;
    for block in out.chunks_mut(BLOCK) {
        block_kernel(inputs, n, q, signal_variance, at, block);
        at += BLOCK;
    }
    Ok(())
}

/// Σ_i a_i·b_i with `LANES` interleaved partial sums (element i goes to
/// sum i mod 8), added pairwise at the end: a fixed order, so results are
/// reproducible, and one that vectorises.
///
/// Errors: [`GpError::InvalidModel`] if the lengths differ.
pub fn dot(a: &[f64], b: &[f64]) -> Result<f64, GpError> {
    if a.len() != b.len() {
        return Err(GpError::InvalidModel("dot product of different lengths"));
    }
    let mut acc = [0.0; LANES];
    accumulate(&mut acc, a, b);
    Ok(reduce(&acc))
}

/// acc[i mod 8] += a_i·b_i (a.len() == b.len(); blocks start at multiples of 8).
#[inline(always)]
fn accumulate(acc: &mut [f64; LANES], a: &[f64], b: &[f64]) {
    let mut ca = a.chunks_exact(LANES);
    let mut cb = b.chunks_exact(LANES);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for l in 0..LANES {
            acc[l] += x[l] * y[l];
        }
    }
    for (l, (x, y)) in ca.remainder().iter().zip(cb.remainder()).enumerate() {
        acc[l] += x * y;
    }
}

#[inline(always)]
fn reduce(acc: &[f64; LANES]) -> f64 {
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// Σ_i w_i·k_i with k from [`kernel_row`], fused block by block so that
/// nothing of length n is written: equal bit for bit to
/// `kernel_row` followed by [`dot`]. O(n·d) time, a 64-entry stack block.
///
/// Errors: [`GpError::InvalidModel`] if `inputs.len() != d·n` or
/// `weights.len() != n`.
///
/// Always inlined, as [`kernel_row`].
#[inline(always)]
pub fn kernel_dot(
    inputs: &[f64],
    n: usize,
    q: &[f64],
    signal_variance: f64,
    weights: &[f64],
) -> Result<f64, GpError> {
    check_kernel(inputs, n, q)?;
    if weights.len() != n {
        return Err(GpError::InvalidModel("weights.len() != n"));
    }
    let mut acc = [0.0; LANES];
    let mut buf = [0.0; BLOCK];
    let mut start = 0;
    for w in weights.chunks(BLOCK) {
        let k = &mut buf[..w.len()];
        block_kernel(inputs, n, q, signal_variance, start, k);
        accumulate(&mut acc, k, w);
        start += BLOCK;
    }
    Ok(reduce(&acc))
}

/// Solves L·y = v in place for a lower-triangular L packed column by
/// column (N(N+1)/2 numbers, column j = L_jj … L_{N−1,j}): column-oriented
/// forward substitution, skipping zero entries of y. N²/2 multiply-adds.
///
/// Errors: [`GpError::InvalidModel`] if `l.len() != N(N+1)/2` for N = `v.len()`.
pub fn forward_solve_packed(l: &[f64], v: &mut [f64]) -> Result<(), GpError> {
    let n = v.len();
    if n.checked_mul(n + 1).map(|m| m / 2) != Some(l.len()) {
        return Err(GpError::InvalidModel("cholesky.len() != N(N+1)/2"));
    }
    let mut at = 0;
    for j in 0..n {
        let col = &l[at..at + n - j];
        let vj = v[j] / col[0];
        v[j] = vj;
        if vj != 0.0 {
            for (vi, lij) in v[j + 1..].iter_mut().zip(&col[1..]) {
                *vi -= lij * vj;
            }
        }
        at += n - j;
    }
    Ok(())
}

fn finite(what: &'static str, v: &[f64]) -> Result<(), GpError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(GpError::InvalidValue { what, index }),
        None => Ok(()),
    }
}

fn positive(what: &'static str, v: &[f64]) -> Result<(), GpError> {
    match v.iter().position(|x| !(x.is_finite() && *x > 0.0)) {
        Some(index) => Err(GpError::InvalidValue { what, index }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn sq(x: f64) -> f64 {
        x * x
    }

    /// e^x = 2^k·(hi + lo) in double-double arithmetic, independent of any libm:
    /// argument reduction by a 3-part ln 2 with exact products (Dekker) and
    /// a Taylor series summed in double-double. Accurate to ≈ 1e-30
    /// relative for x in [−708, 0].
    fn exp_dd(x: f64) -> (f64, f64, i32) {
        fn two_sum(a: f64, b: f64) -> (f64, f64) {
            let s = a + b;
            let bb = s - a;
            (s, (a - (s - bb)) + (b - bb))
        }
        fn split(a: f64) -> (f64, f64) {
            let c = 134_217_729.0 * a;
            let hi = c - (c - a);
            (hi, a - hi)
        }
        fn two_prod(a: f64, b: f64) -> (f64, f64) {
            let p = a * b;
            let (ah, al) = split(a);
            let (bh, bl) = split(b);
            (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
        }
        fn add(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
            let (s, e) = two_sum(a.0, b.0);
            let e = e + a.1 + b.1;
            two_sum(s, e)
        }
        fn mul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
            let (p, e) = two_prod(a.0, b.0);
            let e = e + a.0 * b.1 + a.1 * b.0;
            two_sum(p, e)
        }
        // ln 2 = L1 + L2 + L3 with L1, L2 of 32 bits (exact products with |k| < 2^21).
        // ln 2 in double-double: LN_2 (the correctly rounded double) plus
        // the next 53 bits
        let ln2: (f64, f64) = (core::f64::consts::LN_2, 2.319_046_813_846_299_6e-17);
        let l1 = f64::from_bits(ln2.0.to_bits() & 0xFFFF_FFFF_E000_0000);
        let l2full = add(ln2, (-l1, 0.0));
        let l2 = f64::from_bits(l2full.0.to_bits() & 0xFFFF_FFFF_E000_0000);
        let l3 = add(l2full, (-l2, 0.0));
        let k = libm::round(x / core::f64::consts::LN_2);
        // r = x − k·ln2 in double-double
        let mut r = add((x, 0.0), (-(k * l1), 0.0));
        r = add(r, (-(k * l2), 0.0));
        r = add(r, mul((-k, 0.0), l3));
        // Taylor to degree 30 in double-double, Horner
        let mut s = (1.0, 0.0);
        for i in (1..=30).rev() {
            let inv = {
                // 1/i in double-double: q + (1 − q·i)/i
                let q = 1.0 / i as f64;
                let (p, e) = two_prod(q, i as f64);
                let err = (1.0 - p) - e;
                (q, err / i as f64)
            };
            s = add((1.0, 0.0), mul(mul(s, r), inv));
        }
        (s.0, s.1, k as i32)
    }

    /// |got − e^x| in ulps of e^x, with e^x = 2^k·(hi + lo) from [`exp_dd`]
    /// (compared at scale 2^0, so the reference's low part never underflows).
    fn ulp_error(got: f64, (hi, lo, k): (f64, f64, i32)) -> f64 {
        let g = libm::ldexp(got, -k); // exact: got is normal
        let ulp = f64::from_bits(hi.to_bits() + 1) - hi;
        ((g - hi) - lo).abs() / ulp
    }

    /// The mean's gradient against central differences of the mean, on a
    /// GP with every normalisation on (shift, scale, length scales, output
    /// scale, prior mean) in two dimensions. Step 1e-5: the mean is smooth
    /// at scale 1 and sums four terms of size ≤ 3, so the difference's
    /// error is O(h²) + O(ε/h) ≈ 1e-10; tolerance 1e-8.
    #[test]
    fn mean_gradient_matches_differences() {
        static INPUTS: [f64; 8] = [-1.0, 0.2, 0.7, 1.5, 0.4, -0.8, 1.1, 0.0];
        static WEIGHTS: [f64; 4] = [0.5, -1.2, 2.0, 0.3];
        let gp: ExportedGp<'_, 2> = ExportedGp {
            inputs: &INPUTS,
            weights: &WEIGHTS,
            length_scales: [0.8, 1.3],
            signal_variance: 1.5,
            input_shift: [0.1, -0.2],
            input_scale: [2.0, 0.5],
            output_scale: 1.7,
            prior_mean: 0.4,
            cholesky: None,
        };
        let h = 1e-5;
        for x in [[0.3, -0.1], [-1.2, 0.4], [2.0, 0.05]] {
            let (m, g) = gp.predict_mean_gradient(&x).unwrap();
            assert_eq!(m.to_bits(), gp.predict_mean(&x).unwrap().to_bits());
            for j in 0..2 {
                let (mut a, mut b) = (x, x);
                a[j] += h;
                b[j] -= h;
                let fd = (gp.predict_mean(&a).unwrap() - gp.predict_mean(&b).unwrap()) / (2.0 * h);
                assert!(
                    (fd - g[j]).abs() <= 1e-8,
                    "x {x:?}, j {j}: {} vs {fd}",
                    g[j]
                );
            }
        }
        assert!(gp.predict_mean_gradient(&[f64::NAN, 0.0]).is_err());
    }

    #[test]
    fn kernel_exp_within_one_ulp() {
        // independent reference: double-double e^x (no libm involved)
        let mut worst: f64 = 0.0;
        let mut wx = 0.0;
        let mut i = 0u64;
        while i < 400_000 {
            // quasi-random in [−708, 0], plus dense small arguments
            let u = (i as f64 * 0.618_033_988_749_894_9) % 1.0;
            let x = if i % 2 == 0 { -708.0 * u } else { -2.0 * u };
            let got = kernel_exp(x);
            let e = ulp_error(got, exp_dd(x));
            if e > worst {
                worst = e;
                wx = x;
            }
            i += 1;
        }
        std::println!("kernel_exp: max error {worst:.3} ulp (at x = {wx})");
        assert!(
            worst < 1.0,
            "max error {worst:e} ulp at {wx:e}: {:e} vs {:?}",
            kernel_exp(wx),
            exp_dd(wx)
        );
        // exact at 0, zero below the cut-off and at −∞
        assert_eq!(kernel_exp(0.0), 1.0);
        assert_eq!(kernel_exp(-0.0), 1.0);
        assert_eq!(kernel_exp(-709.0), 0.0);
        assert_eq!(kernel_exp(f64::NEG_INFINITY), 0.0);
    }

    #[test]
    fn fused_mean_equals_row_then_dot_and_naive_sum() {
        // n not a multiple of the block or lane count
        let (n, d) = (150, 3);
        let mut inputs = [0.0; 450];
        for (i, v) in inputs.iter_mut().enumerate() {
            *v = ((i as f64 * 0.754_877_666_246_692_7) % 1.0) * 4.0 - 2.0;
        }
        let mut w = [0.0; 150];
        for (i, v) in w.iter_mut().enumerate() {
            *v = libm::sin(i as f64 * 0.37);
        }
        let q = [0.3, -0.2, 0.9];
        let fused = kernel_dot(&inputs, n, &q, 1.7, &w).unwrap();
        let mut k = [0.0; 150];
        kernel_row(&inputs, n, &q, 1.7, &mut k).unwrap();
        assert_eq!(fused.to_bits(), dot(&k, &w).unwrap().to_bits());
        // naive row-major sum with libm::exp: agreement to rounding (the
        // sum of |terms| bounds the cancellation)
        let (mut naive, mut mag) = (0.0, 0.0);
        for i in 0..n {
            let mut r2 = 0.0;
            for j in 0..d {
                let u = inputs[j * n + i] - q[j];
                r2 += u * u;
            }
            let t = 1.7 * libm::exp(-0.5 * r2) * w[i];
            naive += t;
            mag += t.abs();
        }
        assert!((fused - naive).abs() <= 1e-15 * mag, "{fused} vs {naive}");
    }

    #[test]
    fn kernel_row_sums_the_dimensions_in_order_for_every_d() {
        // d = 1…26 covers the fixed-dimension paths (≤ 8) and the
        // any-dimension path with 0–3 columns past its groups of four.
        // Reference: r² summed from 0 in column order, then
        // kernel_from_sqdist; bit for bit, and within 1e-15 of libm's exp.
        let n = 70;
        for d in 1..=26 {
            let inputs: std::vec::Vec<f64> = (0..n * d)
                .map(|i| ((i as f64 * 0.754_877_666_246_692_7) % 1.0) * 2.0 - 1.0)
                .collect();
            let q: std::vec::Vec<f64> = (0..d).map(|j| 0.1 * j as f64 - 0.5).collect();
            let mut got = std::vec![0.0; n];
            kernel_row(&inputs, n, &q, 1.3, &mut got).unwrap();
            let mut r2 = std::vec![0.0; n];
            for (i, r) in r2.iter_mut().enumerate() {
                for j in 0..d {
                    let u = inputs[j * n + i] - q[j];
                    *r += u * u;
                }
            }
            let naive: std::vec::Vec<f64> = r2.iter().map(|r| 1.3 * libm::exp(-0.5 * r)).collect();
            kernel_from_sqdist(1.3, &mut r2);
            for i in 0..n {
                assert_eq!(got[i].to_bits(), r2[i].to_bits(), "d {d} i {i}");
                assert!((got[i] - naive[i]).abs() <= 1e-15 * naive[i], "d {d} i {i}");
            }
        }
    }

    #[test]
    fn kernel_row_range_is_a_slice_of_kernel_row() {
        const N: usize = 150;
        const D: usize = 3;
        let n = N;
        let mut inputs = [0.0; N * D];
        for (i, v) in inputs.iter_mut().enumerate() {
            *v = ((i as f64 * 0.754_877_666_246_692_7) % 1.0) * 4.0 - 2.0;
        }
        let q = [0.3, -0.2, 0.9];
        let mut full = [0.0; N];
        kernel_row(&inputs, n, &q, 1.7, &mut full).unwrap();
        // starts off the block grid, ranges crossing blocks, empty, to the end
        for (start, len) in [
            (0, 150),
            (1, 149),
            (63, 2),
            (65, 80),
            (149, 1),
            (150, 0),
            (7, 0),
        ] {
            let mut part = [0.0; N];
            kernel_row_range(&inputs, n, &q, 1.7, start, &mut part[..len]).unwrap();
            for i in 0..len {
                assert_eq!(part[i].to_bits(), full[start + i].to_bits(), "{start} {i}");
            }
        }
        let mut out = [0.0; 3];
        assert!(kernel_row_range(&inputs, n, &q, 1.7, 148, &mut out).is_err());
        assert!(kernel_row_range(&inputs, n, &q, 1.7, usize::MAX, &mut out).is_err());
        assert!(kernel_row_range(&inputs, n, &q[..2], 1.7, 0, &mut out).is_err());
    }

    #[test]
    fn every_dimension_path_gives_the_same_bits() {
        // d = 1..=8 take the fixed-dimension path, d = 9 the generic one;
        // both sum over j in ascending order, so they agree bit for bit.
        let n = 70;
        let mut inputs = [0.0; 9 * 70];
        for (i, v) in inputs.iter_mut().enumerate() {
            *v = ((i as f64 * 0.569_840_290_998_053_3) % 1.0) * 6.0 - 3.0;
        }
        let q = [0.4, -1.1, 0.2, 2.5, -0.3, 0.0, 1.7, -2.2, 0.9];
        for d in 1..=9 {
            let x = &inputs[..d * n];
            let mut fixed = [0.0; 70];
            let mut any = [0.0; 70];
            for (start, (a, b)) in fixed
                .chunks_mut(BLOCK)
                .zip(any.chunks_mut(BLOCK))
                .enumerate()
            {
                block_kernel(x, n, &q[..d], 0.8, start * BLOCK, a);
                block_kernel_any(x, n, &q[..d], 0.8, start * BLOCK, b);
            }
            for (a, b) in fixed.iter().zip(&any) {
                assert_eq!(a.to_bits(), b.to_bits(), "d = {d}");
            }
        }
    }

    #[test]
    fn kernel_is_zero_beyond_the_cutoff_only() {
        // one dimension, query at 0: r² = x²
        let inputs = [libm::sqrt(689.0), libm::sqrt(691.0), 0.0];
        let mut k = [0.0; 3];
        kernel_row(&inputs, 3, &[0.0], 2.0, &mut k).unwrap();
        let e = 2.0 * libm::exp(-0.5 * inputs[0] * inputs[0]);
        assert!((k[0] - e).abs() <= 1e-15 * e && k[0] > 0.0);
        assert_eq!(k[1], 0.0);
        assert_eq!(k[2], 2.0);
    }

    #[test]
    fn forward_solve_matches_dense() {
        // L = [[2,0,0],[1,3,0],[-1,0.5,4]] packed by columns
        let l = [2.0, 1.0, -1.0, 3.0, 0.5, 4.0];
        let y = [1.0, -2.0, 0.5];
        // b = L·y
        let mut b = [2.0, 1.0 - 6.0, -1.0 - 1.0 + 2.0];
        forward_solve_packed(&l, &mut b).unwrap();
        for (a, e) in b.iter().zip(&y) {
            assert!((a - e).abs() < 1e-15);
        }
        assert!(forward_solve_packed(&l[..5], &mut b).is_err());
    }

    static X: [f64; 4] = [-1.0, 1.0, 0.0, 0.5];
    static W: [f64; 2] = [0.5, -0.25];

    fn gp() -> ExportedGp<'static, 2> {
        ExportedGp {
            inputs: &X,
            weights: &W,
            length_scales: [0.7, 1.3],
            signal_variance: 1.5,
            input_shift: [0.1, -0.2],
            input_scale: [2.0, 0.5],
            output_scale: 3.0,
            prior_mean: 0.25,
            cholesky: None,
        }
    }

    #[test]
    fn mean_matches_formula_and_errors_are_typed() {
        let g = gp();
        g.validate().unwrap();
        let x = [0.4, 0.1];
        let m = g.predict_mean(&x).unwrap();
        let q = [((0.4 - 0.1) / 2.0) / 0.7, ((0.1 + 0.2) / 0.5) / 1.3];
        let k0 = 1.5 * libm::exp(-0.5 * (sq(-1.0 - q[0]) + sq(0.0 - q[1])));
        let k1 = 1.5 * libm::exp(-0.5 * (sq(1.0 - q[0]) + sq(0.5 - q[1])));
        let want = 0.25 + 3.0 * (0.5 * k0 - 0.25 * k1);
        assert!((m - want).abs() < 1e-15 * want.abs(), "{m} vs {want}");

        assert_eq!(
            g.predict_mean(&[f64::NAN, 0.0]),
            Err(GpError::NonFiniteInput { index: 0 })
        );
        assert_eq!(
            g.predict_mean(&[0.0, f64::INFINITY]),
            Err(GpError::NonFiniteInput { index: 1 })
        );
        assert_eq!(g.predict(&x, &mut [0.0; 2]), Err(GpError::NoCholesky));
        let bad = ExportedGp {
            inputs: &X[..3],
            ..gp()
        };
        assert!(matches!(
            bad.predict_mean(&x),
            Err(GpError::InvalidModel(_))
        ));
        let bad = ExportedGp {
            input_scale: [0.0, 1.0],
            ..gp()
        };
        assert!(matches!(bad.validate(), Err(GpError::InvalidValue { .. })));
    }

    #[test]
    fn variance_matches_dense_formula() {
        // K + σ²I for the two points above, its Cholesky, packed.
        let g0 = gp();
        let k01 = 1.5 * libm::exp(-0.5 * (sq(2.0) + sq(0.5)));
        let a = [[1.5 + 0.1, k01], [k01, 1.5 + 0.1]];
        let l00 = libm::sqrt(a[0][0]);
        let l10 = a[1][0] / l00;
        let l11 = libm::sqrt(a[1][1] - l10 * l10);
        let l = [l00, l10, l11];
        let g = ExportedGp {
            cholesky: Some(&l),
            ..g0
        };
        g.validate().unwrap();
        let x = [0.4, 0.1];
        let mut scratch = [0.0; 2];
        let (m, v) = g.predict(&x, &mut scratch).unwrap();
        assert_eq!(m.to_bits(), g.predict_mean(&x).unwrap().to_bits());
        // var = s²(σ_f² − kᵀA⁻¹k) with the explicit 2×2 inverse
        let q = [((0.4 - 0.1) / 2.0) / 0.7, ((0.1 + 0.2) / 0.5) / 1.3];
        let k0 = 1.5 * libm::exp(-0.5 * (sq(-1.0 - q[0]) + sq(0.0 - q[1])));
        let k1 = 1.5 * libm::exp(-0.5 * (sq(1.0 - q[0]) + sq(0.5 - q[1])));
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        let quad = (a[1][1] * k0 * k0 - 2.0 * a[0][1] * k0 * k1 + a[0][0] * k1 * k1) / det;
        let want = 9.0 * (1.5 - quad);
        assert!((v - want).abs() < 1e-13 * want, "{v} vs {want}");
        assert_eq!(
            g.predict(&x, &mut [0.0; 1]),
            Err(GpError::ScratchTooSmall { needed: 2, got: 1 })
        );
    }
}
