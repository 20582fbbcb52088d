vigp::mechanism! {
    DoublePendulum {
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, upper.start),
            pivot: revolute(upper.end, lower.start),
        }
    }
}

fn main() {}
