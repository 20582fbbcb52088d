//! The generated closed-form terms (`vigp::embedded::Dynamics`, derived
//! symbolically by the macro) against the independent dual-number
//! reference: the same mechanism's Lagrangian, Rayleigh function and
//! constraints evaluated on num-dual numbers (`vigp::Mechanism`), whose
//! exact derivatives come from automatic differentiation, not from the
//! symbolic derivation. Both views, every system, random states.
//!
//! Tolerance: both sides are exact up to rounding (a few hundred
//! floating-point operations), so they must agree to 1e-12 relative to the
//! size of the compared quantity.

use crate::common;
use common::Rng;
use nalgebra::{SMatrix, SVector};
use num_dual::{Dual2Vec, DualVec};
use vigp::Mechanism;
use vigp::embedded::{Dynamics, Terms};
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

#[path = "../common/slider_crank.rs"]
mod slider_crank;
use slider_crank::SliderCrank;

vigp::mechanism! {
    /// Every kind of kinematic element: a prismatic joint on a rotating
    /// link (its axis turns with the arm), an off-axis anchor, a damped
    /// prismatic loop joint on a tilted world rail, non-default centres of
    /// mass.
    pub Exotic {
        gravity: [0.3, -9.81],
        links {
            arm: { mass: 1.3, length: 0.9, com: [0.4, 0.05] },
            slider: { mass: 0.7, length: 0.5 },
            tip: { mass: 0.4, length: 0.6, inertia: 0.02, com: [0.25, -0.03] },
        }
        joints {
            shoulder: revolute(world @ [0.1, -0.2], arm.start) { damping: 0.1 },
            slide: prismatic(arm.end, slider.start) { axis: [0.3, 1.0], damping: 0.2 },
            wrist: revolute(slider @ [0.2, 0.1], tip.center) { damping: 0.05 },
            guide: prismatic(world @ [0.5, -1.0], tip.end) { axis: [1.0, -0.4], damping: 0.3 },
        }
    }
}

vigp::mechanism! {
    /// Undamped, no loops: no damping or constraint code.
    pub Plain {
        links {
            a: { mass: 2.0, length: 0.7 },
            b: { mass: 0.5, length: 1.1, com: [0.3, 0.2] },
            c: { mass: 1.5, length: 0.4 },
        }
        joints {
            j1: revolute(world, a.start),
            j2: prismatic(a.end, b.start) { axis: [1.0, 0.0] },
            j3: revolute(b.end, c.start),
        }
    }
}

fn assert_close<const R: usize, const K: usize>(
    what: &str,
    a: &SMatrix<f64, R, K>,
    b: &SMatrix<f64, R, K>,
) -> f64 {
    let scale = 1.0 + b.amax();
    let err = (a - b).amax() / scale;
    assert!(err <= 1e-12, "{what}: relative error {err:.2e}\n{a}\n{b}");
    err
}

