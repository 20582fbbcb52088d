vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0, inertia: -0.1 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
