//! The trained multi-output GP: training, fitting at given hyperparameters,
//! prediction and the accessors the error bound needs.

use faer::{Mat, Par, Side};
use rayon::prelude::*;
use vigp_core::gp as core_gp;

use super::error::GpError;
use super::kernel::Hyperparameters;
use super::lbfgs::{self, LbfgsOptions};
use super::lml::{self, Factor};
use super::mean::{PriorMean, Resolved};
use super::normalise::{InputNormaliser, output_scale};
use super::options::{OutputReport, TrainOptions, TrainReport};
use super::rng::SplitMix64;

/// A trained exact Gaussian process with p independent outputs on d inputs.
///
/// Each output has its own ARD squared-exponential kernel, signal and noise
/// variance, fitted to the residual y − m(x) of a shared [`PriorMean`] m.
/// Inputs may be standardised and residuals scaled (see [`TrainOptions`]);
/// all methods take and return *original* units unless their name says
/// otherwise.
///
/// Cost: training is O(N³) per likelihood evaluation (Cholesky and inverse
/// of the N×N Gram matrix), memory O(N²) per output. Prediction is O(N·d)
/// per output for the mean and O(N²) more for the variance (a triangular
/// solve with the stored Cholesky factor).
///
/// ```
/// use vigp_runtime::gp::{Gp, TrainOptions};
/// // y = sin(x) on 20 points, one input, one output.
/// let x: Vec<f64> = (0..20).map(|i| i as f64 * 0.3).collect();
/// let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
/// let (gp, report) = Gp::train(&x, 1, &y, 1, &TrainOptions::default())?;
/// let mut ws = gp.workspace();
/// let (mut m, mut v) = ([0.0], [0.0]);
/// gp.predict_into(&[1.0], &mut m, &mut v, &mut ws)?;
/// assert!((m[0] - 1f64.sin()).abs() < 1e-3 && v[0] >= 0.0);
/// assert!(report.outputs[0].log_marginal_likelihood.is_finite());
/// # Ok::<(), vigp_runtime::gp::GpError>(())
/// ```
#[derive(Clone)]
pub struct Gp {
    pub(crate) n: usize,
    pub(crate) d: usize,
    pub(crate) p: usize,
    pub(crate) inputs: Vec<f64>,
    pub(crate) targets: Vec<f64>,
    pub(crate) prior_at_inputs: Vec<f64>,
    pub(crate) input_norm: InputNormaliser,
    pub(crate) mean: Resolved,
    pub(crate) outputs: Vec<OutputGp>,
}

impl core::fmt::Debug for Gp {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Gp")
            .field("n", &self.n)
            .field("input_dim", &self.d)
            .field("output_dim", &self.p)
            .field(
                "hyperparameters",
                &self.outputs.iter().map(|o| &o.hp).collect::<Vec<_>>(),
            )
            .finish_non_exhaustive()
    }
}

/// One output's GP inside a [`Gp`]: hyperparameters, Cholesky factor and
/// weights α, with the quantities the uniform error bound (DESIGN §3,
/// Lederer et al. 2019) needs.
///
/// Units: "normalised" means after input standardisation x_n = (x − μ)/s_x
/// and residual scaling r_n = (y − m(x))/s_y; "original" means the units of
/// the data. The kernel in original units is
/// k(x, x') = s_y²·σ_f²·exp(−½ Σ_j (x_j − x'_j)² / (s_x,j·ℓ_j)²), which is
/// exactly the normalised kernel scaled by s_y².
#[derive(Clone)]
pub struct OutputGp {
    pub(crate) hp: Hyperparameters,
    pub(crate) output_scale: f64,
    pub(crate) input_scale: Vec<f64>,
    /// Scaled training inputs x_n/ℓ, **column-major** d × N (the layout of
    /// the shared prediction kernels in `vigp_core::gp`).
    pub(crate) xs_cols: Vec<f64>,
    pub(crate) chol: Mat<f64>,
    pub(crate) alpha: Vec<f64>,
    pub(crate) residual: Vec<f64>,
    pub(crate) jitter: f64,
    pub(crate) lml: f64,
}

/// Preallocated buffers for [`Gp::predict_into`]; make one with [`Gp::workspace`].
#[derive(Clone, Debug)]
pub struct Workspace {
    xn: Vec<f64>,
    xs: Vec<f64>,
    kstar: Vec<f64>,
    prior: Vec<f64>,
    n: usize,
    d: usize,
    p: usize,
}

