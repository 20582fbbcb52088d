//! Robots loaded while the program runs: a URDF file becomes a
//! [`Robot`], a fixed-base tree of revolute and prismatic joints stepped
//! by the linear-time engine of `vigp_core::tree` with its constants held
//! as data.
//!
//! ```
//! use vigp_runtime::robot::{Robot, RobotState};
//! let urdf = r#"<robot name="pendulum">
//!   <link name="base"/>
//!   <link name="arm">
//!     <inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
//!       <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.001"/></inertial>
//!   </link>
//!   <joint name="hinge" type="continuous">
//!     <parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
//!     <dynamics damping="0.01"/>
//!   </joint>
//! </robot>"#;
//! let robot = Robot::from_urdf_str(urdf)?.with_actuated(&["hinge"])?;
//! let z0 = RobotState::new(vec![0.5], vec![0.0]);
//! let (z1, report) = robot.step(&z0, &[0.1], 0.002)?;
//! assert_eq!(report.substeps, 1);
//! let run = robot.rollout(&z0, 0.002, 1000)?;
//! assert_eq!(run.states.len(), 1001);
//! # let _ = z1;
//! # Ok::<(), vigp_runtime::robot::RobotError>(())
//! ```
//!
//! # From URDF
//!
//! * `revolute` and `continuous` joints become revolute coordinates,
//!   `prismatic` joints prismatic ones; `fixed` joints are merged: the
//!   child link's inertia (and everything fixed to it) joins its parent
//!   body. Links fixed to the root belong to the world (a fixed base).
//! * Joint `<origin>` (xyz, rpy: R = Rz(y)Ry(p)Rx(r)) places the joint frame
//!   in the parent link frame; `<axis>` (default x, normalised) is in the
//!   joint frame; `<inertial>` origin and inertia are in the link frame.
//! * `<dynamics damping>` is viscous damping on the joint rate (friction
//!   is ignored); `<limit>` is kept ([`vigp_core::tree::Limits`]) and not
//!   enforced (a joint without one, or a continuous joint's position,
//!   has none). Visuals, collisions, meshes, materials are ignored.
//! * Coordinates are in depth-first order from the root, child joints in
//!   file order (Pinocchio's order). Gravity is (0, 0, −9.81) m/s²
//!   ([`Robot::with_gravity`]).
//! * Refused, with a [`RobotError`] naming the element: XML the parser
//!   rejects, mimic joints, floating, planar and spherical joints, NaN or
//!   ±∞ in any number read, a zero axis, a negative mass, an unknown or
//!   duplicate link, a link with two parent joints, no single root, and a
//!   mass matrix that is singular (a moving subtree without inertia).

use std::path::Path;

use nalgebra::{DMatrix, DMatrixView};
use vigp_core::tree::spatial::V3;
use vigp_core::tree::{
    Bodies, Body, BodyScratch, DerivativeBuffers, Engine, EngineError, EngineOptions, EngineReport,
    TermDerivatives, derivative_scratch_len,
};
pub use vigp_urdf::UrdfError;

/// The bodies of a robot as run-time data: what the engine reads (the
/// bodies, parents first, and gravity in world coordinates).
pub type RobotTree = Bodies<Vec<Body>>;

/// Why a robot could not be loaded or stepped.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// The document is not a tree of bodies the engine takes: malformed
    /// XML, a non-finite or out-of-domain number, an unsupported or mimic
    /// joint, links that do not form one tree (the element is named).
    #[error(transparent)]
    Urdf(#[from] UrdfError),
    /// A value out of its domain.
    #[error("invalid {element}: {why}")]
    Invalid {
        /// The element.
        element: String,
        /// What is wrong.
        why: &'static str,
    },
    /// A joint name not among the robot's coordinates.
    #[error("unknown joint `{name}` (joints with a coordinate: {known})")]
    UnknownJoint {
        /// The name.
        name: String,
        /// The known names.
        known: String,
    },
    /// The mass matrix is singular: the named joint moves no inertia.
    #[error("singular mass matrix: joint `{joint}` moves no inertia (a massless subtree)")]
    SingularMass {
        /// The joint.
        joint: String,
    },
    /// A slice or state of the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    WrongLength {
        /// What.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// The engine failed (time step, state, convergence).
    #[error("{0}")]
    Engine(EngineError),
    /// The Newton matrix ∂r/∂v₁ of a converged step is singular (or its
    /// solve not finite), so the step has no derivatives there.
    #[error("the Newton matrix of the step is singular: no derivatives at this state")]
    SingularNewtonMatrix,
    /// A step of a rollout failed.
    #[error("rollout step {step}: {source}")]
    Rollout {
        /// Index of the failing step (0: the step from the initial state).
        step: usize,
        /// Why.
        source: Box<RobotError>,
    },
}

