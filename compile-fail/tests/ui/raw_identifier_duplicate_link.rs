// `r#rod` and `rod` are the same identifier (and would be the same field of
// the generated `PendulumLinks`).
vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
            r#rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
