// m·l²/12 overflows f64: the macro must report it instead of panicking while
// writing an infinite literal.
vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1e300, length: 1e300 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
