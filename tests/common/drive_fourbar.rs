//! The actuated four-bar shared by tests/bound/bound.rs and the `learn`
//! binary (its embedded-stepper and output-error files; included with
//! `#[path]` after tests/common/rhombus.rs).

rhombus! {
    /// The paper's four-bar rhombus driven at the top pivot and at the
    /// loop-closing joint (an actuated loop joint).
    DriveFourbar {
        top1: { damping: 0.1, actuated },
        middle: [{ damping: 0.0 }],
        bottom: { damping: 0.05, actuated },
    }
}
