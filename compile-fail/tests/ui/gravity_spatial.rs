vigp::mechanism! {
    Pendulum {
        gravity: [0.0, 0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
