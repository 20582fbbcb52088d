//! The `vigp` command-line tool, for the paper's systems and for your own
//! planar mechanism (feature `cli`; 3-D mechanisms are learned in Rust with
//! `vigp::spatial::learned::LearnedSpatial`).
//!
//! ```text
//! vigp fit     --system NAME --data train.csv --out model.json
//!              [--encoding sincos|minimal|maximal] [--prior nominal|constant] [--restarts K]
//!              [--max-samples N] [--no-screen | --sparse M [--optimise-inducing]]
//!              [--noise-floor VAR] [--memory K]
//! vigp score   --model model.json --data test.csv --steps 20
//! vigp predict --model model.json --data starts.csv --steps K --out pred.csv
//! vigp export  --model model.json --out model.rs [--variance]
//! ```
//!
//! * `fit` reads measured positions ([`crate::data`] format), builds the
//!   transitions, trains a [`Learned`] model on at most `--max-samples`
//!   of them (evenly spaced; default 512, as exact GP training is O(N³);
//!   `--sparse M` trains the sparse variational GP with M inducing points
//!   on all of them, O(N·M²); `--optimise-inducing` also moves its
//!   inducing points; from 512 transitions the exact GP's starts are
//!   screened on a subset first, `--no-screen` runs them all on every
//!   transition) with the mechanism's
//!   DSL parameters as nominal prior (change them with
//!   `--set links.pole.mass=1.1`), and saves it as one JSON file.
//!   `--encoding minimal` learns on the minimal coordinates as they are,
//!   `sincos` replaces every angle by its sine and cosine, `maximal` learns
//!   in maximal coordinates (each link's x, y, θ; projected onto the joint
//!   constraints).
//! * `score` is the paper's k-step prediction error: from every sample of
//!   every run with k more samples after it, k steps of the learned model
//!   and of the nominal variational integrator, position MSE in minimal
//!   coordinates averaged over the steps and the windows. Its last line is
//!   `nominal_mse=<x> learned_mse=<y>`.
//! * `predict` rolls the learned model out from the first two rows of every
//!   run (position and discrete velocity) and writes the trajectories with
//!   each predicted velocity's one-step error bound and each position's
//!   bound along the prediction (`--bound conformal|rkhs|theorem1`;
//!   conformal with `--calibration`, RKHS without; δ = `--delta`).
//! * `export` writes the Rust source of a `no_std` learned model for
//!   [`crate::embedded::LearnedStepper`] and states its size.
//!
//! An actuated mechanism's data carry one `u_<joint>` column per input
//! ([`crate::data`]): `fit` learns on state and input (the GP's inputs are
//! the encoded state, then the previous and the current input; the prior is
//! the forced nominal step),
//! `score` rolls both models out under the logged inputs, `export` writes
//! a model that steps under u, and `predict` predicts under the inputs
//! logged in each run (the run needs `--steps` + 1 rows; the input in row
//! k + 1 drives the step from row k, after row k's, as in the data) with
//! the bound of
//! [`crate::learned::Learned::predict_forced`] (conformal: the held-out
//! runs of `--calibration` carry their inputs too).
//!
//! Your own mechanism gets the same tool from one line:
//!
//! ```no_run
//! vigp::mechanism! {
//!     /// My robot.
//!     pub Arm {
//!         links { upper: { mass: 1.0, length: 0.5 } }
//!         joints { shoulder: revolute(world, upper.start) { damping: 0.1 } }
//!     }
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     vigp::cli::main::<Arm>()
//! }
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::bound::{BoundError, BoundKind, Calibration};
use crate::data::{DataError, Dataset, ReadOptions};
use crate::gp::{GpError, Method, Screening, SparseOptions, TrainOptions, TrainReport};
use crate::learned::{
    EmbeddedExport, Encoding, ForcedTransition, LearnError, Learned, LoadError, Prior,
    SavedLearned, Transition, forced_transitions, transitions,
};
use crate::{
    Coordinates, Integrator, Mechanism, Parameters, SVector, State, StepError, System, Variational,
    ViewVisitor,
};

/// Everything that can stop a command.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CliError {
    /// Bad command-line arguments (clap's message, or help and version
    /// output, which [`main_with`] prints and exits 0 on).
    #[error("{0}")]
    Args(#[from] clap::Error),
    /// Arguments that parse but do not make sense.
    #[error("{0}")]
    Usage(String),
    /// A data file could not be read.
    #[error("{}", with_path(path, source, matches!(**source, DataError::Io { .. })))]
    Data {
        /// The file.
        path: PathBuf,
        /// Why (boxed: the data errors carry run names and values, and
        /// every command returns this type).
        source: Box<DataError>,
    },
    /// A model file could not be loaded or saved.
    #[error("{}", with_path(path, source, matches!(source, LoadError::Io { .. })))]
    Model {
        /// The file.
        path: PathBuf,
        /// Why.
        source: LoadError,
    },
    /// Training failed.
    #[error("training failed: {0}")]
    Learn(#[from] LearnError),
    /// A prediction failed.
    #[error("prediction failed: {0}")]
    Step(#[from] StepError),
    /// The error bound could not be made or attached.
    #[error("error bound: {0}")]
    Bound(#[from] BoundError),
    /// The GP could not be exported.
    #[error("export failed: {0}")]
    Export(#[from] GpError),
    /// An output file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// "path: why", or "why" alone when it names the path already (the
/// library's I/O errors do).
fn with_path(path: &Path, why: &dyn std::fmt::Display, names_path: bool) -> String {
    if names_path {
        why.to_string()
    } else {
        format!("{}: {why}", path.display())
    }
}

/// An output file's directory must exist, and the path must not be a
/// directory itself (checked before any work).
fn check_out_dir(path: &Path) -> Result<(), CliError> {
    if path.is_dir() {
        return Err(CliError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "is a directory: give a file name",
            ),
        });
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => Err(CliError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("directory {} does not exist", dir.display()),
            ),
        }),
        _ => Ok(()),
    }
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
    move |source| CliError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn data_error(path: &Path) -> impl FnOnce(DataError) -> CliError + '_ {
    move |source| CliError::Data {
        path: path.to_path_buf(),
        source: Box::new(source),
    }
}

#[derive(Parser, Debug)]
#[command(
    name = "vigp",
    version,
    about = "Structure-preserving learned dynamics: fit a GP-augmented variational integrator to measured trajectories, score it, predict with bounds, export it for firmware."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug, Clone)]
enum Command {
    /// Train a learned model on measured trajectories and save it.
    Fit(FitArgs),
    /// k-step position MSE of the learned and the nominal model on held-out runs.
    Score(ScoreArgs),
    /// Learned trajectories from the start of every run, with one-step bounds.
    Predict(PredictArgs),
    /// Rust source of the learned model for no_std firmware.
    Export(ExportArgs),
}

