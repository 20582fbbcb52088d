//! The error bound of a learned robot's predictions: the conformal bound
//! of [`crate::bound`] (split conformal on held-out windows, the same
//! scores, quantiles, tubes and calibrated region), calibrated on windows
//! of a robot's logs ([`RobotCalibration`]) and attached to predictions
//! under planned inputs ([`LearnedRobot::predict`]).
//!
//! Only the conformal kind: the rigorous kinds (Theorem 1, RKHS) need the
//! projection's Lipschitz constant and the step's Jacobian norms of a
//! declared mechanism's integrator, which the tree engine does not
//! provide; a conformal bound here has no fallback outside its calibrated
//! region, and flags the states there ([`RobotPrediction::outside`]).

use super::{LearnedRobot, LearnedRobotError};
use crate::bound::conformal::{
    RegionBuilder, Traced, position_scales, predictive_scale, quantile_index, score_scale,
};
use crate::bound::windows::{CalibrationOf, CalibrationWindow, Windows, window_starts};
use crate::bound::{
    BoundError, BoundParts, ConformalParts, ConformalSettings, ErrorBound, check_delta,
    check_held_out,
};
use crate::robot::RobotState;

/// One held-out case of a robot: a start state and the true positions
/// after it (as [`crate::bound::Window`], with run-time lengths).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotWindow {
    /// z₀ = (q₀, v₀) with the discrete velocity v₀ = (q₁ − q₀)/Δt.
    pub start: RobotState,
    /// The true positions q₁, …, q_K (K ≥ 2).
    pub positions: Vec<Vec<f64>>,
}

impl crate::bound::windows::sealed::Sealed for RobotWindow {}

impl CalibrationWindow for RobotWindow {
    type Sample = Vec<f64>;

    fn cut(p: &[Vec<f64>], s: usize, horizon: usize, dt: f64) -> Self {
        RobotWindow {
            start: RobotState::from_positions(&p[s], &p[s + 1], dt),
            positions: p[s + 1..=s + horizon].to_vec(),
        }
    }

    fn steps(&self) -> usize {
        self.positions.len()
    }

    fn is_finite(&self) -> bool {
        let z = &self.start;
        z.q.iter()
            .chain(&z.v)
            .chain(self.positions.iter().flatten())
            .all(|x| x.is_finite())
    }

    fn defect(&self) -> Option<&'static str> {
        let n = self.start.q.len();
        (self.start.v.len() != n || self.positions.iter().any(|q| q.len() != n))
            .then_some("samples of different lengths")
    }
}

/// Held-out windows of a robot's logs, with the inputs of their steps:
/// what [`LearnedRobot::error_bound`] calibrates on.
pub type RobotCalibration = CalibrationOf<RobotWindow>;

impl CalibrationOf<RobotWindow> {
    /// Windows of `horizon` steps from logged runs: `positions[r][i]` the
    /// joint positions of sample i of run r, `inputs[r][i]` the input
    /// logged with it and held from t_i to t_{i+1} (the data files'
    /// convention; empty vectors for a robot without actuated joints). A
    /// window starts at every `stride`-th sample that leaves room for its
    /// horizon; the step from its state at sample s + k is driven by
    /// sample s + k + 1's input after sample s + k's (as
    /// [`CalibrationOf::from_trajectories_forced`]).
    ///
    /// Errors: those of [`CalibrationOf::from_trajectories`]; not one
    /// input sequence per run, or not one input per sample; inputs of
    /// different lengths; a NaN or ∞ input.
    pub fn from_logs(
        positions: &[Vec<Vec<f64>>],
        inputs: &[Vec<Vec<f64>>],
        dt: f64,
        horizon: usize,
        stride: usize,
    ) -> Result<Self, BoundError> {
        if inputs.len() != positions.len() {
            return Err(BoundError::WrongLength {
                what: "calibration inputs (one sequence per run)",
                expected: positions.len(),
                got: inputs.len(),
            });
        }
        let u = inputs.first().and_then(|r| r.first()).map_or(0, Vec::len);
        for (index, (p, us)) in positions.iter().zip(inputs).enumerate() {
            if us.len() != p.len() {
                return Err(BoundError::Calibration {
                    index,
                    reason: "a run needs one input per sample",
                });
            }
            if us.iter().any(|x| x.len() != u) {
                return Err(BoundError::Calibration {
                    index,
                    reason: "inputs of different lengths",
                });
            }
            if !us.iter().flatten().all(|x| x.is_finite()) {
                return Err(BoundError::Calibration {
                    index,
                    reason: "NaN or infinity in the run's inputs",
                });
            }
        }
        let lengths: Vec<usize> = positions.iter().map(Vec::len).collect();
        let starts = window_starts(&lengths, horizon, stride)?;
        let mut set = Windows::from_starts(&starts, dt, |r, s| {
            RobotWindow::cut(&positions[r], s, horizon, dt)
        })?;
        if u > 0 {
            set.inputs = starts
                .iter()
                .map(|&(r, s)| inputs[r][s + 1..=s + horizon].concat())
                .collect();
            set.previous = starts.iter().map(|&(r, s)| inputs[r][s].clone()).collect();
            set.input_count = u;
        }
        Ok(CalibrationOf { set })
    }

