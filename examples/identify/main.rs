//! The paper's protocol (Brüdigam et al., L4DC 2022, §4; the `paper`
//! example) with an identified prior: per perturbed system and training
//! size N, the 20-step error of
//!
//! * **nominal + GP**, the paper's model: the GP learns what the nominal
//!   variational step leaves (`Prior::Nominal` on the declared parameters);
//! * **identified**: the variational step of the mechanism whose parameters
//!   `vigp::identify` estimated from the same N transitions, no GP;
//! * **identified + GP**: the GP on what the identified step leaves (the
//!   identified mechanism, `model_with`, trained with `Prior::Nominal`);
//!
//! beside the nominal step alone and the step with the true parameters (the
//! floor of any parameter estimate: what remains is the 10 ms first-order
//! step's discretisation error).
//!
//! ```text
//! cargo run --release --example identify              # 4 runs, N = 2 … 512: ~2 min on 2 cores
//! cargo run --release --example identify -- --full    # the paper's settings
//! cargo run --release --example identify -- --help
//! ```
//!
//! **The same N transitions.** A training sample of the paper is a noisy
//! (q_k, v_k, v_{k+1}) with v_k = (q_{k+1} − q_k)/Δt, each entry with its
//! own noise σ = 1e-3. The identification gets exactly these numbers: each
//! sample is one DEL transition on the three positions it implies,
//! (q_k, q_k + Δt·v_k, q_k + Δt·(v_k + v_{k+1})), a log of three samples.
//! Nothing else of the trajectories is used, so the identification cannot
//! smooth over neighbouring samples (instrumental variables need ±8): it is
//! least squares on the first-order DEL residual, the rule of the
//! variational step that both models predict with (`Variational::new`).
//! Position noise in these positions is 1e-3 common to all three (it moves
//! the configuration, not the second difference) and 1e-5 on the
//! differences (Δt·σ of the velocities). On a mechanism with loops (the
//! fourbar) the three positions are projected onto the loop constraints
//! first: the noise moves them off the loop, where the rows see
//! combinations that positions on the loop never show.
//!
//! **The scale.** The paper's systems move freely (no inputs): the DEL
//! residual is homogeneous in π, so the data fix π only up to a common
//! factor, and every factor predicts the same motion. The factor comes
//! from the prior: one combination of π is held at its declared value
//! (`scale.rs`).
//!
//! **Repeated samples.** The draw is with replacement (the `paper`
//! example's), so a large N holds some samples twice; both GPs train on a
//! repeated transition once (`vigp::learned::distinct_rows`), the
//! identification weights its row twice.
//!
//! **Too few transitions.** `identify` estimates the rows' noise from their
//! residuals and refuses fewer rows than base parameters plus one
//! transition; there the identified model is the declared one (the prior
//! alone), and the table says so.

#[path = "../common/figure.rs"]
mod figure;
#[path = "../common/font.rs"]
mod font;
#[path = "../common/median.rs"]
mod median;
// The paper's report writer; this example writes its Fig. 2 part only.
#[allow(dead_code)]
#[path = "../paper/output.rs"]
mod output;
#[path = "../common/protocol.rs"]
mod protocol;
#[path = "../../tests/common/rng.rs"]
mod rng;
mod scale;
#[path = "../common/shard.rs"]
mod shard;
#[path = "../common/windows.rs"]
mod windows;

use clap::parser::ValueSource;
use clap::{CommandFactory, FromArgMatches, Parser};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{DVector, SVector};
use output::{Fig2Point, med};
use protocol::{
    Counts, DT, HORIZON, NOISE, Protocol, add_noise, cartpole_start, double_pendulum_start,
    fourbar_start, ground_truth, mean_mse, pendulum_start, perturb_cartpole,
    perturb_double_pendulum, perturb_fourbar, perturb_pendulum,
};
use rayon::prelude::*;
use rng::Rng;
use scale::ScaleFixed;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Instant;
use vigp::Parameters;
use vigp::gp::{Screening, TrainOptions};
use vigp::identify::{
    DelRegressor, IdentifyError, Intervals, Log, Noise, Options, SampleNoise, identify,
};
use vigp::learned::{Encoding, Learned, Prior, Transition, transitions};
use vigp::prelude::*;
use vigp::projection::{consistent_state, project_configuration};
use vigp::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};

