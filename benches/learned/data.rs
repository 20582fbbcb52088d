//! The double-pendulum training data of the `learned` benchmark, shared
//! with `examples/variance_precision.rs` (which measures the same model):
//! a seeded SplitMix64 generator and the paper's data.

use std::f64::consts::PI;

use nalgebra::SVector;
use vigp::learned::{Transition, transitions};
use vigp::prelude::*;
use vigp::systems::DoublePendulum;

/// The time step of the data and of the learned model.
pub const DT: f64 = 0.01;

#[path = "../../tests/common/rng.rs"]
mod rng;
pub use rng::Rng;

/// The paper's double-pendulum data: a damped, mass-perturbed "truth",
/// trajectories of 2 s from random configurations at rest, noise σ = 1e-3
/// on q, v and the targets; `n` transitions drawn from the pool.
pub fn data(n: usize, seed: u64) -> Vec<Transition<2>> {
    let mut rng = Rng(seed);
    let mut truth = DoublePendulum::default();
    truth.links.upper.mass *= 1.05;
    truth.links.lower.mass *= 0.95;
    truth.joints.shoulder.damping = 0.8;
    truth.joints.elbow.damping = 0.2;
    let vi = Variational::new(truth.minimal(), DT).unwrap();
    let mut pool = Vec::new();
    for _ in 0..20 {
        let q0 = SVector::from([rng.uniform(-PI, PI), rng.uniform(-PI, PI)]);
        let traj = vi
            .rollout(
                &State {
                    q: q0,
                    v: SVector::zeros(),
                },
                200,
            )
            .expect("ground truth");
        let q: Vec<_> = traj.iter().map(|z| z.q).collect();
        pool.extend(transitions(&q, DT));
    }
    (0..n)
        .map(|_| {
            let mut t = pool[(rng.next_u64() % pool.len() as u64) as usize];
            for i in 0..2 {
                t.z.q[i] += 1e-3 * rng.normal();
                t.z.v[i] += 1e-3 * rng.normal();
                t.v_next[i] += 1e-3 * rng.normal();
            }
            t
        })
        .collect()
}
