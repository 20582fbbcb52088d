//! Planar kinematics helpers called by generated forward kinematics,
//! generic over any [`Real`].
//!
//! Conventions (the DSL's, see the `mechanism!` docs): a link's local frame sits at its `start`, its
//! local x-axis runs to its `end`; θ = 0 means the link hangs straight down
//! (local x-axis along world −y); counter-clockwise is positive. A local
//! point (a, b) maps to `origin + a·(sin θ, −cos θ) + b·(cos θ, sin θ)`.

use crate::real::Real;

/// A planar point in world coordinates (x right, y up).
pub type Point2<D> = [D; 2];

/// The pose of a link frame: origin (the link's `start`) and orientation,
/// with sin θ and cos θ computed once (on nested dual numbers and jets they
/// are the most expensive part of the kinematics).
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

impl<D: Real> Pose2<D> {
    /// The pose with orientation `theta` that places the local point `local`
    /// at the world point `at`.
    #[inline]
    pub fn attach(theta: D, at: Point2<D>, local: [f64; 2]) -> Self {
        let [a, b] = local;
        let (s, c) = theta.sincos();
        Self {
            x: at[0] - (s * a + c * b),
            y: at[1] - (s * b - c * a),
            theta,
            sin: s,
            cos: c,
        }
    }

    /// The pose with orientation `theta` whose origin (the link's `start`)
    /// is at `at`: [`Pose2::attach`] with `local = [0, 0]`, without the
    /// products by zero.
    #[inline]
    pub fn attach_start(theta: D, at: Point2<D>) -> Self {
        let (s, c) = theta.sincos();
        Self {
            x: at[0],
            y: at[1],
            theta,
            sin: s,
            cos: c,
        }
    }

    /// World position of the local point (a, 0) on the link's axis (its
    /// `end` for a = length): [`Pose2::point`] without the products by zero.
    #[inline]
    pub fn point_on_axis(&self, a: f64) -> Point2<D> {
        [self.x + self.sin * a, self.y - self.cos * a]
    }

    /// World direction of a local direction (rotation only).
    #[inline]
    pub fn direction(&self, local: [f64; 2]) -> Point2<D> {
        let [a, b] = local;
        let (s, c) = (self.sin, self.cos);
        [s * a + c * b, s * b - c * a]
    }

    /// World position of a local point. A point on the link's axis
    /// (`local[1] == 0`, e.g. every default centre of mass) takes the
    /// [`Pose2::point_on_axis`] path, which skips the products by zero (on
    /// jets and dual numbers these are whole-derivative operations); the
    /// result is the same up to the sign of a zero.
    #[inline]
    pub fn point(&self, local: [f64; 2]) -> Point2<D> {
        if local[1] == 0.0 {
            return self.point_on_axis(local[0]);
        }
        let [dx, dy] = self.direction(local);
        [self.x + dx, self.y + dy]
    }
}

/// A world-fixed point as a scalar point.
#[inline]
pub fn world<D: Real>(p: [f64; 2]) -> Point2<D> {
    [D::from_f64(p[0]), D::from_f64(p[1])]
}

/// `p + s·dir`: a point slid by `s` along a direction.
#[inline]
pub fn slide<D: Real>(p: Point2<D>, dir: Point2<D>, s: D) -> Point2<D> {
    [p[0] + dir[0] * s, p[1] + dir[1] * s]
}

/// `a − b` componentwise.
#[inline]
pub fn sub<D: Real>(a: Point2<D>, b: Point2<D>) -> Point2<D> {
    [a[0] - b[0], a[1] - b[1]]
}

/// 2-D cross product a × b = a_x b_y − a_y b_x.
#[inline]
pub fn cross<D: Real>(a: Point2<D>, b: Point2<D>) -> D {
    a[0] * b[1] - a[1] * b[0]
}

/// Zero of any scalar (the world's orientation).
#[inline]
pub fn zero<D: Real>() -> D {
    D::from_f64(0.0)
}

/// Local coordinates of the centre of a link of length `length`:
/// `[length/2, 0]`.
#[inline]
pub fn center(length: f64) -> [f64; 2] {
    [length * 0.5, 0.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The zero-skipping constructors equal the general ones exactly
    /// (they drop only additions of ±0 and products by 0).
    #[test]
    fn shortcuts_equal_the_general_forms() {
        for theta in [-2.5f64, -0.3, 0.0, 0.7, 3.0] {
            let at: [f64; 2] = [0.4, -1.2];
            let (a, b) = (
                Pose2::attach_start(theta, at),
                Pose2::attach(theta, at, [0.0, 0.0]),
            );
            assert_eq!((a.x, a.y, a.sin, a.cos), (b.x, b.y, b.sin, b.cos));
            for len in [0.0, 0.5, 1.7] {
                assert_eq!(a.point_on_axis(len), a.point([len, 0.0]));
            }
            // a local point is placed at `at`
            let p = Pose2::attach(theta, at, [0.3, 0.1]).point([0.3, 0.1]);
            assert!((p[0] - at[0]).abs() < 1e-15 && (p[1] - at[1]).abs() < 1e-15);
        }
    }
}
