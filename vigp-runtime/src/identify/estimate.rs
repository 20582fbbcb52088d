//! Stacked least squares on the regressor rows of every transition, with
//! a Gaussian prior centred on the declared parameters, the position noise
//! handled by instrumental variables, and an optional robust loss.
//!
//! # The estimate
//!
//! With rows W·π ≈ b (one block of N − C rows per transition), row weights
//! 1/σ_j² per row position j within a block (σ_j from the residuals of a
//! first, prior-free fit on the base parameters: rows of different
//! coordinates carry different units) and the prior π ~ 𝒩(π₀, S²), the
//! estimate is the maximum a posteriori
//!
//! ```text
//! π̂ = argmin  Σ_i w_i (W_i π − b_i)²/σ_j(i)²  +  Σ_p ((π_p − π₀_p)/s_p)²
//! ```
//!
//! The prior makes every standard parameter determined: where the data are
//! silent (directions of the null space of W, or poorly excited ones) the
//! estimate stays at the declared values; where they speak, the prior's
//! weight is (σ/s)² against the data's and vanishes as the data grow.
//!
//! # Noise: instrumental variables
//!
//! Position noise enters W and b together (the rows hold discrete
//! velocities and their differences, 1/Δt and 1/Δt² times the noise), so
//! least squares is biased (errors in variables): E(WᵀW) ≠ W̄ᵀW̄. With
//! [`Noise::InstrumentalVariables`](super::Noise::InstrumentalVariables)
//! every transition k also gets instrument rows Z_k: the regressor at positions x̃_{k−1}, x̃_k, x̃_{k+1}
//! from a local polynomial fitted to the samples around k *leaving out*
//! k−1, k, k+1. The residual of row k depends on the noise of those three
//! samples only, and Z_k on none of them, so E[Z_kᵀ ε_k] = 0 (to second
//! order in the noise) and the instrumental-variable estimate is
//! consistent; Z_k stays strongly correlated with the noise-free rows
//! because the fit is accurate on a smooth trajectory. The estimate is
//! two-stage least squares: the weighted rows are projected onto the span
//! of the instruments before the prior-weighted normal equations.
//!
//! # Robust loss
//!
//! [`Loss::Huber`] and [`Loss::Cauchy`] down-weight rows with large
//! standardised residuals by iteratively reweighted least squares, the
//! scale per row position being 1.4826 × the median absolute residual.

use super::IdentifyError;
use super::base::Base;
use nalgebra::{DMatrix, DVector};

/// The loss on standardised row residuals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Loss {
    /// Squares: ordinary least squares.
    Squared,
    /// Huber's loss with threshold `k` (robust standard deviations; 1.345
    /// gives 95 % efficiency under Gaussian noise).
    Huber(f64),
    /// Cauchy's loss with scale `k` (2.385 gives 95 % efficiency).
    Cauchy(f64),
}

impl Loss {
    fn weight(&self, u: f64) -> f64 {
        match *self {
            Loss::Squared => 1.0,
            Loss::Huber(k) => {
                if u.abs() <= k {
                    1.0
                } else {
                    k / u.abs()
                }
            }
            Loss::Cauchy(k) => 1.0 / (1.0 + (u / k) * (u / k)),
        }
    }
}

/// The stacked rows of all transitions.
#[derive(Clone, Debug)]
pub struct Stack {
    /// W (rows × P).
    pub w: DMatrix<f64>,
    /// b.
    pub b: DVector<f64>,
    /// Instrument rows (same shape as W), for
    /// [`Noise::InstrumentalVariables`](super::Noise::InstrumentalVariables).
    pub z: Option<DMatrix<f64>>,
    /// Position of each row within its transition's block.
    pub slot: Vec<usize>,
    /// Per transition: (log, k) of its middle sample x_k.
    pub origin: Vec<(usize, usize)>,
    /// Rows per transition.
    pub block: usize,
    /// Transitions whose instrument rows came from the leave-out fits (the
    /// others are their own instruments); `z` is `None` when there are
    /// none.
    pub instrumented: usize,
}

impl Stack {
    /// The number of rows n and of `base`'s parameters r, checked:
    /// n ≥ r + one transition's block and r > 0, else
    /// [`IdentifyError::TooFewTransitions`].
    pub(crate) fn rows_for(&self, base: &Base) -> Result<(usize, usize), IdentifyError> {
        let n = self.w.nrows();
        let r = base.rank();
        if n < r + self.block || r == 0 {
            return Err(IdentifyError::TooFewTransitions {
                rows: n,
                needed: r + self.block,
            });
        }
        Ok((n, r))
    }
}

