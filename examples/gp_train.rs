//! GP training timings for the peer comparisons (`docs/gp.md`, "Benchmarks"):
//! the data of `benches/gp.rs` and `scripts/gp_sklearn_bench.py` (Weyl-sequence
//! inputs in [−2, 2]^d, a smooth target plus 0.01 deterministic noise), the
//! default bounds and stopping rules, `1 + restarts` starts.
//!
//! ```text
//! cargo run --release --example gp_train -- --n 512 --restarts 10 --runs 3
//! cargo run --release --example gp_train -- --n 512 --restarts 10 --threads 1
//! cargo run --release --example gp_train -- --n 2048 --restarts 10 --runs 1
//! cargo run --release --example gp_train -- --n 100000 --sparse 256 --restarts 0 --runs 1
//! ```
//!
//! `--seed S` (default 0) seeds the restarts' start points
//! (`TrainOptions::seed`), as `scripts/gp_scipy_evals.py --seed S` does.
//!
//! Prints the machine load (`/proc/loadavg`) before and after, each run's
//! wall time and the process's CPU time over it (on a loaded machine the
//! CPU time divided by the thread count estimates the idle-machine wall
//! time), best LML (normalised units, as scikit-learn reports it with
//! `normalize_y=True`) and the LML + gradient evaluations of every start.
//!
//! `--optimise-inducing` (sparse only) refines the inducing points with the
//! hyperparameters after the starts (`SparseOptions::optimise_inducing`) and
//! prints the refinement's bound before and after, its iterations and
//! evaluations.
//!
//! `--dump-inducing PATH` (sparse only) writes, after the last run, what a
//! peer SGPR needs to optimise the same problem as JSON: the inducing
//! points in original and in normalised (standardised) units (row-major
//! M × d, from `Gp::inducing_points`, mapped with the model's
//! `InputNormaliser`), that normaliser's shift and scale, the constant prior
//! mean and output scale s_y of the targets, the trained hyperparameters
//! (normalised units), the K_uu jitter (absolute, normalised units) and the
//! final bound (normalised units; in original units it is this − N·ln s_y),
//! and the bound at the first start ℓ = 1, σ_f² = 1, σ² = 0.01 (from
//! `vigp::gp::sparse_bound` on the normalised data; a well-conditioned
//! point for checking a peer's bound to rounding).
//! `scripts/sgpr_peer.py` reads it.
//!
//! ```text
//! cargo run --release --example gp_train -- --n 100000 --sparse 256 --restarts 0 --runs 1 --dump-inducing /tmp/z.json
//! ```

use std::time::Instant;

use vigp::gp::{Gp, Method, Screening, SparseOptions, TrainOptions, sparse_bound};

#[path = "../benches/common/gp_data.rs"]
mod gp_data;
use gp_data::bench_data;

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// CPU time (user + system) of this process so far, in seconds, from
/// `/proc/self/stat` (Linux; clock ticks of 1/100 s, the kernel's USER_HZ on
/// every mainstream architecture). On a loaded machine the wall time
/// includes the time other processes held the cores; the CPU time does not,
/// so CPU time / threads estimates the wall time on an idle machine (for a
/// run that keeps all its threads busy).
fn cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses).
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line (1-based),
    // i.e. 11 and 12 after the name (0-based).
    let (u, st): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    Some((u + st) / 100.0)
}

