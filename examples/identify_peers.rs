//! Identification side by side with the continuous-time route, on logs of
//! a continuous-time truth.
//!
//! ```text
//! python3 scripts/identify_pinocchio.py --out target/identify_peers.json
//! cargo run --release --example identify_peers -- target/identify_peers.json
//! ```
//!
//! The script simulates a driven, damped double pendulum (both joints
//! actuated, smooth torques) in continuous time (Pinocchio's ABA, DOP853
//! at 1e-12), samples it, adds position noise, and runs the continuous-time
//! route on every noisy log: Savitzky–Golay velocities and accelerations
//! into Pinocchio's `computeJointTorqueRegressor`, least squares, for every
//! window and order of a grid. This example identifies the same logs with
//! vigp and prints two tables:
//!
//! 1. noise-free logs at Δt = 20, 10, 5 ms: the largest relative error of
//!    the base parameters for the first-order and the midpoint rule, and
//!    the observed order between successive Δt (the discretisation bias
//!    of the DEL residual against the continuous truth);
//! 2. noisy logs (σ = 1e-4 and 1e-3 at 10 ms): the median over seeds of
//!    that error for the continuous-time route at its best grid setting
//!    (chosen by this median, with the truth: an oracle tuning), and for
//!    vigp's regression (least squares; instrumental variables) and its
//!    output-error refinement (midpoint rule).
//!
//! The base parameters (the combinations the data determine) are those of
//! the midpoint regression on the noise-free 10 ms log; every estimate is
//! scored on them, so a method's choice in the directions the data do not
//! see does not count. The log's input row k is the torque at t_k + Δt/2,
//! the value the midpoint rule's quadrature wants (vigp holds row k's
//! input over [t_k, t_k + Δt]); the continuous-time route gets the torque
//! at each sample time.

#[path = "../tests/learn/fixtures.rs"]
mod fixtures;
#[path = "common/median.rs"]
mod median;
#[path = "../tests/common/rng.rs"]
mod rng;

use fixtures::base_error;
use median::median;
use rayon::prelude::*;
use rng::Rng; // the fixtures' generator (`super::Rng`)
use serde::Deserialize;
use vigp::identify::{
    DelRegressor, IdentifyError, Log, Noise, Options, OutputError, Structure, identify,
};

vigp::mechanism! {
    /// A driven, damped double pendulum, both joints actuated: the
    /// declared mechanism of scripts/identify_pinocchio.py (its truth is
    /// heavier, with moved centres of mass and other damping).
    pub Peer {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 0.8, length: 0.7 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.1, actuated },
            elbow: revolute(upper.end, lower.start) { damping: 0.1, actuated },
        }
    }
}

/// The script's file.
#[derive(Deserialize)]
struct File {
    /// π of the truth, in vigp's layout.
    truth: Vec<f64>,
    clean: Vec<Entry>,
    noisy: Vec<Entry>,
}

/// One log and, for noisy logs, the continuous-time route's estimates.
#[derive(Deserialize)]
struct Entry {
    dt: f64,
    positions: Vec<Vec<f64>>,
    inputs: Vec<Vec<f64>>,
    #[serde(default)]
    sigma: f64,
    #[serde(default)]
    pinocchio: Vec<Setting>,
}

/// The continuous-time route at one Savitzky–Golay setting.
#[derive(Deserialize)]
struct Setting {
    window: usize,
    order: usize,
    estimate: Vec<f64>,
}

