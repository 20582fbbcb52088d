//! One bound API over every configuration space: [`BoundSpace`] says what
//! a held-out window, a calibrated bound and a bounded prediction are in a
//! space, and the learned integrator of any such space takes the same four
//! calls, [`LearnedIntegrator::error_bound`] and
//! [`LearnedIntegrator::predict`] and their forced forms.
//!
//! | space | kinds | bound | prediction |
//! |---|---|---|---|
//! | minimal coordinates in ℝⁿ ([`Variational`](crate::Variational), `Learned`) | Theorem 1, RKHS, conformal | [`ErrorBound`](super::ErrorBound) | [`BoundedPrediction`](super::BoundedPrediction): velocity and position bounds per state |
//! | bodies in ℝ³ × SO(3) ([`LieStepper`](vigp_core::spatial::LieStepper), `LearnedSpatial`) | conformal | [`SpatialConformal`](crate::spatial::bound::SpatialConformal) | [`BoundedSpatialState`](crate::spatial::bound::BoundedSpatialState) per state: translation and rotation bounds |
//!
//! A kind a space does not have is [`BoundError::KindUnavailable`].
//!
//! Code written once for every space:
//!
//! ```
//! use vigp_runtime::bound::{BoundError, BoundKind, BoundSpace, CalibrationOf};
//! use vigp_runtime::learned::LearnedIntegrator;
//!
//! /// A conformal bound at δ = 0.05 on held-out windows, then a 20-step
//! /// prediction with it, for a learned model of any space.
//! fn predict_20<S: BoundSpace<N>, const N: usize>(
//!     learned: &LearnedIntegrator<S, N>,
//!     held_out: &CalibrationOf<S::Window>,
//!     z0: &S::State,
//! ) -> Result<S::Prediction, BoundError> {
//!     let bound = learned.error_bound(&BoundKind::conformal(0.05), held_out)?;
//!     learned.predict(z0, 20, &bound)
//! }
//! ```

use super::{BoundError, BoundKind, CalibrationOf, CalibrationWindow};
use crate::integrator::Integrator;
use crate::learned::{LearnedIntegrator, NominalStep};
use nalgebra::SVector;

/// A configuration space whose learned integrator has error bounds (module
/// docs). Implemented by each space's nominal integrator; users call the
/// methods of [`LearnedIntegrator`] instead.
pub trait BoundSpace<const N: usize>: NominalStep<N> + Sized {
    /// One held-out calibration case: a start and the truth after it.
    type Window: CalibrationWindow;
    /// A calibrated bound.
    type Bound;
    /// A prediction whose every state carries its bound.
    type Prediction;

    /// Whether a bound or prediction under `inputs` inputs fits `learned`
    /// at the forced entry points (`error_bound_forced`, `predict_forced`).
    fn check_forced(learned: &LearnedIntegrator<Self, N>, inputs: usize) -> Result<(), BoundError>;

    /// The bound of `kind` for predictions under `U` inputs (`U = 0`: the
    /// unforced entry point), calibrated on `calibration`.
    fn error_bound<const U: usize>(
        learned: &LearnedIntegrator<Self, N>,
        kind: &BoundKind,
        calibration: &CalibrationOf<Self::Window>,
    ) -> Result<Self::Bound, BoundError>
    where
        Self::Mechanism: vigp_core::Inputs<U>;

    /// `steps` learned steps from `z0` with their bounds: unforced when
    /// `U = 0`, else under `inputs` (one per step, `steps` of them) after
    /// `u_prev`.
    fn predict<const U: usize>(
        learned: &LearnedIntegrator<Self, N>,
        z0: &<Self as Integrator>::State,
        run: Planned<'_, U>,
        bound: &Self::Bound,
    ) -> Result<Self::Prediction, BoundError>
    where
        Self::Mechanism: vigp_core::Inputs<U>;
}

/// The steps of a bounded prediction and the inputs planned for them:
/// `steps` steps, under `inputs` after `u_prev` (both unused when `U = 0`).
#[derive(Clone, Copy, Debug)]
pub struct Planned<'a, const U: usize> {
    /// The number of steps (`inputs.len()` under inputs).
    pub steps: usize,
    /// The input that produced the start's velocity.
    pub u_prev: &'a SVector<f64, U>,
    /// One input per step (empty when unforced).
    pub inputs: &'a [SVector<f64, U>],
}

