//! Fixtures of the identification tests, shared with
//! `examples/identify_coverage.rs` (by `#[path]`): a driven, sprung double
//! pendulum, a perturbed "true" mechanism, logs that the variational
//! integrators wrote, position noise, and the base-parameter error.
//! The includer provides `Rng` (tests/common/rng.rs) at its root.

#![allow(dead_code)] // each includer uses its own part of this file

use super::Rng;
use nalgebra::SVector;
use vigp::identify::{Identification, Log, Structure};
use vigp::prelude::*;
use vigp::{Parameters, State, Variational};

vigp::mechanism! {
    /// A driven double pendulum with springs (inputs and stiffness·rest).
    pub DrivenSprung {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 0.8, length: 0.7 },
        }
        joints {
            shoulder: revolute(world, upper.start) { damping: 0.1, actuated, stiffness: 3.0, rest: 0.4 },
            elbow: revolute(upper.end, lower.start) { damping: 0.2, actuated, stiffness: 2.0, rest: -0.3 },
        }
    }
}

/// A torque or force input: a sum of two sines.
pub fn drive(k: usize) -> f64 {
    let t = k as f64 * DT;
    2.0 * (1.7 * t).sin() + 1.0 * (4.3 * t + 0.5).cos()
}

pub const DT: f64 = 0.01;

/// Perturb every inertial parameter (masses and inertias ×U[0.8, 1.2],
/// centres of mass moved by up to 5 cm in every direction) and set every
/// damping to U[0.05, 0.3] (stiffness ×U[0.8, 1.2], rest ±0.1): a "true"
/// mechanism unlike the declared one.
pub fn perturbed<M: Parameters + Copy>(m: M, rng: &mut Rng) -> M {
    let mut t = m;
    let mut factor = 1.0;
    for (i, name) in M::PARAMETER_NAMES.iter().enumerate() {
        let p = t.parameter_mut(i).unwrap();
        if name.ends_with(".mass") || name.ends_with(".stiffness") {
            *p *= rng.uniform(0.8, 1.2);
        } else if name.contains(".inertia") {
            // One factor per link on its principal moments (drawn at the
            // first entry, `inertia` or `inertia.xx`); off-diagonal entries
            // stay (zero): the tensor stays symmetric and realisable.
            if name.ends_with(".inertia") || name.ends_with(".xx") {
                factor = rng.uniform(0.8, 1.2);
            }
            let diag = name.ends_with(".inertia")
                || name.ends_with(".xx")
                || name.ends_with(".yy")
                || name.ends_with(".zz");
            if diag {
                *p *= factor;
            }
        } else if name.contains(".com.") {
            *p += rng.uniform(-0.05, 0.05);
        } else if name.ends_with(".damping") {
            *p = rng.uniform(0.05, 0.3);
        } else if name.ends_with(".rest") {
            *p += rng.uniform(-0.1, 0.1);
        }
    }
    t
}

/// A log written by the VI (first order: α = 0, midpoint: α = ½) of the
/// mechanism `m` from `q0` at rest (projected onto the constraints), with
/// the inputs `u(k)` applied by the forced rollout.
pub fn vi_log<M, const N: usize, const C: usize, const U: usize>(
    m: M,
    alpha: f64,
    q0: SVector<f64, N>,
    steps: usize,
    u: impl Fn(usize) -> SVector<f64, U>,
) -> Log
where
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
{
    let z0 = vigp::projection::consistent_state(&m, &q0, &SVector::zeros(), DT).unwrap();
    let vi = if alpha == 0.0 {
        Variational::new(m, DT).unwrap()
    } else {
        Variational::midpoint(m, DT).unwrap()
    };
    let inputs: Vec<SVector<f64, U>> = (0..steps).map(&u).collect();
    let traj: Vec<State<N>> = vi.rollout_forced(&z0, &inputs).unwrap();
    let mut positions: Vec<Vec<f64>> = traj.iter().map(|z| z.q.as_slice().to_vec()).collect();
    // The last state's discrete velocity gives one more sample.
    let last = traj.last().unwrap();
    positions.push((last.q + last.v * DT).as_slice().to_vec());
    let log_inputs = if U == 0 {
        Vec::new()
    } else {
        // Input j of the rollout acts over [t_{j+1}, t_{j+2}] (log row j + 1).
        // (The last sample's own input acts after the log ends.)
        let mut v = vec![vec![0.0; U]];
        v.extend(inputs.iter().map(|x| x.as_slice().to_vec()));
        v.push(vec![0.0; U]);
        v
    };
    Log {
        positions,
        inputs: log_inputs,
    }
}

/// The largest relative error of the base parameters: |K(π̂ − π*)|_i over
/// Σ_j |K_ij π*_j| (the size of the combination's terms).
pub fn base_error(id: &Identification, truth: &[f64]) -> f64 {
    let k = &id.base.k;
    (0..k.nrows())
        .map(|i| {
            let err: f64 = (0..k.ncols())
                .map(|j| k[(i, j)] * (id.estimate[j] - truth[j]))
                .sum();
            let size: f64 = (0..k.ncols()).map(|j| (k[(i, j)] * truth[j]).abs()).sum();
            err.abs() / size
        })
        .fold(0.0, f64::max)
}

pub fn standard<M: Parameters>(m: &M) -> Vec<f64> {
    Structure::of::<M>()
        .unwrap()
        .standard(|i| m.parameter(i).unwrap())
}

/// Gaussian noise by Box–Muller.
pub fn gauss(rng: &mut Rng) -> f64 {
    let u1 = rng.uniform(1e-300, 1.0);
    let u2 = rng.uniform(0.0, 1.0);
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

pub fn noisy(log: &Log, sigma: f64, rng: &mut Rng) -> Log {
    Log {
        positions: log
            .positions
            .iter()
            .map(|x| x.iter().map(|v| v + sigma * gauss(rng)).collect())
            .collect(),
        inputs: log.inputs.clone(),
    }
}

/// The coverage case: the driven, sprung double pendulum, its truth
/// perturbed with seed 9, logged by the midpoint rule for `steps` steps
/// from (0.5, 0.2) under two sums of sines.
pub struct Coverage {
    /// The declared mechanism.
    pub declared: DrivenSprungMinimal,
    /// The truth's standard parameters.
    pub truth: Vec<f64>,
    /// The noise-free log.
    pub clean: Log,
}

/// [`Coverage`] with a log of `steps` steps.
pub fn coverage_case(steps: usize) -> Coverage {
    let declared = DrivenSprung::default().minimal();
    let truth = perturbed(declared, &mut Rng(9));
    let clean = vi_log::<_, 2, 0, 2>(truth, 0.5, SVector::from([0.5, 0.2]), steps, |k| {
        let t = k as f64 * DT;
        SVector::from([3.0 * (1.3 * t).sin() + 1.0, 2.0 * (2.1 * t + 0.4).cos()])
    });
    Coverage {
        declared,
        truth: standard(&truth),
        clean,
    }
}

/// For each base parameter of `id`, whether its 95 % interval holds the
/// truth's value.
pub fn covers(id: &Identification, truth: &[f64]) -> Vec<bool> {
    let k = &id.base.k;
    (0..k.nrows())
        .map(|i| {
            let t: f64 = (0..k.ncols()).map(|j| k[(i, j)] * truth[j]).sum();
            (id.base_estimate[i] - t).abs() <= id.base_half_width[i]
        })
        .collect()
}
