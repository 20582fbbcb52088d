vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: "heavy", length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
