//! The command line: clap's structures of the commands and their options.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::data::ReadOptions;

#[derive(Parser, Debug)]
#[command(
    name = "vigp",
    version,
    about = "Structure-preserving learned dynamics: fit a GP-augmented variational integrator to measured trajectories, score it, predict with bounds, export it for firmware."
)]
pub(super) struct Cli {
    #[command(subcommand)]
    pub(super) command: Command,
}

#[derive(Subcommand, Debug, Clone)]
pub(super) enum Command {
    /// Train a learned model on measured trajectories and save it.
    Fit(FitArgs),
    /// k-step position MSE of the learned and the nominal model on held-out runs.
    Score(ScoreArgs),
    /// Learned trajectories from the start of every run, with one-step bounds.
    Predict(PredictArgs),
    /// Rust source of the learned model for no_std firmware.
    Export(ExportArgs),
    /// A log CSV of the nominal model from a start state under planned inputs.
    Simulate(SimulateArgs),
    /// Physical parameters (masses, inertias, damping, springs) from a log.
    Identify(IdentifyArgs),
    /// An input plan (a Fourier series per input) that excites the mechanism for `identify`.
    Excite(ExciteArgs),
}

/// What a command runs on: a mechanism given on the command line, or the
/// mechanism that a saved model file names.
#[derive(Clone, Copy, Debug)]
pub(super) enum Target<'a> {
    /// `fit`, `simulate`, `identify`, `excite`: `--system` or `--urdf`.
    Mechanism(&'a MechanismArgs),
    /// `score`, `predict`, `export`: the `--model` file.
    Model(&'a std::path::Path),
}

impl Command {
    /// What the command runs on.
    pub(super) fn target(&self) -> Target<'_> {
        match self {
            Command::Fit(FitArgs { mechanism, .. })
            | Command::Simulate(SimulateArgs { mechanism, .. })
            | Command::Identify(IdentifyArgs { mechanism, .. })
            | Command::Excite(ExciteArgs { mechanism, .. }) => Target::Mechanism(mechanism),
            Command::Score(ScoreArgs { model, .. })
            | Command::Predict(PredictArgs { model, .. })
            | Command::Export(ExportArgs { model, .. }) => Target::Model(model),
        }
    }
}

/// The mechanism of `fit`, `simulate`, `identify` and `excite`: a
/// registered one by name, or a robot loaded from URDF at run time.
#[derive(Args, Debug, Clone, Default)]
pub(super) struct MechanismArgs {
    /// The mechanism (with several registered; case and `_` do not matter).
    #[arg(long)]
    pub(super) system: Option<String>,
    /// A robot from a URDF file instead of `--system`: its joints with a
    /// coordinate (revolute, continuous, prismatic; fixed joints merged)
    /// are the log's columns, stepped by the linear-time tree engine.
    #[arg(long, value_name = "FILE", conflicts_with = "system")]
    pub(super) urdf: Option<PathBuf>,
    /// With `--urdf`: the actuated joints, in input order (columns
    /// `u_<joint>`; comma-separated).
    #[arg(long, value_name = "JOINTS", value_delimiter = ',', requires = "urdf")]
    pub(super) actuated: Vec<String>,
}

/// How the nominal model steps (`score`, `simulate`).
#[derive(Args, Debug, Clone)]
pub(super) struct StepArgs {
    /// Sub-steps of every nominal step (h = dt / K): a more accurate
    /// nominal model.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub(super) substeps: usize,
    /// A nominal step whose Newton solve fails, or whose root is not the
    /// continuation of the motion, is retaken with its sub-step halved, up
    /// to D times, before it is an error; the output says how many steps
    /// did. 0: every failure is an error at once.
    #[arg(long, default_value_t = 8, value_name = "D")]
    pub(super) max_subdivision: u32,
}

impl StepArgs {
    /// The nominal integrator of `model` at `dt` with these settings.
    pub(super) fn integrator<M: crate::Mechanism<N, C> + Clone, const N: usize, const C: usize>(
        &self,
        model: M,
        dt: f64,
    ) -> Result<crate::Variational<M, N, C>, crate::StepError> {
        Ok(crate::Variational::new(model, dt)?
            .substeps(self.substeps)?
            .max_subdivision(self.max_subdivision))
    }
}

