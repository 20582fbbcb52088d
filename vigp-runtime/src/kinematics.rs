//! Planar kinematics helpers called by generated forward kinematics.
//!
//! Conventions (the DSL's, see the `mechanism!` docs): a link's local frame sits at its `start`, its
//! local x-axis runs to its `end`; θ = 0 means the link hangs straight down
//! (local x-axis along world −y); counter-clockwise is positive. A local
//! point (a, b) maps to `origin + a·(sin θ, −cos θ) + b·(cos θ, sin θ)`.

use crate::mechanism::Scalar;
use nalgebra::SVector;
use num_dual::Dual;

pub use vigp_core::kinematics::{Point2, Pose2, center, cross, slide, sub, world, zero};

/// Lift (q, v) to first-order duals q + ε v: any function of the lifted
/// positions carries its time derivative along v in the ε part.
pub fn tangent<D: Scalar, const N: usize>(
    q: &SVector<D, N>,
    v: &SVector<D, N>,
) -> SVector<Dual<D>, N> {
    q.zip_map(v, Dual::new)
}

/// Kinetic energy of one planar rigid body from the tangent of its
/// centre-of-mass position and orientation: ½ m |ṗ|² + ½ J θ̇².
pub fn body_kinetic_energy<D: Scalar>(
    mass: f64,
    inertia: f64,
    com: Point2<Dual<D>>,
    theta: Dual<D>,
) -> D {
    let (vx, vy, w) = (com[0].eps, com[1].eps, theta.eps);
    (vx * vx + vy * vy) * (0.5 * mass) + w * w * (0.5 * inertia)
}

/// Potential energy −m g·p of one body with centre of mass at `com`.
pub fn body_potential_energy<D: Scalar>(mass: f64, gravity: [f64; 2], com: Point2<D>) -> D {
    (com[0] * gravity[0] + com[1] * gravity[1]) * (-mass)
}

/// Lagrangian T − V of one body from the tangent of its centre of mass and
/// orientation: the positions are the real parts, so one tangent pass of the
/// kinematics yields both energies.
pub fn body_lagrangian<D: Scalar>(
    mass: f64,
    inertia: f64,
    gravity: [f64; 2],
    com: Point2<Dual<D>>,
    theta: Dual<D>,
) -> D {
    body_kinetic_energy(mass, inertia, com, theta)
        - body_potential_energy(mass, gravity, [com[0].re, com[1].re])
}
