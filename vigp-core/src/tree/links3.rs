//! A 3-D tree description (links with reference frames, revolute and
//! prismatic joints, [`crate::spatial`]'s conventions) as bodies of the
//! tree engine.
//!
//! The description's conventions: link c on joint j with parent p has the
//! orientation R_c = R_p·Rot(a, θ)·Q (a revolute joint; a the unit axis in
//! the parent link's frame, Q = R_p⁰ᵀR_c⁰ the reference relative
//! orientation), or R_c = R_p·Q with the child point moved by s·R_p·a (a
//! prismatic one); the parent point (in the parent link's frame, or in the
//! world) holds the child point (in the child link's frame).
//!
//! Each engine body's frame is its link's frame moved to the link's own
//! joint anchor. The joint frame then sits in the parent body's frame with
//! the rotation Q, at the parent point minus the parent's own anchor, and
//! the axis in the joint frame is Qᵀa; the centre of mass moves by the
//! anchor and the inertia stays as it is. Q and Qᵀa come from the
//! reference frames, which the macro knows; the points, masses and
//! inertias are the run-time parameters.

use super::model::{Body, JointKind, Limits, TreeArray};
use super::spatial::{M3, V3};
use crate::spatial::Link3;

/// One body of a 3-D tree in the description's terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link3Body {
    /// The parent body's index (smaller than this body's), `None` for the
    /// world.
    pub parent: Option<usize>,
    /// Revolute or prismatic.
    pub joint: JointKind,
    /// The unit axis in the joint frame: Qᵀa.
    pub axis: V3,
    /// The joint frame in the parent link's frame (the world's under the
    /// world): Q = R_p⁰ᵀR_c⁰.
    pub rotation: M3,
    /// Where the joint sits: in the parent link's frame, or in world
    /// coordinates under the world.
    pub at: V3,
    /// The point of this link that the joint holds, in its frame (the
    /// link's own anchor).
    pub anchor: V3,
    /// The link's mass, inertia about the centre of mass and centre of
    /// mass, in its frame.
    pub link: Link3,
    /// Viscous damping on the joint rate.
    pub damping: f64,
    /// Spring stiffness on the joint coordinate.
    pub stiffness: f64,
    /// Spring rest coordinate.
    pub rest: f64,
}

/// The bodies of a 3-D tree, parents first, under `gravity` (world axes).
pub fn link3_tree<const N: usize>(bodies: [Link3Body; N], gravity: V3) -> TreeArray<N> {
    let body = |b: &Link3Body| {
        let base = b.parent.map_or([0.0; 3], |p| bodies[p].anchor);
        Body {
            parent: b.parent,
            joint: b.joint,
            axis: b.axis,
            rotation: b.rotation,
            translation: core::array::from_fn(|i| b.at[i] - base[i]),
            mass: b.link.mass,
            com: core::array::from_fn(|i| b.link.com[i] - b.anchor[i]),
            inertia: b.link.inertia,
            damping: b.damping,
            stiffness: b.stiffness,
            rest: b.rest,
            limits: Limits::NONE,
        }
    };
    TreeArray {
        bodies: core::array::from_fn(|k| body(&bodies[k])),
        gravity,
    }
}
