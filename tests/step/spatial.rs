//! Spatial mechanisms: the Lie-group variational integrator in maximal
//! coordinates and the minimal-coordinate views, against the planar
//! implementation, conservation laws, finite differences and a fine
//! reference; the step allocates nothing.
//!
//! Numbers quoted in docs/spatial.md are printed with `-- --nocapture`.

use crate::common;
use common::{Rng, tight};
use nalgebra::{SVector, UnitQuaternion, Vector3};
use vigp::Integrator;
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::spatial::so3;
use vigp::spatial::{LieStepper, SpatialState, summarize};
use vigp::systems::spatial::{
    DoublePendulum3d, Furuta, SpatialSliderCrank, SphericalPendulum, Tumbler,
};
use vigp::systems::{Cartpole, DoublePendulum, Fourbar};

// ---- planar mechanisms written as spatial ones: every axis along z,
// ---- every link frame hanging along −y (the planar θ = 0), gravity −y.

/// Declares the planar mechanism whose links are `$link…` lifted to 3-D:
/// gravity −y, every link 1 kg and 1 m with principal moments (0.001,
/// 1/12, 1/12) kg·m² and its frame hanging along −y; the joints as given
/// (axes written out).
macro_rules! lifted {
    ($name:ident { $($link:ident),* } joints { $($joints:tt)* }) => {
        vigp::mechanism! {
            $name {
                gravity: [0.0, -9.81, 0.0],
                links {
                    $($link: { mass: 1.0, length: 1.0, inertia: [0.001, 0.08333333333333333, 0.08333333333333333],
                               frame: [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] },)*
                }
                joints { $($joints)* }
            }
        }
    };
}

