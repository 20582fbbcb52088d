//! Learning in space: which rotation representation should a GP see?
//!
//! The Furuta pendulum with unmodelled joint friction is learned on top of
//! its frictionless model (paper eq. 7/8 in maximal coordinates) from K
//! trajectories of random initial states, with the orientations given to
//! the GP as rotation matrices or as quaternions. Prints the mean and worst
//! centre-of-mass error of 0.3 s predictions from fresh random states (and
//! from the same states with every quaternion negated: the same physical
//! state), against the nominal model.
//!
//! ```text
//! cargo run --release --example spatial_learning            # K = 6, 20 steps each
//! cargo run --release --example spatial_learning -- 12 30   # K, steps
//! ```

use nalgebra::SVector;
use vigp::Integrator;
use vigp::gp::TrainOptions;
use vigp::learned::Prior;
use vigp::projection::consistent_state;
use vigp::spatial::learned::{Configuration, LearnedSpatial, Rotation, transitions};
use vigp::spatial::{LieStepper, SpatialState};
use vigp::systems::spatial::Furuta;

#[path = "../tests/common/rng.rs"]
mod rng;
use rng::Rng;

#[path = "../tests/common/spatial_states.rs"]
mod spatial_states;
use spatial_states::{distance, twin};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let k: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(6);
    let steps: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(20);
    let dt = 0.01;
    let mut truth = Furuta::default();
    truth.joints.base.damping = 0.02;
    truth.joints.pivot.damping = 0.001;
    let nominal = Furuta::default();
    let t_step = LieStepper::new(truth.maximal(), dt)?;
    let n_step = LieStepper::new(nominal.maximal(), dt)?;
    let mut rng = Rng(5);
    let random_state = |rng: &mut Rng| -> Result<SpatialState<2>, Box<dyn std::error::Error>> {
        let q = [
            rng.uniform(0.0, std::f64::consts::TAU),
            rng.uniform(1.8, 4.4),
        ];
        let v = [rng.uniform(-4.0, 4.0), rng.uniform(-2.0, 2.0)];
        let z = consistent_state(&nominal.minimal(), &SVector::from(q), &SVector::from(v), dt)?;
        Ok(nominal.minimal().to_maximal(&z, dt))
    };
    let mut data = Vec::new();
    for _ in 0..k {
        let z0 = random_state(&mut rng)?;
        let traj = t_step.rollout(&z0, steps + 1)?;
        let configs: Vec<Configuration<2>> = traj.iter().map(|z| (z.x, z.q)).collect();
        data.extend(transitions(&configs, dt));
    }
    let opts = TrainOptions {
        restarts: 3,
        seed: 1,
        ..TrainOptions::default()
    };
    let t = std::time::Instant::now();
    let (matrix, _) =
        LearnedSpatial::train(n_step, &data, Rotation::Matrix, Prior::Nominal, &opts)?;
    let (quat, _) =
        LearnedSpatial::train(n_step, &data, Rotation::Quaternion, Prior::Nominal, &opts)?;
    println!(
        "Furuta, friction base 0.02 / pivot 0.001 N·m·s/rad unmodelled; {k} trajectories × {steps} steps = {} transitions; training both: {:.1} s",
        data.len(),
        t.elapsed().as_secs_f64()
    );
    let tests = 20;
    let horizon = 30;
    let (mut e_nom, mut e_m, mut e_q, mut e_mt, mut e_qt) =
        (vec![], vec![], vec![], vec![], vec![]);
    for _ in 0..tests {
        let z = random_state(&mut rng)?;
        let reference = t_step.rollout(&z, horizon)?;
        e_nom.push(distance(&reference, &n_step.rollout(&z, horizon)?));
        e_m.push(distance(&reference, &matrix.rollout(&z, horizon)?));
        e_q.push(distance(&reference, &quat.rollout(&z, horizon)?));
        e_mt.push(distance(&reference, &matrix.rollout(&twin(&z), horizon)?));
        e_qt.push(distance(&reference, &quat.rollout(&twin(&z), horizon)?));
    }
    let stats = |e: &[f64]| {
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        let worst = e.iter().cloned().fold(0.0, f64::max);
        let wins = e.iter().zip(&e_nom).filter(|(a, b)| a < b).count();
        (mean, worst, wins)
    };
    println!(
        "{tests} fresh random states, {horizon}-step (0.3 s) predictions, centre-of-mass error (m):"
    );
    println!(
        "{:<34} {:>10} {:>10} {:>14}",
        "model", "mean", "worst", "beats nominal"
    );
    for (name, e) in [
        ("nominal (no friction)", &e_nom),
        ("learned, rotation-matrix inputs", &e_m),
        ("learned, quaternion inputs", &e_q),
        ("  rotation matrix, −q states", &e_mt),
        ("  quaternion, −q states", &e_qt),
    ] {
        let (m, w, n) = stats(e);
        println!("{name:<34} {m:>10.3e} {w:>10.3e} {n:>10}/{tests}");
    }
    Ok(())
}
