//! The actuated four-bar shared by tests/bound/bound.rs and the `learn`
//! binary (its embedded-stepper and output-error files; included with
//! `#[path]`).

vigp::mechanism! {
    /// The paper's four-bar rhombus driven at the top pivot and at the
    /// loop-closing joint (an actuated loop joint).
    pub DriveFourbar {
        links {
            link1: { mass: 1.0, length: 1.0 },
            link2: { mass: 1.0, length: 1.0 },
            link3: { mass: 1.0, length: 1.0 },
            link4: { mass: 1.0, length: 1.0 },
        }
        joints {
            top1: revolute(world, link1.start) { damping: 0.1, actuated },
            middle1: revolute(link1.end, link2.start) { damping: 0.0 },
            top2: revolute(world, link3.start) { damping: 0.0 },
            middle2: revolute(link3.end, link4.start) { damping: 0.0 },
            bottom: revolute(link2.end, link4.end) { damping: 0.05, actuated },
        }
    }
}
