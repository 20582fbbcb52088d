//! The error bounds (`vigp::bound`): settings validation, the constants
//! against a second implementation, `predict`'s bookkeeping, and a
//! property test that no setting yields a NaN, infinite or negative bound
//! without a typed error. Coverage on the four systems is in
//! `tests/bound/bound_coverage.rs`.

use crate::common;
use common::Rng;
use nalgebra::{DMatrix, DVector, SVector};
use proptest::prelude::*;
use std::sync::OnceLock;
use vigp::bound::{
    BoundError, BoundKind, BoundParts, Calibration, ConformalSettings, Fallback, LipschitzF,
    NoiseBound, NormBound, RkhsSettings, Score, SigmaModulus, Tau, Theorem1Settings, Tube, Window,
};
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, Learned, Prior, Transition};
use vigp::prelude::*;
use vigp::systems::{Pendulum, PendulumMinimal};

const DT: f64 = 0.01;

/// Windows of `k` steps of the damped pendulum (the truth) from random
/// states, simulated at Δt/5 by the midpoint VI.
fn pendulum_windows(seed: u64, count: usize, k: usize) -> Vec<Window<1>> {
    let mut truth = Pendulum::default();
    truth.joints.pivot.damping = 0.3;
    truth.links.rod.mass = 1.05;
    let m = truth.minimal();
    let h = DT / 5.0;
    let vi = Variational::midpoint(m, h).unwrap();
    let mut rng = Rng(seed);
    (0..count)
        .map(|_| {
            let mut z = State::new([rng.uniform(-2.0, 2.0)], [rng.uniform(-2.5, 2.5)]);
            let mut p = vec![z.q];
            for _ in 0..k {
                for _ in 0..5 {
                    z = vi.step(&z).unwrap();
                }
                p.push(z.q);
            }
            common::window(&p, DT)
        })
        .collect()
}

/// A small learned pendulum (nominal prior, sin/cos inputs) trained once.
fn model() -> &'static Learned<PendulumMinimal, 1, 0> {
    static MODEL: OnceLock<Learned<PendulumMinimal, 1, 0>> = OnceLock::new();
    MODEL.get_or_init(|| train_noise_free(&common::train_options(1, 3)))
}

/// The noise-free transitions of 40 pendulum windows (seed 1).
fn noise_free_transitions() -> Vec<Transition<1>> {
    pendulum_windows(1, 40, 2)
        .iter()
        .map(|w| common::first_transition(w, DT))
        .collect()
}

/// A sin/cos, nominal-prior pendulum model trained on `data` with `opts`.
fn train_sin_cos(data: &[Transition<1>], opts: &TrainOptions) -> Learned<PendulumMinimal, 1, 0> {
    Learned::train(
        Pendulum::default().minimal(),
        DT,
        data,
        Encoding::SinCos,
        Prior::Nominal,
        opts,
    )
    .unwrap()
    .0
}

/// [`train_sin_cos`] on [`noise_free_transitions`].
fn train_noise_free(opts: &TrainOptions) -> Learned<PendulumMinimal, 1, 0> {
    train_sin_cos(&noise_free_transitions(), opts)
}

/// The same with noisy targets (σ = 3e-3), so that the fitted noise is far
/// above its floor and K + λI is well conditioned.
fn noisy_model() -> &'static Learned<PendulumMinimal, 1, 0> {
    static MODEL: OnceLock<Learned<PendulumMinimal, 1, 0>> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mut rng = Rng(17);
        let data: Vec<Transition<1>> = pendulum_windows(1, 40, 2)
            .iter()
            .map(|w| {
                let (u1, u2) = (rng.uniform(1e-300, 1.0), rng.uniform(0.0, 1.0));
                let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                Transition {
                    z: w.start,
                    v_next: (w.positions[1] - w.positions[0]) / DT + SVector::from([3e-3 * g]),
                }
            })
            .collect();
        train_sin_cos(&data, &common::train_options(1, 3))
    })
}

/// The conformal bound at δ = 0.05 on the latent-std score, falling back
/// to Theorem 1.
fn latent_std_with_theorem1() -> BoundKind {
    BoundKind::Conformal(ConformalSettings {
        delta: 0.05,
        score: Score::LatentStd,
        fallback: Fallback::Theorem1,
        ..ConformalSettings::default()
    })
}

/// The default conformal bound with the fallback `fallback`.
fn conformal_with(fallback: Fallback) -> BoundKind {
    BoundKind::Conformal(ConformalSettings {
        fallback,
        ..ConformalSettings::default()
    })
}

fn calibration() -> &'static Calibration<1> {
    static CAL: OnceLock<Calibration<1>> = OnceLock::new();
    CAL.get_or_init(|| Calibration::new(DT, pendulum_windows(2, 120, 5)).unwrap())
}

/// Overlapping windows (stride 1) of independent runs calibrate the region
/// test by distances to *other* runs: a new start comes from a new run,
/// while a window's neighbours in its own run lie a sample apart. 60 runs
/// of 41 samples cut at stride 1 (2160 windows of 5 steps) calibrate the
/// bound; of 300 starts cut alike from 60 fresh runs, the share flagged
/// outside the calibrated region is the distance test's 1 % plus the box
/// and scale tests' ≈ 2d/(n + 1) (d = 3 GP inputs): ≤ 5 % asserted.
/// With distances to every other window, the same run's included (the
/// rule before), 103 of the 300 (34 %) were flagged.
#[test]
fn overlapping_windows_of_independent_runs_do_not_flag_new_starts() {
    let runs = |seed| -> Vec<Vec<SVector<f64, 1>>> {
        pendulum_windows(seed, 60, 40)
            .into_iter()
            .map(|w| std::iter::once(w.start.q).chain(w.positions).collect())
            .collect()
    };
    let cal = Calibration::from_trajectories(&runs(5), DT, 5, 1).unwrap();
    assert_eq!(cal.len(), 60 * 36);
    assert_eq!(cal.window_runs()[36], 1);
    let bound = model()
        .error_bound(&BoundKind::conformal(0.05), &cal)
        .unwrap();
    let fresh = Calibration::from_trajectories(&runs(6), DT, 5, 1).unwrap();
    let starts: Vec<_> = fresh.windows().iter().step_by(7).take(300).collect();
    let flagged = starts
        .iter()
        .filter(|w| model().predict(&w.start, 5, &bound).unwrap().outside[0])
        .count();
    let share = flagged as f64 / starts.len() as f64;
    println!(
        "stride-1 calibration of 60 runs: {flagged} of {} fresh starts flagged ({share:.3})",
        starts.len()
    );
    assert!(share <= 0.05, "{share}");
}

/// A one-sample pendulum model at 2Δt: every bound of `model()` is a
/// mismatch for it.
fn other_dt_model() -> Learned<PendulumMinimal, 1, 0> {
    Learned::train(
        Pendulum::default().minimal(),
        2.0 * DT,
        &[Transition {
            z: State::new([0.1], [0.0]),
            v_next: SVector::from([0.1]),
        }],
        Encoding::Raw,
        Prior::Nominal,
        &TrainOptions::default(),
    )
    .unwrap()
    .0
}

fn invalid(e: &BoundError) -> bool {
    matches!(
        e,
        BoundError::InvalidSetting { .. }
            | BoundError::WrongLength { .. }
            | BoundError::TooFewCalibration { .. }
    )
}

