vigp::mechanism! {
    Pendulum {
        links {
            world: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, world @ [0.0, 1.0]),
        }
    }
}

fn main() {}
