//! Nominal variational integrator on the paper's four systems and on other
//! planar mechanisms: exact Jacobians, closed forms, long-run energy and
//! constraint behaviour, convergence order, error reporting.

use crate::common;
use common::{Rng, pendulum_reference};
use nalgebra::{SMatrix, SVector};
use vigp::del;
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

use crate::slider_crank;
use slider_crank::SliderCrank;

vigp::mechanism! {
    /// A carriage on a rail carrying a telescopic arm (prismatic joint with a
    /// link parent) and a pendulum at its tip, closed by a prismatic loop.
    Telescope {
        links {
            carriage: { mass: 1.5, length: 0.5 },
            arm: { mass: 0.7, length: 0.8 },
            tip: { mass: 0.3, length: 0.6, com: [0.4, -0.05] },
            sleeve: { mass: 0.4, length: 0.2 },
        }
        joints {
            rail: prismatic(world, carriage.center) { axis: [1.0, 0.0], damping: 0.2 },
            slide: prismatic(carriage.end, arm.start) { axis: [1.0, 0.0], damping: 0.1 },
            wrist: revolute(arm.end, tip.start) { damping: 0.05 },
            pivot: revolute(world @ [0.0, -2.0], sleeve.start),
            guide: prismatic(sleeve.start, tip.end) { axis: [1.0, 0.0], damping: 0.05 },
        }
    }
}

/// Central finite differences of the DEL terms with respect to v₁, compared
/// with the dual-number Jacobian. With h ≈ 1e-6·scale the truncation error is
/// O(h²) ≈ 1e-12 and the rounding error O(ε/h) ≈ 1e-10 relative to the
/// entries, so 1e-7 relative (to the largest entry) is a strict check that
/// still cannot be failed by rounding.
fn check_del_jacobian<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    seed: u64,
    dt: f64,
) {
    let mut rng = Rng(seed);
    for _ in 0..20 {
        let x1 = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let v1 = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let (terms, jac) = del::del_terms_jacobian::<M, N, C>(m, dt, 0.0, &x1, &v1);
        let direct = del::del_terms::<M, f64, N, C>(m, dt, 0.0, &x1, &v1);
        assert!((terms - direct).amax() <= 1e-13 * (1.0 + direct.amax()));
        let mut fd = SMatrix::<f64, N, N>::zeros();
        for j in 0..N {
            let h = 1e-6 * (1.0 + v1[j].abs());
            let (mut vp, mut vm) = (v1, v1);
            vp[j] += h;
            vm[j] -= h;
            let d = (del::del_terms::<M, f64, N, C>(m, dt, 0.0, &x1, &vp)
                - del::del_terms::<M, f64, N, C>(m, dt, 0.0, &x1, &vm))
                / (2.0 * h);
            fd.set_column(j, &d);
        }
        let err = (jac - fd).amax() / jac.amax().max(1e-300);
        assert!(
            err < 1e-7,
            "DEL Jacobian vs central differences: relative error {err:.2e}"
        );

        if C > 0 {
            let g = m.constraint_jacobian(&x1);
            let mut fdg = SMatrix::<f64, C, N>::zeros();
            for j in 0..N {
                let h = 1e-6 * (1.0 + x1[j].abs());
                let (mut xp, mut xm) = (x1, x1);
                xp[j] += h;
                xm[j] -= h;
                fdg.set_column(j, &((m.constraints(&xp) - m.constraints(&xm)) / (2.0 * h)));
            }
            let err = (g - fdg).amax() / g.amax().max(1e-300);
            assert!(
                err < 1e-7,
                "constraint Jacobian vs central differences: relative error {err:.2e}"
            );
        }
    }
}

