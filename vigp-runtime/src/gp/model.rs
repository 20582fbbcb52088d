//! The trained multi-output GP: training, fitting at given hyperparameters,
//! prediction and the accessors the error bound needs.

use std::sync::Arc;

use faer::{Mat, Par, Side};
use rayon::prelude::*;
use vigp_core::gp as core_gp;

use super::error::GpError;
use super::helper::{Helper, Task};
use super::kernel::Hyperparameters;
use super::lbfgs::{self, LbfgsOptions};
use super::lml::{self, Factor};
use super::mean::{PriorMean, Resolved};
use super::normalise::{InputNormaliser, output_scale};
use super::options::{
    Curvature, InducingInit, InducingReport, Method, OutputReport, TrainOptions, TrainReport,
};
use super::rng::SplitMix64;
use super::{sparse, train, tri};

/// How [`Gp::predict_into`] computes the posterior variance of an exact GP
/// (both give σ_f² − kᵀ(K + σ²I)⁻¹k; the mean is not affected).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VarianceMode {
    /// ‖L⁻¹k‖² with L⁻¹ computed once when the model is built (N³/6 flops
    /// and N²/2 more numbers per output): a product of contiguous rows,
    /// the faster path (see `docs/gp.md`, "The variance").
    #[default]
    Inverse,
    /// ‖L⁻¹k‖² by forward substitution with the Cholesky factor L (blocked
    /// by four rows): no extra memory.
    Solve,
}

/// The factorised posterior of one output.
#[derive(Clone)]
pub(crate) enum Posterior {
    /// Exact GP: L = chol(K + (σ_n² + jitter)·I) (packed rows), optionally
    /// L⁻¹ (packed rows), and L⁻¹r (for appending samples).
    Exact {
        l: Vec<f64>,
        linv: Option<Arc<Vec<f64>>>,
        fwd: Vec<f64>,
    },
    /// Sparse GP (see `sparse`): chol(K_uu + ε·σ_f²·I), chol(B), A·r.
    Sparse {
        lu: Vec<f64>,
        lb: Vec<f64>,
        ay: Vec<f64>,
    },
}

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
    /// Inducing inputs of a sparse GP (normalised units, row-major M × d).
    pub(crate) inducing: Option<Vec<f64>>,
    pub(crate) variance_mode: VarianceMode,
    pub(crate) parallel_variance: bool,
    /// The variance helper thread of [`Gp::set_parallel_variance`] (shared
    /// by clones; `None` when off or when no thread could be started).
    pub(crate) helper: Option<Arc<Helper>>,
}

impl Lane {
    fn new(d: usize, b: usize) -> Self {
        Self {
            xs: vec![0.0; d],
            kstar: vec![0.0; b],
            tmp: vec![0.0; b],
            mean: 0.0,
            quad: 0.0,
        }
    }
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
/// weights α, with the quantities the uniform error bound ([`crate::bound`],
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
    /// Scaled training inputs x_n/ℓ (exact) or inducing inputs z/ℓ
    /// (sparse), **column-major** d × N (or d × M): the layout of the shared
    /// prediction kernels in `vigp_core::gp`.
    pub(crate) xs_cols: Vec<f64>,
    pub(crate) post: Posterior,
    /// Weights of the predictive mean: α (N, exact) or u (M, sparse).
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
    tmp: Vec<f64>,
    prior: Vec<f64>,
    /// One set of buffers per output for the parallel variance (empty when
    /// the model never takes that path).
    lanes: Vec<Lane>,
    /// Visit the outputs and L⁻¹'s rows in reverse in the next call
    /// (alternates: the part of L⁻¹ read last is then read first, from
    /// the core's cache; see `tri::lower_matvec_dir`).
    flip: bool,
    n: usize,
    d: usize,
    p: usize,
}

/// One output's buffers and results in the parallel variance path.
#[derive(Clone, Debug)]
struct Lane {
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

/// Curvature pairs (s, y), oldest first.
type CurvaturePairs = Vec<(Vec<f64>, Vec<f64>)>;

/// A candidate's curvature pairs as the seed memory of its refinement on
/// `n` samples: every y scaled by n / `samples` (the likelihood's curvature
/// grows with the sample count). Errors for pairs that are not d + 2 long
/// or not finite, or for `samples` 0.
fn seed_memory(c: &Curvature, n: usize, d: usize) -> Result<CurvaturePairs, GpError> {
    if c.samples == 0 {
        return Err(GpError::InvalidOptions(
            "candidate_curvature: samples must be at least 1",
        ));
    }
    let scale = n as f64 / c.samples as f64;
    c.pairs
        .iter()
        .map(|(s, y)| {
            for v in [s, y] {
                if v.len() != d + 2 {
                    return Err(GpError::DimensionMismatch {
                        what: "candidate_curvature pair (d + 2 log-hyperparameters)",
                        expected: d + 2,
                        got: v.len(),
                    });
                }
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(GpError::InvalidOptions(
                        "candidate_curvature: pairs must be finite",
                    ));
                }
            }
            Ok((s.clone(), y.iter().map(|v| v * scale).collect()))
        })
        .collect()
}

