//! Continuous-time dynamics from the same Lagrangian, with exact
//! derivatives: mass matrix, bias forces and the index-1 KKT system
//! ([`acceleration`] runs on the model's closed-form terms,
//! [`vigp_core::dynamics::acceleration`]; [`mass_matrix`], [`bias_forces`],
//! [`constraint_curvature`] and [`reference_acceleration`] evaluate the
//! Lagrangian on dual numbers, the independent reference the tests use)
//!
//! ```text
//! [ M(q)  −Gᵀ ] [ q̈ ]   [ ∂L/∂q + F − (∂²L/∂v∂q)·q̇ ]
//! [ G     0   ] [ λ  ] = [ −(d²/dt²) g(q + t q̇)|₀  ]
//! ```
//!
//! where M = ∂²L/∂v², and the last row is the acceleration-level constraint
//! G q̈ + Ġ q̇ = 0 with its velocity-product term.

use crate::del;
use crate::mechanism::Mechanism;
use crate::newton::{StepError, solve_kkt_regularised};
use nalgebra::{SMatrix, SVector};
use num_dual::{Dual, DualVec};

/// Mass matrix M(q) = ∂²L/∂v² at (q, v) (independent of v for mechanical
/// Lagrangians), exact.
pub fn mass_matrix<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> SMatrix<f64, N, N> {
    let q = *q;
    num_dual::jacobian(
        |vv: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
            del::momentum::<M, _, N, C>(m, &q.map(DualVec::from_re), &vv)
        },
        v,
    )
    .1
}

/// Bias forces h(q, q̇) = (∂²L/∂v∂q)·q̇ − ∂L/∂q − F, so that the unconstrained
/// equations of motion read M q̈ + h = 0.
pub fn bias_forces<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
) -> SVector<f64, N> {
    let qt = crate::kinematics::tangent(q, qdot);
    let vt = qdot.map(Dual::from_re);
    let pdot_q = del::momentum::<M, Dual<f64>, N, C>(m, &qt, &vt).map(|p| p.eps);
    pdot_q - del::force_terms::<M, f64, N, C>(m, q, qdot)
}

/// The velocity-product term γ = (d²/dt²) g(q + t·q̇) at t = 0 = Ġ q̇, exact
/// (a nested dual number).
pub fn constraint_curvature<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
) -> SVector<f64, C> {
    let path = q.zip_map(qdot, |a, b| Dual::new(Dual::new(a, b), Dual::new(b, 0.0)));
    m.constraints(&path).map(|g| g.eps.eps)
}

/// Accelerations and multipliers from the index-1 KKT system (module docs)
/// on the model's closed-form terms. Cost: one terms evaluation and one
/// O((N+C)³) solve.
///
/// A mass matrix that is singular only in directions the constraints fix
/// (a link without rotational inertia in maximal coordinates) is handled by
/// the regularised KKT solve ([`solve_kkt_regularised`]); NaN or ±∞ in
/// (q, q̇), or an overflow on the way (a velocity of 1e200), is
/// [`StepError::NonFiniteState`], a singular system
/// [`StepError::SingularJacobian`], invalid run-time parameters
/// [`StepError::InvalidModel`].
pub fn acceleration<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
) -> Result<(SVector<f64, N>, SVector<f64, C>), StepError> {
    let k = m.constants()?;
    acceleration_with(m, &k, q, qdot)
}

/// [`acceleration`] with the model's constants computed once by the caller
/// (the classical integrators hold them).
pub fn acceleration_with<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    k: &M::Constants,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
) -> Result<(SVector<f64, N>, SVector<f64, C>), StepError> {
    if !q.iter().chain(qdot.iter()).all(|x| x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    let mut t = vigp_core::Terms::zeros();
    vigp_core::dynamics::try_acceleration_forced(m, k, q, qdot, None, &mut t)
}

/// [`acceleration_with`] under inputs `u` (one per actuated joint; `U`
/// must equal the mechanism's `Dynamics::INPUTS`, or be 0 for no input):
/// the generalized force B(q)u joins the right-hand side. u = 0 is
/// [`acceleration_with`].
pub fn acceleration_forced_with<
    M: Mechanism<N, C> + vigp_core::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    m: &M,
    k: &M::Constants,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
    u: &SVector<f64, U>,
) -> Result<(SVector<f64, N>, SVector<f64, C>), StepError> {
    const {
        assert!(
            U == <M as vigp_core::Dynamics<N, C>>::INPUTS || U == 0,
            "U must equal Dynamics::INPUTS (or 0: no input)"
        )
    };
    if !u.iter().all(|x| x.is_finite()) {
        return Err(StepError::NonFiniteInput { step: None });
    }
    if u.iter().all(|x| *x == 0.0) {
        return acceleration_with(m, k, q, qdot);
    }
    if !q.iter().chain(qdot.iter()).all(|x| x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    let force = m.input_matrix::<U>(k, q) * u;
    let mut t = vigp_core::Terms::zeros();
    vigp_core::dynamics::try_acceleration_forced(m, k, q, qdot, Some(&force), &mut t)
}

/// [`acceleration`] by dual numbers (the reference implementation).
pub fn reference_acceleration<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
) -> Result<(SVector<f64, N>, SVector<f64, C>), StepError> {
    if !q.iter().chain(qdot.iter()).all(|x| x.is_finite()) {
        return Err(StepError::NonFiniteState { step: None });
    }
    let mass = mass_matrix::<M, N, C>(m, q, qdot);
    let rhs = -bias_forces::<M, N, C>(m, q, qdot);
    let (g, gamma) = if C > 0 {
        (
            m.constraint_jacobian(q),
            constraint_curvature::<M, N, C>(m, q, qdot),
        )
    } else {
        (SMatrix::zeros(), SVector::zeros())
    };
    if !mass.iter().chain(rhs.iter()).all(|x| x.is_finite()) {
        return Err(StepError::NonFiniteResidual {
            iteration: 0,
            step: None,
        });
    }
    let ((a, lambda), _) = solve_kkt_regularised(&mass, &(-g.transpose()), &g, &rhs, &(-gamma))
        .ok_or(StepError::SingularJacobian {
            iteration: 0,
            step: None,
        })?;
    if a.iter().chain(lambda.iter()).any(|x| !x.is_finite()) {
        return Err(StepError::NonFiniteResidual {
            iteration: 0,
            step: None,
        });
    }
    Ok((a, lambda))
}

/// A discrete velocity v₀ ≈ (q(Δt) − q(0))/Δt for a continuous state (q, q̇),
/// accurate to O(Δt²): v₀ = q̇ + ½Δt·q̈(q, q̇), then projected so that
/// g(q + Δt·v₀) = 0 when the model has constraints. Second-order
/// integrators need this (starting them with v₀ = q̇ costs an order).
pub fn discrete_velocity<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    q: &SVector<f64, N>,
    qdot: &SVector<f64, N>,
    dt: f64,
) -> Result<SVector<f64, N>, StepError> {
    let (a, _) = acceleration::<M, N, C>(m, q, qdot)?;
    let v = qdot + a * (0.5 * dt);
    if C == 0 {
        return Ok(v);
    }
    crate::projection::project_velocity(m, q, &v, dt, &crate::newton::StepOptions::default())
        .map(|(v, _)| v)
}