#[test]
fn del_jacobian_matches_finite_differences_on_all_systems() {
    let dt = 0.01;
    let mut p = Pendulum::default();
    check_del_jacobian(&p.minimal(), 1, dt);
    p.joints.pivot.damping = 0.7;
    check_del_jacobian(&p.minimal(), 2, dt);

    let mut c = Cartpole::default();
    check_del_jacobian(&c.minimal(), 3, dt);
    c.joints.rail.damping = 0.4;
    c.joints.hinge.damping = 0.9;
    check_del_jacobian(&c.minimal(), 4, dt);

    let mut d = DoublePendulum::default();
    check_del_jacobian(&d.minimal(), 5, dt);
    d.joints.shoulder.damping = 1.5;
    d.joints.elbow.damping = 0.3;
    d.links.lower.mass = 1.07;
    check_del_jacobian(&d.minimal(), 6, dt);

    let mut f = Fourbar::default();
    check_del_jacobian(&f.minimal(), 7, dt);
    f.joints.top1.damping = 1.2;
    f.joints.middle1.damping = 0.4;
    f.joints.middle2.damping = 0.4;
    f.joints.bottom.damping = 0.1; // a damped loop joint: rate from the tangent kinematics
    check_del_jacobian(&f.minimal(), 8, dt);

    check_del_jacobian(&SliderCrank::default().minimal(), 9, dt);
    check_del_jacobian(&Telescope::default().minimal(), 10, dt);
}

/// Pendulum: L = ½ I θ̇² + m g l_c cos θ with I = J + m l_c² (constant), so
/// the DEL equations reduce to symplectic Euler:
/// θ₁ = θ₀ + Δt v₀,  v₁ = v₀ − Δt (m g l_c / I) sin θ₁.
#[test]
fn pendulum_step_equals_closed_form_symplectic_euler() {
    let mut sys = Pendulum::default();
    sys.links.rod.mass = 1.3;
    sys.links.rod.length = 0.8;
    sys.links.rod.com = [0.4, 0.0];
    sys.links.rod.inertia = 1.3 * 0.8 * 0.8 / 12.0;
    let (m, lc, g) = (1.3, 0.4, 9.81);
    let inertia = sys.links.rod.inertia + m * lc * lc;
    let vi = Variational::new(sys.minimal(), 0.01).unwrap();
    let mut z = State::new([1.2], [-0.7]);
    for _ in 0..100 {
        let next = vi.step(&z).unwrap();
        let theta1 = z.q[0] + 0.01 * z.v[0];
        let v1 = z.v[0] - 0.01 * m * g * lc / inertia * theta1.sin();
        assert!(
            (next.q[0] - theta1).abs() <= 1e-14,
            "q: {} vs {}",
            next.q[0],
            theta1
        );
        assert!(
            (next.v[0] - v1).abs() <= 1e-14,
            "v: {} vs {}",
            next.v[0],
            v1
        );
        z = next;
    }
}

/// An independent implementation of the same discrete equations: the
/// textbook closed-form double-pendulum Lagrangian (rods, COM at mid-length),
/// with momentum and ∂L/∂θ written by hand. The step we compute must zero the
/// hand-written DEL residual p₀ − p₁ + Δt·∂L/∂θ(x₁, v₁) − Δt·C v₁.
#[test]
fn double_pendulum_step_zeroes_independent_closed_form_residual() {
    let mut sys = DoublePendulum::default();
    sys.links.upper.mass = 1.1;
    sys.links.lower.mass = 0.9;
    sys.links.upper.inertia = 0.1;
    sys.links.lower.inertia = 0.07;
    sys.joints.shoulder.damping = 0.8;
    sys.joints.elbow.damping = 0.2;
    let (m1, m2, l1, c1, c2, j1, j2, g) = (1.1, 0.9, 1.0, 0.5, 0.5, 0.1, 0.07, 9.81);
    let (d1, d2) = (0.8, 0.2);
    // L = ½a θ̇1² + ½b (θ̇1+θ̇2)² + k cos θ2 θ̇1 (θ̇1+θ̇2) + g(m1 c1 + m2 l1) cos θ1 + g m2 c2 cos(θ1+θ2)
    let a = j1 + m1 * c1 * c1 + m2 * l1 * l1;
    let b = j2 + m2 * c2 * c2;
    let k = m2 * l1 * c2;
    let momentum = |q: [f64; 2], v: [f64; 2]| {
        let w = v[0] + v[1];
        let p2 = b * w + k * q[1].cos() * v[0];
        let p1 = a * v[0] + p2 + k * q[1].cos() * w;
        [p1, p2]
    };
    let dldq = |q: [f64; 2], v: [f64; 2]| {
        let w = v[0] + v[1];
        let s12 = (q[0] + q[1]).sin();
        [
            -g * (m1 * c1 + m2 * l1) * q[0].sin() - g * m2 * c2 * s12,
            -k * q[1].sin() * v[0] * w - g * m2 * c2 * s12,
        ]
    };
    let dt = 0.01;
    // solve to 1e-14 so the comparison measures the equations, not the
    // solver tolerance (1e-12 relative to |p| by default)
    let vi = Variational::new(sys.minimal(), dt)
        .unwrap()
        .tolerance(1e-14)
        .unwrap();
    let mut z = State::new([1.0, -0.5], [0.3, 1.1]);
    for _ in 0..200 {
        let next = vi.step(&z).unwrap();
        let (x0, v0) = ([z.q[0], z.q[1]], [z.v[0], z.v[1]]);
        let (x1, v1) = ([next.q[0], next.q[1]], [next.v[0], next.v[1]]);
        let (p0, p1, dl) = (momentum(x0, v0), momentum(x1, v1), dldq(x1, v1));
        let forces = [-d1 * v1[0], -d2 * v1[1]];
        for i in 0..2 {
            let r = p0[i] - p1[i] + dt * dl[i] + dt * forces[i];
            assert!(r.abs() < 1e-12, "residual {r:e}");
        }
        z = next;
    }
}

