//! Gram matrix, Cholesky with jitter escalation, log marginal likelihood and
//! its analytic gradient.
//!
//! Cost per evaluation: O(N²d) to build K, N³/3 flops for the Cholesky and
//! (gradient only) N³/3 for L⁻¹ plus N³/3 for (K+σ²I)⁻¹ = L⁻ᵀL⁻¹, plus one
//! fused O(N²d) pass over the lower triangle for all gradient components.
//! Memory: four N×N matrices, held in an [`LmlWorkspace`] that the optimiser
//! reuses across evaluations (one workspace per restart).
//!
//! **Subnormals.** Short length scales make K nearly diagonal; its tiny
//! off-diagonal entries, and the fill-in of the Cholesky factor and its
//! inverse (whose entries decay geometrically away from the diagonal), then
//! underflow into the subnormal range, where every floating-point operation
//! takes a slow microcode path (measured: one evaluation at N = 512, ℓ = 0.05
//! took 110 ms instead of 8 ms). Without touching the floating-point
//! environment (flush-to-zero is undefined behaviour in Rust), we keep
//! subnormals out of the hot loops: kernel entries below e^{−345} ≈ 1e-150
//! (relative to σ_f²) are set to 0, and the blocked Cholesky and triangular
//! inverse below set entries below 1e-100 of their natural scale to 0 after
//! each block step, so every product in the next level-3 update is a normal
//! number. Those perturbations are more than 80 orders of magnitude below
//! rounding error (ε ≈ 2e-16 relative).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::matmul::triangular::{self as trmm, BlockStructure};
use faer::linalg::triangular_inverse::invert_lower_triangular;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, Par};

use vigp_core::gp as core_gp;

use crate::error::GpError;
use crate::kernel::Hyperparameters;

/// Jitter ladder: first try relative jitter `JITTER_START` (times the
/// diagonal σ_f² + σ_n²), multiply by 10 until `JITTER_MAX`.
const JITTER_START: f64 = 1e-12;
pub(crate) const JITTER_MAX: f64 = 1e-3;

/// Block size of the blocked Cholesky and triangular inverse.
const NB: usize = 64;

/// Entries of L (relative to √(σ_f² + σ_n²)) and of L⁻¹ (relative to
/// 1/√(σ_f² + σ_n²)) below this are set to 0 during the blocked algorithms.
const SCRUB: f64 = 1e-100;

/// A factorised training Gram matrix A = K + (σ_n² + jitter)·I = L·Lᵀ.
pub(crate) struct Factor {
    /// Lower-triangular Cholesky factor (upper part is garbage, never read).
    pub l: Mat<f64>,
    /// Absolute jitter added to the diagonal (0 if none was needed).
    pub jitter: f64,
}

/// Buffers for repeated likelihood evaluations on the same data size: the
/// optimiser keeps one per restart, so an evaluation allocates nothing of
/// size N² (the N×N matrices are created on first use and then reused).
pub(crate) struct LmlWorkspace {
    n: usize,
    /// Inputs scaled by the current length scales, column-major d × N
    /// (dimension j of point a at `j·N + a`), the layout of the vectorised
    /// kernel rows.
    xs: Vec<f64>,
    /// Noise-free kernel matrix K_f (lower triangle).
    kf: Mat<f64>,
    /// Cholesky factor L of K_f + (σ_n² + jitter)·I (lower triangle).
    l: Mat<f64>,
    /// L⁻¹ (lower triangle), gradient only.
    linv: Mat<f64>,
    /// A⁻¹ = L⁻ᵀL⁻¹ (lower triangle), gradient only.
    ainv: Mat<f64>,
    /// NB × N scratch for the blocked triangular inverse.
    tmp: Mat<f64>,
    alpha: Vec<f64>,
    /// One column's gradient weights (α_aα_b − A⁻¹_ab)·K_ab, gradient only.
    kw: Vec<f64>,
    /// Scratch of faer's Cholesky of one NB × NB diagonal block.
    mem: MemBuffer,
}

