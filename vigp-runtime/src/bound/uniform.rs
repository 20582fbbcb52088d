//! The paper's bound (Theorem 1) from the uniform error bound of Lederer,
//! Umlauft & Hirche (NeurIPS 2019, Thm 3.1), per output, in the GP's
//! normalised units (inputs standardised, residual divided by s_y): the GP
//! in those units is exactly the fitted prior, so the theorem applies there
//! and the bound scales back by s_y.
//!
//! ```text
//! |f(x) − μ(x)| ≤ √β(τ)·σ(x) + γ(τ)   for all x in the box X, w.p. ≥ 1 − δ_i
//! β(τ) = 2·(ln M(τ, X) − ln δ_i),   M(τ, X) ≤ Π_j max(1, ⌈r_j·√d/(2τ)⌉)
//! γ(τ) = (L_μ + L_f)·τ + √β(τ)·ω_σ(τ)
//! L_μ  = L_k·√N·‖α‖,  L_k = σ_f²·e^{−1/2}/ℓ_min
//! ω_σ(τ) = σ_f·τ/ℓ_min                                  (feature space, default)
//!        = √(2τ·L_k·(1 + N·‖(K + σ_n²I)⁻¹‖·σ_f²))     (Lederer et al. 2019)
//! ```

use super::{BoundError, LipschitzF, SigmaModulus, Tau, Theorem1Settings, check_delta};
use crate::gp::Gp;
use serde::{Deserialize, Serialize};

/// The parts of one output's Theorem-1 bound (normalised units unless
/// stated).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Theorem1Output {
    /// β_i(τ) = 2·(ln M(τ, X) − ln(δ/p)).
    pub beta: f64,
    /// γ_i(τ) in the units of the velocity (s_y times its normalised value).
    pub gamma: f64,
    /// Grid constant τ_i of the covering argument (normalised input units).
    pub tau: f64,
    /// L_μ = L_k·√N·‖α‖: Lipschitz bound of the posterior mean.
    pub lipschitz_mean: f64,
    /// L_f: Lipschitz constant used for the true map.
    pub lipschitz_f: f64,
    /// ω_σ(τ): modulus of continuity of the posterior standard deviation at τ.
    pub omega_sigma: f64,
    /// L_σ = ω_σ(τ)/τ: the Lipschitz constant of σ for the feature-space
    /// modulus (σ_f/ℓ_min); for Lederer's, whose ω_σ grows like √τ, the
    /// slope of the secant at τ.
    pub lipschitz_sigma: f64,
    /// Median posterior standard deviation (normalised) at the sample
    /// states, the scale τ was chosen for.
    pub sigma_median: f64,
}

/// Everything Theorem 1 needs of the model, per output.
pub(super) struct Theorem1Parts {
    pub outputs: Vec<Theorem1Output>,
    /// The box X in the GP's (encoded, original-unit) inputs.
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
}

/// ln ⌈x⌉ for x ≥ 1 without overflow (ln x once the ceiling no longer
/// matters in f64), 0 below 1.
fn ln_ceil(x: f64) -> f64 {
    if x <= 1.0 {
        0.0
    } else if x < 1e15 {
        x.ceil().ln()
    } else {
        x.ln()
    }
}

/// ln M(τ, X) for a box of edges `r` in d dimensions: covered by cubes of
/// edge 2τ/√d, each inside a ball of radius τ.
pub(super) fn log_covering(r: &[f64], tau: f64) -> f64 {
    let sd = (r.len() as f64).sqrt();
    r.iter().map(|rj| ln_ceil(rj * sd / (2.0 * tau))).sum()
}