/// A state of a robot: joint coordinates and (discrete) joint velocities,
/// in [`Robot::joint_names`] order.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotState {
    /// Coordinates (rad or m).
    pub q: Vec<f64>,
    /// Velocities (rad/s or m/s).
    pub v: Vec<f64>,
}

impl RobotState {
    /// A state.
    pub fn new(q: Vec<f64>, v: Vec<f64>) -> Self {
        Self { q, v }
    }

    /// The state at positions `q0` whose positions Δt later are `q1`:
    /// (q₀, (q₁ − q₀)/Δt), the velocity convention of
    /// [`State::from_positions`](crate::State::from_positions). `q1` pairs
    /// with `q0` entry by entry (the shorter decides the velocity's
    /// length). Δt is not checked: with Δt = 0, NaN or ±∞ the velocities
    /// are not finite, which every step refuses.
    pub fn from_positions(q0: &[f64], q1: &[f64], dt: f64) -> Self {
        let v = q1.iter().zip(q0).map(|(b, a)| (b - a) / dt).collect();
        Self::new(q0.to_vec(), v)
    }
}

/// The Jacobians of the engine's terms at one (q, v).
pub(crate) struct TermJacobians {
    /// ∂(M v)/∂q.
    pub(crate) p_q: DMatrix<f64>,
    /// ∂(M v)/∂v = M.
    pub(crate) p_v: DMatrix<f64>,
    /// ∂(∂T/∂q)/∂q.
    pub(crate) t_q: DMatrix<f64>,
    /// ∂(∂T/∂q)/∂v.
    pub(crate) t_v: DMatrix<f64>,
    /// ∂(∇V)/∂q.
    pub(crate) v_q: DMatrix<f64>,
}

impl TermJacobians {
    /// ∂/∂q and ∂/∂v of the momentum P = M(q)v, of ∂T/∂q and of ∇V at
    /// (q, v) of `engine`'s tree: [`Engine::term_derivatives`], O(N²).
    pub(crate) fn of<T: vigp_core::tree::Tree>(
        engine: &Engine<T>,
        q: &[f64],
        v: &[f64],
        ws: &mut [BodyScratch],
    ) -> Result<Self, EngineError> {
        let n = engine.dof();
        let mut buf = vec![0.0; 5 * n * n];
        engine.term_derivatives(q, v, TermDerivatives::split(&mut buf, n), ws)?;
        let m = |k: usize| DMatrix::from_row_slice(n, n, &buf[k * n * n..(k + 1) * n * n]);
        Ok(TermJacobians {
            p_q: m(0),
            p_v: m(1),
            t_q: m(2),
            t_v: m(3),
            v_q: m(4),
        })
    }
}

/// What a step's derivatives carry to the next step of a rollout: the
/// momentum and the scratch of [`Engine::step_derivatives`], whose first
/// 2N² entries then hold the momentum's Jacobians at the state `at`.
#[derive(Clone, Debug)]
struct DerivativeCarry {
    p: Vec<f64>,
    /// The step's generalized forces, and its A and B row-major.
    tau: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
    scratch: Vec<f64>,
    /// Whether `p` and the scratch hold the momentum terms at `at`, the
    /// state (q, v) the last step produced.
    start_known: bool,
    at: Vec<f64>,
}

impl DerivativeCarry {
    fn new(n: usize, inputs: usize) -> Self {
        Self {
            p: vec![0.0; n],
            tau: vec![0.0; n],
            a: vec![0.0; 4 * n * n],
            b: vec![0.0; 2 * n * inputs],
            scratch: vec![0.0; derivative_scratch_len(n, inputs)],
            start_known: false,
            at: Vec::with_capacity(2 * n),
        }
    }

    /// Whether it is sized for `n` coordinates and `inputs` inputs.
    fn fits(&self, n: usize, inputs: usize) -> bool {
        self.p.len() == n && self.b.len() == 2 * n * inputs
    }
}

/// The velocities the last steps of a run started from, whose
/// extrapolation ([`extrapolate`]) starts the next step's iteration.
#[derive(Clone, Debug)]
struct History {
    /// The last three, newest first (3N), `known` of them valid.
    past: Vec<f64>,
    known: usize,
    /// The extrapolation for the next step.
    guess: Vec<f64>,
}

