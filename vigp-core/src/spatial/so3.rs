//! The rotation group in unit quaternions: the exponential map and its
//! inverse, the right Jacobian J_r, and the discrete angular momenta of the
//! Lie-group variational integrator with their exact derivatives.
//!
//! Conventions: a quaternion (w, x, y, z) maps body vectors to world
//! vectors; body angular velocities are left-trivialised, q̇ = q ⊗ (0, ω/2).
//! exp(ξ) is the rotation by |ξ| about ξ/|ξ|, and
//! exp(ξ + δ) = exp(ξ) ⊗ exp(J_r(ξ)·δ + O(δ²)).

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Below this rotation angle the closed forms are replaced by their Taylor
/// series (the first omitted terms are below 1e-18 relative there). Above
/// it the closed forms of J_r and β cancel to ~10ε/θ² relative in their ξ̂²
/// coefficients, which is ~ε absolute once multiplied by |ξ̂²| = θ².
const SERIES: f64 = 0.1;

/// The skew-symmetric matrix v̂ with v̂·a = v × a.
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The unit quaternion of the rotation vector ξ: (cos(θ/2), sin(θ/2)·ξ/θ),
/// θ = |ξ|.
pub fn exp(xi: &Vector3<f64>) -> UnitQuaternion<f64> {
    let t2 = xi.norm_squared();
    let theta = libm::sqrt(t2);
    let (c, s_over) = if theta < SERIES {
        // cos(θ/2), sin(θ/2)/θ by their series (to θ⁸)
        let c = 1.0 - t2 / 8.0 + t2 * t2 / 384.0 - t2 * t2 * t2 / 46080.0
            + t2 * t2 * t2 * t2 / 10321920.0;
        let s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0 - t2 * t2 * t2 / 645120.0;
        (c, s)
    } else {
        let (s, c) = libm::sincos(0.5 * theta);
        (c, s / theta)
    };
    UnitQuaternion::new_unchecked(Quaternion::new(
        c,
        s_over * xi.x,
        s_over * xi.y,
        s_over * xi.z,
    ))
}

/// The rotation vector of a unit quaternion (the inverse of [`exp`], angle
/// in [0, π]): the sign of q is chosen so that w ≥ 0.
pub fn log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let q = q.quaternion();
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    if s < 1e-8 {
        // θ = 2·atan2(s, w) = 2s/w·(1 − s²/(3w²) + …); s² ≤ 1e-16
        v * (2.0 / w)
    } else {
        v * (2.0 * libm::atan2(s, w) / s)
    }
}

/// The right Jacobian of exp: J_r(ξ) = I − (1 − cos θ)/θ²·ξ̂ + (θ − sin θ)/θ³·ξ̂².
pub fn right_jacobian(xi: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = xi.norm_squared();
    let theta = libm::sqrt(t2);
    let (a, b) = if theta < SERIES {
        (
            0.5 - t2 / 24.0 + t2 * t2 / 720.0 - t2 * t2 * t2 / 40320.0,
            1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0 - t2 * t2 * t2 / 362880.0,
        )
    } else {
        // 1 − cos θ = 2 sin²(θ/2) without cancellation; θ − sin θ cancels
        // to ~6ε/θ² relative, ~ε after the factor |ξ̂²| = θ²
        let s = libm::sin(theta);
        let sh = libm::sin(0.5 * theta);
        (2.0 * sh * sh / t2, (theta - s) / (t2 * theta))
    };
    let h = hat(xi);
    Matrix3::identity() - h * a + h * h * b
}

/// β(θ) = (1 − (θ/2)·cot(θ/2))/θ², the ξ̂² coefficient of J_r(ξ)⁻¹ =
/// I + ½ξ̂ + β·ξ̂², and β′(θ)/θ.
pub fn beta(theta: f64) -> (f64, f64) {
    let t2 = theta * theta;
    if theta < SERIES {
        // (θ/2)cot(θ/2) = 1 − θ²/12 − θ⁴/720 − θ⁶/30240 − θ⁸/1209600 − θ¹⁰/47900160
        let b = 1.0 / 12.0
            + t2 / 720.0
            + t2 * t2 / 30240.0
            + t2 * t2 * t2 / 1209600.0
            + t2 * t2 * t2 * t2 / 47900160.0;
        let db = 2.0 / 720.0
            + 4.0 * t2 / 30240.0
            + 6.0 * t2 * t2 / 1209600.0
            + 8.0 * t2 * t2 * t2 / 47900160.0;
        (b, db)
    } else {
        let (s, c) = libm::sincos(0.5 * theta);
        let cot = c / s;
        let b = 1.0 / t2 - cot / (2.0 * theta);
        // β′ = −2/θ³ + cot(θ/2)/(2θ²) + 1/(4θ sin²(θ/2))
        let db = -2.0 / (t2 * theta) + cot / (2.0 * t2) + 1.0 / (4.0 * theta * s * s);
        (b, db / theta)
    }
}

