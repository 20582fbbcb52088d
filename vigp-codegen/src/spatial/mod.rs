//! Spatial (3-D) mechanisms: `gravity: [gx, gy, gz]` selects them.
//!
//! The grammar is the planar one with 3-D values:
//!
//! ```text
//! /// docs
//! pub Name {
//!     gravity: [gx, gy, gz],
//!     links {
//!         name: { mass: m, inertia: [i1, i2, i3] | [[..], [..], [..]],
//!                 length?: l, com?: [x, y, z], frame?: [[x axis], [y axis], [z axis]] },
//!     }
//!     joints {
//!         name: revolute(parent, child) { axis: [ax, ay, az], damping?, actuated?, stiffness?, rest? },
//!         name: prismatic(parent, child) { axis: [ax, ay, az], damping?, actuated?, stiffness?, rest? },
//!         name: spherical(parent, child) { damping? },
//!         name: fixed(parent, child),
//!         name: free(parent, child),
//!     }
//! }
//! ```
//!
//! `actuated` (a bare flag) makes a revolute or prismatic joint an input: a
//! torque about the axis, a force along it; inputs are numbered in joint
//! declaration order and named by their joints. `stiffness: k` (≥ 0) and
//! `rest: s0` (default 0, only with `stiffness`) add the spring
//! ½k(s − s0)² on the joint coordinate s (zero in the reference
//! configuration). Spherical, fixed and free joints have no single
//! coordinate and reject all three. As in the planar DSL, only what is
//! declared is generated.
//!
//! Points: `world`, `world @ [x, y, z]`, `link.start`, `link.end`,
//! `link.center`, `link.com`, `link @ [x, y, z]`.
//!
//! The syntax is read by [`crate::syntax`] and checked by
//! [`crate::desc::spatial`]; this module emits Rust for the result: the
//! parameter types, the `vigp::spatial::Spatial` description, the maximal
//! view and the minimal-coordinate `Mechanism` view, which call generic
//! runtime code.

pub mod emit;
pub mod tree;
