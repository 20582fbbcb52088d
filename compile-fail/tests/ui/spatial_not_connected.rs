// A spatial link without a path to the world is reported at its name.
vigp::mechanism! {
    Floating {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            b: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            hinge: revolute(world, a.start) { axis: [0.0, 1.0, 0.0] },
        }
    }
}

fn main() {}
