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
//! Prints the machine load (`/proc/loadavg`) before and after, each run's
//! wall time and the process's CPU time over it (on a loaded machine the
//! CPU time divided by the thread count estimates the idle-machine wall
//! time), best LML (normalised units, as scikit-learn reports it with
//! `normalize_y=True`) and the LML + gradient evaluations of every start.

use std::time::Instant;

use vigp::gp::{Gp, Method, SparseOptions, TrainOptions};

/// Fractional parts of √p for the first primes: Weyl-sequence directions
/// (the same as `benches/gp.rs` and `scripts/gp_sklearn_bench.py`).
const DIRS: [f64; 8] = [
    0.414_213_562_373_095_1,
    0.732_050_807_568_877_2,
    0.236_067_977_499_789_7,
    0.645_751_311_064_590_6,
    0.316_624_790_355_399_85,
    0.605_551_275_463_989_3,
    0.123_105_625_617_660_55,
    0.358_898_943_540_673_6,
];

fn bench_data(n: usize, d: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n * d];
    let mut y = vec![0.0; n];
    for i in 0..n {
        let r = &mut x[i * d..(i + 1) * d];
        for (j, v) in r.iter_mut().enumerate() {
            *v = 4.0 * (((i + 1) as f64) * DIRS[j]).fract() - 2.0;
        }
        let mut t = (3.0 * r[0]).sin() + (2.0 * r[1]).cos();
        if d >= 4 {
            t += 0.5 * r[2] * r[3];
        }
        t += 0.01 * ((((i + 1) as f64) * 0.754_877_666_246_692_8).fract() - 0.5);
        y[i] = t;
    }
    (x, y)
}

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
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (n, d) = (arg("--n", 512), arg("--d", 4));
    let (restarts, runs, threads) = (arg("--restarts", 10), arg("--runs", 3), arg("--threads", 0));
    let sparse = arg("--sparse", 0);
    if !(1..=8).contains(&d) {
        return Err("--d must be in 1..=8".into());
    }
    let (x, y) = bench_data(n, d);
    let opts = TrainOptions {
        restarts,
        seed: 0,
        method: if sparse > 0 {
            Method::Sparse(SparseOptions::kmeans(sparse))
        } else {
            Method::Exact
        },
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    println!(
        "vigp Gp::train: N = {n}, d = {d}, 1 + {restarts} starts, {} thread(s), {}",
        pool.current_num_threads(),
        if sparse > 0 {
            format!("sparse M = {sparse} (k-means++)")
        } else {
            "exact".into()
        }
    );
    println!("load average before: {}", load());
    let mut times = Vec::new();
    for r in 0..runs {
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let (_, rep) = pool.install(|| Gp::train(&x, d, &y, 1, &opts))?;
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
    }
    times.sort_by(f64::total_cmp);
    println!("median {:.3} s over {runs} run(s)", times[runs / 2]);
    println!("load average after: {}", load());
    Ok(())
}
