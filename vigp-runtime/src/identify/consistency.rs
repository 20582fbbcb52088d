//! Physical consistency: every body keeps a positive mass and an inertia
//! that a mass distribution can have, and every joint a damping and a
//! spring stiffness that are not negative.
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
//! A joint's viscous damping c and spring stiffness k must be ≥ 0 (the
//! mechanism refuses negative ones); k·s₀ is free. These are simple
//! bounds, treated by the same barrier as the bodies: −ln c and −ln k, the
//! barrier of the 1 × 1 matrix (c). The interior-point method returns a
//! strictly positive value, so where the best feasible value is 0 (a joint
//! without friction, identified on a clean log) it returns a value of the
//! order of the final barrier weight, 1e-13 of the objective's scale, not
//! a negative rounding error.
//!
//! When the estimate is not feasible, it is projected: the nearest
//! feasible π in the metric of the estimate's own objective (the data's
//! information plus the prior; [`Metric::of_estimate`] caps the data's
//! information at [`DATA_CAP`]² times the prior's). Feasibility is a
//! linear matrix inequality, M_b(π) ≻ 0 per body (the pseudo-inertia; in
//! the plane [[m, hᵀ], [h, I_O·1]]) and π_i > 0 per bounded joint entry,
//! so the projection is a convex problem, solved by a log-barrier
//! interior-point method: Newton's method on |F·π − f|² − μ·(Σ_b ln det
//! M_b(π) + Σ_i ln π_i) from a strictly feasible start, μ divided by 10
//! until the duality gap ν·μ (ν = Σ dim M_b + the number of bounded joint
//! entries) is below 1e-13 of the objective. Newton's method is affine
//! invariant, so the metric's span of decades (the data's precision
//! against the prior's) does not slow it, where a parameterisation of the
//! realisable set (log-Cholesky, Rucker & Wensing 2022) under
//! Levenberg–Marquardt stalled at its start.
//!
//! # Why the data's weight is capped
//!
//! A noise-free log informs some combinations 10²⁸–10³⁴ times more than
//! the prior does the directions the data do not see. In that metric the
//! prior's pull on those directions is below the rounding of the data
//! term: the barrier, weighted at the data's scale early on the central
//! path, pushes them away (a pendulum's mass, which the log cannot see,
//! by orders of magnitude) and nothing measurable brings them back.
//! [`Metric::of_estimate`] therefore caps the data's information per
//! direction: in coordinates whitened by the prior on the base parameters,
//! every singular value of the data's square-root information above
//! [`DATA_CAP`] is set to it. Directions the data inform less keep their
//! exact weight; the others still weigh 10¹⁴ times the prior, so the
//! projection moves an identified combination by about 10⁻¹⁴ of its prior
//! standard deviation per standard deviation of prior pull, while the
//! directions only the prior sees are resolved to rounding.
//!
//! The Newton steps are solved with the columns scaled to the norms of F's
//! columns (their conditioning then follows the capped metric, not the
//! units of π).

use super::IdentifyError;
use super::regressor::{BodySlots, ParameterKind, SYM, Structure};
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

/// The entries of π that must not be negative: every joint's damping and
/// spring stiffness (indices into π).
pub fn bounded_joint_parameters(structure: &Structure) -> Vec<usize> {
    structure
        .kinds()
        .iter()
        .enumerate()
        .filter(|(_, k)| matches!(k, ParameterKind::Damping | ParameterKind::Stiffness))
        .map(|(i, _)| i)
        .collect()
}

/// Which joint dampings and stiffnesses of π are negative (or not finite):
/// their indices into π.
pub fn negative_joint_parameters(structure: &Structure, pi: &[f64]) -> Vec<usize> {
    bounded_joint_parameters(structure)
        .into_iter()
        .filter(|&i| pi[i] < 0.0 || !pi[i].is_finite())
        .collect()
}

