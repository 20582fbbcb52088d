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

impl Link {
    /// A link with the DSL's defaults for what is not given: the inertia
    /// m·l²/12 of a uniform rod about its centre, and the centre of mass
    /// `[length/2, 0]`. `mechanism!` emits this when a default derives from
    /// a value written as an expression (`mass: 2.0 * M`); the values are
    /// checked where every parameter is, when a model is built.
    ///
    /// ```
    /// use vigp_core::Link;
    /// let l = Link::with_defaults(3.0, 2.0, None, None);
    /// assert_eq!((l.inertia, l.com), (1.0, [1.0, 0.0]));
    /// ```
    pub fn with_defaults(
        mass: f64,
        length: f64,
        inertia: Option<f64>,
        com: Option<[f64; 2]>,
    ) -> Self {
        Link {
            mass,
            length,
            inertia: inertia.unwrap_or(mass * length * length / 12.0),
            com: com.unwrap_or_else(|| crate::kinematics::center(length)),
        }
    }
}

/// Run-time parameters of one joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    /// Viscous damping coefficient c ≥ 0 on the joint rate (N·m·s/rad or N·s/m).
    pub damping: f64,
}

/// Run-time parameters of one joint of a mechanism with springs but no
/// damping (some joint declares `stiffness`, none `damping`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    /// Spring stiffness k ≥ 0 (N·m/rad or N/m): potential ½k(s − rest)² on
    /// the joint coordinate s.
    pub stiffness: f64,
    /// Rest coordinate of the spring (rad or m).
    pub rest: f64,
}

/// Run-time parameters of one joint of a mechanism with damping and springs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElasticJoint {
    /// Viscous damping coefficient c ≥ 0 on the joint rate (N·m·s/rad or N·s/m).
    pub damping: f64,
    /// Spring stiffness k ≥ 0 (N·m/rad or N/m): potential ½k(s − rest)² on
    /// the joint coordinate s.
    pub stiffness: f64,
    /// Rest coordinate of the spring (rad or m).
    pub rest: f64,
}

/// A mechanism's name and its run-time parameters as a flat list of named
/// numbers, implemented by `mechanism!` for the parameter struct (and, with
/// the std runtime, for its coordinate views).
///
/// Tools use it to record which mechanism a saved or exported model belongs
/// to and with which parameter values it was trained, and to restore those
/// values. Names are dotted paths of the struct's fields: `gravity.x`,
/// `gravity.y`, then per link `links.<link>.mass`, `.length`, `.inertia`,
/// `.com.x`, `.com.y`, then (for a damped mechanism) per joint
/// `joints.<joint>.damping`, then (for a mechanism with springs) per joint
/// `joints.<joint>.stiffness` and `joints.<joint>.rest`, in declaration
/// order. A spatial mechanism (and its minimal view) lists `gravity.x`,
/// `.y`, `.z`, then per link `mass`, `length`, the nine entries
/// `inertia.xx`, `inertia.xy`, …, `inertia.zz` (row by row) and `com.x`,
/// `.y`, `.z`, then the joints as above.
///
/// ```
/// use vigp_core::{Link, Parameters};
/// /// A hand-written parameter set (what `mechanism!` generates).
/// struct Rod { link: Link }
/// impl Parameters for Rod {
///     const NAME: &'static str = "Rod";
///     const PARAMETER_NAMES: &'static [&'static str] = &["links.rod.mass"];
///     fn parameter(&self, index: usize) -> Option<f64> {
///         (index == 0).then_some(self.link.mass)
///     }
///     fn parameter_mut(&mut self, index: usize) -> Option<&mut f64> {
///         (index == 0).then_some(&mut self.link.mass)
///     }
/// }
/// let mut rod = Rod { link: Link { mass: 1.0, length: 1.0, inertia: 0.1, com: [0.5, 0.0] } };
/// *rod.parameter_mut(0).unwrap() = 2.0;
/// assert_eq!(rod.parameter(0), Some(2.0));
/// assert_eq!(rod.parameter(1), None);
/// ```
pub trait Parameters {
    /// The mechanism's name as declared in `mechanism!` (e.g. `"Cartpole"`).
    const NAME: &'static str;
    /// The name of every parameter, in a fixed order (see the trait docs).
    const PARAMETER_NAMES: &'static [&'static str];

    /// The value of parameter `index` (`None` past the end).
    fn parameter(&self, index: usize) -> Option<f64>;

    /// Mutable access to parameter `index` (`None` past the end).
    fn parameter_mut(&mut self, index: usize) -> Option<&mut f64>;

    /// The index of the parameter called `name`.
    fn parameter_index(name: &str) -> Option<usize> {
        Self::PARAMETER_NAMES.iter().position(|n| *n == name)
    }
}
