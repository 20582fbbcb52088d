//! The output-error stage of identification
//! (`vigp::identify::output_error`): its exact sensitivities against
//! central differences of its own simulation, recovery from noise-free
//! logs, and its gain over the regression under position noise.
//!
//! Numbers are printed with `-- --nocapture`.

use crate::common::Rng;
use crate::fixtures::{
    DT, DrivenSprung, DrivenSprungMinimal, base_error, coverage_case, covers, drive, noisy,
    perturbed, standard, vi_log,
};
use crate::identify::Arm;
use nalgebra::SVector;
use vigp::Parameters;
use vigp::identify::output_error::simulate;
use vigp::identify::{
    DelRegressor, IdentifyError, Log, Noise, Options, OutputError, Regressor, identify,
};
use vigp::systems::Fourbar;

/// The largest |exact − central difference| of the sensitivities of a
/// 40-sample simulation, relative to the largest sensitivity, with step
/// h = 1e-6·(1 + |p|) per parameter or initial position.
fn sensitivity_defect<R: Regressor>(r: &R, log: &Log, pi: &[f64]) -> (f64, f64) {
    let n = r.coordinates();
    let len = 40;
    let initial: Vec<f64> = log.positions[0]
        .iter()
        .chain(&log.positions[1])
        .cloned()
        .collect();
    let exact = simulate(r, log, 0, len, pi, &initial, true).unwrap();
    let flat = |s: &vigp::identify::output_error::Simulation| -> Vec<f64> {
        s.positions.iter().flatten().cloned().collect()
    };
    let central = |f: &dyn Fn(f64) -> Vec<f64>, h: f64| -> Vec<f64> {
        let (p, m) = (f(h), f(-h));
        p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect()
    };
    let mut worst_pi: f64 = 0.0;
    let scale_pi = exact.wrt_pi.amax();
    for i in 0..pi.len() {
        let h = 1e-6 * (1.0 + pi[i].abs());
        let fd = central(
            &|d| {
                let mut p = pi.to_vec();
                p[i] += d;
                flat(&simulate(r, log, 0, len, &p, &initial, false).unwrap())
            },
            h,
        );
        for (row, v) in fd.iter().enumerate() {
            worst_pi = worst_pi.max((exact.wrt_pi[(row, i)] - v).abs() / scale_pi);
        }
    }
    let mut worst_x: f64 = 0.0;
    let scale_x = exact.wrt_start.amax();
    for i in 0..2 * n {
        let h = 1e-6 * (1.0 + initial[i].abs());
        let fd = central(
            &|d| {
                let mut x = initial.clone();
                x[i] += d;
                flat(&simulate(r, log, 0, len, pi, &x, false).unwrap())
            },
            h,
        );
        for (row, v) in fd.iter().enumerate() {
            worst_x = worst_x.max((exact.wrt_start[(row, i)] - v).abs() / scale_x);
        }
    }
    (worst_pi, worst_x)
}

/// A midpoint log of the driven, sprung double pendulum `m` for `steps`
/// steps from (0.5, 0.2) at rest, under `drive(k)` and `drive(k + 30)`.
fn sprung_log(m: DrivenSprungMinimal, steps: usize) -> Log {
    vi_log::<_, 2, 0, 2>(m, 0.5, SVector::from([0.5, 0.2]), steps, |k| {
        SVector::from([drive(k), drive(k + 30)])
    })
}

/// ∂x/∂π and ∂x/∂(x₀, x₁) by the implicit function theorem against
/// central differences of the same simulation, planar (driven, sprung,
/// damped double pendulum, midpoint rule) and spatial (the 3-D arm, first
/// order), at parameters unlike the log's. Tolerance 1e-6 of the largest
/// sensitivity: central differences with h ≈ 1e-6 carry a truncation
/// error ≈ h² ≈ 1e-12 and a rounding error ≈ 1e-16/h ≈ 1e-10 of the
/// positions, amplified along 40 steps.
#[test]
fn sensitivities_match_central_differences() {
    let mut rng = Rng(3);
    let declared = DrivenSprung::default().minimal();
    let truth = perturbed(declared, &mut rng);
    let log = sprung_log(truth, 60);
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let (p, x) = sensitivity_defect(&r, &log, &r.standard());
    println!("driven sprung, midpoint: ∂x/∂π {p:.1e}, ∂x/∂(x0, x1) {x:.1e}");
    assert!(p < 1e-6 && x < 1e-6, "{p:e} {x:e}");

    let declared = Arm::default().minimal();
    let truth = perturbed(declared, &mut rng);
    let log = vi_log::<_, 3, 0, 2>(truth, 0.0, SVector::from([0.3, 0.7, -0.4]), 60, |k| {
        SVector::from([drive(k), drive(k + 50)])
    });
    let r = DelRegressor::first_order(declared, DT).unwrap();
    let (p, x) = sensitivity_defect(&r, &log, &r.standard());
    println!("spatial arm, first order: ∂x/∂π {p:.1e}, ∂x/∂(x0, x1) {x:.1e}");
    assert!(p < 1e-6 && x < 1e-6, "{p:e} {x:e}");
}

