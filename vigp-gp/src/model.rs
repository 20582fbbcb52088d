//! The trained multi-output GP: its types, the checks of its arguments and
//! the accessors the error bound needs. Training is in `train`, prediction
//! in `predict`, online updates in `update`.

use std::sync::Arc;

use faer::Side;
use vigp_core::gp as core_gp;

use crate::error::GpError;
use crate::kernel::Hyperparameters;
use crate::kernel::original_units;
use crate::mean::Resolved;
use crate::normalise::InputNormaliser;
use crate::packed;
use crate::packed::lower_inverse;
use crate::variance_thread::Helper;

/// How [`Gp::predict_into`] computes the posterior variance of an exact GP
/// (both give σ_f² − kᵀ(K + σ²I)⁻¹k; the mean is not affected).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VarianceMode {
    /// ‖L⁻¹k‖² with L⁻¹ computed once when the model is built (N³/6 flops
    /// and N²/2 more numbers per output): a product of contiguous rows,
    /// the faster path (see `docs/gp.md`, "The variance").
    #[default]
    Inverse,
    /// ‖L⁻¹k‖² by forward substitution with the Cholesky factor L (blocked
    /// by four rows): no extra memory.
    Solve,
}

/// The factorised posterior of one output.
#[derive(Clone)]
pub(crate) enum Posterior {
    /// Exact GP: L = chol(K + (σ_n² + jitter)·I) (packed rows), optionally
    /// L⁻¹ (packed rows), and L⁻¹r (for appending samples).
    Exact {
        l: Vec<f64>,
        linv: Option<Arc<Vec<f64>>>,
        fwd: Vec<f64>,
    },
    /// Sparse GP (see `sparse`): chol(K_uu + ε·σ_f²·I), chol(B), A·r.
    Sparse {
        lu: Vec<f64>,
        lb: Vec<f64>,
        ay: Vec<f64>,
    },
}

/// A trained exact Gaussian process with p independent outputs on d inputs.
///
/// Each output has its own ARD squared-exponential kernel, signal and noise
/// variance, fitted to the residual y − m(x) of a shared [`PriorMean`](crate::PriorMean) m.
/// Inputs may be standardised and residuals scaled (see [`TrainOptions`](crate::TrainOptions));
/// all methods take and return *original* units unless their name says
/// otherwise.
///
/// Cost: training is O(N³) per likelihood evaluation (Cholesky and inverse
/// of the N×N Gram matrix), memory O(N²) per output. Prediction is O(N·d)
/// per output for the mean and O(N²) more for the variance (a triangular
/// solve with the stored Cholesky factor).
///
/// ```
/// use vigp_gp::{Gp, TrainOptions};
/// // y = sin(x) on 20 points, one input, one output.
/// let x: Vec<f64> = (0..20).map(|i| i as f64 * 0.3).collect();
/// let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
/// let (gp, report) = Gp::train(&x, 1, &y, 1, &TrainOptions::default())?;
/// let mut ws = gp.workspace();
/// let (mut m, mut v) = ([0.0], [0.0]);
/// gp.predict_into(&[1.0], &mut m, &mut v, &mut ws)?;
/// assert!((m[0] - 1f64.sin()).abs() < 1e-3 && v[0] >= 0.0);
/// assert!(report.outputs[0].log_marginal_likelihood.is_finite());
/// # Ok::<(), vigp_gp::GpError>(())
/// ```
#[derive(Clone)]
pub struct Gp {
    pub(crate) n: usize,
    pub(crate) d: usize,
    pub(crate) p: usize,
    pub(crate) inputs: Vec<f64>,
    pub(crate) targets: Vec<f64>,
    pub(crate) prior_at_inputs: Vec<f64>,
    pub(crate) input_norm: InputNormaliser,
    pub(crate) mean: Resolved,
    pub(crate) outputs: Vec<OutputGp>,
    /// Inducing inputs of a sparse GP (normalised units, row-major M × d).
    pub(crate) inducing: Option<Vec<f64>>,
    pub(crate) variance_mode: VarianceMode,
    pub(crate) parallel_variance: bool,
    /// The variance helper thread of [`Gp::set_parallel_variance`] (shared
    /// by clones; `None` when off or when no thread could be started).
    pub(crate) helper: Option<Arc<Helper>>,
}

impl core::fmt::Debug for Gp {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Gp")
            .field("n", &self.n)
            .field("input_dim", &self.d)
            .field("output_dim", &self.p)
            .field(
                "hyperparameters",
                &self.outputs.iter().map(|o| &o.hp).collect::<Vec<_>>(),
            )
            .finish_non_exhaustive()
    }
}

