//! Online updates: add samples to a trained model without re-optimising.
//!
//! The hyperparameters, the input standardisation, the output scales and
//! the prior mean stay as they are (a constant prior mean keeps its value),
//! so the result is the model [`Gp::from_saved`] builds from the enlarged
//! data with the same hyperparameters and normalisation, up to rounding:
//!
//! * exact GP: the Cholesky factor gains one row per sample,
//!   L' = [[L, 0], [cᵀ, δ]] with c = L⁻¹k and δ² = k(x, x) + σ_n² + jitter − ‖c‖²
//!   (N²/2 multiply-adds, with the stored L⁻¹ or by forward substitution),
//!   L⁻¹r gains one entry, the stored L⁻¹ one row −(L⁻ᵀc)ᵀ/δ (N²/2; without
//!   it, L⁻ᵀc by backward substitution), and α by the block inverse,
//!   α' = (α − L⁻ᵀc·β, β) with β = (r − kᵀα)/δ²: two passes over one
//!   triangle per sample;
//! * sparse GP: a = L_u⁻¹k_u/σ, B ← B + aaᵀ by a rank-one Cholesky update
//!   of L_B, A·r ← A·r + a·r_new (O(M²) per sample), and the weights
//!   u re-solved once per call (O(M²)).

use std::sync::Arc;

use crate::error::GpError;
use crate::likelihood::sqdist;
use crate::model::{Gp, OutputGp, Posterior, check_finite};
use crate::{packed, sparse};

impl Gp {
    /// Adds samples (row-major `inputs`, k × d, and `targets`, k × p, in
    /// original units) to the model at fixed hyperparameters, in
    /// O(k·N²) for an exact GP and O(k·M²) for a sparse one (see the
    /// module docs of `gp::update`). The report of the training run (LML)
    /// is not updated; [`OutputGp::log_marginal_likelihood`](super::OutputGp::log_marginal_likelihood)
    /// is (the exact LML, or the sparse bound, of the enlarged data).
    ///
    /// Errors (the model is unchanged then): dimension mismatches, NaN or ∞
    /// in the samples or in the prior mean at them, or an exact model whose
    /// extended Gram matrix is not numerically positive definite with the
    /// model's jitter (e.g. a duplicate input with a tiny noise variance):
    /// [`GpError::NotPositiveDefinite`]; refit with [`Gp::fit`] then.
    pub fn add_samples(&mut self, inputs: &[f64], targets: &[f64]) -> Result<(), GpError> {
        let (d, p) = (self.d, self.p);
        let k = super::model::check_dims(inputs, d, targets, p)?;
        let mut prior = vec![0.0; k * p];
        for (o, x) in prior.chunks_exact_mut(p).zip(inputs.chunks_exact(d)) {
            self.mean.eval(x, o);
        }
        check_finite("prior mean at the new inputs", &prior)?;
        let mut xn = vec![0.0; k * d];
        for (o, x) in xn.chunks_exact_mut(d).zip(inputs.chunks_exact(d)) {
            self.input_norm.apply(x, o);
        }
        // Factors only grow by appended rows (exact) or are small (sparse):
        // an error undoes the outputs updated so far instead of copying them.
        let mut undo: Vec<Undo> = Vec::with_capacity(p);
        for j in 0..p {
            let o = &mut self.outputs[j];
            undo.push(Undo::of(o));
            if let Err(e) = update_output(o, j, k, d, p, targets, &prior, &xn, self.n) {
                for (o, u) in self.outputs.iter_mut().zip(undo) {
                    u.restore(o);
                }
                return Err(e);
            }
        }
        self.inputs.extend_from_slice(inputs);
        self.targets.extend_from_slice(targets);
        self.prior_at_inputs.extend_from_slice(&prior);
        self.n += k;
        Ok(())
    }
}

/// What restores an output after a failed update.
struct Undo {
    alpha: Vec<f64>,
    xs_cols: Vec<f64>,
    lml: f64,
    residual_len: usize,
    post: UndoPost,
}

enum UndoPost {
    /// Lengths of the appended-to vectors (L, L⁻¹, L⁻¹r).
    Exact {
        l: usize,
        linv: Option<usize>,
        fwd: usize,
    },
    /// Copies of the O(M²) state.
    Sparse { lb: Vec<f64>, ay: Vec<f64> },
}

