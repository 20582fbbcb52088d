//! Syntax of a spatial description: tokens → an unvalidated description
//! with spans. Values nest (`[[1, 0, 0], [0, 1, 0], [0, 0, 1]]`); points
//! take any bracketed value after `@` (the model checks it has three
//! numbers).

use crate::parse::Number;
use proc_macro2::Span;
use syn::parse::{Parse, ParseStream};
use syn::{Attribute, Ident, Token, Visibility, braced, bracketed, parenthesized};

/// A number or a bracketed list of values.
#[derive(Clone)]
pub enum Value {
    /// `1.5`
    Number(Number),
    /// `[a, b, …]` with the span of the brackets.
    Array(Span, Vec<Value>),
    /// A key written without `: value` (`actuated`), with the key's span.
    Flag(Span),
}

impl Value {
    /// Span of the whole value.
    pub fn span(&self) -> Span {
        match self {
            Value::Number(n) => n.span(),
            Value::Array(s, _) | Value::Flag(s) => *s,
        }
    }

    /// The numbers of a flat list of exactly `n` numbers.
    pub fn items(&self, n: usize) -> Option<Vec<&Number>> {
        match self {
            Value::Array(_, items) if items.len() == n => items
                .iter()
                .map(|v| match v {
                    Value::Number(x) => Some(x),
                    Value::Array(..) | Value::Flag(_) => None,
                })
                .collect(),
            _ => None,
        }
    }

    /// The numbers of a 3×3 nested list, row by row.
    pub fn matrix3(&self) -> Option<[[&Number; 3]; 3]> {
        match self {
            Value::Array(_, rows) if rows.len() == 3 => {
                let row = |i: usize| -> Option<[&Number; 3]> {
                    let r = rows[i].items(3)?;
                    Some([r[0], r[1], r[2]])
                };
                Some([row(0)?, row(1)?, row(2)?])
            }
            _ => None,
        }
    }
}

impl Parse for Value {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        if input.peek(syn::token::Bracket) {
            let content;
            let b = bracketed!(content in input);
            let items = content.parse_terminated(Value::parse, Token![,])?;
            Ok(Value::Array(b.span.join(), items.into_iter().collect()))
        } else {
            Ok(Value::Number(input.parse()?))
        }
    }
}

/// `key: value`, or a bare `key` (a flag, [`Value::Flag`]).
#[derive(Clone)]
pub struct Field {
    /// Key.
    pub key: Ident,
    /// Value.
    pub value: Value,
}

impl Parse for Field {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let key: Ident = input.parse()?;
        if input.is_empty() || input.peek(Token![,]) {
            let span = key.span();
            return Ok(Field {
                key,
                value: Value::Flag(span),
            });
        }
        input.parse::<Token![:]>()?;
        let value = input.parse()?;
        Ok(Field { key, value })
    }
}

fn parse_fields(input: ParseStream) -> syn::Result<Vec<Field>> {
    let content;
    braced!(content in input);
    Ok(content
        .parse_terminated(Field::parse, Token![,])?
        .into_iter()
        .collect())
}

/// Where on a link a point sits.
#[derive(Clone)]
pub enum Anchor {
    /// `link.start` (the frame origin).
    Start(Span),
    /// `link.end`: (length, 0, 0).
    End(Span),
    /// `link.center`: (length/2, 0, 0).
    Center(Span),
    /// `link.com`: the centre of mass.
    Com(Span),
    /// `link @ [x, y, z]` in the link frame.
    At(Value),
}

/// A point a joint attaches to.
#[derive(Clone)]
pub enum PointRef {
    /// `world` or `world @ [x, y, z]`.
    World {
        /// The `world` keyword.
        span: Span,
        /// World coordinates (origin if absent).
        at: Option<Value>,
    },
    /// A point on a link.
    Link {
        /// Link name.
        link: Ident,
        /// Anchor on the link.
        anchor: Anchor,
    },
}

impl Parse for PointRef {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let name: Ident = input.parse()?;
        if name == "world" {
            if input.peek(Token![.]) {
                return Err(syn::Error::new(
                    name.span(),
                    "the world has no `start`, `end`, `center` or `com`: write `world` (the origin) or `world @ [x, y, z]`",
                ));
            }
            let at = if input.parse::<Option<Token![@]>>()?.is_some() {
                Some(input.parse()?)
            } else {
                None
            };
            return Ok(PointRef::World {
                span: name.span(),
                at,
            });
        }
        if input.parse::<Option<Token![@]>>()?.is_some() {
            return Ok(PointRef::Link {
                link: name,
                anchor: Anchor::At(input.parse()?),
            });
        }
        if input.parse::<Option<Token![.]>>()?.is_none() {
            return Err(syn::Error::new(
                name.span(),
                format!(
                    "expected `{name}.start`, `{name}.end`, `{name}.center`, `{name}.com` or `{name} @ [x, y, z]`"
                ),
            ));
        }
        let which: Ident = input.parse()?;
        let s = which.span();
        let anchor = match which.to_string().as_str() {
            "start" => Anchor::Start(s),
            "end" => Anchor::End(s),
            "center" => Anchor::Center(s),
            "com" => Anchor::Com(s),
            _ => {
                return Err(syn::Error::new(
                    s,
                    format!(
                        "unknown attachment point `{which}`: expected `start`, `end`, `center`, `com` or `@ [x, y, z]`"
                    ),
                ));
            }
        };
        Ok(PointRef::Link { link: name, anchor })
    }
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

impl Parse for LinkDecl {
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
    /// Joint type keyword.
    pub kind: Ident,
    /// Parent point.
    pub parent: PointRef,
    /// Child point.
    pub child: PointRef,
    /// Optional fields.
    pub fields: Vec<Field>,
}

impl Parse for JointDecl {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let name = input.parse()?;
        input.parse::<Token![:]>()?;
        let kind = input.parse()?;
        let content;
        parenthesized!(content in input);
        let parent = content.parse()?;
        content.parse::<Token![,]>()?;
        let child = content.parse()?;
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
    /// Outer attributes of the mechanism.
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

impl Parse for Input {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis = input.parse()?;
        let name = input.parse()?;
        let content;
        braced!(content in input);
        if !input.is_empty() {
            return Err(input.error("unexpected tokens after the mechanism body"));
        }
        let mut out = Input {
            attrs,
            vis,
            name,
            gravity: None,
            links: None,
            joints: None,
        };
        while !content.is_empty() {
            let key: Ident = content.parse()?;
            let duplicate = || syn::Error::new(key.span(), format!("duplicate section `{key}`"));
            match key.to_string().as_str() {
                "gravity" => {
                    content.parse::<Token![:]>()?;
                    let v = content.parse()?;
                    if out.gravity.is_some() {
                        return Err(duplicate());
                    }
                    out.gravity = Some((key, v));
                }
                "links" => {
                    let inner;
                    braced!(inner in content);
                    let links = inner.parse_terminated(LinkDecl::parse, Token![,])?;
                    if out.links.is_some() {
                        return Err(duplicate());
                    }
                    out.links = Some((key, links.into_iter().collect()));
                }
                "joints" => {
                    let inner;
                    braced!(inner in content);
                    let joints = inner.parse_terminated(JointDecl::parse, Token![,])?;
                    if out.joints.is_some() {
                        return Err(duplicate());
                    }
                    out.joints = Some((key, joints.into_iter().collect()));
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
