//! Typed errors of the GP engine.

use thiserror::Error;

/// Everything that can go wrong when building, training, predicting with,
/// saving or loading a Gaussian process.
///
/// Bad user data is always reported through this type; the GP code never
/// panics on user input and never returns a silent NaN.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum GpError {
    /// The training set has no samples, or a dimension is zero.
    #[error("empty data: {0}")]
    Empty(&'static str),
    /// Array lengths do not agree with the stated dimensions.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    DimensionMismatch {
        /// Which array or argument.
        what: &'static str,
        /// The expected length.
        expected: usize,
        /// The length that was passed.
        got: usize,
    },
    /// A NaN or infinity was found in data or parameters.
    #[error("non-finite value in {what} at index {index}")]
    NonFinite {
        /// Which array (inputs, targets, prior mean, …).
        what: &'static str,
        /// Flat index of the first offending entry.
        index: usize,
    },
    /// A hyperparameter or bound is not strictly positive (or a bound is inverted).
    #[error("invalid hyperparameter {what}: {value}")]
    InvalidHyperparameter {
        /// Which hyperparameter or bound.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// Training options that cannot work: a tolerance that is NaN or
    /// negative, restarts beyond `MAX_RESTARTS`, an optimiser memory
    /// outside 1..=`MAX_MEMORY`, a screening subset below 2 samples or
    /// with a sparse GP, a negative sparse noise floor, candidates with a
    /// sparse GP or beside a warm start.
    #[error("invalid training options: {0}")]
    InvalidOptions(&'static str),
    /// The kernel matrix stayed non positive definite even after the
    /// maximum jitter was added to its diagonal.
    #[error("kernel matrix not positive definite even with jitter {jitter:e}")]
    NotPositiveDefinite {
        /// The largest jitter tried (in normalised units).
        jitter: f64,
    },
    /// Every optimiser start failed (the error of the first one is attached).
    #[error("hyperparameter optimisation failed for output {output}: {reason}")]
    OptimiserFailed {
        /// The output whose GP could not be trained.
        output: usize,
        /// Why the last start failed.
        reason: String,
    },
    /// A function prior mean is needed (the model was saved with one) but none was given,
    /// or one was given to a model that was not trained with it.
    #[error("prior mean mismatch: {0}")]
    PriorMean(String),
    /// A saved model could not be parsed or is internally inconsistent.
    #[error("invalid saved model: {0}")]
    InvalidModel(String),
    /// A model or export options that cannot be written as Rust source
    /// (a function prior mean, an invalid item name or path).
    #[error("cannot export: {0}")]
    Export(String),
}
