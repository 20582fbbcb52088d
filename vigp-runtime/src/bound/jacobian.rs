//! Jacobians behind the bounds: the projection's (for its Lipschitz constant
//! L, paper Assumption 1) and the learned step's (for propagating the
//! rigorous one-step bounds over several steps).

use crate::integrator::Integrator;
use crate::learned::Learned;
use crate::linalg::solve_kkt;
use crate::mechanism::{Mechanism, State};
use crate::newton::{StepError, StepOptions};
use crate::projection::{consistent_state, project_velocity};
use nalgebra::{SMatrix, SVector};
use num_dual::Dual2Vec;

/// Spectral norm ‖A‖₂ of a square matrix: its largest singular value, by
/// nalgebra's SVD (Golub–Kahan; backward stable, so accurate to a few ulps
/// of ‖A‖₂). A power iteration, used before, converges slowly when the two
/// largest singular values are close, and from below: it under-estimated
/// the norms of projected steps by up to 4e-5 relative.
pub(crate) fn spectral_norm<const N: usize>(a: &SMatrix<f64, N, N>) -> f64 {
    if N == 0 {
        return 0.0;
    }
    nalgebra::DMatrix::from_column_slice(N, N, a.as_slice())
        .singular_values()
        .max()
}

/// Jacobian ∂v/∂v_u of the projection v = P(v_u) at a solution, by the
/// implicit function theorem on [v − v_u + Δt·G(x₂)ᵀμ; g(x₂)] = 0 with
/// x₂ = x₁ + Δt·v (exact second derivatives of μᵀg by dual numbers).
///
/// The identity when the mechanism has no constraints.
pub fn projection_jacobian<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    x1: &SVector<f64, N>,
    v_u: &SVector<f64, N>,
    dt: f64,
) -> Result<SMatrix<f64, N, N>, StepError> {
    if C == 0 {
        return Ok(SMatrix::identity());
    }
    let (v, _) = project_velocity(m, x1, v_u, dt, &StepOptions::default())?;
    let x2 = x1 + v * dt;
    let g: SMatrix<f64, C, N> = m.constraint_jacobian(&x2);
    // multipliers: least squares of v − v_u + Δt·Gᵀμ = 0
    let a = g * dt;
    let singular = StepError::SingularJacobian {
        iteration: 0,
        step: None,
    };
    let (_, mu) = solve_kkt(
        &SMatrix::<f64, N, N>::identity(),
        &a.transpose(),
        &a,
        &(v - v_u),
        &SVector::<f64, C>::zeros(),
    )
    .ok_or(singular)?;
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
        let e = SVector::<f64, N>::from_fn(|i, _| f64::from(u8::from(i == k)));
        let (col, _) =
            solve_kkt(&j, &a.transpose(), &a, &e, &SVector::<f64, C>::zeros()).ok_or(singular)?;
        out.set_column(k, &col);
    }
    Ok(out)
}

impl<M: Mechanism<N, C> + Clone, const N: usize, const C: usize> Learned<M, N, C> {
    /// Spectral norms (‖∂v′/∂q‖₂, ‖∂v′/∂v‖₂) of the learned mean step
    /// z = (q, v) ↦ v′ at `z`: the local amplification factors with which
    /// [`Learned::predict`] propagates the rigorous one-step bounds.
    ///
    /// The derivatives are exact: the step's (nominal prior, GP mean
    /// gradient through the encoding, projection by its KKT conditions;
    /// [`Learned::step_derivatives_forced`]). With constraints the step is
    /// composed with the derivative of [`consistent_state`] at `z`, so the
    /// norms measure how the step amplifies errors *along* the constraint
    /// manifold, where the errors of a projected prediction lie, and not
    /// the 1/Δt re-closing of a state pushed off it. At a consistent state
    /// (every state a projected prediction visits) that derivative is the
    /// orthogonal projector onto the tangent space of g(q) = 0 for q, and
    /// the linearised velocity projection onto g(q + Δt·v) = 0 for v.
    ///
    /// When the model projects, the norms are those at
    /// `consistent_state(z)`, which is `z` itself (to solver tolerance) for
    /// every state a projected prediction visits.
    ///
    /// Cost: one mean step with its gradient (O(n·d) per GP output for n
    /// training points and d inputs) and, with constraints, 3N small KKT
    /// solves; not the 2N + 1 mean steps of finite differences.
    ///
    /// A model trained with inputs is differentiated under u = 0, the step
    /// [`Learned::step_mean_in`] and [`Learned::predict`] take.
    ///
    /// Errors: as the step ([`StepError`]); a singular constraint Jacobian
    /// at `z` is [`StepError::SingularJacobian`].
    pub fn step_jacobian_norms(
        &self,
        z: &State<N>,
        ws: &mut crate::gp::Workspace,
    ) -> Result<(f64, f64), StepError> {
        self.step_jacobian_norms_at::<0>(z, &SVector::zeros(), &SVector::zeros(), ws)
    }

