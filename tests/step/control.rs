//! Actuated mechanisms and springs (`actuated`, `stiffness`, `rest` in
//! `mechanism!`), the forced variational step and its exact derivatives.
//!
//! Every new generated term is checked against the dual-number reference
//! (`vigp::Mechanism`: spring energy in V, the input's virtual work
//! W(q; u) = Σ u_i s_i(q) differentiated by num-dual); every forced step
//! against the reference step of the same equations; A = ∂z₁/∂z₀ and
//! B = ∂z₁/∂u against central finite differences; and the physics against
//! closed forms (a constant torque's equilibrium, a spring's period).

use crate::common;
use crate::slider_crank;

use common::{Rng, a_stencil_errors, ab_errors, jacobian_amax, nudged, state_bits, stencil};
use nalgebra::{SMatrix, SVector};
use num_dual::DualVec;
use slider_crank::SliderCrank;
use vigp::embedded::{Dynamics, Stepper, Terms};
use vigp::{Coordinates, Mechanism, State, Variational};

/// Declares the damped pendulum `$name` with the doc comment `$doc`,
/// driven by a torque at its pivot when `$actuated` is given.
macro_rules! torque_pendulum {
    ($(#[doc = $doc:tt])* $name:ident [$($actuated:ident)?]) => {
        vigp::mechanism! {
            $(#[doc = $doc])*
            pub $name {
                gravity: [0.0, -9.81],
                links {
                    rod: { mass: 1.0, length: 1.0 },
                }
                joints {
                    pivot: revolute(world, rod.start) { damping: 2.0 $(, $actuated)? },
                }
            }
        }
    };
}

torque_pendulum! {
    /// A damped pendulum driven by a torque at its pivot.
    TorquePendulum [actuated]
}

torque_pendulum! {
    /// `TorquePendulum` without the actuator.
    PlainPendulum []
}

vigp::mechanism! {
    /// A rod on a torsion spring with a rest angle, no gravity.
    pub SpringRod {
        gravity: [0.0, 0.0],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { stiffness: 4.0, rest: 0.5 },
        }
    }
}

drive_cartpole! {
    /// tests/common/drive_cartpole.rs with a spring on the hinge.
    DriveCartpole {
        rail: [damping: 0.1],
        hinge: [damping: 0.05, stiffness: 0.7, rest: 0.2],
    }
}

vigp::mechanism! {
    /// An acrobot (double pendulum driven at the elbow) with a shoulder
    /// spring; undamped springs only (no `damping` anywhere).
    pub Acrobot {
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { stiffness: 1.5, rest: -0.3 },
            elbow: revolute(upper.end, lower.start) { actuated },
        }
    }
}

rhombus! {
    /// The paper's four-bar rhombus, driven at the top pivot and at the
    /// loop-closing joint (an actuated loop joint), with a spring on it.
    DriveFourbar {
        top1: { damping: 0.1, actuated },
        middle: [{ damping: 0.0 }],
        bottom: { damping: 0.05, stiffness: 2.0, rest: 0.4, actuated },
    }
}

rhombus! {
    /// `DriveFourbar` without actuators.
    TwinFourbar {
        top1: { damping: 0.1 },
        middle: [{ damping: 0.0 }],
        bottom: { damping: 0.05, stiffness: 2.0, rest: 0.4 },
    }
}

slider_crank! {
    /// tests/common/slider_crank.rs driven at the crank pivot and along the
    /// tilted rail (a prismatic input: its direction turns with nothing in
    /// minimal coordinates, with the rail's frame in maximal ones).
    DriveSliderCrank [actuated]
}

vigp::mechanism! {
    /// A prismatic spring on a rotating arm (its axis turns), driven along
    /// the slide: nonlinear joint coordinates in both views.
    pub SlideArm {
        links {
            arm: { mass: 1.3, length: 0.9, com: [0.4, 0.05] },
            slider: { mass: 0.7, length: 0.5 },
        }
        joints {
            shoulder: revolute(world @ [0.1, -0.2], arm.start) { damping: 0.1, actuated },
            slide: prismatic(arm.end, slider.start) { axis: [0.3, 1.0], stiffness: 3.0, rest: 0.1, actuated },
        }
    }
}

/// The first-order (`mid` false) or midpoint variational integrator of
/// `m` at `dt`.
fn vi_rule<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    dt: f64,
    mid: bool,
) -> Variational<M, N, C> {
    if mid {
        Variational::midpoint(m, dt).unwrap()
    } else {
        Variational::new(m, dt).unwrap()
    }
}

fn rel(a: f64, scale: f64) -> f64 {
    a / (1.0 + scale)
}

/// The new generated terms against the dual-number reference at random
/// configurations: V and ∇V (springs included), the force Jacobian, the
/// input matrix B(q) (against ∇_q W(q; e_i)) and Σ u_i ∇²s_i (against the
/// Jacobian of ∇_q W). Exact on both sides up to rounding: 1e-12 relative.
fn check_terms<M, const N: usize, const C: usize, const U: usize>(name: &str, m: M)
where
    M: Mechanism<N, C> + vigp::Inputs<U>,
{
    let k = Dynamics::constants(&m).expect("valid parameters");
    let mut rng = Rng(3);
    let mut worst = 0.0f64;
    for _ in 0..10 {
        let q = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let v = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let us: Vec<f64> = u.iter().copied().collect();
        let mut t = Terms::zeros();
        m.terms(&k, &q, &mut t);
        let v_ref = m.potential_energy(&q);
        let e = rel((Dynamics::potential(&m, &k, &q) - v_ref).abs(), v_ref.abs());
        let grad_ref = num_dual::gradient(|x| m.potential_energy(&x), &q).1;
        let e2 = rel((t.dpotential - grad_ref).amax(), grad_ref.amax());
        let fj_ref = num_dual::jacobian(
            |x: SVector<DualVec<f64, nalgebra::Const<N>>, N>| {
                vigp::del::force_terms::<M, _, N, C>(&m, &x, &v.map(DualVec::from_re))
            },
            &q,
        )
        .1;
        let fj = m.force_jacobian(&k, &q, &v);
        let e3 = rel((fj - fj_ref).amax(), fj_ref.amax());
        let b = m.input_matrix::<U>(&k, &q);
        let bu_ref = m.input_force(&q, &us);
        let e4 = rel((b * u - bu_ref).amax(), bu_ref.amax());
        let mut b_ref = SMatrix::<f64, N, U>::zeros();
        for i in 0..U {
            let mut ei = vec![0.0; U];
            ei[i] = 1.0;
            b_ref.set_column(i, &m.input_force(&q, &ei));
        }
        let e5 = rel((b - b_ref).amax(), b_ref.amax());
        let h_ref = num_dual::jacobian(
            |x: SVector<DualVec<f64, nalgebra::Const<N>>, N>| m.input_force(&x, &us),
            &q,
        )
        .1;
        let h = m.input_force_jacobian::<U>(&k, &q, &u);
        let e6 = rel((h - h_ref).amax(), h_ref.amax());
        for (what, e) in [
            ("V", e),
            ("∇V", e2),
            ("force_jacobian", e3),
            ("B u", e4),
            ("B", e5),
            ("Σu∇²s", e6),
        ] {
            assert!(e <= 1e-12, "{name} {what}: {e:.2e}");
            worst = worst.max(e);
        }
    }
    println!("{name}: worst relative difference {worst:.1e}");
}

#[test]
fn generated_input_and_spring_terms_match_dual_numbers() {
    check_terms::<_, 1, 0, 1>(
        "torque pendulum minimal",
        TorquePendulum::default().minimal(),
    );
    check_terms::<_, 3, 2, 1>(
        "torque pendulum maximal",
        TorquePendulum::default().maximal(),
    );
    check_terms::<_, 1, 0, 0>("spring rod minimal", SpringRod::default().minimal());
    check_terms::<_, 3, 2, 0>("spring rod maximal", SpringRod::default().maximal());
    check_terms::<_, 2, 0, 1>("cartpole minimal", DriveCartpole::default().minimal());
    check_terms::<_, 6, 4, 1>("cartpole maximal", DriveCartpole::default().maximal());
    check_terms::<_, 2, 0, 1>("acrobot minimal", Acrobot::default().minimal());
    check_terms::<_, 6, 4, 1>("acrobot maximal", Acrobot::default().maximal());
    check_terms::<_, 4, 2, 2>("fourbar minimal", DriveFourbar::default().minimal());
    check_terms::<_, 12, 10, 2>("fourbar maximal", DriveFourbar::default().maximal());
    check_terms::<_, 3, 2, 2>(
        "slider-crank minimal",
        DriveSliderCrank::default().minimal(),
    );
    check_terms::<_, 9, 8, 2>(
        "slider-crank maximal",
        DriveSliderCrank::default().maximal(),
    );
    check_terms::<_, 2, 0, 2>("slide arm minimal", SlideArm::default().minimal());
    check_terms::<_, 6, 4, 2>("slide arm maximal", SlideArm::default().maximal());
}

