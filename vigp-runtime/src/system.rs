//! Mechanisms as values that generic tools can take apart: [`System`] is
//! implemented by every `mechanism!` parameter struct and hands its two
//! coordinate views, with their sizes, to a [`ViewVisitor`].
//!
//! The sizes N, C (minimal) and NM, CM (maximal), and the number U of
//! inputs (actuated joints), are const generics of the views' methods,
//! which a trait cannot derive from associated constants on stable Rust;
//! the visitor receives them as const parameters instead. This is how
//! `vigp::cli::main::<MyMechanism>()` runs the whole command-line tool on a
//! user's mechanism from one line.

pub use vigp_core::Parameters;

use crate::mechanism::{Coordinates, Mechanism};

/// A planar mechanism declared with `mechanism!`: its run-time parameters
/// ([`Parameters`], [`Default`] = the DSL's values) and both coordinate
/// views.
///
/// Spatial mechanisms (`gravity: [gx, gy, gz]`) do not implement it: their
/// maximal view is a Lie-group integrator, not a [`Mechanism`], so the
/// command-line tool (`vigp::cli::main`) and other tools generic over
/// `System` take planar mechanisms only. A 3-D mechanism is learned in
/// Rust: `vigp::spatial::learned::LearnedSpatial` (see docs/spatial.md).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a planar `mechanism!`: tools generic over `System` (such as `vigp::cli::main`) take planar mechanisms only",
    note = "a 3-D mechanism (`gravity: [gx, gy, gz]`) is learned in Rust with `vigp::spatial::learned::LearnedSpatial`; the command-line tool does not take it"
)]
pub trait System: Parameters + Default + Copy + Send + Sync + 'static {
    /// Calls `visitor` with the minimal and the maximal view of these
    /// parameters.
    fn visit<V: ViewVisitor>(&self, visitor: V) -> V::Output;
}

/// A computation generic over a mechanism's two coordinate views (see
/// [`System::visit`]).
pub trait ViewVisitor {
    /// What the computation returns.
    type Output;

    /// Runs on the minimal view (`N` coordinates, `C` loop equations) and
    /// the maximal view (`NM` = 3 per link, `CM` joint equations) of a
    /// mechanism with `U` inputs (`Dynamics::INPUTS`, the actuated joints:
    /// the length of the input vectors of its forced steps, which both
    /// views take: [`vigp_core::Inputs`]).
    fn visit<
        Mn,
        Mx,
        const N: usize,
        const C: usize,
        const NM: usize,
        const CM: usize,
        const U: usize,
    >(
        self,
        minimal: Mn,
        maximal: Mx,
    ) -> Self::Output
    where
        Mn: Mechanism<N, C> + Coordinates<N, NM> + Parameters + Copy + Send + Sync + 'static,
        Mx: Mechanism<NM, CM> + Parameters + Copy + Send + Sync + 'static,
        Mn: vigp_core::Inputs<U>,
        Mx: vigp_core::Inputs<U>;
}