/// The discrete angular momentum of a body with inertia `j` (body frame)
/// and discrete body angular velocity ω over a step `dt`:
///
/// * `sign = -1.0`: μ⁻(ω) = J_r(Δt·ω)⁻ᵀ·Jω, the derivative of the discrete
///   kinetic energy Δt·½ωᵀJω with respect to the step's end orientation
///   (left-trivialised),
/// * `sign = +1.0`: μ⁺(ω) = J_r(Δt·ω)⁻¹·Jω, minus its derivative with
///   respect to the start orientation.
///
/// Both are Jω ± (Δt/2)·ω × Jω + Δt²·β(Δt|ω|)·ω × (ω × Jω).
pub fn momentum(j: &Matrix3<f64>, w: &Vector3<f64>, dt: f64, sign: f64) -> Vector3<f64> {
    let u = j * w;
    let a = w.cross(&u);
    let b = w.cross(&a);
    let (beta, _) = beta(dt * w.norm());
    u + a * (sign * 0.5 * dt) + b * (dt * dt * beta)
}

/// The exact Jacobian ∂[`momentum`]/∂ω.
pub fn momentum_jacobian(j: &Matrix3<f64>, w: &Vector3<f64>, dt: f64, sign: f64) -> Matrix3<f64> {
    let u = j * w;
    let a = w.cross(&u);
    let b = w.cross(&a);
    let (beta, dbeta) = beta(dt * w.norm());
    let (wh, uh, ah) = (hat(w), hat(&u), hat(&a));
    // ∂a/∂ω = ŵJ − û, ∂b/∂ω = ŵ(ŵJ − û) − â, ∂β/∂ω = (β′/θ)·Δt²·ωᵀ
    let da = wh * j - uh;
    let db = wh * da - ah;
    j + da * (sign * 0.5 * dt) + (db * beta + b * w.transpose() * (dbeta * dt * dt)) * (dt * dt)
}

