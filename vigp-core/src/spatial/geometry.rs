//! 3-D vectors, rotation matrices, poses and motions generic over any
//! [`Real`] (plain arrays: a jet or dual number is not a nalgebra scalar for
//! every operation we need, and these sizes are fixed anyway).
//!
//! Matrices are row-major, `m[row][column]`. Rotations map link-frame
//! vectors to world vectors.

use crate::real::Real;

/// A 3-vector.
pub type Vec3<R> = [R; 3];
/// A 3×3 matrix, row-major.
pub type Mat3<R> = [[R; 3]; 3];

/// A constant.
#[inline]
pub fn k<R: Real>(x: f64) -> R {
    R::from_f64(x)
}

/// A constant vector.
#[inline]
pub fn lift<R: Real>(a: [f64; 3]) -> Vec3<R> {
    a.map(R::from_f64)
}

/// The zero vector.
#[inline]
pub fn zero3<R: Real>() -> Vec3<R> {
    [k(0.0); 3]
}

/// The identity matrix.
#[inline]
pub fn identity<R: Real>() -> Mat3<R> {
    let (o, l) = (k::<R>(0.0), k::<R>(1.0));
    [[l, o, o], [o, l, o], [o, o, l]]
}

/// a + b.
#[inline]
pub fn add<R: Real>(a: Vec3<R>, b: Vec3<R>) -> Vec3<R> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// a − b.
#[inline]
pub fn sub<R: Real>(a: Vec3<R>, b: Vec3<R>) -> Vec3<R> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a·s.
#[inline]
pub fn scale<R: Real>(a: Vec3<R>, s: R) -> Vec3<R> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// a·s for a constant s.
#[inline]
pub fn scale_f<R: Real>(a: Vec3<R>, s: f64) -> Vec3<R> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// a·b.
#[inline]
pub fn dot<R: Real>(a: Vec3<R>, b: Vec3<R>) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a·b for a constant b.
#[inline]
pub fn dot_f<R: Real>(a: Vec3<R>, b: [f64; 3]) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b.
#[inline]
pub fn cross<R: Real>(a: Vec3<R>, b: Vec3<R>) -> Vec3<R> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// m·v.
#[inline]
pub fn mul_mv<R: Real>(m: &Mat3<R>, v: Vec3<R>) -> Vec3<R> {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// m·v for a constant v.
#[inline]
pub fn mul_mv_f<R: Real>(m: &Mat3<R>, v: [f64; 3]) -> Vec3<R> {
    [dot_f(m[0], v), dot_f(m[1], v), dot_f(m[2], v)]
}

/// mᵀ·v.
#[inline]
pub fn mul_mtv<R: Real>(m: &Mat3<R>, v: Vec3<R>) -> Vec3<R> {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// a·b.
#[inline]
pub fn mul_mm<R: Real>(a: &Mat3<R>, b: &Mat3<R>) -> Mat3<R> {
    let mut out = [[k::<R>(0.0); 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    out
}

/// a·b for a constant b.
#[inline]
pub fn mul_mm_f<R: Real>(a: &Mat3<R>, b: &[[f64; 3]; 3]) -> Mat3<R> {
    let mut out = [[k::<R>(0.0); 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    out
}

/// aᵀ·b.
#[inline]
pub fn mul_mtm<R: Real>(a: &Mat3<R>, b: &Mat3<R>) -> Mat3<R> {
    let mut out = [[k::<R>(0.0); 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j];
        }
    }
    out
}

/// The axial vector of the skew-symmetric part of `m`, vee((m − mᵀ)/2):
/// for a rotation by θ about the unit axis a it is sin θ·a.
#[inline]
pub fn vee_skew<R: Real>(m: &Mat3<R>) -> Vec3<R> {
    [
        (m[2][1] - m[1][2]) * 0.5,
        (m[0][2] - m[2][0]) * 0.5,
        (m[1][0] - m[0][1]) * 0.5,
    ]
}

/// Rotation by `angle` about the constant unit `axis` (Rodrigues:
/// I + sin θ·â + (1 − cos θ)·â²).
#[inline]
pub fn axis_angle<R: Real>(axis: [f64; 3], angle: R) -> Mat3<R> {
    let (s, c) = angle.sincos();
    let one_c = k::<R>(1.0) - c;
    let [x, y, z] = axis;
    [
        [
            one_c * (x * x) + c,
            one_c * (x * y) - s * z,
            one_c * (x * z) + s * y,
        ],
        [
            one_c * (x * y) + s * z,
            one_c * (y * y) + c,
            one_c * (y * z) - s * x,
        ],
        [
            one_c * (x * z) - s * y,
            one_c * (y * z) + s * x,
            one_c * (z * z) + c,
        ],
    ]
}

/// The rotation matrix of a quaternion u = (w, x, y, z), in the homogeneous
/// form (w² − |v|²)·I + 2·v·vᵀ + 2w·v̂, which is |u|² times the rotation of
/// u/|u|: exact for a unit quaternion, and a polynomial (so any [`Real`]
/// differentiates it).
#[inline]
pub fn quat_matrix<R: Real>(u: [R; 4]) -> Mat3<R> {
    let [w, x, y, z] = u;
    let d = w * w - (x * x + y * y + z * z);
    let (xx, yy, zz) = (x * x * 2.0, y * y * 2.0, z * z * 2.0);
    let (xy, xz, yz) = (x * y * 2.0, x * z * 2.0, y * z * 2.0);
    let (wx, wy, wz) = (w * x * 2.0, w * y * 2.0, w * z * 2.0);
    [
        [d + xx, xy - wz, xz + wy],
        [xy + wz, d + yy, yz - wx],
        [xz - wy, yz + wx, d + zz],
    ]
}

/// The angular velocity (in the frame the quaternion maps into) of the
/// rotation u(t) with rate u̇: ω = 2·Vec(u̇ ⊗ u*) = 2(w·ẋ − ẇ·x + x × ẋ)
/// (x the vector part). Exact for unit u; a rate along u itself (a change
/// of norm only) gives zero.
#[inline]
pub fn quat_rate<R: Real>(u: [R; 4], du: [R; 4]) -> Vec3<R> {
    let v = [u[1], u[2], u[3]];
    let dv = [du[1], du[2], du[3]];
    let c = cross(v, dv);
    [
        (u[0] * dv[0] - du[0] * v[0] + c[0]) * 2.0,
        (u[0] * dv[1] - du[0] * v[1] + c[1]) * 2.0,
        (u[0] * dv[2] - du[0] * v[2] + c[2]) * 2.0,
    ]
}

/// The pose of a link frame: its origin (the link's `start`) in world
/// coordinates and its rotation (link frame → world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose3<R> {
    /// World position of the frame origin.
    pub origin: Vec3<R>,
    /// Rotation matrix, link frame → world.
    pub rot: Mat3<R>,
}

impl<R: Real> Pose3<R> {
    /// The world frame (and the reference pose of a link at the origin).
    pub fn identity() -> Self {
        Self {
            origin: zero3(),
            rot: identity(),
        }
    }

    /// World position of the point with link-frame coordinates `local`.
    #[inline]
    pub fn point(&self, local: [f64; 3]) -> Vec3<R> {
        add(self.origin, mul_mv_f(&self.rot, local))
    }

    /// World direction of the link-frame vector `local`.
    #[inline]
    pub fn direction(&self, local: [f64; 3]) -> Vec3<R> {
        mul_mv_f(&self.rot, local)
    }
}

/// The velocity of a link frame: the velocity of its origin and its angular
/// velocity, both in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion3<R> {
    /// World velocity of the frame origin.
    pub velocity: Vec3<R>,
    /// Angular velocity in world coordinates.
    pub omega: Vec3<R>,
}

impl<R: Real> Motion3<R> {
    /// At rest.
    pub fn zero() -> Self {
        Self {
            velocity: zero3(),
            omega: zero3(),
        }
    }

    /// World velocity of the point with link-frame coordinates `local` of
    /// the link at `pose`: v + ω × (R·local).
    #[inline]
    pub fn point_velocity(&self, pose: &Pose3<R>, local: [f64; 3]) -> Vec3<R> {
        add(self.velocity, cross(self.omega, pose.direction(local)))
    }
}

/// Two unit vectors b₁, b₂ with (a, b₁, b₂) a right-handed orthonormal
/// basis, chosen deterministically from the unit vector `a` (its
/// complement for the two constraint rows of a revolute or prismatic joint).
pub fn complement(a: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    // cross with the coordinate axis least aligned with a
    let e = if a[0].abs() <= a[1].abs() && a[0].abs() <= a[2].abs() {
        [1.0, 0.0, 0.0]
    } else if a[1].abs() <= a[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let b1 = cross(a, e);
    let n = libm::sqrt(dot(b1, b1));
    let b1 = scale(b1, 1.0 / n);
    let b2 = cross(a, b1);
    (b1, b2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3<f64>, b: &Mat3<f64>, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    #[test]
    fn axis_angle_matches_unit_quaternion_matrix() {
        let axis = {
            let a = [0.3, -0.5, 0.8];
            let n = libm::sqrt(dot(a, a));
            scale(a, 1.0 / n)
        };
        let th = 1.1;
        let (s, c) = libm::sincos(th / 2.0);
        let u = [c, s * axis[0], s * axis[1], s * axis[2]];
        assert!(close(&axis_angle(axis, th), &quat_matrix(u), 1e-15));
        // homogeneous: 2u gives 4R
        let r2 = quat_matrix(u.map(|x| 2.0 * x));
        let r = quat_matrix(u);
        assert!(close(&r2, &r.map(|row| row.map(|x| 4.0 * x)), 1e-14));
    }

    #[test]
    fn quat_rate_matches_finite_difference_of_rotation() {
        // ω̂ = Ṙ Rᵀ for unit u(t) = exp of a rotation about a moving axis
        let u_at = |t: f64| {
            let a = [libm::cos(t), libm::sin(t), 0.5];
            let n = libm::sqrt(dot(a, a));
            let (s, c) = libm::sincos(0.7 * t);
            [c, s * a[0] / n, s * a[1] / n, s * a[2] / n]
        };
        let (t, h) = (0.4, 1e-6);
        let (up, um, u) = (u_at(t + h), u_at(t - h), u_at(t));
        let du: [f64; 4] = core::array::from_fn(|i| (up[i] - um[i]) / (2.0 * h));
        let w = quat_rate(u, du);
        let (rp, rm, r) = (quat_matrix(up), quat_matrix(um), quat_matrix(u));
        let rdot: Mat3<f64> =
            core::array::from_fn(|i| core::array::from_fn(|j| (rp[i][j] - rm[i][j]) / (2.0 * h)));
        // Ṙ Rᵀ
        let mut wh = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                wh[i][j] = (0..3).map(|l| rdot[i][l] * r[j][l]).sum();
            }
        }
        let from_r = [wh[2][1], wh[0][2], wh[1][0]];
        for i in 0..3 {
            assert!((w[i] - from_r[i]).abs() < 1e-8, "{w:?} {from_r:?}");
        }
        // a rate along u itself is not a rotation
        let radial = quat_rate(u, u);
        assert!(radial.iter().all(|x| x.abs() < 1e-15));
    }

    #[test]
    fn complement_is_orthonormal_and_right_handed() {
        for a in [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.6, 0.0, 0.8]] {
            let (b1, b2) = complement(a);
            for (x, y) in [(a, b1), (a, b2), (b1, b2)] {
                assert!(dot(x, y).abs() < 1e-15);
            }
            assert!((dot(b1, b1) - 1.0).abs() < 1e-15 && (dot(b2, b2) - 1.0).abs() < 1e-15);
            let c = cross(b1, b2);
            assert!((0..3).all(|i| (c[i] - a[i]).abs() < 1e-15));
        }
    }
}
