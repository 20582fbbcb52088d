//! A 3-D tree description (revolute and prismatic joints, no loop) as
//! bodies of the linear-time tree engine: `Name::tree()` and
//! `Name::robot()` ([`crate::tree_items`]). The geometry is
//! `vigp::embedded::tree::links3`'s; the macro computes from the reference
//! frames, which it knows, each joint frame's rotation Q = R_p⁰ᵀR_c⁰ and
//! the axis in it, Qᵀa, and names the run-time points and parameters.

use super::emit::{anchor_expr, triple};
use crate::desc::spatial::{JointKind, Model};
use crate::target::Target;
use proc_macro2::TokenStream;
use quote::quote;

/// The tree items of `m`, or nothing when it has a loop or a joint other
/// than revolute and prismatic in its tree (the engine steps trees of
/// single coordinates).
pub fn emit(m: &Model, target: Target) -> TokenStream {
    let single = m.tree.iter().all(|&j| {
        matches!(
            m.joints[j].kind,
            JointKind::Revolute { .. } | JointKind::Prismatic { .. }
        )
    });
    if !m.loops.is_empty() || !single || m.tree.is_empty() {
        return quote!();
    }
    let core = quote!(::vigp::embedded::tree);
    let bodies = m.placement.iter().zip(&m.order).map(|(&j, &l)| {
        let joint = &m.joints[j];
        let ln = &m.links[l].name;
        let parent = crate::tree_items::parent_body(m, j);
        let (kind, a) = match joint.kind {
            JointKind::Revolute { axis } => (quote!(#core::JointKind::Revolute), axis),
            JointKind::Prismatic { axis } => (quote!(#core::JointKind::Prismatic), axis),
            _ => unreachable!("checked above: revolute or prismatic"),
        };
        let q = m.relative_rotation(joint);
        // Qᵀa
        let axis: [f64; 3] = core::array::from_fn(|i| (0..3).map(|k| q[k][i] * a[k]).sum());
        let rotation = q.map(triple);
        let axis = triple(axis);
        let at = anchor_expr(m, joint.parent);
        let anchor = anchor_expr(m, joint.child);
        let [damping, stiffness, rest] = crate::tree_items::joint_parameters(m, j);
        quote! {
            #core::links3::Link3Body {
                parent: #parent,
                joint: #kind,
                axis: #axis,
                rotation: [#(#rotation),*],
                at: #at,
                anchor: #anchor,
                link: links.#ln,
                damping: #damping,
                stiffness: #stiffness,
                rest: #rest,
            }
        }
    });
    let build = quote! {
        let links = &self.links;
        // frame rotations and axes computed by the macro (cos(π/4), …)
        // are exact values, not approximations of constants
        #[allow(clippy::approx_constant)]
        let bodies = [#(#bodies),*];
        #core::links3::link3_tree(bodies, self.gravity)
    };
    crate::tree_items::emit(m, build, |l| &l.name, target)
}