impl LmlWorkspace {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            n,
            xs: Vec::new(),
            kf: Mat::zeros(n, n),
            l: Mat::zeros(n, n),
            linv: Mat::new(),
            ainv: Mat::new(),
            tmp: Mat::new(),
            alpha: vec![0.0; n],
            kw: Vec::new(),
            mem: MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
                NB.min(n),
                Par::Seq,
                Default::default(),
            )),
        }
    }

    fn ensure_gradient_buffers(&mut self) {
        let n = self.n;
        if self.linv.nrows() != n {
            self.linv = Mat::zeros(n, n);
            self.ainv = Mat::zeros(n, n);
            self.tmp = Mat::zeros(NB.min(n), n);
            self.kw = vec![0.0; n];
        }
    }
}

/// x scaled by the length scales: xs[i, j] = x[i, j] / ℓ_j (row-major).
pub(crate) fn scale_inputs(x: &[f64], d: usize, ls: &[f64]) -> Vec<f64> {
    let mut xs = Vec::with_capacity(x.len());
    scale_inputs_into(x, d, ls, &mut xs);
    xs
}

fn scale_inputs_into(x: &[f64], d: usize, ls: &[f64], xs: &mut Vec<f64>) {
    xs.clear();
    xs.extend_from_slice(x);
    for row in xs.chunks_exact_mut(d) {
        for (v, l) in row.iter_mut().zip(ls) {
            *v /= l;
        }
    }
}

/// x (row-major N × d) scaled by the length scales, transposed:
/// xs[j·N + a] = x[a, j] / ℓ_j (column-major d × N).
fn scale_inputs_colmajor_into(x: &[f64], d: usize, ls: &[f64], xs: &mut Vec<f64>) {
    let n = x.len() / d.max(1);
    xs.clear();
    xs.resize(x.len(), 0.0);
    for (a, row) in x.chunks_exact(d).enumerate() {
        for (j, (v, l)) in row.iter().zip(ls).enumerate() {
            xs[j * n + a] = v / l;
        }
    }
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

#[inline]
fn col_slice(m: &Mat<f64>, j: usize) -> &[f64] {
    m.col(j)
        .try_as_col_major()
        .expect("Mat columns are contiguous")
        .as_slice()
}

/// Noise-free kernel matrix K_f (lower triangle incl. diagonal) from scaled
/// inputs `xs` (column-major d × N); entries below e^{−R2_CUTOFF/2}·σ_f²
/// ([`core_gp::R2_CUTOFF`])
/// are stored as 0. Column b below the diagonal is one
/// [`core_gp::kernel_row_range`], compiled for AVX2 where the CPU has it
/// (pulp's dispatch; the same bits on every path: elementwise arithmetic,
/// the exponential within 1 ulp of the correctly rounded one). With AVX2
/// the squared distances are computed four columns at a time instead
/// ([`sqdist_tile_avx2`]), summed in the same order, so the same bits.
fn kernel_lower_into(xs: &[f64], n: usize, d: usize, sf2: f64, k: &mut Mat<f64>) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        let op = simd_op!(<'a> {
            simd: pulp::x86::V3,
            xs: &'a [f64],
            n: usize,
            d: usize,
            sf2: f64,
            k: &'a mut Mat<f64>,
        } -> () {
            kernel_lower_avx2(simd, xs, n, d, sf2, k)
        });
        return pulp::Simd::vectorize(simd, op);
    }
    let op = simd_op!(<'a> {
        xs: &'a [f64],
        n: usize,
        d: usize,
        sf2: f64,
        k: &'a mut Mat<f64>,
    } -> () {
        kernel_columns(xs, n, d, sf2, k, 0..n)
    });
    pulp::Arch::new().dispatch(op);
}

/// Columns `cols` of [`kernel_lower_into`], one [`kernel_column`] each.
#[inline(always)]
fn kernel_columns(
    xs: &[f64],
    n: usize,
    d: usize,
    sf2: f64,
    k: &mut Mat<f64>,
    cols: core::ops::Range<usize>,
) {
    let mut q = vec![0.0; d];
    for b in cols {
        kernel_column(xs, n, sf2, &mut q, k, b, n);
    }
}

