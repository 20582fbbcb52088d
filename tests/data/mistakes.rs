//! Mistakes a new user makes (issue "data that lies" and "panics and
//! silent nonsense"), each with the typed error it now gets. The table in
//! docs/stability.md lists them with these tests. Every test asserts the
//! error variant and the key words of its message, so each fails if the
//! mistake is accepted again or fails another way.

use crate::common;
use nalgebra::{SVector, UnitQuaternion, Vector3};
use vigp::bound::{BoundError, BoundKind, Calibration, Window};
use vigp::data::{DataError, DataWarning, check_transitions_dt};
use vigp::learned::{Encoding, LearnError, Learned, Prior, Transition};
use vigp::prelude::*;
use vigp::spatial::{LieStepper, SpatialError, SpatialState};
use vigp::systems::{DoublePendulum, Fourbar, Pendulum, PendulumMinimal};

#[macro_use]
#[path = "../common/pinned_chain.rs"]
mod pinned_chain;

pinned_chain!(
    ShortChain,
    5.0,
    "Three 1 m links pinned at the origin and at (5, 0): the chain reaches 3 m, the loop cannot close."
);

pinned_chain!(
    TautChain3,
    3.0,
    "The same chain pinned exactly 3 m apart: it closes, but only at full stretch (the loop Jacobian loses rank there)."
);

vigp::mechanism! {
    /// A rod on a ball joint (minimal coordinates: one quaternion).
    pub BallPendulum {
        gravity: [0.0, 0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0, inertia: [0.001, 0.0833333, 0.0833333] },
        }
        joints {
            ball: spherical(world, rod.start),
        }
    }
}

// ---- panics ----

