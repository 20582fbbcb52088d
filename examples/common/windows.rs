//! Random test windows cut from trajectories, shared by `#[path]` between
//! the sweeps that score predictions on them (`paper`, `scale_sweep`).

use crate::rng::Rng;
use nalgebra::SVector;
use vigp::State;

/// A start state and the true positions from it on.
pub type TestWindow<const N: usize> = (State<N>, Vec<SVector<f64, N>>);

/// `per_trajectory` windows from each of `trajectories` (positions every
/// `dt`), in order: a start k drawn uniform below `len − horizon − 1`
/// (`len`, the samples of every trajectory), the state (q_k,
/// (q_{k+1} − q_k)/dt) and the `horizon + 1` positions q_k … q_{k+horizon}.
pub fn test_windows<const N: usize>(
    trajectories: &[Vec<SVector<f64, N>>],
    per_trajectory: usize,
    len: usize,
    horizon: usize,
    dt: f64,
    rng: &mut Rng,
) -> Vec<TestWindow<N>> {
    let mut windows = Vec::new();
    for traj in trajectories {
        for _ in 0..per_trajectory {
            let k = rng.below(len - horizon - 1);
            windows.push((
                State {
                    q: traj[k],
                    v: (traj[k + 1] - traj[k]) / dt,
                },
                traj[k..=k + horizon].to_vec(),
            ));
        }
    }
    windows
}
