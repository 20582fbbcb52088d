//! The linear-time tree engine (`vigp::Robot`) on planar and spatial chains
//! of N = 2 … 32 rods and on URDF robots (Panda, UR5, Solo-12 from
//! tests/fixtures/robots): time per step of a 2 ms rollout by
//! `Robot::step_in` (the allocation-free loop), iterations per step,
//! subdivided steps, and the fitted slope of log(time) against log(N) from
//! N = 8 on, beside MuJoCo's Euler step on the same URDF files and states
//! (`python3 scripts/robots_bench.py --rollouts`, `mujoco.rollout`, a C
//! loop), run by this example after its own rollouts. Both sides run
//! twice, alternately, and each number is the fastest of the 14 runs (7
//! per round): on a shared machine the fastest run is the least disturbed
//! by other processes. Then one step
//! against one step with its exact A and B (`Robot::step_derivatives`) on
//! the robots of tests/fixtures/robots and on chains, timed side by side.
//! Last, planar chains declared in `mechanism!` (N = 2, 4, 6, 8): the
//! closed-form step (`Variational::step`) against the tree engine's
//! (`Name::robot()`, `Robot::step_in`) on the same description, the
//! measurement behind the macro's rule (docs/robots.md).
//!
//! ```text
//! cargo run --release --example robots [-- --steps 2000]
//! cargo run --release --example robots -- --derivatives   # the second table alone
//! cargo run --release --example robots -- --declared      # the third table alone
//! ```

use std::time::Instant;

use vigp::embedded::tree::{BodyScratch, DerivativeBuffers, derivative_scratch_len};
use vigp::prelude::*;
use vigp::robot::{Robot, RobotState};

vigp::mechanism! {
    /// Two uniform rods (m = 1 kg, l = 0.5 m) in a chain.
    Rods2 {
        links { r0: { mass: 1.0, length: 0.5 }, r1: { mass: 1.0, length: 0.5 } }
        joints { j0: revolute(world, r0.start), j1: revolute(r0.end, r1.start) }
    }
}

vigp::mechanism! {
    /// Four uniform rods in a chain.
    Rods4 {
        links {
            r0: { mass: 1.0, length: 0.5 }, r1: { mass: 1.0, length: 0.5 },
            r2: { mass: 1.0, length: 0.5 }, r3: { mass: 1.0, length: 0.5 },
        }
        joints {
            j0: revolute(world, r0.start), j1: revolute(r0.end, r1.start),
            j2: revolute(r1.end, r2.start), j3: revolute(r2.end, r3.start),
        }
    }
}

vigp::mechanism! {
    /// Six uniform rods in a chain.
    Rods6 {
        links {
            r0: { mass: 1.0, length: 0.5 }, r1: { mass: 1.0, length: 0.5 },
            r2: { mass: 1.0, length: 0.5 }, r3: { mass: 1.0, length: 0.5 },
            r4: { mass: 1.0, length: 0.5 }, r5: { mass: 1.0, length: 0.5 },
        }
        joints {
            j0: revolute(world, r0.start), j1: revolute(r0.end, r1.start),
            j2: revolute(r1.end, r2.start), j3: revolute(r2.end, r3.start),
            j4: revolute(r3.end, r4.start), j5: revolute(r4.end, r5.start),
        }
    }
}

vigp::mechanism! {
    /// Eight uniform rods in a chain.
    Rods8 {
        links {
            r0: { mass: 1.0, length: 0.5 }, r1: { mass: 1.0, length: 0.5 },
            r2: { mass: 1.0, length: 0.5 }, r3: { mass: 1.0, length: 0.5 },
            r4: { mass: 1.0, length: 0.5 }, r5: { mass: 1.0, length: 0.5 },
            r6: { mass: 1.0, length: 0.5 }, r7: { mass: 1.0, length: 0.5 },
        }
        joints {
            j0: revolute(world, r0.start), j1: revolute(r0.end, r1.start),
            j2: revolute(r1.end, r2.start), j3: revolute(r2.end, r3.start),
            j4: revolute(r3.end, r4.start), j5: revolute(r4.end, r5.start),
            j6: revolute(r5.end, r6.start), j7: revolute(r6.end, r7.start),
        }
    }
}

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

