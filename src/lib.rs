//! **vigp**: structure-preserving learned dynamics.
//!
//! Declare a planar mechanism once with [`mechanism!`]; it becomes a
//! specialised variational integrator (Lagrangian, discrete Euler–Lagrange
//! residual, exact Jacobians) that runs on the runtime in this crate; a
//! Gaussian process learns what the nominal model misses; the learned model
//! is saved, scored, and exported to `no_std` firmware.
//!
//! # The workflow, module by module
//!
//! | step | where |
//! |---|---|
//! | declare a mechanism | [`mechanism!`], [`Mechanism`], [`systems`] (the paper's four) |
//! | simulate | [`Variational`] (paper eq. 5–6, midpoint), classical integrators, [`spatial::LieStepper`] (bodies in space), [`Robot`] (URDF at run time); one [`Integrator`] trait over planar and spatial states; [`summarize`] |
//! | consistent states for loops | [`projection`] (`consistent_state`, `consistent_state_holding`) |
//! | load measured data | [`data`] (CSV: `run,t,<coordinates>`) |
//! | learn | [`learned`] (`Learned`, save/load, export), [`gp`] |
//! | bound the error | [`bound`] (paper Theorem 1) |
//! | command line | `cli` (feature `cli`): `vigp fit / score / predict / export` |
//! | embed | [`embedded`] (`no_std`: `Stepper`, `LearnedStepper`, exported GPs) |
//!
//! Solver internals (`del`, `newton`, `linalg`) are grouped under
//! [`solver`]; the types most programs need from them ([`StepOptions`],
//! [`StepError`]) are at the top. [`SVector`] and [`nalgebra`] are
//! re-exported, so no separate `nalgebra` version is needed.
//!
//! ```
//! use vigp::prelude::*;
//!
//! vigp::mechanism! {
//!     /// A double pendulum hanging from the origin.
//!     pub DoublePendulum {
//!         gravity: [0.0, -9.81],
//!         links {
//!             upper: { mass: 1.0, length: 1.0 },
//!             lower: { mass: 1.0, length: 1.0, inertia: 0.0833 },
//!         }
//!         joints {
//!             shoulder: revolute(world, upper.start) { damping: 0.0 },
//!             elbow: revolute(upper.end, lower.start),
//!         }
//!     }
//! }
//!
//! # fn main() -> Result<(), vigp::StepError> {
//! let mut sys = DoublePendulum::default();
//! sys.joints.elbow.damping = 0.3;
//! let model = sys.minimal();
//! let vi = Variational::new(model, 0.01)?;
//! let z0 = model.state([std::f64::consts::FRAC_PI_2, 0.0], [0.0, 0.0]);
//! let z1 = vi.step(&z0)?;
//! let (e, g) = (model.energy(&z1), model.constraint_violation(&z1));
//! assert!(e.is_finite() && g == 0.0);
//! let traj = vi.rollout(&z0, 100)?;
//! assert_eq!(traj.len(), 101);
//! # Ok(())
//! # }
//! ```
//!
//! ## The DSL
//!
//! * `gravity: [gx, gy]` (optional, default `[0, -9.81]`). Three components
//!   `[gx, gy, gz]` declare a spatial mechanism: see `vigp::spatial` and
//!   docs/spatial.md (links with inertia tensors and frames; revolute,
//!   prismatic, spherical, fixed and free joints).
//! * `links { name: { mass, length, inertia?, com? }, … }`: a rigid link with
//!   its local frame at `start` and local x-axis towards `end` = (length, 0).
//!   `inertia` is about the centre of mass (default m·l²/12), `com` in local
//!   coordinates (default (length/2, 0)).
//! * `joints { name: revolute(parent, child) { damping? }, name:
//!   prismatic(parent, child) { axis: [ax, ay], damping? }, … }` with points
//!   `world`, `world @ [x, y]`, `link.start`, `link.end`, `link.center`,
//!   `link @ [x, y]`. A joint whose child is already placed closes a loop and
//!   becomes two constraint equations in minimal coordinates; `world` is
//!   always placed, so `revolute(crank.end, world @ [x, y])` pins a point
//!   to the ground that way (the spatial DSL refuses `world` as a child:
//!   there the ground is always a joint's parent).
//! * Angles: θ = 0 hangs straight down, counter-clockwise positive; a
//!   revolute coordinate is the child's angle relative to its parent; a
//!   prismatic coordinate is the slide distance along the unit axis.
//! * The tree engine: a planar tree (no loop) also gets `Name::tree()`, its
//!   bodies for the linear-time engine `vigp::embedded::tree::Engine`
//!   (`no_std`), and `Name::robot()`, a `vigp::Robot` over them
//!   (docs/robots.md); `Name::TREE_COORDINATES` maps the engine's bodies
//!   (parents first) to the minimal coordinates.
//! * Size: the planar terms are expanded in closed form and grow about
//!   1.5× per link of a chain (12 links: 3.3 MB of Rust, 40 s and 4 GB to
//!   compile). Past 14 joints on one path, or 8 MB, the macro applies a
//!   rule: a tree gets its parameters and the tree engine's items alone
//!   (no `minimal()` or `maximal()`; the expansion grows linearly, 60
//!   links: 0.1 MB), and a loop is refused with a `compile_error!` at the
//!   name that points to the 3-D syntax (gravity `[gx, gy, 0.0]`, revolute
//!   axes `[0.0, 0.0, 1.0]`, an `inertia: [i1, i2, i3]` per link), whose
//!   terms are evaluated at run time.
//! * Damping: when any joint declares `damping` (even `0.0`), every joint
//!   gets a run-time damping parameter and the generated code contains the
//!   Rayleigh dissipation function; when none does, no damping code exists.
//!
//! * Inputs: a joint declaring `actuated` (`{ actuated, damping: 0.1 }`) is
//!   an input — a torque on a revolute joint, a force along a prismatic
//!   axis — applying the generalized force u_i ∇s_i(q) (s_i the joint
//!   coordinate). Inputs are numbered in joint declaration order
//!   (`Name::INPUT_NAMES`); their count is `Dynamics::INPUTS`, and input
//!   vectors are `SVector<f64, U>` with `U` checked against it at compile
//!   time by the bound `M: Inputs<U>` on every forced call (`U` = the count,
//!   or 0 for the input-free step): a wrong `U` is an error at the call,
//!   `cargo check` included. Steps: `Variational::step_forced`, `rollout_forced`, every
//!   [`Integrator`]'s `step_forced`, the embedded `Stepper::step_forced`;
//!   exact derivatives A = ∂z₁/∂z₀, B = ∂z₁/∂u: `Variational::step_derivatives`,
//!   `rollout_derivatives`, `Stepper::step_with_derivatives` (docs/control.md).
//!   With u = 0 an actuated mechanism steps bit for bit as without
//!   `actuated`; no input code exists for an unactuated mechanism.
//! * Springs: `stiffness: k` with optional `rest: s0` adds ½k(s − s0)² on the
//!   joint coordinate to V; when any joint declares `stiffness`, every joint
//!   gets run-time `stiffness` and `rest` parameters (`vigp::Spring`, or
//!   `vigp::ElasticJoint` with damping); otherwise no spring code exists.
//! * Numbers: every value is an f64. A run-time parameter (`mass`, `length`,
//!   `inertia`, `com`, `damping`, `stiffness`, `rest`, `gravity`) may be a
//!   Rust expression such as `mass: 2.0 * M` or `rest: FRAC_PI_4`. Literals
//!   and `+ - * /` of literals are evaluated by the macro (integer literals
//!   count as f64) and checked when it runs: a mass of `-2.0 * 0.5` is a
//!   compile error. An expression that names a constant or calls a function
//!   becomes the default value as written, so the compiler checks its type
//!   (write `2.0 * M`, not `2 * M`, for an `f64` constant). Its value is
//!   checked at run time like any parameter set by hand: `Stepper::new`
//!   and `Variational::new` return the typed `InvalidModel` error. Geometry shapes the generated code, so it must be
//!   known when the macro runs: prismatic `axis`, the points `world @ [x, y]`
//!   and `link @ [x, y]`, and for spatial links `frame` and joint axes.
//!
//! Generated items for `pub Name { … }`: `Name` (run-time parameters with the
//! DSL's values as `Default`), `NameLinks`, `NameJoints` (if damped or
//! elastic),
//! `Name::link_poses` (forward kinematics), an implementation of
//! `vigp::embedded::Model` for `Name` (the `no_std`, fixed-size model behind
//! `vigp::embedded::Stepper`), and, with the default `std` feature,
//! `NameMinimal` implementing `Mechanism` and `NameMaximal` (maximal
//! coordinates); `vigp::embedded::Parameters` (the mechanism's name and its
//! parameters as named numbers, recorded in model files) for `Name` and both
//! views, and [`System`] for `Name` (both views to generic tools such as
//! `vigp::cli::main::<Name>()`). To see or snapshot the generated source of your
//! own mechanism, enable the `codegen` feature and call
//! `vigp::codegen::expand_to_string`.

