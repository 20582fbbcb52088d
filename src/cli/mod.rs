//! The `vigp` command-line tool, for the paper's systems, the 3-D examples
//! of [`crate::systems::spatial`] and your own mechanism, planar or 3-D
//! (feature `cli`). A 3-D mechanism is learned in its minimal coordinates
//! (joint angles and slides; a ball joint's unit quaternion as four columns
//! `<joint>.w`, `.x`, `.y`, `.z`; velocities differenced as for every
//! coordinate, [`crate::data`]); its maximal view (each link's position and
//! orientation) is learned in Rust with
//! `vigp::spatial::learned::LearnedSpatial`.
//!
//! ```text
//! vigp fit     --system NAME --data train.csv --out model.json
//!              [--encoding sincos|minimal|maximal] [--prior nominal|constant|identified:FILE] [--restarts K]
//!              [--max-samples N] [--no-screen | --sparse M [--optimise-inducing]]
//!              [--noise-floor VAR] [--memory K]
//! vigp score   --model model.json --data test.csv --steps 20 [--substeps K] [--max-subdivision D]
//! vigp predict --model model.json --data starts.csv --steps K --out pred.csv
//!              [--stride K] [--inputs plan.csv] [--calibration held_out.csv]
//! vigp export  --model model.json --out model.rs [--variance]
//! vigp simulate --system NAME --q Q,… [--v V,…] --dt DT --steps K
//!              [--inputs plan.csv] [--substeps K] [--max-subdivision D] --out log.csv
//! vigp identify --system NAME --data log.csv --out params.json
//!              [--rule midpoint|first-order] [--noise ls|iv] [--prior-sd S]
//! vigp excite  --system NAME --duration T --dt DT --amplitude U[,…] [--harmonics L]
//!              [--q Q,…] [--out plan.csv]
//! ```
//!
//! A robot from a URDF file takes `--urdf robot.urdf [--actuated j1,j2]`
//! instead of `--system` in `simulate`, `identify`, `excite` and `fit`;
//! `score`, `predict` and `export` read the model `fit` wrote for it. The log's columns are the robot's
//! joints with a coordinate (file depth-first order) and `u_<joint>` per
//! actuated joint; the steps are the tree engine's (`vigp::Robot`), the
//! identification its first-order residual
//! ([`crate::identify::RobotRegressor`]), the model a
//! [`crate::learned::robot::LearnedRobot`] (by default: `--rule` changes
//! the identification's). `predict` of a learned robot's model attaches
//! the conformal bound (`--calibration` required); `export` writes it for
//! `vigp::embedded::tree::LearnedTreeStepper`; `excite --urdf` keeps its
//! design within the URDF's joint limits.
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
//!   a planar mechanism in maximal coordinates (each link's x, y, θ;
//!   projected onto the joint constraints; refused for a 3-D mechanism,
//!   [`CliError::SpatialMaximal`]).
//! * `score` is the paper's k-step prediction error: from every sample s of
//!   every run with k + 1 more samples after it, k steps of the learned
//!   model and of the nominal variational integrator, position MSE in
//!   minimal coordinates averaged over the positions the steps produce
//!   (x_{s+2} … x_{s+k+1}: x_{s+1} = x_s + Δt·v_s is the logged sample
//!   itself) and over the windows. Its last line is
//!   `nominal_mse=<x> learned_mse=<y>`.
//! * `predict` rolls the learned model out from the first two rows of every
//!   run (position and discrete velocity; `--stride k`: from every k-th
//!   sample) and writes the trajectories with
//!   each predicted velocity's one-step error bound and each position's
//!   bound along the prediction (`--bound conformal|rkhs|theorem1`;
//!   conformal with `--calibration`, RKHS without; δ = `--delta`); a
//!   conformal prediction's `fallback` column marks the rows whose bounds
//!   fell back to the RKHS bound, and its summary states what the
//!   guarantee covers (marginal over start states, per step, at 1 − δ).
//! * `simulate` rolls the nominal model out from `--q`/`--v` under planned
//!   (`--inputs`) or zero inputs and writes a log in the data format,
//!   each input on the row the reader expects.
//! * `identify` estimates the physical parameters (masses, centres of
//!   mass, inertias, joint damping and springs) from a log by regression on
//!   the discrete Euler–Lagrange residual ([`crate::identify`]), prints
//!   the table of identifiable combinations with their 95 % intervals, and
//!   writes a parameter file; `fit --prior identified:FILE` then trains the
//!   GP on what the identified model leaves.
//! * `excite` designs an input plan for `identify`: a Fourier series per
//!   input that maximises the regressor's information about the base
//!   parameters within the amplitude ([`crate::identify::excitation`]),
//!   prints its log det against a random input's, and writes it in the
//!   format of `simulate --inputs`.
//! * `export` writes the Rust source of a `no_std` learned model for
//!   [`crate::embedded::LearnedStepper`] and states its size.
//!
//! An actuated mechanism's data carry one `u_<joint>` column per input
//! ([`crate::data`]): `fit` learns on state and input (the GP's inputs are
//! the encoded state, then the previous and the current input; the prior is
//! the forced nominal step),
//! `score` rolls both models out under the logged inputs, `export` writes
//! a model that steps under u, and `predict` predicts under the inputs
//! logged in each run (the run needs `--steps` + 1 rows) or planned in an
//! input-only CSV (`--inputs`, columns `u_<joint>`) with the bound of
//! [`crate::learned::Learned::predict_forced`] (conformal: the held-out
//! runs of `--calibration` carry their inputs too).
//!
//! The row convention of inputs, everywhere: row k's input is held from
//! t_k to t_{k+1}, so the step from row k to row k + 1 is driven by row
//! k + 1's input (`fit` warns when the inputs fit the data markedly better
//! shifted by one row).
//!
//! Your own mechanism, planar or 3-D (`gravity: [gx, gy, gz]`), gets the
//! same tool from one line:
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

