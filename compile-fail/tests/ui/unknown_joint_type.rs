vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: spherical(world, rod.start),
        }
    }
}

fn main() {}
