//! The main job: reproduce the evaluation of Brüdigam et al., "Structure-
//! Preserving Learning Using Gaussian Processes and Variational Integrators"
//! (L4DC 2022), §4, with a small default that finishes in minutes on 2 cores.
//!
//! ```text
//! cargo run --release --example paper                 # small default
//! cargo run --release --example paper -- --full       # the paper's settings
//! cargo run --release --example paper -- --help       # systems, N, runs, seed, …
//! ```
//!
//! Protocol (paper §4): per run a perturbed system (masses and inertias
//! ×U[0.9, 1.1], viscous joint friction drawn per system); ground truth by
//! the fourth-order variational integrator (Suzuki's composition of the
//! midpoint VI) at 2.5 ms, which is more accurate than the paper's
//! second-order reference at 0.1 ms with 5× fewer Newton solves (`--gt-method midpoint
//! --gt-dt 1e-4` restores that; the report states the ground truth's error
//! against half its step and against the midpoint VI at 0.1 ms); model
//! Δt = 10 ms; 2 s trajectories
//! from uniformly random configurations at rest; Gaussian noise σ = 1e-3 on
//! training states; nested training sets (each N the first N samples of one
//! draw from the training trajectories); 20-step predictions from held-out
//! trajectories, position MSE in minimal coordinates. Output: plots (SVG, PNG), CSV and a Markdown
//! report in one directory, named at the end.
//!
//! Sharding (across processes or machines; docs/sharding.md): the sweep is
//! a list of independent units (Fig. 1; each run of each system; the error
//! bounds of each system), each seeded from (seed, system, run) alone.
//! `--shard i/N` (0-based) computes every N-th unit from the i-th and
//! writes their raw results (`shard.json`, floats exact) to its own folder,
//! `target/paper-shards/shard-i-of-N/` unless `--out` is given; `merge`
//! checks the shards and writes the report. A run without `--shard` is the
//! one shard `0/1` and goes through the same check and report, so the
//! merged files equal an unsharded run's byte for byte:
//!
//! ```text
//! for i in 0 1 2 3; do cargo run --release --example paper -- --shard $i/4; done
//! cargo run --release --example paper -- merge target/paper-shards/shard-*-of-4
//! ```
//!
//! Error bounds ([`bounds`]): coverage and tightness of the conformal,
//! Theorem-1 and RKHS bounds at δ = 0.05, one step and 20 steps, per system
//! and coordinate choice, on held-out data from other seeds and on starts
//! outside the training region (`bounds.md`, `bounds.csv`, and the figure
//! `bounds_tube.svg` of a prediction with its bound tubes against the
//! truth); `--no-bounds` skips them.

mod bounds;
#[path = "../common/figure.rs"]
mod figure;
#[path = "../common/font.rs"]
mod font;
#[path = "../common/median.rs"]
mod median;
mod output;
#[path = "../common/protocol.rs"]
mod protocol;
#[path = "../common/shard.rs"]
mod shard;
#[path = "../common/windows.rs"]
mod windows;

use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser};
use indicatif::{ProgressBar, ProgressStyle};
use median::median;
use nalgebra::SVector;
use output::{Fig1, Fig2Point, Series, med};
use protocol::{
    Counts, DT, GT_SOLVER, Gt, GtMethod, HORIZON, Protocol, TRAJ_SAMPLES, add_noise,
    cartpole_start, double_pendulum_start, fourbar_start, ground_truth, mean_mse, pendulum_start,
    perturb_cartpole, perturb_double_pendulum, perturb_fourbar, perturb_pendulum,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use shard::{Shard, ShardFile};
use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;
use vigp::gp::{Curvature, Hyperparameters, Screening, TrainOptions};
use vigp::learned::{Encoding, Learned, Prior, transitions};
use vigp::prelude::*;
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

/// The command line: a run (or one shard of it), or `merge`.
#[derive(Parser, Debug)]
#[command(
    about = "Reproduce the paper's evaluation (Fig. 1 and Fig. 2)",
    args_conflicts_with_subcommands = true
)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    cli: Cli,
}

/// Subcommands.
#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Merge the folders of `--shard i/N` runs (all N of them) into the
    /// report of one unsharded run.
    Merge {
        /// The shard folders (or their `shard.json` files).
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        /// Output directory of the report.
        #[arg(long, default_value = "target/paper")]
        out: PathBuf,
    },
}

