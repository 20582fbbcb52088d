//! Run-time parameters of generated mechanisms (perturb them without
//! recompiling): re-exported from the `no_std` core.

pub use vigp_core::params::{ElasticJoint, Joint, Link, Spring};
