//! A 29-joint humanoid read from its URDF steps in an unoptimised build on
//! the 8 MB stack of a program's main thread: the first-order step, the
//! midpoint step, and the step with its exact derivative A.
//!
//! This package's test profile is unoptimised (the root Cargo.toml), so the
//! generic steps are monomorphised here as in a user's dev build. Its
//! kinematics carries jets in N = 29 directions, and an unoptimised build
//! keeps a copy of every array returned by value in each frame it passes
//! through: this is where the stack would overflow (docs/robots.md,
//! "Build time").

use vigp::embedded::{State, Stepper};
use vigp::prelude::SVector;

vigp::mechanism! {
    /// The Unitree G1 humanoid on a fixed base (example-robot-data).
    pub Humanoid { urdf: "../tests/fixtures/robots/g1.urdf" }
}

/// The main thread's stack on Linux (`ulimit -s`: 8192 KB).
const MAIN_STACK: usize = 8 << 20;

#[test]
fn a_humanoid_steps_on_a_main_thread_stack_unoptimised() {
    let steps = std::thread::Builder::new()
        .stack_size(MAIN_STACK)
        .spawn(|| {
            let model = Humanoid::default().minimal();
            let z0: State<29> = State::new([0.1; 29], [0.0; 29]);
            let first = Stepper::new(model, 0.002).unwrap().step(&z0).unwrap();
            let mid = Stepper::midpoint(model, 0.002).unwrap().step(&z0).unwrap();
            let (with_a, d) = Stepper::new(model, 0.002)
                .unwrap()
                .step_with_derivatives(&z0, &SVector::<f64, 0>::zeros())
                .unwrap();
            (first, mid, with_a, d.a.matrix::<58>())
        })
        .unwrap()
        .join()
        .unwrap();
    let (first, mid, with_a, a) = steps;
    assert!(first.is_finite() && mid.is_finite());
    assert_eq!(with_a, first);
    assert!(a.iter().all(|x| x.is_finite()));
    // gravity moves the humanoid's joints from rest
    assert!((first.v).amax() > 0.0 && (mid.v).amax() > 0.0);
}
