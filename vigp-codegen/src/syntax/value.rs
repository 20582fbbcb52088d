//! Values as written: numbers, nested bracketed lists, bare flags, and the
//! `key: value` fields of links and joints.

use super::list::terminated;
use crate::number::Number;
use proc_macro2::Span;
use syn::parse::ParseStream;
use syn::{Ident, Token, braced, bracketed};

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

    pub(super) fn parse(input: ParseStream) -> syn::Result<Self> {
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
    pub(super) fn parse(input: ParseStream) -> syn::Result<Self> {
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

pub(super) fn parse_fields(input: ParseStream) -> syn::Result<Vec<Field>> {
    let content;
    braced!(content in input);
    terminated(&content, Field::parse)
}
