//! Snapshots of the generated code of the spatial examples (reviewed as
//! diffs; accept intended changes with
//! `INSTA_UPDATE=always cargo test --test dsl spatial_snapshot::`), and what a
//! spatial scene does not need is not emitted.

use crate::sources::named_bodies;
#[test]
fn generated_code_of_the_spatial_examples() {
    let bodies = named_bodies(include_str!("../../src/systems/spatial.rs"));
    let names: Vec<_> = bodies.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "SphericalPendulum",
            "Furuta",
            "DoublePendulum3d",
            "SpatialSliderCrank",
            "Tumbler"
        ]
    );
    for (name, body) in bodies {
        let code = vigp_codegen::expand_to_string(&body).unwrap_or_else(|e| panic!("{name}: {e}"));
        if name == "Furuta" || name == "SpatialSliderCrank" {
            insta::assert_snapshot!(name, code);
        }
    }
}

/// An undamped revolute tree has no joint parameters, no dissipation, no
/// input or spring code and no constraint code in its minimal view (an
/// actuated one gets input code only, a sprung one spring code only); a ball joint brings its
/// unit-norm constraint; the `no_std` expansion has no `Mechanism` impl.
#[test]
fn spatial_code_contains_only_what_the_scene_needs() {
    let tree = vigp_codegen::expand_to_string(
        "pub Arm { gravity: [0.0, 0.0, -9.81], links { a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] } } \
         joints { j: revolute(world, a.start) { axis: [0.0, 1.0, 0.0] } } }",
    )
    .unwrap();
    assert!(tree.contains("impl ::vigp::Mechanism<1, 0> for ArmMinimal"));
    assert!(!tree.contains("fn constraints"));
    assert!(!tree.contains("fn dissipation"));
    assert!(!tree.contains("ArmJoints"));
    // no input or spring code unless declared; with them, exactly theirs
    for absent in ["INPUT", "input_", "springs", "ELASTIC", "Spring"] {
        assert!(!tree.contains(absent), "{absent}");
    }
    let driven = vigp_codegen::expand_to_string(
        "pub Arm { gravity: [0.0, 0.0, -9.81], links { a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] } } \
         joints { j: revolute(world, a.start) { axis: [0.0, 1.0, 0.0], actuated } } }",
    )
    .unwrap();
    assert!(driven.contains("const INPUTS: usize = 1"));
    assert!(driven.contains("fn input_work") && driven.contains("INPUT_JOINTS"));
    assert!(!driven.contains("springs") && !driven.contains("ArmJoints"));
    let sprung = vigp_codegen::expand_to_string(
        "pub Arm { gravity: [0.0, 0.0, -9.81], links { a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] } } \
         joints { j: revolute(world, a.start) { axis: [0.0, 1.0, 0.0], stiffness: 2.0, rest: 0.1 } } }",
    )
    .unwrap();
    assert!(sprung.contains("fn springs") && sprung.contains("::vigp::Spring"));
    assert!(!sprung.contains("INPUT") && !sprung.contains("input_"));
    let ball = vigp_codegen::expand_to_string(
        "pub Ball { gravity: [0.0, 0.0, -9.81], links { a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] } } \
         joints { j: spherical(world, a.start) { damping: 0.1 } } }",
    )
    .unwrap();
    assert!(ball.contains("impl ::vigp::Mechanism<4, 1> for BallMinimal"));
    assert!(ball.contains("fn constraints"));
    assert!(ball.contains("fn dissipation"));
    assert!(ball.contains("Maximal<Self, 1, 1, 6, 3>"));
    let no_std = vigp_codegen::expand_to_string_for(
        &named_bodies(include_str!("../../src/systems/spatial.rs"))[1].1,
        vigp_codegen::Target::NoStd,
    )
    .unwrap();
    assert!(no_std.contains("impl ::vigp::spatial::Spatial<2, 2> for Furuta"));
    assert!(!no_std.contains("::vigp::Mechanism"));
    // a planar description still gets planar code
    let planar = vigp_codegen::expand_to_string(
        "pub P { links { a: { mass: 1.0, length: 1.0 } } joints { j: revolute(world, a.start) } }",
    )
    .unwrap();
    assert!(planar.contains("::vigp::Pose2") && !planar.contains("::vigp::spatial"));
}

/// The code of a universal (Hooke) joint, reviewed as a diff: two angle
/// coordinates in the minimal view, no constraint there for a tree joint,
/// 4 constraint rows in the maximal view, the second axis in the joint's
/// type.
#[test]
fn generated_code_of_a_universal_joint() {
    let code = vigp_codegen::expand_to_string(
        "/// A rod on a Hooke joint.
         pub HookePendulum {
             gravity: [0.0, 0.0, -9.81],
             links {
                 rod: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333],
                        frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] },
             }
             joints {
                 cardan: universal(world, rod.start) { axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], damping: 0.0 },
             }
         }",
    )
    .unwrap();
    assert!(code.contains("impl ::vigp::Mechanism<2, 0> for HookePendulumMinimal"));
    assert!(code.contains("Maximal<Self, 1, 1, 6, 4>"));
    assert!(code.contains("JointType::Universal") && code.contains("second: [0.0, 1.0, 0.0]"));
    insta::assert_snapshot!("HookePendulum", code);
}

/// The generated code of a `urdf:` mechanism (tests/fixtures/robots/wrist.urdf,
/// two joints actuated): the spatial code of its lowered description, the
/// `include_bytes!` that makes the crate depend on the file, and the tree
/// engine's constants (`Wrist::TREE_BODIES`, `WristTree`).
#[test]
fn generated_code_of_a_urdf_mechanism() {
    let code = vigp_codegen::expand_to_string(
        r#"pub Wrist { urdf: "tests/fixtures/robots/wrist.urdf", joints { shoulder: { actuated }, slide: { actuated } } }"#,
    )
    .unwrap();
    insta::assert_snapshot!("WristUrdf", code);
}
