//! Run-time parameters of generated mechanisms (perturb them without
//! recompiling).

/// Physical parameters of one rigid link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// Mass in kg.
    pub mass: f64,
    /// Length from `start` to `end` in m.
    pub length: f64,
    /// Rotational inertia about the centre of mass in kg·m² (default
    /// m·l²/12; it does not follow later changes of `mass` or `length`).
    pub inertia: f64,
    /// Centre of mass in the link's local frame, in m (default
    /// `[length/2, 0]`).
    pub com: [f64; 2],
}

/// Run-time parameters of one joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    /// Viscous damping coefficient c ≥ 0 on the joint rate (N·m·s/rad or N·s/m).
    pub damping: f64,
}
