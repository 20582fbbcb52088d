//! Split conformal prediction on held-out data (Vovk et al. 2005; Lei et
//! al. 2018): a bound with a finite-sample guarantee that needs no model
//! assumption, only exchangeability of the calibration and test cases.
//!
//! Scores on n held-out windows (start z₀ and the true positions after it):
//! * one step: s = ‖v̂₁ − v₁‖ / u₀ with u₀ = √(Σ_i σ_i(z₀)² + σ_n,i²), the
//!   GP's predictive standard deviation (its latent σ plus the fitted noise,
//!   which keeps u > 0);
//! * k steps: s_k = ‖q̂_k − q_k‖ / u_k with u_k = Δt·Σ_{j<k} Σ_{i≤j} ũ_i
//!   along the predicted trajectory (a velocity error made at step i moves
//!   every later position: the double sum is that accumulation).
//!
//! The bound is q̂·u at a new case, where q̂ is the ⌈(n+1)(1−δ)⌉-th smallest
//! score. If the new case and the n calibration cases are exchangeable,
//! P(error ≤ q̂·u) ≥ 1 − δ (marginally over both), and ≤ 1 − δ + 1/(n+1) when
//! the scores have no ties.

use super::windows::{CalibrationOf, CalibrationWindow, Windows};
use super::{BoundError, ConformalSettings, Score, Tube, check_delta};
use crate::integrator::Integrator;
use crate::learned::{Learned, Transition};
use crate::mechanism::{Mechanism, State};
use nalgebra::SVector;
use serde::{Deserialize, Serialize};

/// One held-out case: a start state and the true positions after it.
#[derive(Clone, Debug, PartialEq)]
pub struct Window<const N: usize> {
    /// z₀ = (q₀, v₀) with the discrete velocity v₀ = (q₁ − q₀)/Δt.
    pub start: State<N>,
    /// The true positions q₁, …, q_K (K ≥ 2; q₁ = q₀ + Δt·v₀ for exact
    /// data). The one-step velocity target is v₁ = (q₂ − q₁)/Δt.
    pub positions: Vec<SVector<f64, N>>,
}

impl<const N: usize> crate::bound::windows::sealed::Sealed for Window<N> {}

/// Held-out calibration data for the conformal bound: windows of equal
/// length K, each a start state and the K true positions after it.
///
/// The guarantee needs the calibration windows and the windows you predict
/// to be exchangeable (e.g. drawn independently from the same distribution
/// of starts). Overlapping windows of one trajectory are dependent: the
/// coverage then holds only approximately; prefer one window per
/// trajectory, or a stride of at least the horizon.
///
/// Windows of an actuated mechanism carry the inputs their steps were
/// taken under ([`Calibration::new_forced`],
/// [`Calibration::from_trajectories_forced`]); they calibrate the bound of
/// predictions under inputs ([`Learned::error_bound_forced`]).
pub type Calibration<const N: usize> = CalibrationOf<Window<N>>;

impl<const N: usize> CalibrationWindow for Window<N> {
    type Sample = SVector<f64, N>;

    fn cut(p: &[SVector<f64, N>], s: usize, horizon: usize, dt: f64) -> Self {
        Window {
            start: State::from_positions(p[s], &p[s + 1], dt),
            positions: p[s + 1..=s + horizon].to_vec(),
        }
    }

    fn steps(&self) -> usize {
        self.positions.len()
    }

    fn is_finite(&self) -> bool {
        self.start.is_finite() && self.positions.iter().flatten().all(|x| x.is_finite())
    }
}

impl<const N: usize> Calibration<N> {
    /// No calibration data (enough for the rigorous kinds, which take their
    /// sample states from the training data).
    pub fn empty(dt: f64) -> Self {
        Self {
            set: Windows {
                dt,
                windows: Vec::new(),
                inputs: Vec::new(),
                previous: Vec::new(),
                input_count: 0,
                runs: Vec::new(),
            },
        }
    }