/// Settings of a run. All but `--out`, `--shard` and `--full` (already
/// applied to the others) are written into every shard's file, and `merge`
/// requires them equal.
#[derive(clap::Args, Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Cli {
    /// The protocol's settings.
    #[command(flatten)]
    #[serde(flatten)]
    protocol: Protocol,
    /// Warm starts along the N sweep: within a run, each model after the
    /// first N starts from the optimum of the same model at the previous N
    /// (`TrainOptions::warm_start`) with `--warm-restarts` random restarts
    /// instead of `--restarts`. The first N keeps `--restarts`. Cheaper,
    /// but measured worse on this sweep (docs/paper-evaluation.md): an
    /// optimum fitted to a few samples starts the next N on a poor branch.
    #[arg(long)]
    warm: bool,
    /// Random restarts beside the warm start (with `--warm`).
    #[arg(long, default_value_t = 0)]
    warm_restarts: usize,
    /// Output directory [default: target/paper; with --shard i/N:
    /// target/paper-shards/shard-i-of-N].
    #[arg(long, default_value = "target/paper")]
    #[serde(skip)]
    out: PathBuf,
    /// Compute only shard i of N (0-based, `0/4` … `3/4`): every N-th unit
    /// of work (Fig. 1, a run of a system, a system's bounds) from the i-th,
    /// written as raw results to `shard.json` in the output directory;
    /// `merge` makes the report of all N.
    #[arg(long, value_name = "i/N")]
    #[serde(skip)]
    shard: Option<Shard>,
    /// The paper's settings: 100 runs, 200/100 trajectories, N up to 512,
    /// 10 restarts (each unless given explicitly: `--full --runs 1`).
    #[arg(long)]
    #[serde(skip)]
    full: bool,
    /// Skip the error-bound evaluation.
    #[arg(long)]
    no_bounds: bool,
    /// Run every start of the GP training on all N samples (scikit-learn's
    /// procedure) instead of screening the starts from N = 512.
    #[arg(long)]
    no_screen: bool,
    /// Screen the starts from N = 512 on a fresh random subset of N/2
    /// samples (the library's `Screening::Auto`) instead of refining the
    /// previous N's optima. The training sets are nested (each N's samples
    /// are the first N of one draw), so the previous N's training (N/2
    /// samples, all starts) is such a subset run already: by default
    /// `TrainOptions::candidates` hands its distinct optima over (with the
    /// optimiser's curvature at each, `TrainOptions::candidate_curvature`)
    /// and the subset runs are not repeated.
    #[arg(long)]
    subset_screen: bool,
    /// Calibration trajectories, and as many test trajectories, per system
    /// for the error bounds (each gives 19 windows of 20 steps).
    #[arg(long, default_value_t = 60)]
    bound_trajectories: usize,
}

impl Cli {
    /// The GP training's screening of its starts (`--no-screen`).
    fn screening(&self) -> Screening {
        if self.no_screen {
            Screening::Off
        } else {
            Screening::Auto
        }
    }

    /// The screening of the starts, for the report.
    fn describe_screening(&self) -> &'static str {
        if self.no_screen {
            "every start on all samples"
        } else if self.subset_screen {
            "from N = 512 the starts screened on a random subset of N/2 samples"
        } else {
            "from N = 512 the previous N's distinct optima refined on all samples (seeded with the optimiser's curvature there) instead of the starts"
        }
    }

    /// Whether a training on N samples refines the optima of the previous
    /// N's (on `prev` samples, the first `prev` of the same draw) instead
    /// of screening its starts: where the library would screen, on a
    /// subset at least as large as its own, and neither `--no-screen`,
    /// `--subset-screen` nor `--warm` is given.
    fn refines_previous(&self, n: usize, prev: usize) -> bool {
        !(self.no_screen || self.subset_screen || self.warm)
            && n >= vigp::gp::SCREEN_FROM
            && prev < n
            && prev >= Screening::auto_size(n)
    }
}

/// A training's distinct optima per output and the optimiser's curvature
/// at each (`OutputReport::optima`, `OutputReport::optima_curvature`).
type Optima = (Vec<Vec<Hyperparameters>>, Vec<Vec<Curvature>>);

/// The tag of this example's shard files.
const SHARD_FORMAT: &str = "vigp-paper-shard/1";

/// One unit of work of the sweep: units are independent (each seeded from
/// the seed, its system and its run alone) and their results make the
/// report in any grouping into shards.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Unit {
    /// Fig. 1.
    Fig1,
    /// The error bounds of a system.
    Bounds(String),
    /// One run (perturbed system, data, every N) of a system.
    Run(String, usize),
}

/// The sweep's units in order: shard i of N computes those at positions
/// k with k mod N = i. The bounds (the costliest units of the default)
/// come first, so that they spread over the shards.
fn units(cli: &Cli) -> Vec<Unit> {
    let mut units = vec![Unit::Fig1];
    if !cli.no_bounds {
        units.extend(cli.protocol.systems.iter().map(|s| Unit::Bounds(s.clone())));
    }
    for s in &cli.protocol.systems {
        units.extend((0..cli.protocol.runs).map(|r| Unit::Run(s.clone(), r)));
    }
    units
}

/// The result of one unit.
#[derive(Debug, Serialize, Deserialize)]
enum Output {
    /// Fig. 1 and its finding lines.
    Fig1 { fig1: Fig1, notes: String },
    /// The error bounds of a system.
    Bounds {
        system: String,
        rows: Vec<bounds::BoundRow>,
        tubes: Vec<bounds::Tube>,
    },
    /// One run of a system.
    Run(RunOutput),
}

impl shard::UnitResult for Output {
    type Key = Unit;
    fn key(&self) -> Unit {
        match self {
            Output::Fig1 { .. } => Unit::Fig1,
            Output::Bounds { system, .. } => Unit::Bounds(system.clone()),
            Output::Run(r) => Unit::Run(r.system.clone(), r.run),
        }
    }
}