/// Every `Dynamics` function of `m` against the dual-number reference at
/// 20 random states.
fn check<M, const N: usize, const C: usize>(name: &str, m: M)
where
    M: Mechanism<N, C> + Dynamics<N, C>,
{
    let k = Dynamics::constants(&m).expect("default parameters are valid");
    let mut rng = Rng(11);
    let mut worst = 0.0f64;
    for _ in 0..20 {
        let q = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let v = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let mut t = Terms::zeros();
        m.terms(&k, &q, &mut t);
        // M(q)
        let m_ref = vigp::dynamics::mass_matrix::<M, N, C>(&m, &q, &v);
        worst = worst.max(assert_close("mass", &Dynamics::mass(&m, &k, &q), &m_ref));
        worst = worst.max(assert_close("terms.mass", &t.mass, &m_ref));
        // V(q) and ∇V(q)
        let v_ref = m.potential_energy(&q);
        let v_fast = Dynamics::potential(&m, &k, &q);
        assert!(
            (v_fast - v_ref).abs() <= 1e-12 * (1.0 + v_ref.abs()),
            "{name} V"
        );
        let grad_ref = num_dual::gradient(|x| m.potential_energy(&x), &q).1;
        worst = worst.max(assert_close("∇V", &t.dpotential, &grad_ref));
        // D(q): F = −∂R/∂v = −D v for every v, so D = −∂F/∂v
        if <M as Dynamics<N, C>>::DISSIPATIVE {
            let d_ref = -num_dual::jacobian(
                |vv: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
                    m.generalized_forces(&q.map(DualVec::from_re), &vv)
                },
                &v,
            )
            .1;
            worst = worst.max(assert_close("D", &t.damping, &d_ref));
            // the generated D·v (straight-line over D's structural non-zeros)
            worst = worst.max(assert_close("D v", &M::damping_times(&t, &v), &(d_ref * v)));
        }
        // the generated M·v (straight-line over M's structural non-zeros)
        worst = worst.max(assert_close("M v", &M::mass_times(&t, &v), &(m_ref * v)));
        // ∂M/∂q_l, column by column: ∂(M v)/∂q = Σ_l ∂M/∂q_l v e_lᵀ, by
        // differentiating the reference momentum M(q)v in q
        let dmv_ref = num_dual::jacobian(
            |x: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
                vigp::del::momentum::<M, _, N, C>(&m, &x, &v.map(DualVec::from_re))
            },
            &q,
        )
        .1;
        let mut dmv = SMatrix::<f64, N, N>::zeros();
        if !<M as Dynamics<N, C>>::CONSTANT_MASS {
            for l in 0..N {
                dmv.set_column(l, &(t.dmass[l] * v));
            }
        }
        worst = worst.max(assert_close("∂M/∂q", &dmv, &dmv_ref));
        // the generated contractions (straight-line over the structural
        // non-zeros): Q = [∂M/∂q_l v]_lᵀ, ½vᵀ∂M/∂q_l v, max_l |vᵀ∂M/∂q_l v|
        let (qm, kin) = M::kinetic(&t, &v);
        worst = worst.max(assert_close("Q", &qm, &dmv_ref.transpose()));
        let kin_ref = (dmv_ref.transpose() * v) * 0.5;
        worst = worst.max(assert_close("½vᵀ∂M v", &kin, &kin_ref));
        let quad_ref = kin_ref.amax() * 2.0;
        let quad = M::quadratic_max(&t, &v);
        assert!(
            (quad - quad_ref).abs() <= 1e-12 * (1.0 + quad_ref),
            "{name}: {quad} vs {quad_ref}"
        );
        // ∂/∂q [½ vᵀ∂M/∂q v − ∇V − D v] = ∂/∂q (D_xL + F) at fixed v
        let fj_ref = num_dual::jacobian(
            |x: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
                vigp::del::force_terms::<M, _, N, C>(&m, &x, &v.map(DualVec::from_re))
            },
            &q,
        )
        .1;
        worst = worst.max(assert_close(
            "force_jacobian",
            &m.force_jacobian(&k, &q, &v),
            &fj_ref,
        ));
        // continuous accelerations (index-1 KKT system): the same linear
        // system assembled from both sides, solved by the same solver, so
        // they differ by rounding amplified by its condition number
        // (≲ 1e3 at these random configurations): 1e-10 relative
        let a = vigp::dynamics::acceleration::<M, N, C>(&m, &q, &v).unwrap();
        let a_ref = vigp::dynamics::reference_acceleration::<M, N, C>(&m, &q, &v).unwrap();
        let scale = 1.0 + a_ref.0.amax();
        assert!(
            (a.0 - a_ref.0).amax() <= 1e-10 * scale,
            "{name} q̈: {} vs {}",
            a.0,
            a_ref.0
        );
        // energy
        let e_ref = m.kinetic_energy(&q, &v) + v_ref;
        let e = Dynamics::energy_at(&m, &k, &q, &v);
        assert!((e - e_ref).abs() <= 1e-12 * (1.0 + e_ref.abs()), "{name} E");
        if C > 0 {
            let g_ref = Mechanism::constraints(&m, &q);
            worst = worst.max(assert_close(
                "g",
                &Dynamics::constraint_values(&m, &k, &q),
                &g_ref,
            ));
            let (g, jac) = Dynamics::constraints_and_jacobian(&m, &k, &q);
            worst = worst.max(assert_close("g (with G)", &g, &g_ref));
            let jac_ref = Mechanism::constraint_jacobian(&m, &q);
            worst = worst.max(assert_close("G", &jac, &jac_ref));
            // the declared structural zeros of G are zeros of the reference
            // Jacobian (exactly: a structural zero is no derivative at all)
            for i in 0..C {
                for k in 0..N {
                    if !M::CONSTRAINT_PATTERN[i][k] {
                        assert_eq!(jac_ref[(i, k)], 0.0, "{name}: G[{i}][{k}] declared zero");
                    }
                }
            }
            let mu = SVector::<f64, C>::from_fn(|_, _| rng.uniform(-1.0, 1.0));
            let h_ref = num_dual::hessian(
                |x: SVector<Dual2Vec<f64, nalgebra::Const<N>>, N>| {
                    let g = Mechanism::constraints(&m, &x);
                    let mut s = Dual2Vec::from_re(0.0);
                    for i in 0..C {
                        s += g[i] * mu[i];
                    }
                    s
                },
                &q,
            )
            .2;
            worst = worst.max(assert_close(
                "Σμ∇²g",
                &m.constraint_hessian(&k, &q, &mu),
                &h_ref,
            ));
        }
    }
    println!("{name}: worst relative difference {worst:.1e}");
}

