// Links and joints become struct fields: only doc comments carry over. The
// mechanism's derives are fixed.
vigp::mechanism! {
    /// A pendulum.
    #[derive(Default)]
    Pendulum {
        links {
            /// The rod.
            #[cfg(feature = "rod")]
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
