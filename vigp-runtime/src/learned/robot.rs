//! The paper's learned integrator for a robot loaded at run time
//! ([`Robot`], e.g. from URDF): a Gaussian process learns the velocity map
//! on top of the tree engine's first-order variational step.
//!
//! As for a declared mechanism ([`super::Learned`], module docs "Under
//! inputs"), positions are never learned: q_{k+1} = q_k + Δt·v_k. The next
//! discrete velocity is
//!
//! ```text
//! v_{k+1} = prior(z_k, u_k) + μ(enc(z_k), u_{k−1}, u_k),
//! ```
//!
//! with prior the robot's step ([`Robot::step`], [`Prior::Nominal`]; the
//! robot with identified parameters, [`Prior::Identified`]) or a constant
//! mean ([`Prior::Constant`]), u_k the input held over the new velocity's
//! interval and u_{k−1} the one that produced v_k (both absent for a robot
//! without actuated joints). Training pairs come from logged positions
//! ([`RobotTransition::from_dataset`], the row convention of
//! [`crate::data`]). [`LearnedRobot::step_derivatives`] gives a learned
//! step's exact A = ∂z₁/∂z₀ and B = ∂z₁/∂u (and ∂z₁/∂u_{k−1}) for MPC.
//!
//! A model is one JSON file ([`SavedLearnedRobot`]): the bodies (so that a
//! model trained on identified parameters needs no other file), the
//! joint and link names, the actuated joints, Δt, the encoding, the prior
//! and the GP.

use std::path::Path;

mod bound;
mod export;
pub use bound::{RobotCalibration, RobotPrediction, RobotWindow};

use serde::{Deserialize, Serialize};
use vigp_core::tree::{Body, JointKind, Limits};

use super::{Encoding, IdentifiedError, IdentifiedParameters, Prior};
use crate::data::DynDataset;
use crate::gp::{Gp, GpError, PriorMean, SavedGp, TrainOptions, TrainReport, Workspace};
use crate::identify::{IdentifyError, Regressor, RobotRegressor};
use crate::mechanism::CoordinateKind;
use crate::robot::{Robot, RobotError, RobotState, RobotTree};
use nalgebra::DMatrix;

/// The `format` tag of a learned-robot file.
pub const FORMAT: &str = "vigp-learned-robot";
/// The version written by [`LearnedRobot::to_saved`]; loading accepts only it.
pub const VERSION: u32 = 1;

/// One training pair of a robot: a discrete state, the inputs around it,
/// and the next discrete velocity.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotTransition {
    /// z_k = (x_k, (x_{k+1} − x_k)/Δt).
    pub z: RobotState,
    /// u_{k−1}: the input that produced z_k's velocity (empty without
    /// inputs).
    pub u_prev: Vec<f64>,
    /// u_k: the input held over the new velocity's interval (empty without
    /// inputs).
    pub u: Vec<f64>,
    /// v_{k+1} = (x_{k+2} − x_{k+1})/Δt.
    pub v_next: Vec<f64>,
}

impl RobotTransition {
    /// The transitions of every run of `data` with three or more samples,
    /// each with its run's time step: transition k of a run is driven by
    /// row k + 1's input after row k's ([`crate::data`], *Inputs*).
    pub fn from_dataset(data: &DynDataset) -> Vec<RobotTransition> {
        let mut out = Vec::new();
        for run in &data.runs {
            let Some(dt) = run.dt else { continue };
            let x = &run.positions;
            for k in 0..x.len().saturating_sub(2) {
                let input = |row: usize| run.inputs.get(row).cloned().unwrap_or_default();
                out.push(RobotTransition {
                    z: RobotState::from_positions(x[k].as_slice(), x[k + 1].as_slice(), dt),
                    u_prev: input(k),
                    u: input(k + 1),
                    v_next: RobotState::from_positions(
                        x[k + 1].as_slice(),
                        x[k + 2].as_slice(),
                        dt,
                    )
                    .v,
                });
            }
        }
        out
    }
}

