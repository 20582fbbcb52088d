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