fn arg(name: &str, default: usize) -> usize {
    str_arg(name)
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[path = "common/args.rs"]
mod args;
use args::str_arg;

/// Rows (row-major, `d` wide) through the model's input standardisation.
fn normalised(gp: &Gp, rows: &[f64]) -> Vec<f64> {
    let (norm, d) = (gp.input_normaliser(), gp.input_dim());
    let mut out = vec![0.0; rows.len()];
    for (o, r) in out.chunks_exact_mut(d).zip(rows.chunks_exact(d)) {
        norm.apply(r, o);
    }
    out
}

/// The `--dump-inducing` JSON of a trained sparse model (see the module docs).
fn dump_inducing(path: &str, gp: &Gp, lml: f64) -> Result<(), Box<dyn std::error::Error>> {
    let z = gp
        .inducing_points()
        .ok_or("--dump-inducing needs a sparse model (--sparse M)")?;
    let norm = gp.input_normaliser();
    let d = gp.input_dim();
    let zn = normalised(gp, &z);
    let o = gp.output(0);
    let hp = o.hyperparameters();
    // The constant prior mean (PriorMean::Constant: the same at every input).
    let mean = gp.prior_mean_at_inputs()[0];
    let rows = |v: &[f64]| v.chunks_exact(d).map(|r| r.to_vec()).collect::<Vec<_>>();
    // The bound at the first start (TrainOptions::initial = None), on the
    // model's normalised inputs and residuals.
    let xn = normalised(gp, gp.inputs());
    let mut theta = vec![0.0; d + 2];
    theta[d + 1] = 1e-2f64.ln();
    let (start, _) = sparse_bound(&xn, d, o.residual_normalised(), &zn, &theta, true)?;
    let json = serde_json::json!({
        "n": gp.n(),
        "d": d,
        "m": z.len() / d,
        "inducing_original": rows(&z),
        "inducing_normalised": rows(&zn),
        "input_shift": norm.shift,
        "input_scale": norm.scale,
        "target_mean": mean,
        "output_scale": o.output_scale(),
        "length_scales": hp.length_scales,
        "signal_variance": hp.signal_variance,
        "noise_variance": hp.noise_variance,
        "kuu_jitter": o.jitter(),
        "bound_normalised": lml,
        "bound_at_start_normalised": start,
    });
    std::fs::write(path, serde_json::to_string_pretty(&json)?)?;
    println!("wrote inducing points and normalisation to {path}");
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (n, d) = (arg("--n", 512), arg("--d", 4));
    let (restarts, runs, threads) = (arg("--restarts", 10), arg("--runs", 3), arg("--threads", 0));
    let sparse = arg("--sparse", 0);
    let seed = arg("--seed", 0) as u64;
    let dump = str_arg("--dump-inducing");
    if dump.is_some() && sparse == 0 {
        return Err("--dump-inducing needs --sparse M".into());
    }
    let optimise_inducing = std::env::args().any(|a| a == "--optimise-inducing");
    if optimise_inducing && sparse == 0 {
        return Err("--optimise-inducing needs --sparse M".into());
    }
    if !(1..=8).contains(&d) {
        return Err("--d must be in 1..=8".into());
    }
    let screening = match str_arg("--screen").as_deref() {
        None | Some("auto") => Screening::Auto,
        Some("off") => Screening::Off,
        Some(m) => Screening::Subset(
            m.parse()
                .map_err(|_| "--screen takes auto, off or a subset size")?,
        ),
    };
    let (x, y) = bench_data(n, d);
    let opts = TrainOptions {
        screening,
        restarts,
        seed,
        method: if sparse > 0 {
            Method::Sparse(SparseOptions {
                optimise_inducing,
                ..SparseOptions::kmeans(sparse)
            })
        } else {
            Method::Exact
        },
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    println!(
        "vigp Gp::train: N = {n}, d = {d}, 1 + {restarts} starts (seed {seed}), {} thread(s), {}",
        pool.current_num_threads(),
        if sparse > 0 {
            format!(
                "sparse M = {sparse} (k-means++{})",
                if optimise_inducing {
                    ", then optimised"
                } else {
                    ""
                }
            )
        } else {
            "exact".into()
        }
    );
    println!("load average before: {}", load());
    let mut times = Vec::new();
    let mut last = None;
    for r in 0..runs {
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let (gp, rep) = pool.install(|| Gp::train(&x, d, &y, 1, &opts))?;
        let t = t0.elapsed().as_secs_f64();
        let cpu = match (c0, cpu_seconds()) {
            (Some(a), Some(b)) => format!(
                "CPU {:.1} s = {:.2} of {} thread(s)",
                b - a,
                (b - a) / t,
                pool.current_num_threads()
            ),
            _ => "CPU time unavailable".into(),
        };
        times.push(t);
        let o = &rep.outputs[0];
        println!(
            "run {r}: {t:.3} s ({cpu}), best LML {:.6} (start {}), {} evaluations in {} iterations ({:.2} ms each), per start {:?}",
            o.log_marginal_likelihood,
            o.best_start,
            o.evaluations,
            o.iterations,
            1e3 * t / o.evaluations as f64,
            o.start_evaluations
        );
        let lmls: Vec<String> = o.start_lmls.iter().map(|v| format!("{v:.3}")).collect();
        println!("  final LML per start: [{}]", lmls.join(", "));
        if let Some(s) = &o.screening {
            let lmls: Vec<String> = s.start_lmls.iter().map(|v| format!("{v:.3}")).collect();
            println!(
                "  screened on {} samples: {} evaluations there, per start {:?}, final LML there [{}]; refined starts {:?}{}",
                s.subset,
                s.evaluations,
                s.start_evaluations,
                lmls.join(", "),
                s.refined,
                if s.fell_back {
                    ", fell back to unscreened starts"
                } else {
                    ""
                }
            );
        }
        if let Some(z) = &rep.inducing {
            println!(
                "  inducing points optimised: bound {:.6} -> {:.6}, {} evaluations in {} iterations (converged: {})",
                z.bound_before, z.bound_after, z.evaluations, z.iterations, z.converged
            );
        }
        last = Some((gp, o.log_marginal_likelihood));
    }
    times.sort_by(f64::total_cmp);
    println!("median {:.3} s over {runs} run(s)", times[runs / 2]);
    println!("load average after: {}", load());
    if let (Some(path), Some((gp, lml))) = (dump, last) {
        dump_inducing(&path, &gp, lml)?;
    }
    Ok(())
}