/// `rollout(&z, usize::MAX)` panicked ("range start index 1 out of range"),
/// `usize::MAX / 2` with "capacity overflow"; a duration over Δt = 0 gives
/// such a count (`(10.0 / 0.0) as usize` saturates to `usize::MAX`).
#[test]
fn rollouts_of_impossible_lengths_are_typed_errors() {
    let vi = Variational::new(DoublePendulum::default().minimal(), 0.01).unwrap();
    let z = State::new([0.5, 0.3], [0.0, 0.0]);
    let from_zero_dt = (10.0f64 / 0.0) as usize;
    for steps in [usize::MAX, usize::MAX / 2, usize::MAX / 64, from_zero_dt] {
        let e = vi.rollout(&z, steps).unwrap_err();
        assert!(
            matches!(e, StepError::TooManySteps { steps: s } if s == steps),
            "{e:?}"
        );
        assert!(e.to_string().contains("do not fit in memory"), "{e}");
    }
    // the forced rollout's buffer goes through the same check, and a
    // plausible count still runs
    assert_eq!(vi.rollout(&z, 3).unwrap().len(), 4);
    // the 3-D rollouts
    let stepper = LieStepper::new(BallPendulum::default().maximal(), 0.01).unwrap();
    let z3 = SpatialState::<1> {
        x: [Vector3::new(0.0, 0.0, -0.5)],
        q: [UnitQuaternion::identity()],
        v: [Vector3::zeros()],
        w: [Vector3::zeros()],
    };
    let e = vigp::Integrator::rollout(&stepper, &z3, usize::MAX).unwrap_err();
    assert!(
        matches!(
            e,
            SpatialError::Step(vigp::embedded::StepError::TooManySteps { .. })
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("do not fit in memory"), "{e}");
    // the learned rollout checks the count before it allocates, too
    let m = Pendulum::default().minimal();
    let nominal = Variational::new(m, 0.01).unwrap();
    let mut zp = State::new([0.5], [0.0]);
    let mut tr = Vec::new();
    for _ in 0..20 {
        let z1 = nominal.step(&zp).unwrap();
        tr.push(Transition {
            z: zp,
            v_next: z1.v,
        });
        zp = z1;
    }
    let options = common::restarts(0);
    let (learned, _) =
        Learned::train(m, 0.01, &tr, Encoding::SinCos, Prior::Nominal, &options).unwrap();
    let mut ws = learned.workspace();
    let start = State::new([0.5], [0.0]);
    for steps in [usize::MAX, usize::MAX / 2, usize::MAX / 64] {
        let e = learned
            .rollout_with_info(&start, steps, &mut ws)
            .unwrap_err();
        assert!(matches!(e, StepError::TooManySteps { .. }), "{e:?}");
    }
    assert_eq!(
        learned.rollout_with_info(&start, 3, &mut ws).unwrap().len(),
        3
    );
}

/// The double pendulum at Δt = 2 s: Newton converges, but to a root no
/// motion has (with the check off the energy goes from −17 J to thousands
/// of joules). Without subdivision (`max_subdivision(0)`) the step is
/// `NotContinuation`, with the ratio; by default (a mechanism without
/// constraints subdivides a failing step up to 8 times) it subdivides
/// itself until it resolves the motion.
#[test]
fn a_root_that_is_not_the_continuation_of_the_motion_is_an_error() {
    let m = DoublePendulum::default().minimal();
    let z0 = State::new([0.5, 0.0], [0.0, 0.0]);
    let e0 = m.energy(&z0);
    // with the check off: Ok, and nonsense
    let off = Variational::new(m, 2.0)
        .unwrap()
        .continuation_bound(f64::INFINITY)
        .unwrap();
    let mut z = z0;
    let mut max_e = e0;
    let mut ratios = Vec::new();
    for _ in 0..20 {
        match off.step_with_report(&z) {
            Ok((next, info)) => {
                z = next;
                max_e = max_e.max(m.energy(&z));
                ratios.push(info.continuation);
            }
            Err(_) => break,
        }
    }
    println!("E0 = {e0:.2} J, check off: max E = {max_e:.3e} J, ratios {ratios:.3?}");
    // energy grows by far more than any motion from rest at −17 J allows
    // (the potential's range is ±29.4 J); the first step bends 32 rad
    // (a second implementation of the first-order rule, numpy: 16.1 rad/s
    // after 2 s from rest, E = 58.6 J)
    assert!(max_e > 100.0, "max energy {max_e}");
    assert!(ratios[0] > 30.0, "{ratios:?}");
    // without subdivision: a typed error naming the ratio and the remedy
    let on = Variational::new(m, 2.0).unwrap().max_subdivision(0);
    let e = on.rollout(&z0, 20).unwrap_err();
    println!("max_subdivision(0): {e}");
    match e {
        StepError::NotContinuation { ratio, bound, .. } => {
            assert!(ratio > bound && bound == 1.0, "{e:?}")
        }
        other => panic!("expected NotContinuation, got {other:?}"),
    }
    let text = e.to_string();
    assert!(
        text.contains("not the continuation of the motion"),
        "{text}"
    );
    assert!(text.contains("substeps"), "{text}");
    // by default the step subdivides itself (up to 8 halvings) until its
    // sub-steps resolve the motion: 20 steps of 2 s complete, and the
    // energy stays within the
    // first-order bound of the finest sub-step used (Δt·max|v|·scale, the
    // scale Σ m·|g|·l = 29.4 J plus the largest kinetic energy)
    let default = Variational::new(m, 2.0).unwrap();
    assert_eq!(default.subdivision_depth(), 8);
    let (traj, report) = default.rollout_with_report(&z0, 20).unwrap();
    let h = 2.0 / f64::from(1u32 << report.deepest);
    let vmax = traj
        .iter()
        .flat_map(|z| z.v.iter())
        .fold(0.0f64, |a, x| a.max(x.abs()));
    let drift = traj
        .iter()
        .map(|z| (m.energy(z) - e0).abs())
        .fold(0.0f64, f64::max);
    let scale = 29.4
        + traj
            .iter()
            .map(|z| m.energy(z) - m.potential_energy(&z.q))
            .fold(0.0f64, f64::max);
    println!(
        "default (max_subdivision(8)): {report:?}, finest sub-step {h} s, max |E − E0| {drift:.3e} J (scale {scale:.1} J, max |v| {vmax:.2})"
    );
    assert_eq!((report.steps, report.subdivided), (20, 20), "{report:?}");
    assert!(drift <= h * vmax * scale, "{drift} > {}", h * vmax * scale);
    // a bound ≤ 0 or NaN is refused
    for bad in [0.0, -1.0, f64::NAN] {
        let e = Variational::new(m, 0.01)
            .unwrap()
            .continuation_bound(bad)
            .unwrap_err();
        assert!(matches!(e, StepError::InvalidOptions(_)), "{e:?}");
    }
}

/// The check does not fire on motions resolved by the step: the double
/// pendulum and the fourbar at Δt = 10 ms, 2000 steps from a fast start
/// (the largest bend is printed).
#[test]
fn resolved_motions_pass_the_continuation_check() {
    let dt = 0.01;
    let dp = DoublePendulum::default().minimal();
    let vi = Variational::new(dp, dt).unwrap();
    let mut z = State::new([2.0, -1.0], [3.0, -3.0]);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let (next, info) = vi.step_with_report(&z).unwrap();
        worst = worst.max(info.continuation);
        z = next;
    }
    let fb = Fourbar::default().minimal();
    let z0 = vigp::projection::consistent_state(
        &fb,
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::from([3.0, 0.0, 0.0, 0.0]),
        dt,
    )
    .unwrap();
    let fvi = Variational::new(fb, dt).unwrap();
    let mut z = z0;
    let mut worst_fb = 0.0f64;
    for _ in 0..2000 {
        let (next, info) = fvi.step_with_report(&z).unwrap();
        worst_fb = worst_fb.max(info.continuation);
        z = next;
    }
    println!("largest continuation ratio: double pendulum {worst:.3}, fourbar {worst_fb:.3}");
    // the default bound is 1 rad
    assert!(worst < 1.0 && worst_fb < 1.0);
}