/// One output's GP inside a [`Gp`]: hyperparameters, Cholesky factor and
/// weights α, with the quantities the uniform error bound (`vigp::bound`,
/// Lederer et al. 2019) needs.
///
/// Units: "normalised" means after input standardisation x_n = (x − μ)/s_x
/// and residual scaling r_n = (y − m(x))/s_y; "original" means the units of
/// the data. The kernel in original units is
/// k(x, x') = s_y²·σ_f²·exp(−½ Σ_j (x_j − x'_j)² / (s_x,j·ℓ_j)²), which is
/// exactly the normalised kernel scaled by s_y².
#[derive(Clone)]
pub struct OutputGp {
    pub(crate) hp: Hyperparameters,
    pub(crate) output_scale: f64,
    pub(crate) input_scale: Vec<f64>,
    /// Scaled training inputs x_n/ℓ (exact) or inducing inputs z/ℓ
    /// (sparse), **column-major** d × N (or d × M): the layout of the shared
    /// prediction kernels in `vigp_core::gp`.
    pub(crate) xs_cols: Vec<f64>,
    pub(crate) post: Posterior,
    /// Weights of the predictive mean: α (N, exact) or u (M, sparse).
    pub(crate) alpha: Vec<f64>,
    pub(crate) residual: Vec<f64>,
    pub(crate) jitter: f64,
    pub(crate) lml: f64,
}

/// The shared kernels only fail on inconsistent lengths, which the model's
/// own invariants exclude; reported as an invalid model all the same.
pub(crate) fn core_error(e: core_gp::GpError) -> GpError {
    GpError::InvalidModel(e.to_string())
}

pub(crate) fn check_finite(what: &'static str, v: &[f64]) -> Result<(), GpError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(GpError::NonFinite { what, index }),
        None => Ok(()),
    }
}

pub(crate) fn check_dims(
    inputs: &[f64],
    d: usize,
    targets: &[f64],
    p: usize,
) -> Result<usize, GpError> {
    if d == 0 {
        return Err(GpError::Empty("input dimension is 0"));
    }
    if p == 0 {
        return Err(GpError::Empty("output dimension is 0"));
    }
    if inputs.is_empty() {
        return Err(GpError::Empty("no training samples"));
    }
    if inputs.len() % d != 0 {
        return Err(GpError::DimensionMismatch {
            what: "inputs (length must be a multiple of the input dimension)",
            expected: inputs.len().div_ceil(d) * d,
            got: inputs.len(),
        });
    }
    let n = inputs.len() / d;
    // A corrupt model file can state any output dimension: N·p must not
    // overflow (it cannot equal a real length then).
    let Some(np) = n.checked_mul(p) else {
        return Err(GpError::DimensionMismatch {
            what: "targets (N × output dimension overflows usize)",
            expected: usize::MAX,
            got: targets.len(),
        });
    };
    if targets.len() != np {
        return Err(GpError::DimensionMismatch {
            what: "targets (N × output dimension)",
            expected: np,
            got: targets.len(),
        });
    }
    check_finite("inputs", inputs)?;
    check_finite("targets", targets)?;
    Ok(n)
}

impl Gp {
    /// Number of training samples N.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Input dimension d.
    pub fn input_dim(&self) -> usize {
        self.d
    }

    /// Output dimension p (the number of independent GPs).
    pub fn output_dim(&self) -> usize {
        self.p
    }

    /// Training inputs, original units, row-major N × d.
    pub fn inputs(&self) -> &[f64] {
        &self.inputs
    }

    /// Training targets, original units, row-major N × p.
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// The prior mean evaluated at the training inputs, row-major N × p.
    pub fn prior_mean_at_inputs(&self) -> &[f64] {
        &self.prior_at_inputs
    }

    /// The input standardisation (identity if it was off).
    pub fn input_normaliser(&self) -> &InputNormaliser {
        &self.input_norm
    }

    /// The GP of output `j` (panics if `j >= output_dim()`, like slice indexing).
    pub fn output(&self, j: usize) -> &OutputGp {
        &self.outputs[j]
    }

    /// All outputs' GPs.
    pub fn outputs(&self) -> &[OutputGp] {
        &self.outputs
    }

    /// Per output √(σ_n² + jitter) in the targets' units: the noise part
    /// of a predictive standard deviation (the error bounds' scales).
    pub fn noise_std(&self) -> Vec<f64> {
        self.outputs
            .iter()
            .map(|o| o.regularisation_normalised().sqrt() * o.output_scale())
            .collect()
    }

    /// How the variance of an exact GP is computed (default
    /// [`VarianceMode::Inverse`]).
    pub fn variance_mode(&self) -> VarianceMode {
        self.variance_mode
    }

