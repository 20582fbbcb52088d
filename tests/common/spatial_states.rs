//! Comparisons of spatial trajectories shared by tests/learn/spatial_learned.rs
//! and examples/spatial_learning.rs (included with `#[path]`).

use vigp::spatial::SpatialState;

/// Largest centre-of-mass distance between two trajectories.
pub fn distance<const B: usize>(a: &[SpatialState<B>], b: &[SpatialState<B>]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..B).map(move |i| (x.x[i] - y.x[i]).norm()))
        .fold(0.0, f64::max)
}

/// The same physical state with every quaternion negated (q and −q are the
/// same orientation).
pub fn twin<const B: usize>(z: &SpatialState<B>) -> SpatialState<B> {
    let mut t = *z;
    for q in &mut t.q {
        *q = nalgebra::UnitQuaternion::new_unchecked(-q.into_inner());
    }
    t
}
