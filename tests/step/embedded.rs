//! The `no_std` fixed-size step (`vigp::embedded::Stepper`, the engine of
//! every variational integrator) against the dual-number reference step
//! (`vigp::reference::step`: the same first-order DEL equations derived by
//! automatic differentiation and solved by a chord/Newton hybrid), and the
//! jet-based mechanical terms (`vigp::embedded::model`) against independent
//! computations (the std runtime's dual-number mass matrix, central
//! differences).

use crate::common;
use common::{Rng, same_bits};
use nalgebra::SVector;
use vigp::embedded::{Dynamics, Model, StepError, StepOptions, Stepper, model};
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};
use vigp::{Mechanism, State};

use crate::slider_crank;
use slider_crank::SliderCrank;

/// A random state; for loops, made consistent by the std projection.
fn random_state<M, const N: usize, const C: usize>(m: &M, rng: &mut Rng, dt: f64) -> State<N>
where
    M: Mechanism<N, C>,
{
    let q = SVector::from_fn(|_, _| rng.uniform(-1.0, 1.0));
    let v = SVector::from_fn(|_, _| rng.uniform(-2.0, 2.0));
    if C == 0 {
        return State { q, v };
    }
    vigp::projection::consistent_state(m, &q, &v, dt).expect("projection")
}

/// One step from 20 random states by both implementations. Both solve the
/// DEL equations to a scaled residual of 1e-12; the Newton matrix has a
/// condition number of at most ~1e2 for these systems, so the two solutions
/// must agree to 1e-10 (absolute, in rad/s or m/s).
fn steps_agree<M, const N: usize, const C: usize>(sys: M, minimal: impl Mechanism<N, C> + Copy)
where
    M: Model<N, C> + Dynamics<N, C> + Copy,
{
    let dt = 0.01;
    let fast = Stepper::new(sys, dt).unwrap();
    let mut rng = Rng(7);
    let mut worst = 0.0f64;
    for _ in 0..20 {
        let z = random_state(&minimal, &mut rng, dt);
        let a = fast.step(&z).unwrap();
        let (b, _) = vigp::reference::step(&minimal, dt, 0.0, &StepOptions::default(), &z).unwrap();
        assert_eq!(a.q, b.q, "x₁ = x₀ + Δt·v₀ in both");
        worst = worst.max((a.v - b.v).amax());
        // energies of the same state by the two implementations: 1e-12
        let (e1, e2) = (model::energy(&sys, &z.q, &z.v), minimal.energy(&z));
        assert!((e1 - e2).abs() <= 1e-12 * (1.0 + e2.abs()), "{e1} vs {e2}");
    }
    println!("max |v_embedded − v_std| = {worst:.2e}");
    assert!(worst < 1e-10, "{worst}");
}

#[test]
fn one_step_matches_the_dual_number_reference_on_every_system() {
    steps_agree(Pendulum::default(), Pendulum::default().minimal());
    steps_agree(Cartpole::default(), Cartpole::default().minimal());
    let mut dp = DoublePendulum::default();
    steps_agree(dp, dp.minimal());
    dp.joints.elbow.damping = 0.3;
    steps_agree(dp, dp.minimal());
    let mut fb = Fourbar::default();
    steps_agree(fb, fb.minimal());
    fb.joints.middle1.damping = 0.2;
    steps_agree(fb, fb.minimal());
    let sc = SliderCrank::default();
    steps_agree(sc, sc.minimal());
}

