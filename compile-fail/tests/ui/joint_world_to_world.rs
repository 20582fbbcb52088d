vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
            anchor: revolute(world, world @ [1.0, 0.0]),
        }
    }
}

fn main() {}
