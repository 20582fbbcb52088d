// The command-line tool and other tools generic over `System` take planar
// mechanisms only; a 3-D one gets a message that says so and where to go.
vigp::mechanism! {
    pub Arm {
        gravity: [0.0, 0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 0.8, inertia: [0.002, 0.05, 0.05] },
        }
        joints {
            shoulder: spherical(world, upper.start),
        }
    }
}

fn tool<S: vigp::System>() {}

fn main() {
    tool::<Arm>();
}
