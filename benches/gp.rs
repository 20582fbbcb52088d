//! GP engine benchmarks: likelihood + gradient, full training with restarts,
//! single-point prediction. The data is the deterministic set that
//! scripts/gp_sklearn_bench.py builds for the scikit-learn comparison
//! (docs/gp.md).

use std::hint::black_box;
use std::time::Duration;

use criterion::BatchSize;
use criterion::{Criterion, criterion_group, criterion_main};
use faer::linalg::solvers::DenseSolveCore;
use vigp::gp::{Gp, Hyperparameters, Method, SparseOptions, TrainOptions, log_marginal_likelihood};

#[path = "common/gp_data.rs"]
mod gp_data;
use gp_data::bench_data;

/// The scaled kernel matrix of `bench_data` at ℓ = 1, σ_f² = 1, σ_n² = 0.01.
fn kernel_matrix(x: &[f64], n: usize, d: usize) -> faer::Mat<f64> {
    faer::Mat::from_fn(n, n, |i, j| {
        let r2: f64 = (0..d).map(|k| (x[i * d + k] - x[j * d + k]).powi(2)).sum();
        (-0.5 * r2).exp() + if i == j { 1e-2 } else { 0.0 }
    })
}

fn lml(c: &mut Criterion) {
    let mut g = c.benchmark_group("lml_grad");
    g.sample_size(10).measurement_time(Duration::from_secs(4));
    // The baseline of issue 17: one Cholesky plus one inverse of the same
    // N × N matrix with faer's own routines (sequential and parallel).
    for n in [512, 2048] {
        let (x, _) = bench_data(n, 4);
        let k = kernel_matrix(&x, n, 4);
        for par in [faer::Par::Seq, faer::Par::rayon(0)] {
            let name = format!(
                "N{n}_cholesky_plus_inverse_{}",
                if matches!(par, faer::Par::Seq) {
                    "seq"
                } else {
                    "par"
                }
            );
            g.bench_function(name, |b| {
                b.iter(|| {
                    faer::set_global_parallelism(par);
                    let llt = black_box(&k).llt(faer::Side::Lower).unwrap();
                    let inv = llt.inverse();
                    faer::set_global_parallelism(faer::Par::rayon(0));
                    inv
                })
            });
        }
    }
    for (n, d) in [(512, 4), (512, 8), (2048, 4), (2048, 8)] {
        let (x, y) = bench_data(n, d);
        let theta = Hyperparameters::isotropic(d, 1.0, 1.0, 1e-2).to_log();
        for parallel in [false, true] {
            let name = format!("N{n}_d{d}_{}", if parallel { "par" } else { "seq" });
            g.bench_function(name, |b| {
                b.iter(|| log_marginal_likelihood(black_box(&x), d, &y, &theta, parallel).unwrap())
            });
        }
    }
    g.finish();
}

/// The training options of the scikit-learn comparison: 10 restarts (11
/// starts), the default bounds, ℓ = 1, σ_f² = 1, σ_n² = 0.01 initially.
pub fn train_options() -> TrainOptions {
    TrainOptions {
        restarts: 10,
        seed: 0,
        ..Default::default()
    }
}

fn train(c: &mut Criterion) {
    let mut g = c.benchmark_group("train");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    let (x, y) = bench_data(512, 4);
    let opts = train_options();
    let (_, report) = Gp::train(&x, 4, &y, 1, &opts).unwrap();
    let r = &report.outputs[0];
    eprintln!(
        "train N512_d4: best LML {:.6} (start {}), {} evaluations, {} iterations over 11 starts",
        r.log_marginal_likelihood, r.best_start, r.evaluations, r.iterations
    );
    g.bench_function("N512_d4_10restarts", |b| {
        b.iter(|| Gp::train(black_box(&x), 4, &y, 1, &opts).unwrap())
    });
    g.finish();
}

fn predict(c: &mut Criterion) {
    let mut g = c.benchmark_group("predict");
    let (x, y) = bench_data(512, 4);
    let hp = Hyperparameters::isotropic(4, 0.8, 1.0, 1e-4);
    let gp = Gp::fit(&x, 4, &y, 1, &[hp], &TrainOptions::default()).unwrap();
    let mut ws = gp.workspace();
    let (mut m, mut v) = ([0.0], [0.0]);
    let q = [0.1, -0.3, 0.7, 1.2];
    g.bench_function("N512_d4_mean_var", |b| {
        b.iter(|| {
            gp.predict_into(black_box(&q), &mut m, &mut v, &mut ws)
                .unwrap()
        })
    });
    g.bench_function("N512_d4_mean", |b| {
        b.iter(|| {
            gp.predict_mean_into(black_box(&q), &mut m, &mut ws)
                .unwrap()
        })
    });
    g.finish();
}

/// Online updates (`Gp::add_samples`): 16 samples added one call at a time
/// to a model of N = 2048 (divide by 16 for the cost per sample; the
/// factor's storage grows geometrically, so a reallocation is amortised as
/// it is while a system runs), and the sparse GP's one-point prediction at
/// M = 256.
/// Adds the samples `xn` (4 inputs each), `yn` (1 output each) to a copy of
/// `gp` one at a time.
fn bench_add_one_at_a_time(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
    gp: &Gp,
    xn: &[f64],
    yn: &[f64],
) {
    g.bench_function(name, |b| {
        b.iter_batched(
            || gp.clone(),
            |mut gp| {
                for (xi, yi) in xn.chunks(4).zip(yn.chunks(1)) {
                    gp.add_samples(black_box(xi), yi).unwrap();
                }
                gp
            },
            BatchSize::LargeInput,
        )
    });
}

fn online_and_sparse(c: &mut Criterion) {
    let mut g = c.benchmark_group("online");
    g.sample_size(20).measurement_time(Duration::from_secs(6));
    let (x, y) = bench_data(2048 + 16, 4);
    let hp = Hyperparameters::isotropic(4, 0.8, 1.0, 1e-4);
    let exact = Gp::fit(
        &x[..2048 * 4],
        4,
        &y[..2048],
        1,
        std::slice::from_ref(&hp),
        &TrainOptions::default(),
    )
    .unwrap();
    let (xn, yn) = (&x[2048 * 4..], &y[2048..]);
    bench_add_one_at_a_time(&mut g, "exact_N2048_add_16_one_at_a_time", &exact, xn, yn);
    let sopts = TrainOptions {
        method: Method::Sparse(SparseOptions::kmeans(256)),
        ..Default::default()
    };
    let sparse = Gp::fit(&x[..2048 * 4], 4, &y[..2048], 1, &[hp], &sopts).unwrap();
    bench_add_one_at_a_time(&mut g, "sparse_M256_add_16_one_at_a_time", &sparse, xn, yn);
    g.finish();
    let mut g = c.benchmark_group("predict");
    let mut ws = sparse.workspace();
    let (mut m, mut v) = ([0.0], [0.0]);
    let q = [0.1, -0.3, 0.7, 1.2];
    g.bench_function("sparse_M256_d4_mean", |b| {
        b.iter(|| {
            sparse
                .predict_mean_into(black_box(&q), &mut m, &mut ws)
                .unwrap()
        })
    });
    g.bench_function("sparse_M256_d4_mean_var", |b| {
        b.iter(|| {
            sparse
                .predict_into(black_box(&q), &mut m, &mut v, &mut ws)
                .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, lml, train, predict, online_and_sparse);
criterion_main!(benches);
