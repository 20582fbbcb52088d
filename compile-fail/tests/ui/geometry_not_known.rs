// Axes and attachment points shape the generated code: the macro must know
// them, so they cannot name constants (run-time parameters can).
const TILT: f64 = 0.1;

vigp::mechanism! {
    Slider {
        links {
            block: { mass: 1.0, length: 0.2 },
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, block.center) { axis: [1.0, TILT] },
            hinge: revolute(block @ [TILT, 0.0], rod.start),
        }
    }
}

vigp::mechanism! {
    Top {
        gravity: [0.0, 0.0, -9.81],
        links {
            body: { mass: 1.0, length: 1.0, inertia: [0.1, 0.1, 0.1] },
        }
        joints {
            pivot: revolute(world, body.start) { axis: [0.0, TILT, 1.0] },
        }
    }
}

fn main() {}
