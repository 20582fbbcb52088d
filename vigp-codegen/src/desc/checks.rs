//! The checks every description shares, planar or spatial: attributes,
//! the mechanism's name, keys (unknown, duplicate), numbers (single,
//! positive, non-negative, known to the macro), lists of numbers, and a
//! joint's inputs and springs.

use super::model::DefaultValue;
use crate::ctxt::Ctxt;
use crate::number::Number;
use crate::syntax::{Field, LinkDecl, Value};
use proc_macro2::{Ident, Span};
use std::collections::HashMap;
use syn::Attribute;

/// A declaration's fields by key (each key once).
pub type Fields<'a> = HashMap<String, &'a Field>;

/// Rust's primitive type names: a mechanism named like one shadows it in
/// the generated items (`f64` fields, `[f64; N]` arrays), and rustc's
/// errors then point at the whole macro call.
const PRIMITIVE_TYPES: [&str; 17] = [
    "bool", "char", "str", "f32", "f64", "i8", "i16", "i32", "i64", "i128", "isize", "u8", "u16",
    "u32", "u64", "u128", "usize",
];

/// An error at the mechanism's name if the generated items cannot use it.
pub fn mechanism_name(cx: &mut Ctxt, name: &Ident) {
    let text = name.to_string();
    let text = text.strip_prefix("r#").unwrap_or(&text);
    if PRIMITIVE_TYPES.contains(&text) {
        cx.push(
            name.span(),
            format!(
                "a mechanism cannot be named `{text}`: the generated items use the primitive type \
                 `{text}`, which the name would shadow; choose another name"
            ),
        );
    }
}

/// Links and joints become fields of generated structs (joints only when
/// some joint is damped), so only doc comments carry over meaningfully; a
/// `cfg` would leave the generated code inconsistent. On the mechanism, the
/// derives are fixed and a `cfg` would not reach the generated impls.
pub fn attrs(cx: &mut Ctxt, attrs: &[Attribute], on_mechanism: bool) {
    for attr in attrs {
        let path = attr.path();
        let ok = if on_mechanism {
            !["derive", "cfg", "cfg_attr"]
                .iter()
                .any(|name| path.is_ident(name))
        } else {
            path.is_ident("doc")
        };
        if !ok {
            let msg = if on_mechanism {
                "`derive`, `cfg` and `cfg_attr` are not supported on a mechanism: the generated types derive `Clone, Copy, Debug, PartialEq`"
            } else {
                "only doc comments are allowed on links and joints"
            };
            let span = path
                .segments
                .first()
                .map_or_else(Span::call_site, |s| s.ident.span());
            cx.push(span, msg);
        }
    }
}

/// "`a`", "one of `a`, `b`", or "no keys".
pub fn one_of(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.as_slice() {
        [] => "no keys".into(),
        [one] => one.clone(),
        _ => format!("one of {}", quoted.join(", ")),
    }
}

/// Collect fields into a map, reporting duplicates and keys not in
/// `allowed` (`what` names the declaration: "a link").
pub fn fields<'a>(cx: &mut Ctxt, fields: &'a [Field], allowed: &[&str], what: &str) -> Fields<'a> {
    let mut map = HashMap::new();
    for f in fields {
        let key = f.key.to_string();
        if !allowed.contains(&key.as_str()) {
            let expected = if allowed.is_empty() {
                "this joint takes no keys".to_string()
            } else {
                format!("expected {}", one_of(allowed))
            };
            cx.push(
                f.key.span(),
                format!("unknown key `{key}` for {what}: {expected}"),
            );
        } else if map.insert(key.clone(), f).is_some() {
            cx.push(f.key.span(), format!("duplicate key `{key}`"));
        }
    }
    map
}

/// The number of a key that takes one.
pub fn number<'a>(cx: &mut Ctxt, f: &'a Field) -> Option<&'a Number> {
    match &f.value {
        Value::Number(n) => Some(n),
        Value::Array(s, _) | Value::Flag(s) => {
            cx.push(*s, format!("`{}` takes a single number", f.key));
            None
        }
    }
}

