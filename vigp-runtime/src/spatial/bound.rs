//! Conformal error bounds for learned spatial predictions
//! ([`LearnedSpatial`]): split conformal prediction on held-out windows, as
//! the planar [`ConformalSettings`] bound (`crate::bound`), with the error
//! of a pose measured per link.
//!
//! A window is a start state z₀ and the true configurations after it. The
//! learned model predicts the window (under its inputs, for a model trained
//! with them), and two errors are scored at every horizon k = 1…K:
//! * **translation**: max over links of ‖x̂_k − x_k‖ (centre of mass, m);
//! * **rotation**: max over links of the angle of q̂_k⁻¹ q_k (rad).
//!
//! Each is divided by its scale u_k = Δt·Σ_{j<k} Σ_{i≤j} ũ_i, where ũ_i is
//! the predictive standard deviation of step i's linear (translation) or
//! angular (rotation) velocities ([`Score`]): a velocity error made at step
//! i moves every later pose. The bound at a new prediction is q̂_k·u_k, with
//! q̂_k the ⌈(n+1)(1−δ)⌉-th smallest of the n calibration scores.
//!
//! **Guarantee.** If the new case (start and inputs) and the n calibration
//! windows are exchangeable, P(error_k ≤ q̂_k·u_k) ≥ 1 − δ for each k
//! ([`Tube::PerStep`]) or for all k at once ([`Tube::Simultaneous`]),
//! separately for the translation and the rotation bound, marginally over
//! the calibration and the new case. Windows cut with a stride shorter than
//! the horizon from one trajectory are dependent, and a start unlike every
//! calibration start is not covered by the guarantee. Such states are
//! flagged ([`BoundedSpatialState::outside`]) by the planar bound's region
//! test ([`Region`]: the box of the calibration starts' GP inputs, their
//! nearest-neighbour distances, their largest predictive standard
//! deviation). Unlike the planar bound there is no rigorous bound to fall
//! back to: a flagged state keeps its conformal bounds and its flag. The
//! one-step velocity quantiles are kept as well.
//!
//! Cost: calibration predicts every window once with the GP variance
//! (O(N²) per output and step, N training samples); a bounded prediction
//! is one such prediction.

use super::learned::{Configuration, LearnedSpatial, Trace, between};
use super::{LieStepper, Spatial, SpatialState};
use crate::bound::conformal::{
    RegionBuilder, Traced, calibrate_traced, position_scales, predictive_scale, quantile_index,
    score_scale,
};
use crate::bound::space::{BoundSpace, Planned};
use crate::bound::windows::{CalibrationOf, CalibrationWindow};
use crate::bound::{BoundError, BoundKind, ConformalSettings, Region, Score, Tube, check_delta};
use crate::learned::LearnError;
use nalgebra::SVector;
use serde::{Deserialize, Serialize};
use vigp_core::spatial::maximal::off_unit_sphere;

/// One held-out case: a start state and the true configurations after it.
#[derive(Clone, Debug, PartialEq)]
pub struct SpatialWindow<const B: usize> {
    /// z₀: configuration 0 and the velocities of the step to configuration
    /// 1 (from the data: (x₁ − x₀)/Δt and log(q₀⁻¹q₁)/Δt).
    pub start: SpatialState<B>,
    /// The true configurations 1, …, K (K ≥ 2). Configuration 1 follows
    /// from z₀ exactly; the one-step velocity targets come from
    /// configurations 1 and 2.
    pub configurations: Vec<Configuration<B>>,
}

impl<const B: usize> crate::bound::windows::sealed::Sealed for SpatialWindow<B> {}

/// Held-out calibration windows of equal length K for the spatial
/// conformal bound, with their inputs for a model trained under inputs.
///
/// The guarantee needs the calibration windows and the windows you predict
/// to be exchangeable (e.g. starts and input sequences drawn the same way).
/// Overlapping windows of one trajectory are dependent: prefer a stride of
/// at least the horizon.
pub type SpatialCalibration<const B: usize> = CalibrationOf<SpatialWindow<B>>;

