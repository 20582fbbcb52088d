//! Maximal coordinates and the classical integrators, from the same
//! descriptions: energies agree between views, trajectories converge
//! together, the VIs keep constraints and energy where explicit Euler
//! drifts, and every integrator shows its order.

use crate::common;
use common::{Rng, pendulum_reference};
use nalgebra::SVector;
use vigp::dynamics::{acceleration, discrete_velocity, mass_matrix};
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

fn check_energy_views<Mn, Mx, const N: usize, const C: usize, const M: usize, const K: usize>(
    min: &Mn,
    max: &Mx,
    seed: u64,
) where
    Mn: Mechanism<N, C> + Coordinates<N, M>,
    Mx: Mechanism<M, K>,
{
    let mut rng = Rng(seed);
    for _ in 0..50 {
        let q = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let qd = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-4.0, 4.0));
        let e_min = min.energy(&State { q, v: qd });
        let x = min.maximal_positions(&q);
        let xd = min.maximal_velocity(&q, &qd);
        let e_max = max.energy(&State { q: x, v: xd });
        // 1e-12 relative to the energy scale (both are sums of O(10) terms)
        assert!(
            (e_min - e_max).abs() <= 1e-12 * (1.0 + e_min.abs()),
            "{e_min} vs {e_max}"
        );
        // maximal positions of any minimal configuration satisfy every tree
        // joint, so the maximal violation is exactly the loop violation
        let (g_max, g_min) = (
            max.constraint_violation(&State { q: x, v: xd }),
            min.constraint_violation(&State { q, v: qd }),
        );
        assert!((g_max - g_min).abs() < 1e-12, "{g_max} vs {g_min}");
        // and the minimal coordinates come back
        let back = min.minimal_positions(&x);
        let wrapped = (back - q).map(|d| {
            (d + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
        });
        assert!(wrapped.amax() < 1e-12, "round trip {back:?} vs {q:?}");
    }
}

#[test]
fn the_same_state_has_the_same_energy_in_both_views() {
    let mut p = Pendulum::default();
    p.links.rod.mass = 1.3;
    check_energy_views(&p.minimal(), &p.maximal(), 1);
    let c = Cartpole::default();
    check_energy_views(&c.minimal(), &c.maximal(), 2);
    let d = DoublePendulum::default();
    check_energy_views(&d.minimal(), &d.maximal(), 3);
    let f = Fourbar::default();
    check_energy_views(&f.minimal(), &f.maximal(), 4);
}

#[test]
fn continuous_dynamics_match_the_closed_form_pendulum() {
    let mut sys = Pendulum::default();
    sys.joints.pivot.damping = 0.4;
    let inertia = sys.links.rod.inertia + 0.25;
    let m = sys.minimal();
    let (q, qd) = (SVector::from([0.7]), SVector::from([-1.3]));
    assert!((mass_matrix(&m, &q, &qd)[(0, 0)] - inertia).abs() < 1e-14);
    let (a, _) = acceleration(&m, &q, &qd).unwrap();
    let expected = (-9.81 * 0.5 * 0.7f64.sin() - 0.4 * -1.3) / inertia;
    assert!((a[0] - expected).abs() < 1e-13, "{} vs {expected}", a[0]);
    // maximal view: the same angular acceleration, with the pin force
    let mx = sys.maximal();
    let x = m.maximal_positions(&q);
    let xd = m.maximal_velocity(&q, &qd);
    let (ax, _) = acceleration(&mx, &x, &xd).unwrap();
    assert!((ax[2] - expected).abs() < 1e-12, "{} vs {expected}", ax[2]);
    assert_eq!(
        mass_matrix(&mx, &x, &xd),
        nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 1.0 / 12.0))
    );
}

/// Max over a 1 s rollout of the distance between minimal and maximal VI
/// configurations (mapped back to minimal coordinates).
fn view_gap<Mn, Mx, const N: usize, const C: usize, const M: usize, const K: usize>(
    min: Mn,
    max: Mx,
    q0: [f64; N],
    dt: f64,
) -> f64
where
    Mn: Mechanism<N, C> + Coordinates<N, M> + Copy,
    Mx: Mechanism<M, K> + Copy,
{
    let steps = (1.0 / dt).round() as usize;
    let z0 = State::new(q0, [0.0; N]);
    let zm0 = min.to_maximal(&z0, dt);
    let a = Variational::new(min, dt)
        .unwrap()
        .rollout(&z0, steps)
        .unwrap();
    let b = Variational::new(max, dt)
        .unwrap()
        .rollout(&zm0, steps)
        .unwrap();
    a.iter()
        .zip(&b)
        .map(|(za, zb)| (min.minimal_positions(&zb.q) - za.q).amax())
        .fold(0.0, f64::max)
}

