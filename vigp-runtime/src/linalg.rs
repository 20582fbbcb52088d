//! Small fixed-size dense solvers for the Newton steps: re-exported from
//! the `no_std` core, where the embedded steps use them too.

pub use vigp_core::linalg::*;
