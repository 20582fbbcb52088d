//! Prediction: the posterior mean, its gradient and variance at one point
//! (allocation-free with a [`Workspace`]) and in batches.

use std::sync::Arc;

use rayon::prelude::*;
use vigp_core::gp as core_gp;

use crate::error::GpError;
use crate::mean::Resolved;
use crate::model::*;
use crate::packed;
use crate::variance_thread::Task;

/// Preallocated buffers for [`Gp::predict_into`]; make one with [`Gp::workspace`].
#[derive(Clone, Debug)]
pub struct Workspace {
    xn: Vec<f64>,
    xs: Vec<f64>,
    kstar: Vec<f64>,
    tmp: Vec<f64>,
    prior: Vec<f64>,
    /// One set of buffers per output for the parallel variance (empty when
    /// the model never takes that path).
    lanes: Vec<Lane>,
    /// Visit the outputs and L⁻¹'s rows in reverse in the next call
    /// (alternates: the part of L⁻¹ read last is then read first, from
    /// the core's cache; see `packed::lower_matvec_dir`).
    flip: bool,
    n: usize,
    d: usize,
    p: usize,
}

/// One output's buffers and results in the parallel variance path.
#[derive(Clone, Debug)]
pub(crate) struct Lane {
    xs: Vec<f64>,
    kstar: Vec<f64>,
    tmp: Vec<f64>,
    mean: f64,
    quad: f64,
}

/// Smallest N at which [`Gp::predict_into`] computes the outputs' variances
/// on parallel threads (see [`Gp::set_parallel_variance`]). Below it the
/// O(N²) work per output (2 µs at N = 256 from L2) does not pay for waking a
/// second thread.
pub const PARALLEL_VARIANCE_MIN_N: usize = 256;

/// Batch prediction: row-major `m × p` means and latent variances.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// Posterior means, original units, row-major (point-major).
    pub mean: Vec<f64>,
    /// Posterior variances of the latent function (without observation noise),
    /// original units, same layout as `mean`.
    pub variance: Vec<f64>,
}

impl Lane {
    pub(crate) fn new(d: usize, b: usize) -> Self {
        Self {
            xs: vec![0.0; d],
            kstar: vec![0.0; b],
            tmp: vec![0.0; b],
            mean: 0.0,
            quad: 0.0,
        }
    }
}

impl Gp {
    /// Buffers for the allocation-free [`predict_into`](Self::predict_into).
    pub fn workspace(&self) -> Workspace {
        let b = self.basis();
        Workspace {
            xn: vec![0.0; self.d],
            xs: vec![0.0; self.d],
            kstar: vec![0.0; b],
            tmp: vec![0.0; b],
            prior: vec![0.0; self.p],
            lanes: if self.takes_parallel_variance() {
                (0..self.p).map(|_| Lane::new(self.d, b)).collect()
            } else {
                Vec::new()
            },
            flip: false,
            n: b,
            d: self.d,
            p: self.p,
        }
    }

    /// Number of kernel centres per output: N (exact) or M (sparse).
    fn basis(&self) -> usize {
        self.outputs.first().map_or(self.n, |o| o.alpha.len())
    }

    /// Checks the query and the workspace; a workspace of this model from
    /// before [`add_samples`](Self::add_samples) is resized (allocates once).
    fn check_point(&self, x: &[f64], ws: &mut Workspace) -> Result<(), GpError> {
        if x.len() != self.d {
            return Err(GpError::DimensionMismatch {
                what: "prediction input",
                expected: self.d,
                got: x.len(),
            });
        }
        if ws.d != self.d || ws.p != self.p {
            return Err(GpError::DimensionMismatch {
                what: "workspace (made by another model)",
                expected: self.d,
                got: ws.d,
            });
        }
        let b = self.basis();
        if ws.n != b {
            ws.kstar.resize(b, 0.0);
            ws.tmp.resize(b, 0.0);
            for lane in &mut ws.lanes {
                lane.kstar.resize(b, 0.0);
                lane.tmp.resize(b, 0.0);
            }
            ws.n = b;
        }
        if ws.lanes.len() != self.p && self.takes_parallel_variance() {
            ws.lanes = (0..self.p).map(|_| Lane::new(self.d, b)).collect();
        }
        check_finite("prediction input", x)
    }

