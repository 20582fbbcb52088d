//! Mechanisms as values that generic tools can take apart: [`System`] is
//! implemented by every `mechanism!` parameter struct and hands its
//! coordinate views, with their sizes, to a [`ViewVisitor`]: a planar
//! mechanism both its minimal and its maximal view
//! ([`ViewVisitor::visit`]), a 3-D mechanism its minimal view
//! ([`ViewVisitor::visit_minimal`]; its maximal view, each link's position
//! and orientation, is a Lie-group integrator, not a [`Mechanism`]).
//!
//! The sizes N, C (minimal) and NM, CM (maximal), and the number U of
//! inputs (actuated joints), are const generics of the views' methods,
//! which a trait cannot derive from associated constants on stable Rust;
//! the visitor receives them as const parameters instead. This is how
//! `vigp::cli::main::<MyMechanism>()` runs the whole command-line tool on a
//! user's mechanism, planar or 3-D, from one line.

pub use vigp_core::Parameters;

use crate::mechanism::{Coordinates, Mechanism};

/// A mechanism declared with `mechanism!`: its run-time parameters
/// ([`Parameters`], [`Default`] = the DSL's values) and its coordinate
/// views, handed to a [`ViewVisitor`]. Planar mechanisms hand over both
/// views ([`ViewVisitor::visit`]); 3-D mechanisms (`gravity: [gx, gy, gz]`)
/// their minimal view ([`ViewVisitor::visit_minimal`]): their maximal view
/// is a Lie-group integrator (`vigp::spatial::LieStepper`, learned with
/// `vigp::spatial::learned::LearnedSpatial`), not a [`Mechanism`].
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a `mechanism!`: tools generic over `System` (such as `vigp::cli::main`) take the parameter structs that `mechanism!` declares",
    note = "declare the mechanism with `vigp::mechanism!` (with vigp's `std` feature) and pass its parameter struct, not one of its views"
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

    /// Runs on the minimal view alone (`N` coordinates, `C` constraint
    /// equations: loop closures, then one unit-norm row per quaternion) of a
    /// 3-D mechanism with `U` inputs, whose maximal view is not a
    /// [`Mechanism`] (each link's position and orientation: a Lie group,
    /// integrated by `vigp::spatial::LieStepper`).
    fn visit_minimal<Mn, const N: usize, const C: usize, const U: usize>(
        self,
        minimal: Mn,
    ) -> Self::Output
    where
        Mn: Mechanism<N, C> + Parameters + Copy + Send + Sync + 'static,
        Mn: vigp_core::Inputs<U>;
}
