//! The tree engine's items of a description (planar or 3-D): the maps
//! between the engine's bodies (parents first) and the minimal
//! coordinates and inputs, `Name::tree()` (`no_std`) and `Name::robot()`
//! (std). Each dimension says how its bodies are built
//! ([`crate::planar_tree`], [`crate::spatial::tree`]); the items around
//! them are written here once.

use crate::desc::model::Model;
use crate::target::Target;
use proc_macro2::{Literal, TokenStream};
use quote::quote;
use syn::Ident;
use syn::ext::IdentExt;

/// The engine's index of the body that the joint `j`'s parent link is
/// (`None`: the world), as Rust.
pub fn parent_body<L, K, A, const D: usize>(m: &Model<L, K, A, D>, j: usize) -> TokenStream {
    let parent = m.joints[j]
        .parent
        .link()
        .and_then(|l| m.order.iter().position(|&o| o == l));
    match parent {
        Some(p) => {
            let p = Literal::usize_unsuffixed(p);
            quote!(::core::option::Option::Some(#p))
        }
        None => quote!(::core::option::Option::None),
    }
}

/// Joint `j`'s damping, stiffness and rest read from the run-time
/// parameters (0 where the description declares none).
pub fn joint_parameters<L, K, A, const D: usize>(
    m: &Model<L, K, A, D>,
    j: usize,
) -> [TokenStream; 3] {
    let jn = &m.joints[j].name;
    let damping = if m.dissipative() {
        quote!(self.joints.#jn.damping)
    } else {
        quote!(0.0)
    };
    if m.elastic() {
        [
            damping,
            quote!(self.joints.#jn.stiffness),
            quote!(self.joints.#jn.rest),
        ]
    } else {
        [damping, quote!(0.0), quote!(0.0)]
    }
}

/// The items of a tree description `m` (bodies in its placement order)
/// whose `TreeArray` the expression `build` (of `self`) makes, in one
/// `impl` block of the parameter struct; `robot()` only for std.
pub fn emit<L, K, A, const D: usize>(
    m: &Model<L, K, A, D>,
    build: TokenStream,
    link_name: impl Fn(&L) -> &Ident,
    target: Target,
) -> TokenStream {
    let t = TreeItems {
        coordinates: m
            .placement
            .iter()
            .map(|&j| m.coordinate_of(j).expect("a tree joint has a coordinate"))
            .collect(),
        inputs: m
            .inputs()
            .iter()
            .map(|&j| {
                let body = m.placement.iter().position(|&p| p == j);
                body.expect("an actuated tree joint places a body")
            })
            .collect(),
        joint_names: m.placement.iter().map(|&j| &m.joints[j].name).collect(),
        link_names: m.order.iter().map(|&l| link_name(&m.links[l])).collect(),
        input_names: m.inputs().into_iter().map(|j| &m.joints[j].name).collect(),
    };
    items(&m.name, &build, &t, target)
}

/// What the items need of a description, per body and per input.
struct TreeItems<'a> {
    /// Per body: its minimal coordinate.
    coordinates: Vec<usize>,
    /// Per input: the body it drives.
    inputs: Vec<usize>,
    /// Per body: the joint that places it.
    joint_names: Vec<&'a Ident>,
    /// Per body: its link.
    link_names: Vec<&'a Ident>,
    /// The actuated joints in declaration order.
    input_names: Vec<&'a Ident>,
}

fn items(name: &Ident, build: &TokenStream, t: &TreeItems, target: Target) -> TokenStream {
    let core = quote!(::vigp::embedded::tree);
    let n = Literal::usize_unsuffixed(t.coordinates.len());
    let u = Literal::usize_unsuffixed(t.inputs.len());
    let coordinates = t.coordinates.iter().map(|&c| Literal::usize_unsuffixed(c));
    let inputs = t.inputs.iter().map(|&b| Literal::usize_unsuffixed(b));
    let doc_tree = format!(
        " The mechanism as the bodies of the linear-time tree engine, from these \
         parameters, parents first (body `k` is minimal coordinate \
         [`{name}::TREE_COORDINATES`]`[k]`): `vigp::embedded::tree::Engine::new(sys.tree())` \
         steps it in O(N) per residual and per solve, without allocation. The \
         engine's first-order step is that of `Variational::new(sys.minimal(), dt)`."
    );
    // only what is declared: no input items without `actuated`
    let (tree_inputs, actuated) = if t.inputs.is_empty() {
        (quote!(), quote!())
    } else {
        let names = t.input_names.iter().map(|i| i.unraw().to_string());
        (
            quote! {
                #[doc = " The body of [`Self::tree`] that each input drives (the `actuated` joints in declaration order)."]
                pub const TREE_INPUTS: [usize; #u] = [#(#inputs),*];
            },
            quote!(?.with_actuated(&[#(#names),*])),
        )
    };
    let robot = if target == Target::Std {
        let unraw = |names: &[&Ident]| -> Vec<String> {
            names.iter().map(|i| i.unraw().to_string()).collect()
        };
        let (joints, links) = (unraw(&t.joint_names), unraw(&t.link_names));
        let name_str = name.unraw().to_string();
        quote! {
            #[doc = " The mechanism as a [`vigp::Robot`] on the tree engine (its coordinates in [`Self::TREE_COORDINATES`] order, inputs on the `actuated` joints in declaration order): the std road of a robot (rollouts, exact A and B, `vigp::learned::robot`). A parameter out of its domain is a [`vigp::RobotError`]."]
            pub fn robot(&self) -> ::core::result::Result<::vigp::Robot, ::vigp::RobotError> {
                let tree = self.tree();
                ::vigp::Robot::from_bodies(
                    #name_str,
                    &tree.bodies,
                    tree.gravity,
                    &[#(#joints),*],
                    &[#(#links),*],
                )
                #actuated
            }
        }
    } else {
        quote!()
    };
    quote! {
        impl #name {
            #[doc = " The minimal coordinate of each body of [`Self::tree`] (bodies come parents first; coordinates follow the tree joints' declaration order)."]
            pub const TREE_COORDINATES: [usize; #n] = [#(#coordinates),*];
            #tree_inputs

            #[doc = #doc_tree]
            pub fn tree(&self) -> #core::TreeArray<#n> {
                #build
            }

            #robot
        }
    }
}