/// On a log that the VI itself wrote (no noise), the simulation at the
/// true parameters reproduces the log, so the refinement keeps the first
/// stage's exact recovery: every base parameter to ≤ 1e-8 relative (the
/// standard of the noise-free tests of the first stage).
#[test]
fn noise_free_logs_stay_recovered() {
    let mut rng = Rng(5);
    let declared = DrivenSprung::default().minimal();
    let truth = perturbed(declared, &mut rng);
    let log = sprung_log(truth, 600);
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let options = Options {
        output_error: Some(OutputError::default()),
        ..Options::default()
    };
    let id = identify(&r, &[log], &options).unwrap();
    let err = base_error(&id, &standard(&truth));
    let refinement = id.refinement.as_ref().unwrap();
    println!("noise-free: max relative base error {err:.1e}; {refinement:?}");
    assert!(err <= 1e-8, "{err:e}");
}

/// Position noise σ = 1e-3 at 10 ms on the driven, sprung double
/// pendulum (midpoint rule, 15 s): the first stage (instrumental
/// variables) against the first stage refined by output error, over 4
/// seeds. Accuracy is the largest relative base-parameter error of a
/// seed. The refinement must be more accurate on every seed and at least
/// 3× more accurate in the root mean square over the seeds ("several
/// times better"; measured: 2.3× to 30× per seed), its intervals must
/// hold the truth in at least 85 % of the (seed, base parameter) pairs (48 pairs: 95 % coverage gives ≥ 85 % with
/// probability > 0.99), and its estimate of σ must be within 10 % of the
/// true one (≈ 6000 residuals: the standard error of σ̂ is 1 %).
#[test]
fn output_error_beats_the_regression_under_noise() {
    let case = coverage_case(1500);
    let r = DelRegressor::midpoint(case.declared, DT).unwrap();
    let t = &case.truth;
    let first = Options {
        noise: Noise::IV,
        ..Options::default()
    };
    let second = Options {
        output_error: Some(OutputError::default()),
        ..first
    };
    let (mut covered, mut total) = (0, 0);
    let (mut sa, mut sb) = (0.0, 0.0);
    for seed in 0..4 {
        let log = noisy(&case.clean, 1e-3, &mut Rng(2000 + seed));
        let a = identify(&r, std::slice::from_ref(&log), &first).unwrap();
        let b = identify(&r, &[log], &second).unwrap();
        let (ea, eb) = (base_error(&a, t), base_error(&b, t));
        let refinement = b.refinement.as_ref().unwrap();
        println!(
            "seed {seed}: regression {ea:.2e}, output error {eb:.2e} ({:.1}×); σ̂ {:.3e}, \
             {} iterations, rms {:.2e} → {:.2e}",
            ea / eb,
            refinement.position_sigma,
            refinement.iterations,
            refinement.rms_start,
            refinement.rms
        );
        assert!(eb < ea, "seed {seed}: {eb:e} vs {ea:e}");
        sa += ea * ea;
        sb += eb * eb;
        assert!(
            (refinement.position_sigma / 1e-3 - 1.0).abs() < 0.1,
            "{}",
            refinement.position_sigma
        );
        let hits = covers(&b, t);
        total += hits.len();
        covered += hits.iter().filter(|h| **h).count();
    }
    let gain = (sa / sb).sqrt();
    let frac = covered as f64 / total as f64;
    println!(
        "root mean square over seeds: {gain:.1}× more accurate; 95 % intervals hold the \
         truth in {covered}/{total} = {frac:.3}"
    );
    assert!(gain >= 3.0, "{gain}");
    assert!(frac >= 0.85, "{frac}");
}