/// Batch prediction: row-major `m × p` means and latent variances.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// Posterior means, original units, row-major (point-major).
    pub mean: Vec<f64>,
    /// Posterior variances of the latent function (without observation noise),
    /// original units, same layout as `mean`.
    pub variance: Vec<f64>,
}

/// Validated and normalised training data.
pub(crate) struct Prepared {
    pub n: usize,
    pub d: usize,
    pub p: usize,
    pub xn: Vec<f64>,
    pub norm: InputNormaliser,
    pub mean: Resolved,
    pub prior: Vec<f64>,
    /// Per output: normalised residual and its scale.
    pub residuals: Vec<(Vec<f64>, f64)>,
}

/// The shared kernels only fail on inconsistent lengths, which the model's
/// own invariants exclude; reported as an invalid model all the same.
fn core_error(e: core_gp::GpError) -> GpError {
    GpError::InvalidModel(e.to_string())
}

pub(crate) fn check_finite(what: &'static str, v: &[f64]) -> Result<(), GpError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(GpError::NonFinite { what, index }),
        None => Ok(()),
    }
}

pub(crate) fn check_dims(
    inputs: &[f64],
    d: usize,
    targets: &[f64],
    p: usize,
) -> Result<usize, GpError> {
    if d == 0 {
        return Err(GpError::Empty("input dimension is 0"));
    }
    if p == 0 {
        return Err(GpError::Empty("output dimension is 0"));
    }
    if inputs.is_empty() {
        return Err(GpError::Empty("no training samples"));
    }
    if inputs.len() % d != 0 {
        return Err(GpError::DimensionMismatch {
            what: "inputs (length must be a multiple of the input dimension)",
            expected: inputs.len().div_ceil(d) * d,
            got: inputs.len(),
        });
    }
    let n = inputs.len() / d;
    // A corrupt model file can state any output dimension: N·p must not
    // overflow (it cannot equal a real length then).
    let Some(np) = n.checked_mul(p) else {
        return Err(GpError::DimensionMismatch {
            what: "targets (N × output dimension overflows usize)",
            expected: usize::MAX,
            got: targets.len(),
        });
    };
    if targets.len() != np {
        return Err(GpError::DimensionMismatch {
            what: "targets (N × output dimension)",
            expected: np,
            got: targets.len(),
        });
    }
    check_finite("inputs", inputs)?;
    check_finite("targets", targets)?;
    Ok(n)
}

pub(crate) fn prepare(
    inputs: &[f64],
    d: usize,
    targets: &[f64],
    p: usize,
    mean: &PriorMean,
    normalise_inputs: bool,
    normalise_outputs: bool,
) -> Result<Prepared, GpError> {
    let n = check_dims(inputs, d, targets, p)?;
    let norm = if normalise_inputs {
        InputNormaliser::fit(inputs, d)
    } else {
        InputNormaliser::identity(d)
    };
    let mut xn = vec![0.0; n * d];
    for (o, x) in xn.chunks_exact_mut(d).zip(inputs.chunks_exact(d)) {
        norm.apply(x, o);
    }
    let resolved = match mean {
        PriorMean::Zero => Resolved::Zero,
        PriorMean::Constant => {
            let mut c = vec![0.0; p];
            for row in targets.chunks_exact(p) {
                for (a, b) in c.iter_mut().zip(row) {
                    *a += b;
                }
            }
            c.iter_mut().for_each(|a| *a /= n as f64);
            Resolved::Constant(c)
        }
        PriorMean::Function(f) => Resolved::Function(f.clone()),
    };
    let mut prior = vec![0.0; n * p];
    for (o, x) in prior.chunks_exact_mut(p).zip(inputs.chunks_exact(d)) {
        resolved.eval(x, o);
    }
    check_finite("prior mean at the training inputs", &prior)?;
    let residuals = residuals_of(n, p, targets, &prior, normalise_outputs)?;
    Ok(Prepared {
        n,
        d,
        p,
        xn,
        norm,
        mean: resolved,
        prior,
        residuals,
    })
}

