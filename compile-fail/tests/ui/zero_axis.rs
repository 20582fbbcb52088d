vigp::mechanism! {
    Cart {
        links {
            cart: { mass: 1.0, length: 0.5 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [0.0, 0.0] },
        }
    }
}

fn main() {}