/// The command line.
#[derive(Parser, Debug, Clone)]
#[command(about = "The paper's protocol with an identified prior (Fig. 2 axis, three models)")]
struct Cli {
    /// The protocol's settings (defaults here: 4 runs, N from 2 to 512).
    #[command(flatten)]
    protocol: Protocol,
    /// Relative standard deviation of the identification's prior on the
    /// declared parameters (`vigp::identify::Prior::relative`).
    #[arg(long, default_value_t = 0.5)]
    prior_sd: f64,
    /// Diagnostic: the identification gets the N training samples without
    /// their noise (the GPs still train on the noisy ones), which separates
    /// what the noise does to the identification from the rest.
    #[arg(long)]
    noise_free_identification: bool,
    /// Diagnostic: leave out of both GPs' training (not of the
    /// identification) the samples whose velocity the projection onto the
    /// loop constraints moves by more than this (rad/s): noisy samples
    /// near a pose where the constraint Jacobian loses rank, where the
    /// projection magnifies the noise. Mechanisms without loops keep every
    /// sample.
    #[arg(long)]
    drop_projected: Option<f64>,
    /// Refine the regression by output error (`Options::output_error`),
    /// each training sample a segment of its three positions whose first
    /// two are estimated with the parameters.
    #[arg(long)]
    output_error: bool,
    /// Treat the samples' noise as known (σ on q, v and v_next) by
    /// bias-compensated least squares (`Noise::ErrorsInVariables`) instead
    /// of least squares.
    #[arg(long)]
    errors_in_variables: bool,
    /// Output directory (figures, CSV, report.md).
    #[arg(long, default_value = "docs/identify")]
    out: PathBuf,
    /// The paper's settings: 100 runs, 200/100 trajectories, 10 restarts,
    /// N from 2 to 512 (each unless given explicitly).
    #[arg(long)]
    full: bool,
}

/// The methods, as named in the CSV files and the figures' legends.
const NOMINAL: &str = "nominal";
const TRUE_PI: &str = "true parameters";
const NOMINAL_GP: &str = "nominal + GP";
const IDENTIFIED: &str = "identified";
const IDENTIFIED_GP: &str = "identified + GP";

/// How the identification of one (run, N) went.
#[derive(Clone, Debug)]
enum IdStatus {
    /// Identified: the number of base parameters, and whether h(π̂) was
    /// unrealisable and π̂ is the model (`scale.rs`).
    Identified(usize, bool),
    /// Too few rows for `identify`: the declared parameters (the prior).
    Prior,
    /// Failed otherwise; the identified models are NaN (the message is
    /// printed).
    Failed,
}

/// One run's points and the identification status per N.
struct RunOutput {
    points: Vec<Fig2Point>,
    status: Vec<(usize, IdStatus)>,
    failed: usize,
    windows: usize,
}

/// What one system contributes.
struct System<S, M, const N: usize> {
    name: &'static str,
    perturb: fn(&mut S, &mut Rng),
    start: fn(&mut Rng) -> SVector<f64, N>,
    minimal: fn(&S) -> M,
}

/// The log of one training sample: the three positions it implies
/// (module docs), each projected onto the loop constraints of `model` if
/// it has any.
fn log_of<M: Mechanism<N, C>, const N: usize, const C: usize>(
    model: &M,
    t: &Transition<N>,
) -> Result<Log, StepError> {
    let x1 = t.z.q + DT * t.z.v;
    let x2 = x1 + DT * t.v_next;
    let project = |x: SVector<f64, N>| -> Result<Vec<f64>, StepError> {
        let x = if C > 0 {
            project_configuration(model, &x, &StepOptions::default())?.0
        } else {
            x
        };
        Ok(x.as_slice().to_vec())
    };
    Ok(Log::new(vec![project(t.z.q)?, project(x1)?, project(x2)?]))
}

/// The identification's prior: `relative` × the declared values.
fn id_prior(relative: f64) -> vigp::identify::Prior {
    vigp::identify::Prior {
        relative,
        ..Default::default()
    }
}