/// Why a learned robot could not be trained, stepped, saved or loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LearnedRobotError {
    /// No training data.
    #[error("no training transitions")]
    Empty,
    /// A transition, state or input of the wrong length.
    #[error("{what} has length {found}, expected {expected}")]
    Length {
        /// What.
        what: String,
        /// Required length.
        expected: usize,
        /// Given length.
        found: usize,
    },
    /// A training transition, state or input holds NaN or ±∞.
    #[error("{0} is not finite (NaN or ∞)")]
    NonFinite(String),
    /// Δt is not finite and > 0.
    #[error("dt = {0}: must be finite and > 0")]
    TimeStep(f64),
    /// The robot's step failed (for a training transition, at its index).
    #[error("{}the robot's step: {source}", match .transition {
        Some(k) => format!("training transition {k}: "),
        None => String::new(),
    })]
    Step {
        /// The training transition, if any.
        transition: Option<usize>,
        /// Why.
        source: RobotError,
    },
    /// The robot could not be built (from a file's bodies, or with the
    /// identified parameters).
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The GP could not be trained or evaluated.
    #[error(transparent)]
    Gp(#[from] GpError),
    /// The identified parameters do not fit the robot.
    #[error("identified prior: {0}")]
    Identified(#[from] IdentifiedError),
    /// The identified parameters could not be written into the robot.
    #[error("identified prior: {0}")]
    Identify(#[from] IdentifyError),
    /// A step of a rollout failed.
    #[error("rollout step {step}: {source}")]
    Rollout {
        /// Index of the failing step (0: the step from the initial state).
        step: usize,
        /// Why.
        source: Box<LearnedRobotError>,
    },
    /// A model file could not be read, parsed or written, or does not
    /// describe a valid model.
    #[error("model file: {0}")]
    File(String),
}

/// The robot with identified parameters `p` (standard parameters by name,
/// as [`RobotRegressor::parameter_names`] and [`crate::identify`] name
/// them): the robot's bodies with every mass, centre of mass, inertia,
/// damping and spring replaced, its geometry, gravity, limits and
/// actuated joints kept. `dt` is any time step the regressor accepts (it
/// does not change the result).
///
/// Errors: parameters of another robot ([`IdentifiedError::Mechanism`]),
/// a missing or unknown name, or bodies that the engine refuses.
pub fn identified_robot(
    robot: &Robot,
    dt: f64,
    p: &IdentifiedParameters,
) -> Result<Robot, LearnedRobotError> {
    if p.mechanism() != robot.name() {
        return Err(IdentifiedError::Mechanism {
            expected: robot.name().to_string(),
            found: p.mechanism().to_string(),
        }
        .into());
    }
    let regressor = RobotRegressor::new(robot, dt)?;
    let names = &regressor.structure().names;
    for v in p.parameters() {
        if !names.contains(&v.name) {
            return Err(IdentifiedError::UnknownParameter(v.name.clone()).into());
        }
    }
    let pi = names
        .iter()
        .map(|n| {
            p.value(n)
                .ok_or_else(|| IdentifiedError::MissingParameter(n.clone()))
        })
        .collect::<Result<Vec<f64>, _>>()?;
    let tree = regressor.tree_with(&pi)?;
    rebuild(robot, tree)
}

/// `robot` with other bodies, its names and actuated joints kept.
fn rebuild(robot: &Robot, tree: RobotTree) -> Result<Robot, LearnedRobotError> {
    let out = Robot::from_tree(
        robot.name(),
        tree,
        robot.joint_names().to_vec(),
        robot.link_names().to_vec(),
    )?
    .with_options(*robot.engine().options())?
    .with_actuated(&robot.input_names())?;
    Ok(out)
}

/// What each of a robot's coordinates measures.
pub fn coordinate_kinds(robot: &Robot) -> Vec<CoordinateKind> {
    robot
        .tree()
        .bodies
        .iter()
        .map(|b| match b.joint {
            JointKind::Revolute => CoordinateKind::Angle,
            JointKind::Prismatic => CoordinateKind::Length,
        })
        .collect()
}

/// Everything of a learned robot but its GP: the prior and how states
/// and inputs are presented to the GP.
#[derive(Clone, Debug)]
struct PriorModel {
    robot: Robot,
    kinds: Vec<CoordinateKind>,
    dt: f64,
    prior: Prior,
    encoding: Encoding,
}

impl PriorModel {
    fn inputs(&self) -> usize {
        self.robot.input_names().len()
    }

    /// The GP's input dimension: the encoded state, then u_prev and u.
    fn input_dim(&self) -> usize {
        self.encoding.dim(&self.kinds) + 2 * self.inputs()
    }

    /// The GP's prior mean: zero on top of a step, else a constant.
    fn gp_mean(&self) -> PriorMean {
        if self.prior.uses_nominal_step() {
            PriorMean::Zero
        } else {
            PriorMean::Constant
        }
    }

    fn gp_input(&self, z: &RobotState, u_prev: &[f64], u: &[f64], out: &mut [f64]) {
        let e = self.encoding.dim(&self.kinds);
        self.encoding
            .encode_parts(&self.kinds, &z.q, &z.v, &mut out[..e]);
        let m = self.inputs();
        out[e..e + m].copy_from_slice(u_prev);
        out[e + m..e + 2 * m].copy_from_slice(u);
    }

    /// The prior's next velocity: the robot's step, or zero under a
    /// constant mean (the GP's mean then carries it).
    fn velocity(&self, z: &RobotState, u: &[f64]) -> Result<Vec<f64>, RobotError> {
        if self.prior.uses_nominal_step() {
            Ok(self.robot.step(z, u, self.dt)?.0.v)
        } else {
            Ok(vec![0.0; self.robot.dof()])
        }
    }

    /// Lengths and finiteness of a state, its inputs and (training) the
    /// next velocity.
    fn check(
        &self,
        z: &RobotState,
        u_prev: &[f64],
        u: &[f64],
        v_next: Option<&[f64]>,
    ) -> Result<(), LearnedRobotError> {
        let (n, m) = (self.robot.dof(), self.inputs());
        let next = v_next.unwrap_or(&z.v);
        for (what, expected, found) in [
            ("q", n, z.q.len()),
            ("v", n, z.v.len()),
            ("v_next", n, next.len()),
            ("u_prev", m, u_prev.len()),
            ("u", m, u.len()),
        ] {
            if expected != found {
                return Err(LearnedRobotError::Length {
                    what: what.into(),
                    expected,
                    found,
                });
            }
        }
        let all = [&z.q[..], &z.v[..], next, u_prev, u];
        if !all.iter().all(|x| x.iter().all(|v| v.is_finite())) {
            return Err(LearnedRobotError::NonFinite("the state or an input".into()));
        }
        Ok(())
    }
}

impl LearnedRobotError {
    /// The error with the training transition it concerns named.
    fn in_transition(self, i: usize) -> Self {
        match self {
            LearnedRobotError::Length {
                what,
                expected,
                found,
            } => LearnedRobotError::Length {
                what: format!("training transition {i}: {what}"),
                expected,
                found,
            },
            LearnedRobotError::NonFinite(_) => {
                LearnedRobotError::NonFinite(format!("training transition {i}"))
            }
            e => e,
        }
    }
}

/// One learned mean step with its exact derivatives
/// ([`LearnedRobot::step_derivatives`]); states ordered z = (q, v).
#[derive(Clone, Debug, PartialEq)]
pub struct LearnedRobotDerivatives {
    /// The state after the step (that of [`LearnedRobot::step`], bit for
    /// bit).
    pub state: RobotState,
    /// A = ∂z₁/∂z₀, 2N × 2N.
    pub a: DMatrix<f64>,
    /// B = ∂z₁/∂u, 2N × U.
    pub b: DMatrix<f64>,
    /// B_prev = ∂z₁/∂u_prev, 2N × U (the GP reads the previous input).
    pub b_prev: DMatrix<f64>,
}

/// A GP-augmented variational integrator of a [`Robot`] (module docs).
#[derive(Clone, Debug)]
pub struct LearnedRobot {
    model: PriorModel,
    gp: Gp,
}

impl LearnedRobot {
    /// Trains on `data` (transitions at time step `dt`, e.g.
    /// [`RobotTransition::from_dataset`]). `robot` is the nominal model;
    /// with [`Prior::Identified`] its parameters are replaced by the
    /// identified ones first ([`identified_robot`]), and the learned model
    /// keeps that robot. The GP options' `mean` is overridden by `prior`.
    ///
    /// A transition that repeats an earlier one exactly (the same state,
    /// inputs and next velocity, bit for bit) is one measurement recorded
    /// twice, and the GP trains on it once ([`super::distinct_rows`], as
    /// for a declared mechanism): the learned model's `gp().n()` counts the
    /// distinct transitions.
    ///
    /// Errors: no data, transitions of the wrong lengths or not finite, a
    /// bad `dt`, identified parameters that do not fit, a failing step of
    /// the prior, or GP training.
    pub fn train(
        robot: Robot,
        dt: f64,
        data: &[RobotTransition],
        encoding: Encoding,
        prior: Prior,
        options: &TrainOptions,
    ) -> Result<(Self, TrainReport), LearnedRobotError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(LearnedRobotError::TimeStep(dt));
        }
        if data.is_empty() {
            return Err(LearnedRobotError::Empty);
        }
        let robot = match &prior {
            Prior::Identified(p) => identified_robot(&robot, dt, p)?,
            _ => robot,
        };
        let prior_model = PriorModel {
            kinds: coordinate_kinds(&robot),
            robot,
            dt,
            prior,
            encoding,
        };
        let n = prior_model.robot.dof();
        let d = prior_model.input_dim();
        let mut inputs = vec![0.0; data.len() * d];
        let mut targets = Vec::with_capacity(data.len() * n);
        for (i, t) in data.iter().enumerate() {
            prior_model
                .check(&t.z, &t.u_prev, &t.u, Some(&t.v_next))
                .map_err(|e| e.in_transition(i))?;
            prior_model.gp_input(&t.z, &t.u_prev, &t.u, &mut inputs[i * d..(i + 1) * d]);
            let base =
                prior_model
                    .velocity(&t.z, &t.u)
                    .map_err(|source| LearnedRobotError::Step {
                        transition: Some(i),
                        source,
                    })?;
            targets.extend(t.v_next.iter().zip(&base).map(|(v, b)| v - b));
        }
        super::distinct_rows(&mut inputs, d, &mut targets, n);
        let mut opts = options.clone();
        opts.mean = prior_model.gp_mean();
        let (gp, report) = Gp::train(&inputs, d, &targets, n, &opts)?;
        Ok((
            LearnedRobot {
                model: prior_model,
                gp,
            },
            report,
        ))
    }

    /// The robot of the prior (with the identified parameters under
    /// [`Prior::Identified`]).
    pub fn robot(&self) -> &Robot {
        &self.model.robot
    }

    /// The time step Δt (s).
    pub fn dt(&self) -> f64 {
        self.model.dt
    }

    /// The prior.
    pub fn prior(&self) -> &Prior {
        &self.model.prior
    }

    /// The GP input encoding.
    pub fn encoding(&self) -> Encoding {
        self.model.encoding
    }

    /// The GP.
    pub fn gp(&self) -> &Gp {
        &self.gp
    }

    /// Number of inputs (the robot's actuated joints).
    pub fn inputs(&self) -> usize {
        self.model.inputs()
    }

    /// A workspace for [`LearnedRobot::step_in`].
    pub fn workspace(&self) -> Workspace {
        self.gp.workspace()
    }

    /// One learned mean step from `z` under `u` after `u_prev` (module
    /// docs): q₁ = q + Δt·v, v₁ = prior(z, u) + μ(enc(z), u_prev, u), with
    /// the posterior variance of each v₁ entry into `var` when given.
    pub fn step_in(
        &self,
        z: &RobotState,
        u_prev: &[f64],
        u: &[f64],
        ws: &mut Workspace,
        var: Option<&mut [f64]>,
    ) -> Result<RobotState, LearnedRobotError> {
        let m = &self.model;
        m.check(z, u_prev, u, None)?;
        let n = m.robot.dof();
        let mut input = vec![0.0; m.input_dim()];
        m.gp_input(z, u_prev, u, &mut input);
        let mut mean = vec![0.0; n];
        match var {
            Some(var) => self.gp.predict_into(&input, &mut mean, var, ws)?,
            None => self.gp.predict_mean_into(&input, &mut mean, ws)?,
        }
        let prior = m.velocity(z, u).map_err(|source| LearnedRobotError::Step {
            transition: None,
            source,
        })?;
        let v: Vec<f64> = prior.iter().zip(&mean).map(|(p, m)| p + m).collect();
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LearnedRobotError::NonFinite(
                "the predicted velocity".into(),
            ));
        }
        let q = z.q.iter().zip(&z.v).map(|(q, v)| q + m.dt * v).collect();
        Ok(RobotState::new(q, v))
    }

    /// One learned mean step (as [`LearnedRobot::step_in`]) with its
    /// exact derivatives A = ∂z₁/∂z₀, B = ∂z₁/∂u and B_prev = ∂z₁/∂u_prev,
    /// for MPC and iLQR on the learned model. q₁ = q + Δt·v gives the top
    /// rows [I, Δt·I | 0]; v₁ = prior(z, u) + μ(enc(z), u_prev, u)
    /// differentiates into the robot's exact step derivatives
    /// ([`Robot::step_derivatives`], the implicit function theorem on the
    /// tree engine's residual; zero under [`Prior::Constant`], which does
    /// not depend on z or u) plus the GP mean's gradient
    /// ([`Gp::predict_mean_gradient_into`]) through the encoding
    /// (∂(sin θ, cos θ)/∂θ = (cos θ, −sin θ) under [`Encoding::SinCos`]).
    ///
    /// Finite-difference checks: the GP mean k(x)ᵀα sums terms much larger
    /// than itself when the trained noise variance is small, so the step
    /// carries rounding noise of 1e-9 or so; use steps of about 1e-3 with a
    /// five-point stencil rather than 1e-6.
    pub fn step_derivatives(
        &self,
        z: &RobotState,
        u_prev: &[f64],
        u: &[f64],
        ws: &mut Workspace,
    ) -> Result<LearnedRobotDerivatives, LearnedRobotError> {
        let m = &self.model;
        m.check(z, u_prev, u, None)?;
        let (n, nu, dt) = (m.robot.dof(), m.inputs(), m.dt);
        let mut a = DMatrix::<f64>::zeros(2 * n, 2 * n);
        let mut b = DMatrix::<f64>::zeros(2 * n, nu);
        let mut b_prev = DMatrix::<f64>::zeros(2 * n, nu);
        for i in 0..n {
            a[(i, i)] = 1.0;
            a[(i, n + i)] = dt;
        }
        // the prior's velocity and its rows of A and B
        let mut v = vec![0.0; n];
        if m.prior.uses_nominal_step() {
            let d =
                m.robot
                    .step_derivatives(z, u, dt)
                    .map_err(|source| LearnedRobotError::Step {
                        transition: None,
                        source,
                    })?;
            v = d.state.v;
            a.rows_mut(n, n).copy_from(&d.a.rows(n, n));
            b.rows_mut(n, n).copy_from(&d.b.rows(n, n));
        }
        // the GP's mean and its gradient in the GP input
        let dim = m.input_dim();
        let mut input = vec![0.0; dim];
        m.gp_input(z, u_prev, u, &mut input);
        let mut mean = vec![0.0; n];
        let mut grad = vec![0.0; n * dim];
        self.gp
            .predict_mean_gradient_into(&input, &mut mean, &mut grad, ws)?;
        let e = m.encoding.dim(&m.kinds);
        for j in 0..n {
            v[j] += mean[j];
            let g = &grad[j * dim..(j + 1) * dim];
            m.encoding
                .pull_back(&m.kinds, &z.q, g, |i, x| a[(n + j, i)] += x);
            for c in 0..nu {
                b_prev[(n + j, c)] = g[e + c];
                b[(n + j, c)] += g[e + nu + c];
            }
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LearnedRobotError::NonFinite(
                "the predicted velocity".into(),
            ));
        }
        let q = z.q.iter().zip(&z.v).map(|(q, v)| q + dt * v).collect();
        Ok(LearnedRobotDerivatives {
            state: RobotState::new(q, v),
            a,
            b,
            b_prev,
        })
    }

    /// The learned mean rollout of [`LearnedRobot::rollout`] with every
    /// step's exact derivatives: entry k is [`LearnedRobot::step_derivatives`]
    /// at (z_k, u_{k−1}, u_k) (`u_prev` before the first), so its `state`
    /// is z_{k+1}, bit for bit that of the rollout, and its `a`, `b`,
    /// `b_prev` are A_k, B_k and B_prev,k: the linearisation along the
    /// trajectory that iLQR and linear MPC take. Across steps the
    /// derivatives chain as ∂z_K/∂z_0 = A_{K−1}⋯A_0 and, since u_j reaches
    /// z_{j+1} through B_j and z_{j+2} through B_prev,(j+1),
    /// ∂z_{k+1}/∂u_j = A_k ∂z_k/∂u_j + [j = k] B_k + [j = k − 1] B_prev,k.
    /// A failure names the step.
    pub fn rollout_derivatives(
        &self,
        z0: &RobotState,
        u_prev: &[f64],
        inputs: &[Vec<f64>],
        ws: &mut Workspace,
    ) -> Result<Vec<LearnedRobotDerivatives>, LearnedRobotError> {
        let mut out: Vec<LearnedRobotDerivatives> = Vec::with_capacity(inputs.len());
        let mut prev = u_prev;
        for (k, u) in inputs.iter().enumerate() {
            let z = out.last().map_or(z0, |d| &d.state);
            let d =
                self.step_derivatives(z, prev, u, ws)
                    .map_err(|e| LearnedRobotError::Rollout {
                        step: k,
                        source: Box::new(e),
                    })?;
            out.push(d);
            prev = u;
        }
        Ok(out)
    }

    /// [`LearnedRobot::step_in`] with its own workspace and no variance.
    pub fn step(
        &self,
        z: &RobotState,
        u_prev: &[f64],
        u: &[f64],
    ) -> Result<RobotState, LearnedRobotError> {
        self.step_in(z, u_prev, u, &mut self.workspace(), None)
    }

    /// The learned mean rollout from `z0`: step k runs under `inputs[k]`
    /// after `inputs[k − 1]` (`u_prev` before the first), so the states
    /// after the `inputs.len()` steps come back. Without actuated joints
    /// pass `steps` empty inputs (`vec![vec![]; steps]`) and `u_prev = &[]`.
    pub fn rollout(
        &self,
        z0: &RobotState,
        u_prev: &[f64],
        inputs: &[Vec<f64>],
    ) -> Result<Vec<RobotState>, LearnedRobotError> {
        let mut ws = self.workspace();
        let mut out = Vec::with_capacity(inputs.len());
        let mut z = z0.clone();
        let mut prev = u_prev;
        for (k, u) in inputs.iter().enumerate() {
            z = self.step_in(&z, prev, u, &mut ws, None).map_err(|e| {
                LearnedRobotError::Rollout {
                    step: k,
                    source: Box::new(e),
                }
            })?;
            out.push(z.clone());
            prev = u;
        }
        Ok(out)
    }

    /// The serde form of the model (module docs).
    pub fn to_saved(&self) -> SavedLearnedRobot {
        let m = &self.model;
        let tree = m.robot.tree();
        SavedLearnedRobot {
            format: FORMAT.into(),
            version: VERSION,
            robot: m.robot.name().into(),
            joints: m.robot.joint_names().to_vec(),
            links: m.robot.link_names().to_vec(),
            actuated: m
                .robot
                .input_names()
                .iter()
                .map(|s| s.to_string())
                .collect(),
            gravity: tree.gravity,
            bodies: tree.bodies.iter().map(SavedBody::from).collect(),
            dt: m.dt,
            encoding: m.encoding,
            prior: m.prior.clone(),
            gp: self.gp.to_saved(),
        }
    }

    /// The model of a [`SavedLearnedRobot`], checked: format and version,
    /// the bodies (as the engine validates them), names of the right
    /// count, Δt, and the GP's dimensions against the robot and the
    /// encoding.
    pub fn from_saved(s: &SavedLearnedRobot) -> Result<Self, LearnedRobotError> {
        let bad = |why: String| Err(LearnedRobotError::File(why));
        if s.format != FORMAT {
            return bad(format!("format `{}`, expected `{FORMAT}`", s.format));
        }
        if s.version != VERSION {
            return bad(format!("version {}, expected {VERSION}", s.version));
        }
        if !(s.dt.is_finite() && s.dt > 0.0) {
            return Err(LearnedRobotError::TimeStep(s.dt));
        }
        let bodies = s
            .bodies
            .iter()
            .map(SavedBody::to_body)
            .collect::<Result<Vec<_>, _>>()
            .map_err(LearnedRobotError::File)?;
        let tree = RobotTree {
            bodies,
            gravity: s.gravity,
        };
        let actuated: Vec<&str> = s.actuated.iter().map(String::as_str).collect();
        let robot = Robot::from_tree(&s.robot, tree, s.joints.clone(), s.links.clone())?
            .with_actuated(&actuated)?;
        let model = PriorModel {
            kinds: coordinate_kinds(&robot),
            robot,
            dt: s.dt,
            prior: s.prior.clone(),
            encoding: s.encoding,
        };
        // zero and constant means are saved with the GP
        let gp = Gp::from_saved(&s.gp, None)?;
        if gp.input_dim() != model.input_dim() || gp.output_dim() != model.robot.dof() {
            return bad(format!(
                "the GP maps {} inputs to {} outputs; the robot and encoding need {} to {}",
                gp.input_dim(),
                gp.output_dim(),
                model.input_dim(),
                model.robot.dof()
            ));
        }
        Ok(LearnedRobot { model, gp })
    }

    /// Writes the model as JSON.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LearnedRobotError> {
        let path = path.as_ref();
        let text = serde_json::to_string(&self.to_saved())
            .map_err(|e| LearnedRobotError::File(e.to_string()))?;
        std::fs::write(path, text)
            .map_err(|e| LearnedRobotError::File(format!("{}: {e}", path.display())))
    }

    /// Reads a model written by [`LearnedRobot::save`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LearnedRobotError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|e| LearnedRobotError::File(format!("{}: {e}", path.display())))?;
        let saved: SavedLearnedRobot = serde_json::from_str(&text)
            .map_err(|e| LearnedRobotError::File(format!("{}: {e}", path.display())))?;
        Self::from_saved(&saved)
    }
}

