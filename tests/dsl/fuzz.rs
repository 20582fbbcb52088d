//! Helpers shared by the `mechanism!` fuzz tests (tests/dsl/codegen_fuzz.rs
//! and tests/dsl/spatial_fuzz.rs): token flattening, panic catching and
//! token-level mutations.

use crate::sources::mechanism_bodies;
use proc_macro2::TokenStream;
use proptest::prelude::*;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// The mechanism descriptions of the crate source `src` (the text inside
/// each `crate::mechanism! { … }`).
pub fn descriptions(src: &str) -> Vec<String> {
    mechanism_bodies(src, "crate::mechanism! {")
        .into_iter()
        .map(String::from)
        .collect()
}

/// The description as a flat list of token texts (delimiters separate);
/// `what` names the source in the panic if it does not parse.
pub fn flat_tokens(src: &str, what: &str) -> Vec<String> {
    fn walk(ts: TokenStream, out: &mut Vec<String>) {
        for tt in ts {
            match tt {
                proc_macro2::TokenTree::Group(g) => {
                    let (open, close) = match g.delimiter() {
                        proc_macro2::Delimiter::Brace => ("{", "}"),
                        proc_macro2::Delimiter::Bracket => ("[", "]"),
                        proc_macro2::Delimiter::Parenthesis => ("(", ")"),
                        proc_macro2::Delimiter::None => ("", ""),
                    };
                    out.push(open.into());
                    walk(g.stream(), out);
                    out.push(close.into());
                }
                other => out.push(other.to_string()),
            }
        }
    }
    let mut out = Vec::new();
    walk(src.parse().expect(what), &mut out);
    out
}

/// Expand `src` (text) both ways; a panic is reported as `Err(message)`.
pub fn expand_no_panic(src: &str) -> Result<(), String> {
    let r = catch_unwind(AssertUnwindSafe(|| {
        if let Ok(ts) = src.parse::<TokenStream>() {
            match vigp_codegen::expand(ts) {
                Ok(code) => assert!(!code.is_empty(), "empty expansion"),
                Err(e) => assert!(!e.to_string().is_empty(), "empty error"),
            }
        }
        match vigp_codegen::expand_to_string(src) {
            Ok(code) => assert!(code.contains("impl"), "no impl in {code}"),
            Err(msg) => assert!(!msg.is_empty(), "empty error message"),
        }
    }));
    r.map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "non-string panic".into())
    })
}

/// Expands `src`, failing the proptest case with the source on a panic.
pub fn expand_case(src: &str) -> Result<(), TestCaseError> {
    expand_no_panic(src).map_err(|p| TestCaseError::fail(format!("panic on {src:?}: {p}")))
}

/// Expands every case, failing with the case on a panic.
pub fn assert_cases_do_not_panic(cases: &[&str]) {
    for c in cases {
        expand_no_panic(c).unwrap_or_else(|p| panic!("panic on {c:?}: {p}"));
    }
}

/// One token-level edit of a description.
#[derive(Clone, Debug)]
pub enum Mutation {
    Delete(usize),
    Duplicate(usize),
    Swap(usize, usize),
    Replace(usize, usize),
}

/// Applies `m` to `tokens` (indices modulo the length; replacements drawn
/// from `vocab`).
pub fn apply(tokens: &mut Vec<String>, m: &Mutation, vocab: &[&str]) {
    let n = tokens.len();
    if n == 0 {
        return;
    }
    match *m {
        Mutation::Delete(i) => {
            tokens.remove(i % n);
        }
        Mutation::Duplicate(i) => {
            let t = tokens[i % n].clone();
            tokens.insert(i % n, t);
        }
        Mutation::Swap(i, j) => tokens.swap(i % n, j % n),
        Mutation::Replace(i, v) => tokens[i % n] = vocab[v % vocab.len()].to_string(),
    }
}

/// The `tokens` with every one of `mutations` applied in turn, joined
/// into source text.
pub fn mutated(mut tokens: Vec<String>, mutations: &[Mutation], vocab: &[&str]) -> String {
    for m in mutations {
        apply(&mut tokens, m, vocab);
    }
    tokens.join(" ")
}

/// A random [`Mutation`].
pub fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Delete),
        any::<usize>().prop_map(Mutation::Duplicate),
        (any::<usize>(), any::<usize>()).prop_map(|(i, j)| Mutation::Swap(i, j)),
        (any::<usize>(), any::<usize>()).prop_map(|(i, v)| Mutation::Replace(i, v)),
    ]
}
