// A universal joint needs two non-zero, non-parallel axes: each mistake is
// reported at the offending axis.
vigp::mechanism! {
    Cardans {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            b: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            c: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            d: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            no_axes: universal(world, a.start),
            zero: universal(a.end, b.start) { axes: [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]] },
            parallel: universal(b.end, c.start) { axes: [[0.0, 0.0, 1.0], [0.0, 0.0, -2.0]] },
            one_axis: universal(c.end, d.start) { axes: [1.0, 0.0, 0.0] },
            actuated_cross: universal(world, d.end) { axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], actuated },
        }
    }
}

fn main() {}
