//! Output error for robots loaded at run time: the robot regressor's
//! exact position Jacobians (the engine's closed-form term derivatives)
//! against central differences of its residual, and the output-error
//! stage on a noisy log of a perturbed arm against the regression alone.

use vigp_runtime::identify::regressor::Transition;
use vigp_runtime::identify::{
    Log, Noise, Options, OutputError, Regressor, RobotRegressor, identify,
};
use vigp_runtime::{Robot, RobotState};

#[path = "../../tests/common/rng.rs"]
mod rng;
use rng::Rng;

const DT: f64 = 0.002;

fn fixture(name: &str) -> String {
    std::fs::read_to_string(format!(
        "{}/../tests/fixtures/robots/{name}.urdf",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
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

#[test]
fn position_jacobians_match_central_differences() {
    let text = fixture("panda").replace(r#"damping="0.003""#, r#"damping="0.2""#);
    let robot = Robot::from_urdf_str(&text)
        .unwrap()
        .with_actuated(&["panda_joint2", "panda_joint4"])
        .unwrap();
    let q0 = [0.1, -0.6, 0.2, -2.0, 0.3, 1.4, 0.7];
    let log = rollout(&robot, &q0, 40, 0.3);
    let regressor = RobotRegressor::new(&robot, DT).unwrap();
    let pi = regressor.standard();
    for k in [5, 30] {
        let t = Transition {
            positions: [
                &log.positions[k - 1],
                &log.positions[k],
                &log.positions[k + 1],
            ],
            inputs: [&log.inputs[k - 1], &log.inputs[k]],
        };
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
            "transition {k}: exact against central differences {worst:.1e} of the largest entry"
        );
        assert!(worst < 1e-7, "{worst}");
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
    let truth = Robot::from_urdf_str(&truth_text)
        .unwrap()
        .with_actuated(&actuated)
        .unwrap();
    let declared = Robot::from_urdf_str(&fixture("arm3"))
        .unwrap()
        .with_actuated(&actuated)
        .unwrap();
    let regressor = RobotRegressor::new(&declared, DT).unwrap();
    let pi_true = RobotRegressor::new(&truth, DT).unwrap().standard();
    let clean: Vec<Log> = [[0.2, -0.4, 0.05], [-0.5, 0.1, 0.0], [0.6, -0.8, 0.1]]
        .iter()
        .enumerate()
        .map(|(i, q0)| rollout(&truth, q0, 300, 1.1 * i as f64))
        .collect();
    // the largest relative error of the base parameters, each against the
    // size of its combination's terms, a term's size being the larger of
    // |π*_j| and the prior's scale of π_j (combinations whose true value
    // is zero: a damping the arm lacks, a centre of mass on an axis)
    let base_error = |id: &vigp_runtime::identify::Identification| {
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
    };
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
    let noisy: Vec<Log> = clean
        .iter()
        .map(|log| Log {
            positions: log
                .positions
                .iter()
                .map(|x| x.iter().map(|v| v + 1e-5 * rng.normal()).collect())
                .collect(),
            inputs: log.inputs.clone(),
        })
        .collect();
    // the first stage with instrumental variables (least squares on
    // second differences of this noise is ~100 % off, and its projection
    // onto consistent parameters lands on the feasible set's boundary,
    // where output error's shortened steps stall), then output error
    let iv = Options {
        noise: Noise::IV,
        ..Options::default()
    };
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