    /// One-step calibration cases from held-out transitions (K = 2:
    /// q₁ = q₀ + Δt·v₀, q₂ = q₁ + Δt·v_next). Enough for one-step bounds
    /// and for predictions of up to 2 steps.
    pub fn from_transitions(data: &[Transition<N>], dt: f64) -> Result<Self, BoundError> {
        let windows = data
            .iter()
            .map(|t| {
                let q1 = t.z.q + t.z.v * dt;
                Window {
                    start: t.z,
                    positions: vec![q1, q1 + t.v_next * dt],
                }
            })
            .collect();
        Self::new(dt, windows)
    }
}

/// The calibrated constants of a conformal bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConformalParts {
    /// The normalisation of the scores (the one [`Score::Auto`] chose).
    pub score: Score,
    /// Per-step or simultaneous K-step quantiles.
    pub tube: Tube,
    /// Number of windows the quantiles were calibrated on.
    pub calibration_size: usize,
    /// Number of windows [`Score::Auto`] chose the normalisation on (0 when
    /// it did not choose); they are not among the calibrated ones.
    pub selection_size: usize,
    /// Windows whose prediction failed (counted as misses: score +∞).
    pub failed: usize,
    /// q̂ of the one-step velocity scores.
    pub one_step_quantile: f64,
    /// q̂_k of the k-step position scores, k = 1…K (per step), or one value
    /// repeated K times (simultaneous).
    pub position_quantiles: Vec<f64>,
    /// Where the calibration starts lie: a state outside it is unlike
    /// every calibration case ([`super::Fallback`]). Saved as the five
    /// fields of [`Region`] beside the others.
    #[serde(flatten)]
    pub region: Region,
    /// Number of inputs the calibration windows were predicted under (0:
    /// unforced): the bound covers predictions under that many inputs
    /// only.
    #[serde(default)]
    pub inputs: usize,
}

/// The calibrated region of a conformal bound: where its calibration
/// starts lie, in the GP's inputs. A state is *outside* when its GP input
/// lies outside the box of the starts' inputs, or farther (in the GP's
/// normalised inputs) from every start than 99 % of the starts are from
/// their nearest start of another run, or when its predictive standard
/// deviation exceeds every start's. Such a case is unlike the calibration
/// cases, and the conformal guarantee does not apply to it. A heuristic
/// detector: about 1 % of new starts drawn like the calibration starts
/// are flagged by the distance test, and the box test flags about 2d/(n+1)
/// of them (d inputs, n starts); states late in a prediction, unlike any
/// start, are flagged more often.
///
/// Shared by the planar ([`ConformalParts`]) and the spatial
/// (`vigp::spatial::bound::SpatialConformal`) conformal bounds. Cost of a
/// test: O(n·d).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    /// The largest predictive standard deviation ũ at a calibration start
    /// (a start beyond it is unlike every calibration case).
    pub max_scale: f64,
    /// Lower corner of the box of the calibration starts' GP inputs
    /// (encoded, original units).
    pub input_lower: Vec<f64>,
    /// Upper corner of that box.
    pub input_upper: Vec<f64>,
    /// The calibration starts' GP inputs in the GP's normalised units
    /// (row-major n × d), for the nearest-neighbour test.
    pub starts_normalised: Vec<f64>,
    /// A start farther than this (normalised units) from every calibration
    /// start is outside: the 99 % conformal quantile of the calibration
    /// starts' leave-one-out nearest-neighbour distances.
    pub distance_threshold: f64,
}

/// Level of the nearest-neighbour distance threshold: about 1 % of cases
/// drawn like the calibration starts are flagged.
const DISTANCE_LEVEL: f64 = 0.01;

impl Region {
    /// Distance (normalised units) from `xn` to the nearest calibration
    /// start, skipping the indices `skip` is true of.
    fn nearest(&self, xn: &[f64], skip: impl Fn(usize) -> bool) -> f64 {
        let d = xn.len();
        let mut best = f64::INFINITY;
        for (i, row) in self.starts_normalised.chunks_exact(d).enumerate() {
            if skip(i) {
                continue;
            }
            let mut s = 0.0;
            for (a, b) in row.iter().zip(xn) {
                s += (a - b) * (a - b);
                if s >= best {
                    break;
                }
            }
            best = best.min(s);
        }
        best.sqrt()
    }

