//! The optimiser runs of [`Gp::train`](super::Gp::train): every (output,
//! start) run in parallel, the white-noise plateau's second chances, and
//! the screening of the starts on a subset of the samples
//! ([`Screening`](super::Screening)).
//!
//! Data flow of one exact training with screening:
//!
//! 1. every start runs on a seeded random subset of m samples (same
//!    normalised units as the full data): scipy's L-BFGS-B iteration, the
//!    plateau retry and the rescue starts, exactly as without screening;
//! 2. per output, the distinct optima found there (equal LML to 1e-6
//!    relative, or equal log-hyperparameters to 1e-2, count once; optima on
//!    the white-noise plateau are dropped when another is not) are refined
//!    on all N samples, from the subset's end point;
//! 3. an output whose best refined fit is still not preferred over white
//!    noise runs its starts again on all samples without screening.
//!
//! With [`TrainOptions::candidates`](super::TrainOptions::candidates) the
//! given optima (of an earlier training on a subset) replace step 1 and
//! its optima; steps 2 and 3 are the same.
//!
//! One evaluation costs ≈ N³ flops, so a start on m = N/4 samples costs
//! 1/64 of one on all of them; the refinements start near an optimum and
//! need fewer evaluations than a random start.

use std::sync::atomic::{AtomicUsize, Ordering};

use faer::Par;
use rayon::prelude::*;

use crate::error::GpError;
use crate::lbfgs::{self, LbfgsOptions, LbfgsResult};
use crate::likelihood;
use crate::options::ScreeningReport;
use crate::rng::SplitMix64;
use crate::sparse;

/// One optimiser run.
#[derive(Clone)]
pub(crate) struct Job {
    /// Output index.
    pub out: usize,
    /// Start index (0 the initial point, then the random restarts, then
    /// rescue starts).
    pub start: usize,
    /// Start point θ₀ (log-hyperparameters, normalised units).
    pub theta: Vec<f64>,
    /// Curvature pairs of an earlier run on a subset, to seed the
    /// optimiser's model (empty: scipy's start).
    pub memory: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Job {
    /// A start from θ₀ with an empty optimiser memory.
    pub(crate) fn new(out: usize, start: usize, theta: Vec<f64>) -> Self {
        Self {
            out,
            start,
            theta,
            memory: Vec::new(),
        }
    }
}

/// The outcome of one optimiser run.
pub(crate) type RunResult = Result<LbfgsResult, GpError>;

/// From this many samples an exact training run's evaluations use the
/// thread pool too: below it one evaluation is a few milliseconds and the
/// starts alone keep the threads busy, until fewer runs than threads are
/// left (then the remaining runs use the pool).
const PARALLEL_EVALUATION_FROM: usize = 1024;

/// Two subset optima whose log marginal likelihoods agree to this
/// (relative, of max(1, |LML|)) are one optimum: refining both on all
/// samples would repeat a run. The same tolerance as the acceptance test
/// against scikit-learn's best LML.
const SAME_LML: f64 = 1e-6;

/// Two subset optima whose log-hyperparameters agree to this in every
/// coordinate (max norm, natural log units: 1 %) are one optimum.
const SAME_THETA: f64 = 1e-2;

/// The data one stage of training sees: normalised inputs (row-major
/// n × d) and each output's normalised residual.
pub(crate) struct StageData<'a> {
    pub xn: &'a [f64],
    pub n: usize,
    pub d: usize,
    pub ys: Vec<&'a [f64]>,
}

/// What every run of a training shares besides the data.
#[derive(Clone, Copy)]
pub(crate) struct StageSettings<'a> {
    pub lo: &'a [f64],
    pub hi: &'a [f64],
    pub lopt: LbfgsOptions,
    /// Inducing inputs of a sparse GP (normalised, row-major M × d).
    pub inducing: Option<&'a [f64]>,
    /// Faer's parallelism inside one sparse evaluation.
    pub inner_sparse: Par,
}

/// −LML of white noise at its best variance yᵀy/n.
fn white_noise(y: &[f64]) -> f64 {
    let n = y.len() as f64;
    let s2 = y.iter().map(|v| v * v).sum::<f64>() / n;
    0.5 * n * (1.0 + (2.0 * core::f64::consts::PI * s2).ln())
}

