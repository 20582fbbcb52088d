vigp::mechanism! {
    DoublePendulum {
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start),
            elbow: revolute(upper.middle, lower.start),
        }
    }
}

fn main() {}