/// One run's Fig. 2 points, for run 0 the ground truth's accuracy (see
/// `ground_truth_error`), and its failed and attempted prediction windows.
#[derive(Debug, Serialize, Deserialize)]
struct RunOutput {
    system: String,
    run: usize,
    points: Vec<Fig2Point>,
    #[serde(with = "shard::exact")]
    gt_err: Option<(f64, f64)>,
    failed: usize,
    windows: usize,
}

#[path = "../../tests/common/rng.rs"]
mod rng;
use rng::Rng;

/// The ground truth's accuracy over one trajectory: the max position
/// difference against its own integrator at half the step (a Richardson-
/// style estimate of its error: ≈ 16/15 of this for a fourth-order method,
/// 4/3 for a second-order one), and against the paper's reference, the
/// midpoint VI at 0.1 ms.
fn ground_truth_error<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    q0: &SVector<f64, N>,
    gt: Gt,
) -> Result<(f64, f64), StepError> {
    let diff = |a: &[SVector<f64, N>], b: &[SVector<f64, N>]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).amax())
            .fold(0.0, f64::max)
    };
    let a = ground_truth(m, q0, gt)?;
    let half = ground_truth(
        m,
        q0,
        Gt {
            dt: gt.dt / 2.0,
            ..gt
        },
    )?;
    let paper = ground_truth(
        m,
        q0,
        Gt {
            method: GtMethod::Midpoint,
            dt: 1e-4,
        },
    )?;
    Ok((diff(&a, &half), diff(&a, &paper)))
}

/// What one system contributes to Fig. 2.
struct SystemSpec<S, Mn, Mx> {
    name: &'static str,
    prior: Prior,
    perturb: fn(&mut S, &mut Rng),
    minimal: fn(&S) -> Mn,
    maximal: fn(&S) -> Mx,
}

impl<S: Default, Mn, Mx> SystemSpec<S, Mn, Mx> {
    /// A perturbed truth drawn from `rng` in minimal coordinates, and the
    /// nominal system in minimal and maximal coordinates.
    fn models(&self, rng: &mut Rng) -> (Mn, Mn, Mx) {
        let nominal = S::default();
        let mut truth = S::default();
        (self.perturb)(&mut truth, rng);
        (
            (self.minimal)(&truth),
            (self.minimal)(&nominal),
            (self.maximal)(&nominal),
        )
    }
}

