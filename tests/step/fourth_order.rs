//! The fourth-order variational integrator (`Composition`, a symmetric
//! composition of the midpoint rule): its order against an independent
//! fine reference (RK4 at a much smaller step), its energy behaviour, and
//! its constraints through the fourbar's folded pose; and its explicit
//! (Störmer–Verlet) path for constant-mass models.

use crate::common;
use nalgebra::SVector;
use vigp::prelude::*;
use vigp::systems::{DoublePendulum, Fourbar};

/// Observed order on the conservative double pendulum: position errors at
/// t = 1 s for Δt = 0.04, 0.02, 0.01 against RK4 at Δt = 1e-4 (whose own
/// error, ~h⁴·C ≈ 1e-14, is far below the errors measured). Each halving
/// must divide the error by 2^(4 ± 0.5), for both coefficient sets.
#[test]
fn composition_is_fourth_order() {
    let m = DoublePendulum::default().minimal();
    let z0 = State::new([1.2, -0.4], [0.0, 0.0]);
    let t_end = 1.0;
    let reference = {
        let h = 1e-4;
        let n = (t_end / h) as usize;
        Rk4::new(m, h).rollout(&z0, n).unwrap()[n].q
    };
    for (name, make) in [
        (
            "suzuki",
            Composition::new as fn(_, f64) -> Result<Composition<_, 2, 0>, _>,
        ),
        ("triple jump", Composition::triple_jump),
    ] {
        let mut errors = Vec::new();
        for steps in [25usize, 50, 100] {
            let dt = t_end / steps as f64;
            let traj = make(m, dt).unwrap().rollout(&z0, steps).unwrap();
            errors.push((traj[steps].q - reference).amax());
        }
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!("{name}: errors {errors:?}, observed orders {orders:.2?}");
        for p in orders {
            assert!((3.5..=4.5).contains(&p), "{name}: order {p} ({errors:?})");
        }
    }
}

/// Energy over 2·10⁴ steps of the chaotic double pendulum at Δt = 0.01:
/// bounded (the maximum over the last tenth is at most 1.5× that over the
/// first tenth) and small (fourth order: ≤ 1e-3 J of a ~20 J motion).
#[test]
fn composition_energy_is_bounded() {
    let m = DoublePendulum::default().minimal();
    let vi = Composition::new(m, 0.01).unwrap();
    let z0 = State::new([1.6, -0.5], [0.0, 0.0]);
    let traj = vi.rollout(&z0, 20_000).unwrap();
    let e0 = vi.energy(&z0);
    let dev: Vec<f64> = traj.iter().map(|z| (vi.energy(z) - e0).abs()).collect();
    let tenth = dev.len() / 10;
    let first = dev[..tenth].iter().copied().fold(0.0, f64::max);
    let last = dev[dev.len() - tenth..].iter().copied().fold(0.0, f64::max);
    println!("max |ΔE|: first tenth {first:.2e} J, last tenth {last:.2e} J");
    assert!(last <= 1.5 * first.max(1e-12), "{first} → {last}");
    assert!(dev.iter().copied().fold(0.0, f64::max) <= 1e-3);
}

/// The fourbar swings through its folded pose (where RK4 leaves the branch,
/// see the work-precision report); every sub-step solves g = 0 at position
/// level, so |g| stays at solver tolerance over 10⁴ steps.
#[test]
fn composition_holds_the_fourbar_constraints() {
    let m = Fourbar::default().minimal();
    let z = common::at_rest(&m, [0.5, -0.9, -0.4, 0.9], 0.01);
    // continuous state at rest: q̇ = 0 is tangent
    let z0 = State {
        q: z.q,
        v: SVector::zeros(),
    };
    let vi = Composition::new(m, 0.01).unwrap();
    let traj = vi.rollout(&z0, 10_000).unwrap();
    let g = traj
        .iter()
        .map(|z| m.constraint_violation(z))
        .fold(0.0, f64::max);
    let e0 = vi.energy(&z0);
    let de = traj
        .iter()
        .map(|z| (vi.energy(z) - e0).abs())
        .fold(0.0, f64::max);
    println!("fourbar, 10⁴ steps: max |g| = {g:.1e}, max |ΔE| = {de:.2e} J");
    assert!(g <= 1e-10, "{g}");
    assert!(de <= 1e-2, "{de}");
}

