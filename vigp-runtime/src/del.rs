//! The discrete Euler–Lagrange (DEL) residual of the variational integrators
//! (paper eq. 5–6) and its exact Jacobian.
//!
//! The discrete Lagrangian is L_d(x_k, x_{k+1}) = Δt·L(x_k + αΔt·v_k, v_k)
//! with v_k = (x_{k+1} − x_k)/Δt: α = 0 is the paper's first-order
//! (rectangle) rule, α = ½ the second-order midpoint rule. With
//! x₁ = x₀ + Δt·v₀ fixed, the unknowns are v₁ and the multipliers λ:
//!
//! ```text
//! d(v₁, λ) = p₀ + (1−α)Δt·(D_xL + F)(m₁, v₁) − D_vL(m₁, v₁) − G(x₁)ᵀλ = 0
//! c(v₁)    = g(x₁ + Δt·v₁) = 0
//! p₀       = D_vL(m₀, v₀) + αΔt·(D_xL + F)(m₀, v₀),   m_k = x_k + αΔt·v_k
//! ```
//!
//! For α = 0 this is exactly the paper's first-order rule (eq. 5–6):
//! p₀ − D_vL(x₁, v₁) + Δt·D_xL(x₁, v₁) + Δt·F(x₁, v₁) − G(x₁)ᵀλ = 0.

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

/// D_xL(x, v) + F(x, v): the generalized force side of the Euler–Lagrange
/// equations, exact.
pub fn force_terms<M, D, const N: usize, const C: usize>(
    m: &M,
    x: &SVector<D, N>,
    v: &SVector<D, N>,
) -> SVector<D, N>
where
    M: Mechanism<N, C>,
    D: Scalar,
{
    let vv = v.map(DualVec::from_re);
    let mut f = gradient(|x| m.lagrangian(&x, &vv), x).1;
    if M::DISSIPATIVE {
        f += m.generalized_forces(x, v);
    }
    f
}

/// The "previous step" momentum p₀ of the DEL residual (see module docs).
pub fn previous_momentum<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    x0: &SVector<f64, N>,
    v0: &SVector<f64, N>,
) -> SVector<f64, N>
where
    M: Mechanism<N, C>,
{
    if alpha == 0.0 {
        return momentum::<M, f64, N, C>(m, x0, v0);
    }
    let m0 = x0 + v0 * (alpha * dt);
    momentum::<M, f64, N, C>(m, &m0, v0) + force_terms::<M, f64, N, C>(m, &m0, v0) * (alpha * dt)
}

/// The v₁-dependent part of the DEL residual,
/// (1−α)Δt·(D_xL + F)(m₁, v₁) − D_vL(m₁, v₁) with m₁ = x₁ + αΔt·v₁, generic
/// over the scalar so that its Jacobian comes from the same body.
pub fn del_terms<M, D, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    x1: &SVector<D, N>,
    v1: &SVector<D, N>,
) -> SVector<D, N>
where
    M: Mechanism<N, C>,
    D: Scalar,
{
    del_terms_forced::<M, D, N, C>(m, dt, alpha, x1, v1, &[])
}

/// [`del_terms`] under inputs `u`: the generalized input force
/// ∇_q W(m₁; u) ([`Mechanism::input_force`]) joins the forces,
/// (1−α)Δt·(D_xL + F + ∇W)(m₁, v₁) − D_vL(m₁, v₁).
pub fn del_terms_forced<M, D, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    x1: &SVector<D, N>,
    v1: &SVector<D, N>,
    u: &[f64],
) -> SVector<D, N>
where
    M: Mechanism<N, C>,
    D: Scalar,
{
    let m1 = if alpha == 0.0 {
        *x1
    } else {
        x1 + v1 * D::from(alpha * dt)
    };
    let mut f = force_terms::<M, D, N, C>(m, &m1, v1);
    if u.iter().any(|x| *x != 0.0) {
        f += m.input_force(&m1, u);
    }
    f * D::from((1.0 - alpha) * dt) - momentum::<M, D, N, C>(m, &m1, v1)
}

/// Full DEL residual d(v₁, λ) for given p₀ and x₁.
pub fn residual<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    p0: &SVector<f64, N>,
    x1: &SVector<f64, N>,
    v1: &SVector<f64, N>,
    lambda: &SVector<f64, C>,
) -> SVector<f64, N>
where
    M: Mechanism<N, C>,
{
    let mut r = p0 + del_terms::<M, f64, N, C>(m, dt, alpha, x1, v1);
    if C > 0 {
        r -= m.constraint_jacobian(x1).transpose() * lambda;
    }
    r
}

/// Residual terms and their exact Jacobian ∂d/∂v₁ (N×N) in one dual pass.
pub fn del_terms_jacobian<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    x1: &SVector<f64, N>,
    v1: &SVector<f64, N>,
) -> (SVector<f64, N>, SMatrix<f64, N, N>)
where
    M: Mechanism<N, C>,
{
    del_terms_forced_jacobian::<M, N, C>(m, dt, alpha, x1, v1, &[])
}

/// [`del_terms_forced`] and its exact Jacobian ∂d/∂v₁ in one dual pass.
pub fn del_terms_forced_jacobian<M, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    x1: &SVector<f64, N>,
    v1: &SVector<f64, N>,
    u: &[f64],
) -> (SVector<f64, N>, SMatrix<f64, N, N>)
where
    M: Mechanism<N, C>,
{
    let x1 = *x1;
    num_dual::jacobian(
        |v: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
            let x = x1.map(DualVec::from_re);
            del_terms_forced::<M, _, N, C>(m, dt, alpha, &x, &v, u)
        },
        v1,
    )
}
