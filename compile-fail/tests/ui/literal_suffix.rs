// Parameters are f64; a suffix such as `f32` or `u8` would silently be
// ignored, so it is rejected.
vigp::mechanism! {
    Pendulum {
        links {
            rod: { mass: 1.0f32, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start),
        }
    }
}

fn main() {}