/// The fastest ns per step of `reps` rollouts of `steps` unforced steps by
/// `Robot::step_in` (no allocation in the loop), and the iterations per
/// step and subdivided steps of the last rollout.
fn time(robot: &Robot, z0: &RobotState, dt: f64, steps: usize, reps: usize) -> (f64, f64, usize) {
    time_driven(robot, z0, dt, steps, reps, |_, _, _| {})
}

/// [`time`] with the inputs of step k set by `law(k, z_k, u)` inside the
/// timed loop.
fn time_driven(
    robot: &Robot,
    z0: &RobotState,
    dt: f64,
    steps: usize,
    reps: usize,
    mut law: impl FnMut(usize, &RobotState, &mut [f64]),
) -> (f64, f64, usize) {
    let mut ws = robot.workspace();
    let mut u = vec![0.0; robot.input_names().len()];
    let mut times = Vec::new();
    let (mut iterations, mut subdivided) = (0, 0);
    for _ in 0..reps {
        let mut z = z0.clone();
        let mut p = robot.momentum(&z).expect("momentum");
        (iterations, subdivided) = (0, 0);
        let t = Instant::now();
        for k in 0..steps {
            law(k, &z, &mut u);
            let r = robot
                .step_in(&mut z, &mut p, &u, dt, &mut ws)
                .expect("step");
            iterations += r.iterations;
            subdivided += usize::from(r.depth > 0);
        }
        times.push(t.elapsed().as_secs_f64() * 1e9 / steps as f64);
        std::hint::black_box(&z);
    }
    (
        times.iter().copied().fold(f64::INFINITY, f64::min),
        iterations as f64 / steps as f64,
        subdivided,
    )
}

/// MuJoCo's ns per step from `python3 scripts/robots_bench.py --rollouts`
/// (empty, with the reason printed, when Python or MuJoCo is missing).
fn mujoco_rollouts() -> std::collections::HashMap<(String, usize), f64> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/robots_bench.py");
    let mut out = std::collections::HashMap::new();
    match std::process::Command::new("python3")
        .arg(script)
        .arg("--rollouts")
        .output()
    {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            if let Some(first) = text.lines().next() {
                println!("peer: {first} (`python3 scripts/robots_bench.py --rollouts`)");
            }
            for line in text.lines() {
                let cells: Vec<&str> = line.split('|').map(str::trim).collect();
                // | name | N | ns |
                if let [_, name, n, ns, _] = cells[..]
                    && let (Ok(n), Ok(ns)) = (n.parse(), ns.parse())
                {
                    out.insert((name.to_string(), n), ns);
                }
            }
        }
        Ok(o) => println!(
            "peer: scripts/robots_bench.py failed: {}",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => println!("peer: python3 not run: {e}"),
    }
    out
}

