//! The regressor of a robot loaded at run time ([`crate::Robot`], e.g.
//! from URDF): the DEL residual of the linear-time tree engine, affine in
//! the standard parameters of every body and joint.
//!
//! Two rules, with L_d(a, b) = Δt·L(a + αΔt·v, v), v = (b − a)/Δt, as for
//! declared mechanisms ([`super::DelRegressor`], `crate::del`). For a
//! logged triple (x_{k−1}, x_k, x_{k+1}) with v_{k−1} = (x_k − x_{k−1})/Δt
//! and v_k = (x_{k+1} − x_k)/Δt, P = M(q)v, F(q, v) = ∂T/∂q − ∇V − D·v:
//!
//! * the first-order rule (α = 0, [`RobotRegressor::new`]), the tree
//!   engine's own step (module docs of `vigp_core::tree::Engine`):
//!
//!   ```text
//!   r = P(x_{k−1}, v_{k−1}) − P(x_k, v_k) + Δt·(F(x_k, v_k) + τ(u_k));
//!   ```
//!
//! * the midpoint rule (α = ½, [`RobotRegressor::midpoint`]), second
//!   order, so that logs of a continuous-time system bias the estimate by
//!   O(Δt²) instead of O(Δt): with m_{k−1} = (x_{k−1} + x_k)/2 and
//!   m_k = (x_k + x_{k+1})/2,
//!
//!   ```text
//!   r = P(m_{k−1}, v_{k−1}) + ½Δt·(F(m_{k−1}, v_{k−1}) + τ(u_{k−1}))
//!       − P(m_k, v_k) + ½Δt·(F(m_k, v_k) + τ(u_k)),
//!   ```
//!
//! τ(u_k) the input held over [t_k, t_{k+1}] on the actuated joints. The
//! parameters carry DSL-style names, so that the report and the parameter
//! files read as for a declared mechanism: per link `links.<l>.mass`,
//! `.com.x|y|z` and the nine entries `.inertia.xx` … `.zz` (about the centre
//! of mass, in the link frame); per joint `joints.<j>.damping` and, for a
//! joint with a spring, `.stiffness` and `.rest`.
//!
//! Y is obtained as [`super::DelRegressor`] does, column by column from the
//! residual at π₀ and at π₀ + s_i·e_i, exact to rounding because r is
//! affine. The steps are large (1 + |π_i|), so that the rounding of a
//! column that should vanish stays below the zero threshold of
//! [`super::Base`]; the engine refuses a body with a negative mass or
//! inertia diagonal, so a first moment is flipped (m·c_a → −m·c_a, which
//! leaves the diagonal of I_c unchanged) or, where it is zero, moved by no
//! more than the body's inertia allows.
//!
//! Output error ([`super::output_error`]) simulates with this residual:
//! [`Regressor::position_jacobians`] comes from the engine's closed-form
//! term derivatives, exact to rounding.

use super::regressor::{Regressor, Structure, Transition, finite_rows, position_differences};
use super::{IdentifyError, check_finite_vector, check_time_step};
use crate::robot::{Robot, RobotTree, TermJacobians};
use nalgebra::{DMatrix, DVector};
use vigp_core::tree::{BodyScratch, Engine};

/// Relative size, against the row's largest residual change, below which a
/// column's change is rounding (about 10⁴ ε: the residual sums some tens
/// of terms of the size of the largest change).
const ROUNDING: f64 = 1e-12;

/// Which field of which body a named parameter is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Field {
    Mass,
    Com(usize),
    Inertia(usize, usize),
    Damping,
    Stiffness,
    Rest,
}

/// The discrete regressor of a [`Robot`] (module docs).
#[derive(Clone, Debug)]
pub struct RobotRegressor {
    /// The declared robot (what [`RobotRegressor::robot`] returns).
    robot: Robot,
    tree: RobotTree,
    inputs: Vec<usize>,
    dt: f64,
    names: Vec<String>,
    fields: Vec<(usize, Field)>,
    structure: Structure,
    base: Vec<f64>,
    steps: Vec<f64>,
    /// The quadrature weight: 0 (first order) or ½ (midpoint).
    alpha: f64,
}