/// The mechanism identified from `data` (module docs), or the declared one
/// where the data are too few.
fn identified<M, const N: usize, const C: usize>(
    regressor: &DelRegressor<M, N, C>,
    data: &[Transition<N>],
    direction: &DVector<f64>,
    prior_sd: f64,
    output_error: bool,
    errors_in_variables: bool,
) -> Result<(M, IdStatus), IdentifyError>
where
    M: Mechanism<N, C> + Parameters + Copy,
{
    let logs = data
        .iter()
        .map(|t| log_of(regressor.model(), t))
        .collect::<Result<Vec<Log>, StepError>>()
        .map_err(|e| IdentifyError::Simulation {
            message: format!("projecting a sample onto the loop constraints: {e}"),
        })?;
    let options = Options {
        prior: id_prior(prior_sd),
        // the intervals are not used here
        intervals: Intervals::Independent,
        output_error: output_error.then_some(vigp::identify::OutputError {
            segment: 3,
            ..Default::default()
        }),
        noise: if errors_in_variables {
            Noise::ErrorsInVariables(SampleNoise::from_states(NOISE, NOISE, DT))
        } else {
            Options::default().noise
        },
        ..Options::default()
    };
    let scaled = ScaleFixed::new(regressor, direction.clone(), &options.prior);
    match identify(&scaled, &logs, &options) {
        Ok(id) => {
            // h(π̂) is π̂ unless the consistency projection moved π̂ along
            // the held direction; moved back, a body can lose its
            // realisability, and then π̂ itself (consistent) is the model
            let held = regressor.model_with(&scaled.hold(&id.estimate))?;
            if vigp::embedded::Dynamics::constants(&held).is_ok() {
                Ok((held, IdStatus::Identified(id.base.rank(), false)))
            } else {
                Ok((
                    regressor.model_with(&id.estimate)?,
                    IdStatus::Identified(id.base.rank(), true),
                ))
            }
        }
        Err(IdentifyError::TooFewTransitions { .. }) => Ok((*regressor.model(), IdStatus::Prior)),
        Err(e) => Err(e),
    }
}

/// The samples whose velocity the projection onto `m`'s constraints
/// (`consistent_state`, at the sample's own configuration) moves by at most
/// `limit` (a sample the projection fails on is left out too), and the
/// largest such move.
fn kept_by_projection<M: Mechanism<N, C>, const N: usize, const C: usize>(
    m: &M,
    data: &[Transition<N>],
    limit: f64,
) -> (Vec<Transition<N>>, f64) {
    let mut largest = 0.0f64;
    let kept = data
        .iter()
        .filter(|t| match consistent_state(m, &t.z.q, &t.z.v, DT) {
            Ok(z) => {
                let moved = (z.v - t.z.v).norm();
                largest = largest.max(moved);
                moved <= limit
            }
            Err(_) => false,
        })
        .copied()
        .collect();
    (kept, largest)
}