impl Entry {
    fn log(&self) -> Log {
        Log {
            positions: self.positions.clone(),
            inputs: self.inputs.clone(),
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .ok_or("usage: identify_peers FILE (written by scripts/identify_pinocchio.py)")?;
    let file: File = serde_json::from_str(&std::fs::read_to_string(&path)?)?;
    let declared = Peer::default().minimal();
    let structure = Structure::of::<PeerMinimal>()?;
    if file.truth.len() != structure.len() {
        return Err(format!(
            "the file's truth has {} parameters, the mechanism {}",
            file.truth.len(),
            structure.len()
        )
        .into());
    }
    let truth = &file.truth;
    // the noise-free logs measure the bias of the residual itself: least
    // squares, the rows without instruments
    let least_squares = Options {
        noise: Noise::LeastSquares,
        ..Options::default()
    };
    let reference = file
        .clean
        .iter()
        .find(|e| (e.dt - 0.01).abs() < 1e-12)
        .ok_or("no noise-free 10 ms log")?;
    let id = identify(
        &DelRegressor::midpoint(declared, reference.dt)?,
        &[reference.log()],
        &least_squares,
    )?;
    let base = id.base.clone();
    println!(
        "base parameters ({} of {}): {}",
        base.rank(),
        structure.len(),
        id.base_names.join(", ")
    );
    // the largest relative base error of an estimate, on the common base
    let score = |estimate: &[f64]| {
        let mut scored = id.clone();
        scored.estimate = estimate.to_vec();
        base_error(&scored, truth)
    };

    println!("\nnoise-free logs of the continuous truth: largest relative base-parameter error");
    println!("| Δt | first order | order | midpoint | order |");
    println!("|---|---|---|---|---|");
    let mut previous: Option<(f64, f64, f64)> = None;
    for e in &file.clean {
        let mut errors = [0.0; 2];
        for (i, alpha) in [0.0, 0.5].into_iter().enumerate() {
            let r = DelRegressor::new(declared, e.dt, alpha)?;
            errors[i] = score(&identify(&r, &[e.log()], &least_squares)?.estimate);
        }
        let order = |i: usize| match previous {
            Some((dt, a, b)) => {
                let prev = if i == 0 { a } else { b };
                format!("{:.2}", (prev / errors[i]).ln() / (dt / e.dt).ln())
            }
            None => "—".into(),
        };
        println!(
            "| {} ms | {:.2e} | {} | {:.2e} | {} |",
            e.dt * 1e3,
            errors[0],
            order(0),
            errors[1],
            order(1)
        );
        previous = Some((e.dt, errors[0], errors[1]));
    }

    let mut sigmas: Vec<f64> = file.noisy.iter().map(|e| e.sigma).collect();
    sigmas.dedup();
    println!(
        "\nnoisy logs, 10 ms, {} s: median over seeds of the largest relative base-parameter error",
        reference.positions.len() as f64 * reference.dt
    );
    println!(
        "| σ | seeds | Savitzky–Golay + Pinocchio regressor (best setting) | vigp least squares | vigp instrumental variables | vigp + output error |"
    );
    println!("|---|---|---|---|---|---|");
    for sigma in sigmas {
        let logs: Vec<&Entry> = file.noisy.iter().filter(|e| e.sigma == sigma).collect();
        let r = DelRegressor::midpoint(declared, logs[0].dt)?;
        let ls = least_squares;
        let iv = Options {
            noise: Noise::IV,
            ..Options::default()
        };
        let oe = Options {
            output_error: Some(OutputError::default()),
            ..iv
        };
        let ours: Vec<[f64; 3]> = logs
            .par_iter()
            .map(|e| {
                let log = e.log();
                let mut out = [0.0; 3];
                for (o, options) in out.iter_mut().zip([&ls, &iv, &oe]) {
                    *o = score(&identify(&r, std::slice::from_ref(&log), options)?.estimate);
                }
                Ok(out)
            })
            .collect::<Result<_, IdentifyError>>()?;
        // the continuous-time route: every setting, the best by its median
        let settings = logs[0].pinocchio.len();
        let mut best = (f64::INFINITY, 0, 0);
        for s in 0..settings {
            let m = median(
                &mut logs
                    .iter()
                    .map(|e| score(&e.pinocchio[s].estimate))
                    .collect::<Vec<_>>(),
            );
            if m < best.0 {
                best = (m, logs[0].pinocchio[s].window, logs[0].pinocchio[s].order);
            }
        }
        let col = |i: usize| median(&mut ours.iter().map(|o| o[i]).collect::<Vec<_>>());
        println!(
            "| {sigma:e} | {} | {:.2e} (window {}, order {}) | {:.2e} | {:.2e} | {:.2e} |",
            logs.len(),
            best.0,
            best.1,
            best.2,
            col(0),
            col(1),
            col(2)
        );
    }
    Ok(())
}
