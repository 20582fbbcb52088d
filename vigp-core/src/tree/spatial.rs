//! 3-vectors, rotations and 6-D spatial vectors for the tree engine,
//! generic over the scalar ([`Real`]: `f64` for the step, jets for its
//! exact derivatives). Matrices are row-major (`m[row][column]`); rotations
//! map body-frame vectors to world vectors.
//!
//! A **motion** (twist) is (ω, v_O): the angular velocity and the velocity
//! of the body point at the world origin. A **force** (wrench) is (n_O, f):
//! the moment about the world origin and the force. Their pairing
//! `dot6(motion, force)` is power. Every vector of the engine is expressed
//! in world coordinates at the world origin, so no transform is needed
//! between bodies.

use crate::Real;

/// A 3-vector.
pub type V3<R = f64> = [R; 3];
/// A 3×3 matrix, row-major.
pub type M3<R = f64> = [[R; 3]; 3];
/// A spatial motion (ω, v_O) or force (n_O, f).
pub type V6<R = f64> = [R; 6];
/// A 6×6 matrix, row-major.
pub type M6<R = f64> = [[R; 6]; 6];

/// The 3×3 identity.
pub const IDENTITY: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The zero of the scalar.
#[inline(always)]
pub fn zero<R: Real>() -> R {
    R::from_f64(0.0)
}

/// An `f64` vector as constants of the scalar.
#[inline(always)]
pub fn lift3<R: Real>(a: V3) -> V3<R> {
    a.map(R::from_f64)
}

/// An `f64` matrix as constants of the scalar.
#[inline(always)]
pub fn lift33<R: Real>(m: &M3) -> M3<R> {
    m.map(|row| row.map(R::from_f64))
}

/// a + b.
#[inline(always)]
pub fn add<R: Real>(a: V3<R>, b: V3<R>) -> V3<R> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// a·s.
#[inline(always)]
pub fn scale<R: Real>(a: V3<R>, s: R) -> V3<R> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// a·b.
#[inline(always)]
pub fn dot<R: Real>(a: V3<R>, b: V3<R>) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b.
#[inline(always)]
pub fn cross<R: Real>(a: V3<R>, b: V3<R>) -> V3<R> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// m·a.
#[inline(always)]
pub fn mul_mv<R: Real>(m: &M3<R>, a: V3<R>) -> V3<R> {
    [dot(m[0], a), dot(m[1], a), dot(m[2], a)]
}

/// a·b for matrices.
#[inline(always)]
pub fn mul_mm<R: Real>(a: &M3<R>, b: &M3<R>) -> M3<R> {
    // written out: the step's hottest 3 × 3 product, which nested
    // `array::from_fn` closures left uninlined
    let col = |j: usize| [b[0][j], b[1][j], b[2][j]];
    let (c0, c1, c2) = (col(0), col(1), col(2));
    let row = |r: V3<R>| [dot(r, c0), dot(r, c1), dot(r, c2)];
    [row(a[0]), row(a[1]), row(a[2])]
}

/// a·bᵀ for matrices.
#[inline(always)]
pub fn mul_mmt<R: Real>(a: &M3<R>, b: &M3<R>) -> M3<R> {
    let row = |r: V3<R>| [dot(r, b[0]), dot(r, b[1]), dot(r, b[2])];
    [row(a[0]), row(a[1]), row(a[2])]
}

/// r·m·rᵀ: a tensor given in a frame rotated by r, in the outer frame.
#[inline(always)]
pub fn congruence<R: Real>(r: &M3<R>, m: &M3<R>) -> M3<R> {
    mul_mmt(&mul_mm(r, m), r)
}

/// The rotation by `angle` about the unit `axis` (right-handed, Rodrigues).
pub fn axis_angle<R: Real>(axis: V3, angle: R) -> M3<R> {
    let (s, c) = angle.sincos();
    let t = -c + 1.0;
    let [x, y, z] = axis;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// The URDF rotation of roll, pitch, yaw (fixed axes x, y, z in that
/// order): R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn rpy(roll: f64, pitch: f64, yaw: f64) -> M3 {
    let (sr, cr) = libm::sincos(roll);
    let (sp, cp) = libm::sincos(pitch);
    let (sy, cy) = libm::sincos(yaw);
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// a·b for spatial vectors (a motion against a force: power).
#[inline(always)]
pub fn dot6<R: Real>(a: &V6<R>, b: &V6<R>) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

/// The motion cross product a ×ₘ b = (ωa × ωb, ωa × vb + va × ωb): the rate
/// of change of the world-fixed twist b carried by the motion a.
#[inline(always)]
pub fn cross_motion<R: Real>(a: &V6<R>, b: &V6<R>) -> V6<R> {
    let (wa, va) = ([a[0], a[1], a[2]], [a[3], a[4], a[5]]);
    let (wb, vb) = ([b[0], b[1], b[2]], [b[3], b[4], b[5]]);
    let w = cross(wa, wb);
    let v = add(cross(wa, vb), cross(va, wb));
    [w[0], w[1], w[2], v[0], v[1], v[2]]
}

/// The force cross product a ×f f = (ωa × n + va × f_lin, ωa × f_lin): the
/// rate of change of the world-fixed wrench f carried by the motion a.
#[inline(always)]
pub fn cross_force<R: Real>(a: &V6<R>, f: &V6<R>) -> V6<R> {
    let (wa, va) = ([a[0], a[1], a[2]], [a[3], a[4], a[5]]);
    let (n, fl) = ([f[0], f[1], f[2]], [f[3], f[4], f[5]]);
    let m = add(cross(wa, n), cross(va, fl));
    let l = cross(wa, fl);
    [m[0], m[1], m[2], l[0], l[1], l[2]]
}

/// The spatial inertia of a body (or a set of bodies) about the world
/// origin in world axes: mass m, first moment m·c (c the centre of mass)
/// and the rotational inertia about the origin I_O = I_c + m(|c|²1 − ccᵀ).
/// As a 6×6 matrix `[[I_O, [mc]×], [[mc]×ᵀ, m·1]]`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Inertia6<R = f64> {
    /// Mass (kg).
    pub mass: R,
    /// First moment m·c about the origin (kg·m).
    pub first: V3<R>,
    /// Rotational inertia about the origin (kg·m²).
    pub rot: M3<R>,
}

