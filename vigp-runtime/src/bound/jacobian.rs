//! Jacobians behind the bounds: the projection's (for its Lipschitz constant
//! L, paper Assumption 1) and the learned step's (for propagating the
//! rigorous one-step bounds over several steps).

use crate::learned::Learned;
use crate::linalg::solve_kkt;
use crate::mechanism::{Mechanism, State};
use crate::newton::{NewtonOptions, StepError};
use crate::projection::{consistent_state, project_velocity};
use crate::variational::Integrator;
use nalgebra::{SMatrix, SVector};
use num_dual::Dual2Vec;

/// Spectral norm ‖A‖₂ of a square matrix: the square root of the largest
/// eigenvalue of AᵀA, by power iteration from the all-ones vector and from
/// each unit vector (the largest estimate wins, so a start orthogonal to
/// the dominant direction cannot hide it).
pub(crate) fn spectral_norm<const N: usize>(a: &SMatrix<f64, N, N>) -> f64 {
    let ata = a.transpose() * a;
    let mut best = 0.0f64;
    let starts = core::iter::once(SVector::<f64, N>::from_element(1.0))
        .chain((0..N).map(|k| SVector::<f64, N>::from_fn(|i, _| f64::from(u8::from(i == k)))));
    for x0 in starts {
        let mut x = x0;
        let mut lambda = 0.0;
        for _ in 0..100 {
            let y = ata * x;
            let n = y.norm();
            if n == 0.0 || !n.is_finite() {
                break;
            }
            x = y / n;
            lambda = n;
        }
        best = best.max(lambda);
    }
    best.sqrt()
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
    let (v, _) = project_velocity(m, x1, v_u, dt, &NewtonOptions::default())?;
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
    /// z = (q, v) ↦ v′ at `z`, by forward differences (relative step 1e-6:
    /// truncation ~1e-6 relative, rounding of the 1e-12-converged
    /// projection ~1e-6, ample for a Lipschitz estimate).
    ///
    /// With constraints, each perturbed state is first made consistent
    /// ([`consistent_state`]): the norms then measure how the step amplifies
    /// errors *along* the constraint manifold, where the errors of a
    /// projected prediction lie, and not the 1/Δt re-closing of a state
    /// pushed off it.
    pub(crate) fn step_jacobian_norms(
        &self,
        z: &State<N>,
        ws: &mut crate::gp::Workspace,
    ) -> Result<(f64, f64), StepError> {
        let dt = Integrator::dt(self);
        let mut dq = SMatrix::<f64, N, N>::zeros();
        let mut dv = SMatrix::<f64, N, N>::zeros();
        let constrained = C > 0 && self.projects();
        let mut eval = |p: State<N>| -> Result<SVector<f64, N>, StepError> {
            let p = if constrained {
                consistent_state(self.model(), &p.q, &p.v, dt)?
            } else {
                p
            };
            Ok(self.step_mean_with(&p, ws)?.v)
        };
        let base = eval(*z)?;
        for k in 0..2 * N {
            let x = if k < N { z.q[k] } else { z.v[k - N] };
            let h = 1e-6 * x.abs().max(1.0);
            let mut p = *z;
            if k < N {
                p.q[k] += h;
            } else {
                p.v[k - N] += h;
            }
            let col = (eval(p)? - base) / h;
            if k < N {
                dq.set_column(k, &col);
            } else {
                dv.set_column(k - N, &col);
            }
        }
        Ok((spectral_norm(&dq), spectral_norm(&dv)))
    }
}

#[cfg(test)]
mod tests {
    use super::spectral_norm;
    use nalgebra::SMatrix;

    /// Against the singular values from nalgebra's SVD (relative 1e-10: the
    /// power iteration converges geometrically in 100 steps for these
    /// well-separated spectra).
    #[test]
    fn spectral_norm_matches_svd() {
        let a = SMatrix::<f64, 3, 3>::new(1.0, -2.0, 0.5, 0.3, 4.0, -1.0, 2.0, 0.0, 1.5);
        let svd = a.svd(false, false);
        let max = svd.singular_values.max();
        assert!((spectral_norm(&a) - max).abs() < 1e-10 * max);
        // a start orthogonal to the dominant direction (all-ones) still finds it
        let b = SMatrix::<f64, 2, 2>::new(1.0, -1.0, -1.0, 1.0) * 3.0;
        assert!((spectral_norm(&b) - 6.0).abs() < 1e-10);
        assert_eq!(spectral_norm(&SMatrix::<f64, 2, 2>::zeros()), 0.0);
    }
}
