//! The driven double pendulum shared by `benches/step.rs` and
//! `examples/step_cost.rs` (included with `#[path]`), so that the bench and
//! the instruction counts measure the same mechanism.

vigp::mechanism! {
    /// The paper's double pendulum with a motor on each joint (as
    /// scripts/mujoco_models.py's actuated double pendulum).
    pub DrivenDoublePendulum {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { actuated },
            elbow: revolute(upper.end, lower.start) { actuated },
        }
    }
}
