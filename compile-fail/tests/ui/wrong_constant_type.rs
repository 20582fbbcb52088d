// Parameters are f64: a constant of another type is the compiler's type
// error at the expression.
const MASS: f32 = 1.0;

vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: MASS, length: 1.0, inertia: 0.1, com: [0.5, 0.0] },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
