//! Output error for robots loaded at run time: the robot regressor's
//! exact position Jacobians (the engine's closed-form term derivatives)
//! against central differences of its residual, and the output-error
//! stage on a noisy log of a perturbed arm against the regression alone.

use vigp_runtime::identify::{
    Identification, Log, Noise, Options, OutputError, Regressor, RobotRegressor, identify,
};
use vigp_runtime::{Robot, RobotState};

mod common;
#[path = "../../tests/common/rng.rs"]
mod rng;
use rng::Rng;

const DT: f64 = 0.002;

/// The text of the URDF fixture `name`.
fn fixture(name: &str) -> String {
    std::fs::read_to_string(format!(
        "{}/../tests/fixtures/robots/{name}.urdf",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

/// The robot of the URDF text `urdf`, the joints `actuated` driven.
fn driven(urdf: &str, actuated: &[&str]) -> Robot {
    Robot::from_urdf_str(urdf)
        .unwrap()
        .with_actuated(actuated)
        .unwrap()
}

/// `log` with Gaussian noise of σ = 1e-5 (draws from `rng`) on every
/// position.
fn with_noise(log: &Log, rng: &mut Rng) -> Log {
    Log {
        positions: log
            .positions
            .iter()
            .map(|x| x.iter().map(|v| v + 1e-5 * rng.normal()).collect())
            .collect(),
        inputs: log.inputs.clone(),
    }
}

/// The identification options with instrumental variables.
fn iv() -> Options {
    Options {
        noise: Noise::IV,
        ..Options::default()
    }
}

/// A driven rollout's positions (q of every state, then q + Δt·v of the
/// last) and the inputs on the log's rows (row k + 1 holds step k's).
fn rollout(robot: &Robot, q0: &[f64], steps: usize, phase: f64) -> Log {
    let m = robot.input_names().len();
    let us: Vec<Vec<f64>> = (0..steps)
        .map(|k| {
            let t = k as f64 * DT;
            (0..m)
                .map(|j| 2.0 * ((1.3 + 0.7 * j as f64) * t + phase + j as f64).sin())
                .collect()
        })
        .collect();
    let z0 = RobotState::new(q0.to_vec(), vec![0.0; q0.len()]);
    let roll = robot
        .rollout_with(&z0, DT, steps, |k, _| us[k].clone())
        .unwrap();
    let mut positions: Vec<Vec<f64>> = roll.states.iter().map(|z| z.q.clone()).collect();
    let last = roll.states.last().unwrap();
    positions.push(
        last.q
            .iter()
            .zip(&last.v)
            .map(|(q, v)| q + DT * v)
            .collect(),
    );
    let mut inputs = vec![vec![0.0; m]];
    inputs.extend(us.iter().cloned());
    inputs.push(us[steps - 1].clone());
    Log { positions, inputs }
}

/// The largest relative error of the base parameters, each against the
/// size of its combination's terms, a term's size being the larger of
/// |π*_j| and the prior's scale of π_j (combinations whose true value is
/// zero: a damping the arm lacks, a centre of mass on an axis).
fn base_error(id: &Identification, pi_true: &[f64]) -> f64 {
    let k = &id.base.k;
    (0..k.nrows())
        .map(|i| {
            let err: f64 = (0..k.ncols())
                .map(|j| k[(i, j)] * (id.estimate[j] - pi_true[j]))
                .sum();
            let size: f64 = (0..k.ncols())
                .map(|j| k[(i, j)].abs() * pi_true[j].abs().max(id.prior_sd[j]))
                .sum();
            err.abs() / size
        })
        .fold(0.0, f64::max)
}

#[test]
fn position_jacobians_match_central_differences() {
    let text = fixture("panda").replace(r#"damping="0.003""#, r#"damping="0.2""#);
    let robot = driven(&text, &["panda_joint2", "panda_joint4"]);
    let q0 = [0.1, -0.6, 0.2, -2.0, 0.3, 1.4, 0.7];
    let log = rollout(&robot, &q0, 40, 0.3);
    for (rule, regressor) in [
        ("first order", RobotRegressor::new(&robot, DT).unwrap()),
        ("midpoint", RobotRegressor::midpoint(&robot, DT).unwrap()),
    ] {
        let pi = regressor.standard();
        for k in [5, 30] {
            let t = common::transition_at(&log, k);
            let (r, [j0, j1, j2]) = regressor.position_jacobians(&t, &pi).unwrap();
            assert_eq!(r, regressor.residual(&t, &pi).unwrap());
            // central differences, truncation ≈ 1e-12 and rounding ≈ 1e-10
            // of the largest entry: 1e-7 leaves a margin of 10³
            let fd = regressor.noise_jacobian(&t, &pi).unwrap();
            let n = q0.len();
            let big = fd.amax();
            let mut worst = 0.0f64;
            for (s, j) in [j0, j1, j2].iter().enumerate() {
                let gap = (j - fd.columns(s * n, n)).amax() / big;
                worst = worst.max(gap);
            }
            eprintln!(
                "{rule}, transition {k}: exact against central differences {worst:.1e} of the \
             largest entry"
            );
            assert!(worst < 1e-7, "{worst}");
            // the regressor's rows: Y·π − b is the residual at any π (r is
            // affine in π), here at a perturbed π
            let (y, b) = regressor.transition(&t).unwrap();
            let moved: Vec<f64> = pi
                .iter()
                .enumerate()
                .map(|(i, x)| x * (1.0 + 0.05 * ((i % 7) as f64 - 3.0) / 3.0))
                .collect();
            let r_moved = regressor.residual(&t, &moved).unwrap();
            let affine = &y * vigp_runtime::nalgebra::DVector::from_column_slice(&moved) - &b;
            let gap = (&affine - &r_moved).amax() / r_moved.amax().max(b.amax());
            assert!(gap < 1e-10, "{rule}: Y·π − b against r(π): {gap:.1e}");
        }
    }
}

#[test]
fn output_error_beats_the_regression_on_a_noisy_robot_log() {
    // the truth: heavier distal links, and damping on every joint (two of
    // which the declaration lacks), all inside the feasible set
    let truth_text = fixture("arm3")
        .replace(r#"<mass value="1.2"/>"#, r#"<mass value="1.38"/>"#)
        .replace(r#"<mass value="0.5"/>"#, r#"<mass value="0.6"/>"#)
        .replace(r#"damping="0.1""#, r#"damping="0.25""#)
        .replace(
            r#"<limit lower="-0.1" upper="0.2" effort="100" velocity="0.5"/>"#,
            r#"<limit lower="-0.1" upper="0.2" effort="100" velocity="0.5"/>
    <dynamics damping="0.4"/>"#,
        )
        .replace(
            r#"<limit lower="-2.9" upper="2.9" effort="50" velocity="2"/>"#,
            r#"<limit lower="-2.9" upper="2.9" effort="50" velocity="2"/>
    <dynamics damping="0.05"/>"#,
        );
    let actuated = ["j1", "j2", "j3"];
    let truth = driven(&truth_text, &actuated);
    let declared = driven(&fixture("arm3"), &actuated);
    let regressor = RobotRegressor::new(&declared, DT).unwrap();
    let pi_true = RobotRegressor::new(&truth, DT).unwrap().standard();
    let clean: Vec<Log> = [[0.2, -0.4, 0.05], [-0.5, 0.1, 0.0], [0.6, -0.8, 0.1]]
        .iter()
        .enumerate()
        .map(|(i, q0)| rollout(&truth, q0, 300, 1.1 * i as f64))
        .collect();
    let base_error = |id: &Identification| base_error(id, &pi_true);
    // noise-free: the regression is exact, and output error keeps it
    let plain = identify(&regressor, &clean, &Options::default()).unwrap();
    let refined_options = Options {
        output_error: Some(OutputError::default()),
        ..Options::default()
    };
    let refined_clean = identify(&regressor, &clean, &refined_options).unwrap();
    eprintln!(
        "noise-free: regression {:.1e}, with output error {:.1e}",
        base_error(&plain),
        base_error(&refined_clean)
    );
    assert!(base_error(&plain) < 1e-8, "{}", base_error(&plain));
    assert!(base_error(&refined_clean) < 1e-8);
    // σ = 1e-5 rad (or m) on every position: the regression's noisy second
    // differences bias it; the simulation error does not
    let mut rng = Rng(7);
    let noisy: Vec<Log> = clean.iter().map(|log| with_noise(log, &mut rng)).collect();
    // the first stage with instrumental variables (least squares on
    // second differences of this noise is ~100 % off, and its projection
    // onto consistent parameters lands on the feasible set's boundary,
    // where output error's shortened steps stall), then output error
    let iv = iv();
    let regression = identify(&regressor, &noisy, &iv).unwrap();
    let refined_iv = Options {
        output_error: Some(OutputError::default()),
        ..iv
    };
    let refined = identify(&regressor, &noisy, &refined_iv).unwrap();
    let r = refined.refinement.as_ref().unwrap();
    eprintln!(
        "σ = 1e-5: regression (IV) {:.2e}, with output error {:.2e} ({} segments, {} iterations, \
         rms simulation error {:.2e}, σ̂ {:.2e})",
        base_error(&regression),
        base_error(&refined),
        r.segments,
        r.iterations,
        r.rms,
        r.position_sigma
    );
    // the simulation error reaches the noise
    assert!(base_error(&refined) < 0.2 * base_error(&regression));
    assert!(
        (r.position_sigma / 1e-5 - 1.0).abs() < 0.2,
        "{}",
        r.position_sigma
    );
    // from least squares, whose estimate is far off and projected onto
    // the consistent set's boundary: the projected steps slide along it
    let ls = identify(&regressor, &noisy, &Options::default()).unwrap();
    let ls_refined = identify(&regressor, &noisy, &refined_options).unwrap();
    let r = ls_refined.refinement.as_ref().unwrap();
    eprintln!(
        "σ = 1e-5: regression (least squares) {:.2e}, with output error {:.2e} ({} iterations, \
         σ̂ {:.2e})",
        base_error(&ls),
        base_error(&ls_refined),
        r.iterations,
        r.position_sigma
    );
    assert!(base_error(&ls_refined) < 0.2 * base_error(&ls));
}

/// Logs of a continuous-time truth: the arm of arm3.urdf integrated by
/// Pinocchio's articulated-body algorithm and DOP853 at 1e-12 under inputs
/// held over 10 ms on every joint (`scripts/robot_continuous_log.py`),
/// sampled every 10, 5 and 2.5 ms, identified from a declaration whose
/// distal links are 20 % heavier. No noise, so the regression's error is
/// the rule's discretisation bias: O(Δt) for the first-order rule, O(Δt²)
/// for the midpoint rule. Measured (printed), the largest base-parameter
/// error at 10, 5 and 2.5 ms: first order 2.7e-1, 1.4e-1, 6.8e-2 (each
/// halving divides it by 1.97, 2.04), midpoint 3.6e-3, 8.9e-4, 2.2e-4
/// (4.00, 4.03). Required: each
/// halving divides the first-order error by more than 1.8 and the
/// midpoint error by more than 3.5 (fitted orders within 0.15 of 1 and
/// 0.2 of 2), and the midpoint error is below a tenth of the first-order
/// one at every Δt.
#[test]
fn the_midpoint_rule_shrinks_the_bias_on_continuous_time_logs() {
    let path = format!(
        "{}/../tests/fixtures/robots/arm3_continuous.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let rows = |v: &serde_json::Value| -> Vec<Vec<f64>> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|r| {
                r.as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            })
            .collect()
    };
    let (hold, sample) = (
        json["hold"].as_f64().unwrap(),
        json["sample"].as_f64().unwrap(),
    );
    let actuated = ["j1", "j2", "j3"];
    let truth = driven(&fixture("arm3"), &actuated);
    let declared_text = fixture("arm3")
        .replace(r#"<mass value="1.2"/>"#, r#"<mass value="1.44"/>"#)
        .replace(r#"<mass value="0.5"/>"#, r#"<mass value="0.6"/>"#);
    let declared = driven(&declared_text, &actuated);
    let pi_true = RobotRegressor::new(&truth, DT).unwrap().standard();
    let mut errors = Vec::new();
    for stride in [4, 2, 1] {
        let dt = sample * stride as f64;
        let per_hold = (hold / dt).round() as usize;
        let logs: Vec<Log> = json["runs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|run| {
                let positions: Vec<Vec<f64>> = rows(&run["positions"])
                    .into_iter()
                    .step_by(stride)
                    .collect();
                let held = rows(&run["inputs"]);
                // inputs[k] is held over [t_k, t_{k+1}]
                let inputs = (0..positions.len())
                    .map(|k| held[(k / per_hold).min(held.len() - 1)].clone())
                    .collect();
                Log { positions, inputs }
            })
            .collect();
        let mut row = Vec::new();
        for regressor in [
            RobotRegressor::new(&declared, dt).unwrap(),
            RobotRegressor::midpoint(&declared, dt).unwrap(),
        ] {
            // noise-free logs: the bias of the residual itself, measured by
            // least squares (the default's instruments change it, by
            // another order)
            let options = Options {
                noise: Noise::LeastSquares,
                ..Options::default()
            };
            let id = identify(&regressor, &logs, &options).unwrap();
            row.push(base_error(&id, &pi_true));
        }
        eprintln!(
            "Δt = {:.1} ms: first order {:.2e}, midpoint {:.2e}",
            dt * 1e3,
            row[0],
            row[1]
        );
        assert!(row[1] < 0.1 * row[0], "{row:?}");
        errors.push(row);
    }
    for w in errors.windows(2) {
        let (first, mid) = (w[0][0] / w[1][0], w[0][1] / w[1][1]);
        eprintln!("halving Δt divides the error by {first:.2} (first order), {mid:.2} (midpoint)");
        assert!(first > 1.8 && first < 2.2, "{first}");
        assert!(mid > 3.5 && mid < 4.6, "{mid}");
    }
}

/// ln det of a symmetric positive definite matrix.
fn log_det(a: &nalgebra::DMatrix<f64>) -> f64 {
    let l = a.clone().cholesky().expect("positive definite").l();
    l.diagonal().iter().map(|d| 2.0 * d.ln()).sum()
}

/// Excitation design for a robot loaded from URDF (`Excitation::robot`),
/// within the URDF's own position and velocity limits, the arm lying on a
/// horizontal table (gravity off: a zero-mean periodic torque cannot hold
/// a joint against a static load, so under gravity the limits could not
/// be met by any input of the design's form): the designed input
/// must beat each of 8 random inputs of the same peak amplitude by the
/// design's criterion (log det of the scaled base-parameter information),
/// and identification (instrumental variables, σ = 1e-5 on every
/// position, the same noise draws) from its log must give a smaller log
/// det of the base-parameter covariance than the median of the random
/// inputs' logs, and than each of them that informs as many base
/// parameters. No margin is asked beyond strict inequality (the claim is
/// the ordering); the margins are printed.
#[test]
fn a_designed_input_identifies_a_urdf_arm_better_than_random_inputs() {
    use vigp_runtime::identify::excitation::{Excitation, Problem};
    let robot = driven(&fixture("arm3"), &["j1", "j2", "j3"])
        .with_gravity([0.0, 0.0, 0.0])
        .unwrap();
    let regressor = RobotRegressor::new(&robot, DT).unwrap();
    let mut problem = Problem::new(vec![0.2, -0.4, 0.05], 200, 2, vec![1.0, 1.0, 1.0]);
    // (the optimiser's default is 60 iterations; 15 keep the test short)
    problem.optimiser.max_iters = 15;
    let limits: Vec<_> = robot.tree().bodies.iter().map(|b| b.limits).collect();
    problem.position_limits = limits.iter().map(|l| (l.lower, l.upper)).collect();
    problem.velocity_limits = limits.iter().map(|l| l.velocity).collect();
    let ex = Excitation::robot(&regressor, &problem).unwrap();
    let d = ex.design().unwrap();
    eprintln!(
        "arm3: design log det {:.3} (best random start {:.3}), {} iterations, peak {:?}, limit \
         excess {:.2e}",
        d.evaluation.log_det,
        d.start_log_det,
        d.iterations,
        d.evaluation.peak,
        d.evaluation.violation
    );
    for (p, a) in d.evaluation.peak.iter().zip(&problem.amplitude) {
        // the amplitude bound is exact (scaled down to it): rounding only
        assert!(*p <= a * (1.0 + 1e-12), "peak {p} > {a}");
    }
    assert!(d.evaluation.violation <= problem.limit_tolerance);
    let iv = iv();
    let noisy = |log: &Log| with_noise(log, &mut Rng(31));
    let designed = identify(&regressor, &[noisy(&d.evaluation.log)], &iv).unwrap();
    let cov_design = log_det(&designed.base_covariance);
    let mut random_cov = Vec::new();
    for seed in 0..8u64 {
        let e = ex.evaluate(&ex.random(1000 + seed)).unwrap();
        let id = identify(&regressor, &[noisy(&e.log)], &iv).unwrap();
        // a log that informs fewer base parameters leaves some unidentified
        // (an infinite variance); one that informs more beats the design
        assert!(
            id.base.rank() <= designed.base.rank(),
            "random input {seed}"
        );
        let c = if id.base.rank() < designed.base.rank() {
            f64::INFINITY
        } else {
            // both covariances in the design's base coordinates (θ = K·π
            // for the same null space; K is the identity at its
            // independent columns)
            let t = designed.base.k.select_columns(&id.base.independent);
            log_det(&(&t * &id.base_covariance * t.transpose()))
        };
        eprintln!(
            "arm3: random input {seed}: log det information {:.3}, covariance {c:.3}, limit \
             excess {:.2e}",
            e.log_det, e.violation
        );
        assert!(d.evaluation.log_det > e.log_det, "random input {seed}");
        random_cov.push(c);
    }
    random_cov.sort_by(f64::total_cmp);
    let median = 0.5 * (random_cov[3] + random_cov[4]);
    eprintln!(
        "arm3: log det covariance of {} base parameters: design {cov_design:.3}, random median \
         {median:.3}",
        designed.base.rank()
    );
    assert!(cov_design < median, "{cov_design} vs {median}");
    // and every random input that informs as many base parameters
    assert!(
        cov_design < random_cov[0],
        "{cov_design} vs {}",
        random_cov[0]
    );
}