impl RobotRegressor {
    /// The regressor of the first-order rule, the tree engine's step, of
    /// `robot` (its bodies' declared parameters as the base point, its
    /// actuated joints as the inputs) at time step `dt`.
    pub fn new(robot: &Robot, dt: f64) -> Result<Self, IdentifyError> {
        Self::with_alpha(robot, dt, 0.0)
    }

    /// The regressor of the midpoint rule (module docs) of `robot` at time
    /// step `dt`: for logs of a continuous-time system, whose discretisation
    /// bias it shrinks from O(Δt) to O(Δt²).
    pub fn midpoint(robot: &Robot, dt: f64) -> Result<Self, IdentifyError> {
        Self::with_alpha(robot, dt, 0.5)
    }

    /// The robot whose declared parameters are the regressor's base point
    /// (its actuated joints are the inputs).
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The quadrature weight α (0: first order, ½: midpoint).
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    fn with_alpha(robot: &Robot, dt: f64, alpha: f64) -> Result<Self, IdentifyError> {
        check_time_step(dt)?;
        let tree = robot.tree().clone();
        let (joints, links) = (robot.joint_names(), robot.link_names());
        let inputs = robot
            .input_names()
            .iter()
            .map(|n| joints.iter().position(|j| j == n))
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| IdentifyError::Layout {
                message: "an input names no joint of the robot".into(),
            })?;
        let mut names = Vec::new();
        let mut fields = Vec::new();
        for (i, l) in links.iter().enumerate() {
            names.push(format!("links.{l}.mass"));
            fields.push((i, Field::Mass));
            for (a, x) in ["x", "y", "z"].iter().enumerate() {
                names.push(format!("links.{l}.com.{x}"));
                fields.push((i, Field::Com(a)));
            }
            for r in 0..3 {
                for c in 0..3 {
                    let rc = ["x", "y", "z"];
                    names.push(format!("links.{l}.inertia.{}{}", rc[r], rc[c]));
                    fields.push((i, Field::Inertia(r, c)));
                }
            }
        }
        for (i, j) in joints.iter().enumerate() {
            names.push(format!("joints.{j}.damping"));
            fields.push((i, Field::Damping));
            if tree.bodies[i].stiffness != 0.0 {
                names.push(format!("joints.{j}.stiffness"));
                fields.push((i, Field::Stiffness));
                names.push(format!("joints.{j}.rest"));
                fields.push((i, Field::Rest));
            }
        }
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let structure = Structure::from_names(&refs)?;
        let mut out = RobotRegressor {
            robot: robot.clone(),
            tree,
            inputs,
            dt,
            names,
            fields,
            structure,
            base: Vec::new(),
            steps: Vec::new(),
            alpha,
        };
        out.base = out.standard();
        if let Some(i) = out.base.iter().position(|x| !x.is_finite()) {
            return Err(IdentifyError::NonFinite {
                what: format!("declared parameter `{}`", out.structure.names[i]),
            });
        }
        if let Some(b) = out
            .structure
            .body_offsets()
            .iter()
            .position(|&o| out.base[o] <= 0.0)
        {
            return Err(IdentifyError::NoDslForm {
                parameter: format!("links.{}.mass", links[b]),
            });
        }
        out.steps = out.step_sizes();
        Ok(out)
    }

    /// The DSL-style names of the robot's parameters (module docs), in
    /// the order [`Structure`] reads them.
    pub fn parameter_names(&self) -> &[String] {
        &self.names
    }

    /// The time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The value of the parameter named `name` (one of
    /// [`RobotRegressor::parameter_names`]) in `tree`, e.g. the robot's
    /// declared tree or [`RobotRegressor::tree_with`] an estimate.
    pub fn value(&self, tree: &RobotTree, name: &str) -> Option<f64> {
        let i = self.names.iter().position(|n| n == name)?;
        (self.fields[i].0 < tree.bodies.len()).then(|| self.get(tree, i))
    }

    fn get(&self, tree: &RobotTree, i: usize) -> f64 {
        let (b, f) = self.fields[i];
        let body = &tree.bodies[b];
        match f {
            Field::Mass => body.mass,
            Field::Com(a) => body.com[a],
            Field::Inertia(r, c) => body.inertia[r][c],
            Field::Damping => body.damping,
            Field::Stiffness => body.stiffness,
            Field::Rest => body.rest,
        }
    }

    /// The bodies with standard parameters π (geometry, gravity and
    /// limits as loaded).
    pub fn tree_with(&self, pi: &[f64]) -> Result<RobotTree, IdentifyError> {
        let mut tree = self.tree.clone();
        self.structure.set_standard(pi, |i, v| {
            let (b, f) = self.fields[i];
            let body = &mut tree.bodies[b];
            match f {
                Field::Mass => body.mass = v,
                Field::Com(a) => body.com[a] = v,
                Field::Inertia(r, c) => body.inertia[r][c] = v,
                Field::Damping => body.damping = v,
                Field::Stiffness => body.stiffness = v,
                Field::Rest => body.rest = v,
            }
        })?;
        Ok(tree)
    }

    /// Steps as large as the body's validity allows, so that the
    /// columns' rounding stays below [`super::Base`]'s zero threshold
    /// (module docs).
    fn step_sizes(&self) -> Vec<f64> {
        let mut steps = Vec::with_capacity(self.base.len());
        let offsets = self.structure.body_offsets();
        for (b, o) in offsets.iter().enumerate() {
            let m = self.base[*o];
            let ic = self.tree.bodies[b].inertia;
            // more mass with m·c and I_O held: I_c grows
            steps.push(1.0 + m);
            for a in 0..3 {
                let h = self.base[o + 1 + a];
                steps.push(if h != 0.0 {
                    // m·c_a → −m·c_a: |c| and the diagonal of I_c unchanged
                    -2.0 * h
                } else {
                    // I_c loses s²/m on the two other axes: keep half
                    let other = (0..3)
                        .filter(|&x| x != a)
                        .map(|x| ic[x][x])
                        .fold(f64::INFINITY, f64::min);
                    let s = (0.5 * m * other).sqrt();
                    if s > 0.0 { s } else { 1e-3 * m }
                });
            }
            for x in &self.base[o + 4..o + 10] {
                steps.push(1.0 + x.abs());
            }
        }
        for x in &self.base[steps.len()..] {
            steps.push(1.0 + x.abs());
        }
        steps
    }

    /// The raw residual of a transition with bodies `tree`.
    fn raw(&self, tree: RobotTree, t: &Transition<'_>) -> Result<Vec<f64>, IdentifyError> {
        self.raw_in(&Self::engine(tree)?, t)
    }

    /// The engine of bodies `tree`, or why it refuses them.
    fn engine(tree: RobotTree) -> Result<Engine<RobotTree>, IdentifyError> {
        Engine::new(tree).map_err(|e| IdentifyError::Layout {
            message: format!("the robot with these parameters: {e}"),
        })
    }

    /// The raw residual of a transition on `engine`.
    fn raw_in(
        &self,
        engine: &Engine<RobotTree>,
        t: &Transition<'_>,
    ) -> Result<Vec<f64>, IdentifyError> {
        let n = engine.dof();
        for x in t.positions {
            check_finite_vector("positions", x, n)?;
        }
        // τ(u_{k−1}) (read by the midpoint rule only) and τ(u_k) on the
        // actuated joints
        let mut tau = [vec![0.0; n], vec![0.0; n]];
        let first = usize::from(self.alpha == 0.0);
        for (side, u) in tau.iter_mut().zip(t.inputs).skip(first) {
            if !u.is_empty() {
                check_finite_vector("inputs", u, self.inputs.len())?;
            }
            for (&j, &x) in self.inputs.iter().zip(u) {
                side[j] += x;
            }
        }
        let dt = self.dt;
        let [x0, x1, x2] = t.positions;
        let v0: Vec<f64> = (0..n).map(|i| (x1[i] - x0[i]) / dt).collect();
        let v1: Vec<f64> = (0..n).map(|i| (x2[i] - x1[i]) / dt).collect();
        let mut ws = vec![BodyScratch::default(); n];
        let mut r = vec![0.0; n];
        let err = |e| IdentifyError::Simulation {
            message: format!("tree engine: {e}"),
        };
        if self.alpha == 0.0 {
            let mut p0 = vec![0.0; n];
            engine.momentum_of(x0, &v0, &mut p0, &mut ws).map_err(err)?;
            engine
                .residual(x0, &v0, &p0, &tau[1], &v1, dt, &mut r, &mut ws)
                .map_err(err)?;
            return Ok(r);
        }
        // midpoint: P ± ½Δt·(F + τ) at each interval's midpoint
        let half = 0.5 * dt;
        let (mut p, mut dtdq, mut dvdq) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for (side, (a, b, v)) in [(x0, x1, &v0), (x1, x2, &v1)].into_iter().enumerate() {
            let m: Vec<f64> = (0..n).map(|i| 0.5 * (a[i] + b[i])).collect();
            engine
                .terms(&m, v, &mut p, &mut dtdq, &mut dvdq, &mut ws)
                .map_err(err)?;
            let sign = if side == 0 { 1.0 } else { -1.0 };
            for i in 0..n {
                let damping = engine.tree().bodies[i].damping;
                let f = dtdq[i] - dvdq[i] - damping * v[i] + tau[side][i];
                r[i] += sign * p[i] + half * f;
            }
        }
        Ok(r)
    }
}

