//! A learned robot ([`LearnedRobot`]): the logs of a robot read at run
//! time ([`DynDataset`], the same reader as for a declared mechanism), its
//! transitions, training on top of the tree engine's step, the step's
//! composition checked against the robot's step and the GP's own
//! prediction, a model file that round-trips bit for bit, typed errors
//! for wrong input, a transition repeated exactly trained on once, and the
//! conformal bound's coverage on held-out windows.

use vigp_runtime::data::{Dataset, DynDataset, ReadOptions};
use vigp_runtime::gp::TrainOptions;
use vigp_runtime::learned::robot::{
    LearnedRobot, LearnedRobotError, RobotTransition, coordinate_kinds, identified_robot,
};
use vigp_runtime::learned::{Encoding, IdentifiedParameters, Prior};
use vigp_runtime::nalgebra::DMatrix;
use vigp_runtime::{CoordinateKind, Robot, RobotState};

#[path = "../../tests/common/rng.rs"]
mod rng;

const DT: f64 = 0.002;

/// The kinds of the arm's coordinates j1, j2, j3.
const KINDS: [CoordinateKind; 3] = [
    CoordinateKind::Angle,
    CoordinateKind::Angle,
    CoordinateKind::Length,
];

/// The test arm with `damping` in place of its declared 0.1, driven on j2.
fn arm(damping: f64) -> Robot {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/robots/arm3.urdf"
    ))
    .unwrap()
    .replace(r#"damping="0.1""#, &format!(r#"damping="{damping}""#));
    Robot::from_urdf_str(&text)
        .unwrap()
        .with_actuated(&["j2"])
        .unwrap()
}

/// A log of `robot` from `q0` under a sine on j2, as CSV text in the data
/// format (row k + 1 holds step k's input).
fn log(robot: &Robot, q0: [f64; 3], steps: usize) -> String {
    let us: Vec<Vec<f64>> = (0..steps)
        .map(|k| vec![3.0 + 1.5 * (7.0 * k as f64 * DT).sin()])
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
    let data = DynDataset::from_rollout(
        &["j1", "j2", "j3"],
        &["j2"],
        "a",
        (0.0, DT),
        &states,
        (&[0.0], &inputs),
    )
    .unwrap();
    let mut text = Vec::new();
    data.write_csv(&mut text).unwrap();
    String::from_utf8(text).unwrap()
}

/// Two runs of `truth` (`a` and `b`, `steps` steps each) as one CSV text.
fn two_runs(truth: &Robot, steps: usize) -> String {
    let mut text = log(truth, [0.1, -0.2, 0.05], steps);
    let more = log(truth, [-0.2, 0.3, 0.0], steps).replace("\na,", "\nb,");
    text.push_str(more.split_once('\n').unwrap().1);
    text
}

/// The data of two runs of `truth` (`steps` steps each) and their
/// transitions.
fn two_run_data(truth: &Robot, steps: usize) -> (DynDataset, Vec<RobotTransition>) {
    let data = read(&two_runs(truth, steps));
    let ts = RobotTransition::from_dataset(&data);
    (data, ts)
}

/// The data of a CSV text, read with the arm's coordinates and input.
fn read(text: &str) -> DynDataset {
    DynDataset::read_csv_with_inputs(
        text.as_bytes(),
        &["j1", "j2", "j3"],
        &KINDS,
        &["j2"],
        &ReadOptions::default(),
    )
    .unwrap()
}

/// The training options with one restart.
fn one_restart() -> TrainOptions {
    TrainOptions {
        restarts: 1,
        ..TrainOptions::default()
    }
}

/// `declared` with a GP trained on `ts` (sin/cos encoding, the robot's
/// step as prior).
fn train(declared: Robot, ts: &[RobotTransition], options: &TrainOptions) -> LearnedRobot {
    LearnedRobot::train(declared, DT, ts, Encoding::SinCos, Prior::Nominal, options)
        .unwrap()
        .0
}

