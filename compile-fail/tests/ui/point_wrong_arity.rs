vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world @ [0.0, 1.0, 2.0], rod.start),
        }
    }
}

fn main() {}