/// Each bad setting is its typed error, never a NaN or negative bound (the
/// old API returned NaN bounds for `lipschitz_f: NaN` and negative ones for
/// a negative value).
#[test]
fn bad_settings_are_typed_errors() {
    let l = model();
    let cal = calibration();
    let t1 = |f: fn(&mut Theorem1Settings)| {
        let mut s = Theorem1Settings::default();
        f(&mut s);
        BoundKind::Theorem1(s)
    };
    let rk = |f: fn(&mut RkhsSettings)| {
        let mut s = RkhsSettings::default();
        f(&mut s);
        BoundKind::Rkhs(s)
    };
    let cases = [
        t1(|s| s.delta = f64::NAN),
        t1(|s| s.delta = 0.0),
        t1(|s| s.delta = 1.0),
        t1(|s| s.delta = -0.1),
        t1(|s| s.lipschitz_f = LipschitzF::Given(vec![f64::NAN])),
        t1(|s| s.lipschitz_f = LipschitzF::Given(vec![-1.0])),
        t1(|s| s.lipschitz_f = LipschitzF::Given(vec![f64::INFINITY])),
        t1(|s| s.lipschitz_f = LipschitzF::Given(vec![1.0, 2.0])),
        t1(|s| s.tau = Tau::Relative(0.0)),
        t1(|s| s.tau = Tau::Relative(f64::NAN)),
        t1(|s| s.tau = Tau::Relative(-1e-3)),
        t1(|s| s.domain_margin = -0.5),
        t1(|s| s.domain_margin = f64::INFINITY),
        rk(|s| s.delta = 2.0),
        rk(|s| s.norm_bound = NormBound::MeanTimes(f64::NAN)),
        rk(|s| s.norm_bound = NormBound::MeanTimes(0.0)),
        rk(|s| s.norm_bound = NormBound::Given(vec![-1.0])),
        rk(|s| s.norm_bound = NormBound::Given(vec![])),
        rk(|s| s.noise = NoiseBound::Given(vec![f64::NEG_INFINITY])),
        BoundKind::conformal(f64::NAN),
        BoundKind::conformal(0.0),
        // 120 windows cannot give δ = 0.005 (needs 199)
        BoundKind::conformal(0.005),
    ];
    for kind in &cases {
        match l.error_bound(kind, cal) {
            Err(e) if invalid(&e) => {}
            other => panic!("{kind:?}: expected a typed setting error, got {other:?}"),
        }
    }
    // the conformal kind needs calibration data; the others do not
    assert!(matches!(
        l.error_bound(&BoundKind::conformal(0.05), &Calibration::empty(DT)),
        Err(BoundError::Empty(_))
    ));
    assert!(
        l.error_bound(&BoundKind::theorem1(0.05), &Calibration::empty(DT))
            .is_ok()
    );
    // calibration data of another Δt
    let other = Calibration::new(2.0 * DT, pendulum_windows(4, 30, 3)).unwrap();
    assert!(matches!(
        l.error_bound(&BoundKind::conformal(0.05), &other),
        Err(BoundError::Mismatch(_))
    ));
}

/// Malformed calibration windows are typed errors naming the window.
#[test]
fn bad_calibration_windows_are_typed_errors() {
    let mut w = pendulum_windows(5, 4, 3);
    assert!(Calibration::new(DT, w.clone()).is_ok());
    w[2].positions[1][0] = f64::NAN;
    assert!(matches!(
        Calibration::new(DT, w.clone()),
        Err(BoundError::Calibration { index: 2, .. })
    ));
    let mut w = pendulum_windows(5, 4, 3);
    w[1].positions.pop();
    assert!(matches!(
        Calibration::new(DT, w),
        Err(BoundError::Calibration { index: 1, .. })
    ));
    let mut w = pendulum_windows(5, 1, 3);
    w[0].positions.truncate(1);
    assert!(Calibration::new(DT, w).is_err());
    assert!(Calibration::<1>::new(f64::NAN, vec![]).is_err());
    let traj: Vec<SVector<f64, 1>> = (0..10).map(|i| SVector::from([i as f64])).collect();
    assert!(matches!(
        Calibration::from_trajectories(&[&traj[..3]], DT, 5, 1),
        Err(BoundError::Empty(_))
    ));
    assert!(Calibration::from_trajectories(&[&traj], DT, 1, 1).is_err());
    assert!(Calibration::from_trajectories(&[&traj], DT, 4, 0).is_err());
    // 10 samples, horizon 4, stride 2: starts 0, 2, 4 (start + 4 < 10) → 3 windows
    let c = Calibration::from_trajectories(&[&traj], DT, 4, 2).unwrap();
    assert_eq!((c.len(), c.horizon()), (3, 4));
    assert_eq!(c.windows()[1].start.q[0], 2.0);
    assert_eq!(c.windows()[1].positions[3][0], 6.0);
    assert!((c.windows()[1].start.v[0] - 1.0 / DT).abs() < 1e-9);
}

/// The RKHS constants against a second implementation with nalgebra: the
/// Gram matrix rebuilt from the hyperparameters and the normalised inputs,
/// its own Cholesky for ln det, its own solve for ‖μ‖_k = √(αᵀKα).
///
/// On the model with noisy targets (λ well above its floor). Tolerances
/// from the conditioning: the two Gram matrices differ by rounding,
/// ‖ΔK‖ ≤ 4N·ε·σ_f², which moves each of the N terms ln(e_i + λ) by at most
/// ‖ΔK‖/λ: |Δ ln det| ≤ 4N²·ε·σ_f²/λ (absolute). The mean's norm carries
/// the solve's relative error cond·ε ≤ 10·N·σ_f²/λ·ε. (With noise-free data
/// λ sits at its floor, 1e-10, and these bounds say little: both
/// implementations then agree to ~3e-5 only.)
#[test]
fn rkhs_constants_match_a_second_implementation() {
    let l = noisy_model();
    let b = l
        .error_bound(&BoundKind::rkhs(0.05), &Calibration::empty(DT))
        .unwrap();
    let BoundParts::Rkhs { outputs } = &b.parts else {
        panic!()
    };
    let gp = l.gp();
    let (n, d) = (gp.n(), gp.input_dim());
    let mut xn = vec![0.0; n * d];
    for (o, x) in xn.chunks_exact_mut(d).zip(gp.inputs().chunks_exact(d)) {
        gp.input_normaliser().apply(x, o);
    }
    for (i, out) in outputs.iter().enumerate() {
        let o = gp.output(i);
        let hp = o.hyperparameters();
        let lambda = hp.noise_variance + o.jitter();
        assert_eq!(out.regularisation, lambda);
        let k = DMatrix::from_fn(n, n, |a, c| {
            hp.kernel(&xn[a * d..(a + 1) * d], &xn[c * d..(c + 1) * d])
        });
        let chol = (k.clone() + DMatrix::identity(n, n) * lambda)
            .cholesky()
            .unwrap();
        let log_det: f64 = 2.0 * chol.l().diagonal().iter().map(|x| x.ln()).sum::<f64>()
            + n as f64 * (lambda.max(1.0) / lambda).ln();
        let r = DVector::from_column_slice(o.residual_normalised());
        let alpha = chol.solve(&r);
        let mean_norm = (alpha.transpose() * &k * &alpha)[0].sqrt();
        let eps = f64::EPSILON;
        let sf2 = hp.signal_variance;
        let tol_det = 4.0 * (n * n) as f64 * eps * sf2 / lambda;
        let tol_norm = 10.0 * n as f64 * sf2 / lambda * eps;
        eprintln!(
            "N = {n}, λ = {lambda:.2e}: ln det {} vs {log_det} (tol {tol_det:.1e}); ‖μ‖ {} vs {mean_norm} (rel tol {tol_norm:.1e})",
            out.log_det, out.mean_norm
        );
        assert!(
            tol_det < 1e-6 && tol_norm < 1e-6,
            "badly conditioned test model"
        );
        assert!((out.log_det - log_det).abs() <= tol_det);
        assert!((out.mean_norm - mean_norm).abs() <= tol_norm * mean_norm);
        // the formula, assembled from the reported parts
        let beta = 2.0 * out.mean_norm
            + hp.noise_variance.sqrt() / lambda.sqrt()
                * (out.log_det - 2.0 * (0.05f64 / gp.output_dim() as f64).ln()).sqrt();
        assert!((out.beta - beta).abs() <= 1e-12 * beta);
    }
}

/// Theorem 1's β and γ against the formulas evaluated here from the
/// reported τ and the box rebuilt from the training inputs, and the
/// one-step bound against L·Σ(√β σ + γ).
#[test]
fn theorem1_constants_match_the_formulas() {
    let l = model();
    for modulus in [SigmaModulus::FeatureSpace, SigmaModulus::Lederer2019] {
        let kind = BoundKind::Theorem1(Theorem1Settings {
            sigma_modulus: modulus,
            ..Theorem1Settings::default()
        });
        let b = l.error_bound(&kind, &Calibration::empty(DT)).unwrap();
        let BoundParts::Theorem1 {
            outputs,
            domain_lower,
            domain_upper,
            ..
        } = &b.parts
        else {
            panic!()
        };
        let gp = l.gp();
        let (d, p) = (gp.input_dim(), gp.output_dim());
        let norm = gp.input_normaliser();
        // edges of X in normalised units: 2× the training box (margin 0.5)
        let r: Vec<f64> = (0..d)
            .map(|j| (domain_upper[j] - domain_lower[j]) / norm.scale[j])
            .collect();
        let mut xn = vec![0.0; d];
        for j in 0..d {
            let col = gp.inputs().chunks_exact(d).map(|x| {
                norm.apply(x, &mut xn);
                xn[j]
            });
            let (lo, hi) = col.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            assert!((r[j] - 2.0 * (hi - lo)).abs() < 1e-9 * r[j].max(1.0));
        }
        for (i, o) in outputs.iter().enumerate() {
            let log_m: f64 = r
                .iter()
                .map(|rj| {
                    (rj * (d as f64).sqrt() / (2.0 * o.tau))
                        .ceil()
                        .max(1.0)
                        .ln()
                })
                .sum();
            let beta = 2.0 * (log_m - (0.05f64 / p as f64).ln());
            assert!((o.beta - beta).abs() < 1e-9 * beta, "{} {beta}", o.beta);
            let hp = gp.output(i).hyperparameters();
            let lmin = hp
                .length_scales
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min);
            let omega = match modulus {
                SigmaModulus::FeatureSpace => hp.signal_variance.sqrt() * o.tau / lmin,
                _ => o.omega_sigma,
            };
            assert!((o.omega_sigma - omega).abs() <= 1e-12 * omega);
            assert!((o.lipschitz_sigma * o.tau - omega).abs() <= 1e-12 * omega);
            let gamma = ((o.lipschitz_mean + o.lipschitz_f) * o.tau + beta.sqrt() * omega)
                * gp.output(i).output_scale();
            assert!((o.gamma - gamma).abs() <= 1e-9 * gamma);
            assert_eq!(o.lipschitz_f, o.lipschitz_mean);
        }
        let sd = [0.01];
        let expect = b.projection_lipschitz * (outputs[0].beta.sqrt() * 0.01 + outputs[0].gamma);
        assert!((b.one_step(&sd).unwrap() - expect).abs() < 1e-12 * expect);
        eprintln!("{b}");
    }
}

