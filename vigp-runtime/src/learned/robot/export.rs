//! A trained [`LearnedRobot`] as Rust source for the `no_std`
//! [`vigp_core::tree::LearnedTreeStepper`]: the GP arrays, the bodies and
//! one `LearnedTree` static.

use core::fmt::Write;

use super::LearnedRobot;
use crate::gp::GpError;
use crate::learned::embedded::source_names;
use crate::learned::{EmbeddedExport, ExportSize};
use vigp_core::tree::{Body, JointKind};

/// A float literal that round-trips, ±∞ included (URDF limits).
fn lit(v: f64) -> String {
    if v == f64::INFINITY {
        "f64::INFINITY".into()
    } else if v == f64::NEG_INFINITY {
        "f64::NEG_INFINITY".into()
    } else {
        format!("{v:?}")
    }
}

fn v3(v: &[f64; 3]) -> String {
    format!("[{}, {}, {}]", lit(v[0]), lit(v[1]), lit(v[2]))
}

fn m3(m: &[[f64; 3]; 3]) -> String {
    format!("[{}, {}, {}]", v3(&m[0]), v3(&m[1]), v3(&m[2]))
}

/// One body as a struct expression of `{core}::tree::Body`.
fn body(b: &Body, core: &str) -> String {
    let l = &b.limits;
    format!(
        "    {core}::tree::Body {{\n\
         \x20       parent: {parent},\n\
         \x20       joint: {core}::tree::JointKind::{joint},\n\
         \x20       axis: {axis},\n\
         \x20       rotation: {rotation},\n\
         \x20       translation: {translation},\n\
         \x20       mass: {mass},\n\
         \x20       com: {com},\n\
         \x20       inertia: {inertia},\n\
         \x20       damping: {damping},\n\
         \x20       stiffness: {stiffness},\n\
         \x20       rest: {rest},\n\
         \x20       limits: {core}::tree::Limits {{ lower: {lo}, upper: {hi}, effort: {effort}, velocity: {vel} }},\n\
         \x20   }},\n",
        parent = b.parent.map_or("None".into(), |p| format!("Some({p})")),
        joint = match b.joint {
            JointKind::Revolute => "Revolute",
            JointKind::Prismatic => "Prismatic",
        },
        axis = v3(&b.axis),
        rotation = m3(&b.rotation),
        translation = v3(&b.translation),
        mass = lit(b.mass),
        com = v3(&b.com),
        inertia = m3(&b.inertia),
        damping = lit(b.damping),
        stiffness = lit(b.stiffness),
        rest = lit(b.rest),
        lo = lit(l.lower),
        hi = lit(l.upper),
        effort = lit(l.effort),
        vel = lit(l.velocity),
    )
}

impl LearnedRobot {
    /// This model as Rust source for
    /// [`vigp_core::tree::LearnedTreeStepper`]: static arrays of what the
    /// GP means need (as [`crate::learned::Learned::to_embedded_source`];
    /// with [`EmbeddedExport::variance`] also the Cholesky factors), a
    /// `<NAME>_BODIES` static of the prior's bodies (the identified ones
    /// under an identified prior) and a `LearnedTree` static named
    /// [`EmbeddedExport::name`]. The text compiles in a `#![no_std]`
    /// crate and is deterministic; floats round-trip exactly. On the
    /// target: `LearnedTreeStepper::new(&NAME)?.step(&z, &u_prev, &u, &mut
    /// [BodyScratch::zeroed(); N])`.
    pub fn to_embedded_source(
        &self,
        opts: &EmbeddedExport,
    ) -> Result<(String, ExportSize), GpError> {
        let m = &self.model;
        let bodies_name = format!("{}_BODIES", opts.name);
        let (mut s, gp_name) = opts.gp_source(&self.gp)?;
        let core = &opts.core_path;
        let d = self.gp.input_dim();
        let robot = &m.robot;
        let tree = robot.tree();
        let dof = robot.dof();
        let joints: Vec<String> = robot
            .joint_names()
            .iter()
            .map(|j| format!("{j:?}"))
            .collect();
        let inputs: Vec<String> = robot
            .input_names()
            .iter()
            .map(|j| format!("{j:?}"))
            .collect();
        let _ = write!(
            s,
            "\n/// The bodies of `{name}`'s prior, parents first.\n\
             #[rustfmt::skip]\n\
             pub static {bodies_name}: [{core}::tree::Body; {dof}] = [\n",
            name = opts.name
        );
        for b in &tree.bodies {
            s.push_str(&body(b, core));
        }
        s.push_str("];\n");
        let (encoding, prior) = source_names(&m.encoding, &m.prior);
        let o = robot.engine().options();
        let _ = write!(
            s,
            "\n/// The learned robot `{robot_name}` (Δt = {dt} s, {encoding} encoding, {prior} prior, \
             inputs [{input_list}]; GP input (enc(z), u_prev, u)):\n\
             /// `{core}::tree::LearnedTreeStepper::new(&{name})` steps it.\n\
             #[rustfmt::skip]\n\
             pub static {name}: {core}::tree::LearnedTree<'static, {dof}, {d}> = {core}::tree::LearnedTree {{\n\
             \x20   robot: {robot_name:?},\n\
             \x20   joints: [{joints}],\n\
             \x20   bodies: &{bodies_name},\n\
             \x20   gravity: {gravity},\n\
             \x20   inputs: &[{inputs}],\n\
             \x20   dt: {dtl},\n\
             \x20   encoding: {core}::learned::Encoding::{encoding},\n\
             \x20   prior: {core}::learned::Prior::{prior},\n\
             \x20   options: {core}::tree::EngineOptions {{ tolerance: {tol}, max_iterations: {iters}, max_depth: {depth}, max_contraction: {contraction}, energy_tolerance: {energy} }},\n\
             \x20   gps: &{gp_name},\n\
             }};\n",
            name = opts.name,
            robot_name = robot.name(),
            dt = m.dt,
            dtl = lit(m.dt),
            joints = joints.join(", "),
            inputs = inputs.join(", "),
            input_list = robot.input_names().join(", "),
            gravity = v3(&tree.gravity),
            tol = lit(o.tolerance),
            iters = o.max_iterations,
            depth = o.max_depth,
            contraction = lit(o.max_contraction),
            energy = lit(o.energy_tolerance),
        );
        let size = ExportSize::of(&self.gp, opts.variance, s.len());
        Ok((s, size))
    }
}
