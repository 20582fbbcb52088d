//! The tool on a robot loaded from URDF at run time (`--urdf FILE
//! [--actuated J,…]`): `simulate`, `identify`, `excite` and `fit` on the linear-time
//! tree engine ([`crate::Robot`]), and `score`, `predict` and `export` of the
//! models `fit` writes ([`LearnedRobot`]). The log's columns are the robot's joints with a
//! coordinate, in the file's depth-first order, and `u_<joint>` per
//! actuated joint, as for a declared mechanism ([`crate::data`]).

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use super::args::{
    Command, EncodingArg, FitArgs, MechanismArgs, ReadArgs, ScoreArgs, SimulateArgs,
};
use super::excite::excite_robot;
use super::fit::{choose, report_data, report_saved, resolve_prior, train_options, train_timed};
use super::identify::identify_robot;
use super::simulate::{INPUT_ROWS, check_start, one_plan, write_log};
use super::{
    CliError, bar, check_out_dir, data_error, read_plan_rows, report_read, robot_state_at, w,
};
use crate::data::DynDataset;
use crate::learned::Encoding;
use crate::learned::robot::{LearnedRobot, RobotTransition, coordinate_kinds};
use crate::robot::{Robot, RobotState};
use vigp_core::tree::EngineOptions;

/// Whether a model file is a learned robot's (its `format`), so that
/// `score` reads it as one.
pub(super) fn is_robot_model(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    serde_json::from_str::<serde_json::Value>(&text)
        .is_ok_and(|v| v["format"] == crate::learned::robot::FORMAT)
}

/// Runs a command on a robot: `urdf` for `fit`, `simulate`, `identify`
/// and `excite`, the model file for `score`, `predict` and `export`.
pub(super) fn run(command: &Command, out: &mut dyn Write) -> Result<(), CliError> {
    match command {
        Command::Simulate(a) => simulate(a, &load(&a.mechanism, &a.set)?, out),
        Command::Identify(a) => {
            let robot = load(&a.mechanism, &a.set)?;
            let (data, dt) = read_log(&robot, &a.data, &a.read)?;
            identify_robot(a, &robot, &data, dt, out)
        }
        Command::Fit(a) => fit(a, load(&a.mechanism, &a.set)?, out),
        Command::Score(a) => score(a, out),
        Command::Predict(a) => super::predict::predict_robot(a, out),
        Command::Export(a) => super::export::export_robot(a, out),
        Command::Excite(a) => excite_robot(a, &load(&a.mechanism, &a.set)?, out),
    }
}

/// The robot of `--urdf` with its `--actuated` joints.
fn load(mechanism: &MechanismArgs, set: &[String]) -> Result<Robot, CliError> {
    let Some(path) = &mechanism.urdf else {
        return Err(CliError::Usage("--urdf FILE is needed".into()));
    };
    if !set.is_empty() {
        return Err(CliError::Usage(
            "--set changes a declared mechanism's parameters; for a robot, edit the URDF file \
             (or fit with --prior identified:FILE)"
                .into(),
        ));
    }
    let names: Vec<&str> = mechanism.actuated.iter().map(String::as_str).collect();
    Robot::from_urdf(path)
        .and_then(|r| r.with_actuated(&names))
        .map_err(|e| CliError::Usage(format!("--urdf {}: {e}", path.display())))
}

/// A robot's log and its runs' common time step.
fn read_log(robot: &Robot, path: &Path, read: &ReadArgs) -> Result<(DynDataset, f64), CliError> {
    let data = read_data(robot, path, read)?;
    let dt = data.dt(read.time_tolerance).map_err(data_error(path))?;
    Ok((data, dt))
}

/// A log of `robot`'s joints and inputs, with what the reader noticed
/// reported on stderr.
fn read_data(robot: &Robot, path: &Path, read: &ReadArgs) -> Result<DynDataset, CliError> {
    let names: Vec<&str> = robot.joint_names().iter().map(String::as_str).collect();
    let data = DynDataset::read_path_with_inputs(
        path,
        &names,
        &coordinate_kinds(robot),
        &robot.input_names(),
        &read.options(),
    )
    .map_err(data_error(path))?;
    report_read(path, &data.warnings, &data.dropped);
    Ok(data)
}

/// A log of `robot` for a learned model of time step `dt` (`score`,
/// `predict`): read as [`read_data`], its runs checked to step by `dt`.
pub(super) fn read_data_at(
    robot: &Robot,
    path: &Path,
    read: &ReadArgs,
    dt: f64,
) -> Result<DynDataset, CliError> {
    let data = read_data(robot, path, read)?;
    data.check_dt(dt, read.time_tolerance)
        .map_err(data_error(path))?;
    Ok(data)
}

