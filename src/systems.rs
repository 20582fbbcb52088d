//! The paper's four benchmark systems, declared with [`mechanism!`]
//! (all links m = 1 kg, l = 1 m, J = m·l²/12, every joint damped so that
//! friction can be set at run time; the DSL default is 0).
//!
//! These are ordinary `mechanism!` outputs; the snapshot tests review their
//! generated code.
//!
//! [`mechanism!`]: macro@crate::mechanism

crate::mechanism! {
    /// A pendulum hanging from the origin (1 coordinate: `pivot`).
    pub Pendulum {
        gravity: [0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A cart on a horizontal rail with a pole pinned at its centre
    /// (coordinates: `rail` slide in m, `hinge` pole angle).
    pub Cartpole {
        gravity: [0.0, -9.81],
        links {
            cart: { mass: 1.0, length: 1.0 },
            pole: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], damping: 0.0 },
            hinge: revolute(cart.center, pole.start) { damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A double pendulum hanging from the origin.
    pub DoublePendulum {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.0 },
            elbow: revolute(upper.end, lower.start) { damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// The fourbar segment: a rhombus of four links hanging from one pivot P
    /// (link 1 P→A, link 2 A→B, link 3 P→C, link 4 C→B), closed at B.
    /// Minimal coordinates: 4 tree joints and 2 loop equations (2 DOF).
    pub Fourbar {
        gravity: [0.0, -9.81],
        links {
            link1: { mass: 1.0, length: 1.0 },
            link2: { mass: 1.0, length: 1.0 },
            link3: { mass: 1.0, length: 1.0 },
            link4: { mass: 1.0, length: 1.0 },
        }
        joints {
            /// Top pivot P, left arm.
            top1: revolute(world, link1.start) { damping: 0.0 },
            /// Middle joint A.
            middle1: revolute(link1.end, link2.start) { damping: 0.0 },
            /// Top pivot P, right arm.
            top2: revolute(world, link3.start) { damping: 0.0 },
            /// Middle joint C.
            middle2: revolute(link3.end, link4.start) { damping: 0.0 },
            /// Bottom joint B, closing the loop.
            bottom: revolute(link2.end, link4.end) { damping: 0.0 },
        }
    }
}

pub mod spatial;
