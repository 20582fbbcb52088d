//! `vigp score`: k-step position error of the learned and the nominal
//! model on held-out runs.

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use super::args::ScoreArgs;
use super::{CliError, bar, check_model_inputs, data_error, sparse_note, w, window_place};
use crate::data::Dataset;
use crate::learned::Learned;
use crate::variational::RolloutReport;
use crate::{Integrator, Mechanism, SVector, State, StepError};

/// The k positions a rollout's k steps produced, in minimal coordinates:
/// those of states 2 … k (state j's position is state j − 1's plus Δt times
/// its velocity, so state 1's is the start's x₁, produced by no step) and
/// q_k + Δt·v_k, the end of the last step's velocity. `states`: the states
/// after steps 1 … k.
fn produced<const K: usize, const N: usize>(
    states: &[State<K>],
    dt: f64,
    to_minimal: impl Fn(&SVector<f64, K>) -> SVector<f64, N>,
) -> Vec<SVector<f64, N>> {
    let mut p: Vec<_> = states[1..].iter().map(|z| to_minimal(&z.q)).collect();
    if let Some(last) = states.last() {
        p.push(to_minimal(&(last.q + last.v * dt)));
    }
    p
}

/// The k-step windows of runs of `lengths` samples: (run, first sample)
/// for every sample with k more after it (and one more for v₀).
pub(super) fn windows(lengths: impl Iterator<Item = usize>, k: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (r, len) in lengths.enumerate() {
        if len >= k + 2 {
            out.extend((0..len - k - 1).map(|s| (r, s)));
        }
    }
    out
}

/// Mean over steps 1..=k of |p − t|²/n.
fn window_mse<const N: usize>(pred: &[SVector<f64, N>], truth: &[SVector<f64, N>]) -> f64 {
    let s: f64 = pred
        .iter()
        .zip(truth)
        .map(|(p, t)| (p - t).norm_squared() / N as f64)
        .sum();
    s / pred.len() as f64
}

/// `U`: the mechanism's inputs (0 for none; then the data has no input
/// columns and both models step unforced).
pub(super) fn score<
    L,
    Mn,
    const N: usize,
    const C: usize,
    const K: usize,
    const CK: usize,
    const U: usize,
