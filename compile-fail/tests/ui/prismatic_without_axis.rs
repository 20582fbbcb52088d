vigp::mechanism! {
    Cart {
        links {
            cart: { mass: 1.0, length: 0.5 },
        }
        joints {
            rail: prismatic(world, cart.center) { damping: 0.1 },
        }
    }
}

fn main() {}
