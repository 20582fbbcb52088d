//! A pendulum declared with the DSL: the nominal variational integrator
//! against the closed form of its first step, and a 10^4-step summary.
//!
//! Run: `cargo run --release --example pendulum`

use std::f64::consts::FRAC_PI_2;
use vigp::prelude::*;

vigp::mechanism! {
    /// A 1 m, 1 kg rod on a pivot at the origin.
    pub Pendulum {
        gravity: [0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: 0.0 },
        }
    }
}

fn main() -> Result<(), StepError> {
    let dt = 0.01;
    let mut sys = Pendulum::default();
    let z0 = State::new([FRAC_PI_2], [0.0]);

    println!("pendulum, dt = {dt} s, from θ = π/2 at rest");
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt), &model, &z0, 10_000)?;
    println!("  conservative: {s}");

    sys.joints.pivot.damping = 0.5;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt), &model, &z0, 10_000)?;
    println!("  damped c=0.5: {s}");
    Ok(())
}