impl Regressor for RobotRegressor {
    fn structure(&self) -> &Structure {
        &self.structure
    }

    fn coordinates(&self) -> usize {
        self.tree.bodies.len()
    }

    fn inputs(&self) -> usize {
        self.inputs.len()
    }

    fn rows(&self) -> usize {
        self.tree.bodies.len()
    }

    fn standard(&self) -> Vec<f64> {
        self.structure.standard(|i| self.get(&self.tree, i))
    }

    fn residual(&self, t: &Transition<'_>, pi: &[f64]) -> Result<DVector<f64>, IdentifyError> {
        Ok(DVector::from_vec(self.raw(self.tree_with(pi)?, t)?))
    }

    fn transition(
        &self,
        t: &Transition<'_>,
    ) -> Result<(DMatrix<f64>, DVector<f64>), IdentifyError> {
        let n = self.coordinates();
        let p = self.structure.len();
        let r0 = DVector::from_vec(self.raw(self.tree_with(&self.base)?, t)?);
        let mut y = DMatrix::zeros(n, p);
        let mut pi = self.base.clone();
        for i in 0..p {
            pi[i] = self.base[i] + self.steps[i];
            let ri = DVector::from_vec(self.raw(self.tree_with(&pi)?, t)?);
            pi[i] = self.base[i];
            y.set_column(i, &((ri - &r0) / self.steps[i]));
        }
        // A change at the rounding of the row's largest change is zero (a
        // parameter that does not enter this coordinate's residual, e.g.
        // the mass of a link turning about a vertical axis): left as
        // rounding, Base would scale it to a unit column and count it.
        for i in 0..n {
            let big = (0..p)
                .map(|j| (y[(i, j)] * self.steps[j]).abs())
                .fold(0.0, f64::max);
            for j in 0..p {
                if (y[(i, j)] * self.steps[j]).abs() <= ROUNDING * big {
                    y[(i, j)] = 0.0;
                }
            }
        }
        let b = &y * DVector::from_column_slice(&self.base) - r0;
        finite_rows((y, b))
    }

