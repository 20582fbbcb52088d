//! Newcomer-facing details of the workflow: `summarize` reports each
//! integrator's own energy, `consistent_state_holding` keeps chosen
//! coordinates fixed, and a step that fails from a state off the
//! constraints says so and names the remedy.

use vigp::prelude::*;
use vigp::projection::{consistent_state, consistent_state_holding};
use vigp::systems::{DoublePendulum, Fourbar};
use vigp::{SVector, summarize};

/// The midpoint VI's energy error is second order when measured at its
/// quadrature point (what `summarize` now uses): halving Δt divides the max
/// energy error over 2 s by ≈ 4 (measured 3.9–4.1); with the model's energy
/// at the discrete velocity it would look first order (÷ ≈ 2). The paper's
/// first-order VI stays first order (÷ ≈ 2). Tolerances: ratios in
/// [3.5, 4.5] and [1.6, 2.4], well apart.
#[test]
fn summarize_uses_each_integrators_own_energy() {
    let m = DoublePendulum::default().minimal();
    let z0 = |dt: f64| {
        let q = SVector::from([1.0, 0.5]);
        State {
            q,
            v: vigp::dynamics::discrete_velocity(&m, &q, &SVector::zeros(), dt).unwrap(),
        }
    };
    // max |ΔE| over 2 s at Δt = 0.004 and 0.002 (printed), and their ratio
    let halving_ratio = |name: &str, midpoint: bool| {
        let err = |dt: f64| {
            let vi = if midpoint {
                Variational::midpoint(m, dt)
            } else {
                Variational::new(m, dt)
            }
            .unwrap();
            let steps = (2.0 / dt).round() as usize;
            summarize(&vi, &m, &z0(dt), steps).unwrap().max_energy_error
        };
        let (a, b) = (err(0.004), err(0.002));
        let ratio = a / b;
        eprintln!("{name}: max |ΔE| {a:.3e} → {b:.3e}, ratio {ratio:.2}");
        ratio
    };
    let ratio = halving_ratio("midpoint VI", true);
    assert!((3.5..=4.5).contains(&ratio), "{ratio}");
    // the model's energy at the midpoint VI's discrete velocity is off by O(Δt)
    let vi = Variational::midpoint(m, 0.004).unwrap();
    let z = State::new([1.0, 0.5], [1.0, -1.0]);
    assert!((vi.energy(&z) - m.energy(&z)).abs() > 1e-3);
    let ratio = halving_ratio("paper VI", false);
    assert!((1.6..=2.4).contains(&ratio), "{ratio}");
}

#[test]
fn consistent_state_can_hold_chosen_coordinates() {
    let m = Fourbar::default().minimal();
    let dt = 0.01;
    let q = SVector::from([0.7, -1.0, -0.5, 1.0]);
    let v = SVector::from([0.3, 0.0, 0.1, 0.0]);
    assert!(m.constraints(&q).amax() > 0.1, "the guess is off the loop");
    let z = consistent_state_holding(&m, &q, &v, dt, &[0]).unwrap();
    assert_eq!(z.q[0], 0.7, "the held angle is kept exactly");
    assert_eq!(z.v[0], 0.3, "and its velocity");
    assert!(m.constraints(&z.q).amax() < 1e-12);
    assert!(m.constraints(&(z.q + z.v * dt)).amax() < 1e-12);
    // without holding, the projection moves the first angle too
    let free = consistent_state(&m, &q, &v, dt).unwrap();
    assert!((free.q[0] - 0.7).abs() > 1e-3);
    // holding two coordinates
    let z = consistent_state_holding(&m, &q, &v, dt, &[0, 2]).unwrap();
    assert_eq!((z.q[0], z.q[2]), (0.7, -0.5));
    assert!(m.constraints(&z.q).amax() < 1e-12);
    // held values the loop cannot reach: with links 1, 2 and 3 held, B and
    // C are fixed and |B − C| = 1 (link 4) does not hold
    let e = consistent_state_holding(&m, &q, &v, dt, &[0, 1, 2]).unwrap_err();
    assert!(matches!(e, StepError::NotConverged { .. }), "{e:?}");
    let e = consistent_state_holding(&m, &q, &v, dt, &[4]).unwrap_err();
    assert!(matches!(e, StepError::InvalidOptions(_)), "{e:?}");
    // every coordinate held: nothing can move, and the error says so
    let e = consistent_state_holding(&m, &q, &v, dt, &[0, 1, 2, 3]).unwrap_err();
    assert!(
        matches!(e, StepError::InvalidOptions(why) if why.contains("every coordinate is held")),
        "{e:?}"
    );
}

