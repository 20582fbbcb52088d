//! Property tests (proptest) over random states and parameters: a step
//! either solves its own equations or is a typed error; the motion does not
//! depend on the mass unit; the midpoint VI is time-reversible; projections
//! land on the manifold; GP training, prediction and loading never panic
//! and never return NaN. Failing inputs are shrunk to a minimal case.

use nalgebra::SVector;
use proptest::prelude::*;
use vigp::gp::{Gp, GpError, SavedGp, TrainOptions};
use vigp::prelude::*;
use vigp::projection::{consistent_state, project_configuration};
use vigp::systems::{DoublePendulum, Fourbar};

/// Log-uniform in [10^lo, 10^hi].
fn log_uniform(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    (lo..hi).prop_map(|e| 10f64.powf(e))
}

/// Random double-pendulum parameters: masses and lengths 1e-2…1e2 (ratios
/// up to 1e4), inertias m·l²/12, damping 0…2.
fn double_pendulum() -> impl Strategy<Value = DoublePendulum> {
    (
        log_uniform(-2.0, 2.0),
        log_uniform(-2.0, 2.0),
        log_uniform(-1.0, 1.0),
        log_uniform(-1.0, 1.0),
        0.0..2.0f64,
    )
        .prop_map(|(m1, m2, l1, l2, c)| {
            let mut s = DoublePendulum::default();
            for (link, m, l) in [(&mut s.links.upper, m1, l1), (&mut s.links.lower, m2, l2)] {
                link.mass = m;
                link.length = l;
                link.inertia = m * l * l / 12.0;
                link.com = [l / 2.0, 0.0];
            }
            s.joints.elbow.damping = c;
            s
        })
}

fn angle() -> impl Strategy<Value = f64> {
    -std::f64::consts::PI..std::f64::consts::PI
}

