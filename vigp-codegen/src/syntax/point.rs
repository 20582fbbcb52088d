//! Points as written: `world`, `world @ [..]`, `link.start` and the other
//! named anchors of the dimension, `link @ [..]`.

use super::dim::Dim;
use super::value::Value;
use proc_macro2::Span;
use syn::parse::ParseStream;
use syn::{Ident, Token};

/// Where on a link a point sits, as written.
#[derive(Clone)]
pub enum Anchor {
    /// `link.start` (the link's origin).
    Start(Span),
    /// `link.end`: (length, 0[, 0]).
    End(Span),
    /// `link.center`: (length/2, 0[, 0]).
    Center(Span),
    /// `link.com`, the centre of mass (spatial only).
    Com(Span),
    /// `link @ [x, …]` in the link's coordinates.
    At(Value),
}

/// A point a joint attaches to, as written.
#[derive(Clone)]
pub enum PointRef {
    /// `world` or `world @ [x, …]`.
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

impl PointRef {
    /// The span a joint's point is reported at: `world` or the link name.
    pub fn span(&self) -> Span {
        match self {
            PointRef::World { span, .. } => *span,
            PointRef::Link { link, .. } => link.span(),
        }
    }

    pub(super) fn parse(input: ParseStream, dim: Dim) -> syn::Result<Self> {
        let quoted = |prefix: &str| -> Vec<String> {
            dim.anchors()
                .iter()
                .map(|a| format!("`{prefix}{a}`"))
                .collect()
        };
        let point = dim.point();
        let name: Ident = input.parse()?;
        if name == "world" {
            if input.peek(Token![.]) {
                return Err(syn::Error::new(
                    name.span(),
                    format!(
                        "the world has no {}: write `world` (the origin) or `world @ {point}`",
                        or_list(&quoted(""))
                    ),
                ));
            }
            let at = if input.parse::<Option<Token![@]>>()?.is_some() {
                Some(coordinates(input, dim)?)
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
                anchor: Anchor::At(coordinates(input, dim)?),
            });
        }
        if input.parse::<Option<Token![.]>>()?.is_none() {
            let mut forms = quoted(&format!("{name}."));
            forms.push(format!("`{name} @ {point}`"));
            return Err(syn::Error::new(
                name.span(),
                format!("expected {}", or_list(&forms)),
            ));
        }
        let which: Ident = input.parse()?;
        let s = which.span();
        let known = dim.anchors().iter().any(|a| which == a);
        let anchor = match which.to_string().as_str() {
            "start" => Anchor::Start(s),
            "end" => Anchor::End(s),
            "center" => Anchor::Center(s),
            "com" if known => Anchor::Com(s),
            _ => {
                let mut forms = quoted("");
                forms.push(format!("`@ {point}`"));
                return Err(syn::Error::new(
                    s,
                    format!(
                        "unknown attachment point `{which}`: expected {}",
                        or_list(&forms)
                    ),
                ));
            }
        };
        Ok(PointRef::Link { link: name, anchor })
    }
}

/// The coordinates after `@`. A planar point is checked here (two
/// numbers); a spatial one when the description is checked, among the
/// other errors.
fn coordinates(input: ParseStream, dim: Dim) -> syn::Result<Value> {
    let v = Value::parse(input)?;
    if dim == Dim::Planar && v.items(2).is_none() {
        return Err(syn::Error::new(
            v.span(),
            "expected a point `[x, y]` of two numbers",
        ));
    }
    Ok(v)
}

/// "a, b or c".
fn or_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}
