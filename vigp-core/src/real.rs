//! The scalar the generated kinematics is generic over, and forward-mode
//! jets that carry exact first (and second) derivatives through it.
//!
//! [`Real`] is deliberately small: the ring operations, products and sums
//! with `f64` constants, `sincos`, and `atan2` (the angle of a spatial
//! revolute joint read back from two link orientations).
//! It is implemented for `f64` (via `libm`, so it works in `no_std`), for
//! [`Jet1`] and [`Jet2`] here, and, with the `dual` feature, for every
//! num-dual number, so the std runtime and this crate run the same
//! generated body.

use core::fmt::Debug;
use core::ops::{Add, Mul, Neg, Sub};

/// A scalar for planar kinematics: `f64`, a jet, or (feature `dual`) a
/// num-dual number.
pub trait Real:
    Copy
    + Debug
    + PartialEq
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
{
    /// A constant.
    fn from_f64(x: f64) -> Self;
    /// `(sin x, cos x)` with their derivatives.
    fn sincos(self) -> (Self, Self);
    /// The angle atan2(self, x) ∈ (−π, π] of the point (x, self), with its
    /// derivatives (finite wherever x² + self² > 0).
    fn atan2(self, x: Self) -> Self;
    /// The value without its derivatives (for tests of finiteness and
    /// for reading results).
    fn value(self) -> f64;
}

#[cfg(not(feature = "dual"))]
impl Real for f64 {
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn sincos(self) -> (Self, Self) {
        libm::sincos(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2(self, x)
    }
    #[inline]
    fn value(self) -> f64 {
        self
    }
}

#[cfg(feature = "dual")]
impl<T> Real for T
where
    T: num_dual::DualNum<Primitive = f64> + Copy,
{
    #[inline]
    fn from_f64(x: f64) -> Self {
        T::from(x)
    }
    #[inline]
    fn sincos(self) -> (Self, Self) {
        self.sin_cos()
    }
    /// θ₀ + atan(n/d) with θ₀ = atan2 of the values and (n, d) the point
    /// rotated by −θ₀: n = 0 and d = r > 0 at the value, so the derivatives
    /// stay finite where num-dual's atan2 (through y/x) divides by x = 0.
    #[inline]
    fn atan2(self, x: Self) -> Self {
        let t0 = self.re().atan2(x.re());
        let (s0, c0) = t0.sin_cos();
        let n = self * T::from(c0) - x * T::from(s0);
        let d = x * T::from(c0) + self * T::from(s0);
        (n / d).atan() + T::from(t0)
    }
    #[inline]
    fn value(self) -> f64 {
        self.re()
    }
}

#[inline]
fn sincos_f64(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// The operations of a jet with a value field `v` that touch the value
/// alone or reduce to a product: −x = x·(−1) and x ± c.
macro_rules! scalar_shifts {
    ($jet:ident) => {
        impl<const N: usize> Neg for $jet<N> {
            type Output = Self;
            #[inline]
            fn neg(self) -> Self {
                self * -1.0
            }
        }

        impl<const N: usize> Add<f64> for $jet<N> {
            type Output = Self;
            #[inline]
            fn add(mut self, o: f64) -> Self {
                self.v += o;
                self
            }
        }

        impl<const N: usize> Sub<f64> for $jet<N> {
            type Output = Self;
            #[inline]
            fn sub(mut self, o: f64) -> Self {
                self.v -= o;
                self
            }
        }
    };
}

/// Inside `impl Real for` a jet with a value field `v`: `from_f64` (a
/// constant) and `value` (the field).
macro_rules! value_of_v {
    () => {
        #[inline]
        fn from_f64(x: f64) -> Self {
            Self::constant(x)
        }
        #[inline]
        fn value(self) -> f64 {
            self.v
        }
    };
}

scalar_shifts!(Jet1);
scalar_shifts!(Jet2);

/// A first-order jet in `N` directions: value `v` and gradient `g`.
///
/// Cost: one value operation plus `N` for the gradient (products: `2N`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jet1<const N: usize> {
    /// Value.
    pub v: f64,
    /// Gradient ∂/∂x_i.
    pub g: [f64; N],
}

impl<const N: usize> Jet1<N> {
    /// A constant (zero gradient).
    #[inline]
    pub fn constant(v: f64) -> Self {
        Self { v, g: [0.0; N] }
    }

