//! A `#![no_std]` program on **vigp**, as firmware would use it: the
//! mechanism is declared with `vigp::mechanism!` (no `std` feature, so only
//! the fixed-size items are generated), stepped by
//! [`vigp::embedded::Stepper`] on stack data, and nothing allocates.
//!
//! `cargo check -p vigp-embedded-demo` builds this crate with `vigp`'s
//! default features off: `vigp`, `vigp-core`, `nalgebra` and `libm` all
//! compile as `no_std`. `cargo run -p vigp-embedded-demo --example host`
//! runs it on the host.

#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use vigp::embedded::{Composition, RolloutError, State, StepError, Stepper};

pub mod learned;

vigp::mechanism! {
    /// The paper's double pendulum: two 1 m, 1 kg links hanging from the
    /// origin, a damped elbow.
    pub DoublePendulum {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start),
            elbow: revolute(upper.end, lower.start) { damping: 0.05 },
        }
    }
}

/// Control period (s).
pub const DT: f64 = 0.01;

/// The controller's model: the generated mechanism behind the fixed-size
/// first-order variational step.
pub fn stepper() -> Result<Stepper<DoublePendulum, 2, 0>, StepError> {
    Stepper::new(DoublePendulum::default(), DT)
}

/// An MPC-style prediction: `K` steps from `z0` into a caller-owned array
/// (`out[0] = z0`). No allocation.
pub fn predict<const K: usize>(
    stepper: &Stepper<DoublePendulum, 2, 0>,
    z0: &State<2>,
    out: &mut [State<2>; K],
) -> Result<(), RolloutError> {
    stepper.rollout_into(z0, out)
}

/// The second-order (midpoint) variational step in **maximal coordinates**
/// (x, y, θ of each link; the joints are 4 constraints held at position
/// level every step), two sub-steps per control period: the fixed-size path
/// runs every rule and view without allocation.
pub fn maximal_midpoint_stepper() -> Result<Stepper<DoublePendulumMaximal, 6, 4>, StepError> {
    Stepper::midpoint(DoublePendulum::default().maximal(), DT)?.substeps(2)
}

/// The fourth-order variational integrator (Suzuki's composition of the
/// midpoint step); its state velocity is the continuous q̇.
pub fn fourth_order() -> Result<Composition<DoublePendulum, 2, 0>, StepError> {
    Composition::new(DoublePendulum::default(), DT)
}

/// Total energy of a state (J), for monitoring.
pub fn energy(z: &State<2>) -> f64 {
    vigp::embedded::model::energy(&DoublePendulum::default(), &z.q, &z.v)
}