impl<S: BoundSpace<N>, const N: usize> LearnedIntegrator<S, N> {
    /// The error bound of this trained model, calibrated on `calibration`
    /// (held-out windows of the space; required by the conformal kind).
    ///
    /// * Minimal coordinates: every [`BoundKind`]; see
    ///   [`crate::bound`] for the three kinds, their guarantees and costs,
    ///   and the errors (invalid settings, too few or malformed windows,
    ///   windows with another Δt, a failed step at a sample state, a
    ///   non-finite constant, a rigorous kind of a sparse GP). A model
    ///   trained with inputs is sampled under u = 0 here, the step
    ///   [`LearnedIntegrator::predict`] takes; for predictions under inputs
    ///   use [`LearnedIntegrator::error_bound_forced`].
    /// * Bodies in ℝ³ × SO(3): the conformal kind
    ///   ([`crate::spatial::bound`]: translation and rotation bounds; its
    ///   `fallback` does not apply), for a model trained without inputs;
    ///   another kind is [`BoundError::KindUnavailable`].
    pub fn error_bound(
        &self,
        kind: &BoundKind,
        calibration: &CalibrationOf<S::Window>,
    ) -> Result<S::Bound, BoundError> {
        S::error_bound::<0>(self, kind, calibration)
    }

    /// [`LearnedIntegrator::error_bound`] for predictions under inputs
    /// ([`LearnedIntegrator::predict_forced`]) of a model trained with
    /// them: the conformal kind predicts each calibration window under its
    /// own inputs (windows built with `from_trajectories_forced` or
    /// `new_forced`); in minimal coordinates the rigorous kinds estimate
    /// their constants at the training inputs and the calibration starts,
    /// each state with its input.
    ///
    /// Errors: those of `error_bound`; `U` other than the model's inputs,
    /// or calibration windows without (or with other) inputs. A `U` other
    /// than the mechanism's number of actuated joints does not compile.
    pub fn error_bound_forced<const U: usize>(
        &self,
        kind: &BoundKind,
        calibration: &CalibrationOf<S::Window>,
    ) -> Result<S::Bound, BoundError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        S::check_forced(self, U)?;
        S::error_bound::<U>(self, kind, calibration)
    }

    /// A `steps`-step prediction from `z0` (e.g. 20 steps for MPC) in
    /// which every state carries its bound (`bound` from
    /// [`LearnedIntegrator::error_bound`]).
    ///
    /// * Minimal coordinates: a [`BoundedPrediction`](super::BoundedPrediction),
    ///   the one-step velocity bound of each step and the position bound of
    ///   each state; the rigorous kinds propagate the one-step bounds with
    ///   the learned step's exact Jacobian norms. A model trained with
    ///   inputs predicts under u = 0 here.
    /// * Bodies in ℝ³ × SO(3): entry k is z_k with the translation and
    ///   rotation bounds at horizon k
    ///   ([`BoundedSpatialState`](crate::spatial::bound::BoundedSpatialState)).
    ///
    /// Errors: a bound made for another model, more steps than a conformal
    /// bound was calibrated for ([`BoundError::HorizonTooLong`]), a failed
    /// step, a non-finite bound.
    pub fn predict(
        &self,
        z0: &S::State,
        steps: usize,
        bound: &S::Bound,
    ) -> Result<S::Prediction, BoundError> {
        let run = Planned {
            steps,
            u_prev: &SVector::<f64, 0>::zeros(),
            inputs: &[],
        };
        S::predict::<0>(self, z0, run, bound)
    }

    /// [`LearnedIntegrator::predict`] under planned inputs, for a model
    /// trained with them and a bound from
    /// [`LearnedIntegrator::error_bound_forced`]: `inputs.len()` steps, step
    /// k from the predicted z_k under `inputs[k]` after `inputs[k − 1]`, the
    /// first after `u_prev` (the input that produced z₀'s velocity;
    /// [`crate::learned`], "Under inputs"). The bounds are on the distance
    /// to the true trajectory under the same inputs.
    ///
    /// Errors: those of `predict`; `U` other than the model's inputs, a
    /// bound calibrated under other inputs, a NaN or ∞ input.
    pub fn predict_forced<const U: usize>(
        &self,
        z0: &S::State,
        u_prev: &SVector<f64, U>,
        inputs: &[SVector<f64, U>],
        bound: &S::Bound,
    ) -> Result<S::Prediction, BoundError>
    where
        S::Mechanism: vigp_core::Inputs<U>,
    {
        S::check_forced(self, U)?;
        let run = Planned {
            steps: inputs.len(),
            u_prev,
            inputs,
        };
        S::predict::<U>(self, z0, run, bound)
    }
}