    /// The residual and its exact Jacobians in x_{k−1}, x_k and x_{k+1}
    /// from the engine's closed-form term derivatives
    /// ([`Engine::term_derivatives`], O(N²)). With the derivatives of P, of
    /// ∂T/∂q (T_q, T_v) and of ∇V (V_q) at each interval's point (0: the
    /// first, 1: the second; x_{k−1} and x_k under the first-order rule,
    /// the midpoints under the midpoint rule) and D the dampings:
    ///
    /// ```text
    /// first order:
    /// ∂r/∂x_{k−1} = P_q0 − P_v0/Δt
    /// ∂r/∂x_k     = P_v0/Δt − P_q1 + P_v1/Δt + Δt·(T_q1 − V_q1) − T_v1 + D
    /// ∂r/∂x_{k+1} = −P_v1/Δt + T_v1 − D
    /// midpoint, with G = P + ½Δt·F and H = ½Δt·F − P (F = ∂T/∂q − ∇V − D·v):
    /// ∂r/∂x_{k−1} = ½G_q0 − G_v0/Δt
    /// ∂r/∂x_k     = ½G_q0 + G_v0/Δt + ½H_q1 − H_v1/Δt
    /// ∂r/∂x_{k+1} = ½H_q1 + H_v1/Δt
    /// ```
    fn position_jacobians(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<(DVector<f64>, [DMatrix<f64>; 3]), IdentifyError> {
        let tree = self.tree_with(pi)?;
        let damping: Vec<f64> = tree.bodies.iter().map(|b| b.damping).collect();
        let engine = Self::engine(tree)?;
        let r = self.raw_in(&engine, t)?;
        let (n, h) = (damping.len(), self.dt);
        let [x0, x1, x2] = t.positions;
        let v0: Vec<f64> = (0..n).map(|i| (x1[i] - x0[i]) / h).collect();
        let v1: Vec<f64> = (0..n).map(|i| (x2[i] - x1[i]) / h).collect();
        let mut ws = vec![BodyScratch::default(); n];
        let terms = |q: &[f64], v: &[f64], ws: &mut [BodyScratch]| {
            TermJacobians::of(&engine, q, v, ws).map_err(|e| IdentifyError::Simulation {
                message: format!("tree engine: {e}"),
            })
        };
        let d = DMatrix::from_diagonal(&DVector::from_vec(damping));
        if self.alpha == 0.0 {
            let start = terms(x0, &v0, &mut ws)?;
            let TermJacobians {
                p_q: p_q1,
                p_v: p_v1,
                t_q: t_q1,
                t_v: t_v1,
                v_q: v_q1,
            } = terms(x1, &v1, &mut ws)?;
            let (p_q0, p_v0) = (start.p_q, start.p_v);
            let j0 = &p_q0 - &p_v0 / h;
            let j1 = &p_v0 / h - &p_q1 + &p_v1 / h + (&t_q1 - &v_q1) * h - &t_v1 + &d;
            let j2 = -&p_v1 / h + &t_v1 - &d;
            return Ok((DVector::from_vec(r), [j0, j1, j2]));
        }
        let mid = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a.iter().zip(b).map(|(a, b)| 0.5 * (a + b)).collect()
        };
        // (∂/∂q, ∂/∂v) of ½Δt·F ± P at one midpoint
        let halves = |j: TermJacobians, sign: f64| {
            let f_q = (&j.t_q - &j.v_q) * (0.5 * h);
            let f_v = (&j.t_v - &d) * (0.5 * h);
            (f_q + &j.p_q * sign, f_v + &j.p_v * sign)
        };
        let (g_q, g_v) = halves(terms(&mid(x0, x1), &v0, &mut ws)?, 1.0);
        let (h_q, h_v) = halves(terms(&mid(x1, x2), &v1, &mut ws)?, -1.0);
        let j0 = &g_q * 0.5 - &g_v / h;
        let j1 = &g_q * 0.5 + &g_v / h + &h_q * 0.5 - &h_v / h;
        let j2 = &h_q * 0.5 + &h_v / h;
        Ok((DVector::from_vec(r), [j0, j1, j2]))
    }

    fn noise_jacobian(
        &self,
        t: &Transition<'_>,
        pi: &[f64],
    ) -> Result<DMatrix<f64>, IdentifyError> {
        let tree = self.tree_with(pi)?;
        let x: [Vec<f64>; 3] = t.positions.map(|x| x.to_vec());
        position_differences(t.positions, |s, c, d| {
            let mut xs = x.clone();
            xs[s][c] += d;
            let moved = Transition {
                positions: [&xs[0], &xs[1], &xs[2]],
                inputs: t.inputs,
            };
            self.raw(tree.clone(), &moved).map(DVector::from_vec)
        })
    }
}