    fn check_out(&self, what: &'static str, v: &[f64]) -> Result<(), GpError> {
        if v.len() != self.p {
            return Err(GpError::DimensionMismatch {
                what,
                expected: self.p,
                got: v.len(),
            });
        }
        Ok(())
    }

    /// One output's kernel row k(x*, X) for the normalised query `xn` into
    /// `kstar` (the query scaled by its length scales into `xs`).
    #[inline]
    fn kernel_row_at(
        o: &OutputGp,
        xn: &[f64],
        b: usize,
        xs: &mut [f64],
        kstar: &mut [f64],
    ) -> Result<(), GpError> {
        Self::scale_query(o, xn, xs);
        kernel_row_dispatched(&o.xs_cols, b, xs, o.hp.signal_variance, kstar).map_err(core_error)
    }

    /// The scaled query x_n/ℓ of output `o` into `xs`.
    #[inline]
    fn scale_query(o: &OutputGp, xn: &[f64], xs: &mut [f64]) {
        for ((s, v), l) in xs.iter_mut().zip(xn).zip(&o.hp.length_scales) {
            *s = v / l;
        }
    }

    /// Posterior mean and latent variance at one point, without allocating
    /// (provided a function prior mean does not allocate, and unless
    /// [`set_parallel_variance`](Self::set_parallel_variance) is on).
    ///
    /// `x` has length d; `mean` and `var` length p. `var` is the variance of
    /// the latent function f(x), not of a new noisy observation: add
    /// [`OutputGp::hyperparameters_original`]`.noise_variance` for that.
    /// Cost O(p·N·(d + N)) for the exact GP (see [`VarianceMode`]), O(p·M·(d + M))
    /// for a sparse one.
    pub fn predict_into(
        &self,
        x: &[f64],
        mean: &mut [f64],
        var: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), GpError> {
        self.check_point(x, ws)?;
        self.check_out("mean output", mean)?;
        self.check_out("variance output", var)?;
        self.input_norm.apply(x, &mut ws.xn);
        self.mean.eval(x, &mut ws.prior);
        let b = ws.n;
        let flip = ws.flip;
        ws.flip = !flip;
        if self.takes_parallel_variance()
            && ws.lanes.len() == self.p
            && self.predict_parallel(mean, var, ws, flip)?
        {
            return Ok(());
        }
        for j in 0..self.p {
            let j = if flip { self.p - 1 - j } else { j };
            let o = &self.outputs[j];
            Self::kernel_row_at(o, &ws.xn, b, &mut ws.xs, &mut ws.kstar)?;
            let mn = core_gp::dot(&ws.kstar, &o.alpha).map_err(core_error)?;
            let vv = match &o.post {
                Posterior::Exact {
                    linv: Some(linv), ..
                } if self.variance_mode == VarianceMode::Inverse => {
                    packed::lower_matvec_dir(linv, &ws.kstar, &mut ws.tmp, flip);
                    packed::norm2(&ws.tmp)
                }
                Posterior::Exact { l, .. } => {
                    packed::forward_rows(l, &mut ws.kstar);
                    packed::norm2(&ws.kstar)
                }
                Posterior::Sparse { lu, lb, .. } => {
                    packed::forward_rows(lu, &mut ws.kstar);
                    let a = packed::norm2(&ws.kstar);
                    packed::forward_rows(lb, &mut ws.kstar);
                    a - packed::norm2(&ws.kstar)
                }
            };
            let s = o.output_scale;
            mean[j] = ws.prior[j] + s * mn;
            var[j] = s * s * (o.hp.signal_variance - vv).max(0.0);
        }
        check_finite("prediction (prior mean function output)", mean)?;
        check_finite("prediction variance", var)
    }

