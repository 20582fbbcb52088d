//! Work-precision report: for the four paper systems and the six
//! integrators (explicit Euler, symplectic Euler, RK4, the paper's
//! first-order VI, the midpoint VI, the fourth-order VI), the position error at t = 2 s against
//! the compute time per simulated second over a range of time steps, and
//! the long-horizon energy error against the same cost.
//!
//! ```text
//! cargo run --release --example work_precision               # default, ~20 s on 2 cores
//! cargo run --release --example work_precision -- --full     # 32 time steps, more repetitions, 1000 s energy runs
//! cargo run --release --example work_precision -- --help     # systems, dt range, reference, output directory
//! ```
//!
//! Method (details in the written `report.md`):
//! - every system starts at rest from a fixed configuration, undamped;
//! - error: max_i |q_i(T) − q_ref,i(T)| over the minimal coordinates —
//!   positions only, since the first-order and midpoint VIs carry a
//!   discrete velocity and the classical integrators and the fourth-order
//!   VI (`Composition`) the continuous one;
//! - reference: the midpoint VI at h/2 and h/4, Richardson-extrapolated;
//!   its error is estimated from the extrapolation at h and h/2, and checked
//!   against RK4 (and, for the fourbar, the maximal-coordinate model);
//! - cost: median wall time of the stepping loop per simulated second;
//! - fourbar: all integrators in minimal coordinates; the classical ones
//!   integrate the index-1 DAE (acceleration-level constraint) without
//!   projection, the VIs solve g = 0 at position level every step (the
//!   fourth-order VI at each of its midpoint sub-steps);
//! - results that are not finite (explicit Euler blowing up) or solver
//!   failures are recorded as `diverged` / `failed`, never plotted.

mod analysis;
#[path = "../common/figure.rs"]
mod figure;
#[path = "../common/font.rs"]
mod font;
#[path = "../common/median.rs"]
mod median;
mod output;
mod run;

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use nalgebra::SVector;
use vigp::prelude::*;
use vigp::projection::project_configuration;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

use analysis::FitWindow;
use output::{ReferenceSummary, RunInfo, SystemResult};
use run::{Method, Problem, Timing};

const SYSTEMS: [&str; 4] = ["pendulum", "cartpole", "double_pendulum", "fourbar"];

/// Command-line settings. Unset options take the default or `--full` value.
#[derive(Parser, Debug, Clone)]
#[command(about = "Work-precision report: error at T and long-horizon energy error against cost")]
struct Cli {
    /// Systems (comma separated): pendulum, cartpole, double_pendulum, fourbar.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "pendulum,cartpole,double_pendulum,fourbar"
    )]
    systems: Vec<String>,
    /// The heavier run: 32 time steps, ≥ 7 repetitions and ≥ 0.2 s per point,
    /// reference from h = 5e-5 s, 1000 s energy runs at 4 time steps.
    #[arg(long)]
    full: bool,
    /// End time T of the error measurement (s).
    #[arg(long, default_value_t = 2.0)]
    t_end: f64,
    /// Largest time step (s).
    #[arg(long, default_value_t = 0.1)]
    dt_max: f64,
    /// Smallest time step (s).
    #[arg(long, default_value_t = 1e-4)]
    dt_min: f64,
    /// Number of log-spaced time steps [default: 16, --full: 32]. A
    /// fourth-order method has only a decade or so of time steps between
    /// its large-step regime and the round-off/solver floor: 16 steps over
    /// three decades put 4–6 points there.
    #[arg(long)]
    dts: Option<usize>,
    /// Coarsest reference step h (s); the reference uses h/2 and h/4
    /// [default: 1e-4, --full: 5e-5].
    #[arg(long)]
    ref_dt: Option<f64>,
    /// Minimum timed repetitions per point [default: 3, --full: 7].
    #[arg(long)]
    reps: Option<usize>,
    /// Minimum total time of the repetitions of one point (s) [default: 0.05, --full: 0.2].
    #[arg(long)]
    min_time: Option<f64>,
    /// Horizon of the energy runs (s) [default: 100, --full: 1000].
    #[arg(long)]
    energy_horizon: Option<f64>,
    /// Time steps of the energy runs (s, comma separated)
    /// [default: 0.02,0.01,0.005; --full: 0.02,0.01,0.005,0.002].
    #[arg(long, value_delimiter = ',')]
    energy_dt: Option<Vec<f64>>,
    /// Output directory.
    #[arg(long, default_value = "target/work_precision")]
    out: PathBuf,
}

