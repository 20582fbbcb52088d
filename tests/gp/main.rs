//! The GP engine: export, gradients, robustness, screening, scikit-learn
//! agreement, sparse GPs.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;

mod gp_export;
mod gp_gradient;
mod gp_robustness;
mod gp_screening;
mod gp_sklearn;
mod gp_sparse;
