//! **vigp**: structure-preserving learned dynamics.
pub use vigp_runtime::*;