impl Undo {
    fn of(o: &OutputGp) -> Self {
        Self {
            alpha: o.alpha.clone(),
            xs_cols: o.xs_cols.clone(),
            lml: o.lml,
            residual_len: o.residual.len(),
            post: match &o.post {
                Posterior::Exact { l, linv, fwd } => UndoPost::Exact {
                    l: l.len(),
                    linv: linv.as_ref().map(|li| li.len()),
                    fwd: fwd.len(),
                },
                Posterior::Sparse { lb, ay, .. } => UndoPost::Sparse {
                    lb: lb.clone(),
                    ay: ay.clone(),
                },
            },
        }
    }

    fn restore(self, o: &mut OutputGp) {
        o.alpha = self.alpha;
        o.xs_cols = self.xs_cols;
        o.lml = self.lml;
        o.residual.truncate(self.residual_len);
        match (&mut o.post, self.post) {
            (
                Posterior::Exact { l, linv, fwd },
                UndoPost::Exact {
                    l: nl,
                    linv: ni,
                    fwd: nf,
                },
            ) => {
                l.truncate(nl);
                fwd.truncate(nf);
                if let (Some(li), Some(n)) = (linv.as_mut(), ni) {
                    Arc::make_mut(li).truncate(n);
                }
            }
            (Posterior::Sparse { lb, ay, .. }, UndoPost::Sparse { lb: b, ay: a }) => {
                *lb = b;
                *ay = a;
            }
            _ => {}
        }
    }
}

/// Appends the k new samples to output `j` (see [`Gp::add_samples`]).
#[allow(clippy::too_many_arguments)]
fn update_output(
    o: &mut OutputGp,
    j: usize,
    k: usize,
    d: usize,
    p: usize,
    targets: &[f64],
    prior: &[f64],
    xn: &[f64],
    n_old: usize,
) -> Result<(), GpError> {
    let s = o.output_scale;
    let r_new: Vec<f64> = (0..k)
        .map(|i| (targets[i * p + j] - prior[i * p + j]) / s)
        .collect();
    check_finite("residual y - m(x) of the new samples", &r_new)?;
    let xs_new = super::likelihood::scale_inputs(xn, d, &o.hp.length_scales);
    let sf2 = o.hp.signal_variance;
    let centres = o.alpha.len();
    match &mut o.post {
        Posterior::Exact { l, linv, fwd } => {
            let mut n = centres;
            // Row-major scaled training inputs, extended as we go.
            let mut xs = row_major(&o.xs_cols, d, n);
            let diag = sf2 + o.hp.noise_variance + o.jitter;
            let mut alpha = o.alpha.clone();
            let mut c = Vec::with_capacity(n + k);
            for (i, xq) in xs_new.chunks_exact(d).enumerate() {
                let b = kernel_vector(&xs, d, n, xq, sf2);
                // c = L⁻¹b and, with a stored L⁻¹, its new row −cᵀL⁻¹/δ
                // (= −(A⁻¹b)ᵀ/δ) in the same pass over L⁻¹; without it, a
                // forward and a backward solve with L.
                c.clear();
                c.resize(n, 0.0);
                if let Some(li) = linv.as_mut() {
                    packed::matvec_and_inverse_row(Arc::make_mut(li), &b, &mut c);
                } else {
                    c.copy_from_slice(&b);
                    packed::forward_rows(l, &mut c);
                }
                let delta2 = diag - packed::norm2(&c);
                if !(delta2 > 0.0 && delta2.is_finite()) {
                    // the undo record truncates the appended row of L⁻¹
                    return Err(GpError::NotPositiveDefinite { jitter: o.jitter });
                }
                let delta = delta2.sqrt();
                // A⁻¹b = L⁻ᵀc: the unscaled new row of L⁻¹, negated.
                let ainv_b: Vec<f64> = match linv.as_mut() {
                    Some(li) => {
                        let li = Arc::make_mut(li);
                        let start = packed::row_start(n);
                        let w: Vec<f64> = li[start..start + n].iter().map(|v| -v).collect();
                        packed::finish_inverse_row(li, n, delta);
                        w
                    }
                    None => {
                        let mut t = c.clone();
                        packed::backward_rows(l, &mut t);
                        t
                    }
                };
                // Block inverse: α' = (α − A⁻¹b·β, β), β = (r − bᵀα)/δ².
                let beta = (r_new[i] - packed::dot(&b, &alpha)) / delta2;
                for (a, q) in alpha.iter_mut().zip(&ainv_b) {
                    *a -= q * beta;
                }
                alpha.push(beta);
                fwd.push((r_new[i] - packed::dot(&c, fwd)) / delta);
                l.extend_from_slice(&c);
                l.push(delta);
                xs.extend_from_slice(xq);
                n += 1;
            }
            let fit = packed::norm2(fwd);
            let ln2pi = (2.0 * core::f64::consts::PI).ln();
            let log_det: f64 = 2.0
                * (0..n)
                    .map(|i| l[packed::row_start(i) + i].ln())
                    .sum::<f64>();
            o.lml = -0.5 * fit - 0.5 * log_det - 0.5 * n as f64 * ln2pi;
            if alpha.iter().any(|a| !a.is_finite()) || !o.lml.is_finite() {
                return Err(GpError::NotPositiveDefinite { jitter: o.jitter });
            }
            o.alpha = alpha;
            o.xs_cols = col_major(&xs, d);
        }
        Posterior::Sparse { lu, lb, ay, .. } => {
            let m = centres;
            let sigma = o.hp.noise_variance.sqrt();
            let zs = row_major(&o.xs_cols, d, m);
            for (i, xq) in xs_new.chunks_exact(d).enumerate() {
                let mut a = kernel_vector(&zs, d, m, xq, sf2);
                packed::forward_rows(lu, &mut a);
                a.iter_mut().for_each(|v| *v /= sigma);
                for (y, v) in ay.iter_mut().zip(&a) {
                    *y += v * r_new[i];
                }
                sparse::chol_update(lb, &mut a);
            }
            o.alpha = sparse::weights(lu, lb, ay, sigma);
            o.lml = sparse_bound(
                lb,
                ay,
                o.residual.iter().chain(&r_new),
                n_old + k,
                sf2,
                o.hp.noise_variance,
            );
        }
    }
    o.residual.extend_from_slice(&r_new);
    Ok(())
}