/// A random consistent state (loops: projected by the std runtime).
fn random_state<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: &M,
    rng: &mut Rng,
    dt: f64,
) -> State<N> {
    let q = SVector::from_fn(|_, _| rng.uniform(-1.0, 1.0));
    let v = SVector::from_fn(|_, _| rng.uniform(-1.5, 1.5));
    if C == 0 {
        return State { q, v };
    }
    vigp::projection::consistent_state(m, &q, &v, dt).expect("projection")
}

fn minimal_and_maximal_states<Mn, const N: usize, const C: usize, const NM: usize>(
    m: &Mn,
    seed: u64,
    count: usize,
    dt: f64,
) -> (Vec<State<N>>, Vec<State<NM>>)
where
    Mn: Mechanism<N, C> + Coordinates<N, NM> + Copy,
{
    let mut rng = Rng(seed);
    let states: Vec<State<N>> = (0..count).map(|_| random_state(m, &mut rng, dt)).collect();
    let max = states.iter().map(|z| m.to_maximal(z, dt)).collect();
    (states, max)
}

/// Runs `$check::<_, N, C, U>(name, view, states, extra…)` on the minimal
/// and the maximal view of each actuated test mechanism (its sizes are
/// const generics, hence a macro), at `$count` random consistent states
/// (seed `$seed`, step `$dt`) of its minimal view and their maximal images.
macro_rules! on_actuated_views {
    ($check:ident $extra:tt, $seed:expr, $count:expr, $dt:expr) => {
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "torque pendulum", TorquePendulum::default(), 1, 0, 3, 2, 1);
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "cartpole", DriveCartpole::default(), 2, 0, 6, 4, 1);
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "acrobot", Acrobot::default(), 2, 0, 6, 4, 1);
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "fourbar", DriveFourbar::default(), 4, 2, 12, 10, 2);
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "slider-crank", DriveSliderCrank::default(), 3, 2, 9, 8, 2);
        on_actuated_views!(@one $check $extra, $seed, $count, $dt,
            "slide arm", SlideArm::default(), 2, 0, 6, 4, 2);
    };
    (@one $check:ident ($($extra:expr),*), $seed:expr, $count:expr, $dt:expr,
     $name:expr, $sys:expr, $n:literal, $c:literal, $nm:literal, $cm:literal, $u:literal) => {{
        let sys = $sys;
        let (s, x) = minimal_and_maximal_states::<_, $n, $c, $nm>(&sys.minimal(), $seed, $count, $dt);
        $check::<_, $n, $c, $u>(&format!("{} minimal", $name), sys.minimal(), &s $(, $extra)*);
        $check::<_, $nm, $cm, $u>(&format!("{} maximal", $name), sys.maximal(), &x $(, $extra)*);
    }};
}

/// The engine's forced step against the dual-number reference step
/// (`vigp::reference::step_forced`: the input force by differentiating the
/// virtual work on dual numbers), both rules, both solved to 1e-14: the
/// velocities agree to 1e-11 (as for the unforced step, tests/dsl/dynamics.rs).
fn forced_matches_reference<M, const N: usize, const C: usize, const U: usize>(
    name: &str,
    m: M,
    states: &[State<N>],
) where
    M: Mechanism<N, C> + Copy,
    M: vigp::Inputs<U>,
{
    let dt = 0.01;
    let opts = common::tight();
    let mut rng = Rng(17);
    let mut worst = 0.0f64;
    for (alpha, vi) in [
        (0.0, Variational::new(m, dt).unwrap()),
        (0.5, Variational::midpoint(m, dt).unwrap()),
    ] {
        let vi = vi.with_options(opts).unwrap();
        for z in states {
            let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-5.0, 5.0));
            let us: Vec<f64> = u.iter().copied().collect();
            let reference = vigp::reference::step_forced(&m, dt, alpha, &opts, z, &us);
            let d = common::reference_gap(name, alpha, vi.step_forced(z, &u), reference);
            worst = worst.max(d);
        }
    }
    println!("{name}: max |v_engine − v_reference| = {worst:.1e}");
}

#[test]
fn forced_steps_match_the_dual_number_reference() {
    let dt = 0.01;
    on_actuated_views!(forced_matches_reference(), 5, 8, dt);
}

/// u = 0 reproduces the same mechanism without `actuated` bit for bit:
/// single steps and rollouts, both rules, both views, loops included.
fn bitwise<A, B, const N: usize, const C: usize, const U: usize>(
    name: &str,
    actuated: A,
    plain: B,
    states: &[State<N>],
) where
    A: Dynamics<N, C> + Copy,
    B: Dynamics<N, C> + Copy,
    A: vigp::Inputs<U>,
{
    let dt = 0.01;
    let zero = SVector::<f64, U>::zeros();
    for mid in [false, true] {
        let (sa, sb) = if mid {
            (
                Stepper::midpoint(actuated, dt).unwrap(),
                Stepper::midpoint(plain, dt).unwrap(),
            )
        } else {
            (
                Stepper::new(actuated, dt).unwrap(),
                Stepper::new(plain, dt).unwrap(),
            )
        };
        for z in states {
            let a = state_bits(&sa.step_forced(z, &zero).unwrap());
            let b = state_bits(&sb.step(z).unwrap());
            let c = state_bits(&sa.step(z).unwrap());
            assert_eq!(a, b, "{name} mid={mid}");
            assert_eq!(c, b, "{name} mid={mid} (step)");
        }
        let mut ra = [states[0]; 20];
        let mut rb = ra;
        sa.steps_forced_into(&states[0], &[zero; 20], &mut ra)
            .unwrap();
        sb.steps_into(&states[0], &mut rb).unwrap();
        for (a, b) in ra.iter().zip(&rb) {
            assert_eq!(state_bits(a), state_bits(b), "{name} mid={mid} rollout");
        }
    }
}

#[test]
fn zero_input_is_the_unactuated_mechanism_bit_for_bit() {
    let (a, p) = (TorquePendulum::default(), PlainPendulum::default());
    let (actuated, plain) = ((a.minimal(), a.maximal()), (p.minimal(), p.maximal()));
    bitwise_views::<_, _, _, _, 1, 0, 3, 2, 1>("pendulum", actuated, plain);
    let (a, p) = (DriveFourbar::default(), TwinFourbar::default());
    let (actuated, plain) = ((a.minimal(), a.maximal()), (p.minimal(), p.maximal()));
    bitwise_views::<_, _, _, _, 4, 2, 12, 10, 2>("fourbar", actuated, plain);
    let (a, p) = (DriveSliderCrank::default(), SliderCrank::default());
    let (actuated, plain) = ((a.minimal(), a.maximal()), (p.minimal(), p.maximal()));
    bitwise_views::<_, _, _, _, 3, 2, 9, 8, 2>("slider-crank", actuated, plain);
}

/// [`bitwise`] in both views: the actuated (minimal, maximal) pair against
/// the plain one at 5 random consistent states (seed 9) of the plain
/// minimal view, and at their maximal images.
fn bitwise_views<
    A,
    P,
    AX,
    PX,
    const N: usize,
    const C: usize,
    const NM: usize,
    const CM: usize,
    const U: usize,
>(
    name: &str,
    actuated: (A, AX),
    plain: (P, PX),
) where
    A: Dynamics<N, C> + Copy + vigp::Inputs<U>,
    P: Dynamics<N, C> + Mechanism<N, C> + Coordinates<N, NM> + Copy,
    AX: Dynamics<NM, CM> + Copy + vigp::Inputs<U>,
    PX: Dynamics<NM, CM> + Copy,
{
    let (s, x) = minimal_and_maximal_states::<_, N, C, NM>(&plain.0, 9, 5, 0.01);
    bitwise::<_, _, N, C, U>(&format!("{name} minimal"), actuated.0, plain.0, &s);
    bitwise::<_, _, NM, CM, U>(&format!("{name} maximal"), actuated.1, plain.1, &x);
}

