//! Probabilistic error bounds of the learned integrators (paper Theorem 1),
//! built on the uniform GP error bound of Lederer, Umlauft & Hirche
//! (NeurIPS 2019, Thm 3.1).
//!
//! For each velocity component i (p = N outputs, union bound δ_i = δ/p),
//! with probability ≥ 1 − δ for all z in the input box X:
//!
//! ```text
//! |f_i(z) − μ_i(z)| ≤ √β_i(τ)·σ_i(z) + γ_i(τ)
//! β_i(τ) = 2·ln(M(τ, X)/δ_i),  M(τ, X) ≤ (r·√d/(2τ))^d
//! γ_i(τ) = (L_μ + L_f)·τ + √β_i(τ)·ω_σ(τ)
//! L_μ ≤ L_k·√N·‖α‖,   ω_σ(τ) ≤ √(2τ·L_k·(1 + N·‖(K+σ²I)⁻¹‖·max k))
//! ```
//!
//! and the projected prediction obeys ‖v − v_true‖ ≤ L·Σ_i(√β_i σ_i + γ_i)
//! with L the Lipschitz constant of the projection (1 without constraints),
//! estimated from its exact Jacobian (implicit function theorem) at sampled
//! points.
//!
//! Caveats: the theorem assumes the true velocity map is a sample of the GP
//! prior with the fitted hyperparameters; L_f (the map's Lipschitz constant)
//! is unknown and estimated here by L_μ unless given; L is estimated, not
//! proven. Check coverage on held-out data.

use crate::learned::{LearnError, Learned};
use crate::linalg::solve_kkt;
use crate::mechanism::{Mechanism, State};
use crate::newton::{NewtonOptions, StepError};
use crate::projection::project_velocity;
use nalgebra::{SMatrix, SVector};
use num_dual::{Dual2Vec, DualNum};

/// Settings of the bound.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundSettings {
    /// Failure probability δ of the whole bound (union over outputs).
    pub delta: f64,
    /// Grid constant τ of the covering argument, relative to the input box
    /// edge r (τ = tau_rel·r). Small τ shrinks γ and grows β only
    /// logarithmically. Default 1e-9.
    pub tau_rel: f64,
    /// Lipschitz constants of the true velocity map per output; `None` uses
    /// each output's L_μ bound.
    pub lipschitz_f: Option<Vec<f64>>,
}

impl Default for BoundSettings {
    fn default() -> Self {
        Self {
            delta: 0.01,
            tau_rel: 1e-9,
            lipschitz_f: None,
        }
    }
}

/// The constants of a one-step bound (computed once per trained model).
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorBound {
    /// β_i per output.
    pub beta: Vec<f64>,
    /// γ_i per output.
    pub gamma: Vec<f64>,
    /// Lipschitz constant L of the projection (1 without constraints).
    pub projection_lipschitz: f64,
    /// δ used.
    pub delta: f64,
    /// τ used (input units).
    pub tau: f64,
}

impl ErrorBound {
    /// ‖v − v_true‖ ≤ L·Σ_i(√β_i σ_i + γ_i) for posterior standard deviations σ.
    pub fn one_step(&self, std_dev: &[f64]) -> f64 {
        let s: f64 = std_dev
            .iter()
            .zip(self.beta.iter().zip(&self.gamma))
            .map(|(s, (b, g))| b.sqrt() * s + g)
            .sum();
        self.projection_lipschitz * s
    }
}

/// Spectral norm of a square matrix by power iteration on AᵀA.
fn spectral_norm<const N: usize>(a: &SMatrix<f64, N, N>) -> f64 {
    let ata = a.transpose() * a;
    let mut x = SVector::<f64, N>::from_element(1.0);
    let mut lambda = 0.0;
    for _ in 0..200 {
        let y = ata * x;
        let n = y.norm();
        if n == 0.0 {
            return 0.0;
        }
        x = y / n;
        lambda = n;
    }
    lambda.sqrt()
}