/// How data files are read.
#[derive(Args, Debug, Clone)]
pub(super) struct ReadArgs {
    /// Resample uneven runs onto this time step (s) by linear interpolation.
    #[arg(long, value_name = "DT", allow_negative_numbers = true)]
    pub(super) resample: Option<f64>,
    /// Do not unwrap angle coordinates.
    #[arg(long)]
    pub(super) no_unwrap: bool,
    /// Accepted deviation of a time step from its run's median step
    /// (relative), on top of the rounding of the printed timestamps.
    #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true)]
    pub(super) time_tolerance: f64,
    /// Drop readings that imply an implausible speed (sensor spikes) and
    /// split their runs there, instead of refusing the file; the count is
    /// printed.
    #[arg(long)]
    pub(super) drop_outliers: bool,
    /// The largest plausible speed of any coordinate (rad/s or m/s);
    /// default: from the data's own extent.
    #[arg(long, value_name = "SPEED", allow_negative_numbers = true)]
    pub(super) max_speed: Option<f64>,
}

impl ReadArgs {
    pub(super) fn options(&self) -> ReadOptions {
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
pub(super) enum EncodingArg {
    /// Angles as (sin, cos), minimal coordinates.
    Sincos,
    /// Minimal coordinates as they are.
    Minimal,
    /// Maximal coordinates (x, y, θ of every link), projected onto the joints
    /// (planar mechanisms only).
    Maximal,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(super) enum BoundArg {
    /// Split conformal prediction on held-out runs (`--calibration`): coverage ≥ 1 − δ of a new
    /// case exchangeable with them; falls back to the RKHS bound outside their region.
    Conformal,
    /// The paper's Theorem 1 (the true map is a sample of the fitted GP), uniform over a box.
    Theorem1,
    /// The RKHS-norm bound of Fiedler et al. (2021), uniform over all inputs.
    Rkhs,
}

/// The prior of `fit`: `nominal`, `constant` or `identified:FILE`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) enum PriorArg {
    /// The nominal variational step (the GP learns the residual).
    Nominal,
    /// No model: a constant mean.
    Constant,
    /// The nominal step with the parameters of a `vigp identify` file.
    Identified(PathBuf),
}

impl std::str::FromStr for PriorArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "nominal" => Ok(PriorArg::Nominal),
            "constant" => Ok(PriorArg::Constant),
            _ => match s.strip_prefix("identified:") {
                Some(path) if !path.is_empty() => Ok(PriorArg::Identified(path.into())),
                _ => Err(format!(
                    "`{s}`: expected nominal, constant or identified:FILE (a file of `vigp identify`)"
                )),
            },
        }
    }
}

/// The discrete Euler–Lagrange rule of `identify`'s regression.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(super) enum RuleArg {
    /// The midpoint rule: on samples of a continuous motion its bias is
    /// O(Δt²).
    Midpoint,
    /// The first-order rule of `fit`'s nominal model: exact on logs that
    /// this rule wrote, biased by O(Δt) on others.
    FirstOrder,
}

/// How `identify` treats the positions' noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(super) enum NoiseArg {
    /// Least squares: right for noise-free logs, biased under noise.
    Ls,
    /// Instrumental variables from local polynomial fits that leave each
    /// transition's own samples out.
    Iv,
    /// Bias-compensated least squares for independent position noise of
    /// the size `--noise-sigma` gives: for logs of short runs, where the
    /// instruments have no neighbours.
    Eiv,
}