/// A damped pendulum under a constant torque u settles where gravity's
/// torque balances it, m g l_c sin θ = u. The discrete equilibrium of the
/// forced DEL equations (v = 0) is exactly the continuous one, so after
/// the transient has decayed (rate c/(2 I_pivot) = 3/s; 20 s) the angle
/// matches to 1e-8 (both rules, both views).
#[test]
fn constant_torque_settles_at_the_static_equilibrium() {
    let sys = TorquePendulum::default();
    let (m, g, lc) = (1.0, 9.81, 0.5);
    let dt = 0.01;
    for u0 in [2.0, -3.5] {
        let u = SVector::<f64, 1>::new(u0);
        let target = u0 / (m * g * lc);
        let inputs = vec![u; 2000];
        for mid in [false, true] {
            let z0 = State::new([0.0], [0.0]);
            let min = vi_rule(sys.minimal(), dt, mid);
            let traj = min.rollout_forced(&z0, &inputs).unwrap();
            let theta = traj.last().unwrap().q[0];
            let err = (theta.sin() - target).abs();
            println!("u = {u0}, mid = {mid}: minimal |sin θ − u/(m g l_c)| = {err:.1e}");
            assert!(err <= 1e-8, "minimal mid={mid}: {err:.2e}");
            let max = vi_rule(sys.maximal(), dt, mid);
            let traj = max
                .rollout_forced(&sys.minimal().to_maximal(&z0, dt), &inputs)
                .unwrap();
            let theta = traj.last().unwrap().q[2];
            let err = (theta.sin() - target).abs();
            println!("u = {u0}, mid = {mid}: maximal |sin θ − u/(m g l_c)| = {err:.1e}");
            assert!(err <= 1e-8, "maximal mid={mid}: {err:.2e}");
        }
    }
}

/// Times of the upward crossings of `level` by the samples (linear
/// interpolation between samples).
fn crossings(xs: &[f64], dt: f64, level: f64) -> Vec<f64> {
    let mut out = Vec::new();
    for (k, w) in xs.windows(2).enumerate() {
        let (a, b) = (w[0] - level, w[1] - level);
        if a < 0.0 && b >= 0.0 {
            out.push((k as f64 + a / (a - b)) * dt);
        }
    }
    out
}

/// A torsion spring with rest angle s0 and no gravity: θ oscillates about
/// s0 with period T = 2π √(I_pivot / k). The midpoint VI is the implicit
/// midpoint rule on this linear oscillator, whose discrete period is
/// 2πh / arccos((1 − ω²h²/4)/(1 + ω²h²/4)) = T(1 + ω²h²/12 + O(h⁴)): the
/// measured period must show that O(Δt²) error (ratio 4 when Δt halves)
/// and match the discrete closed form to 1e-6 s (linear interpolation of
/// the crossings, error O(Δt³) at a zero of the second derivative).
#[test]
fn spring_oscillates_about_its_rest_angle_with_the_closed_form_period() {
    let sys = SpringRod::default();
    let (k, s0): (f64, f64) = (4.0, 0.5);
    let inertia: f64 = 1.0 / 12.0 + 0.25;
    let omega = (k / inertia).sqrt();
    let period = 2.0 * std::f64::consts::PI / omega;
    let mut errors = Vec::new();
    for dt in [0.01, 0.005] {
        let vi = Variational::midpoint(sys.minimal(), dt).unwrap();
        let z0 = State::new([s0 + 0.3], [0.0]);
        let steps = (10.0 * period / dt) as usize;
        let traj = vigp::Integrator::rollout(&vi, &z0, steps).unwrap();
        let theta: Vec<f64> = traj.iter().map(|z| z.q[0]).collect();
        // oscillation about s0: symmetric extremes
        let (lo, hi) = theta
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(
            ((lo + hi) / 2.0 - s0).abs() < 1e-3,
            "centre {}",
            (lo + hi) / 2.0
        );
        let c = crossings(&theta, dt, s0);
        let measured = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        let wh: f64 = omega * dt;
        let discrete = 2.0 * std::f64::consts::PI * dt
            / ((1.0 - wh * wh / 4.0) / (1.0 + wh * wh / 4.0)).acos();
        println!(
            "dt = {dt}: period {measured:.9} s, discrete closed form {discrete:.9}, continuous {period:.9}"
        );
        assert!(
            (measured - discrete).abs() < 1e-6,
            "{measured} vs {discrete}"
        );
        errors.push((measured - period).abs());
    }
    let ratio = errors[0] / errors[1];
    println!("period error ratio (Δt halved): {ratio:.3}");
    assert!((3.8..4.2).contains(&ratio), "ratio {ratio}");
}

