//! A cartpole declared with the DSL (prismatic rail + revolute pole).
//!
//! Run: `cargo run --release --example cartpole`

use vigp::prelude::*;

vigp::mechanism! {
    /// A cart on a horizontal rail with a pole pinned at its centre.
    pub Cartpole {
        gravity: [0.0, -9.81],
        links {
            cart: { mass: 1.0, length: 1.0 },
            pole: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], damping: 0.0 },
            hinge: revolute(cart.center, pole.start) { damping: 0.0 },
        }
    }
}

fn main() -> Result<(), StepError> {
    let dt = 0.01;
    let mut sys = Cartpole::default();
    let z0 = State::new([0.0, 2.5], [0.5, 0.0]);
    println!("cartpole, dt = {dt} s, pole at 2.5 rad, cart moving at 0.5 m/s");
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt), &model, &z0, 10_000)?;
    println!("  conservative:           {s}");
    sys.joints.rail.damping = 0.25;
    sys.joints.hinge.damping = 0.5;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt), &model, &z0, 10_000)?;
    println!("  damped c1=0.25, c2=0.5: {s}");
    Ok(())
}