#[derive(Args, Debug, Clone)]
pub(super) struct IdentifyArgs {
    #[command(flatten)]
    pub(super) mechanism: MechanismArgs,
    /// The log (CSV: run,t,<coordinates>[,u_<joint>…], as for `fit`).
    #[arg(long)]
    pub(super) data: PathBuf,
    /// Where to write the identified parameters (JSON; `fit --prior
    /// identified:FILE` reads it).
    #[arg(long)]
    pub(super) out: PathBuf,
    /// The discrete Euler–Lagrange rule of the regression [default:
    /// midpoint; a robot from `--urdf`: first-order, the rule of the tree
    /// engine that `simulate` and `fit` step with (give midpoint for logs
    /// of a real robot)].
    #[arg(long, value_enum)]
    pub(super) rule: Option<RuleArg>,
    /// The treatment of position noise (runs shorter than the instruments'
    /// 19-sample window enter by least squares; the output says how many
    /// transitions had instruments).
    #[arg(long, value_enum, default_value = "iv")]
    pub(super) noise: NoiseArg,
    /// The standard deviation of every logged position's noise (the log's
    /// units), which `--noise eiv` needs.
    #[arg(long)]
    pub(super) noise_sigma: Option<f64>,
    /// Refine the regression by output error: the log simulated in
    /// segments of SAMPLES samples (default 50), their initial positions
    /// estimated with the parameters. Unbiased under position noise; loops
    /// are simulated with their multipliers.
    #[arg(long, value_name = "SAMPLES", num_args = 0..=1, default_missing_value = "50")]
    pub(super) output_error: Option<usize>,
    /// The prior's standard deviation around the declared values, relative
    /// to each parameter's scale (its weight against the data vanishes as
    /// the log grows).
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true)]
    pub(super) prior_sd: f64,
    /// Change a declared parameter (the prior's centre), e.g. `--set
    /// links.pole.mass=1.1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub(super) set: Vec<String>,
    #[command(flatten)]
    pub(super) read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