/// What the solver returns.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The MAP estimate of π (before any consistency projection).
    pub pi: DVector<f64>,
    /// The MAP estimate of the base parameters K·π.
    pub theta: DVector<f64>,
    /// The posterior covariance of the base parameters under independent
    /// rows (r × r).
    pub base_covariance: DMatrix<f64>,
    /// The posterior covariance of π under independent rows (P × P).
    pub covariance: DMatrix<f64>,
    /// The data-only least-squares estimate of the base parameters and the
    /// upper-triangular factor R of its information (RᵀR): the data term of
    /// the objective is |R·(K·π − θ_data)|² up to a constant.
    pub data: (DVector<f64>, DMatrix<f64>),
    /// Noise standard deviation per row position (classical or robust).
    pub sigma: Vec<f64>,
    /// Final row weights (1 without a robust loss).
    pub weights: Vec<f64>,
    /// Residuals b − W·π̂, unweighted.
    pub residuals: DVector<f64>,
    /// IRLS iterations taken (0 for squares).
    pub iterations: usize,
    /// The weighted (two-stage) rows Ŵ on the base parameters (n × r):
    /// θ̂ − θ = (ŴᵀŴ + P)⁻¹ Ŵᵀ D ε for row errors ε.
    pub fitted_rows: DMatrix<f64>,
    /// The row scales D (√weight/σ_j).
    pub row_scale: Vec<f64>,
    /// The prior precision P = (K S² Kᵀ)⁻¹ of the base parameters.
    pub prior_precision: DMatrix<f64>,
}

/// Solve for π (module docs).
///
/// The data see π only through the base parameters θ = K·π, so the MAP
/// problem splits: the prior on π induces θ ~ 𝒩(K·π₀, K S² Kᵀ); θ̂ solves
/// the prior-weighted (IV) least squares on the independent columns, as
/// one stacked system by SVD (no normal equations: a noise-free log
/// weights the data some 10³⁰ above the prior); and π̂ is the prior's
/// conditional mean given θ̂, π̂ = π₀ + S²Kᵀ(K S² Kᵀ)⁻¹(θ̂ − K·π₀), with
/// covariance S² − A K S² + A Σ_θ Aᵀ, A = S²Kᵀ(K S² Kᵀ)⁻¹.
pub fn solve(
    stack: &Stack,
    base: &Base,
    prior_mean: &[f64],
    prior_sd: &[f64],
    loss: Loss,
) -> Result<Fit, IdentifyError> {
    let (n, r) = stack.rows_for(base)?;
    let cols =
        |m: &DMatrix<f64>| DMatrix::from_fn(m.nrows(), r, |i, c| m[(i, base.independent[c])]);
    let w1 = cols(&stack.w);
    let z1 = stack.z.as_ref().map(cols);
    // First pass, no prior: base parameters by (IV) least squares.
    let first = data_rows(&w1, &stack.b, z1.as_ref(), &vec![1.0; n])?;
    let theta0 = lstsq(&first.0, &first.1)?;
    let e = &stack.b - &w1 * &theta0;
    let dof = n as f64 - r as f64;
    let mut sigma = per_slot(stack, |rows| {
        let ss: f64 = rows.iter().map(|&i| e[i] * e[i]).sum();
        (ss / (dof * rows.len() as f64 / n as f64)).sqrt()
    });
    floor_sigma(&mut sigma, stack);
    let prior = BasePrior::new(base, prior_mean, prior_sd)?;
    let (prior_theta, linv) = (&prior.theta, &prior.linv);
    let mut weights: Vec<f64> = vec![1.0; n];
    let max_iter = if loss == Loss::Squared { 1 } else { 100 };
    let mut theta = prior_theta.clone();
    let mut iterations = 0;
    let mut result = None;
    for it in 0..max_iter {
        let d: Vec<f64> = (0..n)
            .map(|i| weights[i].sqrt() / sigma[stack.slot[i]])
            .collect();
        let wt = DMatrix::from_fn(n, r, |i, j| w1[(i, j)] * d[i]);
        let bt = DVector::from_fn(n, |i, _| stack.b[i] * d[i]);
        let zt = z1
            .as_ref()
            .map(|z| DMatrix::from_fn(n, r, |i, j| z[(i, j)] * d[i]));
        let (a, c) = data_rows(&wt, &bt, zt.as_ref(), &vec![1.0; n])?;
        let rows = a.nrows();
        let mut stacked = DMatrix::zeros(rows + r, r);
        stacked.rows_mut(0, rows).copy_from(&a);
        stacked.rows_mut(rows, r).copy_from(linv);
        let mut rhs = DVector::zeros(rows + r);
        rhs.rows_mut(0, rows).copy_from(&c);
        rhs.rows_mut(rows, r).copy_from(&(linv * prior_theta));
        let svd = stacked.svd(true, true);
        let new_theta = svd.solve(&rhs, 0.0).map_err(|_| IdentifyError::Singular)?;
        let vt = svd.v_t.as_ref().ok_or(IdentifyError::Singular)?;
        let inv_s2 = DMatrix::from_diagonal(&svd.singular_values.map(|s| 1.0 / (s * s)));
        let cov_theta = vt.transpose() * inv_s2 * vt;
        let data_theta = lstsq(&a, &c)?;
        let data_r = a.clone().qr().r();
        let change = (&new_theta - &theta).amax() / new_theta.amax().max(f64::MIN_POSITIVE);
        theta = new_theta;
        iterations = it;
        let fitted = match &zt {
            None => wt.clone(),
            Some(z) => {
                let q = z.clone().qr().q();
                &q * (q.transpose() * &wt)
            }
        };
        result = Some((cov_theta, data_theta, data_r, fitted, d));
        if loss == Loss::Squared {
            break;
        }
        let res = &stack.b - &w1 * &theta;
        let mut s = per_slot(stack, |rows| {
            let mut a: Vec<f64> = rows.iter().map(|&i| res[i].abs()).collect();
            a.sort_by(f64::total_cmp);
            1.4826 * a[a.len() / 2]
        });
        floor_sigma(&mut s, stack);
        sigma = s;
        for i in 0..n {
            weights[i] = loss.weight(res[i] / sigma[stack.slot[i]]);
        }
        if it > 0 && change < 1e-12 {
            break;
        }
    }
    let (cov_theta, data_theta, data_r, fitted_rows, row_scale) =
        result.ok_or(IdentifyError::Singular)?;
    let prior_precision = prior.precision();
    let (pi, covariance) = prior.standard(&base.k, &theta, &cov_theta);
    let residuals = &stack.b - &stack.w * &pi;
    Ok(Fit {
        pi,
        theta,
        base_covariance: cov_theta,
        covariance,
        data: (data_theta, data_r),
        sigma,
        weights,
        residuals,
        iterations,
        fitted_rows,
        row_scale,
        prior_precision,
    })
}