/// The runs `runs` of one system.
fn evaluate<S, M, const N: usize, const C: usize>(
    sys: &System<S, M, N>,
    cli: &Cli,
    progress: &ProgressBar,
) -> Result<Vec<RunOutput>, Box<dyn std::error::Error + Send + Sync>>
where
    S: Default + Sync,
    M: Mechanism<N, C> + Parameters + Copy + Send + Sync,
{
    let one_run = |run: usize| -> Result<RunOutput, Box<dyn std::error::Error + Send + Sync>> {
        // the `paper` example's seed of this system's run
        let mut rng = Rng(cli.protocol.seed
            ^ (run as u64 + 1).wrapping_mul(0x2545_F491_4F6C_DD1D)
            ^ sys.name.len() as u64);
        let mut t = S::default();
        (sys.perturb)(&mut t, &mut rng);
        let (truth, nominal) = ((sys.minimal)(&t), (sys.minimal)(&S::default()));
        let starts: Vec<SVector<f64, N>> = (0..cli.protocol.train_trajectories
            + cli.protocol.test_trajectories)
            .map(|_| (sys.start)(&mut rng))
            .collect();
        let trajs: Vec<Vec<SVector<f64, N>>> = starts
            .par_iter()
            .map(|q0| ground_truth(truth, q0, cli.protocol.gt()))
            .collect::<Result<_, _>>()?;
        let (train, test) = trajs.split_at(cli.protocol.train_trajectories);
        let clean: Vec<Transition<N>> = train
            .iter()
            .flat_map(|traj| transitions(traj, DT))
            .collect();
        let pool: Vec<Transition<N>> = clean.iter().map(|a| add_noise(a, &mut rng)).collect();
        let windows = cli.protocol.test_windows(test, &mut rng);
        let counts = Counts::default();
        let vi_mse = |m: M| {
            // a model the integrator refuses fails every window, as a
            // failed rollout does
            let vi = Variational::new(m, DT);
            mean_mse(&windows, &counts, |z| {
                let vi = vi.as_ref().map_err(|e| *e)?;
                Ok(vi.rollout(z, HORIZON)?.into_iter().map(|z| z.q).collect())
            })
        };
        let gp_mse = |m: M, data: &[Transition<N>], n: usize, what: &str| {
            let options = TrainOptions {
                restarts: cli.protocol.restarts,
                seed: cli.protocol.seed ^ n as u64,
                screening: Screening::Auto,
                memory: cli.protocol.memory,
                ..TrainOptions::default()
            };
            match Learned::train(m, DT, data, Encoding::Raw, Prior::Nominal, &options) {
                Ok((l, _)) => mean_mse(&windows, &counts, |z| {
                    Ok(l.rollout(z, HORIZON)?.into_iter().map(|z| z.q).collect())
                }),
                Err(e) => {
                    eprintln!("{} run {run} N {n} {what}: training failed: {e}", sys.name);
                    f64::NAN
                }
            }
        };
        let (nominal_mse, true_mse) = (vi_mse(nominal), vi_mse(truth));
        let regressor = DelRegressor::first_order(nominal, DT)?;
        // the parameter that fixes the scale (scale.rs), from arbitrary
        // position triples of the declared mechanism: random starts and
        // velocities in [−1, 1], on their own seed
        let mut triples_rng = Rng(cli.protocol.seed ^ 0x5CA1_E5CA_1E5C_A1E5);
        let triples = (0..64)
            .map(|_| {
                let q = (sys.start)(&mut triples_rng);
                let mut v = || SVector::from_fn(|_, _| triples_rng.uniform(-1.0, 1.0));
                let (v, v_next) = (v(), v());
                log_of(
                    &nominal,
                    &Transition {
                        z: State { q, v },
                        v_next,
                    },
                )
            })
            .collect::<Result<Vec<Log>, StepError>>()?;
        let direction = scale::scale_direction(&regressor, &triples, &id_prior(cli.prior_sd))?;
        // nested training sets: each N's samples are the first N of one draw
        let draw = cli.protocol.draw(pool.len(), &mut rng);
        let mut points = Vec::new();
        let mut status = Vec::new();
        for &n in &cli.protocol.n {
            let data: Vec<Transition<N>> =
                draw[..n.min(pool.len())].iter().map(|&i| pool[i]).collect();
            let mut point = |method: &str, mse: f64| {
                points.push(Fig2Point {
                    system: sys.name.into(),
                    method: method.into(),
                    n,
                    run,
                    mse,
                })
            };
            point(NOMINAL, nominal_mse);
            point(TRUE_PI, true_mse);
            let gp_data = match cli.drop_projected {
                Some(limit) if C > 0 => {
                    let (kept, largest) = kept_by_projection(&nominal, &data, limit);
                    eprintln!(
                        "{} run {run} N {n}: {} of {} samples left out of the GPs \
                         (--drop-projected); the largest velocity change by the \
                         projection {largest:.2e}",
                        sys.name,
                        data.len() - kept.len(),
                        data.len()
                    );
                    kept
                }
                _ => data.clone(),
            };
            point(NOMINAL_GP, gp_mse(nominal, &gp_data, n, NOMINAL_GP));
            let id_data: Vec<Transition<N>> = if cli.noise_free_identification {
                draw[..n.min(pool.len())]
                    .iter()
                    .map(|&i| clean[i])
                    .collect()
            } else {
                data.clone()
            };
            match identified(
                &regressor,
                &id_data,
                &direction,
                cli.prior_sd,
                cli.output_error,
                cli.errors_in_variables,
            ) {
                Ok((model, s)) => {
                    point(IDENTIFIED, vi_mse(model));
                    point(IDENTIFIED_GP, gp_mse(model, &gp_data, n, IDENTIFIED_GP));
                    status.push((n, s));
                }
                Err(e) => {
                    eprintln!("{} run {run} N {n}: identification failed: {e}", sys.name);
                    point(IDENTIFIED, f64::NAN);
                    point(IDENTIFIED_GP, f64::NAN);
                    status.push((n, IdStatus::Failed));
                }
            }
            progress.inc(1);
        }
        Ok(RunOutput {
            points,
            status,
            failed: counts.failed.load(Ordering::Relaxed),
            windows: counts.windows.load(Ordering::Relaxed),
        })
    };
    (0..cli.protocol.runs)
        .into_par_iter()
        .map(one_run)
        .collect()
}