#[test]
fn generated_terms_match_dual_numbers_in_both_views() {
    check("pendulum minimal", Pendulum::default().minimal());
    check("pendulum maximal", Pendulum::default().maximal());
    check("cartpole minimal", Cartpole::default().minimal());
    check("cartpole maximal", Cartpole::default().maximal());
    check(
        "double pendulum minimal",
        DoublePendulum::default().minimal(),
    );
    check(
        "double pendulum maximal",
        DoublePendulum::default().maximal(),
    );
    check("fourbar minimal", Fourbar::default().minimal());
    check("fourbar maximal", Fourbar::default().maximal());
    check("slider-crank minimal", SliderCrank::default().minimal());
    check("slider-crank maximal", SliderCrank::default().maximal());
    check("exotic minimal", Exotic::default().minimal());
    check("exotic maximal", Exotic::default().maximal());
    check("plain minimal", Plain::default().minimal());
    check("plain maximal", Plain::default().maximal());
}

/// G's declared structural zeros, counted by hand: in maximal coordinates
/// (x, y, θ per link) a revolute joint's two rows read x₁ ± (l/2)cos θ₁ −
/// x₂ ∓ … and y₁ ± (l/2)sin θ₁ − y₂ ∓ …, so each row has 4 entries (2 for
/// a joint to the world, whose second body is fixed). The fourbar's five
/// joints (two to the world) give 2·(2 + 4 + 2 + 4 + 4) = 32 of 10 × 12;
/// the double pendulum's two 2·(2 + 4) = 12 of 4 × 6. A loop closure in
/// minimal coordinates depends on every angle of its loop (fourbar: all
/// four), so its pattern is dense there.
#[test]
fn constraint_patterns_have_the_joint_structure() {
    fn count<M: Dynamics<N, C>, const N: usize, const C: usize>(_: &M) -> usize {
        M::CONSTRAINT_PATTERN
            .iter()
            .map(|row| row.iter().filter(|x| **x).count())
            .sum()
    }
    assert_eq!(count(&Fourbar::default().maximal()), 32);
    assert_eq!(count(&DoublePendulum::default().maximal()), 12);
    assert_eq!(count(&Fourbar::default().minimal()), 2 * 4);
    // the parameter struct steps its minimal view and says so
    assert_eq!(
        <Fourbar as Dynamics<4, 2>>::CONSTRAINT_PATTERN,
        <vigp::systems::FourbarMinimal as Dynamics<4, 2>>::CONSTRAINT_PATTERN
    );
}

/// Perturbed run-time parameters flow into the constants: the terms of a
/// perturbed model still match its dual-number reference.
#[test]
fn perturbed_parameters_are_used() {
    let mut sys = SliderCrank::default();
    sys.links.rod.mass *= 1.7;
    sys.links.crank.length = 0.55;
    sys.links.block.com = [0.1, -0.05];
    sys.joints.rail.damping = 0.9;
    sys.gravity = [1.0, -3.0];
    check("perturbed slider-crank minimal", sys.minimal());
    check("perturbed slider-crank maximal", sys.maximal());
}

/// Invalid run-time parameters are typed errors naming the parameter.
#[test]
fn invalid_parameters_are_refused_by_name() {
    use vigp::embedded::StepError;
    let mut sys = DoublePendulum::default();
    sys.links.lower.mass = -1.0;
    let err = Dynamics::constants(&sys.minimal()).unwrap_err();
    assert_eq!(
        err,
        StepError::InvalidModel("link `lower`: mass must be finite and >= 0")
    );
    assert!(Dynamics::constants(&sys.maximal()).is_err());
    let mut sys = DoublePendulum::default();
    sys.links.upper.length = f64::NAN;
    assert!(Dynamics::constants(&sys.minimal()).is_err());
    let mut sys = DoublePendulum::default();
    sys.joints.elbow.damping = -0.1;
    assert!(Dynamics::constants(&sys.minimal()).is_err());
    let mut sys = DoublePendulum::default();
    sys.gravity[1] = f64::INFINITY;
    assert!(Dynamics::constants(&sys.minimal()).is_err());
    // admissible parameters whose products overflow
    let mut sys = DoublePendulum::default();
    sys.links.upper.mass = 1e300;
    sys.links.upper.length = 1e300;
    assert!(Dynamics::constants(&sys.minimal()).is_err());
}