    /// Whether the normalised GP input `xn` is farther from every
    /// calibration start than [`Region::distance_threshold`].
    fn far(&self, xn: &[f64]) -> bool {
        !self.starts_normalised.is_empty() && self.nearest(xn, |_| false) > self.distance_threshold
    }

    /// Checks that the region fits GP inputs of dimension `d` (a bound
    /// edited or loaded from a file): the box corners have d entries, the
    /// starts whole rows of d, and the thresholds are not NaN.
    pub(crate) fn check(&self, d: usize) -> Result<(), BoundError> {
        if self.input_lower.len() != d
            || self.input_upper.len() != d
            || self.starts_normalised.len().checked_rem(d) != Some(0)
        {
            return Err(BoundError::Mismatch("GP input dimension of the region"));
        }
        for (what, value) in [
            ("region scale", self.max_scale),
            ("region distance threshold", self.distance_threshold),
        ] {
            if value.is_nan() {
                return Err(BoundError::NonFinite { what, value });
            }
        }
        Ok(())
    }

    /// Whether a state with GP input `input` (`input_n` in the GP's
    /// normalised units) and predictive standard deviation `scale` lies
    /// outside the region (see [`Region`]); `scale = 0` skips the scale
    /// test. The inputs must have the calibration's dimension d.
    pub fn outside(&self, input: &[f64], input_n: &[f64], scale: f64) -> bool {
        scale > self.max_scale
            || input
                .iter()
                .zip(self.input_lower.iter().zip(&self.input_upper))
                .any(|(x, (lo, hi))| x < lo || x > hi)
            || self.far(input_n)
    }
}

/// Collects the calibration starts of a [`Region`]: their GP inputs (in
/// order), and the predictive scales of those whose prediction succeeded.
pub(crate) struct RegionBuilder {
    region: Region,
}

impl RegionBuilder {
    /// An empty region for d GP inputs.
    pub(crate) fn new(d: usize) -> Self {
        Self {
            region: Region {
                max_scale: 0.0,
                input_lower: vec![f64::INFINITY; d],
                input_upper: vec![f64::NEG_INFINITY; d],
                starts_normalised: Vec::new(),
                distance_threshold: f64::INFINITY,
            },
        }
    }

    /// One more start: its GP input and the same normalised.
    pub(crate) fn start(&mut self, input: &[f64], input_n: &[f64]) {
        let r = &mut self.region;
        for (j, x) in input.iter().enumerate() {
            r.input_lower[j] = r.input_lower[j].min(*x);
            r.input_upper[j] = r.input_upper[j].max(*x);
        }
        r.starts_normalised.extend_from_slice(input_n);
    }

    /// The predictive scale at a start whose prediction succeeded.
    pub(crate) fn scale(&mut self, scale: f64) {
        self.region.max_scale = self.region.max_scale.max(scale);
    }

    /// The region, with its distance threshold from the starts'
    /// leave-one-out nearest-neighbour distances (O(n²·d)): with n ≥ 99
    /// their 99 % quantile, else their maximum. `runs[i]` is the run start
    /// i was cut from. A new start comes from a new run, so each start's
    /// distance is to the starts of other runs: overlapping windows of one
    /// run (stride 1) lie next to each other, and their distances would set
    /// a threshold that flags nearly every new start. With a single run,
    /// to the other starts.
    pub(crate) fn finish(self, runs: &[usize]) -> Region {
        let mut region = self.region;
        let d = region.input_lower.len();
        let n = region.starts_normalised.len().checked_div(d).unwrap_or(0);
        let one_run = runs.iter().all(|r| *r == runs[0]);
        let mut nn: Vec<f64> = (0..n)
            .map(|i| {
                let xi = &region.starts_normalised[i * d..(i + 1) * d];
                if one_run {
                    region.nearest(xi, |j| j == i)
                } else {
                    region.nearest(xi, |j| runs[j] == runs[i])
                }
            })
            .collect();
        nn.sort_by(f64::total_cmp);
        let level = quantile_index(n, DISTANCE_LEVEL).unwrap_or(n);
        region.distance_threshold = nn
            .get(level.saturating_sub(1))
            .copied()
            .unwrap_or(f64::INFINITY);
        region
    }
}