#[allow(clippy::too_many_arguments)]
fn evaluate_system<S, Mn, Mx, const N: usize, const C: usize, const M: usize, const K: usize>(
    spec: &SystemSpec<S, Mn, Mx>,
    sample_q0: impl Fn(&mut Rng) -> SVector<f64, N> + Sync,
    runs: &[usize],
    cli: &Cli,
    progress: &ProgressBar,
) -> Result<Vec<RunOutput>, Box<dyn std::error::Error>>
where
    S: Default + Copy + Send + Sync,
    Mn: Mechanism<N, C> + Coordinates<N, M> + vigp::Parameters + Copy + Send + Sync,
    Mx: Mechanism<M, K> + vigp::Parameters + Copy + Send + Sync,
{
    // The runs are independent (each its own seeded RNG, its own training
    // sets and fits), so they run side by side: the idle ends of one run's
    // trainings take the other's work. The points come back in run order.
    let one_run = |run: usize| -> Result<RunOutput, StepError> {
        let mut points = Vec::new();
        let counts = Counts::default();
        let mut rng = Rng(cli.protocol.seed
            ^ (run as u64 + 1).wrapping_mul(0x2545_F491_4F6C_DD1D)
            ^ spec.name.len() as u64);
        let (tmin, nmin, nmax) = spec.models(&mut rng);
        let starts: Vec<SVector<f64, N>> = (0..cli.protocol.train_trajectories
            + cli.protocol.test_trajectories)
            .map(|_| sample_q0(&mut rng))
            .collect();
        let trajs: Vec<Vec<SVector<f64, N>>> = starts
            .par_iter()
            .map(|q0| ground_truth(tmin, q0, cli.protocol.gt()))
            .collect::<Result<_, _>>()?;
        let gt_err = if run == 0 {
            Some(ground_truth_error(tmin, &starts[0], cli.protocol.gt())?)
        } else {
            None
        };
        let (train, test) = trajs.split_at(cli.protocol.train_trajectories);
        // training pool (noisy), in minimal and maximal coordinates
        let mut pool_min = Vec::new();
        let mut pool_max = Vec::new();
        for traj in train {
            let tmax: Vec<SVector<f64, M>> =
                traj.iter().map(|q| tmin.maximal_positions(q)).collect();
            for (a, b) in transitions(traj, DT)
                .iter()
                .zip(transitions(&tmax, DT).iter())
            {
                pool_min.push(add_noise(a, &mut rng));
                pool_max.push(add_noise(b, &mut rng));
            }
        }
        // test windows: noise-free starts z_k and the next HORIZON positions
        let windows = cli.protocol.test_windows(test, &mut rng);
        let nominal_vi = Variational::new(nmin, DT)?;
        let nominal_mse = mean_mse(&windows, &counts, |z| {
            Ok(nominal_vi
                .rollout(z, HORIZON)?
                .into_iter()
                .map(|z| z.q)
                .collect())
        });
        // `--warm`: each model's optimum at the previous N (minimal,
        // sin/cos, maximal), the next N's start 0; a failed training
        // keeps the one before
        let mut warm: [Option<Vec<Hyperparameters>>; 3] = [None, None, None];
        // nested training sets: each N's samples are the first N of one draw
        let draw = cli.protocol.draw(pool_min.len(), &mut rng);
        // per model: the previous N's sample count and distinct optima
        let mut previous: [Option<(usize, Optima)>; 3] = [None, None, None];
        for &n in &cli.protocol.n {
            let n_eff = n.min(pool_min.len());
            let idx = &draw[..n_eff];
            let dmin: Vec<_> = idx.iter().map(|&i| pool_min[i]).collect();
            let dmax: Vec<_> = idx.iter().map(|&i| pool_max[i]).collect();
            // each model's options at this N (from the previous N's fits)
            let options: [TrainOptions; 3] = core::array::from_fn(|model| {
                let warm_start = warm[model].clone().filter(|_| cli.warm);
                let (candidates, candidate_curvature) = previous[model]
                    .clone()
                    .filter(|(prev, _)| cli.refines_previous(n_eff, *prev))
                    .map(|(_, optima)| optima)
                    .unzip();
                TrainOptions {
                    restarts: if warm_start.is_some() {
                        cli.warm_restarts
                    } else {
                        cli.protocol.restarts
                    },
                    seed: cli.protocol.seed ^ n as u64,
                    warm_start,
                    screening: cli.screening(),
                    memory: cli.protocol.memory,
                    candidates,
                    candidate_curvature,
                    ..TrainOptions::default()
                }
            });
            let optima = |r: &vigp::gp::TrainReport| -> Optima {
                r.outputs
                    .iter()
                    .map(|o| (o.optima.clone(), o.optima_curvature.clone()))
                    .unzip()
            };
            points.push(Fig2Point {
                system: spec.name.into(),
                method: "nominal".into(),
                n,
                run,
                mse: nominal_mse,
            });
            for (model, (method, enc)) in [("minimal", Encoding::Raw), ("sincos", Encoding::SinCos)]
                .into_iter()
                .enumerate()
            {
                let mse =
                    match Learned::train(nmin, DT, &dmin, enc, spec.prior.clone(), &options[model])
                    {
                        Ok((l, report)) => {
                            warm[model] = Some(l.gp().warm_start());
                            previous[model] = Some((n_eff, optima(&report)));
                            mean_mse(&windows, &counts, |z| {
                                Ok(l.rollout(z, HORIZON)?.into_iter().map(|z| z.q).collect())
                            })
                        }
                        Err(e) => {
                            eprintln!(
                                "{} run {run} N {n} {method}: training failed: {e}",
                                spec.name
                            );
                            f64::NAN
                        }
                    };
                points.push(Fig2Point {
                    system: spec.name.into(),
                    method: method.into(),
                    n,
                    run,
                    mse,
                });
            }
            let mse = match Learned::train(
                nmax,
                DT,
                &dmax,
                Encoding::Raw,
                spec.prior.clone(),
                &options[2],
            ) {
                Ok((l, report)) => {
                    warm[2] = Some(l.gp().warm_start());
                    previous[2] = Some((n_eff, optima(&report)));
                    mean_mse(&windows, &counts, |z| {
                        let zm = nmin.to_maximal(z, DT);
                        // the learned maximal model predicts; positions are compared in minimal coordinates
                        Ok(l.rollout(&zm, HORIZON)?
                            .into_iter()
                            .map(|z| nmin.minimal_positions(&z.q))
                            .collect())
                    })
                }
                Err(e) => {
                    eprintln!(
                        "{} run {run} N {n} maximal: training failed: {e}",
                        spec.name
                    );
                    f64::NAN
                }
            };
            points.push(Fig2Point {
                system: spec.name.into(),
                method: "maximal".into(),
                n,
                run,
                mse,
            });
            progress.inc(1);
        }
        Ok(RunOutput {
            system: spec.name.into(),
            run,
            points,
            gt_err,
            failed: counts.failed.load(Ordering::Relaxed),
            windows: counts.windows.load(Ordering::Relaxed),
        })
    };
    Ok(runs
        .par_iter()
        .map(|&run| one_run(run))
        .collect::<Result<_, _>>()?)
}

