//! Which items a mechanism expands to: everything (std) or only the
//! `no_std` items.

/// Which items a mechanism expands to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Everything: the `no_std` items plus the std runtime's dual-number
    /// views (`Mechanism` impls, the maximal view, the coordinate maps).
    /// What `vigp` with its default `std` feature gets.
    Std,
    /// Only the `no_std` items: parameters, forward kinematics and the
    /// `vigp::embedded::Model` impl. What `vigp` without `std` gets.
    NoStd,
}
