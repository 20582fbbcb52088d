//! `no_std` core of **vigp**: what generated code and firmware-style users
//! need without allocation or the standard library.
//!
//! * [`Real`], [`Jet1`], [`Jet2`]: the scalar the generated kinematics is
//!   generic over, and forward-mode jets for exact derivatives.
//! * [`kinematics`]: planar poses ([`Pose2`]) and helpers.
//! * [`Model`]: what `mechanism!` implements for every mechanism; [`model`]
//!   computes M(q), ∂M/∂q, ∇V, D and the energy from it.
//! * [`Stepper`]: the first-order variational step on fixed-size data.
//! * [`gp`]: prediction with a Gaussian process exported as Rust source.
//! * [`LearnedStepper`]: the learned step (nominal prior + exported GP
//!   means + projection for loops) of a model exported by the std runtime.
//! * [`Tangent`]: step derivatives A, B in tangent coordinates (2·DoF) for
//!   minimal views with unit quaternions, for controllers.
//! * [`spatial`]: 3-D mechanisms: minimal coordinates and the Lie-group
//!   variational integrator in maximal coordinates (unit quaternions).
//! * [`tree`]: the linear-time engine of kinematic trees (robots): the
//!   variational step in O(N) per residual and solve, with adaptive
//!   sub-steps.
//!
//! Everything here works on `nalgebra` static vectors and plain arrays, and
//! never allocates. The std runtime (`vigp-runtime`) re-exports the shared
//! pieces.

#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod compose;
pub mod dynamics;
pub mod error;
pub mod forced;
pub mod gp;
pub mod kinematics;
pub mod learned;
pub mod linalg;
pub mod model;
pub mod params;
pub mod projection;
pub mod real;
pub mod spatial;
pub mod state;
pub mod step;
pub mod tangent;
pub mod tree;

pub use compose::Composition;
pub use dynamics::{Dynamics, Inputs, Terms};
pub use forced::{
    InputJacobian, MomentumDerivatives, RolloutDerivativeBuffers, StateJacobian, StepDerivatives,
};
pub use kinematics::{Point2, Pose2};
pub use learned::{LearnedError, LearnedModel, LearnedStepper};
pub use model::{Body, Model};
pub use params::{ElasticJoint, Joint, Link, Parameters, Spring};
pub use real::{Jet1, Jet2, JetDir, Real};
pub use state::{CoordinateKind, State};
pub use step::{
    MAX_SUBSTEPS, RolloutError, StepError, StepOptions, StepReport, StepWorkspace, Stepper,
};
pub use tangent::{Tangent, TangentDerivatives, TangentError};

/// Re-exports for generated code. Not part of the public API.
#[doc(hidden)]
pub mod __private {
    pub use nalgebra;
}