/// The serde form of a [`LearnedRobot`] (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedLearnedRobot {
    /// Always `"vigp-learned-robot"`.
    pub format: String,
    /// File format version (1).
    pub version: u32,
    /// The robot's name.
    pub robot: String,
    /// The joints with a coordinate, in coordinate order.
    pub joints: Vec<String>,
    /// The link each coordinate moves.
    pub links: Vec<String>,
    /// The actuated joints, in input order.
    pub actuated: Vec<String>,
    /// Gravity in world coordinates (m/s²).
    pub gravity: [f64; 3],
    /// The bodies, parents first.
    pub bodies: Vec<SavedBody>,
    /// Time step Δt (s).
    pub dt: f64,
    /// GP input encoding.
    pub encoding: Encoding,
    /// Prior of the velocity map.
    pub prior: Prior,
    /// The GP.
    pub gp: SavedGp,
}

/// The serde form of a tree body ([`Body`]); a limit that is absent
/// (±∞ in [`Limits`]) is `null`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedBody {
    /// The parent body's index, `null` for the world.
    pub parent: Option<usize>,
    /// `"revolute"` or `"prismatic"`.
    pub joint: String,
    /// Unit joint axis in the joint frame.
    pub axis: [f64; 3],
    /// Orientation of the joint frame in the parent frame, row by row.
    pub rotation: [[f64; 3]; 3],
    /// Origin of the joint frame in the parent frame (m).
    pub translation: [f64; 3],
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the body frame (m).
    pub com: [f64; 3],
    /// Inertia about the centre of mass in body axes (kg·m²), row by row.
    pub inertia: [[f64; 3]; 3],
    /// Viscous joint damping.
    pub damping: f64,
    /// Spring stiffness.
    pub stiffness: f64,
    /// Spring rest coordinate.
    pub rest: f64,
    /// Lower, upper, effort and velocity limits (`null`: none).
    pub limits: [Option<f64>; 4],
}