/// The settings after defaults, validated.
struct Settings {
    t_end: f64,
    steps: Vec<usize>,
    ref_steps: usize,
    timing: Timing,
    energy_horizon: f64,
    energy_steps: Vec<usize>,
    fit_points: usize,
}

fn settings(cli: &Cli) -> Result<Settings, Box<dyn Error>> {
    let full = cli.full;
    let dts = cli.dts.unwrap_or(if full { 32 } else { 16 });
    let ref_dt = cli.ref_dt.unwrap_or(if full { 5e-5 } else { 1e-4 });
    let reps = cli.reps.unwrap_or(if full { 7 } else { 3 });
    let min_time = cli.min_time.unwrap_or(if full { 0.2 } else { 0.05 });
    let horizon = cli
        .energy_horizon
        .unwrap_or(if full { 1000.0 } else { 100.0 });
    let energy_dt = cli.energy_dt.clone().unwrap_or_else(|| {
        if full {
            vec![0.02, 0.01, 0.005, 0.002]
        } else {
            vec![0.02, 0.01, 0.005]
        }
    });
    let t = cli.t_end;
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(t) || !positive(cli.dt_max) || !positive(cli.dt_min) || cli.dt_min > cli.dt_max {
        return Err("need T > 0 and 0 < dt-min <= dt-max".into());
    }
    if cli.dt_max > t {
        return Err("dt-max must not exceed T".into());
    }
    if !(1..=64).contains(&dts) {
        return Err("--dts must be between 1 and 64".into());
    }
    if !positive(ref_dt) || ref_dt > cli.dt_min {
        return Err("need 0 < ref-dt <= dt-min".into());
    }
    if reps == 0 || !(min_time.is_finite() && min_time >= 0.0) {
        return Err("need reps >= 1 and min-time >= 0".into());
    }
    if !positive(horizon)
        || energy_dt.is_empty()
        || energy_dt.iter().any(|&d| !positive(d) || d > horizon)
    {
        return Err("need an energy horizon > 0 and energy time steps in (0, horizon]".into());
    }
    // log-spaced dt, rounded to whole numbers of steps to T
    let mut steps: Vec<usize> = (0..dts)
        .map(|i| {
            let f = if dts == 1 {
                0.0
            } else {
                i as f64 / (dts - 1) as f64
            };
            let dt = cli.dt_max * (cli.dt_min / cli.dt_max).powf(f);
            (t / dt).round().max(1.0) as usize
        })
        .collect();
    steps.dedup();
    let ref_steps = (t / ref_dt).round().max(1.0) as usize;
    let max_steps = 50_000_000;
    let energy_steps: Vec<usize> = energy_dt
        .iter()
        .map(|&d| (horizon / d).round().max(1.0) as usize)
        .collect();
    if 4 * ref_steps > max_steps || energy_steps.iter().any(|&n| n > max_steps) {
        return Err(format!("more than {max_steps} steps in one run: choose larger steps").into());
    }
    Ok(Settings {
        t_end: t,
        steps,
        ref_steps,
        timing: Timing {
            min_reps: reps,
            min_total: min_time,
            max_reps: reps.max(1000),
        },
        energy_horizon: horizon,
        energy_steps,
        // the smallest admitted time steps, a quarter of them (at least 4):
        // the asymptotic regime of a fourth-order method spans few points
        fit_points: (dts / 4).max(4),
    })
}

