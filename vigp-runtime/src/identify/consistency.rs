//! Physical consistency: every body keeps a positive mass and an inertia
//! that a mass distribution can have.
//!
//! A spatial body's standard parameters (m, h = m·c, I_O) are realisable
//! exactly when its pseudo-inertia
//!
//! ```text
//! J = [ Σ   h ]      Σ = ½ tr(I_O)·1 − I_O   (the second moment ∫ x xᵀ dm)
//!     [ hᵀ  m ]
//! ```
//!
//! is positive definite (Wensing, Kim & Slotine 2018). A planar body
//! (m, h, I_O about the plane's normal) is realisable exactly when m > 0
//! and I_O − |h|²/m > 0 (its inertia about the centre of mass is
//! positive): a 3 × 3 planar pseudo-inertia [[Σ, h], [hᵀ, m]] with
//! tr Σ = I_O exists then (Σ = h hᵀ/m + ½ I_c·1).
//!
//! When the estimate is not realisable, it is projected: the nearest
//! realisable π in the metric of the estimate's own objective (the data's
//! information plus the prior). Realisability is a linear matrix
//! inequality, M_b(π) ≻ 0 per body (the pseudo-inertia; in the plane
//! [[m, hᵀ], [h, I_O·1]]), so the projection is a convex problem, solved
//! by a log-barrier interior-point method: Newton's method on
//! |F·π − f|² − μ·Σ_b ln det M_b(π) from the declared parameters (which
//! are realisable), μ divided by 10 until the duality gap ν·μ (ν = Σ dim
//! M_b) is below 1e-13 of the objective. Newton's method is affine
//! invariant, so the metric's span of decades (the data's precision
//! against the prior's) does not slow it, where a parameterisation of the
//! realisable set (log-Cholesky, Rucker & Wensing 2022) under
//! Levenberg–Marquardt stalled at its start: a noise-free log informs
//! some combinations 10²⁸ times more than the prior the others.

use super::IdentifyError;
use super::regressor::{BodySlots, SYM, Structure};
use nalgebra::{DMatrix, DVector, Matrix4};

/// Is body `b` (its block of π) physically realisable, strictly?
pub fn body_consistent(body: &BodySlots, pi: &[f64]) -> bool {
    match body {
        BodySlots::Planar { .. } => {
            let m = pi[0];
            m > 0.0 && pi[3] - (pi[1] * pi[1] + pi[2] * pi[2]) / m > 0.0
        }
        BodySlots::Spatial { .. } => pseudo_inertia(pi).cholesky().is_some() && pi[0] > 0.0,
    }
}

/// Which bodies of π are not realisable (their indices).
pub fn inconsistent_bodies(structure: &Structure, pi: &[f64]) -> Vec<usize> {
    let offsets = structure.body_offsets();
    structure
        .bodies
        .iter()
        .enumerate()
        .filter(|(i, b)| {
            let o = offsets[*i];
            !body_consistent(b, &pi[o..o + b.len()])
        })
        .map(|(i, _)| i)
        .collect()
}

/// The 4 × 4 pseudo-inertia of a spatial body's standard parameters.
pub fn pseudo_inertia(pi: &[f64]) -> Matrix4<f64> {
    let mut io = [[0.0; 3]; 3];
    for (k, (r, s)) in SYM.iter().enumerate() {
        io[*r][*s] = pi[4 + k];
        io[*s][*r] = pi[4 + k];
    }
    let half_tr = 0.5 * (io[0][0] + io[1][1] + io[2][2]);
    let mut j = Matrix4::zeros();
    for r in 0..3 {
        for s in 0..3 {
            j[(r, s)] = if r == s { half_tr } else { 0.0 } - io[r][s];
        }
        j[(r, 3)] = pi[1 + r];
        j[(3, r)] = pi[1 + r];
    }
    j[(3, 3)] = pi[0];
    j
}

/// The symmetric matrix M_b(π), linear in body `b`'s block of π, whose
/// positive definiteness is the body's realisability: the spatial
/// pseudo-inertia, or for a planar body [[m, hᵀ], [h, I_O·1]] (positive
/// definite exactly when m > 0 and I_O − |h|²/m > 0).
fn body_matrix(body: &BodySlots, pi: &[f64]) -> DMatrix<f64> {
    match body {
        BodySlots::Planar { .. } => {
            let mut m = DMatrix::zeros(3, 3);
            m[(0, 0)] = pi[0];
            for k in 0..2 {
                m[(0, k + 1)] = pi[1 + k];
                m[(k + 1, 0)] = pi[1 + k];
                m[(k + 1, k + 1)] = pi[3];
            }
            m
        }
        BodySlots::Spatial { .. } => {
            let j = pseudo_inertia(pi);
            DMatrix::from_fn(4, 4, |r, c| j[(r, c)])
        }
    }
}

/// The body barriers −ln det M_b(π) summed, with their gradient and the
/// Cholesky factor L_b (H_b = L_b L_bᵀ) of each body's Hessian block;
/// `None` where some M_b is not positive definite.
struct Barrier {
    value: f64,
    gradient: DVector<f64>,
    /// (offset of the body's block in π, L_b)
    factors: Vec<(usize, DMatrix<f64>)>,
}

