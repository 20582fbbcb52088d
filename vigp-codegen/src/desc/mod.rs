//! The meaning of a description: names resolved, numbers and shapes
//! checked, the joint graph split into a spanning tree (minimal
//! coordinates) and loop-closing joints (constraints). Every problem
//! becomes a spanned `syn::Error`, collected in a [`crate::ctxt::Ctxt`].
//!
//! A planar mechanism is a spatial one confined to a plane: both are a
//! [`Model`] of links and [`Joint`]s between [`Point`]s, checked by one
//! driver ([`validate()`]) that follows the [`Rules`] of a dimension:
//! [`planar`] and [`spatial`] say which keys a link takes, which joint
//! types exist (their `JOINTS` table: the one place to add a joint type)
//! and what their values mean. The checks every description shares live
//! in [`checks`], the spanning tree in [`graph`].

pub mod checks;
pub mod graph;
pub mod model;
pub mod planar;
pub mod spatial;
pub mod validate;

pub use model::{DefaultValue, Joint, Model, Point};
pub use validate::{Rules, validate};