/// q ⊗ exp(Δt·ω), renormalised (the product of two unit quaternions is
/// unit up to rounding; renormalising keeps |‖q‖ − 1| at the rounding level
/// over any number of steps).
pub fn advance(q: &UnitQuaternion<f64>, w: &Vector3<f64>, dt: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(q.quaternion() * exp(&(w * dt)).quaternion())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vectors() -> [Vector3<f64>; 6] {
        [
            Vector3::new(0.3, -0.2, 0.5),
            Vector3::new(1e-9, 2e-9, -1e-9),
            Vector3::new(0.05, 0.04, -0.03),
            Vector3::new(0.099, 0.0, 0.0),
            Vector3::new(0.0, 0.1001, 0.0),
            Vector3::new(-1.5, 1.0, 2.0),
        ]
    }

    #[test]
    fn exp_matches_nalgebra_and_log_inverts_it() {
        for xi in vectors() {
            let q = exp(&xi);
            let reference = UnitQuaternion::from_scaled_axis(xi);
            assert!(
                (q.quaternion() - reference.quaternion()).norm() < 1e-15,
                "{xi}"
            );
            assert!((q.quaternion().norm() - 1.0).abs() < 1e-15);
            assert!((log(&q) - xi).norm() < 1e-15 * (1.0 + xi.norm()), "{xi}");
        }
    }

    /// J_r against central differences of exp: exp(ξ)⁻¹·exp(ξ + hδ) ≈ exp(h·J_r δ).
    #[test]
    fn right_jacobian_matches_finite_differences() {
        for xi in vectors() {
            let jr = right_jacobian(&xi);
            let h = 1e-6;
            for k in 0..3 {
                let mut d = Vector3::zeros();
                d[k] = h;
                let p = log(&(exp(&xi).inverse() * exp(&(xi + d))));
                let m = log(&(exp(&xi).inverse() * exp(&(xi - d))));
                let col = (p - m) / (2.0 * h);
                assert!(
                    (col - jr.column(k)).norm() < 1e-9,
                    "{xi}: {col} vs {}",
                    jr.column(k)
                );
            }
            // J_r⁻¹ = I + ½ξ̂ + βξ̂²
            let theta = xi.norm();
            let h = hat(&xi);
            let inv = Matrix3::identity() + h * 0.5 + h * h * beta(theta).0;
            assert!((inv * jr - Matrix3::identity()).amax() < 1e-14);
        }
    }

    #[test]
    fn beta_derivative_matches_finite_differences() {
        // h = 1e-4: truncation ~h²·β‴ < 1e-11, rounding of the closed form
        // (~1e-14 absolute near θ = 0.1) / h ~ 1e-10
        for theta in [1e-3, 0.05, 0.0999, 0.1001, 0.7, 2.0f64] {
            let h = 1e-4 * theta.min(1.0);
            let fd = (beta(theta + h).0 - beta(theta - h).0) / (2.0 * h);
            assert!((fd / theta - beta(theta).1).abs() < 1e-8, "{theta}");
        }
        // the series and the closed form meet at the switch
        let (a, b) = (beta(SERIES * (1.0 - 1e-12)), beta(SERIES * (1.0 + 1e-12)));
        assert!((a.0 - b.0).abs() < 1e-14 && (a.1 - b.1).abs() < 1e-11);
    }

    #[test]
    fn momentum_jacobian_matches_finite_differences() {
        let j = Matrix3::new(0.4, 0.05, -0.02, 0.05, 0.7, 0.01, -0.02, 0.01, 1.1);
        for w in [
            Vector3::new(3.0, -2.0, 5.0),
            Vector3::new(1e-6, 0.0, 2e-6),
            Vector3::new(40.0, 25.0, -30.0),
        ] {
            for sign in [-1.0, 1.0] {
                let dt = 0.01;
                let jac = momentum_jacobian(&j, &w, dt, sign);
                for k in 0..3 {
                    let h = 1e-6 * (1.0 + w.amax());
                    let mut d = Vector3::zeros();
                    d[k] = h;
                    let fd = (momentum(&j, &(w + d), dt, sign) - momentum(&j, &(w - d), dt, sign))
                        / (2.0 * h);
                    let scale = jac.amax();
                    assert!((fd - jac.column(k)).amax() < 1e-8 * scale, "{w} {sign}");
                }
            }
        }
    }

    /// μ⁻ is the derivative of the discrete kinetic energy Δt·½ωᵀJω,
    /// ω = log(q_k⁻¹q_{k+1})/Δt, along a left-trivialised variation of
    /// q_{k+1}; μ⁺ that of q_k (with a minus sign).
    #[test]
    fn momenta_are_derivatives_of_the_discrete_lagrangian() {
        let j = Matrix3::new(0.4, 0.05, -0.02, 0.05, 0.7, 0.01, -0.02, 0.01, 1.1);
        let dt = 0.02;
        let q0 = exp(&Vector3::new(0.3, -1.0, 0.4));
        let w = Vector3::new(7.0, -3.0, 11.0);
        let q1 = q0 * exp(&(w * dt));
        let ld = |a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>| {
            let w = log(&(a.inverse() * b)) / dt;
            dt * 0.5 * w.dot(&(j * w))
        };
        let h = 1e-6;
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            let d1 = (ld(&q0, &(q1 * exp(&e))) - ld(&q0, &(q1 * exp(&-e)))) / (2.0 * h);
            let d0 = (ld(&(q0 * exp(&e)), &q1) - ld(&(q0 * exp(&-e)), &q1)) / (2.0 * h);
            assert!((d1 - momentum(&j, &w, dt, -1.0)[k]).abs() < 1e-7, "end {k}");
            assert!(
                (d0 + momentum(&j, &w, dt, 1.0)[k]).abs() < 1e-7,
                "start {k}"
            );
        }
    }
}
