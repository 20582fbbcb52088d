//! Training sets drawn with replacement from a pool of transitions, with
//! the paper's measurement noise. Shared by `#[path]` between
//! `examples/export_gp.rs` and `benches/learned/data.rs`; the includer
//! brings the generator of tests/common/rng.rs into scope as `Rng`.

use super::Rng;
use vigp::learned::Transition;

/// `n` transitions drawn from `pool`, each with noise σ = 1e-3 added to
/// its positions, velocities and target velocities.
pub fn noisy_draw<const N: usize>(
    pool: &[Transition<N>],
    n: usize,
    rng: &mut Rng,
) -> Vec<Transition<N>> {
    (0..n)
        .map(|_| {
            let mut t = pool[(rng.next_u64() % pool.len() as u64) as usize];
            for i in 0..N {
                t.z.q[i] += 1e-3 * rng.normal();
                t.z.v[i] += 1e-3 * rng.normal();
                t.v_next[i] += 1e-3 * rng.normal();
            }
            t
        })
        .collect()
}
