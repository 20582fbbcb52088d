//! The description items of a mechanism, emitted next to [`crate::emit`]:
//! its name and named parameter list (`vigp::embedded::Parameters`, for the
//! parameter struct and, with the std runtime, for both coordinate views),
//! and with the std runtime the `vigp::System` impl that hands both views to
//! generic tools (the command-line tool, saved models).
//!
//! Kept apart from `emit` so that the kinematics generator can change
//! without touching what saved models record.

use crate::desc::planar::Model;
use crate::target::Target;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};
use syn::ext::IdentExt;

/// `(name, place)` of every parameter, in the order documented on
/// `vigp_core::Parameters`: `place` is the field path below `self`.
fn parameter_places(m: &Model) -> Vec<(String, TokenStream)> {
    let mut out = vec![
        ("gravity.x".to_string(), quote!(gravity[0])),
        ("gravity.y".to_string(), quote!(gravity[1])),
    ];
    for l in &m.links {
        let (ln, s) = (&l.name, l.name.unraw().to_string());
        out.push((format!("links.{s}.mass"), quote!(links.#ln.mass)));
        out.push((format!("links.{s}.length"), quote!(links.#ln.length)));
        out.push((format!("links.{s}.inertia"), quote!(links.#ln.inertia)));
        out.push((format!("links.{s}.com.x"), quote!(links.#ln.com[0])));
        out.push((format!("links.{s}.com.y"), quote!(links.#ln.com[1])));
    }
    out.extend(joint_places(
        m.joints.iter().map(|j| &j.name),
        m.dissipative(),
        m.elastic(),
    ));
    out
}

/// The joints' `(name, place)` pairs, planar and spatial alike: per joint
/// `damping` (a damped mechanism), then per joint `stiffness` and `rest`
/// (a mechanism with springs), in declaration order.
pub(crate) fn joint_places<'a>(
    joints: impl Iterator<Item = &'a syn::Ident> + Clone,
    dissipative: bool,
    elastic: bool,
) -> Vec<(String, TokenStream)> {
    let mut out = Vec::new();
    if dissipative {
        for jn in joints.clone() {
            let s = jn.unraw().to_string();
            out.push((format!("joints.{s}.damping"), quote!(joints.#jn.damping)));
        }
    }
    if elastic {
        for jn in joints {
            let s = jn.unraw().to_string();
            out.push((
                format!("joints.{s}.stiffness"),
                quote!(joints.#jn.stiffness),
            ));
            out.push((format!("joints.{s}.rest"), quote!(joints.#jn.rest)));
        }
    }
    out
}

/// `impl Parameters` for `ty` of the mechanism called `name`, whose
/// parameter struct is reached as `base` (`self` or `self.sys`); planar and
/// spatial mechanisms share it.
pub(crate) fn parameters_impl(
    name: &syn::Ident,
    ty: &TokenStream,
    base: &TokenStream,
    places: &[(String, TokenStream)],
) -> TokenStream {
    let name = name.unraw().to_string();
    let names = places.iter().map(|(n, _)| n);
    let read = places.iter().enumerate().map(|(i, (_, p))| {
        let i = Literal::usize_unsuffixed(i);
        quote!(#i => ::core::option::Option::Some(#base.#p),)
    });
    let write = places.iter().enumerate().map(|(i, (_, p))| {
        let i = Literal::usize_unsuffixed(i);
        quote!(#i => ::core::option::Option::Some(&mut #base.#p),)
    });
    quote! {
        impl ::vigp::embedded::Parameters for #ty {
            const NAME: &'static str = #name;
            const PARAMETER_NAMES: &'static [&'static str] = &[#(#names),*];
            fn parameter(&self, index: usize) -> ::core::option::Option<f64> {
                match index {
                    #(#read)*
                    _ => ::core::option::Option::None,
                }
            }
            fn parameter_mut(&mut self, index: usize) -> ::core::option::Option<&mut f64> {
                match index {
                    #(#write)*
                    _ => ::core::option::Option::None,
                }
            }
        }
    }
}

/// The `Parameters` implementation of the parameter struct alone (a
/// description without coordinate views: [`crate::planar_tree`]).
pub fn emit_own(m: &Model) -> TokenStream {
    let name = &m.name;
    parameters_impl(&m.name, &quote!(#name), &quote!(self), &parameter_places(m))
}

/// The description items of `m` for `target`.
pub fn emit(m: &Model, target: Target) -> TokenStream {
    let name = &m.name;
    let places = parameter_places(m);
    let own = parameters_impl(&m.name, &quote!(#name), &quote!(self), &places);
    if target != Target::Std {
        return own;
    }
    let minimal_ty = format_ident!("{}Minimal", name);
    let maximal_ty = format_ident!("{}Maximal", name);
    let minimal = parameters_impl(&m.name, &quote!(#minimal_ty), &quote!(self.sys), &places);
    let maximal = parameters_impl(&m.name, &quote!(#maximal_ty), &quote!(self.sys), &places);
    let n = Literal::usize_unsuffixed(m.dof());
    let c = Literal::usize_unsuffixed(m.loop_constraints());
    let nm = Literal::usize_unsuffixed(3 * m.links.len());
    // the maximal view: every joint is two constraint equations
    let cm = Literal::usize_unsuffixed(2 * m.joints.len());
    let u = Literal::usize_unsuffixed(m.inputs().len());
    quote! {
        #own
        #minimal
        #maximal
        impl ::vigp::System for #name {
            fn visit<V: ::vigp::ViewVisitor>(&self, visitor: V) -> V::Output {
                visitor.visit::<#minimal_ty, #maximal_ty, #n, #c, #nm, #cm, #u>(self.minimal(), self.maximal())
            }
        }
    }
}