/// The noise lower bound no longer makes Theorem 1 vacuous: on noise-free
/// data (fitted noise at its floor) the default bound's σ-multiplier stays
/// below 30 and γ below the median σ, while the paper's modulus with a fixed
/// τ = 1e-9·r (the old default) is orders of magnitude wider.
#[test]
fn theorem1_is_not_vacuous_at_the_noise_floor() {
    let l = model();
    let o = l.gp().output(0);
    eprintln!(
        "fitted noise variance (normalised) {:.2e}",
        o.hyperparameters().noise_variance
    );
    let empty = Calibration::empty(DT);
    let new = l.error_bound(&BoundKind::theorem1(0.05), &empty).unwrap();
    let old = l
        .error_bound(
            &BoundKind::Theorem1(Theorem1Settings {
                tau: Tau::Relative(1e-9),
                sigma_modulus: SigmaModulus::Lederer2019,
                ..Theorem1Settings::default()
            }),
            &empty,
        )
        .unwrap();
    let (BoundParts::Theorem1 { outputs: a, .. }, BoundParts::Theorem1 { outputs: b, .. }) =
        (&new.parts, &old.parts)
    else {
        panic!()
    };
    let sd = [a[0].sigma_median * o.output_scale()];
    let (bn, bo) = (new.one_step(&sd).unwrap(), old.one_step(&sd).unwrap());
    eprintln!(
        "one-step bound at the median sample σ: default {bn:.3e}, old {bo:.3e}; γ {:.2e} vs {:.2e}",
        a[0].gamma, b[0].gamma
    );
    assert!(new.sigma_multipliers()[0] < 30.0);
    assert!(a[0].gamma < sd[0]);
    assert!(bo > 10.0 * bn);
}

/// `predict` attaches a bound to every state; a conformal bound refuses to
/// extrapolate its horizon; a bound of another model is refused.
#[test]
fn predict_carries_a_bound_per_state() {
    let l = model();
    let cal = calibration();
    let z0 = cal.windows()[0].start;
    for kind in [
        BoundKind::theorem1(0.05),
        BoundKind::rkhs(0.05),
        BoundKind::conformal(0.05),
        BoundKind::Conformal(ConformalSettings {
            delta: 0.05,
            score: Score::Absolute,
            tube: Tube::Simultaneous,
            fallback: Fallback::None,
        }),
        latent_std_with_theorem1(),
    ] {
        let b = l.error_bound(&kind, cal).unwrap();
        let p = l.predict(&z0, 5, &b).unwrap();
        assert_eq!(p.states.len(), 6);
        assert_eq!(p.one_step_bounds.len(), 5);
        assert_eq!(p.position_bounds.len(), 6);
        assert_eq!(p.outside.len(), 5);
        assert_eq!(p.position_bounds[0], 0.0);
        assert!(
            p.one_step_bounds
                .iter()
                .chain(&p.position_bounds)
                .all(|b| b.is_finite() && *b >= 0.0)
        );
        if b.kind_name() != "conformal" {
            // propagated bounds never shrink along a prediction
            assert!(p.position_bounds.windows(2).all(|w| w[1] >= w[0]));
        }
        // the mean trajectory is the rollout's
        let roll = l.rollout(&z0, 5).unwrap();
        assert_eq!(roll, p.states);
        if b.kind_name() == "conformal" {
            assert!(matches!(
                l.predict(&z0, 6, &b),
                Err(BoundError::HorizonTooLong {
                    calibrated: 5,
                    requested: 6
                })
            ));
        }
    }
    let b = l.error_bound(&BoundKind::rkhs(0.05), cal).unwrap();
    let other = other_dt_model();
    assert!(matches!(
        other.predict(&z0, 3, &b),
        Err(BoundError::Mismatch(_))
    ));
    assert!(b.one_step(&[f64::NAN]).is_err());
    assert!(b.one_step(&[-1.0]).is_err());
    assert!(b.one_step(&[1.0, 1.0]).is_err());
}

/// `predict_bounds` (one trace and one Jacobian per state for every bound)
/// gives what `predict` gives bound by bound, bit for bit, for every kind
/// including a conformal bound with a fallback, from a start inside and
/// one far outside the data; the rigorous kinds' position bounds equal the
/// recurrence recomputed from `step_jacobian_norms` (1e-14 relative: the
/// same operations); an empty list and a mismatched bound are typed
/// errors.
#[test]
fn predict_bounds_equals_predict_bound_by_bound() {
    let l = model();
    let cal = calibration();
    let kinds = [
        BoundKind::theorem1(0.05),
        BoundKind::rkhs(0.05),
        BoundKind::conformal(0.05),
        latent_std_with_theorem1(),
    ];
    let bounds: Vec<_> = kinds
        .iter()
        .map(|k| l.error_bound(k, cal).unwrap())
        .collect();
    let refs: Vec<_> = bounds.iter().collect();
    let inside = cal.windows()[0].start;
    let outside = State::new([2.9], [7.0]);
    let mut fell_back = false;
    for z0 in [inside, outside] {
        let all = l.predict_bounds(&z0, 5, &refs).unwrap();
        assert_eq!(all.len(), bounds.len());
        for (got, b) in all.iter().zip(&bounds) {
            let want = l.predict(&z0, 5, b).unwrap();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got.position_bounds), bits(&want.position_bounds));
            assert_eq!(bits(&got.one_step_bounds), bits(&want.one_step_bounds));
            assert_eq!(got, &want);
            fell_back |= got.fell_back;
        }
        // the rigorous kinds' position bounds, propagated here from the
        // public Jacobian norms: P₀ = V₀ = 0, P_{k+1} = P_k + Δt·V_k,
        // V_{k+1} = ‖∂v′/∂q‖·P_k + ‖∂v′/∂v‖·V_k + b_k, the norms taken at
        // the interior states (the first and last step add b alone)
        let mut ws = l.workspace();
        for p in &all[..2] {
            let (mut pk, mut vk) = (0.0f64, 0.0f64);
            let steps = p.one_step_bounds.len();
            for (k, b) in p.one_step_bounds.iter().enumerate() {
                let (a, c) = if k > 0 && k + 1 < steps {
                    l.step_jacobian_norms(&p.states[k], &mut ws).unwrap()
                } else {
                    (0.0, 0.0)
                };
                (pk, vk) = (pk + DT * vk, a * pk + c * vk + b);
                assert!(
                    (p.position_bounds[k + 1] - pk).abs() <= 1e-14 * pk,
                    "step {k}: {} vs {pk}",
                    p.position_bounds[k + 1]
                );
            }
        }
    }
    assert!(fell_back, "the far start exercises the fallback");
    assert!(matches!(
        l.predict_bounds(&inside, 5, &[]),
        Err(BoundError::Empty(_))
    ));
    let other = other_dt_model();
    let mismatched = l.error_bound(&BoundKind::rkhs(0.05), cal).unwrap();
    assert!(matches!(
        other.predict_bounds(&inside, 5, &[&mismatched]),
        Err(BoundError::Mismatch(_))
    ));
}

vigp::mechanism! {
    /// A pendulum driven at its pivot, for a model trained with inputs.
    pub DrivenPendulum {
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { damping: 0.1, actuated },
        }
    }
}

#[path = "../common/drive_fourbar.rs"]
mod drive_fourbar;
use drive_fourbar::DriveFourbar;