vigp::mechanism! {
    /// A five-bar linkage: two cranks on the ground 1 m apart, two
    /// couplers meeting at a tip (not one of the shipped systems).
    pub FiveBar {
        gravity: [0.0, -9.81],
        links {
            l1: { mass: 1.0, length: 1.0 },
            l2: { mass: 1.0, length: 1.5 },
            l3: { mass: 1.0, length: 1.0 },
            l4: { mass: 1.0, length: 1.5 },
        }
        joints {
            m1: revolute(world, l1.start),
            e1: revolute(l1.end, l2.start),
            m2: revolute(world @ [1.0, 0.0], l3.start),
            e2: revolute(l3.end, l4.start),
            tip: revolute(l2.end, l4.end),
        }
    }
}

/// Guesses with the loop open by ≈ 4 m and 2.9 m: the projection lands
/// near them, not whole turns away (before the corrections were capped,
/// the first guess came back 33.6 rad away, m1 three turns round). The
/// nearest consistent configurations, by scipy's SLSQP from 200 starts
/// (minimise ‖q − q₀‖² subject to g(q) = 0), are 1.612 and 1.289 rad
/// away; Gauss–Newton is nearest only to first order, so the test allows
/// twice that.
#[test]
fn projection_lands_near_the_guess() {
    let m = FiveBar::default().minimal();
    let dt = 0.01;
    for (guess, nearest) in [
        ([1.6, 0.0, -1.6, 0.0], 1.612),
        ([1.6, -0.5, -1.6, 0.5], 1.289),
    ] {
        let q0 = SVector::from(guess);
        let z = consistent_state(&m, &q0, &SVector::zeros(), dt).unwrap();
        let moved = (z.q - q0).norm();
        eprintln!(
            "guess {guess:?}: {:?}, moved {moved:.3} rad",
            z.q.as_slice()
        );
        assert!(m.constraints(&z.q).amax() < 1e-12);
        assert!(moved <= 2.0 * nearest, "{moved}");
        // holding the cranks: the couplers close the loop within π
        let z = consistent_state_holding(&m, &q0, &SVector::zeros(), dt, &[0, 2]).unwrap();
        assert_eq!((z.q[0], z.q[2]), (q0[0], q0[2]));
        assert!(m.constraints(&z.q).amax() < 1e-12);
        assert!((z.q - q0).amax() <= std::f64::consts::PI, "{:?}", z.q);
    }
}

/// A fourbar started with its loop open by 3.3 m (a guessed
/// configuration): the first step cannot close the gap; the error says the state is off the constraints and names
/// `consistent_state`. From the consistent state the same step converges.
#[test]
fn a_failed_step_off_the_constraints_names_the_remedy() {
    let m = Fourbar::default().minimal();
    let q = SVector::from([2.0, 1.0, -0.5, 0.5]);
    let z = State {
        q,
        v: SVector::zeros(),
    };
    let g = m.constraints(&q).amax();
    let e = Variational::new(m, 0.01).unwrap().step(&z).unwrap_err();
    eprintln!("|g| = {g:.2}: {e}");
    assert!(matches!(e, StepError::OffConstraints { .. }), "{e:?}");
    assert!(e.to_string().contains("consistent_state"), "{e}");
    let good = consistent_state(&m, &q, &SVector::zeros(), 0.01).unwrap();
    Variational::new(m, 0.01).unwrap().step(&good).unwrap();
}