/// How data files are read.
#[derive(Args, Debug, Clone)]
struct ReadArgs {
    /// Resample uneven runs onto this time step (s) by linear interpolation.
    #[arg(long, value_name = "DT", allow_negative_numbers = true)]
    resample: Option<f64>,
    /// Do not unwrap angle coordinates.
    #[arg(long)]
    no_unwrap: bool,
    /// Accepted deviation of a time step from its run's median step
    /// (relative), on top of the rounding of the printed timestamps.
    #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true)]
    time_tolerance: f64,
    /// Drop readings that imply an implausible speed (sensor spikes) and
    /// split their runs there, instead of refusing the file; the count is
    /// printed.
    #[arg(long)]
    drop_outliers: bool,
    /// The largest plausible speed of any coordinate (rad/s or m/s);
    /// default: from the data's own extent.
    #[arg(long, value_name = "SPEED", allow_negative_numbers = true)]
    max_speed: Option<f64>,
}

impl ReadArgs {
    fn options(&self) -> ReadOptions {
        ReadOptions {
            unwrap_angles: !self.no_unwrap,
            time_tolerance: self.time_tolerance,
            resample: self.resample,
            max_speed: self.max_speed,
            drop_outliers: self.drop_outliers,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum EncodingArg {
    /// Angles as (sin, cos), minimal coordinates.
    Sincos,
    /// Minimal coordinates as they are.
    Minimal,
    /// Maximal coordinates (x, y, θ of every link), projected onto the joints.
    Maximal,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum BoundArg {
    /// Split conformal prediction on held-out runs (`--calibration`): coverage ≥ 1 − δ of a new
    /// case exchangeable with them; falls back to the RKHS bound outside their region.
    Conformal,
    /// The paper's Theorem 1 (the true map is a sample of the fitted GP), uniform over a box.
    Theorem1,
    /// The RKHS-norm bound of Fiedler et al. (2021), uniform over all inputs.
    Rkhs,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum PriorArg {
    /// The nominal variational step (the GP learns the residual).
    Nominal,
    /// No model: a constant mean.
    Constant,
}

#[derive(Args, Debug, Clone)]
struct FitArgs {
    /// The mechanism (with several registered; case and `_` do not matter).
    #[arg(long)]
    system: Option<String>,
    /// Training data (CSV: run,t,<coordinates>).
    #[arg(long)]
    data: PathBuf,
    /// Where to save the model (JSON).
    #[arg(long)]
    out: PathBuf,
    /// GP input coordinates.
    #[arg(long, value_enum, default_value = "sincos")]
    encoding: EncodingArg,
    /// Prior of the velocity map.
    #[arg(long, value_enum, default_value = "nominal")]
    prior: PriorArg,
    /// Random restarts of the hyperparameter optimisation (besides the first start).
    #[arg(long, default_value_t = 5)]
    restarts: usize,
    /// Seed of the restarts.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Curvature pairs of the L-BFGS-B optimiser (scipy's `maxcor`, 10 by
    /// default). A memory of at least d + 2 (d GP inputs) needs fewer
    /// likelihood evaluations on many inputs, e.g. `--encoding maximal`
    /// (3 per link, doubled with velocities): 30 cut those on all 512
    /// samples by 30 % in the paper's evaluation.
    #[arg(long, default_value_t = 10, value_name = "K")]
    memory: usize,
    /// Largest number of training transitions (evenly spaced over the data);
    /// default 512 for the exact GP, every transition with `--sparse`.
    #[arg(long)]
    max_samples: Option<usize>,
    /// Train Titsias' sparse variational GP with M inducing points
    /// (k-means++ on the inputs) instead of the exact GP: O(N·M²) per
    /// likelihood evaluation instead of O(N³), so long logs can be used
    /// whole. Its noise variance is kept at or above 1e-6 (normalised
    /// units: noise-free logs fit far better than at the exact GP's 1e-10).
    /// `predict` bounds such a model with the conformal bound only
    /// (`--calibration`; Theorem 1 and RKHS assume the exact GP), and
    /// `export` writes its mean (M inducing points), not its variance.
    #[arg(long, value_name = "M")]
    sparse: Option<usize>,
    /// With `--sparse`: after the hyperparameter starts, move the inducing
    /// points together with the hyperparameters to raise the variational
    /// bound (one L-BFGS run over M·d + outputs·(d + 2) variables, up to
    /// 500 iterations; each costs about one bound evaluation per output).
    #[arg(long, requires = "sparse")]
    optimise_inducing: bool,
    /// Run every start of the exact GP on all training transitions. By
    /// default, from 512 transitions on, the starts run first on a random
    /// subset and only the distinct optima found there are refined on all
    /// of them (several times faster, the same optimum on the data sets
    /// checked; `vigp::gp::Screening`).
    #[arg(long, conflicts_with = "sparse")]
    no_screen: bool,
    /// Lower bound of each GP's noise variance, in the normalised units the
    /// GP trains in (outputs scaled to unit variance); default 1e-10. On
    /// nearly noise-free data the fitted noise can reach it, and then the
    /// posterior variance σ_f² − kᵀ(K + σ_n²I)⁻¹k is lost to rounding at
    /// some states, where `predict`'s variance-based bounds (RKHS and
    /// Theorem 1) refuse the run. What counts is the ratio to the fitted signal
    /// variance σ_f² (which can grow to 1e4 on smooth data): a floor of
    /// about 1e-10·σ_f² keeps the bounds usable, and `fit` prints that
    /// value when a fitted noise variance is below it.
    // negative numbers are values to refuse with a reason, not flags
    #[arg(long, value_name = "VAR", allow_negative_numbers = true)]
    noise_floor: Option<f64>,
    /// Change a nominal parameter, e.g. `--set links.pole.mass=1.1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
struct ScoreArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    model: PathBuf,
    /// Held-out data (CSV: run,t,<coordinates>).
    #[arg(long)]
    data: PathBuf,
    /// Prediction horizon k.
    #[arg(long, default_value_t = 20)]
    steps: usize,
    #[command(flatten)]
    read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
struct PredictArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    model: PathBuf,
    /// Start states: the first two rows of every run (an actuated mechanism's
    /// runs also give the inputs of the predicted steps: rows 1 to `--steps`).
    #[arg(long)]
    data: PathBuf,
    /// Steps to predict.
    #[arg(long)]
    steps: usize,
    /// Output CSV: run,t,<coordinates>,v_<coordinate>…,[u_<joint>…,]bound,position_bound.
    #[arg(long)]
    out: PathBuf,
    /// Failure probability δ of the bounds.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
    delta: f64,
    /// Kind of error bound [default: conformal with `--calibration`, rkhs without].
    #[arg(long, value_enum)]
    bound: Option<BoundArg>,
    /// Held-out runs (same CSV format as `--data`, not used for training) that calibrate the
    /// conformal bound over `--steps`-step windows; the rigorous kinds use their start states
    /// to estimate Lipschitz constants.
    #[arg(long)]
    calibration: Option<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
struct ExportArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    model: PathBuf,
    /// The Rust file to write.
    #[arg(long)]
    out: PathBuf,
    /// Also export the Cholesky factors (posterior variances; N(N+1)/2 numbers per output).
    #[arg(long)]
    variance: bool,
    /// Name of the generated `LearnedModel` static.
    #[arg(long, default_value = "LEARNED")]
    name: String,
    /// Path of vigp's no_std core in the generated code.
    #[arg(long, default_value = "vigp::embedded")]
    core_path: String,
}

/// One mechanism the tool knows (see [`system`]).
#[derive(Clone, Copy)]
pub struct SystemEntry {
    name: &'static str,
    run: fn(&Command, &mut dyn Write) -> Result<(), CliError>,
}

impl SystemEntry {
    /// The mechanism's name.
    pub fn name(&self) -> &'static str {
        self.name
    }
}

impl core::fmt::Debug for SystemEntry {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SystemEntry")
            .field("name", &self.name)
            .finish()
    }
}

/// The entry of mechanism `S` for [`main_with`] / [`run`].
pub fn system<S: System>() -> SystemEntry {
    SystemEntry {
        name: S::NAME,
        run: run_system::<S>,
    }
}

/// The paper's four systems (`vigp::systems`), as the `vigp` binary has them.
pub fn paper_systems() -> Vec<SystemEntry> {
    use crate::systems::{Cartpole, DoublePendulum, Fourbar, Pendulum};
    vec![
        system::<Pendulum>(),
        system::<Cartpole>(),
        system::<DoublePendulum>(),
        system::<Fourbar>(),
    ]
}

/// The whole tool for one mechanism: `fn main() -> ExitCode { vigp::cli::main::<MyMechanism>() }`.
pub fn main<S: System>() -> ExitCode {
    main_with(&[system::<S>()])
}

/// The tool for several mechanisms, with the process's arguments; prints
/// errors to stderr and returns the exit code.
pub fn main_with(systems: &[SystemEntry]) -> ExitCode {
    let mut stdout = std::io::stdout().lock();
    match run(systems, std::env::args_os(), &mut stdout) {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Args(e)) => {
            let _ = e.print();
            if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Runs one command line (`args` including the program name) for the given
/// mechanisms, writing the report to `out`. Progress bars go to stderr
/// (only on a terminal).
pub fn run<I, T>(systems: &[SystemEntry], args: I, out: &mut dyn Write) -> Result<(), CliError>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = Cli::try_parse_from(args)?;
    let entry = match &cli.command {
        Command::Fit(a) => match &a.system {
            Some(name) => find(systems, name)?,
            None if systems.len() == 1 => systems[0],
            None => {
                return Err(CliError::Usage(format!(
                    "--system is needed: one of {}",
                    names(systems)
                )));
            }
        },
        Command::Score(ScoreArgs { model, .. })
        | Command::Predict(PredictArgs { model, .. })
        | Command::Export(ExportArgs { model, .. }) => {
            let saved = read_saved(model)?;
            find(systems, &saved.mechanism)?
        }
    };
    (entry.run)(&cli.command, out)
}

fn names(systems: &[SystemEntry]) -> String {
    systems
        .iter()
        .map(|s| s.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// `DoublePendulum`, `double_pendulum`, `double-pendulum` all match.
fn normalise(name: &str) -> String {
    name.chars()
        .filter(|c| *c != '_' && *c != '-')
        .flat_map(char::to_lowercase)
        .collect()
}

fn find(systems: &[SystemEntry], name: &str) -> Result<SystemEntry, CliError> {
    systems
        .iter()
        .find(|s| normalise(s.name) == normalise(name))
        .copied()
        .ok_or_else(|| {
            CliError::Usage(format!(
                "unknown mechanism `{name}`: this tool knows {}",
                names(systems)
            ))
        })
}

fn read_saved(path: &Path) -> Result<SavedLearned, CliError> {
    SavedLearned::read(path).map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })
}

fn run_system<S: System>(cmd: &Command, out: &mut dyn Write) -> Result<(), CliError> {
    let mut sys = S::default();
    match cmd {
        Command::Fit(a) => {
            for s in &a.set {
                set_parameter(&mut sys, s)?;
            }
            sys.visit(Visit { cmd, out })
        }
        _ => sys.visit(Visit { cmd, out }),
    }
}

fn set_parameter<P: Parameters>(p: &mut P, assignment: &str) -> Result<(), CliError> {
    let bad = |why: String| CliError::Usage(format!("--set {assignment}: {why}"));
    let (name, value) = assignment
        .split_once('=')
        .ok_or_else(|| bad("expected NAME=VALUE".into()))?;
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| bad(format!("{value:?} is not a number")))?;
    if !value.is_finite() {
        return Err(bad("the value must be finite".into()));
    }
    let i = P::parameter_index(name.trim()).ok_or_else(|| {
        bad(format!(
            "no parameter `{name}`; the parameters are {}",
            P::PARAMETER_NAMES.join(", ")
        ))
    })?;
    if let Some(slot) = p.parameter_mut(i) {
        *slot = value;
    }
    Ok(())
}

/// Sets `p`'s parameters from a saved model's.
fn restore_parameters<P: Parameters>(
    p: &mut P,
    saved: &SavedLearned,
    path: &Path,
) -> Result<(), CliError> {
    for (i, name) in P::PARAMETER_NAMES.iter().enumerate() {
        let value = saved
            .parameters
            .get(*name)
            .copied()
            .ok_or_else(|| CliError::Model {
                path: path.to_path_buf(),
                source: LoadError::MissingParameter(name.to_string()),
            })?;
        if let Some(slot) = p.parameter_mut(i) {
            *slot = value;
        }
    }
    Ok(())
}

struct Visit<'a> {
    cmd: &'a Command,
    out: &'a mut dyn Write,
}

fn spinner(message: String) -> ProgressBar {
    let pb = ProgressBar::new_spinner();
    pb.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    pb.set_message(message);
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

fn bar(len: usize, message: &'static str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    pb.set_style(
        ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb.set_message(message);
    pb
}

fn w(out: &mut dyn Write, text: std::fmt::Arguments<'_>) -> Result<(), CliError> {
    out.write_fmt(text)
        .and_then(|_| out.write_all(b"\n"))
        .map_err(io_error(Path::new("<stdout>")))
}

/// Reads a data file with the mechanism's coordinates and, for an actuated
/// mechanism, its input columns `u_<joint>`.
fn read_data<const N: usize>(
    path: &Path,
    names: &[&'static str; N],
    kinds: &[crate::CoordinateKind; N],
    inputs: &[&str],
    read: &ReadArgs,
) -> Result<Dataset<N>, CliError> {
    let data = Dataset::read_path_with_inputs(path, names, kinds, inputs, &read.options())
        .map_err(data_error(path))?;
    // unit heuristics and dropped outliers: on stderr, the results stay
    // on stdout
    for warning in &data.warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
    if !data.dropped.is_empty() {
        let first = &data.dropped[0];
        eprintln!(
            "note: {}: dropped {} outlier reading(s) (--drop-outliers), the first at run `{}`, line {}, column `{}`",
            path.display(),
            data.dropped.len(),
            first.run,
            first.line,
            first.column
        );
    }
    Ok(data)
}

/// ", sparse GP, M = …" for a sparse model, "" for an exact one.
fn sparse_note(gp: &crate::gp::Gp) -> String {
    if gp.is_sparse() {
        format!(", sparse GP, M = {}", gp.posterior_points())
    } else {
        String::new()
    }
}

/// `--max-samples` of the exact GP when none is given (training is O(N³)).
const DEFAULT_MAX_SAMPLES: usize = 512;

/// Evenly spaced selection of at most `max` items.
fn spread<T: Copy>(all: &[T], max: usize) -> Vec<T> {
    if all.len() <= max {
        return all.to_vec();
    }
    (0..max).map(|i| all[i * all.len() / max]).collect()
}

impl ViewVisitor for Visit<'_> {
    type Output = Result<(), CliError>;

    fn visit<
        Mn,
        Mx,
        const N: usize,
        const C: usize,
        const NM: usize,
        const CM: usize,
        const U: usize,
    >(
        self,
        minimal: Mn,
        maximal: Mx,
    ) -> Self::Output
    where
        Mn: Mechanism<N, C> + Coordinates<N, NM> + Parameters + Copy + Send + Sync + 'static,
        Mx: Mechanism<NM, CM> + Parameters + Copy + Send + Sync + 'static,
    {
        let Visit { cmd, out } = self;
        match cmd {
            Command::Fit(a) => fit::<Mn, Mx, N, C, NM, CM, U>(a, minimal, maximal, out),
            Command::Score(a) => {
                let (saved, nominal, data) = model_and_data(&a.model, &a.data, &a.read, minimal)?;
                if in_minimal::<Mn, Mx, N, C, NM, CM>(&a.model, &saved)? {
                    let l = load(&a.model, &saved, minimal)?;
                    score::<_, _, N, C, N, C, U>(a, &l, nominal, &data, |z| *z, |q| *q, out)
                } else {
                    let l = load(&a.model, &saved, maximal)?;
                    let dt = saved.dt;
                    score::<_, _, N, C, NM, CM, U>(
                        a,
                        &l,
                        nominal,
                        &data,
                        |z| nominal.to_maximal(z, dt),
                        |x| nominal.minimal_positions(x),
                        out,
                    )
                }
            }
            Command::Predict(a) => {
                let (saved, nominal, data) = model_and_data(&a.model, &a.data, &a.read, minimal)?;
                if in_minimal::<Mn, Mx, N, C, NM, CM>(&a.model, &saved)? {
                    let l = load(&a.model, &saved, minimal)?;
                    let coords = (&Mn::COORDINATES, &Mn::KINDS, Mn::INPUT_NAMES);
                    predict::<_, N, N, C, U>(a, &l, &data, coords, |z| *z, |z| *z, out)
                } else {
                    let l = load(&a.model, &saved, maximal)?;
                    let dt = saved.dt;
                    predict::<_, N, NM, CM, U>(
                        a,
                        &l,
                        &data,
                        (&Mn::COORDINATES, &Mn::KINDS, Mn::INPUT_NAMES),
                        |z| nominal.to_maximal(z, dt),
                        |z| nominal.to_minimal(z, dt),
                        out,
                    )
                }
            }
            Command::Export(a) => {
                let saved = read_saved(&a.model)?;
                if in_minimal::<Mn, Mx, N, C, NM, CM>(&a.model, &saved)? {
                    let l = load(&a.model, &saved, minimal)?;
                    export(a, &l, out)
                } else {
                    let l = load(&a.model, &saved, maximal)?;
                    export(a, &l, out)
                }
            }
        }
    }
}

/// A saved model, the nominal minimal model with the file's parameters, and
/// the data (with the mechanism's input columns): what `score` and
/// `predict` start from.
fn model_and_data<Mn, const N: usize, const C: usize>(
    model: &Path,
    data: &Path,
    read: &ReadArgs,
    minimal: Mn,
) -> Result<(SavedLearned, Mn, Dataset<N>), CliError>
where
    Mn: Mechanism<N, C> + Parameters,
{
    let saved = read_saved(model)?;
    let mut nominal = minimal;
    restore_parameters(&mut nominal, &saved, model)?;
    let data = read_data(data, &Mn::COORDINATES, &Mn::KINDS, Mn::INPUT_NAMES, read)?;
    Ok((saved, nominal, data))
}

/// `true` when a model file is in the minimal coordinates, `false` when in
/// the maximal ones; an error naming both when in neither (an edited or
/// corrupted file), rather than a complaint against one of them.
fn in_minimal<Mn, Mx, const N: usize, const C: usize, const NM: usize, const CM: usize>(
    path: &Path,
    saved: &SavedLearned,
) -> Result<bool, CliError>
where
    Mn: Mechanism<N, C>,
    Mx: Mechanism<NM, CM>,
{
    if saved.coordinates == Mn::COORDINATES {
        Ok(true)
    } else if saved.coordinates == Mx::COORDINATES {
        Ok(false)
    } else {
        Err(CliError::Usage(format!(
            "{}: field `coordinates`: [{}] are neither the minimal coordinates [{}] nor the \
             maximal ones [{}] of {}",
            path.display(),
            saved.coordinates.join(", "),
            Mn::COORDINATES.join(", "),
            Mx::COORDINATES.join(", "),
            saved.mechanism
        )))
    }
}

fn load<M: Mechanism<N, C> + Parameters + Clone, const N: usize, const C: usize>(
    path: &Path,
    saved: &SavedLearned,
    model: M,
) -> Result<Learned<M, N, C>, CliError> {
    Learned::from_saved(model, saved).map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })
}

/// `U`: the mechanism's inputs; with inputs the data carries `u_<joint>`
/// columns and the model learns on state and input (GP input: the encoded
/// state, then the previous and the current input; prior: the forced
/// nominal step).
fn fit<Mn, Mx, const N: usize, const C: usize, const NM: usize, const CM: usize, const U: usize>(
    a: &FitArgs,
    minimal: Mn,
    maximal: Mx,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Coordinates<N, NM> + Parameters + Copy + Send + Sync + 'static,
    Mx: Mechanism<NM, CM> + Parameters + Copy + Send + Sync + 'static,
{
    // usage errors before the data are read (a long log takes a while),
    // the nominal parameters first (`--set` may have made a mass negative)
    if let Err(e) = minimal.constants().and_then(|_| maximal.constants()) {
        return Err(CliError::Usage(format!(
            "the nominal model (with --set): {e}"
        )));
    }
    if a.max_samples == Some(0) {
        return Err(CliError::Usage("--max-samples must be at least 1".into()));
    }
    if a.sparse == Some(0) {
        return Err(CliError::Usage(
            "--sparse needs at least 1 inducing point".into(),
        ));
    }
    if a.restarts > vigp_runtime::gp::MAX_RESTARTS {
        return Err(CliError::Usage(format!(
            "--restarts must be at most {}",
            vigp_runtime::gp::MAX_RESTARTS
        )));
    }
    if !(1..=vigp_runtime::gp::MAX_MEMORY).contains(&a.memory) {
        return Err(CliError::Usage(format!(
            "--memory must be from 1 to {}",
            vigp_runtime::gp::MAX_MEMORY
        )));
    }
    let prior = match a.prior {
        PriorArg::Nominal => Prior::Nominal,
        PriorArg::Constant => Prior::Constant,
    };
    let mut opts = TrainOptions {
        restarts: a.restarts,
        seed: a.seed,
        memory: a.memory,
        method: match a.sparse {
            Some(m) => Method::Sparse(SparseOptions {
                optimise_inducing: a.optimise_inducing,
                ..SparseOptions::kmeans(m)
            }),
            None => Method::Exact,
        },
        screening: if a.no_screen {
            Screening::Off
        } else {
            Screening::Auto
        },
        ..TrainOptions::default()
    };
    if let Some(floor) = a.noise_floor {
        let upper = opts.bounds.noise_variance.1;
        if !(floor.is_finite() && floor > 0.0 && floor < upper) {
            return Err(CliError::Usage(format!(
                "--noise-floor must be finite and in (0, {upper}): {floor}"
            )));
        }
        opts.bounds.noise_variance.0 = floor;
    }
    // before the training, which the write would otherwise waste
    check_out_dir(&a.out)?;
    let data = read_data(
        &a.data,
        &Mn::COORDINATES,
        &Mn::KINDS,
        Mn::INPUT_NAMES,
        &a.read,
    )?;
    let dt = data
        .dt(a.read.time_tolerance)
        .map_err(data_error(&a.data))?;
    let short: Vec<&str> = data.short_runs().map(|r| r.name.as_str()).collect();
    w(
        out,
        format_args!(
            "data: {}: {} runs, {} samples, dt = {dt} s",
            a.data.display(),
            data.runs.len(),
            data.samples()
        ),
    )?;
    if !short.is_empty() {
        w(
            out,
            format_args!(
                "note: {} run(s) with fewer than 3 samples give no transitions: {}",
                short.len(),
                short.join(", ")
            ),
        )?;
    }
    match a.encoding {
        EncodingArg::Sincos | EncodingArg::Minimal => {
            let enc = if a.encoding == EncodingArg::Sincos {
                Encoding::SinCos
            } else {
                Encoding::Raw
            };
            if U == 0 {
                let all = data.transitions();
                let train = |chosen: &[Transition<N>]| {
                    Learned::train(minimal, dt, chosen, enc, prior, &opts)
                };
                fit_view(a, &all, (enc, prior), 0, &opts, train, out)
            } else {
                let all = data
                    .forced_transitions::<U>()
                    .map_err(data_error(&a.data))?;
                let train = |chosen: &[ForcedTransition<N, U>]| {
                    Learned::train_forced(minimal, dt, chosen, enc, prior, &opts)
                };
                fit_view(a, &all, (enc, prior), 2 * U, &opts, train, out)
            }
        }
        EncodingArg::Maximal => {
            // each run's transitions in the maximal coordinates, with its
            // inputs when the mechanism has some
            let inputs = data.input_vectors::<U>().map_err(data_error(&a.data))?;
            let (mut plain, mut forced) = (Vec::new(), Vec::new());
            for (run, us) in data.runs.iter().zip(&inputs) {
                let Some(run_dt) = run.dt else { continue };
                let xs: Vec<SVector<f64, NM>> = run
                    .positions
                    .iter()
                    .map(|q| minimal.maximal_positions(q))
                    .collect();
                if U == 0 {
                    plain.extend(transitions(&xs, run_dt));
                } else {
                    forced.extend(forced_transitions(&xs, us, run_dt));
                }
            }
            if U == 0 {
                let train = |chosen: &[Transition<NM>]| {
                    Learned::train(maximal, dt, chosen, Encoding::Raw, prior, &opts)
                };
                fit_view(a, &plain, (Encoding::Raw, prior), 0, &opts, train, out)
            } else {
                let train = |chosen: &[ForcedTransition<NM, U>]| {
                    Learned::train_forced(maximal, dt, chosen, Encoding::Raw, prior, &opts)
                };
                fit_view(a, &forced, (Encoding::Raw, prior), 2 * U, &opts, train, out)
            }
        }
    }
}

/// Trains on at most `--max-samples` of `all` (`train`: the plain or the
/// forced training of one view, with `encoding` and `prior`), reports and
/// saves. `u_dim`: the GP inputs that are control inputs, after the
/// `encoding`'s state inputs (2·U for a forced model: the previous and the
/// current input).
/// A fitted noise variance below this fraction of the signal variance
/// leaves the posterior variance σ_f² − kᵀ(K + σ_n²I)⁻¹k at the level of
/// its rounding error near the data (≈ N·ε·σ_f² ≈ 1e-13·σ_f² at N = 512,
/// with a margin of 10³): `fit` then says so and names a floor.
const VARIANCE_RESOLVED: f64 = 1e-10;

fn fit_view<M, T, const N: usize, const C: usize>(
    a: &FitArgs,
    all: &[T],
    (encoding, prior): (Encoding, Prior),
    u_dim: usize,
    opts: &TrainOptions,
    train: impl FnOnce(&[T]) -> Result<(Learned<M, N, C>, TrainReport), LearnError>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Clone,
    T: Copy,
{
    let max = match (a.max_samples, a.sparse) {
        (Some(max), _) => max,
        (None, Some(_)) => usize::MAX,
        (None, None) => DEFAULT_MAX_SAMPLES,
    };
    let chosen = spread(all, max);
    if let Some(m) = a.sparse.filter(|&m| m > chosen.len()) {
        return Err(CliError::Usage(format!(
            "--sparse {m}: more inducing points than the {} training transitions",
            chosen.len()
        )));
    }
    let d = encoding.dim(&M::KINDS) + u_dim;
    w(
        out,
        format_args!(
            "fit: {} in coordinates [{}]{}, {encoding:?} encoding ({d} inputs), {prior:?} prior: \
             N = {} of {} transitions, {} restarts{}",
            M::NAME,
            M::COORDINATES.join(", "),
            if u_dim > 0 {
                format!(" with inputs [{}]", M::INPUT_NAMES.join(", "))
            } else {
                String::new()
            },
            chosen.len(),
            all.len(),
            opts.restarts,
            match a.sparse {
                Some(m) => format!(
                    ", sparse GP with {m} inducing points{}",
                    if a.optimise_inducing {
                        " (optimised)"
                    } else {
                        ""
                    }
                ),
                None => String::new(),
            }
        ),
    )?;
    let pb = spinner(format!(
        "training {N} GPs on N = {} ({} starts each)",
        chosen.len(),
        1 + opts.restarts
    ));
    let start = Instant::now();
    let result = train(&chosen);
    pb.finish_and_clear();
    let (learned, report) = result?;
    w(
        out,
        format_args!("trained in {:.1} s", start.elapsed().as_secs_f64()),
    )?;
    for (j, o) in report.outputs.iter().enumerate() {
        w(
            out,
            format_args!(
                "  v_{}: log marginal likelihood {:.4e}, best start {}, jitter {:.1e}{}{}",
                M::COORDINATES[j],
                o.log_marginal_likelihood,
                o.best_start,
                o.jitter,
                if o.converged { "" } else { " (iteration cap)" },
                match &o.screening {
                    Some(s) if s.fell_back => format!(
                        " (screened on {} transitions; refit on all as white noise won)",
                        s.subset
                    ),
                    Some(s) => format!(
                        " (screened on {} transitions, {} {} refined on all)",
                        s.subset,
                        s.refined.len(),
                        if s.refined.len() == 1 {
                            "optimum"
                        } else {
                            "optima"
                        }
                    ),
                    None => String::new(),
                }
            ),
        )?;
    }
    if let Some(z) = &report.inducing {
        w(
            out,
            format_args!(
                "  inducing points optimised: summed bound {:.4e} -> {:.4e} in {} iterations{}",
                z.bound_before,
                z.bound_after,
                z.iterations,
                if z.converged { "" } else { " (iteration cap)" }
            ),
        )?;
    }
    if a.sparse.is_none() {
        for (j, o) in learned.gp().outputs().iter().enumerate() {
            let hp = o.hyperparameters();
            let ratio = hp.noise_variance / hp.signal_variance;
            // the smallest power of ten at or above the resolvable floor
            // (the 1e-9 keeps an exact power of ten from rounding up)
            let floor =
                10f64.powf(((VARIANCE_RESOLVED * hp.signal_variance).log10() - 1e-9).ceil());
            if hp.noise_variance < 0.5 * floor {
                w(
                    out,
                    format_args!(
                        "note: v_{}: noise variance {:.1e} is {ratio:.0e} of the signal variance \
                         {:.1e} (normalised units): the posterior variance can be lost to rounding \
                         and `predict --bound rkhs|theorem1` refuse such states; refit with \
                         --noise-floor {floor:e} or bound with --calibration",
                        M::COORDINATES[j],
                        hp.noise_variance,
                        hp.signal_variance,
                    ),
                )?;
            }
        }
    }
    learned.save(&a.out).map_err(|source| CliError::Model {
        path: a.out.clone(),
        source,
    })?;
    let bytes = std::fs::metadata(&a.out).map(|m| m.len()).unwrap_or(0);
    w(
        out,
        format_args!("wrote {} ({bytes} bytes)", a.out.display()),
    )
}

/// Mean over steps 1..=k of |p − t|²/n.
fn window_mse<const N: usize>(pred: &[SVector<f64, N>], truth: &[SVector<f64, N>]) -> f64 {
    let s: f64 = pred
        .iter()
        .zip(truth)
        .map(|(p, t)| (p - t).norm_squared() / N as f64)
        .sum();
    s / pred.len() as f64
}

/// `U`: the mechanism's inputs (0 for none; then the data has no input
/// columns and both models step unforced).
fn score<L, Mn, const N: usize, const C: usize, const K: usize, const CK: usize, const U: usize>(
    a: &ScoreArgs,
    learned: &Learned<L, K, CK>,
    nominal: Mn,
    data: &Dataset<N>,
    to_view: impl Fn(&State<N>) -> State<K> + Sync,
    to_minimal: impl Fn(&SVector<f64, K>) -> SVector<f64, N> + Sync,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    L: Mechanism<K, CK> + Clone + Sync,
    Mn: Mechanism<N, C> + Copy + Sync,
{
    let k = a.steps;
    if k == 0 {
        return Err(CliError::Usage("--steps must be at least 1".into()));
    }
    if learned.inputs() != U {
        return Err(CliError::Usage(format!(
            "{}: the model takes {} input(s), the mechanism has {U}{}",
            a.model.display(),
            learned.inputs(),
            if U > 0 {
                " (fit it with the input columns: `vigp fit` on data with `u_<joint>`)"
            } else {
                ""
            }
        )));
    }
    let dt = learned.dt();
    data.check_dt(dt, a.read.time_tolerance)
        .map_err(data_error(&a.data))?;
    // windows: every sample with k more after it (and one more for v₀)
    let mut windows: Vec<(usize, usize)> = Vec::new();
    for (r, run) in data.runs.iter().enumerate() {
        let len = run.positions.len();
        if len >= k + 2 {
            windows.extend((0..len - k - 1).map(|s| (r, s)));
        }
    }
    let too_short = data
        .runs
        .iter()
        .filter(|r| r.positions.len() < k + 2)
        .count();
    w(
        out,
        format_args!(
            "model: {} ({} coordinates, {:?} encoding, {:?} prior, N = {}{}, dt = {dt} s)",
            a.model.display(),
            K,
            learned.encoding(),
            learned.prior(),
            learned.gp().n(),
            sparse_note(learned.gp())
        ),
    )?;
    w(
        out,
        format_args!(
            "data: {}: {} runs ({too_short} shorter than {} samples), {} windows of {k} steps",
            a.data.display(),
            data.runs.len(),
            k + 2,
            windows.len()
        ),
    )?;
    if windows.is_empty() {
        return Err(CliError::Usage(format!(
            "no run has {} samples: nothing to score with --steps {k}",
            k + 2
        )));
    }
    // each run's logged inputs, once (none without inputs)
    let inputs = data.input_vectors::<U>().map_err(data_error(&a.data))?;
    let vi = Variational::new(nominal, dt);
    let pb = bar(windows.len(), "scoring");
    type Scored = Result<f64, StepError>;
    let results: Vec<(Scored, Scored)> = windows
        .par_iter()
        .map(|&(r, s)| {
            let run = &data.runs[r];
            let truth = &run.positions[s + 1..=s + k];
            let z0 = State {
                q: run.positions[s],
                v: (run.positions[s + 1] - run.positions[s]) / dt,
            };
            // step j of the window (from sample s + j) under the input
            // logged over its new velocity's interval, row s + j + 1's,
            // after row s + j's (the learned step takes both)
            let us = if U == 0 {
                &[][..]
            } else {
                &inputs[r][s + 1..=s + k]
            };
            let mut buf = vec![z0; k];
            let nom = if U == 0 {
                vi.rollout_into(&z0, &mut buf)
            } else {
                vi.rollout_forced_into(&z0, us, &mut buf)
            };
            let nom = nom.map(|()| {
                let p: Vec<_> = buf.iter().map(|z| z.q).collect();
                window_mse(&p, truth)
            });
            let zv = to_view(&z0);
            let mut buf = vec![zv; k];
            let lrn = if U == 0 {
                learned.rollout_into(&zv, &mut buf)
            } else {
                learned.rollout_mean_forced_into(&zv, &inputs[r][s], us, &mut buf)
            };
            let lrn = lrn.map(|()| {
                let p: Vec<_> = buf.iter().map(|z| to_minimal(&z.q)).collect();
                window_mse(&p, truth)
            });
            pb.inc(1);
            (nom, lrn)
        })
        .collect();
    pb.finish_and_clear();
    let nominal_failed = results.iter().filter(|r| r.0.is_err()).count();
    let learned_failed = results.iter().filter(|r| r.1.is_err()).count();
    let both: Vec<(f64, f64)> = results
        .iter()
        .filter_map(|(a, b)| Some(((*a).ok()?, (*b).ok()?)))
        .collect();
    // the first failure of each model, with the run and the line its
    // window starts at
    for (what, pick) in [("nominal", 0usize), ("learned", 1usize)] {
        let first = windows.iter().zip(&results).find_map(|(&(r, s), res)| {
            let e = if pick == 0 {
                res.0.as_ref()
            } else {
                res.1.as_ref()
            };
            e.err().map(|e| (r, s, *e))
        });
        if let Some((r, s, e)) = first {
            let run = &data.runs[r];
            w(
                out,
                format_args!(
                    "first {what} failure: {}: {e}",
                    window_place(run, s, a.read.resample.is_some())
                ),
            )?;
        }
    }
    w(
        out,
        format_args!(
            "failed windows: nominal {nominal_failed}, learned {learned_failed} (scored: {} windows where both succeed)",
            both.len()
        ),
    )?;
    if both.is_empty() {
        return Err(CliError::Usage(
            "every window failed for the nominal or the learned model".into(),
        ));
    }
    let n = both.len() as f64;
    let nominal_mse = both.iter().map(|p| p.0).sum::<f64>() / n;
    let learned_mse = both.iter().map(|p| p.1).sum::<f64>() / n;
    w(
        out,
        format_args!("nominal_mse={nominal_mse:e} learned_mse={learned_mse:e}"),
    )
}

/// Where a window from sample `s` of `run` starts: the run, the sample and
/// its file line (not for a resampled run, whose samples have none).
fn window_place<const N: usize>(run: &crate::data::Run<N>, s: usize, resampled: bool) -> String {
    if resampled {
        format!("run `{}`, window from sample {s} (resampled)", run.name)
    } else {
        format!(
            "run `{}`, window from line {} (sample {s})",
            run.name,
            run.line + s as u64
        )
    }
}

/// `U`: the mechanism's inputs (0 for none; with inputs each run's logged
/// inputs drive its prediction).
fn predict<L, const N: usize, const K: usize, const CK: usize, const U: usize>(
    a: &PredictArgs,
    learned: &Learned<L, K, CK>,
    data: &Dataset<N>,
    (names, kinds, inputs): (
        &[&'static str; N],
        &[crate::CoordinateKind; N],
        &[&'static str],
    ),
    to_view: impl Fn(&State<N>) -> State<K>,
    to_minimal: impl Fn(&State<K>) -> State<N>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    L: Mechanism<K, CK> + Clone,
{
    if a.steps == 0 {
        return Err(CliError::Usage("--steps must be at least 1".into()));
    }
    if learned.inputs() != U {
        return Err(CliError::Usage(format!(
            "{}: the model takes {} input(s), the mechanism has {U}{}",
            a.model.display(),
            learned.inputs(),
            if U > 0 {
                " (fit it with the input columns: `vigp fit` on data with `u_<joint>`)"
            } else {
                ""
            }
        )));
    }
    check_out_dir(&a.out)?;
    let dt = learned.dt();
    data.check_dt(dt, a.read.time_tolerance)
        .map_err(data_error(&a.data))?;
    // each run's logged inputs (none without inputs)
    let logged = data.input_vectors::<U>().map_err(data_error(&a.data))?;
    // a start state needs two rows (position and discrete velocity), and a
    // forced prediction of k steps the inputs of rows 1..=k: shorter runs
    // are skipped with a note, as `fit` notes its short runs
    let rows = if U > 0 { a.steps + 1 } else { 2 };
    let mut starts = Vec::with_capacity(data.runs.len());
    let mut short = Vec::new();
    for (r, run) in data.runs.iter().enumerate() {
        match run.state(0) {
            Some(z) if run.positions.len() >= rows => {
                // the inputs of rows 1..=k, after row 0's (which produced
                // the start's velocity)
                let (up, us): (SVector<f64, U>, &[SVector<f64, U>]) = if U > 0 {
                    (logged[r][0], &logged[r][1..=a.steps])
                } else {
                    (SVector::zeros(), &[])
                };
                starts.push((run, z, up, us));
            }
            _ => short.push(run.name.as_str()),
        }
    }
    // what a skipped run lacks, for the note and the error
    let (too_few, why) = if U > 0 {
        (
            format!("fewer than {rows} rows"),
            format!(
                "a start state needs two, and the prediction the inputs logged in rows 1 to {}",
                a.steps
            ),
        )
    } else {
        ("one row".to_string(), "a start state needs two".to_string())
    };
    if starts.is_empty() {
        return Err(CliError::Usage(format!(
            "{}: every run has {too_few} ({why})",
            a.data.display()
        )));
    }
    if !short.is_empty() {
        w(
            out,
            format_args!(
                "note: skipped {} run(s) of {too_few} ({why}): {}",
                short.len(),
                short.join(", ")
            ),
        )?;
    }
    let view_starts: Vec<State<K>> = starts.iter().map(|(_, z, _, _)| to_view(z)).collect();
    let kind_arg = a.bound.unwrap_or(if a.calibration.is_some() {
        BoundArg::Conformal
    } else {
        BoundArg::Rkhs
    });
    let calibration = match &a.calibration {
        Some(path) => {
            let held_out = read_data(path, names, kinds, inputs, &a.read)?;
            held_out
                .check_dt(dt, a.read.time_tolerance)
                .map_err(data_error(path))?;
            // windows in the model's coordinates: positions of the view
            // (and, with inputs, each sample's logged input)
            let trajectories: Vec<Vec<SVector<f64, K>>> = held_out
                .runs
                .iter()
                .map(|run| {
                    run.positions
                        .iter()
                        .map(|q| {
                            to_view(&State {
                                q: *q,
                                v: SVector::zeros(),
                            })
                            .q
                        })
                        .collect()
                })
                .collect();
            if U > 0 {
                let logged = held_out.input_vectors::<U>().map_err(data_error(path))?;
                Calibration::from_trajectories_forced(
                    &trajectories,
                    &logged,
                    dt,
                    a.steps.max(2),
                    1,
                )?
            } else {
                Calibration::from_trajectories(&trajectories, dt, a.steps.max(2), 1)?
            }
        }
        None if kind_arg == BoundArg::Conformal => {
            return Err(CliError::Usage(
                "--bound conformal needs held-out runs: pass --calibration FILE".into(),
            ));
        }
        None => Calibration::empty(dt),
    };
    let kind = match kind_arg {
        BoundArg::Conformal => BoundKind::conformal(a.delta),
        BoundArg::Theorem1 => BoundKind::theorem1(a.delta),
        BoundArg::Rkhs => BoundKind::rkhs(a.delta),
    };
    // (U = 0 is `error_bound`; the model's input count is checked above)
    let bound = learned.error_bound_forced::<U>(&kind, &calibration)?;
    let file = std::fs::File::create(&a.out).map_err(io_error(&a.out))?;
    let mut wtr = csv::Writer::from_writer(std::io::BufWriter::new(file));
    let coords: Vec<String> = data.coordinates.clone();
    let mut header = vec!["run".to_string(), "t".to_string()];
    header.extend(coords.iter().cloned());
    header.extend(coords.iter().map(|c| format!("v_{c}")));
    // the input that drove the step into each row (the data's convention)
    header.extend(inputs.iter().map(|j| format!("u_{j}")));
    header.push("bound".into());
    header.push("position_bound".into());
    let csv_err = |e: csv::Error| CliError::Io {
        path: a.out.clone(),
        source: std::io::Error::other(e),
    };
    wtr.write_record(&header).map_err(csv_err)?;
    let pb = bar(starts.len(), "predicting");
    let mut failed = 0usize;
    let mut first_error = None;
    // states outside what the bound covers, and the runs holding them
    let (mut outside, mut outside_runs) = (0usize, 0usize);
    for ((run, z0, up, us), zv) in starts.iter().zip(&view_starts) {
        let pred = if U > 0 {
            learned.predict_forced(zv, up, us, &bound)
        } else {
            learned.predict(zv, a.steps, &bound)
        };
        let pred = match pred {
            Ok(p) => p,
            Err(e) => {
                failed += 1;
                w(
                    out,
                    format_args!("{}: {e}", window_place(run, 0, a.read.resample.is_some())),
                )?;
                first_error.get_or_insert(e);
                continue;
            }
        };
        let n_out = pred.outside.iter().filter(|&&o| o).count();
        outside += n_out;
        outside_runs += usize::from(n_out > 0);
        for (k, z) in pred.states.iter().enumerate() {
            let zm = if k == 0 { *z0 } else { to_minimal(z) };
            let mut row = vec![run.name.clone(), format!("{:?}", run.t0 + k as f64 * dt)];
            row.extend(zm.q.iter().map(|x| format!("{x:?}")));
            row.extend(zm.v.iter().map(|x| format!("{x:?}")));
            match us.get(k.wrapping_sub(1)) {
                Some(u) => row.extend(u.iter().map(|x| format!("{x:?}"))),
                None => row.extend(inputs.iter().map(|_| String::new())),
            }
            row.push(if k == 0 {
                String::new()
            } else {
                format!("{:?}", pred.one_step_bounds[k - 1])
            });
            row.push(format!("{:?}", pred.position_bounds[k]));
            wtr.write_record(&row).map_err(csv_err)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    wtr.flush().map_err(io_error(&a.out))?;
    if failed == starts.len()
        && let Some(e) = first_error
    {
        // a file with the header alone is no result: fail (exit code 1)
        w(
            out,
            format_args!(
                "every run failed ({failed}); {} holds no predictions",
                a.out.display()
            ),
        )?;
        return Err(e.into());
    }
    if outside > 0 {
        let what = match (&bound.fallback, bound.kind_name()) {
            (Some(f), _) => format!(
                "outside the calibrated region: their bounds (and, where the start is \
                 outside, the whole run's position bounds) are the larger of the conformal \
                 and the {} bound",
                f.kind_name()
            ),
            (None, "conformal") => format!(
                "outside the calibrated region: the conformal guarantee does not cover them{}",
                if learned.gp().is_sparse() {
                    " (a sparse GP has no rigorous bound to fall back to)"
                } else {
                    ""
                }
            ),
            _ => {
                "outside the box of the training inputs, where the bound's constants were estimated"
                    .into()
            }
        };
        w(
            out,
            format_args!("note: {outside} predicted states in {outside_runs} run(s) lie {what}"),
        )?;
    }
    w(
        out,
        format_args!(
            "wrote {}: {} runs × {} steps ({failed} failed); {} bound, probability ≥ {}: `bound` \
             bounds ‖v − v_true‖ of each predicted velocity (one step from the predicted state), \
             `position_bound` ‖q_k − q_true,k‖ along the prediction",
            a.out.display(),
            starts.len() - failed,
            a.steps,
            bound.kind_name(),
            1.0 - a.delta
        ),
    )
}

fn export<M, const N: usize, const C: usize>(
    a: &ExportArgs,
    learned: &Learned<M, N, C>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Clone,
{
    let opts = EmbeddedExport {
        name: a.name.clone(),
        core_path: a.core_path.clone(),
        variance: a.variance,
        header: vec![format!(
            "exported by `vigp export` from {}",
            a.model.file_name().map_or_else(
                || a.model.display().to_string(),
                |f| f.to_string_lossy().into()
            )
        )],
    };
    check_out_dir(&a.out)?;
    let (src, size) = learned.to_embedded_source(&opts)?;
    let sparse = learned.gp().is_sparse();
    std::fs::write(&a.out, &src).map_err(io_error(&a.out))?;
    w(
        out,
        format_args!(
            "wrote {}: {} GPs on {} = {} {}points, d = {} inputs{}: {} numbers = {} bytes of f64 \
             data ({}), {} bytes of source",
            a.out.display(),
            size.outputs,
            if sparse { "M" } else { "N" },
            size.n,
            if sparse { "inducing " } else { "" },
            size.input_dim,
            if learned.inputs() > 0 {
                format!(
                    " (state, then control inputs {}{})",
                    M::INPUT_NAMES[..learned.inputs().min(M::INPUT_NAMES.len())].join(", "),
                    if learned.takes_previous_input() {
                        ", previous then current"
                    } else {
                        ""
                    }
                )
            } else {
                String::new()
            },
            size.numbers,
            size.data_bytes,
            if a.variance {
                "mean and variance"
            } else if sparse {
                "mean only: a sparse model exports no variance"
            } else {
                "mean only; --variance adds the Cholesky factors"
            },
            size.source_bytes
        ),
    )
}