    /// Switches the variance path of an exact GP: `Inverse` computes L⁻¹
    /// once (O(N³/6) per output, N²/2 numbers of memory), `Solve` drops it.
    /// No effect on a sparse GP (whose variance always solves with its two
    /// M × M factors). Means are unchanged bit for bit.
    pub fn set_variance_mode(&mut self, mode: VarianceMode) {
        self.variance_mode = mode;
        for o in &mut self.outputs {
            if let Posterior::Exact { l, linv, .. } = &mut o.post {
                match mode {
                    VarianceMode::Solve => *linv = None,
                    VarianceMode::Inverse => {
                        if linv.is_none() {
                            let n = o.alpha.len();
                            *linv = Some(Arc::new(lower_inverse(&packed::unpack(l, n))));
                        }
                    }
                }
            }
        }
    }

    /// Whether [`predict_into`](Self::predict_into) (and so the learned
    /// step with its bound) computes some outputs' variances on a helper
    /// thread (default `false`). It applies to an exact GP with
    /// [`VarianceMode::Inverse`], p ≥ 2 outputs and N ≥
    /// [`PARALLEL_VARIANCE_MIN_N`](crate::PARALLEL_VARIANCE_MIN_N): the variance streams each output's N²/2
    /// stored numbers, and on two cores two outputs stream at once.
    ///
    /// Switching it on starts one thread for this model (shared by its
    /// clones; one caller at a time, others take the sequential path). The
    /// thread busy-waits for the next prediction for 200 µs after each one,
    /// then parks: while predictions follow each other faster than that (a
    /// control loop, a rollout with bounds) the hand-off takes well under a
    /// microsecond, but the helper keeps a core busy; after a pause the
    /// first prediction pays for waking it (tens of µs). Measured on 2 cores
    /// (`cargo bench --bench learned`, N = 512, p = 2): see `docs/gp.md`,
    /// "Prediction and the learned step". The results equal the sequential
    /// path bit for bit, and after the first call (which sizes the buffers)
    /// a prediction allocates nothing. Leave it off in code that already
    /// runs one task per core. Switching it off stops the thread once no
    /// clone uses it. A workspace made before a switch stays valid (the
    /// first call after it may allocate the per-output buffers).
    pub fn set_parallel_variance(&mut self, on: bool) {
        self.parallel_variance = on;
        if !on {
            self.helper = None;
        } else if self.helper.is_none() {
            self.helper = Helper::spawn().map(Arc::new);
        }
    }

    /// Whether the parallel variance is allowed (see
    /// [`set_parallel_variance`](Self::set_parallel_variance)).
    pub fn parallel_variance(&self) -> bool {
        self.parallel_variance
    }

    /// `true` for a sparse (SGPR) model.
    pub fn is_sparse(&self) -> bool {
        self.inducing.is_some()
    }

    /// Points the posterior is written in (the length of each output's
    /// weights): the N training points of an exact GP, the M inducing
    /// points of a sparse one.
    pub fn posterior_points(&self) -> usize {
        self.outputs
            .first()
            .map_or(self.n, |o| o.alpha_normalised().len())
    }

    /// Inducing inputs of a sparse GP in original units (row-major M × d),
    /// `None` for an exact GP.
    pub fn inducing_points(&self) -> Option<Vec<f64>> {
        self.inducing.as_ref().map(|z| {
            let mut out = z.clone();
            for row in out.chunks_exact_mut(self.d) {
                for ((v, m), s) in row
                    .iter_mut()
                    .zip(&self.input_norm.shift)
                    .zip(&self.input_norm.scale)
                {
                    *v = *v * s + m;
                }
            }
            out
        })
    }

    /// Hyperparameters of every output in original units, for
    /// [`TrainOptions::warm_start`](crate::TrainOptions::warm_start) of the next training run (e.g. after
    /// more samples arrived).
    pub fn warm_start(&self) -> Vec<Hyperparameters> {
        self.outputs
            .iter()
            .map(|o| o.hyperparameters_original())
            .collect()
    }
}

impl OutputGp {
    /// Hyperparameters in normalised units (what the optimiser sees).
    pub fn hyperparameters(&self) -> &Hyperparameters {
        &self.hp
    }

    /// Hyperparameters in original units: ℓ_j·s_x,j, σ_f²·s_y², σ_n²·s_y².
    pub fn hyperparameters_original(&self) -> Hyperparameters {
        original_units(&self.hp, &self.input_scale, self.output_scale)
    }

    /// The output scale s_y (1 if output normalisation was off).
    pub fn output_scale(&self) -> f64 {
        self.output_scale
    }

    /// Number of training samples N.
    pub fn n(&self) -> usize {
        self.residual.len()
    }