/// The index ⌈(n+1)(1−δ)⌉ (1-based) of the conformal quantile, or an error
/// when n is too small for δ (n < 1/δ − 1 makes it n + 1).
pub(crate) fn quantile_index(n: usize, delta: f64) -> Result<usize, BoundError> {
    // a hair below (n+1)(1−δ) so that exact products (n = 19, δ = 0.05) are
    // not pushed up by rounding
    let k = ((n as f64 + 1.0) * (1.0 - delta) - 1e-9).ceil().max(1.0) as usize;
    if k > n {
        return Err(BoundError::TooFewCalibration {
            delta,
            needed: ((1.0 / delta) - 1.0 - 1e-9).ceil() as usize,
            got: n,
        });
    }
    Ok(k)
}

/// The conformal quantile of `scores` (consumed: sorted in place).
pub(crate) fn quantile(scores: &mut [f64], delta: f64) -> Result<f64, BoundError> {
    let k = quantile_index(scores.len(), delta)?;
    scores.sort_by(f64::total_cmp);
    let q = scores[k - 1];
    if !q.is_finite() {
        return Err(BoundError::NonFinite {
            what: "conformal quantile (too many calibration predictions failed)",
            value: q,
        });
    }
    Ok(q)
}

/// The predictive scale ũ = √(Σ σ_i² + σ_n,i²) of a state with latent
/// standard deviations `std_dev` and noise standard deviations `noise`.
pub(crate) fn predictive_scale(std_dev: &[f64], noise: &[f64]) -> f64 {
    std_dev
        .iter()
        .zip(noise)
        .map(|(s, n)| s * s + n * n)
        .sum::<f64>()
        .sqrt()
}

/// The scale a one-step score is divided by: the predictive standard
/// deviation ([`Score::GpStd`]), the latent one ([`Score::LatentStd`],
/// floored at 1e-6 of the noise so that it stays positive) or 1.
pub(crate) fn score_scale(score: Score, std_dev: &[f64], noise: &[f64]) -> f64 {
    match score {
        Score::LatentStd => {
            let floor = (1e-6 * noise.iter().fold(0.0f64, |m, n| m.max(*n))).max(f64::MIN_POSITIVE);
            std_dev.iter().map(|s| s * s).sum::<f64>().sqrt().max(floor)
        }
        // Auto is resolved before any score is computed; as a scale it is
        // the default normalisation
        Score::GpStd | Score::Auto => predictive_scale(std_dev, noise),
        Score::Absolute => 1.0,
    }
}

/// u_k = Δt·Σ_{j<k} Σ_{i≤j} ũ_i for k = 1…K from the scales ũ_0…ũ_{K−1}.
pub(crate) fn position_scales(scales: &[f64], dt: f64) -> Vec<f64> {
    let (mut inner, mut outer) = (0.0, 0.0);
    scales
        .iter()
        .map(|s| {
            inner += s;
            outer += dt * inner;
            outer
        })
        .collect()
}

/// What calibration keeps of one window's prediction (None: it failed).
pub(crate) struct Traced {
    /// One-step velocity error ‖v̂₁ − v₁‖.
    pub e1: f64,
    /// Position errors ‖q̂_k − q_k‖, k = 1…K.
    pub e: Vec<f64>,
    /// Per output latent standard deviations along the prediction (K × p).
    pub std_devs: Vec<Vec<f64>>,
}

/// The calibrated quantiles of traced windows.
pub(crate) struct Calibrated {
    /// The normalisation (the one [`Score::Auto`] chose).
    pub score: Score,
    /// q̂ of the one-step velocity scores.
    pub one_step: f64,
    /// q̂_k of the k-step position scores, k = 1…K.
    pub positions: Vec<f64>,
    /// Windows the quantiles were calibrated on.
    pub calibration_size: usize,
    /// Windows [`Score::Auto`] chose on (0: no choice made).
    pub selection_size: usize,
}

