//! The parameter struct a description becomes, in either dimension:
//! `Name` (gravity, links, joints), `NameLinks`, `NameJoints` (only when a
//! joint declares damping or a spring) and `Default` with the declared
//! values. The planar and the spatial emitters give the link type and the
//! links' default values; everything else is written here once.

use crate::desc::{DefaultValue, Model};
use crate::lit::lit;
use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use syn::ext::IdentExt;
use syn::{Attribute, Ident};

/// The doc comments given, or a one-line doc when there are none.
pub(crate) fn doc_or(attrs: &[Attribute], fallback: String) -> TokenStream {
    if attrs.is_empty() {
        quote!(#[doc = #fallback])
    } else {
        quote!(#(#attrs)*)
    }
}

/// What the emitter of one dimension says of its links.
pub(crate) struct Links<'a, L> {
    /// The run-time link type (`::vigp::Link`, `::vigp::spatial::Link3`).
    pub ty: TokenStream,
    /// A link's name and doc comments.
    pub name: &'a dyn Fn(&L) -> (&Ident, &[Attribute]),
    /// Each link's `name: value,` in the `Default` impl.
    pub defaults: Vec<TokenStream>,
}

/// The parameter struct of `m` with its link and joint types and its
/// `Default` impl (preceded by `default_attrs`).
pub(crate) fn parameter_struct<L, K, A, const D: usize>(
    m: &Model<L, K, A, D>,
    links: Links<'_, L>,
    default_attrs: TokenStream,
) -> TokenStream {
    let Model {
        attrs, vis, name, ..
    } = m;
    let links_ty = format_ident!("{}Links", name);
    let joints_ty = format_ident!("{}Joints", name);
    let (dissipative, elastic) = (m.dissipative(), m.elastic());
    let link_ty = &links.ty;
    let link_fields = m.links.iter().map(|l| {
        let (ln, la) = (links.name)(l);
        let doc = doc_or(la, format!(" Link `{}`.", ln.unraw()));
        quote!(#doc pub #ln: #link_ty,)
    });
    let link_defaults = &links.defaults;
    let (joints_items, joints_field, joints_default) = if dissipative || elastic {
        let joint_ty = match (dissipative, elastic) {
            (true, true) => quote!(::vigp::ElasticJoint),
            (false, true) => quote!(::vigp::Spring),
            _ => quote!(::vigp::Joint),
        };
        let fields = m.joints.iter().map(|jt| {
            let jn = &jt.name;
            let doc = doc_or(&jt.attrs, format!(" Joint `{}`.", jn.unraw()));
            quote!(#doc pub #jn: #joint_ty,)
        });
        let defaults = m.joints.iter().map(|jt| {
            let value = |x: &Option<DefaultValue>| {
                x.as_ref().map_or_else(|| lit(0.0), DefaultValue::tokens)
            };
            let jn = &jt.name;
            let (d, k, r) = (value(&jt.damping), value(&jt.stiffness), value(&jt.rest));
            match (dissipative, elastic) {
                (true, true) => {
                    quote!(#jn: ::vigp::ElasticJoint { damping: #d, stiffness: #k, rest: #r },)
                }
                (false, true) => quote!(#jn: ::vigp::Spring { stiffness: #k, rest: #r },),
                _ => quote!(#jn: ::vigp::Joint { damping: #d },),
            }
        });
        let doc = format!(" Joint parameters of [`{}`].", name.unraw());
        let field_doc = match (dissipative, elastic) {
            (true, true) => " Joint parameters (damping and springs).",
            (false, true) => " Joint parameters (springs).",
            _ => " Joint parameters (damping).",
        };
        (
            quote! {
                #[doc = #doc]
                #[derive(Clone, Copy, Debug, PartialEq)]
                #vis struct #joints_ty { #(#fields)* }
            },
            quote!(#[doc = #field_doc] pub joints: #joints_ty,),
            quote!(joints: #joints_ty { #(#defaults)* },),
        )
    } else {
        (quote!(), quote!(), quote!())
    };
    let d = proc_macro2::Literal::usize_unsuffixed(D);
    let gravity = m.gravity.iter().map(DefaultValue::tokens);
    let links_doc = format!(" Link parameters of [`{}`].", name.unraw());
    quote! {
        #(#attrs)*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #name {
            #[doc = " Gravitational acceleration in world coordinates (m/s²)."]
            pub gravity: [f64; #d],
            #[doc = " Link parameters."]
            pub links: #links_ty,
            #joints_field
        }

        #[doc = #links_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #vis struct #links_ty { #(#link_fields)* }

        #joints_items

        #default_attrs
        impl ::core::default::Default for #name {
            fn default() -> Self {
                Self {
                    gravity: [#(#gravity),*],
                    links: #links_ty { #(#link_defaults)* },
                    #joints_default
                }
            }
        }
    }
}
