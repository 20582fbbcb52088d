//! Runtime of **vigp**: the traits that `mechanism!`-generated code implements,
//! the variational integrators that run on them, and the Gaussian-process
//! machinery that learns what the nominal model misses.
//!
//! Data flows one way: DSL → model → code → integrator → learned integrator →
//! prediction with bound. This crate holds everything after "code".

#![forbid(unsafe_code)]
#![warn(missing_docs)]

/// The Gaussian-process engine (the crate `vigp-gp`): exact and sparse GPs,
/// training, prediction, online updates, save/load and export.
#[cfg(feature = "alloc")]
pub use vigp_gp as gp;

#[cfg(feature = "alloc")]
pub mod bound;
pub mod classical;
pub mod composition;
#[cfg(feature = "alloc")]
pub mod data;
pub mod del;
pub mod dynamics;
#[cfg(feature = "alloc")]
pub mod identify;
pub mod integrator;
pub mod kinematics;
#[cfg(feature = "alloc")]
pub mod learned;
pub mod linalg;
pub mod mechanism;
pub mod newton;
pub mod params;
pub mod projection;
pub mod reference;
#[cfg(feature = "urdf")]
pub mod robot;
mod scratch;
pub mod spatial;
pub mod summary;
pub mod system;
pub mod variational;

pub use classical::{ExplicitEuler, Rk4, SymplecticEuler};
pub use composition::Composition;
pub use integrator::{Integrator, StepFailure};
pub use kinematics::Pose2;
pub use mechanism::{CoordinateKind, Coordinates, Mechanism, Scalar, State};
/// The linear-algebra crate of vigp's public types (`SVector` in states and
/// transitions), so that users need not guess a matching version.
pub use nalgebra::{self, SMatrix, SVector};
pub use newton::{StepError, StepOptions, StepReport};
pub use params::{ElasticJoint, Joint, Link, Spring};
#[cfg(feature = "urdf")]
pub use robot::{Robot, RobotError, RobotState};
pub use summary::RolloutSummary;
#[cfg(feature = "std")]
pub use summary::summarize;
pub use system::{Parameters, System, ViewVisitor};
#[cfg(feature = "alloc")]
pub use variational::RolloutDerivatives;
pub use variational::{DEFAULT_SUBDIVISION, Variational};
pub use vigp_core as embedded;
pub use vigp_core::Inputs;
pub use vigp_core::Real;

/// Solver internals, grouped: the discrete Euler–Lagrange residual and its
/// Jacobian ([`del`]), Newton options, diagnostics, the step error and the
/// regularised KKT solve ([`newton`]), and small dense solvers with pivoting
/// ([`linalg`]). Most programs need only [`StepOptions`], [`StepError`]
/// and [`StepReport`], re-exported at the top; the modules are public for
/// tests, benchmarks and callers who build their own steps.
pub mod solver {
    pub use crate::{del, linalg, newton};
}

/// Re-exports for generated code. Not part of the public API.
#[doc(hidden)]
pub mod __private {
    pub use nalgebra;
    pub use num_dual;
}