/// Max |E_k − E_0| over each tenth of a conservative rollout.
fn energy_deviation_by_tenth(dt: f64, steps: usize) -> Vec<f64> {
    let model = DoublePendulum::default().minimal();
    let vi = Variational::new(model, dt).unwrap();
    let z0 = State::new([std::f64::consts::FRAC_PI_2, 0.0], [0.0, 0.0]);
    let e0 = model.energy(&z0);
    let mut z = z0;
    let mut tenths = vec![0.0f64; 10];
    for k in 0..steps {
        z = vi.step(&z).unwrap();
        let t = k * 10 / steps;
        tenths[t] = tenths[t].max((model.energy(&z) - e0).abs());
    }
    tenths
}

/// Conservative double pendulum (chaotic from θ = (π/2, 0)), dt = 0.01,
/// 10^5 steps: the energy error oscillates but does not grow, and its size is
/// the O(Δt) oscillation of a first-order symplectic method (halving Δt halves
/// it), not drift.
#[test]
fn double_pendulum_energy_is_bounded_over_1e5_steps() {
    let coarse = energy_deviation_by_tenth(0.01, 100_000);
    let (first, last) = (coarse[0], coarse[9]);
    let all = coarse.iter().cloned().fold(0.0, f64::max);
    eprintln!("double pendulum dt=0.01 max |ΔE| per tenth: {coarse:.3?}");
    // No secular growth: the last tenth's worst deviation is within 1.5x of
    // the first tenth's (a drifting integrator grows by orders of magnitude
    // over 10^5 steps).
    assert!(
        last <= 1.5 * first,
        "first tenth {first:.3e}, last tenth {last:.3e}"
    );
    // Bounded and first order: at dt/2 over the same number of steps the
    // worst deviation is about half (ratio 1.5–2.8 allows for the chaotic
    // trajectories visiting different states).
    let fine = energy_deviation_by_tenth(0.005, 100_000);
    let all_fine = fine.iter().cloned().fold(0.0, f64::max);
    let ratio = all / all_fine;
    eprintln!("max |ΔE|: dt=0.01 {all:.3e}, dt=0.005 {all_fine:.3e}, ratio {ratio:.2}");
    assert!((1.5..=2.8).contains(&ratio), "ratio {ratio}");
}

/// Smallest singular value of the 2×4 loop Jacobian.
fn sigma_min(g: &SMatrix<f64, 2, 4>) -> f64 {
    let ggt = g * g.transpose();
    let (a, b, d) = (ggt[(0, 0)], ggt[(0, 1)], ggt[(1, 1)]);
    let tr = a + d;
    let det = a * d - b * b;
    let lo = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt());
    lo.max(0.0).sqrt()
}

