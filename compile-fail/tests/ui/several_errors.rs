// Validation reports every problem it finds, each at its own token, not just
// the first one.
vigp::mechanism! {
    DoublePendulum {
        gravity: [0.0, 0.0, -9.81, 0.0],
        links {
            upper: { mass: 0.0, length: 1.0, inertia: -1.0 },
            lower: { mas: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: -0.1 },
            elbow: revolute(upper.end, lowr.start),
            elbow: hinge(upper.end, lower.start),
        }
    }
}

fn main() {}