pub(super) struct FitArgs {
    #[command(flatten)]
    pub(super) mechanism: MechanismArgs,
    /// Training data (CSV: run,t,<coordinates>[,u_<joint>…]; row k's input is
    /// held from t_k to t_{k+1}, so the step from row k to row k + 1 is
    /// driven by row k + 1's input).
    #[arg(long)]
    pub(super) data: PathBuf,
    /// Where to save the model (JSON).
    #[arg(long)]
    pub(super) out: PathBuf,
    /// GP input coordinates.
    #[arg(long, value_enum, default_value = "sincos")]
    pub(super) encoding: EncodingArg,
    /// Prior of the velocity map: `nominal` (the declared parameters),
    /// `constant`, or `identified:FILE` (the nominal step with the
    /// parameters of a `vigp identify` file; `--set` still overrides).
    #[arg(long, default_value = "nominal", value_name = "PRIOR")]
    pub(super) prior: PriorArg,
    /// Random restarts of the hyperparameter optimisation (besides the first start).
    #[arg(long, default_value_t = 5)]
    pub(super) restarts: usize,
    /// Seed of the restarts.
    #[arg(long, default_value_t = 0)]
    pub(super) seed: u64,
    /// Curvature pairs of the L-BFGS-B optimiser (scipy's `maxcor`, 10 by
    /// default). A memory of at least d + 2 (d GP inputs) needs fewer
    /// likelihood evaluations on many inputs, e.g. `--encoding maximal`
    /// (3 per link, doubled with velocities): 30 cut those on all 512
    /// samples by 30 % in the paper's evaluation.
    #[arg(long, default_value_t = 10, value_name = "K")]
    pub(super) memory: usize,
    /// Largest number of training transitions (evenly spaced over the data);
    /// default 512 for the exact GP, every transition with `--sparse`.
    #[arg(long)]
    pub(super) max_samples: Option<usize>,
    /// Train Titsias' sparse variational GP with M inducing points
    /// (k-means++ on the inputs) instead of the exact GP: O(N·M²) per
    /// likelihood evaluation instead of O(N³), so long logs can be used
    /// whole. Its noise variance is kept at or above 1e-6 (normalised
    /// units: noise-free logs fit far better than at the exact GP's 1e-10).
    /// `predict` bounds such a model with the conformal bound only
    /// (`--calibration`; Theorem 1 and RKHS assume the exact GP), and
    /// `export` writes its mean (M inducing points), not its variance.
    #[arg(long, value_name = "M")]
    pub(super) sparse: Option<usize>,
    /// With `--sparse`: after the hyperparameter starts, move the inducing
    /// points together with the hyperparameters to raise the variational
    /// bound (one L-BFGS run over M·d + outputs·(d + 2) variables, up to
    /// 500 iterations; each costs about one bound evaluation per output).
    #[arg(long, requires = "sparse")]
    pub(super) optimise_inducing: bool,
    /// Run every start of the exact GP on all training transitions. By
    /// default, from 512 transitions on, the starts run first on a random
    /// subset and only the distinct optima found there are refined on all
    /// of them (several times faster, the same optimum on the data sets
    /// checked; `vigp::gp::Screening`).
    #[arg(long, conflicts_with = "sparse")]
    pub(super) no_screen: bool,
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
    pub(super) noise_floor: Option<f64>,
    /// Change a nominal parameter, e.g. `--set links.pole.mass=1.1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub(super) set: Vec<String>,
    #[command(flatten)]
    pub(super) read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
pub(super) struct ScoreArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    pub(super) model: PathBuf,
    /// Held-out data (CSV: run,t,<coordinates>).
    #[arg(long)]
    pub(super) data: PathBuf,
    /// Prediction horizon k.
    #[arg(long, default_value_t = 20)]
    pub(super) steps: usize,
    #[command(flatten)]
    pub(super) stepping: StepArgs,
    #[command(flatten)]
    pub(super) read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
pub(super) struct PredictArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    pub(super) model: PathBuf,
    /// Start states: the first two rows of every run, or with `--stride`
    /// rows s and s + 1 for s = 0, k, 2k, …. An actuated mechanism's runs
    /// also give the inputs of the predicted steps (rows s + 1 to
    /// s + `--steps`; row k's input is held from t_k to t_{k+1}, so the step
    /// from row k to row k + 1 is driven by row k + 1's input), unless
    /// `--inputs` gives them.
    #[arg(long)]
    pub(super) data: PathBuf,
    /// Start a prediction every k samples of every run (each needs its two
    /// start rows, and without `--inputs` the inputs of the `--steps` rows
    /// after its first); the output then has a `start` column, the start's
    /// sample. Default: one prediction from each run's first two rows.
    #[arg(long, value_name = "K")]
    pub(super) stride: Option<usize>,
    /// Planned inputs instead of the logged ones: a CSV with one column
    /// `u_<joint>` per input (any order; an optional `run` column gives each
    /// run of `--data` its own plan; a `t` column is ignored), no
    /// positions. Its row j drives the predicted step j + 1, from output row
    /// j to j + 1 (held from t_{s+j+1} to t_{s+j+2}); the start row's own
    /// input in `--data` is the one held over the start's velocity. It
    /// needs `--steps` rows.
    #[arg(long, value_name = "PLAN")]
    pub(super) inputs: Option<PathBuf>,
    /// Steps to predict.
    #[arg(long)]
    pub(super) steps: usize,
    /// Output CSV: run,[start,]t,<coordinates>,v_<coordinate>…,[u_<joint>…,]bound,position_bound
    /// (conformal: then `fallback`, the rigorous kind a row's bounds fell back to, or empty).
    #[arg(long)]
    pub(super) out: PathBuf,
    /// Failure probability δ of the bounds.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
    pub(super) delta: f64,
    /// Kind of error bound [default: conformal with `--calibration`, rkhs without].
    #[arg(long, value_enum)]
    pub(super) bound: Option<BoundArg>,
    /// Held-out runs (same CSV format as `--data`, not used for training) that calibrate the
    /// conformal bound over `--steps`-step windows; the rigorous kinds use their start states
    /// to estimate Lipschitz constants.
    #[arg(long)]
    pub(super) calibration: Option<PathBuf>,
    #[command(flatten)]
    pub(super) read: ReadArgs,
}