/// Whether an objective value `f` (−LML) is not preferred over white noise
/// (−LML `white`) by Akaike's criterion: the d length scales buy at most d
/// nats.
pub(crate) fn on_plateau(white: f64, f: f64, d: usize) -> bool {
    white.is_finite() && white - f <= d as f64
}

/// Runs every job in parallel (one rayon task each), each sequential and
/// seeded by its start point, so results do not depend on scheduling.
///
/// A job's seed memory is scaled by `y_scale` (see
/// [`lbfgs::minimise_seeded`]).
pub(crate) fn run_jobs(
    data: &StageData,
    set: StageSettings,
    jobs: &[Job],
    lopt: LbfgsOptions,
    y_scale: f64,
) -> Vec<RunResult> {
    let (n, d) = (data.n, data.d);
    // Exact runs at large N offer their Cholesky, inverse and products
    // to the pool as well: while every thread has a run of its own the
    // offered halves run on the offering thread (no idle thread steals
    // them), and when the last runs are left (the slowest start alone
    // at the end) the idle threads take their share. faer splits these
    // kernels by output blocks, so the bits do not depend on the split
    // (`tests/gp/gp_robustness.rs`). Below that size the same happens once
    // fewer runs than threads are left: at N = 512, d = 4, 1 + 10 starts
    // this took the busy share of two threads from 1.76 to 1.93 and the
    // wall time from 1.33 to 1.25 s.
    let inner_exact = if n >= PARALLEL_EVALUATION_FROM {
        Par::rayon(0)
    } else {
        Par::Seq
    };
    let threads = rayon::current_num_threads();
    let unfinished = AtomicUsize::new(jobs.len());
    jobs.par_iter()
        .with_max_len(1)
        .map(|job| {
            let y = data.ys[job.out];
            let t0 = &job.theta;
            let res = match set.inducing {
                None => {
                    // One workspace per run: no N×N allocation per evaluation.
                    let mut ws = likelihood::LmlWorkspace::new(n);
                    lbfgs::minimise_seeded(
                        |t| {
                            let par = if unfinished.load(Ordering::Relaxed) < threads {
                                Par::rayon(0)
                            } else {
                                inner_exact
                            };
                            let e = likelihood::lml_ws(&mut ws, data.xn, d, y, t, true, par)?;
                            Ok((-e.value, e.gradient.into_iter().map(|g| -g).collect()))
                        },
                        t0,
                        set.lo,
                        set.hi,
                        lopt,
                        &job.memory,
                        y_scale,
                    )
                }
                Some(z) => {
                    let mut ws = sparse::SparseWorkspace::new(z.len() / d, n);
                    lbfgs::minimise(
                        |t| {
                            let e = sparse::elbo_ws(
                                &mut ws,
                                data.xn,
                                z,
                                d,
                                y,
                                t,
                                true,
                                set.inner_sparse,
                            )?;
                            Ok((-e.value, e.gradient.into_iter().map(|g| -g).collect()))
                        },
                        t0,
                        set.lo,
                        set.hi,
                        lopt,
                    )
                }
            };
            unfinished.fetch_sub(1, Ordering::Relaxed);
            res
        })
        .collect()
}

/// Per output, the successful run that reached the lowest objective (−LML;
/// the first of equals), or `None` if every run of that output failed.
pub(crate) fn best_runs<'a>(
    jobs: &[Job],
    results: &'a [RunResult],
    p: usize,
) -> Vec<Option<&'a LbfgsResult>> {
    let mut best: Vec<Option<&LbfgsResult>> = vec![None; p];
    for (job, res) in jobs.iter().zip(results) {
        if let Ok(r) = res
            && best[job.out].is_none_or(|b| r.f < b.f)
        {
            best[job.out] = Some(r);
        }
    }
    best
}

/// The runs of one stage: every job, and what it added.
pub(crate) struct Stage {
    /// The jobs run, the rescue starts appended.
    pub jobs: Vec<Job>,
    /// One result per job.
    pub results: Vec<RunResult>,
    /// Per output: rescue starts added after the `starts` numbered ones.
    pub extra: Vec<usize>,
}

