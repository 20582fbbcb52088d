//! Exciting trajectories (`vigp::identify::excitation`): the designed
//! Fourier input against random Fourier inputs of the same amplitude, by
//! the design's own criterion and by what it is for, the covariance of the
//! identified base parameters from a noisy log.
//!
//! Numbers are printed with `-- --nocapture`.

use crate::common::Rng;
use crate::fixtures::{DT, noisy};
use crate::identify::{DrivenCartpole, DrivenDoublePendulum};
use nalgebra::DMatrix;
use vigp::identify::excitation::{Excitation, Fourier, Problem};
use vigp::identify::{DelRegressor, Identification, IdentifyError, Noise, Options, identify};
use vigp::prelude::*;
use vigp::{Inputs, Parameters};

/// ln det of a symmetric positive definite matrix.
fn log_det(a: &DMatrix<f64>) -> f64 {
    let l = a.clone().cholesky().expect("positive definite").l();
    l.diagonal().iter().map(|d| 2.0 * d.ln()).sum()
}

/// The covariance of `id`'s base parameters in the coordinates of
/// `reference`'s: both are K·π for the same null space, and K has the
/// identity at its independent columns, so θ_ref = K_ref[:, indep]·θ.
fn covariance_in(reference: &Identification, id: &Identification) -> DMatrix<f64> {
    assert_eq!(
        reference.base.rank(),
        id.base.rank(),
        "the logs inform different numbers of base parameters"
    );
    let t = reference.base.k.select_columns(&id.base.independent);
    &t * &id.base_covariance * t.transpose()
}

/// The test's own random input: coefficients uniform in [−1, 1] from the
/// tests' generator, scaled so that the peak over the samples is the
/// amplitude (the bound the design obeys).
fn random_input(rng: &mut Rng, period: f64, problem: &Problem) -> Fourier {
    let u = problem.amplitude.len();
    let f = Fourier {
        period,
        harmonics: problem.harmonics,
        coefficients: (0..u * 2 * problem.harmonics)
            .map(|_| rng.uniform(-1.0, 1.0))
            .collect(),
    };
    let peak = f.peak(problem.steps, DT);
    let factor: Vec<f64> = (0..u).map(|i| problem.amplitude[i] / peak[i]).collect();
    f.scaled(&factor)
}

/// Design for `declared`, then (i) the design's criterion (log det of the
/// scaled base-parameter information) must exceed that of each of 10
/// random inputs of the same peak amplitude, and (ii) identification
/// (midpoint rule, instrumental variables, position-noise covariance)
/// from the design's log with positions ± 1e-4 (Gaussian, σ = 1e-4)
/// must give a base-parameter covariance with a smaller log det than the
/// median of the random inputs' logs with the same noise seed. No margin
/// is asked beyond strict inequality: the claim is the ordering; the
/// margins are printed.
fn compare<M, const N: usize, const C: usize, const U: usize>(
    name: &str,
    declared: M,
    problem: &Problem,
) where
    M: Mechanism<N, C> + Parameters + Copy + Inputs<U>,
{
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let ex = Excitation::new::<U>(&r, problem).unwrap();
    let d = ex.design().unwrap();
    println!(
        "{name}: design log det {:.3} (best random start {:.3}), {} iterations, {} evaluations, \
         peak {:?} of {:?}, limit excess {:.2e}",
        d.evaluation.log_det,
        d.start_log_det,
        d.iterations,
        d.evaluations,
        d.evaluation.peak,
        problem.amplitude,
        d.evaluation.violation
    );
    for (p, a) in d.evaluation.peak.iter().zip(&problem.amplitude) {
        // The amplitude bound is exact (scaled down to it): rounding only.
        assert!(*p <= a * (1.0 + 1e-12), "{name}: peak {p} > {a}");
    }
    assert!(d.evaluation.violation <= problem.limit_tolerance);

    let options = Options {
        noise: Noise::IV,
        ..Options::default()
    };
    let noise_seed = 31;
    let id_design = identify(
        &r,
        &[noisy(&d.evaluation.log, 1e-4, &mut Rng(noise_seed))],
        &options,
    )
    .unwrap();
    let cov_design = log_det(&id_design.base_covariance);

    let mut rng = Rng(2024);
    let mut random_cov = Vec::new();
    for k in 0..10 {
        let f = random_input(&mut rng, ex.period(), problem);
        let e = ex.evaluate(&f).unwrap();
        let id = identify(&r, &[noisy(&e.log, 1e-4, &mut Rng(noise_seed))], &options).unwrap();
        let c = log_det(&covariance_in(&id_design, &id));
        println!(
            "{name}: random input {k}: log det information {:.3}, log det covariance {c:.3}, limit excess {:.2e}",
            e.log_det, e.violation
        );
        assert!(
            d.evaluation.log_det > e.log_det,
            "{name}: random input {k} is more informative ({} ≥ {})",
            e.log_det,
            d.evaluation.log_det
        );
        random_cov.push(c);
    }
    random_cov.sort_by(f64::total_cmp);
    let median = 0.5 * (random_cov[4] + random_cov[5]);
    println!(
        "{name}: log det covariance of the {} base parameters: design {cov_design:.3}, random median {median:.3} (best {:.3}, worst {:.3})",
        id_design.base.rank(),
        random_cov[0],
        random_cov[9]
    );
    assert!(
        cov_design < median,
        "{name}: design {cov_design} vs median {median}"
    );
}

