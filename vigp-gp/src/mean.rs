//! Prior mean functions m(x): the GP models the residual y − m(x).

use std::fmt;
use std::sync::Arc;

/// A user prior mean: writes m(x) for all outputs into the second argument.
///
/// The input slice has length d (original input units), the output slice
/// length p (original output units). It must be deterministic; for the
/// allocation-free prediction path it must not allocate either.
pub type MeanFn = Arc<dyn Fn(&[f64], &mut [f64]) + Send + Sync>;

/// The prior mean of every output's GP.
///
/// * `Zero`: m(x) = 0.
/// * `Constant`: m(x) = the mean of that output's training targets (the
///   default, and what scikit-learn's `normalize_y=True` does).
/// * `Function(f)`: any function of the input, e.g. a nominal dynamics model,
///   so that the GP learns only what the model misses.
///
/// A function cannot be serialised: a saved model records its values at the
/// training inputs, and [`Gp::from_saved`](super::Gp::from_saved) takes the
/// function again and checks that it reproduces them.
#[derive(Clone, Default)]
pub enum PriorMean {
    /// m(x) = 0.
    Zero,
    /// m(x) = mean of the training targets, per output.
    #[default]
    Constant,
    /// m(x) = f(x), a user function of the input.
    Function(MeanFn),
}

impl PriorMean {
    /// Wraps a closure as a function mean.
    pub fn function<F>(f: F) -> Self
    where
        F: Fn(&[f64], &mut [f64]) + Send + Sync + 'static,
    {
        Self::Function(Arc::new(f))
    }
}

impl fmt::Debug for PriorMean {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Zero => f.write_str("Zero"),
            Self::Constant => f.write_str("Constant"),
            Self::Function(_) => f.write_str("Function(..)"),
        }
    }
}

/// The prior mean of a trained model (constant values resolved).
#[derive(Clone)]
pub(crate) enum Resolved {
    Zero,
    Constant(Vec<f64>),
    Function(MeanFn),
}

impl Resolved {
    #[inline]
    pub(crate) fn eval(&self, x: &[f64], out: &mut [f64]) {
        match self {
            Self::Zero => out.iter_mut().for_each(|v| *v = 0.0),
            Self::Constant(c) => out.copy_from_slice(c),
            Self::Function(f) => f(x, out),
        }
    }
}
