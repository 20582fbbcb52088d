//! The sparse variational GP (SGPR; Titsias 2009, "Variational learning of
//! inducing variables in sparse Gaussian processes"): the collapsed evidence
//! lower bound, its analytic gradient, the posterior it defines, inducing
//! points by k-means++, and rank-one online updates.
//!
//! With M inducing inputs Z (shared by all outputs), K_uu = k(Z, Z) (plus a
//! relative jitter ε·σ_f² on its diagonal), K_uf = k(Z, X) and noise σ², the
//! bound on the log marginal likelihood is
//!
//! ```text
//! F = log N(y | 0, Q + σ²I) − tr(K_ff − Q)/(2σ²),    Q = K_fu K_uu⁻¹ K_uf,
//! ```
//!
//! computed in the well-conditioned form of GPflow's `SGPR`:
//! L_u = chol(K_uu), A = L_u⁻¹K_uf/σ, B = I + AAᵀ, L_B = chol(B),
//! v1 = B⁻¹Ay, r = y − Aᵀv1 and
//! F = −N/2·ln 2π − Σ ln (L_B)_ii − N/2·ln σ² − ½(‖r‖² + ‖v1‖²)/σ²
//!     − ½Σ_n (σ_f² − σ²‖a_n‖²)/σ²
//! (a_n the columns of A; the last sum is tr(K_ff − Q)/σ², see "Rounding").
//!
//! **Gradient.** With α = (Q + σ²I)⁻¹y = σ⁻²(y − AᵀB⁻¹Ay) and
//! u = K_uu⁻¹K_uf α = σ⁻¹L_u⁻ᵀB⁻¹Ay (which is also the weight vector of the
//! predictive mean), the partial derivatives of F are
//!
//! ```text
//! ∂F/∂K_uf = u αᵀ + σ⁻¹ L_u⁻ᵀ (I − B⁻¹) A                       (M × N)
//! ∂F/∂K_uu = −½ u uᵀ − ½ L_u⁻ᵀ (I − B⁻¹) AAᵀ L_u⁻¹                (M × M)
//! ∂F/∂σ²   = ½(αᵀα − σ⁻²(N − M + tr B⁻¹)) + tr(K_ff − Q)/(2σ⁴)
//! ```
//!
//! (from dF = ½tr((ααᵀ − Σ⁻¹)dΣ) and Σ⁻¹ = σ⁻²(I − AᵀB⁻¹A)), chained to
//! ln ℓ through ∂k/∂ln ℓ_j = k·(x_j − z_j)²/ℓ_j². σ_f² scales K_uf, K_uu
//! (with its relative jitter), Q and K_ff alike, so
//! ∂F/∂ln σ_f² = ½(αᵀQα − tr Σ⁻¹Q) − tr(K_ff − Q)/(2σ²) with
//! αᵀQα = ‖v1‖²/σ² and tr Σ⁻¹Q = M − tr B⁻¹. Nothing of size N × N is formed.
//! The same two matrices give the gradient in the inducing inputs
//! ([`elbo_z_ws`], for `SparseOptions::optimise_inducing`) through
//! ∂k(z, x)/∂z_k = k·(x_k − z_k)/ℓ_k².
//!
//! **Cost** per evaluation: M·N kernel entries (the branch-free kernels of
//! `vigp_core::gp`), the triangular solve L_u⁻¹K_uf (M²N flops), the lower
//! triangle of AAᵀ (M²N) and, for the gradient, R·A (2M²N), all through
//! faer's level-3 kernels on fixed blocks of 4096 columns (parallel over
//! blocks, partial sums added in block order: the same bits on any number
//! of threads); O(M·N·d) for the contraction and O(M³) for the rest;
//! memory two M × N matrices (K_uf and A).
//!
//! **Rounding.** With little noise the terms of F are huge and nearly
//! cancel (yᵀy/σ² against ‖L_B⁻¹Ay‖²/σ², Nσ_f²/σ² against tr AAᵀ, each of
//! size N·σ_f²/σ² ≈ 10¹² at N = 10⁵, σ_f²/σ² = 3·10⁷): summed that way F
//! would carry rounding noise ≈ 10⁻², which stalls the optimiser's line
//! searches. Instead yᵀ(Q + σ²I)⁻¹y = (‖y − Aᵀv1‖² + ‖v1‖²)/σ² (v1 = B⁻¹Ay,
//! from AAᵀ = B − I), tr(K_ff − Q) is summed point by point, and
//! ∂F/∂ln σ_f² uses the scaling identity below; log det B still carries
//! noise ≈ ε·‖B‖·tr B⁻¹ (≈ 10⁻³ in that example).
//!
//! **Prediction.** mean = k_uᵀu, latent variance
//! σ_f² − ‖L_u⁻¹k_u‖² + ‖L_B⁻¹L_u⁻¹k_u‖². M = N with Z = X gives the exact
//! GP (up to the jitter).

use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self as trimul, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, Par, Side};

use crate::error::GpError;
use crate::kernel::Hyperparameters;
use crate::likelihood::{LmlEval, sqdist};
use crate::packed;
use crate::rng::SplitMix64;
use vigp_core::gp as core_gp;

/// Relative jitter on the diagonal of K_uu (times σ_f²), the first rung of
/// the ladder; ×10 per failed Cholesky up to [`KUU_JITTER_MAX`].
pub(crate) const KUU_JITTER: f64 = 1e-10;
pub(crate) const KUU_JITTER_MAX: f64 = 1e-2;