fn fd_eps() -> f64 {
    std::env::var("FD_EPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1e-4)
}

/// A and B of a forced step (`Variational::step_derivatives`, the core
/// `Stepper` underneath) against five-point central differences of the
/// step, for random states and inputs. The steps are solved to 1e-14 and
/// the difference step is 1e-4 (relative to each entry's scale, at least
/// 1): the truncation error O(ε⁴) and the solver noise (~1e-13/1e-4 for
/// the constrained systems, whose converged velocities carry the
/// constraint residual divided by Δt) are well below the 1e-6 relative
/// acceptance bound. (Plain central differences at ε = 1e-5 reach only
/// ~2e-6 on the four-bar with sub-steps: truncation and noise both near
/// 1e-6 there.)
fn check_derivatives<M, const N: usize, const C: usize, const U: usize>(
    name: &str,
    m: M,
    states: &[State<N>],
    substeps: usize,
) -> f64
where
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
{
    let dt = 0.01;
    let mut rng = Rng(23);
    let mut worst = 0.0f64;
    for mid in [false, true] {
        let vi = vi_rule(m, dt, mid)
            .tolerance(1e-14)
            .unwrap()
            .substeps(substeps)
            .unwrap();
        for z in states {
            let u = SVector::<f64, U>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
            let (z1, d) = vi.step_derivatives(z, &u).unwrap();
            assert_eq!(z1, vi.step_forced(z, &u).unwrap());
            let (e, e_b) = ab_errors(z, &u, &d, fd_eps(), |z, u| vi.step_forced(z, u).unwrap());
            assert!(e <= 1e-6, "{name} mid={mid}: A relative error {e:.2e}");
            if U > 0 {
                assert!(e_b <= 1e-6, "{name} mid={mid}: B relative error {e_b:.2e}");
            }
            worst = worst.max(e).max(if U > 0 { e_b } else { 0.0 });
        }
    }
    println!("{name} (substeps {substeps}): worst relative |A − A_fd|, |B − B_fd| = {worst:.1e}");
    worst
}

#[test]
fn step_derivatives_match_central_differences() {
    let dt = 0.01;
    on_actuated_views!(check_derivatives(1), 31, 3, dt);
    // unactuated (U = 0: A alone), and sub-steps
    let (s, _) =
        minimal_and_maximal_states::<_, 1, 0, 3>(&SpringRod::default().minimal(), 31, 3, dt);
    check_derivatives::<_, 1, 0, 0>("spring rod minimal", SpringRod::default().minimal(), &s, 1);
    let (s, _) =
        minimal_and_maximal_states::<_, 2, 0, 6>(&DriveCartpole::default().minimal(), 31, 3, dt);
    check_derivatives::<_, 2, 0, 1>(
        "cartpole minimal",
        DriveCartpole::default().minimal(),
        &s,
        3,
    );
    let (s, _) =
        minimal_and_maximal_states::<_, 4, 2, 12>(&DriveFourbar::default().minimal(), 31, 3, dt);
    check_derivatives::<_, 4, 2, 2>("fourbar minimal", DriveFourbar::default().minimal(), &s, 2);
}

/// The K-step rollout derivatives (∂z_K/∂z_0 and ∂z_K/∂u_j, chained through
/// the carried momentum) against central differences of the whole forced
/// rollout, both rules, a tree and a loop.
fn check_rollout<M, const N: usize, const C: usize, const U: usize>(name: &str, m: M, z0: &State<N>)
where
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
{
    let dt = 0.01;
    let k_steps = 6;
    let mut rng = Rng(41);
    let inputs: Vec<SVector<f64, U>> = (0..k_steps)
        .map(|_| SVector::from_fn(|_, _| rng.uniform(-3.0, 3.0)))
        .collect();
    for mid in [false, true] {
        let vi = vi_rule(m, dt, mid).tolerance(1e-14).unwrap();
        let d = vi.rollout_derivatives(z0, &inputs).unwrap();
        let traj = vi.rollout_forced(z0, &inputs).unwrap();
        // the same steps, Newton started differently: equal to the solver
        // tolerance
        for (a, b) in d.states.iter().zip(&traj) {
            assert!((a.q - b.q).amax() <= 1e-12 && (a.v - b.v).amax() <= 1e-10);
        }
        let last = |z: &State<N>, us: &[SVector<f64, U>]| {
            *vi.rollout_forced(z, us).unwrap().last().unwrap()
        };
        let eps = 1e-5;
        let mut worst = 0.0f64;
        // ∂z_K/∂v_0 column j and ∂z_K/∂q_0 column j
        let jk = &d.initial[k_steps];
        let scale = jacobian_amax(jk);
        for j in 0..N {
            for pos in [true, false] {
                let p = last(&nudged(z0, j, pos, eps), &inputs);
                let q = last(&nudged(z0, j, pos, -eps), &inputs);
                let dq = (p.q - q.q) / (2.0 * eps);
                let dv = (p.v - q.v) / (2.0 * eps);
                let (eq, ev) = if pos {
                    (jk.q_q.column(j) - dq, jk.v_q.column(j) - dv)
                } else {
                    (jk.q_v.column(j) - dq, jk.v_v.column(j) - dv)
                };
                worst = worst.max(eq.amax().max(ev.amax()) / scale);
            }
        }
        for (j, bj) in d.inputs[k_steps].iter().enumerate() {
            let bscale = bj.q_u.amax().max(bj.v_u.amax());
            for i in 0..U {
                let (mut up, mut um) = (inputs.clone(), inputs.clone());
                up[j][i] += eps;
                um[j][i] -= eps;
                let (p, q) = (last(z0, &up), last(z0, &um));
                let eq = bj.q_u.column(i) - (p.q - q.q) / (2.0 * eps);
                let ev = bj.v_u.column(i) - (p.v - q.v) / (2.0 * eps);
                worst = worst.max(eq.amax().max(ev.amax()) / bscale);
            }
        }
        println!(
            "{name} mid={mid}: {k_steps}-step rollout derivatives, worst relative error {worst:.1e}"
        );
        assert!(worst <= 1e-6, "{name} mid={mid}: {worst:.2e}");
    }
}

#[test]
fn rollout_derivatives_match_central_differences() {
    let dt = 0.01;
    let cp = DriveCartpole::default().minimal();
    check_rollout::<_, 2, 0, 1>("cartpole minimal", cp, &State::new([0.1, 2.5], [0.3, -0.4]));
    let fb = DriveFourbar::default().minimal();
    let (s, _) = minimal_and_maximal_states::<_, 4, 2, 12>(&fb, 43, 1, dt);
    check_rollout::<_, 4, 2, 2>("fourbar minimal", fb, &s[0]);
}

/// Non-finite inputs are typed errors, not NaN states.
#[test]
fn non_finite_inputs_are_refused() {
    let vi = Variational::new(TorquePendulum::default().minimal(), 0.01).unwrap();
    let z = State::new([0.1], [0.0]);
    for bad in [f64::NAN, f64::INFINITY] {
        let e = vi
            .step_forced(&z, &SVector::<f64, 1>::new(bad))
            .unwrap_err();
        assert!(matches!(e, vigp::StepError::NonFiniteInput { .. }), "{e}");
        assert!(
            vi.step_derivatives(&z, &SVector::<f64, 1>::new(bad))
                .is_err()
        );
    }
    let e = vi
        .rollout_forced(
            &z,
            &[
                SVector::<f64, 1>::new(1.0),
                SVector::<f64, 1>::new(f64::NAN),
            ],
        )
        .unwrap_err();
    assert!(
        matches!(e, vigp::StepError::NonFiniteInput { step: Some(1) }),
        "{e}"
    );
}

/// The explicit integrators report an acceleration that overflows (a
/// velocity of 1e200 squared, an input of 1e300) as a non-finite state,
/// not as a singular Newton matrix they do not have.
#[test]
fn explicit_integrators_report_overflow_as_a_non_finite_state() {
    use vigp::{ExplicitEuler, Integrator, Rk4, SymplecticEuler};
    let m = DriveCartpole::default().minimal();
    let fast = State::new([0.0, 0.3], [0.0, 1e200]);
    let z = State::new([0.0, 0.3], [0.0, 0.0]);
    let huge = SVector::<f64, 1>::new(1e300);
    let check =
        |e: vigp::StepError| assert!(matches!(e, vigp::StepError::NonFiniteState { .. }), "{e:?}");
    check(Rk4::new(m, 0.01).step(&fast).unwrap_err());
    check(Rk4::new(m, 0.01).step_forced(&z, &huge).unwrap_err());
    check(SymplecticEuler::new(m, 0.01).step(&fast).unwrap_err());
    check(ExplicitEuler::new(m, 0.01).step(&fast).unwrap_err());
    check(vigp::dynamics::acceleration(&m, &fast.q, &fast.v).unwrap_err());
}

/// For the first-order rule a step with k sub-steps is k steps of Δt/k
/// (the momentum M(x)v carried between sub-steps is that of the state),
/// so its derivatives are the product of the sub-steps' derivatives: an
/// exact algebraic check of the sub-step chain (rounding only: 1e-10).
#[test]
fn substep_derivatives_are_the_chain_of_smaller_steps() {
    let dt = 0.01;
    let fb = DriveFourbar::default().minimal();
    let (s, _) = minimal_and_maximal_states::<_, 4, 2, 12>(&fb, 31, 3, dt);
    let u = SVector::<f64, 2>::new(1.5, -0.7);
    let two = Variational::new(fb, dt)
        .unwrap()
        .tolerance(1e-14)
        .unwrap()
        .substeps(2)
        .unwrap();
    let half = Variational::new(fb, dt / 2.0)
        .unwrap()
        .tolerance(1e-14)
        .unwrap();
    for z in &s {
        let (z2, d2) = two.step_derivatives(z, &u).unwrap();
        let (za, da) = half.step_derivatives(z, &u).unwrap();
        let (zb, db) = half.step_derivatives(&za, &u).unwrap();
        assert!((z2.v - zb.v).amax() < 1e-11);
        let a = db.a.after(&da.a);
        let b = db.a.times_input(&da.b);
        let b_qu = b.q_u + db.b.q_u;
        let b_vu = b.v_u + db.b.v_u;
        let scale = a.v_q.amax().max(a.v_v.amax());
        let e = [
            (a.q_q - d2.a.q_q).amax(),
            (a.q_v - d2.a.q_v).amax(),
            (a.v_q - d2.a.v_q).amax(),
            (a.v_v - d2.a.v_v).amax(),
            (b_qu - d2.b.q_u).amax(),
            (b_vu - d2.b.v_u).amax(),
        ];
        println!("chain vs sub-steps: {e:?} (scale {scale:.2e})");
        for x in e {
            assert!(x <= 1e-10 * scale, "{e:?}");
        }
    }
}

/// Every integrator takes inputs. The classical ones integrate
/// M q̈ = f + B(q)u: a damped pendulum under a constant torque settles at
/// the same equilibrium sin θ = u/(m g l_c) (their fixed point is exact
/// too), and the fourth-order composition's forced step with constant u
/// converges at fourth order to a fine reference (error ratio ≥ 12 when Δt
/// halves, 16 asymptotically). u = 0 is each integrator's plain step.
#[test]
fn every_integrator_takes_inputs() {
    use vigp::{Composition, ExplicitEuler, Integrator, Rk4, SymplecticEuler};
    let sys = TorquePendulum::default();
    let m = sys.minimal();
    let u = SVector::<f64, 1>::new(2.0);
    let target = 2.0 / (9.81 * 0.5);
    let z0 = State::new([0.0], [0.0]);
    fn settle<I: Integrator<State = State<1>>>(
        name: &str,
        i: &I,
        z0: &State<1>,
        u: &SVector<f64, 1>,
        target: f64,
    ) where
        I::Mechanism: vigp::Inputs<1>,
    {
        let mut out = vec![*z0; 3000];
        i.rollout_forced_into(z0, &vec![*u; 3000], &mut out)
            .unwrap();
        let err = (out.last().unwrap().q[0].sin() - target).abs();
        println!("{name}: |sin θ − u/(m g l_c)| = {err:.1e}");
        assert!(err <= 1e-8, "{name}: {err:.2e}");
        let zero = SVector::<f64, 1>::zeros();
        assert_eq!(
            i.step_forced(&out[10], &zero).unwrap(),
            i.step(&out[10]).unwrap()
        );
    }
    settle(
        "explicit Euler",
        &ExplicitEuler::new(m, 0.005),
        &z0,
        &u,
        target,
    );
    settle(
        "symplectic Euler",
        &SymplecticEuler::new(m, 0.005),
        &z0,
        &u,
        target,
    );
    settle("RK4", &Rk4::new(m, 0.01), &z0, &u, target);
    settle(
        "Composition",
        &Composition::new(m, 0.01).unwrap(),
        &z0,
        &u,
        target,
    );
    settle(
        "Variational",
        &Variational::midpoint(m, 0.01).unwrap(),
        &z0,
        &u,
        target,
    );
    // fourth order under a constant input (undamped spring-free acrobot)
    let a = Acrobot::default().minimal();
    let z = State::new([0.4, -0.3], [0.0, 0.0]);
    let ua = SVector::<f64, 1>::new(1.3);
    let t_end = 0.5;
    let run = |dt: f64| {
        let vi = Composition::new(a, dt).unwrap();
        let n = (t_end / dt).round() as usize;
        let mut out = vec![z; n];
        vi.rollout_forced_into(&z, &vec![ua; n], &mut out).unwrap();
        out[n - 1].q
    };
    let reference = run(0.0005);
    let (e1, e2) = (
        (run(0.02) - reference).amax(),
        (run(0.01) - reference).amax(),
    );
    println!(
        "Composition forced: errors {e1:.2e}, {e2:.2e}, ratio {:.1}",
        e1 / e2
    );
    assert!(e1 / e2 >= 12.0, "ratio {}", e1 / e2);
}

/// Forced steps, forced rollouts and the step derivatives run without heap
/// allocation (the embedded engine underneath `Variational`), loops
/// included.
#[test]
fn forced_steps_and_derivatives_do_not_allocate() {
    let dt = 0.01;
    let fb = DriveFourbar::default().minimal();
    let (s, _) = minimal_and_maximal_states::<_, 4, 2, 12>(&fb, 7, 1, dt);
    let u = SVector::<f64, 2>::new(0.4, -0.2);
    let inputs = [u; 30];
    let mut out = [s[0]; 30];
    for vi in [
        Variational::new(fb, dt).unwrap(),
        Variational::midpoint(fb, dt).unwrap(),
    ] {
        let stepper = *vi.stepper();
        let p0 = stepper.momentum(&s[0]);
        // the K-step rollout derivatives into caller-owned buffers
        const K: usize = 8;
        let mut states = [s[0]; K];
        let mut initial = [vigp::embedded::StateJacobian::<4>::zeros(); K];
        let mut wrt_u = [vigp::embedded::InputJacobian::<4, 2>::zeros(); K * K];
        let mut momentum = [SMatrix::<f64, 4, 2>::zeros(); K];
        let info = allocation_counter::measure(|| {
            let z1 = vi.step_forced(&s[0], &u).unwrap();
            let _ = vi.step_derivatives(&z1, &u).unwrap();
            vi.rollout_forced_into(&s[0], &inputs, &mut out).unwrap();
            let _ = stepper
                .step_with_momentum_derivatives(&s[0], &p0, &u)
                .unwrap();
            let buffers = vigp::embedded::RolloutDerivativeBuffers {
                states: &mut states,
                initial: &mut initial,
                inputs: &mut wrt_u,
            };
            stepper
                .rollout_derivatives_into(&s[0], &inputs[..K], buffers, &mut momentum)
                .unwrap();
        });
        assert_eq!(info.count_total, 0, "forced steps / derivatives allocated");
        // the std rollout derivatives (checked against differences in
        // `rollout_derivatives_match_central_differences`) are these
        let d = vi.rollout_derivatives(&s[0], &inputs[..K]).unwrap();
        assert_eq!(&d.states[1..], &states[..]);
        assert_eq!(&d.initial[1..], &initial[..]);
        for k in 0..K {
            assert_eq!(&d.inputs[k + 1][..], &wrt_u[k * K..(k + 1) * K]);
        }
        // buffers of the wrong length: an error before any step
        let buffers = vigp::embedded::RolloutDerivativeBuffers {
            states: &mut states[..K - 1],
            initial: &mut initial,
            inputs: &mut wrt_u,
        };
        let e = stepper
            .rollout_derivatives_into(&s[0], &inputs[..K], buffers, &mut momentum)
            .unwrap_err();
        assert!(
            matches!(e.error, vigp::StepError::InvalidOptions(_)) && e.step == 0,
            "{e:?}"
        );
    }
    // in maximal coordinates (N = 12, C = 10) the std forced step and the
    // step with derivatives keep their 24 KB workspace per thread: the
    // thread's first such call allocates it (once: the box, and the
    // thread's list on its first use); the calls after it do not allocate
    let fbm = DriveFourbar::default().maximal();
    let zm = fb.to_maximal(&s[0], dt);
    for (i, vi) in [
        Variational::new(fbm, dt).unwrap(),
        Variational::midpoint(fbm, dt).unwrap(),
    ]
    .iter()
    .enumerate()
    {
        let first = allocation_counter::measure(|| {
            let _ = vi.step_forced(&zm, &u).unwrap();
        });
        // none after the thread's first (the same workspace type); none at
        // all would mean the step no longer keeps its workspace
        let expected = if i == 0 { 1..=2 } else { 0..=0 };
        assert!(
            expected.contains(&first.count_total),
            "first forced step: {first:?}"
        );
        let info = allocation_counter::measure(|| {
            let z1 = vi.step_forced(&zm, &u).unwrap();
            let _ = vi.step_derivatives(&z1, &u).unwrap();
            let _ = vi.step_forced(&z1, &u).unwrap();
        });
        assert_eq!(info.count_total, 0, "maximal forced steps allocated");
    }
}

/// The bits of a state and of a step's derivatives, in one list.
fn bits<const N: usize, const U: usize>(
    z: &State<N>,
    d: Option<&vigp::embedded::StepDerivatives<N, U>>,
) -> Vec<u64> {
    let mut out = state_bits(z);
    if let Some(d) = d {
        for m in [&d.a.q_q, &d.a.q_v, &d.a.v_q, &d.a.v_v] {
            out.extend(m.iter().map(|x| x.to_bits()));
        }
        for m in [&d.b.q_u, &d.b.v_u] {
            out.extend(m.iter().map(|x| x.to_bits()));
        }
    }
    out
}

/// Forced steps and steps with derivatives in a kept workspace
/// (`Stepper::step_forced_in`, `Stepper::step_with_derivatives_in`, which
/// the std `Variational::step_forced` and `step_derivatives` use for the
/// larger systems) give the bits of the same steps in a fresh workspace:
/// the maximal driven fourbar (N = 12, C = 10, damped: the Newton matrix is
/// not diagonal) under both rules, and the unactuated maximal fourbar
/// (U = 0), interleaved through one workspace, so that every step finds it
/// as another stepper, input or state left it. A non-finite state or input
/// is the typed error of the fresh step.
#[test]
fn kept_workspace_forced_steps_equal_fresh_ones_bit_for_bit() {
    let dt = 0.01;
    let fb = DriveFourbar::default();
    let (_, zs) = minimal_and_maximal_states::<_, 4, 2, 12>(&fb.minimal(), 11, 6, dt);
    let twin = TwinFourbar::default().maximal();
    let steppers = [
        Stepper::new(fb.maximal(), dt).unwrap(),
        Stepper::midpoint(fb.maximal(), dt).unwrap(),
    ];
    let plain = Stepper::new(twin, dt).unwrap();
    let mut ws = vigp::embedded::StepWorkspace::<12, 10>::new();
    let none = SVector::<f64, 0>::zeros();
    let mut rng = Rng(5);
    let vis = [
        Variational::new(fb.maximal(), dt).unwrap(),
        Variational::midpoint(fb.maximal(), dt).unwrap(),
    ];
    for (k, z) in zs.iter().enumerate() {
        let u = SVector::<f64, 2>::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
        for (s, vi) in steppers.iter().zip(&vis) {
            let kept = s.step_forced_in(z, &u, &mut ws).unwrap();
            let fresh = s.step_forced(z, &u).unwrap();
            assert_eq!(
                bits::<12, 0>(&kept, None),
                bits::<12, 0>(&fresh, None),
                "state {k}"
            );
            // the momentum from the public `momentum` and the solve in a
            // fresh workspace give the same bits
            let (zp, _, _) = s.step_forced_with_momentum(z, &s.momentum(z), &u).unwrap();
            assert_eq!(bits::<12, 0>(&zp, None), bits::<12, 0>(&fresh, None));
            let (zk, dk) = s.step_with_derivatives_in(z, &u, &mut ws).unwrap();
            let (zf, df) = s.step_with_derivatives(z, &u).unwrap();
            assert_eq!(bits(&zk, Some(&dk)), bits(&zf, Some(&df)), "state {k}");
            // the std runtime's steps (kept per thread) give the same bits
            assert_eq!(
                bits::<12, 0>(&vi.step_forced(z, &u).unwrap(), None),
                bits::<12, 0>(&fresh, None)
            );
            let (zv, dv) = vi.step_derivatives(z, &u).unwrap();
            assert_eq!(bits(&zv, Some(&dv)), bits(&zf, Some(&df)));
        }
        let kept = plain.step_forced_in(z, &none, &mut ws).unwrap();
        assert_eq!(
            bits::<12, 0>(&kept, None),
            bits::<12, 0>(&plain.step(z).unwrap(), None)
        );
        let (zk, dk) = plain.step_with_derivatives_in(z, &none, &mut ws).unwrap();
        let (zf, df) = plain.step_with_derivatives(z, &none).unwrap();
        assert_eq!(bits(&zk, Some(&dk)), bits(&zf, Some(&df)));
    }
    let mut bad = zs[0];
    bad.v[3] = f64::NAN;
    let u = SVector::<f64, 2>::new(0.1, 0.2);
    assert_eq!(
        steppers[0].step_forced_in(&bad, &u, &mut ws).unwrap_err(),
        steppers[0].step_forced(&bad, &u).unwrap_err()
    );
    let inf = SVector::<f64, 2>::new(f64::INFINITY, 0.0);
    assert_eq!(
        steppers[0]
            .step_forced_in(&zs[0], &inf, &mut ws)
            .unwrap_err(),
        steppers[0].step_forced(&zs[0], &inf).unwrap_err()
    );
    assert_eq!(
        steppers[1]
            .step_with_derivatives_in(&bad, &u, &mut ws)
            .unwrap_err(),
        steppers[1].step_with_derivatives(&bad, &u).unwrap_err()
    );
}

/// The learned integrator with inputs: a "true" cartpole (masses ×1.1,
/// pole inertia ×0.9, more rail friction) driven by random piecewise
/// constant forces gives transitions with their inputs; the GP learns the
/// residual of the nominal forced step (GP input = encoded state + u). On
/// held-out states and inputs its one-step velocity error against the true
/// system must be well below the nominal model's (≤ 1/5 of it: the
/// residual is smooth and well sampled), its exact derivatives must match
/// five-point differences (ε = 1e-3: relative 1e-6), the learned step under u = 0
/// must not equal the one under u (the input is used), and the model file
/// round-trips with its inputs.
#[test]
fn learned_integrator_takes_inputs() {
    use vigp::learned::{Encoding, ForcedTransition, Learned, Prior, forced_transitions};
    let dt = 0.01;
    let nominal = DriveCartpole::default();
    let mut truth = nominal;
    truth.links.cart.mass *= 1.1;
    truth.links.pole.mass *= 1.1;
    truth.links.pole.inertia *= 0.9;
    truth.joints.rail.damping = 0.4;
    let true_vi = Variational::new(truth.minimal(), dt).unwrap();
    let nominal_vi = Variational::new(nominal.minimal(), dt).unwrap();
    let mut rng = Rng(77);
    let mut data = Vec::new();
    for _ in 0..4 {
        let mut z = State::new([rng.uniform(-0.5, 0.5), rng.uniform(-1.0, 1.0)], [0.0, 0.0]);
        let mut positions = vec![z.q];
        let mut logged = vec![SVector::<f64, 1>::zeros()];
        let mut u = SVector::<f64, 1>::zeros();
        for k in 0..120 {
            if k % 10 == 0 {
                u = SVector::<f64, 1>::new(rng.uniform(-4.0, 4.0));
            }
            z = true_vi.step_forced(&z, &u).unwrap();
            positions.push(z.q);
            // the input logged at the sample where the step's new
            // velocity interval starts (data docs: Run::step_input)
            logged.push(u);
        }
        data.extend(forced_transitions(&positions, &logged, dt));
    }
    // the indexing of forced_transitions matches the simulation
    let t0: ForcedTransition<2, 1> = data[0];
    let again = true_vi.step_forced(&t0.z, &t0.u).unwrap();
    assert!((again.v - t0.v_next).amax() < 1e-9);
    // and the previous input is the one logged a row earlier
    let t1: ForcedTransition<2, 1> = data[1];
    assert_eq!(t1.u_prev, t0.u);
    // measurement noise on the velocities (σ = 1e-4, uniform): it keeps
    // the GP's noise variance, and with it the weights α, moderate, so
    // that the learned step can be checked against finite differences
    // (noise-free data drives σ_n² → 0 and α up, and the mean's rounding
    // through Σ α_i k_i then limits differences to ~1e-5)
    let data: Vec<_> = data
        .iter()
        .step_by(2)
        .map(|t| {
            let mut t = *t;
            for x in t.v_next.iter_mut() {
                *x += rng.uniform(-1.7e-4, 1.7e-4);
            }
            t
        })
        .collect();
    let options = common::train_options(2, 3);
    let (l, _) = Learned::train_forced(
        nominal.minimal(),
        dt,
        &data,
        Encoding::SinCos,
        Prior::Nominal,
        &options,
    )
    .unwrap();
    assert_eq!(l.inputs(), 1);
    let mut ws = l.workspace();
    let (mut e_learned, mut e_nominal) = (0.0f64, 0.0f64);
    for _ in 0..100 {
        let z = State::new(
            [rng.uniform(-0.5, 0.5), rng.uniform(-1.0, 1.0)],
            [rng.uniform(-0.5, 0.5), rng.uniform(-1.5, 1.5)],
        );
        let u = SVector::<f64, 1>::new(rng.uniform(-4.0, 4.0));
        let target = true_vi.step_forced(&z, &u).unwrap().v;
        // the first-order VI's step does not depend on the previous input:
        // the one held over z's velocity interval, here u itself
        let learned = l.step_mean_forced_in(&z, &u, &u, &mut ws).unwrap().v;
        let nominal_next = nominal_vi.step_forced(&z, &u).unwrap().v;
        e_learned += (learned - target).norm_squared();
        e_nominal += (nominal_next - target).norm_squared();
    }
    let (e_learned, e_nominal) = ((e_learned / 100.0).sqrt(), (e_nominal / 100.0).sqrt());
    println!(
        "one-step RMS |Δv| against the true system: learned {e_learned:.2e}, nominal {e_nominal:.2e}"
    );
    assert!(
        e_learned < 0.2 * e_nominal,
        "{e_learned:e} vs {e_nominal:e}"
    );
    // exact derivatives of the learned step (nominal forced step's + GP
    // mean gradient through the encoding) against five-point differences
    let mut worst = 0.0f64;
    for _ in 0..5 {
        let z = State::new(
            [rng.uniform(-0.5, 0.5), rng.uniform(-1.0, 1.0)],
            [rng.uniform(-0.5, 0.5), rng.uniform(-1.5, 1.5)],
        );
        let u = SVector::<f64, 1>::new(rng.uniform(-4.0, 4.0));
        let up = SVector::<f64, 1>::new(rng.uniform(-4.0, 4.0));
        let (z1, d, dp) = l.step_derivatives_forced(&z, &up, &u, &mut ws).unwrap();
        assert_eq!(z1, l.step_mean_forced_in(&z, &up, &u, &mut ws).unwrap());
        let mut ws2 = l.workspace();
        let (err, scale) = a_stencil_errors(&z, &d.a, 1e-3, |zp| {
            l.step_mean_forced_in(zp, &up, &u, &mut ws2).unwrap()
        });
        let (dq, dv) = stencil(1e-3, |e| {
            l.step_mean_forced_in(&z, &up, &(u + SVector::<f64, 1>::new(e)), &mut ws2)
                .unwrap()
        });
        let eb = (d.b.q_u.column(0) - dq)
            .amax()
            .max((d.b.v_u.column(0) - dv).amax());
        let bscale = dv.amax();
        // ∂z₁/∂u_prev: the truth does not depend on u_prev, so the GP's
        // dependence is small; compare against the whole of B's scale
        let (pq, pv) = stencil(1e-3, |e| {
            l.step_mean_forced_in(&z, &(up + SVector::<f64, 1>::new(e)), &u, &mut ws2)
                .unwrap()
        });
        let ep = (dp.q_u.column(0) - pq)
            .amax()
            .max((dp.v_u.column(0) - pv).amax());
        println!(
            "A err {:.2e}, B err {:.2e}, B_prev err {:.2e}",
            err / scale,
            eb / bscale,
            ep / bscale
        );
        worst = worst.max(err / scale).max(eb / bscale).max(ep / bscale);
    }
    println!("learned step derivatives: worst relative error {worst:.1e}");
    assert!(worst <= 1e-6, "{worst:e}");
    // the K-step rollout derivatives (A, B and B_prev chained) against
    // five-point differences of the whole learned mean rollout
    let k_steps = 5;
    let z0 = State::new([0.1, -0.6], [0.4, 1.1]);
    let up = SVector::<f64, 1>::new(1.5);
    let plan: Vec<SVector<f64, 1>> = (0..k_steps)
        .map(|_| SVector::<f64, 1>::new(rng.uniform(-4.0, 4.0)))
        .collect();
    let rd = l
        .rollout_derivatives_forced(&z0, &up, &plan, &mut ws)
        .unwrap();
    let mut traj = vec![z0; k_steps];
    l.rollout_mean_forced_into(&z0, &up, &plan, &mut traj)
        .unwrap();
    assert_eq!(&rd.states[1..], &traj[..]);
    let last = |z: &State<2>, us: &[SVector<f64, 1>]| {
        let mut out = vec![*z; us.len()];
        l.rollout_mean_forced_into(z, &up, us, &mut out).unwrap();
        out[us.len() - 1]
    };
    let jk = &rd.initial[k_steps];
    let (err, scale) = a_stencil_errors(&z0, jk, 1e-3, |zp| last(zp, &plan));
    let mut rollout_worst = err / scale;
    for (j, bj) in rd.inputs[k_steps].iter().enumerate() {
        let (dq, dv) = stencil(1e-3, |e| {
            let mut us = plan.clone();
            us[j][0] += e;
            last(&z0, &us)
        });
        let e = (bj.q_u.column(0) - dq)
            .amax()
            .max((bj.v_u.column(0) - dv).amax());
        rollout_worst = rollout_worst.max(e / dq.amax().max(dv.amax()));
    }
    // inputs act on later states only
    assert!(
        rd.inputs[2][2..]
            .iter()
            .all(|b| b.q_u.amax() == 0.0 && b.v_u.amax() == 0.0)
    );
    println!(
        "learned {k_steps}-step rollout derivatives: worst relative error {rollout_worst:.1e}"
    );
    assert!(rollout_worst <= 1e-6, "{rollout_worst:e}");
    // the input matters, and the Integrator trait reaches it
    let z = State::new([0.0, 0.3], [0.0, 0.0]);
    let a = vigp::Integrator::step_forced(&l, &z, &SVector::<f64, 1>::new(3.0)).unwrap();
    let b = vigp::Integrator::step_forced(&l, &z, &SVector::<f64, 1>::zeros()).unwrap();
    assert!((a.v - b.v).amax() > 1e-3);
    // the model file keeps the inputs
    let json = l.to_json();
    assert!(json.contains("\"rail\""));
    let back = Learned::<_, 2, 0>::from_json(nominal.minimal(), &json).unwrap();
    assert_eq!(back.inputs(), 1);
    let c = vigp::Integrator::step_forced(&back, &z, &SVector::<f64, 1>::new(3.0)).unwrap();
    assert_eq!(a, c);
    // U = 0 is "no input" (u = 0), as for every other integrator: the
    // trait's step, the mean step, the prediction with variances, the
    // derivatives (A equal, B empty) and the rollout with information all
    // equal the calls under u = 0 bit for bit
    let none = SVector::<f64, 0>::zeros();
    let zero = SVector::<f64, 1>::zeros();
    let z = State::new([0.2, -0.4], [0.3, 0.9]);
    assert_eq!(
        vigp::Integrator::step_forced(&l, &z, &none).unwrap(),
        vigp::Integrator::step_forced(&l, &z, &zero).unwrap()
    );
    assert_eq!(
        l.step_mean_forced_in(&z, &none, &none, &mut ws).unwrap(),
        l.step_mean_in(&z, &mut ws).unwrap()
    );
    assert_eq!(
        l.predict_velocity_forced(&z, &none, &none, &mut ws)
            .unwrap(),
        l.predict_velocity_forced(&z, &zero, &zero, &mut ws)
            .unwrap()
    );
    let (z0, d0, _) = l
        .step_derivatives_forced(&z, &none, &none, &mut ws)
        .unwrap();
    let (z1, d1, _) = l
        .step_derivatives_forced(&z, &zero, &zero, &mut ws)
        .unwrap();
    assert_eq!((z0, d0.a.matrix::<4>()), (z1, d1.a.matrix::<4>()));
    let r0 = l
        .rollout_forced_with_info(&z, &none, &[none; 5], &mut ws)
        .unwrap();
    let r1 = l
        .rollout_forced_with_info(&z, &zero, &[zero; 5], &mut ws)
        .unwrap();
    assert_eq!(r0.len(), 5);
    for ((s0, i0), (s1, i1)) in r0.iter().zip(&r1) {
        assert_eq!((s0, i0.std_dev), (s1, i1.std_dev));
    }
}

/// A (B is empty: no inputs) of learned steps of unactuated tree systems
/// of the paper, with both priors and two encodings, against five-point
/// differences of the learned mean step. The training velocities carry
/// measurement noise (σ ≈ 1e-4), as in `learned_integrator_takes_inputs`,
/// so that the GP weights stay moderate and the differences are accurate.
#[test]
fn learned_step_derivatives_of_the_paper_systems() {
    use vigp::Integrator;
    use vigp::gp::TrainOptions;
    use vigp::learned::{Encoding, Learned, Prior, transitions};
    use vigp::systems::{Cartpole, DoublePendulum, Pendulum};

    fn check<M: Mechanism<N, C> + vigp::Parameters + Copy, const N: usize, const C: usize>(
        name: &str,
        nominal: M,
        truth: M,
        encoding: Encoding,
        prior: Prior,
        seed: u64,
    ) -> f64 {
        let dt = 0.01;
        let vi = Variational::new(truth, dt).unwrap();
        let mut rng = Rng(seed);
        let mut data = Vec::new();
        for _ in 0..4 {
            let z0 = State {
                q: SVector::from_fn(|_, _| rng.uniform(-1.0, 1.0)),
                v: SVector::zeros(),
            };
            let traj = vi.rollout(&z0, 60).unwrap();
            let q: Vec<SVector<f64, N>> = traj.iter().map(|z| z.q).collect();
            data.extend(transitions(&q, dt).into_iter().step_by(2).map(|mut t| {
                for x in t.v_next.iter_mut() {
                    *x += rng.uniform(-1.7e-4, 1.7e-4);
                }
                t
            }));
        }
        let options = TrainOptions {
            restarts: 1,
            seed,
            ..TrainOptions::default()
        };
        let (l, _) = Learned::train(nominal, dt, &data, encoding, prior, &options).unwrap();
        let mut ws = l.workspace();
        let mut ws2 = l.workspace();
        let u = SVector::<f64, 0>::zeros();
        // the mean's rounding (~1e-16·Σ|α_i k_i|) divided by ε limits the
        // differences: measured on the double pendulum (constant prior,
        // the largest weights) the error falls as 1/ε (1.5e-6, 9.5e-7,
        // 2.6e-7 at ε = 3e-4, 1e-3, 3e-3) while the truncation O(ε⁴) stays
        // below 1e-10 on the others
        let eps = 3e-3;
        let mut worst = 0.0f64;
        for _ in 0..3 {
            let z = State {
                q: SVector::from_fn(|_, _| rng.uniform(-0.8, 0.8)),
                v: SVector::from_fn(|_, _| rng.uniform(-1.0, 1.0)),
            };
            let (z1, d, _) = l.step_derivatives_forced(&z, &u, &u, &mut ws).unwrap();
            assert_eq!(z1, l.step_mean_forced_in(&z, &u, &u, &mut ws).unwrap());
            worst = worst.max(learned_a_error(&l, &z, &d, eps, &mut ws2));
        }
        println!("{name}: learned A, worst relative error {worst:.1e}");
        worst
    }

    let mut p = Pendulum::default();
    p.joints.pivot.damping = 0.3;
    let mut cp = Cartpole::default();
    cp.links.pole.mass *= 1.1;
    cp.joints.rail.damping = 0.4;
    let mut dp = DoublePendulum::default();
    dp.links.upper.mass *= 1.1;
    dp.joints.elbow.damping = 0.2;
    let worst = [
        check(
            "pendulum, sin/cos, nominal prior",
            Pendulum::default().minimal(),
            p.minimal(),
            Encoding::SinCos,
            Prior::Nominal,
            11,
        ),
        check(
            "cartpole, minimal, nominal prior",
            Cartpole::default().minimal(),
            cp.minimal(),
            Encoding::Raw,
            Prior::Nominal,
            12,
        ),
        check(
            "double pendulum, sin/cos, constant prior",
            DoublePendulum::default().minimal(),
            dp.minimal(),
            Encoding::SinCos,
            Prior::Constant,
            13,
        ),
    ]
    .into_iter()
    .fold(0.0f64, f64::max);
    // relative 1e-6, as for the nominal steps
    assert!(worst < 1e-6, "worst relative error {worst:e}");
}

/// The same for learned steps that project onto constraints (the fourbar's
/// loop in minimal coordinates, the double pendulum's joints in maximal
/// coordinates): the projection differentiates implicitly through its KKT
/// conditions. Trajectories of a perturbed truth give the data; the
/// derivatives are checked at states of held-out trajectories.
#[test]
fn projected_learned_step_derivatives_match_differences() {
    use vigp::Integrator;
    use vigp::learned::{Encoding, Learned, Prior, transitions};
    use vigp::systems::{DoublePendulum, Fourbar};

    fn check<M: Mechanism<N, C> + vigp::Parameters + Copy, const N: usize, const C: usize>(
        name: &str,
        nominal: M,
        runs: &[Vec<SVector<f64, N>>],
        prior: Prior,
    ) -> f64 {
        let dt = 0.01;
        let mut rng = Rng(21);
        let (train, test) = runs.split_at(runs.len() - 1);
        let mut data = Vec::new();
        for q in train {
            data.extend(transitions(q, dt).into_iter().step_by(2).map(|mut t| {
                for x in t.v_next.iter_mut() {
                    *x += rng.uniform(-1.7e-4, 1.7e-4);
                }
                t
            }));
        }
        let options = common::train_options(1, 5);
        let (l, _) = Learned::train(nominal, dt, &data, Encoding::Raw, prior, &options).unwrap();
        let (mut ws, mut ws2) = (l.workspace(), l.workspace());
        let u = SVector::<f64, 0>::zeros();
        // the fourbar's projected step has large higher derivatives: the
        // five-point error grows as ε⁴ (1.0e-8, 8.1e-7, 1.1e-4 at ε = 1e-3,
        // 3e-3, 1e-2), so a smaller ε than for the trees
        let eps = 1e-3;
        let mut worst = 0.0f64;
        for k in [5, 20, 35] {
            let q = &test[0];
            let z = common::state_at(q, k, dt);
            let (z1, d, _) = l.step_derivatives_forced(&z, &u, &u, &mut ws).unwrap();
            assert!((z1.v - l.step_mean_forced_in(&z, &u, &u, &mut ws).unwrap().v).amax() < 1e-12);
            worst = worst.max(learned_a_error(&l, &z, &d, eps, &mut ws2));
        }
        println!("{name}: projected learned A, worst relative error {worst:.1e}");
        worst
    }

    let dt = 0.01;
    let mut rng = Rng(9);
    // fourbar, minimal coordinates (a loop): runs from consistent starts
    let mut fb = Fourbar::default();
    fb.joints.top1.damping = 0.2;
    let fb_vi = Variational::new(fb.minimal(), dt).unwrap();
    let fb_runs: Vec<Vec<SVector<f64, 4>>> = (0..4)
        .map(|_| {
            // the parallelogram branch: q = (t₁, t₃ − t₁, t₃, t₁ − t₃)
            let t1 = rng.uniform(-1.0, 1.0);
            let t3 = t1 + rng.uniform(-0.2, 0.2);
            let z0 = common::at_rest(&fb.minimal(), [t1, t3 - t1, t3, t1 - t3], dt);
            fb_vi
                .rollout(&z0, 50)
                .unwrap()
                .iter()
                .map(|z| z.q)
                .collect()
        })
        .collect();
    // double pendulum, maximal coordinates (joints as constraints)
    let mut dp = DoublePendulum::default();
    dp.joints.elbow.damping = 0.2;
    let dp_vi = Variational::new(dp.minimal(), dt).unwrap();
    let dp_runs: Vec<Vec<SVector<f64, 6>>> = (0..4)
        .map(|_| {
            let z0 = State::new([rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)], [0.0, 0.0]);
            dp_vi
                .rollout(&z0, 50)
                .unwrap()
                .iter()
                .map(|z| dp.minimal().maximal_positions(&z.q))
                .collect()
        })
        .collect();
    let worst = check(
        "fourbar, minimal",
        Fourbar::default().minimal(),
        &fb_runs,
        Prior::Nominal,
    )
    .max(check(
        "double pendulum, maximal",
        DoublePendulum::default().maximal(),
        &dp_runs,
        Prior::Constant,
    ));
    assert!(worst < 1e-6, "worst relative error {worst:e}");
}