    /// `predict_into`'s exact-GP, stored-inverse path with the variance
    /// products of the outputs ⌈p/2⌉..p on the helper thread (see
    /// [`set_parallel_variance`](Self::set_parallel_variance)): each output
    /// runs the same kernels on its own buffers, so the results equal the
    /// sequential path's bit for bit. Returns `Ok(false)` without touching
    /// the outputs when the helper is taken (another clone of the model is
    /// using it) or gone: the caller then takes the sequential path.
    fn predict_parallel(
        &self,
        mean: &mut [f64],
        var: &mut [f64],
        ws: &mut Workspace,
        reverse: bool,
    ) -> Result<bool, GpError> {
        let Some(claim) = self.helper.as_ref().and_then(|h| h.claim()) else {
            return Ok(false);
        };
        let (p, b) = (self.p, ws.n);
        let h = p.div_ceil(2);
        let linv_of = |o: &OutputGp| -> Result<Arc<Vec<f64>>, GpError> {
            match &o.post {
                Posterior::Exact {
                    linv: Some(linv), ..
                } => Ok(Arc::clone(linv)),
                _ => Err(GpError::InvalidModel(
                    "parallel variance needs the stored inverse".into(),
                )),
            }
        };
        // the helper's outputs first: their kernel rows, then the hand-off
        {
            let mut tasks = claim.tasks();
            tasks.resize_with(p - h, Task::default);
            for (t, j) in tasks.iter_mut().zip(h..p) {
                let (o, lane) = (&self.outputs[j], &mut ws.lanes[j]);
                Self::kernel_row_at(o, &ws.xn, b, &mut lane.xs, &mut lane.kstar)?;
                t.linv = Some(linv_of(o)?);
                t.k.clear();
                t.k.extend_from_slice(&lane.kstar);
            }
        }
        let g = claim.post();
        for (j, o) in self.outputs.iter().enumerate() {
            let lane = &mut ws.lanes[j];
            if j < h {
                Self::kernel_row_at(o, &ws.xn, b, &mut lane.xs, &mut lane.kstar)?;
            }
            lane.mean = core_gp::dot(&lane.kstar, &o.alpha).map_err(core_error)?;
            if j < h {
                let linv = linv_of(o)?;
                packed::lower_matvec_dir(&linv, &lane.kstar, &mut lane.tmp, reverse);
                lane.quad = packed::norm2(&lane.tmp);
            }
        }
        for (t, lane) in claim.wait(g).iter().zip(&mut ws.lanes[h..]) {
            lane.quad = t.quad;
        }
        for (j, (o, lane)) in self.outputs.iter().zip(&ws.lanes).enumerate() {
            let s = o.output_scale;
            mean[j] = ws.prior[j] + s * lane.mean;
            var[j] = s * s * (o.hp.signal_variance - lane.quad).max(0.0);
        }
        check_finite("prediction (prior mean function output)", mean)?;
        check_finite("prediction variance", var)?;
        Ok(true)
    }

    /// Whether `predict_into` takes the parallel variance path: an exact GP
    /// with a stored inverse, p ≥ 2, N ≥ [`PARALLEL_VARIANCE_MIN_N`], and
    /// [`set_parallel_variance`](Self::set_parallel_variance) not switched off.
    fn takes_parallel_variance(&self) -> bool {
        self.parallel_variance
            && self.p >= 2
            && self.basis() >= PARALLEL_VARIANCE_MIN_N
            && self.variance_mode == VarianceMode::Inverse
            && self
                .outputs
                .iter()
                .all(|o| matches!(o.post, Posterior::Exact { linv: Some(_), .. }))
    }

    /// Posterior mean only, at one point, without allocating: O(p·N·d)
    /// (O(p·M·d) for a sparse GP).
    pub fn predict_mean_into(
        &self,
        x: &[f64],
        mean: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), GpError> {
        self.check_point(x, ws)?;
        self.check_out("mean output", mean)?;
        self.input_norm.apply(x, &mut ws.xn);
        self.mean.eval(x, &mut ws.prior);
        let b = ws.n;
        for (j, o) in self.outputs.iter().enumerate() {
            Self::scale_query(o, &ws.xn, &mut ws.xs);
            let mn = kernel_dot_dispatched(&o.xs_cols, b, &ws.xs, o.hp.signal_variance, &o.alpha)
                .map_err(core_error)?;
            mean[j] = ws.prior[j] + o.output_scale * mn;
        }
        check_finite("prediction (prior mean function output)", mean)
    }