/// Fourbar, minimal coordinates, 10^4 steps: |g| ≤ 1e-10 at every step, and
/// the rollout passes through the folded pose where the loop Jacobian loses
/// rank.
#[test]
fn fourbar_constraints_hold_through_the_folded_pose() {
    let model = Fourbar::default().minimal();
    let dt = 0.01;
    // Arms at absolute angles 0.9 and -0.4: a consistent rhombus.
    let (t1, t3) = (0.9f64, -0.4f64);
    let q = SVector::from([t1, t3 - t1, t3, t1 - t3]);
    let z0 = consistent_state(&model, &q, &SVector::zeros(), dt).unwrap();
    assert!(model.constraint_violation(&z0) < 1e-12);
    let vi = Variational::new(model, dt).unwrap();
    let mut z = z0;
    let (mut worst, mut smin) = (0.0f64, f64::INFINITY);
    for k in 0..10_000 {
        z = vi.step(&z).unwrap_or_else(|e| panic!("step {k}: {e}"));
        let g = model.constraint_violation(&z);
        worst = worst.max(g);
        assert!(g <= 1e-10, "step {k}: |g| = {g:e}");
        smin = smin.min(sigma_min(&model.constraint_jacobian(&z.q)));
    }
    assert!(
        smin < 1e-2,
        "the rollout should pass near the folded pose (min σ = {smin:e})"
    );
    eprintln!("fourbar: max |g| = {worst:.2e}, min σ(G) = {smin:.2e}");
}

/// A rollout of 2000 steps of the VI of `m` at `dt` from the consistent
/// state near (`q`, `v`), and its largest constraint violation |g|.
fn constrained_rollout<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    q: [f64; N],
    v: [f64; N],
    dt: f64,
) -> (Vec<State<N>>, f64) {
    let z0 = consistent_state(&m, &SVector::from(q), &SVector::from(v), dt).unwrap();
    let traj = Variational::new(m, dt)
        .unwrap()
        .rollout(&z0, 2_000)
        .unwrap();
    let worst = traj
        .iter()
        .map(|z| m.constraint_violation(z))
        .fold(0.0, f64::max);
    (traj, worst)
}

/// Slider-crank and telescope (prismatic joints, offsets, prismatic loop):
/// the constraints hold over a damped rollout.
#[test]
fn other_loop_mechanisms_keep_their_constraints() {
    let dt = 0.005;
    let sc = SliderCrank::default().minimal();
    let (traj, worst) = constrained_rollout(sc, [0.3, 1.0, 0.5], [2.0, 0.0, 0.0], dt);
    assert!(worst <= 1e-10, "slider-crank |g| = {worst:e}");
    // damping dissipates energy
    assert!(sc.energy(traj.last().unwrap()) < sc.energy(&traj[0]));

    let tel = Telescope::default().minimal();
    let (_, worst) = constrained_rollout(tel, [0.0, 0.2, 0.3, 0.5], [0.5, 0.0, 0.0, 0.0], dt);
    assert!(worst <= 1e-10, "telescope |g| = {worst:e}");
}

/// First-order convergence: the position error at t = 1 s halves when Δt
/// halves (ratios within [1.7, 2.3]).
#[test]
fn variational_integrator_converges_at_first_order() {
    let mut sys = Pendulum::default();
    sys.joints.pivot.damping = 0.3;
    let inertia = sys.links.rod.inertia + 0.25;
    let reference = pendulum_reference(1.0, 0.0, 1.0, inertia, 9.81 * 0.5, 0.3);
    let mut errors = Vec::new();
    for &steps in &[50usize, 100, 200, 400, 800] {
        let dt = 1.0 / steps as f64;
        let traj = Variational::new(sys.minimal(), dt)
            .unwrap()
            .rollout(&State::new([1.0], [0.0]), steps)
            .unwrap();
        errors.push((traj[steps].q[0] - reference).abs());
    }
    for w in errors.windows(2) {
        let ratio = w[0] / w[1];
        assert!((1.7..=2.3).contains(&ratio), "errors {errors:?}");
    }
}

#[test]
fn a_step_that_cannot_converge_is_an_error_not_nan() {
    let model = DoublePendulum::default().minimal();
    // the error itself is under test, not the subdivision that would
    // otherwise retry the step
    let vi = Variational::new(model, 1.0)
        .unwrap()
        .max_iterations(2)
        .unwrap()
        .max_subdivision(0);
    let z = State::new([2.5, -1.0], [4.0, -3.0]);
    match vi.step(&z) {
        Err(StepError::NotConverged {
            iterations,
            residual,
            ..
        }) => {
            assert_eq!(iterations, 2);
            assert!(residual.is_finite() && residual > 1e-12);
        }
        other => panic!("expected NotConverged, got {other:?}"),
    }
    // the fourbar at a huge step too
    let fb = Fourbar::default().minimal();
    let r = Variational::new(fb, 1.0)
        .unwrap()
        .max_iterations(2)
        .unwrap()
        .step(&State::new([1.0, -1.0, -0.5, 0.5], [3.0, 0.0, 0.0, 0.0]));
    assert!(r.is_err());
    // rollouts name the failing step
    let err = vi.rollout(&z, 5).unwrap_err();
    assert!(matches!(err, StepError::NotConverged { step: Some(0), .. }));
}

