//! The slider-crank shared by tests/step/nominal.rs and tests/step/embedded.rs (included
//! with `#[path]` by the tests that use it, so the others do not compile it),
//! and the macro that declares it, which tests/step/control.rs also uses
//! (with `#[macro_use]`) for the same slider-crank driven.

/// Declares the slider-crank `$name` with the doc comment `$doc`: inputs
/// at the crank pivot and along the rail when `$actuated` is given.
macro_rules! slider_crank {
    ($(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?]) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, -9.81],
                links {
                    crank: { mass: 0.5, length: 0.4, com: [0.15, 0.02] },
                    rod: { mass: 0.8, length: 1.2, inertia: 0.11 },
                    block: { mass: 2.0, length: 0.3 },
                }
                joints {
                    pivot: revolute(world @ [0.1, 0.2], crank.start) { damping: 0.05 $(, $actuated)? },
                    pin: revolute(crank @ [0.4, 0.01], rod.start) { damping: 0.02 },
                    rail: prismatic(world @ [1.0, 0.0], block.center) { axis: [1.0, 0.2], damping: 0.3 $(, $actuated)? },
                    wrist: revolute(rod.end, block.center) { damping: 0.01 },
                }
            }
        }
    };
}

slider_crank! {
    /// Slider-crank with offsets: a crank on a world pivot away from the
    /// origin, a connecting rod attached off its end, and a block on a tilted
    /// rail; the rod's end is pinned to the block (a loop). Damping on every
    /// joint (prismatic joint, loop, damped loop joint).
    SliderCrank []
}