/// Every job of `jobs` on `data`, then the white-noise plateau's second
/// chances (see [`Gp::train`](super::Gp::train)):
///
/// * an output whose best fit is not preferred over white noise by
///   Akaike's criterion has probably failed: its starts whose first trial
///   was a corner of the box (the way onto the plateau) run again with
///   `unit_start`, and per start the better end counts, with both runs'
///   evaluations;
/// * an output still on the plateau after that, when other outputs fitted
///   (here, or the `donors` given: log-hyperparameters fitted elsewhere),
///   gets one more start from each fitted optimum, numbered from `starts`
///   on.
pub(crate) fn optimise(
    data: &StageData,
    set: StageSettings,
    mut jobs: Vec<Job>,
    starts: usize,
    p: usize,
    donors: &[Vec<f64>],
) -> Stage {
    let d = data.d;
    let mut results = run_jobs(data, set, &jobs, set.lopt, 1.0);
    let lowest_of = |jobs: &[Job], results: &[RunResult]| -> Vec<f64> {
        best_runs(jobs, results, p)
            .iter()
            .map(|r| r.map_or(f64::INFINITY, |r| r.f))
            .collect()
    };
    let white: Vec<f64> = (0..p).map(|o| white_noise(data.ys[o])).collect();
    let lowest = lowest_of(&jobs, &results);
    let again: Vec<usize> = (0..jobs.len())
        .filter(|&j| {
            let out = jobs[j].out;
            on_plateau(white[out], lowest[out], d)
                && results[j].as_ref().is_ok_and(|r| r.corner_start)
        })
        .collect();
    if !again.is_empty() {
        let retry: Vec<Job> = again.iter().map(|&j| jobs[j].clone()).collect();
        let guarded = LbfgsOptions {
            unit_start: true,
            ..set.lopt
        };
        for (j, res) in again
            .into_iter()
            .zip(run_jobs(data, set, &retry, guarded, 1.0))
        {
            let (Ok(first), Ok(second)) = (&mut results[j], res) else {
                continue;
            };
            let evaluations = first.evaluations + second.evaluations;
            let iterations = first.iterations + second.iterations;
            if second.f < first.f {
                *first = second;
            }
            first.evaluations = evaluations;
            first.iterations = iterations;
        }
    }
    // Outputs still on the white-noise plateau, when other outputs (on
    // the same inputs, in the same normalised units) did fit: one more
    // start from each fitted output's optimum (its length scales are a
    // start that sees the inputs' structure; random restarts can all
    // miss it, e.g. one velocity of a maximal-coordinate model).
    let mut extra = vec![0usize; p];
    let lowest = lowest_of(&jobs, &results);
    let mut all_donors: Vec<Vec<f64>> = best_runs(&jobs, &results, p)
        .iter()
        .enumerate()
        .filter_map(|(o, r)| r.filter(|r| !on_plateau(white[o], r.f, d)))
        .map(|r| r.x.clone())
        .collect();
    all_donors.extend(donors.iter().cloned());
    let present: Vec<bool> = (0..p).map(|o| jobs.iter().any(|j| j.out == o)).collect();
    if p > 1 || !donors.is_empty() {
        let mut rescue = Vec::new();
        for out in (0..p).filter(|&o| present[o] && on_plateau(white[o], lowest[o], d)) {
            for t in &all_donors {
                rescue.push(Job::new(out, starts + extra[out], t.clone()));
                extra[out] += 1;
            }
        }
        if !rescue.is_empty() {
            let more = run_jobs(data, set, &rescue, set.lopt, 1.0);
            jobs.extend(rescue);
            results.extend(more);
        }
    }
    Stage {
        jobs,
        results,
        extra,
    }
}

/// `m` distinct indices of 0..n, drawn by a seeded partial Fisher–Yates
/// shuffle and returned in ascending order (rows stay in their order).
pub(crate) fn subset_indices(n: usize, m: usize, seed: u64) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    let mut rng = SplitMix64::new(seed ^ 0x5C2E_E1D3_6A7B_9F01);
    for i in 0..m.min(n) {
        // uniform in i..n (the bias of the modulo is below 2⁻⁴⁰ for n < 2²⁴)
        let j = i + (rng.next_u64() % (n - i) as u64) as usize;
        idx.swap(i, j);
    }
    idx.truncate(m.min(n));
    idx.sort_unstable();
    idx
}