/// Spectral norm by nalgebra's SVD (the library's own is a power iteration).
fn norm2<const N: usize>(a: &nalgebra::SMatrix<f64, N, N>) -> f64 {
    DMatrix::from_column_slice(N, N, a.as_slice())
        .svd(false, false)
        .singular_values
        .max()
}

/// The reference for `Learned::step_jacobian_norms`: five-point central
/// differences ([`common::stencil`], h = 1e-3·max(|x|, 1)) of z ↦ v′ of
/// `step_mean_in`, each perturbed state first made consistent when the
/// model projects, i.e. the definition the analytic derivative implements,
/// evaluated a second way.
fn fd_norms<M: vigp::Mechanism<N, C> + Clone, const N: usize, const C: usize>(
    l: &Learned<M, N, C>,
    z: &State<N>,
) -> (f64, f64) {
    fd_norms_by(l, z, |p, ws| l.step_mean_in(p, ws).unwrap())
}

/// [`fd_norms`] of the mean step `step`.
fn fd_norms_by<M: vigp::Mechanism<N, C> + Clone, const N: usize, const C: usize>(
    l: &Learned<M, N, C>,
    z: &State<N>,
    step: impl Fn(&State<N>, &mut vigp::gp::Workspace) -> State<N>,
) -> (f64, f64) {
    let mut ws = l.workspace();
    let mut dq = nalgebra::SMatrix::<f64, N, N>::zeros();
    let mut dv = dq;
    for k in 0..2 * N {
        let x = if k < N { z.q[k] } else { z.v[k - N] };
        let (_, col) = common::stencil(1e-3 * x.abs().max(1.0), |e| {
            let mut p = *z;
            if k < N {
                p.q[k] += e;
            } else {
                p.v[k - N] += e;
            }
            if C > 0 && l.projects() {
                p = vigp::projection::consistent_state(l.model(), &p.q, &p.v, l.dt()).unwrap();
            }
            step(&p, &mut ws)
        });
        if k < N {
            dq.set_column(k, &col);
        } else {
            dv.set_column(k - N, &col);
        }
    }
    (norm2(&dq), norm2(&dv))
}

/// Noisy transitions (uniform noise of σ ≈ 3e-3 on the velocities) along a
/// damped rollout of `truth` from `z0`: the noise keeps the GP's noise
/// variance and weights moderate, so that differences of the mean are not
/// swamped by rounding (noise-free data drives σ_n² → 0 and the rounding
/// of Σ αᵢkᵢ up: 1e-6 relative already at σ ≈ 1e-4).
fn noisy_transitions<M: vigp::Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    truth: M,
    z0: &State<N>,
    steps: usize,
    seed: u64,
) -> Vec<Transition<N>> {
    let traj = Variational::new(truth, DT)
        .unwrap()
        .rollout(z0, steps)
        .unwrap();
    let q: Vec<_> = traj.iter().map(|z| z.q).collect();
    let mut rng = Rng(seed);
    vigp::learned::transitions(&q, DT)
        .into_iter()
        .map(|mut t| {
            for x in t.v_next.iter_mut() {
                *x += rng.uniform(-5e-3, 5e-3);
            }
            t
        })
        .collect()
}

/// `Learned::step_jacobian_norms` (exact derivatives: the nominal step's,
/// the GP mean's gradient, the projection's and the consistent-state map's
/// KKT derivatives) against central differences of the mean step, on
/// consistent states along each model's own prediction: the pendulum
/// (sin/cos, nominal prior), the fourbar in minimal coordinates (2 loop
/// equations; nominal and constant prior), the double pendulum in maximal
/// coordinates (6 coordinates, 4 joint constraints) and a model trained
/// with an input (differentiated under u = 0, the step `predict` takes).
/// Off the manifold they are the norms at the consistent state (1e-9: the
/// projection of a projected state moves it by rounding only).
///
/// Tolerance 1e-6 relative to the norm: the five-point differences'
/// truncation is ~h⁴ = 1e-12 times the fifth derivative and their rounding
/// ~1e-16·‖α‖₁/h. Measured on the pendulum model here (noise-level weights
/// ‖α‖₁ after the training kernel's exponential changed in its last bit):
/// worst relative error 9.1e-8 at h = 1e-3, 1.9e-7 at 3e-4, 1.1e-6 at 1e-4,
/// 9.4e-6 at 1e-5 — the 1/h of rounding, so h = 1e-3 (1e-4 before). An
/// error in the chain rule (a dropped term of the
/// projection's derivative or of the consistent-state map) changes the
/// norms by O(1), the off-manifold directions being amplified by 1/Δt;
/// the power iteration used before for ‖·‖₂ missed the fourbar's norm by
/// 4e-5 (two close singular values), which this test caught.
#[test]
fn step_jacobian_norms_match_central_differences() {
    use vigp::systems::{DoublePendulum, Fourbar};
    let opts = common::train_options(1, 5);
    fn check<M: vigp::Mechanism<N, C> + Clone, const N: usize, const C: usize>(
        name: &str,
        l: &Learned<M, N, C>,
        z0: &State<N>,
    ) {
        let mut ws = l.workspace();
        let states = l.rollout(z0, 12).unwrap();
        for (k, z) in states.iter().enumerate().step_by(3) {
            let (a, c) = l.step_jacobian_norms(z, &mut ws).unwrap();
            let (fa, fc) = fd_norms(l, z);
            for (got, want, what) in [(a, fa, "|dv'/dq|"), (c, fc, "|dv'/dv|")] {
                assert!(
                    (got - want).abs() <= 1e-6 * want.max(1.0),
                    "{name}, state {k}, {what}: {got:e} vs differences {want:e}"
                );
            }
        }
        if C > 0 && l.projects() {
            // off the manifold: the norms at consistent_state(z)
            let mut off = states[4];
            off.q[0] += 1e-3;
            off.v[0] -= 2e-2;
            let on = vigp::projection::consistent_state(l.model(), &off.q, &off.v, l.dt()).unwrap();
            let (a, c) = l.step_jacobian_norms(&off, &mut ws).unwrap();
            let (a0, c0) = l.step_jacobian_norms(&on, &mut ws).unwrap();
            assert!((a - a0).abs() <= 1e-9 * a0 && (c - c0).abs() <= 1e-9 * c0);
        }
    }
    let mut pendulum = Pendulum::default();
    pendulum.joints.pivot.damping = 0.3;
    let data = noisy_transitions(pendulum.minimal(), &State::new([1.2], [0.0]), 50, 1);
    for (encoding, prior) in [
        (Encoding::SinCos, Prior::Nominal),
        (Encoding::Raw, Prior::Constant),
    ] {
        let (l, _) = Learned::train(
            Pendulum::default().minimal(),
            DT,
            &data,
            encoding,
            prior,
            &opts,
        )
        .unwrap();
        check("pendulum", &l, &data[7].z);
    }

    let mut fourbar = Fourbar::default();
    fourbar.joints.top1.damping = 0.2;
    let z0 = vigp::projection::consistent_state(
        &fourbar.minimal(),
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::zeros(),
        DT,
    )
    .unwrap();
    let data = noisy_transitions(fourbar.minimal(), &z0, 50, 2);
    for prior in [Prior::Nominal, Prior::Constant] {
        let (l, _) = Learned::train(
            Fourbar::default().minimal(),
            DT,
            &data,
            Encoding::Raw,
            prior,
            &opts,
        )
        .unwrap();
        assert!(l.projects());
        check("fourbar", &l, &data[5].z);
    }

    let mut double = DoublePendulum::default();
    double.joints.elbow.damping = 0.2;
    let m = double.maximal();
    let q0 = vigp::projection::consistent_state(
        &m,
        &SVector::from([0.4, -0.45, 0.5, 1.0, -1.4, 1.2]),
        &SVector::zeros(),
        DT,
    )
    .unwrap();
    let data = noisy_transitions(m, &q0, 40, 3);
    let (l, _) = Learned::train(
        DoublePendulum::default().maximal(),
        DT,
        &data,
        Encoding::Raw,
        Prior::Nominal,
        &opts,
    )
    .unwrap();
    check("double pendulum, maximal", &l, &data[4].z);

    // a model trained with an input: u is random per step in the data
    let truth = DrivenPendulum::default().minimal();
    let mut rng = Rng(9);
    let z = State::new([0.8], [0.0]);
    let data = forced_data::<_, 1, 0, 1>(truth, &z, 60, 2.0, 5e-3, &mut rng);
    let (l, _) =
        Learned::train_forced(truth, DT, &data, Encoding::SinCos, Prior::Nominal, &opts).unwrap();
    assert_eq!(l.inputs(), 1);
    check("driven pendulum, u = 0", &l, &data[3].z);
    check_forced::<_, 1, 0, 1>("driven pendulum", &l, &data[3].z, &mut rng);

    // a driven loop (two inputs, one of them on the loop-closing joint):
    // the forced step projects, and so do the differences
    let truth = DriveFourbar::default().minimal();
    let z = vigp::projection::consistent_state(
        &truth,
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::zeros(),
        DT,
    )
    .unwrap();
    let data = forced_data::<_, 4, 2, 2>(truth, &z, 50, 1.0, 5e-3, &mut rng);
    let (l, _) =
        Learned::train_forced(truth, DT, &data, Encoding::Raw, Prior::Nominal, &opts).unwrap();
    assert!(l.projects());
    check_forced::<_, 4, 2, 2>("driven fourbar", &l, &data[5].z, &mut rng);

    // the same loop in maximal coordinates (12 coordinates, 10 joint
    // constraints), the view `vigp fit --encoding maximal` trains
    let maximal = DriveFourbar::default().maximal();
    let zm = truth.to_maximal(&z, DT);
    let data = forced_data::<_, 12, 10, 2>(maximal, &zm, 40, 1.0, 5e-3, &mut rng);
    let (l, _) =
        Learned::train_forced(maximal, DT, &data, Encoding::Raw, Prior::Nominal, &opts).unwrap();
    assert!(l.projects());
    check_forced::<_, 12, 10, 2>("driven fourbar, maximal", &l, &data[4].z, &mut rng);
}

