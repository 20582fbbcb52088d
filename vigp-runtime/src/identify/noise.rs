//! How the position noise of a log is treated by the regression
//! ([`Noise`]), and the noise of one transition's samples that the
//! bias-compensated estimate takes ([`SampleNoise`]).

use super::IdentifyError;

/// How the position noise of the log is treated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Noise {
    /// Ordinary (weighted) least squares: right for noise-free logs,
    /// biased under position noise.
    LeastSquares,
    /// Bias-compensated least squares for position noise of a known size
    /// ([`super::errors_in_variables`]): each row weighted by its own
    /// predicted noise, the noise's expected contribution to the normal
    /// equations removed. Needs no neighbouring samples, so it serves logs
    /// of isolated transitions, where instrumental variables cannot. The
    /// robust losses do not combine with it.
    ErrorsInVariables(SampleNoise),
    /// Instrumental variables from leave-out local polynomial fits (module
    /// docs): `half_window` samples on each side beyond the three left
    /// out, polynomial `degree`. In a log long enough for the window it
    /// uses the transitions with a full window only; a shorter log's
    /// transitions are their own instruments (least squares).
    InstrumentalVariables {
        /// Samples used on each side of the left-out triple.
        half_window: usize,
        /// Degree of the local polynomial (below 2·half_window).
        degree: usize,
    },
}

impl Noise {
    /// Instrumental variables with 8 samples each side and degree 4.
    pub const IV: Noise = Noise::InstrumentalVariables {
        half_window: 8,
        degree: 4,
    };
}

/// The position noise of one transition's three samples x_{k−1}, x_k,
/// x_{k+1}: their 3 × 3 covariance, the same for every coordinate, and
/// coordinates independent of one another.
///
/// ```
/// use vigp_runtime::identify::SampleNoise;
/// // A log of positions, each sample with independent noise of 1e-4 rad.
/// let log = SampleNoise::independent(1e-4);
/// assert_eq!(log.covariance[1][1], 1e-8);
/// // Transitions built from sampled states (q, v, v_next) with noise
/// // 1e-3 on each, 10 ms apart: x = (q, q + Δt·v, q + Δt·(v + v_next)).
/// let states = SampleNoise::from_states(1e-3, 1e-3, 0.01);
/// assert!((states.covariance[2][2] - (1e-6 + 2e-10)).abs() < 1e-20);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleNoise {
    /// Covariance between the three samples' noise (position units²).
    pub covariance: [[f64; 3]; 3],
}

impl SampleNoise {
    /// Independent noise of standard deviation `sigma` on every sample.
    pub fn independent(sigma: f64) -> Self {
        let v = sigma * sigma;
        SampleNoise {
            covariance: [[v, 0.0, 0.0], [0.0, v, 0.0], [0.0, 0.0, v]],
        }
    }

    /// The three positions of a sampled state (q, v, v_next):
    /// (q, q + Δt·v, q + Δt·(v + v_next)), with independent noise of
    /// standard deviation `sigma_q` on q and `sigma_v` on each velocity.
    /// The noise of q is common to the three positions; each velocity's
    /// enters the positions after it.
    pub fn from_states(sigma_q: f64, sigma_v: f64, dt: f64) -> Self {
        let (q, d) = (sigma_q * sigma_q, dt * dt * sigma_v * sigma_v);
        SampleNoise {
            covariance: [[q, q, q], [q, q + d, q + d], [q, q + d, q + 2.0 * d]],
        }
    }

    /// Finite, symmetric, positive semi-definite and not zero; otherwise
    /// [`IdentifyError::Options`].
    pub fn validate(&self) -> Result<(), IdentifyError> {
        let c = nalgebra::Matrix3::from_fn(|i, j| self.covariance[i][j]);
        let bad = |message: &str| {
            Err(IdentifyError::Options {
                message: format!("sample noise {:?}: {message}", self.covariance),
            })
        };
        if c.iter().any(|v| !v.is_finite()) {
            return bad("not finite");
        }
        if (c - c.transpose()).amax() > 1e-12 * c.amax() {
            return bad("not symmetric");
        }
        let eig = c.symmetric_eigenvalues();
        if eig.max() <= 0.0 {
            return bad("zero: least squares is right for noise-free logs");
        }
        if eig.min() < -1e-12 * eig.max() {
            return bad("not positive semi-definite");
        }
        Ok(())
    }

    /// The largest standard deviation of the three samples.
    pub(super) fn scale(&self) -> f64 {
        (0..3)
            .map(|i| self.covariance[i][i])
            .fold(0.0, f64::max)
            .sqrt()
    }
}