/// Per output, the distinct optima of a stage's successful runs, best
/// first (then by start index): one per optimum ([`SAME_LML`],
/// [`SAME_THETA`]), with plateau optima left out when the output has a
/// fitted one. Each comes with its start index.
pub(crate) fn distinct<'a>(
    stage: &'a Stage,
    data: &StageData,
    p: usize,
) -> Vec<Vec<(&'a LbfgsResult, usize)>> {
    let d = data.d;
    (0..p)
        .map(|out| {
            let white = white_noise(data.ys[out]);
            let mut cands: Vec<(&LbfgsResult, usize)> = stage
                .jobs
                .iter()
                .zip(&stage.results)
                .filter(|(j, _)| j.out == out)
                .filter_map(|(j, r)| r.as_ref().ok().map(|r| (r, j.start)))
                .filter(|(r, _)| r.f.is_finite())
                .collect();
            cands.sort_by(|a, b| a.0.f.total_cmp(&b.0.f).then(a.1.cmp(&b.1)));
            let fitted = cands.iter().any(|c| !on_plateau(white, c.0.f, d));
            let mut kept: Vec<(&LbfgsResult, usize)> = Vec::new();
            for (r, start) in cands {
                if fitted && on_plateau(white, r.f, d) {
                    continue;
                }
                let same = kept.iter().any(|(k, _)| {
                    (r.f - k.f).abs() <= SAME_LML * k.f.abs().max(1.0)
                        || k.x
                            .iter()
                            .zip(&r.x)
                            .all(|(a, b)| (a - b).abs() <= SAME_THETA)
                });
                if !same {
                    kept.push((r, start));
                }
            }
            kept
        })
        .collect()
}

/// Per output, the subset's optima to refine on all samples ([`distinct`]),
/// as refinement jobs keyed by the start index whose optimum they refine.
pub(crate) fn distinct_optima(stage: &Stage, data: &StageData, p: usize) -> Vec<Job> {
    distinct(stage, data, p)
        .into_iter()
        .enumerate()
        .flat_map(|(out, kept)| {
            kept.into_iter().map(move |(r, start)| Job {
                out,
                start,
                theta: r.x.clone(),
                memory: r.memory.clone(),
            })
        })
        .collect()
}

/// Training with screening ([`Screening`](super::Screening)): `jobs` on a
/// seeded subset of `m` samples of `full`, the distinct optima refined on
/// all samples, and the unscreened [`optimise`] for an output whose refined
/// fit is not preferred over white noise. Returns the runs on all samples
/// (numbered as the starts they refine) and each output's report.
pub(crate) fn screened(
    full: &StageData,
    set: StageSettings,
    jobs: Vec<Job>,
    starts: usize,
    p: usize,
    m: usize,
    seed: u64,
) -> (Stage, Vec<ScreeningReport>) {
    let d = full.d;
    let idx = subset_indices(full.n, m, seed);
    let xs: Vec<f64> = idx
        .iter()
        .flat_map(|&i| full.xn[i * d..(i + 1) * d].iter().copied())
        .collect();
    let ys: Vec<Vec<f64>> = (0..p)
        .map(|o| idx.iter().map(|&i| full.ys[o][i]).collect())
        .collect();
    let sub = StageData {
        xn: &xs,
        n: idx.len(),
        d,
        ys: ys.iter().map(Vec::as_slice).collect(),
    };
    let originals = jobs.clone();
    let screen = optimise(&sub, set, jobs, starts, p, &[]);
    let refine = distinct_optima(&screen, &sub, p);
    // the likelihood's curvature grows with the sample count
    let y_scale = full.n as f64 / sub.n as f64;
    let (stage, fell_back) = refine_or_fall_back(
        full,
        set,
        refine,
        originals,
        starts,
        p,
        y_scale,
        screen.extra.clone(),
    );
    let reports = (0..p)
        .map(|o| {
            let mut start_lmls = vec![f64::NAN; starts + screen.extra[o]];
            let mut start_evaluations = vec![0; starts + screen.extra[o]];
            for (j, r) in screen.jobs.iter().zip(&screen.results) {
                if j.out == o
                    && let Ok(r) = r
                {
                    start_lmls[j.start] = -r.f;
                    start_evaluations[j.start] = r.evaluations;
                }
            }
            ScreeningReport {
                subset: idx.len(),
                evaluations: start_evaluations.iter().sum(),
                start_lmls,
                start_evaluations,
                refined: refined_starts(&stage, o, fell_back[o]),
                fell_back: fell_back[o],
            }
        })
        .collect();
    (stage, reports)
}

