//! Bias-compensated, noise-weighted least squares for position noise of a
//! known size ([`super::Noise::ErrorsInVariables`]).
//!
//! # Why
//!
//! Position noise enters the rows W and the right-hand side b together, so
//! the least-squares normal matrix is biased: E(WᵀW) = W̄ᵀW̄ + (the noise's
//! own contribution), and likewise Wᵀb (errors in variables). Instrumental
//! variables remove the bias when each transition has neighbours to build
//! instruments from; logs of isolated transitions (three samples each) have
//! none. This estimator needs no neighbours, only the size of the noise.
//!
//! # The estimate
//!
//! Write the rows of transition k on the base parameters as A_k = [W₁ | b]
//! and θ̃ = (θ, −1), so that the residual is A_k θ̃. For every column c of
//! A_k its derivative D_{k,c} = ∂A_k[·, c]/∂x in the transition's 3N
//! positions is taken by central differences of the rows
//! ([`super::Regressor::transition`]); the residual's noise Jacobian is then
//! J_k = Σ_c θ̃_c D_{k,c}, and row a of transition k has the noise variance
//! v_{k,a} = J_{k,a} Σ_x J_{k,a}ᵀ, with Σ_x the positions' covariance
//! ([`SampleNoise`]). With the weights w_{k,a} = 1/v_{k,a} at the current θ̂,
//!
//! ```text
//! M = Σ w A_aᵀ A_a          (the weighted normal matrix, augmented)
//! C = Σ w D_a Σ_x D_aᵀ      (its expected noise part, D_a the (r+1) × 3N
//!                            derivatives of row a's entries)
//! θ̂ = argmin  θ̃ᵀ (M − C) θ̃ + (θ − K·π₀)ᵀ P (θ − K·π₀)
//! ```
//!
//! to first order in the noise, E(M) − C is the noise-free normal matrix, so
//! the estimate is consistent (as the transitions grow, θ̂ tends to the
//! parameters the noise-free rows give). The weights make it the
//! generalised least squares of rows whose noise differs from transition to
//! transition (a fast swing's rows are noisier than a slow one's). The
//! weights depend on θ̂, so the solve is repeated from the prior's mean
//! until θ̂ settles (at most [`ITERATIONS`] times). The prior's precision P
//! is the same as in [`super::estimate::solve`]; the rows are in units of
//! their noise, so no noise level is estimated. One weight serves all rows
//! of a transition (the inverse of their mean predicted variance), so that
//! M and C do not depend on the basis a regressor chose for a loop's rows.
//!
//! Along a direction that the noise-free rows do not see (the rank-revealing
//! decomposition of noisy rows counts such directions as base parameters),
//! M − C is zero plus a fluctuation. In coordinates whitened by the prior,
//! the data count along an eigenvector of M − C only where its eigenvalue
//! exceeds [`SIGNIFICANCE`] standard deviations of that fluctuation; along
//! the others the prior holds θ.
//!
//! # Loops
//!
//! A sample on the loop (|g(x)| below 10⁻³ of the noise's standard
//! deviation: it was projected onto the constraints, as
//! `vigp::projection::project_configuration` does) carries noise along the
//! loop only: its covariance is projected onto the constraints' tangent
//! space, Σ_x ← T Σ_x Tᵀ with T = I − G⁺G. A sample off the loop keeps the
//! full covariance.
//!
//! # Limits
//!
//! The correction is first order in the noise: it is exact for the terms of
//! the residual that are linear in each sample's noise and leaves O(σ⁴)
//! relative terms. The weights are right for noise in the positions, not
//! for the rule's own discretisation error, which a log of a continuous
//! system adds to every row: where that error dominates the noise, least
//! squares, which weights the rows alike, predicts better
//! (docs/identify.md measures both).

use super::IdentifyError;
use super::Log;
use super::base::Base;
use super::estimate::{BasePrior, Fit, Stack};
use super::noise::SampleNoise;
use super::regressor::{Regressor, Transition};
use nalgebra::{DMatrix, DVector};

/// The most reweighting passes of the estimate (module docs).
pub const ITERATIONS: usize = 8;

