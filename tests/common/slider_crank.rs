//! The slider-crank shared by tests/step/nominal.rs and tests/step/embedded.rs (included
//! with `#[path]` by the tests that use it, so the others do not compile it).

vigp::mechanism! {
    /// Slider-crank with offsets: a crank on a world pivot away from the
    /// origin, a connecting rod attached off its end, and a block on a tilted
    /// rail; the rod's end is pinned to the block (a loop). Damping on every
    /// joint (prismatic joint, loop, damped loop joint).
    pub SliderCrank {
        gravity: [0.0, -9.81],
        links {
            crank: { mass: 0.5, length: 0.4, com: [0.15, 0.02] },
            rod: { mass: 0.8, length: 1.2, inertia: 0.11 },
            block: { mass: 2.0, length: 0.3 },
        }
        joints {
            pivot: revolute(world @ [0.1, 0.2], crank.start) { damping: 0.05 },
            pin: revolute(crank @ [0.4, 0.01], rod.start) { damping: 0.02 },
            rail: prismatic(world @ [1.0, 0.0], block.center) { axis: [1.0, 0.2], damping: 0.3 },
            wrist: revolute(rod.end, block.center) { damping: 0.01 },
        }
    }
}