    /// Window `index`'s previous input (held over its start's velocity
    /// interval) and its K inputs, one per step (empty vectors for a robot
    /// without actuated joints); `None` out of range.
    pub fn window_inputs_of(&self, index: usize) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
        let k = self.set.windows.get(index)?.steps();
        let u = self.set.input_count;
        if u == 0 {
            return Some((Vec::new(), vec![Vec::new(); k]));
        }
        let flat = self.set.inputs.get(index)?;
        Some((
            self.set.previous_input(index).to_vec(),
            flat.chunks_exact(u).map(<[f64]>::to_vec).collect(),
        ))
    }
}

/// A learned robot's prediction in which every state carries its bound
/// (as [`crate::bound::BoundedPrediction`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotPrediction {
    /// z_0, z_1, …, z_K.
    pub states: Vec<RobotState>,
    /// K values: the bound on ‖v_{k+1} − v_true(z_k)‖ of the velocity
    /// predicted from z_k (marginal coverage ≥ 1 − δ).
    pub one_step_bounds: Vec<f64>,
    /// K + 1 values: the bound on ‖q_k − q_true,k‖ along the prediction
    /// from z_0 (0 at k = 0), each step's with marginal coverage ≥ 1 − δ
    /// (per-step tube) or all at once (simultaneous tube).
    pub position_bounds: Vec<f64>,
    /// K values: the GP posterior standard deviations σ(z_k), per joint.
    pub std_devs: Vec<Vec<f64>>,
    /// K values: `true` where z_k lies outside the calibrated region (its
    /// GP input outside the box of, or far from, the calibration starts,
    /// or its predictive standard deviation beyond theirs): the guarantee
    /// does not cover it. `outside[0]` is the start's test.
    pub outside: Vec<bool>,
}

/// States and standard deviations of a learned prediction.
struct RobotTrace {
    states: Vec<RobotState>,
    std_devs: Vec<Vec<f64>>,
}

impl LearnedRobot {
    /// `inputs.len()` learned steps with variances from `z0` after
    /// `u_prev`.
    fn trace(
        &self,
        z0: &RobotState,
        u_prev: &[f64],
        inputs: &[Vec<f64>],
    ) -> Result<RobotTrace, LearnedRobotError> {
        let n = self.model.robot.dof();
        let mut ws = self.workspace();
        let mut t = RobotTrace {
            states: Vec::with_capacity(inputs.len() + 1),
            std_devs: Vec::with_capacity(inputs.len()),
        };
        t.states.push(z0.clone());
        let mut prev = u_prev;
        let mut var = vec![0.0; n];
        for (k, u) in inputs.iter().enumerate() {
            let next = self
                .step_in(&t.states[k], prev, u, &mut ws, Some(&mut var))
                .map_err(|e| LearnedRobotError::Rollout {
                    step: k,
                    source: Box::new(e),
                })?;
            t.std_devs
                .push(var.iter().map(|v| v.max(0.0).sqrt()).collect());
            t.states.push(next);
            prev = u;
        }
        Ok(t)
    }

