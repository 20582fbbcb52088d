//! The double pendulum of the README's first example: a chaotic conservative rollout whose
//! energy error stays bounded, and a damped one.
//!
//! Run: `cargo run --release --example double_pendulum`

use std::f64::consts::FRAC_PI_2;
use vigp::prelude::*;

vigp::mechanism! {
    /// A double pendulum hanging from the origin.
    pub DoublePendulum {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0, inertia: 0.0833 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.0 },
            elbow: revolute(upper.end, lower.start),
        }
    }
}

fn main() -> Result<(), StepError> {
    let mut sys = DoublePendulum::default();
    let z0 = State::new([FRAC_PI_2, 0.0], [0.0, 0.0]);
    println!("double pendulum from (π/2, 0) at rest");
    for dt in [0.01, 0.005] {
        let model = sys.minimal();
        let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 100_000)?;
        println!("  conservative, dt = {dt}: {s}");
    }
    sys.joints.shoulder.damping = 1.0;
    sys.joints.elbow.damping = 0.3;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, 0.01)?, &model, &z0, 10_000)?;
    println!("  damped, dt = 0.01:     {s}");
    Ok(())
}