/// A stiff, heavily damped link bends the path by more than the bound in
/// one correct step while its energy barely changes (719.35 J → 722.87 J):
/// the check refuses a large bend only with an energy jump, and accepts
/// this step (a bend-only check refused it). The case is the one the property test
/// of random double pendulums found (tests/step/properties.rs): a 0.25 m,
/// 0.25 kg lower link with elbow damping 1.1 at Δt = 0.047 s.
#[test]
fn a_stiff_damped_step_that_bends_far_is_accepted() {
    let mut s = DoublePendulum::default();
    let (m1, l1, m2, l2) = (
        1.0,
        4.526629883858304,
        0.25251198906291616,
        0.24791269335396096,
    );
    for (link, m, l) in [(&mut s.links.upper, m1, l1), (&mut s.links.lower, m2, l2)] {
        link.mass = m;
        link.length = l;
        link.inertia = m * l * l / 12.0;
        link.com = [l / 2.0, 0.0];
    }
    s.joints.elbow.damping = 1.1061245367594892;
    let m = s.minimal();
    let vi = Variational::new(m, 0.047040756234092526).unwrap();
    let z = State::new([0.0, -1.7990825640243568], [11.226092073870637, 0.0]);
    let (z1, info) = vi.step_with_report(&z).unwrap();
    println!(
        "stiff damped step: bend {:.2} rad, energy {:.3} J -> {:.3} J",
        info.continuation,
        m.energy(&z),
        m.energy(&z1)
    );
    assert!(info.continuation > 1.0, "bend {}", info.continuation);
    let (e0, e1) = (m.energy(&z), m.energy(&z1));
    assert!((e1 - e0).abs() < 0.01 * e0.abs(), "energy {e0} -> {e1}");
}

/// A loop that cannot close compiled and failed at the first step
/// (`NotConverged … residual 7.0`); it is now refused when the integrator
/// is built, with the residual. Loops that close (the fourbar, a chain at
/// full stretch) pass.
#[test]
fn a_loop_that_cannot_close_is_refused_at_construction() {
    let e = Variational::new(ShortChain::default().minimal(), 0.01).unwrap_err();
    println!("{e}");
    match e {
        StepError::LoopCannotClose { residual } => assert!(residual > 0.1, "{e:?}"),
        other => panic!("expected LoopCannotClose, got {other:?}"),
    }
    assert!(e.to_string().contains("cannot close"), "{e}");
    assert!(matches!(
        Variational::midpoint(ShortChain::default().minimal(), 0.01),
        Err(StepError::LoopCannotClose { .. })
    ));
    Variational::new(TautChain3::default().minimal(), 0.01).unwrap();
    Variational::new(Fourbar::default().minimal(), 0.01).unwrap();
}