#[test]
fn invalid_inputs_are_typed_errors() {
    let model = Pendulum::default().minimal();
    let z = State::new([f64::NAN], [0.0]);
    assert!(matches!(
        Variational::new(model, 0.01).unwrap().step(&z),
        Err(StepError::NonFiniteState { .. })
    ));
    let z = State::new([0.1], [f64::INFINITY]);
    assert!(matches!(
        Variational::new(model, 0.01).unwrap().step(&z),
        Err(StepError::NonFiniteState { .. })
    ));
    assert!(matches!(
        Variational::new(model, 0.0),
        Err(StepError::InvalidTimeStep { .. })
    ));
    assert!(matches!(
        Variational::new(model, f64::NAN),
        Err(StepError::InvalidTimeStep { .. })
    ));
    assert!(matches!(
        Variational::new(model, 0.01).unwrap().tolerance(-1.0),
        Err(StepError::InvalidOptions(_))
    ));
    // non-finite parameters surface as an error, not a NaN state
    let mut sys = Pendulum::default();
    sys.links.rod.mass = f64::NAN;
    assert!(Variational::new(sys.minimal(), 0.01).is_err());
}

/// Settings and parameters that cannot work are refused by name, with the
/// Δt the user gave (found by probing unseen mechanisms through the public
/// API: each of these used to pass, hang, or report another Δt).
#[test]
fn degenerate_settings_are_typed_errors() {
    let model = Pendulum::default().minimal();
    let z = State::new([0.5], [3.0]);
    // the fourth-order VI names the user's Δt, not a stage's
    for dt in [-0.01, 1e300, 5e-324, f64::NAN] {
        let e = Composition::new(model, dt).unwrap_err();
        assert!(
            matches!(e, StepError::InvalidTimeStep { dt: d } if d.to_bits() == dt.to_bits()),
            "{dt}: {e:?}"
        );
    }
    // the classical integrators check Δt as the variational ones do
    for dt in [5e-324, f64::MIN_POSITIVE, 1e300] {
        let expect = |e: Result<State<1>, StepError>| {
            assert!(
                matches!(e, Err(StepError::InvalidTimeStep { dt: d }) if d == dt),
                "{dt}: {e:?}"
            )
        };
        expect(Rk4::new(model, dt).step(&z));
        expect(ExplicitEuler::new(model, dt).step(&z));
        expect(SymplecticEuler::new(model, dt).step(&z));
        expect(Variational::new(model, dt).and_then(|vi| vi.step(&z)));
        // the projections and the Lie-group stepper check it likewise
        // (they accepted 1e300 and 5e-324, and LieStepper stepped with
        // Δt² = 0 at 1e-200)
        let fourbar = Fourbar::default().minimal();
        let q = SVector::from([0.9, -1.3, -0.4, 1.3]);
        let e = consistent_state(&fourbar, &q, &SVector::zeros(), dt);
        assert!(
            matches!(e, Err(StepError::InvalidTimeStep { dt: d }) if d == dt),
            "{dt}: {e:?}"
        );
        let e = consistent_state(&model, &z.q, &z.v, dt);
        assert!(
            matches!(e, Err(StepError::InvalidTimeStep { dt: d }) if d == dt),
            "{dt}: {e:?}"
        );
    }
    for dt in [5e-324, 1e-200, 1e200, 1e300] {
        let e = vigp::spatial::LieStepper::new(
            vigp::systems::spatial::SphericalPendulum::default().maximal(),
            dt,
        );
        assert!(
            matches!(e, Err(vigp::embedded::StepError::InvalidTimeStep { dt: d }) if d == dt),
            "{dt}"
        );
    }
    // run-time parameters: every std integrator refuses a negative or NaN
    // mass (docs/stability.md)
    for mass in [-1.0, f64::NAN] {
        let mut bad = Pendulum::default();
        bad.links.rod.mass = mass;
        let m = bad.minimal();
        let refused = |e: Result<(), StepError>| {
            assert!(
                matches!(e, Err(StepError::InvalidModel(_))),
                "{mass}: {e:?}"
            )
        };
        // the variational integrators at construction, the classical ones
        // at the step
        refused(Variational::new(m, 0.01).map(drop));
        refused(Variational::midpoint(m, 0.01).map(drop));
        refused(Composition::new(m, 0.01).map(drop));
        refused(Rk4::new(m, 0.01).step(&z).map(drop));
        refused(ExplicitEuler::new(m, 0.01).step(&z).map(drop));
        refused(SymplecticEuler::new(m, 0.01).step(&z).map(drop));
    }
    // no Newton iteration allowed, or a step that would never return
    let invalid = |e: Result<(), StepError>| matches!(e, Err(StepError::InvalidOptions(_)));
    let vi = Variational::new(model, 0.01).unwrap();
    assert!(invalid(vi.max_iterations(0).map(drop)));
    assert!(invalid(vi.substeps(usize::MAX).map(drop)));
    assert!(invalid(
        vi.substeps(vigp::embedded::MAX_SUBSTEPS + 1).map(drop)
    ));
    let stepper = vigp::embedded::Stepper::new(model, 0.01).unwrap();
    assert!(stepper.substeps(usize::MAX).is_err());
    assert!(stepper.substeps(vigp::embedded::MAX_SUBSTEPS).is_ok());
    // a link without mass or inertia: M = 0, so the DEL equations do not
    // determine v (every guess used to pass, returning v unchanged)
    let mut massless = Pendulum::default();
    massless.links.rod.mass = 0.0;
    massless.links.rod.inertia = 0.0;
    let singular = |e: Result<State<1>, StepError>| {
        assert!(
            matches!(e, Err(StepError::SingularJacobian { .. })),
            "{e:?}"
        )
    };
    singular(Variational::new(massless.minimal(), 0.01).unwrap().step(&z));
    singular(
        Variational::midpoint(massless.minimal(), 0.01)
            .unwrap()
            .step(&z),
    );
    singular(Composition::new(massless.minimal(), 0.01).unwrap().step(&z));
    let e = Variational::new(massless.maximal(), 0.01)
        .unwrap()
        .step(
            &massless
                .maximal()
                .state([0.5 * 0.5f64.sin(), -0.5 * 0.5f64.cos(), 0.5], [0.0; 3]),
        )
        .unwrap_err();
    assert!(matches!(e, StepError::SingularJacobian { .. }), "{e:?}");
    // a mass so small that M underflows likewise
    let mut tiny = Pendulum::default();
    tiny.links.rod.mass = 1e-320;
    tiny.links.rod.inertia = 0.0;
    singular(Variational::new(tiny.minimal(), 0.01).unwrap().step(&z));
}

