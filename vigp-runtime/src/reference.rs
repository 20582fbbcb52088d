//! The **dual-number reference** of the variational step: the DEL
//! equations of [`crate::del`] (the Lagrangian evaluated on nested dual
//! numbers, its Jacobian by automatic differentiation) solved by a
//! chord/Newton hybrid with a merit-function line search.
//!
//! This was the production path before the closed-form engine
//! ([`vigp_core::Stepper`]); it stays as an independent second
//! implementation for tests: the same equations, derived and solved
//! differently. It is 10–50× slower; do not use it to integrate.

use crate::del;
use crate::mechanism::{Mechanism, State};
use crate::newton::{StepError, StepOptions, StepReport, solve_kkt_regularised};
use nalgebra::{SMatrix, SVector};

/// One variational step (α = 0: the paper's first-order rule; α = ½: the
/// midpoint rule) from `z`, by dual numbers. Returns the state and the
/// solver diagnostics.
pub fn step<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    options: &StepOptions,
    z: &State<N>,
) -> Result<(State<N>, StepReport), StepError> {
    step_forced(m, dt, alpha, options, z, &[])
}

/// [`step`] under inputs `u` (one per actuated joint): the generalized
/// input force ∇_q W(m₁; u) joins the forces of the residual
/// ([`del::del_terms_forced`]); the momentum p₀ is the input-free one of
/// `z`, as in `vigp_core::Stepper::step_forced`.
pub fn step_forced<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    dt: f64,
    alpha: f64,
    options: &StepOptions,
    z: &State<N>,
    u: &[f64],
) -> Result<(State<N>, StepReport), StepError> {
    vigp_core::step::check_time_step(dt)?;
    if !z.is_finite() {
        return Err(StepError::NonFiniteState { step: None });
    }
    options.validate()?;
    let x1 = z.q + z.v * dt;
    let p0 = del::previous_momentum::<M, N, C>(m, dt, alpha, &z.q, &z.v);
    let g1t: SMatrix<f64, N, C> = if C > 0 {
        Mechanism::constraint_jacobian(m, &x1).transpose()
    } else {
        SMatrix::zeros()
    };

    // Residuals in plain f64; the Jacobian (N dual directions, nested
    // duals inside) is refreshed only when contraction is slow: a
    // chord/Newton hybrid that needs one Jacobian per step in the common
    // case of a good initial guess.
    let eval = |v: &SVector<f64, N>, lambda: &SVector<f64, C>| {
        let r = p0 + del::del_terms_forced::<M, f64, N, C>(m, dt, alpha, &x1, v, u) - g1t * lambda;
        let c = if C > 0 {
            Mechanism::constraints(m, &(x1 + v * dt))
        } else {
            SVector::zeros()
        };
        (r, c)
    };
    let jacobian =
        |v: &SVector<f64, N>| del::del_terms_forced_jacobian::<M, N, C>(m, dt, alpha, &x1, v, u).1;
    let mut v = z.v;
    let mut lambda = SVector::<f64, C>::zeros();
    let mut jac = jacobian(&v);
    // Residual scales. Momentum: |p₀| + m̄·(1 unit of velocity), with m̄
    // the largest diagonal entry of the Newton matrix (≈ the largest
    // mass-matrix entry), so that the test does not depend on the mass
    // unit (a 1e-9 kg or 1e9 kg double pendulum converges like a 1 kg
    // one). Constraints: absolute (length units), scaled by the size of
    // the configuration.
    let m_bar = (0..N).map(|i| jac[(i, i)].abs()).fold(0.0, f64::max);
    let p_scale = match p0.amax() + m_bar {
        0.0 => 1.0,
        s => s,
    };
    let g_scale = crate::mechanism::length_scale::<M, N, C>(&x1);
    let merit = |r: &SVector<f64, N>, c: &SVector<f64, C>| {
        let a = r.norm() / p_scale;
        let b = c.norm() / g_scale;
        a * a + b * b
    };
    let (mut r, mut c) = eval(&v, &lambda);
    let mut fresh = true;
    let mut regularised = false;
    let tol = options.tolerance;
    let mut stalled = false;
    for iter in 0..=options.max_iterations {
        let res_r = r.amax() / p_scale;
        let res_c = c.amax() / g_scale;
        if !(res_r.is_finite() && res_c.is_finite()) {
            return Err(StepError::NonFiniteResidual {
                iteration: iter,
                step: None,
            });
        }
        // Converged; or stalled at the attainable accuracy of a
        // near-singular KKT system (e.g. a loop at a configuration where
        // its constraint Jacobian loses rank, so that g is quadratic in
        // the lost direction and no linear correction reduces it): Newton
        // can no longer decrease the residual and both parts are within
        // `stall_tolerance`.
        let converged = res_r <= tol && res_c <= tol;
        let stall_tol = options.stall_tolerance;
        let accept_stall = stalled && res_c <= stall_tol && res_r <= stall_tol;
        if converged || accept_stall {
            let next = State { q: x1, v };
            if !next.is_finite() {
                return Err(StepError::NonFiniteState { step: None });
            }
            return Ok((
                next,
                StepReport {
                    iterations: iter,
                    residual: res_r.max(res_c),
                    stalled: !converged,
                    regularised,
                    ..StepReport::default()
                },
            ));
        }
        if iter == options.max_iterations {
            return Err(StepError::NotConverged {
                iterations: iter,
                residual: res_r.max(res_c),
                tolerance: tol,
                step: None,
            });
        }
        let a: SMatrix<f64, C, N> = if C > 0 {
            Mechanism::constraint_jacobian(m, &(x1 + v * dt)) * dt
        } else {
            SMatrix::zeros()
        };
        if !jac.iter().chain(a.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFiniteResidual {
                iteration: iter,
                step: None,
            });
        }
        let Some(((dv, dl), reg)) = solve_kkt_regularised(&jac, &(-g1t), &a, &r, &c) else {
            return Err(StepError::SingularJacobian {
                iteration: iter,
                step: None,
            });
        };
        regularised |= reg;
        // Newton direction is −(dv, dl); backtrack on the merit function.
        let phi0 = merit(&r, &c);
        let mut alpha = 1.0;
        loop {
            let v_try = v - dv * alpha;
            let l_try = lambda - dl * alpha;
            let (r_try, c_try) = eval(&v_try, &l_try);
            let phi = merit(&r_try, &c_try);
            if phi.is_finite() && phi <= (1.0 - 1e-4 * alpha) * phi0 {
                (v, lambda, r, c) = (v_try, l_try, r_try, c_try);
                // slow contraction: the old Jacobian is stale
                if phi > 1e-2 * phi0 {
                    jac = jacobian(&v);
                    fresh = true;
                } else {
                    fresh = false;
                }
                break;
            }
            if alpha <= options.min_step {
                if fresh {
                    // no decrease along the exact Newton direction: keep
                    // the iterate and let the acceptance test decide
                    stalled = true;
                } else {
                    jac = jacobian(&v);
                    fresh = true;
                }
                break;
            }
            alpha *= 0.5;
        }
    }
    unreachable!("the loop returns on its last iteration")
}