/// The SGPR bound from L_B, A·y and the targets (see `sparse`):
/// tr(AAᵀ) = ‖L_B‖_F² − M.
fn sparse_bound<'a>(
    lb: &[f64],
    ay: &[f64],
    y: impl Iterator<Item = &'a f64>,
    n: usize,
    sf2: f64,
    s2: f64,
) -> f64 {
    let m = ay.len();
    let mut c = ay.to_vec();
    packed::forward_rows(lb, &mut c);
    let ctc = packed::norm2(&c) / s2;
    let yty: f64 = y.map(|v| v * v).sum();
    let tr_aat = packed::norm2(lb) - m as f64;
    let logdet_b: f64 = (0..m).map(|i| lb[packed::row_start(i) + i].ln()).sum();
    let nf = n as f64;
    -0.5 * nf * (2.0 * core::f64::consts::PI).ln() - logdet_b - 0.5 * nf * s2.ln() - 0.5 * yty / s2
        + 0.5 * ctc
        - 0.5 * nf * sf2 / s2
        + 0.5 * tr_aat
}

/// k(x_a, x_q) = σ_f²·exp(−½‖x_a − x_q‖²) for the first `n` rows x_a of
/// the row-major scaled inputs `xs` (d each) and the scaled query `xq`; 0
/// where the squared distance exceeds [`vigp_core::gp::R2_CUTOFF`].
fn kernel_vector(xs: &[f64], d: usize, n: usize, xq: &[f64], sf2: f64) -> Vec<f64> {
    (0..n)
        .map(|a| {
            let r2 = sqdist(&xs[a * d..(a + 1) * d], xq);
            if r2 > vigp_core::gp::R2_CUTOFF {
                0.0
            } else {
                sf2 * (-0.5 * r2).exp()
            }
        })
        .collect()
}

fn row_major(cols: &[f64], d: usize, n: usize) -> Vec<f64> {
    let mut out = vec![0.0; n * d];
    for j in 0..d {
        for i in 0..n {
            out[i * d + j] = cols[j * n + i];
        }
    }
    out
}

fn col_major(rows: &[f64], d: usize) -> Vec<f64> {
    let n = rows.len() / d;
    let mut out = vec![0.0; n * d];
    for i in 0..n {
        for j in 0..d {
            out[j * n + i] = rows[i * d + j];
        }
    }
    out
}
