//! Gaussian-process regression: exact ARD GPs trained by marginal likelihood.
//!
//! * [`Gp::train`]: p independent GPs (one per output) with ARD
//!   squared-exponential kernels, fitted to y − m(x) for a [`PriorMean`] m,
//!   by bounded L-BFGS on the log marginal likelihood from seeded parallel
//!   restarts.
//! * [`Gp::predict_into`]: allocation-free single-point mean and variance;
//!   [`Gp::predict`] for batches.
//! * [`OutputGp`]: per-output accessors for the uniform error bound.
//! * [`SavedGp`]: serde form of a trained model.
//! * [`Gp::to_rust_source`]: the model as Rust source with `static` arrays
//!   for `no_std` prediction with `vigp_core::gp::ExportedGp` (bit-identical
//!   means: both use the kernels of `vigp_core::gp`).
//! * [`log_marginal_likelihood`]: the objective and its gradient on raw data;
//!   [`sparse_bound`] likewise for the sparse GP.
//! * [`TrainOptions::method`]: the exact GP or Titsias' sparse variational
//!   GP (SGPR) with M inducing points, behind the same [`Gp`] type (train,
//!   predict, save/load, export of the mean).
//! * [`Gp::add_samples`]: online updates at fixed hyperparameters
//!   (exact: O(N²) per sample; sparse: O(M²)); [`Gp::warm_start`] and
//!   [`TrainOptions::warm_start`] restart the optimiser from a previous model.
//! * [`optimise::minimise`]: the L-BFGS-B of the training, for any
//!   box-constrained objective with a gradient.
//!
//! Complexity: one likelihood evaluation costs O(N²d + N³) time and O(N²)
//! memory (N³/3 for the Cholesky, 2N³/3 for the inverse the gradient
//! needs; both blocked, zeroing entries far below rounding so that
//! subnormals stay out of the level-3 updates); a trained model predicts
//! the mean in O(Nd) and the variance in O(N²) per output and point.
//!
//! Numerical caveats: with tiny noise the Gram matrix is ill-conditioned
//! (condition number up to σ_f²·N/σ_n²); the Cholesky then escalates a
//! diagonal jitter (relative 1e-12, ×10 per step, at most 1e-3), reported per
//! output. Variances are clamped at 0 against round-off; for points close to
//! the data with tiny noise they carry absolute errors of order
//! ε·cond(K)·σ_f². See `docs/gp.md` for the method notes and benchmarks.

/// A [`pulp::WithSimd`] operation: a value of a local struct `Op` whose
/// fields are the locals `$field` (by those names, of types `$ty` with
/// lifetime `$lt`), and whose `with_simd` binds them again by the same
/// names and evaluates `$body` to an `$out`. A struct, not a closure:
/// `with_simd` is always inlined into pulp's AVX2 function, a closure's
/// body is not reliably, and its intrinsics then become calls (measured
/// 30× slower).
macro_rules! simd_op {
    (<$lt:lifetime> { $($field:ident: $ty:ty),* $(,)? } -> $out:ty $body:block) => {{
        struct Op<$lt> {
            $($field: $ty,)*
        }
        impl pulp::WithSimd for Op<'_> {
            type Output = $out;
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
                let Op { $($field),* } = self;
                $body
            }
        }
        Op { $($field),* }
    }};
}

mod error;
mod export;
mod kernel;
mod lbfgs;
mod likelihood;
mod mean;
mod model;
mod normalise;
pub mod optimise;
mod options;
mod packed;
mod predict;
mod restarts;
mod rng;
mod save;
mod sparse;
mod train;
mod update;
mod variance_thread;

pub use error::GpError;
pub use export::{ExportOptions, ExportedArrays};
pub use kernel::Hyperparameters;
pub use mean::{MeanFn, PriorMean};
pub use model::{Gp, OutputGp, VarianceMode};
pub use normalise::InputNormaliser;
pub use options::{
    Bounds, Curvature, InducingInit, InducingReport, MAX_MEMORY, MAX_RESTARTS, Method,
    OutputReport, SCREEN_FROM, SPARSE_MIN_NOISE_VARIANCE, Screening, ScreeningReport,
    SparseOptions, TrainOptions, TrainReport,
};
pub use predict::{PARALLEL_VARIANCE_MIN_N, Prediction, Workspace};
pub use save::{SavedGp, SavedMean, SavedOutput};

