//! The double-pendulum training data and model of the `learned` benchmark,
//! shared with `examples/variance_precision.rs` (which measures the same
//! model): a seeded SplitMix64 generator, the paper's data and the training.

use std::f64::consts::PI;

use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, LearnError, Learned, Prior, Transition, transitions};
use vigp::prelude::*;
use vigp::systems::{DoublePendulum, DoublePendulumMinimal};

/// The time step of the data and of the learned model.
pub const DT: f64 = 0.01;

#[path = "../../tests/common/rng.rs"]
mod rng;
pub use rng::Rng;

#[path = "../../examples/common/noisy_draw.rs"]
mod noisy_draw;
use noisy_draw::noisy_draw;

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
    noisy_draw(&pool, n, &mut rng)
}

/// The model the benchmark measures: a GP on [`data`]`(n, 7 + n)` with the
/// sin/cos encoding and `prior` (2 restarts, seed 1).
pub fn train(n: usize, prior: Prior) -> Result<Learned<DoublePendulumMinimal, 2, 0>, LearnError> {
    let opts = TrainOptions {
        restarts: 2,
        seed: 1,
        ..TrainOptions::default()
    };
    let (l, _) = Learned::train(
        DoublePendulum::default().minimal(),
        DT,
        &data(n, 7 + n as u64),
        Encoding::SinCos,
        prior,
        &opts,
    )?;
    Ok(l)
}
