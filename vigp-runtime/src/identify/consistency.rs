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
//! information plus the prior), over a smooth parameterisation that
//! covers the realisable set and nothing else. Spatial bodies use the
//! log-Cholesky parameterisation of Rucker & Wensing (RA-L 2022):
//! J = U Uᵀ with U upper triangular, diagonal exp(α_i), ten free numbers.
//! Planar bodies use (ln m, c_x, c_y, ln I_c). The projection is a
//! Levenberg–Marquardt solve with the exact Jacobian of π(θ), started at
//! the declared parameters (which are realisable).

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

/// Parameterisation of one body: θ ↦ π and its Jacobian.
fn body_pi(body: &BodySlots, theta: &[f64]) -> (Vec<f64>, DMatrix<f64>) {
    match body {
        BodySlots::Planar { .. } => {
            let (m, cx, cy, ic) = (theta[0].exp(), theta[1], theta[2], theta[3].exp());
            let pi = vec![m, m * cx, m * cy, ic + m * (cx * cx + cy * cy)];
            let mut j = DMatrix::zeros(4, 4);
            j[(0, 0)] = m;
            j[(1, 0)] = m * cx;
            j[(1, 1)] = m;
            j[(2, 0)] = m * cy;
            j[(2, 2)] = m;
            j[(3, 0)] = m * (cx * cx + cy * cy);
            j[(3, 1)] = 2.0 * m * cx;
            j[(3, 2)] = 2.0 * m * cy;
            j[(3, 3)] = ic;
            (pi, j)
        }
        BodySlots::Spatial { .. } => {
            let u = upper(theta);
            let jm = u * u.transpose();
            let pi = from_pseudo(&jm);
            let mut jac = DMatrix::zeros(10, 10);
            for (t, (a, b)) in UPPER.iter().enumerate() {
                // ∂U/∂θ_t = E_ab (times U_aa on the diagonal).
                let scale = if a == b { u[(*a, *b)] } else { 1.0 };
                let mut e = Matrix4::zeros();
                e[(*a, *b)] = scale;
                let dj = e * u.transpose() + u * e.transpose();
                let dpi = from_pseudo(&dj);
                for (i, v) in dpi.iter().enumerate() {
                    jac[(i, t)] = *v;
                }
            }
            (pi, jac)
        }
    }
}

/// The ten entries of an upper-triangular 4 × 4 U, in θ order.
const UPPER: [(usize, usize); 10] = [
    (0, 0),
    (1, 1),
    (2, 2),
    (3, 3),
    (0, 1),
    (0, 2),
    (0, 3),
    (1, 2),
    (1, 3),
    (2, 3),
];

fn upper(theta: &[f64]) -> Matrix4<f64> {
    let mut u = Matrix4::zeros();
    for (t, (a, b)) in UPPER.iter().enumerate() {
        u[(*a, *b)] = if a == b { theta[t].exp() } else { theta[t] };
    }
    u
}

/// Standard parameters of a pseudo-inertia (linear): m = J₄₄, h = J[0..3, 3],
/// I_O = tr(Σ)·1 − Σ.
fn from_pseudo(j: &Matrix4<f64>) -> Vec<f64> {
    let tr = j[(0, 0)] + j[(1, 1)] + j[(2, 2)];
    let mut pi = vec![j[(3, 3)], j[(0, 3)], j[(1, 3)], j[(2, 3)]];
    for (r, s) in SYM {
        pi.push(if r == s { tr } else { 0.0 } - j[(r, s)]);
    }
    pi
}

/// θ of a realisable body (inverse of `body_pi`).
fn body_theta(body: &BodySlots, pi: &[f64]) -> Option<Vec<f64>> {
    match body {
        BodySlots::Planar { .. } => {
            let m = pi[0];
            let (cx, cy) = (pi[1] / m, pi[2] / m);
            let ic = pi[3] - m * (cx * cx + cy * cy);
            (m > 0.0 && ic > 0.0).then(|| vec![m.ln(), cx, cy, ic.ln()])
        }
        BodySlots::Spatial { .. } => {
            // J = U Uᵀ, U upper: with the exchange permutation P,
            // P J P = (P U P)(P U P)ᵀ and P U P is lower triangular.
            let j = pseudo_inertia(pi);
            let p = Matrix4::from_fn(|r, c| if r + c == 3 { 1.0 } else { 0.0 });
            let l = (p * j * p).cholesky()?.l();
            let u = p * l * p;
            Some(
                UPPER
                    .iter()
                    .map(|(a, b)| {
                        if a == b {
                            u[(*a, *b)].ln()
                        } else {
                            u[(*a, *b)]
                        }
                    })
                    .collect(),
            )
        }
    }
}

