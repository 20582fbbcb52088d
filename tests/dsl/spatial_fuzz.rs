//! The spatial `mechanism!` path on mutated, random and extreme input: any
//! token stream gives code or an error, never a panic (the spatial
//! counterpart of tests/dsl/codegen_fuzz.rs).

use crate::sources::mechanism_bodies;
use proc_macro2::TokenStream;
use proptest::prelude::*;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// The descriptions of `src/systems/spatial.rs`.
fn descriptions() -> Vec<String> {
    mechanism_bodies(
        include_str!("../../src/systems/spatial.rs"),
        "crate::mechanism! {",
    )
    .into_iter()
    .map(String::from)
    .collect()
}

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
    walk(src.parse().expect("spatial systems parse"), &mut out);
    out
}

const VOCAB: &[&str] = &[
    "gravity",
    "links",
    "joints",
    "mass",
    "length",
    "inertia",
    "com",
    "frame",
    "damping",
    "axis",
    "revolute",
    "prismatic",
    "spherical",
    "fixed",
    "free",
    "universal",
    "axes",
    "world",
    "start",
    "end",
    "center",
    "com",
    "a",
    "b",
    ":",
    ",",
    ".",
    "@",
    "-",
    "{",
    "}",
    "[",
    "]",
    "(",
    ")",
    "0",
    "1.0",
    "-1.0",
    "0.0",
    "1e308",
    "1e-320",
    "[0.0, 0.0, 1.0]",
    "[1.0, 2.0]",
    "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
    "[[1e308, 0.0, 0.0], [0.0, 1e308, 0.0], [0.0, 0.0, 1e308]]",
    "[0.0, 0.0, -9.81]",
    "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]",
    "[[1e308, 0.0, 0.0], [1e308, 1e-320, 0.0]]",
];

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

#[test]
fn extreme_spatial_values_do_not_panic() {
    let cases = [
        "X { gravity: [1e308, -1e308, 1e308], links { a: { mass: 1e308, inertia: [1e308, 1e308, 1e308] } } joints { j: free(world, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [[1e308, 1e308, 0.0], [1e308, 1e308, 0.0], [0.0, 0.0, 1.0]] } } joints { j: spherical(world, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1e-320, 1e-320, 1e-320] } } joints { j: spherical(world, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0], frame: [[1e308, 0.0, 0.0], [0.0, 1e-320, 0.0], [0.0, 0.0, 1e308]] } } joints { j: spherical(world, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: revolute(world @ [1e308, 1e308, 1e308], a @ [-1e308, 0.0, 0.0]) { axis: [1e-320, 1e308, 0.0] } } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0], frame: [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] } } joints { j: fixed(world, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [[1.0], [2.0], [3.0]], com: [[1.0]] } } }",
        "X { gravity: [0.0, 0.0, 0.0], links { } joints { } }",
        "X { gravity: [0.0, 0.0, 0.0,], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: free(a.com, a.com) } }",
        "X { gravity: [0.0, 0.0, 0.0] }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: universal(world, a.com) { axes: [[1e308, 1e308, 0.0], [1e-320, 0.0, 1e308]] } } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: universal(world, a.com) { axes: [[1.0, 0.0, 0.0], [1.0, 1e-320, 0.0]] } } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: universal(world, a.com) { axes: [[[1.0]], [0.0, 1.0]] } } }",
        "X { gravity: [0.0, 0.0, 0.0], links { a: { mass: 1.0, inertia: [1.0, 1.0, 1.0] } } joints { j: universal(world, a.com) { axes: [] } } }",
    ];
    for c in cases {
        expand_no_panic(c).unwrap_or_else(|p| panic!("panic on {c:?}: {p}"));
    }
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

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// One to four mutations of one of the spatial examples.
    #[test]
    fn mutated_spatial_descriptions_do_not_panic(
        which in 0usize..5,
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let mut tokens = flat_tokens(&descriptions()[which]);
        for m in &mutations {
            apply(&mut tokens, m);
        }
        let src = tokens.join(" ");
        prop_assert!(expand_no_panic(&src).is_ok(), "panic on {src:?}: {:?}", expand_no_panic(&src));
    }

    /// Random sequences after a spatial header.
    #[test]
    fn random_spatial_bodies_do_not_panic(
        picks in prop::collection::vec(0usize..VOCAB.len(), 0..60),
    ) {
        let body: Vec<&str> = picks.iter().map(|&i| VOCAB[i]).collect();
        let src = format!("X {{ gravity: [0.0, 0.0, -9.81], {} }}", body.join(" "));
        prop_assert!(expand_no_panic(&src).is_ok(), "panic on {src:?}: {:?}", expand_no_panic(&src));
    }
}
