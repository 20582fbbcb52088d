//! The linear-time tree engine (`vigp::Robot`) on planar and spatial chains
//! of N = 2 … 32 rods and on URDF robots (Panda, UR5 from
//! tests/fixtures/robots): median time per step of a 2 ms rollout,
//! iterations per step, subdivided steps, and the fitted slope of
//! log(time) against log(N) from N = 8 on. Then one step against one step
//! with its exact A and B (`Robot::step_derivatives`) on the robots of
//! tests/fixtures/robots and on chains, timed side by side.
//!
//! ```text
//! cargo run --release --example robots [-- --steps 2000]
//! ```

use std::time::Instant;

use vigp::robot::{Robot, RobotState};

/// A chain of n rods (m = 1, l = 0.5) hanging along −z; `spatial`
/// alternates the axes z, y (else every axis is y: a planar chain).
fn chain(n: usize, spatial: bool) -> String {
    let (m, l) = (1.0, 0.5);
    let i = m * l * l / 12.0;
    let mut s = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
    for k in 1..=n {
        let z = if k == 1 { 0.0 } else { -l };
        let axis = if spatial && k % 2 == 1 {
            "0 0 1"
        } else {
            "0 1 0"
        };
        // spatial chains: links along x so that a z axis moves them
        let (com, origin) = if spatial {
            (
                format!("{} 0 0", l / 2.0),
                format!("{} 0 0", if k == 1 { 0.0 } else { l }),
            )
        } else {
            (format!("0 0 {}", -l / 2.0), format!("0 0 {z}"))
        };
        s += &format!(
            "<link name=\"l{k}\"><inertial><origin xyz=\"{com}\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{i}\" ixy=\"0\" ixz=\"0\" iyy=\"{i}\" iyz=\"0\" izz=\"{i}\"/></inertial></link>\
             <joint name=\"j{k}\" type=\"continuous\"><parent link=\"l{}\"/><child link=\"l{k}\"/>\
             <origin xyz=\"{origin}\"/><axis xyz=\"{axis}\"/></joint>",
            k - 1
        );
    }
    s + "</robot>"
}

/// Median ns per step over `reps` rollouts of `steps` steps, and the
/// rollout's report of the last one.
fn time(robot: &Robot, z0: &RobotState, dt: f64, steps: usize, reps: usize) -> (f64, f64, usize) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..reps {
        let t = Instant::now();
        let run = robot.rollout(z0, dt, steps).expect("rollout");
        times.push(t.elapsed().as_secs_f64() * 1e9 / steps as f64);
        last = Some(run.report);
    }
    times.sort_by(f64::total_cmp);
    let r = last.unwrap();
    (
        times[times.len() / 2],
        r.iterations as f64 / r.steps as f64,
        r.subdivided,
    )
}

/// Least-squares slope of log y against log x.
fn slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) = points.iter().map(|(x, y)| (x.ln(), y.ln())).unzip();
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let steps = args
        .iter()
        .position(|a| a == "--steps")
        .and_then(|i| args.get(i + 1))
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(2000);
    let dt = 0.002;
    println!("tree engine, dt = 2 ms, {steps}-step rollouts, median of 5");
    println!("| mechanism | N | ns/step | iterations/step | subdivided steps |");
    println!("|---|---|---|---|---|");
    for spatial in [false, true] {
        let mut fit = Vec::new();
        for n in [2, 4, 8, 12, 16, 24, 32] {
            let robot = Robot::from_urdf_str(&chain(n, spatial))?;
            let mut q = vec![0.0; n];
            q[0] = 1.0;
            q[1] = -0.5;
            let z0 = RobotState::new(q, vec![0.0; n]);
            let (ns, it, sub) = time(&robot, &z0, dt, steps, 5);
            let name = if spatial {
                "spatial chain (z/y)"
            } else {
                "planar chain"
            };
            println!("| {name} | {n} | {ns:.0} | {it:.2} | {sub} |");
            if n >= 8 {
                fit.push((n as f64, ns));
            }
        }
        println!(
            "| fitted slope of log time vs log N, N = 8…32 | | {:.2} | | |",
            slope(&fit)
        );
    }
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/robots");
    for (name, file, q) in [
        (
            "Panda",
            "panda.urdf",
            vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8],
        ),
        ("UR5", "ur5.urdf", vec![0.3, -1.2, 1.0, -0.5, 0.8, 0.2]),
    ] {
        let robot = Robot::from_urdf(format!("{dir}/{file}"))?;
        let n = robot.dof();
        let z0 = RobotState::new(q, vec![0.3; n]);
        let (ns, it, sub) = time(&robot, &z0, dt, steps, 5);
        println!("| {name} | {n} | {ns:.0} | {it:.2} | {sub} |");
    }
    derivatives(dir, dt)
}

/// Median ns of `f` over `reps` calls, after one warm-up call.
fn median_ns(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e9
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// One step (`Robot::step`, from a moving state, every joint driven)
/// against the same step with its exact A and B, timed one after the other
/// in the same run.
fn derivatives(dir: &str, dt: f64) -> Result<(), Box<dyn std::error::Error>> {
    println!();
    println!(
        "one step of dt = 2 ms with every joint driven, and with exact A (2N × 2N) and B (2N × N); median of 301 calls"
    );
    println!("| mechanism | N | step (µs) | step with A, B (µs) | ratio |");
    println!("|---|---|---|---|---|");
    let mut cases: Vec<(String, Robot)> = Vec::new();
    for (name, file) in [
        ("Panda", "panda.urdf"),
        ("UR5", "ur5.urdf"),
        ("Solo-12 (fixed base)", "solo12.urdf"),
        ("G1 humanoid (fixed base)", "g1.urdf"),
    ] {
        cases.push((name.to_string(), Robot::from_urdf(format!("{dir}/{file}"))?));
    }
    for n in [8, 16, 32] {
        cases.push((
            format!("spatial chain (z/y), {n} rods"),
            Robot::from_urdf_str(&chain(n, true))?,
        ));
    }
    for (name, robot) in cases {
        let n = robot.dof();
        let joints: Vec<String> = robot.joint_names().to_vec();
        let names: Vec<&str> = joints.iter().map(String::as_str).collect();
        let robot = robot.with_actuated(&names)?;
        let q: Vec<f64> = (0..n).map(|i| 0.3 * ((i as f64) * 1.7).sin()).collect();
        let v: Vec<f64> = (0..n).map(|i| 0.4 * ((i as f64) * 0.9).cos()).collect();
        let u: Vec<f64> = (0..n).map(|i| 0.2 * ((i as f64) * 1.3).sin()).collect();
        let z = RobotState::new(q, v);
        let step = median_ns(301, || {
            std::hint::black_box(robot.step(&z, &u, dt).expect("step"));
        });
        let with = median_ns(301, || {
            std::hint::black_box(robot.step_derivatives(&z, &u, dt).expect("derivatives"));
        });
        println!(
            "| {name} | {n} | {:.1} | {:.1} | {:.2} |",
            step * 1e-3,
            with * 1e-3,
            with / step
        );
    }
    Ok(())
}
