//! A trained GP exported for `no_std` prediction (`Gp::export_output`,
//! `Gp::to_rust_source`, `vigp::embedded::gp::ExportedGp`):
//!
//! * the exported model reproduces the std model's posterior mean bit for
//!   bit and its variance to 1e-10·σ_f²s_y² (both variance paths of the std
//!   model; see `compare`), on random points inside and
//!   outside the data, for several model shapes (normalisation on/off,
//!   zero/constant prior, d = 1…9, N not a multiple of the block size, a
//!   nearly noise-free ill-conditioned fit);
//! * both agree with an independent dense computation in original units
//!   (nalgebra Cholesky, `f64::exp`) to rounding: mean within
//!   1e-12·Σ|k_i·α_i|, variance within 1e-9·σ_f²s_y² (well-conditioned
//!   models only);
//! * the generated source round-trips every float exactly (parsed back,
//!   compared by `to_bits`) and is deterministic (same model → same text;
//!   retrained with the same seed → same text);
//! * the committed `embedded-demo/src/gp_model.rs` compiles here too and
//!   reproduces the check values it carries.

use crate::common;
use common::Rng;
use nalgebra::{DMatrix, DVector};
use vigp::gp::{ExportOptions, ExportedArrays, Gp, GpError, PriorMean, TrainOptions, VarianceMode};

#[allow(dead_code, clippy::all)]
mod demo_model {
    include!("../../embedded-demo/src/gp_model.rs");
}

/// Smooth multi-output data on `d` inputs.
fn data(n: usize, d: usize, p: usize, noise: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng(seed);
    let x: Vec<f64> = (0..n * d)
        .map(|_| rng.uniform(-2.0, 2.0) * 1.5 + 0.3)
        .collect();
    let y: Vec<f64> = x
        .chunks(d)
        .flat_map(|r| {
            let s: f64 = r
                .iter()
                .enumerate()
                .map(|(j, v)| (j as f64 + 1.0) * v)
                .sum();
            let noise = noise * rng.uniform(-1.0, 1.0);
            (0..p)
                .map(|j| (s * 0.3 + j as f64).sin() * 2.0 + r[0] * j as f64 + noise + 5.0)
                .collect::<Vec<_>>()
        })
        .collect();
    (x, y)
}

fn train(n: usize, d: usize, p: usize, noise: f64, opts: TrainOptions) -> Gp {
    let (x, y) = data(n, d, p, noise, 11 + n as u64 + d as u64);
    Gp::train(&x, d, &y, p, &opts).unwrap().0
}

/// Worst variance differences between the std model and its exported
/// outputs over `m` random points, relative to the variance and relative to
/// σ_f²·s_y², for both variance paths of the std model (means: bit for bit).
///
/// The exported model solves L·w = k column by column; the std model's
/// `VarianceMode::Solve` solves it row by row (blocked), and its default
/// `VarianceMode::Inverse` multiplies by a stored L⁻¹. All three are
/// accurate to ≈ ε·cond(L)·σ_f² in absolute terms, so they agree to that
/// scale, not bit for bit: near the data of a nearly noise-free model the
/// variance itself is ≈ 1e-9·σ_f² and differs by up to 2 % between paths
/// (1.4e-11·σ_f² absolute).
fn compare<const D: usize>(gp: &Gp, m: usize, seed: u64) -> (f64, f64) {
    let mut solve = gp.clone();
    solve.set_variance_mode(VarianceMode::Solve);
    let (sr, sa) = compare_mode::<D>(&solve, m, seed);
    assert_eq!(gp.variance_mode(), VarianceMode::Inverse);
    let (ir, ia) = compare_mode::<D>(gp, m, seed);
    println!(
        "  solve: {sr:.1e} of var, {sa:.1e} of σ_f²; inverse: {ir:.1e} of var, {ia:.1e} of σ_f²"
    );
    assert!(
        sa <= 1e-10 && ia <= 1e-10,
        "variance differs by {sa:e} / {ia:e} of σ_f²"
    );
    (sr.max(ir), sa.max(ia))
}

