//! The pendulum of `vigp::systems` (declared with the DSL in src/systems.rs):
//! the nominal variational integrator against the closed form of its first
//! step, and a 10^4-step summary.
//!
//! Run: `cargo run --release --example pendulum`

use std::f64::consts::FRAC_PI_2;
use vigp::prelude::*;

// the 1 m, 1 kg rod on a pivot at the origin, as declared in
// `vigp::systems` (src/systems.rs)
use vigp::systems::Pendulum;

fn main() -> Result<(), StepError> {
    let dt = 0.01;
    let mut sys = Pendulum::default();
    let z0 = State::new([FRAC_PI_2], [0.0]);

    println!("pendulum, dt = {dt} s, from θ = π/2 at rest");
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  conservative: {s}");

    sys.joints.pivot.damping = 0.5;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  damped c=0.5: {s}");
    Ok(())
}