    /// Posterior mean and its gradient with respect to the input at one
    /// point, without allocating: `mean` has length p, `grad` is row-major
    /// p × d (∂mean_j/∂x_m at `grad[j * d + m]`). For the squared-exponential
    /// kernel on normalised inputs x̃ = (x − shift)/scale,
    /// ∂m_j/∂x_m = s_j Σ_i α_i k(x̃, x̃_i) (x̃_i,m − x̃_m)/ℓ_m² / scale_m (ℓ
    /// in normalised units). A user function prior mean has no known
    /// gradient: [`GpError::InvalidModel`]. O(p·N·d).
    pub fn predict_mean_gradient_into(
        &self,
        x: &[f64],
        mean: &mut [f64],
        grad: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), GpError> {
        self.check_point(x, ws)?;
        self.check_out("mean output", mean)?;
        let d = ws.d;
        if grad.len() != self.p * d {
            return Err(GpError::DimensionMismatch {
                what: "gradient output (p × d)",
                expected: self.p * d,
                got: grad.len(),
            });
        }
        if matches!(self.mean, Resolved::Function(_)) {
            return Err(GpError::InvalidModel(
                "the gradient of a function prior mean is unknown".into(),
            ));
        }
        self.input_norm.apply(x, &mut ws.xn);
        self.mean.eval(x, &mut ws.prior);
        let b = ws.n;
        for (j, o) in self.outputs.iter().enumerate() {
            Self::kernel_row_at(o, &ws.xn, b, &mut ws.xs, &mut ws.kstar)?;
            // as predict_mean_into (kernel_dot = kernel_row + dot), bit for bit
            let mn = core_gp::dot(&ws.kstar, &o.alpha).map_err(core_error)?;
            mean[j] = ws.prior[j] + o.output_scale * mn;
            // w_i = α_i k_i, in place of k (no longer needed)
            for (k, a) in ws.kstar.iter_mut().zip(&o.alpha) {
                *k *= a;
            }
            for m in 0..d {
                // Σ_i w_i (x̃s_i,m − x̃s_m), x̃s = x̃/ℓ (scaled inputs), by
                // the lane-wise dot product (its sums do not wait on one
                // another)
                let col = &o.xs_cols[m * b..(m + 1) * b];
                for (t, xi) in ws.tmp.iter_mut().zip(col) {
                    *t = xi - ws.xs[m];
                }
                let g = core_gp::dot(&ws.kstar, &ws.tmp).map_err(core_error)?;
                let dxs_dx = 1.0 / (o.hp.length_scales[m] * self.input_norm.scale[m]);
                grad[j * d + m] = o.output_scale * g * dxs_dx;
            }
        }
        check_finite("prediction (prior mean function output)", mean)?;
        check_finite("prediction gradient", grad)
    }

    /// Posterior means and latent variances at m points (row-major m × d);
    /// results are identical, bit for bit, to calling
    /// [`predict_into`](Self::predict_into) on each point.
    ///
    /// Cost O(m·p·N·(d + N)) as m single-point predictions, but for an exact
    /// GP with the stored inverse ([`VarianceMode::Inverse`], the default)
    /// the points go in chunks, and each chunk reads each output's packed
    /// L⁻¹ (N²/2 values, 1 MB at N = 512, more than a core's L2) once, with
    /// the products in AVX2 registers where the CPU has them.
    /// Chunks run in parallel (rayon); with fewer chunks than threads the
    /// outputs of a chunk do; single points run in parallel on the other
    /// paths. Allocates the outputs and O(chunk·N) buffers (per output when
    /// the outputs run in parallel).
    pub fn predict(&self, points: &[f64]) -> Result<Prediction, GpError> {
        if points.len() % self.d != 0 {
            return Err(GpError::DimensionMismatch {
                what: "prediction inputs (multiple of the input dimension)",
                expected: points.len().div_ceil(self.d) * self.d,
                got: points.len(),
            });
        }
        let m = points.len() / self.d;
        let mut mean = vec![0.0; m * self.p];
        let mut variance = vec![0.0; m * self.p];
        if self.batches_variance() && self.d > 0 {
            let chunk = self.batch_chunk();
            // Fewer chunks than threads (a short horizon): the outputs of a
            // chunk run in parallel instead.
            let lanes = if m.div_ceil(chunk) < rayon::current_num_threads() {
                self.p
            } else {
                1
            };
            points
                .par_chunks(chunk * self.d)
                .zip(mean.par_chunks_mut(chunk * self.p))
                .zip(variance.par_chunks_mut(chunk * self.p))
                .try_for_each_init(
                    || Batch::new(chunk, self.d, self.p, self.basis(), lanes),
                    |buf, ((x, mu), va)| self.predict_chunk(x, mu, va, buf),
                )?;
            return Ok(Prediction { mean, variance });
        }
        points
            .par_chunks_exact(self.d)
            .zip(mean.par_chunks_exact_mut(self.p))
            .zip(variance.par_chunks_exact_mut(self.p))
            .try_for_each_init(
                || self.workspace(),
                |ws, ((x, mu), va)| self.predict_into(x, mu, va, ws),
            )?;
        Ok(Prediction { mean, variance })
    }