impl<const B: usize> CalibrationWindow for SpatialWindow<B> {
    type Sample = Configuration<B>;

    fn cut(c: &[Configuration<B>], s: usize, horizon: usize, dt: f64) -> Self {
        SpatialWindow {
            start: between(&c[s], &c[s + 1], dt),
            configurations: c[s + 1..=s + horizon].to_vec(),
        }
    }

    fn steps(&self) -> usize {
        self.configurations.len()
    }

    fn is_finite(&self) -> bool {
        self.start.is_finite()
            && self.configurations.iter().all(|(x, q)| {
                x.iter().all(|x| x.iter().all(|v| v.is_finite()))
                    && q.iter().all(|q| q.coords.iter().all(|v| v.is_finite()))
            })
    }

    /// A start or a true orientation whose quaternion is not of unit norm
    /// ([`off_unit_sphere`]): the step refuses such a start, and a true
    /// orientation off the unit sphere would distort the rotation errors
    /// the bound is calibrated on.
    fn defect(&self) -> Option<&'static str> {
        self.start
            .q
            .iter()
            .chain(self.configurations.iter().flat_map(|(_, q)| q))
            .any(|q| off_unit_sphere(q.quaternion().norm()))
            .then_some(
                "a quaternion is not of unit norm (to 1e-9): normalise it, e.g. UnitQuaternion::new_normalize",
            )
    }
}

/// The calibrated constants of one part of the spatial bound
/// (translations or rotations).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseQuantiles {
    /// The normalisation (the one [`Score::Auto`] chose).
    pub score: Score,
    /// q̂ of the one-step scores ‖ν̂₁ − ν₁‖/ũ₀ of the linear (translation)
    /// or angular (rotation) velocities.
    pub one_step: f64,
    /// q̂_k of the k-step pose scores, k = 1…K (one value repeated for
    /// [`Tube::Simultaneous`]).
    pub per_step: Vec<f64>,
    /// Windows the quantiles were calibrated on.
    pub calibration_size: usize,
    /// Windows [`Score::Auto`] chose the normalisation on (0: no choice).
    pub selection_size: usize,
}

/// A calibrated conformal bound for a [`LearnedSpatial`] model
/// ([`LearnedIntegrator::error_bound`](crate::learned::LearnedIntegrator::error_bound)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpatialConformal {
    /// Miscoverage δ.
    pub delta: f64,
    /// Per-step or simultaneous tube.
    pub tube: Tube,
    /// Centres of mass: max over links of ‖x̂_k − x_k‖ (m).
    pub translation: PoseQuantiles,
    /// Orientations: max over links of the angle of q̂_k⁻¹q_k (rad).
    pub rotation: PoseQuantiles,
    /// Windows whose prediction failed (counted as misses: score +∞).
    pub failed: usize,
    /// The calibration horizon K: predictions of at most K steps.
    pub horizon: usize,
    /// Δt of the model the bound was calibrated for.
    pub dt: f64,
    /// Number of inputs the windows were predicted under (0: unforced).
    pub inputs: usize,
    /// Per GP output, √(σ_n² + jitter) in velocity units.
    pub noise_std: Vec<f64>,
    /// Where the calibration starts lie (their GP inputs: the encoded pose
    /// and velocities, then the first step's input), and the largest
    /// predictive standard deviation over all 6B velocity outputs there.
    pub region: Region,
}

/// A predicted state with its bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundedSpatialState<const B: usize> {
    /// The mean prediction z_k.
    pub state: SpatialState<B>,
    /// Every link's centre of mass lies within this distance (m) of its
    /// prediction, with probability ≥ 1 − δ (0 at k = 0; at k = 1 of the
    /// order of rounding, configuration 1 following from z₀ exactly).
    pub translation: f64,
    /// Every link's orientation lies within this angle (rad) of its
    /// prediction, with probability ≥ 1 − δ.
    pub rotation: f64,
    /// z_k lies outside the calibrated region ([`Region`]): the GP input
    /// of the step from it (the state, then the step's input) is outside
    /// the box of the calibration starts', far from all of them, or its
    /// predictive standard deviation exceeds theirs. At k = K, where no
    /// step follows, the state is tested with the last step's input and
    /// without the scale test. The guarantee is about predictions from
    /// starts like the calibration starts: when z₀ is flagged, it does not
    /// cover any bound of this prediction.
    pub outside: bool,
}

