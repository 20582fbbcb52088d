//! Screened GP training (`Screening`): the starts run first on a subset,
//! the distinct optima are refined on all samples. Checked against the
//! unscreened training (every start on all samples, scikit-learn's
//! procedure, itself checked against scikit-learn in `tests/gp_sklearn.rs`)
//! and against the likelihood recomputed at the result's hyperparameters.

mod common;

use common::Rng;
use vigp::gp::{
    Gp, GpError, Method, SCREEN_FROM, Screening, SparseOptions, TrainOptions,
    log_marginal_likelihood,
};

/// Deterministic pseudo-random numbers in [0, 1) (Weyl sequence).
fn weyl(i: usize, k: f64) -> f64 {
    (i as f64 * k).fract()
}

/// N × 2 inputs in [−2, 2]², a smooth target plus 0.02 uniform noise.
fn smooth(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = Vec::with_capacity(2 * n);
    let mut y = Vec::with_capacity(n);
    for i in 1..=n {
        let (a, b) = (
            4.0 * weyl(i, 0.414_213_562_373_095) - 2.0,
            4.0 * weyl(i, 0.732_050_807_568_877) - 2.0,
        );
        x.extend([a, b]);
        y.push((2.0 * a).sin() * b.cos() + 0.3 * b + 0.04 * (weyl(i, 0.754_877_666_246_693) - 0.5));
    }
    (x, y)
}

fn opts(screening: Screening) -> TrainOptions {
    TrainOptions {
        restarts: 6,
        seed: 3,
        screening,
        ..Default::default()
    }
}

#[test]
fn screening_reaches_the_unscreened_optimum_with_fewer_full_evaluations() {
    let (x, y) = smooth(640);
    let (gp_s, rep_s) = Gp::train(&x, 2, &y, 1, &opts(Screening::Auto)).unwrap();
    let (_, rep_u) = Gp::train(&x, 2, &y, 1, &opts(Screening::Off)).unwrap();
    let (s, u) = (&rep_s.outputs[0], &rep_u.outputs[0]);
    let scr = s
        .screening
        .as_ref()
        .expect("N = 640 is screened by default");
    println!(
        "screened: LML {:.9} with {} evaluations on all samples (+{} on {} samples), refined {:?}; \
         unscreened: LML {:.9} with {} evaluations",
        s.log_marginal_likelihood,
        s.evaluations,
        scr.evaluations,
        scr.subset,
        scr.refined,
        u.log_marginal_likelihood,
        u.evaluations
    );
    assert!(u.screening.is_none());
    // the acceptance tolerance against scikit-learn's best LML
    let rel =
        (s.log_marginal_likelihood - u.log_marginal_likelihood) / u.log_marginal_likelihood.abs();
    assert!(
        rel >= -1e-6,
        "screened LML {rel:e} (relative) below the unscreened one"
    );
    assert_eq!(scr.subset, Screening::auto_size(640));
    assert!(!scr.fell_back && !scr.refined.is_empty());
    assert!(scr.refined.iter().all(|&k| k < 7));
    assert!(scr.start_lmls.iter().all(|v| v.is_finite()));
    assert_eq!(scr.evaluations, scr.start_evaluations.iter().sum::<usize>());
    // only refined starts ran on all samples
    for (k, lml) in s.start_lmls.iter().enumerate() {
        assert_eq!(lml.is_finite(), scr.refined.contains(&k), "start {k}");
    }
    assert!(scr.refined.contains(&s.best_start));
    // the point of screening: far fewer evaluations on all samples
    assert!(
        2 * s.evaluations < u.evaluations,
        "{} vs {}",
        s.evaluations,
        u.evaluations
    );
    // the reported LML is the likelihood at the returned hyperparameters,
    // recomputed on the model's normalised data by the raw objective
    // (relative 1e-9: the same formula, evaluated once more)
    let o = gp_s.output(0);
    let mut xn = vec![0.0; x.len()];
    for (dst, src) in xn.chunks_exact_mut(2).zip(x.chunks_exact(2)) {
        gp_s.input_normaliser().apply(src, dst);
    }
    let (v, _) = log_marginal_likelihood(
        &xn,
        2,
        o.residual_normalised(),
        &o.hyperparameters().to_log(),
        false,
    )
    .unwrap();
    assert!(
        (v - s.log_marginal_likelihood).abs() <= 1e-9 * v.abs(),
        "{v} vs {}",
        s.log_marginal_likelihood
    );
}

