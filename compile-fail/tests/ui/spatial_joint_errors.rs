// Every mistake in a spatial joint is reported, each at its token.
vigp::mechanism! {
    Joints {
        gravity: [0.0, 0.0, -9.81],
        links {
            a: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            b: { mass: 1.0, inertia: [1.0, 1.0, 1.0] },
            c: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
            d: { mass: 1.0, length: 1.0, inertia: [0.1, 1.0, 1.0] },
        }
        joints {
            no_axis: revolute(world, a.start),
            zero_axis: prismatic(world, b.com) { axis: [0.0, 0.0, 0.0] },
            flat_axis: revolute(a.end, c.start) { axis: [0.0, 1.0] },
            universal: universal(c.end, d.start),
            welded: fixed(c.end, d.start) { damping: 0.1 },
            leaky: spherical(b.com, d.start) { damping: -0.5 },
            lengthless: spherical(b.end, d.start),
            flat_point: spherical(world @ [1.0, 2.0], d.start),
            upside_down: revolute(a.end, world) { axis: [0.0, 0.0, 1.0] },
            selfish: spherical(a.end, a.start),
            ghost: spherical(e.end, d.start),
            // An axis shapes the generated code: the macro must know it, so
            // it cannot name a constant (run-time parameters can).
            tilted: revolute(world, a.start) { axis: [0.0, TILT, 1.0] },
        }
    }
}

const TILT: f64 = 0.1;

fn main() {}