#[test]
fn minimal_and_maximal_trajectories_converge_together() {
    for (name, gaps) in [
        (
            "double pendulum",
            [0.01, 0.005, 0.0025].map(|dt| {
                view_gap(
                    DoublePendulum::default().minimal(),
                    DoublePendulum::default().maximal(),
                    [1.2, -0.4],
                    dt,
                )
            }),
        ),
        (
            "cartpole",
            [0.01, 0.005, 0.0025].map(|dt| {
                view_gap(
                    Cartpole::default().minimal(),
                    Cartpole::default().maximal(),
                    [0.3, 2.0],
                    dt,
                )
            }),
        ),
    ] {
        eprintln!(
            "{name}: max |q_min − q(X_max)| over 1 s at dt = 0.01, 0.005, 0.0025: {gaps:.3?}"
        );
        assert!(
            gaps[0] < 0.1,
            "{name}: views differ by more than O(dt): {gaps:?}"
        );
        for w in gaps.windows(2) {
            let ratio = w[0] / w[1];
            assert!(
                (1.6..=2.5).contains(&ratio),
                "{name}: gap ratio {ratio} ({gaps:?})"
            );
        }
    }
}

fn max_violation<
    I: Integrator<State = State<N>>,
    Mx: Mechanism<N, K>,
    const N: usize,
    const K: usize,
>(
    i: &I,
    m: &Mx,
    z0: &State<N>,
    steps: usize,
) -> (f64, f64) {
    let mut z = *z0;
    let mut worst = 0.0f64;
    for k in 0..steps {
        z = i.step(&z).unwrap_or_else(|e| panic!("step {k}: {e}"));
        worst = worst.max(m.constraint_violation(&z));
    }
    (worst, m.constraint_violation(&z))
}

/// Paper Fig. 1b without learning: the maximal-coordinate VI keeps
/// |g| ≤ 1e-10 every step; explicit Euler with acceleration-level
/// constraints drifts.
#[test]
fn maximal_vi_keeps_constraints_while_explicit_euler_drifts() {
    let dt = 0.01;
    let dp = DoublePendulum::default();
    let (min, max) = (dp.minimal(), dp.maximal());
    let zd = max.to_maximal_start(&min, [std::f64::consts::FRAC_PI_2, 0.0], dt);
    let (vi, _) = max_violation(&Variational::new(max, dt).unwrap(), &max, &zd, 10_000);
    let zc = State {
        q: zd.q,
        v: min.maximal_velocity(
            &SVector::from([std::f64::consts::FRAC_PI_2, 0.0]),
            &SVector::zeros(),
        ),
    };
    let (_, ee_end) = max_violation(&ExplicitEuler::new(max, dt), &max, &zc, 1_000);
    eprintln!(
        "double pendulum (maximal): VI max |g| = {vi:.2e} over 1e4 steps; explicit Euler |g| after 1e3 steps = {ee_end:.2e}"
    );
    assert!(vi <= 1e-10);
    assert!(ee_end > 1e-3, "explicit Euler should drift: {ee_end:e}");

    let fb = Fourbar::default();
    let (min, max) = (fb.minimal(), fb.maximal());
    let z0 = common::at_rest(&min, [0.9, -1.3, -0.4, 1.3], dt);
    let zm = min.to_maximal(&z0, dt);
    let zm = consistent_state(&max, &zm.q, &zm.v, dt).unwrap();
    let (vi, _) = max_violation(&Variational::new(max, dt).unwrap(), &max, &zm, 10_000);
    let zc = State {
        q: zm.q,
        v: SVector::zeros(),
    };
    let (_, ee_end) = max_violation(&ExplicitEuler::new(max, dt), &max, &zc, 300);
    eprintln!(
        "fourbar (maximal): VI max |g| = {vi:.2e} over 1e4 steps; explicit Euler |g| after 300 steps = {ee_end:.2e}"
    );
    assert!(vi <= 1e-10);
    assert!(ee_end > 1e-3, "explicit Euler should drift: {ee_end:e}");
}

trait MaximalStart<const M: usize> {
    fn to_maximal_start<Mn: Coordinates<N, M>, const N: usize>(
        &self,
        min: &Mn,
        q: [f64; N],
        dt: f64,
    ) -> State<M>;
}
impl<T, const M: usize> MaximalStart<M> for T {
    fn to_maximal_start<Mn: Coordinates<N, M>, const N: usize>(
        &self,
        min: &Mn,
        q: [f64; N],
        dt: f64,
    ) -> State<M> {
        min.to_maximal(&State::new(q, [0.0; N]), dt)
    }
}