/// Transitions of `truth` (the VI at Δt) along `steps` steps from `z0`,
/// each under an input drawn uniformly from [−amplitude, amplitude] per
/// component, with uniform velocity noise of half-width `noise`.
fn forced_data<
    M: vigp::Mechanism<N, C> + Copy + vigp::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    truth: M,
    z0: &State<N>,
    steps: usize,
    amplitude: f64,
    noise: f64,
    rng: &mut Rng,
) -> Vec<vigp::learned::ForcedTransition<N, U>> {
    let vi = Variational::new(truth, DT).unwrap();
    let mut z = *z0;
    let (mut positions, mut inputs) = (vec![z.q], vec![SVector::<f64, U>::zeros()]);
    for _ in 0..steps {
        let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-amplitude, amplitude));
        z = vi.step_forced(&z, &u).unwrap();
        positions.push(z.q);
        inputs.push(u);
    }
    let mut data = vigp::learned::forced_transitions(&positions, &inputs, DT);
    for t in &mut data {
        for x in t.v_next.iter_mut() {
            *x += rng.uniform(-noise, noise);
        }
    }
    data
}

/// `step_jacobian_norms_forced` at states of a forced prediction against
/// central differences of `step_mean_forced_in` under the same input;
/// `predict_forced` along the same inputs, and under zero inputs against
/// `predict`.
fn check_forced<
    M: vigp::Mechanism<N, C> + Clone + vigp::Inputs<U>,
    const N: usize,
    const C: usize,
    const U: usize,
>(
    name: &str,
    l: &Learned<M, N, C>,
    z0: &State<N>,
    rng: &mut Rng,
) {
    let mut ws = l.workspace();
    let us: Vec<SVector<f64, U>> = (0..12)
        .map(|_| SVector::from_fn(|_, _| rng.uniform(-1.5, 1.5)))
        .collect();
    // the input before the first (that produced z0's velocity), then the
    // previous step's
    let up0 = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-1.5, 1.5));
    let prev = |k: usize| if k == 0 { up0 } else { us[k - 1] };
    let mut states = vec![*z0];
    for (k, u) in us.iter().enumerate() {
        let next = l
            .step_mean_forced_in(states.last().unwrap(), &prev(k), u, &mut ws)
            .unwrap();
        states.push(next);
    }
    for k in (0..us.len()).step_by(3) {
        let (z, up, u) = (&states[k], prev(k), &us[k]);
        let (a, c) = l.step_jacobian_norms_forced(z, &up, u, &mut ws).unwrap();
        let (fa, fc) = fd_norms_by(l, z, |p, ws| l.step_mean_forced_in(p, &up, u, ws).unwrap());
        for (got, want, what) in [(a, fa, "|dv'/dq|"), (c, fc, "|dv'/dv|")] {
            assert!(
                (got - want).abs() <= 1e-6 * want.max(1.0),
                "{name}, state {k} under u = {u:?}, {what}: {got:e} vs differences {want:e}"
            );
        }
        // the input matters: under u = 0 the norms differ (the GP mean's
        // gradient depends on the input)
        let (a0, c0) = l.step_jacobian_norms(z, &mut ws).unwrap();
        assert!(a0 != a || c0 != c, "{name}, state {k}");
    }
    // the bounded prediction steps as the mean steps above (bit for bit),
    // and under zero inputs it is the unforced prediction
    let bound = l
        .error_bound_forced::<U>(&BoundKind::rkhs(0.05), &Calibration::empty(l.dt()))
        .unwrap();
    let p = l.predict_forced(z0, &up0, &us, &bound).unwrap();
    assert_eq!(p.states, states, "{name}");
    assert!(p.position_bounds.iter().all(|b| b.is_finite()), "{name}");
    let zeros = vec![SVector::<f64, U>::zeros(); 6];
    assert_eq!(
        l.predict_forced(z0, &zeros[0], &zeros, &bound).unwrap(),
        l.predict(z0, 6, &bound).unwrap(),
        "{name}"
    );
}

/// Decoding inverts encoding (angles modulo 2π).
#[test]
fn encoding_round_trips() {
    use vigp::CoordinateKind::{Angle, Length};
    let kinds = [Length, Angle];
    let z = State::new([0.3, 2.0 + std::f64::consts::TAU], [-1.0, 4.0]);
    for enc in [Encoding::Raw, Encoding::SinCos] {
        let mut x = vec![0.0; enc.dim(&kinds)];
        enc.encode(&kinds, &z, &mut x);
        let back = enc.decode(&kinds, &x);
        assert_eq!(back.v, z.v);
        assert_eq!(back.q[0], z.q[0]);
        let dq = (back.q[1] - z.q[1]).rem_euclid(std::f64::consts::TAU);
        assert!(dq.min(std::f64::consts::TAU - dq) < 1e-12);
    }
}

/// Any f64 including NaN, ±∞, 0, negatives and huge values.
fn any_f64() -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-1.0),
        Just(1e300),
        Just(1e-300),
        -10.0..10.0f64,
        0.0..1.0f64,
        proptest::num::f64::ANY,
    ]
}

