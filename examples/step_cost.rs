//! Cost of the fixed-size (`vigp::embedded`) step.
//!
//! **Wall-time table** (`cargo run --profile bench --example step_cost -- table`):
//! for every system, 64 states spread over a long trajectory (so that the
//! angle ranges `libm::sincos` reduces are all visited), the time of a step
//! from a state (the embedded `Stepper::step`, which zeroes its solver
//! scratch at every call, and the std `vigp::Variational::step`, which keeps
//! the scratch of larger systems per thread) and of a 100-step rollout per
//! step. Each entry is the
//! minimum over 15 repetitions of the mean over the 64 states: on a shared
//! machine the minimum estimates the uninterrupted cost (criterion medians
//! from `cargo bench --bench step` include interference).
//!
//! **Newton iterations** (`… --example step_cost -- iterations [steps]`): the
//! mean and largest iteration count per step of a rollout of the double
//! pendulum and the fourbar's modes, and of steps from the same states
//! (momentum from the state, Newton started at its velocity).
//!
//! **Instruction counts** (load-independent):
//!
//! ```text
//! cargo build --profile bench --example step_cost
//! valgrind --tool=callgrind target/release/examples/step_cost double_pendulum 1000
//! valgrind --tool=callgrind target/release/examples/step_cost double_pendulum 0
//! ```
//!
//! The difference of the two totals divided by the step count is the
//! instruction count of one rollout step (`driven_step` and `driven_step_ab`
//! instead of a system name: a forced step of the actuated double pendulum
//! without and with its exact A and B; `driven_midpoint_step[_ab]` for the
//! midpoint rule; `fourbar_maximal_single`: single steps from the states of
//! a rollout, whose instruction count minus that of `fourbar_maximal` with
//! the same count is the cost of the steps from a state;
//! `fourbar_maximal_single_in` the same in a kept workspace); `callgrind_annotate` splits it by
//! function (build with `--release` instead to keep functions apart).

use nalgebra::SVector;
use vigp::embedded::{Dynamics, State, Stepper};
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

fn run<M: Dynamics<N, C> + Copy, const N: usize, const C: usize>(
    sys: M,
    z0: State<N>,
    steps: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let s = Stepper::new(sys, 0.01)?;
    let mut out = vec![z0; steps + 1];
    let t = std::time::Instant::now();
    s.rollout_into(&z0, &mut out).map_err(|e| format!("{e}"))?;
    let dt = t.elapsed().as_secs_f64();
    if steps > 0 {
        println!(
            "{steps} steps, {:.0} ns per step (one run), final q = {:?}",
            dt / steps as f64 * 1e9,
            out[steps].q.as_slice()
        );
    }
    Ok(())
}

/// `steps` single steps from the states of a `steps`-step rollout (the
/// cost of a step from a state, which computes the momentum and starts
/// Newton without a previous velocity); the rollout's own cost is that of
/// [`run`] with the same count. `kept`: in one kept
/// [`vigp::embedded::StepWorkspace`] ([`Stepper::step_in`]) instead of a
/// fresh one per step ([`Stepper::step`]).
fn run_single<M: Dynamics<N, C> + Copy, const N: usize, const C: usize>(
    sys: M,
    z0: State<N>,
    steps: usize,
    kept: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let s = Stepper::new(sys, 0.01)?;
    let mut out = vec![z0; steps + 1];
    s.rollout_into(&z0, &mut out).map_err(|e| format!("{e}"))?;
    let mut ws = vigp::embedded::StepWorkspace::new();
    let mut sum = 0.0;
    for z in &out[..steps] {
        let z = std::hint::black_box(z);
        let z1 = if kept {
            s.step_in(z, &mut ws)
        } else {
            s.step(z)
        };
        sum += z1.map_err(|e| format!("{e}"))?.q[0];
    }
    let how = if kept { " in a kept workspace" } else { "" };
    println!("{steps} single steps{how}, sum of q[0] = {sum}");
    Ok(())
}