fn energy_by_tenth<I: Integrator<State = State<N>>, const N: usize>(
    i: &I,
    energy: impl Fn(&State<N>) -> f64,
    z0: &State<N>,
    steps: usize,
) -> [f64; 10] {
    let e0 = energy(z0);
    let mut z = *z0;
    let mut t = [0.0f64; 10];
    for k in 0..steps {
        z = i.step(&z).unwrap();
        let slot = k * 10 / steps;
        t[slot] = t[slot].max((energy(&z) - e0).abs());
    }
    t
}

/// Paper Fig. 1a without learning: explicit Euler's energy grows on the
/// conservative pendulum; both VIs' stays bounded (maximal coordinates,
/// dt = 10 ms, from θ = π/2).
#[test]
fn explicit_euler_energy_grows_while_the_vis_stay_bounded() {
    let dt = 0.01;
    let p = Pendulum::default();
    let (min, max) = (p.minimal(), p.maximal());
    let z0 = min.to_maximal(&State::new([std::f64::consts::FRAC_PI_2], [0.0]), dt);
    let steps = 10_000;
    let ee = energy_by_tenth(
        &ExplicitEuler::new(max, dt),
        |z| max.energy(z),
        &State {
            q: z0.q,
            v: SVector::zeros(),
        },
        steps,
    );
    let vi = energy_by_tenth(
        &Variational::new(max, dt).unwrap(),
        |z| max.energy(z),
        &z0,
        steps,
    );
    // the midpoint rule's discrete velocity belongs to the interval midpoint
    let midpoint = Variational::midpoint(max, dt).unwrap();
    let mid = energy_by_tenth(&midpoint, |z| midpoint.energy(z), &z0, steps);
    eprintln!(
        "pendulum max |ΔE| per tenth (J):\n  explicit Euler {ee:.3?}\n  VI (1st order) {vi:.3?}\n  VI (midpoint)  {mid:.3?}"
    );
    assert!(
        ee[9] > 10.0 * ee[0],
        "explicit Euler energy should grow: {ee:?}"
    );
    assert!(
        vi[9] <= 1.5 * vi[0] && vi[9] < 0.2,
        "first-order VI energy: {vi:?}"
    );
    assert!(
        mid[9] <= 1.5 * mid[0] && mid[9] < 0.01,
        "midpoint VI energy: {mid:?}"
    );
}

/// Observed order from the errors at Δt = 1/40 and 1/160. Classical
/// integrators start from the continuous state (1, 0); the VIs from the
/// consistent discrete velocity `discrete_velocity` (q̇ + ½Δt·q̈).
fn observed_order<I: Integrator<State = State<1>>>(
    make: impl Fn(f64) -> I,
    reference: f64,
    discrete: bool,
) -> (Vec<f64>, f64) {
    let mut sys = Pendulum::default();
    sys.joints.pivot.damping = 0.3;
    let errs: Vec<f64> = [20usize, 40, 80, 160]
        .iter()
        .map(|&n| {
            let dt = 1.0 / n as f64;
            let i = make(dt);
            let q = SVector::from([1.0]);
            let v = if discrete {
                discrete_velocity(&sys.minimal(), &q, &SVector::zeros(), dt).unwrap()
            } else {
                SVector::zeros()
            };
            let traj = i.rollout(&State { q, v }, n).unwrap();
            (traj[n].q[0] - reference).abs()
        })
        .collect();
    let order = (errs[1] / errs[3]).log2() / 2.0;
    (errs, order)
}

#[test]
fn measured_convergence_orders() {
    let mut sys = Pendulum::default();
    sys.joints.pivot.damping = 0.3;
    let m = sys.minimal();
    let r = pendulum_reference(1.0, 0.0, 1.0, sys.links.rod.inertia + 0.25, 9.81 * 0.5, 0.3);
    let cases = [
        (
            "explicit Euler",
            observed_order(|dt| ExplicitEuler::new(m, dt), r, false),
            1.0,
        ),
        (
            "symplectic Euler",
            observed_order(|dt| SymplecticEuler::new(m, dt), r, false),
            1.0,
        ),
        (
            "paper VI",
            observed_order(|dt| Variational::new(m, dt).unwrap(), r, true),
            1.0,
        ),
        (
            "midpoint VI",
            observed_order(|dt| Variational::midpoint(m, dt).unwrap(), r, true),
            2.0,
        ),
        ("RK4", observed_order(|dt| Rk4::new(m, dt), r, false), 4.0),
    ];
    for (name, (errs, order), expected) in &cases {
        eprintln!("{name:>16}: errors at dt = 1/20..1/160: {errs:.3?}, observed order {order:.2}");
        assert!(
            (order - expected).abs() < 0.25,
            "{name}: order {order} (expected {expected})"
        );
    }
}