fn barrier(structure: &Structure, pi: &DVector<f64>) -> Option<Barrier> {
    let offsets = structure.body_offsets();
    let mut value = 0.0;
    let mut gradient = DVector::zeros(pi.len());
    let mut factors = Vec::with_capacity(structure.bodies.len());
    for (b, &o) in structure.bodies.iter().zip(&offsets) {
        let n = b.len();
        let block = &pi.as_slice()[o..o + n];
        let chol = body_matrix(b, block).cholesky()?;
        value -= 2.0 * chol.l().diagonal().map(f64::ln).sum();
        let inv = chol.inverse();
        // ∂M/∂π_i = A_i: M is linear without a constant term
        let a: Vec<DMatrix<f64>> = (0..n)
            .map(|i| {
                let mut e = vec![0.0; n];
                e[i] = 1.0;
                body_matrix(b, &e)
            })
            .collect();
        let ma: Vec<DMatrix<f64>> = a.iter().map(|ai| &inv * ai).collect();
        let mut h = DMatrix::zeros(n, n);
        for i in 0..n {
            gradient[o + i] = -ma[i].trace();
            for j in 0..=i {
                let t = (&ma[i] * &ma[j]).trace();
                h[(i, j)] = t;
                h[(j, i)] = t;
            }
        }
        factors.push((o, h.cholesky()?.l()));
    }
    Some(Barrier {
        value,
        gradient,
        factors,
    })
}

/// The objective of the projection as stacked residuals: e(π) = F·π − f,
/// |e|² = the estimate's objective up to a constant.
pub struct Metric {
    /// F (rows × P).
    pub f: DMatrix<f64>,
    /// f.
    pub rhs: DVector<f64>,
}

/// The realisable π nearest to the estimate in `metric`, from `start`
/// (strictly realisable), by a log-barrier interior-point method (module
/// docs). Returns the projected π and the Newton steps taken.
pub fn project(
    structure: &Structure,
    metric: &Metric,
    start: &[f64],
) -> Result<(Vec<f64>, usize), IdentifyError> {
    let p = structure.len();
    let mut pi = DVector::from_column_slice(start);
    if metric.f.ncols() != p || metric.rhs.len() != metric.f.nrows() || pi.len() != p {
        return Err(IdentifyError::Dimension {
            what: "projection metric",
            expected: p,
            found: metric.f.ncols(),
        });
    }
    if let Some(i) = inconsistent_bodies(structure, start).first() {
        return Err(IdentifyError::Inconsistent {
            message: format!(
                "the start of the projection is not realisable (link `{}`)",
                structure.bodies[*i].name()
            ),
        });
    }
    let quadratic = |pi: &DVector<f64>| (&metric.f * pi - &metric.rhs).norm_squared();
    // ν: the barrier's degree, Σ dim M_b; the duality gap of the central
    // point at weight μ is ν·μ
    let nu: usize = structure
        .bodies
        .iter()
        .map(|b| match b {
            BodySlots::Planar { .. } => 3,
            BodySlots::Spatial { .. } => 4,
        })
        .sum();
    let nu = nu.max(1) as f64;
    let mut mu = (1.0 + quadratic(&pi)) / nu;
    let rows = metric.f.nrows();
    let barrier_rows: usize = structure.bodies.iter().map(|b| b.len()).sum();
    let mut steps = 0;
    loop {
        for _ in 0..100 {
            let Some(bar) = barrier(structure, &pi) else {
                break;
            };
            let e = &metric.f * &pi - &metric.rhs;
            let phi = e.norm_squared() + mu * bar.value;
            let grad = metric.f.transpose() * &e * 2.0 + &bar.gradient * mu;
            // Newton's step of Φ = |Fπ − f|² + μ·barrier as a stacked least
            // squares (the metric spans decades: never the normal
            // equations): [√2·F; √μ·L_bᵀ] Δ ≈ −[√2·e; √μ·L_b⁻¹g_b]
            let mut a = DMatrix::zeros(rows + barrier_rows, p);
            let mut rhs = DVector::zeros(rows + barrier_rows);
            a.rows_mut(0, rows)
                .copy_from(&(&metric.f * std::f64::consts::SQRT_2));
            rhs.rows_mut(0, rows)
                .copy_from(&(&e * -std::f64::consts::SQRT_2));
            let mut r = rows;
            for (o, l) in &bar.factors {
                let n = l.nrows();
                let g = bar.gradient.rows(*o, n).into_owned();
                let lg = l
                    .clone()
                    .solve_lower_triangular(&g)
                    .ok_or(IdentifyError::Singular)?;
                a.view_mut((r, *o), (n, n))
                    .copy_from(&(l.transpose() * mu.sqrt()));
                rhs.rows_mut(r, n).copy_from(&(lg * -mu.sqrt()));
                r += n;
            }
            let step = a
                .svd(true, true)
                .solve(&rhs, 0.0)
                .map_err(|_| IdentifyError::Singular)?;
            let slope = grad.dot(&step);
            // converged at this μ: Newton's decrement λ² = −∇Φ·Δ below
            // the rounding of Φ
            if slope.is_nan() || slope >= -1e-13 * (1.0 + phi.abs()) {
                break;
            }
            let mut t = 1.0;
            let mut moved = false;
            for _ in 0..60 {
                let trial = &pi + &step * t;
                if let Some(tb) = barrier(structure, &trial)
                    && quadratic(&trial) + mu * tb.value <= phi + 0.25 * t * slope
                {
                    pi = trial;
                    moved = true;
                    break;
                }
                t *= 0.5;
            }
            steps += 1;
            if !moved {
                break;
            }
        }
        if nu * mu <= 1e-13 * (1.0 + quadratic(&pi)) {
            break;
        }
        mu *= 0.1;
    }
    Ok((pi.iter().cloned().collect(), steps))
}