/// The units of one system among `todo`: its runs (Fig. 2), then its error
/// bounds.
fn run_system<S, Mn, Mx, const N: usize, const C: usize, const M: usize, const K: usize>(
    spec: &SystemSpec<S, Mn, Mx>,
    sample: &bounds::Start<'_, N>,
    shifted: &bounds::MovingStart<'_, N>,
    cli: &Cli,
    todo: &[Unit],
    progress: &ProgressBar,
) -> Result<Vec<Output>, Box<dyn std::error::Error>>
where
    S: Default + Copy + Send + Sync,
    Mn: Mechanism<N, C> + Coordinates<N, M> + vigp::Parameters + Copy + Send + Sync,
    Mx: Mechanism<M, K> + vigp::Parameters + Copy + Send + Sync,
{
    let runs: Vec<usize> = todo
        .iter()
        .filter_map(|u| match u {
            Unit::Run(s, r) if s == spec.name => Some(*r),
            _ => None,
        })
        .collect();
    let mut out: Vec<Output> = evaluate_system(spec, sample, &runs, cli, progress)?
        .into_iter()
        .map(Output::Run)
        .collect();
    if todo.contains(&Unit::Bounds(spec.name.into())) {
        progress.set_message(format!("{}: error bounds", spec.name));
        let (rows, tubes) = bounds::evaluate(spec, sample, shifted, cli)?;
        out.push(Output::Bounds {
            system: spec.name.into(),
            rows,
            tubes,
        });
    }
    Ok(out)
}