/// The cart-pole with its rail actuated (±5 N, 3 s, 4 harmonics, the rail
/// kept within ±2 m).
#[test]
fn designed_input_beats_random_inputs_on_the_cartpole() {
    let mut problem = Problem::new(vec![0.0, 0.3], 300, 4, vec![5.0]);
    problem.position_limits = vec![(-2.0, 2.0), (f64::NEG_INFINITY, f64::INFINITY)];
    compare::<_, 2, 0, 1>("cartpole", DrivenCartpole::default().minimal(), &problem);
}

/// The double pendulum with its shoulder actuated (±4 N·m, 3 s, 4
/// harmonics).
#[test]
fn designed_input_beats_random_inputs_on_the_double_pendulum() {
    let problem = Problem::new(vec![0.3, -0.2], 300, 4, vec![4.0]);
    compare::<_, 2, 0, 1>(
        "double pendulum",
        DrivenDoublePendulum::default().minimal(),
        &problem,
    );
}

/// Bad problems are typed errors, not panics.
#[test]
fn bad_problems_are_errors() {
    let r = DelRegressor::midpoint(DrivenCartpole::default().minimal(), DT).unwrap();
    let good = Problem::new(vec![0.0, 0.3], 100, 2, vec![1.0]);
    let err = |p: &Problem| Excitation::new::<1>(&r, p).err();
    let mut p = good.clone();
    p.amplitude = vec![0.0];
    assert!(matches!(err(&p), Some(IdentifyError::Options { .. })));
    p.amplitude = vec![f64::NAN];
    assert!(matches!(err(&p), Some(IdentifyError::Options { .. })));
    let mut p = good.clone();
    p.position_limits = vec![(f64::NAN, 1.0), (-1.0, 1.0)];
    assert!(matches!(err(&p), Some(IdentifyError::Options { .. })));
    let mut p = good.clone();
    p.velocity_limits = vec![f64::NAN, 1.0];
    assert!(matches!(err(&p), Some(IdentifyError::Options { .. })));
    let mut p = good.clone();
    p.harmonics = 0;
    assert!(matches!(err(&p), Some(IdentifyError::Options { .. })));
    let mut p = good.clone();
    p.start = vec![0.0];
    assert!(matches!(err(&p), Some(IdentifyError::Dimension { .. })));
    let mut p = good.clone();
    p.steps = 5;
    assert!(matches!(
        err(&p),
        Some(IdentifyError::TooFewTransitions { .. })
    ));
    // A mechanism without inputs.
    let unforced =
        DelRegressor::midpoint(vigp::systems::Cartpole::default().minimal(), DT).unwrap();
    assert!(matches!(
        Excitation::new::<0>(&unforced, &Problem::new(vec![0.0, 0.3], 100, 2, vec![])),
        Err(IdentifyError::NoInputs)
    ));
}