/// The bias-compensated estimate (module docs) on the stacked `stack` of
/// `logs`, with `base`'s parameters and the prior 𝒩(`prior_mean`,
/// `prior_sd`²).
pub fn solve<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    stack: &Stack,
    base: &Base,
    prior_mean: &[f64],
    prior_sd: &[f64],
    noise: SampleNoise,
) -> Result<Fit, IdentifyError> {
    noise.validate()?;
    let (n, r) = stack.rows_for(base)?;
    let prior = BasePrior::new(base, prior_mean, prior_sd)?;
    let transitions = derivatives(regressor, logs, stack, base, noise)?;
    let rows = augmented(&stack.w, &stack.b, base);
    let mut theta = prior.theta.clone();
    let mut iterations = 0;
    let mut last = None;
    for it in 0..ITERATIONS {
        let (mc, weights) = accumulate(&rows, stack.block, &transitions, &theta);
        let spread = |v: &DVector<f64>| noise_spread(&transitions, &weights, stack.block, v);
        let post = Posterior::new(&mc, &prior, spread)?;
        let change = (&post.theta - &theta).amax() / post.theta.amax().max(f64::MIN_POSITIVE);
        theta = post.theta.clone();
        iterations = it + 1;
        last = Some((post, weights));
        if change < 1e-12 {
            break;
        }
    }
    let (post, weights) = last.ok_or(IdentifyError::Singular)?;
    let Posterior {
        cov_theta,
        data_theta,
        root,
        ..
    } = post;
    let (pi, covariance) = prior.standard(&base.k, &theta, &cov_theta);
    let residuals = &stack.b - &stack.w * &pi;
    let row_scale: Vec<f64> = weights.iter().map(|w| w.sqrt()).collect();
    let fitted_rows = DMatrix::from_fn(n, r, |i, c| rows[(i, c)] * row_scale[i]);
    // σ per row position: the r.m.s. of the rows' predicted noise
    let sigma = (0..stack.block)
        .map(|j| {
            let v: Vec<f64> = (j..n)
                .step_by(stack.block)
                .map(|i| 1.0 / weights[i])
                .collect();
            (v.iter().sum::<f64>() / v.len().max(1) as f64).sqrt()
        })
        .collect();
    Ok(Fit {
        pi,
        theta,
        base_covariance: cov_theta,
        covariance,
        data: (data_theta, root),
        sigma,
        weights: vec![1.0; n],
        residuals,
        iterations,
        fitted_rows,
        row_scale,
        prior_precision: prior.precision(),
    })
}

/// The prior-weighted solve of one pass (module docs), in coordinates
/// whitened by the prior, θ = K·π₀ + L·φ with K S² Kᵀ = L Lᵀ: the data's
/// information there, Lᵀ(M − C)_θθ L = U Λ Uᵀ, counts only along its
/// positive eigenvalues; along the others the noise's expected part
/// outweighs what the rows show, the data say nothing, and the prior
/// holds θ.
struct Posterior {
    theta: DVector<f64>,
    cov_theta: DMatrix<f64>,
    /// The data-only estimate (the prior's mean along uninformed
    /// directions).
    data_theta: DVector<f64>,
    /// A square root R of the data's (clipped) information, RᵀR.
    root: DMatrix<f64>,
}

impl Posterior {
    fn new(
        mc: &DMatrix<f64>,
        prior: &BasePrior,
        spread: impl Fn(&DVector<f64>) -> f64,
    ) -> Result<Self, IdentifyError> {
        let r = mc.nrows() - 1;
        let info = mc.view((0, 0), (r, r));
        let l = &prior.l;
        let a = l.transpose() * info * l;
        let eig = ((&a + a.transpose()) * 0.5).symmetric_eigen();
        let (u, lam) = (&eig.eigenvectors, &eig.eigenvalues);
        let g = l.transpose() * (mc.column(r).rows(0, r) - info * &prior.theta);
        let ug = u.transpose() * g;
        // informed: information above SIGNIFICANCE standard deviations of
        // what the noise alone gives along that direction
        let kept = DVector::from_fn(r, |i, _| {
            let v = l * u.column(i);
            if lam[i] > SIGNIFICANCE * spread(&v) {
                lam[i]
            } else {
                0.0
            }
        });
        let phi = u * DVector::from_fn(r, |i, _| ug[i] / (kept[i] + 1.0));
        let phi_data =
            u * DVector::from_fn(r, |i, _| if kept[i] > 0.0 { ug[i] / kept[i] } else { 0.0 });
        let cov_phi = u * DMatrix::from_diagonal(&kept.map(|x| 1.0 / (x + 1.0))) * u.transpose();
        Ok(Posterior {
            theta: &prior.theta + l * phi,
            cov_theta: l * cov_phi * l.transpose(),
            data_theta: &prior.theta + l * phi_data,
            root: DMatrix::from_diagonal(&kept.map(f64::sqrt)) * u.transpose() * &prior.linv,
        })
    }
}

/// How many standard deviations of its noise-only value the corrected
/// information along a direction must exceed for the data to count there.
pub const SIGNIFICANCE: f64 = 3.0;