/// Quantiles of `traced` (K = `k_max` steps each) with `settings`:
/// [`Score::Auto`] chooses the normalisation on the first fifth of the
/// windows and calibrates it on the rest (independent of the choice), when
/// both parts are large enough for δ; else the default normalisation on
/// all of them.
pub(crate) fn calibrate_traced(
    traced: &[Option<Traced>],
    settings: &ConformalSettings,
    noise: &[f64],
    dt: f64,
    k_max: usize,
) -> Result<Calibrated, BoundError> {
    let n = traced.len();
    let (score, calibrate_on, selection_size) = match settings.score {
        Score::Auto => {
            let n_select = n / 5;
            let enough = |m: usize| quantile_index(m, settings.delta).is_ok();
            if enough(n_select) && enough(n - n_select) {
                let choice = select_score(&traced[..n_select], settings, noise, dt, k_max)
                    .unwrap_or(Score::GpStd);
                (choice, &traced[n_select..], n_select)
            } else {
                (Score::GpStd, traced, 0)
            }
        }
        s => (s, traced, 0),
    };
    let (one_step, positions) = quantiles(calibrate_on, score, settings, noise, dt, k_max)?;
    Ok(Calibrated {
        score,
        one_step,
        positions,
        calibration_size: calibrate_on.len(),
        selection_size,
    })
}

/// The scores of `windows` with normalisation `score`: one-step, per
/// horizon (K vectors), and the simultaneous max over horizons.
#[allow(clippy::type_complexity)]
fn scores(
    windows: &[Option<Traced>],
    score: Score,
    noise: &[f64],
    dt: f64,
    k_max: usize,
) -> (Vec<f64>, Vec<Vec<f64>>, Vec<f64>) {
    let n = windows.len();
    let mut one = Vec::with_capacity(n);
    let mut per_step = vec![Vec::with_capacity(n); k_max];
    let mut simultaneous = Vec::with_capacity(n);
    for w in windows {
        let Some(t) = w else {
            one.push(f64::INFINITY);
            per_step.iter_mut().for_each(|s| s.push(f64::INFINITY));
            simultaneous.push(f64::INFINITY);
            continue;
        };
        let scales: Vec<f64> = t
            .std_devs
            .iter()
            .map(|s| score_scale(score, s, noise))
            .collect();
        one.push(t.e1 / scales[0]);
        let u = position_scales(&scales, dt);
        let mut worst = 0.0f64;
        for (k, s) in per_step.iter_mut().enumerate() {
            let v = t.e[k] / u[k];
            s.push(v);
            worst = worst.max(v);
        }
        simultaneous.push(worst);
    }
    (one, per_step, simultaneous)
}

/// Calibrated quantiles (one step, per horizon) of `windows` with `score`.
fn quantiles(
    windows: &[Option<Traced>],
    score: Score,
    settings: &ConformalSettings,
    noise: &[f64],
    dt: f64,
    k_max: usize,
) -> Result<(f64, Vec<f64>), BoundError> {
    let (mut one, mut per_step, mut simultaneous) = scores(windows, score, noise, dt, k_max);
    let q1 = quantile(&mut one, settings.delta)?;
    let qk = match settings.tube {
        Tube::PerStep => per_step
            .iter_mut()
            .map(|s| quantile(s, settings.delta))
            .collect::<Result<_, _>>()?,
        Tube::Simultaneous => vec![quantile(&mut simultaneous, settings.delta)?; k_max],
    };
    Ok((q1, qk))
}

/// [`Score::Auto`]: the candidate whose bounds, calibrated on `select`,
/// have the smallest geometric-mean width (one step and K steps) on
/// `select`; `None` if a candidate cannot be calibrated there.
fn select_score(
    select: &[Option<Traced>],
    settings: &ConformalSettings,
    noise: &[f64],
    dt: f64,
    k_max: usize,
) -> Option<Score> {
    let mut best: Option<(f64, Score)> = None;
    for score in [Score::GpStd, Score::LatentStd, Score::Absolute] {
        let (q1, qk) = quantiles(select, score, settings, noise, dt, k_max).ok()?;
        let mut width = 0.0;
        for t in select.iter().flatten() {
            let scales: Vec<f64> = t
                .std_devs
                .iter()
                .map(|s| score_scale(score, s, noise))
                .collect();
            let u = position_scales(&scales, dt);
            width += (q1 * scales[0]).max(f64::MIN_POSITIVE).ln()
                + (qk[k_max - 1] * u[k_max - 1]).max(f64::MIN_POSITIVE).ln();
        }
        if best.is_none_or(|(w, _)| width < w) {
            best = Some((width, score));
        }
    }
    best.map(|(_, s)| s)
}

