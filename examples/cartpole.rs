//! A cartpole (`vigp::systems::Cartpole`, declared with the DSL in src/systems.rs:
//! prismatic rail + revolute pole), conservative and damped.
//!
//! Run: `cargo run --release --example cartpole`

use vigp::prelude::*;

// the cart on a horizontal rail with a pole pinned at its centre, as declared
// in `vigp::systems` (src/systems.rs)
use vigp::systems::Cartpole;

fn main() -> Result<(), StepError> {
    let dt = 0.01;
    let mut sys = Cartpole::default();
    let z0 = State::new([0.0, 2.5], [0.5, 0.0]);
    println!("cartpole, dt = {dt} s, pole at 2.5 rad, cart moving at 0.5 m/s");
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  conservative:           {s}");
    sys.joints.rail.damping = 0.25;
    sys.joints.hinge.damping = 0.5;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  damped c1=0.25, c2=0.5: {s}");
    Ok(())
}
