//! The discrete Euler–Lagrange (DEL) residual of the first-order variational
//! integrator (paper eq. 5–6, DESIGN §3) and its exact Jacobian.
//!
//! With x₁ = x₀ + Δt·v₀ fixed, the unknowns are v₁ and the multipliers λ:
//!
//! ```text
//! d(v₁, λ) = p₀ − D_vL(x₁, v₁) + Δt·D_xL(x₁, v₁) + Δt·F(x₁, v₁) − G(x₁)ᵀλ = 0
//! c(v₁)    = g(x₁ + Δt·v₁) = 0,            p₀ = D_vL(x₀, v₀)
//! ```

use crate::mechanism::{Mechanism, Scalar};
use nalgebra::{SMatrix, SVector};
use num_dual::{DualVec, gradient};

/// Momentum p = D_vL(x, v), exact.
pub fn momentum<M, D, const N: usize, const C: usize>(
    m: &M,
    x: &SVector<D, N>,
    v: &SVector<D, N>,
) -> SVector<D, N>
where
    M: Mechanism<N, C>,
    D: Scalar,
{
    let x = x.map(DualVec::from_re);
    gradient(|v| m.lagrangian(&x, &v), v).1
}

/// The v₁-dependent part of the DEL residual,
/// −D_vL(x₁, v₁) + Δt·D_xL(x₁, v₁) + Δt·F(x₁, v₁), generic over the scalar
/// so that its Jacobian comes from the same body.
pub fn del_terms<M, D, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    x1: &SVector<D, N>,
    v1: &SVector<D, N>,
) -> SVector<D, N>
where
    M: Mechanism<N, C>,
    D: Scalar,
{
    let p1 = momentum::<M, D, N, C>(m, x1, v1);
    let vv = v1.map(DualVec::from_re);
    let dxl = gradient(|x| m.lagrangian(&x, &vv), x1).1;
    let mut r = dxl * D::from(dt) - p1;
    if M::DISSIPATIVE {
        r += m.generalized_forces(x1, v1) * D::from(dt);
    }
    r
}

/// Full DEL residual d(v₁, λ) for given p₀ and x₁.
pub fn residual<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    p0: &SVector<f64, N>,
    x1: &SVector<f64, N>,
    v1: &SVector<f64, N>,
    lambda: &SVector<f64, C>,
) -> SVector<f64, N>
where
    M: Mechanism<N, C>,
{
    let mut r = p0 + del_terms::<M, f64, N, C>(m, dt, x1, v1);
    if C > 0 {
        r -= m.constraint_jacobian(x1).transpose() * lambda;
    }
    r
}

/// Residual terms and their exact Jacobian ∂d/∂v₁ (N×N) in one dual pass.
pub fn del_terms_jacobian<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    x1: &SVector<f64, N>,
    v1: &SVector<f64, N>,
) -> (SVector<f64, N>, SMatrix<f64, N, N>)
where
    M: Mechanism<N, C>,
{
    let x1 = *x1;
    num_dual::jacobian(
        |v: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
            let x = x1.map(DualVec::from_re);
            del_terms::<M, _, N, C>(m, dt, &x, &v)
        },
        v1,
    )
}