/// Column b of K_f from its diagonal σ_f² down to row `end` (exclusive):
/// one [`core_gp::kernel_row_range`], with `q` (length d) as the buffer
/// for input b.
#[inline(always)]
fn kernel_column(
    xs: &[f64],
    n: usize,
    sf2: f64,
    q: &mut [f64],
    k: &mut Mat<f64>,
    b: usize,
    end: usize,
) {
    for (j, qj) in q.iter_mut().enumerate() {
        *qj = xs[j * n + b];
    }
    let col = k
        .col_mut(b)
        .try_as_col_major_mut()
        .expect("Mat columns are contiguous")
        .as_slice_mut();
    col[b] = sf2;
    core_gp::kernel_row_range(xs, n, q, sf2, b + 1, &mut col[b + 1..end])
        .expect("shapes fixed by the workspace");
}

/// [`kernel_lower_into`] with AVX2: for each group of four columns
/// b₀…b₀+3, the small triangle above row b₀+4 column by column, then the
/// rows below it for all four columns at once ([`sqdist_tile_avx2`]), so
/// that each input is read once per four columns instead of once per
/// column; the columns past the last group of four one by one.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn kernel_lower_avx2(
    simd: pulp::x86::V3,
    xs: &[f64],
    n: usize,
    d: usize,
    sf2: f64,
    k: &mut Mat<f64>,
) {
    const T: usize = 4;
    let groups = n / T;
    let mut q = vec![0.0; d];
    for g in 0..groups {
        let b0 = T * g;
        // the triangle: rows b0 + 1 .. b0 + T of each column
        for b in b0..b0 + T {
            kernel_column(xs, n, sf2, &mut q, k, b, b0 + T);
        }
        // the rows below, four columns at once
        let r0 = b0 + T;
        if r0 < n {
            let block = k.as_mut().submatrix_mut(r0, b0, n - r0, T);
            let (c0, rest) = block.split_at_col_mut(1);
            let (c1, rest) = rest.split_at_col_mut(1);
            let (c2, c3) = rest.split_at_col_mut(1);
            let mut out = [c0, c1, c2, c3].map(single_col_slice);
            sqdist_tile_avx2(simd, xs, n, d, b0, r0, &mut out);
            for o in out {
                core_gp::kernel_from_sqdist(sf2, o);
            }
        }
    }
    for b in T * groups..n {
        kernel_column(xs, n, sf2, &mut q, k, b, n);
    }
}

/// The entries of a one-column block of a column-major matrix.
fn single_col_slice(c: MatMut<'_, f64>) -> &mut [f64] {
    c.col_mut(0)
        .try_as_col_major_mut()
        .expect("Mat columns are contiguous")
        .as_slice_mut()
}

/// out[c][i] = Σ_j (x̃_j,r0+i − x̃_j,b0+c)² for c = 0..3, each sum from 0
/// in column order j = 0, 1, …, d − 1, the order of
/// [`core_gp::kernel_row_range`], so the same bits. Eight rows by four
/// columns are held in eight AVX2 registers through all d dimensions.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sqdist_tile_avx2(
    simd: pulp::x86::V3,
    xs: &[f64],
    n: usize,
    d: usize,
    b0: usize,
    r0: usize,
    out: &mut [&mut [f64]; 4],
) {
    use pulp::{Simd, x86::V3};
    let rows = n - r0;
    let full = rows / 8 * 8;
    let mut i = 0;
    while i < full {
        let zero = simd.splat_f64s(0.0);
        let mut s = [[zero; 2]; 4];
        for j in 0..d {
            let xc = &xs[j * n..(j + 1) * n];
            let (xv, _) = V3::as_simd_f64s(&xc[r0 + i..r0 + i + 8]);
            for (c, sc) in s.iter_mut().enumerate() {
                let q = simd.splat_f64s(xc[b0 + c]);
                for (h, sh) in sc.iter_mut().enumerate() {
                    let u = simd.sub_f64s(xv[h], q);
                    *sh = simd.add_f64s(*sh, simd.mul_f64s(u, u));
                }
            }
        }
        for (o, sc) in out.iter_mut().zip(&s) {
            let (ov, _) = V3::as_mut_simd_f64s(&mut o[i..i + 8]);
            ov[0] = sc[0];
            ov[1] = sc[1];
        }
        i += 8;
    }
    for (c, o) in out.iter_mut().enumerate() {
        for (ii, v) in o[full..rows].iter_mut().enumerate() {
            let mut acc = 0.0;
            for j in 0..d {
                let u = xs[j * n + r0 + full + ii] - xs[j * n + b0 + c];
                acc += u * u;
            }
            *v = acc;
        }
    }
}