    /// The `i`-th independent variable with value `v` (gradient e_i). An
    /// out-of-range `i` gives a constant.
    #[inline]
    pub fn variable(v: f64, i: usize) -> Self {
        let mut g = [0.0; N];
        if let Some(gi) = g.get_mut(i) {
            *gi = 1.0;
        }
        Self { v, g }
    }

    #[inline]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut g = self.g;
        for gi in &mut g {
            *gi *= df;
        }
        Self { v: f, g }
    }
}

impl<const N: usize> Add for Jet1<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for (a, b) in self.g.iter_mut().zip(o.g) {
            *a += b;
        }
        self
    }
}

impl<const N: usize> Sub for Jet1<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: Self) -> Self {
        self.v -= o.v;
        for (a, b) in self.g.iter_mut().zip(o.g) {
            *a -= b;
        }
        self
    }
}

impl<const N: usize> Mul for Jet1<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut g = [0.0; N];
        for ((gi, a), b) in g.iter_mut().zip(self.g).zip(o.g) {
            *gi = a * o.v + self.v * b;
        }
        Self { v: self.v * o.v, g }
    }
}

impl<const N: usize> Mul<f64> for Jet1<N> {
    type Output = Self;
    #[inline]
    fn mul(mut self, o: f64) -> Self {
        self.v *= o;
        for a in &mut self.g {
            *a *= o;
        }
        self
    }
}

impl<const N: usize> Real for Jet1<N> {
    value_of_v!();
    #[inline]
    fn sincos(self) -> (Self, Self) {
        let (s, c) = sincos_f64(self.v);
        (self.chain(s, c), self.chain(c, -s))
    }
    /// θ = atan2(y, x): ∂θ/∂y = x/r², ∂θ/∂x = −y/r².
    #[inline]
    fn atan2(self, x: Self) -> Self {
        let r2 = x.v * x.v + self.v * self.v;
        let (ty, tx) = (x.v / r2, -self.v / r2);
        let mut out = Self::constant(libm::atan2(self.v, x.v));
        for i in 0..N {
            out.g[i] = ty * self.g[i] + tx * x.g[i];
        }
        out
    }
}

/// A second-order jet in `N` directions: value `v`, gradient `g` and the
/// upper triangle of the Hessian `h`.
///
/// The Hessian is symmetric, so only `h[i][j]` with `i ≤ j` is computed and
/// stored; entries below the diagonal stay zero. Read it with
/// [`Jet2::hessian`], which mirrors.
///
/// Cost: a product is `O(N²)` (`N(N+1)/2` Hessian entries of 4
/// multiplications each, plus `2N + 1`); sums and products with constants are
/// `N(N+1)/2 + N + 1` operations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jet2<const N: usize> {
    /// Value.
    pub v: f64,
    /// Gradient ∂/∂x_i.
    pub g: [f64; N],
    /// Hessian ∂²/∂x_i∂x_j for `i ≤ j` (upper triangle; the rest is zero).
    pub h: [[f64; N]; N],
}

impl<const N: usize> Jet2<N> {
    /// A constant.
    #[inline]
    pub fn constant(v: f64) -> Self {
        Self {
            v,
            g: [0.0; N],
            h: [[0.0; N]; N],
        }
    }

    /// The `i`-th independent variable with value `v`. An out-of-range `i`
    /// gives a constant.
    #[inline]
    pub fn variable(v: f64, i: usize) -> Self {
        let mut x = Self::constant(v);
        if let Some(gi) = x.g.get_mut(i) {
            *gi = 1.0;
        }
        x
    }

    /// The Hessian entry ∂²/∂x_i∂x_j (either order).
    ///
    /// # Panics
    /// If `i` or `j` is not below `N`.
    #[inline]
    pub fn hessian(&self, i: usize, j: usize) -> f64 {
        if i <= j { self.h[i][j] } else { self.h[j][i] }
    }