/// The standard deviation of the corrected information vᵀ(M − C)v along a
/// direction v of θ that the noise-free rows do not see: each transition
/// contributes w·(|e|² − E|e|²), e its rows' noise along v, of variance
/// 2·(w·E|e|²)² for Gaussian noise (one row; at most that for a block).
fn noise_spread(
    transitions: &[Derivatives],
    weights: &[f64],
    block: usize,
    v: &DVector<f64>,
) -> f64 {
    let r = v.len();
    let var: f64 = transitions
        .iter()
        .enumerate()
        .map(|(t, d)| {
            let s: f64 = d
                .rows
                .iter()
                .map(|da| (da.rows(0, r).transpose() * v).norm_squared())
                .sum();
            let ws = weights[t * block] * s;
            2.0 * ws * ws
        })
        .sum();
    var.sqrt()
}

/// One transition's row derivatives: for each derivative row a, the
/// (r + 1) × 3N matrix of the derivatives of the rows' independent entries
/// and of b in the transition's positions, already multiplied by a square
/// root of the positions' covariance (so that D Σ_x Dᵀ is a plain
/// product). Without loops these are the transition's own rows; with
/// loops, the N rows of T(x_k)·(∂raw − ∂Gᵀ·μ) (module docs), which span
/// the same derivatives in a basis that does not depend on the regressor's
/// choice of null-space basis.
struct Derivatives {
    rows: Vec<DMatrix<f64>>,
}

/// Central differences in the 3N positions of `positions`: `at(xs)` gives
/// a matrix (any fixed shape); column (s, c) of the result's matrix j is
/// the derivative of `at`'s column j in coordinate c of sample s, as a
/// vector of its rows. Step 1e-6·(1 + |x|): truncation ≈ 1e-12 relative,
/// rounding ≈ 1e-10, ample for a correction of the noise's size.
fn column_differences(
    positions: &[Vec<f64>; 3],
    mut at: impl FnMut(&[Vec<f64>; 3]) -> Result<DMatrix<f64>, IdentifyError>,
) -> Result<Vec<DMatrix<f64>>, IdentifyError> {
    let n = positions[0].len();
    let mut out: Vec<DMatrix<f64>> = Vec::new();
    for s in 0..3 {
        for c in 0..n {
            let h = 1e-6 * (1.0 + positions[s][c].abs());
            let mut xs = positions.clone();
            xs[s][c] += h;
            let plus = at(&xs)?;
            xs[s][c] -= 2.0 * h;
            let minus = at(&xs)?;
            if out.is_empty() {
                out = vec![DMatrix::zeros(plus.nrows(), 3 * n); plus.ncols()];
            }
            for (j, o) in out.iter_mut().enumerate() {
                o.set_column(s * n + c, &((plus.column(j) - minus.column(j)) / (2.0 * h)));
            }
        }
    }
    Ok(out)
}

/// The rows (Y, b) as one matrix [Y₁ | b] on the independent columns.
fn augmented(y: &DMatrix<f64>, b: &DVector<f64>, base: &Base) -> DMatrix<f64> {
    let r = base.rank();
    DMatrix::from_fn(y.nrows(), r + 1, |i, e| {
        if e < r {
            y[(i, base.independent[e])]
        } else {
            b[i]
        }
    })
}

/// The derivatives of every stacked transition's rows (module docs).
fn derivatives<R: Regressor>(
    regressor: &R,
    logs: &[Log],
    stack: &Stack,
    base: &Base,
    noise: SampleNoise,
) -> Result<Vec<Derivatives>, IdentifyError> {
    let n = regressor.coordinates();
    let r = base.rank();
    let zeros = vec![0.0; regressor.inputs()];
    let sample_root = covariance_root(&noise.covariance);
    let mut out = Vec::with_capacity(stack.origin.len());
    for &(li, k) in &stack.origin {
        let at = logs[li].transition(k, &zeros);
        let positions = at.positions.map(<[f64]>::to_vec);
        let inputs = at.inputs;
        let rows_of = |xs: &[Vec<f64>; 3], project: bool| {
            let t = Transition {
                positions: [&xs[0], &xs[1], &xs[2]],
                inputs,
            };
            let rows = if project {
                regressor.transition(&t)?
            } else {
                regressor.unprojected_transition(&t)?
            };
            Ok(augmented(&rows.0, &rows.1, base))
        };
        // per column of [Y₁ | b]: its derivative, rows × 3N
        let columns = match regressor.loop_constraints(&positions[1])? {
            Some((_, g)) if g.nrows() > 0 => {
                // λ held per column: μ = (G Gᵀ)⁻¹ G·column at x_k
                let raw = rows_of(&positions, false)?;
                let mu = (&g * g.transpose())
                    .lu()
                    .solve(&(&g * &raw))
                    .ok_or(IdentifyError::Singular)?;
                let tangent = tangent_of(&g)?;
                let held = column_differences(&positions, |xs| {
                    let gk = regressor
                        .loop_constraints(&xs[1])?
                        .map(|(_, g)| g)
                        .ok_or(IdentifyError::Singular)?;
                    Ok(rows_of(xs, false)? - gk.transpose() * &mu)
                })?;
                held.into_iter().map(|d| &tangent * d).collect()
            }
            _ => column_differences(&positions, |xs| rows_of(xs, true))?,
        };
        // Σ_x = (sample covariance ⊗ 1) projected on the loop's tangent at
        // samples on the loop: Σ_x^{1/2} = blocks L_st·T_s
        let tangent: Vec<DMatrix<f64>> = positions
            .iter()
            .map(|x| tangent_projector(regressor, x, noise.scale()))
            .collect::<Result<_, _>>()?;
        let mut root = DMatrix::zeros(3 * n, 3 * n);
        for s in 0..3 {
            for t in 0..3 {
                if sample_root[(s, t)] != 0.0 {
                    root.view_mut((s * n, t * n), (n, n))
                        .copy_from(&(&tangent[s] * sample_root[(s, t)]));
                }
            }
        }
        let count = columns.first().map_or(0, |c| c.nrows());
        let rows = (0..count)
            .map(|a| DMatrix::from_fn(r + 1, 3 * n, |e, j| columns[e][(a, j)]) * &root)
            .collect();
        out.push(Derivatives { rows });
    }
    Ok(out)
}

