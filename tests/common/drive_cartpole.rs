//! An actuated cart-pole shared by tests/learn/embedded_learned.rs and the
//! fixture generator examples/learned_forced_fixture.rs (the exported
//! fixture names this mechanism, so both must declare the same one), and
//! the macro that declares it, which tests/learn/held_inputs.rs and
//! tests/step/control.rs also use (with `#[macro_use]`) for the same
//! cart-pole with other damping or a spring.

/// Declares the cart-pole `$name` with the doc comment `$doc` and gravity
/// `$gravity` when given: a 1 kg, 0.5 m cart pushed along a horizontal
/// rail (input `rail`, a force in N) with the keys `$rail` after its axis,
/// and a 0.3 kg, 0.8 m pole hinged at the cart's centre with the keys
/// `$hinge`.
macro_rules! drive_cartpole {
    (
        $(#[doc = $doc:tt])*
        $name:ident {
            $(gravity: $gravity:tt,)?
            rail: [$($rail:tt)*],
            hinge: [$($hinge:tt)*],
        }
    ) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                $(gravity: $gravity,)?
                links {
                    cart: { mass: 1.0, length: 0.5 },
                    pole: { mass: 0.3, length: 0.8 },
                }
                joints {
                    rail: prismatic(world, cart.center) { axis: [1.0, 0.0], $($rail)*, actuated },
                    hinge: revolute(cart.center, pole.start) { $($hinge)* },
                }
            }
        }
    };
}

drive_cartpole! {
    /// A cart-pole pushed along its rail (input `rail`, a force in N).
    DriveCartpole {
        rail: [damping: 0.1],
        hinge: [damping: 0.05],
    }
}
