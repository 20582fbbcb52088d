//! The syntax of a description, planar and spatial alike: tokens → a
//! typed tree with spans (sections, links, joints, fields, values,
//! points). Nothing here judges meaning; [`crate::desc`] does.
//!
//! The two grammars differ only in their points: a spatial point has three
//! coordinates and one more anchor (`link.com`). [`Dim`] says which one is
//! read; it is chosen from the tokens before parsing ([`Dim::of`]).

mod dim;
mod list;
mod point;
mod value;

pub use dim::Dim;
pub use point::{Anchor, PointRef};
pub use value::{Field, Value};

use list::terminated;
use proc_macro2::TokenStream;
use syn::parse::{ParseStream, Parser};
use syn::{Attribute, Ident, Token, Visibility, braced, parenthesized};
use value::parse_fields;

/// A value (a number or a bracketed list), for grammars built on this one.
pub fn parse_value(input: ParseStream) -> syn::Result<Value> {
    Value::parse(input)
}

/// `{ key: value, flag, … }`, for grammars built on this one.
pub fn parse_field_block(input: ParseStream) -> syn::Result<Vec<Field>> {
    parse_fields(input)
}

/// `/// doc  name: { key: value, … }`
#[derive(Clone)]
pub struct LinkDecl {
    /// Outer attributes (doc comments).
    pub attrs: Vec<Attribute>,
    /// Link name.
    pub name: Ident,
    /// Its fields.
    pub fields: Vec<Field>,
}

impl LinkDecl {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let name = input.parse()?;
        input.parse::<Token![:]>()?;
        let fields = parse_fields(input)?;
        Ok(LinkDecl {
            attrs,
            name,
            fields,
        })
    }
}

/// `/// doc  name: kind(parent, child) { key: value, … }`
#[derive(Clone)]
pub struct JointDecl {
    /// Outer attributes (doc comments).
    pub attrs: Vec<Attribute>,
    /// Joint name.
    pub name: Ident,
    /// Joint type keyword (`revolute`, …), judged by [`crate::desc`].
    pub kind: Ident,
    /// Parent point.
    pub parent: PointRef,
    /// Child point.
    pub child: PointRef,
    /// Optional fields.
    pub fields: Vec<Field>,
}

impl JointDecl {
    fn parse(input: ParseStream, dim: Dim) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let name = input.parse()?;
        input.parse::<Token![:]>()?;
        let kind = input.parse()?;
        let content;
        parenthesized!(content in input);
        let parent = PointRef::parse(&content, dim)?;
        content.parse::<Token![,]>()?;
        let child = PointRef::parse(&content, dim)?;
        content.parse::<Option<Token![,]>>()?;
        if !content.is_empty() {
            return Err(content.error("expected `(parent_point, child_point)`"));
        }
        let fields = if input.peek(syn::token::Brace) {
            parse_fields(input)?
        } else {
            Vec::new()
        };
        Ok(JointDecl {
            attrs,
            name,
            kind,
            parent,
            child,
            fields,
        })
    }
}

/// The whole description.
#[derive(Clone)]
pub struct Input {
    /// Which grammar it was read with.
    pub dim: Dim,
    /// Outer attributes of the mechanism (doc comments; derives are not allowed).
    pub attrs: Vec<Attribute>,
    /// Visibility of the generated types.
    pub vis: Visibility,
    /// Name of the generated parameter type.
    pub name: Ident,
    /// `gravity: [..]`, with the key.
    pub gravity: Option<(Ident, Value)>,
    /// `links { … }` with the keyword.
    pub links: Option<(Ident, Vec<LinkDecl>)>,
    /// `joints { … }` with the keyword.
    pub joints: Option<(Ident, Vec<JointDecl>)>,
}

impl Input {
    /// Parse a `mechanism!` body with the grammar of `dim`.
    pub fn parse2(tokens: TokenStream, dim: Dim) -> syn::Result<Input> {
        (|input: ParseStream| Input::parse(input, dim)).parse2(tokens)
    }

    fn parse(input: ParseStream, dim: Dim) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis = input.parse()?;
        let name = input.parse()?;
        let content;
        braced!(content in input);
        if !input.is_empty() {
            return Err(input.error("unexpected tokens after the mechanism body"));
        }
        let mut out = Input {
            dim,
            attrs,
            vis,
            name,
            gravity: None,
            links: None,
            joints: None,
        };
        while !content.is_empty() {
            let key: Ident = content.parse()?;
            match key.to_string().as_str() {
                "gravity" => {
                    content.parse::<Token![:]>()?;
                    let v = Value::parse(&content)?;
                    section(&mut out.gravity, key, v)?;
                }
                "links" => {
                    let inner;
                    braced!(inner in content);
                    let links = terminated(&inner, LinkDecl::parse)?;
                    section(&mut out.links, key, links)?;
                }
                "joints" => {
                    let inner;
                    braced!(inner in content);
                    let joints = terminated(&inner, |i| JointDecl::parse(i, dim))?;
                    section(&mut out.joints, key, joints)?;
                }
                _ => {
                    return Err(syn::Error::new(
                        key.span(),
                        format!("unknown section `{key}`: expected `gravity`, `links` or `joints`"),
                    ));
                }
            }
            content.parse::<Option<Token![,]>>()?;
        }
        Ok(out)
    }
}

/// Fill a section's slot, or an error at a second `key` section.
fn section<T>(slot: &mut Option<(Ident, T)>, key: Ident, value: T) -> syn::Result<()> {
    if slot.is_some() {
        return Err(syn::Error::new(
            key.span(),
            format!("duplicate section `{key}`"),
        ));
    }
    *slot = Some((key, value));
    Ok(())
}
