//! Cost of the fixed-size (`vigp::embedded`) step for instruction counting.
//!
//! ```text
//! cargo build --release --example step_cost
//! valgrind --tool=callgrind target/release/examples/step_cost double_pendulum 1000
//! valgrind --tool=callgrind target/release/examples/step_cost double_pendulum 0
//! ```
//!
//! The difference of the two totals divided by the step count is the
//! instruction count of one rollout step (load-independent, unlike wall
//! time); `callgrind_annotate` splits it by function. Without valgrind it
//! prints wall time per step (one run: use `cargo bench --bench step` for
//! medians).

use nalgebra::SVector;
use vigp::embedded::{Model, State, Stepper};
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

fn run<M: Model<N, C> + Copy, const N: usize, const C: usize>(
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

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let system = args.get(1).map_or("double_pendulum", String::as_str);
    let steps: usize = match args.get(2) {
        Some(s) => s.parse()?,
        None => 1000,
    };
    match system {
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
        "fourbar" => {
            let fb = Fourbar::default();
            let z0 = consistent_state(
                &fb.minimal(),
                &SVector::from([0.9, -1.3, -0.4, 1.3]),
                &SVector::from([0.5, 0.0, 0.0, 0.0]),
                0.01,
            )?;
            run(fb, z0, steps)
        }
        other => Err(format!(
            "unknown system {other:?}: pendulum, cartpole, double_pendulum or fourbar"
        )
        .into()),
    }
}
