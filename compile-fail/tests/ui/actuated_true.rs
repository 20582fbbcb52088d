vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { actuated: true },
        }
    }
}

fn main() {}