/// ± a uniform draw from [lo, hi] (a random sign).
fn spin(r: &mut Rng, lo: f64, hi: f64) -> f64 {
    let s = if r.uniform(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
    s * r.uniform(lo, hi)
}

/// Fig. 1: (a) energy error over 100 s, explicit Euler vs the GP-only
/// learned integrator with 10 and 20 samples of one pendulum trajectory from
/// θ = π/2 (maximal coordinates); (b) constraint drift, explicit Euler vs the
/// projected learned integrator (double pendulum, maximal coordinates).
fn figure1(cli: &Cli) -> Result<(Fig1, String), Box<dyn std::error::Error>> {
    let steps = 10_000;
    let every = 10;
    let opts = TrainOptions {
        restarts: cli.protocol.restarts,
        seed: cli.protocol.seed,
        memory: cli.protocol.memory,
        ..TrainOptions::default()
    };
    let series = |label: &str, values: Vec<f64>| Series {
        label: label.into(),
        t: (0..values.len()).map(|k| (k * every) as f64 * DT).collect(),
        y: values,
    };
    let sample = |traj: &[State<3>], f: &dyn Fn(&State<3>) -> f64| {
        traj.iter().step_by(every).map(f).collect::<Vec<_>>()
    };

    let p = Pendulum::default();
    let (pmin, pmax) = (p.minimal(), p.maximal());
    let traj = ground_truth(pmin, &SVector::from([FRAC_PI_2]), cli.protocol.gt())?;
    let tmax: Vec<SVector<f64, 3>> = traj.iter().map(|q| pmin.maximal_positions(q)).collect();
    let data = transitions(&tmax, DT);
    let z0 = data[0].z;
    let e0 = pmax.energy(&z0);
    let de = |z: &State<3>| (pmax.energy(z) - e0).abs();
    let euler = ExplicitEuler::new(pmax, DT).rollout(
        &State {
            q: z0.q,
            v: SVector::zeros(),
        },
        steps,
    )?;
    let mut energy = vec![series("explicit Euler", sample(&euler, &de))];
    let mut notes = String::new();
    for n in [10, 20] {
        let stride = data.len() / n;
        let d: Vec<_> = data.iter().step_by(stride).take(n).copied().collect();
        let (l, _) = Learned::train(pmax, DT, &d, Encoding::Raw, Prior::Constant, &opts)?;
        let traj = l.rollout(&z0, steps)?;
        let s = sample(&traj, &de);
        notes += &format!(
            "- Fig. 1a, learned with {n} samples: max |ΔE| over the first 10 s {:.3e} J, over the last 10 s {:.3e} J (explicit Euler: {:.3e} → {:.3e} J).\n",
            s[..100].iter().cloned().fold(0.0, f64::max),
            s[s.len() - 100..].iter().cloned().fold(0.0, f64::max),
            energy[0].y[..100].iter().cloned().fold(0.0, f64::max),
            energy[0].y[energy[0].y.len() - 100..]
                .iter()
                .cloned()
                .fold(0.0, f64::max),
        );
        energy.push(series(&format!("learned, {n} samples"), s));
    }

    let dp = DoublePendulum::default();
    let (dmin, dmax) = (dp.minimal(), dp.maximal());
    let traj = ground_truth(dmin, &SVector::from([FRAC_PI_2, 0.0]), cli.protocol.gt())?;
    let tmax: Vec<SVector<f64, 6>> = traj.iter().map(|q| dmin.maximal_positions(q)).collect();
    let data = transitions(&tmax, DT);
    let z0 = data[0].z;
    let g = |z: &State<6>| dmax.constraint_violation(z);
    let euler = ExplicitEuler::new(dmax, DT).rollout(
        &State {
            q: z0.q,
            v: SVector::zeros(),
        },
        steps,
    )?;
    let d: Vec<_> = data
        .iter()
        .step_by(data.len() / 20)
        .take(20)
        .copied()
        .collect();
    let (l, _) = Learned::train(dmax, DT, &d, Encoding::Raw, Prior::Constant, &opts)?;
    let learned = l.rollout(&z0, steps)?;
    let pick = |traj: &[State<6>]| traj.iter().step_by(every).map(g).collect::<Vec<_>>();
    let drift = vec![
        series("explicit Euler", pick(&euler)),
        series("learned + projection", pick(&learned)),
    ];
    notes += &format!(
        "- Fig. 1b: explicit Euler's |g| reaches {:.3e} after 100 s; the projected learned integrator's max |g| is {:.3e}.\n",
        drift[0].y.last().copied().unwrap_or(f64::NAN),
        drift[1].y.iter().cloned().fold(0.0, f64::max)
    );
    Ok((Fig1 { energy, drift }, notes))
}

/// The paper's claims, checked on the numbers.
fn findings(points: &[Fig2Point], cli: &Cli) -> String {
    let mut out = String::new();
    let ns = &cli.protocol.n;
    let has = |s: &str| points.iter().any(|p| p.system == s);
    for sys in ["pendulum", "cartpole"].into_iter().filter(|s| has(s)) {
        for method in ["minimal", "sincos", "maximal"] {
            let big: Vec<usize> = ns.iter().copied().filter(|&n| n >= 16).collect();
            let below = big
                .iter()
                .filter(|&&n| med(points, sys, method, n) < med(points, sys, "nominal", n))
                .count();
            out += &format!(
                "- {sys}, learned ({method}) below nominal for N ≥ 16: {below}/{} sample counts ({}).\n",
                big.len(),
                if below == big.len() {
                    "matches the paper"
                } else {
                    "differs from the paper"
                }
            );
        }
    }
    for sys in ["pendulum", "cartpole", "double_pendulum", "fourbar"]
        .into_iter()
        .filter(|s| has(s))
    {
        for method in ["minimal", "sincos", "maximal"] {
            let (first, last) = (ns[0], ns[ns.len() - 1]);
            let (a, b) = (
                med(points, sys, method, first),
                med(points, sys, method, last),
            );
            out += &format!(
                "- {sys}, {method}: median MSE {a:.3e} at N = {first} → {b:.3e} at N = {last} ({}).\n",
                if b < a {
                    "falls with N, as in the paper"
                } else {
                    "does not fall"
                }
            );
        }
    }
    if has("pendulum") {
        let big: Vec<usize> = ns.iter().copied().filter(|&n| n >= 16).collect();
        let better = big
            .iter()
            .filter(|&&n| {
                med(points, "pendulum", "sincos", n) <= med(points, "pendulum", "minimal", n)
            })
            .count();
        out += &format!(
            "- pendulum: sin/cos at least as good as minimal at {better}/{} sample counts N ≥ 16.\n",
            big.len()
        );
    }
    for sys in ["pendulum", "cartpole", "double_pendulum", "fourbar"]
        .into_iter()
        .filter(|s| has(s))
    {
        let ratios: Vec<f64> = ns
            .iter()
            .map(|&n| {
                (med(points, sys, "maximal", n) / med(points, sys, "minimal", n))
                    .log10()
                    .abs()
            })
            .collect();
        let mut r = ratios.clone();
        out += &format!(
            "- {sys}: minimal vs maximal medians differ by a factor 10^{:.2} (median over N; max 10^{:.2}).\n",
            median(&mut r),
            ratios.iter().cloned().fold(0.0, f64::max)
        );
    }
    out
}

/// One finding line per bound kind: its coverage and tightness ranges over
/// the systems and coordinate choices (details in `bounds.md`).
fn bound_findings(rows: &[bounds::BoundRow]) -> String {
    let mut out = String::new();
    for kind in ["conformal", "conformal-latent", "theorem1", "rkhs"] {
        for set in ["held-out", "shifted"] {
            let r: Vec<&bounds::BoundRow> = rows
                .iter()
                .filter(|r| r.kind == kind && r.set == set)
                .collect();
            if r.is_empty() {
                continue;
            }
            let range = |f: &dyn Fn(&bounds::BoundRow) -> f64| {
                let v = r.iter().map(|x| f(x));
                (
                    v.clone().fold(f64::INFINITY, f64::min),
                    v.fold(f64::NEG_INFINITY, f64::max),
                )
            };
            let (c1, c2) = range(&|x| x.one_step_coverage);
            let (t1, t2) = range(&|x| x.one_step_tightness);
            let (k1, k2) = range(&|x| x.k_step_coverage);
            let (u1, u2) = range(&|x| x.k_step_tightness);
            out += &format!(
                "- Error bound {kind} (δ = {}), {set} starts: one-step coverage {c1:.3}–{c2:.3}, tightness {t1:.1}–{t2:.1}; 20-step coverage {k1:.3}–{k2:.3}, tightness {u1:.1}–{u2:.1} (bounds.md).\n",
                bounds::DELTA
            );
        }
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let matches = Args::command().get_matches();
    let args = Args::from_arg_matches(&matches)?;
    match args.command {
        Some(Command::Merge { shards, out }) => merge(&shards, out),
        None => run(args.cli, &matches),
    }
}

/// `merge`: the shards' units, checked, into the report.
fn merge(dirs: &[PathBuf], out: PathBuf) -> Result<(), Box<dyn std::error::Error>> {
    let t0 = Instant::now();
    let files = dirs
        .iter()
        .map(|d| shard::read::<Cli, Output>(d))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())?;
    let (mut cli, outputs) = shard::merge(files, SHARD_FORMAT, units).map_err(|e| e.to_string())?;
    cli.out = out;
    println!(
        "merged {} shards: {} units of systems {:?}, N {:?}, {} runs, seed {}",
        dirs.len(),
        outputs.len(),
        cli.protocol.systems,
        cli.protocol.n,
        cli.protocol.runs,
        cli.protocol.seed
    );
    report(&cli, outputs, t0)
}

/// A run: every unit, or those of `--shard i/N`.
fn run(mut cli: Cli, matches: &ArgMatches) -> Result<(), Box<dyn std::error::Error>> {
    let given = |id: &str| matches.value_source(id) == Some(ValueSource::CommandLine);
    if cli.full {
        cli.protocol.full(given);
    }
    cli.protocol.check()?;
    if let Some(shard) = cli.shard.filter(|_| !given("out")) {
        cli.out = Path::new("target/paper-shards").join(shard.dir_name());
    }
    let whole = cli.shard.unwrap_or(Shard::WHOLE);
    let todo: Vec<Unit> = units(&cli)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| whole.owns(*k))
        .map(|(_, u)| u)
        .collect();
    let t0 = Instant::now();
    println!("vigp paper reproduction: {}", cli.protocol.describe());
    if let Some(shard) = cli.shard {
        println!(
            "shard {shard}: {} of {} units",
            todo.len(),
            units(&cli).len()
        );
    }
    let mut outputs = Vec::new();

    if todo.contains(&Unit::Fig1) {
        let spinner = ProgressBar::new_spinner()
            .with_message("Fig. 1: energy and constraint drift (10^4 steps each)");
        spinner.enable_steady_tick(std::time::Duration::from_millis(200));
        let (fig1, notes) = figure1(&cli)?;
        spinner.finish_with_message(format!("Fig. 1 done ({:.0} s)", t0.elapsed().as_secs_f64()));
        outputs.push(Output::Fig1 { fig1, notes });
    }

    let runs = todo.iter().filter(|u| matches!(u, Unit::Run(..))).count();
    let total = (runs * cli.protocol.n.len()) as u64;
    let bar = ProgressBar::new(total).with_style(ProgressStyle::with_template(
        "Fig. 2 {bar:40} {pos}/{len} (system, run, N) {msg} [{elapsed_precise}, eta {eta}]",
    )?);
    let angle = |rng: &mut Rng| rng.uniform(-PI, PI);
    for system in &cli.protocol.systems {
        bar.set_message(system.clone());
        outputs.extend(match system.as_str() {
            // shifted starts (error bounds): more energy than any training
            // start, which is at rest
            "pendulum" => run_system(
                &SystemSpec {
                    name: "pendulum",
                    prior: Prior::Nominal,
                    perturb: perturb_pendulum,
                    minimal: Pendulum::minimal,
                    maximal: Pendulum::maximal,
                },
                &pendulum_start,
                &|r| {
                    (
                        SVector::from([angle(r)]),
                        SVector::from([spin(r, 8.0, 10.0)]),
                    )
                },
                &cli,
                &todo,
                &bar,
            )?,
            "cartpole" => run_system(
                &SystemSpec {
                    name: "cartpole",
                    prior: Prior::Nominal,
                    perturb: perturb_cartpole,
                    minimal: Cartpole::minimal,
                    maximal: Cartpole::maximal,
                },
                &cartpole_start,
                &|r| {
                    (
                        SVector::from([r.uniform(-1.0, 1.0), angle(r)]),
                        SVector::from([0.0, spin(r, 8.0, 10.0)]),
                    )
                },
                &cli,
                &todo,
                &bar,
            )?,
            "double_pendulum" => run_system(
                &SystemSpec {
                    name: "double_pendulum",
                    prior: Prior::Constant,
                    perturb: perturb_double_pendulum,
                    minimal: DoublePendulum::minimal,
                    maximal: DoublePendulum::maximal,
                },
                &double_pendulum_start,
                &|r| {
                    (
                        SVector::from([angle(r), angle(r)]),
                        SVector::from([spin(r, 5.0, 7.0), spin(r, 5.0, 7.0)]),
                    )
                },
                &cli,
                &todo,
                &bar,
            )?,
            "fourbar" => run_system(
                &SystemSpec {
                    name: "fourbar",
                    prior: Prior::Constant,
                    perturb: perturb_fourbar,
                    minimal: Fourbar::minimal,
                    maximal: Fourbar::maximal,
                },
                &fourbar_start,
                &|r| {
                    let (t1, t3) = (
                        r.uniform(-FRAC_PI_2, FRAC_PI_2),
                        r.uniform(-FRAC_PI_2, FRAC_PI_2),
                    );
                    let (w1, w3) = (spin(r, 3.0, 5.0), spin(r, 3.0, 5.0));
                    (
                        SVector::from([t1, t3 - t1, t3, t1 - t3]),
                        SVector::from([w1, w3 - w1, w3, w1 - w3]),
                    )
                },
                &cli,
                &todo,
                &bar,
            )?,
            other => {
                return Err(format!(
                    "unknown system `{other}` (pendulum, cartpole, double_pendulum, fourbar)"
                )
                .into());
            }
        });
    }
    bar.finish();
    match cli.shard {
        Some(shard) => {
            let path = shard::write(&cli.out, SHARD_FORMAT, shard, &cli, &outputs)
                .map_err(|e| e.to_string())?;
            println!(
                "shard {shard}: wrote {} units to {} in {:.0} s",
                outputs.len(),
                path.display(),
                t0.elapsed().as_secs_f64()
            );
            Ok(())
        }
        None => {
            // the unsharded run is the one shard 0/1, checked as `merge`
            // checks shards
            let this = ShardFile {
                format: SHARD_FORMAT.into(),
                shard: Shard::WHOLE,
                options: cli.clone(),
                units: outputs,
            };
            let (_, outputs) = shard::merge(vec![("this run".into(), this)], SHARD_FORMAT, units)
                .map_err(|e| e.to_string())?;
            report(&cli, outputs, t0)
        }
    }
}