/// A failure must be a Newton failure with finite diagnostics, or a
/// converged root the continuation check refused (its bend finite and above
/// the bound it names).
fn typed_failure(e: &StepError) -> bool {
    match e {
        StepError::NotConverged { residual, .. } | StepError::LineSearchFailed { residual, .. } => {
            residual.is_finite()
        }
        StepError::SingularJacobian { .. } | StepError::NonFiniteResidual { .. } => true,
        StepError::NotContinuation { ratio, bound, .. } => ratio.is_finite() && ratio > bound,
        _ => false,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// One paper-VI step from a random state with random parameters:
    /// `Ok` means a finite state whose DEL residual, recomputed
    /// independently of the solver's loop, is within the accepted
    /// tolerance (1e-10 = the stall tolerance, relative to |p₀| + m̄ as the
    /// solver scales it); otherwise a typed failure (see `typed_failure`).
    #[test]
    fn paper_step_solves_its_equations_or_fails_typed(
        sys in double_pendulum(),
        q in (angle(), angle()),
        v in (-12.0..12.0f64, -12.0..12.0f64),
        dt in 1e-3..0.05f64,
    ) {
        let m = sys.minimal();
        let z = State::new([q.0, q.1], [v.0, v.1]);
        // one step of Δt, not the sub-steps a failing step would take
        let vi = Variational::new(m, dt).unwrap().max_subdivision(0);
        match vi.step(&z) {
            Ok(z1) => {
                prop_assert!(z1.is_finite());
                prop_assert!((z1.q - (z.q + z.v * dt)).amax() == 0.0);
                let p0 = vigp::del::previous_momentum::<_, 2, 0>(&m, dt, 0.0, &z.q, &z.v);
                let r = vigp::del::residual::<_, 2, 0>(&m, dt, 0.0, &p0, &z1.q, &z1.v, &SVector::zeros());
                let (_, j) = vigp::del::del_terms_jacobian::<_, 2, 0>(&m, dt, 0.0, &z1.q, &z.v);
                let scale = p0.amax() + j[(0, 0)].abs().max(j[(1, 1)].abs());
                prop_assert!(r.amax() <= 1e-10 * scale, "residual {:e} scale {:e}", r.amax(), scale);
            }
            Err(e) => prop_assert!(typed_failure(&e), "{e:?}"),
        }
    }

    /// Scaling every mass and inertia by s ∈ [1e-6, 1e6] leaves one step
    /// unchanged (the Lagrangian scales by s): same outcome, and velocities
    /// equal to 1e-9 relative (the Newton tolerance is 1e-12 of the
    /// momentum scale, which scales with s).
    #[test]
    fn one_step_does_not_depend_on_the_mass_unit(
        q in (angle(), angle()),
        v in (-8.0..8.0f64, -8.0..8.0f64),
        s in log_uniform(-6.0, 6.0),
    ) {
        let unit = DoublePendulum::default();
        let mut scaled = unit;
        for l in [&mut scaled.links.upper, &mut scaled.links.lower] {
            l.mass *= s;
            l.inertia *= s;
        }
        let z = State::new([q.0, q.1], [v.0, v.1]);
        let a = Variational::new(unit.minimal(), 0.01).unwrap().step(&z);
        let b = Variational::new(scaled.minimal(), 0.01).unwrap().step(&z);
        match (a, b) {
            (Ok(a), Ok(b)) => {
                let d = (a.v - b.v).amax();
                prop_assert!(d <= 1e-9 * (1.0 + a.v.amax()), "differ by {d:e}");
            }
            (Err(_), Err(_)) => {}
            (a, b) => prop_assert!(false, "outcomes differ: {a:?} vs {b:?}"),
        }
    }

    /// The conservative midpoint VI is symmetric: step, reverse the motion
    /// ((q, v) ↦ (q + Δt·v, −v)), step, reverse again returns the start to
    /// 1e-9 (Newton tolerance 1e-12 of the momentum scale, amplified by
    /// two solves).
    #[test]
    fn midpoint_vi_is_time_reversible(
        q in (angle(), angle()),
        v in (-6.0..6.0f64, -6.0..6.0f64),
        dt in 1e-3..0.03f64,
    ) {
        let vi = Variational::midpoint(DoublePendulum::default().minimal(), dt).unwrap();
        let reverse = |z: &State<2>| State { q: z.q + z.v * dt, v: -z.v };
        let z = State::new([q.0, q.1], [v.0, v.1]);
        if let Ok(z1) = vi.step(&z) {
            if let Ok(back) = vi.step(&reverse(&z1)) {
                let z2 = reverse(&back);
                prop_assert!((z2.q - z.q).amax() <= 1e-9, "q {:?} vs {:?}", z2.q, z.q);
                prop_assert!((z2.v - z.v).amax() <= 1e-9 * (1.0 + z.v.amax()), "v {:?} vs {:?}", z2.v, z.v);
            }
        }
    }

    /// Fourbar from a random rhombus and velocity: the consistent state and
    /// the step keep |g| ≤ 1e-10 (stall tolerance) or fail typed.
    #[test]
    fn fourbar_steps_stay_on_the_manifold(
        t1 in angle(),
        t3 in angle(),
        v in prop::array::uniform4(-10.0..10.0f64),
        dt in 1e-3..0.03f64,
    ) {
        let fb = Fourbar::default().minimal();
        let q = SVector::from([t1, t3 - t1, t3, t1 - t3]);
        match consistent_state(&fb, &q, &SVector::from(v), dt) {
            Ok(z) => match Variational::new(fb, dt).unwrap().step(&z) {
                Ok(z1) => {
                    prop_assert!(z1.is_finite());
                    prop_assert!(fb.constraint_violation(&z1) <= 1e-10 * (1.0 + z1.q.amax()));
                }
                Err(e) => prop_assert!(typed_failure(&e), "{e:?}"),
            },
            Err(e) => prop_assert!(typed_failure(&e), "{e:?}"),
        }
    }

    /// The configuration projection from anywhere within ±50 rad: on the
    /// manifold to the tolerance 1e-12, or a typed failure.
    #[test]
    fn configuration_projection_lands_on_the_manifold(
        q in prop::array::uniform4(-50.0..50.0f64),
    ) {
        let fb = Fourbar::default().minimal();
        match project_configuration(&fb, &SVector::from(q), &StepOptions::default()) {
            Ok((p, _)) => prop_assert!(fb.constraints(&p).amax() <= 1e-12),
            Err(e) => prop_assert!(typed_failure(&e), "{e:?}"),
        }
    }

    /// Explicit integrators on random states and parameters: a finite
    /// state or a typed error.
    #[test]
    fn classical_integrators_never_return_nan(
        sys in double_pendulum(),
        q in (angle(), angle()),
        v in (-30.0..30.0f64, -30.0..30.0f64),
        dt in 1e-4..0.1f64,
    ) {
        let m = sys.minimal();
        let z = State::new([q.0, q.1], [v.0, v.1]);
        for r in [
            ExplicitEuler::new(m, dt).step(&z),
            SymplecticEuler::new(m, dt).step(&z),
            Rk4::new(m, dt).step(&z),
        ] {
            match r {
                Ok(z1) => prop_assert!(z1.is_finite()),
                Err(e) => prop_assert!(typed_failure(&e), "{e:?}"),
            }
        }
    }
}

/// Random GP data: n points in d dimensions at scale 10^e (|e| ≤ 8), with
/// duplicated rows and targets at their own scale.
fn gp_data() -> impl Strategy<Value = (usize, Vec<f64>, Vec<f64>)> {
    (1usize..4, 1usize..20, -8i32..8, -8i32..8).prop_flat_map(|(d, n, ex, ey)| {
        let sx = 10f64.powi(ex);
        let sy = 10f64.powi(ey);
        (
            Just(d),
            prop::collection::vec(-1.0..1.0f64, n * d),
            prop::collection::vec(-1.0..1.0f64, n),
            0usize..n,
        )
            .prop_map(move |(d, mut x, mut y, dups)| {
                // duplicate the first `dups` rows exactly
                for i in 0..dups {
                    let row: Vec<f64> = x[i * d..(i + 1) * d].to_vec();
                    x.extend(row);
                    y.push(y[i]);
                }
                (
                    d,
                    x.iter().map(|v| v * sx).collect(),
                    y.iter().map(|v| v * sy).collect(),
                )
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// GP training on random data either fails with a typed error or gives
    /// a model whose predictions are finite everywhere (at the data, far
    /// away, at ±1e300) with non-negative variances; and its saved form
    /// loads back to the same predictions.
    #[test]
    fn gp_training_and_prediction_never_give_nan((d, x, y) in gp_data()) {
        let opts = TrainOptions { restarts: 1, max_iters: 60, ..Default::default() };
        match Gp::train(&x, d, &y, 1, &opts) {
            Ok((gp, _)) => {
                let mut probe = x[..d].to_vec();
                probe.extend(std::iter::repeat_n(1e300, d));
                probe.extend(std::iter::repeat_n(-1e6, d));
                let p = gp.predict(&probe).unwrap();
                prop_assert!(p.mean.iter().all(|v| v.is_finite()), "{p:?}");
                prop_assert!(p.variance.iter().all(|v| v.is_finite() && *v >= 0.0), "{p:?}");
                let back = Gp::from_saved(&gp.to_saved(), None).unwrap();
                prop_assert_eq!(back.predict(&probe).unwrap(), p);
            }
            Err(e) => prop_assert!(
                matches!(e, GpError::NotPositiveDefinite { .. } | GpError::OptimiserFailed { .. }),
                "{e:?}"
            ),
        }
    }

    /// A saved model with one number replaced by an extreme value loads
    /// with a typed error, or loads and predicts finite values.
    #[test]
    fn corrupt_saved_models_never_panic_or_give_nan(
        field in 0usize..8,
        value in prop::sample::select(vec![
            0.0, -1.0, 1e-320, 1e-300, 1e300, f64::MAX, f64::MIN_POSITIVE, 3.0, -1e10,
        ]),
        dim in prop::sample::select(vec![0usize, 1, 2, 3, 1000, usize::MAX]),
    ) {
        let x: Vec<f64> = (0..12).map(|i| (i as f64 * 0.37).sin()).collect();
        let y: Vec<f64> = x.iter().map(|v| v * v).collect();
        let (gp, _) = Gp::train(&x, 1, &y, 1, &TrainOptions { restarts: 0, ..Default::default() }).unwrap();
        let mut s: SavedGp = gp.to_saved();
        match field {
            0 => s.inputs[3] = value,
            1 => s.targets[5] = value,
            2 => s.input_normaliser.scale[0] = value,
            3 => s.outputs[0].hyperparameters.length_scales[0] = value,
            4 => s.outputs[0].hyperparameters.signal_variance = value,
            5 => s.outputs[0].output_scale = value,
            6 => s.outputs[0].jitter = value,
            _ => s.output_dim = dim,
        }
        if field == 7 && dim == 1 {
            s.input_dim = dim;
        }
        if let Ok(g) = Gp::from_saved(&s, None) {
            let probe = vec![0.3; g.input_dim()];
            if let Ok(p) = g.predict(&probe) {
                prop_assert!(p.mean.iter().chain(&p.variance).all(|v| v.is_finite()), "{p:?}");
            }
        }
    }
}
