// Spatial attachment points: `start`, `end`, `center`, `com` or `@ [x, y, z]`.
vigp::mechanism! {
    Tip {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            hinge: revolute(world, a.tip) { axis: [0.0, 1.0, 0.0] },
        }
    }
}

fn main() {}