/// Kernel entries with r² above this are 0 (as in the exact GP).
const R2_CUTOFF: f64 = 690.0;

#[inline]
fn kval(sf2: f64, r2: f64) -> f64 {
    if r2 > R2_CUTOFF {
        0.0
    } else {
        sf2 * (-0.5 * r2).exp()
    }
}

/// Inputs divided by the length scales, row-major.
fn scaled(x: &[f64], d: usize, ls: &[f64]) -> Vec<f64> {
    let mut out = x.to_vec();
    for r in out.chunks_exact_mut(d) {
        for (v, l) in r.iter_mut().zip(ls) {
            *v /= l;
        }
    }
    out
}

/// K_uu (no jitter) from scaled inducing inputs.
fn kuu(zs: &[f64], m: usize, d: usize, sf2: f64) -> Mat<f64> {
    Mat::from_fn(m, m, |i, j| {
        kval(
            sf2,
            sqdist(&zs[i * d..(i + 1) * d], &zs[j * d..(j + 1) * d]),
        )
    })
}

/// Inputs divided by the length scales, column-major d × M (the layout of
/// the shared kernels of `vigp_core::gp`).
fn scaled_cols(z: &[f64], d: usize, ls: &[f64]) -> Vec<f64> {
    let m = z.len() / d;
    let mut out = vec![0.0; m * d];
    for (i, r) in z.chunks_exact(d).enumerate() {
        for (k, (v, l)) in r.iter().zip(ls).enumerate() {
            out[k * m + i] = v / l;
        }
    }
    out
}

/// How the N columns of K_uf are split into work.
#[derive(Clone, Copy)]
struct Blocks {
    /// Columns per parallel task. The partition is fixed (it does not
    /// depend on the number of threads) and the tasks' partial sums are
    /// added in task order, so an evaluation gives the same bits
    /// sequentially and in parallel, on any number of threads.
    task: usize,
    /// Columns per dense product inside a task in the gradient pass (an
    /// M × 512 panel of R·A stays in the core's cache).
    sub: usize,
}

const BLOCKS: Blocks = Blocks {
    task: 4096,
    sub: 512,
};

/// Contiguous column `j` of a column-major faer matrix.
#[inline]
fn col(m: faer::MatRef<'_, f64>, j: usize) -> &[f64] {
    m.col(j).try_as_col_major().expect("contiguous").as_slice()
}

#[inline]
fn col_mut(m: faer::MatMut<'_, f64>, j: usize) -> &mut [f64] {
    m.col_mut(j)
        .try_as_col_major_mut()
        .expect("contiguous")
        .as_slice_mut()
}

/// Runs `f` on each task in order (sequential) or on rayon's pool, and
/// returns the results in task order either way.
fn run_tasks<T, R, F>(tasks: Vec<T>, par: Par, f: F) -> Vec<R>
where
    T: Send,
    R: Send,
    F: Fn(T) -> R + Sync + Send,
{
    use rayon::prelude::*;
    if matches!(par, Par::Seq) {
        tasks.into_iter().map(f).collect()
    } else {
        tasks.into_par_iter().map(f).collect()
    }
}