/// A run-time parameter that must be positive (when known).
pub fn positive(cx: &mut Ctxt, f: &Field) -> Option<DefaultValue> {
    let n = number(cx, f)?;
    match n.value {
        Some(x) if x <= 0.0 => {
            cx.add(n.error(format!("`{}` must be positive, got {x}", f.key)));
            None
        }
        _ => Some(DefaultValue::from(n)),
    }
}

/// A run-time parameter that must not be negative (when known).
pub fn non_negative(cx: &mut Ctxt, f: &Field) -> Option<DefaultValue> {
    let n = number(cx, f)?;
    match n.value {
        Some(x) if x < 0.0 => {
            cx.add(n.error(format!("`{}` must not be negative, got {x}", f.key)));
            None
        }
        _ => Some(DefaultValue::from(n)),
    }
}

/// A positive run-time parameter every link of the dimension declares
/// (1 after reporting a problem, so that checking goes on).
pub fn required_positive(
    cx: &mut Ctxt,
    decl: &LinkDecl,
    name: &str,
    f: &Fields,
    key: &str,
) -> DefaultValue {
    match f.get(key) {
        None => {
            cx.push(decl.name.span(), format!("link `{name}` needs `{key}`"));
            DefaultValue::Known(1.0)
        }
        Some(field) => positive(cx, field).unwrap_or(DefaultValue::Known(1.0)),
    }
}

/// The numbers of a list of exactly `N`; `shape` says what was expected.
pub fn numbers<'a, const N: usize>(
    cx: &mut Ctxt,
    v: &'a Value,
    shape: impl FnOnce() -> String,
) -> Option<[&'a Number; N]> {
    let out = v.array::<N>();
    if out.is_none() {
        cx.push(v.span(), shape());
    }
    out
}

/// Numbers the macro must know (geometry that shapes the generated code):
/// `what` names them in the error.
pub fn known<const N: usize>(cx: &mut Ctxt, x: [&Number; N], what: &str) -> Option<[f64; N]> {
    let mut out = [0.0; N];
    for (o, n) in out.iter_mut().zip(x) {
        *o = cx.ok(n.known(what))?;
    }
    Some(out)
}

/// `actuated` (a bare flag).
fn actuated(cx: &mut Ctxt, f: &Fields) -> bool {
    match f.get("actuated") {
        None => false,
        Some(field) => match &field.value {
            Value::Flag(_) => true,
            other => {
                cx.push(
                    other.span(),
                    "`actuated` takes no value: write `actuated` to make the joint an input",
                );
                false
            }
        },
    }
}

/// `rest: s0`, only with `stiffness`.
fn rest(cx: &mut Ctxt, f: &Fields, joint: &str) -> Option<DefaultValue> {
    let field = f.get("rest")?;
    let n = number(cx, field)?;
    if !f.contains_key("stiffness") {
        cx.push(
            field.key.span(),
            format!("`rest` of joint `{joint}` needs `stiffness` (a spring ½k(s − rest)²)"),
        );
    }
    Some(DefaultValue::from(n))
}

/// What acts on a joint's coordinate: damping, an input, a spring.
pub struct Actuation {
    /// `damping: c` (c ≥ 0 when known).
    pub damping: Option<DefaultValue>,
    /// `actuated`.
    pub actuated: bool,
    /// `stiffness: k` (k ≥ 0 when known).
    pub stiffness: Option<DefaultValue>,
    /// `rest: s0` (only with `stiffness`).
    pub rest: Option<DefaultValue>,
}

/// The keys of inputs and springs, which only joints with a single
/// coordinate take.
pub const ACTUATION_KEYS: [&str; 3] = ["actuated", "stiffness", "rest"];

/// A joint's damping, input and spring, in that order.
pub fn actuation(cx: &mut Ctxt, f: &Fields, joint: &str) -> Actuation {
    let damping = f.get("damping").and_then(|field| non_negative(cx, field));
    let actuated = actuated(cx, f);
    let stiffness = f.get("stiffness").and_then(|field| non_negative(cx, field));
    let rest = rest(cx, f, joint);
    Actuation {
        damping,
        actuated,
        stiffness,
        rest,
    }
}

/// "`what` takes three numbers `[x, y, z]`".
pub fn shape<const D: usize>(what: &str) -> String {
    let (count, point) = match D {
        2 => ("two", "[x, y]"),
        _ => ("three", "[x, y, z]"),
    };
    format!("{what} takes {count} numbers `{point}`")
}
