// Every mistake in a planar joint is reported, each at its token.
//
// Axes and attachment points shape the generated code: the macro must know
// them, so they cannot name constants (run-time parameters can).
const TILT: f64 = 0.1;

vigp::mechanism! {
    Joints {
        links {
            rod: { mass: 1.0, length: 1.0 },
            cart: { mass: 1.0, length: 0.5 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: 0.1, rest: 0.5 },
            pivot: revolute(rod.end, cart.center),
            fold: revolute(rod.end, rod.start),
            anchor: revolute(world, world @ [1.0, 0.0]),
            typo: revolute(world, rdo.start),
            ball: spherical(world, rod.start),
            rail: prismatic(world, cart.center) { damping: 0.1 },
            still: prismatic(world, cart.center) { axis: [0.0, 0.0] },
            tilted: prismatic(world, cart.center) { axis: [1.0, TILT] },
            hinge: revolute(cart @ [TILT, 0.0], rod.start),
            // `axis` belongs to prismatic joints only.
            sliding: revolute(world, rod.start) { axis: [1.0, 0.0] },
            valued: revolute(world, rod.start) { actuated: 1.0 },
            twice: revolute(world, rod.start) { actuated, damping: 0.1, actuated },
            leaky: revolute(world, rod.start) { damping: -0.5 },
            paired: revolute(world, rod.start) { damping: [0.1, 0.2] },
            soft: revolute(world, rod.start) { stiffness: -2.0, rest: 0.5 },
            bare: revolute(world, rod.start) { stiffness, rest: 0.5 },
        }
    }
}

fn main() {}