fn compare_mode<const D: usize>(gp: &Gp, m: usize, seed: u64) -> (f64, f64) {
    assert_eq!(gp.input_dim(), D);
    let p = gp.output_dim();
    let exported: Vec<ExportedArrays> =
        (0..p).map(|j| gp.export_output(j, true).unwrap()).collect();
    let views: Vec<_> = exported
        .iter()
        .map(|a| a.as_exported::<D>().unwrap())
        .collect();
    let mut ws = gp.workspace();
    let (mut mean, mut var, mut mean_only) = (vec![0.0; p], vec![0.0; p], vec![0.0; p]);
    let mut scratch = vec![0.0; gp.n()];
    let mut rng = Rng(seed);
    let mut worst_var = 0.0f64;
    let mut worst_abs = 0.0f64;
    for _ in 0..m {
        // inside the data and far outside (down to the kernel cut-off)
        let spread = if rng.uniform(0.0, 1.0) < 0.8 {
            3.0
        } else {
            30.0
        };
        let x: [f64; D] = std::array::from_fn(|_| rng.uniform(-spread, spread));
        gp.predict_into(&x, &mut mean, &mut var, &mut ws).unwrap();
        gp.predict_mean_into(&x, &mut mean_only, &mut ws).unwrap();
        for j in 0..p {
            let m_exp = views[j].predict_mean(&x).unwrap();
            assert_eq!(
                m_exp.to_bits(),
                mean_only[j].to_bits(),
                "mean {m_exp} vs {}",
                mean_only[j]
            );
            assert_eq!(
                mean[j].to_bits(),
                mean_only[j].to_bits(),
                "std mean paths differ"
            );
            let (m2, v2) = views[j].predict(&x, &mut scratch).unwrap();
            assert_eq!(m2.to_bits(), m_exp.to_bits());
            let scale = gp.output(j).kernel_max();
            worst_var = worst_var.max((v2 - var[j]).abs() / var[j].abs().max(1e-300 * scale));
            worst_abs = worst_abs.max((v2 - var[j]).abs() / scale);
        }
    }
    (worst_var, worst_abs)
}

/// Independent dense reference in original units for a model with the
/// constant prior: k from the original hyperparameters and `f64::exp`, α
/// from `OutputGp::alpha()`, the variance from a fresh nalgebra Cholesky of
/// K + (σ_n² + jitter)I.
fn dense_reference(gp: &Gp, x: &[f64], j: usize) -> (f64, f64, f64) {
    let o = gp.output(j);
    let hp = o.hyperparameters_original();
    let (n, d) = (gp.n(), gp.input_dim());
    let xs = gp.inputs();
    let k = |a: &[f64], b: &[f64]| -> f64 {
        let r2: f64 = (0..d)
            .map(|i| ((a[i] - b[i]) / hp.length_scales[i]).powi(2))
            .sum();
        if r2 > 690.0 {
            0.0
        } else {
            hp.signal_variance * (-0.5 * r2).exp()
        }
    };
    let kstar = DVector::from_fn(n, |i, _| k(&xs[i * d..(i + 1) * d], x));
    let alpha = o.alpha();
    // the constant prior mean: the mean of output j's training targets
    let p = gp.output_dim();
    let prior = gp.targets().iter().skip(j).step_by(p).sum::<f64>() / n as f64;
    let terms: Vec<f64> = (0..n).map(|i| kstar[i] * alpha[i]).collect();
    let mean = prior + terms.iter().sum::<f64>();
    let magnitude = prior.abs() + terms.iter().map(|t| t.abs()).sum::<f64>();
    let noise = (o.hyperparameters().noise_variance + o.jitter()) * o.output_scale().powi(2);
    let a = DMatrix::from_fn(n, n, |r, c| {
        k(&xs[r * d..(r + 1) * d], &xs[c * d..(c + 1) * d]) + if r == c { noise } else { 0.0 }
    });
    let chol = a.cholesky().expect("positive definite");
    let sol = chol.solve(&kstar);
    let var = (hp.signal_variance - kstar.dot(&sol)).max(0.0);
    (mean, var, magnitude)
}