impl<R: Real> Inertia6<R> {
    /// No mass.
    pub fn zero() -> Self {
        Self {
            mass: zero(),
            first: [zero(); 3],
            rot: [[zero(); 3]; 3],
        }
    }

    /// The inertia of a body of mass `m` whose centre of mass is at `c`
    /// with rotational inertia `ic` about it (world axes).
    pub fn from_com(m: R, c: V3<R>, ic: &M3<R>) -> Self {
        let cc = dot(c, c);
        let mut rot = *ic;
        for (i, row) in rot.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = *x + m * (if i == j { cc } else { zero() } - c[i] * c[j]);
            }
        }
        Self {
            mass: m,
            first: scale(c, m),
            rot,
        }
    }

    /// Sum of two inertias (about the same origin).
    #[inline(always)]
    pub fn add(&self, o: &Inertia6<R>) -> Self {
        let mut rot = self.rot;
        for (r, ro) in rot.iter_mut().zip(&o.rot) {
            for (x, y) in r.iter_mut().zip(ro) {
                *x = *x + *y;
            }
        }
        Self {
            mass: self.mass + o.mass,
            first: add(self.first, o.first),
            rot,
        }
    }

    /// The momentum I·V of a motion V = (ω, v): (I_O ω + mc × v, m v − mc × ω).
    #[inline(always)]
    pub fn mul(&self, v: &V6<R>) -> V6<R> {
        let (w, lin) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
        let n = add(mul_mv(&self.rot, w), cross(self.first, lin));
        let mw = cross(self.first, w);
        let f = [
            self.mass * lin[0] - mw[0],
            self.mass * lin[1] - mw[1],
            self.mass * lin[2] - mw[2],
        ];
        [n[0], n[1], n[2], f[0], f[1], f[2]]
    }

    /// The gravity wrench of this mass distribution under gravity `g`
    /// about the origin: (mc × g, m·g).
    #[inline(always)]
    pub fn gravity_wrench(&self, g: V3) -> V6<R> {
        let n = cross(self.first, lift3(g));
        [
            n[0],
            n[1],
            n[2],
            self.mass * g[0],
            self.mass * g[1],
            self.mass * g[2],
        ]
    }
}

impl Inertia6 {
    /// The 6×6 matrix.
    pub fn matrix(&self) -> M6 {
        let h = self.first;
        // [h]× and its transpose
        let hx = [[0.0, -h[2], h[1]], [h[2], 0.0, -h[0]], [-h[1], h[0], 0.0]];
        let mut m = [[0.0; 6]; 6];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = self.rot[i][j];
                m[i][j + 3] = hx[i][j];
                m[i + 3][j] = hx[j][i];
            }
            m[i + 3][i + 3] = self.mass;
        }
        m
    }
}

/// m·a for 6×6 matrices.
#[inline(always)]
pub fn mul6(m: &M6, a: &V6) -> V6 {
    let mut out = [0.0; 6];
    for (o, row) in out.iter_mut().zip(m) {
        *o = dot6(row, a);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_is_z_y_x_product() {
        // R = Rz(y) Ry(p) Rx(r) against the product of axis rotations
        let (r, p, y) = (0.3, -0.7, 1.9);
        let expect = mul_mm(
            &axis_angle([0.0, 0.0, 1.0], y),
            &mul_mm(
                &axis_angle([0.0, 1.0, 0.0], p),
                &axis_angle([1.0, 0.0, 0.0], r),
            ),
        );
        let got = rpy(r, p, y);
        for i in 0..3 {
            for j in 0..3 {
                assert!((got[i][j] - expect[i][j]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn inertia_product_matches_matrix() {
        let ic = [[0.3, 0.01, -0.02], [0.01, 0.2, 0.03], [-0.02, 0.03, 0.25]];
        let i6 = Inertia6::from_com(1.7, [0.2, -0.4, 0.9], &ic);
        let v = [0.3, -1.1, 0.4, 2.0, 0.5, -0.7];
        let a = i6.mul(&v);
        let b = mul6(&i6.matrix(), &v);
        for k in 0..6 {
            assert!((a[k] - b[k]).abs() < 1e-14);
        }
    }
}