/// The load average of the machine (Linux), for the tables' headers.
fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
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
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/robots");
    if args.iter().any(|a| a == "--derivatives") {
        println!("load average at the start: {}", load());
        return derivatives(dir, dt);
    }
    if args.iter().any(|a| a == "--declared") {
        println!("load average at the start: {}", load());
        return declared(steps, dt);
    }
    println!("load average at the start: {}", load());
    // two rounds of ours, then MuJoCo's; the fastest run of each side
    let mut rows = own_rollouts(steps, dt)?;
    let mut peer = mujoco_rollouts();
    for (r, r2) in rows.iter_mut().zip(own_rollouts(steps, dt)?) {
        r.2 = r.2.min(r2.2);
    }
    for (k, ns) in mujoco_rollouts() {
        let e = peer.entry(k).or_insert(ns);
        *e = e.min(ns);
    }
    println!("load average after both: {}", load());
    println!(
        "tree engine (`Robot::step_in`), dt = 2 ms, {steps}-step rollouts, the fastest of 2 × 7; \
         MuJoCo's Euler step (`mujoco.rollout`, 2000 steps, the fastest of 2 × 7), measured alternately"
    );
    println!(
        "| mechanism | N | ns/step | iterations/step | subdivided steps | MuJoCo ns/step | ratio |"
    );
    println!("|---|---|---|---|---|---|---|");
    let (mut fit, mut fit_peer) = (Vec::new(), Vec::new());
    for (k, (name, n, ns, it, sub)) in rows.iter().enumerate() {
        let key = if name == PANDA_PD { "Panda" } else { name };
        let mj = peer.get(&(key.to_string(), *n)).copied();
        let (mj_s, ratio) = match mj {
            Some(mj) => (format!("{mj:.0}"), format!("{:.2}", ns / mj)),
            None => ("n/a".into(), "n/a".into()),
        };
        println!("| {name} | {n} | {ns:.0} | {it:.2} | {sub} | {mj_s} | {ratio} |");
        if name.contains("chain") && *n >= 8 {
            fit.push((*n as f64, *ns));
            if let Some(mj) = mj {
                fit_peer.push((*n as f64, mj));
            }
        }
        // the fitted slopes after each family of chains
        if name.contains("chain") && rows.get(k + 1).is_none_or(|next| &next.0 != name) {
            let peer_slope = if fit_peer.len() == fit.len() {
                format!("{:.2}", slope(&fit_peer))
            } else {
                "n/a".into()
            };
            println!(
                "| fitted slope of log time vs log N, N = 8…32 | | {:.2} | | | {peer_slope} | |",
                slope(&fit)
            );
            (fit, fit_peer) = (Vec::new(), Vec::new());
        }
    }
    derivatives(dir, dt)?;
    declared(steps, dt)
}

/// N and the ns/step of a rollout of `steps` steps of the closed form
/// (`Variational::step`) and of the tree engine (`Robot::step_in` on
/// `robot()`) of one planar description, from q = (1, −0.5, 0, …) at rest;
/// the fastest of 7 rollouts each, alternating.
fn declared_row<M: Mechanism<N, 0> + Copy, const N: usize>(
    model: M,
    robot: &Robot,
    steps: usize,
    dt: f64,
) -> Result<(usize, f64, f64), Box<dyn std::error::Error>> {
    let vi = Variational::new(model, dt)?;
    let mut q0 = [0.0; N];
    (q0[0], q0[1]) = (1.0, -0.5);
    let z0 = model.state(q0, [0.0; N]);
    let robot_z0 = RobotState::new(q0.to_vec(), vec![0.0; N]);
    let mut closed = f64::INFINITY;
    let mut engine = f64::INFINITY;
    for _ in 0..7 {
        let t = Instant::now();
        let mut z = z0;
        for _ in 0..steps {
            z = vi.step(&z)?;
        }
        std::hint::black_box(&z);
        closed = closed.min(t.elapsed().as_secs_f64() * 1e9 / steps as f64);
        engine = engine.min(time(robot, &robot_z0, dt, steps, 1).0);
    }
    Ok((N, closed, engine))
}

/// The closed form against the tree engine on the same planar
/// descriptions (`mechanism!`): the measurement behind the macro's rule.
fn declared(steps: usize, dt: f64) -> Result<(), Box<dyn std::error::Error>> {
    println!();
    println!(
        "planar chains declared in `mechanism!`, dt = 2 ms, {steps}-step rollouts from rest, \
         the fastest of 7 each, alternating: the closed form (`Variational::step`) against the \
         tree engine (`Name::robot()`, `Robot::step_in`)"
    );
    println!("| N | closed form (ns/step) | tree engine (ns/step) | engine / closed form |");
    println!("|---|---|---|---|");
    let (rods2, rods4, rods6, rods8) = (
        Rods2::default(),
        Rods4::default(),
        Rods6::default(),
        Rods8::default(),
    );
    let rows = [
        declared_row(rods2.minimal(), &rods2.robot()?, steps, dt)?,
        declared_row(rods4.minimal(), &rods4.robot()?, steps, dt)?,
        declared_row(rods6.minimal(), &rods6.robot()?, steps, dt)?,
        declared_row(rods8.minimal(), &rods8.robot()?, steps, dt)?,
    ];
    for (n, closed, engine) in rows {
        println!(
            "| {n} | {closed:.0} | {engine:.0} | {:.2} |",
            engine / closed
        );
    }
    println!("load average after: {}", load());
    Ok(())
}

