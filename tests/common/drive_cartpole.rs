//! An actuated cart-pole shared by tests/learn/embedded_learned.rs and the
//! fixture generator examples/learned_forced_fixture.rs (the exported
//! fixture names this mechanism, so both must declare the same one).

vigp::mechanism! {
    /// A cart-pole pushed along its rail (input `rail`, a force in N).
    pub DriveCartpole {
        links {
            cart: { mass: 1.0, length: 0.5 },
            pole: { mass: 0.3, length: 0.8 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], damping: 0.1, actuated },
            hinge: revolute(cart.center, pole.start) { damping: 0.05 },
        }
    }
}