/// A 3-D start state with a non-unit quaternion failed with "singular
/// Newton matrix at iteration 0" (or another Newton failure) and no hint;
/// it now names the quaternion, its norm and `consistent_state`.
#[test]
fn a_non_unit_quaternion_start_gets_the_consistent_state_hint() {
    let m = BallPendulum::default().minimal();
    let vi = Variational::new(m, 0.01).unwrap();
    // a unit start steps
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
    let q = tilt.quaternion();
    let unit = State::new([q.w, q.i, q.j, q.k], [0.0; 4]);
    vi.step(&unit).unwrap();
    for scale in [2.0, 0.5] {
        let z = State::new(
            [scale * q.w, scale * q.i, scale * q.j, scale * q.k],
            [0.0; 4],
        );
        let e = vi.step(&z).unwrap_err();
        println!("norm {scale}: {e}");
        match e {
            StepError::NonUnitQuaternion { link: 0, norm, .. } => {
                assert!((norm - scale).abs() < 1e-12, "{e:?}")
            }
            other => panic!("expected NonUnitQuaternion, got {other:?}"),
        }
        assert!(e.to_string().contains("consistent_state"), "{e}");
    }
}

// ---- data that lies ----

/// A pendulum log at 100 Hz (positions from the VI), `runs` runs of
/// `rows` rows, as CSV text; `edit(run, row, value)` may replace a reading.
fn pendulum_log(
    runs: usize,
    rows: usize,
    time: impl Fn(usize) -> String,
    edit: impl Fn(usize, usize, f64) -> f64,
) -> String {
    let vi = Variational::new(Pendulum::default().minimal(), 0.01).unwrap();
    let mut text = String::from("run,t,pivot\n");
    for r in 0..runs {
        let mut z = State::new([0.4 + 0.3 * r as f64], [0.0]);
        for k in 0..rows {
            let x = edit(r, k, z.q[0]);
            text.push_str(&format!("r{r},{},{x}\n", time(k)));
            z = vi.step(&z).unwrap();
        }
    }
    text
}

fn seconds(k: usize) -> String {
    format!("{:.2}", k as f64 * 0.01)
}

fn read(text: &str, opts: &ReadOptions) -> Result<Dataset<1>, DataError> {
    Dataset::<1>::read_for::<PendulumMinimal, 0, _>(text.as_bytes(), opts)
}

/// One angle reading of 1e6 or 1e308 was unwrapped to −0.358 rad and
/// accepted; it is now an outlier naming run, line and column, or, with
/// `drop_outliers`, dropped, counted, and its run split there.
#[test]
fn a_sensor_spike_is_an_outlier_naming_run_line_and_column() {
    for spike in [1e6, 1e308, -1e6] {
        // run r1, row 30: file line 1 (header) + 60 (run r0) + 30 + 1
        let text = pendulum_log(
            2,
            60,
            seconds,
            |r, k, x| {
                if r == 1 && k == 30 { spike } else { x }
            },
        );
        let e = read(&text, &ReadOptions::default()).unwrap_err();
        println!("{e}");
        match &e {
            DataError::Outlier {
                run,
                line,
                column,
                value,
                ..
            } => {
                assert_eq!((run.as_str(), *line, column.as_str()), ("r1", 92, "pivot"));
                assert_eq!(*value, spike);
            }
            other => panic!("expected Outlier, got {other:?}"),
        }
        assert!(e.to_string().contains("drop_outliers"), "{e}");
        let d = read(
            &text,
            &ReadOptions {
                drop_outliers: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.dropped.len(), 1);
        assert_eq!((d.dropped[0].line, d.dropped[0].value), (92, spike));
        // r0, r1 before the spike (30 rows), r1 after it (29 rows)
        let names: Vec<&str> = d.runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["r0", "r1", "r1@93"]);
        assert_eq!(d.samples(), 119);
        // every velocity is a motion again: below 3 rad/s
        for run in &d.runs {
            for k in 0..run.positions.len() - 1 {
                assert!(run.state(k).unwrap().v[0].abs() < 3.0);
            }
        }
    }
    // the clean log reads as before: no outlier, no warning
    let d = read(
        &pendulum_log(2, 60, seconds, |_, _, x| x),
        &ReadOptions::default(),
    )
    .unwrap();
    assert!(d.dropped.is_empty() && d.warnings.is_empty());
    assert_eq!(d.runs.len(), 2);
}

