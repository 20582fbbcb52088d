//! Runtime of **vigp**: the traits that `mechanism!`-generated code implements,
//! the variational integrators that run on them, and the Gaussian-process
//! machinery that learns what the nominal model misses.
//!
//! Data flows one way: DSL → model → code → integrator → learned integrator →
//! prediction with bound. This crate holds everything after "code".

#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "alloc")]
pub mod gp;

#[cfg(feature = "alloc")]
pub mod bound;
pub mod classical;
pub mod del;
pub mod dynamics;
pub mod kinematics;
#[cfg(feature = "alloc")]
pub mod learned;
pub mod linalg;
pub mod mechanism;
pub mod newton;
pub mod params;
pub mod projection;
pub mod spatial;
pub mod summary;
pub mod variational;

pub use classical::{ExplicitEuler, Rk4, SymplecticEuler};
pub use kinematics::Pose2;
pub use mechanism::{CoordinateKind, Coordinates, Mechanism, Scalar, State};
pub use newton::{NewtonOptions, StepError, StepInfo};
pub use params::{Joint, Link};
pub use summary::RolloutSummary;
#[cfg(feature = "std")]
pub use summary::summarize;
pub use variational::{Integrator, Variational};
pub use vigp_core as embedded;
pub use vigp_core::Real;

/// Re-exports for generated code. Not part of the public API.
#[doc(hidden)]
pub mod __private {
    pub use crate::mechanism::fixed_size_step;
    pub use nalgebra;
    pub use num_dual;
}
