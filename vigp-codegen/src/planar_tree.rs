//! A planar tree description as bodies of the linear-time tree engine:
//! `Name::tree()` (`no_std`: the bodies from the run-time parameters, no
//! allocation) and `Name::robot()` (std: a `vigp::Robot` over them), with
//! the maps between the engine's body order and the minimal coordinates.
//! The geometry is `vigp::embedded::tree::planar`'s; this module only
//! names each body's parent, joint, anchors and parameters. A description
//! with loops gets none of it (the engine steps trees).

use crate::desc::planar::{JointKind, Model, Point};
use crate::emit::{ParameterItems, anchor_local, parameter_items};
use crate::lit::lit;
use crate::target::Target;
use proc_macro2::TokenStream;
use quote::quote;

/// The tree items of `m`, or nothing when it has loops.
pub fn emit(m: &Model, target: Target) -> TokenStream {
    if !m.loops.is_empty() {
        return quote!();
    }
    let core = quote!(::vigp::embedded::tree);
    let params = quote!(self);
    // body k is placed by joint m.placement[k]; its link is m.order[k]
    let bodies = m.placement.iter().zip(&m.order).map(|(&j, &l)| {
        let joint = &m.joints[j];
        let ln = &m.links[l].name;
        let parent = crate::tree_items::parent_body(m, j);
        let kind = match joint.kind {
            JointKind::Revolute => quote!(#core::planar::PlanarJoint::Revolute),
            JointKind::Prismatic { axis } => {
                let (x, y) = (lit(axis[0]), lit(axis[1]));
                quote!(#core::planar::PlanarJoint::Prismatic { axis: [#x, #y] })
            }
        };
        let at = match joint.parent {
            Point::World(w) => {
                let (x, y) = (lit(w[0]), lit(w[1]));
                quote!([#x, #y])
            }
            Point::Link { link, anchor } => anchor_local(m, &params, link, anchor),
        };
        let anchor = match joint.child {
            Point::Link { link, anchor } => anchor_local(m, &params, link, anchor),
            Point::World(_) => unreachable!("a tree joint's child is a link"),
        };
        let [damping, stiffness, rest] = crate::tree_items::joint_parameters(m, j);
        quote! {
            #core::planar::PlanarBody {
                parent: #parent,
                joint: #kind,
                at: #at,
                anchor: #anchor,
                link: self.links.#ln,
                damping: #damping,
                stiffness: #stiffness,
                rest: #rest,
            }
        }
    });
    let tree = quote!(#core::planar::planar_tree([#(#bodies),*], self.gravity));
    crate::tree_items::emit(m, tree, |l| &l.name, target)
}

/// The longest path from the world, in tree joints, above which the
/// closed-form terms are not attempted: a chain of 14 links expands to
/// 7.8 MB of Rust in 1.3 s of macro time, each further link about 1.5×
/// both, past [`crate::MAX_PLANAR_EXPANSION`].
pub const MAX_CLOSED_FORM_DEPTH: usize = 14;

/// The number of tree joints on the longest path from the world.
pub fn depth(m: &Model) -> usize {
    let mut depth = vec![0usize; m.links.len()];
    for (&j, &l) in m.placement.iter().zip(&m.order) {
        depth[l] = 1 + m.joints[j].parent.link().map_or(0, |p| depth[p]);
    }
    depth.into_iter().max().unwrap_or(0)
}

/// The whole expansion of a planar tree whose closed-form terms would be
/// too large to compile: the parameter types, forward kinematics and the
/// tree engine's items, without the coordinate views (`minimal()`,
/// `maximal()`), which the struct's documentation says.
pub fn emit_tree_only(m: &Model, target: Target, why: &str) -> TokenStream {
    let mut m = m.clone();
    let note = format!(
        " This mechanism has no closed-form coordinate views (`minimal()`, \
         `maximal()`): {why}. It steps on the linear-time tree engine: \
         `vigp::embedded::tree::Engine::new(sys.tree())` (`no_std`), or \
         `sys.robot()` (std: rollouts, exact A and B, learned robots)."
    );
    if !m.attrs.is_empty() {
        m.attrs.push(syn::parse_quote!(#[doc = ""]));
    }
    m.attrs.push(syn::parse_quote!(#[doc = #note]));
    let ParameterItems {
        types,
        consts,
        link_poses,
    } = parameter_items(&m);
    let name = &m.name;
    let own = crate::describe::emit_own(&m);
    let tree = emit(&m, target);
    quote! {
        #types

        impl #name {
            #consts

            #link_poses
        }

        #own

        #tree
    }
}