/// Mean Newton iterations per step ([`vigp::embedded::StepReport`]) of a
/// `steps`-step rollout from `z0`, replaying [`Stepper::steps_into`]
/// (carried momentum, Newton started at 2v_k − v_{k−1}) through the public
/// [`Stepper::solve`], which returns each step's report.
fn iterations<M: Dynamics<N, C> + Copy, const N: usize, const C: usize>(
    name: &str,
    sys: M,
    z0: State<N>,
    steps: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let s = Stepper::new(sys, 0.01)?;
    let (mut z, mut p, mut v_prev) = (z0, s.momentum(&z0), z0.v);
    let (mut total, mut most) = (0usize, 0usize);
    let (mut total_single, mut most_single) = (0usize, 0usize);
    for _ in 0..steps {
        let x1 = z.q + z.v * s.dt();
        let guess = z.v * 2.0 - v_prev;
        let (v1, p1, r) = s.solve(&x1, &p, s.dt(), &guess)?;
        (total, most) = (total + r.iterations, most.max(r.iterations));
        // the same state stepped from scratch (momentum from z, Newton
        // started at v)
        let (_, r1) = s.step_with_report(&z)?;
        (total_single, most_single) =
            (total_single + r1.iterations, most_single.max(r1.iterations));
        v_prev = z.v;
        (z, p) = (State { q: x1, v: v1 }, p1);
    }
    println!(
        "| {name} | {:.3} | {most} | {:.3} | {most_single} |",
        total as f64 / steps.max(1) as f64,
        total_single as f64 / steps.max(1) as f64
    );
    Ok(())
}

/// Mean time per step (ns) of `step`, of the std `Variational::step` and
/// of a 100-step rollout over 64
/// states taken every 50 steps of a trajectory from `z0`; minimum over 15
/// repetitions.
fn table_row<M: vigp::Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    name: &str,
    sys: M,
    z0: State<N>,
) -> Result<(), Box<dyn std::error::Error>> {
    use std::hint::black_box;
    use std::time::Instant;
    let s = Stepper::new(sys, 0.01)?;
    let vi = vigp::Variational::new(sys, 0.01)?;
    let mut long = vec![z0; 64 * 50 + 1];
    s.rollout_into(&z0, &mut long).map_err(|e| format!("{e}"))?;
    let states: Vec<State<N>> = long.iter().step_by(50).take(64).copied().collect();
    let mut out = [z0; 101];
    let (mut best_step, mut best_roll) = (f64::INFINITY, f64::INFINITY);
    let mut best_std = f64::INFINITY;
    for _ in 0..15 {
        let t = Instant::now();
        for _ in 0..20 {
            for z in &states {
                black_box(s.step(black_box(z)).map_err(|e| format!("{e}"))?);
            }
        }
        best_step = best_step.min(t.elapsed().as_secs_f64() / (20.0 * 64.0));
        let t = Instant::now();
        for _ in 0..20 {
            for z in &states {
                black_box(vi.step(black_box(z)).map_err(|e| format!("{e}"))?);
            }
        }
        best_std = best_std.min(t.elapsed().as_secs_f64() / (20.0 * 64.0));
        let t = Instant::now();
        for z in &states {
            s.rollout_into(black_box(z), &mut out)
                .map_err(|e| format!("{e}"))?;
            black_box(&out);
        }
        best_roll = best_roll.min(t.elapsed().as_secs_f64() / (64.0 * 100.0));
    }
    println!(
        "| {name} | {:.0} ns | {:.0} ns | {:.0} ns |",
        best_step * 1e9,
        best_std * 1e9,
        best_roll * 1e9
    );
    Ok(())
}

#[path = "../benches/common/driven_double_pendulum.rs"]
mod driven_double_pendulum;
use driven_double_pendulum::DrivenDoublePendulum;

/// `steps` forced steps of the driven double pendulum from the states of
/// a trajectory, with (`ab`) or without their exact A and B: the
/// instruction counts of the two runs give the cost of the derivatives.
fn derivatives(
    midpoint: bool,
    with_ab: bool,
    steps: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let sys = DrivenDoublePendulum::default();
    let s = if midpoint {
        Stepper::midpoint(sys, 0.01)?
    } else {
        Stepper::new(sys, 0.01)?
    };
    let u = SVector::<f64, 2>::new(0.3, -0.2);
    let mut z = State::new([1.0, -0.5], [0.5, 1.0]);
    let mut trace = 0.0;
    for _ in 0..steps {
        z = if with_ab {
            let (z1, d) = s.step_with_derivatives(&z, &u)?;
            trace += d.a.v_v.trace() + d.b.v_u[(0, 0)];
            z1
        } else {
            s.step_forced(&z, &u)?
        };
    }
    println!(
        "{steps} steps (A and B: {with_ab}), final q = {:?}, {trace:.3}",
        z.q
    );
    Ok(())
}

/// The fourbar and the consistent start state every fourbar mode uses.
/// The fourbar with damping 0.1 on every joint (the maximal Newton matrix
/// −M − a·D is then non-diagonal).
fn with_joint_damping(mut fb: Fourbar) -> Fourbar {
    for j in [
        &mut fb.joints.top1,
        &mut fb.joints.middle1,
        &mut fb.joints.top2,
        &mut fb.joints.middle2,
        &mut fb.joints.bottom,
    ] {
        j.damping = 0.1;
    }
    fb
}