/// The linear-velocity (translation) and angular-velocity (rotation)
/// parts of a GP output vector ν = (v₀, ω₀, v₁, ω₁, …).
fn split<const B: usize>(nu: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (mut v, mut w) = (Vec::with_capacity(3 * B), Vec::with_capacity(3 * B));
    for i in 0..B {
        v.extend_from_slice(&nu[6 * i..6 * i + 3]);
        w.extend_from_slice(&nu[6 * i + 3..6 * i + 6]);
    }
    (v, w)
}

/// max over links of the centre-of-mass distance and of the rotation angle
/// between a state and a configuration.
fn pose_errors<const B: usize>(z: &SpatialState<B>, c: &Configuration<B>) -> (f64, f64) {
    (0..B).fold((0.0f64, 0.0f64), |(t, r), i| {
        (
            t.max((z.x[i] - c.0[i]).norm()),
            r.max(z.q[i].angle_to(&c.1[i])),
        )
    })
}

/// The conformal bound of the [module docs](self): `error_bound` takes
/// [`BoundKind::Conformal`] (its `fallback` does not apply here) and a
/// model trained without inputs, `error_bound_forced` a model from
/// [`LearnedSpatial::train_forced`] with windows that carry their inputs
/// ([`SpatialCalibration::new_forced`],
/// [`SpatialCalibration::from_trajectories_forced`]). Errors: δ ∉ (0, 1),
/// too few windows for δ (at least ⌈1/δ − 1⌉), windows with other inputs or
/// another Δt ([`BoundError::Mismatch`]), a model trained with other inputs
/// ([`BoundError::Inputs`]); a quantile that is not finite (too many failed
/// windows).
impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize> BoundSpace<N>
    for LieStepper<S, B, J, N, C>
{
    type Window = SpatialWindow<B>;
    type Bound = SpatialConformal;
    type Prediction = Vec<BoundedSpatialState<B>>;

    /// The model's inputs are checked with the calibration or the
    /// prediction, for both entry points.
    fn check_forced(_: &LearnedSpatial<S, B, J, N, C>, _: usize) -> Result<(), BoundError> {
        Ok(())
    }

    fn error_bound<const U: usize>(
        learned: &LearnedSpatial<S, B, J, N, C>,
        kind: &BoundKind,
        calibration: &SpatialCalibration<B>,
    ) -> Result<SpatialConformal, BoundError>
    where
        S: vigp_core::Inputs<U>,
    {
        let BoundKind::Conformal(settings) = kind else {
            return Err(BoundError::KindUnavailable {
                kind: kind.name(),
                space: "bodies in ℝ³ × SO(3)",
            });
        };
        learned.check_inputs(U)?;
        if U > 0 && calibration.input_count() != U {
            return Err(BoundError::Mismatch(
                "calibration windows carry other inputs",
            ));
        }
        let mut ws = learned.workspace();
        learned.calibrate(calibration, settings, U, |i, w| {
            if U == 0 {
                return learned.trace(&w.start, w.configurations.len(), &mut ws);
            }
            let us: Vec<SVector<f64, U>> = calibration
                .window_inputs(i)
                .expect("input count checked above");
            let up: SVector<f64, U> = calibration
                .window_previous_input(i)
                .expect("input count checked above");
            learned.trace_forced(&w.start, &up, &us, &mut ws)
        })
    }

    /// Entry k is z_k with the translation and rotation bounds at horizon
    /// k; z_K is tested against the region with the last step's inputs
    /// (u_prev and 0 without steps).
    fn predict<const U: usize>(
        learned: &LearnedSpatial<S, B, J, N, C>,
        z0: &SpatialState<B>,
        run: Planned<'_, U>,
        bound: &SpatialConformal,
    ) -> Result<Vec<BoundedSpatialState<B>>, BoundError>
    where
        S: vigp_core::Inputs<U>,
    {
        learned.check_bound(bound, U, run.steps)?;
        let mut ws = learned.workspace();
        if U == 0 {
            let trace = learned.trace(z0, run.steps, &mut ws)?;
            return learned.bounded(trace, bound, |_| (&[], &[]));
        }
        let trace = learned.trace_forced(z0, run.u_prev, run.inputs, &mut ws)?;
        let zero = SVector::<f64, U>::zeros();
        learned.bounded(trace, bound, |k| match run.inputs.len() {
            0 => (zero.as_slice(), zero.as_slice()),
            n => super::learned::step_inputs(run.u_prev, run.inputs, k.min(n - 1)),
        })
    }
}

