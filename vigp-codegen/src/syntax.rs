//! The syntax of a description, planar and spatial alike: tokens → a
//! typed tree with spans (sections, links, joints, fields, values,
//! points). Nothing here judges meaning; [`crate::desc`] does.
//!
//! The two grammars differ only in their points: a spatial point has three
//! coordinates and one more anchor (`link.com`). [`Dim`] says which one is
//! read; it is chosen from the tokens before parsing ([`Dim::of`]).

use crate::number::Number;
use proc_macro2::{Delimiter, Span, TokenStream, TokenTree};
use syn::parse::{ParseStream, Parser};
use syn::{Attribute, Ident, Token, Visibility, braced, bracketed, parenthesized};

/// Which description a mechanism is: its gravity has two components
/// (or none) or three.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dim {
    /// Bodies in a plane: points `[x, y]`.
    Planar,
    /// Rigid bodies in space: points `[x, y, z]`.
    Spatial,
}

impl Dim {
    /// [`Dim::Spatial`] when the description's `gravity` has three
    /// components. Scans the tokens only; the planar checks report every
    /// other shape of `gravity`.
    pub fn of(input: &TokenStream) -> Dim {
        let Some(body) = input.clone().into_iter().find_map(|t| match t {
            TokenTree::Group(g) if g.delimiter() == Delimiter::Brace => Some(g.stream()),
            _ => None,
        }) else {
            return Dim::Planar;
        };
        let tokens: Vec<TokenTree> = body.into_iter().collect();
        for w in tokens.windows(3) {
            if let (TokenTree::Ident(key), TokenTree::Punct(colon), TokenTree::Group(g)) =
                (&w[0], &w[1], &w[2])
                && key == "gravity"
                && colon.as_char() == ':'
                && g.delimiter() == Delimiter::Bracket
            {
                return if components(g.stream()) == 3 {
                    Dim::Spatial
                } else {
                    Dim::Planar
                };
            }
        }
        Dim::Planar
    }

    /// The named points on a link.
    pub fn anchors(self) -> &'static [&'static str] {
        match self {
            Dim::Planar => &["start", "end", "center"],
            Dim::Spatial => &["start", "end", "center", "com"],
        }
    }

    /// How a point's coordinates are written.
    pub fn point(self) -> &'static str {
        match self {
            Dim::Planar => "[x, y]",
            Dim::Spatial => "[x, y, z]",
        }
    }
}

/// Number of comma-separated items (a trailing comma does not count).
fn components(stream: TokenStream) -> usize {
    let mut count = 0;
    let mut item = false;
    for t in stream {
        match t {
            TokenTree::Punct(p) if p.as_char() == ',' => {
                if item {
                    count += 1;
                }
                item = false;
            }
            _ => item = true,
        }
    }
    count + usize::from(item)
}

/// "a, b or c".
fn or_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

/// Items separated by commas, a trailing comma allowed (as
/// `ParseBuffer::parse_terminated`, for parsers that capture a [`Dim`]).
fn terminated<T>(
    input: ParseStream,
    mut item: impl FnMut(ParseStream) -> syn::Result<T>,
) -> syn::Result<Vec<T>> {
    let mut out = Vec::new();
    while !input.is_empty() {
        out.push(item(input)?);
        if input.is_empty() {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    Ok(out)
}

/// A number or a bracketed list of values; lists nest
/// (`[[1, 0, 0], [0, 1, 0], [0, 0, 1]]`).
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

    /// The numbers of a flat list of exactly `N` numbers, as an array.
    pub fn array<const N: usize>(&self) -> Option<[&Number; N]> {
        self.items(N)?.try_into().ok()
    }

    /// The numbers of a 3×3 nested list, row by row.
    pub fn matrix3(&self) -> Option<[[&Number; 3]; 3]> {
        match self {
            Value::Array(_, rows) if rows.len() == 3 => {
                Some([rows[0].array()?, rows[1].array()?, rows[2].array()?])
            }
            _ => None,
        }
    }

    fn parse(input: ParseStream) -> syn::Result<Self> {
        if input.peek(syn::token::Bracket) {
            let content;
            let b = bracketed!(content in input);
            let items = terminated(&content, Value::parse)?;
            Ok(Value::Array(b.span.join(), items))
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

impl Field {
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
        // `actuated: true` reads naturally but is not the syntax: name the
        // flag form instead of "expected a number"
        if input.peek(syn::LitBool) {
            let b: syn::LitBool = input.parse()?;
            // `actuated` is the DSL's one flag; every other key takes a number
            let msg = if key == "actuated" {
                format!(
                    "`{key}: {}`: no booleans here; a flag is written bare (`{key}`) to set \
                     it and left out to unset it",
                    b.value
                )
            } else {
                format!("`{key}` takes a number, not `{}`", b.value)
            };
            return Err(syn::Error::new(b.span(), msg));
        }
        let value = Value::parse(input)?;
        Ok(Field { key, value })
    }
}

fn parse_fields(input: ParseStream) -> syn::Result<Vec<Field>> {
    let content;
    braced!(content in input);
    terminated(&content, Field::parse)
}

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

    fn parse(input: ParseStream, dim: Dim) -> syn::Result<Self> {
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