mod args;
mod excite;
mod export;
mod fit;
mod identify;
mod predict;
mod registry;
mod robot;
mod score;
mod simulate;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};

use crate::bound::BoundError;
use crate::data::{DataError, Dataset};
use crate::gp::GpError;
use crate::learned::{LearnError, Learned, LoadError, SavedLearned};
use crate::{Mechanism, Parameters, SVector, StepError, System};

use args::{Cli, ReadArgs, Target};
pub use registry::{SystemEntry, paper_systems, spatial_systems, system};
use registry::{find, names};

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
    /// A 3-D mechanism's maximal view was asked for (`fit --encoding
    /// maximal`): the tool learns a 3-D mechanism in its minimal
    /// coordinates only.
    #[error(
        "{mechanism} is a 3-D mechanism: {what} is not available; the tool learns a 3-D \
         mechanism in its minimal coordinates (--encoding sincos or minimal), and its maximal \
         view (each link's position and orientation) in Rust with \
         vigp::spatial::learned::LearnedSpatial"
    )]
    SpatialMaximal {
        /// The mechanism.
        mechanism: &'static str,
        /// What was asked for.
        what: &'static str,
    },
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
    // a robot from URDF, or a model of one, runs on the tree engine
    let target = cli.command.target();
    let on_robot = match target {
        Target::Mechanism(mechanism) => mechanism.urdf.is_some(),
        Target::Model(model) => robot::is_robot_model(model),
    };
    if on_robot {
        return robot::run(&cli.command, out);
    }
    let entry = match target {
        Target::Mechanism(mechanism) => match &mechanism.system {
            Some(name) => find(systems, name)?,
            None if systems.len() == 1 => systems[0],
            None => {
                return Err(CliError::Usage(format!(
                    "--system is needed: one of {}",
                    names(systems)
                )));
            }
        },
        Target::Model(model) => {
            let saved = read_saved(model)?;
            find(systems, &saved.mechanism)?
        }
    };
    (entry.run)(&cli.command, out)
}

