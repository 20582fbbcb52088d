//! `vigp predict`: learned trajectories with error bounds (of a declared
//! mechanism's model, or of a learned robot's: [`predict_robot`]).

use std::io::Write;
use std::path::Path;

use super::args::{BoundArg, PredictArgs};
use super::robot::{load_learned, read_data_at};
use super::{
    CliError, bar, check_model_inputs, check_out_dir, data_error, io_error, read_data, read_plan,
    read_plan_rows, robot_state_at, w, window_place,
};
use crate::bound::{
    BoundError, BoundKind, BoundParts, Calibration, ConformalSettings, ErrorBound, Tube,
};
use crate::data::{Dataset, DynDataset, RunOf};
use crate::learned::Learned;
use crate::learned::robot::RobotCalibration;
use crate::{Integrator, Mechanism, SVector, State};

/// `U`: the mechanism's inputs (0 for none; with inputs each run's logged
/// inputs drive its prediction).
pub(super) fn predict<L, const N: usize, const K: usize, const CK: usize, const U: usize>(
    a: &PredictArgs,
    learned: &Learned<L, K, CK>,
    data: &Dataset<N>,
    (names, kinds, inputs): (
        &[&'static str; N],
        &[crate::CoordinateKind; N],
        &[&'static str],
    ),
    to_view: impl Fn(&State<N>) -> State<K>,
    to_minimal: impl Fn(&State<K>) -> State<N>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    L: Mechanism<K, CK> + Clone,
    L: crate::Inputs<U>,
{
    check_counts(a)?;
    check_model_inputs::<U>(&a.model, learned.inputs())?;
    check_out_dir(&a.out)?;
    let dt = learned.dt();
    data.check_dt(dt, a.read.time_tolerance)
        .map_err(data_error(&a.data))?;
    // each run's logged inputs (none without inputs)
    let logged = data.input_vectors::<U>().map_err(data_error(&a.data))?;
    // planned inputs, when given (refused for a mechanism without inputs)
    let plans = match &a.inputs {
        Some(path) => Some((path, read_plan::<U>(path, inputs)?)),
        None => None,
    };
    // shorter runs are skipped with a note, as `fit` notes its short runs
    let (starts, short, rows) = gather_starts(a, &data.runs, U > 0, &plans, |r, s, plan| {
        let run = &data.runs[r];
        let z = run.state(s)?;
        // the inputs of rows s+1..=s+k (or the plan's), after row s's
        // (which produced the start's velocity)
        let (up, us): (SVector<f64, U>, Vec<SVector<f64, U>>) = if U > 0 {
            let us = match plan {
                Some(p) => p.to_vec(),
                None => logged[r][s + 1..=s + a.steps].to_vec(),
            };
            (logged[r][s], us)
        } else {
            (SVector::zeros(), Vec::new())
        };
        Some((run, s, z, up, us))
    })?;
    // what a skipped run lacks, for the note and the error
    let (too_few, why) = if rows > 2 {
        (
            format!("fewer than {rows} rows"),
            format!(
                "a start state needs two, and the prediction the inputs logged in rows 1 to {}",
                a.steps
            ),
        )
    } else {
        ("one row".to_string(), "a start state needs two".to_string())
    };
    if starts.is_empty() {
        return Err(CliError::Usage(format!(
            "{}: every run has {too_few} ({why})",
            a.data.display()
        )));
    }
    if !short.is_empty() {
        w(
            out,
            format_args!(
                "note: skipped {} run(s) of {too_few} ({why}): {}",
                short.len(),
                short.join(", ")
            ),
        )?;
    }
    let view_starts: Vec<State<K>> = starts.iter().map(|(_, _, z, _, _)| to_view(z)).collect();
    let kind_arg = a.bound.unwrap_or(if a.calibration.is_some() {
        BoundArg::Conformal
    } else {
        BoundArg::Rkhs
    });
    let calibration = match &a.calibration {
        Some(path) => {
            let held_out = read_data(path, names, kinds, inputs, &a.read)?;
            held_out
                .check_dt(dt, a.read.time_tolerance)
                .map_err(data_error(path))?;
            // a window of h steps needs h + 1 samples of one run
            let horizon = a.steps.max(2);
            check_horizon(path, &held_out.runs, a.steps, horizon, true)?;
            // windows in the model's coordinates: positions of the view
            // (and, with inputs, each sample's logged input)
            let trajectories: Vec<Vec<SVector<f64, K>>> = held_out
                .runs
                .iter()
                .map(|run| {
                    run.positions
                        .iter()
                        .map(|q| {
                            to_view(&State {
                                q: *q,
                                v: SVector::zeros(),
                            })
                            .q
                        })
                        .collect()
                })
                .collect();
            if U > 0 {
                let logged = held_out.input_vectors::<U>().map_err(data_error(path))?;
                Calibration::from_trajectories_forced(
                    &trajectories,
                    &logged,
                    dt,
                    a.steps.max(2),
                    1,
                )?
            } else {
                Calibration::from_trajectories(&trajectories, dt, a.steps.max(2), 1)?
            }
        }
        None if kind_arg == BoundArg::Conformal => {
            return Err(CliError::Usage(
                "--bound conformal needs held-out runs: pass --calibration FILE".into(),
            ));
        }
        None => Calibration::empty(dt),
    };
    let kind = match kind_arg {
        BoundArg::Conformal => BoundKind::conformal(a.delta),
        BoundArg::Theorem1 => BoundKind::theorem1(a.delta),
        BoundArg::Rkhs => BoundKind::rkhs(a.delta),
    };
    // (U = 0 is `error_bound`; the model's input count is checked above)
    let bound = learned.error_bound_forced::<U>(&kind, &calibration)?;
    let mut header = header(a, &data.coordinates, inputs);
    // which rows' bounds are the conformal bound's fallback (see below)
    let conformal = bound.kind_name() == "conformal";
    if conformal {
        header.push("fallback".into());
    }
    let mut csv = CsvOut::create(&a.out, &header)?;
    let pb = bar(starts.len(), "predicting");
    let mut tally = Tally::default();
    for ((run, s, z0, up, us), zv) in starts.iter().zip(&view_starts) {
        let pred = if U > 0 {
            learned.predict_forced(zv, up, us, &bound)
        } else {
            learned.predict(zv, a.steps, &bound)
        };
        let place = || window_place(run, *s, a.read.resample.is_some());
        let Some(pred) = tally.take(pred, place, out)? else {
            continue;
        };
        tally.count_outside(&pred.outside);
        for (k, z) in pred.states.iter().enumerate() {
            let zm = if k == 0 { *z0 } else { to_minimal(z) };
            let mut row = row(
                a,
                (&run.name, run.t0, run.dt.unwrap_or(dt)),
                (*s, k),
                (zm.q.as_slice(), zm.v.as_slice()),
                us.get(k.wrapping_sub(1)).map(|u| u.as_slice()),
                inputs.len(),
                (&pred.one_step_bounds, &pred.position_bounds),
            );
            if conformal {
                row.push(match (&bound.fallback, flagged(&pred.outside, k)) {
                    (Some(f), true) => f.kind_name().to_string(),
                    (None, true) => "outside".to_string(),
                    (_, false) => String::new(),
                });
            }
            csv.write(&row)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    csv.finish()?;
    tally.every_run_failed(a, starts.len(), out)?;
    let what = match (&bound.fallback, bound.kind_name()) {
        (Some(f), _) => format!(
            "outside the calibrated region: their bounds (and, where the start is outside, the \
             whole run's position bounds) are the larger of the conformal and the {} bound",
            f.kind_name()
        ),
        (None, "conformal") => format!(
            "outside the calibrated region: the conformal guarantee does not cover them{}",
            if learned.gp().is_sparse() {
                " (a sparse GP has no rigorous bound to fall back to)"
            } else {
                ""
            }
        ),
        _ => "outside the box of the training inputs, where the bound's constants were estimated"
            .into(),
    };
    tally.note_outside(&what, out)?;
    let failed = tally.failed;
    let what = if a.stride.is_some() {
        format!(
            "{} predictions (every {} samples of {} run(s))",
            starts.len() - failed,
            a.stride.unwrap_or(1),
            data.runs.len() - short.len()
        )
    } else {
        format!("{} runs", starts.len() - failed)
    };
    w(
        out,
        format_args!(
            "wrote {}: {what} × {} steps ({failed} failed); {}: `bound` bounds ‖v − v_true‖ of \
             each predicted velocity (one step from the predicted state), `position_bound` \
             ‖q_k − q_true,k‖ along the prediction",
            a.out.display(),
            a.steps,
            guarantee(&bound, a.delta)
        ),
    )
}

/// The checks of `--steps` and `--stride`, before any work.
fn check_counts(a: &PredictArgs) -> Result<(), CliError> {
    if a.steps == 0 {
        return Err(CliError::Usage("--steps must be at least 1".into()));
    }
    if a.stride == Some(0) {
        return Err(CliError::Usage("--stride must be at least 1".into()));
    }
    Ok(())
}

/// Refuses held-out runs (`runs` of the file `path`) none of which is long
/// enough for a calibration window of `horizon` steps (for `--steps`
/// `steps`); with `per_run` the message lists the runs' lengths.
fn check_horizon<P>(
    path: &Path,
    runs: &[RunOf<P>],
    steps: usize,
    horizon: usize,
    per_run: bool,
) -> Result<(), CliError> {
    let longest = runs.iter().map(|r| r.positions.len()).max().unwrap_or(0);
    if longest > horizon {
        return Ok(());
    }
    let lengths = if per_run {
        let mut lengths: Vec<String> = runs
            .iter()
            .take(8)
            .map(|r| format!("`{}` {}", r.name, r.positions.len()))
            .collect();
        if runs.len() > 8 {
            lengths.push(format!("… ({} runs)", runs.len()));
        }
        format!(" (samples per run: {})", lengths.join(", "))
    } else {
        String::new()
    };
    Err(CliError::Usage(format!(
        "{}: --steps {steps} is calibrated on windows of {horizon} steps, which need runs of at \
         least {} samples; the longest run has {longest}{lengths}. Give longer held-out runs or \
         fewer --steps",
        path.display(),
        horizon + 1,
    )))
}

/// The output CSV of `--out`.
struct CsvOut<'a> {
    wtr: csv::Writer<std::io::BufWriter<std::fs::File>>,
    path: &'a Path,
}

impl<'a> CsvOut<'a> {
    /// Creates the file `path` and writes its `header`.
    fn create(path: &'a Path, header: &[String]) -> Result<Self, CliError> {
        let file = std::fs::File::create(path).map_err(io_error(path))?;
        let wtr = csv::Writer::from_writer(std::io::BufWriter::new(file));
        let mut csv = CsvOut { wtr, path };
        csv.write(header)?;
        Ok(csv)
    }

    /// Writes one record.
    fn write(&mut self, record: &[String]) -> Result<(), CliError> {
        self.wtr.write_record(record).map_err(|e| CliError::Io {
            path: self.path.to_path_buf(),
            source: std::io::Error::other(e),
        })
    }

    /// Flushes what is buffered to the file.
    fn finish(mut self) -> Result<(), CliError> {
        self.wtr.flush().map_err(io_error(self.path))
    }
}

/// What became of the predictions: how many failed (and the first
/// error), and the predicted states outside what the bound covers, and
/// the runs holding them.
#[derive(Default)]
struct Tally {
    failed: usize,
    first_error: Option<BoundError>,
    outside: usize,
    outside_runs: usize,
}

impl Tally {
    /// The prediction `pred`, or `None` when it failed: then it is counted
    /// and its error said at its `place`.
    fn take<P>(
        &mut self,
        pred: Result<P, BoundError>,
        place: impl FnOnce() -> String,
        out: &mut dyn Write,
    ) -> Result<Option<P>, CliError> {
        match pred {
            Ok(p) => Ok(Some(p)),
            Err(e) => {
                self.failed += 1;
                w(out, format_args!("{}: {e}", place()))?;
                self.first_error.get_or_insert(e);
                Ok(None)
            }
        }
    }

    /// Counts the states of one prediction that lie `outside`.
    fn count_outside(&mut self, outside: &[bool]) {
        let n_out = outside.iter().filter(|&&o| o).count();
        self.outside += n_out;
        self.outside_runs += usize::from(n_out > 0);
    }

    /// The note on the predicted states outside what the bound covers, if
    /// any (`what`: where they lie, and what that means).
    fn note_outside(&self, what: &str, out: &mut dyn Write) -> Result<(), CliError> {
        if self.outside == 0 {
            return Ok(());
        }
        w(
            out,
            format_args!(
                "note: {} predicted states in {} run(s) lie {what}",
                self.outside, self.outside_runs
            ),
        )
    }

    /// A file with the header alone is no result: when every one of
    /// `total` predictions failed, says so and returns the first error
    /// (exit code 1).
    fn every_run_failed(
        &mut self,
        a: &PredictArgs,
        total: usize,
        out: &mut dyn Write,
    ) -> Result<(), CliError> {
        let failed = self.failed;
        if failed == total
            && let Some(e) = self.first_error.take()
        {
            w(
                out,
                format_args!(
                    "every run failed ({failed}); {} holds no predictions",
                    a.out.display()
                ),
            )?;
            return Err(e.into());
        }
        Ok(())
    }
}

/// Whether output row `k` of a prediction whose states lie `outside` the
/// bound's region is flagged in column `fallback`: row k's `bound` is
/// predicted from state k − 1, and every position bound falls back (or
/// leaves the guarantee) when the start is outside.
fn flagged(outside: &[bool], k: usize) -> bool {
    k > 0 && (outside[k - 1] || outside[0])
}

/// The output's columns before `fallback`: run, [start,] t, the
/// coordinates, their velocities, the inputs that drove the steps into
/// the rows (the data's convention), the one-step and the position bound.
fn header(a: &PredictArgs, coordinates: &[String], inputs: &[&str]) -> Vec<String> {
    let mut header = vec!["run".to_string()];
    if a.stride.is_some() {
        header.push("start".into());
    }
    header.push("t".into());
    header.extend(coordinates.iter().cloned());
    header.extend(coordinates.iter().map(|c| format!("v_{c}")));
    header.extend(inputs.iter().map(|j| format!("u_{j}")));
    header.push("bound".into());
    header.push("position_bound".into());
    header
}

/// Row k of the prediction from sample s of a run (name, t₀, Δt): the
/// columns of [`header`], `u` the input of the step into the row (none at
/// k = 0, and for `inputs` = 0), `bounds` the prediction's one-step and
/// position bounds.
fn row(
    a: &PredictArgs,
    (name, t0, dt): (&str, f64, f64),
    (s, k): (usize, usize),
    (q, v): (&[f64], &[f64]),
    u: Option<&[f64]>,
    inputs: usize,
    (one_step, position): (&[f64], &[f64]),
) -> Vec<String> {
    let mut row = vec![name.to_string()];
    if a.stride.is_some() {
        row.push(s.to_string());
    }
    // t_0 + (s + k)·Δt from the integer index, without float noise
    row.push(crate::data::format_time(t0, dt, s + k));
    row.extend(q.iter().map(|x| format!("{x:?}")));
    row.extend(v.iter().map(|x| format!("{x:?}")));
    match u {
        Some(u) => row.extend(u.iter().map(|x| format!("{x:?}"))),
        None => row.extend((0..inputs).map(|_| String::new())),
    }
    row.push(if k == 0 {
        String::new()
    } else {
        format!("{:?}", one_step[k - 1])
    });
    row.push(format!("{:?}", position[k]));
    row
}

/// Plans per run (the run's name, or `None` for every run).
type RunPlans<'p, T> = &'p [(Option<String>, Vec<T>)];

/// The planned inputs of run `run` (the plan file's own run, or its one
/// plan for every run), its first `--steps` rows; `None` without
/// `--inputs`.
/// The planned inputs of `--inputs` (the file and its plans), if given.
type Planned<'a, T> = Option<(&'a std::path::PathBuf, Vec<(Option<String>, Vec<T>)>)>;

/// The prediction starts of every run of `runs`: rows s = 0, k, 2k, …
/// with `--stride k` (row 0 alone without), while the rows a start needs
/// from s are in the run (two, the position and the discrete velocity;
/// `forced` without `plans`: also the inputs of rows s+1..=s+k for k
/// steps). `start(r, s, plan)` makes the start of run r at row s with the
/// run's planned inputs, if any (`None`: no more starts in this run).
/// Also the names of the runs without a start, and the rows a start needs.
fn gather_starts<'d, 'p, P, T, S>(
    a: &PredictArgs,
    runs: &'d [RunOf<P>],
    forced: bool,
    plans: &'p Planned<'_, T>,
    mut start: impl FnMut(usize, usize, Option<&'p [T]>) -> Option<S>,
) -> Result<(Vec<S>, Vec<&'d str>, usize), CliError> {
    let rows = if forced && plans.is_none() {
        a.steps + 1
    } else {
        2
    };
    let plans = plans.as_ref().map(|(p, v)| (p.as_path(), v.as_slice()));
    let mut starts = Vec::new();
    let mut short = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        let plan = plan_for(a, plans, &run.name)?;
        let before = starts.len();
        let mut s = 0usize;
        while s
            .checked_add(rows)
            .is_some_and(|end| end <= run.positions.len())
        {
            let Some(made) = start(r, s, plan) else { break };
            starts.push(made);
            // one start per run without --stride
            match a.stride.and_then(|k| s.checked_add(k)) {
                Some(next) => s = next,
                None => break,
            }
        }
        if starts.len() == before {
            short.push(run.name.as_str());
        }
    }
    Ok((starts, short, rows))
}

fn plan_for<'p, T>(
    a: &PredictArgs,
    plans: Option<(&std::path::Path, RunPlans<'p, T>)>,
    run: &str,
) -> Result<Option<&'p [T]>, CliError> {
    let Some((path, plans)) = plans else {
        return Ok(None);
    };
    let found = plans
        .iter()
        .find(|(name, _)| name.as_deref().is_none_or(|n| n == run));
    let Some((_, plan)) = found else {
        return Err(CliError::Usage(format!(
            "{}: no inputs for run `{run}` of {}",
            path.display(),
            a.data.display()
        )));
    };
    if plan.len() < a.steps {
        return Err(CliError::Usage(format!(
            "{}: {} input row(s){}, --steps {} needs {}",
            path.display(),
            plan.len(),
            if plans[0].0.is_some() {
                format!(" for run `{run}`")
            } else {
                String::new()
            },
            a.steps,
            a.steps
        )));
    }
    Ok(Some(&plan[..a.steps]))
}

/// What the bound's probability covers, for `predict`'s summary: the
/// conformal guarantee is marginal over start states exchangeable with
/// the calibration windows' starts and holds per step (or for the whole
/// tube at once), at level 1 − δ; the rigorous kinds hold for every state
/// at once with probability 1 − δ over the data.
fn guarantee(bound: &ErrorBound, delta: f64) -> String {
    let level = 1.0 - delta;
    match &bound.parts {
        BoundParts::Conformal(c) => format!(
            "conformal bound ({:?} score{}, {} tube, {} calibration windows{}): coverage ≥ {level} \
             marginal over start states exchangeable with the calibration windows' starts (not \
             conditional on one start), {}{}",
            c.score,
            if c.selection_size > 0 {
                format!(" chosen on {} other windows", c.selection_size)
            } else {
                String::new()
            },
            match c.tube {
                Tube::PerStep => "per-step",
                Tube::Simultaneous => "simultaneous",
            },
            c.calibration_size,
            if c.failed > 0 {
                format!(", {} of them failed and count as misses", c.failed)
            } else {
                String::new()
            },
            match c.tube {
                Tube::PerStep => {
                    "per step: each row's bounds hold at that level on their own, not all rows \
                     of a prediction at once"
                }
                Tube::Simultaneous => {
                    "per step for `bound`; the `position_bound`s of a prediction hold all at once"
                }
            },
            match &bound.fallback {
                Some(f) => format!(
                    "; rows outside the calibrated region fall back to the larger of it and the \
                     {} bound (column `fallback`)",
                    f.kind_name()
                ),
                None => "; rows outside the calibrated region are marked `outside` in column \
                         `fallback`, where the guarantee does not apply"
                    .to_string(),
            }
        ),
        BoundParts::Rkhs { .. } => format!(
            "rkhs bound: probability ≥ {level} over the data's noise, for every state at once \
             (uniform over the GP's inputs, if the velocity map's RKHS norm is within the bound's)"
        ),
        BoundParts::Theorem1 { .. } => format!(
            "theorem1 bound: probability ≥ {level}, for every state in the box of the training \
             inputs at once (if the velocity map is a sample of the fitted GP)"
        ),
    }
}

/// `predict` with a learned robot's model (`fit --urdf`): the learned
/// mean prediction under the logged (or planned) inputs, each state with
/// the conformal bound calibrated on `--calibration`'s held-out runs
/// ([`LearnedRobot::error_bound`]); the rigorous kinds need a declared
/// mechanism's integrator and are refused.
///
/// [`LearnedRobot::error_bound`]: crate::learned::robot::LearnedRobot::error_bound
pub(super) fn predict_robot(a: &PredictArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let usage = |why: String| Err(CliError::Usage(why));
    check_counts(a)?;
    if matches!(a.bound, Some(BoundArg::Rkhs | BoundArg::Theorem1)) {
        return usage(
            "a learned robot's predictions carry the conformal bound (--calibration FILE): the \
             rkhs and theorem1 bounds need the Lipschitz constants of a declared mechanism's \
             integrator"
                .into(),
        );
    }
    let Some(cal_path) = &a.calibration else {
        return usage(
            "a learned robot's bound is conformal: pass --calibration FILE (held-out runs in the \
             format of --data, not used for training)"
                .into(),
        );
    };
    let learned = load_learned(&a.model)?;
    check_out_dir(&a.out)?;
    let robot = learned.robot();
    let dt = learned.dt();
    let names: Vec<&str> = robot.joint_names().iter().map(String::as_str).collect();
    let inputs = robot.input_names();
    let m = inputs.len();
    let data = read_data_at(robot, &a.data, &a.read, dt)?;
    let held_out = read_data_at(robot, cal_path, &a.read, dt)?;
    // a window of h steps needs h + 1 samples of one run
    let horizon = a.steps.max(2);
    let positions = |d: &DynDataset| -> Vec<Vec<Vec<f64>>> {
        d.runs
            .iter()
            .map(|r| r.positions.iter().map(|x| x.as_slice().to_vec()).collect())
            .collect()
    };
    let logged = |d: &DynDataset| -> Vec<Vec<Vec<f64>>> {
        d.runs
            .iter()
            .map(|r| {
                if m == 0 {
                    vec![Vec::new(); r.positions.len()]
                } else {
                    r.inputs.clone()
                }
            })
            .collect()
    };
    check_horizon(cal_path, &held_out.runs, a.steps, horizon, false)?;
    let calibration =
        RobotCalibration::from_logs(&positions(&held_out), &logged(&held_out), dt, horizon, 1)?;
    let settings = ConformalSettings {
        delta: a.delta,
        ..ConformalSettings::default()
    };
    let bound = learned.error_bound(&settings, &calibration)?;
    let plans = match &a.inputs {
        Some(path) => Some((path, read_plan_rows(path, &inputs)?)),
        None => None,
    };
    let run_inputs = logged(&data);
    // each start: (run, sample, state, previous input, the steps' inputs)
    let (starts, short, rows) = gather_starts(a, &data.runs, m > 0, &plans, |r, s, plan| {
        let us: Vec<Vec<f64>> = match plan {
            Some(p) => p.to_vec(),
            None if m > 0 => run_inputs[r][s + 1..=s + a.steps].to_vec(),
            None => vec![Vec::new(); a.steps],
        };
        let z0 = robot_state_at(&data.runs[r], s, dt);
        Some((r, s, z0, run_inputs[r][s].clone(), us))
    })?;
    if starts.is_empty() {
        return usage(format!(
            "{}: every run is shorter than {rows} rows (a start needs two{})",
            a.data.display(),
            if rows > 2 {
                ", and the prediction the inputs logged in the rows after it"
            } else {
                ""
            }
        ));
    }
    if !short.is_empty() {
        w(
            out,
            format_args!(
                "note: skipped {} run(s) shorter than {rows} rows: {}",
                short.len(),
                short.join(", ")
            ),
        )?;
    }
    let coordinates: Vec<String> = names.iter().map(|c| c.to_string()).collect();
    let mut header = header(a, &coordinates, &inputs);
    // (`fallback` as for a declared mechanism's conformal bound without a
    // fallback: `outside` where the guarantee does not apply)
    header.push("fallback".into());
    let mut csv = CsvOut::create(&a.out, &header)?;
    let pb = bar(starts.len(), "predicting");
    let mut tally = Tally::default();
    for (r, s, z0, u_prev, us) in &starts {
        let run = &data.runs[*r];
        let pred = learned.predict(z0, u_prev, us, &bound);
        // a robot's window is named by its file line, resampled or not
        let place = || window_place(run, *s, false);
        let Some(pred) = tally.take(pred, place, out)? else {
            continue;
        };
        tally.count_outside(&pred.outside);
        for (k, z) in pred.states.iter().enumerate() {
            let mut row = row(
                a,
                (&run.name, run.t0, run.dt.unwrap_or(dt)),
                (*s, k),
                (&z.q, &z.v),
                us.get(k.wrapping_sub(1)).map(Vec::as_slice),
                m,
                (&pred.one_step_bounds, &pred.position_bounds),
            );
            row.push(if flagged(&pred.outside, k) {
                "outside".into()
            } else {
                String::new()
            });
            csv.write(&row)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    csv.finish()?;
    tally.every_run_failed(a, starts.len(), out)?;
    tally.note_outside(
        "outside the calibrated region (`outside` in column `fallback`): the conformal \
         guarantee does not cover them",
        out,
    )?;
    let failed = tally.failed;
    w(
        out,
        format_args!(
            "wrote {}: {} predictions × {} steps of {} ({failed} failed); {}",
            a.out.display(),
            starts.len() - failed,
            a.steps,
            robot.name(),
            guarantee(&bound, a.delta)
        ),
    )
}