impl From<&Body> for SavedBody {
    fn from(b: &Body) -> Self {
        let finite = |x: f64| x.is_finite().then_some(x);
        SavedBody {
            parent: b.parent,
            joint: match b.joint {
                JointKind::Revolute => "revolute",
                JointKind::Prismatic => "prismatic",
            }
            .into(),
            axis: b.axis,
            rotation: b.rotation,
            translation: b.translation,
            mass: b.mass,
            com: b.com,
            inertia: b.inertia,
            damping: b.damping,
            stiffness: b.stiffness,
            rest: b.rest,
            limits: [
                finite(b.limits.lower),
                finite(b.limits.upper),
                finite(b.limits.effort),
                finite(b.limits.velocity),
            ],
        }
    }
}

impl SavedBody {
    /// The body (checked by the engine when the robot is built).
    fn to_body(&self) -> Result<Body, String> {
        let joint = match self.joint.as_str() {
            "revolute" => JointKind::Revolute,
            "prismatic" => JointKind::Prismatic,
            other => return Err(format!("joint `{other}`: expected revolute or prismatic")),
        };
        let [lower, upper, effort, velocity] = self.limits;
        Ok(Body {
            parent: self.parent,
            joint,
            axis: self.axis,
            rotation: self.rotation,
            translation: self.translation,
            mass: self.mass,
            com: self.com,
            inertia: self.inertia,
            damping: self.damping,
            stiffness: self.stiffness,
            rest: self.rest,
            limits: Limits {
                lower: lower.unwrap_or(f64::NEG_INFINITY),
                upper: upper.unwrap_or(f64::INFINITY),
                effort: effort.unwrap_or(f64::INFINITY),
                velocity: velocity.unwrap_or(f64::INFINITY),
            },
        })
    }
}