    /// f(self) from f, f′, f″ at the value.
    #[inline]
    fn chain(self, f: f64, df: f64, d2f: f64) -> Self {
        let mut out = Self::constant(f);
        for i in 0..N {
            out.g[i] = df * self.g[i];
            let d2fg = d2f * self.g[i];
            for j in i..N {
                out.h[i][j] = df * self.h[i][j] + d2fg * self.g[j];
            }
        }
        out
    }
}

impl<const N: usize> Add for Jet2<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for i in 0..N {
            self.g[i] += o.g[i];
            for j in i..N {
                self.h[i][j] += o.h[i][j];
            }
        }
        self
    }
}

impl<const N: usize> Sub for Jet2<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: Self) -> Self {
        self.v -= o.v;
        for i in 0..N {
            self.g[i] -= o.g[i];
            for j in i..N {
                self.h[i][j] -= o.h[i][j];
            }
        }
        self
    }
}

impl<const N: usize> Mul for Jet2<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut out = Self::constant(self.v * o.v);
        for i in 0..N {
            out.g[i] = self.g[i] * o.v + self.v * o.g[i];
            for j in i..N {
                out.h[i][j] = self.h[i][j] * o.v
                    + self.v * o.h[i][j]
                    + self.g[i] * o.g[j]
                    + o.g[i] * self.g[j];
            }
        }
        out
    }
}

impl<const N: usize> Mul<f64> for Jet2<N> {
    type Output = Self;
    #[inline]
    fn mul(mut self, o: f64) -> Self {
        self.v *= o;
        for i in 0..N {
            self.g[i] *= o;
            for j in i..N {
                self.h[i][j] *= o;
            }
        }
        self
    }
}

impl<const N: usize> Real for Jet2<N> {
    value_of_v!();
    #[inline]
    fn sincos(self) -> (Self, Self) {
        let (s, c) = sincos_f64(self.v);
        (self.chain(s, c, -s), self.chain(c, -s, -c))
    }
    /// θ = atan2(y, x): θ_y = x/r², θ_x = −y/r², θ_yy = −2xy/r⁴ = −θ_xx,
    /// θ_xy = (y² − x²)/r⁴.
    #[inline]
    fn atan2(self, x: Self) -> Self {
        let (yv, xv) = (self.v, x.v);
        let r2 = xv * xv + yv * yv;
        let r4 = r2 * r2;
        let (ty, tx) = (xv / r2, -yv / r2);
        let tyy = -2.0 * xv * yv / r4;
        let txy = (yv * yv - xv * xv) / r4;
        let mut out = Self::constant(libm::atan2(yv, xv));
        for i in 0..N {
            out.g[i] = ty * self.g[i] + tx * x.g[i];
            for j in i..N {
                out.h[i][j] = ty * self.h[i][j]
                    + tx * x.h[i][j]
                    + tyy * (self.g[i] * self.g[j] - x.g[i] * x.g[j])
                    + txy * (self.g[i] * x.g[j] + x.g[i] * self.g[j]);
            }
        }
        out
    }
}

impl<const N: usize> Jet1<N> {
    /// 1/self (the value must not be zero).
    #[inline]
    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r)
    }
}

/// One column of a second-order jet: a first-order jet in `N` directions
/// carried together with its derivative along one further direction,
/// x + ε·dx with ε² = 0 (a hyper-dual number whose parts are [`Jet1`]s).
///
/// Seeded with [`JetDir::variable`]`(v, i, l)`, a scalar function's
/// `dx.g` is column l of its Hessian: N passes give the Hessian that one
/// [`Jet2`] pass gives, with 2(N + 1) numbers per scalar instead of
/// N² + N + 1 (480 bytes instead of 7 KB at N = 29), so that kinematics
/// of many bodies keeps its jets on a small stack. A product costs three
/// [`Jet1`] products.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JetDir<const N: usize> {
    /// The jet.
    pub x: Jet1<N>,
    /// Its derivative along the extra direction.
    pub dx: Jet1<N>,
}