#[derive(Args, Debug, Clone)]
pub(super) struct ExportArgs {
    /// A model saved by `vigp fit`.
    #[arg(long)]
    pub(super) model: PathBuf,
    /// The Rust file to write.
    #[arg(long)]
    pub(super) out: PathBuf,
    /// Also export the Cholesky factors (posterior variances; N(N+1)/2 numbers per output).
    #[arg(long)]
    pub(super) variance: bool,
    /// Name of the generated `LearnedModel` static.
    #[arg(long, default_value = "LEARNED")]
    pub(super) name: String,
    /// Path of vigp's no_std core in the generated code.
    #[arg(long, default_value = "vigp::embedded")]
    pub(super) core_path: String,
}

#[derive(Args, Debug, Clone)]
pub(super) struct SimulateArgs {
    #[command(flatten)]
    pub(super) mechanism: MechanismArgs,
    /// Start positions, one per coordinate in the log's column order
    /// (comma-separated).
    #[arg(
        long,
        value_name = "Q",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub(super) q: Vec<f64>,
    /// Start discrete velocities (x_1 − x_0)/Δt [default: zeros].
    #[arg(
        long,
        value_name = "V",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub(super) v: Vec<f64>,
    /// Time step (s).
    #[arg(long, allow_negative_numbers = true)]
    pub(super) dt: f64,
    /// Steps to simulate; the log has `--steps` + 2 rows.
    #[arg(long)]
    pub(super) steps: usize,
    #[command(flatten)]
    pub(super) stepping: StepArgs,
    /// Planned inputs (the input-only CSV of `predict --inputs`, without a
    /// `run` column): row j drives step j, written on log row j + 1;
    /// default zero inputs. Log row 0 holds zero (the start is taken as
    /// reached under no input).
    #[arg(long, value_name = "PLAN")]
    pub(super) inputs: Option<PathBuf>,
    /// Label of the run in the log.
    #[arg(long, default_value = "sim")]
    pub(super) run: String,
    /// Time of the first row (s).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(super) t0: f64,
    /// Change a nominal parameter, e.g. `--set links.pole.mass=1.1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub(super) set: Vec<String>,
    /// The log to write (CSV: run,t,<coordinates>[,u_<joint>…]).
    #[arg(long)]
    pub(super) out: PathBuf,
}

#[derive(Args, Debug, Clone)]
pub(super) struct ExciteArgs {
    /// The mechanism, or a robot from URDF, its design kept within the
    /// URDF's joint position and velocity limits.
    #[command(flatten)]
    pub(super) mechanism: MechanismArgs,
    /// Length of the experiment (s); also the period of the inputs.
    #[arg(long, allow_negative_numbers = true)]
    pub(super) duration: f64,
    /// Time step (s) of the log to identify from.
    #[arg(long, allow_negative_numbers = true)]
    pub(super) dt: f64,
    /// Harmonics L of each input's Fourier series.
    #[arg(long, default_value_t = 4)]
    pub(super) harmonics: usize,
    /// The largest |u| per input (one value for all, or one per input,
    /// comma-separated).
    #[arg(
        long,
        value_name = "U",
        value_delimiter = ',',
        allow_hyphen_values = true,
        required = true
    )]
    pub(super) amplitude: Vec<f64>,
    /// Start positions, at rest (comma-separated) [default: zeros].
    #[arg(
        long,
        value_name = "Q",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub(super) q: Vec<f64>,
    /// The discrete Euler–Lagrange rule of the regression (and of a
    /// declared mechanism's simulation) [default: midpoint; a robot from
    /// `--urdf`: first-order, the rule of the tree engine that simulates
    /// the design].
    #[arg(long, value_enum)]
    pub(super) rule: Option<RuleArg>,
    /// Random inputs tried before the optimisation starts from the best.
    #[arg(long, default_value_t = 8)]
    pub(super) starts: usize,
    /// Seed of the random inputs.
    #[arg(long, default_value_t = 0)]
    pub(super) seed: u64,
    /// Change a declared parameter, e.g. `--set links.pole.mass=1.1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub(super) set: Vec<String>,
    /// Where to write the plan (CSV: t,u_<joint>…; the format of
    /// `simulate --inputs`).
    #[arg(long)]
    pub(super) out: Option<PathBuf>,
}