#[test]
fn exported_predictions_equal_the_std_model() {
    // (d = 2, p = 2), constant prior, both normalisations: the default
    let gp = train(77, 2, 2, 0.05, common::restarts(1));
    let w2 = compare::<2>(&gp, 300, 1);
    // d = 6 as the learned double pendulum (zero prior = nominal prior), N > 2 blocks
    let gp6 = train(
        150,
        6,
        2,
        0.05,
        TrainOptions {
            mean: PriorMean::Zero,
            restarts: 1,
            ..Default::default()
        },
    );
    let w6 = compare::<6>(&gp6, 200, 2);
    // no normalisation, d = 1 and d = 9 (the generic kernel path)
    let raw = TrainOptions {
        normalise_inputs: false,
        normalise_outputs: false,
        restarts: 1,
        ..Default::default()
    };
    let w1 = compare::<1>(&train(40, 1, 1, 0.01, raw.clone()), 200, 3);
    let w9 = compare::<9>(&train(70, 9, 1, 0.05, raw), 200, 4);
    // nearly noise-free: tiny noise variance, large weights (ill-conditioned)
    let gpi = train(60, 2, 1, 0.0, common::restarts(1));
    let wi = compare::<2>(&gpi, 200, 5);
    println!(
        "max variance difference (of var, of σ_f²): {w2:?} (d=2) {w6:?} (d=6) {w1:?} (d=1) {w9:?} (d=9) {wi:?} (noise-free, σ_n² = {:e})",
        gpi.output(0).hyperparameters().noise_variance
    );
}

#[test]
fn std_and_exported_agree_with_a_dense_reference() {
    let gp = train(60, 3, 2, 0.05, common::restarts(1));
    let views: Vec<ExportedArrays> = (0..2).map(|j| gp.export_output(j, true).unwrap()).collect();
    let mut rng = Rng(9);
    let mut scratch = vec![0.0; gp.n()];
    let (mut worst_mean, mut worst_var) = (0.0f64, 0.0f64);
    let mut ws = gp.workspace();
    let (mut ms, mut vs) = ([0.0; 2], [0.0; 2]);
    for _ in 0..100 {
        let x: [f64; 3] = std::array::from_fn(|_| rng.uniform(-3.0, 3.0));
        // the std model's default variance path (stored L⁻¹)
        gp.predict_into(&x, &mut ms, &mut vs, &mut ws).unwrap();
        for (j, a) in views.iter().enumerate() {
            let e = a.as_exported::<3>().unwrap();
            let (m, v) = e.predict(&x, &mut scratch).unwrap();
            let (mr, vr, mag) = dense_reference(&gp, &x, j);
            worst_mean = worst_mean.max((m - mr).abs() / mag);
            worst_var = worst_var.max((v - vr).abs() / gp.output(j).kernel_max());
            worst_var = worst_var.max((vs[j] - vr).abs() / gp.output(j).kernel_max());
        }
    }
    println!(
        "vs dense reference: mean {worst_mean:e} of Σ|kα|, variance {worst_var:e} of σ_f²s_y²"
    );
    assert!(worst_mean <= 1e-12, "{worst_mean}");
    assert!(worst_var <= 1e-9, "{worst_var}");
}

/// The numbers of `static <name>: [f64; K] = [ … ];` in the source.
fn parse_array(src: &str, name: &str) -> Vec<f64> {
    let head = format!("pub static {name}: [f64; ");
    let start = src.find(&head).unwrap_or_else(|| panic!("{name} missing"));
    let body = &src[start..];
    let open = body.find("= [").unwrap() + 3;
    let close = body.find("\n];").unwrap();
    body[open..close]
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .flat_map(|l| l.split(','))
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<f64>().unwrap_or_else(|e| panic!("{t}: {e}")))
        .collect()
}

