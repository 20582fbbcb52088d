//! Error bounds: the RKHS bound, Theorem 1, conformal calibration and its coverage.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;
/// The four-bar rhombus of bound.rs's actuated four-bar.
#[macro_use]
#[path = "../common/rhombus.rs"]
mod rhombus;

mod bound;
mod bound_coverage;
