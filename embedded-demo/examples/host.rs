//! Runs the `no_std` demo on the host and prints a prediction.
//!
//! `cargo run --release -p vigp-embedded-demo --example host`

use vigp::embedded::State;
use vigp_embedded_demo::{DT, energy, predict, stepper};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let s = stepper()?;
    let z0 = State::new([1.0, -0.5], [0.0, 0.0]);
    let mut out = [z0; 501];
    let t = std::time::Instant::now();
    predict(&s, &z0, &mut out)?;
    let per_step = t.elapsed().as_secs_f64() / 500.0;
    for (k, z) in out.iter().enumerate().step_by(100) {
        println!(
            "t = {:4.2} s  q = [{:+.4}, {:+.4}]  E = {:.5} J",
            k as f64 * DT,
            z.q[0],
            z.q[1],
            energy(z)
        );
    }
    println!(
        "{:.0} ns per step (one run, not a benchmark)",
        per_step * 1e9
    );
    Ok(())
}
