//! The hand-written closed-form double-pendulum step (`handwritten/dp.rs`)
//! against vigp's steps of the same equations, in one run:
//!
//! * `closed_form`: the hand-written step (closed-form M(q), ∂M/∂q₂, ∇V,
//!   Cramer's rule; the same Newton iteration, tolerance and scaling);
//! * `stepper`: the generated fixed-size step, `vigp::embedded::Stepper`;
//! * `std_variational`: the std runtime's `Variational::new`.
//!
//! A step from the state (1.0, −0.5; 0.5, 1.0) (`step`, all three), a
//! 100-step rollout that carries the momentum and starts Newton from
//! 2v_k − v_{k−1} (`rollout_100`, time per 100 steps; all three, the std
//! one through `Integrator::rollout_into`), and one step from each of 64
//! states every 50 steps along a trajectory (`step_64_states`, time per 64
//! steps; closed form and `Stepper`). Δt = 0.01 s.
//!
//! Run: `cargo bench --bench handwritten`. After criterion's output it
//! prints a table per step: criterion's median and the fastest of its 30
//! samples, each with its ratio to the closed form (read back from this
//! run's `estimates.json` and `sample.json`).
//! Record `uptime` with the numbers: the machine is shared.
//!
//! **Instruction counts** (load-independent): with `VIGP_COUNT=<what>:<n>`
//! the binary skips criterion and runs `n` steps of one kind, `what` one of
//! `closed_form_rollout`, `stepper_rollout` (a rollout of `n` steps),
//! `closed_form_step`, `stepper_step`, `std_variational_step` (`n` steps
//! from the 64 states in turn). The difference of callgrind's totals at `n` and at 0, divided by
//! `n`, is the count per step:
//!
//! ```text
//! cargo bench --bench handwritten --no-run      # prints the binary's path
//! VIGP_COUNT=closed_form_rollout:10000 valgrind --tool=callgrind target/release/deps/handwritten-…
//! VIGP_COUNT=closed_form_rollout:0     valgrind --tool=callgrind target/release/deps/handwritten-…
//! ```

use criterion::{BenchmarkGroup, Criterion, measurement::WallTime};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, SystemTime};
use vigp::embedded::{State, Stepper};
use vigp::systems::DoublePendulum;
use vigp::{Integrator, Variational};

mod handwritten {
    pub mod dp;
}
use handwritten::dp::{self, ClosedForm, Params};

const GROUP: &str = "handwritten";
const DT: f64 = 0.01;

/// (benchmark id, steps per iteration, label in the table)
const ROWS: [(&str, f64, &str); 8] = [
    ("dp_closed_form_step", 1.0, "closed form, step from a state"),
    (
        "dp_stepper_step",
        1.0,
        "embedded Stepper, step from a state",
    ),
    ("dp_std_variational_step", 1.0, "std Variational::new, step"),
    (
        "dp_closed_form_rollout_100",
        100.0,
        "closed form, rollout step",
    ),
    (
        "dp_stepper_rollout_100",
        100.0,
        "embedded Stepper, rollout step",
    ),
    (
        "dp_std_variational_rollout_100",
        100.0,
        "std Variational::new, rollout step",
    ),
    (
        "dp_closed_form_step_64_states",
        64.0,
        "closed form, step, 64 states",
    ),
    (
        "dp_stepper_step_64_states",
        64.0,
        "embedded Stepper, step, 64 states",
    ),
];

fn to_hand(z: &State<2>) -> dp::State {
    ([z.q[0], z.q[1]], [z.v[0], z.v[1]])
}

/// The 64 states every 50 steps along the Stepper's trajectory from `z`.
fn states_along(stepper: &Stepper<DoublePendulum, 2, 0>, z: &State<2>) -> Vec<State<2>> {
    let mut long = vec![*z; 64 * 50 + 1];
    stepper.rollout_into(z, &mut long).unwrap();
    long.iter().step_by(50).take(64).copied().collect()
}