/// Σ_i h_i·(x − z_i)² with eight interleaved partial sums (vectorises).
#[inline]
fn weighted_sq(h: &[f64], z: &[f64], x: f64) -> f64 {
    let mut acc = [0.0f64; 8];
    let mut ch = h.chunks_exact(8);
    let mut cz = z.chunks_exact(8);
    for (a, b) in (&mut ch).zip(&mut cz) {
        for l in 0..8 {
            let e = x - b[l];
            acc[l] += a[l] * e * e;
        }
    }
    for (l, (a, b)) in ch.remainder().iter().zip(cz.remainder()).enumerate() {
        let e = x - b;
        acc[l] += a * e * e;
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// Lower Cholesky factor of K_uu + ε·σ_f²·I, escalating ε from
/// `start` (relative) on failure. Returns (L, ε).
fn chol_kuu(k: &Mat<f64>, sf2: f64, start: f64) -> Result<(Mat<f64>, f64), GpError> {
    let m = k.nrows();
    let mut eps = start.max(KUU_JITTER);
    loop {
        let mut a = k.clone();
        for i in 0..m {
            a[(i, i)] += eps * sf2;
        }
        if let Ok(llt) = a.llt(Side::Lower) {
            let l = llt.L().to_owned();
            if (0..m).all(|i| l[(i, i)].is_finite() && l[(i, i)] > 0.0) {
                return Ok((l, eps));
            }
        }
        eps *= 10.0;
        if eps > KUU_JITTER_MAX * 1.000_001 {
            return Err(GpError::NotPositiveDefinite { jitter: eps / 10.0 });
        }
    }
}

/// Everything an evaluation needs beyond the data, reused across
/// evaluations of one optimiser run: K_uf and A = L_u⁻¹K_uf/σ (two M × N
/// buffers).
pub(crate) struct SparseWorkspace {
    kuf: Mat<f64>,
    a: Mat<f64>,
}

impl SparseWorkspace {
    pub(crate) fn new(m: usize, n: usize) -> Self {
        Self {
            kuf: Mat::zeros(m, n),
            a: Mat::zeros(m, n),
        }
    }
}

/// The factorised sparse posterior of one output.
pub(crate) struct SparseFactor {
    /// chol(K_uu + ε·σ_f²·I), lower, packed rows.
    pub lu: Vec<f64>,
    /// chol(B), lower, packed rows.
    pub lb: Vec<f64>,
    /// A·y (M).
    pub ay: Vec<f64>,
    /// Predictive weights u (M).
    pub u: Vec<f64>,
    /// The relative K_uu jitter ε.
    pub eps: f64,
    /// The bound F.
    pub elbo: f64,
}

/// Intermediate results of one bound evaluation.
struct Core {
    /// K_uu without jitter (the gradient's K_uu term reuses it).
    kuu: Mat<f64>,
    lu: Mat<f64>,
    lb: Mat<f64>,
    eps: f64,
    ay: Vec<f64>,
    /// B⁻¹Ay
    v1: Vec<f64>,
    /// AAᵀ (both triangles).
    aat: Mat<f64>,
    /// tr(K_ff − Q), summed point by point.
    trace: f64,
    /// ‖y − Aᵀv1‖² = σ⁴‖α‖² (NaN until [`Core::finish`]).
    rr: f64,
    /// The bound F (NaN until [`Core::finish`]).
    elbo: f64,
    sigma: f64,
    /// N.
    n: usize,
    /// σ².
    s2: f64,
    /// σ_f².
    sf2: f64,
}

impl Core {
    /// Completes the bound from the residual sum ‖y − Aᵀv1‖² (computed by
    /// the residual pass of [`core`] or, with the gradient, by the
    /// gradient pass, which forms the same residuals anyway).
    fn finish(&mut self, rr: f64) -> Result<(), GpError> {
        let (n, m, s2) = (self.n, self.lb.nrows(), self.s2);
        // yᵀ(Q + σ²I)⁻¹y = (‖r‖² + ‖v1‖²)/σ², a sum of positive terms
        // (from AAᵀ = B − I), where yᵀy/σ² − ‖L_B⁻¹Ay‖²/σ² would cancel
        // terms of size N/σ².
        let fit = (rr + packed::norm2(&self.v1)) / s2;
        let logdet_b: f64 = (0..m).map(|i| self.lb[(i, i)].ln()).sum();
        let nf = n as f64;
        let elbo = -0.5 * nf * (2.0 * core::f64::consts::PI).ln()
            - logdet_b
            - 0.5 * nf * s2.ln()
            - 0.5 * fit
            - 0.5 * self.trace / s2;
        if !elbo.is_finite() {
            return Err(GpError::NotPositiveDefinite {
                jitter: self.eps * self.sf2,
            });
        }
        self.rr = rr;
        self.elbo = elbo;
        Ok(())
    }
}

/// ‖y_j − a_jᵀv1‖² summed over the columns of one task, in column order
/// (the residual pass and the gradient pass add the same terms in the
/// same order, so either gives the same bits).
#[inline]
fn residual(y: f64, a: &[f64], v1: &[f64]) -> f64 {
    y - packed::dot(a, v1)
}

/// The bound's first pass: K_uf, A = L_u⁻¹K_uf/σ, AAᵀ and Ay, column
/// block by column block (each block's kernel values, triangular solve
/// and product stay in cache), then the M × M algebra.
/// `xs` are the scaled inputs (row-major N × d), `zs` the scaled inducing
/// inputs row-major, `zc` the same column-major. With `residual_pass`
/// a last pass over A sums ‖y − Aᵀv1‖² and completes the bound; without
/// it the caller does (see [`Core::finish`]).
#[allow(clippy::too_many_arguments)]
fn core(
    ws: &mut SparseWorkspace,
    xs: &[f64],
    zs: &[f64],
    zc: &[f64],
    d: usize,
    y: &[f64],
    hp: &Hyperparameters,
    eps_start: f64,
    par: Par,
    blocks: Blocks,
    residual_pass: bool,
) -> Result<Core, GpError> {
    let n = y.len();
    let m = zs.len() / d;
    let sf2 = hp.signal_variance;
    let s2 = hp.noise_variance;
    let sigma = s2.sqrt();
    let kuu0 = kuu(zs, m, d, sf2);
    let (lu, eps) = chol_kuu(&kuu0, sf2, eps_start)?;
    let inv_sigma = 1.0 / sigma;
    // Fixed column blocks of K_uf and A.
    let mut tasks = Vec::with_capacity(n.div_ceil(blocks.task));
    {
        let (mut kr, mut ar) = (ws.kuf.as_mut(), ws.a.as_mut());
        let mut s = 0;
        while s < n {
            let w = blocks.task.min(n - s);
            let (kl, kr2) = kr.split_at_col_mut(w);
            let (al, ar2) = ar.split_at_col_mut(w);
            tasks.push((s, kl, al));
            (kr, ar) = (kr2, ar2);
            s += w;
        }
    }
    let lur = lu.as_ref();
    let parts = run_tasks(tasks, par, |(s, mut kb, mut ab)| {
        let w = kb.ncols();
        let mut aat = Mat::<f64>::zeros(m, m);
        let mut ay = vec![0.0; m];
        let mut trace = 0.0;
        // Panels of `blocks.sub` columns: kernel values, solve and product
        // of one panel while it is in cache.
        let mut p0 = 0;
        while p0 < w {
            let pw = blocks.sub.min(w - p0);
            for j in p0..p0 + pw {
                let kc = col_mut(kb.rb_mut(), j);
                let xq = &xs[(s + j) * d..(s + j + 1) * d];
                core_gp::kernel_row(zc, m, xq, sf2, kc).expect("shapes checked by construction");
                let ac = col_mut(ab.rb_mut(), j);
                for (a, k) in ac.iter_mut().zip(col(kb.rb(), j)) {
                    *a = k * inv_sigma;
                }
            }
            let mut panel = ab.rb_mut().subcols_mut(p0, pw);
            solve_lower_triangular_in_place(lur, panel.rb_mut(), Par::Seq);
            trimul::matmul(
                aat.as_mut(),
                BlockStructure::TriangularLower,
                if p0 == 0 { Accum::Replace } else { Accum::Add },
                panel.rb(),
                BlockStructure::Rectangular,
                panel.rb().transpose(),
                BlockStructure::Rectangular,
                1.0,
                Par::Seq,
            );
            // tr(K_ff − Q) point by point: σ_f² − σ²‖a_j‖² (the Nyström
            // residual of one point, small where the inducing points cover).
            for j in 0..pw {
                let yj = y[s + p0 + j];
                let ac = col(panel.rb(), j);
                for (o, a) in ay.iter_mut().zip(ac) {
                    *o += a * yj;
                }
                trace += sf2 - s2 * packed::norm2(ac);
            }
            p0 += pw;
        }
        (aat, ay, trace)
    });
    let mut aat = Mat::<f64>::zeros(m, m);
    let mut ay = vec![0.0; m];
    let mut trace = 0.0;
    for (pa, py, pt) in parts {
        for j in 0..m {
            for i in j..m {
                aat[(i, j)] += pa[(i, j)];
            }
        }
        for (o, v) in ay.iter_mut().zip(&py) {
            *o += v;
        }
        trace += pt;
    }
    for j in 0..m {
        for i in 0..j {
            aat[(i, j)] = aat[(j, i)];
        }
    }
    let mut b = aat.clone();
    for i in 0..m {
        b[(i, i)] += 1.0;
    }
    let lb = b
        .llt(Side::Lower)
        .map_err(|_| GpError::NotPositiveDefinite { jitter: eps * sf2 })?
        .L()
        .to_owned();
    // v1 = B⁻¹ A y = L_B⁻ᵀ L_B⁻¹ A y
    let mut c = Mat::<f64>::from_fn(m, 1, |i, _| ay[i]);
    solve_lower_triangular_in_place(lb.as_ref(), c.as_mut(), Par::Seq);
    solve_upper_triangular_in_place(lb.as_ref().transpose(), c.as_mut(), Par::Seq);
    let v1: Vec<f64> = (0..m).map(|i| c[(i, 0)]).collect();
    let mut out = Core {
        kuu: kuu0,
        lu,
        lb,
        eps,
        ay,
        v1,
        aat,
        trace,
        rr: f64::NAN,
        elbo: f64::NAN,
        sigma,
        n,
        s2,
        sf2,
    };
    if residual_pass {
        // The residual r = y − Aᵀv1 = σ²α, point by point (a second pass
        // over A).
        let ar = ws.a.as_ref();
        let v1 = &out.v1;
        let starts: Vec<usize> = (0..n).step_by(blocks.task).collect();
        let rr: f64 = run_tasks(starts, par, |s| {
            (s..(s + blocks.task).min(n))
                .map(|j| {
                    let r = residual(y[j], col(ar, j), v1);
                    r * r
                })
                .sum::<f64>()
        })
        .iter()
        .sum();
        out.finish(rr)?;
    }
    Ok(out)
}

/// The bound F and (if `grad`) ∂F/∂θ for θ = (ln ℓ, ln σ_f², ln σ_n²), on
/// normalised inputs `x` (row-major N × d), inducing inputs `z` (row-major
/// M × d, same units) and targets `y`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn elbo_ws(
    ws: &mut SparseWorkspace,
    x: &[f64],
    z: &[f64],
    d: usize,
    y: &[f64],
    log_params: &[f64],
    grad: bool,
    par: Par,
) -> Result<LmlEval, GpError> {
    elbo_blocks(ws, x, z, d, y, log_params, grad, false, par, BLOCKS)
}

/// [`elbo_ws`] with the gradient in the inducing inputs as well: the
/// gradient holds ∂F/∂θ (d + 2 entries) followed by ∂F/∂Z (M × d,
/// row-major, in the units of `z`).
///
/// With H = (uαᵀ + R·A) ∘ K_uf (the matrix the length-scale gradient
/// contracts) and G = ∂F/∂K_uu, ∂k(z, x)/∂z_k = k·(x_k − z_k)/ℓ_k² gives
/// ℓ_k·∂F/∂z_ik = Σ_n H_in (x̃_nk − z̃_ik) + Σ_j (G_ij + G_ji) K_ij (z̃_jk − z̃_ik)
/// (tildes: divided by ℓ_k; the diagonal of K_uu and its jitter do not
/// move with Z). Extra cost over [`elbo_ws`]: 2·M·N·d flops in the pass
/// that already contracts H, and O(M²·d).
#[allow(clippy::too_many_arguments)]
pub(crate) fn elbo_z_ws(
    ws: &mut SparseWorkspace,
    x: &[f64],
    z: &[f64],
    d: usize,
    y: &[f64],
    log_params: &[f64],
    par: Par,
) -> Result<LmlEval, GpError> {
    elbo_blocks(ws, x, z, d, y, log_params, true, true, par, BLOCKS)
}

/// [`elbo_ws`] with a given column partition (the tests vary it).
#[allow(clippy::too_many_arguments)]
fn elbo_blocks(
    ws: &mut SparseWorkspace,
    x: &[f64],
    z: &[f64],
    d: usize,
    y: &[f64],
    log_params: &[f64],
    grad: bool,
    want_z: bool,
    par: Par,
    blocks: Blocks,
) -> Result<LmlEval, GpError> {
    let hp = Hyperparameters::from_log(log_params)?;
    let xs = scaled(x, d, &hp.length_scales);
    let zs = scaled(z, d, &hp.length_scales);
    let zc = scaled_cols(z, d, &hp.length_scales);
    let mut c = core(ws, &xs, &zs, &zc, d, y, &hp, KUU_JITTER, par, blocks, !grad)?;
    if !grad {
        return Ok(LmlEval {
            value: c.elbo,
            gradient: Vec::new(),
        });
    }
    let n = y.len();
    let m = zs.len() / d;
    // inducing points whose gradient is wanted: all or none
    let mz = if want_z { m } else { 0 };
    let (sf2, s2, sigma) = (hp.signal_variance, hp.noise_variance, c.sigma);
    // B⁻¹ from L_B.
    let mut binv = Mat::<f64>::identity(m, m);
    solve_lower_triangular_in_place(c.lb.as_ref(), binv.as_mut(), Par::Seq);
    solve_upper_triangular_in_place(c.lb.as_ref().transpose(), binv.as_mut(), Par::Seq);
    // R = σ⁻¹ L_u⁻ᵀ (I − B⁻¹)
    let mut r = Mat::<f64>::from_fn(m, m, |i, j| {
        let e = if i == j { 1.0 } else { 0.0 };
        (e - binv[(i, j)]) / sigma
    });
    solve_upper_triangular_in_place(c.lu.as_ref().transpose(), r.as_mut(), Par::Seq);
    // u = σ⁻¹ L_u⁻ᵀ v1
    let mut um = Mat::<f64>::from_fn(m, 1, |i, _| c.v1[i] / sigma);
    solve_upper_triangular_in_place(c.lu.as_ref().transpose(), um.as_mut(), Par::Seq);
    let u: Vec<f64> = (0..m).map(|i| um[(i, 0)]).collect();
    // Second pass, block by block: α = σ⁻²(y − Aᵀv1) (and ‖y − Aᵀv1‖²
    // for the bound, in the residual pass's order), T = R·A (an M × 512
    // panel at a time), H = (uαᵀ + T) ∘ K_uf, and its contraction with
    // ∂k/∂ln ℓ_k = k·(x_k − z_k)².
    let (kuf, a) = (ws.kuf.as_ref(), ws.a.as_ref());
    let starts: Vec<usize> = (0..n).step_by(blocks.task).collect();
    let (rr, v1) = (r.as_ref(), &c.v1);
    let parts = run_tasks(starts, par, |s| {
        let w = blocks.task.min(n - s);
        let mut t = Mat::<f64>::zeros(m, blocks.sub.min(w));
        let mut gl = vec![0.0; d];
        let mut rr_task = 0.0;
        // ∂F/∂Z: Σ_n H_in x̃_nk (column-major d × M) and Σ_n H_in (M).
        let (mut hx, mut hsum) = (vec![0.0; mz * d], vec![0.0; mz]);
        let mut sub = 0;
        while sub < w {
            let ws_ = blocks.sub.min(w - sub);
            let ab = a.subcols(s + sub, ws_);
            let mut tb = t.as_mut().subcols_mut(0, ws_);
            matmul(tb.rb_mut(), Accum::Replace, rr, ab, 1.0, Par::Seq);
            for jj in 0..ws_ {
                let j = s + sub + jj;
                let r = residual(y[j], col(ab, jj), v1);
                rr_task += r * r;
                let aj = r / s2;
                let h = col_mut(tb.rb_mut(), jj);
                for ((hi, ui), ki) in h.iter_mut().zip(&u).zip(col(kuf, j)) {
                    *hi = (ui * aj + *hi) * ki;
                }
                let xq = &xs[j * d..(j + 1) * d];
                for (k, g) in gl.iter_mut().enumerate() {
                    *g += weighted_sq(h, &zc[k * m..(k + 1) * m], xq[k]);
                }
                if want_z {
                    for (hs, hi) in hsum.iter_mut().zip(h.iter()) {
                        *hs += hi;
                    }
                    for (k, xk) in xq.iter().enumerate() {
                        for (o, hi) in hx[k * m..(k + 1) * m].iter_mut().zip(h.iter()) {
                            *o += hi * xk;
                        }
                    }
                }
            }
            sub += ws_;
        }
        (gl, rr_task, hx, hsum)
    });
    let mut gl = vec![0.0; d];
    let mut rr_sum = 0.0;
    let (mut hx, mut hsum) = (vec![0.0; mz * d], vec![0.0; mz]);
    // Fixed order of the partial sums: the result does not depend on scheduling.
    for (g, rt, px, ps) in parts {
        for (a, b) in gl.iter_mut().zip(&g) {
            *a += b;
        }
        rr_sum += rt;
        for (a, b) in hx.iter_mut().zip(&px) {
            *a += b;
        }
        for (a, b) in hsum.iter_mut().zip(&ps) {
            *a += b;
        }
    }
    c.finish(rr_sum)?;
    // G_uu = −½ u uᵀ − ½ L_u⁻ᵀ (I − B⁻¹) AAᵀ L_u⁻¹
    //      = −½ u uᵀ − ½ σ · R · AAᵀ L_u⁻¹.
    let mut w = c.aat.transpose().to_owned(); // (AAᵀ)ᵀ = AAᵀ
    // w ← L_u⁻¹ᵀ-side: we need AAᵀ L_u⁻¹ = (L_u⁻ᵀ AAᵀ)ᵀ.
    solve_upper_triangular_in_place(c.lu.as_ref().transpose(), w.as_mut(), Par::Seq);
    let w = w.transpose().to_owned(); // AAᵀ L_u⁻¹
    let mut guu = Mat::<f64>::zeros(m, m);
    matmul(
        guu.as_mut(),
        Accum::Replace,
        r.as_ref(),
        w.as_ref(),
        -0.5 * sigma,
        Par::Seq,
    );
    let kuu0 = &c.kuu;
    // ∂F/∂z̃ (scaled units), row-major M × d: the K_uf part from the pass
    // above, then the K_uu part in the loop below.
    let mut gz = vec![0.0; mz * d];
    for i in 0..mz {
        for k in 0..d {
            gz[i * d + k] = hx[k * m + i] - zs[i * d + k] * hsum[i];
        }
    }
    for i in 0..m {
        for j in 0..m {
            let g = guu[(i, j)] - 0.5 * u[i] * u[j];
            if i != j {
                let zi = &zs[i * d..(i + 1) * d];
                let zj = &zs[j * d..(j + 1) * d];
                let gk = g * kuu0[(i, j)];
                for k in 0..d {
                    let e = zi[k] - zj[k];
                    gl[k] += gk * e * e;
                }
                if want_z {
                    // G_ij moves z_i and z_j: K_ij depends on both.
                    for k in 0..d {
                        let e = zj[k] - zi[k];
                        gz[i * d + k] += gk * e;
                        gz[j * d + k] -= gk * e;
                    }
                }
            }
        }
    }
    // σ_f² scales K_uf, K_uu (with its relative jitter), Q and K_ff alike,
    // so ∂F/∂ln σ_f² = ½(αᵀQα − tr Σ⁻¹Q) − tr(K_ff − Q)/(2σ²) with
    // Σ = Q + σ²I, αᵀQα = αᵀy − σ²‖α‖² = ‖v1‖²/σ² and tr Σ⁻¹Q = M − tr B⁻¹:
    // small terms only (the contraction with K_uf and K_uu would cancel
    // terms of size N·σ_f²/σ²).
    let nf = n as f64;
    let tr_binv: f64 = (0..m).map(|i| binv[(i, i)]).sum();
    let gsf = 0.5 * (packed::norm2(&c.v1) / s2 - m as f64 + tr_binv) - 0.5 * c.trace / s2;
    // ∂F/∂σ² with σ²‖α‖² = ‖r‖²/σ² and N σ_f² − σ² tr AAᵀ = tr(K_ff − Q).
    let ds2 = 0.5 * (c.rr / s2 - (nf - m as f64 + tr_binv)) / s2 + c.trace / (2.0 * s2 * s2);
    let mut gradient = gl;
    gradient.push(gsf);
    gradient.push(s2 * ds2);
    // scaled → the units of z: z̃_k = z_k/ℓ_k
    for (i, g) in gz.iter().enumerate() {
        gradient.push(g / hp.length_scales[i % d]);
    }
    if gradient.iter().any(|g| !g.is_finite()) {
        return Err(GpError::NotPositiveDefinite {
            jitter: c.eps * sf2,
        });
    }
    Ok(LmlEval {
        value: c.elbo,
        gradient,
    })
}

/// The posterior of one output at given hyperparameters, starting the K_uu
/// jitter ladder at `eps_start` (relative).
pub(crate) fn factorise(
    x: &[f64],
    z: &[f64],
    d: usize,
    y: &[f64],
    hp: &Hyperparameters,
    eps_start: f64,
    par: Par,
) -> Result<SparseFactor, GpError> {
    let n = y.len();
    let m = z.len() / d;
    let xs = scaled(x, d, &hp.length_scales);
    let zs = scaled(z, d, &hp.length_scales);
    let zc = scaled_cols(z, d, &hp.length_scales);
    let mut ws = SparseWorkspace::new(m, n);
    let c = core(
        &mut ws, &xs, &zs, &zc, d, y, hp, eps_start, par, BLOCKS, true,
    )?;
    let lu = packed::pack_rows(&c.lu);
    let lb = packed::pack_rows(&c.lb);
    let u = weights(&lu, &lb, &c.ay, c.sigma);
    Ok(SparseFactor {
        lu,
        lb,
        ay: c.ay,
        u,
        eps: c.eps,
        elbo: c.elbo,
    })
}

/// u = σ⁻¹ L_u⁻ᵀ L_B⁻ᵀ L_B⁻¹ (A y).
pub(crate) fn weights(lu: &[f64], lb: &[f64], ay: &[f64], sigma: f64) -> Vec<f64> {
    let mut v = ay.to_vec();
    packed::forward_rows(lb, &mut v);
    packed::backward_rows(lb, &mut v);
    v.iter_mut().for_each(|x| *x /= sigma);
    packed::backward_rows(lu, &mut v);
    v
}

/// Rank-one update of a packed-rows Cholesky factor: L·Lᵀ + x·xᵀ
/// (`x` is overwritten). O(M²).
pub(crate) fn chol_update(l: &mut [f64], x: &mut [f64]) {
    let m = x.len();
    for k in 0..m {
        let lkk = l[packed::row_start(k) + k];
        let r = lkk.hypot(x[k]);
        let c = r / lkk;
        let s = x[k] / lkk;
        l[packed::row_start(k) + k] = r;
        for (i, xi) in x.iter_mut().enumerate().take(m).skip(k + 1) {
            let at = packed::row_start(i) + k;
            let lik = (l[at] + s * *xi) / c;
            *xi = c * *xi - s * lik;
            l[at] = lik;
        }
    }
}

/// k-means++ seeding (Arthur & Vassilvitskii 2007) of `m` centres among the
/// rows of `x` (N × d), then `lloyd` Lloyd iterations. Deterministic for a
/// seed. O(N·M·d) per pass.
pub(crate) fn kmeans_pp(x: &[f64], d: usize, m: usize, lloyd: usize, seed: u64) -> Vec<f64> {
    let n = x.len() / d;
    let mut rng = SplitMix64::new(seed ^ 0x5EED_1D00_C0FF_EE00);
    let first = (rng.next_u64() % n as u64) as usize;
    let mut centres: Vec<f64> = x[first * d..(first + 1) * d].to_vec();
    let mut dist: Vec<f64> = (0..n)
        .map(|i| sqdist(&x[i * d..(i + 1) * d], &centres[..d]))
        .collect();
    let mut chosen = vec![false; n];
    chosen[first] = true;
    while centres.len() < m * d {
        let total: f64 = dist.iter().sum();
        let pick = if total > 0.0 && total.is_finite() {
            let mut t = rng.next_f64() * total;
            let mut p = n - 1;
            for (i, di) in dist.iter().enumerate() {
                if t < *di {
                    p = i;
                    break;
                }
                t -= di;
            }
            // rounding at the end of the scan: the last point with weight
            while dist[p] == 0.0 && p > 0 {
                p -= 1;
            }
            p
        } else {
            // Fewer distinct points than centres: take unchosen rows in order.
            (0..n).find(|i| !chosen[*i]).unwrap_or(0)
        };
        chosen[pick] = true;
        let c = &x[pick * d..(pick + 1) * d];
        centres.extend_from_slice(c);
        for (i, di) in dist.iter_mut().enumerate() {
            let e = sqdist(&x[i * d..(i + 1) * d], c);
            if e < *di {
                *di = e;
            }
        }
    }
    for _ in 0..lloyd {
        let mut sum = vec![0.0; m * d];
        let mut count = vec![0usize; m];
        for i in 0..n {
            let xi = &x[i * d..(i + 1) * d];
            let mut best = (f64::INFINITY, 0);
            for c in 0..m {
                let e = sqdist(xi, &centres[c * d..(c + 1) * d]);
                if e < best.0 {
                    best = (e, c);
                }
            }
            count[best.1] += 1;
            for (s, v) in sum[best.1 * d..(best.1 + 1) * d].iter_mut().zip(xi) {
                *s += v;
            }
        }
        for c in 0..m {
            if count[c] > 0 {
                for k in 0..d {
                    centres[c * d + k] = sum[c * d + k] / count[c] as f64;
                }
            }
        }
    }
    centres
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(n: usize, d: usize) -> (Vec<f64>, Vec<f64>) {
        let mut r = SplitMix64::new(3);
        let x: Vec<f64> = (0..n * d).map(|_| r.uniform(-2.0, 2.0)).collect();
        let y = x
            .chunks(d)
            .map(|p| (2.0 * p[0]).sin() + 0.3 * p[d - 1] + 0.05 * r.uniform(-1.0, 1.0))
            .collect();
        (x, y)
    }

    /// Size of the tests' problem: N samples, d inputs, M inducing points.
    const N: usize = 120;
    const D: usize = 3;
    const M: usize = 15;

    /// The tests' problem: inputs, targets, inducing inputs (k-means++ with
    /// two Lloyd iterations), a point θ = (ln ℓ, ln σ_f², ln σ_n²) and a
    /// workspace of its size.
    fn problem() -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, SparseWorkspace) {
        let (x, y) = data(N, D);
        let z = kmeans_pp(&x, D, M, 2, 1);
        let ws = SparseWorkspace::new(M, N);
        (x, y, z, vec![0.2, -0.3, 0.5, 0.4, -3.0], ws)
    }

    /// The bound F alone (no gradient, sequential) on the tests' problem
    /// size, for the finite differences.
    fn bound(ws: &mut SparseWorkspace, x: &[f64], z: &[f64], y: &[f64], theta: &[f64]) -> f64 {
        elbo_ws(ws, x, z, D, y, theta, false, Par::Seq)
            .unwrap()
            .value
    }

    /// (f(a + h·e_k) − f(a − h·e_k))/(2h) with h = 1e-5.
    fn central_difference(mut f: impl FnMut(&[f64]) -> f64, at: &[f64], k: usize) -> f64 {
        let h = 1e-5;
        let mut p = at.to_vec();
        p[k] += h;
        let fp = f(&p);
        p[k] = at[k] - h;
        (fp - f(&p)) / (2.0 * h)
    }

    /// Asserts that `analytic` is ∂f/∂a_k at a = `at` to 1e-6·(1 + |fd|),
    /// fd the [`central_difference`]; `what` names the component in the
    /// message.
    fn assert_matches_central_difference(
        f: impl FnMut(&[f64]) -> f64,
        at: &[f64],
        k: usize,
        analytic: f64,
        what: &str,
    ) {
        let fd = central_difference(f, at, k);
        assert!(
            (fd - analytic).abs() <= 1e-6 * (1.0 + fd.abs()),
            "{what} {k}: analytic {analytic} vs fd {fd}"
        );
    }

    #[test]
    fn gradient_matches_central_differences() {
        let d = D;
        let (x, y, z, theta, mut ws) = problem();
        let e = elbo_ws(&mut ws, &x, &z, d, &y, &theta, true, Par::Seq).unwrap();
        for k in 0..theta.len() {
            // central differences: O(h²) truncation ≈ 1e-10·|f'''|, rounding
            // ≈ ε·|F|/h ≈ 1e-9 here
            let f = |t: &[f64]| bound(&mut ws, &x, &z, &y, t);
            assert_matches_central_difference(f, &theta, k, e.gradient[k], "component");
        }
        // the parallel path gives the same bits (fixed partition, partial
        // sums added in task order)
        let ep = elbo_ws(&mut ws, &x, &z, d, &y, &theta, true, Par::rayon(2)).unwrap();
        assert_eq!(ep.value.to_bits(), e.value.to_bits());
        assert_eq!(ep.gradient, e.gradient);
    }

    #[test]
    fn inducing_gradient_matches_central_differences() {
        // ∂F/∂Z against central differences of F in every coordinate of
        // every inducing point (h = 1e-5 in units where the inputs span
        // [−2, 2]: truncation ≈ h²·|F‴| ≈ 1e-9, rounding ≈ ε·|F|/h ≈
        // 1e-9), and the θ part equal to elbo_ws's bit for bit.
        let (d, m) = (D, M);
        let (x, y, z, theta, mut ws) = problem();
        let e = elbo_z_ws(&mut ws, &x, &z, d, &y, &theta, Par::Seq).unwrap();
        assert_eq!(e.gradient.len(), d + 2 + m * d);
        let t = elbo_ws(&mut ws, &x, &z, d, &y, &theta, true, Par::Seq).unwrap();
        assert_eq!(t.value.to_bits(), e.value.to_bits());
        assert_eq!(t.gradient[..], e.gradient[..d + 2]);
        let mut largest = 0.0f64;
        for k in 0..m * d {
            let an = e.gradient[d + 2 + k];
            largest = largest.max(an.abs());
            let f = |zk: &[f64]| bound(&mut ws, &x, zk, &y, &theta);
            assert_matches_central_difference(f, &z, k, an, "inducing coordinate");
        }
        // the check is not vacuous: the bound does move with Z here
        assert!(largest > 1e-2, "largest |dF/dz| {largest}");
        let ep = elbo_z_ws(&mut ws, &x, &z, d, &y, &theta, Par::rayon(2)).unwrap();
        assert_eq!(ep.gradient, e.gradient);
    }

    #[test]
    fn column_partition_does_not_change_the_result() {
        // One task (as the numpy fixtures of tests/gp/gp_sparse.rs check)
        // against many small tasks with a partial last one and several
        // panels per task: the same bound and gradient up to the order of
        // the sums (relative 1e-12: ≈ N·ε over N = 120 terms, with margin).
        let (n, d) = (N, D);
        let (x, y, z, theta, mut ws) = problem();
        let one = Blocks { task: n, sub: n };
        let e = elbo_blocks(&mut ws, &x, &z, d, &y, &theta, true, true, Par::Seq, one).unwrap();
        for blocks in [Blocks { task: 17, sub: 5 }, Blocks { task: 64, sub: 64 }] {
            for par in [Par::Seq, Par::rayon(2)] {
                let f =
                    elbo_blocks(&mut ws, &x, &z, d, &y, &theta, true, true, par, blocks).unwrap();
                assert!((f.value - e.value).abs() <= 1e-12 * e.value.abs());
                for (a, b) in f.gradient.iter().zip(&e.gradient) {
                    assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn cholesky_update_matches_refactorisation() {
        let m = 7;
        let a = Mat::<f64>::from_fn(m, m, |i, j| {
            if i == j {
                3.0 + i as f64
            } else {
                0.2 * ((i + j) as f64).sin()
            }
        });
        let l = a.llt(Side::Lower).unwrap().L().to_owned();
        let mut lp = packed::pack_rows(&l);
        let x: Vec<f64> = (0..m).map(|i| (i as f64 * 0.7).cos()).collect();
        let mut xx = x.clone();
        chol_update(&mut lp, &mut xx);
        let b = Mat::<f64>::from_fn(m, m, |i, j| a[(i, j)] + x[i] * x[j]);
        let lb = packed::pack_rows(&b.llt(Side::Lower).unwrap().L().to_owned());
        for (p, q) in lp.iter().zip(&lb) {
            assert!((p - q).abs() < 1e-13, "{p} vs {q}");
        }
    }
}