#[test]
fn the_run_time_reader_reads_what_the_fixed_size_reader_reads() {
    let text = log(&arm(0.3), [0.1, -0.2, 0.05], 60);
    let dynamic = read(&text);
    let kinds = KINDS;
    let fixed = Dataset::<3>::read_csv_with_inputs(
        text.as_bytes(),
        &["j1", "j2", "j3"],
        &kinds,
        &["j2"],
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(dynamic.runs.len(), 1);
    let (d, f) = (&dynamic.runs[0], &fixed.runs[0]);
    assert_eq!((d.dt, d.t0, &d.inputs), (f.dt, f.t0, &f.inputs));
    for (a, b) in d.positions.iter().zip(&f.positions) {
        assert_eq!(a.as_slice(), b.as_slice());
    }
    // kinds of another count than the names: a typed error
    let e = DynDataset::read_csv_with_inputs(
        text.as_bytes(),
        &["j1", "j2", "j3"],
        &kinds[..2],
        &["j2"],
        &ReadOptions::default(),
    );
    assert!(e.is_err());
    // transitions: the state, the inputs around it, the next velocity
    let ts = RobotTransition::from_dataset(&dynamic);
    assert_eq!(ts.len(), 60);
    let x = &d.positions;
    let t = &ts[7];
    let diff = |k: usize| -> Vec<f64> { (&x[k + 1] - &x[k]).iter().map(|d| d / DT).collect() };
    assert_eq!(t.z.q, x[7].as_slice());
    assert_eq!(t.z.v, diff(7));
    assert_eq!(t.v_next, diff(8));
    assert_eq!((&t.u_prev, &t.u), (&d.inputs[7], &d.inputs[8]));
}

/// A learned step's exact A, B and B_prev against five-point central
/// differences of the learned step itself, under the robot's step as prior
/// (sin/cos encoding: the chain rule through the angles) and under a
/// constant mean (raw encoding), with the state of `step` to the bit.
///
/// Tolerance: 1e-6 of the largest entry (and of 1). The step h = 1e-3 of
/// a five-point stencil truncates at O(h⁴·f⁽⁵⁾) ≈ 1e-12 here. The GP mean
/// k(x)ᵀα sums terms far larger than itself when the trained noise sits
/// near its default floor (1e-10): under the constant prior, where the GP
/// carries the whole velocity, that rounding noise reached ~1e-8 in v₁,
/// erratic in h (differences off by 1e-6 to 4e-5 for h = 3e-3 … 1e-4),
/// so the noise variance is kept ≥ 1e-6 (normalised units), as
/// `Learned::step_derivatives_forced` advises; the derivatives are exact
/// for any hyperparameters. A wrong block (a sign of the sin/cos chain
/// rule, u and u_prev swapped, a missing prior term) is off by the size
/// of the entry itself. The rollout derivatives, chained from the
/// per-step A, B and B_prev, are checked the same way against differences
/// of a whole 4-step rollout.
#[test]
fn learned_step_derivatives_match_differences_of_the_step() {
    let truth = arm(0.3);
    let declared = arm(0.1);
    let text = two_runs(&truth, 120);
    let ts = RobotTransition::from_dataset(&read(&text));
    let options = TrainOptions {
        restarts: 1,
        bounds: vigp_runtime::gp::Bounds {
            noise_variance: (1e-6, 10.0),
            ..vigp_runtime::gp::Bounds::default()
        },
        ..TrainOptions::default()
    };
    let z = RobotState::new(vec![0.05, -0.1, 0.02], vec![0.3, -0.2, 0.1]);
    let (u_prev, u) = (vec![3.2], vec![3.4]);
    for (encoding, prior) in [
        (Encoding::SinCos, Prior::Nominal),
        (Encoding::Raw, Prior::Constant),
    ] {
        let (learned, _) =
            LearnedRobot::train(declared.clone(), DT, &ts, encoding, prior.clone(), &options)
                .unwrap();
        let mut ws = learned.workspace();
        let d = learned.step_derivatives(&z, &u_prev, &u, &mut ws).unwrap();
        assert_eq!(d.state, learned.step(&z, &u_prev, &u).unwrap());
        let n = 3;
        // z₁ as one vector, from a perturbed state and inputs
        let next = |z: &RobotState, up: &[f64], u: &[f64]| -> Vec<f64> {
            let z1 = learned.step(z, up, u).unwrap();
            z1.q.into_iter().chain(z1.v).collect()
        };
        let h = 1e-3;
        let stencil = |f: &dyn Fn(f64) -> Vec<f64>| -> Vec<f64> {
            let (a, b, c, e) = (f(-2.0 * h), f(-h), f(h), f(2.0 * h));
            (0..2 * n)
                .map(|r| (a[r] - 8.0 * b[r] + 8.0 * c[r] - e[r]) / (12.0 * h))
                .collect()
        };
        let mut worst: f64 = 0.0;
        let mut compare =
            |name: &str, exact: &vigp_runtime::nalgebra::DMatrix<f64>, col: usize, fd: Vec<f64>| {
                let scale = exact.iter().fold(1.0f64, |m, x| m.max(x.abs()));
                for (r, x) in fd.iter().enumerate() {
                    let err = (exact[(r, col)] - x).abs() / scale;
                    worst = worst.max(err);
                    assert!(
                        err <= 1e-6,
                        "{prior:?}: {name}[{r}][{col}] exact {} vs differences {x}",
                        exact[(r, col)]
                    );
                }
            };
        // z with its state entry c (q then v) moved by e
        let nudged = |c: usize, e: f64| {
            let mut zz = z.clone();
            if c < n {
                zz.q[c] += e;
            } else {
                zz.v[c - n] += e;
            }
            zz
        };
        for c in 0..2 * n {
            let fd = stencil(&|e| next(&nudged(c, e), &u_prev, &u));
            compare("A", &d.a, c, fd);
        }
        compare("B", &d.b, 0, stencil(&|e| next(&z, &u_prev, &[u[0] + e])));
        compare(
            "B_prev",
            &d.b_prev,
            0,
            stencil(&|e| next(&z, &[u_prev[0] + e], &u)),
        );
        // a K-step rollout: the per-step A, B and B_prev chained against
        // differences of the whole rollout
        let plan = vec![vec![3.0], vec![3.6], vec![2.9], vec![3.3]];
        let k_steps = plan.len();
        let steps = learned
            .rollout_derivatives(&z, &u_prev, &plan, &mut ws)
            .unwrap();
        let traj = learned.rollout(&z, &u_prev, &plan).unwrap();
        assert!(steps.iter().zip(&traj).all(|(d, s)| d.state == *s));
        let last = |z: &RobotState, plan: &[Vec<f64>]| -> Vec<f64> {
            let z1 = learned.rollout(z, &u_prev, plan).unwrap().pop().unwrap();
            z1.q.into_iter().chain(z1.v).collect()
        };
        let mut initial = DMatrix::<f64>::identity(2 * n, 2 * n);
        let mut wrt_u = vec![DMatrix::<f64>::zeros(2 * n, 1); k_steps];
        for (k, d) in steps.iter().enumerate() {
            initial = &d.a * &initial;
            for (j, b) in wrt_u.iter_mut().enumerate().take(k + 1) {
                *b = &d.a * &*b;
                if j == k {
                    *b += &d.b;
                } else if j + 1 == k {
                    *b += &d.b_prev;
                }
            }
        }
        for c in 0..2 * n {
            let fd = stencil(&|e| last(&nudged(c, e), &plan));
            compare("rollout ∂z_K/∂z_0", &initial, c, fd);
        }
        for (j, b) in wrt_u.iter().enumerate() {
            let fd = stencil(&|e| {
                let mut p = plan.clone();
                p[j][0] += e;
                last(&z, &p)
            });
            compare(&format!("rollout ∂z_K/∂u_{j}"), b, 0, fd);
        }
        println!("{prior:?}, {encoding:?}: largest scaled difference {worst:.1e}");
        // the GP reads u_prev: B_prev is not zero
        assert!(d.b_prev.iter().any(|x| *x != 0.0));
    }
}

#[test]
fn a_learned_robot_steps_saves_and_refuses_bad_input() {
    // the truth damps the elbow 3× more than the declared robot
    let truth = arm(0.3);
    let declared = arm(0.1);
    let (_, ts) = two_run_data(&truth, 150);
    assert_eq!(ts.len(), 300);
    let options = one_restart();
    let learned = train(declared.clone(), &ts, &options);
    assert_eq!(coordinate_kinds(learned.robot())[2], CoordinateKind::Length);

    // one step: q + Δt·v, and the declared robot's velocity plus the GP's
    // mean at (sin/cos of the angles, the slide, v, u_prev, u)
    let z = RobotState::new(vec![0.05, -0.1, 0.02], vec![0.3, -0.2, 0.1]);
    let (u_prev, u) = ([3.2], [3.4]);
    let next = learned.step(&z, &u_prev, &u).unwrap();
    let prior = declared.step(&z, &u, DT).unwrap().0;
    let point = [
        z.q[0].sin(),
        z.q[0].cos(),
        z.q[1].sin(),
        z.q[1].cos(),
        z.q[2],
        z.v[0],
        z.v[1],
        z.v[2],
        u_prev[0],
        u[0],
    ];
    let mean = learned.gp().predict(&point).unwrap().mean;
    for (i, (v, m)) in next.v.iter().zip(&mean).enumerate() {
        assert_eq!(next.q[i], z.q[i] + DT * z.v[i]);
        // the GP's batch and single-point predictions sum in other orders
        assert!((v - (prior.v[i] + m)).abs() <= 1e-12 * (1.0 + v.abs()));
    }
    // the learned step is closer to the truth's than the declared one
    let true_next = truth.step(&z, &u, DT).unwrap().0;
    let gap = |a: &RobotState| {
        a.v.iter()
            .zip(&true_next.v)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f64, f64::max)
    };
    assert!(
        gap(&next) < 0.5 * gap(&prior),
        "{} {}",
        gap(&next),
        gap(&prior)
    );

    // the model file round-trips: the same predictions, bit for bit
    let dir = std::env::temp_dir().join(format!("vigp-learned-robot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("model.json");
    learned.save(&path).unwrap();
    let loaded = LearnedRobot::load(&path).unwrap();
    let inputs = vec![vec![3.0]; 25];
    let a = learned.rollout(&z, &u_prev, &inputs).unwrap();
    let b = loaded.rollout(&z, &u_prev, &inputs).unwrap();
    assert_eq!(a, b);
    assert_eq!(loaded.to_saved(), learned.to_saved());

    // wrong input: typed errors
    let bad = RobotState::new(vec![0.0, f64::NAN, 0.0], vec![0.0; 3]);
    assert!(matches!(
        learned.step(&bad, &u_prev, &u),
        Err(LearnedRobotError::NonFinite(_))
    ));
    assert!(matches!(
        learned.step(&z, &u_prev, &[1.0, 2.0]),
        Err(LearnedRobotError::Length { .. })
    ));
    assert!(matches!(
        learned.rollout(&bad, &u_prev, &inputs),
        Err(LearnedRobotError::Rollout { step: 0, .. })
    ));
    // the declared robot trained raw with Δt = `dt` on `ts`
    let train_raw = |dt, ts: &[RobotTransition]| {
        LearnedRobot::train(
            declared.clone(),
            dt,
            ts,
            Encoding::Raw,
            Prior::Nominal,
            &options,
        )
    };
    assert!(matches!(
        train_raw(0.0, &ts),
        Err(LearnedRobotError::TimeStep(_))
    ));
    assert!(matches!(train_raw(DT, &[]), Err(LearnedRobotError::Empty)));
    let mut short = ts[..3].to_vec();
    short[1].v_next.pop();
    let e = train_raw(DT, &short).unwrap_err();
    assert!(e.to_string().contains("training transition 1"), "{e}");
    // a file whose GP does not fit the robot
    let mut saved = learned.to_saved();
    saved.encoding = Encoding::Raw;
    assert!(matches!(
        LearnedRobot::from_saved(&saved),
        Err(LearnedRobotError::File(_))
    ));
    // identified parameters of another robot
    let other = IdentifiedParameters::new(
        "panda",
        &["links.link1.mass".to_string()],
        &[1.0],
        &vigp_runtime::nalgebra::DMatrix::zeros(1, 1),
    )
    .unwrap();
    assert!(matches!(
        identified_robot(&declared, DT, &other),
        Err(LearnedRobotError::Identified(_))
    ));
}

/// A transition repeated exactly is one measurement, as for a declared
/// mechanism (`vigp_runtime::learned::distinct_rows`): training on a log's
/// transitions with the first 15 of them given twice (each repeat right
/// after its original) gives the model trained on the log's transitions,
/// bit for bit (its GP on the distinct rows, in their order). Kept twice,
/// the repeats would be 15 more rows of the GP (`gp().n()` 55, not 40), a
/// different GP.
#[test]
fn a_repeated_transition_trains_once() {
    let data = read(&log(&arm(0.3), [0.1, -0.2, 0.05], 40));
    let ts = RobotTransition::from_dataset(&data);
    assert_eq!(ts.len(), 40);
    let repeated: Vec<RobotTransition> = ts
        .iter()
        .enumerate()
        .flat_map(|(i, t)| std::iter::repeat_n(t.clone(), if i < 15 { 2 } else { 1 }))
        .collect();
    assert_eq!(repeated.len(), 55);
    let options = one_restart();
    let (once, twice) = (
        train(arm(0.1), &ts, &options),
        train(arm(0.1), &repeated, &options),
    );
    assert_eq!(twice.gp().n(), 40);
    assert_eq!(twice.to_saved(), once.to_saved());
}

/// A run of `truth` from rest at a random start under a random sine on j2
/// (`steps` steps): the positions of its states and the input logged with
/// each (row 0: the input before the run, zero; row k + 1: step k's).
fn random_run(truth: &Robot, rng: &mut rng::Rng, steps: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let q0 = vec![
        rng.uniform(-0.5, 0.5),
        rng.uniform(-0.5, 0.5),
        rng.uniform(-0.05, 0.15),
    ];
    let (a, w, phase) = (
        rng.uniform(1.0, 5.0),
        rng.uniform(3.0, 9.0),
        rng.uniform(0.0, 6.3),
    );
    let us: Vec<Vec<f64>> = (0..steps)
        .map(|k| vec![3.0 + a * (w * k as f64 * DT + phase).sin()])
        .collect();
    let roll = truth
        .rollout_with(&RobotState::new(q0, vec![0.0; 3]), DT, steps, |k, _| {
            us[k].clone()
        })
        .unwrap();
    let positions = roll.states.iter().map(|z| z.q.clone()).collect();
    let mut inputs = vec![vec![0.0]];
    inputs.extend(us);
    (positions, inputs)
}

/// The conformal bound of a learned robot (`LearnedRobot::error_bound`,
/// `predict`): trained on two runs of a "real" arm (3× the declared elbow
/// damping) over the declared one, calibrated on 300 held-out windows of
/// 10 steps (one per run, random starts and inputs), then tried on 300
/// more drawn alike. Split conformal promises coverage ≥ 1 − δ = 0.9,
/// and ≤ 1 − δ + 1/(n + 1) = 0.903 without ties, marginally over the
/// calibration draw and the test case. The quantiles are calibrated on
/// 240 of the windows (`Score::Auto` chooses its normalisation on the
/// other 60), so the coverage given the calibration draw varies by
/// √(0.09/242) = 0.019, and that of 300 test windows by √(0.09/300) =
/// 0.017: together 0.026. The test asks 0.82–0.98 (three of those
/// standard deviations) for the one-step velocity bound and the 10-step
/// position bound. With seeds 5 to 16 (this test's is 5), the coverage
/// ranged over 0.820–0.950 (one step, mean 0.893) and 0.827–0.923 (10
/// steps, mean 0.895). Windows that start at training states are
/// refused.
#[test]
fn the_conformal_bound_of_a_learned_robot_covers_held_out_windows() {
    use vigp_runtime::bound::ConformalSettings;
    use vigp_runtime::learned::robot::RobotCalibration;
    let truth = arm(0.3);
    let declared = arm(0.1);
    let (data, ts) = two_run_data(&truth, 150);
    let learned = train(declared, &ts, &one_restart());
    let k = 10;
    let mut rng = rng::Rng(5);
    let runs = |rng: &mut rng::Rng| -> (Vec<_>, Vec<_>) {
        (0..300).map(|_| random_run(&truth, rng, k + 1)).unzip()
    };
    let (cal_q, cal_u) = runs(&mut rng);
    let calibration = RobotCalibration::from_logs(&cal_q, &cal_u, DT, k, k).unwrap();
    assert_eq!(calibration.len(), 300);
    let settings = ConformalSettings {
        delta: 0.1,
        ..ConformalSettings::default()
    };
    let bound = learned.error_bound(&settings, &calibration).unwrap();
    let (test_q, test_u) = runs(&mut rng);
    let test = RobotCalibration::from_logs(&test_q, &test_u, DT, k, k).unwrap();
    let (mut one, mut last, mut widths, mut errors) = (0, 0, Vec::new(), Vec::new());
    for (i, w) in test.windows().iter().enumerate() {
        let (prev, us) = test.window_inputs_of(i).unwrap();
        let p = learned.predict(&w.start, &prev, &us, &bound).unwrap();
        assert_eq!(p.position_bounds.len(), k + 1);
        let v1: Vec<f64> = w.positions[1]
            .iter()
            .zip(&w.positions[0])
            .map(|(b, a)| (b - a) / DT)
            .collect();
        let dist = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        one += usize::from(dist(&p.states[1].v, &v1) <= p.one_step_bounds[0]);
        let e = dist(&p.states[k].q, &w.positions[k - 1]);
        last += usize::from(e <= p.position_bounds[k]);
        widths.push(p.position_bounds[k]);
        errors.push(e);
    }
    widths.sort_by(f64::total_cmp);
    errors.sort_by(f64::total_cmp);
    let (one, last) = (one as f64 / 300.0, last as f64 / 300.0);
    eprintln!(
        "learned arm, δ = 0.1, 300 calibration and 300 test windows of {k} steps: coverage one \
         step {one:.3}, {k} steps {last:.3}; median {k}-step bound {:.2e} against the median \
         error {:.2e}",
        widths[150], errors[150]
    );
    assert!((0.82..=0.98).contains(&one), "{one}");
    assert!((0.82..=0.98).contains(&last), "{last}");
    // windows cut from the training runs are refused
    let (train_q, train_u): (Vec<Vec<Vec<f64>>>, Vec<_>) = data
        .runs
        .iter()
        .map(|r| {
            let q = r.positions.iter().map(|x| x.as_slice().to_vec()).collect();
            (q, r.inputs.clone())
        })
        .unzip();
    let overlapping = RobotCalibration::from_logs(&train_q, &train_u, DT, k, k).unwrap();
    assert!(matches!(
        learned.error_bound(&settings, &overlapping),
        Err(vigp_runtime::bound::BoundError::CalibrationOverlapsTraining { .. })
    ));
    // more steps than calibrated
    let (prev, mut us) = test.window_inputs_of(0).unwrap();
    us.push(us[0].clone());
    assert!(matches!(
        learned.predict(&test.windows()[0].start, &prev, &us, &bound),
        Err(vigp_runtime::bound::BoundError::HorizonTooLong { .. })
    ));
}