impl History {
    fn new(n: usize) -> Self {
        Self {
            past: vec![0.0; 3 * n],
            known: 0,
            guess: vec![0.0; n],
        }
    }

    /// For a step from velocity `v`: the extrapolation into `guess`
    /// (`true`) when there is history (else `false`), then `v` recorded.
    fn next(&mut self, v: &[f64]) -> bool {
        let n = v.len();
        let guessed = self.known > 0;
        if guessed {
            extrapolate(v, &self.past, self.known, &mut self.guess);
        }
        self.past.copy_within(0..2 * n, n);
        self.past[..n].copy_from_slice(v);
        self.known = (self.known + 1).min(3);
        guessed
    }
}

/// One step with its exact derivatives ([`Robot::step_derivatives`]).
///
/// Each converged sub-step of h solves
/// r = P(q₀, v₀) − P(q₁, v₁) + h·(∂T/∂q(q₁, v₁) − ∇V(q₁) − D·v₁ + S·u) = 0
/// with q₁ = q₀ + h·v₀, P(q, v) = M(q)v and S the input selection. With
/// J = ∂r/∂v₁ and K = ∂r/∂q₁ (at fixed q₀, v₀):
///
/// ```text
/// ∂q₁/∂q₀ = 1,  ∂q₁/∂v₀ = h,
/// ∂v₁/∂q₀ = −J⁻¹(∂P/∂q(q₀, v₀) + K),  ∂v₁/∂v₀ = −J⁻¹(M(q₀) + h·K),
/// ∂v₁/∂u = −h·J⁻¹S.
/// ```
///
/// The terms' derivatives are the engine's closed forms
/// ([`Engine::term_derivatives`], O(N·depth) per sub-step, exact to
/// rounding); J has the tree's pattern (an entry for each pair of bodies on
/// one path from the root) and is factored in it, leaves first, without
/// fill (O(Σ depth²); a dense pivoting factorisation where a pivot is
/// tiny), and each of the 2N + U right-hand sides costs O(Σ depth).
#[derive(Clone, Debug, PartialEq)]
pub struct StepDerivatives {
    /// The state after the step (that of [`Robot::step`]).
    pub state: RobotState,
    /// A = ∂z₁/∂z₀, 2N × 2N, z = (q, v).
    pub a: DMatrix<f64>,
    /// B = ∂z₁/∂u, 2N × U (inputs in [`Robot::input_names`] order).
    pub b: DMatrix<f64>,
    /// What the step took (as [`Robot::step`]'s report, except that a
    /// sub-step refused for its energy jump adds no iterations).
    pub report: EngineReport,
}

impl StepDerivatives {
    /// No state and empty matrices: a slot that
    /// [`Robot::rollout_derivatives_into`] fills.
    fn empty() -> Self {
        Self {
            state: RobotState::new(Vec::new(), Vec::new()),
            a: DMatrix::zeros(0, 0),
            b: DMatrix::zeros(0, 0),
            report: EngineReport::default(),
        }
    }
}

/// A rollout: the states (the initial one first) and what the steps took.
#[derive(Clone, Debug, PartialEq)]
pub struct Rollout {
    /// States at t = 0, Δt, 2Δt, …
    pub states: Vec<RobotState>,
    /// Diagnostics.
    pub report: RolloutReport,
}

/// What a rollout's steps took.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct RolloutReport {
    /// Steps taken.
    pub steps: usize,
    /// Steps that subdivided themselves (their iteration failed at Δt).
    pub subdivided: usize,
    /// The deepest halving: the smallest sub-step was Δt/2^deepest.
    pub deepest: u32,
    /// Sub-steps solved in all.
    pub substeps: usize,
    /// Iterations (articulated-body solves) in all.
    pub iterations: usize,
    /// Largest final scaled residual of a sub-step.
    pub residual: f64,
}

impl RolloutReport {
    fn add(&mut self, r: &EngineReport) {
        self.steps += 1;
        self.subdivided += usize::from(r.depth > 0);
        self.deepest = self.deepest.max(r.depth);
        self.substeps += r.substeps;
        self.iterations += r.iterations;
        self.residual = self.residual.max(r.residual);
    }
}

/// The kept scratch of a robot's steps ([`Robot::step_in`],
/// [`Robot::step_derivatives_in`]): one [`BodyScratch`] per body, the
/// generalized forces, the velocities of the last steps (the start of the
/// next step's iteration) and, for the derivatives, the momentum terms at
/// the last state.
#[derive(Clone, Debug)]
pub struct RobotWorkspace {
    bodies: Vec<BodyScratch>,
    tau: Vec<f64>,
    /// The state (q, v) the last step produced (2N; empty: none).
    last: Vec<f64>,
    /// The velocities of the run that produced `last`.
    history: History,
    /// The carry of [`Robot::step_derivatives_in`], made on its first call.
    carry: Option<DerivativeCarry>,
}