/// An explicit speed bound (`max_speed`) applies to every coordinate.
#[test]
fn a_speed_bound_set_by_the_user_refuses_faster_readings() {
    // a jump of 0.05 rad in one sample (5 rad/s) against a 2 rad/s bound
    let text = pendulum_log(1, 40, seconds, |_, k, x| if k == 20 { x + 0.05 } else { x });
    let opts = ReadOptions {
        max_speed: Some(2.0),
        ..Default::default()
    };
    let e = read(&text, &opts).unwrap_err();
    assert!(
        matches!(&e, DataError::Outlier { line: 22, bound, .. } if *bound == 2.0),
        "{e:?}"
    );
    // the default bound (the run's extent) lets it pass: it is plausible
    read(&text, &ReadOptions::default()).unwrap();
}

/// A log in degrees was read with max |v| = 313 rad/s, and timestamps in
/// milliseconds were read too, with no word. Both now come with a warning
/// that names the likely unit.
#[test]
fn degrees_and_milliseconds_get_a_unit_warning() {
    let degrees = pendulum_log(1, 200, seconds, |_, _, x| x.to_degrees());
    let d = read(&degrees, &ReadOptions::default()).unwrap();
    println!("{:?}", d.warnings);
    assert!(
        d.warnings.iter().any(
            |w| matches!(w, DataWarning::LooksLikeDegrees { column, .. } if column == "pivot")
        ),
        "{:?}",
        d.warnings
    );
    assert!(d.warnings[0].to_string().contains("degrees"));
    let ms = pendulum_log(1, 50, |k| format!("{}", k * 10), |_, _, x| x);
    let d = read(&ms, &ReadOptions::default()).unwrap();
    assert!(
        matches!(&d.warnings[..], [DataWarning::LooksLikeMilliseconds { dt, .. }] if *dt == 10.0),
        "{:?}",
        d.warnings
    );
    assert!(d.warnings[0].to_string().contains("milliseconds"));
}

/// `train` took Δt = 0.02 on 0.01 s data without a word. The transitions
/// carry the Δt they were formed with; `check_transitions_dt` finds it
/// and refuses another, with the factor.
#[test]
fn a_dt_that_contradicts_the_data_is_a_typed_error() {
    let d = read(
        &pendulum_log(2, 60, seconds, |_, _, x| x),
        &ReadOptions::default(),
    )
    .unwrap();
    let tr = d.transitions();
    check_transitions_dt(&tr, 0.01, 1e-6).unwrap();
    let e = check_transitions_dt(&tr, 0.02, 1e-6).unwrap_err();
    println!("{e}");
    match &e {
        DataError::DtContradictsData { given, found, .. } => {
            assert_eq!((*given, *found), (0.02, 0.01))
        }
        other => panic!("expected DtContradictsData, got {other:?}"),
    }
    assert!(e.to_string().contains("factor of 2"), "{e}");
    // and the dataset's own check against a model's Δt
    assert!(matches!(
        d.check_dt(0.02, 1e-6),
        Err(DataError::TimeStepMismatch { .. })
    ));
    // training itself refuses the contradicting Δt before fitting anything
    // (and takes the right one)
    let model = Pendulum::default().minimal();
    let options = common::restarts(0);
    let train = |dt: f64| {
        Learned::train(model, dt, &tr, Encoding::SinCos, Prior::Nominal, &options).map(|_| ())
    };
    for (dt, factor) in [(0.02, "factor of 2"), (10.0, "factor of 1000")] {
        let e = train(dt).unwrap_err();
        println!("{e}");
        match &e {
            LearnError::DtContradictsData { given, found, .. } => {
                assert_eq!(*given, dt);
                assert!((found - 0.01).abs() < 1e-12, "{found}");
            }
            other => panic!("expected DtContradictsData, got {other:?}"),
        }
        assert!(e.to_string().contains(factor), "{e}");
    }
    train(0.01).unwrap();
}