/// M − C (augmented, (r + 1)²) and the rows' weights at θ (module docs):
/// one weight per transition, the inverse of its rows' mean predicted
/// noise variance, so that M and C do not depend on the basis a
/// regressor chose for a loop's rows.
fn accumulate(
    rows: &DMatrix<f64>,
    block: usize,
    transitions: &[Derivatives],
    theta: &DVector<f64>,
) -> (DMatrix<f64>, Vec<f64>) {
    let r = rows.ncols() - 1;
    let mut tilde = DVector::zeros(r + 1);
    tilde.rows_mut(0, r).copy_from(theta);
    tilde[r] = -1.0;
    let variances: Vec<f64> = transitions
        .iter()
        .map(|d| {
            let total: f64 = d
                .rows
                .iter()
                .map(|da| (da.transpose() * &tilde).norm_squared())
                .sum();
            total / block.max(1) as f64
        })
        .collect();
    let top = variances.iter().cloned().fold(0.0, f64::max);
    let floor = 1e-30 * top.max(f64::MIN_POSITIVE);
    let mut mc = DMatrix::zeros(r + 1, r + 1);
    let mut weights = Vec::with_capacity(rows.nrows());
    for (t, d) in transitions.iter().enumerate() {
        let w = 1.0 / variances[t].max(floor);
        for i in t * block..(t + 1) * block {
            let row = rows.row(i).transpose();
            mc.ger(w, &row, &row, 1.0);
            weights.push(w);
        }
        for da in &d.rows {
            mc.gemm(-w, da, &da.transpose(), 1.0);
        }
    }
    (mc, weights)
}

/// A square root L of the 3 × 3 sample covariance (L Lᵀ = Σ), by its
/// eigen-decomposition (it may be singular).
fn covariance_root(c: &[[f64; 3]; 3]) -> nalgebra::Matrix3<f64> {
    let m = nalgebra::Matrix3::from_fn(|i, j| 0.5 * (c[i][j] + c[j][i]));
    let eig = m.symmetric_eigen();
    let sq = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    eig.eigenvectors * nalgebra::Matrix3::from_diagonal(&sq)
}

/// T = I − G⁺G at a sample on the loop (|g(x)| ≤ 10⁻³·`scale`), the
/// identity elsewhere and without loops.
fn tangent_projector<R: Regressor>(
    regressor: &R,
    x: &[f64],
    scale: f64,
) -> Result<DMatrix<f64>, IdentifyError> {
    match regressor.loop_constraints(x)? {
        Some((g, jac)) if g.amax() <= 1e-3 * scale && jac.nrows() > 0 => tangent_of(&jac),
        _ => Ok(DMatrix::identity(x.len(), x.len())),
    }
}

/// T = I − G⁺G: the orthogonal projector onto the null space of the
/// constraint Jacobian G (C × N), the loop's tangent space.
fn tangent_of(g: &DMatrix<f64>) -> Result<DMatrix<f64>, IdentifyError> {
    let pinv = g
        .clone()
        .pseudo_inverse(1e-12)
        .map_err(|_| IdentifyError::Singular)?;
    Ok(DMatrix::identity(g.ncols(), g.ncols()) - pinv * g)
}