    /// Whether [`predict`](Self::predict) shares the pass over L⁻¹ between
    /// points: an exact GP whose outputs all store their inverse, in
    /// [`VarianceMode::Inverse`].
    fn batches_variance(&self) -> bool {
        self.variance_mode == VarianceMode::Inverse
            && self
                .outputs
                .iter()
                .all(|o| matches!(o.post, Posterior::Exact { linv: Some(_), .. }))
    }

    /// Points per chunk of the batched variance: their kernel rows and
    /// products (2 × chunk × N values) within ≈ 256 KB, half a Zen 3 L2,
    /// and at most 32 (at N = 512, 20 points per pass already cut the
    /// product from 28.6 to 8.6 µs per point).
    fn batch_chunk(&self) -> usize {
        (BATCH_BYTES / (16 * self.basis().max(1))).clamp(1, 32)
    }

    /// [`predict_into`](Self::predict_into) for the points of one chunk,
    /// with the variance's pass over L⁻¹ shared: the same kernels on the
    /// same values in the same order, so the same bits.
    fn predict_chunk(
        &self,
        points: &[f64],
        mean: &mut [f64],
        var: &mut [f64],
        buf: &mut Batch,
    ) -> Result<(), GpError> {
        let (d, p) = (self.d, self.p);
        let m = points.len() / d;
        let Batch { xn, prior, lanes } = buf;
        for (h, x) in points.chunks_exact(d).enumerate() {
            check_finite("prediction input", x)?;
            self.input_norm.apply(x, &mut xn[h * d..(h + 1) * d]);
            self.mean.eval(x, &mut prior[h * p..(h + 1) * p]);
        }
        let mut write = |j: usize, o: &OutputGp, lane: &OutputBatch| {
            let s = o.output_scale;
            for h in 0..m {
                mean[h * p + j] = prior[h * p + j] + s * lane.mn[h];
                var[h * p + j] = s * s * (o.hp.signal_variance - lane.quad[h]).max(0.0);
            }
        };
        if lanes.len() == p && p > 1 {
            // one output per rayon task (one chunk, idle threads)
            lanes
                .par_iter_mut()
                .zip(self.outputs.par_iter())
                .try_for_each(|(lane, o)| self.output_chunk(o, xn, m, lane))?;
            for (j, (o, lane)) in self.outputs.iter().zip(lanes.iter()).enumerate() {
                write(j, o, lane);
            }
        } else {
            let lane = &mut lanes[0];
            for (j, o) in self.outputs.iter().enumerate() {
                self.output_chunk(o, xn, m, lane)?;
                write(j, o, lane);
            }
        }
        for (mu, va) in mean.chunks_exact(p).zip(var.chunks_exact(p)) {
            check_finite("prediction (prior mean function output)", mu)?;
            check_finite("prediction variance", va)?;
        }
        Ok(())
    }

