//! Syntax of the `mechanism!` DSL: tokens → an unvalidated description with
//! spans. Nothing here judges meaning; `model` does.

use proc_macro2::Span;
use syn::parse::{Parse, ParseStream};
use syn::{Attribute, Ident, Token, Visibility, braced, bracketed, parenthesized};

/// A number: a literal, arithmetic of literals (`0.5 * 3.0`), or a Rust
/// expression the compiler evaluates (`2.0 * M`, `core::f64::consts::PI`).
#[derive(Clone)]
pub struct Number {
    /// The value when the macro can compute it: literals, unary `-` and
    /// `+ - * /` of literals (evaluated in f64; integer literals count as
    /// f64), always finite. `None` when the expression names something
    /// (a constant, a function): then only the compiler knows the value.
    pub value: Option<f64>,
    /// The expression as written.
    pub expr: Box<syn::Expr>,
}

impl Number {
    /// An error that points at the whole expression, minus sign included.
    pub fn error(&self, msg: impl std::fmt::Display) -> syn::Error {
        syn::Error::new_spanned(&self.expr, msg)
    }

    /// The span of the expression's first token.
    pub fn span(&self) -> Span {
        syn::spanned::Spanned::span(&self.expr)
    }

    /// The value, which `what` needs when the macro runs: an error naming
    /// the expression when it refers to a constant or function.
    pub fn known(&self, what: &str) -> syn::Result<f64> {
        self.value.ok_or_else(|| {
            self.error(format!(
                "{what} must be a number the macro can evaluate (literals and `+ - * /` of literals): it shapes the generated code. Only run-time parameters (mass, length, inertia, com, damping, stiffness, rest, gravity) may name constants"
            ))
        })
    }
}

/// The value of a literal-only expression: `Ok(None)` when it refers to
/// anything else, an error for a literal that is not a number, a suffix
/// other than `f64`, or a non-finite result.
fn fold(e: &syn::Expr) -> syn::Result<Option<f64>> {
    use syn::{BinOp, Expr, Lit, UnOp};
    let value = match e {
        Expr::Lit(lit) => {
            let (value, suffix) = match &lit.lit {
                Lit::Float(f) => (f.base10_parse::<f64>()?, f.suffix().to_owned()),
                Lit::Int(i) => (i.base10_parse::<f64>()?, i.suffix().to_owned()),
                other => return Err(syn::Error::new(other.span(), "expected a number")),
            };
            // Every parameter is an f64; a suffix such as `1u8` or `1.5f32`
            // would be silently ignored, so it is rejected.
            if !suffix.is_empty() && suffix != "f64" {
                return Err(syn::Error::new(
                    lit.lit.span(),
                    format!("unexpected suffix `{suffix}`: parameters are plain numbers (f64)"),
                ));
            }
            if !value.is_finite() {
                return Err(syn::Error::new(
                    lit.lit.span(),
                    "number is too large for an f64",
                ));
            }
            return Ok(Some(value));
        }
        Expr::Paren(p) => return fold(&p.expr),
        Expr::Group(g) => return fold(&g.expr),
        Expr::Unary(u) if matches!(u.op, UnOp::Neg(_)) => fold(&u.expr)?.map(|x| -x),
        Expr::Binary(b)
            if matches!(
                b.op,
                BinOp::Add(_) | BinOp::Sub(_) | BinOp::Mul(_) | BinOp::Div(_)
            ) =>
        {
            // both sides are folded so that a bad literal anywhere is reported
            let (l, r) = (fold(&b.left)?, fold(&b.right)?);
            match (l, r) {
                (Some(l), Some(r)) => Some(match b.op {
                    BinOp::Add(_) => l + r,
                    BinOp::Sub(_) => l - r,
                    BinOp::Mul(_) => l * r,
                    _ => l / r,
                }),
                _ => None,
            }
        }
        _ => None,
    };
    match value {
        Some(x) if !x.is_finite() => Err(syn::Error::new_spanned(
            e,
            format!("this evaluates to {x}, not a finite number"),
        )),
        v => Ok(v),
    }
}

impl Parse for Number {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        if input.is_empty() || input.peek(Token![,]) {
            return Err(input.error("expected a number"));
        }
        let expr: Box<syn::Expr> = input.parse()?;
        let value = fold(&expr)?;
        Ok(Number { value, expr })
    }
}

/// A value: a number or a bracketed list of numbers, or nothing (a bare
/// flag such as `actuated`).
#[derive(Clone)]
pub enum Value {
    /// `1.5`
    Number(Number),
    /// `[1.0, 2.0]` with the span of the brackets.
    Array(Span, Vec<Number>),
    /// A key written without `: value` (the key's span).
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
}

impl Parse for Value {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        if input.peek(syn::token::Bracket) {
            let content;
            let b = bracketed!(content in input);
            let items = content.parse_terminated(Number::parse, Token![,])?;
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
    /// `link.start` (local origin).
    Start,
    /// `link.end` (local (length, 0)).
    End,
    /// `link.center` (local (length/2, 0)).
    Center,
    /// `link @ [x, y]` (local coordinates).
    At([Number; 2]),
}

/// A point a joint attaches to.
#[derive(Clone)]
pub enum PointRef {
    /// `world` or `world @ [x, y]`.
    World {
        /// The `world` keyword.
        span: Span,
        /// World coordinates (origin if absent).
        at: Option<[Number; 2]>,
    },
    /// `link.start`, `link.end`, `link.center` or `link @ [x, y]`.
    Link {
        /// Link name.
        link: Ident,
        /// Anchor on the link.
        anchor: Anchor,
    },
}

fn parse_pair(input: ParseStream) -> syn::Result<[Number; 2]> {
    let v: Value = input.parse()?;
    match v {
        Value::Array(_, ref items) if items.len() == 2 => Ok([items[0].clone(), items[1].clone()]),
        other => Err(syn::Error::new(
            other.span(),
            "expected a point `[x, y]` of two numbers",
        )),
    }
}

impl Parse for PointRef {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let name: Ident = input.parse()?;
        if name == "world" {
            if input.peek(Token![.]) {
                return Err(syn::Error::new(
                    name.span(),
                    "the world has no `start`, `end` or `center`: write `world` (the origin) or `world @ [x, y]`",
                ));
            }
            let at = if input.parse::<Option<Token![@]>>()?.is_some() {
                Some(parse_pair(input)?)
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
                anchor: Anchor::At(parse_pair(input)?),
            });
        }
        if input.parse::<Option<Token![.]>>()?.is_none() {
            return Err(syn::Error::new(
                name.span(),
                format!(
                    "expected `{name}.start`, `{name}.end`, `{name}.center` or `{name} @ [x, y]`"
                ),
            ));
        }
        let which: Ident = input.parse()?;
        let anchor = match which.to_string().as_str() {
            "start" => Anchor::Start,
            "end" => Anchor::End,
            "center" => Anchor::Center,
            _ => {
                return Err(syn::Error::new(
                    which.span(),
                    format!(
                        "unknown attachment point `{which}`: expected `start`, `end`, `center` or `@ [x, y]`"
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
    /// `revolute` or `prismatic`.
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
    /// Outer attributes of the mechanism (doc comments, derives are not allowed).
    pub attrs: Vec<Attribute>,
    /// Visibility of the generated types.
    pub vis: Visibility,
    /// Name of the generated parameter type.
    pub name: Ident,
    /// `gravity: [..]`, with the key's span.
    pub gravity: Option<(Ident, Value)>,
    /// `links { … }` with the keyword's span.
    pub links: Option<(Ident, Vec<LinkDecl>)>,
    /// `joints { … }` with the keyword's span.
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