/// The row of the Panda driven by a PD law (MuJoCo's Euler step costs the
/// same in any state without contacts, so its Panda row is the peer).
const PANDA_PD: &str = "Panda, every joint PD-tracking q₀ + 0.3 sin(πt) rad";

/// One round of our rollouts: (name, N, ns/step, iterations/step,
/// subdivided steps) of the chains and the robots, from the states of
/// scripts/robots_bench.py (v = 0, no input).
#[allow(clippy::type_complexity)]
fn own_rollouts(
    steps: usize,
    dt: f64,
) -> Result<Vec<(String, usize, f64, f64, usize)>, Box<dyn std::error::Error>> {
    let mut rows = Vec::new();
    for spatial in [false, true] {
        for n in [2, 4, 8, 12, 16, 24, 32] {
            let robot = Robot::from_urdf_str(&chain(n, spatial))?;
            let mut q = vec![0.0; n];
            q[0] = 1.0;
            q[1] = -0.5;
            let z0 = RobotState::new(q, vec![0.0; n]);
            let (ns, it, sub) = time(&robot, &z0, dt, steps, 7);
            let name = if spatial {
                "spatial chain (z/y)"
            } else {
                "planar chain"
            };
            rows.push((name.into(), n, ns, it, sub));
        }
    }
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/robots");
    for (name, file, q) in [
        (
            "Panda",
            "panda.urdf",
            Some(vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]),
        ),
        (
            "UR5",
            "ur5.urdf",
            Some(vec![0.3, -1.2, 1.0, -0.5, 0.8, 0.2]),
        ),
        ("Solo-12 (fixed base)", "solo12.urdf", None),
    ] {
        let robot = Robot::from_urdf(format!("{dir}/{file}"))?;
        let n = robot.dof();
        let z0 = RobotState::new(q.unwrap_or_else(|| vec![0.0; n]), vec![0.0; n]);
        let (ns, it, sub) = time(&robot, &z0, dt, steps, 7);
        rows.push((name.into(), n, ns, it, sub));
        if name == "Panda" {
            // every joint driven by a PD law tracking q0 + 0.3 sin(πt) rad,
            // gains of a 10 rad/s critically damped loop on the diagonal of
            // M(q0) (no gravity compensation)
            let joints = robot.joint_names().to_vec();
            let names: Vec<&str> = joints.iter().map(String::as_str).collect();
            let m = robot.mass_matrix(&z0.q)?;
            let driven = robot.with_actuated(&names)?;
            let q0 = z0.q.clone();
            let (ns, it, sub) = time_driven(&driven, &z0, dt, steps, 7, |k, z, u| {
                let offset = 0.3 * (std::f64::consts::PI * k as f64 * dt).sin();
                for i in 0..u.len() {
                    let mii = m[i * n + i];
                    u[i] = -100.0 * mii * (z.q[i] - q0[i] - offset) - 20.0 * mii * z.v[i];
                }
            });
            rows.push((PANDA_PD.into(), n, ns, it, sub));
        }
    }
    Ok(rows)
}

/// Median ns of `f` and of `g` over `reps` calls each, after one warm-up
/// call, the calls alternating (f, g, f, g, …) so that both see the same
/// load of a shared machine.
fn medians_ns(reps: usize, mut f: impl FnMut(), mut g: impl FnMut()) -> (f64, f64) {
    f();
    g();
    let time = |h: &mut dyn FnMut()| {
        let t = Instant::now();
        h();
        t.elapsed().as_secs_f64() * 1e9
    };
    let (mut a, mut b): (Vec<f64>, Vec<f64>) =
        (0..reps).map(|_| (time(&mut f), time(&mut g))).unzip();
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    (a[reps / 2], b[reps / 2])
}