/// Normalised-unit hyperparameters in original units: ℓ_j·s_x,j,
/// σ_f²·s_y², σ_n²·s_y² (`input_scale` s_x, `output_scale` s_y).
fn original_units(hp: &Hyperparameters, input_scale: &[f64], output_scale: f64) -> Hyperparameters {
    let s2 = output_scale * output_scale;
    Hyperparameters {
        length_scales: hp
            .length_scales
            .iter()
            .zip(input_scale)
            .map(|(l, s)| l * s)
            .collect(),
        signal_variance: hp.signal_variance * s2,
        noise_variance: hp.noise_variance * s2,
    }
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
        PriorMean::Constant => Resolved::Constant(super::normalise::column_means(targets, p)),
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

/// (start LMLs, evaluations, first error, iterations, start evaluations).
type StartTally = (Vec<f64>, usize, Option<GpError>, usize, Vec<usize>);

/// Mixes the seed and output index into an independent SplitMix64 stream.
fn stream_seed(seed: u64, output: usize) -> u64 {
    let mut r = SplitMix64::new(seed ^ (output as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
    r.next_u64()
}

/// Row-major N × d → column-major d × N.
fn column_major(x: &[f64], d: usize) -> Vec<f64> {
    let n = x.len() / d;
    let mut out = vec![0.0; n * d];
    for (i, row) in x.chunks_exact(d).enumerate() {
        for (j, v) in row.iter().enumerate() {
            out[j * n + i] = *v;
        }
    }
    out
}

/// L⁻¹ of a lower-triangular factor (the upper part of `l` is ignored),
/// packed by rows.
fn lower_inverse(l: &Mat<f64>) -> Vec<f64> {
    let n = l.nrows();
    let mut low = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for i in j..n {
            low[(i, j)] = l[(i, j)];
        }
    }
    let mut inv = Mat::<f64>::zeros(n, n);
    faer::linalg::triangular_inverse::invert_lower_triangular(inv.as_mut(), low.as_ref(), Par::Seq);
    tri::pack_rows(&inv)
}

/// The inducing inputs (normalised units, row-major M × d) of a sparse
/// `opts.method`, or `None` for the exact GP.
fn inducing_points(prep: &Prepared, opts: &TrainOptions) -> Result<Option<Vec<f64>>, GpError> {
    let Method::Sparse(so) = &opts.method else {
        return Ok(None);
    };
    let (n, d) = (prep.n, prep.d);
    let m = so.inducing;
    if m == 0 || m > n {
        return Err(GpError::DimensionMismatch {
            what: "inducing points (1..=N)",
            expected: n,
            got: m,
        });
    }
    Ok(Some(match &so.init {
        InducingInit::KMeansPlusPlus { lloyd_iters } => {
            sparse::kmeans_pp(&prep.xn, d, m, *lloyd_iters, opts.seed)
        }
        InducingInit::First => prep.xn[..m * d].to_vec(),
        InducingInit::Given(z) => {
            if z.len() != m * d {
                return Err(GpError::DimensionMismatch {
                    what: "given inducing points (M × d)",
                    expected: m * d,
                    got: z.len(),
                });
            }
            check_finite("inducing points", z)?;
            let mut out = vec![0.0; m * d];
            for (o, x) in out.chunks_exact_mut(d).zip(z.chunks_exact(d)) {
                prep.norm.apply(x, o);
            }
            out
        }
    }))
}

/// The joint refinement of [`SparseOptions::optimise_inducing`]: maximises
/// Σ_o F_o(θ_o, Z) over every output's θ_o (in the box `lo`, `hi`) and the
/// shared inducing inputs Z (normalised units, row-major M × d; each
/// coordinate within the inputs' range widened by the range on either
/// side, or by as much more as a given initial point needs)
/// with one L-BFGS run from `thetas` and `z0`, where the bounds sum to
/// `bound_before`.
///
/// [`SparseOptions::optimise_inducing`]: super::SparseOptions::optimise_inducing
fn refine_inducing(
    prep: &Prepared,
    z0: Vec<f64>,
    thetas: &[Vec<f64>],
    bound_before: f64,
    lo: &[f64],
    hi: &[f64],
    lopt: LbfgsOptions,
) -> Result<Refined, GpError> {
    let (n, d, p) = (prep.n, prep.d, prep.p);
    let m = z0.len() / d;
    let k = d + 2;
    // per input: the data's range widened by that range on either side
    let (mut zlo, mut zhi) = (vec![f64::INFINITY; d], vec![f64::NEG_INFINITY; d]);
    for r in prep.xn.chunks_exact(d) {
        for j in 0..d {
            zlo[j] = zlo[j].min(r[j]);
            zhi[j] = zhi[j].max(r[j]);
        }
    }
    for (l, h) in zlo.iter_mut().zip(zhi.iter_mut()) {
        let w = if *h > *l { *h - *l } else { 1.0 };
        (*l, *h) = (*l - w, *h + w);
    }
    let (mut blo, mut bhi) = (lo.repeat(p), hi.repeat(p));
    for zi in z0.chunks_exact(d) {
        for j in 0..d {
            // given inducing points outside that box widen it: the run
            // starts where `bound_before` was evaluated
            blo.push(zlo[j].min(zi[j]));
            bhi.push(zhi[j].max(zi[j]));
        }
    }
    let mut x0: Vec<f64> = thetas.iter().flatten().copied().collect();
    x0.extend_from_slice(&z0);
    // One workspace per output; outputs evaluated in parallel (a single
    // output uses the pool inside its evaluation instead).
    let mut wss: Vec<sparse::SparseWorkspace> =
        (0..p).map(|_| sparse::SparseWorkspace::new(m, n)).collect();
    let inner = if p == 1 { Par::rayon(0) } else { Par::Seq };
    let mut objective = |x: &[f64]| -> Result<(f64, Vec<f64>), GpError> {
        let z = &x[p * k..];
        let evals: Vec<Result<lml::LmlEval, GpError>> = wss
            .par_iter_mut()
            .enumerate()
            .map(|(o, ws)| {
                let t = &x[o * k..(o + 1) * k];
                sparse::elbo_z_ws(ws, &prep.xn, z, d, &prep.residuals[o].0, t, inner)
            })
            .collect();
        let mut f = 0.0;
        let mut g = vec![0.0; x.len()];
        for (o, e) in evals.into_iter().enumerate() {
            let e = e?;
            f -= e.value;
            for (gi, ei) in g[o * k..(o + 1) * k].iter_mut().zip(&e.gradient[..k]) {
                *gi = -ei;
            }
            for (gi, ei) in g[p * k..].iter_mut().zip(&e.gradient[k..]) {
                *gi -= ei;
            }
        }
        Ok((f, g))
    };
    let r = lbfgs::minimise(&mut objective, &x0, &blo, &bhi, lopt)?;
    Ok(Refined {
        thetas: r.x[..p * k].chunks_exact(k).map(<[f64]>::to_vec).collect(),
        z: r.x[p * k..].to_vec(),
        report: InducingReport {
            bound_before,
            bound_after: -r.f,
            iterations: r.iterations,
            evaluations: r.evaluations,
            converged: r.converged,
        },
    })
}

/// What [`refine_inducing`] returns.
struct Refined {
    /// Inducing inputs (normalised units, row-major M × d).
    z: Vec<f64>,
    /// Log hyperparameters, one vector per output.
    thetas: Vec<Vec<f64>>,
    report: InducingReport,
}

impl Gp {
    /// Trains p independent GPs on row-major `inputs` (N × d) and `targets`
    /// (N × p) by maximising each output's log marginal likelihood (or, for
    /// [`Method::Sparse`], its variational lower bound) with a bounded
    /// L-BFGS in log-hyperparameter space, from `1 + opts.restarts` starts
    /// (the initial point or the warm start, then log-uniform random points
    /// in the bounds). All (output, start) runs go to rayon in parallel;
    /// each run is sequential and seeded, so the result does not depend on
    /// scheduling. The start with the highest likelihood wins (ties: the
    /// lowest start index). A single sparse run (one output, no restarts)
    /// uses all threads inside its evaluations instead.
    ///
    /// Each start follows scipy's L-BFGS-B iteration. If an output's best
    /// fit is not preferred over white noise by Akaike's criterion (its
    /// best LML exceeds −(N/2)(1 + ln(2π·yᵀy/N)), white noise at its best
    /// variance, by at most d), the starts whose first trial was a corner
    /// of the box (the way onto the white-noise plateau, where the length
    /// scales are too short for any two inputs to correlate) are run again
    /// with a first step of unit length (see the `lbfgs` module), and the
    /// better end of each counts; the report's evaluations include both
    /// runs. An output still not preferred over white noise after that,
    /// when other outputs were (p > 1), gets one more start from each such
    /// output's optimum (normalised units: the same inputs, and in a
    /// mechanism's velocity components often the same relevant ones); the
    /// report numbers these starts after the random restarts. On the
    /// maximal-coordinate cart-pole log of `docs/gp.md` (sparse, 1 + 1
    /// starts) this fitted v_pole.y, which had stayed on the plateau.
    ///
    /// An exact GP from N = [`SCREEN_FROM`](super::SCREEN_FROM) samples
    /// screens its starts by default ([`TrainOptions::screening`]): all of
    /// the above runs on a seeded subset, and the distinct optima found
    /// there are refined on all samples, each from the subset run's end
    /// point and curvature memory. At N = 512, d = 4, 1 + 10 starts that is
    /// 42 evaluations on all samples (plus 396 on 256 of them) instead of
    /// 381, at the same optimum (`docs/gp.md`, "Screening the starts").
    /// [`TrainOptions::candidates`] hands over the optima of an earlier
    /// training on a subset of the samples instead (a nested sweep's
    /// previous N, [`OutputReport::optima`](super::OutputReport::optima)):
    /// those are refined, and no start runs unless an output falls back;
    /// with [`TrainOptions::candidate_curvature`] each refinement starts
    /// from the earlier run's curvature pairs, as a screened one does.
    ///
    /// Errors: empty data, mismatched lengths (also a warm start or
    /// candidate list per output), non-finite values, invalid bounds,
    /// initial, warm-start or candidate hyperparameters, unusable options
    /// ([`GpError::InvalidOptions`]), an inducing-point count outside
    /// 1..=N, or every start failing.
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
        opts.validate_settings()?;
        let (n, d, p) = (prep.n, prep.d, prep.p);
        let inducing = inducing_points(&prep, opts)?;
        let (lo, hi) = opts.log_box(d);
        let init = match &opts.initial {
            Some(h) => {
                h.validate(d)?;
                h.to_log()
            }
            None => Hyperparameters::isotropic(d, 1.0, 1.0, 1e-2).to_log(),
        };
        // original units → this model's normalised log-hyperparameters
        let normalised = |h: &Hyperparameters, s: f64| -> Result<Vec<f64>, GpError> {
            h.validate(d)?;
            let hn = Hyperparameters {
                length_scales: h
                    .length_scales
                    .iter()
                    .zip(&prep.norm.scale)
                    .map(|(l, sx)| l / sx)
                    .collect(),
                signal_variance: h.signal_variance / (s * s),
                noise_variance: h.noise_variance / (s * s),
            };
            Ok(hn.to_log())
        };
        let per_output = |what: &'static str, got: usize| {
            if got == p {
                Ok(())
            } else {
                Err(GpError::DimensionMismatch {
                    what,
                    expected: p,
                    got,
                })
            }
        };
        let clamp = |t: &[f64]| -> Vec<f64> {
            t.iter()
                .zip(lo.iter().zip(&hi))
                .map(|(t, (l, h))| t.clamp(*l, *h))
                .collect()
        };
        let warm: Option<Vec<Vec<f64>>> = match &opts.warm_start {
            None => None,
            Some(w) => {
                per_output("warm_start (one per output)", w.len())?;
                let out = w
                    .iter()
                    .zip(&prep.residuals)
                    .map(|(h, (_, s))| normalised(h, *s))
                    .collect::<Result<_, _>>()?;
                Some(out)
            }
        };
        let candidates: Option<Vec<train::Job>> = match &opts.candidates {
            None => None,
            Some(c) => {
                per_output("candidates (one list per output)", c.len())?;
                let curvature = opts.candidate_curvature.as_ref();
                if let Some(cc) = curvature {
                    per_output("candidate_curvature (one list per output)", cc.len())?;
                }
                let mut jobs = Vec::new();
                for (out, (list, (_, s))) in c.iter().zip(&prep.residuals).enumerate() {
                    let curv = curvature.map(|cc| &cc[out]);
                    if let Some(cv) = curv
                        && cv.len() != list.len()
                    {
                        return Err(GpError::DimensionMismatch {
                            what: "candidate_curvature (one per candidate)",
                            expected: list.len(),
                            got: cv.len(),
                        });
                    }
                    for (k, h) in list.iter().enumerate() {
                        let mut job = train::Job::new(out, k, clamp(&normalised(h, *s)?));
                        if let Some(cv) = curv {
                            job.memory = seed_memory(&cv[k], n, d)?;
                        }
                        jobs.push(job);
                    }
                }
                Some(jobs)
            }
        };
        let mut jobs = Vec::with_capacity(p * (1 + opts.restarts));
        for out in 0..p {
            let mut rng = SplitMix64::new(stream_seed(opts.seed, out));
            let start = warm.as_ref().map_or(&init, |w| &w[out]);
            jobs.push(train::Job::new(out, 0, clamp(start)));
            for s in 0..opts.restarts {
                let t = lo
                    .iter()
                    .zip(&hi)
                    .map(|(l, h)| rng.uniform(*l, *h))
                    .collect();
                jobs.push(train::Job::new(out, s + 1, t));
            }
        }
        let lopt = LbfgsOptions {
            memory: opts.memory,
            max_iters: opts.max_iters,
            pgtol: opts.pgtol,
            ftol: opts.ftol,
            unit_start: false,
        };
        let set = train::StageSettings {
            lo: &lo,
            hi: &hi,
            lopt,
            inducing: inducing.as_deref(),
            // a single sparse run (one output, no restarts) uses all
            // threads inside its evaluations
            inner_sparse: if jobs.len() == 1 && inducing.is_some() {
                Par::rayon(0)
            } else {
                Par::Seq
            },
        };
        let full = train::StageData {
            xn: &prep.xn,
            n,
            d,
            ys: prep.residuals.iter().map(|r| r.0.as_slice()).collect(),
        };
        // start indices run to the longest candidate list when that is longer
        let starts = opts
            .candidates
            .iter()
            .flatten()
            .map(Vec::len)
            .fold(1 + opts.restarts, usize::max);
        let screen = opts
            .screening
            .subset(n, inducing.is_some(), opts.warm_start.is_some());
        let (stage, screening) = match (candidates, screen) {
            (Some(c), _) => {
                let (stage, reports) = train::from_candidates(&full, set, c, jobs, starts, p);
                (stage, Some(reports))
            }
            (None, None) => (train::optimise(&full, set, jobs, starts, p, &[]), None),
            (None, Some(m)) => {
                let (stage, reports) = train::screened(&full, set, jobs, starts, p, m, opts.seed);
                (stage, Some(reports))
            }
        };
        // every distinct optimum on all samples (original units, best
        // first) and the curvature pairs of the run that reached it
        let (optima, optima_curvature): (Vec<Vec<Hyperparameters>>, Vec<Vec<Curvature>>) =
            train::distinct(&stage, &full, p)
                .iter()
                .zip(&prep.residuals)
                .map(|(kept, (_, s))| {
                    let curvature = kept
                        .iter()
                        .map(|(r, _)| Curvature {
                            samples: n,
                            pairs: r.memory.clone(),
                        })
                        .collect();
                    kept.iter()
                        .map(|(r, _)| {
                            Hyperparameters::from_log(&r.x)
                                .map(|h| original_units(&h, &prep.norm.scale, *s))
                        })
                        .collect::<Result<Vec<_>, _>>()
                        .map(|h| (h, curvature))
                })
                .collect::<Result<Vec<_>, _>>()?
                .into_iter()
                .unzip();
        let train::Stage {
            jobs,
            results,
            extra,
        } = stage;
        let mut best: Vec<Option<(usize, Vec<f64>, bool)>> = vec![None; p];
        // Per output: final LML and evaluations of every start, total
        // evaluations and iterations, the first error.
        let mut reports: Vec<StartTally> = extra
            .iter()
            .map(|e| (vec![f64::NAN; starts + e], 0, None, 0, vec![0; starts + e]))
            .collect();
        for (job, res) in jobs.iter().zip(results) {
            let (out, start) = (&job.out, &job.start);
            match res {
                Ok(r) => {
                    let value = -r.f;
                    reports[*out].0[*start] = value;
                    reports[*out].1 += r.evaluations;
                    reports[*out].3 += r.iterations;
                    reports[*out].4[*start] = r.evaluations;
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
        let mut thetas = Vec::with_capacity(p);
        for (out, b) in best.iter().enumerate() {
            match b {
                Some((_, t, _)) => thetas.push(t.clone()),
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
        let (inducing, inducing_report) = match (&opts.method, inducing) {
            (Method::Sparse(so), Some(z)) if so.optimise_inducing => {
                // the bounds at the winning starts (their optimiser's best points)
                let before = best
                    .iter()
                    .zip(&reports)
                    .map(|(b, r)| b.as_ref().map_or(f64::NAN, |(s, _, _)| r.0[*s]))
                    .sum();
                let r = refine_inducing(&prep, z, &thetas, before, &lo, &hi, lopt)?;
                thetas = r.thetas;
                (Some(r.z), Some(r.report))
            }
            (_, z) => (z, None),
        };
        let hps = thetas
            .iter()
            .map(|t| Hyperparameters::from_log(t))
            .collect::<Result<Vec<_>, _>>()?;
        let gp = Self::from_prepared(inputs, targets, prep, &hps, None, inducing)?;
        let report = TrainReport {
            inducing: inducing_report,
            outputs: (0..p)
                .map(|o| {
                    let (start, _, converged) = best[o].as_ref().expect("checked above");
                    OutputReport {
                        log_marginal_likelihood: gp.outputs[o].lml,
                        best_start: *start,
                        start_lmls: reports[o].0.clone(),
                        iterations: reports[o].3,
                        evaluations: reports[o].1,
                        start_evaluations: reports[o].4.clone(),
                        converged: *converged,
                        jitter: gp.outputs[o].jitter,
                        screening: screening.as_ref().map(|s| s[o].clone()),
                        optima: optima[o].clone(),
                        optima_curvature: optima_curvature[o].clone(),
                    }
                })
                .collect(),
        };
        Ok((gp, report))
    }

    /// Conditions p GPs on the data at given hyperparameters (one per output,
    /// in normalised units), without optimisation. `opts.mean`, the
    /// normalisation flags and `opts.method` (with the inducing points it
    /// chooses) are used; the optimiser settings are ignored.
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
        let inducing = inducing_points(&prep, opts)?;
        Self::from_prepared(inputs, targets, prep, hyperparameters, None, inducing)
    }

    /// Builds the model: factorises each output's Gram matrix (exact) or its
    /// sparse posterior (when `inducing` is given), in parallel over outputs,
    /// starting the jitter ladder at `start_jitter[o]` if given (absolute
    /// for the exact GP, relative K_uu jitter ε for the sparse one).
    pub(crate) fn from_prepared(
        inputs: &[f64],
        targets: &[f64],
        prep: Prepared,
        hps: &[Hyperparameters],
        start_jitter: Option<&[f64]>,
        inducing: Option<Vec<f64>>,
    ) -> Result<Self, GpError> {
        let (n, d, p) = (prep.n, prep.d, prep.p);
        let mode = VarianceMode::default();
        let par = if p == 1 { Par::rayon(0) } else { Par::Seq };
        let outputs = (0..p)
            .into_par_iter()
            .map(|o| {
                let hp = hps[o].clone();
                let (r, s) = &prep.residuals[o];
                let j0 = start_jitter.map_or(0.0, |j| j[o]);
                let out = match &inducing {
                    None => {
                        let xs = lml::scale_inputs(&prep.xn, d, &hp.length_scales);
                        let xs_cols = column_major(&xs, d);
                        let Factor { l, jitter } =
                            lml::factorise(&xs_cols, n, d, &hp, j0, Par::Seq)?;
                        let linv = match mode {
                            VarianceMode::Inverse => Some(Arc::new(lower_inverse(&l))),
                            VarianceMode::Solve => None,
                        };
                        let l = tri::pack_rows(&l);
                        let mut fwd = r.clone();
                        tri::forward_rows(&l, &mut fwd);
                        let mut alpha = fwd.clone();
                        tri::backward_rows(&l, &mut alpha);
                        let fit: f64 = fwd.iter().map(|a| a * a).sum();
                        let log_det: f64 =
                            2.0 * (0..n).map(|i| l[tri::row_start(i) + i].ln()).sum::<f64>();
                        let lml = -0.5 * fit
                            - 0.5 * log_det
                            - 0.5 * n as f64 * (2.0 * core::f64::consts::PI).ln();
                        if !lml.is_finite() || alpha.iter().any(|a| !a.is_finite()) {
                            return Err(GpError::NotPositiveDefinite { jitter });
                        }
                        OutputGp {
                            xs_cols,
                            post: Posterior::Exact { l, linv, fwd },
                            alpha,
                            jitter,
                            lml,
                            hp,
                            output_scale: *s,
                            input_scale: prep.norm.scale.clone(),
                            residual: r.clone(),
                        }
                    }
                    Some(z) => {
                        let f = sparse::factorise(
                            &prep.xn,
                            z,
                            d,
                            r,
                            &hp,
                            j0.max(sparse::KUU_JITTER),
                            par,
                        )?;
                        let zs = lml::scale_inputs(z, d, &hp.length_scales);
                        OutputGp {
                            xs_cols: column_major(&zs, d),
                            post: Posterior::Sparse {
                                lu: f.lu,
                                lb: f.lb,
                                ay: f.ay,
                            },
                            alpha: f.u,
                            jitter: f.eps * hp.signal_variance,
                            lml: f.elbo,
                            hp,
                            output_scale: *s,
                            input_scale: prep.norm.scale.clone(),
                            residual: r.clone(),
                        }
                    }
                };
                Ok(out)
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
            inducing,
            variance_mode: mode,
            parallel_variance: false,
            helper: None,
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

    /// Per output √(σ_n² + jitter) in the targets' units: the noise part
    /// of a predictive standard deviation (the error bounds' scales).
    pub(crate) fn noise_std(&self) -> Vec<f64> {
        self.outputs
            .iter()
            .map(|o| o.regularisation_normalised().sqrt() * o.output_scale())
            .collect()
    }

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
    /// `lane.kstar` (the query scaled by its length scales into `lane.xs`).
    fn lane_kernel_row(o: &OutputGp, xn: &[f64], b: usize, lane: &mut Lane) -> Result<(), GpError> {
        Self::scale_query(o, xn, &mut lane.xs);
        kernel_row_dispatched(
            &o.xs_cols,
            b,
            &lane.xs,
            o.hp.signal_variance,
            &mut lane.kstar,
        )
        .map_err(core_error)
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
            Self::scale_query(o, &ws.xn, &mut ws.xs);
            kernel_row_dispatched(&o.xs_cols, b, &ws.xs, o.hp.signal_variance, &mut ws.kstar)
                .map_err(core_error)?;
            let mn = core_gp::dot(&ws.kstar, &o.alpha).map_err(core_error)?;
            let vv = match &o.post {
                Posterior::Exact {
                    linv: Some(linv), ..
                } if self.variance_mode == VarianceMode::Inverse => {
                    tri::lower_matvec_dir(linv, &ws.kstar, &mut ws.tmp, flip);
                    tri::norm2(&ws.tmp)
                }
                Posterior::Exact { l, .. } => {
                    tri::forward_rows(l, &mut ws.kstar);
                    tri::norm2(&ws.kstar)
                }
                Posterior::Sparse { lu, lb, .. } => {
                    tri::forward_rows(lu, &mut ws.kstar);
                    let a = tri::norm2(&ws.kstar);
                    tri::forward_rows(lb, &mut ws.kstar);
                    a - tri::norm2(&ws.kstar)
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
                Self::lane_kernel_row(o, &ws.xn, b, lane)?;
                t.linv = Some(linv_of(o)?);
                t.k.clear();
                t.k.extend_from_slice(&lane.kstar);
            }
        }
        let g = claim.post();
        for (j, o) in self.outputs.iter().enumerate() {
            let lane = &mut ws.lanes[j];
            if j < h {
                Self::lane_kernel_row(o, &ws.xn, b, lane)?;
            }
            lane.mean = core_gp::dot(&lane.kstar, &o.alpha).map_err(core_error)?;
            if j < h {
                let linv = linv_of(o)?;
                tri::lower_matvec_dir(&linv, &lane.kstar, &mut lane.tmp, reverse);
                lane.quad = tri::norm2(&lane.tmp);
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
            Self::scale_query(o, &ws.xn, &mut ws.xs);
            kernel_row_dispatched(&o.xs_cols, b, &ws.xs, o.hp.signal_variance, &mut ws.kstar)
                .map_err(core_error)?;
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

    /// How the variance of an exact GP is computed (default
    /// [`VarianceMode::Inverse`]).
    pub fn variance_mode(&self) -> VarianceMode {
        self.variance_mode
    }

    /// Switches the variance path of an exact GP: `Inverse` computes L⁻¹
    /// once (O(N³/6) per output, N²/2 numbers of memory), `Solve` drops it.
    /// No effect on a sparse GP (whose variance always solves with its two
    /// M × M factors). Means are unchanged bit for bit.
    pub fn set_variance_mode(&mut self, mode: VarianceMode) {
        self.variance_mode = mode;
        for o in &mut self.outputs {
            if let Posterior::Exact { l, linv, .. } = &mut o.post {
                match mode {
                    VarianceMode::Solve => *linv = None,
                    VarianceMode::Inverse => {
                        if linv.is_none() {
                            let n = o.alpha.len();
                            *linv = Some(Arc::new(lower_inverse(&tri::unpack(l, n))));
                        }
                    }
                }
            }
        }
    }

    /// Whether [`predict_into`](Self::predict_into) (and so the learned
    /// step with its bound) computes some outputs' variances on a helper
    /// thread (default `false`). It applies to an exact GP with
    /// [`VarianceMode::Inverse`], p ≥ 2 outputs and N ≥
    /// [`PARALLEL_VARIANCE_MIN_N`]: the variance streams each output's N²/2
    /// stored numbers, and on two cores two outputs stream at once.
    ///
    /// Switching it on starts one thread for this model (shared by its
    /// clones; one caller at a time, others take the sequential path). The
    /// thread busy-waits for the next prediction for 200 µs after each one,
    /// then parks: while predictions follow each other faster than that (a
    /// control loop, a rollout with bounds) the hand-off takes well under a
    /// microsecond, but the helper keeps a core busy; after a pause the
    /// first prediction pays for waking it (tens of µs). Measured on 2 cores
    /// (`cargo bench --bench learned`, N = 512, p = 2): see `docs/gp.md`,
    /// "Prediction and the learned step". The results equal the sequential
    /// path bit for bit, and after the first call (which sizes the buffers)
    /// a prediction allocates nothing. Leave it off in code that already
    /// runs one task per core. Switching it off stops the thread once no
    /// clone uses it. A workspace made before a switch stays valid (the
    /// first call after it may allocate the per-output buffers).
    pub fn set_parallel_variance(&mut self, on: bool) {
        self.parallel_variance = on;
        if !on {
            self.helper = None;
        } else if self.helper.is_none() {
            self.helper = Helper::spawn().map(Arc::new);
        }
    }

    /// Whether the parallel variance is allowed (see
    /// [`set_parallel_variance`](Self::set_parallel_variance)).
    pub fn parallel_variance(&self) -> bool {
        self.parallel_variance
    }

    /// `true` for a sparse (SGPR) model.
    pub fn is_sparse(&self) -> bool {
        self.inducing.is_some()
    }

    /// Points the posterior is written in (the length of each output's
    /// weights): the N training points of an exact GP, the M inducing
    /// points of a sparse one.
    pub fn posterior_points(&self) -> usize {
        self.outputs
            .first()
            .map_or(self.n, |o| o.alpha_normalised().len())
    }

    /// Inducing inputs of a sparse GP in original units (row-major M × d),
    /// `None` for an exact GP.
    pub fn inducing_points(&self) -> Option<Vec<f64>> {
        self.inducing.as_ref().map(|z| {
            let mut out = z.clone();
            for row in out.chunks_exact_mut(self.d) {
                for ((v, m), s) in row
                    .iter_mut()
                    .zip(&self.input_norm.shift)
                    .zip(&self.input_norm.scale)
                {
                    *v = *v * s + m;
                }
            }
            out
        })
    }

    /// Hyperparameters of every output in original units, for
    /// [`TrainOptions::warm_start`] of the next training run (e.g. after
    /// more samples arrived).
    pub fn warm_start(&self) -> Vec<Hyperparameters> {
        self.outputs
            .iter()
            .map(|o| o.hyperparameters_original())
            .collect()
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
            Self::scale_query(o, &xn[h * d..(h + 1) * d], &mut lane.xs);
            kernel_row_dispatched(&o.xs_cols, b, &lane.xs, o.hp.signal_variance, k)
                .map_err(core_error)?;
            lane.mn[h] = core_gp::dot(k, &o.alpha).map_err(core_error)?;
        }
        let tmp = &mut lane.tmp[..m * b];
        tri::lower_matvec_many(linv, b, ks, tmp);
        for (q, t) in lane.quad.iter_mut().zip(tmp.chunks_exact(b)) {
            *q = tri::norm2(t);
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
    struct Op<'a> {
        inputs: &'a [f64],
        n: usize,
        q: &'a [f64],
        signal_variance: f64,
        out: &'a mut [f64],
    }
    impl pulp::WithSimd for Op<'_> {
        type Output = Result<(), core_gp::GpError>;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
            core_gp::kernel_row(self.inputs, self.n, self.q, self.signal_variance, self.out)
        }
    }
    pulp::Arch::new().dispatch(Op {
        inputs,
        n,
        q,
        signal_variance,
        out,
    })
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
    struct Op<'a> {
        inputs: &'a [f64],
        n: usize,
        q: &'a [f64],
        signal_variance: f64,
        weights: &'a [f64],
    }
    impl pulp::WithSimd for Op<'_> {
        type Output = Result<f64, core_gp::GpError>;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
            core_gp::kernel_dot(
                self.inputs,
                self.n,
                self.q,
                self.signal_variance,
                self.weights,
            )
        }
    }
    pulp::Arch::new().dispatch(Op {
        inputs,
        n,
        q,
        signal_variance,
        weights,
    })
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

impl OutputGp {
    /// Hyperparameters in normalised units (what the optimiser sees).
    pub fn hyperparameters(&self) -> &Hyperparameters {
        &self.hp
    }

    /// Hyperparameters in original units: ℓ_j·s_x,j, σ_f²·s_y², σ_n²·s_y².
    pub fn hyperparameters_original(&self) -> Hyperparameters {
        original_units(&self.hp, &self.input_scale, self.output_scale)
    }

    /// The output scale s_y (1 if output normalisation was off).
    pub fn output_scale(&self) -> f64 {
        self.output_scale
    }

    /// Number of training samples N.
    pub fn n(&self) -> usize {
        self.residual.len()
    }

    /// `true` for an output of a sparse (SGPR) model.
    pub fn is_sparse(&self) -> bool {
        matches!(self.post, Posterior::Sparse { .. })
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

    /// α_n = (K_n + (σ_n² + jitter)·I)⁻¹ r_n in normalised units (for a
    /// sparse GP the M weights u of the inducing points instead:
    /// mean = k(x, Z)·u).
    pub fn alpha_normalised(&self) -> &[f64] {
        &self.alpha
    }

    /// α = (K + σ²I)⁻¹ (y − m(X)) in original units (= α_n / s_y), where
    /// K, σ² are in original units and the jitter counts as noise (sparse:
    /// the inducing-point weights u / s_y).
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
    ///
    /// Errors: [`GpError::InvalidModel`] for a sparse GP (no N × N factor).
    pub fn log_det_normalised(&self) -> Result<f64, GpError> {
        let Posterior::Exact { l, .. } = &self.post else {
            return Err(GpError::InvalidModel(
                "log_det_normalised is defined for exact GPs only (this output is sparse)".into(),
            ));
        };
        // packed rows: row i starts at i(i+1)/2, its diagonal is entry i
        Ok(2.0
            * (0..self.n())
                .map(|i| l[i * (i + 1) / 2 + i].ln())
                .sum::<f64>())
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
    ///
    /// Errors: [`GpError::InvalidModel`] for a sparse GP, whose posterior
    /// has no N × N Gram matrix factor (the uniform error bound of
    /// `vigp::bound` is stated for exact GPs).
    pub fn inv_gram_norm(&self) -> Result<f64, GpError> {
        let Posterior::Exact { l, .. } = &self.post else {
            return Err(GpError::InvalidModel(
                "inv_gram_norm is defined for exact GPs only (this output is sparse)".into(),
            ));
        };
        let n = self.n();
        let l = tri::unpack(l, n);
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
