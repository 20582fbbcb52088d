//! Screened GP training (`Screening`): the starts run first on a subset,
//! the distinct optima are refined on all samples; and the same refinement
//! from the optima of an earlier training on a subset
//! (`TrainOptions::candidates`). Checked against the
//! unscreened training (every start on all samples, scikit-learn's
//! procedure, itself checked against scikit-learn in `tests/gp/gp_sklearn.rs`)
//! and against the likelihood recomputed at the result's hyperparameters.

use crate::common;
use common::Rng;
use vigp::gp::{
    Curvature, Gp, GpError, Hyperparameters, Method, SCREEN_FROM, Screening, SparseOptions,
    TrainOptions, TrainReport, log_marginal_likelihood,
};

/// Deterministic pseudo-random numbers in [0, 1) (Weyl sequence).
fn weyl(i: usize, k: f64) -> f64 {
    (i as f64 * k).fract()
}

/// N × 2 Weyl inputs (a, b) in [−2, 2]² and the target f(i, a, b) at
/// each (i = 1…N).
fn sample(n: usize, f: impl Fn(usize, f64, f64) -> f64) -> (Vec<f64>, Vec<f64>) {
    let mut x = Vec::with_capacity(2 * n);
    let mut y = Vec::with_capacity(n);
    for i in 1..=n {
        let (a, b) = (
            4.0 * weyl(i, 0.414_213_562_373_095) - 2.0,
            4.0 * weyl(i, 0.732_050_807_568_877) - 2.0,
        );
        x.extend([a, b]);
        y.push(f(i, a, b));
    }
    (x, y)
}