/// The numbers of `field: [a, b, …],` or `field: a,` for output `j`.
fn parse_field(src: &str, j: usize, field: &str) -> Vec<f64> {
    let block = src.split("ExportedGp {").nth(j + 1).unwrap();
    let line = block
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{field}:")))
        .unwrap();
    let v = line.split_once(':').unwrap().1.trim().trim_end_matches(',');
    v.trim_matches(|c| c == '[' || c == ']')
        .split(',')
        .map(|t| t.trim().parse::<f64>().unwrap())
        .collect()
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn rust_source_round_trips_every_float_and_is_deterministic() {
    let opts = common::train_options(1, 3);
    let gp = train(50, 4, 2, 0.05, opts.clone());
    let export = ExportOptions {
        name: "MODEL".into(),
        cholesky: true,
        check_points: vec![vec![0.1, 0.2, 0.3, 0.4], vec![-1.0, 2.0, 0.0, 5.0]],
        ..Default::default()
    };
    let src = gp.to_rust_source(&export).unwrap();
    assert_eq!(
        src,
        gp.to_rust_source(&export).unwrap(),
        "same model, same text"
    );
    let again = train(50, 4, 2, 0.05, opts);
    assert_eq!(
        src,
        again.to_rust_source(&export).unwrap(),
        "retrained with the same seed"
    );
    for j in 0..2 {
        let a = gp.export_output(j, true).unwrap();
        assert!(same_bits(
            &parse_array(&src, &format!("MODEL_{j}_INPUTS")),
            &a.inputs
        ));
        assert!(same_bits(
            &parse_array(&src, &format!("MODEL_{j}_WEIGHTS")),
            &a.weights
        ));
        assert!(same_bits(
            &parse_array(&src, &format!("MODEL_{j}_CHOLESKY")),
            a.cholesky.as_ref().unwrap()
        ));
        assert!(same_bits(
            &parse_field(&src, j, "length_scales"),
            &a.length_scales
        ));
        assert!(same_bits(
            &parse_field(&src, j, "input_shift"),
            &a.input_shift
        ));
        assert!(same_bits(
            &parse_field(&src, j, "input_scale"),
            &a.input_scale
        ));
        assert!(same_bits(
            &parse_field(&src, j, "signal_variance"),
            &[a.signal_variance]
        ));
        assert!(same_bits(
            &parse_field(&src, j, "output_scale"),
            &[a.output_scale]
        ));
        assert!(same_bits(
            &parse_field(&src, j, "prior_mean"),
            &[a.prior_mean]
        ));
    }
    // without the factor: no CHOLESKY arrays, no variances
    let lean = gp
        .to_rust_source(&ExportOptions {
            cholesky: false,
            ..export
        })
        .unwrap();
    assert!(!lean.contains("CHOLESKY") && lean.contains("cholesky: None"));
}

#[test]
fn export_errors_are_typed() {
    let (x, y) = data(20, 2, 1, 0.05, 1);
    let opts = TrainOptions {
        mean: PriorMean::function(|x, m| m[0] = x[0]),
        restarts: 0,
        ..Default::default()
    };
    let (gp, _) = Gp::train(&x, 2, &y, 1, &opts).unwrap();
    assert!(matches!(
        gp.export_output(0, false),
        Err(GpError::Export(_))
    ));
    let gp = train(20, 2, 1, 0.05, common::restarts(0));
    assert!(matches!(
        gp.export_output(1, false),
        Err(GpError::DimensionMismatch { .. })
    ));
    for bad in [
        ExportOptions {
            name: "lower".into(),
            ..Default::default()
        },
        ExportOptions {
            core_path: "vigp::".into(),
            ..Default::default()
        },
        ExportOptions {
            header: vec!["a\nb".into()],
            ..Default::default()
        },
    ] {
        assert!(matches!(gp.to_rust_source(&bad), Err(GpError::Export(_))));
    }
    let wrong = ExportOptions {
        check_points: vec![vec![0.0; 3]],
        ..Default::default()
    };
    assert!(matches!(
        gp.to_rust_source(&wrong),
        Err(GpError::DimensionMismatch { .. })
    ));
    let a = gp.export_output(0, false).unwrap();
    assert!(a.as_exported::<3>().is_err());
    let e = a.as_exported::<2>().unwrap();
    assert!(matches!(
        e.predict(&[0.0, 0.0], &mut [0.0; 20]),
        Err(vigp::embedded::gp::GpError::NoCholesky)
    ));
}

/// The committed demo model, compiled into this (std) test: its GPs give
/// the check values the exporting std model wrote, bit for bit.
#[test]
fn committed_demo_model_reproduces_its_check_values() {
    use demo_model::*;
    let mut scratch = [0.0; GP_N];
    for ((x, means), vars) in GP_CHECK_POINTS
        .iter()
        .zip(&GP_CHECK_MEANS)
        .zip(&GP_CHECK_VARIANCES)
    {
        for j in 0..GP_OUTPUT_DIM {
            assert_eq!(GP[j].predict_mean(x).unwrap().to_bits(), means[j].to_bits());
            let (_, v) = GP[j].predict(x, &mut scratch).unwrap();
            assert!((v - vars[j]).abs() <= 1e-12 * vars[j], "{v} vs {}", vars[j]);
        }
    }
    assert_eq!(
        (GP_INPUT_DIM, GP_DT, GP_ENCODING, GP_PRIOR),
        (6, 0.01, "sincos", "nominal")
    );
}

#[allow(dead_code)]
#[path = "../../examples/export_gp.rs"]
mod export_example;

/// The text of generated source with every floating-point literal (a
/// number token containing `.`, `e` or `E`) replaced by `#`; integers (array
/// sizes, N, d) stay.
fn mask_floats(src: &str) -> String {
    let chars: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let prev_ident = i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_');
        let starts_number = c.is_ascii_digit()
            || (c == '-' && chars.get(i + 1).is_some_and(|d| d.is_ascii_digit()));
        if starts_number && !prev_ident {
            let mut j = i + 1;
            while j < chars.len() && (chars[j].is_ascii_digit() || ".eE+-".contains(chars[j])) {
                j += 1;
            }
            let token: String = chars[i..j].iter().collect();
            if token.contains(['.', 'e', 'E']) {
                out.push('#');
            } else {
                out.push_str(&token);
            }
            i = j;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

#[test]
fn float_masking_keeps_integers_and_names() {
    assert_eq!(
        mask_floats("pub static GP_0_W: [f64; 64] = [1.5, -2e-3, 7.0E5, 12];"),
        "pub static GP_0_W: [f64; 64] = [#, #, #, 12];"
    );
}

/// Regenerates the demo model with the example's recipe (the same seeded
/// data and training) and compares it with the committed file.
///
/// Not bit for bit: faer picks its SIMD kernels at run time, so another CPU
/// rounds the training differently, and the likelihood is flat in some
/// length scales. Measured on the generating machine, perturbing the
/// training targets by a relative 1e-15 (rounding level) moved the
/// hyperparameters by up to 3e-5 (relative) and the predicted means by up
/// to 1.1e-4 of each output's scale. So the check is:
/// - the text with every float literal masked is identical (names, layout,
///   array sizes, N, d, options: the generator's format), exactly;
/// - the regenerated GPs predict the committed check means
///   (`GP_CHECK_MEANS`) to 2e-3 of each output's scale (≈20× the measured
///   rounding sensitivity); a different recipe or a training bug moves them
///   by far more (the correction itself is O(1) in these units).
#[test]
fn committed_demo_model_is_what_the_example_generates() {
    let e = export_example::generate(64).unwrap();
    let committed = include_str!("../../embedded-demo/src/gp_model.rs");
    if e.source != committed {
        let path = std::env::temp_dir().join("gp_model_regenerated.rs");
        std::fs::write(&path, &e.source).unwrap();
        println!(
            "regenerated text differs in some digits: {}",
            path.display()
        );
    }
    assert!(
        mask_floats(&e.source) == mask_floats(committed),
        "the generator's output format changed: regenerate with \
         `cargo run --release --example export_gp`"
    );
    let points: Vec<f64> = demo_model::GP_CHECK_POINTS
        .iter()
        .flatten()
        .copied()
        .collect();
    let prediction = e.learned.gp().predict(&points).unwrap();
    let outputs = e.learned.gp().outputs();
    let mut worst = 0.0f64;
    for (k, means) in demo_model::GP_CHECK_MEANS.iter().enumerate() {
        for (j, committed_mean) in means.iter().enumerate() {
            let got = prediction.mean[k * demo_model::GP_OUTPUT_DIM + j];
            let rel = (got - committed_mean).abs() / outputs[j].output_scale();
            worst = worst.max(rel);
        }
    }
    println!("regenerated vs committed check means: max |Δ|/output scale = {worst:.2e}");
    assert!(
        worst <= 2e-3,
        "{worst:.3e}: regenerate with `cargo run --release --example export_gp`"
    );
}

/// The mean-only learned step (`step_mean_in`, used by `Integrator::step`
/// and rollouts) is the full step (`step_in`, which also computes the
/// variances) without the variances: the same next state, bit for bit.
#[test]
fn mean_only_learned_step_equals_the_full_step() {
    use vigp::learned::Prior;
    use vigp::prelude::*;
    let dt = 0.01;
    let data = damped_pendulum_data(dt);
    let opts = common::restarts(1);
    for prior in [Prior::Nominal, Prior::Constant] {
        let l = learned_pendulum(dt, &data, prior, &opts);
        let mut ws = l.workspace();
        for t in &data {
            let a = l.step_mean_in(&t.z, &mut ws).unwrap();
            let (b, _) = l.step_in(&t.z, &mut ws).unwrap();
            let c = l.step(&t.z).unwrap();
            assert_eq!((a.q, a.v), (b.q, b.v));
            assert_eq!((a.q, a.v), (c.q, c.v));
        }
    }
    // a constrained model: the projection runs on the same unprojected mean
    let (_, data, l) = learned_fourbar(dt, &opts);
    let mut ws = l.workspace();
    for t in data.iter().step_by(5) {
        let a = l.step_mean_in(&t.z, &mut ws).unwrap();
        let (b, _) = l.step_in(&t.z, &mut ws).unwrap();
        assert_eq!((a.q, a.v), (b.q, b.v));
    }
}

/// The opt-in parallel variance path (the last output's variance on the
/// model's helper thread, taken for an exact GP with p ≥ 2, N ≥
/// `PARALLEL_VARIANCE_MIN_N` and the stored inverse) gives the sequential
/// path's means and variances bit for bit, also with two clones predicting
/// at once from two threads (one of them then takes the sequential path),
/// and both agree with the dense reference (N = 300, p = 3, d = 3).
#[test]
fn parallel_variance_equals_the_sequential_path() {
    let n = vigp::gp::PARALLEL_VARIANCE_MIN_N + 44;
    let mut gp = train(n, 3, 3, 0.05, common::restarts(0));
    assert!(!gp.parallel_variance(), "off by default");
    gp.set_parallel_variance(true);
    let mut ws = gp.workspace();
    let mut rng = Rng(21);
    let points: Vec<[f64; 3]> = (0..40)
        .map(|_| std::array::from_fn(|_| rng.uniform(-3.0, 3.0)))
        .collect();
    let mut par = Vec::new();
    for x in &points {
        let (mut m, mut v) = ([0.0; 3], [0.0; 3]);
        gp.predict_into(x, &mut m, &mut v, &mut ws).unwrap();
        par.push((m, v));
    }
    // two clones sharing the helper, predicting at once
    std::thread::scope(|scope| {
        for _ in 0..2 {
            let (g, pts, par) = (gp.clone(), &points, &par);
            scope.spawn(move || {
                let mut ws = g.workspace();
                for _ in 0..20 {
                    for (x, (pm, pv)) in pts.iter().zip(par) {
                        let (mut m, mut v) = ([0.0; 3], [0.0; 3]);
                        g.predict_into(x, &mut m, &mut v, &mut ws).unwrap();
                        assert_eq!(m.map(f64::to_bits), pm.map(f64::to_bits));
                        assert_eq!(v.map(f64::to_bits), pv.map(f64::to_bits));
                    }
                }
            });
        }
    });
    gp.set_parallel_variance(false);
    // a workspace made with the parallel buffers serves the sequential path
    for (x, (pm, pv)) in points.iter().zip(&par) {
        let (mut m, mut v) = ([0.0; 3], [0.0; 3]);
        gp.predict_into(x, &mut m, &mut v, &mut ws).unwrap();
        assert_eq!(
            m.map(f64::to_bits),
            pm.map(f64::to_bits),
            "means differ at {x:?}"
        );
        assert_eq!(
            v.map(f64::to_bits),
            pv.map(f64::to_bits),
            "variances differ at {x:?}"
        );
        for j in 0..3 {
            let (mr, vr, mag) = dense_reference(&gp, x, j);
            assert!((pm[j] - mr).abs() <= 1e-12 * mag, "mean {j} at {x:?}");
            assert!(
                (pv[j] - vr).abs() <= 1e-9 * gp.output(j).kernel_max(),
                "variance {j} at {x:?}: {} vs {vr}",
                pv[j]
            );
        }
    }
    // and a workspace made while it was off serves the parallel path
    let mut ws_seq = gp.workspace();
    gp.set_parallel_variance(true);
    let (mut m, mut v) = ([0.0; 3], [0.0; 3]);
    gp.predict_into(&points[0], &mut m, &mut v, &mut ws_seq)
        .unwrap();
    assert_eq!(v.map(f64::to_bits), par[0].1.map(f64::to_bits));
}

/// `Gp::predict` over many points shares each pass over an output's stored
/// L⁻¹ between the points of a chunk (at most 32); its means and variances
/// equal `predict_into` point by point, bit for bit: across chunk
/// boundaries (75 points), for one chunk whose outputs run in parallel (5
/// points), with a function prior mean, and in the `VarianceMode::Solve`
/// path (which predicts point by point). A non-finite point is an error in
/// each.
#[test]
fn batched_prediction_equals_single_points() {
    let n = 300;
    let (x, y) = data(n, 3, 3, 0.05, 5);
    let opts = TrainOptions {
        restarts: 0,
        mean: PriorMean::function(|x, m| {
            m[0] = x[0];
            m[1] = 0.5 * x[1];
            m[2] = x[2].sin();
        }),
        ..Default::default()
    };
    let mut gp = Gp::train(&x, 3, &y, 3, &opts).unwrap().0;
    let mut rng = Rng(8);
    let many: Vec<f64> = (0..75 * 3).map(|_| rng.uniform(-3.5, 3.5)).collect();
    // 75 points: three chunks; 5 points: one chunk, whose three outputs run
    // in parallel (fewer chunks than the pool's two threads)
    for (points, mode) in [
        (&many[..], VarianceMode::Inverse),
        (&many[..5 * 3], VarianceMode::Inverse),
        (&many[..], VarianceMode::Solve),
    ] {
        gp.set_variance_mode(mode);
        let batch = common::in_pool(2, || gp.predict(points)).unwrap();
        let mut ws = gp.workspace();
        for (h, q) in points.chunks_exact(3).enumerate() {
            let (mut m, mut v) = ([0.0; 3], [0.0; 3]);
            gp.predict_into(q, &mut m, &mut v, &mut ws).unwrap();
            assert!(
                same_bits(&batch.mean[3 * h..3 * h + 3], &m),
                "{mode:?}: means differ at point {h}"
            );
            assert!(
                same_bits(&batch.variance[3 * h..3 * h + 3], &v),
                "{mode:?}: variances differ at point {h}"
            );
            assert!(v.iter().all(|s| *s >= 0.0));
        }
        let mut bad = points.to_vec();
        let middle = bad.len() / 2;
        bad[middle] = f64::NAN;
        assert!(
            matches!(gp.predict(&bad), Err(GpError::NonFinite { .. })),
            "{mode:?}"
        );
    }
}

/// `Learned::rollout_with_info` (mean steps, then the variances of all
/// visited points in one batched prediction) reports what `steps` calls of
/// `step_in` report, bit for bit: states, unprojected velocities,
/// standard deviations and projection corrections; with the nominal and the
/// constant prior, and with a projection (fourbar). A non-finite start is
/// the same typed error, at step 0.
#[test]
fn rollout_with_info_equals_repeated_full_steps() {
    use vigp::learned::{Learned, Prior};
    use vigp::prelude::*;
    let dt = 0.01;
    let data = damped_pendulum_data(dt);
    let opts = common::restarts(1);
    fn check<M: vigp::Mechanism<N, C> + Clone, const N: usize, const C: usize>(
        l: &Learned<M, N, C>,
        z0: &State<N>,
        steps: usize,
    ) {
        let mut ws = l.workspace();
        let got = l.rollout_with_info(z0, steps, &mut ws).unwrap();
        assert_eq!(got.len(), steps);
        let mut z = *z0;
        for (k, (state, info)) in got.iter().enumerate() {
            let (next, want) = l.step_in(&z, &mut ws).unwrap();
            assert!(
                same_bits(next.q.as_slice(), state.q.as_slice()),
                "q, step {k}"
            );
            assert!(
                same_bits(next.v.as_slice(), state.v.as_slice()),
                "v, step {k}"
            );
            assert!(
                same_bits(want.unprojected.as_slice(), info.unprojected.as_slice()),
                "v_u, step {k}"
            );
            assert!(
                same_bits(want.std_dev.as_slice(), info.std_dev.as_slice()),
                "σ, step {k}: {} vs {}",
                want.std_dev,
                info.std_dev
            );
            assert_eq!(
                want.correction.to_bits(),
                info.correction.to_bits(),
                "step {k}"
            );
            z = next;
        }
        let mut bad = *z0;
        bad.v[0] = f64::NAN;
        let a = l.rollout_with_info(&bad, steps, &mut ws).unwrap_err();
        let b = l.step_in(&bad, &mut ws).unwrap_err().at_step(0);
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
    }
    for prior in [Prior::Nominal, Prior::Constant] {
        let l = learned_pendulum(dt, &data, prior, &opts);
        check(&l, &data[3].z, 40);
    }
    let (z0, _, l) = learned_fourbar(dt, &opts);
    assert!(l.projects());
    check(&l, &z0, 25);
}

/// Transitions of a damped pendulum (pivot damping 0.4) released at rest
/// from θ = 1: 60 steps of `dt` of the first-order VI.
fn damped_pendulum_data(dt: f64) -> Vec<vigp::learned::Transition<1>> {
    use vigp::prelude::*;
    let mut truth = vigp::systems::Pendulum::default();
    truth.joints.pivot.damping = 0.4;
    let traj = Variational::new(truth.minimal(), dt)
        .unwrap()
        .rollout(&State::new([1.0], [0.0]), 60)
        .unwrap();
    let q: Vec<_> = traj.iter().map(|z| z.q).collect();
    vigp::learned::transitions(&q, dt)
}

/// The default pendulum learned at `dt` on `data` (sin/cos encoding) with
/// `prior`.
fn learned_pendulum(
    dt: f64,
    data: &[vigp::learned::Transition<1>],
    prior: vigp::learned::Prior,
    opts: &TrainOptions,
) -> vigp::learned::Learned<vigp::systems::PendulumMinimal, 1, 0> {
    use vigp::learned::{Encoding, Learned};
    let m = vigp::systems::Pendulum::default().minimal();
    Learned::train(m, dt, data, Encoding::SinCos, prior, opts)
        .unwrap()
        .0
}

/// The default fourbar's consistent start, the transitions of a 40-step
/// run from it at `dt`, and the fourbar learned on them (raw encoding,
/// constant prior).
fn learned_fourbar(
    dt: f64,
    opts: &TrainOptions,
) -> (
    vigp::State<4>,
    Vec<vigp::learned::Transition<4>>,
    vigp::learned::Learned<vigp::systems::FourbarMinimal, 4, 2>,
) {
    use vigp::learned::{Encoding, Learned, Prior, transitions};
    use vigp::prelude::*;
    let fb = vigp::systems::Fourbar::default().minimal();
    let z0 = common::at_rest(&fb, [0.9, -1.3, -0.4, 1.3], dt);
    let traj = Variational::new(fb, dt).unwrap().rollout(&z0, 40).unwrap();
    let q: Vec<_> = traj.iter().map(|z| z.q).collect();
    let data = transitions(&q, dt);
    let (l, _) = Learned::train(fb, dt, &data, Encoding::Raw, Prior::Constant, opts).unwrap();
    (z0, data, l)
}
