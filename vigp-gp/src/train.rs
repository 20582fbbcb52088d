//! Training ([`Gp::train`]) and fitting at given hyperparameters
//! ([`Gp::fit`]): validation and normalisation of the data, the inducing
//! points of a sparse GP, the optimiser runs (`restarts`) and the
//! posterior of the winning hyperparameters.

use std::sync::Arc;

use faer::Par;
use rayon::prelude::*;

use crate::error::GpError;
use crate::kernel::Hyperparameters;
use crate::kernel::original_units;
use crate::lbfgs::{self, LbfgsOptions};
use crate::likelihood::{self, Factor};
use crate::mean::{PriorMean, Resolved};
use crate::model::*;
use crate::normalise::{InputNormaliser, output_scale};
use crate::options::{
    Curvature, InducingInit, InducingReport, Method, OutputReport, TrainOptions, TrainReport,
};
use crate::packed::lower_inverse;
use crate::rng::SplitMix64;
use crate::{packed, restarts, sparse};

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

/// The data as [`Gp::train`] and [`Gp::fit`] model it: dimensions checked,
/// inputs and targets normalised and the prior mean resolved as `opts`
/// ([`TrainOptions::mean`], [`TrainOptions::normalise_inputs`],
/// [`TrainOptions::normalise_outputs`]) say.
pub(crate) fn prepare(
    inputs: &[f64],
    d: usize,
    targets: &[f64],
    p: usize,
    opts: &TrainOptions,
) -> Result<Prepared, GpError> {
    let (mean, normalise_inputs, normalise_outputs) =
        (&opts.mean, opts.normalise_inputs, opts.normalise_outputs);
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
        let evals: Vec<Result<likelihood::LmlEval, GpError>> = wss
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
        let prep = prepare(inputs, input_dim, targets, output_dim, opts)?;
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
        let candidates: Option<Vec<restarts::Job>> = match &opts.candidates {
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
                        let mut job = restarts::Job::new(out, k, clamp(&normalised(h, *s)?));
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
            jobs.push(restarts::Job::new(out, 0, clamp(start)));
            for s in 0..opts.restarts {
                let t = lo
                    .iter()
                    .zip(&hi)
                    .map(|(l, h)| rng.uniform(*l, *h))
                    .collect();
                jobs.push(restarts::Job::new(out, s + 1, t));
            }
        }
        let lopt = LbfgsOptions {
            memory: opts.memory,
            max_iters: opts.max_iters,
            pgtol: opts.pgtol,
            ftol: opts.ftol,
            unit_start: false,
        };
        let set = restarts::StageSettings {
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
        let full = restarts::StageData {
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
                let (stage, reports) = restarts::from_candidates(&full, set, c, jobs, starts, p);
                (stage, Some(reports))
            }
            (None, None) => (restarts::optimise(&full, set, jobs, starts, p, &[]), None),
            (None, Some(m)) => {
                let (stage, reports) =
                    restarts::screened(&full, set, jobs, starts, p, m, opts.seed);
                (stage, Some(reports))
            }
        };
        // every distinct optimum on all samples (original units, best
        // first) and the curvature pairs of the run that reached it
        let (optima, optima_curvature): (Vec<Vec<Hyperparameters>>, Vec<Vec<Curvature>>) =
            restarts::distinct(&stage, &full, p)
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
        let restarts::Stage {
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
        let prep = prepare(inputs, input_dim, targets, output_dim, opts)?;
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
                        let xs = likelihood::scale_inputs(&prep.xn, d, &hp.length_scales);
                        let xs_cols = column_major(&xs, d);
                        let Factor { l, jitter } =
                            likelihood::factorise(&xs_cols, n, d, &hp, j0, Par::Seq)?;
                        let linv = match mode {
                            VarianceMode::Inverse => Some(Arc::new(lower_inverse(&l))),
                            VarianceMode::Solve => None,
                        };
                        let l = packed::pack_rows(&l);
                        let mut fwd = r.clone();
                        packed::forward_rows(&l, &mut fwd);
                        let mut alpha = fwd.clone();
                        packed::backward_rows(&l, &mut alpha);
                        let fit: f64 = fwd.iter().map(|a| a * a).sum();
                        let log_det: f64 = 2.0
                            * (0..n)
                                .map(|i| l[packed::row_start(i) + i].ln())
                                .sum::<f64>();
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
                        let zs = likelihood::scale_inputs(z, d, &hp.length_scales);
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
}
