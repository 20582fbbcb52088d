//! The embedded program allocates nothing: not per step, not per prediction.

use vigp::embedded::State;
use vigp_embedded_demo::{energy, predict, stepper};

#[test]
fn steps_and_predictions_do_not_allocate() {
    let s = stepper().unwrap();
    let z0 = State::new([1.0, -0.5], [0.0, 0.0]);
    let mut out = [z0; 200];
    // warm-up outside the measurement (nothing is lazily initialised, but
    // this keeps the measurement about the steady state)
    predict(&s, &z0, &mut out).unwrap();
    let info = allocation_counter::measure(|| {
        let z1 = s.step(&z0).unwrap();
        predict(&s, &z1, &mut out).unwrap();
        assert!(energy(&out[199]).is_finite());
    });
    assert_eq!(info.count_total, 0, "{info:?}");
}

/// The same program's prediction is a real simulation: a damped pendulum
/// loses energy, and the first step is the closed-form x₁ = x₀ + Δt·v₀.
#[test]
fn prediction_is_a_damped_simulation() {
    let s = stepper().unwrap();
    let z0 = State::new([1.0, -0.5], [0.3, 0.0]);
    let mut out = [z0; 1001];
    predict(&s, &z0, &mut out).unwrap();
    assert!((out[1].q - (z0.q + z0.v * vigp_embedded_demo::DT)).amax() < 1e-15);
    let (e0, e1) = (energy(&out[0]), energy(&out[1000]));
    println!("energy {e0:.4} J -> {e1:.4} J after 10 s");
    assert!(e1 < e0 - 1e-3, "{e0} -> {e1}");
}
