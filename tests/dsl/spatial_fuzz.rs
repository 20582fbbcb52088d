//! The spatial `mechanism!` path on mutated, random and extreme input: any
//! token stream gives code or an error, never a panic (the spatial
//! counterpart of tests/dsl/codegen_fuzz.rs).

use crate::fuzz::{assert_cases_do_not_panic, expand_case, flat_tokens, mutated, mutation};
use proptest::prelude::*;

/// The descriptions of `src/systems/spatial.rs`.
fn descriptions() -> Vec<String> {
    crate::fuzz::descriptions(include_str!("../../src/systems/spatial.rs"))
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
    assert_cases_do_not_panic(&cases);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// One to four mutations of one of the spatial examples.
    #[test]
    fn mutated_spatial_descriptions_do_not_panic(
        which in 0usize..5,
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let tokens = flat_tokens(&descriptions()[which], "spatial systems parse");
        let src = mutated(tokens, &mutations, VOCAB);
        expand_case(&src)?;
    }

    /// Random sequences after a spatial header.
    #[test]
    fn random_spatial_bodies_do_not_panic(
        picks in prop::collection::vec(0usize..VOCAB.len(), 0..60),
    ) {
        let body: Vec<&str> = picks.iter().map(|&i| VOCAB[i]).collect();
        let src = format!("X {{ gravity: [0.0, 0.0, -9.81], {} }}", body.join(" "));
        expand_case(&src)?;
    }
}