/// Computes each output's parts. `sigma_samples[i]` are output i's
/// normalised posterior standard deviations at the sample states (used only
/// to pick τ); `inputs_norm` are the normalised training inputs (row-major).
pub(super) fn compute(
    gp: &Gp,
    settings: &Theorem1Settings,
    sigma_samples: &[Vec<f64>],
) -> Result<Theorem1Parts, BoundError> {
    check_delta(settings.delta)?;
    let m = settings.domain_margin;
    if !(m.is_finite() && m >= 0.0) {
        return Err(BoundError::InvalidSetting {
            what: "domain_margin (must be finite and >= 0)",
            value: m,
        });
    }
    if let Tau::Relative(t) = settings.tau
        && !(t.is_finite() && t > 0.0)
    {
        return Err(BoundError::InvalidSetting {
            what: "tau (relative; must be finite and > 0)",
            value: t,
        });
    }
    let (n, d, p) = (gp.n(), gp.input_dim(), gp.output_dim());
    if let LipschitzF::Given(v) = &settings.lipschitz_f {
        if v.len() != p {
            return Err(BoundError::WrongLength {
                what: "lipschitz_f (one per GP output)",
                expected: p,
                got: v.len(),
            });
        }
        if let Some(bad) = v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
            return Err(BoundError::InvalidSetting {
                what: "lipschitz_f (must be finite and >= 0)",
                value: *bad,
            });
        }
    }
    // the box X: the training inputs' box in normalised units, widened by
    // `margin` times its edge on each side
    let norm = gp.input_normaliser();
    let mut lo = vec![f64::INFINITY; d];
    let mut hi = vec![f64::NEG_INFINITY; d];
    let mut xn = vec![0.0; d];
    for row in gp.inputs().chunks_exact(d) {
        norm.apply(row, &mut xn);
        for j in 0..d {
            lo[j] = lo[j].min(xn[j]);
            hi[j] = hi[j].max(xn[j]);
        }
    }
    let mut r = vec![0.0; d];
    for j in 0..d {
        let w = hi[j] - lo[j];
        lo[j] -= m * w;
        hi[j] += m * w;
        r[j] = hi[j] - lo[j];
    }
    if let Some(bad) = r.iter().find(|x| !x.is_finite()) {
        return Err(BoundError::NonFinite {
            what: "Theorem 1 domain edge",
            value: *bad,
        });
    }
    let r_max = r.iter().copied().fold(0.0f64, f64::max);
    let ln_delta_i = (settings.delta / p as f64).ln();
    let max_scale = norm.scale.iter().copied().fold(0.0f64, f64::max);
    let mut outputs = Vec::with_capacity(p);
    for (i, o) in gp.outputs().iter().enumerate() {
        let hp = o.hyperparameters();
        let sf2 = hp.signal_variance;
        let lmin = hp
            .length_scales
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let lk = hp.kernel_lipschitz();
        let alpha = o.alpha_normalised();
        let alpha_norm = alpha.iter().map(|a| a * a).sum::<f64>().sqrt();
        let l_mu = lk * (n as f64).sqrt() * alpha_norm;
        let s_y = o.output_scale();
        let l_f = match &settings.lipschitz_f {
            LipschitzF::FromMean => l_mu,
            // f_n(x_n) = f(shift + scale ⊙ x_n)/s_y: ‖∇f_n‖ ≤ max scale·‖∇f‖/s_y
            LipschitzF::Given(v) => v[i] * max_scale / s_y,
        };
        let lederer_c = match settings.sigma_modulus {
            SigmaModulus::FeatureSpace => 0.0,
            // ‖(K + σ²I)⁻¹‖ in normalised units
            SigmaModulus::Lederer2019 => 1.0 + n as f64 * o.inv_gram_norm()? * s_y * s_y * sf2,
        };
        let omega = |tau: f64| match settings.sigma_modulus {
            SigmaModulus::FeatureSpace => sf2.sqrt() * tau / lmin,
            SigmaModulus::Lederer2019 => (2.0 * tau * lk * lederer_c).sqrt(),
        };
        let beta_of = |tau: f64| 2.0 * (log_covering(&r, tau) - ln_delta_i);
        let gamma_of = |tau: f64, beta: f64| (l_mu + l_f) * tau + beta.sqrt() * omega(tau);
        let mut sig: Vec<f64> = sigma_samples
            .get(i)
            .map(|v| v.iter().copied().filter(|s| s.is_finite()).collect())
            .unwrap_or_default();
        sig.sort_by(f64::total_cmp);
        // a floor far below any σ that matters keeps τ finite when every
        // sample sits on a training point
        let sigma_median = sig
            .get(sig.len() / 2)
            .copied()
            .unwrap_or(0.0)
            .max(1e-12 * sf2.sqrt());
        let tau = match settings.tau {
            Tau::Relative(t) => t * r_max.max(f64::MIN_POSITIVE),
            Tau::Optimise => {
                // minimise √β(τ)·σ̃ + γ(τ) on a grid of 0.01 decades from
                // 1e-40 to 10× the largest edge
                let top = (r_max.max(1e-300) * 10.0).log10();
                let mut best = (f64::INFINITY, 1.0);
                let mut t = -40.0;
                while t <= top {
                    let tau = 10f64.powf(t);
                    let b = beta_of(tau);
                    let j = b.sqrt() * sigma_median + gamma_of(tau, b);
                    if j < best.0 {
                        best = (j, tau);
                    }
                    t += 0.01;
                }
                best.1
            }
        };
        let beta = beta_of(tau);
        let gamma_n = gamma_of(tau, beta);
        let out = Theorem1Output {
            beta,
            gamma: gamma_n * s_y,
            tau,
            lipschitz_mean: l_mu,
            lipschitz_f: l_f,
            omega_sigma: omega(tau),
            lipschitz_sigma: omega(tau) / tau,
            sigma_median,
        };
        for (what, value) in [
            ("Theorem 1 beta", out.beta),
            ("Theorem 1 gamma", out.gamma),
            ("Theorem 1 L_mu", out.lipschitz_mean),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(BoundError::NonFinite { what, value });
            }
        }
        outputs.push(out);
    }
    let lower = (0..d)
        .map(|j| norm.shift[j] + norm.scale[j] * lo[j])
        .collect();
    let upper = (0..d)
        .map(|j| norm.shift[j] + norm.scale[j] * hi[j])
        .collect();
    Ok(Theorem1Parts {
        outputs,
        lower,
        upper,
    })
}

#[cfg(test)]
mod tests {
    use super::log_covering;

    /// The covering number of a box by balls of radius τ: a unit square
    /// (d = 2) needs ⌈√2/(2τ)⌉² cubes of edge 2τ/√2 = √2·τ.
    #[test]
    fn covering_number_of_a_square() {
        let tau = 0.1;
        let k = (2f64.sqrt() / (2.0 * tau)).ceil();
        assert!((log_covering(&[1.0, 1.0], tau) - 2.0 * k.ln()).abs() < 1e-12);
        // a flat dimension needs one cube, and a huge ratio does not overflow
        assert_eq!(log_covering(&[0.0, 0.0], 1e-3), 0.0);
        assert!(log_covering(&[1.0; 12], 1e-300).is_finite());
    }
}
