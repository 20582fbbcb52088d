//! The description language: generated code (snapshots), fuzzed descriptions,
//! constants, the generated step against hand-written closed forms.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;

mod codegen_fuzz;
mod constants;
mod dynamics;
mod fuzz;
mod snapshots;
mod sources;
mod spatial_fuzz;
mod spatial_snapshot;
mod tree_engine;
mod urdf;