/// One step (`Robot::step`, from a moving state, every joint driven)
/// against the same step with its exact A and B, timed one after the other
/// in the same run.
fn derivatives(dir: &str, dt: f64) -> Result<(), Box<dyn std::error::Error>> {
    println!();
    println!(
        "one step of dt = 2 ms with every joint driven, and with exact A (2N × 2N) and B (2N × N); medians of 1001 calls each, alternating; then per step of 100-step rollouts under the same inputs, medians of 31 each, alternating"
    );
    println!(
        "| mechanism | N | `Robot::step` (µs) | `Robot::step_derivatives` (µs) | ratio | `Engine::step` on slices (µs) | `Engine::step_derivatives` on slices (µs) | ratio | `Robot::rollout_with`, per step (µs) | `Robot::rollout_derivatives_into`, per step (µs) | ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
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
        let (step, with) = medians_ns(
            1001,
            || {
                std::hint::black_box(robot.step(&z, &u, dt).expect("step"));
            },
            || {
                std::hint::black_box(robot.step_derivatives(&z, &u, dt).expect("derivatives"));
            },
        );
        // the same pair on the engine with caller-owned slices (what a
        // control loop keeps between calls): every joint driven, input i
        // on body i, from the same state on every call
        let engine = robot.engine();
        let inputs: Vec<usize> = (0..n).collect();
        let mut p0 = vec![0.0; n];
        let mut ws = vec![BodyScratch::zeroed(); n];
        engine.momentum_of(&z.q, &z.v, &mut p0, &mut ws)?;
        let mut ws2 = ws.clone();
        let (mut q1, mut v1, mut p1) = (z.q.clone(), z.v.clone(), p0.clone());
        let (mut q2, mut v2, mut p2) = (z.q.clone(), z.v.clone(), p0.clone());
        let (mut a, mut b) = (vec![0.0; 4 * n * n], vec![0.0; 2 * n * n]);
        let mut scratch = vec![0.0; derivative_scratch_len(n, n)];
        let (slice_step, slice_with) = medians_ns(
            1001,
            || {
                q1.copy_from_slice(&z.q);
                v1.copy_from_slice(&z.v);
                p1.copy_from_slice(&p0);
                engine
                    .step(&mut q1, &mut v1, &mut p1, &u, dt, &mut ws)
                    .expect("step");
                std::hint::black_box(&v1);
            },
            || {
                q2.copy_from_slice(&z.q);
                v2.copy_from_slice(&z.v);
                p2.copy_from_slice(&p0);
                let out = DerivativeBuffers {
                    a: &mut a,
                    b: &mut b,
                    scratch: &mut scratch,
                    start_known: false,
                };
                engine
                    .step_derivatives(&mut q2, &mut v2, &mut p2, &u, &inputs, dt, out, &mut ws2)
                    .expect("derivatives");
                std::hint::black_box(&a);
            },
        );
        // per step of a driven rollout from the same state: what an iLQR
        // linearisation of a trajectory pays on every cycle (the
        // derivatives' start terms carried from the step before, both
        // loops starting each iteration from the extrapolation of the last
        // velocities, the derivatives' matrices kept between calls)
        let inputs_k = vec![u.clone(); ROLLOUT_STEPS];
        let mut kept = Vec::new();
        let (roll_step, roll_with) = medians_ns(
            ROLLOUT_REPS,
            || {
                let r = robot.rollout_with(&z, dt, ROLLOUT_STEPS, |k, _| inputs_k[k].clone());
                std::hint::black_box(r.expect("rollout"));
            },
            || {
                robot
                    .rollout_derivatives_into(&z, &inputs_k, dt, &mut kept)
                    .expect("rollout derivatives");
                std::hint::black_box(&kept);
            },
        );
        let per = 1e-3 / ROLLOUT_STEPS as f64;
        println!(
            "| {name} | {n} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            step * 1e-3,
            with * 1e-3,
            with / step,
            slice_step * 1e-3,
            slice_with * 1e-3,
            slice_with / slice_step,
            roll_step * per,
            roll_with * per,
            roll_with / roll_step
        );
    }
    Ok(())
}

/// Steps of the driven rollouts of [`derivatives`], and how many of each
/// are timed.
const ROLLOUT_STEPS: usize = 100;
const ROLLOUT_REPS: usize = 31;