    /// One output's k*ᵀα (normalised units) and ‖L⁻¹k*‖² at the m points
    /// of a chunk (`xn` holds their normalised inputs), into `lane.mn` and
    /// `lane.quad`; the pass over L⁻¹ is shared between the points.
    fn output_chunk(
        &self,
        o: &OutputGp,
        xn: &[f64],
        m: usize,
        lane: &mut OutputBatch,
    ) -> Result<(), GpError> {
        let (d, b) = (self.d, self.basis());
        let Posterior::Exact {
            linv: Some(linv), ..
        } = &o.post
        else {
            return Err(GpError::InvalidModel(
                "batched variance needs the stored inverse".into(),
            ));
        };
        let ks = &mut lane.kstar[..m * b];
        for (h, k) in ks.chunks_exact_mut(b).enumerate() {
            Self::kernel_row_at(o, &xn[h * d..(h + 1) * d], b, &mut lane.xs, k)?;
            lane.mn[h] = core_gp::dot(k, &o.alpha).map_err(core_error)?;
        }
        let tmp = &mut lane.tmp[..m * b];
        packed::lower_matvec_many(linv, b, ks, tmp);
        for (q, t) in lane.quad.iter_mut().zip(tmp.chunks_exact(b)) {
            *q = packed::norm2(t);
        }
        Ok(())
    }
}

/// [`core_gp::kernel_row`] compiled for AVX2 where the CPU has it (see
/// [`kernel_dot_dispatched`]; the same bits).
fn kernel_row_dispatched(
    inputs: &[f64],
    n: usize,
    q: &[f64],
    signal_variance: f64,
    out: &mut [f64],
) -> Result<(), core_gp::GpError> {
    let op = simd_op!(<'a> {
        inputs: &'a [f64],
        n: usize,
        q: &'a [f64],
        signal_variance: f64,
        out: &'a mut [f64],
    } -> Result<(), core_gp::GpError> {
        core_gp::kernel_row(inputs, n, q, signal_variance, out)
    });
    pulp::Arch::new().dispatch(op)
}

/// [`core_gp::kernel_dot`] compiled for AVX2 where the CPU has it: inlined
/// into pulp's AVX2 function, so its exponentials run four to a register
/// (two on baseline x86-64). The same bits either way: the exponential is
/// elementwise and the sums keep their lanes and order.
fn kernel_dot_dispatched(
    inputs: &[f64],
    n: usize,
    q: &[f64],
    signal_variance: f64,
    weights: &[f64],
) -> Result<f64, core_gp::GpError> {
    let op = simd_op!(<'a> {
        inputs: &'a [f64],
        n: usize,
        q: &'a [f64],
        signal_variance: f64,
        weights: &'a [f64],
    } -> Result<f64, core_gp::GpError> {
        core_gp::kernel_dot(inputs, n, q, signal_variance, weights)
    });
    pulp::Arch::new().dispatch(op)
}

/// Bytes of kernel rows and products a chunk of [`Gp::predict`] keeps.
const BATCH_BYTES: usize = 256 * 1024;

/// Buffers of one chunk of [`Gp::predict`]'s batched variance: the
/// points' normalised inputs and prior means, and one [`OutputBatch`] (or
/// one per output when the outputs run in parallel).
struct Batch {
    xn: Vec<f64>,
    prior: Vec<f64>,
    lanes: Vec<OutputBatch>,
}

/// One output's buffers and results for a chunk of points.
struct OutputBatch {
    xs: Vec<f64>,
    kstar: Vec<f64>,
    tmp: Vec<f64>,
    mn: Vec<f64>,
    quad: Vec<f64>,
}

impl Batch {
    fn new(chunk: usize, d: usize, p: usize, b: usize, lanes: usize) -> Self {
        Self {
            xn: vec![0.0; chunk * d],
            prior: vec![0.0; chunk * p],
            lanes: (0..lanes)
                .map(|_| OutputBatch {
                    xs: vec![0.0; d],
                    kstar: vec![0.0; chunk * b],
                    tmp: vec![0.0; chunk * b],
                    mn: vec![0.0; chunk],
                    quad: vec![0.0; chunk],
                })
                .collect(),
        }
    }
}