/// M(q) from jets vs the std runtime's dual-number mass matrix, and ∂M/∂q vs
/// central differences of M. Step 1e-6: truncation O(h²)·|M'''| ≈ 1e-12,
/// rounding O(ε|M|/h) ≈ 1e-10, so 1e-8 cannot be failed by rounding.
#[test]
fn mass_matrix_and_its_derivatives_are_exact() {
    fn check<M, const N: usize, const C: usize>(sys: M, minimal: impl Mechanism<N, C>)
    where
        M: Model<N, C>,
    {
        let mut rng = Rng(3);
        for _ in 0..10 {
            let q: SVector<f64, N> = SVector::from_fn(|_, _| rng.uniform(-1.5, 1.5));
            let t = model::terms(&sys, &q);
            let reference = vigp::dynamics::mass_matrix(&minimal, &q, &SVector::zeros());
            assert!((t.mass - reference).amax() < 1e-12 * (1.0 + reference.amax()));
            assert!(
                (model::mass_matrix(&sys, &q) - reference).amax()
                    < 1e-12 * (1.0 + reference.amax())
            );
            let h = 1e-6;
            for i in 0..N {
                let mut e = SVector::<f64, N>::zeros();
                e[i] = h;
                let fd = (model::mass_matrix(&sys, &(q + e)) - model::mass_matrix(&sys, &(q - e)))
                    / (2.0 * h);
                assert!(
                    (t.dmass[i] - fd).amax() < 1e-8 * (1.0 + fd.amax()),
                    "∂M/∂q{i}"
                );
            }
            // ∇V against central differences of V = E(q, 0)
            for i in 0..N {
                let mut e = SVector::<f64, N>::zeros();
                e[i] = h;
                let z = SVector::zeros();
                let fd = (model::energy(&sys, &(q + e), &z) - model::energy(&sys, &(q - e), &z))
                    / (2.0 * h);
                assert!(
                    (t.dpotential[i] - fd).abs() < 1e-7 * (1.0 + fd.abs()),
                    "∇V{i}"
                );
            }
        }
    }
    check(
        DoublePendulum::default(),
        DoublePendulum::default().minimal(),
    );
    check(Cartpole::default(), Cartpole::default().minimal());
    check(Fourbar::default(), Fourbar::default().minimal());
    check(SliderCrank::default(), SliderCrank::default().minimal());
}

/// Rollouts: the carried momentum gives the same steps as stepping from
/// each state; loops stay on the constraint manifold; the energy of a
/// conservative double pendulum stays bounded (first-order VI: |ΔE| = O(Δt)).
#[test]
fn rollouts_carry_momentum_and_keep_structure() {
    let dp = DoublePendulum::default();
    let fast = Stepper::new(dp, 0.01).unwrap();
    let z0 = State::new([1.2, -0.4], [0.0, 0.0]);
    let mut traj = [z0; 2001];
    fast.rollout_into(&z0, &mut traj).unwrap();
    // Each rollout step (carried momentum, extrapolated Newton start) equals
    // a fresh step from the same state (recomputed momentum, start at v_k)
    // to the solver tolerance: each solve leaves a residual ≤ 1e-12·(|p|∞ + m̄),
    // i.e. an error ≤ that times |A⁻¹| ≈ |M⁻¹| (A = Δt(Q − D) − M, a 1%
    // perturbation of −M here), so two solves differ by at most twice that;
    // a factor 2 covers A vs M.
    let mut worst = 0.0f64;
    for k in 0..2000 {
        let z = fast.step(&traj[k]).unwrap();
        assert_eq!(z.q, traj[k + 1].q);
        let p = fast.momentum(&traj[k]).amax();
        let m = model::mass_matrix(&dp, &z.q);
        let m_bar = m.diagonal().amax();
        let minv = m.try_inverse().unwrap().norm();
        let bound = 2.0 * 2.0 * 1e-12 * (p + m_bar) * minv;
        let diff = (z.v - traj[k + 1].v).amax();
        assert!(diff <= bound, "step {k}: {diff:.3e} > {bound:.3e}");
        worst = worst.max(diff / bound);
    }
    println!("rollout vs fresh steps: max difference / bound = {worst:.3}");
    let e0 = model::energy(&dp, &z0.q, &z0.v);
    let drift = traj
        .iter()
        .map(|z| (model::energy(&dp, &z.q, &z.v) - e0).abs())
        .fold(0.0, f64::max);
    println!("double pendulum, 2000 steps of 0.01 s: max |ΔE| = {drift:.3}");
    // The std integrator's own bound for this state and dt (tests/step/nominal.rs
    // measures ~2 J at higher energy); an unbounded drift would exceed it.
    assert!(drift < 1.0, "{drift}");

    let fb = Fourbar::default();
    let m = fb.minimal();
    let z0 = common::at_rest(&m, [0.5, -0.9, -0.4, 0.9], 0.01);
    let fast = Stepper::new(fb, 0.01).unwrap();
    let mut traj = [z0; 1001];
    fast.rollout_into(&z0, &mut traj).unwrap();
    let g = traj
        .iter()
        .map(|z| m.constraint_violation(z))
        .fold(0.0, f64::max);
    println!("fourbar, 1000 steps: max |g| = {g:.2e}");
    assert!(g < 1e-10, "{g}");
}