pub(super) fn calibrate<
    M: Mechanism<N, C> + Clone + vigp_core::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    learned: &Learned<M, N, C>,
    settings: &ConformalSettings,
    cal: &Calibration<N>,
    noise: &[f64],
) -> Result<ConformalParts, BoundError> {
    check_delta(settings.delta)?;
    let n = cal.len();
    // fail early, before the predictions
    quantile_index(n, settings.delta)?;
    let dt = Integrator::dt(learned);
    let k_max = cal.horizon();
    let mut ws = learned.workspace();
    let d = learned.gp().input_dim();
    let mut input = vec![0.0; d];
    let mut input_n = vec![0.0; d];
    let mut region = RegionBuilder::new(d);
    let mut traced = Vec::with_capacity(n);
    for (index, w) in cal.windows().iter().enumerate() {
        // the start's GP input: encoded state, then the first step's input
        let us: Vec<SVector<f64, U>> = if U > 0 {
            cal.window_inputs(index).ok_or(BoundError::Mismatch(
                "calibration windows carry other inputs",
            ))?
        } else {
            Vec::new()
        };
        let prev: SVector<f64, U> = cal
            .window_previous_input(index)
            .or_else(|| us.first().copied())
            .unwrap_or_else(SVector::zeros);
        match us.first() {
            Some(u) => learned.gp_input_into(&w.start, prev.as_slice(), u.as_slice(), &mut input),
            None => learned.gp_input_into(&w.start, &[], &[], &mut input),
        }
        learned.gp().input_normaliser().apply(&input, &mut input_n);
        region.start(&input, &input_n);
        let Ok(trace) = learned.trace(&w.start, k_max, &prev, &us, &mut ws) else {
            traced.push(None);
            continue;
        };
        region.scale(predictive_scale(trace.std_devs[0].as_slice(), noise));
        let v1 = (w.positions[1] - w.positions[0]) / dt;
        traced.push(Some(Traced {
            e1: (trace.states[1].v - v1).norm(),
            e: (1..=k_max)
                .map(|k| (trace.states[k].q - w.positions[k - 1]).norm())
                .collect(),
            std_devs: trace
                .std_devs
                .iter()
                .map(|s| s.as_slice().to_vec())
                .collect(),
        }));
    }
    let region = region.finish(cal.window_runs());
    ConformalParts::calibrate(&traced, settings, noise, (dt, k_max), region, U)
}

