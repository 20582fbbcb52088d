//! Learning: learned integrators (planar and spatial), model files, held
//! inputs, the embedded learned stepper, parameter identification and
//! exciting trajectories.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;
use common::Rng;

/// The four-bar rhombus, declared by `drive_fourbar` and in identify.rs.
#[macro_use]
#[path = "../common/rhombus.rs"]
mod rhombus;
/// The actuated four-bar, shared by the embedded-stepper and
/// output-error files.
#[path = "../common/drive_fourbar.rs"]
mod drive_fourbar;
/// The actuated cart-pole of the embedded-stepper file, and the macro
/// that declares it, which held_inputs.rs also uses.
#[macro_use]
#[path = "../common/drive_cartpole.rs"]
mod drive_cartpole;

mod embedded_learned;
mod errors_in_variables;
mod excitation;
mod fixtures;
mod held_inputs;
mod identified_prior;
mod identify;
mod learned;
mod learned_file;
mod output_error;
mod spatial_learned;
