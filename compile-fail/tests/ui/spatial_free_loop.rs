// A free joint constrains nothing, so it cannot close a loop.
vigp::mechanism! {
    FreeLoop {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            hinge: revolute(world, a.start) { axis: [0.0, 1.0, 0.0] },
            drift: free(world, a.end),
        }
    }
}

fn main() {}
