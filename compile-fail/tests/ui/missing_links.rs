vigp::mechanism! {
    Pendulum {
        gravity: [0.0, -9.81],
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