fn any_kind() -> impl Strategy<Value = BoundKind> {
    let vecs = proptest::collection::vec(any_f64(), 0..3);
    prop_oneof![
        (
            any_f64(),
            prop_oneof![Just(None), any_f64().prop_map(Some)],
            any::<bool>(),
            prop_oneof![Just(None), vecs.clone().prop_map(Some)],
            any_f64()
        )
            .prop_map(|(delta, tau, lederer, lf, margin)| {
                BoundKind::Theorem1(Theorem1Settings {
                    delta,
                    tau: tau.map_or(Tau::Optimise, Tau::Relative),
                    sigma_modulus: if lederer {
                        SigmaModulus::Lederer2019
                    } else {
                        SigmaModulus::FeatureSpace
                    },
                    lipschitz_f: lf.map_or(LipschitzF::FromMean, LipschitzF::Given),
                    domain_margin: margin,
                })
            }),
        (
            any_f64(),
            prop_oneof![
                any_f64().prop_map(NormBound::MeanTimes),
                vecs.clone().prop_map(NormBound::Given)
            ],
            prop_oneof![Just(NoiseBound::Fitted), vecs.prop_map(NoiseBound::Given)]
        )
            .prop_map(|(delta, norm_bound, noise)| BoundKind::Rkhs(RkhsSettings {
                delta,
                norm_bound,
                noise
            })),
        (
            any_f64(),
            prop_oneof![
                Just(Score::GpStd),
                Just(Score::LatentStd),
                Just(Score::Absolute),
                Just(Score::Auto)
            ],
            any::<bool>()
        )
            .prop_map(|(delta, score, sim)| {
                BoundKind::Conformal(ConformalSettings {
                    delta,
                    score,
                    tube: if sim {
                        Tube::Simultaneous
                    } else {
                        Tube::PerStep
                    },
                    ..ConformalSettings::default()
                })
            }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// No setting yields a NaN, negative or infinite bound without a typed
    /// error: either `error_bound` fails, or every constant, every one-step
    /// bound (at any finite σ ≥ 0) and every position bound of a 5-step
    /// prediction is finite and ≥ 0. `model()` is fitted to noise-free data
    /// (σ_n² at its floor), so a prediction may also meet a state whose GP
    /// variance is lost to rounding: that is `VarianceLost`, the typed
    /// error for a variance-based bound that would be 0 (which state, if
    /// any, depends on the last bits of the trained model).
    #[test]
    fn no_setting_gives_a_bad_bound(kind in any_kind(), sd in 0.0..1e3f64, start in 0usize..120) {
        let l = model();
        let cal = calibration();
        match l.error_bound(&kind, cal) {
            Err(_) => {}
            Ok(b) => {
                prop_assert!(b.projection_lipschitz.is_finite() && b.projection_lipschitz >= 1.0);
                for m in b.sigma_multipliers() {
                    prop_assert!(m.is_finite() && m >= 0.0, "multiplier {}", m);
                }
                // a bound can still overflow at use (B = 1e300 times σ):
                // then it is a typed error, never an ∞ or NaN value
                match b.one_step(&[sd]) {
                    Ok(one) => prop_assert!(one.is_finite() && one >= 0.0),
                    Err(e) => prop_assert!(matches!(e, BoundError::NonFinite { .. }), "{e}"),
                }
                match l.predict(&cal.windows()[start].start, 5, &b) {
                    Ok(p) => {
                        for v in p.one_step_bounds.iter().chain(&p.position_bounds) {
                            prop_assert!(v.is_finite() && *v >= 0.0, "bound {}", v);
                        }
                    }
                    Err(e) => prop_assert!(
                        matches!(e, BoundError::NonFinite { .. } | BoundError::VarianceLost { .. }),
                        "{e}"
                    ),
                }
            }
        }
    }
}

/// [`train_noise_free`] with the hyperparameters fixed (a zero-width box):
/// length scales 20, σ_f² = 1e4 (normalised) and σ_n² = `noise`.
fn fixed_noise_model(noise: f64) -> Learned<PendulumMinimal, 1, 0> {
    train_noise_free(&TrainOptions {
        restarts: 0,
        bounds: vigp::gp::Bounds {
            length_scale: (20.0, 20.0),
            signal_variance: (1e4, 1e4),
            noise_variance: (noise, noise),
        },
        ..TrainOptions::default()
    })
}

/// Nearly noise-free data, σ_n² = 1e-10 against σ_f² = 1e4 and length
/// scales 20 (normalised; fixed by a zero-width box): σ_f² − kᵀ(K + σ_n²I)⁻¹k
/// is lost to rounding at the training states and clamped to 0, and the
/// RKHS and Theorem 1 bounds used to come out as 0 and ≈ 1e-14 whatever the
/// error (found by a new user on a noise-free cart-pole fit through
/// `vigp predict`). They are `VarianceLost` now; with σ_n² = 1e-4 the same
/// prediction has its bounds.
#[test]
fn a_variance_lost_to_rounding_is_an_error_not_a_zero_bound() {
    let empty = Calibration::empty(DT);
    let z0 = noise_free_transitions()[3].z;
    let tight = fixed_noise_model(1e-10);
    let sd = tight
        .step_in(&z0, &mut tight.workspace())
        .unwrap()
        .1
        .std_dev[0];
    eprintln!("std dev at a training state with σ_n² = 1e-10: {sd:e}");
    for kind in [BoundKind::rkhs(0.05), BoundKind::theorem1(0.05)] {
        let bound = tight.error_bound(&kind, &empty).unwrap();
        let e = tight.predict(&z0, 5, &bound).unwrap_err();
        assert!(
            matches!(e, BoundError::VarianceLost { output: 0, .. }),
            "{e:?}"
        );
        let loose = fixed_noise_model(1e-4);
        let bound = loose.error_bound(&kind, &empty).unwrap();
        let p = loose.predict(&z0, 5, &bound).unwrap();
        let b = &p.one_step_bounds;
        assert!(b.iter().all(|b| *b > 0.0), "{b:?}");
    }
}

/// A conformal bound falls back to the RKHS bound at flagged states; on
/// the nearly noise-free model of
/// `a_variance_lost_to_rounding_is_an_error_not_a_zero_bound` the RKHS
/// bound does not exist where the variance is lost. The fallback used to
/// be evaluated at every state of a prediction with a flagged one, so a
/// single lost variance anywhere failed the prediction (`vigp predict
/// --bound conformal` on a noise-free cart-pole fit: every run failed).
/// Now each prediction succeeds; a flagged state keeps its conformal bound
/// (that of `Fallback::None`) where the fallback's variance is lost and
/// takes the larger of the two elsewhere; unflagged states are unchanged.
#[test]
fn a_conformal_bound_survives_a_fallback_without_variance() {
    let tight = fixed_noise_model(1e-10);
    let cal = calibration();
    let with = tight.error_bound(&BoundKind::conformal(0.05), cal).unwrap();
    let without = tight
        .error_bound(&conformal_with(Fallback::None), cal)
        .unwrap();
    let rkhs = tight.error_bound(&BoundKind::rkhs(0.05), cal).unwrap();
    let (mut flagged, mut kept, mut raised, mut mixed) = (0, 0, 0, 0);
    for tr in noise_free_transitions() {
        let p = tight.predict(&tr.z, 5, &with).unwrap();
        let n = tight.predict(&tr.z, 5, &without).unwrap();
        assert_eq!(p.outside, n.outside);
        // the RKHS bound alone: lost variance somewhere on the prediction?
        let lost = matches!(
            tight.predict(&tr.z, 5, &rkhs),
            Err(BoundError::VarianceLost { .. })
        );
        for ((a, b), o) in p
            .one_step_bounds
            .iter()
            .zip(&n.one_step_bounds)
            .zip(&p.outside)
        {
            assert!(a.is_finite() && *a >= *b, "{a} < {b}");
            if !o {
                assert_eq!(a, b);
            } else {
                flagged += 1;
                if a == b {
                    kept += 1;
                } else {
                    raised += 1;
                }
            }
        }
        // the case that used to fail
        mixed += usize::from(p.outside.iter().any(|o| *o) && lost);
    }
    eprintln!(
        "flagged states {flagged}: conformal kept {kept}, raised by the fallback {raised}; \
         {mixed} predictions flagged with a lost variance"
    );
    assert!(
        kept > 0 && raised > 0 && mixed > 0,
        "the test does not exercise both cases"
    );
}

/// A sparse GP (SGPR) has no exact posterior: Theorem 1 and the RKHS bound
/// are typed errors that name the conformal bound, and the conformal bound
/// works, without a fallback whatever the setting (its flagged states keep
/// their conformal bound, as with `Fallback::None`).
#[test]
fn a_sparse_model_is_bounded_conformally_only() {
    use vigp::gp::{Method, SparseOptions};
    let data: Vec<Transition<1>> = pendulum_windows(5, 60, 2)
        .iter()
        .map(|w| common::first_transition(w, DT))
        .collect();
    let opts = TrainOptions {
        method: Method::Sparse(SparseOptions::kmeans(16)),
        ..TrainOptions::default()
    };
    let sparse = train_sin_cos(&data, &opts);
    assert!(sparse.gp().is_sparse());
    let cal = calibration();
    for (kind, name) in [
        (BoundKind::theorem1(0.05), "Theorem-1"),
        (BoundKind::rkhs(0.05), "RKHS"),
    ] {
        let e = sparse.error_bound(&kind, cal).unwrap_err();
        assert!(
            matches!(e, BoundError::SparseModel { kind } if kind == name),
            "{e}"
        );
        assert!(e.to_string().contains("use the conformal bound"), "{e}");
    }
    let flag_only = sparse
        .error_bound(&conformal_with(Fallback::None), cal)
        .unwrap();
    for fallback in [Fallback::Rkhs, Fallback::Theorem1] {
        let b = sparse.error_bound(&conformal_with(fallback), cal).unwrap();
        assert!(b.fallback.is_none());
        let z = data[7].z;
        let (p, q) = (
            sparse.predict(&z, 5, &b).unwrap(),
            sparse.predict(&z, 5, &flag_only).unwrap(),
        );
        assert_eq!(p.one_step_bounds, q.one_step_bounds);
        assert!(p.one_step_bounds.iter().all(|v| v.is_finite() && *v > 0.0));
    }
}

/// The driven pendulum's truth for the forced bounds: heavier (×1.08) and
/// with three times the nominal pivot friction.
fn driven_truth() -> DrivenPendulumMinimal {
    let mut truth = DrivenPendulum::default();
    truth.links.rod.mass = 1.08;
    truth.joints.pivot.damping = 0.3;
    truth.minimal()
}

/// A forced model of the driven pendulum (sin/cos, nominal prior: the
/// unperturbed pendulum) trained on 150 transitions of [`driven_truth`]
/// (the midpoint VI at Δt) along six trajectories from random states under
/// inputs drawn uniformly from [−2, 2] per step, with uniform velocity
/// noise of σ = 1e-3 (as the paper).
fn driven_model() -> &'static Learned<DrivenPendulumMinimal, 1, 0> {
    static MODEL: OnceLock<Learned<DrivenPendulumMinimal, 1, 0>> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mut rng = Rng(21);
        let half = 1e-3 * 3f64.sqrt();
        let mut data = Vec::new();
        for _ in 0..6 {
            let z = State::new([rng.uniform(-2.0, 2.0)], [rng.uniform(-2.0, 2.0)]);
            data.extend(forced_data::<_, 1, 0, 1>(
                driven_truth(),
                &z,
                26,
                2.0,
                half,
                &mut rng,
            ));
        }
        let opts = common::train_options(2, 4);
        let nominal = DrivenPendulum::default().minimal();
        Learned::train_forced(nominal, DT, &data, Encoding::SinCos, Prior::Nominal, &opts)
            .unwrap()
            .0
    })
}

