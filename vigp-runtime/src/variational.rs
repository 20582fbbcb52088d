//! The first-order variational integrator (paper eq. 5–6) and the
//! [`Integrator`] trait shared by every integrator in vigp.

use crate::del;
use crate::mechanism::{Mechanism, State};
use crate::newton::{NewtonOptions, StepError, StepInfo, solve_kkt_regularised};
use nalgebra::{SMatrix, SVector};

/// A one-step map z_k ↦ z_{k+1} with a fixed time step.
///
/// Implemented by every integrator, so a user swaps integrators in one line.
pub trait Integrator<const N: usize> {
    /// The time step Δt in seconds.
    fn dt(&self) -> f64;

    /// One step. Never returns a non-finite state.
    fn step(&self, z: &State<N>) -> Result<State<N>, StepError>;

    /// The energy of a state as this integrator defines it, when that is
    /// not the model's `energy(z)`: the midpoint VI's discrete velocity
    /// belongs to the interval's midpoint ([`Variational::energy`]).
    /// `None` (the default) means the model's energy; [`crate::summarize`]
    /// uses this.
    fn state_energy(&self, z: &State<N>) -> Option<f64> {
        let _ = z;
        None
    }

    /// Fill `out` with the states after 1, 2, …, `out.len()` steps from `z0`,
    /// without allocating. Stops at the first error (which names the step).
    fn rollout_into(&self, z0: &State<N>, out: &mut [State<N>]) -> Result<(), StepError> {
        let mut z = *z0;
        for (k, slot) in out.iter_mut().enumerate() {
            z = self.step(&z).map_err(|e| e.at_step(k))?;
            *slot = z;
        }
        Ok(())
    }

    /// The trajectory z_0, z_1, …, z_steps (`steps + 1` states).
    #[cfg(feature = "alloc")]
    fn rollout(&self, z0: &State<N>, steps: usize) -> Result<Vec<State<N>>, StepError> {
        let mut traj = vec![*z0; steps + 1];
        self.rollout_into(z0, &mut traj[1..])?;
        Ok(traj)
    }
}

/// A variational integrator on a [`Mechanism`]: the paper's first-order
/// rule ([`Variational::new`]) or the second-order midpoint rule
/// ([`Variational::midpoint`]); see [`crate::del`].
///
/// Each step sets x₁ = x₀ + Δt·v₀ and solves the DEL equations with the
/// constraint g(x₁ + Δt·v₁) = 0 for (v₁, λ) by Newton's method on the KKT
/// system with exact Jacobians (dual numbers) and a backtracking line search.
/// Cost per Newton iteration: one dual-number evaluation of the residual and
/// its N×N Jacobian, one O((N+C)³) pivoted solve; no allocation.
///
/// **Large steps.** The DEL equations are quadratic in v₁ (velocity terms of
/// D_xL); when Δt·|v| is large against the configuration's curvature they
/// can have no root near v₀, and the step fails with
/// [`StepError::NotConverged`] (e.g. the double pendulum at Δt = 0.1 s and
/// 3 rev/s). [`Variational::substeps`] is the opt-in remedy.
#[derive(Clone, Copy, Debug)]
pub struct Variational<M, const N: usize, const C: usize> {
    model: M,
    dt: f64,
    alpha: f64,
    options: NewtonOptions,
    substeps: usize,
}

impl<M: Mechanism<N, C>, const N: usize, const C: usize> Variational<M, N, C> {
    /// An integrator for `model` with time step `dt` and default Newton
    /// options. An invalid `dt` (≤ 0 or not finite) is reported by `step`.
    pub fn new(model: M, dt: f64) -> Self {
        Self {
            model,
            dt,
            alpha: 0.0,
            options: NewtonOptions::default(),
            substeps: 1,
        }
    }

    /// The second-order variational integrator of the midpoint discrete
    /// Lagrangian L_d = Δt·L((x_k + x_{k+1})/2, (x_{k+1} − x_k)/Δt).
    pub fn midpoint(model: M, dt: f64) -> Self {
        Self {
            alpha: 0.5,
            ..Self::new(model, dt)
        }
    }

    /// Order of accuracy of the discretisation (1 or 2).
    pub fn order(&self) -> usize {
        if self.alpha == 0.0 { 1 } else { 2 }
    }

    /// Replace the Newton options.
    pub fn with_options(mut self, options: NewtonOptions) -> Self {
        self.options = options;
        self
    }