/// Training from given candidate optima ([`TrainOptions::candidates`](
/// super::TrainOptions::candidates)): `candidates` (one job per candidate,
/// numbered by its index) refined on all samples, and the unscreened
/// [`optimise`] of `originals` for an output whose refined fit is not
/// preferred over white noise (or that has no candidate).
pub(crate) fn from_candidates(
    full: &StageData,
    set: StageSettings,
    candidates: Vec<Job>,
    originals: Vec<Job>,
    starts: usize,
    p: usize,
) -> (Stage, Vec<ScreeningReport>) {
    let (stage, fell_back) =
        refine_or_fall_back(full, set, candidates, originals, starts, p, 1.0, vec![0; p]);
    let reports = (0..p)
        .map(|o| ScreeningReport {
            subset: 0,
            start_lmls: Vec::new(),
            start_evaluations: Vec::new(),
            evaluations: 0,
            refined: refined_starts(&stage, o, fell_back[o]),
            fell_back: fell_back[o],
        })
        .collect();
    (stage, reports)
}

/// The starts of output `o` refined on all samples (none if it fell back).
fn refined_starts(stage: &Stage, o: usize, fell_back: bool) -> Vec<usize> {
    if fell_back {
        return Vec::new();
    }
    stage
        .jobs
        .iter()
        .filter(|j| j.out == o)
        .map(|j| j.start)
        .collect()
}

/// The refinement on all samples shared by [`screened`] and
/// [`from_candidates`]: every `refine` job runs on `full` (its seed memory
/// scaled by `y_scale`), and an output whose best refined fit is not
/// preferred over white noise, or that had nothing to refine, runs its
/// `originals` again on all samples with [`optimise`] (the fitted outputs'
/// optima as rescue starts), replacing its refinements. `extra`: rescue
/// starts per output so far. Returns the stage and which outputs fell back.
#[allow(clippy::too_many_arguments)]
fn refine_or_fall_back(
    full: &StageData,
    set: StageSettings,
    refine: Vec<Job>,
    originals: Vec<Job>,
    starts: usize,
    p: usize,
    y_scale: f64,
    mut extra: Vec<usize>,
) -> (Stage, Vec<bool>) {
    let d = full.d;
    let mut results = run_jobs(full, set, &refine, set.lopt, y_scale);
    let mut jobs = refine;
    // outputs whose refined fit is not preferred over white noise: their
    // starts again on all samples, with the fitted outputs' optima as
    // rescue starts
    let white: Vec<f64> = (0..p).map(|o| white_noise(full.ys[o])).collect();
    let best = best_runs(&jobs, &results, p);
    let fell_back: Vec<bool> = (0..p)
        .map(|o| best[o].is_none_or(|r| on_plateau(white[o], r.f, d)))
        .collect();
    if fell_back.iter().any(|&b| b) {
        let donors: Vec<Vec<f64>> = best
            .iter()
            .enumerate()
            .filter(|(o, _)| !fell_back[*o])
            .filter_map(|(_, r)| r.map(|r| r.x.clone()))
            .collect();
        let again: Vec<Job> = originals.into_iter().filter(|j| fell_back[j.out]).collect();
        let redo = optimise(full, set, again, starts, p, &donors);
        let keep: Vec<bool> = jobs.iter().map(|j| !fell_back[j.out]).collect();
        let mut k = keep.iter();
        jobs.retain(|_| *k.next().expect("one flag per job"));
        let mut k = keep.iter();
        results.retain(|_| *k.next().expect("one flag per job"));
        jobs.extend(redo.jobs);
        results.extend(redo.results);
        for (e, r) in extra.iter_mut().zip(redo.extra) {
            *e = (*e).max(r);
        }
    }
    (
        Stage {
            jobs,
            results,
            extra,
        },
        fell_back,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subset_indices_are_distinct_sorted_and_seeded() {
        let a = subset_indices(1000, 250, 7);
        assert_eq!(a.len(), 250);
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert!(*a.last().unwrap() < 1000);
        assert_eq!(a, subset_indices(1000, 250, 7));
        assert_ne!(a, subset_indices(1000, 250, 8));
        // spread over the range, not a prefix
        assert!(a[0] < 50 && a[249] > 950);
        assert_eq!(subset_indices(5, 9, 0), vec![0, 1, 2, 3, 4]);
    }
}