/// Writes the report (figures, CSV files, `report.md`, `bounds.*`) of
/// every unit's output, in the sweep's order (as `shard::merge` returns
/// them).
fn report(cli: &Cli, outputs: Vec<Output>, t0: Instant) -> Result<(), Box<dyn std::error::Error>> {
    let mut fig1 = Fig1::default();
    let mut notes1 = String::new();
    let mut points = Vec::new();
    let mut gt_err = BTreeMap::new();
    let (mut failed, mut windows) = (0, 0);
    let mut bound_out = (Vec::new(), Vec::new());
    for output in outputs {
        match output {
            Output::Fig1 { fig1: f, notes } => (fig1, notes1) = (f, notes),
            Output::Bounds { rows, tubes, .. } => {
                bound_out.0.extend(rows);
                bound_out.1.extend(tubes);
            }
            Output::Run(r) => {
                points.extend(r.points);
                if let Some(e) = r.gt_err {
                    gt_err.insert(r.system, e);
                }
                failed += r.failed;
                windows += r.windows;
            }
        }
    }
    let mut gt_notes = String::new();
    for system in &cli.protocol.systems {
        let err = gt_err.get(system).copied().unwrap_or((0.0, 0.0));
        gt_notes += &format!("| {system} | {:.2e} | {:.2e} |\n", err.0, err.1);
    }

    let settings = format!(
        "| setting | value |\n|---|---|\n| systems | {} |\n| training samples N | {:?} (nested: the first N of one draw per run) |\n| runs per system | {} |\n| trajectories (train + test) | {} + {} (2 s each, random configurations at rest) |\n| 20-step windows per test trajectory | {} |\n| model Δt | 10 ms |\n| ground truth | {}, Δt = {:e} s |\n| observation noise | σ = 1e-3 on training q, v and targets |\n| perturbations | masses, inertias ×U[0.9, 1.1]; damping as in the paper |\n| GP | ARD SE per velocity component, {} |\n| priors | pendulum, cartpole: nominal VI step; double pendulum, fourbar: constant mean |\n\nGround-truth accuracy over one 2 s trajectory of the first run (max position difference against the same integrator at Δt/2, and against the paper's reference, the midpoint VI at 0.1 ms, whose own error is ≈ 4/3 of its difference to 0.05 ms):\n\n| system | max \\|q(Δt) − q(Δt/2)\\| | max \\|q − q_midpoint(0.1 ms)\\| |\n|---|---|---|\n{}",
        cli.protocol.systems.join(", "),
        cli.protocol.n,
        cli.protocol.runs,
        cli.protocol.train_trajectories,
        cli.protocol.test_trajectories,
        cli.protocol.windows,
        cli.protocol.gt_method.describe(),
        cli.protocol.gt().dt,
        if cli.warm {
            format!(
                "{} extra restarts at the first N, then warm starts from the previous N's optimum with {} extra restarts, L-BFGS memory {}, seed {}",
                cli.protocol.restarts, cli.warm_restarts, cli.protocol.memory, cli.protocol.seed
            )
        } else {
            format!(
                "{} extra restarts, L-BFGS memory {}, seed {}; {}",
                cli.protocol.restarts,
                cli.protocol.memory,
                cli.protocol.seed,
                cli.describe_screening()
            )
        },
        gt_notes
    );
    let findings = format!(
        "{notes1}{}- prediction windows that failed (a projection or nominal step that did not converge): {} of {}; their runs average the remaining windows.\n",
        findings(&points, cli),
        failed,
        windows
    );
    let mut findings = findings;
    let mut files = Vec::new();
    if !cli.no_bounds {
        let (rows, tubes) = &bound_out;
        let tube = tubes
            .iter()
            .find(|t| t.system == "double_pendulum" && t.coords == "minimal")
            .or(tubes.first());
        files.extend(bounds::write(&cli.out, rows, tube, cli)?);
        findings += &bound_findings(rows);
    }
    files.extend(output::write_all(
        &cli.out, &settings, &fig1, &points, &findings,
    )?);
    println!("\n{findings}");
    println!(
        "wrote {} files to {} in {:.0} s",
        files.len(),
        cli.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