/// Whether `x` is the state `z`, stored as (q, v).
fn holds_state(x: &[f64], z: &RobotState) -> bool {
    let n = z.q.len();
    x.len() == 2 * n && x[..n] == z.q[..] && x[n..] == z.v[..]
}

/// The velocity of the next step extrapolated from the current one `v`
/// and the `known` (1 to 3) before it in `past` (newest first, N each):
/// the polynomial through them, of degree `known` (2v − v₋₁;
/// 3v − 3v₋₁ + v₋₂; 4v − 6v₋₁ + 4v₋₂ − v₋₃): on a smooth motion the cubic
/// starts the iteration closer to its root than the line, so that fewer
/// iterations are needed (docs/robots.md, "The engine").
fn extrapolate(v: &[f64], past: &[f64], known: usize, out: &mut [f64]) {
    let n = v.len();
    for i in 0..n {
        let a = past[i];
        out[i] = match known {
            1 => 2.0 * v[i] - a,
            2 => 3.0 * v[i] - 3.0 * a + past[n + i],
            _ => 4.0 * v[i] - 6.0 * a + 4.0 * past[n + i] - past[2 * n + i],
        };
    }
}

/// A robot: a tree of rigid bodies in minimal coordinates with its joint
/// names, the actuated joints, and the engine that steps it.
#[derive(Clone, Debug)]
pub struct Robot {
    name: String,
    joints: Vec<String>,
    links: Vec<String>,
    engine: Engine<RobotTree>,
    inputs: Vec<usize>,
}

