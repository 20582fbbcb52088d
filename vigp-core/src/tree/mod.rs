//! The linear-time engine of kinematic trees: minimal coordinates (one per
//! revolute or prismatic joint) of a fixed-base tree of rigid bodies, the
//! first-order variational step in O(N) per residual and per solve.
//!
//! * [`model`]: the tree as data ([`Body`]: parent, joint type and axis,
//!   joint placement, mass properties, damping, spring, limits) and the
//!   [`Tree`] trait through which the engine reads it. Run-time data
//!   ([`TreeRef`], [`TreeArray`], or a `Vec`-backed model in the std runtime) and
//!   generated constants implement the same trait.
//! * [`links3`]: a 3-D tree description (links with reference frames)
//!   as such bodies.
//! * [`planar`]: a planar tree (what `mechanism!` declares in the plane)
//!   as such bodies.
//! * [`spatial`]: 6-D motion and force vectors and spatial inertias, all in
//!   world coordinates at the world origin.
//! * [`Engine`]: momentum, ∂T/∂q, ∇V, the DEL residual, the articulated-body
//!   solve and the self-subdividing step ([`engine`] has the equations), and
//!   the step's exact derivatives A and B ([`derivatives`]).
//! * [`LearnedTree`]: a learned robot as exported data (bodies, prior,
//!   encoding, one GP per joint) and its allocation-free stepper.
//!
//! Nothing here allocates: the caller passes a slice of [`BodyScratch`],
//! one per body (about 1 KB each).

pub mod derivatives;
pub mod engine;
pub mod learned;
pub mod links3;
pub mod model;
pub mod planar;
pub mod spatial;

pub use derivatives::{DerivativeBuffers, derivative_scratch_len};
pub use engine::{BodyScratch, Engine, EngineError, EngineOptions, EngineReport, TermDerivatives};
pub use learned::{LearnedTree, LearnedTreeDerivatives, LearnedTreeStepper, TreeDerivativeScratch};
pub use model::{Bodies, Body, InvalidTree, JointKind, Limits, Tree, TreeArray, TreeRef, validate};

#[cfg(test)]
mod tests;