/// The checks [`log_marginal_likelihood`] and [`sparse_bound`] share: the
/// data's dimensions and θ's length (d + 2) and finiteness. Returns the
/// number of points N and faer's parallelism for `parallel`.
fn check_objective(
    inputs: &[f64],
    input_dim: usize,
    targets: &[f64],
    log_params: &[f64],
    parallel: bool,
) -> Result<(usize, faer::Par), GpError> {
    let n = model::check_dims(inputs, input_dim, targets, 1)?;
    if log_params.len() != input_dim + 2 {
        return Err(GpError::DimensionMismatch {
            what: "log_params (d + 2)",
            expected: input_dim + 2,
            got: log_params.len(),
        });
    }
    model::check_finite("log_params", log_params)?;
    let par = if parallel {
        faer::Par::rayon(0)
    } else {
        faer::Par::Seq
    };
    Ok((n, par))
}

/// Log marginal likelihood and its gradient on data as given (no
/// normalisation, zero prior mean).
///
/// `inputs` is row-major N × d, `targets` has length N, `log_params` is
/// θ = (ln ℓ_1, …, ln ℓ_d, ln σ_f², ln σ_n²). Returns (value, ∂value/∂θ).
/// `parallel` lets faer use all rayon threads for the Cholesky and inverse.
/// If the Gram matrix is not numerically positive definite, jitter is added
/// (see the module docs) and the value is that of the jittered matrix.
///
/// ```
/// use vigp_gp::log_marginal_likelihood;
/// let (v, g) = log_marginal_likelihood(&[0.0, 1.0], 1, &[0.0, 0.5], &[0.0, 0.0, -2.0], false)?;
/// assert!(v.is_finite() && g.len() == 3);
/// # Ok::<(), vigp_gp::GpError>(())
/// ```
pub fn log_marginal_likelihood(
    inputs: &[f64],
    input_dim: usize,
    targets: &[f64],
    log_params: &[f64],
    parallel: bool,
) -> Result<(f64, Vec<f64>), GpError> {
    let (n, par) = check_objective(inputs, input_dim, targets, log_params, parallel)?;
    let e = likelihood::lml(inputs, n, input_dim, targets, log_params, true, par)?;
    Ok((e.value, e.gradient))
}

/// The sparse GP's evidence lower bound (Titsias 2009; see [`Method::Sparse`])
/// and its gradient on data as given (no normalisation, zero prior mean),
/// for inducing inputs `inducing` (row-major M × d, the units of `inputs`).
///
/// `log_params` is θ = (ln ℓ_1, …, ln ℓ_d, ln σ_f², ln σ_n²), as for
/// [`log_marginal_likelihood`]; K_uu carries the relative jitter 1e-10·σ_f²
/// (more if its Cholesky fails). With the inducing inputs equal to the
/// training inputs the bound equals the exact log marginal likelihood up to
/// that jitter. `parallel` lets faer and rayon use all threads.
///
/// ```
/// use vigp_gp::sparse_bound;
/// let x = [0.0, 0.5, 1.0, 1.5];
/// let (v, g) = sparse_bound(&x, 1, &[0.0, 0.4, 0.8, 1.0], &[0.2, 1.2], &[0.0, 0.0, -2.0], false)?;
/// assert!(v.is_finite() && g.len() == 3);
/// # Ok::<(), vigp_gp::GpError>(())
/// ```
pub fn sparse_bound(
    inputs: &[f64],
    input_dim: usize,
    targets: &[f64],
    inducing: &[f64],
    log_params: &[f64],
    parallel: bool,
) -> Result<(f64, Vec<f64>), GpError> {
    let (n, par) = check_objective(inputs, input_dim, targets, log_params, parallel)?;
    model::check_finite("inducing points", inducing)?;
    if inducing.is_empty() || inducing.len() % input_dim != 0 {
        return Err(GpError::DimensionMismatch {
            what: "inducing points (M × d, M ≥ 1)",
            expected: input_dim,
            got: inducing.len(),
        });
    }
    let mut ws = sparse::SparseWorkspace::new(inducing.len() / input_dim, n);
    let e = sparse::elbo_ws(
        &mut ws, inputs, inducing, input_dim, targets, log_params, true, par,
    )?;
    Ok((e.value, e.gradient))
}