#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// Lets generated code name `::vigp` inside this crate too (`systems`).
extern crate self as vigp;

pub use vigp_macros::mechanism;
#[cfg(feature = "std")]
pub use vigp_runtime::*;

/// The `no_std` core: fixed-size models and steps, exported-GP prediction.
#[cfg(not(feature = "std"))]
pub use vigp_core as embedded;
#[cfg(not(feature = "std"))]
pub use vigp_core::{
    CoordinateKind, ElasticJoint, Joint, Link, Pose2, Real, Spring, State, kinematics, spatial,
};

/// Re-exports for generated code. Not part of the public API.
#[cfg(not(feature = "std"))]
#[doc(hidden)]
pub mod __private {
    pub use vigp_core::__private::nalgebra;
}

#[cfg(feature = "codegen")]
pub use vigp_codegen as codegen;

#[cfg(feature = "cli")]
pub mod cli;

pub mod systems;

/// The README's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// The example of docs/embedded.md, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../docs/embedded.md")]
pub struct EmbeddedDoctests;

/// The examples of docs/spatial.md, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/spatial.md")]
pub struct SpatialDoctests;

/// The examples of docs/robots.md, compiled and run as doctests.
#[cfg(all(doctest, feature = "std"))]
#[doc = include_str!("../docs/robots.md")]
pub struct RobotsDoctests;

/// The examples of docs/control.md, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/control.md")]
pub struct ControlDoctests;

/// The names most programs need.
#[cfg(feature = "std")]
pub mod prelude {
    pub use vigp_runtime::data::{Dataset, ReadOptions};
    pub use vigp_runtime::embedded::Dynamics;
    pub use vigp_runtime::gp::TrainOptions;
    pub use vigp_runtime::learned::{Encoding, Learned, Prior};
    pub use vigp_runtime::{
        Composition, Coordinates, ExplicitEuler, Integrator, Mechanism, Rk4, SVector, State,
        StepError, StepOptions, SymplecticEuler, Variational,
    };
}