/// Jacobian ∂v/∂v_u of the projection v = P(v_u) at a solution, by the
/// implicit function theorem on [v − v_u + Δt·G(x₂)ᵀμ; g(x₂)] = 0 with
/// x₂ = x₁ + Δt·v (exact second derivatives of μᵀg by dual numbers).
pub fn projection_jacobian<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    x1: &SVector<f64, N>,
    v_u: &SVector<f64, N>,
    dt: f64,
) -> Result<SMatrix<f64, N, N>, StepError> {
    if C == 0 {
        return Ok(SMatrix::identity());
    }
    let (v, _) = project_velocity(m, x1, v_u, dt, &NewtonOptions::default())?;
    let x2 = x1 + v * dt;
    let g: SMatrix<f64, C, N> = m.constraint_jacobian(&x2);
    // multipliers: least squares of v − v_u + Δt·Gᵀμ = 0
    let a = g * dt;
    let (_, mu) = solve_kkt(
        &SMatrix::<f64, N, N>::identity(),
        &a.transpose(),
        &a,
        &(v - v_u),
        &SVector::<f64, C>::zeros(),
    )
    .ok_or(StepError::SingularJacobian {
        iteration: 0,
        step: None,
    })?;
    let mu = -mu;
    let (_, _, h) = num_dual::hessian(
        |x: SVector<Dual2Vec<f64, nalgebra::Const<N>>, N>| {
            let gx = m.constraints(&x);
            let mut s = Dual2Vec::from_re(0.0);
            for i in 0..C {
                s += gx[i] * mu[i];
            }
            s
        },
        &x2,
    );
    let j = SMatrix::<f64, N, N>::identity() + h * (dt * dt);
    let mut out = SMatrix::<f64, N, N>::zeros();
    for k in 0..N {
        let e = SVector::<f64, N>::from_fn(|i, _| if i == k { 1.0 } else { 0.0 });
        let (col, _) = solve_kkt(&j, &a.transpose(), &a, &e, &SVector::<f64, C>::zeros()).ok_or(
            StepError::SingularJacobian {
                iteration: 0,
                step: None,
            },
        )?;
        out.set_column(k, &col);
    }
    Ok(out)
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// The bound constants for this trained model. `samples` are states at
    /// which the projection's Lipschitz constant is estimated (e.g. the
    /// training states); the largest spectral norm of its Jacobian wins.
    pub fn error_bound(
        &self,
        settings: &BoundSettings,
        samples: &[State<N>],
    ) -> Result<ErrorBound, LearnError> {
        if !(settings.delta > 0.0 && settings.delta < 1.0) {
            return Err(LearnError::InvalidSetting {
                what: "delta (must be in (0, 1))",
                value: settings.delta,
            });
        }
        if !(settings.tau_rel > 0.0 && settings.tau_rel.is_finite()) {
            return Err(LearnError::InvalidSetting {
                what: "tau_rel (must be finite and > 0)",
                value: settings.tau_rel,
            });
        }
        let gp = self.gp();
        let (n, d, p) = (gp.n(), gp.input_dim(), gp.output_dim());
        // input box edge r: the largest range of the training inputs
        let x = gp.inputs();
        let mut r = 0.0f64;
        for j in 0..d {
            let (lo, hi) = x
                .chunks(d)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), row| {
                    (lo.min(row[j]), hi.max(row[j]))
                });
            r = r.max(hi - lo);
        }
        let r = r.max(f64::MIN_POSITIVE);
        let tau = settings.tau_rel * r;
        let log_m = d as f64 * (r * (d as f64).sqrt() / (2.0 * tau)).ln().max(0.0);
        let delta_i = settings.delta / p as f64;
        let beta_i = 2.0 * (log_m - delta_i.ln());
        let mut beta = Vec::with_capacity(p);
        let mut gamma = Vec::with_capacity(p);
        for (i, o) in gp.outputs().iter().enumerate() {
            let lk = o.kernel_lipschitz();
            let alpha_norm = o.alpha().iter().map(|a| a * a).sum::<f64>().sqrt();
            let l_mu = lk * (n as f64).sqrt() * alpha_norm;
            let l_f = settings
                .lipschitz_f
                .as_ref()
                .and_then(|v| v.get(i).copied())
                .unwrap_or(l_mu);
            let inv = o.inv_gram_norm()?;
            let omega = (2.0 * tau * lk * (1.0 + n as f64 * inv * o.kernel_max())).sqrt();
            beta.push(beta_i);
            gamma.push((l_mu + l_f) * tau + beta_i.sqrt() * omega);
        }
        let mut lip = 1.0f64;
        if self.projects() && C > 0 {
            let mut ws = self.workspace();
            for z in samples {
                let (vu, _) = self.predict_velocity(z, &mut ws)?;
                let jac = projection_jacobian(
                    self.model(),
                    &(z.q + z.v * self.dt_value()),
                    &vu,
                    self.dt_value(),
                )?;
                lip = lip.max(spectral_norm(&jac));
            }
        }
        Ok(ErrorBound {
            beta,
            gamma,
            projection_lipschitz: lip,
            delta: settings.delta,
            tau,
        })
    }

    fn dt_value(&self) -> f64 {
        crate::variational::Integrator::dt(self)
    }

    /// Multi-step prediction (e.g. 20 steps for MPC): the trajectory
    /// z_0 … z_steps, each step's one-step bound, and the projection
    /// corrections.
    pub fn predict(
        &self,
        z0: &State<N>,
        steps: usize,
        bound: &ErrorBound,
    ) -> Result<BoundedPrediction<N>, StepError> {
        let mut ws = self.workspace();
        let mut out = BoundedPrediction {
            states: Vec::with_capacity(steps + 1),
            one_step_bounds: Vec::with_capacity(steps),
            corrections: Vec::with_capacity(steps),
        };
        out.states.push(*z0);
        let mut z = *z0;
        for k in 0..steps {
            let (next, info) = self.step_with(&z, &mut ws).map_err(|e| e.at_step(k))?;
            out.one_step_bounds
                .push(bound.one_step(info.std_dev.as_slice()));
            out.corrections.push(info.correction);
            out.states.push(next);
            z = next;
        }
        Ok(out)
    }
}

/// A multi-step prediction with per-step bounds.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundedPrediction<const N: usize> {
    /// z_0, z_1, …, z_steps.
    pub states: Vec<State<N>>,
    /// One-step bound on ‖v_{k+1} − v_true‖ for each step (probability ≥ 1 − δ).
    pub one_step_bounds: Vec<f64>,
    /// Size of each projection correction.
    pub corrections: Vec<f64>,
}