/// max |A − A_fd| / max |A_fd| of an unforced learned step at `z`: the
/// columns of the exact A (`d`) against five-point differences of the
/// learned mean step in every coordinate of q and v.
fn learned_a_error<M: Mechanism<N, C> + Clone, const N: usize, const C: usize>(
    l: &vigp::learned::Learned<M, N, C>,
    z: &State<N>,
    d: &vigp::embedded::StepDerivatives<N, 0>,
    eps: f64,
    ws: &mut vigp::gp::Workspace,
) -> f64 {
    let u = SVector::<f64, 0>::zeros();
    let (err, scale) = a_stencil_errors(z, &d.a, eps, |zp| {
        l.step_mean_forced_in(zp, &u, &u, ws).unwrap()
    });
    err / scale
}

/// `U = 0` is the input-free step for any mechanism, actuated ones
/// included: `step_forced::<0>` and `step_with_derivatives::<0>` of the
/// driven cartpole equal the step under u = 0 bit for bit (state and A),
/// in the embedded `Stepper` and the std `Variational`, on both the
/// minimal and the midpoint rule. (The learned step's bound differentiates
/// the input-free step of every model through this.)
#[test]
fn zero_length_input_is_the_input_free_step() {
    let z = State::new([0.3, -0.7], [0.4, 1.1]);
    let zero = SVector::<f64, 1>::zeros();
    let none = SVector::<f64, 0>::zeros();
    for vi in [
        Variational::new(DriveCartpole::default().minimal(), 0.01).unwrap(),
        Variational::midpoint(DriveCartpole::default().minimal(), 0.01).unwrap(),
    ] {
        let (z1, d1) = vi.step_derivatives(&z, &zero).unwrap();
        let (z0, d0) = vi.step_derivatives(&z, &none).unwrap();
        assert_eq!(z0, z1);
        assert_eq!(d0.a.matrix::<4>(), d1.a.matrix::<4>());
        assert_eq!(vi.step_forced(&z, &none).unwrap(), vi.step(&z).unwrap());
        let stepper = *vi.stepper();
        let (s1, e1) = stepper.step_with_derivatives(&z, &zero).unwrap();
        let (s0, e0) = stepper.step_with_derivatives(&z, &none).unwrap();
        assert_eq!((s0, e0.a.matrix::<4>()), (s1, e1.a.matrix::<4>()));
        assert_eq!(
            stepper.step_forced(&z, &none).unwrap(),
            stepper.step(&z).unwrap()
        );
    }
}