    /// [`Learned::step_jacobian_norms`] of the step under inputs `u` after
    /// `u_prev` (a model from [`Learned::train_forced`]; both held fixed):
    /// the factors with which [`Learned::predict_forced`] propagates its
    /// bounds.
    ///
    /// Errors: those of `step_jacobian_norms`; `U` other than the model's
    /// inputs ([`StepError::InputsNotSupported`]); a NaN or ∞ in `u`.
    pub fn step_jacobian_norms_forced<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut crate::gp::Workspace,
    ) -> Result<(f64, f64), StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        if U != self.inputs() {
            return Err(StepError::InputsNotSupported);
        }
        self.step_jacobian_norms_at(z, u_prev, u, ws)
    }

    /// The norms under `u` after `u_prev` (`U` the model's inputs, or 0
    /// for u = 0).
    pub(super) fn step_jacobian_norms_at<const U: usize>(
        &self,
        z: &State<N>,
        u_prev: &SVector<f64, U>,
        u: &SVector<f64, U>,
        ws: &mut crate::gp::Workspace,
    ) -> Result<(f64, f64), StepError>
    where
        M: vigp_core::Inputs<U>,
    {
        let dt = Integrator::dt(self);
        let constrained = C > 0 && self.projects();
        let z = if constrained {
            consistent_state(self.model(), &z.q, &z.v, dt)?
        } else {
            *z
        };
        let (_, d, _) = self.step_derivatives_forced(&z, u_prev, u, ws)?;
        let (mut dq, mut dv) = (d.a.v_q, d.a.v_v);
        if constrained {
            let (cq, cvq, cvv) = consistent_state_jacobian(self.model(), &z, dt)?;
            // v′ ∘ consistent_state: ∂v′/∂q = V_q·C_q + V_v·C_vq, ∂v′/∂v = V_v·C_vv
            dq = d.a.v_q * cq + d.a.v_v * cvq;
            dv = d.a.v_v * cvv;
        }
        Ok((spectral_norm(&dq), spectral_norm(&dv)))
    }
}

/// Derivative of [`consistent_state`] at a consistent state z = (q, v):
/// (∂q′/∂q, ∂v′/∂q, ∂v′/∂v). The configuration projection's is the
/// orthogonal projector onto ker G(q), from the KKT system
/// [I, Gᵀ; G, 0][dq′; μ] = [dq; 0]. The velocity projection
/// v′ = argmin ½‖w − v‖² subject to g(q′ + Δt·w) = 0 has multipliers 0 at a
/// consistent v, so its derivative is the solution of
/// [I, Δt·Gᵀ; Δt·G, 0][dv′; dλ] = [dv; −G·dq′] with G = G(q + Δt·v).
#[allow(clippy::type_complexity)]
fn consistent_state_jacobian<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    z: &State<N>,
    dt: f64,
) -> Result<(SMatrix<f64, N, N>, SMatrix<f64, N, N>, SMatrix<f64, N, N>), StepError> {
    let singular = StepError::SingularJacobian {
        iteration: 0,
        step: None,
    };
    let eye = SMatrix::<f64, N, N>::identity();
    let g0: SMatrix<f64, C, N> = m.constraint_jacobian(&z.q);
    let g1: SMatrix<f64, C, N> = m.constraint_jacobian(&(z.q + z.v * dt));
    let a1 = g1 * dt;
    let zero = SVector::<f64, C>::zeros();
    let (mut cq, mut cvq, mut cvv) = (eye, eye, eye);
    for k in 0..N {
        let e = eye.column(k).into_owned();
        let (dq, _) = solve_kkt(&eye, &g0.transpose(), &g0, &e, &zero).ok_or(singular)?;
        cq.set_column(k, &dq);
        let (dvq, _) = solve_kkt(&eye, &a1.transpose(), &a1, &SVector::zeros(), &-(g1 * dq))
            .ok_or(singular)?;
        cvq.set_column(k, &dvq);
        let (dvv, _) = solve_kkt(&eye, &a1.transpose(), &a1, &e, &zero).ok_or(singular)?;
        cvv.set_column(k, &dvv);
    }
    Ok((cq, cvq, cvv))
}

#[cfg(test)]
mod tests {
    use super::spectral_norm;
    use nalgebra::SMatrix;

    /// Against closed forms: a diagonal matrix, a rank-one matrix, and two
    /// nearly equal singular values (where a power iteration stalls).
    #[test]
    fn spectral_norm_matches_closed_forms() {
        use nalgebra::{Rotation3, Vector3};
        // R₁·diag(3, 3 − 1e-6, 0.5)·R₂ᵀ: the norm is 3 (rotations keep
        // singular values); close top pair, rounding ~1e-15 relative
        let r1 = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.7).into_inner();
        let r2 = Rotation3::from_euler_angles(0.3, -1.1, 2.0).into_inner();
        let a = r1
            * SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::new(3.0 - 1e-6, 3.0, 0.5))
            * r2.transpose();
        assert!((spectral_norm(&a) - 3.0).abs() < 1e-13);
        // rank one u·vᵀ: ‖u‖·‖v‖
        let (u, v) = (Vector3::new(1.0, -2.0, 2.0), Vector3::new(0.0, 3.0, 4.0));
        assert!((spectral_norm(&(u * v.transpose())) - 15.0).abs() < 1e-13);
        let b = SMatrix::<f64, 2, 2>::new(1.0, -1.0, -1.0, 1.0) * 3.0;
        assert!((spectral_norm(&b) - 6.0).abs() < 1e-13);
        assert_eq!(spectral_norm(&SMatrix::<f64, 2, 2>::zeros()), 0.0);
    }
}
