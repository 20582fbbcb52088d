// Arithmetic of literals is evaluated by the macro and gets the same checks
// as a literal.
vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: -2.0 * 0.5, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