/// The map θ ↦ π over the whole vector (bodies, then joints unchanged).
fn full_pi(structure: &Structure, theta: &[f64]) -> (DVector<f64>, DMatrix<f64>) {
    let p = structure.len();
    let mut pi = DVector::zeros(p);
    let mut jac = DMatrix::zeros(p, p);
    let mut o = 0;
    for b in &structure.bodies {
        let n = b.len();
        let (bp, bj) = body_pi(b, &theta[o..o + n]);
        for i in 0..n {
            pi[o + i] = bp[i];
            for k in 0..n {
                jac[(o + i, o + k)] = bj[(i, k)];
            }
        }
        o += n;
    }
    for i in o..p {
        pi[i] = theta[i];
        jac[(i, i)] = 1.0;
    }
    (pi, jac)
}

/// The objective of the projection as stacked residuals: e(π) = F·π − f,
/// |e|² = the estimate's objective up to a constant.
pub struct Metric {
    /// F (rows × P).
    pub f: DMatrix<f64>,
    /// f.
    pub rhs: DVector<f64>,
}

/// The realisable π nearest to the estimate in `metric`, by
/// Levenberg–Marquardt from `start` (realisable). Returns the projected π
/// and the iterations taken.
pub fn project(
    structure: &Structure,
    metric: &Metric,
    start: &[f64],
) -> Result<(Vec<f64>, usize), IdentifyError> {
    let p = structure.len();
    let mut theta = Vec::with_capacity(p);
    let offsets = structure.body_offsets();
    for (i, b) in structure.bodies.iter().enumerate() {
        let o = offsets[i];
        theta.extend(body_theta(b, &start[o..o + b.len()]).ok_or_else(|| {
            IdentifyError::Inconsistent {
                message: format!(
                    "the start of the projection is not realisable (link `{}`)",
                    b.name()
                ),
            }
        })?);
    }
    theta.extend_from_slice(&start[theta.len()..]);
    // The realisable set is open; its boundary (a zero mass, a zero
    // principal moment of Σ) is approached but kept at a margin, so that
    // π(θ) is strictly realisable in floating point too: the planar
    // ln m, ln I_c stay above their start − ln 1e8, the spatial
    // log-diagonal of U (J = U Uᵀ: squares) above its start − ln 1e4.
    let mut floor = vec![f64::NEG_INFINITY; p];
    for (i, b) in structure.bodies.iter().enumerate() {
        let o = offsets[i];
        let (logs, margin): (&[usize], f64) = match b {
            BodySlots::Planar { .. } => (&[0, 3], 1e8f64.ln()),
            BodySlots::Spatial { .. } => (&[0, 1, 2, 3], 1e4f64.ln()),
        };
        for k in logs {
            floor[o + k] = theta[o + k] - margin;
        }
    }
    let clamp = |th: &mut Vec<f64>| {
        for (t, f) in th.iter_mut().zip(&floor) {
            *t = t.max(*f);
        }
    };
    let cost = |th: &[f64]| {
        let (pi, _) = full_pi(structure, th);
        (&metric.f * pi - &metric.rhs).norm_squared()
    };
    let mut c0 = cost(&theta);
    let mut mu: f64 = 1e-3;
    let mut iters = 0;
    for it in 0..500 {
        iters = it;
        let (pi, jp) = full_pi(structure, &theta);
        let e = &metric.f * &pi - &metric.rhs;
        let j = &metric.f * jp;
        // Scale-invariant damping: μ·diag(JᵀJ), solved as a stacked least
        // squares (never the normal equations: the metric spans decades).
        let d: Vec<f64> = (0..p).map(|k| j.column(k).norm().max(1e-300)).collect();
        let mut improved = false;
        for _ in 0..30 {
            let mut a = DMatrix::zeros(j.nrows() + p, p);
            a.rows_mut(0, j.nrows()).copy_from(&j);
            for k in 0..p {
                a[(j.nrows() + k, k)] = mu.sqrt() * d[k];
            }
            let mut rhs = DVector::zeros(j.nrows() + p);
            rhs.rows_mut(0, j.nrows()).copy_from(&(-&e));
            let step = a
                .svd(true, true)
                .solve(&rhs, 0.0)
                .map_err(|_| IdentifyError::Singular)?;
            let mut trial: Vec<f64> = theta.iter().zip(step.iter()).map(|(t, s)| t + s).collect();
            clamp(&mut trial);
            let c = cost(&trial);
            if c.is_finite() && c < c0 {
                let rel = (c0 - c) / c0.max(f64::MIN_POSITIVE);
                theta = trial;
                c0 = c;
                mu = (mu * 0.3).max(1e-12);
                improved = true;
                if rel < 1e-14 {
                    return Ok((full_pi(structure, &theta).0.iter().cloned().collect(), it));
                }
                break;
            }
            mu *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Ok((
        full_pi(structure, &theta).0.iter().cloned().collect(),
        iters,
    ))
}
