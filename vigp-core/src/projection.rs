//! The velocity projection of paper eq. (8) on fixed-size data: the one
//! implementation behind the embedded learned step
//! ([`crate::LearnedStepper`]) and the std runtime's
//! `vigp::projection::project_velocity` (which adds a restart from the
//! projected configuration far off the manifold).
//!
//! v = argmin ‖v − v_u‖² subject to g(x₁ + Δt·v) = 0, by exact Newton on
//! the KKT system
//!
//! ```text
//! [ I + Δt²·Σ μ_i ∇²g_i(x₂)   Δt·Gᵀ ] [ Δv ]   [ v − v_u + Δt·Gᵀμ ]
//! [ Δt·G                       0     ] [ Δμ ] = [ g(x₂)            ],   x₂ = x₁ + Δt·v
//! ```
//!
//! (closed-form constraints, Jacobian and Σ μ_i ∇²g_i of the model; a
//! Gauss–Newton step without the curvature term stalls when the correction
//! is large) with a backtracking line search on the scaled residual, and a
//! regularised KKT solve where the matrix is singular
//! ([`crate::linalg::solve_kkt_regularised`]). The velocity residual is
//! scaled by 1 + |v_u|∞, the constraint residual by 1 + the largest length
//! coordinate. A Newton direction along which the residual no longer
//! decreases is accepted at [`StepOptions::stall_tolerance`].

use crate::dynamics::Dynamics;
use crate::linalg::solve_kkt_regularised;
use crate::state::CoordinateKind;
use crate::step::{StepError, StepOptions, StepReport, check_time_step};
use nalgebra::{SMatrix, SVector};

/// The projected velocity of `v_u` from the position `x1` (module docs),
/// Newton started at v_u.
pub fn project_velocity<M: Dynamics<N, C>, const N: usize, const C: usize>(
    model: &M,
    k: &M::Constants,
    x1: &SVector<f64, N>,
    v_u: &SVector<f64, N>,
    dt: f64,
    options: &StepOptions,
) -> Result<SVector<f64, N>, StepError> {
    project_velocity_from(model, k, x1, v_u, v_u, dt, options).map(|(v, _)| v)
}

/// [`project_velocity`] with Newton started at `start`, and its
/// diagnostics (iterations, final scaled residual, whether it was accepted
/// as stalled or needed the regularised solve). Errors: an invalid Δt or
/// options, a non-finite input or residual, no convergence within
/// [`StepOptions::max_iterations`], a singular KKT matrix.
pub fn project_velocity_from<M: Dynamics<N, C>, const N: usize, const C: usize>(
    model: &M,
    k: &M::Constants,
    x1: &SVector<f64, N>,
    v_u: &SVector<f64, N>,
    start: &SVector<f64, N>,
    dt: f64,
    options: &StepOptions,
) -> Result<(SVector<f64, N>, StepReport), StepError> {
    check_time_step(dt)?;
    options.validate()?;
    if !(x1.iter().chain(v_u).chain(start).all(|x| x.is_finite())) {
        return Err(StepError::NonFiniteState { step: None });
    }
    if C == 0 {
        return Ok((*v_u, StepReport::default()));
    }
    let v_scale = 1.0 + v_u.amax();
    let mut length = 0.0f64;
    for (x, kind) in x1.iter().zip(M::KINDS.iter()) {
        if *kind == CoordinateKind::Length {
            length = length.max(x.abs());
        }
    }
    let g_scale = 1.0 + length;
    // r = v − v_u + Δt·Gᵀμ, c = g(x₂), J = I + Δt²·Σ μ_i ∇²g_i(x₂)
    let eval = |v: &SVector<f64, N>, mu: &SVector<f64, C>| {
        let x2 = x1 + v * dt;
        let (c, gj) = model.constraints_and_jacobian(k, &x2);
        let hess = model.constraint_hessian(k, &x2, mu) * (dt * dt);
        let r = v - v_u + gj.transpose() * mu * dt;
        (r, c, gj, SMatrix::<f64, N, N>::identity() + hess)
    };
    let merit = |r: &SVector<f64, N>, c: &SVector<f64, C>| {
        let (a, b) = (r.norm() / v_scale, c.norm() / g_scale);
        a * a + b * b
    };
    let mut v = *start;
    let mut mu = SVector::<f64, C>::zeros();
    let (mut r, mut c, mut gj, mut jac) = eval(&v, &mu);
    let mut stalled = false;
    let mut regularised = false;
    for iteration in 0..=options.max_iterations {
        let (res_r, res_c) = (r.amax() / v_scale, c.amax() / g_scale);
        if !(res_r.is_finite() && res_c.is_finite()) {
            return Err(StepError::non_finite_residual(iteration));
        }
        let converged = res_r <= options.tolerance && res_c <= options.tolerance;
        let accept_stall = stalled && res_r.max(res_c) <= options.stall_tolerance;
        if converged || accept_stall {
            let report = StepReport::newton(iteration, res_r.max(res_c), !converged, regularised);
            return Ok((v, report));
        }
        if iteration == options.max_iterations {
            return Err(StepError::not_converged(
                iteration,
                res_r.max(res_c),
                options.tolerance,
            ));
        }
        let a = gj * dt;
        let Some(((dv, dmu), reg)) = solve_kkt_regularised(&jac, &a.transpose(), &a, &r, &c) else {
            return Err(StepError::singular(iteration));
        };
        regularised |= reg;
        let phi0 = merit(&r, &c);
        let mut alpha = 1.0;
        loop {
            let (v_try, mu_try) = (v - dv * alpha, mu - dmu * alpha);
            let (r_try, c_try, gj_try, jac_try) = eval(&v_try, &mu_try);
            let phi = merit(&r_try, &c_try);
            if phi.is_finite() && phi <= (1.0 - 1e-4 * alpha) * phi0 {
                (v, mu, r, c, gj, jac) = (v_try, mu_try, r_try, c_try, gj_try, jac_try);
                break;
            }
            if alpha <= options.min_step {
                // no decrease along the Newton direction (see
                // `StepOptions::stall_tolerance`)
                stalled = true;
                break;
            }
            alpha *= 0.5;
        }
    }
    // the loop returns on its last iteration (iteration == max_iterations)
    Err(StepError::not_converged(
        options.max_iterations,
        f64::NAN,
        options.tolerance,
    ))
}
