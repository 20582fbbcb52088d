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
//! c = L_B⁻¹Ay/σ and
//! F = −N/2·ln 2π − Σ ln (L_B)_ii − N/2·ln σ² − ½yᵀy/σ² + ½cᵀc − ½Nσ_f²/σ² + ½tr(AAᵀ).
//!
//! **Gradient.** With α = (Q + σ²I)⁻¹y = σ⁻²(y − AᵀB⁻¹Ay) and
//! u = K_uu⁻¹K_uf α = σ⁻¹L_u⁻ᵀB⁻¹Ay (which is also the weight vector of the
//! predictive mean), the partial derivatives of F are
//!
//! ```text
//! ∂F/∂K_uf = u αᵀ + σ⁻¹ L_u⁻ᵀ (I − B⁻¹) A                       (M × N)
//! ∂F/∂K_uu = −½ u uᵀ − ½ L_u⁻ᵀ (I − B⁻¹) AAᵀ L_u⁻¹                (M × M)
//! ∂F/∂σ²   = ½(αᵀα − σ⁻²(N − M + tr B⁻¹)) + (Nσ_f² − σ²tr AAᵀ)/(2σ⁴)
//! ∂F/∂σ_f² (diagonal of K_ff) = −N/(2σ²)
//! ```
//!
//! (from dF = ½tr((ααᵀ − Σ⁻¹)dΣ) and Σ⁻¹ = σ⁻²(I − AᵀB⁻¹A)), chained to
//! θ = (ln ℓ, ln σ_f², ln σ_n²) through ∂k/∂ln ℓ_j = k·(x_j − z_j)²/ℓ_j² and
//! ∂k/∂ln σ_f² = k. Nothing of size N × N is formed.
//!
//! **Cost** per evaluation: M·N kernel entries, the triangular solve
//! L_u⁻¹K_uf (M²N), AAᵀ (M²N/… a full product here, M²N·2 flops), the
//! product (I − B⁻¹)-term · A (2M²N) and O(M·N·d) for the contraction,
//! all through faer's level-3 kernels; memory three M × N matrices.
//!
//! **Prediction.** mean = k_uᵀu, latent variance
//! σ_f² − ‖L_u⁻¹k_u‖² + ‖L_B⁻¹L_u⁻¹k_u‖². M = N with Z = X gives the exact
//! GP (up to the jitter).

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, Mat, Par, Side};

use super::error::GpError;
use super::kernel::Hyperparameters;
use super::lml::{LmlEval, sqdist};
use super::rng::SplitMix64;
use super::tri;

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

/// K_uf (M × N, column n = k(Z, x_n)) from scaled inputs; blocks of
/// columns in parallel unless `par` is sequential.
fn kuf_into(zs: &[f64], xs: &[f64], m: usize, d: usize, sf2: f64, k: &mut Mat<f64>, par: Par) {
    use rayon::prelude::*;
    let n = xs.len() / d;
    let fill = |s: usize, mut v: faer::MatMut<'_, f64>| {
        for j in 0..v.ncols() {
            let col = v
                .rb_mut()
                .col_mut(j)
                .try_as_col_major_mut()
                .expect("contiguous")
                .as_slice_mut();
            let xn = &xs[(s + j) * d..(s + j + 1) * d];
            for (i, c) in col[..m].iter_mut().enumerate() {
                *c = kval(sf2, sqdist(&zs[i * d..(i + 1) * d], xn));
            }
        }
    };
    if matches!(par, Par::Seq) {
        fill(0, k.as_mut());
        return;
    }
    let block = 1024usize;
    let mut views = Vec::new();
    let mut rest = k.as_mut();
    let mut start = 0;
    while start < n {
        let w = block.min(n - start);
        let (left, right) = rest.split_at_col_mut(w);
        views.push((start, left));
        rest = right;
        start += w;
    }
    views.into_par_iter().for_each(|(s, v)| fill(s, v));
}