    /// `true` for an output of a sparse (SGPR) model.
    pub fn is_sparse(&self) -> bool {
        matches!(self.post, Posterior::Sparse { .. })
    }

    /// Log marginal likelihood of the normalised residuals at the fitted
    /// hyperparameters. In original units it is this minus N·ln s_y.
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.lml
    }

    /// Jitter added to the diagonal, normalised units (0 if none was needed).
    /// In original units: this times s_y².
    pub fn jitter(&self) -> f64 {
        self.jitter
    }

    /// α_n = (K_n + (σ_n² + jitter)·I)⁻¹ r_n in normalised units (for a
    /// sparse GP the M weights u of the inducing points instead:
    /// mean = k(x, Z)·u).
    pub fn alpha_normalised(&self) -> &[f64] {
        &self.alpha
    }

    /// α = (K + σ²I)⁻¹ (y − m(X)) in original units (= α_n / s_y), where
    /// K, σ² are in original units and the jitter counts as noise (sparse:
    /// the inducing-point weights u / s_y).
    pub fn alpha(&self) -> Vec<f64> {
        self.alpha.iter().map(|a| a / self.output_scale).collect()
    }

    /// Normalised residuals r_n = (y − m(X)) / s_y at the training inputs.
    pub fn residual_normalised(&self) -> &[f64] {
        &self.residual
    }

    /// ln det(K_n + (σ_n² + jitter)·I) of the normalised Gram matrix, from
    /// the stored Cholesky factor in O(N) (the RKHS error bound's
    /// information-gain term needs it). In original units add 2N·ln s_y.
    ///
    /// Errors: [`GpError::InvalidModel`] for a sparse GP (no N × N factor).
    pub fn log_det_normalised(&self) -> Result<f64, GpError> {
        let Posterior::Exact { l, .. } = &self.post else {
            return Err(GpError::InvalidModel(
                "log_det_normalised is defined for exact GPs only (this output is sparse)".into(),
            ));
        };
        // packed rows: row i starts at i(i+1)/2, its diagonal is entry i
        Ok(2.0
            * (0..self.n())
                .map(|i| l[i * (i + 1) / 2 + i].ln())
                .sum::<f64>())
    }

    /// The regularisation λ = σ_n² + jitter (normalised units) that the
    /// posterior mean and variance were computed with.
    pub fn regularisation_normalised(&self) -> f64 {
        self.hp.noise_variance + self.jitter
    }

    /// Cheap rigorous upper bound on ‖(K + σ²I)⁻¹‖₂ in original units:
    /// 1 / ((σ_n² + jitter)·s_y²), since K is positive semi-definite.
    pub fn inv_gram_norm_bound(&self) -> f64 {
        1.0 / ((self.hp.noise_variance + self.jitter) * self.output_scale * self.output_scale)
    }

    /// ‖(K + σ²I)⁻¹‖₂ = 1/λ_min in original units, from the eigenvalues of
    /// L·Lᵀ: O(N³) time and O(N²) memory per call.
    ///
    /// Errors: [`GpError::InvalidModel`] for a sparse GP, whose posterior
    /// has no N × N Gram matrix factor (the uniform error bound of
    /// `vigp::bound` is stated for exact GPs).
    pub fn inv_gram_norm(&self) -> Result<f64, GpError> {
        let Posterior::Exact { l, .. } = &self.post else {
            return Err(GpError::InvalidModel(
                "inv_gram_norm is defined for exact GPs only (this output is sparse)".into(),
            ));
        };
        let n = self.n();
        let l = packed::unpack(l, n);
        let a = &l * l.transpose();
        let ev = a
            .self_adjoint_eigenvalues(Side::Lower)
            .map_err(|e| GpError::InvalidModel(format!("eigenvalues failed: {e:?}")))?;
        let lmin = ev.iter().copied().fold(f64::INFINITY, f64::min);
        // Rounding can put λ_min slightly below its true value; never below
        // the noise, which bounds it from below in exact arithmetic.
        let lmin = lmin.max(self.hp.noise_variance + self.jitter);
        Ok(1.0 / (lmin * self.output_scale * self.output_scale))
    }

    /// Lipschitz constant of x ↦ k(x, x') in original input units (Euclidean
    /// norm): s_y²·σ_f²·e^{−1/2} / min_j(s_x,j·ℓ_j).
    pub fn kernel_lipschitz(&self) -> f64 {
        self.hyperparameters_original().kernel_lipschitz()
    }

    /// max_x k(x, x) = s_y²·σ_f², original units.
    pub fn kernel_max(&self) -> f64 {
        self.hp.signal_variance * self.output_scale * self.output_scale
    }
}
