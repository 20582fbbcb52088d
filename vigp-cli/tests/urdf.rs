//! The tool on a robot loaded from URDF (`--urdf`): `simulate` writes the
//! tree engine's rollout (checked against the library's), `identify`
//! recovers a perturbed robot from its log (its identified robot then
//! reproduces a held-out log), `fit` learns on top of the nominal and of
//! the identified robot, `score` compares them, `predict` attaches the
//! conformal bound, `excite` designs inputs within the URDF's limits, and
//! wrong use is a clear error.

use std::path::Path;

use vigp::learned::IdentifiedParameters;
use vigp::learned::robot::identified_robot;
use vigp::{Robot, RobotState};

mod common;
use common::{
    argv, line_starting, mse_line, number_after, parameter_row, predict_args, read_json, run_tool,
    s, score_args, table, table_with_header, temp_dir, write_file,
};

const DT: f64 = 0.002;
const ACTUATED: &str = "j1,j2,j3";

/// The test arm as declared (the nominal model).
fn nominal_urdf() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/robots/arm3.urdf"
    ))
    .unwrap()
}

/// The "real" arm: heavier distal links, more damping at the elbow, and
/// damping at the base joint, which the declaration lacks.
fn truth_urdf() -> String {
    let text = nominal_urdf()
        .replace(r#"<mass value="1.2"/>"#, r#"<mass value="1.38"/>"#)
        .replace(r#"<mass value="0.5"/>"#, r#"<mass value="0.6"/>"#)
        .replace(r#"damping="0.1""#, r#"damping="0.25""#)
        .replace(
            r#"<limit lower="-2.9" upper="2.9" effort="50" velocity="2"/>"#,
            r#"<limit lower="-2.9" upper="2.9" effort="50" velocity="2"/>
    <dynamics damping="0.05"/>"#,
        );
    assert_ne!(text, nominal_urdf());
    text
}

/// The robot of the URDF text `urdf`, its three joints actuated.
fn arm(urdf: &str) -> Robot {
    Robot::from_urdf_str(urdf)
        .unwrap()
        .with_actuated(&["j1", "j2", "j3"])
        .unwrap()
}

/// The tool in-process (no registered mechanism: `--urdf` needs none).
fn run(args: &[&str]) -> Result<String, vigp::cli::CliError> {
    run_tool(&[], "vigp", args)
}

/// A smooth plan for the three joints, `phase` apart per run.
fn write_plan(path: &Path, steps: usize, phase: f64) -> Vec<Vec<f64>> {
    let mut text = String::from("u_j1,u_j2,u_j3\n");
    let mut rows = Vec::new();
    for k in 0..steps {
        let t = k as f64 * DT;
        let u = vec![
            0.5 * (2.1 * t + phase).sin(),
            4.0 + 1.0 * (3.3 * t + 0.5 * phase).sin(),
            1.5 * (1.7 * t + phase).sin(),
        ];
        text.push_str(&format!("{:?},{:?},{:?}\n", u[0], u[1], u[2]));
        rows.push(u);
    }
    std::fs::write(path, text).unwrap();
    rows
}

/// The positions of a log (rows after the header, columns 2..2+n).
fn positions(path: &Path, n: usize) -> Vec<Vec<f64>> {
    table(path)[1..]
        .iter()
        .map(|r| r[2..2 + n].iter().map(|x| x.parse().unwrap()).collect())
        .collect()
}

/// `simulate --urdf` of the three actuated joints from `q` under the plan
/// in `plan`, into `log` as run `label`. `--max-subdivision 0`: every step
/// is one step of the first-order rule, so that a window's start state
/// (x_s, (x_(s+1) − x_s)/Δt) is the engine's own state.
fn simulate(urdf: &Path, q: &str, plan: &Path, log: &Path, label: &str) {
    let line = "simulate --urdf {} --actuated {} --q {} --dt 0.002 --steps 400 --inputs {} \
                --out {} --run {} --max-subdivision 0";
    run(&argv(line, &[s(urdf), ACTUATED, q, s(plan), s(log), label])).unwrap();
}

/// The largest |x − y| over the states' positions and a log's rows.
fn largest_gap(states: &[RobotState], log: &[Vec<f64>]) -> f64 {
    states
        .iter()
        .zip(log)
        .flat_map(|(z, x)| z.q.iter().zip(x).map(|(a, b)| (a - b).abs()))
        .fold(0.0f64, f64::max)
}

#[test]
fn simulate_identify_fit_score_on_a_perturbed_arm() {
    let dir = temp_dir("arm");
    let nominal = write_file(&dir, "arm3.urdf", nominal_urdf());
    let truth = write_file(&dir, "arm3_truth.urdf", truth_urdf());
    // training: three runs from different starts under different plans;
    // held out: a fourth
    let starts = [
        [0.2, -0.4, 0.05],
        [-0.5, 0.1, 0.0],
        [0.6, -0.8, 0.1],
        [-0.3, 0.3, 0.0],
    ];
    let mut plans = Vec::new();
    let mut logs = Vec::new();
    for (i, q) in starts.iter().enumerate() {
        let plan = dir.join(format!("plan{i}.csv"));
        plans.push(write_plan(&plan, 400, 1.3 * i as f64));
        let log = dir.join(format!("log{i}.csv"));
        let q = format!("{},{},{}", q[0], q[1], q[2]);
        simulate(&truth, &q, &plan, &log, &format!("r{i}"));
        logs.push(log);
    }
    let (train, test) = (dir.join("train.csv"), logs[3].clone());
    let mut text = std::fs::read_to_string(&logs[0]).unwrap();
    for log in &logs[1..3] {
        let more = std::fs::read_to_string(log).unwrap();
        text.push_str(more.split_once('\n').unwrap().1);
    }
    std::fs::write(&train, text).unwrap();

    // the log is the library's rollout of the same robot under the plan,
    // row k + 1 holding the input of step k; numbers are written in their
    // shortest round-trip form, so they agree bit for bit
    let rollout = |r: &Robot, i: usize| {
        let z0 = RobotState::new(starts[i].to_vec(), vec![0.0; 3]);
        r.rollout_with(&z0, DT, 400, |k, _| plans[i][k].clone())
            .unwrap()
            .states
    };
    let logged = positions(&logs[0], 3);
    assert_eq!(logged.len(), 402);
    for (k, z) in rollout(&arm(&truth_urdf()), 0).iter().enumerate() {
        assert_eq!(logged[k], z.q, "row {k}");
    }
    let rows = table(&logs[0]);
    assert_eq!(rows[0][5..], ["u_j1", "u_j2", "u_j3"]);
    assert_eq!(rows[1][5..], ["0.0", "0.0", "0.0"]);
    let row1: Vec<f64> = rows[2][5..].iter().map(|x| x.parse().unwrap()).collect();
    assert_eq!(row1, plans[0][0]);

    // identification with the declared arm as the prior's centre
    let params = dir.join("params.json");
    let line = "identify --urdf {} --actuated {} --data {} --out {}";
    let said = run(&argv(line, &[s(&nominal), ACTUATED, s(&train), s(&params)])).unwrap();
    assert!(said.contains("first-order rule"), "{said}");
    let file = read_json(&params);
    let dsl = |name: &str| parameter_row(&file, name)["identified"].as_f64().unwrap();
    // a noise-free log written by the rule the regression uses: the
    // dampings, each identifiable on its own here, to the rounding of the
    // regression (1e-8 absolute on values of 0.05–0.25)
    for (name, want) in [
        ("joints.j1.damping", 0.05),
        ("joints.j2.damping", 0.25),
        ("joints.j3.damping", 0.0),
    ] {
        let got = dsl(name);
        assert!((got - want).abs() < 1e-8, "{name}: {got} against {want}");
    }
    // the identified robot reproduces the held-out log it never saw
    let identified: IdentifiedParameters =
        serde_json::from_value(file["identified"].clone()).unwrap();
    let declared = arm(&nominal_urdf());
    let fitted = identified_robot(&declared, DT, &identified).unwrap();
    let test_log = positions(&test, 3);
    let off = largest_gap(&rollout(&fitted, 3), &test_log);
    let declared_off = largest_gap(&rollout(&declared, 3), &test_log);
    eprintln!("held-out log, 2 s: identified robot {off:.2e}, declared robot {declared_off:.2e}");
    // 400 steps that amplify the estimate's rounding: 1e-8 rad or m
    assert!(off < 1e-8, "{off}");
    assert!(declared_off > 1e-3, "{declared_off}");

    // learning on top of the declared robot, then of the identified one
    let (m_nominal, m_identified) = (dir.join("nominal.json"), dir.join("identified.json"));
    let prior = format!("identified:{}", s(&params));
    for (model, prior) in [(&m_nominal, "nominal"), (&m_identified, prior.as_str())] {
        let line = "fit --urdf {} --actuated {} --data {} --out {} --prior {} --restarts 1 \
                    --max-samples 400";
        run(&argv(
            line,
            &[s(&nominal), ACTUATED, s(&train), s(model), prior],
        ))
        .unwrap();
    }
    let score = |model: &Path| mse_line(&run(&score_args(s(model), s(&test), "20")).unwrap());
    let (nominal_mse, learned_mse) = score(&m_nominal);
    let (identified_mse, identified_learned_mse) = score(&m_identified);
    eprintln!(
        "20-step MSE: declared {nominal_mse:.3e}, declared + GP {learned_mse:.3e}, identified \
         {identified_mse:.3e}, identified + GP {identified_learned_mse:.3e}"
    );
    // the GP learns part of what the declared robot misses on a run it
    // never saw, from another start (measured: half the error, with 400
    // of the 1200 transitions in 14 GP inputs)
    assert!(
        learned_mse < 0.7 * nominal_mse,
        "{learned_mse} {nominal_mse}"
    );
    // the identified robot is the truth to rounding (the score's nominal
    // model of a model with an identified prior is the identified robot)
    assert!(identified_mse < 1e-16, "{identified_mse}");
    assert!(
        identified_learned_mse < 1e-3 * learned_mse,
        "{identified_learned_mse}"
    );
}

/// A CSV log of `robot`'s rollouts (run `r<i>` from `starts[i]` at rest
/// under a sine plan of phase i), in the data format.
fn logs(robot: &Robot, starts: &[[f64; 3]], steps: usize) -> String {
    let mut text = String::new();
    for (i, q0) in starts.iter().enumerate() {
        let us: Vec<Vec<f64>> = (0..steps)
            .map(|k| {
                let t = k as f64 * DT + 0.37 * i as f64;
                vec![
                    0.5 * (2.1 * t).sin(),
                    4.0 + (3.3 * t).sin(),
                    1.5 * (1.7 * t).sin(),
                ]
            })
            .collect();
        let z0 = RobotState::new(q0.to_vec(), vec![0.0; 3]);
        let roll = robot
            .rollout_with(&z0, DT, steps, |k, _| us[k].clone())
            .unwrap();
        let states: Vec<(&[f64], &[f64])> = roll
            .states
            .iter()
            .map(|z| (z.q.as_slice(), z.v.as_slice()))
            .collect();
        let inputs: Vec<&[f64]> = us.iter().map(Vec::as_slice).collect();
        let data = vigp::data::DynDataset::from_rollout(
            &["j1", "j2", "j3"],
            &["j1", "j2", "j3"],
            &format!("r{i}"),
            (0.0, DT),
            &states,
            (&[0.0; 3], &inputs),
        )
        .unwrap();
        let mut csv = Vec::new();
        data.write_csv(&mut csv).unwrap();
        let csv = String::from_utf8(csv).unwrap();
        text.push_str(if i == 0 {
            &csv
        } else {
            csv.split_once('\n').unwrap().1
        });
    }
    text
}

/// `predict` with a learned robot's model: the learned mean prediction
/// with the conformal bound calibrated on held-out runs, equal (bit for
/// bit, through the CSV's shortest round-trip numbers) to the library's
/// `LearnedRobot::error_bound` and `predict` on the model file; the rows
/// and columns of a declared mechanism's prediction; the rigorous kinds
/// and a missing `--calibration` refused with a reason.
#[test]
fn predict_attaches_the_conformal_bound_to_a_learned_robot() {
    use vigp::bound::ConformalSettings;
    use vigp::learned::robot::{LearnedRobot, RobotCalibration};
    let dir = temp_dir("predict");
    let nominal = write_file(&dir, "arm3.urdf", nominal_urdf());
    let truth = arm(&truth_urdf());
    let start = |i: usize| {
        let x = i as f64;
        [
            0.6 * (1.7 * x).sin(),
            -0.4 + 0.5 * (2.3 * x).cos(),
            0.05 + 0.05 * (0.9 * x).sin(),
        ]
    };
    let write = |name: &str, starts: Vec<[f64; 3]>, steps: usize| {
        write_file(&dir, name, logs(&truth, &starts, steps))
    };
    let train = write("train.csv", (0..2).map(start).collect(), 300);
    let cal = write("cal.csv", (10..50).map(start).collect(), 30);
    let test = write("test.csv", vec![start(100)], 60);
    let model = dir.join("model.json");
    let line = "fit --urdf {} --actuated {} --data {} --out {} --restarts 1 --max-samples 300";
    run(&argv(line, &[s(&nominal), ACTUATED, s(&train), s(&model)])).unwrap();
    let out = dir.join("pred.csv");
    let base = argv(
        "predict --model {} --data {} --steps 10 --stride 10 --delta 0.1 --out {}",
        &[s(&model), s(&test), s(&out)],
    );
    let said = run(&[&base[..], &["--calibration", s(&cal)]].concat()).unwrap();
    eprintln!("{said}");
    assert!(said.contains("conformal bound"), "{said}");
    let rows = table_with_header(
        &out,
        "run,start,t,j1,j2,j3,v_j1,v_j2,v_j3,u_j1,u_j2,u_j3,bound,position_bound,fallback",
    );
    // starts 0, 10, …, 50 of 62 samples (a start needs its 10 inputs after it)
    assert_eq!(rows.len(), 1 + 6 * 11);
    // the library on the same files
    let learned = LearnedRobot::load(&model).unwrap();
    let robot = learned.robot().clone();
    let read = |path: &Path| {
        let kinds = vigp::learned::robot::coordinate_kinds(&robot);
        vigp::data::DynDataset::read_path_with_inputs(
            path,
            &["j1", "j2", "j3"],
            &kinds,
            &["j1", "j2", "j3"],
            &vigp::data::ReadOptions::default(),
        )
        .unwrap()
    };
    type Runs = Vec<Vec<Vec<f64>>>;
    let split = |d: &vigp::data::DynDataset| -> (Runs, Runs) {
        d.runs
            .iter()
            .map(|r| {
                let q = r.positions.iter().map(|x| x.as_slice().to_vec()).collect();
                (q, r.inputs.clone())
            })
            .unzip()
    };
    let (cq, cu) = split(&read(&cal));
    let calibration = RobotCalibration::from_logs(&cq, &cu, DT, 10, 1).unwrap();
    let settings = ConformalSettings {
        delta: 0.1,
        ..ConformalSettings::default()
    };
    let bound = learned.error_bound(&settings, &calibration).unwrap();
    let (tq, tu) = split(&read(&test));
    for (p, first) in (0..6).map(|p| (p, 1 + 11 * p)) {
        let s0 = 10 * p;
        let v0 = (0..3)
            .map(|j| (tq[0][s0 + 1][j] - tq[0][s0][j]) / DT)
            .collect();
        let z0 = RobotState::new(tq[0][s0].clone(), v0);
        let pred = learned
            .predict(&z0, &tu[0][s0], &tu[0][s0 + 1..=s0 + 10], &bound)
            .unwrap();
        for k in 0..=10 {
            let row = &rows[first + k];
            assert_eq!(row[1], s0.to_string());
            let q: Vec<f64> = row[3..6].iter().map(|x| x.parse().unwrap()).collect();
            assert_eq!(q, pred.states[k].q, "start {s0}, step {k}");
            let pb: f64 = row[13].parse().unwrap();
            assert_eq!(pb, pred.position_bounds[k], "start {s0}, step {k}");
            if k > 0 {
                let b: f64 = row[12].parse().unwrap();
                assert_eq!(b, pred.one_step_bounds[k - 1]);
                // (q_1 = q_0 + Δt·v_0 is known exactly: its bound is 0)
                assert!(b > 0.0 && (pb > 0.0 || k == 1), "{b} {pb} at step {k}");
            }
        }
    }
    let refused = |extra: &[&str]| {
        run(&[&base[..], extra].concat())
            .expect_err("must fail")
            .to_string()
    };
    let e = refused(&[]);
    assert!(e.contains("--calibration"), "{e}");
    let e = refused(&["--calibration", s(&cal), "--bound", "rkhs"]);
    assert!(e.contains("conformal"), "{e}");
    // calibration windows cut from the training runs
    let e = refused(&["--calibration", s(&train)]);
    assert!(e.contains("training state"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `excite --urdf` on the test arm with its elbow axis turned vertical (a
/// SCARA-like arm: gravity does no work, so zero-mean periodic torques can
/// keep it within its limits): the design beats a random input of the
/// same amplitude by its log det information (the line it prints), stays
/// within the URDF's joint position and velocity limits (the excess it
/// prints, at most the design's tolerance 1e-3), writes a plan of |u| ≤ 1
/// per input, and `simulate --urdf --inputs` runs on it.
#[test]
fn excite_designs_within_the_urdf_limits() {
    let dir = temp_dir("excite");
    let scara = nominal_urdf().replace(r#"<axis xyz="0 1 0"/>"#, r#"<axis xyz="0 0 1"/>"#);
    assert_ne!(scara, nominal_urdf());
    let urdf = write_file(&dir, "scara.urdf", scara);
    let plan = dir.join("plan.csv");
    let line = "excite --urdf {} --actuated {} --duration 0.2 --dt 0.002 --harmonics 1 \
                --amplitude 1 --q 0.2,-0.4,0.05 --out {}";
    let text = run(&argv(line, &[s(&urdf), ACTUATED, s(&plan)])).unwrap();
    eprintln!("{text}");
    let info = line_starting(&text, "log det information: design ");
    assert!(
        number_after(info, "design ") > number_after(info, "same amplitude "),
        "{info}"
    );
    let limits = line_starting(&text, "joint limits (the URDF's)");
    assert!(number_after(limits, "of the design ") <= 1e-3, "{limits}");
    let rows = table_with_header(&plan, "t,u_j1,u_j2,u_j3");
    assert_eq!(rows.len(), 1 + 100);
    for r in &rows[1..] {
        for u in &r[1..] {
            let u: f64 = u.parse().unwrap();
            assert!(u.abs() <= 1.0 + 1e-12, "{u}");
        }
    }
    let log = dir.join("log.csv");
    let line = "simulate --urdf {} --actuated {} --q 0.2,-0.4,0.05 --dt 0.002 --steps 100 \
                --inputs {} --out {}";
    run(&argv(line, &[s(&urdf), ACTUATED, s(&plan), s(&log)])).unwrap();
    // 101 states and the last one's q + Δt·v
    assert_eq!(positions(&log, 3).len(), 102);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn wrong_use_is_a_clear_error() {
    let dir = temp_dir("errors");
    let urdf = write_file(&dir, "arm3.urdf", nominal_urdf());
    let fails = |args: &[&str]| run(args).expect_err("must fail").to_string();
    let out = dir.join("out.csv");
    // `simulate` of `urdf` from `q` for 5 steps, then `extra`: its error
    let simulate = |urdf: &Path, q: &str, extra: &[&str]| {
        let line = "simulate --urdf {} --q {} --dt 0.01 --steps 5 --out {}";
        fails(&[&argv(line, &[s(urdf), q, s(&out)])[..], extra].concat())
    };
    let sim = |extra: &[&str]| simulate(&urdf, "0,0,0", extra);
    let e = sim(&["--actuated", "j9"]);
    assert!(
        e.contains("unknown joint `j9`") && e.contains("j1, j2, j3"),
        "{e}"
    );
    let e = simulate(&dir.join("missing.urdf"), "0,0,0", &[]);
    assert!(e.contains("missing.urdf"), "{e}");
    let e = simulate(&urdf, "0,0", &[]);
    assert!(
        e.contains("--q has 2 value(s)") && e.contains("j1, j2, j3"),
        "{e}"
    );
    let e = sim(&["--set", "links.link1.mass=2"]);
    assert!(e.contains("edit the URDF"), "{e}");
    let e = sim(&["--substeps", "2"]);
    assert!(e.contains("--substeps"), "{e}");
    let line = "simulate --urdf {} --system pendulum --q 0,0,0 --dt 0.01 --steps 5 --out {}";
    let e = fails(&argv(line, &[s(&urdf), s(&out)]));
    assert!(e.contains("--system"), "{e}");
    // a log to read
    let line = "simulate --urdf {} --q 0.1,0.2,0 --dt 0.01 --steps 40 --out {}";
    run(&argv(line, &[s(&urdf), s(&out)])).unwrap();
    // the midpoint rule (for logs of a real robot) is the regressor's other
    // rule, named in the report
    let line = "identify --urdf {} --data {} --out {} --rule midpoint";
    let report = run(&argv(line, &[s(&urdf), s(&out), s(&dir.join("p.json"))])).unwrap();
    assert!(report.contains("midpoint rule"), "{report}");
    // the log has no input columns, the robot now has inputs
    let line = "fit --urdf {} --actuated j2 --data {} --out {}";
    let e = fails(&argv(line, &[s(&urdf), s(&out), s(&dir.join("m.json"))]));
    assert!(e.contains("u_j2"), "{e}");
    let line = "fit --urdf {} --data {} --out {} --encoding maximal";
    let e = fails(&argv(line, &[s(&urdf), s(&out), s(&dir.join("m.json"))]));
    assert!(e.contains("joint coordinates"), "{e}");
    // a model of the robot: `predict` says what takes it
    let model = dir.join("m.json");
    let line = "fit --urdf {} --data {} --out {} --restarts 0";
    run(&argv(line, &[s(&urdf), s(&out), s(&model)])).unwrap();
    let e = fails(&predict_args(
        s(&model),
        s(&out),
        "3",
        s(&dir.join("p.csv")),
    ));
    assert!(e.contains("--calibration"), "{e}");
    // export writes the learned robot for the no_std stepper (the
    // generated source is compiled and checked in tests/learn)
    let rs = dir.join("m.rs");
    let said = run(&["export", "--model", s(&model), "--out", s(&rs)]).unwrap();
    assert!(said.contains("LearnedTreeStepper"), "{said}");
    let src = std::fs::read_to_string(&rs).unwrap();
    assert!(src.contains("pub static LEARNED: vigp::embedded::tree::LearnedTree<'static, 3,"));
}
