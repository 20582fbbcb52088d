// A run-time parameter may name a constant; one that does not exist is the
// compiler's error at the name.
vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 2.0 * HEAVY, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