/// Is π feasible for the mechanism: every body realisable and every joint
/// damping and stiffness ≥ 0?
pub fn feasible(structure: &Structure, pi: &[f64]) -> bool {
    inconsistent_bodies(structure, pi).is_empty()
        && negative_joint_parameters(structure, pi).is_empty()
}

/// A strictly feasible start for [`project`] from declared parameters
/// (realisable bodies, joint entries ≥ 0): each bounded joint entry that
/// is 0 is set to 10⁻³ × its `scale` (the prior's standard deviation).
/// The start only sets where the central path begins: the projection's
/// result does not depend on it.
pub fn interior_start(structure: &Structure, declared: &[f64], scale: &[f64]) -> Vec<f64> {
    let mut start = declared.to_vec();
    for i in bounded_joint_parameters(structure) {
        if start[i].is_nan() || start[i] <= 0.0 {
            start[i] = 1e-3 * scale[i].abs();
        }
    }
    start
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

/// The barriers −ln det M_b(π) of the bodies and −ln π_i of the bounded
/// joint entries, summed, with their gradient and the Cholesky factor L_b
/// (H_b = L_b L_bᵀ) of each block of the Hessian; `None` where some M_b is
/// not positive definite or some bounded entry not positive.
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
    for i in bounded_joint_parameters(structure) {
        let x = pi[i];
        if !(x > 0.0 && x.is_finite()) {
            return None;
        }
        // −ln x: gradient −1/x, Hessian 1/x² = (1/x)²
        value -= x.ln();
        gradient[i] = -1.0 / x;
        factors.push((i, DMatrix::from_element(1, 1, 1.0 / x)));
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

/// The largest square-root information of the data, per direction,
/// relative to the prior's in [`Metric::of_estimate`]: the data weigh at
/// most `DATA_CAP`² = 10¹⁴ times the prior in any direction of the
/// projection (module docs).
pub const DATA_CAP: f64 = 1e7;

impl Metric {
    /// The metric of an estimate's objective, |R(K·π − θ_data)|² +
    /// |S⁻¹(π − π₀)|², with the data's information capped at [`DATA_CAP`]
    /// times the prior's per direction (module docs): `k` the base
    /// parameters' K (r × P), `r` the upper-triangular square root of the
    /// data's information on θ = K·π (r × r), `theta_data` the data-only
    /// estimate of θ, `declared` π₀, `prior_sd` the diagonal of S.
    ///
    /// With L Lᵀ = K S² Kᵀ (the prior's covariance of θ) and the singular
    /// values R·L = U Σ Vᵀ, the capped square root is
    /// R' = U min(Σ, DATA_CAP) Vᵀ L⁻¹.
    pub fn of_estimate(
        k: &DMatrix<f64>,
        r: &DMatrix<f64>,
        theta_data: &DVector<f64>,
        declared: &[f64],
        prior_sd: &[f64],
    ) -> Result<Self, IdentifyError> {
        let p = declared.len();
        let rank = k.nrows();
        if k.ncols() != p || prior_sd.len() != p || r.ncols() != rank || theta_data.len() != rank {
            return Err(IdentifyError::Dimension {
                what: "estimate metric",
                expected: p,
                found: k.ncols(),
            });
        }
        let s2 = DMatrix::from_diagonal(&DVector::from_iterator(p, prior_sd.iter().map(|s| s * s)));
        let l = (k * s2 * k.transpose())
            .cholesky()
            .ok_or(IdentifyError::Singular)?
            .l();
        let linv = l
            .clone()
            .solve_lower_triangular(&DMatrix::identity(rank, rank))
            .ok_or(IdentifyError::Singular)?;
        let svd = (r * &l).svd(true, true);
        let (u, vt) = match (&svd.u, &svd.v_t) {
            (Some(u), Some(vt)) => (u, vt),
            _ => return Err(IdentifyError::Singular),
        };
        let capped = svd.singular_values.map(|x| x.min(DATA_CAP));
        let rc = u * DMatrix::from_diagonal(&capped) * vt * linv;
        let rk = &rc * k;
        let rows = rk.nrows();
        let mut f = DMatrix::zeros(rows + p, p);
        f.rows_mut(0, rows).copy_from(&rk);
        let mut rhs = DVector::zeros(rows + p);
        rhs.rows_mut(0, rows).copy_from(&(&rc * theta_data));
        for j in 0..p {
            f[(rows + j, j)] = 1.0 / prior_sd[j];
            rhs[rows + j] = declared[j] / prior_sd[j];
        }
        if f.iter().chain(rhs.iter()).any(|x| !x.is_finite()) {
            return Err(IdentifyError::NonFinite {
                what: "projection metric".into(),
            });
        }
        Ok(Metric { f, rhs })
    }
}

/// The feasible π nearest to the estimate in `metric` (realisable bodies,
/// joint dampings and stiffnesses ≥ 0), from `start` (strictly feasible:
/// realisable bodies, bounded joint entries > 0; [`interior_start`]), by a
/// log-barrier interior-point method (module docs). Returns the projected
/// π and the Newton steps taken.
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
    let bounded = bounded_joint_parameters(structure);
    if let Some(i) = bounded
        .iter()
        .find(|&&i| start[i].is_nan() || start[i] <= 0.0)
    {
        return Err(IdentifyError::Inconsistent {
            message: format!(
                "the start of the projection is not strictly positive (`{}` = {})",
                structure.names[*i], start[*i]
            ),
        });
    }
    let quadratic = |pi: &DVector<f64>| (&metric.f * pi - &metric.rhs).norm_squared();
    // ν: the barrier's degree, Σ dim M_b plus one per bounded entry; the
    // duality gap of the central point at weight μ is ν·μ
    let nu: usize = structure
        .bodies
        .iter()
        .map(|b| match b {
            BodySlots::Planar { .. } => 3,
            BodySlots::Spatial { .. } => 4,
        })
        .sum::<usize>()
        + bounded.len();
    let nu = nu.max(1) as f64;
    let mut mu = (1.0 + quadratic(&pi)) / nu;
    let rows = metric.f.nrows();
    let barrier_rows: usize =
        structure.bodies.iter().map(|b| b.len()).sum::<usize>() + bounded.len();
    // Column scales of the Newton systems: F's column norms (module docs).
    let scale: Vec<f64> = (0..p)
        .map(|j| {
            let n = metric.f.column(j).norm();
            if n > 0.0 && n.is_finite() {
                1.0 / n
            } else {
                1.0
            }
        })
        .collect();
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
            for (j, sj) in scale.iter().enumerate() {
                a.column_mut(j).scale_mut(*sj);
            }
            let mut step = a
                .svd(true, true)
                .solve(&rhs, 0.0)
                .map_err(|_| IdentifyError::Singular)?;
            for (j, sj) in scale.iter().enumerate() {
                step[j] *= sj;
            }
            let slope = grad.dot(&step);
            let merit = |trial: &DVector<f64>| {
                barrier(structure, trial).map(|tb| quadratic(trial) + mu * tb.value)
            };
            // converged at this μ: Newton's decrement λ² = −∇Φ·Δ below
            // the rounding of Φ; the last step (of size λ in Φ's metric)
            // is still taken where it keeps Φ within its rounding, so
            // that the result is resolved to λ², not λ
            if slope.is_nan() || slope >= -1e-13 * (1.0 + phi.abs()) {
                let trial = &pi + &step;
                if let Some(v) = merit(&trial)
                    && v <= phi + 1e-13 * (1.0 + phi.abs())
                {
                    pi = trial;
                }
                break;
            }
            let mut t = 1.0;
            let mut moved = false;
            for _ in 0..60 {
                let trial = &pi + &step * t;
                if let Some(v) = merit(&trial)
                    && v <= phi + 0.25 * t * slope
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
