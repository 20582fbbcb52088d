//! A number in a description: a literal, arithmetic of literals, or a Rust
//! expression only the compiler evaluates; folded to an `f64` when the
//! macro can.

use proc_macro2::Span;
use syn::Token;
use syn::parse::{Parse, ParseStream};

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