fn read_saved(path: &Path) -> Result<SavedLearned, CliError> {
    SavedLearned::read(path).map_err(|source| CliError::Model {
        path: path.to_path_buf(),
        source,
    })
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

/// Reads a log of mechanism `M` ([`read_data`]) and its runs' common time
/// step.
fn read_log<M: Mechanism<N, C>, const N: usize, const C: usize>(
    path: &Path,
    read: &ReadArgs,
) -> Result<(Dataset<N>, f64), CliError> {
    let data = read_data(path, &M::COORDINATES, &M::KINDS, M::INPUT_NAMES, read)?;
    let dt = data.dt(read.time_tolerance).map_err(data_error(path))?;
    Ok((data, dt))
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
    report_read(path, &data.warnings, &data.dropped);
    Ok(data)
}

/// The unit heuristics that fired and the outliers dropped while reading
/// `path`: on stderr, the results stay on stdout.
fn report_read(
    path: &Path,
    warnings: &[crate::data::DataWarning],
    dropped: &[crate::data::Dropped],
) {
    for warning in warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
    if let Some(first) = dropped.first() {
        eprintln!(
            "note: {}: dropped {} outlier reading(s) (--drop-outliers), the first at run `{}`, line {}, column `{}`",
            path.display(),
            dropped.len(),
            first.run,
            first.line,
            first.column
        );
    }
}

/// ", sparse GP, M = …" for a sparse model, "" for an exact one.
fn sparse_note(gp: &crate::gp::Gp) -> String {
    if gp.is_sparse() {
        format!(", sparse GP, M = {}", gp.posterior_points())
    } else {
        String::new()
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
/// the maximal ones (`maximal`: their names; `None` for a 3-D mechanism,
/// whose maximal view the tool does not take); an error naming both when
/// in neither (an edited or corrupted file), rather than a complaint
/// against one of them.
fn in_minimal<Mn: Mechanism<N, C>, const N: usize, const C: usize>(
    path: &Path,
    saved: &SavedLearned,
    maximal: Option<&[&'static str]>,
) -> Result<bool, CliError> {
    if saved.coordinates == Mn::COORDINATES {
        return Ok(true);
    }
    let found = format!(
        "{}: field `coordinates`: [{}] are",
        path.display(),
        saved.coordinates.join(", ")
    );
    match maximal {
        Some(mx) if saved.coordinates == mx => Ok(false),
        Some(mx) => Err(CliError::Usage(format!(
            "{found} neither the minimal coordinates [{}] nor the maximal ones [{}] of {}",
            Mn::COORDINATES.join(", "),
            mx.join(", "),
            saved.mechanism
        ))),
        None => Err(CliError::Usage(format!(
            "{found} not the minimal coordinates [{}] of {}, a 3-D mechanism, whose models the \
             tool takes in minimal coordinates only",
            Mn::COORDINATES.join(", "),
            saved.mechanism
        ))),
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

/// A robot's state at sample `s` of `run`, with the log's common time
/// step `dt` ([`RobotState::from_positions`](crate::robot::RobotState::from_positions)).
fn robot_state_at(run: &crate::data::DynRun, s: usize, dt: f64) -> crate::robot::RobotState {
    let (q0, q1) = (&run.positions[s], &run.positions[s + 1]);
    crate::robot::RobotState::from_positions(q0.as_slice(), q1.as_slice(), dt)
}

/// Where a window from sample `s` of `run` starts: the run, the sample and
/// its file line (not for a resampled run, whose samples have none).
fn window_place<P>(run: &crate::data::RunOf<P>, s: usize, resampled: bool) -> String {
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

/// A model of `found` inputs for a mechanism of `U`: a usage error naming
/// the model file (`score` and `predict`).
fn check_model_inputs<const U: usize>(model: &Path, found: usize) -> Result<(), CliError> {
    if found == U {
        return Ok(());
    }
    Err(CliError::Usage(format!(
        "{}: the model takes {found} input(s), the mechanism has {U}{}",
        model.display(),
        if U > 0 {
            " (fit it with the input columns: `vigp fit` on data with `u_<joint>`)"
        } else {
            ""
        }
    )))
}

/// An input-only CSV of planned inputs (`predict --inputs`, `simulate
/// --inputs`): one column `u_<joint>` per input, an optional `run` column
/// (rows of one run contiguous), an ignored `t` column. Each plan in file
/// order, with its run label (`None` without a `run` column).
type Plans<const U: usize> = Vec<(Option<String>, Vec<SVector<f64, U>>)>;

/// [`Plans`] of an input count known at run time: each row a vector.
type PlanRows = Vec<(Option<String>, Vec<Vec<f64>>)>;

fn read_plan<const U: usize>(path: &Path, inputs: &[&str]) -> Result<Plans<U>, CliError> {
    Ok(read_plan_rows(path, &inputs[..U.min(inputs.len())])?
        .into_iter()
        .map(|(run, rows)| {
            let us = rows.iter().map(|u| SVector::from_column_slice(u)).collect();
            (run, us)
        })
        .collect())
}

/// [`read_plan`] for an input count known at run time (`inputs.len()`):
/// each plan's rows as vectors.
fn read_plan_rows(path: &Path, inputs: &[&str]) -> Result<PlanRows, CliError> {
    let bad = |why: String| CliError::Usage(format!("{}: {why}", path.display()));
    let u_count = inputs.len();
    if u_count == 0 {
        return Err(bad(
            "the mechanism has no inputs (no `actuated` joint): nothing to plan".into(),
        ));
    }
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| bad(e.to_string()))?;
    let header = rdr.headers().map_err(|e| bad(e.to_string()))?.clone();
    let (mut run_col, mut cols) = (None, vec![None; u_count]);
    for (i, name) in header.iter().enumerate() {
        if name == "t" {
            // times are implied: row j drives step j
            continue;
        }
        if name == "run" {
            run_col = Some(i);
        } else if let Some(j) = inputs.iter().position(|n| format!("u_{n}") == name) {
            if cols[j].replace(i).is_some() {
                return Err(bad(format!("line 1: column `{name}` appears twice")));
            }
        } else {
            return Err(bad(format!(
                "line 1: unknown column `{name}`: a plan has the input columns {} (and may have `run` and `t`), no positions",
                inputs
                    .iter()
                    .map(|n| format!("`u_{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    if let Some(j) = cols.iter().position(Option::is_none) {
        return Err(bad(format!("line 1: missing column `u_{}`", inputs[j])));
    }
    let mut plans: PlanRows = Vec::new();
    for (n, record) in rdr.records().enumerate() {
        let line = n + 2;
        let record = record.map_err(|e| bad(format!("line {line}: {e}")))?;
        let mut u = vec![0.0; u_count];
        for (j, col) in cols.iter().enumerate() {
            let col = col.unwrap_or_default();
            let text = record.get(col).unwrap_or("");
            u[j] = match text.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => {
                    return Err(bad(format!(
                        "line {line}, column `u_{}`: {text:?} is not a finite number",
                        inputs[j]
                    )));
                }
            };
        }
        let run = run_col.map(|c| record.get(c).unwrap_or("").to_string());
        match plans.last_mut() {
            Some((r, us)) if *r == run => us.push(u),
            _ => {
                if plans.iter().any(|(r, _)| *r == run) {
                    return Err(bad(format!(
                        "line {line}: run `{}` reappears after another run",
                        run.unwrap_or_default()
                    )));
                }
                plans.push((run, vec![u]));
            }
        }
    }
    if plans.is_empty() {
        return Err(bad("no input rows".into()));
    }
    Ok(plans)
}

/// The prior's name in the tool's messages: `Nominal`, `Constant` or
/// `Identified` (the identified values are in the model file).
pub(crate) fn prior_name(prior: &crate::learned::Prior) -> &'static str {
    use crate::learned::Prior;
    match prior {
        Prior::Nominal => "Nominal",
        Prior::Constant => "Constant",
        Prior::Identified(_) => "Identified",
    }
}