impl<const N: usize> JetDir<N> {
    /// A constant.
    #[inline]
    pub fn constant(v: f64) -> Self {
        Self {
            x: Jet1::constant(v),
            dx: Jet1::constant(0.0),
        }
    }

    /// The `i`-th independent variable with value `v`, differentiated
    /// along the `l`-th direction (dx = 1 when `i == l`). An out-of-range
    /// `i` gives a constant.
    #[inline]
    pub fn variable(v: f64, i: usize, l: usize) -> Self {
        let varies = i < N;
        Self {
            x: Jet1::variable(v, i),
            dx: Jet1::constant(if varies && i == l { 1.0 } else { 0.0 }),
        }
    }
}

impl<const N: usize> Add for JetDir<N> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self {
            x: self.x + o.x,
            dx: self.dx + o.dx,
        }
    }
}

impl<const N: usize> Sub for JetDir<N> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self {
            x: self.x - o.x,
            dx: self.dx - o.dx,
        }
    }
}

impl<const N: usize> Mul for JetDir<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        Self {
            x: self.x * o.x,
            dx: self.x * o.dx + self.dx * o.x,
        }
    }
}

impl<const N: usize> Neg for JetDir<N> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self {
            x: -self.x,
            dx: -self.dx,
        }
    }
}

impl<const N: usize> Add<f64> for JetDir<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: f64) -> Self {
        self.x = self.x + o;
        self
    }
}

impl<const N: usize> Sub<f64> for JetDir<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: f64) -> Self {
        self.x = self.x - o;
        self
    }
}

impl<const N: usize> Mul<f64> for JetDir<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: f64) -> Self {
        Self {
            x: self.x * o,
            dx: self.dx * o,
        }
    }
}