impl Robot {
    /// Loads a URDF file (module docs).
    pub fn from_urdf(path: impl AsRef<Path>) -> Result<Self, RobotError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| RobotError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_urdf_str(&text)
    }

    /// Loads a URDF document from a string (module docs). The conversion
    /// is `vigp_urdf::parse`, which `mechanism! { urdf: … }` shares.
    pub fn from_urdf_str(urdf: &str) -> Result<Self, RobotError> {
        let t = vigp_urdf::parse(urdf)?;
        let tree = RobotTree {
            bodies: t.bodies,
            gravity: [0.0, 0.0, -9.81],
        };
        Self::from_tree(&t.name, tree, t.joints, t.links)
    }

    /// A robot from bodies built by hand (names per body: joint, link).
    pub fn from_tree(
        name: &str,
        tree: RobotTree,
        joints: Vec<String>,
        links: Vec<String>,
    ) -> Result<Self, RobotError> {
        let n = tree.bodies.len();
        for (what, got) in [("joint names", joints.len()), ("link names", links.len())] {
            if got != n {
                return Err(RobotError::WrongLength {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        let robot = Robot {
            name: name.to_string(),
            joints,
            links,
            engine: Engine::new(tree).map_err(RobotError::Engine)?,
            inputs: Vec::new(),
        };
        robot.check_mass()?;
        Ok(robot)
    }

    /// A robot from borrowed bodies and names (what `mechanism!`'s
    /// `Name::robot()` calls with a declared tree's bodies): as
    /// [`Robot::from_tree`], with `joints[k]` and `links[k]` the names of
    /// body k's joint and link.
    pub fn from_bodies(
        name: &str,
        bodies: &[Body],
        gravity: V3,
        joints: &[&str],
        links: &[&str],
    ) -> Result<Self, RobotError> {
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect();
        Self::from_tree(
            name,
            RobotTree {
                bodies: bodies.to_vec(),
                gravity,
            },
            names(joints),
            names(links),
        )
    }

    /// Factorises M at q = 0 to name a joint that moves no inertia.
    fn check_mass(&self) -> Result<(), RobotError> {
        let n = self.dof();
        let z = RobotState::new(vec![0.0; n], vec![0.0; n]);
        self.step(&z, &vec![0.0; self.inputs.len()], 1e-3)
            .map(|_| ())
    }

    /// The robot with these joints actuated: input i is a torque (force)
    /// on joint `names[i]`. Replaces any earlier choice.
    pub fn with_actuated(mut self, names: &[&str]) -> Result<Self, RobotError> {
        let mut inputs = Vec::with_capacity(names.len());
        for name in names {
            let Some(i) = self.joints.iter().position(|j| j == name) else {
                return Err(RobotError::UnknownJoint {
                    name: name.to_string(),
                    known: self.joints.join(", "),
                });
            };
            if inputs.contains(&i) {
                return Err(RobotError::Invalid {
                    element: format!("actuated joint `{name}`"),
                    why: "listed twice",
                });
            }
            inputs.push(i);
        }
        self.inputs = inputs;
        Ok(self)
    }

    /// The robot under another gravity (m/s², world frame).
    pub fn with_gravity(self, gravity: [f64; 3]) -> Result<Self, RobotError> {
        let mut tree = self.engine.tree().clone();
        tree.gravity = gravity;
        let engine =
            Engine::with_options(tree, *self.engine.options()).map_err(RobotError::Engine)?;
        Ok(Self { engine, ..self })
    }

    /// The robot with other engine options (tolerance, iterations, the
    /// deepest subdivision).
    pub fn with_options(self, options: EngineOptions) -> Result<Self, RobotError> {
        let engine = Engine::with_options(self.engine.tree().clone(), options)
            .map_err(RobotError::Engine)?;
        Ok(Self { engine, ..self })
    }

    /// The robot's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Number of coordinates.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// The joints with a coordinate, in coordinate order.
    pub fn joint_names(&self) -> &[String] {
        &self.joints
    }

    /// The link each coordinate moves (the body's own link; fixed children
    /// are merged into it).
    pub fn link_names(&self) -> &[String] {
        &self.links
    }

    /// The actuated joints, in input order.
    pub fn input_names(&self) -> Vec<&str> {
        self.inputs
            .iter()
            .map(|&i| self.joints[i].as_str())
            .collect()
    }

    /// The bodies and gravity.
    pub fn tree(&self) -> &RobotTree {
        self.engine.tree()
    }

    /// The engine.
    pub fn engine(&self) -> &Engine<RobotTree> {
        &self.engine
    }

    /// A workspace for [`Robot::step_in`].
    pub fn workspace(&self) -> RobotWorkspace {
        let n = self.dof();
        RobotWorkspace {
            bodies: vec![BodyScratch::default(); n],
            tau: vec![0.0; n],
            last: Vec::with_capacity(2 * n),
            history: History::new(n),
            carry: None,
        }
    }

    fn engine_error(&self, e: EngineError) -> RobotError {
        match e {
            EngineError::SingularMass { body } => RobotError::SingularMass {
                joint: self.joints[body].clone(),
            },
            EngineError::SingularNewtonMatrix => RobotError::SingularNewtonMatrix,
            e => RobotError::Engine(e),
        }
    }

    fn check_state(&self, z: &RobotState) -> Result<(), RobotError> {
        let n = self.dof();
        for (what, got) in [("q", z.q.len()), ("v", z.v.len())] {
            if got != n {
                return Err(RobotError::WrongLength {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        Ok(())
    }

    fn check_inputs(&self, u: &[f64]) -> Result<(), RobotError> {
        if u.len() == self.inputs.len() {
            Ok(())
        } else {
            Err(RobotError::WrongLength {
                what: "inputs",
                expected: self.inputs.len(),
                got: u.len(),
            })
        }
    }

    /// The discrete momentum p = M(q)v of a state (what a rollout carries).
    pub fn momentum(&self, z: &RobotState) -> Result<Vec<f64>, RobotError> {
        self.check_state(z)?;
        let mut ws = self.workspace();
        let mut p = vec![0.0; self.dof()];
        self.engine
            .momentum_of(&z.q, &z.v, &mut p, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))?;
        Ok(p)
    }

    /// One step of `dt` from `z` with inputs `u` (one per actuated joint,
    /// held over the step), with the engine's report. Allocates its
    /// workspace, the momentum and the new state on every call, and starts
    /// the iteration from v; a simulation loop uses [`Robot::step_in`].
    pub fn step(
        &self,
        z: &RobotState,
        u: &[f64],
        dt: f64,
    ) -> Result<(RobotState, EngineReport), RobotError> {
        self.check_state(z)?;
        let mut ws = self.workspace();
        let mut z1 = z.clone();
        let mut p = vec![0.0; self.dof()];
        self.engine
            .momentum_of(&z.q, &z.v, &mut p, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))?;
        let r = self.step_guessed(&mut z1, &mut p, u, dt, None, &mut ws)?;
        Ok((z1, r))
    }

    /// One step in place: `z` and its momentum `p` (from
    /// [`Robot::momentum`] or the previous step) advance by `dt`. The fast
    /// path of a simulation loop: no allocation (after the first call with
    /// a workspace from [`Robot::workspace`]), and when `z` is the state
    /// the workspace's previous step produced, the iteration starts from
    /// the extrapolation of the velocities of up to four steps of that run
    /// (a cubic once there are four: 4v_k − 6v_{k−1} + 4v_{k−2} − v_{k−3});
    /// [`Robot::rollout_with`] is a loop of `step_in`. The converged step
    /// equals [`Robot::step`]'s (which starts from v_k) to the solver's
    /// tolerance.
    pub fn step_in(
        &self,
        z: &mut RobotState,
        p: &mut [f64],
        u: &[f64],
        dt: f64,
        ws: &mut RobotWorkspace,
    ) -> Result<EngineReport, RobotError> {
        self.check_state(z)?;
        self.continue_run(z, ws);
        let guessed = ws.history.next(&z.v);
        let guess = std::mem::take(&mut ws.history.guess);
        let r = self.step_guessed(z, p, u, dt, guessed.then_some(&guess[..]), ws);
        ws.history.guess = guess;
        ws.last.clear();
        if r.is_ok() {
            ws.last.extend_from_slice(&z.q);
            ws.last.extend_from_slice(&z.v);
        }
        r
    }

    /// Sizes `ws` for this robot, and forgets its run's velocities unless
    /// `z` is the state its last step produced.
    fn continue_run(&self, z: &RobotState, ws: &mut RobotWorkspace) {
        let n = self.dof();
        if ws.tau.len() != n || ws.bodies.len() < n || ws.history.past.len() != 3 * n {
            *ws = self.workspace();
        }
        if !holds_state(&ws.last, z) {
            ws.history.known = 0;
        }
    }

    /// The generalized forces of inputs `u` into `tau` (input i on the
    /// coordinate of the i-th actuated joint, zero elsewhere).
    fn generalized_forces(&self, u: &[f64], tau: &mut [f64]) {
        tau.fill(0.0);
        for (&i, &x) in self.inputs.iter().zip(u) {
            tau[i] = x;
        }
    }

    fn step_guessed(
        &self,
        z: &mut RobotState,
        p: &mut [f64],
        u: &[f64],
        dt: f64,
        guess: Option<&[f64]>,
        ws: &mut RobotWorkspace,
    ) -> Result<EngineReport, RobotError> {
        self.check_state(z)?;
        self.check_inputs(u)?;
        if ws.tau.len() != self.dof() || ws.bodies.len() < self.dof() {
            *ws = self.workspace();
        }
        self.generalized_forces(u, &mut ws.tau);
        self.engine
            .step_guessed(&mut z.q, &mut z.v, p, &ws.tau, dt, guess, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))
    }

    /// One step of `dt` from `z` with inputs `u`, with its exact
    /// derivatives A = ∂z₁/∂z₀ (2N × 2N) and B = ∂z₁/∂u (2N × U), states
    /// ordered (q, v), by the implicit function theorem on the converged
    /// DEL residual of every sub-step (module docs of
    /// [`StepDerivatives`]). The state is [`Robot::step`]'s, bit for bit:
    /// the same sub-steps are taken, and when the step subdivides itself,
    /// A and B are the products of the sub-steps' derivatives.
    pub fn step_derivatives(
        &self,
        z: &RobotState,
        u: &[f64],
        dt: f64,
    ) -> Result<StepDerivatives, RobotError> {
        self.check_state(z)?;
        self.check_inputs(u)?;
        let mut ws = vec![BodyScratch::default(); self.dof()];
        let mut carry = DerivativeCarry::new(self.dof(), self.inputs.len());
        let mut history = History::new(self.dof());
        let mut out = StepDerivatives::empty();
        self.derivatives_into(z, &mut carry, &mut history, u, dt, &mut ws, &mut out)?;
        Ok(out)
    }

    /// [`Robot::step_derivatives`] with a kept workspace, into `out`
    /// (its matrices reused when they have the right shape): what a
    /// control loop that linearises at every tick calls, allocating
    /// nothing after its first call. When `z` is the state the last call
    /// (or [`Robot::step_in`]) produced, the iteration starts from the
    /// extrapolation of the run's last velocities, as in `step_in`, and,
    /// after a call of this method, the momentum and its Jacobians at `z`
    /// are taken from it instead of recomputed. The state and its
    /// derivatives equal [`Robot::step_derivatives`]'s to the solver's
    /// tolerance.
    pub fn step_derivatives_in(
        &self,
        z: &RobotState,
        u: &[f64],
        dt: f64,
        ws: &mut RobotWorkspace,
        out: &mut StepDerivatives,
    ) -> Result<(), RobotError> {
        self.check_state(z)?;
        self.check_inputs(u)?;
        let (n, nu) = (self.dof(), self.inputs.len());
        self.continue_run(z, ws);
        let RobotWorkspace {
            bodies,
            last,
            history,
            carry,
            ..
        } = ws;
        let carry = match carry {
            Some(c) if c.fits(n, nu) => c,
            slot => slot.insert(DerivativeCarry::new(n, nu)),
        };
        carry.start_known &= holds_state(&carry.at, z);
        let r = self.derivatives_into(z, carry, history, u, dt, bodies, out);
        last.clear();
        if r.is_ok() {
            last.extend_from_slice(&out.state.q);
            last.extend_from_slice(&out.state.v);
        }
        r
    }

    /// [`Robot::step_derivatives`] from z with the momentum and its
    /// Jacobians in `carry` when known (a rollout carries them from the
    /// step before); `carry` then holds them at the new state. Into `out`,
    /// whose matrices are reused when they have the right shape.
    #[allow(clippy::too_many_arguments)]
    fn derivatives_into(
        &self,
        z: &RobotState,
        carry: &mut DerivativeCarry,
        history: &mut History,
        u: &[f64],
        dt: f64,
        ws: &mut [BodyScratch],
        out: &mut StepDerivatives,
    ) -> Result<(), RobotError> {
        let (n, nu) = (self.dof(), self.inputs.len());
        self.generalized_forces(u, &mut carry.tau);
        out.state.q.clone_from(&z.q);
        out.state.v.clone_from(&z.v);
        let buffers = DerivativeBuffers {
            a: &mut carry.a,
            b: &mut carry.b,
            scratch: &mut carry.scratch,
            start_known: carry.start_known,
        };
        let guessed = history.next(&z.v);
        let result = self.engine.step_derivatives_guessed(
            &mut out.state.q,
            &mut out.state.v,
            &mut carry.p,
            &carry.tau,
            &self.inputs,
            dt,
            guessed.then_some(&history.guess[..]),
            buffers,
            ws,
        );
        carry.start_known = result.is_ok();
        carry.at.clear();
        out.report = result.map_err(|e| self.engine_error(e))?;
        carry.at.extend_from_slice(&out.state.q);
        carry.at.extend_from_slice(&out.state.v);
        // the engine's matrices are row-major: as column-major views they
        // are the transposes
        if out.a.shape() != (2 * n, 2 * n) {
            out.a = DMatrix::zeros(2 * n, 2 * n);
        }
        out.a
            .tr_copy_from(&DMatrixView::from_slice(&carry.a, 2 * n, 2 * n));
        if out.b.shape() != (2 * n, nu) {
            out.b = DMatrix::zeros(2 * n, nu);
        }
        out.b
            .tr_copy_from(&DMatrixView::from_slice(&carry.b, nu, 2 * n));
        Ok(())
    }

    /// A driven rollout with every step's exact derivatives: entry k is
    /// [`Robot::step_derivatives`] from z_k with inputs `inputs[k]`, so its
    /// `state` is z_{k+1} and its `a`, `b` are A_k = ∂z_{k+1}/∂z_k and
    /// B_k = ∂z_{k+1}/∂u_k: the linearisation along the trajectory that
    /// iLQR and linear MPC take. Derivatives across steps are the products:
    /// ∂z_K/∂z_0 = A_{K−1}⋯A_0 and ∂z_K/∂u_j = A_{K−1}⋯A_{j+1}B_j. Each step
    /// starts its iteration from the extrapolation of the last velocities,
    /// as [`Robot::rollout_with`] does, so the states agree with that
    /// rollout's to the solver's tolerance; the momentum and the term
    /// derivatives at each state are carried from the step before, not
    /// recomputed. A failure names the step.
    pub fn rollout_derivatives(
        &self,
        z0: &RobotState,
        inputs: &[Vec<f64>],
        dt: f64,
    ) -> Result<Vec<StepDerivatives>, RobotError> {
        let mut out = Vec::new();
        self.rollout_derivatives_into(z0, inputs, dt, &mut out)?;
        Ok(out)
    }

    /// [`Robot::rollout_derivatives`] into `out`, which ends with one entry
    /// per input: the entries it already holds are overwritten in place
    /// (their matrices and states reused), so a control loop that
    /// linearises a horizon of the same length on every cycle allocates
    /// only the call's scratch (one [`RobotWorkspace`]) after its first.
    /// A loop of [`Robot::step_derivatives_in`]. On an error `out` holds
    /// the steps before the failing one.
    pub fn rollout_derivatives_into(
        &self,
        z0: &RobotState,
        inputs: &[Vec<f64>],
        dt: f64,
        out: &mut Vec<StepDerivatives>,
    ) -> Result<(), RobotError> {
        let fail = |step, e| RobotError::Rollout {
            step,
            source: Box::new(e),
        };
        out.truncate(inputs.len());
        if inputs.is_empty() {
            return Ok(());
        }
        self.check_state(z0).map_err(|e| fail(0, e))?;
        // each step continues the run of the one before: the extrapolated
        // start and the carried momentum terms of `step_derivatives_in`
        let mut ws = self.workspace();
        for (k, u) in inputs.iter().enumerate() {
            if out.len() == k {
                out.push(StepDerivatives::empty());
            }
            let (done, rest) = out.split_at_mut(k);
            let z = done.last().map_or(z0, |d| &d.state);
            if let Err(e) = self.step_derivatives_in(z, u, dt, &mut ws, &mut rest[0]) {
                out.truncate(k);
                return Err(fail(k, e));
            }
        }
        Ok(())
    }

    /// `steps` unforced steps of `dt` from `z0` (inputs zero).
    pub fn rollout(&self, z0: &RobotState, dt: f64, steps: usize) -> Result<Rollout, RobotError> {
        let u = vec![0.0; self.inputs.len()];
        self.rollout_with(z0, dt, steps, |_, _| u.clone())
    }

    /// A rollout whose input at step k is `input(k, z_k)`: a loop of
    /// [`Robot::step_in`], whose iterations start from the extrapolation of
    /// the last velocities (the converged steps are those of
    /// [`Robot::step`] to the solver tolerance).
    pub fn rollout_with(
        &self,
        z0: &RobotState,
        dt: f64,
        steps: usize,
        mut input: impl FnMut(usize, &RobotState) -> Vec<f64>,
    ) -> Result<Rollout, RobotError> {
        let fail = |step, e| RobotError::Rollout {
            step,
            source: Box::new(e),
        };
        let mut ws = self.workspace();
        let mut p = self.momentum(z0).map_err(|e| fail(0, e))?;
        let mut z = z0.clone();
        let mut states = Vec::with_capacity(steps + 1);
        states.push(z.clone());
        let mut report = RolloutReport::default();
        for k in 0..steps {
            let u = input(k, &z);
            let r = self
                .step_in(&mut z, &mut p, &u, dt, &mut ws)
                .map_err(|e| fail(k, e))?;
            report.add(&r);
            states.push(z.clone());
        }
        Ok(Rollout { states, report })
    }

    /// Energy T + V of a state (kinetic, gravity; no spring in URDF).
    pub fn energy(&self, z: &RobotState) -> Result<f64, RobotError> {
        self.check_state(z)?;
        let mut ws = self.workspace();
        self.engine
            .energy(&z.q, &z.v, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))
    }

    /// The mass matrix M(q), row-major (N² entries; O(N²)).
    pub fn mass_matrix(&self, q: &[f64]) -> Result<Vec<f64>, RobotError> {
        let n = self.dof();
        let mut ws = self.workspace();
        let mut m = vec![0.0; n * n];
        self.engine
            .mass_matrix(q, &mut m, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))?;
        Ok(m)
    }

    /// The bias forces b(q, v) = Ṁv − ∂T/∂q + ∇V of M q̈ + b = τ
    /// (Pinocchio's `rnea(q, v, 0)`, "nonlinear effects").
    pub fn bias_forces(&self, q: &[f64], v: &[f64]) -> Result<Vec<f64>, RobotError> {
        let mut ws = self.workspace();
        let mut b = vec![0.0; self.dof()];
        self.engine
            .bias_forces(q, v, &mut b, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))?;
        Ok(b)
    }

    /// (p, ∂T/∂q, ∇V) at (q, v): the momentum M(q)v, the kinetic energy's
    /// configuration gradient and the potential's gradient.
    #[allow(clippy::type_complexity)]
    pub fn terms(
        &self,
        q: &[f64],
        v: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>), RobotError> {
        let n = self.dof();
        let mut ws = self.workspace();
        let (mut p, mut dt, mut dv) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        self.engine
            .terms(q, v, &mut p, &mut dt, &mut dv, &mut ws.bodies)
            .map_err(|e| self.engine_error(e))?;
        Ok((p, dt, dv))
    }
}