fn fourbar_start() -> Result<(Fourbar, State<4>), Box<dyn std::error::Error>> {
    let fb = Fourbar::default();
    let z0 = consistent_state(
        &fb.minimal(),
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::from([0.5, 0.0, 0.0, 0.0]),
        0.01,
    )?;
    Ok((fb, z0))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("table") {
        let (fb, fb_z0) = fourbar_start()?;
        println!(
            "| system | step from a state | std `Variational::step` | per step of a rollout |"
        );
        println!("|---|---|---|---|");
        use vigp::Coordinates;
        table_row(
            "pendulum",
            Pendulum::default().minimal(),
            State::new([1.0], [0.5]),
        )?;
        table_row(
            "cartpole",
            Cartpole::default().minimal(),
            State::new([0.2, 2.0], [0.3, 0.5]),
        )?;
        table_row(
            "double pendulum",
            DoublePendulum::default().minimal(),
            State::new([1.0, -0.5], [0.5, 1.0]),
        )?;
        table_row("fourbar", fb.minimal(), fb_z0)?;
        return table_row(
            "fourbar (maximal)",
            fb.maximal(),
            fb.minimal().to_maximal(&fb_z0, 0.01),
        );
    }
    let system = args.get(1).map_or("double_pendulum", String::as_str);
    let steps: usize = match args.get(2) {
        Some(s) => s.parse()?,
        None => 1000,
    };
    if system == "iterations" {
        use vigp::Coordinates;
        let (fb, fb_z0) = fourbar_start()?;
        let damped = with_joint_damping(fb);
        println!(
            "| system ({steps}-step rollout) | Newton iterations per step | most | from a state | most |"
        );
        println!("|---|---|---|---|---|");
        iterations(
            "double pendulum",
            DoublePendulum::default(),
            State::new([1.0, -0.5], [0.5, 1.0]),
            steps,
        )?;
        iterations("fourbar", fb, fb_z0, steps)?;
        iterations(
            "fourbar (maximal)",
            fb.maximal(),
            fb.minimal().to_maximal(&fb_z0, 0.01),
            steps,
        )?;
        return iterations(
            "fourbar (maximal, damped)",
            damped.maximal(),
            damped.minimal().to_maximal(&fb_z0, 0.01),
            steps,
        );
    }
    match system {
        "driven_step" => derivatives(false, false, steps),
        "driven_step_ab" => derivatives(false, true, steps),
        "driven_midpoint_step" => derivatives(true, false, steps),
        "driven_midpoint_step_ab" => derivatives(true, true, steps),
        "pendulum" => run(Pendulum::default(), State::new([1.0], [0.5]), steps),
        "cartpole" => run(
            Cartpole::default(),
            State::new([0.2, 2.0], [0.3, 0.5]),
            steps,
        ),
        "double_pendulum" => run(
            DoublePendulum::default(),
            State::new([1.0, -0.5], [0.5, 1.0]),
            steps,
        ),
        "fourbar_maximal_single" => {
            let (fb, z0) = fourbar_start()?;
            use vigp::Coordinates;
            run_single(fb.maximal(), fb.minimal().to_maximal(&z0, 0.01), steps, false)
        }
        "fourbar_maximal_single_in" => {
            let (fb, z0) = fourbar_start()?;
            use vigp::Coordinates;
            run_single(fb.maximal(), fb.minimal().to_maximal(&z0, 0.01), steps, true)
        }
        "fourbar_maximal" => {
            let (fb, z0) = fourbar_start()?;
            use vigp::Coordinates;
            run(fb.maximal(), fb.minimal().to_maximal(&z0, 0.01), steps)
        }
        "fourbar" => {
            let (fb, z0) = fourbar_start()?;
            run(fb, z0, steps)
        }
        // joint damping makes the maximal Newton matrix −M − a·D
        // non-diagonal: the general (LU + sparse Schur) KKT path
        "fourbar_maximal_damped" => {
            let (fb, z0) = fourbar_start()?;
            let fb = with_joint_damping(fb);
            use vigp::Coordinates;
            run(fb.maximal(), fb.minimal().to_maximal(&z0, 0.01), steps)
        }
        other => Err(format!(
            "unknown system {other:?}: pendulum, cartpole, double_pendulum, fourbar, fourbar_maximal or fourbar_maximal_damped"
        )
        .into()),
    }
}