>(
    a: &ScoreArgs,
    learned: &Learned<L, K, CK>,
    nominal: Mn,
    data: &Dataset<N>,
    to_view: impl Fn(&State<N>) -> State<K> + Sync,
    to_minimal: impl Fn(&SVector<f64, K>) -> SVector<f64, N> + Sync,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    L: Mechanism<K, CK> + Clone + Sync,
    Mn: Mechanism<N, C> + Copy + Sync,
    L: crate::Inputs<U>,
    Mn: crate::Inputs<U>,
{
    let k = a.steps;
    if k == 0 {
        return Err(CliError::Usage("--steps must be at least 1".into()));
    }
    check_model_inputs::<U>(&a.model, learned.inputs())?;
    let dt = learned.dt();
    data.check_dt(dt, a.read.time_tolerance)
        .map_err(data_error(&a.data))?;
    let windows = windows(data.runs.iter().map(|r| r.positions.len()), k);
    let too_short = data
        .runs
        .iter()
        .filter(|r| r.positions.len() < k + 2)
        .count();
    w(
        out,
        format_args!(
            "model: {} ({} coordinates, {:?} encoding, {} prior, N = {}{}, dt = {dt} s)",
            a.model.display(),
            K,
            learned.encoding(),
            super::prior_name(&learned.prior()),
            learned.gp().n(),
            sparse_note(learned.gp())
        ),
    )?;
    let runs = data.runs.len();
    report_windows(&a.data, runs, Some(too_short), windows.len(), k, out)?;
    // each run's logged inputs, once (none without inputs)
    let inputs = data.input_vectors::<U>().map_err(data_error(&a.data))?;
    let vi = a.stepping.integrator(nominal, dt)?;
    let pb = bar(windows.len(), "scoring");
    type Scored = Result<f64, StepError>;
    let results: Vec<(Scored, Scored, RolloutReport)> = windows
        .par_iter()
        .map(|&(r, s)| {
            let run = &data.runs[r];
            // the positions the k steps produce: x_{s+2} … x_{s+k+1} (x_{s+1}
            // = x_s + Δt·v_s is the logged one, reached by no step)
            let truth = &run.positions[s + 2..=s + k + 1];
            let z0 = State::from_positions(run.positions[s], &run.positions[s + 1], dt);
            // step j of the window (from sample s + j) under the input
            // logged over its new velocity's interval, row s + j + 1's,
            // after row s + j's (the learned step takes both)
            let us = if U == 0 {
                &[][..]
            } else {
                &inputs[r][s + 1..=s + k]
            };
            let nom = if U == 0 {
                vi.rollout_with_report(&z0, k)
            } else {
                vi.rollout_forced_with_report(&z0, us)
            };
            let (nom, report) = match nom {
                Ok((traj, report)) => (
                    Ok(window_mse(&produced(&traj[1..], dt, |q| *q), truth)),
                    report,
                ),
                Err(e) => (Err(e), RolloutReport::default()),
            };
            let zv = to_view(&z0);
            let mut buf = vec![zv; k];
            let lrn = if U == 0 {
                learned.rollout_into(&zv, &mut buf)
            } else {
                learned.rollout_mean_forced_into(&zv, &inputs[r][s], us, &mut buf)
            };
            let lrn = lrn.map(|()| window_mse(&produced(&buf, dt, &to_minimal), truth));
            pb.inc(1);
            (nom, lrn, report)
        })
        .collect();
    pb.finish_and_clear();
    // the first failure of each model, with the run and the line its
    // window starts at
    for (what, pick) in [("nominal", 0usize), ("learned", 1usize)] {
        let first = windows.iter().zip(&results).find_map(|(&(r, s), res)| {
            let e = if pick == 0 {
                res.0.as_ref()
            } else {
                res.1.as_ref()
            };
            e.err().map(|e| (r, s, *e))
        });
        if let Some((r, s, e)) = first {
            let run = &data.runs[r];
            w(
                out,
                format_args!(
                    "first {what} failure: {}: {e}",
                    window_place(run, s, a.read.resample.is_some())
                ),
            )?;
        }
    }
    let subdivided: Vec<&RolloutReport> = results
        .iter()
        .map(|r| &r.2)
        .filter(|r| r.subdivided > 0)
        .collect();
    if !subdivided.is_empty() {
        w(
            out,
            format_args!(
                "nominal steps that subdivided themselves: {} in {} of {} windows, the deepest {} \
                 halvings (--max-subdivision {})",
                subdivided.iter().map(|r| r.subdivided).sum::<usize>(),
                subdivided.len(),
                windows.len(),
                subdivided.iter().map(|r| r.deepest).max().unwrap_or(0),
                a.stepping.max_subdivision
            ),
        )?;
    }
    summary(
        results
            .iter()
            .map(|(a, b, _)| (a.as_ref().ok().copied(), b.as_ref().ok().copied())),
        k,
        out,
    )
}

/// The report's line on the held-out data `path`: its `runs` (with
/// `too_short`, how many of them are shorter than a window) and their
/// `windows` of `k` steps; an error when there is none.
pub(super) fn report_windows(
    path: &Path,
    runs: usize,
    too_short: Option<usize>,
    windows: usize,
    k: usize,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let short = match too_short {
        Some(n) => format!(" ({n} shorter than {} samples)", k + 2),
        None => String::new(),
    };
    w(
        out,
        format_args!(
            "data: {}: {runs} runs{short}, {windows} windows of {k} steps",
            path.display()
        ),
    )?;
    if windows == 0 {
        return Err(CliError::Usage(format!(
            "no run has {} samples: nothing to score with --steps {k}",
            k + 2
        )));
    }
    Ok(())
}

/// The report's end from each window's (nominal, learned) MSE (`None`:
/// the model failed there): the failures, what is averaged, and the last
/// line `nominal_mse=<x> learned_mse=<y>` over the windows where both
/// succeed (an error when there is none).
pub(super) fn summary(
    results: impl Iterator<Item = (Option<f64>, Option<f64>)>,
    k: usize,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let results: Vec<_> = results.collect();
    let both: Vec<(f64, f64)> = results
        .iter()
        .filter_map(|&(a, b)| Some((a?, b?)))
        .collect();
    w(
        out,
        format_args!(
            "failed windows: nominal {}, learned {} (scored: {} windows where both succeed)",
            results.iter().filter(|r| r.0.is_none()).count(),
            results.iter().filter(|r| r.1.is_none()).count(),
            both.len()
        ),
    )?;
    if both.is_empty() {
        return Err(CliError::Usage(
            "every window failed for the nominal or the learned model".into(),
        ));
    }
    w(
        out,
        format_args!(
            "averaged over the positions the steps produce: x_(s+2) … x_(s+{}) of a window from \
             sample s (x_(s+1) = x_s + dt·v_s is logged, not predicted), and over the windows",
            k + 1
        ),
    )?;
    let n = both.len() as f64;
    let nominal_mse = both.iter().map(|p| p.0).sum::<f64>() / n;
    let learned_mse = both.iter().map(|p| p.1).sum::<f64>() / n;
    w(
        out,
        format_args!("nominal_mse={nominal_mse:e} learned_mse={learned_mse:e}"),
    )
}
