//! The tool's prediction road on an actuated cart-pole: `simulate` writes
//! a log with the inputs on the rows the reader expects (the nominal
//! model then reproduces it to rounding, and a log whose inputs are
//! shifted by one row does not, and `fit` warns about it); `score`
//! averages only the positions a model step produced (checked against a
//! direct computation); `predict --stride`, `--inputs PLAN`, the
//! conformal output's `fallback` column and guarantee, and the error for
//! calibration runs too short for the horizon.

use std::path::{Path, PathBuf};

use vigp::SVector;
use vigp::prelude::*;

mod common;
use common::{
    argv, assert_same_mean, cell, line_starting, mse_line, number_after, parameter_row,
    predict_args, read_json, run_tool, s, score_args, table, table_with_header, temp_dir,
    write_file,
};

#[path = "../../tests/common/drive_cartpole.rs"]
mod drive_cartpole;
use drive_cartpole::DriveCartpole;

const DT: f64 = 0.01;

/// The tool of the driven cart-pole, in-process, as the program `drive`.
fn run(args: &[&str]) -> Result<String, vigp::cli::CliError> {
    run_tool(&[vigp::cli::system::<DriveCartpole>()], "drive", args)
}

/// A plan of `n` inputs held for 10 rows each.
fn plan(n: usize) -> Vec<f64> {
    (0..n)
        .map(|j| 2.5 * (0.9 * (j / 10) as f64 + 0.3).sin())
        .collect()
}

/// The plan of `steps` inputs, written into `dir` as `plan.csv`: the inputs
/// and the file's path.
fn plan_file(dir: &Path, steps: usize) -> (Vec<f64>, PathBuf) {
    let us = plan(steps);
    let path = dir.join("plan.csv");
    write_plan(&path, &us);
    (us, path)
}

/// Writes `us` as a plan file (one `u_rail` column).
fn write_plan(path: &Path, us: &[f64]) {
    let mut text = String::from("u_rail\n");
    for u in us {
        text.push_str(&format!("{u:?}\n"));
    }
    std::fs::write(path, text).unwrap();
}

/// Asserts that the positions of a log's rows (after the header) are those
/// of `states`, bit for bit.
fn assert_positions(rows: &[Vec<String>], states: &[State<2>]) {
    for (k, z) in states.iter().enumerate() {
        let row = &rows[1 + k];
        assert_eq!((cell(row, 2), cell(row, 3)), (z.q[0], z.q[1]), "row {k}");
    }
}

#[test]
fn time_column_has_no_float_noise() {
    // 3 · 0.1 is 0.30000000000000004 in f64 and 6 · 0.010000000000000002
    // (a run's mean step from printed times) 0.06000000000000001: each
    // prints as the decimal the index means
    assert_eq!(vigp::data::format_time(0.0, 0.1, 3), "0.3");
    assert_eq!(vigp::data::format_time(0.0, 0.02, 3), "0.06");
    assert_eq!(
        vigp::data::format_time(0.0, 0.010000000000000002, 6),
        "0.06"
    );
    assert_eq!(vigp::data::format_time(1.5, 0.1, 3), "1.8");
    assert_eq!(vigp::data::format_time(2.0, 1.0, 3), "5.0");
}