/// A learned robot's model file (`fit --urdf`).
pub(super) fn load_learned(path: &Path) -> Result<LearnedRobot, CliError> {
    LearnedRobot::load(path).map_err(|e| CliError::Usage(format!("{}: {e}", path.display())))
}

/// `robot` with at most `max_depth` halvings of a failing step
/// (`--max-subdivision`), its other engine options kept.
fn with_max_subdivision(robot: &Robot, max_depth: u32) -> Result<Robot, CliError> {
    robot
        .clone()
        .with_options(EngineOptions {
            max_depth,
            ..*robot.engine().options()
        })
        .map_err(|e| CliError::Usage(e.to_string()))
}

/// `simulate --urdf`: the robot's rollout from `--q`, `--v` under the
/// planned or zero inputs, written with [`DynDataset::from_rollout`] (row
/// k's input held from t_k to t_{k+1}).
fn simulate(a: &SimulateArgs, robot: &Robot, out: &mut dyn Write) -> Result<(), CliError> {
    let usage = |why: String| Err(CliError::Usage(why));
    let n = robot.dof();
    let names: Vec<&str> = robot.joint_names().iter().map(String::as_str).collect();
    check_start(a, robot.name(), &names)?;
    if a.stepping.substeps != 1 {
        return usage(
            "--substeps: the tree engine halves a step by itself where it must \
             (--max-subdivision D bounds the halvings)"
                .into(),
        );
    }
    check_out_dir(&a.out)?;
    let robot = with_max_subdivision(robot, a.stepping.max_subdivision)?;
    let inputs = robot.input_names();
    let m = inputs.len();
    let plan: Vec<Vec<f64>> = match &a.inputs {
        Some(path) => one_plan(path, &read_plan_rows(path, &inputs)?, a.steps)?.to_vec(),
        None => vec![vec![0.0; m]; a.steps],
    };
    let v0 = if a.v.is_empty() {
        vec![0.0; n]
    } else {
        a.v.clone()
    };
    let z0 = RobotState::new(a.q.clone(), v0);
    let rollout = robot
        .rollout_with(&z0, a.dt, a.steps, |k, _| plan[k].clone())
        .map_err(|e| CliError::Usage(format!("simulate: {e}")))?;
    let states: Vec<(&[f64], &[f64])> = rollout
        .states
        .iter()
        .map(|z| (z.q.as_slice(), z.v.as_slice()))
        .collect();
    let us: Vec<&[f64]> = plan.iter().map(Vec::as_slice).collect();
    let log = DynDataset::from_rollout(
        &names,
        &inputs,
        &a.run,
        (a.t0, a.dt),
        &states,
        (&vec![0.0; m], &us),
    )
    .map_err(|e| CliError::Usage(e.to_string()))?;
    write_log(&log, &a.out)?;
    let r = &rollout.report;
    w(
        out,
        format_args!(
            "wrote {}: run `{}`, {} rows at dt = {} s ({} steps of {}, {} coordinates; {} of them \
             subdivided, the deepest {} halvings){}",
            a.out.display(),
            a.run,
            a.steps + 2,
            a.dt,
            a.steps,
            robot.name(),
            n,
            r.subdivided,
            r.deepest,
            if m > 0 { INPUT_ROWS } else { "" }
        ),
    )
}