#[test]
fn generated_constants_and_kinematics() {
    assert_eq!(Fourbar::DOF, 4);
    assert_eq!(Fourbar::LOOP_CONSTRAINTS, 2);
    assert_eq!(
        <vigp::systems::FourbarMinimal as Mechanism<4, 2>>::COORDINATES,
        ["top1", "middle1", "top2", "middle2"]
    );
    assert_eq!(
        <vigp::systems::CartpoleMinimal as vigp::embedded::Dynamics<2, 0>>::KINDS,
        [vigp::CoordinateKind::Length, vigp::CoordinateKind::Angle]
    );
    // θ = π/2 points the pendulum to the right: its end is at (1, 0).
    let [rod] = Pendulum::default().link_poses(&SVector::from([std::f64::consts::FRAC_PI_2]));
    let end = rod.point([1.0, 0.0]);
    assert!((end[0] - 1.0).abs() < 1e-15 && end[1].abs() < 1e-15);
    // cartpole: the pole hangs from the cart's centre, which is on the rail
    let [cart, pole] = Cartpole::default().link_poses(&SVector::<f64, 2>::from([0.7, 0.0]));
    let c = cart.point([0.5, 0.0]);
    assert!((c[0] - 0.7).abs() < 1e-15 && c[1].abs() < 1e-15);
    assert!((pole.point([1.0, 0.0])[1] + 1.0).abs() < 1e-15);
    // potential energy of the hanging double pendulum: −m g (0.5 + 1.5)
    let e: f64 = DoublePendulum::default()
        .minimal()
        .potential_energy(&SVector::from([0.0, 0.0]));
    assert!((e + 9.81 * 2.0).abs() < 1e-12);
}
