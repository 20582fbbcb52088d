//! Snapshots of the generated code for the paper's four systems, reviewed as
//! diffs (SymForce's habit): a change to the generator shows up here.
//!
//! The descriptions are read from `src/systems.rs`, the same text that
//! `vigp::systems` compiles, so the snapshots always show shipped code.
//! Accept intended changes with `INSTA_UPDATE=always cargo test --test snapshots`
//! (or `cargo insta review`); with `CI` set, mismatches fail.

use crate::sources::named_bodies;
/// The text of the minimal view's `Mechanism` impl in a pretty-printed
/// expansion (the maximal view always has joint constraints).
fn minimal_impl(code: &str) -> &str {
    let start = code
        .find("Minimal {\n    const COORDINATES")
        .expect("minimal impl");
    let end = code[start..]
        .find("\n}\n")
        .map_or(code.len(), |e| start + e);
    &code[start..end]
}

#[test]
fn generated_code_of_the_paper_systems() {
    let src = include_str!("../../src/systems.rs");
    let bodies = named_bodies(src);
    let names: Vec<_> = bodies.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["Pendulum", "Cartpole", "DoublePendulum", "Fourbar"]);
    for (name, body) in bodies {
        let code = vigp_codegen::expand_to_string(&body).unwrap_or_else(|e| panic!("{name}: {e}"));
        insta::assert_snapshot!(name, code);
    }
}

vigp::mechanism! {
    /// An undamped tree: no joint parameters, no dissipation, no constraints.
    pub Bare {
        links {
            arm: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, arm.start),
        }
    }
}

/// Only what the scene needs: a tree has no constraint code, an undamped
/// scene no dissipation code and no joint parameters.
#[test]
fn generated_code_contains_only_what_the_scene_needs() {
    let bare = vigp_codegen::expand_to_string(
        "pub Bare { links { arm: { mass: 1.0, length: 1.0 } } joints { pivot: revolute(world, arm.start) } }",
    )
    .unwrap();
    let minimal = minimal_impl(&bare);
    assert!(!minimal.contains("fn constraints"));
    assert!(!bare.contains("fn dissipation"));
    assert!(!bare.contains("Joints"));
    insta::assert_snapshot!("Bare", bare);

    let dp = vigp_codegen::expand_to_string(
        "pub Dp { links { a: { mass: 1.0, length: 1.0 }, b: { mass: 1.0, length: 1.0 } } \
         joints { j1: revolute(world, a.start), j2: revolute(a.end, b.start) { damping: 0.1 } } }",
    )
    .unwrap();
    assert!(!minimal_impl(&dp).contains("fn constraints"));
    assert!(minimal_impl(&dp).contains("fn dissipation"));

    let fourbar =
        vigp_codegen::expand_to_string(&named_bodies(include_str!("../../src/systems.rs"))[3].1)
            .unwrap();
    assert!(minimal_impl(&fourbar).contains("fn constraints"));
    // the same for the no_std model: dampers and constraints only if needed
    let embedded = |code: &str| {
        let start = code
            .find("impl ::vigp::embedded::Model")
            .expect("embedded impl");
        code[start..start + code[start..].find("\n}\n").unwrap()].to_string()
    };
    assert!(!embedded(&bare).contains("fn for_each_damper"));
    assert!(!embedded(&bare).contains("fn constraints"));
    assert!(embedded(&dp).contains("fn for_each_damper"));
    assert!(!embedded(&dp).contains("fn constraints"));
    assert!(embedded(&fourbar).contains("fn constraints"));
    // the closed-form terms likewise: no constraint functions for a tree,
    // no damping matrix for an undamped scene
    let dynamics = |code: &str, view: &str| {
        let start = code
            .find(&format!("for {view} {{\n    const KINDS"))
            .expect("dynamics impl");
        code[start..start + code[start..].find("\n}\n").unwrap()].to_string()
    };
    assert!(!dynamics(&bare, "BareMinimal").contains("fn constraint"));
    assert!(!dynamics(&bare, "BareMinimal").contains("out.damping"));
    assert!(dynamics(&bare, "BareMinimal").contains("const DISSIPATIVE: bool = false"));
    assert!(dynamics(&bare, "BareMaximal").contains("fn constraints_and_jacobian"));
    assert!(dynamics(&dp, "DpMinimal").contains("out.damping"));
    assert!(!dynamics(&dp, "DpMinimal").contains("fn constraint"));
    assert!(dynamics(&fourbar, "FourbarMinimal").contains("fn constraint_hessian"));
    // maximal coordinates: constant mass, so no ∂M/∂q is computed
    assert!(dynamics(&dp, "DpMaximal").contains("const CONSTANT_MASS: bool = true"));
    assert!(!dynamics(&dp, "DpMaximal").contains("out.dmass"));
    // the generated code is the code that compiles: `Bare` above is usable
    let _ = Bare::default().minimal();
}

/// The `no_std` expansion (what `vigp` without its `std` feature gets):
/// parameters, kinematics, the closed-form terms of both views, no
/// dual-number views.
#[test]
fn no_std_expansion_has_only_the_fixed_size_items() {
    let body = &named_bodies(include_str!("../../src/systems.rs"))[2].1;
    let code = vigp_codegen::expand_to_string_for(body, vigp_codegen::Target::NoStd).unwrap();
    assert!(code.contains("impl ::vigp::embedded::Model<2, 0> for DoublePendulum"));
    assert!(!code.contains("::vigp::Mechanism"));
    assert!(code.contains("impl ::vigp::embedded::Dynamics<6, 4> for DoublePendulumMaximal"));
    assert!(code.contains("impl ::vigp::embedded::Dynamics<2, 0> for DoublePendulumMinimal"));
    assert!(!code.contains("num_dual"));
    insta::assert_snapshot!("DoublePendulum_no_std", code);
}