impl<S: Spatial<B, J>, const B: usize, const J: usize, const N: usize, const C: usize>
    LearnedSpatial<S, B, J, N, C>
{
    fn check_bound(
        &self,
        bound: &SpatialConformal,
        inputs: usize,
        steps: usize,
    ) -> Result<(), BoundError> {
        self.check_inputs(inputs)?;
        if bound.inputs != inputs {
            return Err(BoundError::Mismatch(
                "the bound was calibrated under another number of inputs",
            ));
        }
        if let Some(bad) = bound
            .noise_std
            .iter()
            .find(|s| !(s.is_finite() && **s >= 0.0))
        {
            return Err(BoundError::NonFinite {
                what: "noise standard deviation",
                value: *bad,
            });
        }
        if bound.noise_std.len() != N || !same_dt(bound.dt, self.stepper().dt()) {
            return Err(BoundError::Mismatch(
                "the bound was calibrated for another model",
            ));
        }
        bound.region.check(self.gp().input_dim())?;
        // a bound edited or loaded from a file: its quantiles must cover
        // the steps asked for
        let calibrated = bound
            .horizon
            .min(bound.translation.per_step.len())
            .min(bound.rotation.per_step.len());
        if steps > calibrated {
            return Err(BoundError::HorizonTooLong {
                calibrated,
                requested: steps,
            });
        }
        Ok(())
    }

    /// Predicts every window with `trace(index, window)`, scores both
    /// parts and calibrates their quantiles and region (the starts' GP
    /// inputs with their first step's input).
    fn calibrate(
        &self,
        cal: &SpatialCalibration<B>,
        settings: &ConformalSettings,
        inputs: usize,
        mut trace: impl FnMut(usize, &SpatialWindow<B>) -> Result<Trace<B, N>, LearnError>,
    ) -> Result<SpatialConformal, BoundError> {
        check_delta(settings.delta)?;
        // fail early, before the predictions
        quantile_index(cal.len(), settings.delta)?;
        let dt = self.stepper().dt();
        if !same_dt(cal.dt(), dt) {
            return Err(BoundError::Mismatch(
                "calibration dt differs from the model's",
            ));
        }
        let noise_std = self.gp().noise_std();
        let (noise_v, noise_w) = split::<B>(&noise_std);
        let k_max = cal.horizon();
        let mut translation = Vec::with_capacity(cal.len());
        let mut rotation = Vec::with_capacity(cal.len());
        let d = self.gp().input_dim();
        let (mut input, mut input_n) = (vec![0.0; d], vec![0.0; d]);
        let mut region = RegionBuilder::new(d);
        for (i, w) in cal.windows().iter().enumerate() {
            self.gp_input(
                &w.start,
                cal.set.previous_input(i),
                cal.set.first_input(i),
                &mut input,
            );
            self.gp().input_normaliser().apply(&input, &mut input_n);
            region.start(&input, &input_n);
            let Ok(t) = trace(i, w) else {
                translation.push(None);
                rotation.push(None);
                continue;
            };
            region.scale(predictive_scale(t.std_devs[0].as_slice(), &noise_std));
            let c = &w.configurations;
            let SpatialState { v: v1, w: w1, .. } = between(&c[0], &c[1], dt);
            let e1v = (0..B)
                .map(|b| (t.states[1].v[b] - v1[b]).norm_squared())
                .sum::<f64>()
                .sqrt();
            let e1w = (0..B)
                .map(|b| (t.states[1].w[b] - w1[b]).norm_squared())
                .sum::<f64>()
                .sqrt();
            let (et, er): (Vec<f64>, Vec<f64>) = (1..=k_max)
                .map(|k| pose_errors(&t.states[k], &c[k - 1]))
                .unzip();
            let (sv, sw): (Vec<Vec<f64>>, Vec<Vec<f64>>) =
                t.std_devs.iter().map(|s| split::<B>(s.as_slice())).unzip();
            translation.push(Some(Traced {
                e1: e1v,
                e: et,
                std_devs: sv,
            }));
            rotation.push(Some(Traced {
                e1: e1w,
                e: er,
                std_devs: sw,
            }));
        }
        let failed = translation.iter().filter(|t| t.is_none()).count();
        let part = |traced: &[Option<Traced>], noise: &[f64]| {
            calibrate_traced(traced, settings, noise, dt, k_max).map(|c| PoseQuantiles {
                score: c.score,
                one_step: c.one_step,
                per_step: c.positions,
                calibration_size: c.calibration_size,
                selection_size: c.selection_size,
            })
        };
        Ok(SpatialConformal {
            delta: settings.delta,
            tube: settings.tube,
            translation: part(&translation, &noise_v)?,
            rotation: part(&rotation, &noise_w)?,
            failed,
            horizon: k_max,
            dt,
            inputs,
            noise_std,
            region: region.finish(cal.window_runs()),
        })
    }

    /// The bounds and region flags along a traced prediction; `input(k)`
    /// is the previous and the current input of the step from z_k (empty:
    /// unforced). A bound that
    /// is NaN, infinite or negative (the constants of an edited or loaded
    /// bound) is [`BoundError::NonFinite`].
    fn bounded<'u>(
        &self,
        trace: Trace<B, N>,
        bound: &SpatialConformal,
        input: impl Fn(usize) -> (&'u [f64], &'u [f64]),
    ) -> Result<Vec<BoundedSpatialState<B>>, BoundError> {
        let dt = self.stepper().dt();
        let (noise_v, noise_w) = split::<B>(&bound.noise_std);
        let (mut st, mut sr) = (Vec::new(), Vec::new());
        for sd in &trace.std_devs {
            let (v, w) = split::<B>(sd.as_slice());
            st.push(score_scale(bound.translation.score, &v, &noise_v));
            sr.push(score_scale(bound.rotation.score, &w, &noise_w));
        }
        let (ut, ur) = (position_scales(&st, dt), position_scales(&sr, dt));
        let d = self.gp().input_dim();
        let (mut x, mut xn) = (vec![0.0; d], vec![0.0; d]);
        trace
            .states
            .iter()
            .enumerate()
            .map(|(k, z)| {
                let at = |q: &PoseQuantiles, u: &[f64]| {
                    if k == 0 {
                        0.0
                    } else {
                        q.per_step[k - 1] * u[k - 1]
                    }
                };
                let (up, u) = input(k);
                self.gp_input(z, up, u, &mut x);
                self.gp().input_normaliser().apply(&x, &mut xn);
                let scale = trace
                    .std_devs
                    .get(k)
                    .map_or(0.0, |s| predictive_scale(s.as_slice(), &bound.noise_std));
                let state = BoundedSpatialState {
                    state: *z,
                    translation: at(&bound.translation, &ut),
                    rotation: at(&bound.rotation, &ur),
                    outside: bound.region.outside(&x, &xn, scale),
                };
                for (what, value) in [
                    ("translation bound", state.translation),
                    ("rotation bound", state.rotation),
                ] {
                    if !(value.is_finite() && value >= 0.0) {
                        return Err(BoundError::NonFinite { what, value });
                    }
                }
                Ok(state)
            })
            .collect()
    }
}

fn same_dt(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs()
}
