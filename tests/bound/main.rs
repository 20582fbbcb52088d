//! Error bounds: the RKHS bound, Theorem 1, conformal calibration and its coverage.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;

mod bound;
mod bound_coverage;