use faer::reborrow::ReborrowMut;

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
/// evaluations of one optimiser run (three M × N buffers).
pub(crate) struct SparseWorkspace {
    kuf: Mat<f64>,
    a: Mat<f64>,
    /// R·A of the gradient (allocated on the first gradient evaluation).
    t: Mat<f64>,
}

impl SparseWorkspace {
    pub(crate) fn new(m: usize, n: usize) -> Self {
        Self {
            kuf: Mat::zeros(m, n),
            a: Mat::zeros(m, n),
            t: Mat::new(),
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
    lu: Mat<f64>,
    lb: Mat<f64>,
    eps: f64,
    ay: Vec<f64>,
    /// B⁻¹Ay
    v1: Vec<f64>,
    aat: Mat<f64>,
    elbo: f64,
    sigma: f64,
}

#[allow(clippy::too_many_arguments)]
fn core(
    ws: &mut SparseWorkspace,
    xs: &[f64],
    zs: &[f64],
    d: usize,
    y: &[f64],
    hp: &Hyperparameters,
    eps_start: f64,
    par: Par,
) -> Result<Core, GpError> {
    let n = y.len();
    let m = zs.len() / d;
    let sf2 = hp.signal_variance;
    let s2 = hp.noise_variance;
    let sigma = s2.sqrt();
    let (lu, eps) = chol_kuu(&kuu(zs, m, d, sf2), sf2, eps_start)?;
    kuf_into(zs, xs, m, d, sf2, &mut ws.kuf, par);
    ws.a.copy_from(&ws.kuf);
    solve_lower_triangular_in_place(lu.as_ref(), ws.a.as_mut(), par);
    let inv_sigma = 1.0 / sigma;
    for j in 0..n {
        for v in
            ws.a.col_mut(j)
                .try_as_col_major_mut()
                .expect("contiguous")
                .as_slice_mut()
        {
            *v *= inv_sigma;
        }
    }
    let mut aat = Mat::<f64>::zeros(m, m);
    matmul(
        aat.as_mut(),
        Accum::Replace,
        ws.a.as_ref(),
        ws.a.as_ref().transpose(),
        1.0,
        par,
    );
    let mut ay = vec![0.0; m];
    for (j, &yj) in y.iter().enumerate() {
        if yj != 0.0 {
            let col =
                ws.a.col(j)
                    .try_as_col_major()
                    .expect("contiguous")
                    .as_slice();
            for (o, a) in ay.iter_mut().zip(col) {
                *o += a * yj;
            }
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
    // c = L_B⁻¹ A y / σ
    let mut c = Mat::<f64>::from_fn(m, 1, |i, _| ay[i]);
    solve_lower_triangular_in_place(lb.as_ref(), c.as_mut(), Par::Seq);
    let ctc: f64 = (0..m).map(|i| c[(i, 0)] * c[(i, 0)]).sum::<f64>() / s2;
    // v1 = B⁻¹ A y = L_B⁻ᵀ L_B⁻¹ A y
    solve_upper_triangular_in_place(lb.as_ref().transpose(), c.as_mut(), Par::Seq);
    let v1: Vec<f64> = (0..m).map(|i| c[(i, 0)]).collect();
    let yty: f64 = y.iter().map(|v| v * v).sum();
    let tr_aat: f64 = (0..m).map(|i| aat[(i, i)]).sum();
    let logdet_b: f64 = (0..m).map(|i| lb[(i, i)].ln()).sum();
    let nf = n as f64;
    let elbo = -0.5 * nf * (2.0 * core::f64::consts::PI).ln()
        - logdet_b
        - 0.5 * nf * s2.ln()
        - 0.5 * yty / s2
        + 0.5 * ctc
        - 0.5 * nf * sf2 / s2
        + 0.5 * tr_aat;
    if !elbo.is_finite() {
        return Err(GpError::NotPositiveDefinite { jitter: eps * sf2 });
    }
    Ok(Core {
        lu,
        lb,
        eps,
        ay,
        v1,
        aat,
        elbo,
        sigma,
    })
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
    let hp = Hyperparameters::from_log(log_params)?;
    let xs = scaled(x, d, &hp.length_scales);
    let zs = scaled(z, d, &hp.length_scales);
    let c = core(ws, &xs, &zs, d, y, &hp, KUU_JITTER, par)?;
    if !grad {
        return Ok(LmlEval {
            value: c.elbo,
            gradient: Vec::new(),
        });
    }
    let n = y.len();
    let m = zs.len() / d;
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
    // α = σ⁻²(y − Aᵀ v1)
    let alpha: Vec<f64> = (0..n)
        .map(|j| {
            let col =
                ws.a.col(j)
                    .try_as_col_major()
                    .expect("contiguous")
                    .as_slice();
            (y[j] - tri::dot(col, &c.v1)) / s2
        })
        .collect();
    // T = R·A (M × N), then G_uf = u αᵀ + T, contracted with K_uf ∘ D.
    if ws.t.nrows() != m || ws.t.ncols() != n {
        ws.t = Mat::zeros(m, n);
    }
    matmul(
        ws.t.as_mut(),
        Accum::Replace,
        r.as_ref(),
        ws.a.as_ref(),
        1.0,
        par,
    );
    let t = &ws.t;
    let contract = |j: usize, tcol: &[f64], gl: &mut [f64], gs: &mut f64| {
        let kcol = ws
            .kuf
            .col(j)
            .try_as_col_major()
            .expect("contiguous")
            .as_slice();
        let xn = &xs[j * d..(j + 1) * d];
        let aj = alpha[j];
        for i in 0..m {
            let h = (u[i] * aj + tcol[i]) * kcol[i];
            if h == 0.0 {
                continue;
            }
            *gs += h;
            let zi = &zs[i * d..(i + 1) * d];
            for k in 0..d {
                let e = xn[k] - zi[k];
                gl[k] += h * e * e;
            }
        }
    };
    let mut gl = vec![0.0; d];
    let mut gsf = 0.0;
    {
        use rayon::prelude::*;
        let tref = t;
        let chunk = 2048usize;
        let nchunks = n.div_ceil(chunk);
        let parts: Vec<(Vec<f64>, f64)> = if matches!(par, Par::Seq) {
            vec![{
                let (mut g, mut s) = (vec![0.0; d], 0.0);
                for j in 0..n {
                    let tcol = tref
                        .col(j)
                        .try_as_col_major()
                        .expect("contiguous")
                        .as_slice();
                    contract(j, tcol, &mut g, &mut s);
                }
                (g, s)
            }]
        } else {
            (0..nchunks)
                .into_par_iter()
                .map(|ci| {
                    let (mut g, mut s) = (vec![0.0; d], 0.0);
                    for j in ci * chunk..((ci + 1) * chunk).min(n) {
                        let tcol = tref
                            .col(j)
                            .try_as_col_major()
                            .expect("contiguous")
                            .as_slice();
                        contract(j, tcol, &mut g, &mut s);
                    }
                    (g, s)
                })
                .collect()
        };
        // Fixed order of the partial sums: the result does not depend on scheduling.
        for (g, s) in parts {
            for (a, b) in gl.iter_mut().zip(&g) {
                *a += b;
            }
            gsf += s;
        }
    }
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
    let kuu0 = kuu(&zs, m, d, sf2);
    for i in 0..m {
        for j in 0..m {
            let g = guu[(i, j)] - 0.5 * u[i] * u[j];
            let kij = kuu0[(i, j)] + if i == j { c.eps * sf2 } else { 0.0 };
            gsf += g * kij;
            if i != j {
                let zi = &zs[i * d..(i + 1) * d];
                let zj = &zs[j * d..(j + 1) * d];
                for k in 0..d {
                    let e = zi[k] - zj[k];
                    gl[k] += g * kuu0[(i, j)] * e * e;
                }
            }
        }
    }
    // Direct σ_f² term of the trace, and the noise.
    let nf = n as f64;
    gsf += sf2 * (-0.5 * nf / s2);
    let ata: f64 = alpha.iter().map(|a| a * a).sum();
    let tr_binv: f64 = (0..m).map(|i| binv[(i, i)]).sum();
    let tr_aat: f64 = (0..m).map(|i| c.aat[(i, i)]).sum();
    let ds2 =
        0.5 * (ata - (nf - m as f64 + tr_binv) / s2) + (nf * sf2 - s2 * tr_aat) / (2.0 * s2 * s2);
    let mut gradient = gl;
    gradient.push(gsf);
    gradient.push(s2 * ds2);
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
    let mut ws = SparseWorkspace::new(m, n);
    let c = core(&mut ws, &xs, &zs, d, y, hp, eps_start, par)?;
    let lu = tri::pack_rows(&c.lu);
    let lb = tri::pack_rows(&c.lb);
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
    tri::forward_rows(lb, &mut v);
    tri::backward_rows(lb, &mut v);
    v.iter_mut().for_each(|x| *x /= sigma);
    tri::backward_rows(lu, &mut v);
    v
}

/// Rank-one update of a packed-rows Cholesky factor: L·Lᵀ + x·xᵀ
/// (`x` is overwritten). O(M²).
pub(crate) fn chol_update(l: &mut [f64], x: &mut [f64]) {
    let m = x.len();
    for k in 0..m {
        let lkk = l[tri::row_start(k) + k];
        let r = lkk.hypot(x[k]);
        let c = r / lkk;
        let s = x[k] / lkk;
        l[tri::row_start(k) + k] = r;
        for (i, xi) in x.iter_mut().enumerate().take(m).skip(k + 1) {
            let at = tri::row_start(i) + k;
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

    #[test]
    fn gradient_matches_central_differences() {
        let (n, d, m) = (120, 3, 15);
        let (x, y) = data(n, d);
        let z = kmeans_pp(&x, d, m, 2, 1);
        let theta = vec![0.2, -0.3, 0.5, 0.4, -3.0];
        let mut ws = SparseWorkspace::new(m, n);
        let e = elbo_ws(&mut ws, &x, &z, d, &y, &theta, true, Par::Seq).unwrap();
        for k in 0..theta.len() {
            let h = 1e-5;
            let mut tp = theta.clone();
            tp[k] += h;
            let mut tm = theta.clone();
            tm[k] -= h;
            let fp = elbo_ws(&mut ws, &x, &z, d, &y, &tp, false, Par::Seq)
                .unwrap()
                .value;
            let fm = elbo_ws(&mut ws, &x, &z, d, &y, &tm, false, Par::Seq)
                .unwrap()
                .value;
            let fd = (fp - fm) / (2.0 * h);
            // central differences: O(h²) truncation ≈ 1e-10·|f'''|, rounding
            // ≈ ε·|F|/h ≈ 1e-9 here
            assert!(
                (fd - e.gradient[k]).abs() <= 1e-6 * (1.0 + fd.abs()),
                "component {k}: analytic {} vs fd {fd}",
                e.gradient[k]
            );
        }
        // the parallel path gives the same numbers up to summation order
        let ep = elbo_ws(&mut ws, &x, &z, d, &y, &theta, true, Par::rayon(2)).unwrap();
        assert!((ep.value - e.value).abs() <= 1e-10 * e.value.abs());
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
        let mut lp = tri::pack_rows(&l);
        let x: Vec<f64> = (0..m).map(|i| (i as f64 * 0.7).cos()).collect();
        let mut xx = x.clone();
        chol_update(&mut lp, &mut xx);
        let b = Mat::<f64>::from_fn(m, m, |i, j| a[(i, j)] + x[i] * x[j]);
        let lb = tri::pack_rows(&b.llt(Side::Lower).unwrap().L().to_owned());
        for (p, q) in lp.iter().zip(&lb) {
            assert!((p - q).abs() < 1e-13, "{p} vs {q}");
        }
    }
}