#[test]
fn simulate_fit_score_predict() {
    let dir = temp_dir("sim");
    let steps = 200;
    let (us, plan_path) = plan_file(&dir, steps);
    let log = dir.join("log.csv");
    let line = "simulate --q 0.1,0.5 --dt 0.01 --steps 200 --inputs {} --out {} --run a";
    let said = run(&argv(line, &[s(&plan_path), s(&log)])).unwrap();
    assert!(said.contains("202 rows"), "{said}");
    let rows = table_with_header(&log, "run,t,rail,hinge,u_rail");
    assert_eq!(rows.len(), 1 + steps + 2);
    // t without float noise
    assert_eq!(rows[1 + 6][1], "0.06");
    assert_eq!(rows[1 + 7][1], "0.07");
    // the log is the rollout z_0 … z_K under the plan (written in
    // round-trip form: bit for bit), one more row q_K + Δt·v_K, and log row
    // k + 1 holds the input of step k (row 0: zero; the last row repeats)
    let vi = Variational::new(DriveCartpole::default().minimal(), DT).unwrap();
    let plan_u: Vec<SVector<f64, 1>> = us.iter().map(|u| SVector::from([*u])).collect();
    let states = vi
        .rollout_forced(&State::new([0.1, 0.5], [0.0, 0.0]), &plan_u)
        .unwrap();
    let last = states[steps].q + states[steps].v * DT;
    for (k, row) in rows[1..].iter().enumerate() {
        let q = states.get(k).map_or(last, |z| z.q);
        assert_eq!((cell(row, 2), cell(row, 3)), (q[0], q[1]), "row {k}");
        let u = match k {
            0 => 0.0,
            k if k <= steps => us[k - 1],
            _ => us[steps - 1],
        };
        assert_eq!(cell(row, 4), u, "row {k}");
    }

    // a truth with a heavier cart (simulate --set) to learn from
    let heavy = dir.join("heavy.csv");
    let line = "simulate --q 0.1,0.5 --dt 0.01 --steps 200 --inputs {} --out {} \
                --set links.cart.mass=1.5";
    run(&argv(line, &[s(&plan_path), s(&heavy)])).unwrap();
    // fit on it (no warning about the inputs), and score on the log: the
    // nominal model (the file's parameters, the defaults) reproduces it to
    // rounding (the numbers are written in round-trip form)
    let model = dir.join("m.json");
    // `fit` on `data` into `out`, quickly (the noise floored)
    let fit = |data: &Path, out: &Path| {
        let line = "fit --data {} --out {} --restarts 0 --max-samples 60 --noise-floor 1e-6";
        run(&argv(line, &[s(data), s(out)])).unwrap()
    };
    let fit_heavy = fit(&heavy, &model);
    assert!(!fit_heavy.contains("warning"), "{fit_heavy}");
    let score = |data: &Path, steps: &str| run(&score_args(s(&model), s(data), steps)).unwrap();
    let report = score(&log, "5");
    assert!(
        report.contains("averaged over the positions the steps produce: x_(s+2) … x_(s+6)"),
        "{report}"
    );
    let (nominal, _) = mse_line(&report);
    assert!(nominal < 1e-24, "{nominal:e}");

    // the same log with every input one row early: fit warns, and the
    // nominal model no longer reproduces it
    let early = dir.join("early.csv");
    let mut text = String::from("run,t,rail,hinge,u_rail\n");
    for k in 1..rows.len() {
        let u = rows
            .get(k + 1)
            .map_or(rows[k][4].as_str(), |r| r[4].as_str());
        text.push_str(&format!(
            "{},{},{},{},{u}\n",
            rows[k][0], rows[k][1], rows[k][2], rows[k][3]
        ));
    }
    std::fs::write(&early, text).unwrap();
    let fit_early = fit(&early, &dir.join("early.json"));
    assert!(
        fit_early.contains("the inputs look logged one row early"),
        "{fit_early}"
    );
    let (nominal_early, _) = mse_line(&score(&early, "5"));
    assert!(nominal_early > 1e-12, "{nominal_early:e}");

    // `--steps 1` scores x_(s+2), produced by one step: against the truth
    // with the heavier cart, the nominal score is the mean of
    // |x̂_(s+2) − x_(s+2)|²/2 over the windows, computed here directly
    let (nominal_1, _) = mse_line(&score(&heavy, "1"));
    let h = table(&heavy);
    let q = |r: usize| SVector::<f64, 2>::new(cell(&h[1 + r], 2), cell(&h[1 + r], 3));
    let (mut sum, mut n) = (0.0, 0);
    for w in 0..h.len() - 3 {
        let z0 = State {
            q: q(w),
            v: (q(w + 1) - q(w)) / DT,
        };
        let z1 = vi
            .step_forced(&z0, &SVector::from([cell(&h[1 + w + 1], 4)]))
            .unwrap();
        sum += (z1.q + z1.v * DT - q(w + 2)).norm_squared() / 2.0;
        n += 1;
    }
    // the same sums in another order: agreement to 1e-9 relative
    assert_same_mean(nominal_1, sum / n as f64);

    // held-out runs for the conformal bound, from another start
    let held = dir.join("held.csv");
    let line = "simulate --q -0.15,-0.4 --dt 0.01 --steps 200 --inputs {} --out {} --run h";
    run(&argv(line, &[s(&plan_path), s(&held)])).unwrap();
    let pred = dir.join("pred.csv");
    let predict = |extra: &[&str]| {
        let line = "predict --model {} --steps 5 --out {} --calibration {}";
        run(&[&argv(line, &[s(&model), s(&pred), s(&held)])[..], extra].concat())
    };
    // --stride 50 on the 202-row log: starts 0, 50, 100, 150 (a start s
    // needs rows s … s + 5 for its inputs)
    let said = predict(&["--data", s(&log), "--stride", "50"]).unwrap();
    assert!(
        said.contains("4 predictions (every 50 samples of 1 run(s)) × 5 steps (0 failed)"),
        "{said}"
    );
    assert!(
        said.contains("calibration windows")
            && said.contains("marginal over start states")
            && said.contains("per step"),
        "{said}"
    );
    let p = table_with_header(
        &pred,
        "run,start,t,rail,hinge,v_rail,v_hinge,u_rail,bound,position_bound,fallback",
    );
    assert_eq!(p.len(), 1 + 4 * 6);
    let starts: Vec<&str> = p[1..].iter().step_by(6).map(|r| r[1].as_str()).collect();
    assert_eq!(starts, ["0", "50", "100", "150"]);
    // the row 2 steps after start 50 is at t = 0.52, and its input is the
    // log's row 52
    assert_eq!(p[1 + 6 + 2][2], "0.52");
    assert_eq!(p[1 + 6 + 2][7], rows[1 + 52][4]);
    assert!(
        p[1..]
            .iter()
            .all(|r| r[10].is_empty() || r[10] == "rkhs" || r[10] == "outside")
    );
    let strided = p.clone();

    // the same prediction from start 50 with the inputs from a plan: the
    // start's two rows alone, no position rows for the inputs
    let start = write_file(
        &dir,
        "start.csv",
        format!(
            "run,t,rail,hinge,u_rail\n{}\n{}\n",
            rows[1 + 50].join(","),
            rows[1 + 51].join(",")
        ),
    );
    let part = dir.join("part.csv");
    write_plan(&part, &us[50..55]);
    let said = predict(&["--data", s(&start), "--inputs", s(&part)]).unwrap();
    assert!(said.contains("1 runs × 5 steps (0 failed)"), "{said}");
    let p = table(&pred);
    assert_eq!(p.len(), 1 + 6);
    for k in 0..6 {
        // the strided output's columns without `start`
        let mut want = strided[1 + 6 + k].clone();
        want.remove(1);
        assert_eq!(p[1 + k], want, "row {k}");
    }
    // too short a plan
    write_plan(&part, &us[50..53]);
    let e = predict(&["--data", s(&start), "--inputs", s(&part)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("3 input row(s), --steps 5 needs 5"), "{e}");
    // a plan with position columns is refused
    std::fs::write(&part, "rail,u_rail\n0,1\n").unwrap();
    let e = predict(&["--data", s(&start), "--inputs", s(&part)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown column `rail`"), "{e}");

    // calibration runs too short for the horizon: the lengths needed and had
    let short = write_file(
        &dir,
        "short.csv",
        format!(
            "run,t,rail,hinge,u_rail\n{}\n",
            rows[1..5]
                .iter()
                .map(|r| r.join(","))
                .collect::<Vec<_>>()
                .join("\n")
        ),
    );
    let mut args = predict_args(s(&model), s(&log), "5", s(&pred));
    args.extend(["--calibration", s(&short)]);
    let e = run(&args).unwrap_err().to_string();
    assert!(
        e.contains("need runs of at least 6 samples; the longest run has 4") && e.contains("`a` 4"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `simulate --substeps K` writes the rollout of `Variational::substeps(K)`,
/// bit for bit (and differs from the single-step rollout).
#[test]
fn simulate_takes_substeps() {
    let dir = temp_dir("substeps");
    let steps = 50;
    let (us, plan_path) = plan_file(&dir, steps);
    let log = dir.join("log.csv");
    let line = "simulate --q 0.1,0.5 --dt 0.01 --steps 50 --substeps 4 --inputs {} --out {}";
    run(&argv(line, &[s(&plan_path), s(&log)])).unwrap();
    let rows = table(&log);
    let plan_u: Vec<SVector<f64, 1>> = us.iter().map(|u| SVector::from([*u])).collect();
    let z0 = State::new([0.1, 0.5], [0.0, 0.0]);
    let model = DriveCartpole::default().minimal();
    let fine = Variational::new(model, DT)
        .unwrap()
        .substeps(4)
        .unwrap()
        .rollout_forced(&z0, &plan_u)
        .unwrap();
    let plain = Variational::new(model, DT)
        .unwrap()
        .rollout_forced(&z0, &plan_u)
        .unwrap();
    assert_positions(&rows, &fine[..=steps]);
    assert!((fine[steps].q - plain[steps].q).amax() > 1e-9);
    // K = 0 is refused with a typed error, not a panic
    let line = "simulate --q 0.1,0.5 --dt 0.01 --steps 5 --substeps 0 --out {}";
    let e = run(&argv(line, &[s(&dir.join("zero.csv"))])).unwrap_err();
    assert!(e.to_string().contains("substeps"), "{e}");
}

/// Where a rollout without subdivision fails (a Newton failure or a root that is not the
/// continuation of the motion, at a Δt far too large for the motion),
/// `simulate` by default retakes the failing steps with halved sub-steps:
/// the log is the default `Variational` rollout (8 halvings) bit for bit, and
/// the output says how many steps subdivided themselves.
/// `--max-subdivision 0` makes the first failure an error that names its
/// step.
#[test]
fn simulate_subdivides_failing_steps_by_default() {
    let dir = temp_dir("subdivide");
    let steps = 40;
    let z0 = State::new([0.1, 2.5], [0.0, 0.0]);
    let model = DriveCartpole::default().minimal();
    let zero = vec![SVector::<f64, 1>::zeros(); steps];
    // the smallest of these Δt at which the plain rollout fails
    let dt = [0.05, 0.1, 0.2, 0.3, 0.5, 1.0]
        .into_iter()
        .find(|&dt| {
            Variational::new(model, dt)
                .unwrap()
                .max_subdivision(0)
                .rollout_forced(&z0, &zero)
                .is_err()
        })
        .expect("a time step at which the plain rollout fails");
    // the library's default for an unconstrained mechanism: 8 halvings
    let resolved = Variational::new(model, dt)
        .unwrap()
        .rollout_forced_with_report(&z0, &zero)
        .unwrap();
    assert!(resolved.1.subdivided > 0);
    let log = dir.join("log.csv");
    let dts = dt.to_string();
    let steps_s = steps.to_string();
    let args = [
        "simulate", "--q", "0.1,2.5", "--dt", &dts, "--steps", &steps_s, "--out",
    ];
    let text = run(&[&args[..], &[s(&log)]].concat()).unwrap();
    let n = resolved.1.subdivided;
    let said = format!(
        "{n} of {steps} steps subdivided {}",
        if n == 1 { "itself" } else { "themselves" }
    );
    assert!(text.contains(&said), "{text}");
    let rows = table(&log);
    assert_positions(&rows, &resolved.0[..=steps]);
    let e = run(&[
        &args[..],
        &[s(&dir.join("plain.csv")), "--max-subdivision", "0"],
    ]
    .concat())
    .unwrap_err();
    assert!(e.to_string().contains("step"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `identify` on a log that the first-order integrator wrote under a
/// persistently exciting plan, for a cart-pole whose pole is heavier and
/// whose joints are more damped than declared: the damping of both joints
/// is identified to rounding (the DEL residual is exactly linear in the
/// parameters and zero at the truth; tolerance 1e-8 relative, far above
/// the regression's rounding of about 1e-12), also with `--output-error`
/// (the log is the rule's own, so its simulation reproduces it at the
/// truth), and with `--noise eiv --noise-sigma 1e-9` (a correction of
/// order σ²; the flag's misuse is refused), and `fit --prior
/// identified:FILE` makes the model file's nominal model the truth's
/// dynamics: its 20-step score on a held-out log is below 1e-6 of the
/// declared model's. The model file records the identified standard
/// parameters and their covariance (as the parameter file has them), and
/// `predict` and `export` run on it. A file of another mechanism, one
/// without the standard parameters, and a `--set` of an identified
/// parameter are refused.
#[test]
fn identify_then_fit_with_the_identified_prior() {
    let dir = temp_dir("identify");
    let truth = "--set links.pole.mass=0.36 --set joints.rail.damping=0.3 \
                 --set joints.hinge.damping=0.08";
    let simulate = |name: &str, q: &str, phase: f64, steps: usize| -> PathBuf {
        let us: Vec<f64> = (0..steps)
            .map(|j| 3.0 * (0.7 * (j / 7) as f64 + phase).sin() + 1.5 * (0.13 * j as f64).cos())
            .collect();
        let plan_path = dir.join(format!("{name}-plan.csv"));
        write_plan(&plan_path, &us);
        let log = dir.join(format!("{name}.csv"));
        let steps_s = steps.to_string();
        let line = "simulate --q {} --dt 0.01 --steps {} --inputs {} --run {} --out {}";
        let args = argv(line, &[q, &steps_s, s(&plan_path), name, s(&log)]);
        run(&[args, argv(truth, &[])].concat()).unwrap();
        log
    };
    let train = simulate("train", "0.1,0.5", 0.3, 400);
    let test = simulate("test", "-0.2,2.0", 1.1, 120);

    // `identify` on the training log into `name`, with `extra` options:
    // the file's path, what the tool said, the file
    let identify_into = |name: &str, extra: &[&str]| {
        let path = dir.join(name);
        let args = argv(
            "identify --data {} --rule first-order --out {}",
            &[s(&train), s(&path)],
        );
        let text = run(&[&args[..], extra].concat()).unwrap();
        let file = read_json(&path);
        (path, text, file)
    };
    let (params, text, file) = identify_into("params.json", &[]);
    assert!(text.contains("base parameters"), "{text}");
    let row = |name: &str| parameter_row(&file, name);
    for (name, declared, true_value) in [
        ("joints.rail.damping", 0.1, 0.3),
        ("joints.hinge.damping", 0.05, 0.08),
    ] {
        let r = row(name);
        assert_eq!(r["status"], "identified", "{r}");
        assert_eq!(r["declared"].as_f64().unwrap(), declared, "{r}");
        let got = r["identified"].as_f64().unwrap();
        assert!(
            (got - true_value).abs() <= 1e-8 * true_value,
            "{name}: {got} vs {true_value}"
        );
    }
    // the output-error stage keeps the recovery (the log is the rule's
    // own: the simulation reproduces it at the truth)
    let (_, text, refined) = identify_into("refined.json", &["--output-error"]);
    assert!(text.contains("output error: 8 segments"), "{text}");
    for (name, true_value) in [("joints.rail.damping", 0.3), ("joints.hinge.damping", 0.08)] {
        let got = parameter_row(&refined, name)["identified"]
            .as_f64()
            .unwrap();
        assert!(
            (got - true_value).abs() <= 1e-8 * true_value,
            "output error, {name}: {got} vs {true_value}"
        );
    }

    // bias compensation for noise far below the log's rounding keeps the
    // recovery (the correction is σ² small); it needs the noise's size
    let (_, _, compensated) =
        identify_into("eiv.json", &["--noise", "eiv", "--noise-sigma", "1e-9"]);
    for (name, true_value) in [("joints.rail.damping", 0.3), ("joints.hinge.damping", 0.08)] {
        let got = parameter_row(&compensated, name)["identified"]
            .as_f64()
            .unwrap();
        assert!(
            (got - true_value).abs() <= 1e-8 * true_value,
            "bias-compensated, {name}: {got} vs {true_value}"
        );
    }
    let refused = dir.join("refused.json");
    for (extra, says) in [
        (&["--noise", "eiv"][..], "needs --noise-sigma"),
        (
            &["--noise", "eiv", "--noise-sigma=-1"][..],
            "positive and finite",
        ),
        (&["--noise-sigma", "1e-4"][..], "serves --noise eiv only"),
    ] {
        let args = argv("identify --data {} --out {}", &[s(&train), s(&refused)]);
        let err = run(&[&args[..], extra].concat()).unwrap_err().to_string();
        assert!(err.contains(says), "{extra:?}: {err}");
    }

    let fit_score = |prior: &str, name: &str| -> (f64, f64) {
        let model = dir.join(format!("{name}.json"));
        let line = "fit --data {} --out {} --prior {} --restarts 0 --max-samples 150";
        let said = run(&argv(line, &[s(&train), s(&model), prior])).unwrap();
        if prior.starts_with("identified:") {
            assert!(said.contains("parameters identified in"), "{said}");
        }
        mse_line(&run(&score_args(s(&model), s(&test), "20")).unwrap())
    };
    let (declared_nominal, _) = fit_score("nominal", "declared");
    let identified = format!("identified:{}", s(&params));
    let (identified_nominal, _) = fit_score(&identified, "identified");
    println!(
        "20-step nominal MSE: declared parameters {declared_nominal:.3e}, identified {identified_nominal:.3e}"
    );
    assert!(
        identified_nominal < 1e-6 * declared_nominal,
        "{identified_nominal:e} vs {declared_nominal:e}"
    );

    // the model file records the identified standard parameters and their
    // covariance as the parameter file has them, and the DSL's values
    let model_path = dir.join("identified.json");
    let model = read_json(&model_path);
    let params_file = read_json(&params);
    let recorded = &model["prior"]["identified"];
    assert_eq!(recorded, &params_file["identified"], "{recorded}");
    assert_eq!(recorded["mechanism"], "DriveCartpole");
    let standard = recorded["parameters"].as_array().unwrap();
    let covariance = recorded["covariance"].as_array().unwrap();
    assert_eq!(covariance.len(), standard.len());
    for (i, row) in covariance.iter().enumerate() {
        let row = row.as_array().unwrap();
        assert_eq!(row.len(), standard.len());
        assert!(row[i].as_f64().unwrap() >= 0.0, "variance {i}: {}", row[i]);
    }
    let rail = standard
        .iter()
        .find(|r| r["name"] == "joints.rail.damping")
        .unwrap();
    assert!(
        (rail["value"].as_f64().unwrap() - 0.3).abs() <= 1e-8 * 0.3,
        "{rail}"
    );
    for name in [
        "joints.rail.damping",
        "joints.hinge.damping",
        "links.pole.mass",
    ] {
        assert_eq!(model["parameters"][name], row(name)["identified"], "{name}");
    }
    // predict and export run on it (score did above); export writes the
    // identified parameters as the embedded model's nominal ones
    let pred = dir.join("identified-pred.csv");
    run(&predict_args(s(&model_path), s(&test), "5", s(&pred))).unwrap();
    assert!(table(&pred).len() > 1);
    let rs = dir.join("identified.rs");
    run(&["export", "--model", s(&model_path), "--out", s(&rs)]).unwrap();
    let source = std::fs::read_to_string(&rs).unwrap();
    let damping = model["parameters"]["joints.rail.damping"].as_f64().unwrap();
    assert!(
        source.contains(&format!("(\"joints.rail.damping\", {damping:?})")),
        "{source}"
    );
    assert!(source.contains("learned::Prior::Nominal"), "{source}");

    // `fit` on the training log with `extra` options must fail: its message
    let never = dir.join("never.json");
    let refused = |extra: &[&str]| {
        let args = ["fit", "--data", s(&train), "--out", s(&never)];
        run(&[&args[..], extra].concat()).unwrap_err().to_string()
    };
    // a `--set` of a parameter the identified prior sets is refused
    let e = refused(&["--prior", &identified, "--set", "joints.hinge.damping=0.2"]);
    assert!(e.contains("sets this parameter"), "{e}");
    // a parameter file without the standard parameters and covariance
    let bare = dir.join("bare.json");
    let mut without = params_file.clone();
    without.as_object_mut().unwrap().remove("identified");
    std::fs::write(&bare, without.to_string()).unwrap();
    let e = refused(&["--prior", &format!("identified:{}", s(&bare))]);
    assert!(e.contains("no \"identified\" section"), "{e}");

    // a parameter file of another mechanism, or no parameter file, is refused
    let other = write_file(
        &dir,
        "other.json",
        std::fs::read_to_string(&params)
            .unwrap()
            .replace("\"DriveCartpole\"", "\"Acrobot\""),
    );
    for (file, says) in [(&other, "identified for `Acrobot`"), (&train, "not JSON")] {
        let e = refused(&["--prior", &format!("identified:{}", s(file))]);
        assert!(e.contains(says), "{e}");
    }
    let e = refused(&["--prior", "identified:"]);
    assert!(e.contains("identified:FILE"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `excite` designs a plan (one Fourier series for the rail force, peak
/// ≤ 2 N) whose log det information beats a random input's of the same
/// amplitude (the line it prints), writes it in the format `simulate
/// --inputs` reads (which then runs on it), and refuses a zero amplitude.
#[test]
fn excite_writes_a_plan_that_simulate_reads() {
    let dir = temp_dir("excite");
    let plan_path = dir.join("plan.csv");
    let excite = "excite --duration 1.5 --dt 0.01 --harmonics 3 --amplitude 2 --q 0,0.3 --out {}";
    let text = run(&argv(excite, &[s(&plan_path)])).unwrap();
    let line = line_starting(&text, "log det information: design ");
    let design = number_after(line, "design ");
    let random = number_after(line, "same amplitude ");
    assert!(design > random, "{line}");
    let rows = table_with_header(&plan_path, "t,u_rail");
    assert_eq!(rows.len(), 1 + 150);
    for r in &rows[1..] {
        let u: f64 = r[1].parse().unwrap();
        assert!(u.abs() <= 2.0 * (1.0 + 1e-12), "{u}");
    }
    let log = dir.join("log.csv");
    let line = "simulate --q 0,0.3 --dt 0.01 --steps 150 --inputs {} --out {}";
    run(&argv(line, &[s(&plan_path), s(&log)])).unwrap();
    let e = run(&argv("excite --duration 1 --dt 0.01 --amplitude 0", &[])).unwrap_err();
    assert!(e.to_string().contains("amplitude"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