/// `VIGP_COUNT=<what>:<n>` (module docs): `n` steps of one kind, for
/// instruction counts.
fn count(spec: &str) -> Result<(), String> {
    let (what, n) = spec.split_once(':').ok_or("VIGP_COUNT=<what>:<n>")?;
    let n: usize = n.parse().map_err(|e| format!("{n}: {e}"))?;
    let sys = DoublePendulum::default();
    let cf = ClosedForm::new(&Params::default(), DT).map_err(|e| format!("{e:?}"))?;
    let stepper = Stepper::new(sys, DT).map_err(|e| e.to_string())?;
    let z = State::new([1.0, -0.5], [0.5, 1.0]);
    let states = states_along(&stepper, &z);
    let states_h: Vec<dp::State> = states.iter().map(to_hand).collect();
    let mut acc = 0.0;
    match what {
        "closed_form_rollout" => {
            let mut out = vec![to_hand(&z); n + 1];
            cf.rollout_into(&to_hand(&z), &mut out)
                .map_err(|e| format!("{e:?}"))?;
            acc += out[n].1[0];
        }
        "stepper_rollout" => {
            let mut out = vec![z; n + 1];
            stepper
                .rollout_into(&z, &mut out)
                .map_err(|e| e.to_string())?;
            acc += out[n].v[0];
        }
        "closed_form_step" => {
            for k in 0..n {
                let z1 = cf.step(black_box(&states_h[k % 64]));
                acc += z1.map_err(|e| format!("{e:?}"))?.1[0];
            }
        }
        "stepper_step" => {
            for k in 0..n {
                let z1 = stepper.step(black_box(&states[k % 64]));
                acc += z1.map_err(|e| e.to_string())?.v[0];
            }
        }
        "std_variational_step" => {
            let vi = Variational::new(sys.minimal(), DT).unwrap();
            for k in 0..n {
                let z1 = vi.step(black_box(&states[k % 64]));
                acc += z1.map_err(|e| e.to_string())?.v[0];
            }
        }
        _ => return Err(format!("unknown VIGP_COUNT kind {what}")),
    }
    println!("{what}: {n} steps (checksum {acc})");
    Ok(())
}

fn bench(g: &mut BenchmarkGroup<'_, WallTime>) {
    let sys = DoublePendulum::default();
    let cf = ClosedForm::new(&Params::default(), DT).expect("valid parameters");
    let stepper = Stepper::new(sys, DT).expect("valid model");
    let vi = Variational::new(sys.minimal(), DT).unwrap();
    let z = State::new([1.0, -0.5], [0.5, 1.0]);
    let zh = to_hand(&z);

    g.bench_function(ROWS[0].0, |b| b.iter(|| cf.step(black_box(&zh)).unwrap()));
    g.bench_function(ROWS[1].0, |b| {
        b.iter(|| stepper.step(black_box(&z)).unwrap())
    });
    g.bench_function(ROWS[2].0, |b| b.iter(|| vi.step(black_box(&z)).unwrap()));

    let mut out_h = [zh; 101];
    g.bench_function(ROWS[3].0, |b| {
        b.iter(|| cf.rollout_into(black_box(&zh), &mut out_h).unwrap())
    });
    let mut out = [z; 101];
    g.bench_function(ROWS[4].0, |b| {
        b.iter(|| stepper.rollout_into(black_box(&z), &mut out).unwrap())
    });
    let mut out_std = [z; 100];
    g.bench_function(ROWS[5].0, |b| {
        b.iter(|| vi.rollout_into(black_box(&z), &mut out_std).unwrap())
    });
    // The same rollout by both: a check that they stay together (they
    // solve the same equations by the same iteration; tests/step/handwritten.rs).
    let gap = out_h
        .iter()
        .zip(&out)
        .map(|(h, s)| (h.1[0] - s.v[0]).abs().max((h.1[1] - s.v[1]).abs()))
        .fold(0.0, f64::max);
    assert!(gap < 1e-11, "rollouts differ by {gap:e}");

    let states = states_along(&stepper, &z);
    let states_h: Vec<dp::State> = states.iter().map(to_hand).collect();
    g.bench_function(ROWS[6].0, |b| {
        b.iter(|| {
            for z in &states_h {
                black_box(cf.step(black_box(z)).unwrap());
            }
        })
    });
    g.bench_function(ROWS[7].0, |b| {
        b.iter(|| {
            for z in &states {
                black_box(stepper.step(black_box(z)).unwrap());
            }
        })
    });
}