/// The training check does not refuse transitions whose velocities were
/// measured rather than differenced: states of a double pendulum from
/// RK4 at Δt/50 with their true velocities, v_next the true velocity one
/// Δt later (x₁ = x₀ + Δt·v₀ then holds only to O(Δt·|a|/|v|)).
#[test]
fn training_accepts_measured_velocities_at_the_right_dt() {
    let model = DoublePendulum::default().minimal();
    let rk = vigp::Rk4::new(model, DT / 50.0);
    let mut z = State::new([1.0, -0.5], [0.0, 0.0]);
    let mut states = vec![z];
    for _ in 0..60 {
        for _ in 0..50 {
            z = rk.step(&z).unwrap();
        }
        states.push(z);
    }
    let tr: Vec<Transition<2>> = states
        .windows(2)
        .map(|w| Transition {
            z: w[0],
            v_next: w[1].v,
        })
        .collect();
    let options = common::restarts(0);
    Learned::train(model, DT, &tr, Encoding::SinCos, Prior::Nominal, &options).unwrap();
    let e = Learned::train(
        model,
        2.0 * DT,
        &tr,
        Encoding::SinCos,
        Prior::Nominal,
        &options,
    )
    .unwrap_err();
    assert!(matches!(e, LearnError::DtContradictsData { .. }), "{e:?}");
}

const DT: f64 = 0.01;

/// Windows of 5 steps of the pendulum from pseudo-random states (a fixed
/// linear congruential sequence per seed).
fn windows(seed: u64, count: usize) -> Vec<Window<1>> {
    let vi = Variational::new(Pendulum::default().minimal(), DT).unwrap();
    let mut s = seed;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| {
            let q0 = 4.0 * next() - 2.0;
            let v0 = 5.0 * next() - 2.5;
            let traj = vi.rollout(&State::new([q0], [v0]), 6).unwrap();
            let p: Vec<_> = traj.iter().map(|z| z.q).collect();
            common::window(&p, DT)
        })
        .collect()
}

/// Calibrating on the training runs was accepted (coverage then fell to
/// 0.90 at δ = 0.05); windows that start at training states are refused.
#[test]
fn calibration_on_the_training_runs_is_refused() {
    let train: Vec<Transition<1>> = windows(1, 40)
        .iter()
        .map(|w| common::first_transition(w, DT))
        .collect();
    let opts = common::train_options(1, 3);
    let (learned, _) = Learned::train(
        Pendulum::default().minimal(),
        DT,
        &train,
        Encoding::SinCos,
        Prior::Nominal,
        &opts,
    )
    .unwrap();
    let kind = BoundKind::conformal(0.05);
    let same = Calibration::new(DT, windows(1, 40)).unwrap();
    let e = learned.error_bound(&kind, &same).unwrap_err();
    println!("{e}");
    assert!(
        matches!(
            e,
            BoundError::CalibrationOverlapsTraining {
                overlapping: 40,
                total: 40,
                first: 0
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("held out"), "{e}");
    // half of them mixed into held-out windows: still refused
    let mut mixed = windows(2, 40);
    mixed.extend(windows(1, 20));
    let e = learned
        .error_bound(&kind, &Calibration::new(DT, mixed).unwrap())
        .unwrap_err();
    assert!(matches!(
        e,
        BoundError::CalibrationOverlapsTraining {
            overlapping: 20,
            first: 40,
            ..
        }
    ));
    // held-out windows calibrate
    learned
        .error_bound(&kind, &Calibration::new(DT, windows(2, 40)).unwrap())
        .unwrap();
    // a bounded prediction of usize::MAX steps is refused before its
    // buffers are allocated (it overflowed steps × d)
    let rkhs = learned
        .error_bound(&BoundKind::rkhs(0.05), &Calibration::empty(DT))
        .unwrap();
    let start = windows(3, 1)[0].start;
    for steps in [usize::MAX, usize::MAX / 2] {
        let e = learned.predict(&start, steps, &rkhs).unwrap_err();
        assert!(
            matches!(e, BoundError::Step(StepError::TooManySteps { .. })),
            "{e:?}"
        );
    }
}
