// `lower` hangs from nothing: its only joint has it as the parent, and that
// joint's child is the world.
vigp::mechanism! {
    DoublePendulum {
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start),
            elbow: revolute(lower.start, world @ [2.0, 0.0]),
        }
    }
}

fn main() {}