/// Windows of [`driven_truth`] under inputs: `count` random starts of the
/// training region, each followed by `k` steps under inputs uniform in
/// [−2, 2] (the truth is the midpoint VI at Δt, so its positions are exact).
fn driven_windows(seed: u64, count: usize, k: usize) -> Vec<(Window<1>, Vec<SVector<f64, 1>>)> {
    let truth = Variational::new(driven_truth(), DT).unwrap();
    let mut rng = Rng(seed);
    (0..count)
        .map(|_| {
            let start = State::new([rng.uniform(-1.5, 1.5)], [rng.uniform(-1.5, 1.5)]);
            let us: Vec<_> = (0..k)
                .map(|_| SVector::<f64, 1>::new(rng.uniform(-2.0, 2.0)))
                .collect();
            let mut z = start;
            let positions = us
                .iter()
                .map(|u| {
                    z = truth.step_forced(&z, u).unwrap();
                    z.q
                })
                .collect();
            (Window { start, positions }, us)
        })
        .collect()
}

/// [`driven_windows`] as a forced calibration set.
fn driven_calibration(seed: u64, count: usize, k: usize) -> Calibration<1> {
    let (windows, inputs) = driven_windows(seed, count, k).into_iter().unzip();
    Calibration::new_forced(DT, windows, inputs).unwrap()
}

/// Windows cut from logged trajectories
/// (`Calibration::from_trajectories_forced`, inputs logged with each sample
/// and held from its time) reproduce the truth: the truth's own step from
/// each window's start under the window's inputs lands on its positions
/// (to rounding, 1e-12; inputs shifted by one sample missed by 1.3e-2
/// here, the inputs being random per step).
#[test]
fn forced_windows_from_trajectories_follow_the_data_convention() {
    let truth = Variational::new(driven_truth(), DT).unwrap();
    let mut rng = Rng(31);
    let (mut trajectories, mut logged) = (Vec::new(), Vec::new());
    for _ in 0..3 {
        let mut z = State::new([rng.uniform(-1.0, 1.0)], [0.0]);
        // sample 0's input drives no step (no step ends before t_0); it is
        // the previous input of the windows that start at sample 0
        let (mut q, mut u) = (vec![z.q], vec![SVector::<f64, 1>::new(9.0)]);
        for _ in 0..30 {
            let ui = SVector::<f64, 1>::new(rng.uniform(-2.0, 2.0));
            z = truth.step_forced(&z, &ui).unwrap();
            q.push(z.q);
            u.push(ui);
        }
        trajectories.push(q);
        logged.push(u);
    }
    let cal = Calibration::from_trajectories_forced(&trajectories, &logged, DT, 6, 4).unwrap();
    assert_eq!(cal.input_count(), 1);
    assert_eq!(cal.len(), 3 * 7);
    let mut worst = 0.0f64;
    for (i, w) in cal.windows().iter().enumerate() {
        let us = cal.window_inputs::<1>(i).unwrap();
        assert_eq!(us.len(), 6);
        assert!(us.iter().all(|u| u[0] != 9.0));
        // the previous input: the one logged with the start's sample (runs
        // of 31 samples, windows every 4 samples: 7 per run)
        let (r, start) = (cal.window_runs()[i], 4 * (i % 7));
        assert_eq!(r, i / 7);
        assert_eq!(cal.window_previous_input::<1>(i).unwrap(), logged[r][start]);
        let mut z = w.start;
        for (u, q) in us.iter().zip(&w.positions) {
            z = truth.step_forced(&z, u).unwrap();
            worst = worst.max((z.q - q).norm());
        }
    }
    assert!(worst <= 1e-12, "{worst:e}");
    assert!(cal.window_inputs::<2>(0).is_none());
    let e =
        Calibration::from_trajectories_forced(&trajectories, &logged[..2], DT, 6, 4).unwrap_err();
    assert!(matches!(e, BoundError::WrongLength { .. }));
    // the message counts what it counts (it said "one per GP output")
    assert!(
        e.to_string().contains("one sequence per trajectory") && !e.to_string().contains("GP"),
        "{e}"
    );
    let mut ragged = logged.clone();
    ragged[1].pop();
    assert!(matches!(
        Calibration::from_trajectories_forced(&trajectories, &ragged, DT, 6, 4),
        Err(BoundError::Calibration { index: 1, .. })
    ));
}

/// The conformal bound of predictions under inputs, calibrated on 1000
/// forced windows of [`driven_truth`] (10 steps, default settings: the
/// score normalisation chosen on the first fifth) and tested on 1000
/// windows from another seed, drawn alike (exchangeable): coverage of the
/// one-step velocity error from the start and of the 10-step position
/// error ≥ 1 − δ − 0.02 at δ = 0.05 (0.02: two standard deviations of the
/// coverage of 1000 cases under a quantile of 800, as in
/// `tests/bound/bound_coverage.rs`).
#[test]
fn a_conformal_bound_under_inputs_covers_exchangeable_windows() {
    let l = driven_model();
    let cal = driven_calibration(41, 1000, 10);
    let bound = l
        .error_bound_forced::<1>(&BoundKind::conformal(0.05), &cal)
        .unwrap();
    let truth = Variational::new(driven_truth(), DT).unwrap();
    let (mut one, mut last, mut n) = (0usize, 0usize, 0usize);
    let (mut ratio1, mut ratio_k) = (Vec::new(), Vec::new());
    for (w, us) in driven_windows(42, 1000, 10) {
        // the windows take their first input as held across the start
        let p = l.predict_forced(&w.start, &us[0], &us, &bound).unwrap();
        let v1 = truth.step_forced(&w.start, &us[0]).unwrap().v;
        let e1 = (p.states[1].v - v1).norm();
        let ek = (p.states[10].q - w.positions[9]).norm();
        one += usize::from(e1 <= p.one_step_bounds[0]);
        last += usize::from(ek <= p.position_bounds[10]);
        ratio1.push(p.one_step_bounds[0] / e1);
        ratio_k.push(p.position_bounds[10] / ek);
        n += 1;
    }
    for r in [&mut ratio1, &mut ratio_k] {
        r.sort_by(f64::total_cmp);
    }
    let (c1, ck) = (one as f64 / n as f64, last as f64 / n as f64);
    println!(
        "conformal under inputs: one-step coverage {c1:.3} (bound/error median {:.2}), \
         10-step {ck:.3} (median {:.2})",
        ratio1[n / 2],
        ratio_k[n / 2]
    );
    assert!(c1 >= 0.93 && ck >= 0.93, "{c1} {ck}");
}