/// A random consistent minimal state (loops: projected by the std runtime).
fn random_state<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: &M,
    rng: &mut Rng,
    dt: f64,
) -> vigp::State<N> {
    let q = SVector::from_fn(|_, _| rng.uniform(-1.2, 1.2));
    let v = SVector::from_fn(|_, _| rng.uniform(-2.0, 2.0));
    if C == 0 {
        return vigp::State { q, v };
    }
    vigp::projection::consistent_state(m, &q, &v, dt).expect("projection")
}

/// One step of the closed-form engine (`vigp::embedded::Stepper`, which
/// `Variational` runs on) against the dual-number reference step
/// (`vigp::reference::step`), both rules, from 20 random states.
///
/// Same equations, so the two solutions differ only by what each solver
/// leaves: with the default tolerance (scaled residual 1e-12, i.e. up to
/// ~1e-11 absolute momentum for these systems) the velocities may differ
/// by ~1e-11; both are therefore solved to 1e-14 here, where the
/// velocities must agree to 1e-11 (the acceptance bound; measured ≤ 1.2e-12).
fn engine_matches_reference<M, const N: usize, const C: usize>(
    name: &str,
    m: M,
    states: &[vigp::State<N>],
) -> f64
where
    M: Mechanism<N, C> + Copy,
{
    let dt = 0.01;
    let opts = common::tight();
    let mut worst = 0.0f64;
    for (alpha, fast) in [
        (0.0, vigp::embedded::Stepper::new(m, dt).unwrap()),
        (0.5, vigp::embedded::Stepper::midpoint(m, dt).unwrap()),
    ] {
        let fast = fast.options(opts).unwrap();
        for z in states {
            let reference = vigp::reference::step(&m, dt, alpha, &opts, z);
            let d = common::reference_gap(name, alpha, fast.step(z), reference);
            worst = worst.max(d);
        }
    }
    println!("{name}: max |v_engine − v_reference| = {worst:.1e}");
    worst
}

fn both_views<Mn, Mx, const N: usize, const C: usize, const NM: usize, const CM: usize>(
    name: &str,
    minimal: Mn,
    maximal: Mx,
) where
    Mn: Mechanism<N, C> + vigp::Coordinates<N, NM> + Copy,
    Mx: Mechanism<NM, CM> + Copy,
{
    let dt = 0.01;
    let mut rng = Rng(5);
    let states: Vec<_> = (0..20)
        .map(|_| random_state(&minimal, &mut rng, dt))
        .collect();
    engine_matches_reference(&format!("{name} minimal"), minimal, &states);
    let max_states: Vec<_> = states.iter().map(|z| minimal.to_maximal(z, dt)).collect();
    engine_matches_reference(&format!("{name} maximal"), maximal, &max_states);
}

#[test]
fn engine_steps_match_the_dual_number_reference() {
    let p = Pendulum::default();
    both_views::<_, _, 1, 0, 3, 2>("pendulum", p.minimal(), p.maximal());
    let cp = Cartpole::default();
    both_views::<_, _, 2, 0, 6, 4>("cartpole", cp.minimal(), cp.maximal());
    let mut dp = DoublePendulum::default();
    dp.joints.elbow.damping = 0.3;
    both_views::<_, _, 2, 0, 6, 4>("double pendulum", dp.minimal(), dp.maximal());
    let mut fb = Fourbar::default();
    fb.joints.bottom.damping = 0.2;
    both_views::<_, _, 4, 2, 12, 10>("fourbar", fb.minimal(), fb.maximal());
    let sc = SliderCrank::default();
    both_views::<_, _, 3, 2, 9, 8>("slider-crank", sc.minimal(), sc.maximal());
    let ex = Exotic::default();
    both_views::<_, _, 3, 2, 9, 8>("exotic", ex.minimal(), ex.maximal());
}
