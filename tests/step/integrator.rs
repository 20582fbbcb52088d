//! The one [`Integrator`] trait over configuration spaces: code written
//! once against it runs the planar variational integrator (`State<N>`) and
//! the spatial Lie-group integrator (`SpatialState<B>`). The reference is
//! the integrator's own single step: the trait's rollouts must be its
//! steps repeated (bit for bit where they step from scratch, to the Newton
//! tolerance where they carry the momentum or extrapolate the start), and
//! a failing rollout must name the failing step in both spaces.

use nalgebra::SVector;
use vigp::Integrator;
use vigp::spatial::{LieStepper, SpatialError, SpatialState};
use vigp::{State, StepError, Variational};

use crate::control::TorquePendulum;
use crate::spatial_control::Arm3;

/// `steps` single steps from `z0` under `inputs[k]` (z₀ first): the
/// reference every rollout of the trait is held to. Written once for
/// every integrator.
fn stepped<I: Integrator, const U: usize>(
    integrator: &I,
    z0: &I::State,
    inputs: &[SVector<f64, U>],
) -> Vec<I::State>
where
    I::Mechanism: vigp::Inputs<U>,
{
    let mut out = vec![*z0];
    for u in inputs {
        let z = integrator.step_forced(out.last().unwrap(), u).unwrap();
        out.push(z);
    }
    out
}

/// The trait's rollouts of one integrator against its single steps:
/// `rollout` and `rollout_forced` within `tol` (the distance `dist`),
/// `rollout_into` and `rollout_forced_into` filling the states after z₀;
/// forced rollouts under `inputs`, unforced ones under zeros.
fn rollouts_are_steps<I: Integrator, const U: usize>(
    integrator: &I,
    z0: &I::State,
    inputs: &[SVector<f64, U>],
    dist: impl Fn(&I::State, &I::State) -> f64,
    tol: f64,
) -> f64
where
    I::Mechanism: vigp::Inputs<U>,
{
    let k = inputs.len();
    let forced = stepped(integrator, z0, inputs);
    let free = stepped(integrator, z0, &vec![SVector::<f64, U>::zeros(); k]);
    let mut worst = 0.0f64;
    let mut compare = |got: &[I::State], want: &[I::State]| {
        assert_eq!(got.len(), want.len());
        for (a, b) in got.iter().zip(want) {
            worst = worst.max(dist(a, b));
        }
    };
    compare(&integrator.rollout(z0, k).unwrap(), &free);
    compare(&integrator.rollout_forced(z0, inputs).unwrap(), &forced);
    let mut out = vec![*z0; k];
    integrator.rollout_into(z0, &mut out).unwrap();
    compare(&out, &free[1..]);
    integrator
        .rollout_forced_into(z0, inputs, &mut out)
        .unwrap();
    compare(&out, &forced[1..]);
    assert!(
        worst <= tol,
        "rollouts differ from the steps by {worst:.1e}"
    );
    worst
}

/// Slowly varying torques for `k` steps.
fn torques<const U: usize>(k: usize) -> Vec<SVector<f64, U>> {
    (0..k)
        .map(|j| SVector::from_fn(|i, _| 0.05 * (0.3 * j as f64 + 1.1 * i as f64).sin()))
        .collect()
}

/// The same generic code steps a planar and a spatial mechanism. The
/// rollouts that carry the momentum (planar) or extrapolate Newton's start
/// (spatial `rollout`/`rollout_forced`) converge to the same roots as the
/// single steps to the Newton tolerance, a residual of 1e-12 in momentum
/// units, which the mass matrix turns into velocities: 1e-10 over 40 steps
/// on the 1 kg pendulum (measured 6.7e-16), 1e-8 on the arm, whose links
/// have 2e-4 kg·m² about their axes, so up to 5e-9 rad/s a step (measured
/// 1.4e-10). The spatial `rollout_into`, which steps from scratch, is bit
/// for bit.
#[test]
fn one_trait_rolls_out_planar_and_spatial_integrators() {
    let dt = 0.01;
    let planar = Variational::new(TorquePendulum::default().minimal(), dt).unwrap();
    let z0 = State::new([0.7], [-0.2]);
    let planar_gap = |a: &State<1>, b: &State<1>| (a.q - b.q).amax().max((a.v - b.v).amax());
    let p = rollouts_are_steps(&planar, &z0, &torques::<1>(40), planar_gap, 1e-10);

    let arm = Arm3::default();
    let spatial = LieStepper::new(arm.maximal(), dt).unwrap();
    let zs = arm
        .minimal()
        .to_maximal(&State::new([0.2, 2.6], [1.0, -0.5]), dt);
    let s = rollouts_are_steps(&spatial, &zs, &torques::<2>(40), spatial_gap, 1e-8);
    // the spatial rollout_into steps from scratch: bit for bit
    let mut out = vec![zs; 40];
    Integrator::rollout_into(&spatial, &zs, &mut out).unwrap();
    let free = stepped(&spatial, &zs, &vec![SVector::<f64, 2>::zeros(); 40]);
    assert_eq!(out, free[1..]);
    println!("rollouts against single steps: planar {p:.1e}, spatial {s:.1e}");
}

/// The largest difference of positions, orientations and velocities.
fn spatial_gap<const B: usize>(a: &SpatialState<B>, b: &SpatialState<B>) -> f64 {
    (0..B)
        .map(|i| {
            [
                (a.x[i] - b.x[i]).amax(),
                a.q[i].angle_to(&b.q[i]),
                (a.v[i] - b.v[i]).amax(),
                (a.w[i] - b.w[i]).amax(),
            ]
            .into_iter()
            .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Failures through the trait, in both spaces: a non-finite state fails at
/// step 0 of a rollout, and too few inputs fail before any step at the
/// first missing one. The planar error carries the step in its variant,
/// the spatial one wraps the step's error in `SpatialError::Rollout`.
#[test]
fn rollouts_name_the_failing_step_in_both_spaces() {
    let dt = 0.01;
    let planar = Variational::new(TorquePendulum::default().minimal(), dt).unwrap();
    let bad = State::new([f64::NAN], [0.0]);
    assert!(matches!(
        planar.rollout(&bad, 3),
        Err(StepError::NonFiniteState { step: Some(0) })
    ));
    let z0 = State::new([0.3], [0.0]);
    let mut out = [z0; 3];
    assert!(matches!(
        Integrator::rollout_forced_into(&planar, &z0, &torques::<1>(2), &mut out),
        Err(StepError::NonFiniteInput { step: Some(2) })
    ));

    let arm = Arm3::default();
    let spatial = LieStepper::new(arm.maximal(), dt).unwrap();
    let zs = arm
        .minimal()
        .to_maximal(&State::new([0.2, 2.6], [0.0; 2]), dt);
    let mut nan = zs;
    nan.v[1].x = f64::NAN;
    match Integrator::rollout(&spatial, &nan, 3) {
        Err(SpatialError::Rollout(e)) => {
            assert_eq!(e.step, 0);
            assert!(matches!(e.error, StepError::NonFiniteState { .. }), "{e}");
        }
        other => panic!("expected a failure at step 0, got {other:?}"),
    }
    let mut out = [zs; 3];
    assert!(matches!(
        Integrator::rollout_forced_into(&spatial, &zs, &torques::<2>(2), &mut out),
        Err(SpatialError::Step(StepError::NonFiniteInput {
            step: Some(2)
        }))
    ));
}