/// A mechanism with loops (the fourbar: 4 angles, 2 loop equations) is
/// simulated with its multipliers: each step solves r = G(x_k)ᵀλ,
/// g(x_{k+1}) = 0 for (x_{k+1}, λ). Checked, on a midpoint log that the VI
/// wrote from a perturbed truth:
/// * the simulation at the truth's parameters from the log's first two
///   samples reproduces the log to 1e-10 rad (the VI and the simulation
///   solve the same equations, each to a Newton tolerance of 1e-12–1e-13,
///   over 60 steps);
/// * its sensitivities match central differences to 1e-6 of the largest
///   (as for the trees in `sensitivities_match_central_differences`);
/// * `identify` refines such a log (unforced, so output error runs by
///   itself) to a simulation error below 1e-8 rad.
#[test]
fn loops_are_simulated_with_their_multipliers() {
    let declared = Fourbar::default().minimal();
    let truth = perturbed(declared, &mut Rng(21));
    let q0 = SVector::from([0.6, -0.4, -0.3, 0.5]);
    let log = vi_log::<_, 4, 2, 0>(truth, 0.5, q0, 300, |_| SVector::zeros());
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let initial: Vec<f64> = log.positions[0]
        .iter()
        .chain(&log.positions[1])
        .cloned()
        .collect();
    let sim = simulate(&r, &log, 0, 60, &standard(&truth), &initial, false).unwrap();
    let gap = sim.error.amax();
    println!("fourbar at the truth: simulation − log {gap:.1e} rad");
    assert!(gap <= 1e-10, "{gap:e}");
    let (p, x) = sensitivity_defect(&r, &log, &r.standard());
    println!("fourbar, midpoint: ∂x/∂π {p:.1e}, ∂x/∂(x0, x1) {x:.1e}");
    assert!(p < 1e-6 && x < 1e-6, "{p:e} {x:e}");
    let id = identify(&r, std::slice::from_ref(&log), &Options::default()).unwrap();
    let refinement = id.refinement.as_ref().expect("output error ran");
    println!("fourbar, noise-free: {refinement:?}");
    assert!(refinement.homogeneous);
    assert!(refinement.rms <= 1e-8, "{refinement:?}");
}

/// Options out of range are typed errors.
#[test]
fn bad_options_are_typed_errors() {
    let declared = DrivenSprung::default().minimal();
    let log = sprung_log(declared, 40);
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    for oe in [
        OutputError {
            segment: 2,
            ..OutputError::default()
        },
        OutputError {
            tolerance: f64::NAN,
            ..OutputError::default()
        },
    ] {
        let options = Options {
            output_error: Some(oe),
            ..Options::default()
        };
        let e = identify(&r, std::slice::from_ref(&log), &options).unwrap_err();
        assert!(matches!(e, IdentifyError::Options { .. }), "{e}");
    }
    let pi = r.standard();
    let e = simulate(&r, &log, 0, 10, &pi, &[0.0; 3], false).unwrap_err();
    assert!(matches!(e, IdentifyError::Dimension { .. }), "{e}");
    let e = simulate(&r, &log, 35, 10, &pi, &[0.0; 4], false).unwrap_err();
    assert!(matches!(e, IdentifyError::Options { .. }), "{e}");
}

/// A log without inputs cannot fix the overall scale of π: the unforced
/// residual is homogeneous, and the simulation does not change when π is
/// scaled. The paper's double pendulum (unforced), its truth perturbed,
/// σ = 1e-4 at 10 ms for 15 s. The regression alone on such noisy rows
/// pulls the scale towards zero (measured: the upper link's I_O 3e-5
/// against 0.33 declared, its ratios off by 30–80 %), so `identify` runs
/// output error by itself there, from the declared values. Checked: it
/// did, the estimate is physically consistent, the ratios of the
/// closed-form base parameters of a double pendulum (a = I_O,1 + m₂l₁²,
/// b = m₁c₁ₓ + m₂l₁, I_O,2, m₂c₂ₓ) are the truth's to 2 %, and a is within
/// 50 % (one prior standard deviation) of the declared value.
#[test]
fn unforced_logs_keep_the_scale_of_the_prior() {
    use vigp::systems::{DoublePendulum, DoublePendulumMinimal};
    let declared = DoublePendulum::default().minimal();
    let truth = perturbed(declared, &mut Rng(11));
    let clean = vi_log::<_, 2, 0, 0>(truth, 0.5, SVector::from([1.2, -0.6]), 1500, |_| {
        SVector::zeros()
    });
    let log = noisy(&clean, 1e-4, &mut Rng(12));
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let names = r.structure().names.clone();
    let at = |name: &str| names.iter().position(|n| n == name).unwrap();
    let l1 = declared
        .parameter(DoublePendulumMinimal::parameter_index("links.upper.length").unwrap())
        .unwrap();
    // the closed-form base parameters used here: a, b, I_O,2, m₂c₂ₓ
    let base = |p: &[f64]| {
        let m2 = p[at("links.lower.mass")];
        [
            p[at("links.upper.inertia_o")] + m2 * l1 * l1,
            p[at("links.upper.mcom.x")] + m2 * l1,
            p[at("links.lower.inertia_o")],
            p[at("links.lower.mcom.x")],
        ]
    };
    let t = base(&standard(&truth));
    let id = identify(&r, &[log], &Options::default()).unwrap();
    let e = base(&id.estimate);
    let d = base(&id.declared);
    let refinement = id.refinement.as_ref().expect("output error ran");
    println!(
        "a, b, I_O2, m2c2x: estimate {e:.4?}, truth {t:.4?}, declared {d:.4?}; {refinement:?}"
    );
    assert!(refinement.homogeneous);
    assert!(vigp::identify::consistency::feasible(
        &id.structure,
        &id.estimate
    ));
    for i in 1..4 {
        let (got, want) = (e[i] / e[0], t[i] / t[0]);
        assert!(
            (got / want - 1.0).abs() < 0.02,
            "ratio {i}: {got} vs {want}"
        );
    }
    assert!((e[0] / d[0] - 1.0).abs() < 0.5, "{e:?}");
}