/// Where criterion writes its results (its own rule without `cargo
/// metadata`: `$CRITERION_HOME`, `$CARGO_TARGET_DIR/criterion`, else the
/// workspace's `target/criterion`).
fn criterion_dir() -> PathBuf {
    if let Some(h) = std::env::var_os("CRITERION_HOME") {
        return h.into();
    }
    if let Some(t) = std::env::var_os("CARGO_TARGET_DIR") {
        return PathBuf::from(t).join("criterion");
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/criterion")
}

/// Median and fastest sample (ns per iteration) of a benchmark measured
/// since `since`, from criterion's `estimates.json` and `sample.json`.
fn result_ns(id: &str, since: SystemTime) -> Option<(f64, f64)> {
    let dir = criterion_dir().join(GROUP).join(id).join("new");
    let read = |name: &str| -> Option<serde_json::Value> {
        let path = dir.join(name);
        if std::fs::metadata(&path).ok()?.modified().ok()? < since {
            return None;
        }
        serde_json::from_slice(&std::fs::read(&path).ok()?).ok()
    };
    let median = read("estimates.json")?["median"]["point_estimate"].as_f64()?;
    let sample = read("sample.json")?;
    let (iters, times) = (sample["iters"].as_array()?, sample["times"].as_array()?);
    let fastest = iters
        .iter()
        .zip(times)
        .filter_map(|(n, t)| Some(t.as_f64()? / n.as_f64()?))
        .fold(f64::INFINITY, f64::min);
    Some((median, fastest))
}

fn main() {
    if let Ok(spec) = std::env::var("VIGP_COUNT") {
        if let Err(e) = count(&spec) {
            eprintln!("{e}");
            std::process::exit(2);
        }
        return;
    }
    let start = SystemTime::now();
    let mut c = Criterion::default()
        .sample_size(30)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500))
        .configure_from_args();
    let mut g = c.benchmark_group(GROUP);
    bench(&mut g);
    g.finish();
    c.final_summary();

    // The table: median and fastest sample per step, and the ratio of the
    // medians to the closed form's row of the same kind (step / rollout
    // step / 64 states). On a loaded machine the fastest of the 30 samples
    // (each the mean of many iterations) is the better estimate of the
    // uninterrupted cost; the median includes interference.
    let res: Vec<Option<(f64, f64)>> = ROWS
        .iter()
        .map(|(id, n, _)| result_ns(id, start).map(|(m, f)| (m / n, f / n)))
        .collect();
    if res.iter().all(Option::is_none) {
        println!("(no results of this run found under {:?})", criterion_dir());
        return;
    }
    let base = [0, 0, 0, 3, 3, 3, 6, 6];
    println!("\ndouble pendulum, dt = {DT}: criterion, ns per step (this run)");
    println!(
        "{:<36} {:>9} {:>8} {:>9} {:>8}",
        "", "median", "× c.f.", "fastest", "× c.f."
    );
    for (i, (_, _, label)) in ROWS.iter().enumerate() {
        let Some((m, f)) = res[i] else { continue };
        let ratio = |x: f64, pick: fn(&(f64, f64)) -> f64| {
            res[base[i]].map_or(String::from("-"), |b| format!("{:.2}", x / pick(&b)))
        };
        println!(
            "{label:<36} {m:>9.1} {:>8} {f:>9.1} {:>8}",
            ratio(m, |b| b.0),
            ratio(f, |b| b.1)
        );
    }
}