/// The prior π ~ 𝒩(π₀, S²) seen on the base parameters θ = K·π:
/// θ ~ 𝒩(K·π₀, K S² Kᵀ), and the way back from an estimate of θ to π
/// ([`solve`]'s docs).
pub(crate) struct BasePrior {
    mean: DVector<f64>,
    s2: DMatrix<f64>,
    /// A = S²Kᵀ(KS²Kᵀ)⁻¹ (P × r).
    gain: DMatrix<f64>,
    /// K·π₀.
    pub(crate) theta: DVector<f64>,
    /// L with K S² Kᵀ = L Lᵀ (lower triangular).
    pub(crate) l: DMatrix<f64>,
    /// L⁻¹: the prior's whitening rows.
    pub(crate) linv: DMatrix<f64>,
}

impl BasePrior {
    /// The prior of mean `prior_mean` and standard deviations `prior_sd`
    /// on `base`'s parameters.
    pub(crate) fn new(
        base: &Base,
        prior_mean: &[f64],
        prior_sd: &[f64],
    ) -> Result<Self, IdentifyError> {
        let r = base.rank();
        let mean = DVector::from_column_slice(prior_mean);
        let s2 = DMatrix::from_diagonal(&DVector::from_iterator(
            prior_sd.len(),
            prior_sd.iter().map(|s| s * s),
        ));
        let ks2 = &base.k * &s2;
        let chol = (&ks2 * base.k.transpose())
            .cholesky()
            .ok_or(IdentifyError::Singular)?;
        let gain = chol.solve(&ks2).transpose();
        let theta = &base.k * &mean;
        let l = chol.l();
        let linv = l
            .solve_lower_triangular(&DMatrix::identity(r, r))
            .ok_or(IdentifyError::Singular)?;
        Ok(BasePrior {
            mean,
            s2,
            gain,
            theta,
            l,
            linv,
        })
    }

    /// The prior precision (K S² Kᵀ)⁻¹ of the base parameters.
    pub(crate) fn precision(&self) -> DMatrix<f64> {
        self.linv.transpose() * &self.linv
    }

