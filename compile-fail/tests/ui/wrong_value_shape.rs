vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: [1.0], length: 1.0, com: 0.5 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: [0.1, 0.2] },
        }
    }
}

fn main() {}
