//! Planar kinematics helpers called by generated forward kinematics.
//!
//! Conventions (DESIGN §2): a link's local frame sits at its `start`, its
//! local x-axis runs to its `end`; θ = 0 means the link hangs straight down
//! (local x-axis along world −y); counter-clockwise is positive. A local
//! point (a, b) maps to `origin + a·(sin θ, −cos θ) + b·(cos θ, sin θ)`.

use crate::mechanism::Scalar;
use nalgebra::SVector;
use num_dual::Dual;

/// A planar point in world coordinates (x right, y up).
pub type Point2<D> = [D; 2];

/// The pose of a link frame: origin (the link's `start`) and orientation,
/// with sin θ and cos θ computed once (on nested dual numbers they are the
/// most expensive part of the kinematics).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose2<D> {
    /// World x of the frame origin.
    pub x: D,
    /// World y of the frame origin.
    pub y: D,
    /// Orientation θ (0 = hanging down, counter-clockwise positive).
    pub theta: D,
    /// sin θ.
    pub sin: D,
    /// cos θ.
    pub cos: D,
}

impl<D: Scalar> Pose2<D> {
    /// The pose with orientation `theta` that places the local point `local`
    /// at the world point `at`.
    pub fn attach(theta: D, at: Point2<D>, local: [f64; 2]) -> Self {
        let [a, b] = local;
        let (s, c) = theta.sin_cos();
        Self {
            x: at[0] - (s * a + c * b),
            y: at[1] - (s * b - c * a),
            theta,
            sin: s,
            cos: c,
        }
    }

    /// World direction of a local direction (rotation only).
    pub fn direction(&self, local: [f64; 2]) -> Point2<D> {
        let [a, b] = local;
        let (s, c) = (self.sin, self.cos);
        [s * a + c * b, s * b - c * a]
    }

    /// World position of a local point.
    pub fn point(&self, local: [f64; 2]) -> Point2<D> {
        let [dx, dy] = self.direction(local);
        [self.x + dx, self.y + dy]
    }
}

/// A world-fixed point as a scalar point.
pub fn world<D: Scalar>(p: [f64; 2]) -> Point2<D> {
    [D::from(p[0]), D::from(p[1])]
}

/// `p + s·dir`: a point slid by `s` along a direction.
pub fn slide<D: Scalar>(p: Point2<D>, dir: Point2<D>, s: D) -> Point2<D> {
    [p[0] + dir[0] * s, p[1] + dir[1] * s]
}

/// `a − b` componentwise.
pub fn sub<D: Scalar>(a: Point2<D>, b: Point2<D>) -> Point2<D> {
    [a[0] - b[0], a[1] - b[1]]
}

/// 2-D cross product a × b = a_x b_y − a_y b_x.
pub fn cross<D: Scalar>(a: Point2<D>, b: Point2<D>) -> D {
    a[0] * b[1] - a[1] * b[0]
}

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

/// Zero of any scalar (the world's orientation).
pub fn zero<D: Scalar>() -> D {
    D::from(0.0)
}

/// Local coordinates of the centre of a link of length `length`:
/// `[length/2, 0]`.
pub fn center(length: f64) -> [f64; 2] {
    [length * 0.5, 0.0]
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