    /// π̂, the prior's conditional mean given θ̂ (of covariance
    /// `cov_theta`), and its covariance.
    pub(crate) fn standard(
        &self,
        k: &DMatrix<f64>,
        theta: &DVector<f64>,
        cov_theta: &DMatrix<f64>,
    ) -> (DVector<f64>, DMatrix<f64>) {
        let pi = &self.mean + &self.gain * (theta - &self.theta);
        // S² − A K S² in its product form (I − AK) S² (I − AK)ᵀ (AK is a
        // projector and A K S² symmetric, so the two are equal): the
        // difference cancels to rounding on parameters the data fix, and
        // can leave a variance of −1e-21 there; the product's diagonal is
        // a sum of non-negative terms
        let p = self.gain.nrows();
        let free = DMatrix::<f64>::identity(p, p) - &self.gain * k;
        let covariance =
            &free * &self.s2 * free.transpose() + &self.gain * cov_theta * self.gain.transpose();
        let covariance = (&covariance + covariance.transpose()) * 0.5;
        (pi, covariance)
    }
}

/// The data rows of the (weighted) base problem: W₁ itself, or with
/// instruments Z₁ the two-stage rows Qᵀ·W₁, Qᵀ·b (Q an orthonormal basis
/// of Z₁'s columns), whose least squares is the IV estimate
/// (Z₁ᵀW₁)⁻¹Z₁ᵀb.
fn data_rows(
    w1: &DMatrix<f64>,
    b: &DVector<f64>,
    z1: Option<&DMatrix<f64>>,
    _weights: &[f64],
) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
    match z1 {
        None => Ok((w1.clone(), b.clone())),
        Some(z) => {
            let q = z.clone().qr().q();
            Ok((q.transpose() * w1, q.transpose() * b))
        }
    }
}

fn lstsq(a: &DMatrix<f64>, b: &DVector<f64>) -> Result<DVector<f64>, IdentifyError> {
    a.clone()
        .svd(true, true)
        .solve(b, 0.0)
        .map_err(|_| IdentifyError::Singular)
}

fn per_slot(stack: &Stack, f: impl Fn(&[usize]) -> f64) -> Vec<f64> {
    (0..stack.block)
        .map(|j| {
            let rows: Vec<usize> = (0..stack.slot.len())
                .filter(|i| stack.slot[*i] == j)
                .collect();
            if rows.is_empty() { 0.0 } else { f(&rows) }
        })
        .collect()
}

/// A noise level of exactly zero (a log that the integrator wrote, fitted
/// exactly) would make the weights infinite: floor each σ_j at the
/// rounding level of its rows, 1e-15 × the r.m.s. right-hand side.
fn floor_sigma(sigma: &mut [f64], stack: &Stack) {
    let n = stack.b.len() as f64;
    let rms = (stack.b.norm_squared() / n)
        .sqrt()
        .max(stack.w.amax() * 1e-3);
    let floor = 1e-15 * rms.max(f64::MIN_POSITIVE);
    for s in sigma.iter_mut() {
        if !(s.is_finite() && *s > floor) {
            *s = floor;
        }
    }
}

/// The weights of a local polynomial of `degree` fitted to the samples at
/// offsets ±(2..=half_window+1) from the centre, evaluated at offsets −1,
/// 0, 1: row e of the result gives x̃_{k+e−1} = Σ_j w_ej·x_{k+τ_j}.
pub fn leave_out_weights(
    half_window: usize,
    degree: usize,
) -> Result<(Vec<i64>, DMatrix<f64>), IdentifyError> {
    if half_window == 0 || degree + 1 > 2 * half_window {
        return Err(IdentifyError::Options {
            message: format!(
                "instrumental variables: degree {degree} needs more than {} samples (half window {half_window})",
                2 * half_window
            ),
        });
    }
    let h = half_window as i64;
    let taus: Vec<i64> = (-h - 1..=-2).chain(2..=h + 1).collect();
    let scale = (h + 1) as f64;
    let v = DMatrix::from_fn(taus.len(), degree + 1, |i, j| {
        (taus[i] as f64 / scale).powi(j as i32)
    });
    let e = DMatrix::from_fn(3, degree + 1, |i, j| {
        ((i as f64 - 1.0) / scale).powi(j as i32)
    });
    let pinv = v
        .clone()
        .pseudo_inverse(1e-13)
        .map_err(|_| IdentifyError::Singular)?;
    Ok((taus, e * pinv))
}