impl<const N: usize> Real for JetDir<N> {
    #[inline]
    fn from_f64(x: f64) -> Self {
        Self::constant(x)
    }
    #[inline]
    fn value(self) -> f64 {
        self.x.v
    }
    /// sin(x + ε dx) = sin x + ε cos x·dx, cos(x + ε dx) = cos x − ε sin x·dx.
    #[inline]
    fn sincos(self) -> (Self, Self) {
        let (s, c) = self.x.sincos();
        (
            Self {
                x: s,
                dx: c * self.dx,
            },
            Self {
                x: c,
                dx: -(s * self.dx),
            },
        )
    }
    /// θ = atan2(y, x), dθ = (x·dy − y·dx)/(x² + y²).
    #[inline]
    fn atan2(self, x: Self) -> Self {
        let r2 = x.x * x.x + self.x * self.x;
        Self {
            x: self.x.atan2(x.x),
            dx: (x.x * self.dx - self.x * x.dx) * r2.recip(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x, y) = sin(x·y) · (x − 3) + cos(y)·2, derivatives by hand.
    fn f<R: Real>(x: R, y: R) -> R {
        let (s, _) = (x * y).sincos();
        let (_, c) = y.sincos();
        s * (x - 3.0) + c * 2.0
    }

    #[test]
    fn jets_match_closed_form_derivatives() {
        let (x, y) = (0.7, -1.3);
        let j1 = f(Jet1::<2>::variable(x, 0), Jet1::variable(y, 1));
        let j2 = f(Jet2::<2>::variable(x, 0), Jet2::variable(y, 1));
        let (s, c) = libm::sincos(x * y);
        let value = s * (x - 3.0) + 2.0 * libm::cos(y);
        let fx = c * y * (x - 3.0) + s;
        let fy = c * x * (x - 3.0) - 2.0 * libm::sin(y);
        let fxx = -s * y * y * (x - 3.0) + 2.0 * c * y;
        let fxy = (c - s * x * y) * (x - 3.0) + c * x;
        let fyy = -s * x * x * (x - 3.0) - 2.0 * libm::cos(y);
        // Same arithmetic in a different order: agreement to a few ulps.
        let tol = 1e-14;
        assert!((j1.v - value).abs() < tol && (j2.v - value).abs() < tol);
        assert!((j1.g[0] - fx).abs() < tol && (j1.g[1] - fy).abs() < tol);
        assert!((j2.g[0] - fx).abs() < tol && (j2.g[1] - fy).abs() < tol);
        assert!((j2.hessian(0, 0) - fxx).abs() < tol);
        assert!((j2.hessian(0, 1) - fxy).abs() < tol && (j2.hessian(1, 0) - fxy).abs() < tol);
        assert!((j2.hessian(1, 1) - fyy).abs() < tol);
        // only the upper triangle is stored
        assert_eq!(j2.h[1][0], 0.0);
    }

    /// θ(x, y) = atan2(y, x) composed with (x, y) = (r cos φ, r sin φ) is φ
    /// wherever φ ∈ (−π, π): gradient (0, 1) in (r, φ), Hessian zero; and
    /// in Cartesian form ∂θ/∂y = x/r², ∂²θ/∂x∂y = (y² − x²)/r⁴.
    #[test]
    fn atan2_jets_match_closed_forms() {
        for phi in [0.3, core::f64::consts::FRAC_PI_2, 2.9, -2.9, -1.2] {
            let r = 1.7;
            let (rj, pj) = (Jet2::<2>::variable(r, 0), Jet2::<2>::variable(phi, 1));
            let (s, c) = pj.sincos();
            let t = (rj * s).atan2(rj * c);
            assert!((t.v - phi).abs() < 1e-15, "{phi}");
            assert!(t.g[0].abs() < 1e-15 && (t.g[1] - 1.0).abs() < 1e-15);
            for (i, j) in [(0, 0), (0, 1), (1, 1)] {
                assert!(t.hessian(i, j).abs() < 1e-15, "{phi} {i}{j}");
            }
            let (x, y) = (r * phi.cos(), r * phi.sin());
            let r2 = x * x + y * y;
            let j = Jet2::<2>::variable(y, 1).atan2(Jet2::variable(x, 0));
            let j1 = Jet1::<2>::variable(y, 1).atan2(Jet1::variable(x, 0));
            assert!((j.g[1] - x / r2).abs() < 1e-15 && (j.g[0] + y / r2).abs() < 1e-15);
            assert_eq!(j.g, j1.g);
            assert!((j.hessian(0, 1) - (y * y - x * x) / (r2 * r2)).abs() < 1e-15);
            assert!((j.hessian(0, 0) - 2.0 * x * y / (r2 * r2)).abs() < 1e-15);
        }
    }

    /// N passes of `JetDir` give the Hessian of one `Jet2` pass (the
    /// same derivatives in another order: a few ulps), on a function with
    /// products, sines, cosines and atan2.
    #[test]
    fn jet_columns_give_the_second_order_jets_hessian() {
        fn g<R: Real>(x: R, y: R, z: R) -> R {
            let (s, c) = (x * z).sincos();
            f(x, y) * z + (y * s + 0.4).atan2(c * x - 2.0) * (z * z)
        }
        let p = [0.7, -1.3, 0.45];
        let j2 = g(
            Jet2::<3>::variable(p[0], 0),
            Jet2::variable(p[1], 1),
            Jet2::variable(p[2], 2),
        );
        for l in 0..3 {
            let d = g(
                JetDir::<3>::variable(p[0], 0, l),
                JetDir::variable(p[1], 1, l),
                JetDir::variable(p[2], 2, l),
            );
            assert_eq!(d.value(), j2.v);
            for i in 0..3 {
                let h = j2.hessian(i, l);
                assert!((d.dx.g[i] - h).abs() <= 1e-14 * (1.0 + h.abs()), "{i}{l}");
                assert!((d.x.g[i] - j2.g[i]).abs() <= 1e-15 * (1.0 + j2.g[i].abs()));
            }
        }
    }

    #[test]
    fn out_of_range_variable_is_a_constant() {
        assert_eq!(JetDir::<2>::variable(1.0, 5, 5), JetDir::constant(1.0));
        assert_eq!(Jet1::<2>::variable(1.0, 5), Jet1::constant(1.0));
        assert_eq!(Jet2::<2>::variable(1.0, 5), Jet2::constant(1.0));
    }
}
