//! Spatial (3-D) mechanisms: rigid links with full inertia tensors, joints
//! (revolute, prismatic, spherical, fixed, free), gravity in 3-D.
//!
//! * [`model`]: the description ([`Spatial`], [`Link3`], [`Joint3`]) and
//!   the joint constraint and rate functions, generic over [`Real`](crate::Real).
//! * [`minimal`]: minimal coordinates of the spanning tree (angles, slides,
//!   quaternions), generic over `Real`: the std runtime's `Mechanism`
//!   views evaluate these on dual numbers.
//! * [`maximal`]: maximal coordinates (centre of mass and unit quaternion
//!   per link) and [`LieStepper`], the Lie-group variational integrator
//!   with position-level joint constraints.
//! * [`views`]: the map between minimal and maximal states.
//! * [`so3`]: the exponential map, its Jacobian and the discrete angular
//!   momenta.
//! * [`geometry`]: vectors, rotations, poses and motions over any `Real`.
//!
//! Everything here is `no_std`, fixed-size and allocation-free.

pub mod geometry;
pub mod maximal;
pub mod minimal;
pub mod model;
pub mod so3;
pub mod views;

pub use geometry::{Motion3, Pose3};
pub use maximal::{LieStepReport, LieStepper, Maximal, SpatialState};
pub use model::{Joint3, JointType, Layout, Link3, ModelError, Spatial};

#[cfg(test)]
mod tests;