/// `fit --urdf`: a [`LearnedRobot`] on at most `--max-samples` of the
/// log's transitions.
fn fit(a: &FitArgs, robot: Robot, out: &mut dyn Write) -> Result<(), CliError> {
    let encoding = match a.encoding {
        EncodingArg::Sincos => Encoding::SinCos,
        EncodingArg::Minimal => Encoding::Raw,
        EncodingArg::Maximal => {
            return Err(CliError::Usage(
                "--encoding maximal: a robot is learned in its joint coordinates \
                 (--encoding sincos or minimal)"
                    .into(),
            ));
        }
    };
    let opts = train_options(a)?;
    let prior = resolve_prior(a, robot.name(), out)?;
    check_out_dir(&a.out)?;
    let (data, dt) = read_log(&robot, &a.data, &a.read)?;
    report_data(&a.data, &data, dt, out)?;
    let all = RobotTransition::from_dataset(&data);
    let chosen = choose(a, &all)?;
    let inputs = robot.input_names().join(", ");
    w(
        out,
        format_args!(
            "fit: {} ({} joints [{}]{}), {encoding:?} encoding, {} prior: N = {} of {} \
             transitions, {} restarts",
            robot.name(),
            robot.dof(),
            robot.joint_names().join(", "),
            if inputs.is_empty() {
                String::new()
            } else {
                format!(", inputs [{inputs}]")
            },
            super::prior_name(&prior),
            chosen.len(),
            all.len(),
            opts.restarts
        ),
    )?;
    let (learned, report) = train_timed(robot.dof(), chosen.len(), opts.restarts, out, || {
        LearnedRobot::train(robot, dt, &chosen, encoding, prior, &opts)
            .map_err(|e| CliError::Usage(format!("training failed: {e}")))
    })?;
    for (j, o) in report.outputs.iter().enumerate() {
        w(
            out,
            format_args!(
                "  v_{}: log marginal likelihood {:.4e}, best start {}{}",
                learned.robot().joint_names()[j],
                o.log_marginal_likelihood,
                o.best_start,
                if o.converged { "" } else { " (iteration cap)" },
            ),
        )?;
    }
    learned
        .save(&a.out)
        .map_err(|e| CliError::Usage(format!("{}: {e}", a.out.display())))?;
    report_saved(&a.out, out)
}

/// Mean over the steps of |p − t|²/n.
fn window_mse(pred: &[Vec<f64>], truth: &[crate::nalgebra::DVector<f64>]) -> f64 {
    let s: f64 = pred
        .iter()
        .zip(truth)
        .map(|(p, t)| {
            p.iter()
                .zip(t.iter())
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / p.len() as f64
        })
        .sum();
    s / pred.len() as f64
}

/// The k positions a rollout's k steps produced (`states`: after steps 1
/// … k): those of states 2 … k and q_k + Δt·v_k (as for a declared
/// mechanism's `score`).
fn produced(states: &[RobotState], dt: f64) -> Vec<Vec<f64>> {
    let mut p: Vec<Vec<f64>> = states[1..].iter().map(|z| z.q.clone()).collect();
    if let Some(last) = states.last() {
        p.push(
            last.q
                .iter()
                .zip(&last.v)
                .map(|(q, v)| q + dt * v)
                .collect(),
        );
    }
    p
}

/// `score` of a learned robot: the k-step position MSE of the learned
/// model and of its robot's step (the prior's robot: the identified one
/// under an identified prior) over every window of the held-out runs.
fn score(a: &ScoreArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let k = a.steps;
    if k == 0 {
        return Err(CliError::Usage("--steps must be at least 1".into()));
    }
    if a.stepping.substeps != 1 {
        return Err(CliError::Usage(
            "--substeps: the tree engine halves a step by itself where it must".into(),
        ));
    }
    let learned = load_learned(&a.model)?;
    let dt = learned.dt();
    let data = read_data_at(learned.robot(), &a.data, &a.read, dt)?;
    let nominal = with_max_subdivision(learned.robot(), a.stepping.max_subdivision)?;
    let windows = super::score::windows(data.runs.iter().map(|r| r.positions.len()), k);
    w(
        out,
        format_args!(
            "model: {} ({} joints, {:?} encoding, {} prior, N = {}, dt = {dt} s)",
            a.model.display(),
            nominal.dof(),
            learned.encoding(),
            super::prior_name(learned.prior()),
            learned.gp().n()
        ),
    )?;
    let runs = data.runs.len();
    super::score::report_windows(&a.data, runs, None, windows.len(), k, out)?;
    let m = learned.inputs();
    let pb = bar(windows.len(), "scoring");
    let results: Vec<(Option<f64>, Option<f64>)> = windows
        .par_iter()
        .map(|&(r, s)| {
            let run = &data.runs[r];
            let truth = &run.positions[s + 2..=s + k + 1];
            let z0 = robot_state_at(run, s, dt);
            // step j of the window runs under row s + j + 1's input after
            // row s + j's
            let input = |row: usize| {
                if m == 0 {
                    Vec::new()
                } else {
                    run.inputs[row].clone()
                }
            };
            let us: Vec<Vec<f64>> = (s + 1..=s + k).map(input).collect();
            let nom = nominal
                .rollout_with(&z0, dt, k, |j, _| us[j].clone())
                .ok()
                .map(|roll| window_mse(&produced(&roll.states[1..], dt), truth));
            let lrn = learned
                .rollout(&z0, &input(s), &us)
                .ok()
                .map(|states| window_mse(&produced(&states, dt), truth));
            pb.inc(1);
            (nom, lrn)
        })
        .collect();
    pb.finish_and_clear();
    super::score::summary(results.into_iter(), k, out)
}
