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

/// SplitMix64 with a Box–Muller normal.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
    pub fn normal(&mut self) -> f64 {
        let u = self.uniform(f64::MIN_POSITIVE, 1.0);
        let v = self.uniform(0.0, 1.0);
        (-2.0 * u.ln()).sqrt() * (2.0 * PI * v).cos()
    }
}

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
    let vi = Variational::new(truth.minimal(), DT);
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