    /// Relative residual tolerance (default 1e-12).
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.options.tolerance = tol;
        self
    }

    /// Iteration cap (default 25).
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.options.max_iterations = n;
        self
    }

    /// Opt-in sub-stepping: each step of Δt is `k` variational steps of
    /// h = Δt/k (default 1). The integrator is then exactly the variational
    /// integrator at h, sampled every Δt, and **the state's velocity is the
    /// discrete velocity of the sub-step**, v = (q(t + h) − q(t))/h (start it
    /// with h, e.g. [`crate::dynamics::discrete_velocity`]`(m, q, q̇, Δt/k)`).
    /// Use it when Δt·|v| is too large for the DEL equations to have a root
    /// (module docs); cost k steps. `k = 0` is reported by `step` as
    /// [`StepError::InvalidOptions`].
    pub fn substeps(mut self, k: usize) -> Self {
        self.substeps = k;
        self
    }

    /// The number of sub-steps per step (see [`Variational::substeps`]).
    pub fn substep_count(&self) -> usize {
        self.substeps
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The Newton options in use.
    pub fn options(&self) -> &NewtonOptions {
        &self.options
    }

    /// One step with solver diagnostics (with sub-steps: iterations summed,
    /// the largest residual, and any sub-step's flags).
    pub fn step_with_info(&self, z: &State<N>) -> Result<(State<N>, StepInfo), StepError> {
        let dt = self.dt;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(StepError::InvalidTimeStep { dt });
        }
        if !z.is_finite() {
            return Err(StepError::NonFiniteState { step: None });
        }
        self.options.validate()?;
        if self.substeps == 0 {
            return Err(StepError::InvalidOptions("substeps must be >= 1"));
        }
        if self.substeps == 1 {
            return self.solve_step(z, dt).map_err(|e| self.explain(e, z));
        }
        let h = dt / self.substeps as f64;
        let mut z = *z;
        let mut info = StepInfo {
            iterations: 0,
            residual: 0.0,
            stalled: false,
            regularised: false,
            restarted: false,
        };
        for _ in 0..self.substeps {
            let (next, i) = self.solve_step(&z, h).map_err(|e| self.explain(e, &z))?;
            z = next;
            info.iterations += i.iterations;
            info.residual = info.residual.max(i.residual);
            info.stalled |= i.stalled;
            info.regularised |= i.regularised;
        }
        Ok((z, info))
    }

    /// A `NotConverged` step from a configuration off the constraints
    /// becomes [`StepError::OffConstraints`], which names the remedy.
    fn explain(&self, e: StepError, z: &State<N>) -> StepError {
        match e {
            StepError::NotConverged {
                iterations,
                residual,
                step,
                ..
            } if C > 0 => {
                let scale = crate::mechanism::length_scale::<M, N, C>(&z.q);
                let violation = self.model.constraints(&z.q).amax() / scale;
                // consistent states have |g| at solver tolerance (1e-12)
                if violation > 1e-8 {
                    StepError::OffConstraints {
                        violation,
                        iterations,
                        residual,
                        step,
                    }
                } else {
                    e
                }
            }
            e => e,
        }
    }

    /// One variational step of size `dt` from a validated state.
    fn solve_step(&self, z: &State<N>, dt: f64) -> Result<(State<N>, StepInfo), StepError> {
        let m = &self.model;
        let x1 = z.q + z.v * dt;
        let alpha = self.alpha;
        let p0 = del::previous_momentum::<M, N, C>(m, dt, alpha, &z.q, &z.v);
        let g1t: SMatrix<f64, N, C> = if C > 0 {
            m.constraint_jacobian(&x1).transpose()
        } else {
            SMatrix::zeros()
        };

        // Residuals in plain f64; the Jacobian (N dual directions, nested
        // duals inside) is refreshed only when contraction is slow: a
        // chord/Newton hybrid that needs one Jacobian per step in the common
        // case of a good initial guess.
        let eval = |v: &SVector<f64, N>, lambda: &SVector<f64, C>| {
            let r = p0 + del::del_terms::<M, f64, N, C>(m, dt, alpha, &x1, v) - g1t * lambda;
            let c = if C > 0 {
                m.constraints(&(x1 + v * dt))
            } else {
                SVector::zeros()
            };
            (r, c)
        };
        let jacobian =
            |v: &SVector<f64, N>| del::del_terms_jacobian::<M, N, C>(m, dt, alpha, &x1, v).1;
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
        let tol = self.options.tolerance;
        let mut stalled = false;
        for iter in 0..=self.options.max_iterations {
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
            let stall_tol = self.options.stall_tolerance;
            let accept_stall = stalled && res_c <= stall_tol && res_r <= stall_tol;
            if converged || accept_stall {
                let next = State { q: x1, v };
                if !next.is_finite() {
                    return Err(StepError::NonFiniteState { step: None });
                }
                return Ok((
                    next,
                    StepInfo {
                        iterations: iter,
                        residual: res_r.max(res_c),
                        stalled: !converged,
                        regularised,
                        restarted: false,
                    },
                ));
            }
            if iter == self.options.max_iterations {
                return Err(StepError::NotConverged {
                    iterations: iter,
                    residual: res_r.max(res_c),
                    tolerance: tol,
                    step: None,
                });
            }
            let a: SMatrix<f64, C, N> = if C > 0 {
                m.constraint_jacobian(&(x1 + v * dt)) * dt
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
                if alpha <= self.options.min_step {
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

    /// Energy of a discrete state at this integrator's quadrature point,
    /// E(x + αΔt·v, v): for the midpoint rule the discrete velocity belongs
    /// to the interval's midpoint, and evaluating there is what makes the
    /// measured energy error second order. Equals `model.energy(z)` for the
    /// first-order rule.
    pub fn energy(&self, z: &State<N>) -> f64 {
        let h = self.dt / self.substeps.max(1) as f64;
        let at = State {
            q: z.q + z.v * (self.alpha * h),
            v: z.v,
        };
        self.model.energy(&at)
    }

    /// Multipliers are not part of the state; this returns only the state.
    pub fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        self.step_with_info(z).map(|(z, _)| z)
    }
}

impl<M: Mechanism<N, C>, const N: usize, const C: usize> Integrator<N> for Variational<M, N, C> {
    fn dt(&self) -> f64 {
        self.dt
    }
    fn step(&self, z: &State<N>) -> Result<State<N>, StepError> {
        Variational::step(self, z)
    }
    fn state_energy(&self, z: &State<N>) -> Option<f64> {
        Some(Variational::energy(self, z))
    }
}