impl ConformalParts {
    /// The quantiles of `traced` windows of K = `k_max` steps of `dt`
    /// (None: a failed prediction, a miss) with `settings`
    /// ([`calibrate_traced`]), the calibrated `region`, and the number of
    /// inputs the windows were predicted under.
    pub(crate) fn calibrate(
        traced: &[Option<Traced>],
        settings: &ConformalSettings,
        noise: &[f64],
        (dt, k_max): (f64, usize),
        region: Region,
        inputs: usize,
    ) -> Result<Self, BoundError> {
        let failed = traced.iter().filter(|t| t.is_none()).count();
        let c = calibrate_traced(traced, settings, noise, dt, k_max)?;
        Ok(ConformalParts {
            score: c.score,
            tube: settings.tube,
            calibration_size: c.calibration_size,
            selection_size: c.selection_size,
            failed,
            one_step_quantile: c.one_step,
            position_quantiles: c.positions,
            region,
            inputs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The region's fields are saved beside the other constants, as before
    /// [`Region`] held them (`#[serde(flatten)]`), and round-trip.
    #[test]
    fn conformal_parts_keep_their_saved_form() {
        let mut region = RegionBuilder::new(2);
        region.start(&[0.0, 1.0], &[0.0, 0.5]);
        region.start(&[2.0, -1.0], &[1.0, -0.5]);
        region.scale(0.25);
        let parts = ConformalParts {
            score: Score::GpStd,
            tube: Tube::PerStep,
            calibration_size: 2,
            selection_size: 0,
            failed: 0,
            one_step_quantile: 1.5,
            position_quantiles: vec![0.0, 2.0],
            region: region.finish(&[0, 1]),
            inputs: 0,
        };
        // two starts of two runs: each one's nearest other start is the other
        assert_eq!(parts.region.distance_threshold, 2f64.sqrt());
        assert_eq!(parts.region.input_lower, [0.0, -1.0]);
        assert_eq!(parts.region.input_upper, [2.0, 1.0]);
        let json = serde_json::to_value(&parts).unwrap();
        for key in [
            "max_scale",
            "input_lower",
            "input_upper",
            "starts_normalised",
            "distance_threshold",
            "one_step_quantile",
        ] {
            assert!(json.get(key).is_some(), "{key} missing from {json}");
        }
        assert!(json.get("region").is_none());
        let back: ConformalParts = serde_json::from_value(json).unwrap();
        assert_eq!(back, parts);
        // inside: the box, near a start, scale within; outside: each test
        assert!(!parts.region.outside(&[1.0, 0.0], &[0.5, 0.0], 0.2));
        assert!(parts.region.outside(&[1.0, 0.0], &[0.5, 0.0], 0.3));
        assert!(parts.region.outside(&[2.5, 0.0], &[0.5, 0.0], 0.2));
        assert!(parts.region.outside(&[1.0, 0.0], &[3.0, 0.0], 0.2));
    }

    /// The quantile index against its definition, including the exact
    /// products that rounding could push over n.
    #[test]
    fn quantile_index_is_the_ceiling() {
        assert_eq!(quantile_index(19, 0.05).unwrap(), 19);
        assert!(quantile_index(18, 0.05).is_err());
        assert_eq!(quantile_index(99, 0.01).unwrap(), 99);
        assert!(quantile_index(98, 0.01).is_err());
        assert_eq!(quantile_index(1000, 0.05).unwrap(), 951);
        match quantile_index(10, 0.05) {
            Err(BoundError::TooFewCalibration { needed, got, .. }) => {
                assert_eq!((needed, got), (19, 10));
            }
            other => panic!("{other:?}"),
        }
        let mut s: Vec<f64> = (1..=20).map(f64::from).rev().collect();
        assert_eq!(quantile(&mut s, 0.1).unwrap(), 19.0);
        // a δ near 0 saturates the count: the message says so instead of
        // printing usize::MAX and 300 digits of δ
        let e = quantile_index(51, 1e-300).unwrap_err().to_string();
        assert_eq!(
            e,
            "too few calibration windows for delta = 1e-300: need at least 1.8446744073709552e19 (delta is far too small), got 51"
        );
    }

    /// Exchangeable scores: over independent calibration/test draws the
    /// conformal quantile covers a new score with probability exactly
    /// ⌈(n+1)(1−δ)⌉/(n+1) for continuous scores: 45/50 = 0.9 for δ = 0.1,
    /// n = 49. 20 000 draws: standard error √(0.9·0.1/20000) ≈ 0.0021;
    /// tolerance 0.0065 (3σ), so an index off by one (0.88 or 0.92) fails.
    #[test]
    fn coverage_of_exchangeable_scores() {
        let mut state = 7u64;
        let mut unif = || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let (delta, n, trials) = (0.1, 49, 20_000);
        let mut covered = 0;
        for _ in 0..trials {
            // heavy-tailed scores: the guarantee needs no distribution
            let mut s: Vec<f64> = (0..n).map(|_| 1.0 / (1.0 - unif())).collect();
            let q = quantile(&mut s, delta).unwrap();
            if 1.0 / (1.0 - unif()) <= q {
                covered += 1;
            }
        }
        let c = covered as f64 / trials as f64;
        assert!((c - 0.9).abs() < 0.0065, "coverage {c}");
    }

    #[test]
    fn position_scales_accumulate_twice() {
        let u = position_scales(&[1.0, 2.0, 3.0], 0.5);
        // k=1: 0.5·1; k=2: + 0.5·(1+2); k=3: + 0.5·(1+2+3)
        assert_eq!(u, vec![0.5, 2.0, 5.0]);
    }
}