/// The step does not depend on the mass unit: a double pendulum with all
/// masses and inertias scaled by 1e-9 or 1e9 moves like the 1 kg one (the
/// momentum residual is scaled by |p₀| + m̄). 200 steps from the same state
/// agree to 1e-9 rad (solver tolerance 1e-12 per step, amplified by the
/// motion's sensitivity over 2 s).
#[test]
fn motion_does_not_depend_on_the_mass_unit() {
    let z0 = State::new([1.2, -0.4], [0.0, 0.0]);
    let reference = {
        let s = Stepper::new(DoublePendulum::default(), 0.01).unwrap();
        let mut out = [z0; 201];
        s.rollout_into(&z0, &mut out).unwrap();
        out[200]
    };
    for unit in [1e-9, 1e9] {
        let mut dp = DoublePendulum::default();
        for link in [&mut dp.links.upper, &mut dp.links.lower] {
            link.mass *= unit;
            link.inertia *= unit;
        }
        let s = Stepper::new(dp, 0.01).unwrap();
        let mut out = [z0; 201];
        s.rollout_into(&z0, &mut out).unwrap();
        let diff = (out[200].q - reference.q).amax();
        println!("mass unit {unit:e}: |q − q_1kg| = {diff:.2e}");
        assert!(diff < 1e-9, "{unit}: {diff}");
    }
}

#[test]
fn bad_input_is_a_typed_error() {
    let dp = DoublePendulum::default();
    assert_eq!(
        Stepper::new(dp, 0.0).unwrap_err(),
        StepError::InvalidTimeStep { dt: 0.0 }
    );
    assert!(matches!(
        Stepper::new(dp, f64::NAN),
        Err(StepError::InvalidTimeStep { .. })
    ));
    let opts = StepOptions {
        tolerance: -1.0,
        ..StepOptions::default()
    };
    assert!(matches!(
        Stepper::with_options(dp, 0.01, opts),
        Err(StepError::InvalidOptions(_))
    ));
    // parameters that describe no mechanism are refused up front
    let mut neg_mass = dp;
    neg_mass.links.lower.mass = -1.0;
    let mut nan_inertia = dp;
    nan_inertia.links.upper.inertia = f64::NAN;
    let mut neg_damping = dp;
    neg_damping.joints.elbow.damping = -0.1;
    let mut inf_gravity = dp;
    inf_gravity.gravity[1] = f64::NEG_INFINITY;
    for bad in [neg_mass, nan_inertia, neg_damping, inf_gravity] {
        assert!(matches!(
            Stepper::new(bad, 0.01),
            Err(StepError::InvalidModel(_))
        ));
    }
    // a massless link is valid (the other link carries the mass)
    let mut massless = dp;
    massless.links.lower.mass = 0.0;
    massless.links.lower.inertia = 0.0;
    assert!(Stepper::new(massless, 0.01).is_ok());
    let fast = Stepper::new(dp, 0.01).unwrap();
    let bad = State::new([f64::NAN, 0.0], [0.0, 0.0]);
    assert_eq!(
        fast.step(&bad),
        Err(StepError::NonFiniteState { step: None })
    );
    let mut out = [bad; 3];
    let err = fast.rollout_into(&bad, &mut out).unwrap_err();
    assert_eq!(err.step, 0);
    // one iteration cannot reach 1e-12 from a fast state with a big step
    let opts = StepOptions {
        max_iterations: 1,
        ..StepOptions::default()
    };
    let fast = Stepper::with_options(dp, 0.2, opts).unwrap();
    let z = State::new([2.0, 1.0], [5.0, -6.0]);
    assert!(matches!(
        fast.step(&z),
        Err(StepError::NotConverged { iterations: 1, .. })
    ));
}

