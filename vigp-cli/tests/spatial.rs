//! The tool on 3-D mechanisms, in their minimal coordinates: a logged
//! Furuta pendulum (`vigp::systems::spatial::Furuta`, two revolute joints
//! with non-parallel axes) through `vigp simulate` (with a heavier pendulum
//! and joint friction set by `--set`: the truth), `fit` (on the nominal,
//! frictionless model), `score` (the learned model beats the nominal one;
//! the nominal score checked against a direct computation), `predict`
//! (conformal, calibrated on held-out runs) and `export`; a 3-D mechanism
//! declared here, actuated, through `vigp::cli::system::<M>()` with its
//! input columns, and `identify` with `fit --prior identified:FILE` on
//! it; and the maximal view refused with a typed error.

use std::path::Path;

mod common;
use common::{
    argv, assert_file_is, assert_same_mean, cell, mse_line, parameter_row, read_json, run_tool, s,
    score_args, table, table_with_header, temp_dir, vigp, vigp_fails, write_file,
};

use vigp::SVector;
use vigp::data::{Dataset, ReadOptions};
use vigp::prelude::*;
use vigp::systems::spatial::{Furuta, FurutaMinimal};

const DT: f64 = 0.01;

/// The truth of the Furuta logs: the pendulum 10 % heavier, viscous
/// friction on both joints (the nominal model has none).
const TRUTH: &str = "--set links.pendulum.mass=0.11 --set joints.base.damping=0.004 \
                     --set joints.pivot.damping=0.002";

vigp::mechanism! {
    /// A Furuta pendulum whose arm is driven by a motor (declared only in
    /// this test): the example's links and axes, `actuated` on `base`.
    pub DrivenFuruta {
        gravity: [0.0, 0.0, -9.81],
        links {
            arm: { mass: 0.3, length: 0.25, inertia: [0.000015, 0.0015700, 0.0015700] },
            pendulum: {
                mass: 0.1,
                length: 0.4,
                inertia: [0.000005, 0.0013358, 0.0013358],
                frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            },
        }
        joints {
            base: revolute(world, arm.start) { axis: [0.0, 0.0, 1.0], damping: 0.0, actuated },
            pivot: revolute(arm.end, pendulum.start) { axis: [1.0, 0.0, 0.0], damping: 0.0 },
        }
    }
}

/// Start states (base, pivot, their rates), one per run index from
/// SplitMix64: the pendulum from hanging to near upright, turning either
/// way, and the arm swinging.
fn start(i: usize) -> ([f64; 2], [f64; 2]) {
    let mut state = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5EED;
    let mut x = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    ([2.0 * x(), 5.0 * x()], [4.0 * x(), 6.0 * x()])
}