    /// The conformal error bound of this model's predictions under
    /// inputs, calibrated on held-out windows (of runs the model was not
    /// trained on; `settings` as for a declared mechanism's
    /// [`crate::bound::BoundKind::Conformal`], whose
    /// [`crate::bound::Fallback`] is ignored here: there is no rigorous
    /// bound to fall back to). Each window is predicted under its inputs;
    /// a window whose prediction fails scores +∞ (a miss).
    ///
    /// Errors: δ ∉ (0, 1); fewer windows than δ needs; windows of another
    /// Δt, another number of joints or of inputs ([`BoundError::Mismatch`]);
    /// windows that start at training states
    /// ([`BoundError::CalibrationOverlapsTraining`]: calibrate on runs held
    /// out from training).
    pub fn error_bound(
        &self,
        settings: &ConformalSettings,
        calibration: &RobotCalibration,
    ) -> Result<ErrorBound, BoundError> {
        check_delta(settings.delta)?;
        let n = calibration.len();
        quantile_index(n, settings.delta)?;
        let m = &self.model;
        let dt = m.dt;
        if (calibration.dt() - dt).abs() > 1e-12 * dt {
            return Err(BoundError::Mismatch("time step dt"));
        }
        let (dof, nu) = (m.robot.dof(), m.inputs());
        if calibration.input_count() != nu {
            return Err(BoundError::Mismatch(
                "calibration windows carry another number of inputs than the model's",
            ));
        }
        if calibration
            .windows()
            .first()
            .is_some_and(|w| w.start.q.len() != dof)
        {
            return Err(BoundError::Mismatch("number of joints"));
        }
        let e = m.encoding.dim(&m.kinds);
        let starts = calibration.windows().iter().map(|w| {
            let mut buf = vec![0.0; e];
            m.encoding
                .encode_parts(&m.kinds, &w.start.q, &w.start.v, &mut buf);
            buf
        });
        check_held_out(&self.gp, e, starts)?;
        let noise = self.gp.noise_std();
        let k_max = calibration.horizon();
        let d = m.input_dim();
        let (mut input, mut input_n) = (vec![0.0; d], vec![0.0; d]);
        let mut region = RegionBuilder::new(d);
        let mut traced = Vec::with_capacity(n);
        for (index, w) in calibration.windows().iter().enumerate() {
            let (prev, us) = calibration
                .window_inputs_of(index)
                .ok_or(BoundError::Empty("calibration window"))?;
            m.gp_input(&w.start, &prev, &us[0], &mut input);
            self.gp.input_normaliser().apply(&input, &mut input_n);
            region.start(&input, &input_n);
            let Ok(t) = self.trace(&w.start, &prev, &us) else {
                traced.push(None);
                continue;
            };
            region.scale(predictive_scale(&t.std_devs[0], &noise));
            let v1 = w.positions[1].iter().zip(&w.positions[0]);
            let e1 = t.states[1]
                .v
                .iter()
                .zip(v1)
                .map(|(a, (q2, q1))| (a - (q2 - q1) / dt).powi(2))
                .sum::<f64>()
                .sqrt();
            let e = (1..=k_max)
                .map(|k| {
                    t.states[k]
                        .q
                        .iter()
                        .zip(&w.positions[k - 1])
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            traced.push(Some(Traced {
                e1,
                e,
                std_devs: t.std_devs,
            }));
        }
        let region = region.finish(calibration.window_runs());
        let parts = ConformalParts::calibrate(&traced, settings, &noise, (dt, k_max), region, nu)?;
        Ok(ErrorBound::conformal_alone(
            settings.delta,
            parts,
            dof,
            dt,
            noise,
        ))
    }

    /// The learned mean prediction from `z0` under `inputs` (step k under
    /// `inputs[k]` after `inputs[k − 1]`, the first after `u_prev`, as
    /// [`LearnedRobot::rollout`]), each state with the bound's one-step
    /// and position bounds (module docs). `bound` from
    /// [`LearnedRobot::error_bound`].
    ///
    /// Errors: a bound of another kind, made for another model (outputs,
    /// Δt, GP inputs, inputs) or calibrated for fewer steps; a failed
    /// step; a non-finite bound.
    pub fn predict(
        &self,
        z0: &RobotState,
        u_prev: &[f64],
        inputs: &[Vec<f64>],
        bound: &ErrorBound,
    ) -> Result<RobotPrediction, BoundError> {
        let BoundParts::Conformal(c) = &bound.parts else {
            return Err(BoundError::Mismatch(
                "a learned robot's bound is conformal (LearnedRobot::error_bound)",
            ));
        };
        let m = &self.model;
        let (dt, d) = (m.dt, m.input_dim());
        if bound.outputs() != m.robot.dof() {
            return Err(BoundError::Mismatch("number of GP outputs"));
        }
        if (bound.dt() - dt).abs() > 1e-12 * dt {
            return Err(BoundError::Mismatch("time step dt"));
        }
        if c.inputs != m.inputs() {
            return Err(BoundError::Mismatch(
                "the bound was calibrated under another number of inputs",
            ));
        }
        c.region.check(d)?;
        if inputs.len() > c.position_quantiles.len() {
            return Err(BoundError::HorizonTooLong {
                calibrated: c.position_quantiles.len(),
                requested: inputs.len(),
            });
        }
        let t = self
            .trace(z0, u_prev, inputs)
            .map_err(|e| BoundError::LearnedRobot(Box::new(e)))?;
        let noise = bound.noise();
        let (mut input, mut input_n) = (vec![0.0; d], vec![0.0; d]);
        let mut one_step = Vec::with_capacity(inputs.len());
        let mut outside = Vec::with_capacity(inputs.len());
        let mut scales = Vec::with_capacity(inputs.len());
        for (k, sd) in t.std_devs.iter().enumerate() {
            one_step.push(bound.one_step(sd)?);
            let prev = if k == 0 { u_prev } else { &inputs[k - 1] };
            m.gp_input(&t.states[k], prev, &inputs[k], &mut input);
            self.gp.input_normaliser().apply(&input, &mut input_n);
            outside.push(
                c.region
                    .outside(&input, &input_n, predictive_scale(sd, noise)),
            );
            scales.push(score_scale(c.score, sd, noise));
        }
        let mut position_bounds = vec![0.0];
        position_bounds.extend(
            c.position_quantiles
                .iter()
                .zip(position_scales(&scales, dt))
                .map(|(q, u)| q * u),
        );
        if let Some(bad) = position_bounds
            .iter()
            .find(|b| !(b.is_finite() && **b >= 0.0))
        {
            return Err(BoundError::NonFinite {
                what: "position bound",
                value: *bad,
            });
        }
        Ok(RobotPrediction {
            states: t.states,
            one_step_bounds: one_step,
            position_bounds,
            std_devs: t.std_devs,
            outside,
        })
    }
}