/// For trees the stepper may accept a full Newton step on the quadratic
/// remainder (Δt/2)[Δvᵀ ∂M/∂q_i Δv]_i of the (exactly quadratic) residual
/// instead of evaluating the residual again. Every accepted step must still meet the
/// tolerance: its DEL residual is evaluated here by the std runtime's
/// dual-number implementation (`vigp::del::residual`, a second
/// implementation) and scaled as the solver scales it (|p₀|∞ + m̄). The
/// tolerance is 1e-12; evaluating the residual costs O(ε)·scale ≈ 1e-15 of
/// rounding, which the solver's half-tolerance margin covers, so the
/// comparison is against 1e-12 itself, and against the reported value
/// (remainder or evaluated residual) plus 1e-14.
#[test]
fn accepted_steps_meet_the_tolerance_by_an_independent_residual() {
    fn check<M, const N: usize>(sys: M, minimal: impl Mechanism<N, 0> + Copy, name: &str)
    where
        M: Model<N, 0> + Dynamics<N, 0> + Copy,
    {
        let dt = 0.01;
        let fast = Stepper::new(sys, dt).unwrap();
        let mut rng = Rng(11);
        let mut worst = 0.0f64;
        let mut check_step = |z: &State<N>, p0: &SVector<f64, N>, z1: &State<N>, reported: f64| {
            let d = vigp::del::residual(&minimal, dt, 0.0, p0, &z1.q, &z1.v, &SVector::zeros());
            let m_bar = model::mass_matrix(&sys, &z1.q).diagonal().amax();
            let scaled = d.amax() / (p0.amax() + m_bar);
            assert!(scaled <= 1e-12, "{name}: residual {scaled:.3e} from {z:?}");
            assert!(
                scaled <= reported + 1e-14,
                "{name}: {scaled:.3e} > reported {reported:.3e}"
            );
            worst = worst.max(scaled);
        };
        for _ in 0..200 {
            let z = State {
                q: SVector::from_fn(|_, _| rng.uniform(-3.0, 3.0)),
                v: SVector::from_fn(|_, _| rng.uniform(-4.0, 4.0)),
            };
            let p0 = fast.momentum(&z);
            let (z1, _, report) = fast.step_with_momentum(&z, &p0).unwrap();
            check_step(&z, &p0, &z1, report.residual);
        }
        // rollouts start Newton from the extrapolation 2v_k − v_{k−1}
        let z0 = State {
            q: SVector::from_fn(|_, _| rng.uniform(-2.0, 2.0)),
            v: SVector::from_fn(|_, _| rng.uniform(-2.0, 2.0)),
        };
        let mut traj = [z0; 501];
        fast.rollout_into(&z0, &mut traj).unwrap();
        for k in 0..500 {
            let p0 = fast.momentum(&traj[k]);
            check_step(&traj[k], &p0, &traj[k + 1], 1e-12);
        }
        println!("{name}: max scaled residual {worst:.2e}");
    }
    let p = Pendulum::default();
    check(p, p.minimal(), "pendulum");
    let cp = Cartpole::default();
    check(cp, cp.minimal(), "cartpole");
    let mut dp = DoublePendulum::default();
    check(dp, dp.minimal(), "double pendulum");
    dp.joints.elbow.damping = 0.3;
    dp.joints.shoulder.damping = 0.1;
    check(dp, dp.minimal(), "damped double pendulum");
}