/// Runs of a (system, N) where `a`'s error is at most `b`'s, and runs
/// where both are finite.
fn at_most(points: &[Fig2Point], system: &str, a: &str, b: &str, n: usize) -> (usize, usize) {
    let get = |m: &str, run: usize| {
        points
            .iter()
            .find(|p| p.system == system && p.method == m && p.n == n && p.run == run)
            .map_or(f64::NAN, |p| p.mse)
    };
    let runs: Vec<usize> = points
        .iter()
        .filter(|p| p.system == system && p.method == a && p.n == n)
        .map(|p| p.run)
        .collect();
    let pairs: Vec<(f64, f64)> = runs
        .iter()
        .map(|&r| (get(a, r), get(b, r)))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    (pairs.iter().filter(|(x, y)| x <= y).count(), pairs.len())
}

/// The table of one system (Markdown): medians over runs, the ratios, the
/// runs where identified + GP is no worse than nominal + GP, and how the
/// identification went.
fn table(points: &[Fig2Point], status: &[(usize, IdStatus)], system: &str, ns: &[usize]) -> String {
    let mut out = format!(
        "\n### {}\n\n| N | nominal | true π | nominal + GP | identified | identified + GP | nominal / identified | (nominal + GP) / (identified + GP) | runs identified + GP ≤ nominal + GP | identification |\n|---|---|---|---|---|---|---|---|---|---|\n",
        system.replace('_', " ")
    );
    for &n in ns {
        let m = |method| med(points, system, method, n);
        let (le, of) = at_most(points, system, IDENTIFIED_GP, NOMINAL_GP, n);
        let here: Vec<&IdStatus> = status
            .iter()
            .filter(|(k, _)| *k == n)
            .map(|(_, s)| s)
            .collect();
        let prior = here.iter().filter(|s| matches!(s, IdStatus::Prior)).count();
        let failed = here
            .iter()
            .filter(|s| matches!(s, IdStatus::Failed))
            .count();
        let ranks: Vec<usize> = here
            .iter()
            .filter_map(|s| match s {
                IdStatus::Identified(r, _) => Some(*r),
                _ => None,
            })
            .collect();
        let unheld = here
            .iter()
            .filter(|s| matches!(s, IdStatus::Identified(_, true)))
            .count();
        let mut how = Vec::new();
        if let (Some(lo), Some(hi)) = (ranks.iter().min(), ranks.iter().max()) {
            how.push(if lo == hi {
                format!("{} runs, {lo} base parameters", ranks.len())
            } else {
                format!("{} runs, {lo}–{hi} base parameters", ranks.len())
            });
        }
        if unheld > 0 {
            how.push(format!("{unheld} runs h(π̂) unrealisable: π̂"));
        }
        if prior > 0 {
            how.push(format!("{prior} runs too few rows: declared"));
        }
        if failed > 0 {
            how.push(format!("{failed} runs failed"));
        }
        let _ = writeln!(
            out,
            "| {n} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.1} | {:.2} | {le}/{of} | {} |",
            m(NOMINAL),
            m(TRUE_PI),
            m(NOMINAL_GP),
            m(IDENTIFIED),
            m(IDENTIFIED_GP),
            m(NOMINAL) / m(IDENTIFIED),
            m(NOMINAL_GP) / m(IDENTIFIED_GP),
            how.join("; ")
        );
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let matches = Cli::command()
        .mut_arg("runs", |a| a.default_value("4"))
        .mut_arg("n", |a| a.default_value("2,4,8,16,32,64,128,256,512"))
        .get_matches();
    let mut cli = Cli::from_arg_matches(&matches)?;
    let given = |id: &str| matches.value_source(id) == Some(ValueSource::CommandLine);
    if cli.full {
        cli.protocol.full(given);
    }
    cli.protocol.check()?;
    if !(cli.prior_sd > 0.0 && cli.prior_sd.is_finite()) {
        return Err("--prior-sd must be positive and finite".into());
    }
    if cli
        .drop_projected
        .is_some_and(|l| !(l >= 0.0 && l.is_finite()))
    {
        return Err("--drop-projected must be non-negative and finite".into());
    }
    let t0 = Instant::now();
    let settings = format!(
        "{}, identification prior {} × declared{}{}",
        cli.protocol.describe(),
        cli.prior_sd,
        if cli.noise_free_identification {
            ", identification on the samples without their noise (diagnostic)"
        } else {
            ""
        },
        match cli.drop_projected {
            Some(limit) => format!(
                ", GPs without the samples the loop projection moves by more than {limit} \
                 (diagnostic)"
            ),
            None => String::new(),
        }
    );
    println!("vigp identify example: {settings}");
    let bar = ProgressBar::new(
        (cli.protocol.systems.len() * cli.protocol.runs * cli.protocol.n.len()) as u64,
    )
    .with_style(ProgressStyle::with_template(
        "{bar:40} {pos}/{len} (system, run, N) {msg} [{elapsed_precise}, eta {eta}]",
    )?);
    let mut runs = Vec::new();
    for system in &cli.protocol.systems {
        bar.set_message(system.clone());
        let out = match system.as_str() {
            "pendulum" => evaluate(
                &System {
                    name: "pendulum",
                    perturb: perturb_pendulum,
                    start: pendulum_start,
                    minimal: Pendulum::minimal,
                },
                &cli,
                &bar,
            )?,
            "cartpole" => evaluate(
                &System {
                    name: "cartpole",
                    perturb: perturb_cartpole,
                    start: cartpole_start,
                    minimal: Cartpole::minimal,
                },
                &cli,
                &bar,
            )?,
            "double_pendulum" => evaluate(
                &System {
                    name: "double_pendulum",
                    perturb: perturb_double_pendulum,
                    start: double_pendulum_start,
                    minimal: DoublePendulum::minimal,
                },
                &cli,
                &bar,
            )?,
            _ => evaluate(
                &System {
                    name: "fourbar",
                    perturb: perturb_fourbar,
                    start: fourbar_start,
                    minimal: Fourbar::minimal,
                },
                &cli,
                &bar,
            )?,
        };
        runs.push((system.clone(), out));
    }
    bar.finish();
    let mut points = Vec::new();
    let mut tables = String::new();
    let (mut failed, mut windows) = (0, 0);
    for (system, out) in runs {
        let status: Vec<(usize, IdStatus)> = out.iter().flat_map(|r| r.status.clone()).collect();
        let p: Vec<Fig2Point> = out.iter().flat_map(|r| r.points.clone()).collect();
        failed += out.iter().map(|r| r.failed).sum::<usize>();
        windows += out.iter().map(|r| r.windows).sum::<usize>();
        tables += &table(&p, &status, &system, &cli.protocol.n);
        points.extend(p);
    }
    let report = format!(
        "# The paper's protocol with an identified prior\n\n`cargo run --release --example identify{}`: {settings}.\n\nMedians over runs of the 20-step position MSE (minimal coordinates; GP on raw minimal coordinates). Ratios are of the medians; the runs column compares run by run.\n{tables}\nPrediction windows that failed (a step that did not converge): {failed} of {windows}.\n",
        if cli.full { " -- --full" } else { "" }
    );
    let (files, _) = output::write_fig2(&cli.out, &points).map_err(|e| e.to_string())?;
    let path = cli.out.join("report.md");
    std::fs::write(&path, &report)?;
    println!("\n{report}");
    println!(
        "wrote {} files to {} in {:.0} s",
        files.len() + 1,
        cli.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
