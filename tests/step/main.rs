//! Stepping: the variational integrators (planar and spatial, minimal and
//! maximal views), their derivatives, conservation laws, peers (MuJoCo),
//! robots and stress cases.
//!
//! One test binary per concept (the map: tests/README.md); each module
//! below is one file of it.

#[path = "../common/mod.rs"]
mod common;
#[macro_use]
#[path = "../common/slider_crank.rs"]
mod slider_crank;
#[macro_use]
#[path = "../common/rhombus.rs"]
mod rhombus;
#[macro_use]
#[path = "../common/spatial_four_bar.rs"]
mod spatial_four_bar;
/// The macro of the actuated cart-pole, for control.rs's sprung one.
#[macro_use]
#[allow(dead_code)] // the cart-pole declared beside the macro is not used here
#[path = "../common/drive_cartpole.rs"]
mod drive_cartpole;

mod control;
mod embedded;
mod fourth_order;
mod handwritten;
mod integrator;
mod maximal;
mod nominal;
mod properties;
mod robot;
mod spatial;
mod spatial_control;
mod spatial_mujoco;
mod stress;
mod tangent;
mod universal;
mod workflow;