lifted! {
    LiftedDoublePendulum { upper, lower }
    joints {
        shoulder: revolute(world, upper.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
        elbow: revolute(upper.end, lower.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
    }
}

lifted! {
    LiftedCartpole { cart, pole }
    joints {
        rail: prismatic(world, cart.center) { axis: [1.0, 0.0, 0.0], damping: 0.0 },
        hinge: revolute(cart.center, pole.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
    }
}

lifted! {
    LiftedFourbar { link1, link2, link3, link4 }
    joints {
        top1: revolute(world, link1.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
        middle1: revolute(link1.end, link2.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
        top2: revolute(world, link3.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
        middle2: revolute(link3.end, link4.start) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
        bottom: revolute(link2.end, link4.end) { axis: [0.0, 0.0, 1.0], damping: 0.0 },
    }
}

// ---- the same with inputs and springs (`actuated`, `stiffness`, `rest`),
// ---- planar and lifted: every joint driven, springs with rest angles,
// ---- the fourbar's input and spring on its loop-closing joint. (No
// ---- spring on the cartpole's hinge: the pole is driven round several
// ---- turns, and the maximal view reads a revolute angle only within π
// ---- of its rest angle, while the planar maximal view counts turns.)

vigp::mechanism! {
    DrivenDoublePendulum {
        gravity: [0.0, -9.81],
        links {
            upper: { mass: 1.0, length: 1.0 },
            lower: { mass: 1.0, length: 1.0 },
        }
        joints {
            shoulder: revolute(world, upper.start) { actuated, stiffness: 3.0, rest: 0.4 },
            elbow: revolute(upper.end, lower.start) { damping: 0.2, actuated, stiffness: 2.0, rest: -0.3 },
        }
    }
}

lifted! {
    LiftedDrivenDoublePendulum { upper, lower }
    joints {
        shoulder: revolute(world, upper.start) { axis: [0.0, 0.0, 1.0], actuated, stiffness: 3.0, rest: 0.4 },
        elbow: revolute(upper.end, lower.start) { axis: [0.0, 0.0, 1.0], damping: 0.2, actuated, stiffness: 2.0, rest: -0.3 },
    }
}

vigp::mechanism! {
    DrivenCartpole {
        gravity: [0.0, -9.81],
        links {
            cart: { mass: 1.0, length: 1.0 },
            pole: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], actuated, stiffness: 5.0, rest: 0.2 },
            hinge: revolute(cart.center, pole.start) { actuated },
        }
    }
}

lifted! {
    LiftedDrivenCartpole { cart, pole }
    joints {
        rail: prismatic(world, cart.center) { axis: [1.0, 0.0, 0.0], actuated, stiffness: 5.0, rest: 0.2 },
        hinge: revolute(cart.center, pole.start) { axis: [0.0, 0.0, 1.0], actuated },
    }
}

rhombus! {
    DrivenFourbar {
        gravity: [0.0, -9.81],
        top1: { actuated, stiffness: 1.0, rest: 0.5 },
        middle: [],
        bottom: { actuated, stiffness: 2.0, rest: 0.5 },
    }
}

lifted! {
    LiftedDrivenFourbar { link1, link2, link3, link4 }
    joints {
        top1: revolute(world, link1.start) { axis: [0.0, 0.0, 1.0], actuated, stiffness: 1.0, rest: 0.5 },
        middle1: revolute(link1.end, link2.start) { axis: [0.0, 0.0, 1.0] },
        top2: revolute(world, link3.start) { axis: [0.0, 0.0, 1.0] },
        middle2: revolute(link3.end, link4.start) { axis: [0.0, 0.0, 1.0] },
        bottom: revolute(link2.end, link4.end) { axis: [0.0, 0.0, 1.0], actuated, stiffness: 2.0, rest: 0.5 },
    }
}

/// Planar pose (x, y, θ) of a spatial link state in the x-y plane:
/// q = rot_z(θ − π/2) for a link frame hanging along −y at θ = 0.
fn planar_pose(x: &Vector3<f64>, q: &UnitQuaternion<f64>, near: f64) -> [f64; 3] {
    let qq = q.quaternion();
    let th = 2.0 * qq.k.atan2(qq.w) + std::f64::consts::FRAC_PI_2;
    let two_pi = 2.0 * std::f64::consts::PI;
    [x.x, x.y, th + two_pi * ((near - th) / two_pi).round()]
}

/// The largest difference between a planar maximal trajectory (x, y, θ
/// per link) and a spatial one, and the largest out-of-plane excursion.
fn planar_distance<const B: usize, const M: usize>(
    planar: &[State<M>],
    spatial: &[SpatialState<B>],
) -> (f64, f64) {
    let (mut d, mut out) = (0.0f64, 0.0f64);
    for (p, s) in planar.iter().zip(spatial) {
        for i in 0..B {
            let pose = planar_pose(&s.x[i], &s.q[i], p.q[3 * i + 2]);
            for (k, x) in pose.iter().enumerate() {
                d = d.max((x - p.q[3 * i + k]).abs());
            }
            let qq = s.q[i].quaternion();
            out = out.max(s.x[i].z.abs()).max(qq.i.abs()).max(qq.j.abs());
        }
    }
    (d, out)
}

fn sci(x: &[f64]) -> String {
    x.iter()
        .map(|v| format!("{v:.3e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// [`compare`] under `$drive` on the (planar, lifted) pairs of the double
/// pendulum, the cartpole and the fourbar, from the same energetic starts,
/// named with the prefix `$prefix`. (A macro: the six mechanisms are six
/// types.)
macro_rules! compare_three {
    ($prefix:literal, $drive:expr, $double:expr, $cartpole:expr, $fourbar:expr) => {{
        let drive = $drive;
        let (planar, lifted) = $double;
        let z0 = State::new([1.2, -0.7], [0.5, 1.5]);
        let name = concat!($prefix, "double pendulum");
        compare(name, planar.minimal(), planar.maximal(), lifted, &z0, drive);
        let (planar, lifted) = $cartpole;
        let z0 = State::new([0.1, 2.0], [0.3, -1.0]);
        let name = concat!($prefix, "cartpole");
        compare(name, planar.minimal(), planar.maximal(), lifted, &z0, drive);
        let (planar, lifted) = $fourbar;
        let z0 = fourbar_start(&planar.minimal(), drive.dt_and_steps().0);
        let name = concat!($prefix, "fourbar");
        compare(name, planar.minimal(), planar.maximal(), lifted, &z0, drive);
    }};
}

/// A spatial mechanism whose axes are all parallel reproduces the planar
/// implementation, in both views: the minimal views are the same
/// Lagrangian (same `Variational` integrator), and the maximal Lie-group
/// VI advances a rotation about a fixed axis by exactly Δt·ω, so its
/// equations restricted to the plane are the planar maximal VI's. Double
/// pendulum (damped elbow), cartpole (prismatic + revolute) and fourbar
/// (loop), 300 steps of 10 ms from an energetic state; both solvers at
/// tolerance 1e-14, agreement required to 1e-10 in every coordinate
/// (minimal views through the fourbar's folded pose: see `compare`).
#[test]
fn parallel_axes_reproduce_the_planar_implementation() {
    let dt = 0.01;
    let steps = 300;
    let free = Drive::Free(dt, steps);

    // double pendulum with elbow damping
    let mut planar = DoublePendulum::default();
    planar.joints.elbow.damping = 0.2;
    let mut lifted = LiftedDoublePendulum::default();
    lifted.joints.elbow.damping = 0.2;
    compare_three!(
        "",
        free,
        (planar, lifted),
        (Cartpole::default(), LiftedCartpole::default()),
        (Fourbar::default(), LiftedFourbar::default())
    );

    // the same with inputs and springs: every joint driven by a torque or
    // force varying over the run, springs with rest coordinates (the
    // fourbar's on its loop-closing joint, whose angle both views read
    // from the link poses)
    let inputs = |k: usize| {
        let t = k as f64 * dt;
        SVector::<f64, 2>::new(2.0 * (3.0 * t).sin(), -1.5 + (2.0 * t).cos())
    };
    let inputs: Vec<SVector<f64, 2>> = (0..steps).map(inputs).collect();
    let held = Drive::Forced(dt, &inputs);
    compare_three!(
        "driven ",
        held,
        (
            DrivenDoublePendulum::default(),
            LiftedDrivenDoublePendulum::default()
        ),
        (DrivenCartpole::default(), LiftedDrivenCartpole::default()),
        (DrivenFourbar::default(), LiftedDrivenFourbar::default())
    );
}

/// The fourbar's consistent start for [`compare`] (from an energetic
/// guess, projected at `dt`).
fn fourbar_start<M: Mechanism<4, C>, const C: usize>(m: &M, dt: f64) -> State<4> {
    consistent_state(
        m,
        &SVector::from([0.9, -1.3, -0.4, 1.3]),
        &SVector::from([1.0, -0.5, 0.8, 0.2]),
        dt,
    )
    .unwrap()
}

/// What drives a [`compare`] run of steps `Δt`: free steps, or a forced
/// rollout (`Variational::rollout_forced`, `LieStepper::rollout_forced_into`)
/// under one input a step, the same input sequence for all four.
#[derive(Clone, Copy)]
enum Drive<'a, const U: usize> {
    Free(f64, usize),
    Forced(f64, &'a [SVector<f64, U>]),
}

impl<const U: usize> Drive<'_, U> {
    /// The step Δt and the number of steps of the run.
    fn dt_and_steps(&self) -> (f64, usize) {
        match self {
            Drive::Free(dt, steps) => (*dt, *steps),
            Drive::Forced(dt, inputs) => (*dt, inputs.len()),
        }
    }
}

/// The trajectory of `m` from `z0` under `drive`, solved to 1e-14.
fn run<M, const N: usize, const C: usize, const U: usize>(
    m: M,
    z0: &State<N>,
    drive: Drive<U>,
) -> Vec<State<N>>
where
    M: Mechanism<N, C> + Copy + vigp::Inputs<U>,
{
    let vi = Variational::new(m, drive.dt_and_steps().0)
        .unwrap()
        .tolerance(1e-14)
        .unwrap();
    match drive {
        Drive::Free(_, steps) => vi.rollout(z0, steps).unwrap(),
        Drive::Forced(_, inputs) => vi.rollout_forced(z0, inputs).unwrap(),
    }
}

/// The largest difference in q or v between two trajectories.
fn max_gap<const N: usize>(a: &[State<N>], b: &[State<N>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.q - y.q).amax().max((x.v - y.v).amax()))
        .fold(0.0, f64::max)
}

/// The planar minimal and maximal views against the lifted mechanism's
/// minimal and maximal views (Lie-group stepper) from `z0` under `drive`: minimal
/// views to 1e-10 (or 10× the planar trajectory's own sensitivity),
/// maximal views to 1e-10, out of the plane by at most 1e-12.
fn compare<
    P,
    PM,
    L,
    const N: usize,
    const C: usize,
    const M: usize,
    const CM: usize,
    const CL: usize,
    const B: usize,
    const J: usize,
    const NB: usize,
    const CB: usize,
    const U: usize,
>(
    name: &str,
    planar_min: P,
    planar_max: PM,
    lifted: L,
    z0: &State<N>,
    drive: Drive<U>,
) where
    P: Mechanism<N, C> + vigp::Coordinates<N, M> + Copy + vigp::Inputs<U>,
    PM: Mechanism<M, CM> + Copy + vigp::Inputs<U>,
    L: vigp::spatial::Spatial<B, J> + Copy + Views<B, J, NB, CB> + vigp::Inputs<U>,
    L::Minimal: Mechanism<N, CL> + Copy + vigp::Inputs<U>,
{
    let (dt, steps) = drive.dt_and_steps();
    // minimal views
    let a = run(planar_min, z0, drive);
    let b = run(lifted.minimal_view(), z0, drive);
    let dmin = max_gap(&a, &b);
    // maximal views
    let pm = run(planar_max, &planar_min.to_maximal(z0, dt), drive);
    let stepper = LieStepper::with_options(lifted.maximal_view(), dt, tight()).unwrap();
    let zs = vigp::spatial::views::to_maximal::<L, B, J, N>(&lifted, z0, dt);
    let sm = match drive {
        Drive::Free(_, steps) => stepper.rollout(&zs, steps).unwrap(),
        Drive::Forced(_, inputs) => {
            let mut sm = vec![zs; steps + 1];
            stepper.rollout_forced_into(&zs, inputs, &mut sm).unwrap();
            sm
        }
    };
    let (dmax, out) = planar_distance(&pm, &sm);
    // The planar minimal trajectory's own sensitivity: the same integrator
    // from z₀ moved by one ulp. Through the fourbar's folded pose the loop
    // Jacobian's smallest singular value drops to ~1e-5 and a residual at
    // rounding level moves the solution by ~1e-9: there neither trajectory
    // is determined to better than that, and agreement is required to 10×
    // this sensitivity instead of 1e-10.
    let mut z1 = *z0;
    z1.q[0] = f64::from_bits(z1.q[0].to_bits() + 1);
    let dself = max_gap(&a, &run(planar_min, &z1, drive));
    println!(
        "{name}: minimal views differ by {dmin:.2e} (planar vs itself from z₀ + 1 ulp: {dself:.2e}), maximal views by {dmax:.2e} (out of plane {out:.1e}) over {steps} steps"
    );
    assert!(
        dmin <= 1e-10f64.max(10.0 * dself),
        "{name} minimal: {dmin:e}"
    );
    assert!(dmax <= 1e-10, "{name} maximal: {dmax:e}");
    assert!(out <= 1e-12, "{name}: left the plane by {out:e}");
}

/// The generated `minimal()` and `maximal()` as a trait, so one generic
/// helper serves every test mechanism.
trait Views<const B: usize, const J: usize, const N: usize, const C: usize>: Sized {
    type Minimal;
    fn minimal_view(&self) -> Self::Minimal;
    fn maximal_view(&self) -> vigp::spatial::Maximal<Self, B, J, N, C>;
}

macro_rules! views {
    ($($t:ty, $min:ty: $b:literal, $j:literal, $n:literal, $c:literal;)*) => {$(
        impl Views<$b, $j, $n, $c> for $t {
            type Minimal = $min;
            fn minimal_view(&self) -> $min {
                self.minimal()
            }
            fn maximal_view(&self) -> vigp::spatial::Maximal<Self, $b, $j, $n, $c> {
                self.maximal()
            }
        }
    )*};
}

views! {
    LiftedDrivenDoublePendulum, LiftedDrivenDoublePendulumMinimal: 2, 2, 12, 10;
    LiftedDrivenCartpole, LiftedDrivenCartpoleMinimal: 2, 2, 12, 10;
    LiftedDrivenFourbar, LiftedDrivenFourbarMinimal: 4, 5, 24, 25;
    LiftedDoublePendulum, LiftedDoublePendulumMinimal: 2, 2, 12, 10;
    LiftedCartpole, LiftedCartpoleMinimal: 2, 2, 12, 10;
    LiftedFourbar, LiftedFourbarMinimal: 4, 5, 24, 25;
}

/// A consistent maximal initial state of a spatial mechanism from a guess
/// in minimal coordinates (projected there first).
fn start<M, S, const N: usize, const C: usize, const B: usize, const J: usize>(
    minimal: &M,
    sys: &S,
    q: [f64; N],
    v: [f64; N],
    dt: f64,
) -> (State<N>, SpatialState<B>)
where
    M: Mechanism<N, C>,
    S: vigp::spatial::Spatial<B, J>,
{
    let z = consistent_state(minimal, &SVector::from(q), &SVector::from(v), dt).unwrap();
    (
        z,
        vigp::spatial::views::to_maximal::<S, B, J, N>(sys, &z, dt),
    )
}

/// The spherical pendulum's start of the long runs: swung out and turning.
fn spherical_start(sys: &SphericalPendulum, dt: f64) -> (State<4>, SpatialState<1>) {
    start(
        &sys.minimal(),
        sys,
        [0.8, 0.1, 0.55, 0.2],
        [0.0, 0.5, 0.0, 1.5],
        dt,
    )
}

/// The slider-crank's energetic start: the crank at 6 rad/s.
fn crank_start(sys: &SpatialSliderCrank, dt: f64) -> (State<6>, SpatialState<3>) {
    start(
        &sys.minimal(),
        sys,
        [0.0, 0.99, 0.0, 0.0, 0.12, 0.03],
        [6.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        dt,
    )
}

/// The four examples over 10⁵ steps of 10 ms (1000 s) in maximal
/// coordinates: |g| ≤ 1e-10 and |‖q‖ − 1| ≤ 1e-14 at every step, and the
/// energy error bounded: its maximum over the last tenth is within 1.5× the
/// first tenth's (no growth). Printed: the numbers of docs/spatial.md.
#[test]
fn examples_keep_energy_constraints_and_unit_quaternions_over_1e5_steps() {
    let dt = 0.01;
    let steps = 100_000;
    let check = |name: &str, s: vigp::spatial::SpatialSummary| {
        println!(
            "{name}: max |ΔE| {:.3e} J (first tenth {:.3e}, last tenth {:.3e}), max |g| {:.2e}, max |‖q‖−1| {:.2e}",
            s.max_energy_error, s.first_tenth, s.last_tenth, s.max_violation, s.max_norm_error
        );
        assert!(
            s.max_violation <= 1e-10,
            "{name}: |g| {:e}",
            s.max_violation
        );
        assert!(
            s.max_norm_error <= 1e-14,
            "{name}: norm {:e}",
            s.max_norm_error
        );
        assert!(
            s.last_tenth <= 1.5 * s.first_tenth + 1e-9,
            "{name}: energy error grows: {s:?}"
        );
    };

    let sys = SphericalPendulum::default();
    let (_, z0) = spherical_start(&sys, dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    check(
        "spherical pendulum",
        summarize(&stepper, &stepper.rollout(&z0, steps).unwrap()),
    );

    let sys = Furuta::default();
    let (_, z0) = start(&sys.minimal(), &sys, [0.0, 2.5], [3.0, 0.0], dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    check(
        "furuta",
        summarize(&stepper, &stepper.rollout(&z0, steps).unwrap()),
    );

    let sys = DoublePendulum3d::default();
    let (_, z0) = start(&sys.minimal(), &sys, [1.0, -0.8], [0.0, 0.0], dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    check(
        "3-D double pendulum",
        summarize(&stepper, &stepper.rollout(&z0, steps).unwrap()),
    );

    let sys = SpatialSliderCrank::default();
    let (_, z0) = crank_start(&sys, dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    check(
        "spatial slider-crank",
        summarize(&stepper, &stepper.rollout(&z0, steps).unwrap()),
    );
}

/// A free body spun about its intermediate principal axis (2 rad/s, a
/// 1e-4 rad/s perturbation on the others) flips over (ω_y reverses), spun
/// about the minor or major axis it does not; the discrete angular momentum
/// Σ x × m·v + R(q_{k+1})·μ⁻(ω) is conserved to the solver tolerance (each
/// step may change it by the Newton residual, √3·1e-12·p_scale), and the
/// energy error stays below 1e-3 relative (first-order VI, no growth).
#[test]
fn spinning_body_conserves_angular_momentum_and_flips_about_the_intermediate_axis() {
    let dt = 0.01;
    let stepper = LieStepper::new(Tumbler::default().maximal(), dt).unwrap();
    let spin = |w: Vector3<f64>| SpatialState::<1> {
        x: [Vector3::new(0.3, -0.2, 1.0)],
        q: [UnitQuaternion::identity()],
        v: [Vector3::new(0.5, 0.1, -0.3)],
        w: [w],
    };
    let z0 = spin(Vector3::new(1e-4, 2.0, 1e-4));
    let traj = stepper.rollout(&z0, 5000).unwrap();
    let (_, l0) = stepper.momentum(&z0);
    let e0 = stepper.energy(&z0);
    // p_scale = |μ|∞ + max(m, J_ii) = 4 + 3
    let per_step = 3f64.sqrt() * 1e-12 * 7.0;
    let mut prev = l0;
    let (mut drift, mut de, mut min_wy, mut flips) = (0.0f64, 0.0f64, f64::MAX, 0);
    for w in traj.windows(2) {
        let l = stepper.momentum(&w[1]).1;
        assert!((l - prev).norm() <= per_step);
        prev = l;
        drift = drift.max((l - l0).norm());
        de = de.max((stepper.energy(&w[1]) - e0).abs() / e0);
        min_wy = min_wy.min(w[1].w[0].y);
        if w[0].w[0].y.signum() != w[1].w[0].y.signum() {
            flips += 1;
        }
    }
    println!(
        "tumbler: |L| = {:.6}, max |L − L0| = {drift:.2e} over 5000 steps, max |ΔE|/E = {de:.2e}, min ω_y = {min_wy:.4}, ω_y sign changes: {flips}",
        l0.norm()
    );
    assert!(min_wy < -1.99, "no flip about the intermediate axis");
    assert!(flips >= 2);
    assert!(de < 1e-3);
    for w in [Vector3::new(2.0, 1e-4, 1e-4), Vector3::new(1e-4, 1e-4, 2.0)] {
        let traj = stepper.rollout(&spin(w), 5000).unwrap();
        let dev = traj.iter().map(|z| (z.w[0] - w).norm()).fold(0.0, f64::max);
        assert!(dev < 1e-2, "spin about a stable axis {w} deviates by {dev}");
    }
}

/// Convergence of the maximal Lie-group VI (the rectangle rule) on the
/// spherical pendulum and the 3-D double pendulum: the error in the
/// centres of mass at T = 0.64 s against a fine reference (Δt = 10 µs).
///
/// * Started with the continuous velocity as the first discrete velocity
///   (an O(Δt) error in the start), the error halves with Δt: observed
///   order within [0.8, 1.25].
/// * Started with the discrete velocity of `discrete_velocity`
///   (q̇ + ½Δt·q̈, accurate to O(Δt²)), the positions converge at second
///   order (within [1.8, 2.25]): with constant link masses and inertias
///   the rectangle rule's DEL is symmetric in the positions, as
///   Störmer–Verlet's. The discrete velocity itself approximates the
///   velocity at t_k + Δt/2, not at t_k.
#[test]
fn maximal_integrator_converges_at_first_order_and_second_from_a_consistent_start() {
    fn errors<
        S,
        M,
        const B: usize,
        const J: usize,
        const N: usize,
        const C: usize,
        const NM: usize,
        const CM: usize,
    >(
        sys: S,
        minimal: M,
        q: [f64; NM],
        v: [f64; NM],
        view: impl Fn(&S) -> vigp::spatial::Maximal<S, B, J, N, C>,
        second_order_start: bool,
    ) -> Vec<f64>
    where
        S: vigp::spatial::Spatial<B, J> + Copy,
        M: Mechanism<NM, CM>,
    {
        let t_end = 0.64;
        // the continuous state: q on the joints, q̇ tangent to them (to
        // O(1e-9)), the same for every Δt
        let zc = consistent_state(&minimal, &SVector::from(q), &SVector::from(v), 1e-9).unwrap();
        let run = |dt: f64| {
            let z0 = if second_order_start {
                let vd = vigp::dynamics::discrete_velocity(&minimal, &zc.q, &zc.v, dt).unwrap();
                let z = State { q: zc.q, v: vd };
                vigp::spatial::views::to_maximal::<S, B, J, NM>(&sys, &z, dt)
            } else {
                // q and v as the discrete velocity of the first step
                start(&minimal, &sys, q, v, dt).1
            };
            let stepper = LieStepper::with_options(view(&sys), dt, tight()).unwrap();
            let n = (t_end / dt).round() as usize;
            *stepper.rollout(&z0, n).unwrap().last().unwrap()
        };
        let reference = run(1e-5);
        [0.02, 0.01, 0.005, 0.0025]
            .iter()
            .map(|&dt| {
                let z = run(dt);
                (0..B)
                    .map(|i| (z.x[i] - reference.x[i]).norm())
                    .fold(0.0, f64::max)
            })
            .collect()
    }
    let sp = SphericalPendulum::default();
    let dp = DoublePendulum3d::default();
    for (second, range) in [(false, 0.8..=1.25), (true, 1.8..=2.25)] {
        let e1 = errors(
            sp,
            sp.minimal(),
            [0.8, 0.1, 0.55, 0.2],
            [0.0, 0.5, 0.0, 1.5],
            |s| s.maximal(),
            second,
        );
        let e2 = errors(
            dp,
            dp.minimal(),
            [1.0, -0.8],
            [0.0, 0.0],
            |s| s.maximal(),
            second,
        );
        for (name, e) in [("spherical pendulum", e1), ("3-D double pendulum", e2)] {
            let orders: Vec<f64> = e.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
            println!(
                "{name}, {} start: errors {} at Δt = 20, 10, 5, 2.5 ms; observed orders {orders:.3?}",
                if second {
                    "second-order"
                } else {
                    "first-order"
                },
                sci(&e)
            );
            for p in orders {
                assert!(range.contains(&p), "{name}: order {p}");
            }
        }
    }
}

/// The Newton Jacobians of the maximal step of generated mechanisms (the
/// slider-crank with its loop and damped joints, the 3-D double pendulum)
/// against central differences, relative 1e-7 (h = 1e-6 scaled:
/// truncation ~1e-12, rounding ~1e-10 relative); the minimal views' DEL
/// Jacobians likewise (they are the runtime's dual-number Jacobians).
#[test]
fn del_jacobians_match_finite_differences() {
    let mut rng = Rng(11);
    let mut sc = SpatialSliderCrank::default();
    sc.joints.crankshaft.damping = 0.3;
    sc.joints.rail.damping = 0.2;
    sc.joints.crankpin.damping = 0.05;
    let stepper = LieStepper::new(sc.maximal(), 0.01).unwrap();
    check_maximal(&stepper, &mut rng);
    let mut dp = DoublePendulum3d::default();
    dp.joints.elbow.damping = 0.4;
    let stepper = LieStepper::new(dp.maximal(), 0.01).unwrap();
    check_maximal(&stepper, &mut rng);

    check_minimal(&sc.minimal(), &mut rng);
    check_minimal(&dp.minimal(), &mut rng);
    let mut fu = Furuta::default();
    fu.joints.base.damping = 0.1;
    check_minimal(&fu.minimal(), &mut rng);
}

fn check_maximal<S, const B: usize, const J: usize, const N: usize, const C: usize>(
    stepper: &LieStepper<S, B, J, N, C>,
    rng: &mut Rng,
) where
    S: vigp::spatial::Spatial<B, J>,
{
    let mut vec3 =
        |s: f64| Vector3::new(rng.uniform(-s, s), rng.uniform(-s, s), rng.uniform(-s, s));
    for _ in 0..3 {
        let z = SpatialState::<B> {
            x: std::array::from_fn(|_| vec3(1.0)),
            q: std::array::from_fn(|_| so3::exp(&vec3(2.0))),
            v: std::array::from_fn(|_| vec3(2.0)),
            w: std::array::from_fn(|_| vec3(6.0)),
        };
        let nu = vigp::spatial::maximal::pack::<B, N>(
            &std::array::from_fn(|_| vec3(2.0)),
            &std::array::from_fn(|_| vec3(6.0)),
        );
        let lambda = SVector::<f64, C>::from_fn(|i, _| (i as f64 * 0.37).sin() * 4.0);
        let (a, b, g2) = stepper.del_jacobian(&z, &nu);
        for k in 0..N {
            let h = 1e-6 * (1.0 + nu[k].abs());
            let (mut p, mut m) = (nu, nu);
            p[k] += h;
            m[k] -= h;
            let (rp, cp) = stepper.del_residual(&z, &p, &lambda);
            let (rm, cm) = stepper.del_residual(&z, &m, &lambda);
            let fr = (rp - rm) / (2.0 * h);
            let fc = (cp - cm) / (2.0 * h);
            assert!(
                (fr - a.column(k)).amax() <= 1e-7 * a.amax(),
                "∂r/∂ν column {k}"
            );
            assert!(
                (fc - g2.column(k)).amax() <= 1e-7 * g2.amax(),
                "∂c/∂ν column {k}"
            );
        }
        for k in 0..C {
            let h = 1e-6 * (1.0 + lambda[k].abs());
            let (mut p, mut m) = (lambda, lambda);
            p[k] += h;
            m[k] -= h;
            let fr = (stepper.del_residual(&z, &nu, &p).0 - stepper.del_residual(&z, &nu, &m).0)
                / (2.0 * h);
            assert!(
                (fr - b.column(k)).amax() <= 1e-7 * b.amax(),
                "∂r/∂λ column {k}"
            );
        }
    }
}

fn check_minimal<M: Mechanism<N, C>, const N: usize, const C: usize>(m: &M, rng: &mut Rng) {
    let dt = 0.01;
    for _ in 0..5 {
        let x1 = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-1.5, 1.5));
        let v1 = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-3.0, 3.0));
        let (_, jac) = vigp::del::del_terms_jacobian::<M, N, C>(m, dt, 0.0, &x1, &v1);
        for j in 0..N {
            let h = 1e-6 * (1.0 + v1[j].abs());
            let (mut vp, mut vm) = (v1, v1);
            vp[j] += h;
            vm[j] -= h;
            let fd = (vigp::del::del_terms::<M, f64, N, C>(m, dt, 0.0, &x1, &vp)
                - vigp::del::del_terms::<M, f64, N, C>(m, dt, 0.0, &x1, &vm))
                / (2.0 * h);
            assert!(
                (fd - jac.column(j)).amax() <= 1e-7 * jac.amax(),
                "minimal column {j}"
            );
        }
    }
}

/// The two views describe the same mechanism: a minimal state maps to a
/// consistent maximal one (|g| at rounding level) and back exactly, and
/// both integrators (different first-order discretisations of the same
/// equations) approach each other as Δt shrinks.
#[test]
fn minimal_and_maximal_views_agree() {
    let sys = SpatialSliderCrank::default();
    let dt = 0.005;
    // a consistent state of the crank turning and the rod rolling
    let start_at = |dt| {
        start(
            &sys.minimal(),
            &sys,
            [0.3, 0.99, 0.0, 0.0, 0.12, 0.03],
            [4.0, 0.0, 0.3, 0.0, 0.0, 0.0],
            dt,
        )
    };
    let (zmin, zmax) = start_at(dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    assert!(stepper.constraint_violation(&zmax) <= 1e-12);
    let back = sys.minimal().to_minimal(&zmax, dt);
    assert!((back.q - zmin.q).amax() <= 1e-12 && (back.v - zmin.v).amax() <= 1e-9);
    // the same motion at two step sizes: views agree to O(Δt)
    let mut gaps = Vec::new();
    for dt in [0.004, 0.001] {
        let (zmin, zmax) = start_at(dt);
        let n = (0.4 / dt) as usize;
        let a = Variational::new(sys.minimal(), dt)
            .unwrap()
            .rollout(&zmin, n)
            .unwrap();
        let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
        let b = stepper.rollout(&zmax, n).unwrap();
        let xa = sys.minimal().to_maximal(&a[n], dt);
        let gap = (0..3)
            .map(|i| (xa.x[i] - b[n].x[i]).norm())
            .fold(0.0, f64::max);
        gaps.push(gap);
    }
    println!(
        "slider-crank minimal vs maximal after 0.4 s: {} at Δt = 4, 1 ms",
        sci(&gaps)
    );
    assert!(gaps[1] < gaps[0] / 2.5, "{gaps:?}");
}

/// The fixed-size step, rollout and projections allocate nothing.
#[test]
fn spatial_steps_do_not_allocate() {
    let sys = SpatialSliderCrank::default();
    let dt = 0.01;
    let (zmin, z0) = crank_start(&sys, dt);
    let stepper = LieStepper::new(sys.maximal(), dt).unwrap();
    let mut out = [z0; 50];
    let vi = Variational::new(sys.minimal(), dt).unwrap();
    // the std step keeps its (large) workspace per thread: the thread's
    // first step allocates it once (tests/no_alloc.rs counts that); the
    // steps measured below reuse it
    let _ = vi.step(&zmin).unwrap();
    let info = allocation_counter::measure(|| {
        let mut z = z0;
        for _ in 0..20 {
            z = stepper.step(&z).unwrap();
        }
        stepper.rollout_into(&z0, &mut out).unwrap();
        let (x1, q1) = out[49].advanced(dt);
        let nu = vigp::spatial::maximal::pack::<3, 18>(&out[49].v, &out[49].w);
        let _ = stepper.project_velocity(&x1, &q1, &(nu * 1.01)).unwrap();
        let _ = stepper.consistent_state(&out[10]).unwrap();
        let mut zm = zmin;
        for _ in 0..10 {
            zm = vi.step(&zm).unwrap();
        }
    });
    assert_eq!(info.count_total, 0, "spatial steps allocated");
}

/// The jet-computed terms of a minimal view (M, ∂M/∂q, ∇V, D, the force
/// Jacobian, G and Σμ∇²g: what a fixed-size step runs on) against the
/// dual-number `Mechanism` of the same view (an independent evaluation of
/// the same Lagrangian) and central differences, on random configurations
/// of the damped slider-crank (loop, ball joints, prismatic) and Furuta.
/// Tolerances: 1e-12 relative against dual numbers (same arithmetic, other
/// order); 1e-7 against central differences (h = 1e-6).
#[test]
fn minimal_terms_match_dual_numbers_and_finite_differences() {
    let mut sc = SpatialSliderCrank::default();
    sc.joints.crankshaft.damping = 0.3;
    sc.joints.rail.damping = 0.2;
    sc.joints.crankpin.damping = 0.05;
    sc.joints.wristpin.damping = 0.07;
    check_terms::<_, _, 3, 4, 6, 4>(&sc, &sc.minimal(), 21);
    let mut fu = Furuta::default();
    fu.joints.base.damping = 0.1;
    fu.joints.pivot.damping = 0.02;
    check_terms::<_, _, 2, 2, 2, 0>(&fu, &fu.minimal(), 22);
}

fn check_terms<S, M, const B: usize, const J: usize, const N: usize, const C: usize>(
    sys: &S,
    m: &M,
    seed: u64,
) where
    S: vigp::spatial::Spatial<B, J>,
    M: Mechanism<N, C>,
{
    use nalgebra::SMatrix;
    use vigp::__private::num_dual;
    use vigp::spatial::minimal;
    let mut rng = Rng(seed);
    let close = |a: f64, b: f64, scale: f64, tol: f64, what: &str| {
        assert!(
            (a - b).abs() <= tol * scale,
            "{what}: {a} vs {b} (scale {scale})"
        );
    };
    for _ in 0..4 {
        let q = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-1.0, 1.0));
        let v = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-2.0, 2.0));
        let t = minimal::terms::<S, B, J, N>(sys, &q);
        // M = ∂²T/∂v², D = ∂²R/∂v², ∇V, ∂T/∂q = ½ vᵀ∂M/∂q v by dual numbers
        let (_, _, mh) = num_dual::hessian(
            |v| m.kinetic_energy(&q.map(num_dual::Dual2Vec::from_re), &v),
            &v,
        );
        let (_, _, dh) = num_dual::hessian(
            |v| m.dissipation(&q.map(num_dual::Dual2Vec::from_re), &v),
            &v,
        );
        let (_, gv) = num_dual::gradient(|q| m.potential_energy(&q), &q);
        let (_, gt) = num_dual::gradient(
            |q| m.kinetic_energy(&q, &v.map(num_dual::DualVec::from_re)),
            &q,
        );
        let sm = t.mass.amax();
        for i in 0..N {
            close(t.dpotential[i], gv[i], 1.0 + gv.amax(), 1e-12, "∇V");
            let half: f64 = 0.5 * v.dot(&(t.dmass[i] * v));
            close(half, gt[i], 1.0 + gt.amax(), 1e-12, "½vᵀ∂M/∂q v");
            for k in 0..N {
                close(t.mass[(i, k)], mh[(i, k)], sm, 1e-12, "M");
                close(t.damping[(i, k)], dh[(i, k)], 1.0 + dh.amax(), 1e-12, "D");
            }
        }
        let mm = minimal::mass_matrix::<S, B, J, N>(sys, &q);
        assert!((mm - t.mass).amax() <= 1e-12 * sm);
        // ∂M/∂q and the force Jacobian by central differences
        let force = |q: &SVector<f64, N>| {
            let t = minimal::terms::<S, B, J, N>(sys, q);
            SVector::<f64, N>::from_fn(|i, _| 0.5 * v.dot(&(t.dmass[i] * v)))
                - t.dpotential
                - t.damping * v
        };
        let fj = minimal::force_jacobian::<S, B, J, N>(sys, &q, &v);
        let mu = SVector::<f64, C>::from_fn(|i, _| (i as f64 + 0.5).sin());
        let (g0, gj) = minimal::constraints_and_jacobian::<S, B, J, N, C>(sys, &q);
        let gd: SMatrix<f64, C, N> = m.constraint_jacobian(&q);
        assert!((g0 - m.constraints(&q)).amax() <= 1e-12);
        assert!((gj - gd).amax() <= 1e-12 * (1.0 + gd.amax()));
        let gh = minimal::constraint_hessian::<S, B, J, N, C>(sys, &q, &mu);
        for l in 0..N {
            let h = 1e-6;
            let (mut qp, mut qm) = (q, q);
            qp[l] += h;
            qm[l] -= h;
            let dm = (minimal::mass_matrix::<S, B, J, N>(sys, &qp)
                - minimal::mass_matrix::<S, B, J, N>(sys, &qm))
                / (2.0 * h);
            assert!((dm - t.dmass[l]).amax() <= 1e-7 * (1.0 + sm), "∂M/∂q_{l}");
            let df = (force(&qp) - force(&qm)) / (2.0 * h);
            assert!(
                (df - fj.column(l)).amax() <= 1e-7 * (1.0 + fj.amax()),
                "force Jacobian column {l}"
            );
            let dg = (minimal::constraints_and_jacobian::<S, B, J, N, C>(sys, &qp)
                .1
                .transpose()
                * mu
                - minimal::constraints_and_jacobian::<S, B, J, N, C>(sys, &qm)
                    .1
                    .transpose()
                    * mu)
                / (2.0 * h);
            assert!(
                (dg - gh.column(l)).amax() <= 1e-7 * (1.0 + gh.amax()),
                "Σμ∇²g column {l}"
            );
        }
    }
}

/// Bad input is a typed error, never a panic or a NaN: invalid Δt, NaN in
/// the state, a negative or non-finite mass, an inertia made indefinite at
/// run time, sizes that do not match the description, a state too fast
/// for the step, empty training data.
#[test]
fn spatial_errors_are_typed() {
    use vigp::embedded::StepError as E;
    let sys = SphericalPendulum::default();
    assert!(matches!(
        LieStepper::new(sys.maximal(), 0.0),
        Err(E::InvalidTimeStep { .. })
    ));
    assert!(matches!(
        LieStepper::new(sys.maximal(), f64::NAN),
        Err(E::InvalidTimeStep { .. })
    ));
    let mut bad = sys;
    bad.links.rod.mass = -1.0;
    assert!(matches!(
        LieStepper::new(bad.maximal(), 0.01),
        Err(E::InvalidModel(_))
    ));
    bad.links.rod.mass = f64::INFINITY;
    assert!(matches!(
        LieStepper::new(bad.maximal(), 0.01),
        Err(E::InvalidModel(_))
    ));
    let mut bad = sys;
    bad.links.rod.inertia[0][0] = -0.1;
    assert!(matches!(
        LieStepper::new(bad.maximal(), 0.01),
        Err(E::InvalidModel(_))
    ));
    let mut bad = sys;
    bad.joints.ball.damping = -1.0;
    assert!(matches!(
        LieStepper::new(bad.maximal(), 0.01),
        Err(E::InvalidModel(_))
    ));
    let wrong = vigp::spatial::Maximal::<_, 1, 1, 6, 4>::new(sys);
    assert!(matches!(
        LieStepper::new(wrong, 0.01),
        Err(E::InvalidModel(_))
    ));

    let stepper = LieStepper::new(sys.maximal(), 0.01).unwrap();
    let (_, z0) = spherical_start(&sys, 0.01);
    let mut nan = z0;
    nan.v[0].x = f64::NAN;
    assert!(matches!(
        stepper.step(&nan),
        Err(E::NonFiniteState { step: None })
    ));
    assert!(matches!(
        stepper.consistent_state(&nan),
        Err(E::NonFiniteState { step: None })
    ));
    let mut out = [z0; 3];
    assert!(stepper.rollout_into(&nan, &mut out).is_err());
    // A quaternion that is not of unit norm (nalgebra's `new_unchecked`
    // does not normalise) is not a rotation: refused, never stepped.
    let mut long = z0;
    long.q[0] = UnitQuaternion::new_unchecked(z0.q[0].quaternion() * 1.001);
    match stepper.step(&long) {
        Err(E::NonUnitQuaternion { link: 0, norm, .. }) => assert!((norm - 1.001).abs() < 1e-12),
        other => panic!("a non-unit quaternion was stepped: {other:?}"),
    }
    assert!(matches!(
        stepper.rollout_into(&long, &mut out),
        Err(vigp::embedded::RolloutError {
            step: 0,
            error: E::NonUnitQuaternion { link: 0, .. }
        })
    ));
    // consistent_state projects it back onto the unit sphere (and the
    // joints): the same state as from the unit quaternion.
    let fixed = stepper.consistent_state(&long).unwrap();
    let unit = stepper.consistent_state(&z0).unwrap();
    assert!(fixed.norm_error() <= 1e-15, "{}", fixed.norm_error());
    assert!((fixed.q[0].coords - unit.q[0].coords).amax() <= 1e-12);
    assert!(stepper.step(&fixed).is_ok());
    let mut zero = z0;
    zero.q[0] = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0));
    assert!(matches!(
        stepper.consistent_state(&zero),
        Err(E::NonUnitQuaternion { link: 0, .. })
    ));
    // 1e6 rad/s against Δt = 10 ms: no root near the start; typed, finite
    let mut fast = z0;
    fast.w[0] = Vector3::new(1e6, -3e5, 2e5);
    match stepper.step(&fast) {
        Ok(z) => assert!(z.is_finite()),
        Err(e) => assert!(!format!("{e}").is_empty()),
    }
    let empty: Vec<vigp::learned::Transition<6, SpatialState<1>>> = Vec::new();
    assert!(
        vigp::spatial::learned::LearnedSpatial::train(
            stepper,
            &empty,
            vigp::spatial::learned::Rotation::Matrix,
            vigp::learned::Prior::Nominal,
            &vigp::gp::TrainOptions::default(),
        )
        .is_err()
    );
}

spatial_four_bar! {
    /// An RSSR spatial four-bar: a crank about z, a coupler with a ball
    /// joint at each end, a rocker about x. Its coupler spins freely about
    /// its own axis.
    Rssr {
        crankshaft: [],
        ball: ball_a,
        ball_b: spherical(rocker.end, coupler.end),
    }
}

/// `LieStepper::consistent_state` on guesses whose configuration is
/// consistent and whose velocities need a large correction (the RSSR at
/// its reference pose, random crank, rocker and coupler rates mapped from
/// the minimal view, which does not close the loop one step later). Its
/// Newton matrix leaves out the constraints' curvature, and 57 of these
/// 300 guesses ended in `LineSearchFailed` or `NotConverged` before the
/// line search took the ℓ1 merit function as well. Now all 300 project:
/// the configuration one step later closes the loop to 1e-12, a second
/// projection moves nothing (to 1e-12), and the projected velocities are
/// at least as close to the guess (to rounding) as the consistent ones the
/// minimal view's projection gives: the projection's defining property,
/// checked against an independent solver.
#[test]
fn maximal_velocity_projection_converges_on_large_corrections() {
    let dt = 0.01;
    let m = Rssr::default().minimal();
    let st = LieStepper::new(Rssr::default().maximal(), dt).unwrap();
    let mut rng = Rng(3);
    let mut closest = 0.0f64;
    for _ in 0..300 {
        let mut v = SVector::<f64, 6>::zeros();
        v[0] = rng.uniform(-3.0, 3.0);
        v[5] = rng.uniform(-2.0, 2.0);
        v[2] = rng.uniform(-0.5, 0.5);
        let guess = m.to_maximal(
            &State {
                q: m.reference(),
                v,
            },
            dt,
        );
        assert!(st.constraint_violation(&guess) < 1e-14);
        let z = st.consistent_state(&guess).unwrap();
        let (x2, q2) = z.advanced(dt);
        let next = SpatialState { x: x2, q: q2, ..z };
        assert!(st.constraint_violation(&next) < 1e-12);
        let again = st.consistent_state(&z).unwrap();
        let moved = (0..3)
            .map(|i| {
                (again.v[i] - z.v[i])
                    .norm()
                    .max((again.w[i] - z.w[i]).norm())
            })
            .fold(0.0, f64::max);
        assert!(moved < 1e-12, "{moved:e}");
        // the minimal view's consistent velocities, in the maximal view
        let zm = consistent_state(&m, &m.reference(), &v, dt).unwrap();
        let other = m.to_maximal(&zm, dt);
        let dist = |a: &SpatialState<3>| {
            (0..3)
                .map(|i| {
                    (a.v[i] - guess.v[i]).norm_squared() + (a.w[i] - guess.w[i]).norm_squared()
                })
                .sum::<f64>()
                .sqrt()
        };
        let (ours, theirs) = (dist(&z), dist(&other));
        assert!(ours <= theirs * (1.0 + 1e-9), "{ours} > {theirs}");
        closest = closest.max(ours / theirs);
    }
    println!(
        "RSSR velocity projection: 300 of 300 converge; largest |ν − guess| ÷ that of the minimal view's projection {closest:.4}"
    );
}