/// Runs the reference, the sweep and the energy runs of one system.
/// [`evaluate`] of `model` started at rest at `q0` (`start`: its label),
/// without independent checks; `(name, label)`: the system's name and
/// its label in the progress lines.
fn at_rest<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    (name, label): (&'static str, &str),
    model: M,
    q0: [f64; N],
    start: &str,
    s: &Settings,
) -> Result<SystemResult, Box<dyn Error>> {
    let problem = Problem {
        name,
        model,
        q0: SVector::from(q0),
        qdot0: SVector::zeros(),
    };
    evaluate(&problem, label, start.into(), &[], s)
}

fn evaluate<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    problem: &Problem<M, N, C>,
    label: &str,
    start: String,
    extra_checks: &[run::Check<'_, N>],
    s: &Settings,
) -> Result<SystemResult, Box<dyn Error>> {
    let t0 = Instant::now();
    eprintln!(
        "{label}: reference (midpoint VI at h/2 = {:.1e} s and h/4, extrapolated) …",
        s.t_end / s.ref_steps as f64 / 2.0
    );
    let reference = run::reference(problem, s.ref_steps, s.t_end, extra_checks)
        .map_err(|f| format!("{label}: the reference failed: {}", f.message))?;
    eprintln!(
        "{label}:   reference error estimate {:.2e} (midpoint h/2 vs h/4: {:.2e}); checks: {}",
        reference.error_estimate,
        reference.raw_difference,
        reference
            .checks
            .iter()
            .map(|(n, c)| match c {
                Ok(d) => format!("{n}: {d:.2e}"),
                Err(f) => format!("{n}: {}", f.message),
            })
            .collect::<Vec<_>>()
            .join("; ")
    );
    let mut sweep = Vec::new();
    for method in Method::ALL {
        for &n in &s.steps {
            let p = run::sweep_point(problem, method, n, s.t_end, &reference.q, &s.timing);
            match &p.outcome {
                Ok(m) => eprintln!(
                    "{label}:   {:<26} dt {:.2e}: error {:.2e}, {:.3e} s/s ({} reps)",
                    method.label(),
                    p.dt,
                    m.error,
                    m.cost,
                    m.reps
                ),
                Err(f) => eprintln!(
                    "{label}:   {:<26} dt {:.2e}: {} ({})",
                    method.label(),
                    p.dt,
                    f.status(),
                    f.message
                ),
            }
            sweep.push(p);
        }
    }
    let mut energy = Vec::new();
    for method in Method::ALL {
        for &n in &s.energy_steps {
            let p = run::energy_run(problem, method, n, s.energy_horizon);
            match &p.outcome {
                Ok(e) => eprintln!(
                    "{label}:   energy {:<19} dt {:.2e}: max |ΔE| {:.2e} J, {:.3e} s/s",
                    method.label(),
                    p.dt,
                    e.max_de,
                    e.cost
                ),
                Err(f) => eprintln!(
                    "{label}:   energy {:<19} dt {:.2e}: {} ({})",
                    method.label(),
                    p.dt,
                    f.status(),
                    f.message
                ),
            }
            energy.push(p);
        }
    }
    eprintln!("{label}: done in {:.0} s", t0.elapsed().as_secs_f64());
    // fit window: clear of the reference's error (×10), of the run's
    // solver error and accumulated round-off (×10, `FitWindow::admits`),
    // no blown-up errors, and the smallest steps (the asymptotic regime)
    let fit_window = FitWindow {
        lo: (10.0 * reference.error_estimate).max(1e-13),
        hi: 0.1,
        max_points: s.fit_points,
        roundoff: f64::EPSILON * reference.q.amax().max(1.0),
    };
    Ok(SystemResult {
        name: problem.name.to_string(),
        label: label.to_string(),
        start,
        reference: ReferenceSummary {
            h: reference.h,
            raw_difference: reference.raw_difference,
            error_estimate: reference.error_estimate,
            checks: reference.checks,
            seconds: reference.seconds,
        },
        sweep,
        fit_window,
        energy,
    })
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(", "))
        .unwrap_or_else(|| "n/a".into())
}