/// N × 2 inputs in [−2, 2]², a smooth target plus 0.02 uniform noise.
fn smooth(n: usize) -> (Vec<f64>, Vec<f64>) {
    sample(n, |i, a, b| {
        (2.0 * a).sin() * b.cos() + 0.3 * b + 0.04 * (weyl(i, 0.754_877_666_246_693) - 0.5)
    })
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

/// Two outputs on the inputs of [`smooth`]: its target, and a second
/// smooth function of the other input plus 0.04 uniform noise (without
/// noise the likelihood's optimum sits at the noise floor, where the
/// jitter ladder makes it discontinuous).
fn two_outputs(n: usize) -> (Vec<f64>, Vec<f64>) {
    let (x, y) = smooth(n);
    let t: Vec<f64> = y
        .iter()
        .zip(x.chunks_exact(2))
        .enumerate()
        .flat_map(|(i, (y, xi))| {
            let noise = 0.04 * (weyl(i + 1, 0.569_840_290_998_053) - 0.5);
            [*y, (1.5 * xi[1]).cos() + 0.1 * xi[0] + noise]
        })
        .collect();
    (x, t)
}

/// The setting of the nested-subset tests: 600 samples of
/// [`two_outputs`], and the first half of them trained with every start.
struct HalfData {
    /// The inputs of all samples.
    x: Vec<f64>,
    /// The targets of all samples.
    t: Vec<f64>,
    /// The number of samples in the first half.
    half: usize,
    /// The model trained on the first half.
    gp: Gp,
    /// Its training report.
    report: TrainReport,
    /// Its distinct optima, per output, in original units.
    optima: Vec<Vec<Hyperparameters>>,
}

/// [`HalfData`]: the samples and the first half's training.
fn half_data_training() -> HalfData {
    let n = 600;
    let (x, t) = two_outputs(n);
    let half = n / 2;
    let (gp, report) =
        Gp::train(&x[..2 * half], 2, &t[..2 * half], 2, &opts(Screening::Off)).unwrap();
    let optima = report.outputs.iter().map(|o| o.optima.clone()).collect();
    HalfData {
        x,
        t,
        half,
        gp,
        report,
        optima,
    }
}

#[test]
fn candidates_from_a_nested_subset_reach_the_unscreened_optimum() {
    // The first N/2 samples trained with every start; their distinct
    // optima (original units) refined on all N samples. Checked against
    // every start on all N samples (scikit-learn's procedure).
    let HalfData { x, t, optima, .. } = half_data_training();
    assert!(optima.iter().all(|o| !o.is_empty()));
    let with = TrainOptions {
        candidates: Some(optima.clone()),
        ..opts(Screening::Auto)
    };
    let (gp_c, rep_c) = Gp::train(&x, 2, &t, 2, &with).unwrap();
    let (_, rep_u) = Gp::train(&x, 2, &t, 2, &opts(Screening::Off)).unwrap();
    for (o, cands) in optima.iter().enumerate() {
        let (c, u) = (&rep_c.outputs[o], &rep_u.outputs[o]);
        let scr = c.screening.as_ref().expect("candidates are reported");
        println!(
            "output {o}: candidates {} → LML {:.9} with {} evaluations; unscreened LML {:.9} with {}",
            cands.len(),
            c.log_marginal_likelihood,
            c.evaluations,
            u.log_marginal_likelihood,
            u.evaluations
        );
        assert_eq!(scr.subset, 0);
        assert!(scr.start_lmls.is_empty() && scr.evaluations == 0);
        assert!(!scr.fell_back);
        // every candidate ran, numbered by its index
        assert_eq!(scr.refined, (0..cands.len()).collect::<Vec<_>>());
        assert_eq!(c.start_lmls.len(), 7.max(cands.len()));
        assert!(scr.refined.contains(&c.best_start));
        // the acceptance tolerance against scikit-learn's best LML
        let rel = (c.log_marginal_likelihood - u.log_marginal_likelihood)
            / u.log_marginal_likelihood.abs();
        assert!(rel >= -1e-6, "output {o}: {rel:e} below the unscreened LML");
        assert!(
            2 * c.evaluations < u.evaluations,
            "{} vs {}",
            c.evaluations,
            u.evaluations
        );
        // the first optimum is the model's, in original units
        let (a, b) = (&c.optima[0], gp_c.output(o).hyperparameters_original());
        let close = |p: f64, q: f64| (p - q).abs() <= 1e-12 * q.abs();
        assert!(
            a.length_scales
                .iter()
                .zip(&b.length_scales)
                .all(|(p, q)| close(*p, *q))
        );
        assert!(close(a.signal_variance, b.signal_variance));
        assert!(close(a.noise_variance, b.noise_variance));
    }
}

#[test]
fn candidate_curvature_seeds_the_refinements() {
    // The setting of the test above, with the half data's curvature pairs
    // handed over too: the same optimum (the acceptance tolerance against
    // the unscreened LML) in fewer evaluations on all samples than with
    // empty memories. The pairs themselves are checked against the
    // likelihood's gradient recomputed at the half data's model.
    let HalfData {
        x,
        t,
        half,
        gp: gp_h,
        report: rep_h,
        optima,
    } = half_data_training();
    let curvature: Vec<Vec<Curvature>> = rep_h
        .outputs
        .iter()
        .map(|o| o.optima_curvature.clone())
        .collect();
    // the newest pair of the winning run ends at the model: y is the
    // change of the gradient of −LML (normalised units) along s
    let norm = gp_h.input_normaliser();
    let xn: Vec<f64> = x[..2 * half]
        .chunks_exact(2)
        .flat_map(|r| (0..2).map(move |j| (r[j] - norm.shift[j]) / norm.scale[j]))
        .collect();
    for (o, cs) in curvature.iter().enumerate() {
        assert_eq!(cs.len(), optima[o].len());
        assert!(cs.iter().all(|c| c.samples == half && !c.pairs.is_empty()));
        assert!(cs.iter().flat_map(|c| &c.pairs).all(|(s, y)| {
            s.len() == 4 && y.len() == 4 && s.iter().zip(y).map(|(a, b)| a * b).sum::<f64>() > 0.0
        }));
        let out = gp_h.output(o);
        let theta = out.hyperparameters().to_log();
        let r = out.residual_normalised();
        let grad = |th: &[f64]| -> Vec<f64> {
            let (_, g) = log_marginal_likelihood(&xn, 2, r, th, false).unwrap();
            g.into_iter().map(|v| -v).collect()
        };
        let (s, y) = cs[0].pairs.last().unwrap();
        let before: Vec<f64> = theta.iter().zip(s).map(|(a, b)| a - b).collect();
        let (g1, g0) = (grad(&theta), grad(&before));
        let scale = g0.iter().chain(&g1).fold(1.0f64, |m, v| m.max(v.abs()));
        for k in 0..4 {
            // two gradients of one code at the same points: rounding only
            assert!(
                (g1[k] - g0[k] - y[k]).abs() <= 1e-9 * scale,
                "output {o}, coordinate {k}: {} vs {}",
                g1[k] - g0[k],
                y[k]
            );
        }
    }
    let without = TrainOptions {
        candidates: Some(optima.clone()),
        ..opts(Screening::Auto)
    };
    let with = TrainOptions {
        candidate_curvature: Some(curvature),
        ..without.clone()
    };
    let (_, rep_w) = Gp::train(&x, 2, &t, 2, &with).unwrap();
    let (_, rep_0) = Gp::train(&x, 2, &t, 2, &without).unwrap();
    let (_, rep_u) = Gp::train(&x, 2, &t, 2, &opts(Screening::Off)).unwrap();
    for o in 0..2 {
        let (w, z, u) = (&rep_w.outputs[o], &rep_0.outputs[o], &rep_u.outputs[o]);
        println!(
            "output {o}: seeded LML {:.9} with {} evaluations; empty memories {:.9} with {}; unscreened {:.9} with {}",
            w.log_marginal_likelihood,
            w.evaluations,
            z.log_marginal_likelihood,
            z.evaluations,
            u.log_marginal_likelihood,
            u.evaluations
        );
        assert!(!w.screening.as_ref().unwrap().fell_back);
        let rel = (w.log_marginal_likelihood - u.log_marginal_likelihood)
            / u.log_marginal_likelihood.abs();
        assert!(rel >= -1e-6, "output {o}: {rel:e} below the unscreened LML");
        assert!(w.evaluations < z.evaluations);
    }
}

#[test]
fn candidate_curvature_is_checked() {
    let (x, y) = smooth(40);
    let h = Hyperparameters::isotropic(2, 1.0, 1.0, 1e-2);
    let pair = (vec![0.1, 0.0, 0.0, 0.0], vec![1.0, 0.0, 0.0, 0.0]);
    let with = |c: Vec<Vec<Curvature>>| TrainOptions {
        candidates: Some(vec![vec![h.clone()]]),
        candidate_curvature: Some(c),
        ..opts(Screening::Auto)
    };
    let curv = |samples: usize, pairs: Vec<(Vec<f64>, Vec<f64>)>| Curvature { samples, pairs };
    // a valid seed trains
    assert!(
        Gp::train(
            &x,
            2,
            &y,
            1,
            &with(vec![vec![curv(20, vec![pair.clone()])]])
        )
        .is_ok()
    );
    // shapes: per output, per candidate, d + 2 per vector
    for c in [
        vec![],
        vec![vec![]],
        vec![vec![curv(20, vec![]), curv(20, vec![])]],
        vec![vec![curv(20, vec![(vec![0.1; 3], vec![1.0; 3])])]],
    ] {
        assert!(matches!(
            Gp::train(&x, 2, &y, 1, &with(c)),
            Err(GpError::DimensionMismatch { .. })
        ));
    }
    // values: samples 0, a non-finite pair, curvature without candidates
    let nan = (vec![0.1, 0.0, 0.0, f64::NAN], vec![1.0; 4]);
    for o in [
        with(vec![vec![curv(0, vec![pair.clone()])]]),
        with(vec![vec![curv(20, vec![nan])]]),
        TrainOptions {
            candidates: None,
            ..with(vec![vec![curv(20, vec![pair])]])
        },
    ] {
        assert!(matches!(
            Gp::train(&x, 2, &y, 1, &o),
            Err(GpError::InvalidOptions(_))
        ));
    }
}

#[test]
fn optima_are_distinct_best_first_and_in_original_units() {
    // Inputs scaled by 0.01 and outputs by 1000: the optima must carry the
    // units (ℓ in input units, σ² in output units²), and conditioning on
    // each one (`Gp::fit` takes normalised units) gives its LML. A wiggly
    // target on 60 samples: the starts end at two optima beside the
    // white-noise plateau (seed 3, 1 + 8 starts).
    let (x, y) = sample(60, |i, a, b| {
        let noise = 0.3 * (weyl(i, 0.754_877_666_246_693) - 0.5);
        (5.0 * a).sin() + 0.2 * b + noise
    });
    let xs: Vec<f64> = x.iter().map(|v| 0.01 * v).collect();
    let ys: Vec<f64> = y.iter().map(|v| 1000.0 * v).collect();
    let o = TrainOptions {
        restarts: 8,
        ..opts(Screening::Off)
    };
    let (gp, rep) = Gp::train(&xs, 2, &ys, 1, &o).unwrap();
    let optima = &rep.outputs[0].optima;
    assert_eq!(optima.len(), 2, "{optima:?}");
    let sx = gp.input_normaliser().scale.clone();
    let sy = gp.output(0).output_scale();
    let mut last: Option<f64> = None;
    for h in optima {
        let hn = Hyperparameters {
            length_scales: h
                .length_scales
                .iter()
                .zip(&sx)
                .map(|(l, s)| l / s)
                .collect(),
            signal_variance: h.signal_variance / (sy * sy),
            noise_variance: h.noise_variance / (sy * sy),
        };
        let lml = Gp::fit(&xs, 2, &ys, 1, &[hn], &o)
            .unwrap()
            .output(0)
            .log_marginal_likelihood();
        if let Some(prev) = last {
            // best first, and distinct: optima within 1e-6 (relative) of a
            // better one's LML count once (half that here, for the
            // refactorisation's rounding)
            assert!(
                prev - lml > 0.5e-6 * prev.abs().max(1.0),
                "not best first and distinct: {lml} after {prev}"
            );
        } else {
            // the first is the model's: its LML, recomputed
            let r = rep.outputs[0].log_marginal_likelihood;
            assert!((lml - r).abs() <= 1e-9 * r.abs(), "{lml} vs {r}");
        }
        last = Some(lml);
    }
}

#[test]
fn an_output_without_candidates_runs_its_starts() {
    // The first output's candidates are refined; the second has none, and
    // runs the initial point and the restarts on all samples, as without
    // candidates (the same runs, so the same LML bit for bit).
    let (x, t) = two_outputs(200);
    let (_, rep_h) = Gp::train(&x[..200], 2, &t[..200], 2, &opts(Screening::Off)).unwrap();
    let with = TrainOptions {
        candidates: Some(vec![rep_h.outputs[0].optima.clone(), Vec::new()]),
        ..opts(Screening::Off)
    };
    let (_, rep_c) = Gp::train(&x, 2, &t, 2, &with).unwrap();
    let (_, rep_u) = Gp::train(&x, 2, &t, 2, &opts(Screening::Off)).unwrap();
    let scr = |o: usize| rep_c.outputs[o].screening.clone().unwrap();
    assert!(!scr(0).fell_back);
    assert!(scr(1).fell_back && scr(1).refined.is_empty());
    assert_eq!(
        rep_c.outputs[1].log_marginal_likelihood,
        rep_u.outputs[1].log_marginal_likelihood
    );
    assert_eq!(rep_c.outputs[1].evaluations, rep_u.outputs[1].evaluations);
}

#[test]
fn candidate_options_are_checked() {
    let (x, y) = smooth(40);
    let h = Hyperparameters::isotropic(2, 1.0, 1.0, 1e-2);
    let with = |c: Vec<Vec<Hyperparameters>>| TrainOptions {
        candidates: Some(c),
        ..opts(Screening::Auto)
    };
    assert!(matches!(
        Gp::train(&x, 2, &y, 1, &with(vec![vec![h.clone()], vec![h.clone()]])),
        Err(GpError::DimensionMismatch { .. })
    ));
    let bad = Hyperparameters {
        signal_variance: f64::NAN,
        ..h.clone()
    };
    assert!(Gp::train(&x, 2, &y, 1, &with(vec![vec![bad]])).is_err());
    let short = Hyperparameters::isotropic(3, 1.0, 1.0, 1e-2);
    assert!(Gp::train(&x, 2, &y, 1, &with(vec![vec![short]])).is_err());
    for o in [
        TrainOptions {
            warm_start: Some(vec![h.clone()]),
            ..with(vec![vec![h.clone()]])
        },
        TrainOptions {
            method: Method::Sparse(SparseOptions::kmeans(8)),
            ..with(vec![vec![h.clone()]])
        },
    ] {
        assert!(matches!(
            Gp::train(&x, 2, &y, 1, &o),
            Err(GpError::InvalidOptions(_))
        ));
    }
}