/// `vigp simulate` of the Furuta truth from `start(i)` for each `i` in
/// `runs` (`steps` steps each), concatenated into one log at `path`.
fn furuta_log(dir: &Path, path: &Path, runs: std::ops::Range<usize>, steps: usize, truth: bool) {
    let mut text = String::new();
    for i in runs {
        let (q, v) = start(i);
        let one = dir.join(format!("run{i}.csv"));
        let (q, v) = (format!("{},{}", q[0], q[1]), format!("{},{}", v[0], v[1]));
        let steps = steps.to_string();
        let run = format!("r{i}");
        let line = "simulate --system furuta --q {} --v {} --dt 0.01 --steps {} --run {} --out {}";
        let mut args = argv(line, &[&q, &v, &steps, &run, s(&one)]);
        if truth {
            args.extend(argv(TRUTH, &[]));
        }
        let said = vigp(&args);
        assert!(said.contains("steps of Furuta"), "{said}");
        let log = std::fs::read_to_string(&one).unwrap();
        let mut lines = log.lines();
        let header = lines.next().unwrap();
        assert_eq!(header, "run,t,base,pivot");
        if text.is_empty() {
            text.push_str(header);
            text.push('\n');
        }
        for l in lines {
            text.push_str(l);
            text.push('\n');
        }
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn furuta_fit_score_predict_export() {
    let dir = temp_dir("furuta");
    let (train, test, calib) = (
        dir.join("train.csv"),
        dir.join("test.csv"),
        dir.join("calib.csv"),
    );
    furuta_log(&dir, &train, 0..6, 150, true);
    furuta_log(&dir, &test, 20..26, 60, true);
    furuta_log(&dir, &calib, 40..46, 60, true);

    // the binary knows the 3-D examples and says which
    let e = vigp_fails(&argv("fit --system nope --data {} --out x", &[s(&train)]));
    assert!(
        e.contains("furuta") || e.contains("Furuta"),
        "the registry lists Furuta: {e}"
    );
    for name in [
        "SphericalPendulum",
        "DoublePendulum3d",
        "SpatialSliderCrank",
        "Tumbler",
    ] {
        assert!(e.contains(name), "{name} missing from {e}");
    }

    // a 3-D mechanism's maximal view is refused before the data are read
    let e = vigp_fails(&argv(
        "fit --system furuta --data does-not-exist.csv --out {} --encoding maximal",
        &[s(&dir.join("x.json"))],
    ));
    assert!(
        e.contains("Furuta is a 3-D mechanism: --encoding maximal is not available"),
        "{e}"
    );

    let model = dir.join("furuta.json");
    let fit = vigp(&argv(
        "fit --system furuta --data {} --out {} --restarts 1 --max-samples 300",
        &[s(&train), s(&model)],
    ));
    assert!(
        fit.contains("data: ") && fit.contains("6 runs, 912 samples, dt = 0.01 s"),
        "{fit}"
    );
    assert!(
        fit.contains(
            "fit: Furuta in coordinates [base, pivot], SinCos encoding (6 inputs), Nominal prior: \
             N = 300 of 900 transitions"
        ),
        "{fit}"
    );

    // score on held-out runs: the learned model well below the nominal one
    let report = vigp(&score_args(s(&model), s(&test), "20"));
    assert!(
        report.contains("6 runs (0 shorter than 22 samples), 246 windows"),
        "{report}"
    );
    let (nominal, learned) = mse_line(&report);
    // measured: nominal 5.8e-4, learned 1.0e-8 (the GP learns the friction
    // and the heavier pendulum); checked at 10×, far inside
    assert!(
        nominal > 1e-5,
        "the truth differs from the nominal model: {nominal:e}"
    );
    assert!(
        learned < 0.1 * nominal,
        "learned {learned:e} not 10× below nominal {nominal:e}"
    );

    // `--steps 1` scores x_(s+2), produced by one step: the nominal score
    // is the mean of |x̂_(s+2) − x_(s+2)|²/2 over the windows, computed here
    // with the library's integrator on the frictionless Furuta pendulum
    let (nominal_1, _) = mse_line(&vigp(&score_args(s(&model), s(&test), "1")));
    let m = Furuta::default().minimal();
    let file = std::fs::File::open(&test).unwrap();
    let data: Dataset<2> =
        Dataset::read_for::<FurutaMinimal, 0, _>(file, &ReadOptions::default()).unwrap();
    let vi = Variational::new(m, DT).unwrap();
    let (mut sum, mut n) = (0.0, 0);
    for run in &data.runs {
        for w in 0..run.positions.len() - 2 {
            let z1 = vi.step(&run.state(w).unwrap()).unwrap();
            sum += (z1.q + z1.v * DT - run.positions[w + 2]).norm_squared() / 2.0;
            n += 1;
        }
    }
    // the same sums in another order (score runs the windows in
    // parallel): agreement to 1e-9 relative
    assert_same_mean(nominal_1, sum / n as f64);

    // predict, conformal: calibrated on the held-out runs, from every 5th
    // sample of the test runs (starts exchangeable with the calibration
    // windows, which start at every sample of their runs)
    let pred = dir.join("pred.csv");
    let said = vigp(&argv(
        "predict --model {} --data {} --steps 20 --stride 5 --calibration {} --out {}",
        &[s(&model), s(&test), s(&calib), s(&pred)],
    ));
    // 13 starts per run of 62 rows (s = 0, 5, …, 60: a start needs two)
    assert!(
        said.contains("78 predictions (every 5 samples of 6 run(s)) × 20 steps (0 failed)"),
        "{said}"
    );
    assert!(
        said.contains("conformal bound") && said.contains("coverage ≥ 0.95"),
        "{said}"
    );
    let rows = table_with_header(
        &pred,
        "run,start,t,base,pivot,v_base,v_pivot,bound,position_bound,fallback",
    );
    assert_eq!(rows.len(), 1 + 78 * 21);
    let logged = table(&test);
    let (mut inside, mut total) = (0usize, 0usize);
    for (p, rows) in rows[1..].chunks(21).enumerate() {
        let (j, start) = (p / 13, 5 * (p % 13));
        for (k, row) in rows.iter().enumerate() {
            assert_eq!(row[0], format!("r{}", 20 + j));
            assert_eq!(row[1], start.to_string());
            let pb = cell(row, 8);
            assert!(pb.is_finite() && pb >= 0.0, "{row:?}");
            if k == 0 {
                // no bound of the start's own
                assert_eq!(row[7], "");
            } else {
                let b = cell(row, 7);
                assert!(b.is_finite() && b > 0.0, "{row:?}");
            }
            // the logged truth, where the log reaches
            let Some(truth) = logged
                .get(1 + 62 * j + start + k)
                .filter(|_| start + k < 62)
            else {
                continue;
            };
            // the time of the sample, as the log has it
            assert_eq!(row[2], truth[1], "{row:?}");
            let q = SVector::<f64, 2>::new(cell(row, 3), cell(row, 4));
            let x = SVector::<f64, 2>::new(cell(truth, 2), cell(truth, 3));
            if k == 0 {
                // the start is the logged sample
                assert_eq!(q, x);
            } else if k >= 2 {
                // (x_1 = x_0 + dt·v_0 is logged, not predicted)
                total += 1;
                inside += usize::from((q - x).norm() <= pb);
            }
        }
    }
    // per-step coverage ≥ 0.95, marginal over starts exchangeable with the
    // calibration windows' starts; the windows of one run are correlated,
    // so the pooled fraction over 6 runs is checked at 0.8 (measured: 1168
    // of 1206, 0.97)
    eprintln!("coverage: {inside} of {total}");
    assert!(inside * 10 >= total * 8, "{inside} of {total} inside");

    // export: the no_std source of the learned model, its size stated
    let rs = dir.join("furuta.rs");
    let out = vigp(&["export", "--model", s(&model), "--out", s(&rs)]);
    assert!(
        out.contains("2 GPs on N = 300 points, d = 6 inputs"),
        "{out}"
    );
    let src = std::fs::read_to_string(&rs).unwrap();
    assert!(
        src.contains("pub static LEARNED: vigp::embedded::learned::LearnedModel<'static, 2, 6>"),
        "{}",
        &src[..src.len().min(2000)]
    );
    // the export of a small Furuta model is exactly the fixture that
    // tests/learn/embedded_learned.rs compiles and steps against the std
    // model (1e-12)
    let small = write_file(
        &dir,
        "learned_furuta.json",
        include_str!("../../tests/fixtures/learned_furuta.json"),
    );
    let small_rs = dir.join("learned_furuta.rs");
    vigp(&["export", "--model", s(&small), "--out", s(&small_rs)]);
    assert_file_is(
        &small_rs,
        include_str!("../../tests/fixtures/learned_furuta.rs"),
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The nominal model reproduces a log of itself to rounding: `simulate`
/// and `score` agree on the 3-D minimal view's velocity convention.
#[test]
fn a_furuta_log_of_the_nominal_model_is_reproduced() {
    let dir = temp_dir("nominal");
    let log = dir.join("log.csv");
    furuta_log(&dir, &log, 0..2, 80, false);
    let model = dir.join("m.json");
    vigp(&argv(
        "fit --system furuta --data {} --out {} --restarts 0 --max-samples 60 --noise-floor 1e-6",
        &[s(&log), s(&model)],
    ));
    let (nominal, _) = mse_line(&vigp(&score_args(s(&model), s(&log), "5")));
    assert!(nominal < 1e-24, "{nominal:e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A 3-D mechanism declared here gets the same tool from
/// `vigp::cli::system::<M>()`, inputs included: `simulate` under a plan
/// (with the arm heavier: the truth), `fit` on the input column, `score`
/// under the logged inputs.
#[test]
fn a_driven_3d_mechanism_declared_here_gets_the_same_tool() {
    let dir = temp_dir("driven");
    let tool = [vigp::cli::system::<DrivenFuruta>()];
    let run = |args: &[&str]| run_tool(&tool, "driven", args);
    let mut train = String::new();
    let mut test = String::new();
    for i in 0..6 {
        // piecewise-constant torques, held for 10 rows each
        let plan = dir.join(format!("plan{i}.csv"));
        let mut text = String::from("u_base\n");
        for j in 0..120 {
            text.push_str(&format!("{:?}\n", 0.05 * (0.9 * (j / 10 + i) as f64).sin()));
        }
        std::fs::write(&plan, text).unwrap();
        let (q, v) = start(i);
        let (q, v) = (format!("{},{}", q[0], q[1]), format!("{},{}", v[0], v[1]));
        let one = dir.join(format!("log{i}.csv"));
        let run_name = format!("d{i}");
        let line = "simulate --q {} --v {} --dt 0.01 --steps 120 --inputs {} --run {} --out {} \
                    --set links.pendulum.mass=0.11 --set joints.pivot.damping=0.002";
        run(&argv(line, &[&q, &v, s(&plan), &run_name, s(&one)])).unwrap();
        let log = std::fs::read_to_string(&one).unwrap();
        let dest = if i < 4 { &mut train } else { &mut test };
        for (k, line) in log.lines().enumerate() {
            if k == 0 {
                assert_eq!(line, "run,t,base,pivot,u_base");
                if !dest.is_empty() {
                    continue;
                }
            }
            dest.push_str(line);
            dest.push('\n');
        }
    }
    let train_path = write_file(&dir, "train.csv", train);
    let test_path = write_file(&dir, "test.csv", test);
    let model = dir.join("driven.json");
    let fit = run(&argv(
        "fit --data {} --out {} --restarts 1 --max-samples 300",
        &[s(&train_path), s(&model)],
    ))
    .unwrap();
    assert!(
        fit.contains("with inputs [base], SinCos encoding (8 inputs)"),
        "{fit}"
    );
    assert!(!fit.contains("warning"), "{fit}");
    let (nominal, learned) = mse_line(&run(&score_args(s(&model), s(&test_path), "20")).unwrap());
    // measured: nominal 2.4e-4, learned 1.3e-7; checked at 10×
    assert!(nominal > 1e-6, "{nominal:e}");
    assert!(
        learned < 0.1 * nominal,
        "learned {learned:e} not 10× below nominal {nominal:e}"
    );
    // identify on the same log (written by the first-order integrator):
    // the pivot's friction to 1e-8 relative (the regression is exact on
    // such logs to about 1e-11), and the identified parameters as the
    // nominal model make the nominal score that of the truth itself
    let params = dir.join("params.json");
    let said = run(&[
        "identify",
        "--data",
        s(&train_path),
        "--rule",
        "first-order",
        "--out",
        s(&params),
    ])
    .unwrap();
    let file = read_json(&params);
    let row = |name: &str| parameter_row(&file, name);
    let pivot = row("joints.pivot.damping");
    assert_eq!(pivot["status"], "identified", "{said}");
    let got = pivot["identified"].as_f64().unwrap();
    assert!((got - 0.002).abs() <= 1e-8 * 0.002, "{got}");
    // the frictionless base joint: its damping is 0 in truth, and fit
    // refuses a negative one, so identify must not return one
    let base = row("joints.base.damping")["identified"].as_f64().unwrap();
    assert!((0.0..=1e-8).contains(&base), "{base:e}");
    // a 3-D inertia's lower entries carry their upper mirror's value and
    // status, and name it
    for (lower, upper) in [("yx", "xy"), ("zx", "xz"), ("zy", "yz")] {
        for link in ["arm", "pendulum"] {
            let (l, u) = (
                row(&format!("links.{link}.inertia.{lower}")),
                row(&format!("links.{link}.inertia.{upper}")),
            );
            assert_eq!(l["identified"], u["identified"], "{l} {u}");
            assert_eq!(l["status"], u["status"], "{l} {u}");
            assert_eq!(l["mirror_of"], u["name"], "{l} {u}");
        }
    }
    let identified_model = dir.join("identified.json");
    let prior = format!("identified:{}", s(&params));
    run(&argv(
        "fit --data {} --out {} --prior {} --restarts 0 --max-samples 100",
        &[s(&train_path), s(&identified_model), &prior],
    ))
    .unwrap();
    let score = score_args(s(&identified_model), s(&test_path), "20");
    let (identified_nominal, _) = mse_line(&run(&score).unwrap());
    println!("20-step nominal MSE: declared {nominal:.3e}, identified {identified_nominal:.3e}");
    assert!(
        identified_nominal < 1e-6 * nominal,
        "{identified_nominal:e} vs {nominal:e}"
    );
    // the maximal view is a typed error
    let e = run(&argv(
        "fit --data {} --out {} --encoding maximal",
        &[s(&train_path), s(&model)],
    ))
    .unwrap_err();
    assert!(
        matches!(
            e,
            vigp::cli::CliError::SpatialMaximal {
                mechanism: "DrivenFuruta",
                ..
            }
        ),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Mechanisms with quaternion coordinates, through the binary: a ball
/// joint's unit quaternion is four columns `<joint>.w`, `.x`, `.y`, `.z`
/// (a free joint's position and quaternion seven), its velocity the
/// difference of the logged components over Δt as for every coordinate
/// (the data module's convention, which the minimal view's integrator
/// follows: the nominal model reproduces its own log to rounding). A link
/// declared without a length (the tumbler's body) saves and loads.
/// `simulate` with a perturbed parameter on two runs (the second from the
/// first's start with its velocity 5 % larger, so that it stays in the
/// region the GP saw), `fit` on one, `score` on the other: the learned
/// model beats the nominal one.
#[test]
fn quaternion_mechanisms_fit_and_score() {
    let dir = temp_dir("quaternion");
    // (system, log header, starts q and v of the two runs, the truth's
    // parameter)
    type Case = (
        &'static str,
        &'static str,
        [&'static str; 2],
        [&'static str; 2],
        &'static str,
    );
    let cases: [Case; 2] = [
        (
            "spherical_pendulum",
            "run,t,ball.w,ball.x,ball.y,ball.z",
            ["0.8,0.6,0.0,0.0", "0.8,0.6,0.0,0.0"],
            ["0.0,0.0,0.5,0.8", "0.0,0.0,0.525,0.84"],
            "joints.ball.damping=0.05",
        ),
        (
            "tumbler",
            "run,t,float.x,float.y,float.z,float.qw,float.qx,float.qy,float.qz",
            ["0,0,0,1,0,0,0", "0,0,0,1,0,0,0"],
            ["0.1,0,0,0,0.05,0.5,0.01", "0.1,0,0,0,0.0525,0.525,0.0105"],
            "links.body.inertia.yy=2.3",
        ),
    ];
    for (system, header, qs, vs, truth) in cases {
        let logs = [
            dir.join(format!("{system}_a.csv")),
            dir.join(format!("{system}_b.csv")),
        ];
        for (j, log) in logs.iter().enumerate() {
            let line = "simulate --system {} --q {} --v {} --dt 0.01 --steps 150 --out {} --set {}";
            vigp(&argv(line, &[system, qs[j], vs[j], s(log), truth]));
            assert_eq!(table(log)[0].join(","), header);
        }
        // the nominal model reproduces a log of itself
        let own = dir.join(format!("{system}_own.csv"));
        let line = "simulate --system {} --q {} --v {} --dt 0.01 --steps 30 --out {}";
        vigp(&argv(line, &[system, qs[0], vs[0], s(&own)]));
        let model = dir.join(format!("{system}.json"));
        vigp(&argv(
            "fit --system {} --data {} --out {} --restarts 0 --max-samples 150 --noise-floor 1e-6",
            &[system, s(&logs[0]), s(&model)],
        ));
        let (own_nominal, _) = mse_line(&vigp(&score_args(s(&model), s(&own), "5")));
        assert!(own_nominal < 1e-24, "{system}: {own_nominal:e}");
        let (nominal, learned) = mse_line(&vigp(&score_args(s(&model), s(&logs[1]), "10")));
        // measured: spherical pendulum nominal 1.7e-7, learned 2.8e-10;
        // tumbler nominal 5.0e-11, learned 1.1e-11
        eprintln!("{system}: nominal {nominal:e} learned {learned:e}");
        assert!(nominal > 1e-12, "{system}: {nominal:e}");
        assert!(
            learned < nominal,
            "{system}: learned {learned:e} ≥ nominal {nominal:e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
