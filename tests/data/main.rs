//! Logged data: the CSV reader and the mistakes users make with logs and models.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;

mod data;
mod mistakes;