/// Bounds of predictions under inputs (`Learned::predict_forced`, constants
/// from `Learned::error_bound_forced`) against the truth under the same
/// inputs: 200 windows of 10 steps from random states of the training
/// region, each step's input drawn from the training distribution. The
/// one-step bound at predicted state z_k must cover ‖v_{k+1} −
/// v_true(z_k, u_k)‖, the truth's step from z_k under u_k (the truth is the
/// midpoint VI at Δt, so v_true is exact): the RKHS and Theorem-1 bounds
/// hold with probability ≥ 1 − δ = 0.95 under their assumptions, and the
/// asserted coverage is ≥ 0.95 of the 2000 cases. The propagated position
/// bounds (a first-order estimate, not part of the theorems) are printed.
///
/// That the inputs matter: the same windows predicted by `Learned::predict`
/// (the model under u = 0) are compared with the same forced truth; their
/// one-step bounds must fail on most cases (asserted coverage < 0.5), so a
/// forced path that dropped its inputs somewhere (in the step, the GP
/// input of the variance or the Jacobians) would not pass.
#[test]
fn forced_predictions_carry_bounds_that_hold() {
    let l = driven_model();
    let truth = Variational::new(driven_truth(), DT).unwrap();
    let empty = Calibration::empty(DT);
    let mut rng = Rng(77);
    let windows: Vec<(State<1>, Vec<SVector<f64, 1>>)> = (0..200)
        .map(|_| {
            let z = State::new([rng.uniform(-1.5, 1.5)], [rng.uniform(-1.5, 1.5)]);
            let us = (0..10)
                .map(|_| SVector::<f64, 1>::new(rng.uniform(-2.0, 2.0)))
                .collect();
            (z, us)
        })
        .collect();
    for kind in [BoundKind::rkhs(0.05), BoundKind::theorem1(0.05)] {
        let bound = l.error_bound_forced::<1>(&kind, &empty).unwrap();
        let (mut covered, mut cases, mut pos_covered, mut pos_cases) = (0, 0, 0, 0);
        let (mut unforced_covered, mut ratio) = (0, Vec::new());
        let mut ws = l.workspace();
        for (w, (z0, us)) in windows.iter().enumerate() {
            let p = l.predict_forced(z0, &us[0], us, &bound).unwrap();
            let free = l.predict(z0, us.len(), &bound).unwrap();
            if w < 10 {
                // the variance is the GP's at (z_k, u_{k−1}, u_k), the
                // one-step prediction's own
                for (k, u) in us.iter().enumerate() {
                    let up = &us[k.saturating_sub(1)];
                    let (v, sd) = l
                        .predict_velocity_forced(&p.states[k], up, u, &mut ws)
                        .unwrap();
                    assert_eq!(sd, p.std_devs[k]);
                    assert_eq!(v, p.states[k + 1].v);
                }
            }
            let mut zt = *z0;
            for (k, u) in us.iter().enumerate() {
                let want = truth.step_forced(&p.states[k], u).unwrap().v;
                let err = (p.states[k + 1].v - want).norm();
                covered += usize::from(err <= p.one_step_bounds[k]);
                ratio.push(p.one_step_bounds[k] / err);
                let want = truth.step_forced(&free.states[k], u).unwrap().v;
                let err = (free.states[k + 1].v - want).norm();
                unforced_covered += usize::from(err <= free.one_step_bounds[k]);
                cases += 1;
                zt = truth.step_forced(&zt, u).unwrap();
                let err = (p.states[k + 1].q - zt.q).norm();
                pos_covered += usize::from(err <= p.position_bounds[k + 1]);
                pos_cases += 1;
            }
        }
        ratio.sort_by(f64::total_cmp);
        let frac = |a: usize, b: usize| a as f64 / b as f64;
        println!(
            "{}: one-step coverage {:.4} (bound/error median {:.2}), positions {:.4}; \
             ignoring the inputs: {:.4}",
            bound.kind_name(),
            frac(covered, cases),
            ratio[ratio.len() / 2],
            frac(pos_covered, pos_cases),
            frac(unforced_covered, cases)
        );
        assert!(frac(covered, cases) >= 0.95, "{}", bound.kind_name());
        assert!(frac(unforced_covered, cases) < 0.5, "{}", bound.kind_name());
    }
}

/// With zero inputs the forced prediction is the unforced one of the same
/// model (which steps under u = 0 through its own code path: the nominal
/// step without inputs and a zero-filled GP input): states, standard
/// deviations, corrections and every bound equal bit for bit. A model
/// without inputs predicts with `U = 0` as `predict` does.
#[test]
fn forced_prediction_under_zero_inputs_is_the_unforced_one() {
    let l = driven_model();
    let empty = Calibration::empty(DT);
    let zeros = vec![SVector::<f64, 1>::zeros(); 8];
    let z0 = State::new([0.7], [-0.4]);
    for kind in [BoundKind::rkhs(0.05), BoundKind::theorem1(0.01)] {
        let bound = l.error_bound_forced::<1>(&kind, &empty).unwrap();
        let forced = l.predict_forced(&z0, &zeros[0], &zeros, &bound).unwrap();
        let free = l.predict(&z0, zeros.len(), &bound).unwrap();
        assert_eq!(forced, free, "{}", bound.kind_name());
        assert!(forced.position_bounds[8] > 0.0);
        // an input outside the training range [−2, 2] leaves Theorem 1's
        // box X (the inputs are part of the GP input); inside it does not.
        // The step after it takes it as its previous input: outside too
        let mut us = vec![SVector::<f64, 1>::new(1.0); 5];
        us[2][0] = 5.0;
        let p = l.predict_forced(&z0, &us[0], &us, &bound).unwrap();
        if bound.kind_name() == "theorem1" {
            assert_eq!(p.outside, [false, false, true, true, false]);
        }
    }
    let m = noisy_model();
    let bound = m.error_bound(&BoundKind::rkhs(0.05), &empty).unwrap();
    let free = m.predict(&z0, 6, &bound).unwrap();
    let none: [SVector<f64, 0>; 6] = [SVector::zeros(); 6];
    assert_eq!(
        m.predict_forced(&z0, &none[0], &none, &bound).unwrap(),
        free
    );
    assert_eq!(
        m.error_bound_forced::<0>(&BoundKind::rkhs(0.05), &empty)
            .unwrap(),
        bound
    );
}

/// Misuse of the forced bounds is a typed error: inputs for a model
/// trained without them (an input count other than the mechanism's does
/// not compile: the forced steps assert it), a conformal bound (calibrated
/// on unforced windows) for a prediction under inputs, a NaN input.
#[test]
fn forced_bound_misuse_is_a_typed_error() {
    let l = driven_model();
    let empty = Calibration::empty(DT);
    let z0 = State::new([0.2], [0.1]);
    let data = noisy_transitions(driven_truth(), &State::new([1.0], [0.0]), 30, 8);
    let opts = common::restarts(0);
    let nominal = DrivenPendulum::default().minimal();
    let (plain, _) =
        Learned::train(nominal, DT, &data, Encoding::SinCos, Prior::Nominal, &opts).unwrap();
    assert_eq!(plain.inputs(), 0);
    assert!(matches!(
        plain.error_bound_forced::<1>(&BoundKind::rkhs(0.05), &empty),
        Err(BoundError::Mismatch(_))
    ));
    let bound = l
        .error_bound_forced::<1>(&BoundKind::rkhs(0.05), &empty)
        .unwrap();
    let us = [SVector::<f64, 1>::new(0.5); 2];
    assert!(matches!(
        plain.predict_forced(&z0, &us[0], &us, &bound),
        Err(BoundError::Mismatch(_))
    ));
    // conformal: windows without inputs do not calibrate a forced bound,
    // windows with inputs do not calibrate an unforced one, and a bound
    // calibrated one way is not used the other way
    let e = l
        .error_bound_forced::<1>(&BoundKind::conformal(0.1), calibration())
        .unwrap_err();
    assert!(matches!(e, BoundError::Mismatch(_)), "{e}");
    let forced_cal = driven_calibration(5, 40, 4);
    let e = l
        .error_bound(&BoundKind::conformal(0.1), &forced_cal)
        .unwrap_err();
    assert!(matches!(e, BoundError::Mismatch(_)), "{e}");
    let unforced = l
        .error_bound(&BoundKind::conformal(0.1), calibration())
        .unwrap();
    let e = l.predict_forced(&z0, &us[0], &us, &unforced).unwrap_err();
    assert!(matches!(e, BoundError::Mismatch(_)), "{e}");
    let forced = l
        .error_bound_forced::<1>(&BoundKind::conformal(0.1), &forced_cal)
        .unwrap();
    let e = l.predict(&z0, 2, &forced).unwrap_err();
    assert!(matches!(e, BoundError::Mismatch(_)), "{e}");
    // malformed forced windows
    let windows = forced_cal.windows().to_vec();
    let short = vec![vec![SVector::<f64, 1>::zeros(); 3]; windows.len()];
    assert!(matches!(
        Calibration::new_forced(DT, windows.clone(), short),
        Err(BoundError::Calibration { index: 0, .. })
    ));
    let mut nan = vec![vec![SVector::<f64, 1>::zeros(); 4]; windows.len()];
    nan[7][2][0] = f64::NAN;
    assert!(matches!(
        Calibration::new_forced(DT, windows.clone(), nan),
        Err(BoundError::Calibration { index: 7, .. })
    ));
    assert!(matches!(
        Calibration::new_forced(DT, windows, vec![vec![SVector::<f64, 1>::zeros(); 4]]),
        Err(BoundError::WrongLength { .. })
    ));
    let nan = [SVector::<f64, 1>::new(f64::NAN); 2];
    let e = l.predict_forced(&z0, &nan[0], &nan, &bound).unwrap_err();
    assert!(
        matches!(e, BoundError::Step(StepError::NonFiniteInput { .. })),
        "{e}"
    );
}
