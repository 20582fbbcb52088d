//! The exported GP in the `no_std` demo: it reproduces the std model that
//! wrote it (check values in the generated file, bit for bit), and neither a
//! GP prediction nor a learned step allocates.

use vigp::embedded::State;
use vigp::embedded::gp::GpError;
use vigp_embedded_demo::learned::gp_model::{
    GP, GP_CHECK_MEANS, GP_CHECK_POINTS, GP_CHECK_VARIANCES, GP_N,
};
use vigp_embedded_demo::learned::{
    LearnedError, correction, learned_step, learned_step_with_variance,
};
use vigp_embedded_demo::stepper;

/// Means: the same kernels on the same (round-tripped) numbers, so equal bit
/// for bit. Variances: the same solve order too; asserted to 1e-12 relative
/// (observed: equal bits, printed).
#[test]
fn compiled_export_reproduces_the_std_model() {
    let mut scratch = [0.0; GP_N];
    let mut worst_var = 0.0f64;
    for ((x, means), vars) in GP_CHECK_POINTS
        .iter()
        .zip(&GP_CHECK_MEANS)
        .zip(&GP_CHECK_VARIANCES)
    {
        for j in 0..2 {
            let m = GP[j].predict_mean(x).unwrap();
            assert_eq!(m.to_bits(), means[j].to_bits(), "{m} vs {}", means[j]);
            let (m2, v) = GP[j].predict(x, &mut scratch).unwrap();
            assert_eq!(m2.to_bits(), m.to_bits());
            let rel = (v - vars[j]).abs() / vars[j].abs().max(f64::MIN_POSITIVE);
            worst_var = worst_var.max(rel);
        }
    }
    println!("max relative variance difference {worst_var:e}");
    assert!(worst_var <= 1e-12, "{worst_var}");
    for gp in &GP {
        gp.validate().unwrap();
    }
}

#[test]
fn gp_predictions_and_learned_steps_do_not_allocate() {
    let s = stepper().unwrap();
    let x = GP_CHECK_POINTS[0];
    let z = State::new([0.7, -0.4], [0.3, -1.2]);
    let mut scratch = [0.0; GP_N];
    let _ = learned_step(&s, &z).unwrap(); // warm-up
    let info = allocation_counter::measure(|| {
        let mut acc = 0.0;
        for _ in 0..10 {
            acc += GP[0].predict_mean(&x).unwrap() + GP[1].predict_mean(&x).unwrap();
            acc += GP[1].predict(&x, &mut scratch).unwrap().1;
            let c = correction(&z).unwrap();
            let z1 = learned_step(&s, &z).unwrap();
            let (z2, var) = learned_step_with_variance(&s, &z, &mut scratch).unwrap();
            acc += c[0] + z1.v[1] + z2.v[0] + var[1];
        }
        assert!(acc.is_finite());
    });
    assert_eq!(info.count_total, 0, "{info:?}");
}

/// The learned step is the nominal step plus the GP correction, and bad
/// input is a typed error, not a NaN.
#[test]
fn learned_step_is_nominal_plus_correction_and_rejects_nan() {
    let s = stepper().unwrap();
    let z = State::new([0.7, -0.4], [0.3, -1.2]);
    let nominal = s.step(&z).unwrap();
    let learned = learned_step(&s, &z).unwrap();
    let c = correction(&z).unwrap();
    assert_eq!(learned.q, nominal.q);
    for (j, cj) in c.iter().enumerate() {
        assert_eq!(learned.v[j], nominal.v[j] + cj);
    }
    // the correction is a real one: of the size the GP was trained on
    assert!(c.iter().any(|v| v.abs() > 1e-4), "{c:?}");
    let bad = State::new([f64::NAN, 0.0], [0.0, 0.0]);
    assert!(matches!(learned_step(&s, &bad), Err(LearnedError::Step(_))));
    assert_eq!(
        GP[0].predict_mean(&[0.0, 1.0, f64::INFINITY, 1.0, 0.0, 0.0]),
        Err(GpError::NonFiniteInput { index: 2 })
    );
}