/// The strict-lower-triangle pass of the gradient: adds
/// Σ_{a>b} W_ab·K_ab·(x̃_aj − x̃_bj)² to `gl[j]` (W = ααᵀ − A⁻¹) and
/// returns Σ_a W_aa. Column b's weights W_ab·K_ab go to `kw` once, then
/// each dimension is one contiguous multiply-add pass over that column
/// ([`weighted_sqdist_sum`]: 8 interleaved partial sums in a fixed order,
/// so the bits are the same on every run and thread count). Where the CPU
/// has AVX2 (detected at run time) the partial sums are two 256-bit
/// registers with the same arithmetic, so the same bits: left to the
/// compiler, the 8 sums came out as a mix of 128-bit and scalar
/// instructions, and the pass took 1.6× as long (N = 512, d = 24).
#[allow(clippy::too_many_arguments)]
fn gradient_pass(
    xs: &[f64],
    n: usize,
    d: usize,
    alpha: &[f64],
    ainv: &Mat<f64>,
    kf: &Mat<f64>,
    kw: &mut [f64],
    gl: &mut [f64],
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        let op = simd_op!(<'a> {
            simd: pulp::x86::V3,
            xs: &'a [f64],
            n: usize,
            d: usize,
            alpha: &'a [f64],
            ainv: &'a Mat<f64>,
            kf: &'a Mat<f64>,
            kw: &'a mut [f64],
            gl: &'a mut [f64],
        } -> f64 {
            gradient_pass_with(n, d, alpha, ainv, kf, kw, gl, |w, b, gl| {
                for (j, g) in gl.iter_mut().enumerate() {
                    let col = &xs[j * n + b + 1..(j + 1) * n];
                    *g += weighted_sqdist_sum_avx2(simd, w, col, xs[j * n + b]);
                }
            })
        });
        return pulp::Simd::vectorize(simd, op);
    }
    gradient_pass_with(n, d, alpha, ainv, kf, kw, gl, |w, b, gl| {
        for (j, g) in gl.iter_mut().enumerate() {
            *g += weighted_sqdist_sum(w, &xs[j * n + b + 1..(j + 1) * n], xs[j * n + b]);
        }
    })
}

/// [`gradient_pass`] with `sums(w, b, gl)` adding each dimension j's
/// Σ_{a>b} w_a·(x̃_aj − x̃_bj)² to `gl[j]`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn gradient_pass_with(
    n: usize,
    d: usize,
    alpha: &[f64],
    ainv: &Mat<f64>,
    kf: &Mat<f64>,
    kw: &mut [f64],
    gl: &mut [f64],
    sums: impl Fn(&[f64], usize, &mut [f64]),
) -> f64 {
    let mut w_diag = 0.0;
    for b in 0..n {
        let ac = col_slice(ainv, b);
        let kc = col_slice(kf, b);
        let ab = alpha[b];
        w_diag += ab * ab - ac[b];
        let w = &mut kw[b + 1..n];
        for (((w, &aa), &ai), &k) in w
            .iter_mut()
            .zip(&alpha[b + 1..n])
            .zip(&ac[b + 1..n])
            .zip(&kc[b + 1..n])
        {
            *w = (aa * ab - ai) * k;
        }
        sums(w, b, &mut gl[..d]);
    }
    w_diag
}

/// Partial sums of [`weighted_sqdist_sum`].
const LANES: usize = 8;

/// Σ_a w_a·(x_a − x_b)² with element a added to partial sum a mod 8, and
/// the 8 sums added pairwise at the end (`w.len() == x.len()`).
#[inline(always)]
fn weighted_sqdist_sum(w: &[f64], x: &[f64], xb: f64) -> f64 {
    let mut acc = [0.0; LANES];
    let mut cw = w.chunks_exact(LANES);
    let mut cx = x.chunks_exact(LANES);
    for (wl, xl) in (&mut cw).zip(&mut cx) {
        for l in 0..LANES {
            let u = xl[l] - xb;
            acc[l] += wl[l] * (u * u);
        }
    }
    weighted_sqdist_tail(acc, cw.remainder(), cx.remainder(), xb)
}