fn residuals_of(
    n: usize,
    p: usize,
    targets: &[f64],
    prior: &[f64],
    normalise: bool,
) -> Result<Vec<(Vec<f64>, f64)>, GpError> {
    (0..p)
        .map(|j| {
            let r: Vec<f64> = (0..n)
                .map(|i| targets[i * p + j] - prior[i * p + j])
                .collect();
            check_finite("residual y - m(x)", &r)?;
            let s = if normalise { output_scale(&r) } else { 1.0 };
            Ok((r.into_iter().map(|v| v / s).collect(), s))
        })
        .collect()
}

/// Mixes the seed and output index into an independent SplitMix64 stream.
fn stream_seed(seed: u64, output: usize) -> u64 {
    let mut r = SplitMix64::new(seed ^ (output as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
    r.next_u64()
}

impl Gp {
    /// Trains p independent GPs on row-major `inputs` (N × d) and `targets`
    /// (N × p) by maximising each output's log marginal likelihood with a
    /// bounded L-BFGS in log-hyperparameter space, from
    /// `1 + opts.restarts` starts (the initial point, then log-uniform random
    /// points in the bounds). All (output, start) runs go to rayon in
    /// parallel; each run is sequential and seeded, so the result does not
    /// depend on scheduling. The start with the highest likelihood wins
    /// (ties: the lowest start index).
    ///
    /// Errors: empty data, mismatched lengths, non-finite values, invalid
    /// bounds or initial hyperparameters, or every start failing.
    pub fn train(
        inputs: &[f64],
        input_dim: usize,
        targets: &[f64],
        output_dim: usize,
        opts: &TrainOptions,
    ) -> Result<(Self, TrainReport), GpError> {
        let prep = prepare(
            inputs,
            input_dim,
            targets,
            output_dim,
            &opts.mean,
            opts.normalise_inputs,
            opts.normalise_outputs,
        )?;
        opts.bounds.validate()?;
        let (n, d, p) = (prep.n, prep.d, prep.p);
        let (lo, hi) = opts.bounds.log_box(d);
        let init = match &opts.initial {
            Some(h) => {
                h.validate(d)?;
                h.to_log()
            }
            None => Hyperparameters::isotropic(d, 1.0, 1.0, 1e-2).to_log(),
        };
        let mut jobs = Vec::with_capacity(p * (1 + opts.restarts));
        for out in 0..p {
            let mut rng = SplitMix64::new(stream_seed(opts.seed, out));
            let t0: Vec<f64> = init
                .iter()
                .zip(lo.iter().zip(&hi))
                .map(|(t, (l, h))| t.clamp(*l, *h))
                .collect();
            jobs.push((out, 0usize, t0));
            for s in 0..opts.restarts {
                let t = lo
                    .iter()
                    .zip(&hi)
                    .map(|(l, h)| rng.uniform(*l, *h))
                    .collect();
                jobs.push((out, s + 1, t));
            }
        }
        let lopt = LbfgsOptions {
            memory: 10,
            max_iters: opts.max_iters,
            pgtol: opts.pgtol,
            ftol: opts.ftol,
        };
        let results: Vec<_> = jobs
            .par_iter()
            .map(|(out, _, t0)| {
                let y = &prep.residuals[*out].0;
                // One workspace per (output, start) run: no N×N allocation per evaluation.
                let mut ws = lml::LmlWorkspace::new(n);
                lbfgs::minimise(
                    |t| {
                        let e = lml::lml_ws(&mut ws, &prep.xn, d, y, t, true, Par::Seq)?;
                        Ok((-e.value, e.gradient.into_iter().map(|g| -g).collect()))
                    },
                    t0,
                    &lo,
                    &hi,
                    lopt,
                )
            })
            .collect();
        let mut best: Vec<Option<(usize, Vec<f64>, bool)>> = vec![None; p];
        let mut reports: Vec<(Vec<f64>, usize, Option<GpError>, usize)> =
            vec![(vec![f64::NAN; 1 + opts.restarts], 0, None, 0); p];
        for ((out, start, _), res) in jobs.iter().zip(results) {
            match res {
                Ok(r) => {
                    let value = -r.f;
                    reports[*out].0[*start] = value;
                    reports[*out].1 += r.evaluations;
                    reports[*out].3 += r.iterations;
                    let better = match &best[*out] {
                        None => true,
                        Some((b, _, _)) => value > reports[*out].0[*b],
                    };
                    if better {
                        best[*out] = Some((*start, r.x, r.converged));
                    }
                }
                Err(e) => {
                    reports[*out].2.get_or_insert(e);
                }
            }
        }
        let mut hps = Vec::with_capacity(p);
        for (out, b) in best.iter().enumerate() {
            match b {
                Some((_, t, _)) => hps.push(Hyperparameters::from_log(t)?),
                None => {
                    return Err(GpError::OptimiserFailed {
                        output: out,
                        reason: reports[out]
                            .2
                            .as_ref()
                            .map_or_else(|| "no start".into(), |e| e.to_string()),
                    });
                }
            }
        }
        let gp = Self::from_prepared(inputs, targets, prep, &hps, None)?;
        let report = TrainReport {
            outputs: (0..p)
                .map(|o| {
                    let (start, _, converged) = best[o].as_ref().expect("checked above");
                    OutputReport {
                        log_marginal_likelihood: gp.outputs[o].lml,
                        best_start: *start,
                        start_lmls: reports[o].0.clone(),
                        iterations: reports[o].3,
                        evaluations: reports[o].1,
                        converged: *converged,
                        jitter: gp.outputs[o].jitter,
                    }
                })
                .collect(),
        };
        Ok((gp, report))
    }

    /// Conditions p GPs on the data at given hyperparameters (one per output,
    /// in normalised units), without optimisation. `opts.mean` and the
    /// normalisation flags are used; the optimiser settings are ignored.
    pub fn fit(
        inputs: &[f64],
        input_dim: usize,
        targets: &[f64],
        output_dim: usize,
        hyperparameters: &[Hyperparameters],
        opts: &TrainOptions,
    ) -> Result<Self, GpError> {
        let prep = prepare(
            inputs,
            input_dim,
            targets,
            output_dim,
            &opts.mean,
            opts.normalise_inputs,
            opts.normalise_outputs,
        )?;
        if hyperparameters.len() != output_dim {
            return Err(GpError::DimensionMismatch {
                what: "hyperparameters (one per output)",
                expected: output_dim,
                got: hyperparameters.len(),
            });
        }
        for h in hyperparameters {
            h.validate(input_dim)?;
        }
        Self::from_prepared(inputs, targets, prep, hyperparameters, None)
    }

    /// Builds the model: factorises each output's Gram matrix (in parallel over
    /// outputs), starting the jitter ladder at `start_jitter[o]` if given.
    pub(crate) fn from_prepared(
        inputs: &[f64],
        targets: &[f64],
        prep: Prepared,
        hps: &[Hyperparameters],
        start_jitter: Option<&[f64]>,
    ) -> Result<Self, GpError> {
        let (n, d, p) = (prep.n, prep.d, prep.p);
        let outputs = (0..p)
            .into_par_iter()
            .map(|o| {
                let hp = hps[o].clone();
                let (r, s) = &prep.residuals[o];
                let xs = lml::scale_inputs(&prep.xn, d, &hp.length_scales);
                let j0 = start_jitter.map_or(0.0, |j| j[o]);
                let Factor { l, jitter } = lml::factorise(&xs, n, d, &hp, j0, Par::Seq)?;
                let alpha = lml::solve_alpha(&l, r);
                let fit: f64 = r.iter().zip(&alpha).map(|(a, b)| a * b).sum();
                let lml = -0.5 * fit
                    - 0.5 * lml::log_det(&l)
                    - 0.5 * n as f64 * (2.0 * core::f64::consts::PI).ln();
                if !lml.is_finite() || alpha.iter().any(|a| !a.is_finite()) {
                    return Err(GpError::NotPositiveDefinite { jitter });
                }
                let mut xs_cols = vec![0.0; n * d];
                for (i, row) in xs.chunks_exact(d).enumerate() {
                    for (j, v) in row.iter().enumerate() {
                        xs_cols[j * n + i] = *v;
                    }
                }
                Ok(OutputGp {
                    hp,
                    output_scale: *s,
                    input_scale: prep.norm.scale.clone(),
                    xs_cols,
                    chol: l,
                    alpha,
                    residual: r.clone(),
                    jitter,
                    lml,
                })
            })
            .collect::<Result<Vec<_>, GpError>>()?;
        Ok(Self {
            n,
            d,
            p,
            inputs: inputs.to_vec(),
            targets: targets.to_vec(),
            prior_at_inputs: prep.prior,
            input_norm: prep.norm,
            mean: prep.mean,
            outputs,
        })
    }

    /// Number of training samples N.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Input dimension d.
    pub fn input_dim(&self) -> usize {
        self.d
    }

    /// Output dimension p (the number of independent GPs).
    pub fn output_dim(&self) -> usize {
        self.p
    }

    /// Training inputs, original units, row-major N × d.
    pub fn inputs(&self) -> &[f64] {
        &self.inputs
    }

    /// Training targets, original units, row-major N × p.
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// The prior mean evaluated at the training inputs, row-major N × p.
    pub fn prior_mean_at_inputs(&self) -> &[f64] {
        &self.prior_at_inputs
    }

    /// The input standardisation (identity if it was off).
    pub fn input_normaliser(&self) -> &InputNormaliser {
        &self.input_norm
    }

    /// The GP of output `j` (panics if `j >= output_dim()`, like slice indexing).
    pub fn output(&self, j: usize) -> &OutputGp {
        &self.outputs[j]
    }

    /// All outputs' GPs.
    pub fn outputs(&self) -> &[OutputGp] {
        &self.outputs
    }

    /// Buffers for the allocation-free [`predict_into`](Self::predict_into).
    pub fn workspace(&self) -> Workspace {
        Workspace {
            xn: vec![0.0; self.d],
            xs: vec![0.0; self.d],
            kstar: vec![0.0; self.n],
            prior: vec![0.0; self.p],
            n: self.n,
            d: self.d,
            p: self.p,
        }
    }

    fn check_point(&self, x: &[f64], ws: &Workspace) -> Result<(), GpError> {
        if x.len() != self.d {
            return Err(GpError::DimensionMismatch {
                what: "prediction input",
                expected: self.d,
                got: x.len(),
            });
        }
        if ws.n != self.n || ws.d != self.d || ws.p != self.p {
            return Err(GpError::DimensionMismatch {
                what: "workspace (made by another model)",
                expected: self.n,
                got: ws.n,
            });
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

    /// The scaled query x_n/ℓ of output `o` into ws.xs (ws.xn already set).
    #[inline]
    fn scale_query(o: &OutputGp, ws: &mut Workspace) {
        for ((s, v), l) in ws.xs.iter_mut().zip(&ws.xn).zip(&o.hp.length_scales) {
            *s = v / l;
        }
    }

    /// Posterior mean and latent variance at one point, without allocating
    /// (provided a function prior mean does not allocate).
    ///
    /// `x` has length d; `mean` and `var` length p. `var` is the variance of
    /// the latent function f(x), not of a new noisy observation: add
    /// [`OutputGp::hyperparameters_original`]`.noise_variance` for that.
    /// Cost O(p·N·(d + N)).
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
        for (j, o) in self.outputs.iter().enumerate() {
            Self::scale_query(o, ws);
            core_gp::kernel_row(
                &o.xs_cols,
                self.n,
                &ws.xs,
                o.hp.signal_variance,
                &mut ws.kstar,
            )
            .map_err(core_error)?;
            let mn = core_gp::dot(&ws.kstar, &o.alpha).map_err(core_error)?;
            lml::forward_solve(&o.chol, &mut ws.kstar);
            let vv: f64 = ws.kstar.iter().map(|v| v * v).sum();
            let s = o.output_scale;
            mean[j] = ws.prior[j] + s * mn;
            var[j] = s * s * (o.hp.signal_variance - vv).max(0.0);
        }
        check_finite("prediction (prior mean function output)", mean)?;
        check_finite("prediction variance", var)
    }

    /// Posterior mean only, at one point, without allocating: O(p·N·d).
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
        for (j, o) in self.outputs.iter().enumerate() {
            Self::scale_query(o, ws);
            let mn =
                core_gp::kernel_dot(&o.xs_cols, self.n, &ws.xs, o.hp.signal_variance, &o.alpha)
                    .map_err(core_error)?;
            mean[j] = ws.prior[j] + o.output_scale * mn;
        }
        check_finite("prediction (prior mean function output)", mean)
    }

    /// Posterior means and latent variances at m points (row-major m × d),
    /// computed in parallel over points; results are identical to calling
    /// [`predict_into`](Self::predict_into) on each point.
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
}

impl OutputGp {
    /// Hyperparameters in normalised units (what the optimiser sees).
    pub fn hyperparameters(&self) -> &Hyperparameters {
        &self.hp
    }

    /// Hyperparameters in original units: ℓ_j·s_x,j, σ_f²·s_y², σ_n²·s_y².
    pub fn hyperparameters_original(&self) -> Hyperparameters {
        let s2 = self.output_scale * self.output_scale;
        Hyperparameters {
            length_scales: self
                .hp
                .length_scales
                .iter()
                .zip(&self.input_scale)
                .map(|(l, s)| l * s)
                .collect(),
            signal_variance: self.hp.signal_variance * s2,
            noise_variance: self.hp.noise_variance * s2,
        }
    }

    /// The output scale s_y (1 if output normalisation was off).
    pub fn output_scale(&self) -> f64 {
        self.output_scale
    }

    /// Number of training samples N.
    pub fn n(&self) -> usize {
        self.alpha.len()
    }

    /// Log marginal likelihood of the normalised residuals at the fitted
    /// hyperparameters. In original units it is this minus N·ln s_y.
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.lml
    }

    /// Jitter added to the diagonal, normalised units (0 if none was needed).
    /// In original units: this times s_y².
    pub fn jitter(&self) -> f64 {
        self.jitter
    }

    /// α_n = (K_n + (σ_n² + jitter)·I)⁻¹ r_n in normalised units.
    pub fn alpha_normalised(&self) -> &[f64] {
        &self.alpha
    }

    /// α = (K + σ²I)⁻¹ (y − m(X)) in original units (= α_n / s_y), where
    /// K, σ² are in original units and the jitter counts as noise.
    pub fn alpha(&self) -> Vec<f64> {
        self.alpha.iter().map(|a| a / self.output_scale).collect()
    }

    /// Normalised residuals r_n = (y − m(X)) / s_y at the training inputs.
    pub fn residual_normalised(&self) -> &[f64] {
        &self.residual
    }

    /// ln det(K_n + (σ_n² + jitter)·I) of the normalised Gram matrix, from
    /// the stored Cholesky factor in O(N) (the RKHS error bound's
    /// information-gain term needs it). In original units add 2N·ln s_y.
    pub fn log_det_normalised(&self) -> f64 {
        lml::log_det(&self.chol)
    }

    /// The regularisation λ = σ_n² + jitter (normalised units) that the
    /// posterior mean and variance were computed with.
    pub fn regularisation_normalised(&self) -> f64 {
        self.hp.noise_variance + self.jitter
    }

    /// Cheap rigorous upper bound on ‖(K + σ²I)⁻¹‖₂ in original units:
    /// 1 / ((σ_n² + jitter)·s_y²), since K is positive semi-definite.
    pub fn inv_gram_norm_bound(&self) -> f64 {
        1.0 / ((self.hp.noise_variance + self.jitter) * self.output_scale * self.output_scale)
    }

    /// ‖(K + σ²I)⁻¹‖₂ = 1/λ_min in original units, from the eigenvalues of
    /// L·Lᵀ: O(N³) time and O(N²) memory per call.
    pub fn inv_gram_norm(&self) -> Result<f64, GpError> {
        let n = self.n();
        let mut l = self.chol.clone();
        for j in 0..n {
            for i in 0..j {
                l[(i, j)] = 0.0;
            }
        }
        let a = &l * l.transpose();
        let ev = a
            .self_adjoint_eigenvalues(Side::Lower)
            .map_err(|e| GpError::InvalidModel(format!("eigenvalues failed: {e:?}")))?;
        let lmin = ev.iter().copied().fold(f64::INFINITY, f64::min);
        // Rounding can put λ_min slightly below its true value; never below
        // the noise, which bounds it from below in exact arithmetic.
        let lmin = lmin.max(self.hp.noise_variance + self.jitter);
        Ok(1.0 / (lmin * self.output_scale * self.output_scale))
    }

    /// Lipschitz constant of x ↦ k(x, x') in original input units (Euclidean
    /// norm): s_y²·σ_f²·e^{−1/2} / min_j(s_x,j·ℓ_j).
    pub fn kernel_lipschitz(&self) -> f64 {
        self.hyperparameters_original().kernel_lipschitz()
    }

    /// max_x k(x, x) = s_y²·σ_f², original units.
    pub fn kernel_max(&self) -> f64 {
        self.hp.signal_variance * self.output_scale * self.output_scale
    }
}
