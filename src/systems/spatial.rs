//! Spatial example systems, declared with [`mechanism!`](crate::mechanism!)
//! and `gravity: [gx, gy, gz]` (z up). Link inertias are those of thin
//! solid cylinders (radius r): about the axis ½mr², across it
//! m(3r² + l²)/12, rounded. Every joint declares `damping: 0.0` so that
//! friction can be set at run time.
//!
//! Used by `examples/spatial.rs`, the spatial tests and the MuJoCo
//! comparison (`scripts/spatial_mujoco.py` writes the same models as MJCF).

crate::mechanism! {
    /// A spherical pendulum: a 1 m, 1 kg rod (r = 2 cm) hanging from the
    /// origin by a ball joint. Reference configuration (quaternion
    /// (1, 0, 0, 0)): the rod along +x.
    pub SphericalPendulum {
        gravity: [0.0, 0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0, inertia: [0.0002, 0.0834333, 0.0834333] },
        }
        joints {
            ball: spherical(world, rod.start) { damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A Furuta (rotary inverted) pendulum: a horizontal arm turning about
    /// the vertical (`base`), a pendulum at its end turning about the arm's
    /// axis (`pivot`). Reference configuration: arm along +x, pendulum
    /// hanging down (its frame's x axis along −z).
    pub Furuta {
        gravity: [0.0, 0.0, -9.81],
        links {
            arm: { mass: 0.3, length: 0.25, inertia: [0.000015, 0.0015700, 0.0015700] },
            pendulum: {
                mass: 0.1,
                length: 0.4,
                inertia: [0.000005, 0.0013358, 0.0013358],
                frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            },
        }
        joints {
            base: revolute(world, arm.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
            pivot: revolute(arm.end, pendulum.start) { axis: [1.0, 0.0, 0.0], damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A 3-D double pendulum with non-parallel axes: the upper link swings
    /// about the world y axis, the lower about an axis fixed in the upper
    /// link that is neither parallel nor perpendicular to the first
    /// ((0.8, 0.6, 0) in world coordinates in the reference configuration,
    /// where both links hang down).
    pub DoublePendulum3d {
        gravity: [0.0, 0.0, -9.81],
        links {
            upper: {
                mass: 1.0,
                length: 1.0,
                inertia: [0.0002, 0.0834333, 0.0834333],
                frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            },
            lower: {
                mass: 1.0,
                length: 1.0,
                inertia: [0.0002, 0.0834333, 0.0834333],
                frame: [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            },
        }
        joints {
            shoulder: revolute(world, upper.start) { axis: [0.0, 1.0, 0.0], damping: 0.0 },
            elbow: revolute(upper.end, lower.start) { axis: [0.0, 0.6, 0.8], damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A spatial slider-crank (R-S-S-P): a crank turning about the world y
    /// axis, a connecting rod with ball joints at both ends, and a slider on
    /// a rail along x that runs 0.15 m out of the crank's plane, so the rod
    /// moves in 3-D. The rod's spin about its own axis is a second degree of
    /// freedom. The reference configuration does not close the loop: start
    /// from a projected state.
    pub SpatialSliderCrank {
        gravity: [0.0, 0.0, -9.81],
        links {
            crank: { mass: 0.5, length: 0.2, inertia: [0.0001, 0.0017167, 0.0017167] },
            rod: { mass: 0.4, length: 0.6, inertia: [0.00008, 0.012040, 0.012040] },
            slider: { mass: 0.6, inertia: [0.0005, 0.0008, 0.0008] },
        }
        joints {
            crankshaft: revolute(world, crank.start) { axis: [0.0, 1.0, 0.0], damping: 0.0 },
            crankpin: spherical(crank.end, rod.start) { damping: 0.0 },
            rail: prismatic(world @ [0.75, 0.15, 0.0], slider.com) { axis: [1.0, 0.0, 0.0], damping: 0.0 },
            wristpin: spherical(rod.end, slider.com) { damping: 0.0 },
        }
    }
}

crate::mechanism! {
    /// A free rigid body (no gravity) with distinct principal moments 1, 2
    /// and 3 kg·m² about its frame axes: the intermediate-axis (tennis
    /// racket) demonstration.
    pub Tumbler {
        gravity: [0.0, 0.0, 0.0],
        links {
            body: { mass: 2.0, inertia: [1.0, 2.0, 3.0] },
        }
        joints {
            float: free(world, body.com),
        }
    }
}
