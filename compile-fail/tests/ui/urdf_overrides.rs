// Overrides name joints with a coordinate and take only `actuated`,
// `damping`, `stiffness` and `rest`: an unknown joint, a fixed (merged)
// joint and a geometry key are errors at the override.
vigp::mechanism! {
    Arm {
        urdf: "urdf/arm.urdf",
        joints {
            elbow: { actuated },
            tool_weld: { actuated },
            shoulder: { axis: [1.0, 0.0, 0.0] },
        }
    }
}

vigp::mechanism! {
    Sections {
        urdf: "urdf/arm.urdf",
        base: floting,
    }
}

fn main() {}
