// Inputs and springs on spatial joints: the planar rules, and a clear
// message on joints without a single coordinate.
vigp::mechanism! {
    Driven {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            b: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            c: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            d: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            loose: revolute(world, a.start) { axis: [0.0, 1.0, 0.0], damping: 0.1, rest: 0.5 },
            soft: prismatic(a.end, b.start) { axis: [1.0, 0.0, 0.0], stiffness: -2.0 },
            valued: revolute(b.end, c.start) { axis: [0.0, 1.0, 0.0], actuated: 1.0 },
            bare: revolute(c.end, d.start) { axis: [0.0, 1.0, 0.0], stiffness, rest: 0.5 },
            ball: spherical(d.end, a.end) { actuated, damping: 0.1 },
            welded: fixed(world, b.end) { stiffness: 1.0 },
            floating: free(world, c.com) { rest: 0.0 },
        }
    }
}

fn main() {}
