// Every mistake in a spatial link is reported, each at its token.
vigp::mechanism! {
    Links {
        gravity: [0.0, 0.0, -9.81],
        links {
            no_inertia: { mass: 1.0 },
            flat: { mass: 1.0, inertia: [1.0, 0.0, 1.0] },
            impossible: { mass: 1.0, inertia: [1.0, 1.0, 3.0] },
            skewed: { mass: 1.0, inertia: [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] },
            pair: { mass: 1.0, inertia: [1.0, 2.0] },
            heavy: { mass: -2.0, inertia: [1.0, 1.0, 1.0] },
            offset: { mass: 1.0, inertia: [1.0, 1.0, 1.0], com: [0.5, 0.0] },
            round: { mass: 1.0, inertia: [1.0, 1.0, 1.0], radius: 0.1 },
            bent: { mass: 1.0, inertia: [1.0, 1.0, 1.0], frame: [[1.0, 0.0, 0.0], [0.1, 1.0, 0.0], [0.0, 0.0, 1.0]] },
            mirror: { mass: 1.0, inertia: [1.0, 1.0, 1.0], frame: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]] },
            flat_frame: { mass: 1.0, inertia: [1.0, 1.0, 1.0], frame: [1.0, 0.0, 0.0] },
            short: { mass: 1.0, inertia: [1.0, 1.0, 1.0], length: 0.0 },
        }
        joints {
            a: spherical(world, no_inertia.start),
            b: spherical(world, flat.start),
            c: spherical(world, impossible.start),
            d: spherical(world, skewed.start),
            e: spherical(world, pair.start),
            f: spherical(world, heavy.start),
            g: spherical(world, offset.start),
            h: spherical(world, round.start),
            i: spherical(world, bent.start),
            j: spherical(world, mirror.start),
            k: spherical(world, flat_frame.start),
            l: spherical(world, short.start),
        }
    }
}

fn main() {}