fn main() -> Result<(), Box<dyn Error>> {
    let cli = Cli::parse();
    if let Some(bad) = cli.systems.iter().find(|s| !SYSTEMS.contains(&s.as_str())) {
        return Err(format!(
            "unknown system `{bad}` (expected one of {})",
            SYSTEMS.join(", ")
        )
        .into());
    }
    let s = settings(&cli)?;
    let load_start = loadavg();
    let t0 = Instant::now();
    eprintln!(
        "work-precision: T = {} s, {} time steps {:.1e} … {:.1e} s, energy runs {} s at {:?} steps; load average {load_start}",
        s.t_end,
        s.steps.len(),
        s.t_end / s.steps[0] as f64,
        s.t_end / s.steps[s.steps.len() - 1] as f64,
        s.energy_horizon,
        s.energy_steps
    );
    let mut results = Vec::new();
    for name in &cli.systems {
        let r = match name.as_str() {
            "pendulum" => at_rest(
                ("pendulum", "pendulum"),
                Pendulum::default().minimal(),
                [1.5],
                "θ = 1.5 rad",
                &s,
            )?,
            "cartpole" => at_rest(
                ("cartpole", "cartpole"),
                Cartpole::default().minimal(),
                [0.0, 2.0],
                "x = 0 m, θ = 2.0 rad",
                &s,
            )?,
            "double_pendulum" => at_rest(
                ("double_pendulum", "double pendulum"),
                DoublePendulum::default().minimal(),
                [1.0, 0.5],
                "θ = (1.0, 0.5) rad",
                &s,
            )?,
            "fourbar" => {
                let fb = Fourbar::default();
                let (min, max) = (fb.minimal(), fb.maximal());
                // a rhombus with arms at absolute angles 0.9 and −0.4 rad
                // (closes exactly; projected anyway)
                let (t1, t3) = (0.9, -0.4);
                let guess = SVector::from([t1, t3 - t1, t3, t1 - t3]);
                let (q0, _) = project_configuration(&min, &guess, &StepOptions::default())?;
                let problem = Problem {
                    name: "fourbar",
                    model: min,
                    q0,
                    qdot0: SVector::zeros(),
                };
                // independent check: the same system in maximal coordinates
                // (12 coordinates, 10 constraints), midpoint VI at h/2 and
                // h/4 extrapolated, read back in minimal coordinates
                let (t_end, n) = (s.t_end, s.ref_steps);
                let maximal = move || -> Result<SVector<f64, 4>, StepError> {
                    let run = |steps: usize| -> Result<SVector<f64, 4>, StepError> {
                        let h = t_end / steps as f64;
                        let v = vigp::dynamics::discrete_velocity(&min, &q0, &SVector::zeros(), h)?;
                        let zm = min.to_maximal(&State { q: q0, v }, h);
                        let vi =
                            Variational::midpoint(max, h)?.tolerance(run::REFERENCE_TOLERANCE)?;
                        let (end, _) = run::timed_run(&vi, &zm, steps);
                        Ok(min.minimal_positions(&end?.q))
                    };
                    Ok(run::richardson(&run(2 * n)?, &run(4 * n)?))
                };
                evaluate(
                    &problem,
                    "fourbar",
                    "arms at θ₁ = 0.9, θ₃ = −0.4 rad (rhombus)".into(),
                    &[(
                        "maximal coordinates, midpoint VI, same extrapolation".into(),
                        &maximal,
                    )],
                    &s,
                )?
            }
            other => return Err(format!("unknown system `{other}`").into()),
        };
        results.push(r);
    }
    let info = RunInfo {
        command: std::iter::once("cargo run --release --example work_precision --".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" "),
        t_end: s.t_end,
        energy_horizon: s.energy_horizon,
        min_reps: s.timing.min_reps,
        min_total: s.timing.min_total,
        cpus: std::thread::available_parallelism().map_or(0, |n| n.get()),
        load_start,
        load_end: loadavg(),
        seconds: t0.elapsed().as_secs_f64(),
    };
    let files = output::write_all(&cli.out, &results, &info)?;
    println!("{}", output::summary_table(&results, &info));
    println!(
        "wrote {} files to {} in {:.0} s",
        files.len(),
        cli.out.display(),
        info.seconds
    );
    Ok(())
}
