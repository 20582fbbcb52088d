//! The fourbar segment in minimal coordinates: a loop closed by a constraint,
//! swinging through the folded pose where the loop Jacobian loses rank.
//!
//! Run: `cargo run --release --example fourbar`

use nalgebra::SVector;
use vigp::prelude::*;
use vigp::projection::consistent_state;

// the rhombus of four links hanging from one pivot, closed at the bottom, as
// declared in `vigp::systems` (src/systems.rs)
use vigp::systems::Fourbar;

fn main() -> Result<(), StepError> {
    let dt = 0.01;
    let mut sys = Fourbar::default();
    // a rough guess of an opened rhombus, made consistent (positions on
    // g(q) = 0, discrete velocity with g(q + dt v) = 0)
    let guess = SVector::from([0.9, -1.25, -0.4, 1.35]);
    let z0 = consistent_state(&sys.minimal(), &guess, &SVector::zeros(), dt)?;
    println!(
        "fourbar, dt = {dt} s, consistent start q = {:.4?}",
        z0.q.as_slice()
    );
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  conservative: {s}");
    sys.joints.top1.damping = 1.0;
    sys.joints.middle1.damping = 0.25;
    sys.joints.middle2.damping = 0.25;
    let model = sys.minimal();
    let s = vigp::summarize(&Variational::new(model, dt)?, &model, &z0, 10_000)?;
    println!("  damped:       {s}");
    Ok(())
}