/// `Stepper::step_in` (a kept workspace, reset in O(N²)) gives the state of
/// `step` (a fresh, zeroed one) bit for bit — also when the workspace was
/// last used by a stepper with other parameters whose converged step left
/// its cached constraint Jacobian exactly at the next step's x₁, with
/// damping and without, with either rule, and in minimal coordinates
/// (where ∂M/∂q is read and cleared).
#[test]
fn steps_in_a_kept_workspace_equal_fresh_steps_bit_for_bit() {
    use vigp::Coordinates;
    use vigp::embedded::StepWorkspace;
    let dt = 0.01;
    let fb = Fourbar::default();
    let mut long = fb;
    long.links.link2.length = 1.3;
    long.links.link4.length = 1.3;
    let mut damped = fb;
    damped.joints.middle1.damping = 0.4;
    let mut rng = Rng(5);
    // maximal view: three steppers of one type, one workspace
    let steppers = [
        Stepper::new(fb.maximal(), dt).unwrap(),
        Stepper::new(long.maximal(), dt).unwrap(),
        Stepper::new(damped.maximal(), dt).unwrap(),
        Stepper::midpoint(fb.maximal(), dt).unwrap(),
    ];
    let mut ws = StepWorkspace::new();
    let mut checked = 0;
    for _ in 0..10 {
        let z = random_state(&fb.minimal(), &mut rng, dt);
        let zm = fb.minimal().to_maximal(&z, dt);
        for a in &steppers {
            // a's converged step leaves G cached at z1.q + dt·z1.v, the
            // x₁ of every stepper's next step from z1
            let z1 = a.step_in(&zm, &mut ws).unwrap();
            assert!(same_bits(&z1, &a.step(&zm).unwrap()));
            // the momentum from the public `momentum` (as a rollout starts)
            // and the solve in a fresh workspace: the same bits
            let (z1m, _, _) = a.step_with_momentum(&zm, &a.momentum(&zm)).unwrap();
            assert!(same_bits(&z1, &z1m));
            for b in &steppers {
                let fresh = b.step(&z1).unwrap();
                let kept = b.step_in(&z1, &mut ws).unwrap();
                assert!(same_bits(&kept, &fresh), "{kept:?} vs {fresh:?}");
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 160);
    // minimal coordinates (a moving mass matrix: ∂M/∂q is cleared too)
    let mut ws = StepWorkspace::new();
    let dp = DoublePendulum::default();
    let mut dpd = dp;
    dpd.joints.elbow.damping = 0.3;
    let s = [
        Stepper::new(dp, dt).unwrap(),
        Stepper::new(dpd, dt).unwrap(),
    ];
    for _ in 0..10 {
        let z = random_state(&dp.minimal(), &mut rng, dt);
        for a in &s {
            assert!(same_bits(
                &a.step_in(&z, &mut ws).unwrap(),
                &a.step(&z).unwrap()
            ));
        }
    }
    // errors are those of `step`
    let bad = State::new([f64::NAN, 0.0], [0.0, 0.0]);
    assert!(matches!(
        s[0].step_in(&bad, &mut ws),
        Err(StepError::NonFiniteState { step: None })
    ));
    // the std `Variational::step` keeps one workspace per size and thread:
    // interleaved models of the same size (and other sizes in between)
    // share it and still equal the fixed-size step in a fresh workspace
    use vigp::Variational;
    let vis = [
        Variational::new(fb.maximal(), dt).unwrap(),
        Variational::new(long.maximal(), dt).unwrap(),
        Variational::new(damped.maximal(), dt).unwrap(),
        Variational::midpoint(fb.maximal(), dt).unwrap(),
    ];
    let vdp = Variational::new(dpd.minimal(), dt).unwrap();
    let mut shared = 0;
    for _ in 0..10 {
        let z = random_state(&fb.minimal(), &mut rng, dt);
        let zm = fb.minimal().to_maximal(&z, dt);
        for (a, sa) in vis.iter().zip(&steppers) {
            let z1 = a.step(&zm).unwrap();
            assert!(same_bits(&z1, &sa.step(&zm).unwrap()));
            // the diagnostics path keeps the same workspace
            assert!(same_bits(&a.step_with_report(&zm).unwrap().0, &z1));
            let zd = random_state(&dp.minimal(), &mut rng, dt);
            assert!(same_bits(&vdp.step(&zd).unwrap(), &s[1].step(&zd).unwrap()));
            for (b, sb) in vis.iter().zip(&steppers) {
                assert!(same_bits(&b.step(&z1).unwrap(), &sb.step(&z1).unwrap()));
                shared += 1;
            }
        }
    }
    assert_eq!(shared, 160);
    assert!(matches!(
        Variational::new(dp.minimal(), dt).unwrap().step(&bad),
        Err(vigp::StepError::NonFiniteState { .. })
    ));
}