/// The elements past the last full group of 8, then the pairwise sum.
#[inline(always)]
fn weighted_sqdist_tail(mut acc: [f64; LANES], w: &[f64], x: &[f64], xb: f64) -> f64 {
    for (l, (wl, xl)) in w.iter().zip(x).enumerate() {
        let u = xl - xb;
        acc[l] += wl * (u * u);
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// [`weighted_sqdist_sum`] with partial sums 0–3 and 4–7 in two AVX2
/// registers (separate multiply and add, as the portable code): the same
/// bits.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn weighted_sqdist_sum_avx2(simd: pulp::x86::V3, w: &[f64], x: &[f64], xb: f64) -> f64 {
    use pulp::{Simd, x86::V3};
    let full = w.len() / LANES * LANES;
    let (wv, _) = V3::as_simd_f64s(&w[..full]);
    let (xv, _) = V3::as_simd_f64s(&x[..full]);
    let b = simd.splat_f64s(xb);
    let (mut a0, mut a1) = (simd.splat_f64s(0.0), simd.splat_f64s(0.0));
    for (wp, xp) in wv.chunks_exact(2).zip(xv.chunks_exact(2)) {
        let u0 = simd.sub_f64s(xp[0], b);
        let u1 = simd.sub_f64s(xp[1], b);
        a0 = simd.add_f64s(a0, simd.mul_f64s(wp[0], simd.mul_f64s(u0, u0)));
        a1 = simd.add_f64s(a1, simd.mul_f64s(wp[1], simd.mul_f64s(u1, u1)));
    }
    let acc = [a0.0, a0.1, a0.2, a0.3, a1.0, a1.1, a1.2, a1.3];
    weighted_sqdist_tail(acc, &w[full..], &x[full..], xb)
}

/// Sets the entries of `m` with |v| < tau to 0 (`m` has unit row stride).
fn scrub(mut m: MatMut<'_, f64>, tau: f64) {
    for j in 0..m.ncols() {
        let col = m
            .rb_mut()
            .col_mut(j)
            .try_as_col_major_mut()
            .expect("column-major block")
            .as_slice_mut();
        for v in col {
            if v.abs() < tau {
                *v = 0.0;
            }
        }
    }
}

/// Right-looking blocked Cholesky of the lower triangle of `a` in place,
/// setting panel entries below `tau` to 0 (see the module docs). Returns
/// false if a pivot is not positive and finite.
fn cholesky_blocked(mut a: MatMut<'_, f64>, tau: f64, par: Par, mem: &mut MemBuffer) -> bool {
    let n = a.nrows();
    let mut k = 0;
    while k < n {
        let kb = NB.min(n - k);
        let (mut a11, _, mut a21, a22) = a
            .rb_mut()
            .submatrix_mut(k, k, n - k, n - k)
            .split_at_mut(kb, kb);
        if llt::factor::cholesky_in_place(
            a11.rb_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(mem),
            Default::default(),
        )
        .is_err()
            || (0..kb).any(|i| !(a11[(i, i)].is_finite() && a11[(i, i)] > 0.0))
        {
            return false;
        }
        for j in 0..kb {
            for i in j + 1..kb {
                if a11[(i, j)].abs() < tau {
                    a11[(i, j)] = 0.0;
                }
            }
        }
        if kb < n - k {
            scrub(a21.rb_mut(), tau);
            // A21 ← A21·L11⁻ᵀ, i.e. L11·A21ᵀ = A21ᵀ.
            solve_lower_triangular_in_place(a11.rb(), a21.rb_mut().transpose_mut(), par);
            scrub(a21.rb_mut(), tau);
            // A22 ← A22 − A21·A21ᵀ (lower triangle).
            trmm::matmul(
                a22,
                BlockStructure::TriangularLower,
                Accum::Add,
                a21.rb(),
                BlockStructure::Rectangular,
                a21.rb().transpose(),
                BlockStructure::Rectangular,
                -1.0,
                par,
            );
        }
        k += kb;
    }
    true
}

/// X = L⁻¹ (lower triangle) by block rows, X[r, :r] = −L_rr⁻¹·(L[r, :r]·X[:r, :r]),
/// setting entries below `tau` to 0 after each block row.
fn invert_lower_blocked(l: &Mat<f64>, x: &mut Mat<f64>, tmp: &mut Mat<f64>, tau: f64, par: Par) {
    let n = l.nrows();
    let mut r0 = 0;
    while r0 < n {
        let rb = NB.min(n - r0);
        invert_lower_triangular(
            x.as_mut().submatrix_mut(r0, r0, rb, rb),
            l.as_ref().submatrix(r0, r0, rb, rb),
            par,
        );
        if r0 > 0 {
            let mut t = tmp.as_mut().submatrix_mut(0, 0, rb, r0);
            trmm::matmul(
                t.rb_mut(),
                BlockStructure::Rectangular,
                Accum::Replace,
                l.as_ref().submatrix(r0, 0, rb, r0),
                BlockStructure::Rectangular,
                x.as_ref().submatrix(0, 0, r0, r0),
                BlockStructure::TriangularLower,
                1.0,
                par,
            );
            let (left, diag) = x
                .as_mut()
                .submatrix_mut(r0, 0, rb, r0 + rb)
                .split_at_col_mut(r0);
            trmm::matmul(
                left,
                BlockStructure::Rectangular,
                Accum::Replace,
                diag.rb(),
                BlockStructure::TriangularLower,
                t.rb(),
                BlockStructure::Rectangular,
                -1.0,
                par,
            );
        }
        scrub(x.as_mut().submatrix_mut(r0, 0, rb, r0), tau);
        r0 += rb;
    }
}

/// Factorises K_f + (σ_n² + jitter)·I from `ws.kf` into `ws.l`, escalating
/// the jitter from `start_jitter` (absolute; 0 = try without first). Returns
/// the jitter used.
fn factorise_ws(
    ws: &mut LmlWorkspace,
    hp: &Hyperparameters,
    start_jitter: f64,
    par: Par,
) -> Result<f64, GpError> {
    let n = ws.n;
    let diag_scale = hp.signal_variance + hp.noise_variance;
    let tau = SCRUB * diag_scale.sqrt();
    let mut jitter = start_jitter;
    loop {
        for j in 0..n {
            let src = &col_slice(&ws.kf, j)[j..];
            let dst = &mut ws
                .l
                .col_mut(j)
                .try_as_col_major_mut()
                .expect("contiguous")
                .as_slice_mut()[j..];
            dst.copy_from_slice(src);
            dst[0] += hp.noise_variance + jitter;
        }
        if cholesky_blocked(ws.l.as_mut(), tau, par, &mut ws.mem) {
            return Ok(jitter);
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

/// Cholesky of K_f + (σ_n² + jitter)·I from the scaled inputs `xs_cols`
/// (column-major d × N), escalating the jitter from `start_jitter`
/// (absolute; 0 = try without first) until it succeeds.
pub(crate) fn factorise(
    xs_cols: &[f64],
    n: usize,
    d: usize,
    hp: &Hyperparameters,
    start_jitter: f64,
    par: Par,
) -> Result<Factor, GpError> {
    let mut ws = LmlWorkspace::new(n);
    kernel_lower_into(xs_cols, n, d, hp.signal_variance, &mut ws.kf);
    let jitter = factorise_ws(&mut ws, hp, start_jitter, par)?;
    Ok(Factor { l: ws.l, jitter })
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

/// One-off [`lml_ws`] with a fresh workspace.
pub(crate) fn lml(
    x: &[f64],
    n: usize,
    d: usize,
    y: &[f64],
    log_params: &[f64],
    grad: bool,
    par: Par,
) -> Result<LmlEval, GpError> {
    lml_ws(&mut LmlWorkspace::new(n), x, d, y, log_params, grad, par)
}

/// log p(y | X, θ) = −½ yᵀα − ½ ln det A − (N/2) ln 2π, and (if `grad`) its
/// gradient w.r.t. θ = (ln ℓ, ln σ_f², ln σ_n²):
/// ∂/∂θ_k = ½ tr(W ∂A/∂θ_k) with W = ααᵀ − A⁻¹, where
/// ∂A/∂ln ℓ_k = K ∘ D_k (D_k,ab = (x_ak − x_bk)²/ℓ_k²), ∂A/∂ln σ_f² = K and
/// ∂A/∂ln σ_n² = σ_n² I. The length-scale components come from one pass over
/// the strict lower triangle (W and K are symmetric, D_k vanishes on the
/// diagonal), the σ_f² one from ½ tr(W K) = ½(yᵀα − N) − ½λ tr W
/// (λ = σ_n² + jitter).
pub(crate) fn lml_ws(
    ws: &mut LmlWorkspace,
    x: &[f64],
    d: usize,
    y: &[f64],
    log_params: &[f64],
    grad: bool,
    par: Par,
) -> Result<LmlEval, GpError> {
    let n = ws.n;
    let hp = Hyperparameters::from_log(log_params)?;
    scale_inputs_colmajor_into(x, d, &hp.length_scales, &mut ws.xs);
    kernel_lower_into(&ws.xs, n, d, hp.signal_variance, &mut ws.kf);
    let jitter = factorise_ws(ws, &hp, 0.0, par)?;
    ws.alpha.copy_from_slice(y);
    {
        // α = L⁻ᵀL⁻¹y with faer's blocked, vectorised triangular solves.
        let mut a = faer::MatMut::from_column_major_slice_mut(&mut ws.alpha, n, 1);
        solve_lower_triangular_in_place(ws.l.as_ref(), a.rb_mut(), Par::Seq);
        solve_upper_triangular_in_place(ws.l.as_ref().transpose(), a, Par::Seq);
    }
    let alpha = &ws.alpha;
    let fit: f64 = y.iter().zip(alpha).map(|(a, b)| a * b).sum();
    let value =
        -0.5 * fit - 0.5 * log_det(&ws.l) - 0.5 * n as f64 * (2.0 * core::f64::consts::PI).ln();
    if !value.is_finite() {
        return Err(GpError::NotPositiveDefinite { jitter });
    }
    let mut gradient = Vec::new();
    if grad {
        ws.ensure_gradient_buffers();
        let tau = SCRUB / (hp.signal_variance + hp.noise_variance).sqrt();
        invert_lower_blocked(&ws.l, &mut ws.linv, &mut ws.tmp, tau, par);
        trmm::matmul(
            ws.ainv.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Replace,
            ws.linv.as_ref().transpose(),
            BlockStructure::TriangularUpper,
            ws.linv.as_ref(),
            BlockStructure::TriangularLower,
            1.0,
            par,
        );
        let mut gl = vec![0.0; d];
        let w_diag = gradient_pass(
            &ws.xs, n, d, &ws.alpha, &ws.ainv, &ws.kf, &mut ws.kw, &mut gl,
        );
        gradient.extend_from_slice(&gl);
        // ∂A/∂ln σ_f² = K = A − λI with λ = σ_n² + jitter, so
        // ½ tr(W K) = ½ tr(W A) − ½λ tr W = ½(rᵀα − N) − ½λ Σ_a W_aa
        // (tr(W A) = αᵀAα − tr I). Summing the N² products W_ab K_ab
        // instead loses up to 1e-5 relative to cancellation when σ_f² is
        // large and the length scales long (terms ~1e9 times the result).
        gradient.push(0.5 * (fit - n as f64) - 0.5 * (hp.noise_variance + jitter) * w_diag);
        gradient.push(0.5 * hp.noise_variance * w_diag);
        if gradient.iter().any(|g| !g.is_finite()) {
            return Err(GpError::NotPositiveDefinite { jitter });
        }
    }
    Ok(LmlEval { value, gradient })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quasi-random scaled inputs in [−2, 2], column-major d × n.
    fn inputs(n: usize, d: usize) -> Vec<f64> {
        (0..n * d)
            .map(|i| ((i as f64 * 0.754_877_666_246_692_7 + 0.1) % 1.0) * 4.0 - 2.0)
            .collect()
    }

    /// This CPU's AVX2 token; `None`, said on stderr, when it has no AVX2
    /// (the comparisons with the portable paths then have nothing to do).
    #[cfg(target_arch = "x86_64")]
    fn avx2() -> Option<pulp::x86::V3> {
        let simd = pulp::x86::V3::try_new();
        if simd.is_none() {
            eprintln!("no AVX2 on this CPU: nothing to compare");
        }
        simd
    }

    /// The AVX2 kernel matrix (four columns at a time) has the bits of the
    /// portable column-by-column one, for sizes off the tile grid and
    /// dimensions on both the fixed and the any-dimension paths.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_kernel_matrix_has_the_portable_bits() {
        let Some(simd) = avx2() else { return };
        for n in [1, 2, 3, 4, 5, 7, 8, 9, 12, 13, 17, 40, 75] {
            for d in [1, 3, 4, 8, 9, 12, 14, 24] {
                let xs = inputs(n, d);
                let mut fast = Mat::zeros(n, n);
                kernel_lower_into(&xs, n, d, 1.7, &mut fast);
                let mut portable = Mat::zeros(n, n);
                kernel_columns(&xs, n, d, 1.7, &mut portable, 0..n);
                let mut direct = Mat::zeros(n, n);
                simd.vectorize(|| kernel_lower_avx2(simd, &xs, n, d, 1.7, &mut direct));
                for b in 0..n {
                    for a in b..n {
                        let p = portable[(a, b)].to_bits();
                        assert_eq!(fast[(a, b)].to_bits(), p, "n {n} d {d} ({a}, {b})");
                        assert_eq!(direct[(a, b)].to_bits(), p, "n {n} d {d} ({a}, {b})");
                    }
                }
            }
        }
    }

    /// The AVX2 sums of the gradient pass have the bits of the portable
    /// ones, for lengths around the 8-lane grid.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_gradient_sums_have_the_portable_bits() {
        let Some(simd) = avx2() else { return };
        for m in 0..=41 {
            let w: Vec<f64> = (0..m).map(|i| (i as f64 * 0.37).sin() * 1e3).collect();
            let x = inputs(m, 1);
            for xb in [0.3, -1.7] {
                let portable = weighted_sqdist_sum(&w, &x, xb);
                let fast = simd.vectorize(|| weighted_sqdist_sum_avx2(simd, &w, &x, xb));
                assert_eq!(fast.to_bits(), portable.to_bits(), "m {m}");
                // and the sum itself, to rounding
                let (naive, mag) = w.iter().zip(&x).fold((0.0, 0.0), |(s, g), (w, x)| {
                    let t = w * (x - xb) * (x - xb);
                    (s + t, g + t.abs())
                });
                assert!((portable - naive).abs() <= 1e-14 * mag, "m {m}");
            }
        }
    }

    /// The gradient pass (this CPU's path) agrees with a direct double sum
    /// over the pairs to rounding (relative to the sum of |terms|).
    #[test]
    fn gradient_pass_matches_a_direct_double_sum() {
        let (n, d) = (37, 5);
        let xs = inputs(n, d);
        let mut kf = Mat::zeros(n, n);
        kernel_lower_into(&xs, n, d, 1.0, &mut kf);
        let ainv = Mat::from_fn(n, n, |a, b| 0.1 / (1.0 + (a as f64 - b as f64).abs()));
        let alpha: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).cos()).collect();
        let mut kw = vec![0.0; n];
        let mut gl = vec![0.0; d];
        let w_diag = gradient_pass(&xs, n, d, &alpha, &ainv, &kf, &mut kw, &mut gl);
        let mut want = vec![0.0; d];
        let mut mag = vec![0.0; d];
        let mut diag = 0.0;
        for b in 0..n {
            diag += alpha[b] * alpha[b] - ainv[(b, b)];
            for a in b + 1..n {
                let w = (alpha[a] * alpha[b] - ainv[(a, b)]) * kf[(a, b)];
                for j in 0..d {
                    let u = xs[j * n + a] - xs[j * n + b];
                    want[j] += w * u * u;
                    mag[j] += (w * u * u).abs();
                }
            }
        }
        assert!((w_diag - diag).abs() <= 1e-14 * n as f64);
        for j in 0..d {
            assert!(
                (gl[j] - want[j]).abs() <= 1e-14 * mag[j],
                "{j}: {} vs {}",
                gl[j],
                want[j]
            );
        }
    }
}