#[test]
fn white_noise_falls_back_to_the_unscreened_starts() {
    // Targets without any dependence on the inputs: the white-noise
    // plateau is the answer, and the screened fit runs every start again
    // on all samples, giving the unscreened result bit for bit.
    let n = 520;
    let mut rng = Rng(11);
    let x: Vec<f64> = (0..2 * n).map(|_| rng.uniform(-2.0, 2.0)).collect();
    let y: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let (_, rep_s) = Gp::train(&x, 2, &y, 1, &opts(Screening::Auto)).unwrap();
    let (_, rep_u) = Gp::train(&x, 2, &y, 1, &opts(Screening::Off)).unwrap();
    let (s, u) = (&rep_s.outputs[0], &rep_u.outputs[0]);
    let scr = s.screening.as_ref().unwrap();
    assert!(scr.fell_back && scr.refined.is_empty());
    assert_eq!(s.log_marginal_likelihood, u.log_marginal_likelihood);
    assert_eq!(s.start_lmls.len(), u.start_lmls.len());
    assert_eq!(s.evaluations, u.evaluations);
}

#[test]
fn auto_screening_starts_at_screen_from_and_obeys_the_options() {
    assert_eq!(SCREEN_FROM, 512);
    assert_eq!(Screening::auto_size(512), 256);
    assert_eq!(Screening::auto_size(2048), 512);
    assert_eq!(Screening::auto_size(100_000), 1024);
    let (x, y) = smooth(SCREEN_FROM - 1);
    let fast = |screening| TrainOptions {
        restarts: 0,
        ..opts(screening)
    };
    let (_, r) = Gp::train(&x, 2, &y, 1, &fast(Screening::Auto)).unwrap();
    assert!(r.outputs[0].screening.is_none());
    let (x, y) = smooth(300);
    let (_, r) = Gp::train(&x, 2, &y, 1, &fast(Screening::Subset(100))).unwrap();
    assert_eq!(r.outputs[0].screening.as_ref().unwrap().subset, 100);
    // a subset of N or more samples is no screening
    let (_, r) = Gp::train(&x, 2, &y, 1, &fast(Screening::Subset(300))).unwrap();
    assert!(r.outputs[0].screening.is_none());
    // a warm start turns Auto off
    let (x, y) = smooth(SCREEN_FROM);
    let (gp, _) = Gp::train(&x, 2, &y, 1, &fast(Screening::Off)).unwrap();
    let warm = TrainOptions {
        warm_start: Some(gp.warm_start()),
        ..fast(Screening::Auto)
    };
    let (_, r) = Gp::train(&x, 2, &y, 1, &warm).unwrap();
    assert!(r.outputs[0].screening.is_none());
}

#[test]
fn screening_options_are_checked() {
    let (x, y) = smooth(40);
    let bad = [
        opts(Screening::Subset(1)),
        TrainOptions {
            method: Method::Sparse(SparseOptions::kmeans(8)),
            ..opts(Screening::Subset(20))
        },
    ];
    for o in bad {
        assert!(matches!(
            Gp::train(&x, 2, &y, 1, &o),
            Err(GpError::InvalidOptions(_))
        ));
    }
    // Auto leaves a sparse GP alone
    let sparse = TrainOptions {
        method: Method::Sparse(SparseOptions::kmeans(8)),
        restarts: 0,
        ..opts(Screening::Auto)
    };
    let (_, r) = Gp::train(&x, 2, &y, 1, &sparse).unwrap();
    assert!(r.outputs[0].screening.is_none());
}
