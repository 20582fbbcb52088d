//! The `mechanism!` expansion on random and mutated input: any token stream
//! gives code or an error (a `compile_error!` in the macro), never a panic.
//! The stable counterpart of the cargo-fuzz target in `fuzz/` (which needs
//! nightly features): random token sequences from the DSL's vocabulary, and
//! one to four mutations (delete, duplicate, swap, replace, extreme numbers)
//! of the paper's four descriptions in `src/systems.rs`.

use proc_macro2::TokenStream;
use proptest::prelude::*;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// The mechanism descriptions of `src/systems.rs` (the text inside each
/// `crate::mechanism! { … }`).
fn descriptions() -> Vec<String> {
    let src = include_str!("../src/systems.rs");
    let mut out = Vec::new();
    let mut rest = src;
    while let Some(i) = rest.find("crate::mechanism! {") {
        let body = &rest[i + "crate::mechanism! {".len()..];
        let mut depth = 1;
        let mut end = 0;
        for (k, ch) in body.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                end = k;
                break;
            }
        }
        out.push(body[..end].to_string());
        rest = &body[end..];
    }
    out
}

/// The description as a flat list of token texts (delimiters separate).
fn flat_tokens(src: &str) -> Vec<String> {
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
    walk(src.parse().expect("systems.rs parses"), &mut out);
    out
}

const VOCAB: &[&str] = &[
    "pub",
    "Name",
    "gravity",
    "links",
    "joints",
    "mass",
    "length",
    "inertia",
    "com",
    "damping",
    "axis",
    "revolute",
    "prismatic",
    "world",
    "start",
    "end",
    "center",
    "rod",
    "a",
    "b",
    "r#type",
    "self",
    "crate",
    "_",
    ":",
    ",",
    ".",
    "@",
    "-",
    "+",
    ";",
    "#",
    "!",
    "=",
    "{",
    "}",
    "[",
    "]",
    "(",
    ")",
    "0",
    "1",
    "1.0",
    "-1.0",
    "0.0",
    "-0.0",
    "1e308",
    "1e309",
    "1e-320",
    "2.5e-7",
    "0x10",
    "1_000",
    "1.5f32",
    "2u8",
    "1f64",
    "\"s\"",
    "'c'",
    "/// doc",
    "#[doc = \"x\"]",
    "#[derive(Debug)]",
    "#[cfg(test)]",
];

/// Expand `src` (text) both ways; a panic is reported as `Err(message)`.
fn expand_no_panic(src: &str) -> Result<(), String> {
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

#[derive(Clone, Debug)]
enum Mutation {
    Delete(usize),
    Duplicate(usize),
    Swap(usize, usize),
    Replace(usize, usize),
}

fn apply(tokens: &mut Vec<String>, m: &Mutation) {
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
        Mutation::Replace(i, v) => tokens[i % n] = VOCAB[v % VOCAB.len()].to_string(),
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Delete),
        any::<usize>().prop_map(Mutation::Duplicate),
        (any::<usize>(), any::<usize>()).prop_map(|(i, j)| Mutation::Swap(i, j)),
        (any::<usize>(), any::<usize>()).prop_map(|(i, v)| Mutation::Replace(i, v)),
    ]
}

#[test]
fn the_paper_systems_expand() {
    let all = descriptions();
    assert_eq!(all.len(), 4, "four systems in src/systems.rs");
    for d in &all {
        let code = vigp_codegen::expand_to_string(d).expect("valid description");
        assert!(code.contains("impl ::vigp::Mechanism"));
    }
}

/// Inputs the cargo-fuzz run and hand-written edge cases exercise; kept as
/// fixed regression cases.
#[test]
fn edge_cases_do_not_panic() {
    let cases = [
        "",
        "pub",
        "pub X {}",
        "X { links { } }",
        "X { links { a: { mass: 1e308, length: 1e308 } } joints { j: revolute(world, a.start) } }",
        "X { links { a: { mass: 1e308, length: 1e308, inertia: 1.0 } } joints { j: revolute(world, a.start) } }",
        "X { links { a: { mass: 1.0, length: 1e-320 } } joints { j: revolute(world, a.start) } }",
        "X { links { a: { mass: 1.0, length: 1.0, com: [1e308, -1e308] } } joints { j: revolute(world, a @ [1e308, 1e308]) } }",
        "X { gravity: [1e308, -1e308], links { a: { mass: 1e308, length: 1.0 } } joints { j: prismatic(world @ [1e308, 0.0], a.end) { axis: [1e-320, 1e308], damping: 1e308 } } }",
        "X { links { a: { mass: 1.0, length: 1.0 } } joints { j: prismatic(world, a.start) { axis: [0.0, -0.0] } } }",
        "X { links { r#type: { mass: 1.0, length: 1.0 } } joints { r#fn: revolute(world, r#type.start) } }",
        "X { links { a: { mass: 1.0, length: 1.0 }, a: { mass: 1.0, length: 1.0 } } }",
        "X { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(a.start, a.end) } }",
        "X { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(world, world) } }",
        "#[derive(Debug)] pub(crate) X { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(world, a.start) } } extra",
        "X { links { a: { mass: 0x10, length: 1_0.0_0 } } joints { j: revolute(world, a.start) } }",
        "X { links { a: { mass: 1.0f32, length: 1u8 } } }",
        "X { gravity: [0.0, -9.81, 1.0], gravity: [], links { a: { } } }",
    ];
    for c in cases {
        expand_no_panic(c).unwrap_or_else(|p| panic!("panic on {c:?}: {p}"));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// Random token sequences from the DSL's vocabulary.
    #[test]
    fn random_token_sequences_do_not_panic(
        picks in prop::collection::vec(0usize..VOCAB.len(), 0..80),
    ) {
        let src: Vec<&str> = picks.iter().map(|&i| VOCAB[i]).collect();
        let src = src.join(" ");
        prop_assert!(expand_no_panic(&src).is_ok(), "panic on {src:?}: {:?}", expand_no_panic(&src));
    }

    /// One to four mutations of one of the paper's descriptions.
    #[test]
    fn mutated_descriptions_do_not_panic(
        which in 0usize..4,
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let mut tokens = flat_tokens(&descriptions()[which]);
        for m in &mutations {
            apply(&mut tokens, m);
        }
        let src = tokens.join(" ");
        prop_assert!(expand_no_panic(&src).is_ok(), "panic on {src:?}: {:?}", expand_no_panic(&src));
    }
}