/// A loop under position noise: the four-bar driven at two joints (one of
/// them the loop-closing joint), its truth perturbed, logged by the
/// midpoint rule for 8 s at 10 ms with σ = 1e-4 rad on every angle, two
/// noise seeds. Output error simulates the loop with its multipliers
/// (`loops_are_simulated_with_their_multipliers`). What a right
/// identification must do on such a log, and is checked here:
/// * fit the log to the noise and no further: the simulation's RMS error
///   within 5 % of σ (measured 9.86e-5 and 9.88e-5);
/// * estimate the noise: σ̂ within 10 % of σ (≈ 3200 residuals; measured
///   1.009e-4, 1.011e-4);
/// * say what it does not know: the 95 % intervals hold the truth for at
///   least 85 % of the (seed, base parameter) pairs (34 pairs: 95 %
///   coverage gives ≥ 85 % with probability > 0.99; measured 34/34).
///
/// The log does not determine every base parameter: several keep
/// half-widths of 0.26–0.8 (the prior's), and the largest relative error
/// of a base parameter is 9.5–13.5 (on combinations whose true value is
/// near zero, e.g. −0.018 ± 0.26), so that number is printed, not checked.
#[test]
fn noisy_loops_fit_to_the_noise_with_honest_intervals() {
    use crate::drive_fourbar::DriveFourbar;
    let declared = DriveFourbar::default().minimal();
    let truth = perturbed(declared, &mut Rng(31));
    let q0 = SVector::from([0.9, -1.3, -0.4, 1.3]);
    let clean = vi_log::<_, 4, 2, 2>(truth, 0.5, q0, 800, |k| {
        SVector::from([drive(k), 0.5 * drive(k + 40)])
    });
    let r = DelRegressor::midpoint(declared, DT).unwrap();
    let t = standard(&truth);
    let sigma = 1e-4;
    let options = Options {
        output_error: Some(OutputError::default()),
        ..Options::default()
    };
    let (mut covered, mut total) = (0, 0);
    for seed in 0..2 {
        let log = noisy(&clean, sigma, &mut Rng(500 + seed));
        let id = identify(&r, &[log], &options).unwrap();
        let refinement = id.refinement.as_ref().expect("output error ran");
        let hits = covers(&id, &t);
        println!(
            "seed {seed}: simulation RMS {:.3e} (σ {sigma:e}), σ̂ {:.3e}, {} iterations \
             (converged: {}); intervals hold {}/{} base parameters; largest relative base \
             error {:.1e}",
            refinement.rms,
            refinement.position_sigma,
            refinement.iterations,
            refinement.converged,
            hits.iter().filter(|h| **h).count(),
            hits.len(),
            base_error(&id, &t)
        );
        assert!(
            (refinement.rms / sigma - 1.0).abs() < 0.05,
            "{refinement:?}"
        );
        assert!(
            (refinement.position_sigma / sigma - 1.0).abs() < 0.1,
            "{refinement:?}"
        );
        total += hits.len();
        covered += hits.iter().filter(|h| **h).count();
    }
    let frac = covered as f64 / total as f64;
    println!("95 % intervals hold the truth in {covered}/{total} = {frac:.3}");
    assert!(frac >= 0.85, "{covered}/{total}");
}