vigp::mechanism! {
    /// A pendulum with a motor at its pivot: constant mass, no
    /// constraints, so the fourth-order VI takes its explicit path.
    pub DrivenPendulum {
        gravity: [0.0, -9.81],
        links {
            rod: { mass: 1.0, length: 1.0 },
        }
        joints {
            pivot: revolute(world, rod.start) { actuated },
        }
    }
}

/// Whether the fourth-order VI of `model` at Δt = 0.01 takes the explicit path.
fn explicit<M: Mechanism<N, C>, const N: usize, const C: usize>(model: M) -> bool {
    Composition::new(model, 0.01).unwrap().is_explicit()
}

/// The explicit path (Störmer–Verlet sub-steps, taken for constant mass,
/// no constraints, no damping): which models take it, its order against
/// RK4 at Δt = 1e-4 (as above), its energy over 10⁴ steps, and a constant
/// motor torque against RK4 under the same torque; u = 0 equals the
/// unforced step bit for bit.
#[test]
fn explicit_composition_for_constant_mass() {
    use vigp::systems::{Cartpole, Pendulum};
    let pendulum = Pendulum::default().minimal();
    assert!(explicit(pendulum));
    let mut damped = Pendulum::default();
    damped.joints.pivot.damping = 0.1;
    assert!(!explicit(damped.minimal()));
    let cartpole = Cartpole::default().minimal();
    assert!(!explicit(cartpole));
    let dp = DoublePendulum::default();
    assert!(!explicit(dp.minimal()));
    // maximal coordinates have a constant mass but constraints
    assert!(!explicit(Pendulum::default().maximal()));

    // order, unforced and under a constant torque
    let driven = DrivenPendulum::default().minimal();
    assert!(explicit(driven));
    let z0 = State::new([2.5], [0.3]);
    let t_end = 1.0;
    for u in [0.0, 1.7] {
        let u = SVector::<f64, 1>::new(u);
        let reference = {
            let h = 1e-4;
            let rk = Rk4::new(driven, h);
            let mut z = z0;
            for _ in 0..(t_end / h) as usize {
                z = rk.step_forced(&z, &u).unwrap();
            }
            z.q
        };
        let mut errors = Vec::new();
        for steps in [25usize, 50, 100] {
            let vi = Composition::new(driven, t_end / steps as f64).unwrap();
            let mut z = z0;
            for _ in 0..steps {
                z = vi.step_forced(&z, &u).unwrap();
            }
            errors.push((z.q - reference).amax());
        }
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!(
            "u = {}: errors {errors:?}, observed orders {orders:.2?}",
            u[0]
        );
        for p in orders {
            assert!(
                (3.5..=4.5).contains(&p),
                "u = {}: order {p} ({errors:?})",
                u[0]
            );
        }
    }
    let vi = Composition::new(driven, 0.01).unwrap();
    let zero = SVector::<f64, 1>::zeros();
    let mut z = z0;
    for _ in 0..50 {
        let unforced = vi.step(&z).unwrap();
        let forced = vi.step_forced(&z, &zero).unwrap();
        assert_eq!(unforced, forced);
        z = unforced;
    }

    // energy over 10⁴ steps at Δt = 0.01: bounded (the largest deviation
    // over the last tenth is within 1.5× that over the first tenth) and
    // small (≈ 1e-7 J here, an amplitude of 2.5 rad)
    let vi = Composition::new(pendulum, 0.01).unwrap();
    let traj = vi.rollout(&State::new([2.5], [0.3]), 10_000).unwrap();
    let e0 = vi.energy(&traj[0]);
    let dev = |zs: &[State<1>]| {
        zs.iter()
            .map(|z| (vi.energy(z) - e0).abs())
            .fold(0.0, f64::max)
    };
    let (first, last) = (dev(&traj[..1000]), dev(&traj[9000..]));
    println!("explicit path energy: first tenth {first:.2e} J, last tenth {last:.2e} J");
    assert!(last <= 1.5 * first && last < 1e-6, "{first:e} {last:e}");
}
