//! The `mechanism!` expansion on random and mutated input: any token stream
//! gives code or an error (a `compile_error!` in the macro), never a panic.
//! The stable counterpart of the cargo-fuzz target in `fuzz/` (which needs
//! nightly features): random token sequences from the DSL's vocabulary, and
//! one to four mutations (delete, duplicate, swap, replace, extreme numbers)
//! of the paper's four descriptions in `src/systems.rs`.

use crate::fuzz::{assert_cases_do_not_panic, expand_case, flat_tokens, mutated, mutation};
use proc_macro2::TokenStream;
use proptest::prelude::*;

/// The mechanism descriptions of `src/systems.rs` (the text inside each
/// `crate::mechanism! { … }`).
fn descriptions() -> Vec<String> {
    crate::fuzz::descriptions(include_str!("../../src/systems.rs"))
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
    assert_cases_do_not_panic(&cases);
}

/// A mechanism named like a primitive type is refused at its name (it
/// used to give 15–35 rustc errors at the whole macro call), in both the
/// planar and the 3-D syntax, raw or not.
#[test]
fn a_primitive_type_name_is_refused_at_the_name() {
    for (name, gravity) in [
        ("f64", "[0.0, -9.81]"),
        ("usize", "[0.0, -9.81]"),
        ("r#bool", "[0.0, -9.81]"),
        ("f64", "[0.0, 0.0, -9.81]"),
    ] {
        let src = format!(
            "pub {name} {{ gravity: {gravity}, links {{ a: {{ mass: 1.0, length: 1.0 }} }} \
             joints {{ j: revolute(world, a.start) }} }}"
        );
        let e = vigp_codegen::expand_to_string(&src).unwrap_err();
        assert!(e.contains("primitive type"), "{name} {gravity}: {e}");
    }
    assert!(
        vigp_codegen::expand_to_string(
            "pub F64 { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(world, a.start) } }"
        )
        .is_ok()
    );
}

/// A boolean on a numeric key says that the key takes a number (it used
/// to say that a flag is written bare, which `mass` is not); on
/// `actuated`, the one flag, it still names the flag form.
#[test]
fn a_boolean_on_a_numeric_key_asks_for_a_number() {
    let e = vigp_codegen::expand_to_string(
        "pub X { links { a: { mass: true, length: 1.0 } } joints { j: revolute(world, a.start) } }",
    )
    .unwrap_err();
    assert!(e.contains("`mass` takes a number, not `true`"), "{e}");
    let e = vigp_codegen::expand_to_string(
        "pub X { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(world, a.start) { actuated: true } } }",
    )
    .unwrap_err();
    assert!(e.contains("a flag is written bare"), "{e}");
}

/// A planar chain of n links, each on a revolute joint at the previous
/// link's end.
fn chain(n: usize) -> String {
    let links: Vec<String> = (0..n)
        .map(|i| format!("l{i}: {{ mass: 1.0, length: 0.3 }}"))
        .collect();
    let mut joints = vec!["j0: revolute(world, l0.start)".to_string()];
    joints.extend((1..n).map(|i| format!("j{i}: revolute(l{}.end, l{i}.start)", i - 1)));
    format!(
        "pub Chain {{ links {{ {} }} joints {{ {} }} }}",
        links.join(", "),
        joints.join(", ")
    )
}

/// The closed-form planar terms grow ≈ 1.5× per link of a chain; past
/// 14 joints on one path (`MAX_CLOSED_FORM_DEPTH`; 14 links expand to
/// 7.8 MB, 15 would to 11 MB, and rustc was killed after 5 minutes on a
/// 20-link chain's 83 MB) the macro does not attempt them: a tree gets its
/// parameter types and the tree engine's items alone, with a small
/// expansion that grows linearly, and a loop is refused at the name with
/// the size and the way out.
#[test]
fn a_planar_tree_too_large_for_closed_forms_gets_the_tree_engine_alone() {
    let expand = |src: String| {
        let ts: TokenStream = src.parse().unwrap();
        vigp_codegen::expand(ts).map(|t| t.to_string())
    };
    let fourteen = expand(chain(14)).expect("14 links are within the limit");
    assert!(
        fourteen.len() > 5_000_000 && fourteen.len() < 8_000_000,
        "{}",
        fourteen.len()
    );
    assert!(fourteen.contains("fn minimal") && fourteen.contains("fn tree"));
    let sizes: Vec<usize> = [15, 30, 60]
        .iter()
        .map(|&n| {
            let out = expand(chain(n)).expect("a tree past the limit expands");
            assert!(!out.contains("fn minimal") && !out.contains("fn maximal"));
            assert!(out.contains("fn tree") && out.contains("fn robot"));
            assert!(out.contains("no closed-form coordinate views"));
            out.len()
        })
        .collect();
    // linear in the links: each further link adds the same amount
    let (a, b) = (sizes[1] - sizes[0], sizes[2] - sizes[1]);
    println!("15, 30, 60 links: {sizes:?} bytes");
    assert!(sizes[0] < 100_000, "{sizes:?}");
    assert!((b as f64 / (2 * a) as f64 - 1.0).abs() < 0.05, "{sizes:?}");
    // a loop past the limit: refused with the remedy
    let mut looped = chain(15);
    looped.truncate(looped.len() - " } }".len());
    looped += ", close: revolute(l14.end, world @ [1.0, 0.0]) } }";
    let e = expand(looped).unwrap_err().to_string();
    assert!(
        e.contains("has a loop") && e.contains("15 joints") && e.contains("3-D syntax"),
        "{e}"
    );
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
        expand_case(&src)?;
    }

    /// One to four mutations of one of the paper's descriptions.
    #[test]
    fn mutated_descriptions_do_not_panic(
        which in 0usize..4,
        mutations in prop::collection::vec(mutation(), 1..5),
    ) {
        let tokens = flat_tokens(&descriptions()[which], "systems.rs parses");
        let src = mutated(tokens, &mutations, VOCAB);
        expand_case(&src)?;
    }
}
