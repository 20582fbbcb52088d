//! Measured trajectories in: CSV files of positions, split into runs,
//! checked, and turned into training [`Transition`]s.
//!
//! # File format
//!
//! One header line, then one row per sample:
//!
//! ```text
//! run,t,rail,hinge
//! a,0.00,0.0,3.10
//! a,0.01,0.001,3.13
//! a,0.02,0.003,-3.12
//! b,0.00,0.5,0.0
//! ```
//!
//! * `run`: a label (any non-empty text); the rows of one run are
//!   contiguous. `t`: time in seconds, strictly increasing within a run.
//!   Then one column per coordinate of the mechanism, named as in
//!   `Mechanism::COORDINATES` (joint names for the minimal view), holding
//!   **positions** (rad or m), as the paper's data: velocities are formed as
//!   discrete differences (x_{k+1} − x_k)/Δt, exactly what the learned
//!   integrators need. Columns may come in any order.
//! * A missing coordinate column, an unknown or duplicated column, an empty
//!   run label, a run that reappears after another run, a value that does
//!   not parse, NaN or ±∞: each is a [`DataError`] naming the line (the
//!   file's line number, header = line 1) and the column.
//! * **Uniform time.** Within a run every step t_{k+1} − t_k must equal the
//!   run's median step to within [`ReadOptions::time_tolerance`] (relative,
//!   default 1e-3) plus the rounding of the printed timestamps (four
//!   half-units of their last digit, at most a quarter step); otherwise
//!   [`DataError::NonUniformTime`] names the run and the line that ends the
//!   odd step (a dropped sample is reported at its gap). The run's time step is then the mean step
//!   (t_last − t_first)/(rows − 1); one that no integrator can take (Δt²
//!   not a normal number) is [`DataError::TimeStepOutOfRange`]. Finite
//!   readings whose unwrapped angle or discrete velocity overflows f64 are
//!   [`DataError::Overflow`], with line and column. Resampling
//!   (linear interpolation onto a uniform grid) happens only if asked, with
//!   [`ReadOptions::resample`].
//! * **Angles** (coordinates of kind [`CoordinateKind::Angle`]) are
//!   unwrapped within each run: a jump by more than π between samples is
//!   taken as a wrap (±2π) of an angle sensor's range, so a pendulum logged
//!   in (−π, π] turning past π does not become a 600 rad/s spike. This
//!   assumes |θ̇|·Δt < π (at 100 Hz, below 314 rad/s); turn it off with
//!   [`ReadOptions::unwrap_angles`].
//! * **Outliers.** A reading whose jump from its neighbour implies an
//!   implausible speed is [`DataError::Outlier`], naming run, line and
//!   column. The bound is [`ReadOptions::max_speed`] when set; otherwise an
//!   angle's raw jump beyond 3π (neither a sensor wrap of 2π nor, under the
//!   unwrapping assumption, a motion) or any coordinate's jump beyond twice
//!   the run's extent without its two extreme readings (runs of five or
//!   more samples): one reading of 1e6 or 1e308 in a pendulum's angle
//!   column is refused, not unwrapped to a plausible angle. With
//!   [`ReadOptions::drop_outliers`] a spike's row is dropped instead, its
//!   run split there, and the drop recorded in [`Dataset::dropped`].
//! * **Units.** Angle columns whose readings exceed a turn but stay within
//!   ±400 with implied speeds above 50 rad/s (degrees read as radians),
//!   and integer timestamps a second or more apart (milliseconds read as
//!   seconds), are read as they are and reported in
//!   [`Dataset::warnings`] ([`DataWarning`]). A Δt given to a trainer is
//!   checked against the transitions with [`check_transitions_dt`].
//! * **Short runs.** A run of one or two rows is kept (it is data) but gives
//!   no transition (a transition needs three positions); a run of one row
//!   has no time step. [`Dataset::transitions`] skips them and
//!   [`Dataset::short_runs`] lists them.
//!
//! * **Inputs.** For an actuated mechanism (joints declared `actuated`)
//!   every input has a column `u_<joint>` (torque or force), required when
//!   the mechanism has inputs and refused when it has none. The value on
//!   row k is the input held from t_k to t_{k+1} (zero-order hold; with
//!   [`ReadOptions::resample`] the held value is sampled, not
//!   interpolated). In the variational step from state k to state k+1
//!   the input acts over the interval of the new discrete velocity
//!   v_{k+1} = (x_{k+2} − x_{k+1})/Δt (`vigp_core::forced`), so that step is
//!   driven by row k+1's input: [`Run::step_input`].
//!   [`Dataset::from_rollout`] writes a simulated rollout this way (and
//!   [`Dataset::write_csv`] writes any dataset in this format).

use std::collections::HashSet;
use std::io;
use std::path::{Path, PathBuf};

use nalgebra::{DVector, SVector};

use crate::learned::{ForcedTransition, Transition, time_step};
use crate::mechanism::{CoordinateKind, Mechanism, State};

/// How [`Dataset::read_csv`] reads a file.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadOptions {
    /// Unwrap angle coordinates within each run (default `true`).
    pub unwrap_angles: bool,
    /// Largest accepted deviation of a time step from its run's median step,
    /// relative to that step (default 1e-3), on top of the rounding of the
    /// printed timestamps (four half-units of their last digit, at most a
    /// quarter step): evenly sampled logs pass however few decimals their
    /// timestamps were printed with (a 120 Hz log with t to 3 decimals), a
    /// dropped or duplicated sample (a step off by a whole step) does not.
    pub time_tolerance: f64,
    /// `Some(dt)`: resample every run (at most [`MAX_RESAMPLED`] samples
    /// each, else [`DataError::InvalidOption`]) by linear interpolation onto
    /// t_first + k·dt instead of requiring uniform time (t must still be
    /// strictly increasing). Positions between samples are then
    /// interpolated, which is only as good as the sampling is fine.
    pub resample: Option<f64>,
    /// `Some(v)`: the largest plausible speed, in coordinate units per
    /// second (rad/s, m/s), for every coordinate: a reading whose jump
    /// from its neighbour implies more is an outlier (module docs,
    /// *Outliers*). `None` (default): the bound comes from the data
    /// itself (a jump larger than the run's extent, or an angle jump
    /// that is neither a sensor wrap nor a motion).
    pub max_speed: Option<f64>,
    /// Drop outlier readings instead of refusing the file: the row is
    /// removed, its run split there (the pieces are runs of their own,
    /// named `<run>@<line>` after the first), and each drop is recorded
    /// in [`Dataset::dropped`] (default `false`: [`DataError::Outlier`]).
    pub drop_outliers: bool,
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            unwrap_angles: true,
            time_tolerance: 1e-3,
            resample: None,
            max_speed: None,
            drop_outliers: false,
        }
    }
}

/// A reading removed by [`ReadOptions::drop_outliers`].
#[derive(Clone, Debug, PartialEq)]
pub struct Dropped {
    /// The run it belonged to.
    pub run: String,
    /// Its file line.
    pub line: u64,
    /// The coordinate whose jump exposed it.
    pub column: String,
    /// The reading.
    pub value: f64,
}

/// Something in the data that reads but looks like a unit mistake; the
/// reader keeps the data and reports it in [`Dataset::warnings`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DataWarning {
    /// An angle column whose readings look like degrees: values beyond
    /// one turn (2π) but within ±400, with implied speeds above 50 rad/s.
    #[error(
        "column `{column}` holds angles up to {max_abs} and implies speeds up to {max_speed:.0} rad/s: \
         are these degrees? The reader expects radians (multiply by π/180)"
    )]
    LooksLikeDegrees {
        /// The column.
        column: String,
        /// The largest |reading|.
        max_abs: f64,
        /// The largest implied speed |Δx|/Δt, rad/s.
        max_speed: f64,
    },
    /// A run whose time step is 1 or more with integer timestamps.
    #[error(
        "run `{run}`: time step {dt} with integer timestamps: is t in milliseconds? \
         The reader expects seconds (divide t by 1000)"
    )]
    LooksLikeMilliseconds {
        /// The run.
        run: String,
        /// Its time step.
        dt: f64,
    },
}

/// Resampling's zero-order hold takes a logged sample this close (as a
/// fraction of the sampling interval) before a resampled time as at it.
const HOLD_SLACK: f64 = 1e-6;

/// The most samples one run may have after [`ReadOptions::resample`]
/// (10⁷, ≈ 28 h at 10 ms): a resampling step far below the recorded
/// sampling is refused rather than allocated.
pub const MAX_RESAMPLED: usize = 10_000_000;

/// Why a data file could not be read. Lines are the file's line numbers
/// (the header is line 1).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DataError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: io::Error,
    },
    /// The CSV text itself is malformed (e.g. a row with another number of
    /// fields than the header).
    #[error("line {line}: {message}")]
    Csv {
        /// Line of the error.
        line: u64,
        /// The reader's message.
        message: String,
    },
    /// No header, or a header but no data rows.
    #[error("no data: {0}")]
    Empty(&'static str),
    /// A required column is not in the header.
    #[error("missing column `{name}` (the header must hold run, t and {expected})")]
    MissingColumn {
        /// The missing column.
        name: String,
        /// All coordinate names expected.
        expected: String,
    },
    /// A header column that is not run, t or a coordinate.
    #[error("unknown column `{name}` (column {column}); expected run, t and {expected}{hint}")]
    UnknownColumn {
        /// The column's name.
        name: String,
        /// 1-based column index.
        column: usize,
        /// All coordinate names expected.
        expected: String,
        /// A hint for likely mistakes.
        hint: &'static str,
    },
    /// A column name appears twice.
    #[error("column `{name}` appears twice (columns {first} and {second})")]
    DuplicateColumn {
        /// The column's name.
        name: String,
        /// 1-based index of its first appearance.
        first: usize,
        /// 1-based index of its second appearance.
        second: usize,
    },
    /// An empty run label.
    #[error("line {line}: empty run label")]
    EmptyRun {
        /// Line of the row.
        line: u64,
    },
    /// A run's rows are not contiguous.
    #[error(
        "line {line}: run `{run}` appears again after other runs (keep each run's rows together)"
    )]
    RunNotContiguous {
        /// The run.
        run: String,
        /// Line where it reappears.
        line: u64,
    },
    /// A value that is not a number.
    #[error("line {line}, column `{column}`: cannot read {value:?} as a number")]
    Parse {
        /// Line of the row.
        line: u64,
        /// The column's name.
        column: String,
        /// The text found.
        value: String,
    },
    /// NaN or ±∞ in the data (a number beyond f64's range, such as 1e400,
    /// reads as ±∞).
    #[error(
        "line {line}, column `{column}`: {value} is not finite (NaN, ±inf, or a number beyond ±1.8e308)"
    )]
    NonFinite {
        /// Line of the row.
        line: u64,
        /// The column's name.
        column: String,
        /// The value found.
        value: f64,
    },
    /// Time does not increase within a run.
    #[error("run `{run}`, line {line}: t = {t} does not increase (previous {previous})")]
    TimeNotIncreasing {
        /// The run.
        run: String,
        /// Line of the row.
        line: u64,
        /// Its t.
        t: f64,
        /// The previous row's t.
        previous: f64,
    },
    /// A time step differs from the run's median step.
    #[error(
        "run `{run}`, line {line}: time step {found} differs from the run's median step {expected} \
         by more than {tolerance} relative plus the timestamps' printed rounding \
         (missing or repeated samples?); \
         resample if the sampling is truly uneven"
    )]
    NonUniformTime {
        /// The run.
        run: String,
        /// Line of the row that ends the offending step.
        line: u64,
        /// The run's median step.
        expected: f64,
        /// The step found.
        found: f64,
        /// The tolerance in force.
        tolerance: f64,
    },
    /// Finite readings whose derived value overflows f64: an angle
    /// unwrapped across readings ±1e308 apart, or a discrete velocity
    /// (x_{k+1} − x_k)/Δt.
    #[error(
        "run `{run}`, line {line}, column `{column}`: {what} is not finite (readings too far apart for f64)"
    )]
    Overflow {
        /// The run.
        run: String,
        /// Line of the row whose value overflows (for a resampled run,
        /// the run's first line).
        line: u64,
        /// The coordinate's name.
        column: String,
        /// What overflowed.
        what: &'static str,
    },
    /// A reading that implies an implausible speed (module docs,
    /// *Outliers*): a sensor spike, or a jump in the log.
    #[error(
        "run `{run}`, line {line}, column `{column}`: reading {value:e} jumps by {jump:e} from its neighbour \
         (implied speed {speed:.3e} per second, bound {bound:.3e}): a sensor spike or a jump in the log{hint}; \
         ReadOptions::drop_outliers (vigp --drop-outliers) drops such rows and counts them, \
         ReadOptions::max_speed sets the bound"
    )]
    Outlier {
        /// The run.
        run: String,
        /// Line of the reading.
        line: u64,
        /// The coordinate's name.
        column: String,
        /// The reading.
        value: f64,
        /// Its jump from the neighbouring sample (after unwrapping).
        jump: f64,
        /// The implied speed |jump|/Δt.
        speed: f64,
        /// The speed bound in force.
        bound: f64,
        /// A unit hint (degrees) or empty.
        hint: &'static str,
    },
    /// A time step given with the data (to a trainer or a check) that
    /// contradicts the data's timestamps.
    #[error("dt = {given} contradicts the data: {source_of} is sampled every {found} s{hint}")]
    DtContradictsData {
        /// The Δt given.
        given: f64,
        /// Where the data's time step was found (a run, or transitions).
        source_of: String,
        /// Its time step.
        found: f64,
        /// A hint when the two differ by a round factor.
        hint: &'static str,
    },
    /// A run's time step that no integrator can take (Δt² not a normal
    /// number, e.g. timestamps 5e-324 apart).
    #[error(
        "run `{run}`: time step {dt:e} cannot be integrated (dt must be finite and > 0, with dt² a normal number)"
    )]
    TimeStepOutOfRange {
        /// The run.
        run: String,
        /// Its time step.
        dt: f64,
    },
    /// Runs with different time steps, or a time step other than the
    /// model's.
    #[error("run `{run}`: time step {found} differs from {expected} ({what})")]
    TimeStepMismatch {
        /// The run.
        run: String,
        /// Its time step.
        found: f64,
        /// The time step expected.
        expected: f64,
        /// Whose time step is expected.
        what: &'static str,
    },
    /// No run has two rows: there is no time step.
    #[error("no run has two or more rows: the time step is unknown")]
    NoTimeStep,
    /// An option out of its domain.
    #[error("invalid option {what}: {value}")]
    InvalidOption {
        /// Which option.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// [`Dataset::from_rollout`] was given states, inputs or names that do
    /// not make a log (the message says which).
    #[error("not a rollout to log: {0}")]
    Rollout(String),
    /// Transitions with `expected` inputs asked of a dataset read with
    /// `found` input columns.
    #[error("the data has {found} input column(s), {expected} expected")]
    InputCount {
        /// Inputs asked for.
        expected: usize,
        /// Input columns read.
        found: usize,
    },
}

impl From<csv::Error> for DataError {
    fn from(e: csv::Error) -> Self {
        let line = e.position().map_or(0, |p| p.line());
        DataError::Csv {
            line,
            message: e.to_string(),
        }
    }
}

/// One run: uniformly sampled positions, each a `P`
/// ([`Positions`]: a fixed-size vector in [`Run`], a run-time-sized one
/// in [`DynRun`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RunOf<P> {
    /// The run's label.
    pub name: String,
    /// Time of the first sample (s).
    pub t0: f64,
    /// Time step (s); `None` for a run of one row.
    pub dt: Option<f64>,
    /// Positions, one per sample (angles unwrapped).
    pub positions: Vec<P>,
    /// Inputs, one vector (of the dataset's input count) per sample; empty
    /// when the mechanism has no inputs.
    pub inputs: Vec<Vec<f64>>,
    /// File line of the run's first row.
    pub line: u64,
}

/// One run of a mechanism with `N` coordinates.
pub type Run<const N: usize> = RunOf<SVector<f64, N>>;

/// One run of a mechanism whose coordinate count is known at run time (a
/// [`crate::Robot`] loaded from URDF).
pub type DynRun = RunOf<DVector<f64>>;

/// A sample of positions: what the reader needs of a position vector, for
/// fixed-size ([`SVector`]) and run-time-sized ([`DVector`]) vectors alike.
pub trait Positions:
    Clone + core::ops::Index<usize, Output = f64> + core::ops::IndexMut<usize>
{
    /// `n` zeros (`n` is the vector's size for a fixed-size vector).
    fn zeros(n: usize) -> Self;
    /// The entries.
    fn entries(&self) -> &[f64];
    /// (1 − w)·self + w·other.
    fn lerp(&self, other: &Self, w: f64) -> Self;
}

impl<const N: usize> Positions for SVector<f64, N> {
    fn zeros(_: usize) -> Self {
        SVector::zeros()
    }
    fn entries(&self) -> &[f64] {
        self.as_slice()
    }
    fn lerp(&self, other: &Self, w: f64) -> Self {
        self * (1.0 - w) + other * w
    }
}

impl Positions for DVector<f64> {
    fn zeros(n: usize) -> Self {
        DVector::zeros(n)
    }
    fn entries(&self) -> &[f64] {
        self.as_slice()
    }
    fn lerp(&self, other: &Self, w: f64) -> Self {
        self * (1.0 - w) + other * w
    }
}

impl<P> RunOf<P> {
    /// The input that drives the variational step from state `k` (see
    /// [`Run::state`]) to state k+1: the one held over the interval of the
    /// new discrete velocity, i.e. row k+1's (module docs). `None` past the
    /// end or without inputs.
    pub fn step_input(&self, k: usize) -> Option<&[f64]> {
        self.inputs.get(k + 1).map(Vec::as_slice)
    }
}

impl<const N: usize> Run<N> {
    /// The discrete state at sample `k`: (x_k, (x_{k+1} − x_k)/Δt), if the
    /// run has a sample after `k`.
    pub fn state(&self, k: usize) -> Option<State<N>> {
        let dt = self.dt?;
        let (a, b) = (self.positions.get(k)?, self.positions.get(k + 1)?);
        Some(State::from_positions(*a, b, dt))
    }
}

/// Column roles of a header.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Role {
    Run,
    Time,
    Coordinate(usize),
    Input(usize),
}

/// Trajectories read from CSV, each position a `P` ([`Positions`]):
/// [`Dataset`] for a mechanism with `N` coordinates, [`DynDataset`] for a
/// robot loaded at run time.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetOf<P> {
    /// Coordinate names, in the model's order.
    pub coordinates: Vec<String>,
    /// Input names (the actuated joints; columns `u_<name>`), in the
    /// model's order; empty for an unactuated mechanism.
    pub inputs: Vec<String>,
    /// The runs, in file order.
    pub runs: Vec<RunOf<P>>,
    /// Readings dropped as outliers ([`ReadOptions::drop_outliers`]).
    pub dropped: Vec<Dropped>,
    /// Unit heuristics that fired ([`DataWarning`]); the data was read as
    /// it is.
    pub warnings: Vec<DataWarning>,
}

/// Trajectories of a mechanism with `N` coordinates, read from CSV.
pub type Dataset<const N: usize> = DatasetOf<SVector<f64, N>>;

/// Trajectories of a mechanism whose coordinate count is known at run time
/// (a [`crate::Robot`] loaded from URDF), read from CSV.
pub type DynDataset = DatasetOf<DVector<f64>>;

fn join_names(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn header_roles(
    header: &csv::StringRecord,
    names: &[&str],
    inputs: &[&str],
) -> Result<Vec<Role>, DataError> {
    let input_columns: Vec<String> = inputs.iter().map(|n| format!("u_{n}")).collect();
    let all: Vec<&str> = names
        .iter()
        .copied()
        .chain(input_columns.iter().map(String::as_str))
        .collect();
    let expected = join_names(&all);
    let mut roles = Vec::with_capacity(header.len());
    let mut seen: Vec<(&str, usize)> = Vec::new();
    for (i, raw) in header.iter().enumerate() {
        let name = raw.trim();
        if let Some((_, first)) = seen.iter().find(|(n, _)| *n == name) {
            return Err(DataError::DuplicateColumn {
                name: name.into(),
                first: first + 1,
                second: i + 1,
            });
        }
        seen.push((name, i));
        let role = match name {
            "run" => Role::Run,
            "t" => Role::Time,
            _ => match names.iter().position(|n| *n == name) {
                Some(k) => Role::Coordinate(k),
                None if input_columns.iter().any(|c| c == name) => Role::Input(
                    input_columns
                        .iter()
                        .position(|c| c == name)
                        .unwrap_or_default(),
                ),
                None => {
                    let hint = if name.starts_with("u_") && inputs.is_empty() {
                        " (an input column, but the mechanism has no `actuated` joint)"
                    } else if name.starts_with("u_") {
                        " (input columns are `u_<actuated joint>`)"
                    } else if name.is_empty() {
                        " (an empty header field: a trailing comma?)"
                    } else {
                        ""
                    };
                    return Err(DataError::UnknownColumn {
                        name: name.into(),
                        column: i + 1,
                        expected,
                        hint,
                    });
                }
            },
        };
        roles.push(role);
    }
    let has = |r: Role| roles.contains(&r);
    for (name, role) in [("run", Role::Run), ("t", Role::Time)].into_iter().chain(
        names
            .iter()
            .enumerate()
            .map(|(k, n)| (*n, Role::Coordinate(k))),
    ) {
        if !has(role) {
            return Err(DataError::MissingColumn {
                name: name.into(),
                expected,
            });
        }
    }
    for (k, name) in input_columns.iter().enumerate() {
        if !has(Role::Input(k)) {
            return Err(DataError::MissingColumn {
                name: name.clone(),
                expected,
            });
        }
    }
    Ok(roles)
}

/// A relative time tolerance: finite and ≥ 0 (NaN would let every
/// comparison pass).
fn check_tolerance(tolerance: f64) -> Result<(), DataError> {
    if tolerance.is_finite() && tolerance >= 0.0 {
        Ok(())
    } else {
        Err(DataError::InvalidOption {
            what: "time tolerance (finite, >= 0)",
            value: tolerance,
        })
    }
}

/// Wraps an angle difference into (−π, π].
fn wrap(d: f64) -> f64 {
    use core::f64::consts::{PI, TAU};
    let w = d - TAU * (d / TAU).round();
    if w <= -PI { w + TAU } else { w }
}

/// The mean step rounded to 12 significant digits: timestamps are decimal
/// text, so (t_last − t_first)/(rows − 1) carries binary rounding
/// (0.009999999999999998 for t = 0.00 … 0.29) that no sampling clock has.
fn tidy(dt: f64) -> f64 {
    format!("{dt:.11e}").parse().unwrap_or(dt)
}

/// Half a unit of the last digit a number was printed with: the most the
/// printed value can differ from the one it was rounded from ("0.00833" →
/// 5e-6, "8.33e-3" → 5e-6, "12" → 0.5).
fn printed_half_unit(text: &str) -> f64 {
    let text = text.trim();
    let (mantissa, exponent) = match text.find(['e', 'E']) {
        Some(i) => (&text[..i], text[i + 1..].parse::<i32>().unwrap_or(0)),
        None => (text, 0),
    };
    let decimals = mantissa.find('.').map_or(0, |p| {
        mantissa[p + 1..].bytes().filter(u8::is_ascii_digit).count()
    });
    0.5 * 10f64.powi(exponent.saturating_sub(decimals as i32))
}

/// Where an outlier cuts a run ([`RawRun::outliers`]).
#[derive(Clone, Copy, Debug)]
enum Cut {
    /// Drop the row (a spike in `column`).
    Drop { row: usize, column: usize },
    /// Split before the row (a jump between it and the previous one).
    Split { row: usize },
}

/// A run being read: times, positions and the line of each row.
struct RawRun<P> {
    name: String,
    times: Vec<f64>,
    /// The largest rounding of a printed t ([`printed_half_unit`]).
    time_rounding: f64,
    positions: Vec<P>,
    inputs: Vec<Vec<f64>>,
    lines: Vec<u64>,
}

impl<P: Positions> RawRun<P> {
    /// The run's rows as one or more runs: time checked to increase,
    /// outliers refused or (with [`ReadOptions::drop_outliers`]) dropped
    /// into `dropped` with the run split at them, then each piece checked
    /// and unwrapped ([`RawRun::finish_piece`]).
    fn finish(
        self,
        names: &[&str],
        kinds: &[CoordinateKind],
        opts: &ReadOptions,
        dropped: &mut Vec<Dropped>,
    ) -> Result<Vec<RunOf<P>>, DataError> {
        for k in 1..self.times.len() {
            if self.times[k] <= self.times[k - 1] {
                return Err(DataError::TimeNotIncreasing {
                    run: self.name,
                    line: self.lines[k],
                    t: self.times[k],
                    previous: self.times[k - 1],
                });
            }
        }
        let cuts = self.outliers(names, kinds, opts)?;
        if cuts.is_empty() {
            return Ok(vec![self.finish_piece(names, kinds, opts)?]);
        }
        // pieces between the cuts: a dropped row is left out, a jump
        // splits between its two rows
        let mut out = Vec::new();
        let mut start = 0;
        let n = self.times.len();
        let mut bounds: Vec<(usize, usize)> = Vec::new();
        for cut in &cuts {
            match *cut {
                Cut::Drop { row, column } => {
                    dropped.push(Dropped {
                        run: self.name.clone(),
                        line: self.lines[row],
                        column: names[column].into(),
                        value: self.positions[row][column],
                    });
                    bounds.push((start, row));
                    start = row + 1;
                }
                Cut::Split { row } => {
                    bounds.push((start, row));
                    start = row;
                }
            }
        }
        bounds.push((start, n));
        for (a, b) in bounds {
            if a >= b {
                continue;
            }
            let piece = RawRun {
                name: if out.is_empty() {
                    self.name.clone()
                } else {
                    format!("{}@{}", self.name, self.lines[a])
                },
                times: self.times[a..b].to_vec(),
                time_rounding: self.time_rounding,
                positions: self.positions[a..b].to_vec(),
                inputs: if self.inputs.is_empty() {
                    Vec::new()
                } else {
                    self.inputs[a..b].to_vec()
                },
                lines: self.lines[a..b].to_vec(),
            };
            out.push(piece.finish_piece(names, kinds, opts)?);
        }
        Ok(out)
    }

    /// Readings whose jumps imply an implausible speed. A jump j → j+1 is
    /// *big* when |Δx|/Δt exceeds [`ReadOptions::max_speed`], or, without
    /// it, when an angle's raw jump exceeds 3π (neither a sensor wrap of
    /// 2π nor, under the unwrapping assumption |θ̇|Δt < π, a motion) or any
    /// coordinate's jump exceeds twice the run's extent without its two
    /// extreme readings (runs of five or more samples). A reading with big
    /// jumps on both sides (or on its only side, at a run's end) is a
    /// spike; a big jump between two plausible readings is a jump in the
    /// log. Without [`ReadOptions::drop_outliers`] the first is
    /// [`DataError::Outlier`]; with it a spike's row is dropped and a jump
    /// splits the run. Non-finite jumps (readings ±1e308 apart) are left
    /// to the overflow checks.
    fn outliers(
        &self,
        names: &[&str],
        kinds: &[CoordinateKind],
        opts: &ReadOptions,
    ) -> Result<Vec<Cut>, DataError> {
        let n = self.times.len();
        if n < 2 {
            return Ok(Vec::new());
        }
        let mut steps: Vec<f64> = self.times.windows(2).map(|w| w[1] - w[0]).collect();
        steps.sort_by(f64::total_cmp);
        let dt = steps[steps.len() / 2];
        let mut cuts = Vec::new();
        for i in 0..names.len() {
            let angle = kinds[i] == CoordinateKind::Angle && opts.unwrap_angles;
            let raw: Vec<f64> = self.positions.iter().map(|p| p[i]).collect();
            // the jump j → j+1 as the reader will see it (angles unwrapped)
            let jump = |j: usize| {
                let d = raw[j + 1] - raw[j];
                if angle && d.abs() <= 3.0 * core::f64::consts::PI {
                    wrap(d)
                } else {
                    d
                }
            };
            let extent = if n >= 5 {
                let mut sorted = raw.clone();
                sorted.sort_by(f64::total_cmp);
                let mid = sorted[n / 2].abs();
                (sorted[n - 2] - sorted[1]).max(1e-6 * (1.0 + mid))
            } else {
                f64::INFINITY
            };
            let (bound, hint) = match opts.max_speed {
                Some(v) => (v, ""),
                None => (
                    if angle {
                        (3.0 * core::f64::consts::PI).min(2.0 * extent) / dt
                    } else {
                        2.0 * extent / dt
                    },
                    "",
                ),
            };
            let big: Vec<bool> = (0..n - 1)
                .map(|j| {
                    let d = jump(j);
                    let raw_d = raw[j + 1] - raw[j];
                    raw_d.is_finite()
                        && match opts.max_speed {
                            Some(_) => d.abs() / dt > bound,
                            None if angle => {
                                raw_d.abs() > 3.0 * core::f64::consts::PI || d.abs() > 2.0 * extent
                            }
                            None => d.abs() > 2.0 * extent,
                        }
                })
                .collect();
            let mut j = 0;
            while j < n - 1 {
                if !big[j] {
                    j += 1;
                    continue;
                }
                // spike at j+1 (big jumps in and out, or the run's last
                // reading), or at j (the run's first reading), or a jump
                let (row, spike) = if j + 1 == n - 1 || (j + 1 < n - 1 && big[j + 1]) {
                    (j + 1, true)
                } else if j == 0 && n > 2 {
                    (0, true)
                } else {
                    (j + 1, false)
                };
                if !opts.drop_outliers {
                    let d = jump(j);
                    let degrees = angle && ((raw[j + 1] - raw[j]).abs() - 360.0).abs() < 10.0;
                    return Err(DataError::Outlier {
                        run: self.name.clone(),
                        line: self.lines[row],
                        column: names[i].into(),
                        value: raw[row],
                        jump: d,
                        speed: d.abs() / dt,
                        bound,
                        hint: if degrees {
                            " (a jump of about 360: angles in degrees?)"
                        } else {
                            hint
                        },
                    });
                }
                cuts.push(if spike {
                    Cut::Drop { row, column: i }
                } else {
                    Cut::Split { row }
                });
                j = if spike { row + 1 } else { j + 1 };
            }
        }
        // one cut per row, in row order
        cuts.sort_by_key(|c| match *c {
            Cut::Drop { row, .. } => (row, 0),
            Cut::Split { row } => (row, 1),
        });
        cuts.dedup_by_key(|c| match *c {
            Cut::Drop { row, .. } | Cut::Split { row } => row,
        });
        Ok(cuts)
    }

    /// One piece of a run (time already increasing, outliers gone):
    /// angles unwrapped, time checked uniform (or resampled), velocities
    /// checked finite.
    fn finish_piece(
        self,
        names: &[&str],
        kinds: &[CoordinateKind],
        opts: &ReadOptions,
    ) -> Result<RunOf<P>, DataError> {
        let RawRun {
            name,
            times,
            time_rounding,
            mut positions,
            inputs,
            lines,
        } = self;
        for k in 1..times.len() {
            if times[k] <= times[k - 1] {
                return Err(DataError::TimeNotIncreasing {
                    run: name,
                    line: lines[k],
                    t: times[k],
                    previous: times[k - 1],
                });
            }
        }
        if opts.unwrap_angles {
            for (i, kind) in kinds.iter().enumerate() {
                if *kind != CoordinateKind::Angle {
                    continue;
                }
                let mut prev_raw = positions[0][i];
                for k in 1..positions.len() {
                    let raw = positions[k][i];
                    positions[k][i] = positions[k - 1][i] + wrap(raw - prev_raw);
                    prev_raw = raw;
                    if !positions[k][i].is_finite() {
                        // finite readings ±1e308 apart: the difference
                        // overflows
                        return Err(DataError::Overflow {
                            run: name,
                            line: lines[k],
                            column: names[i].into(),
                            what: "the unwrapped angle",
                        });
                    }
                }
            }
        }
        let (t0, line) = (times[0], lines[0]);
        let n = times.len();
        if n == 1 {
            return Ok(RunOf {
                name,
                t0,
                dt: None,
                positions,
                inputs,
                line,
            });
        }
        if let Some(dt) = opts.resample {
            let steps = ((times[n - 1] - t0) / dt * (1.0 + 1e-12)).floor();
            if steps >= MAX_RESAMPLED as f64 {
                // a step far below the sampling (1e-9 s for 10 ms data)
                // would allocate tens of gigabytes
                return Err(DataError::InvalidOption {
                    what: "resample (more than 10^7 samples in one run: a step far below the recorded sampling)",
                    value: dt,
                });
            }
            let steps = steps as usize;
            let mut out = Vec::with_capacity(steps + 1);
            let mut held = Vec::with_capacity(if inputs.is_empty() { 0 } else { steps + 1 });
            let mut seg = 0;
            for k in 0..=steps {
                let t = t0 + k as f64 * dt;
                while seg + 2 < n && times[seg + 1] < t {
                    seg += 1;
                }
                let (ta, tb) = (times[seg], times[seg + 1]);
                let w = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
                out.push(positions[seg].lerp(&positions[seg + 1], w));
                if !inputs.is_empty() {
                    // zero-order hold: the last sample at or before t. A
                    // sample within 1e-6 of the interval before t counts
                    // as at t: t0 + k·Δt rounds a hair below a logged time
                    // such as 0.68 (0.50 + 18·0.01 = 0.679999…), and the
                    // previous sample's input would be held instead
                    let at = if w >= 1.0 - HOLD_SLACK { seg + 1 } else { seg };
                    held.push(inputs[at].clone());
                }
            }
            // resampled rows have no file line: name the run's first
            return check_velocities(
                RunOf {
                    name,
                    t0,
                    dt: Some(dt),
                    positions: out,
                    inputs: held,
                    line,
                },
                |_| line,
                names,
            );
        }
        // Each step is compared with the run's median step, so that one
        // dropped or repeated sample is reported at its own line (the mean
        // step shifts with the gap and would flag the regular steps too).
        // Printed timestamps are rounded: a step is off by up to the
        // rounding of its two ends, the median step by that of its two, so
        // four times the largest rounding is allowed on top, at most a
        // quarter step (a dropped or repeated sample is a whole step off).
        let mut steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        steps.sort_by(f64::total_cmp);
        let typical = steps[steps.len() / 2];
        let slack = (4.0 * time_rounding).min(0.25 * typical);
        for k in 1..n {
            let step = times[k] - times[k - 1];
            if (step - typical).abs() > opts.time_tolerance * typical + slack {
                return Err(DataError::NonUniformTime {
                    run: name,
                    line: lines[k],
                    expected: typical,
                    found: step,
                    tolerance: opts.time_tolerance,
                });
            }
        }
        let dt = tidy((times[n - 1] - t0) / (n - 1) as f64);
        if vigp_core::step::check_time_step(dt).is_err() {
            return Err(DataError::TimeStepOutOfRange { run: name, dt });
        }
        check_velocities(
            RunOf {
                name,
                t0,
                dt: Some(dt),
                positions,
                inputs,
                line,
            },
            |k| lines[k],
            names,
        )
    }
}

/// Checks that transitions were formed with the time step `dt` a trainer
/// is given (relative `tolerance`, e.g. 1e-6): consecutive transitions of
/// one run (recognised by z_{k+1}.v = v_next of z_k, bit for bit) satisfy
/// x_{k+1} = x_k + Δt·v_k, which gives the Δt they were formed with. The
/// median of those estimates other than `dt` is
/// [`DataError::DtContradictsData`] (with a hint for a factor of 2 or
/// 1000). Transitions with no such pair (all from different runs, or at
/// rest) pass.
pub fn check_transitions_dt<const N: usize>(
    transitions: &[Transition<N>],
    dt: f64,
    tolerance: f64,
) -> Result<(), DataError> {
    check_pairs_dt(transitions.iter().map(|t| (&t.z, &t.v_next)), dt, tolerance)
}

/// [`check_transitions_dt`] for the transitions of an actuated mechanism.
pub fn check_forced_transitions_dt<const N: usize, const U: usize>(
    transitions: &[ForcedTransition<N, U>],
    dt: f64,
    tolerance: f64,
) -> Result<(), DataError> {
    check_pairs_dt(transitions.iter().map(|t| (&t.z, &t.v_next)), dt, tolerance)
}

fn check_pairs_dt<'a, const N: usize>(
    pairs: impl Iterator<Item = (&'a State<N>, &'a SVector<f64, N>)>,
    dt: f64,
    tolerance: f64,
) -> Result<(), DataError> {
    check_tolerance(tolerance)?;
    if vigp_core::step::check_time_step(dt).is_err() {
        return Err(DataError::InvalidOption {
            what: "dt (finite and > 0, with dt² a normal number)",
            value: dt,
        });
    }
    let Some((found, i)) = time_step::estimate(pairs) else {
        return Ok(());
    };
    // printed data carries ~1e-12 relative rounding in Δt·v
    if (found - dt).abs() > tolerance.max(1e-9) * dt {
        let hint = time_step::factor_hint(dt, found);
        return Err(DataError::DtContradictsData {
            given: dt,
            source_of: format!("the run of transitions {i} and {}", i + 1),
            found: tidy(found),
            hint,
        });
    }
    Ok(())
}

/// The unit heuristics ([`DataWarning`]) over the runs read:
/// `integer_times` when every timestamp was an integer.
fn unit_warnings<P: Positions>(
    runs: &[RunOf<P>],
    names: &[&str],
    kinds: &[CoordinateKind],
    integer_times: &bool,
) -> Vec<DataWarning> {
    let mut out = Vec::new();
    for i in 0..names.len() {
        if kinds[i] != CoordinateKind::Angle {
            continue;
        }
        let (mut max_abs, mut max_speed) = (0.0f64, 0.0f64);
        for r in runs {
            for p in &r.positions {
                max_abs = max_abs.max(p[i].abs());
            }
            if let Some(dt) = r.dt {
                for w in r.positions.windows(2) {
                    max_speed = max_speed.max((w[1][i] - w[0][i]).abs() / dt);
                }
            }
        }
        if max_abs > core::f64::consts::TAU && max_abs <= 400.0 && max_speed > 50.0 {
            out.push(DataWarning::LooksLikeDegrees {
                column: names[i].into(),
                max_abs,
                max_speed,
            });
        }
    }
    if *integer_times {
        if let Some(r) = runs.iter().find(|r| r.dt.is_some_and(|dt| dt >= 1.0)) {
            out.push(DataWarning::LooksLikeMilliseconds {
                run: r.name.clone(),
                dt: r.dt.unwrap_or_default(),
            });
        }
    }
    out
}

/// The run unchanged if every discrete velocity (x_{k+1} − x_k)/Δt is
/// finite: finite readings far apart (±1e308) or a tiny Δt overflow.
/// `line(k)` is the file line of sample k.
fn check_velocities<P: Positions>(
    run: RunOf<P>,
    line: impl Fn(usize) -> u64,
    names: &[&str],
) -> Result<RunOf<P>, DataError> {
    let Some(dt) = run.dt else { return Ok(run) };
    for k in 1..run.positions.len() {
        let (a, b) = (run.positions[k - 1].entries(), run.positions[k].entries());
        if let Some(i) = (0..a.len()).position(|i| !((b[i] - a[i]) / dt).is_finite()) {
            return Err(DataError::Overflow {
                run: run.name,
                line: line(k),
                column: names[i].into(),
                what: "the discrete velocity (x_{k+1} − x_k)/Δt",
            });
        }
    }
    Ok(run)
}

impl<P: Positions> DatasetOf<P> {
    /// Reads CSV text (module docs) for coordinates `names` of kinds
    /// `kinds` (as many) and inputs `inputs` (columns `u_<name>`).
    fn read_rows<R: io::Read>(
        reader: R,
        names: &[&str],
        kinds: &[CoordinateKind],
        inputs: &[&str],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        if !(opts.time_tolerance.is_finite() && opts.time_tolerance >= 0.0) {
            return Err(DataError::InvalidOption {
                what: "time_tolerance (finite, >= 0)",
                value: opts.time_tolerance,
            });
        }
        if let Some(dt) = opts.resample {
            if vigp_core::step::check_time_step(dt).is_err() {
                return Err(DataError::InvalidOption {
                    what: "resample (a time step, finite and > 0, with dt² a normal number)",
                    value: dt,
                });
            }
        }
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .from_reader(reader);
        let header = rdr.headers()?.clone();
        if header.is_empty() || header.iter().all(str::is_empty) {
            return Err(DataError::Empty("no header line"));
        }
        let roles = header_roles(&header, names, inputs)?;
        let mut runs: Vec<RunOf<P>> = Vec::new();
        let mut finished: HashSet<String> = HashSet::new();
        let mut current: Option<RawRun<P>> = None;
        let mut dropped = Vec::new();
        // every timestamp integral (for the milliseconds heuristic)
        let mut time_texts = true;
        let mut record = csv::StringRecord::new();
        while rdr.read_record(&mut record)? {
            let line = record.position().map_or(0, |p| p.line());
            let mut run = "";
            let mut t = 0.0;
            let mut t_rounding = 0.0;
            let mut q = P::zeros(names.len());
            let mut u = vec![0.0; inputs.len()];
            for (field, (role, col)) in record.iter().zip(roles.iter().zip(header.iter())) {
                let number = || -> Result<f64, DataError> {
                    let v: f64 = field.parse().map_err(|_| DataError::Parse {
                        line,
                        column: col.trim().into(),
                        value: field.into(),
                    })?;
                    if !v.is_finite() {
                        return Err(DataError::NonFinite {
                            line,
                            column: col.trim().into(),
                            value: v,
                        });
                    }
                    Ok(v)
                };
                match role {
                    Role::Run => run = field,
                    Role::Time => {
                        t = number()?;
                        time_texts &= t.fract() == 0.0;
                        t_rounding = printed_half_unit(field);
                    }
                    Role::Coordinate(k) => q[*k] = number()?,
                    Role::Input(k) => u[*k] = number()?,
                }
            }
            if run.is_empty() {
                return Err(DataError::EmptyRun { line });
            }
            let same = current.as_ref().is_some_and(|c| c.name == run);
            if !same {
                if finished.contains(run) {
                    return Err(DataError::RunNotContiguous {
                        run: run.into(),
                        line,
                    });
                }
                if let Some(done) = current.take() {
                    finished.insert(done.name.clone());
                    runs.extend(done.finish(names, kinds, opts, &mut dropped)?);
                }
                current = Some(RawRun {
                    name: run.into(),
                    times: Vec::new(),
                    time_rounding: 0.0,
                    positions: Vec::new(),
                    inputs: Vec::new(),
                    lines: Vec::new(),
                });
            }
            if let Some(c) = current.as_mut() {
                c.times.push(t);
                c.time_rounding = f64::max(c.time_rounding, t_rounding);
                c.positions.push(q);
                if !inputs.is_empty() {
                    c.inputs.push(u);
                }
                c.lines.push(line);
            }
        }
        match current {
            Some(done) => runs.extend(done.finish(names, kinds, opts, &mut dropped)?),
            None => return Err(DataError::Empty("a header but no data rows")),
        }
        let warnings = unit_warnings(&runs, names, kinds, &time_texts);
        Ok(Self {
            coordinates: names.iter().map(|s| s.to_string()).collect(),
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            runs,
            dropped,
            warnings,
        })
    }

    /// The one-run log of [`Dataset::from_rollout`] from states given as
    /// (q, v) slices of the coordinates' count and inputs as slices of the
    /// input names' count.
    fn rollout_log(
        coordinates: &[&str],
        input_names: &[&str],
        run: &str,
        (t0, dt): (f64, f64),
        states: &[(&[f64], &[f64])],
        (previous, inputs): (&[f64], &[&[f64]]),
    ) -> Result<Self, DataError> {
        let bad = |why: String| Err(DataError::Rollout(why));
        if !(dt.is_finite() && dt > 0.0 && t0.is_finite()) {
            return bad(format!("dt = {dt} and t0 = {t0} must be finite, dt > 0"));
        }
        if states.is_empty() || inputs.len() + 1 != states.len() {
            return bad(format!(
                "{} states and {} inputs: a rollout of K steps has K + 1 states and K inputs",
                states.len(),
                inputs.len()
            ));
        }
        let (n, m) = (coordinates.len(), input_names.len());
        if states.iter().any(|(q, v)| q.len() != n || v.len() != n) {
            return bad(format!(
                "a state does not have {n} coordinates and velocities"
            ));
        }
        if inputs.iter().chain([&previous]).any(|u| u.len() != m) {
            return bad(format!("an input does not have {m} entries"));
        }
        let finite = states
            .iter()
            .all(|(q, v)| q.iter().chain(v.iter()).all(|x| x.is_finite()))
            && inputs
                .iter()
                .chain([&previous])
                .all(|u| u.iter().all(|x| x.is_finite()));
        if !finite {
            return bad("a state or an input holds NaN or ±∞".into());
        }
        let position = |q: &[f64]| {
            let mut p = P::zeros(n);
            for (i, x) in q.iter().enumerate() {
                p[i] = *x;
            }
            p
        };
        let mut positions: Vec<P> = states.iter().map(|(q, _)| position(q)).collect();
        let (q, v) = states[states.len() - 1];
        let end: Vec<f64> = q.iter().zip(v).map(|(q, v)| q + v * dt).collect();
        positions.push(position(&end));
        let run_inputs = if m == 0 {
            Vec::new()
        } else {
            let mut rows = Vec::with_capacity(positions.len());
            rows.push(previous.to_vec());
            rows.extend(inputs.iter().map(|u| u.to_vec()));
            let hold = rows[rows.len() - 1].clone();
            rows.push(hold);
            rows
        };
        Ok(Self {
            coordinates: coordinates.iter().map(|c| c.to_string()).collect(),
            inputs: input_names.iter().map(|c| c.to_string()).collect(),
            runs: vec![RunOf {
                name: run.to_string(),
                t0,
                dt: Some(dt),
                positions,
                inputs: run_inputs,
                line: 2,
            }],
            dropped: Vec::new(),
            warnings: Vec::new(),
        })
    }

    /// Opens a CSV file for reading (a directory is an error here, not an
    /// empty read at "line 0").
    fn open(path: &Path) -> Result<io::BufReader<std::fs::File>, DataError> {
        let io_error = |source| DataError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io_error)?;
        if file.metadata().map_err(io_error)?.is_dir() {
            return Err(io_error(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory, not a CSV file",
            )));
        }
        Ok(io::BufReader::new(file))
    }

    /// The common time step of the runs: every run with two or more rows
    /// must have the first such run's step to within `tolerance`
    /// (relative).
    pub fn dt(&self, tolerance: f64) -> Result<f64, DataError> {
        check_tolerance(tolerance)?;
        let mut dt = None;
        for r in &self.runs {
            let Some(d) = r.dt else { continue };
            match dt {
                None => dt = Some(d),
                Some(first) => {
                    if (d - first).abs() > tolerance * first {
                        return Err(DataError::TimeStepMismatch {
                            run: r.name.clone(),
                            found: d,
                            expected: first,
                            what: "the first run's",
                        });
                    }
                }
            }
        }
        dt.ok_or(DataError::NoTimeStep)
    }

    /// Checks that every run's time step is `dt` to within `tolerance`
    /// (relative), e.g. the time step of a trained model.
    pub fn check_dt(&self, dt: f64, tolerance: f64) -> Result<(), DataError> {
        check_tolerance(tolerance)?;
        if vigp_core::step::check_time_step(dt).is_err() {
            return Err(DataError::InvalidOption {
                what: "dt (finite and > 0, with dt² a normal number)",
                value: dt,
            });
        }
        for r in &self.runs {
            if let Some(d) = r.dt {
                if (d - dt).abs() > tolerance * dt {
                    return Err(DataError::TimeStepMismatch {
                        run: r.name.clone(),
                        found: d,
                        expected: dt,
                        what: "the model's",
                    });
                }
            }
        }
        Ok(())
    }

    /// The runs too short to give a transition (fewer than three samples).
    pub fn short_runs(&self) -> impl Iterator<Item = &RunOf<P>> {
        self.runs.iter().filter(|r| r.positions.len() < 3)
    }

    /// Number of samples over all runs.
    pub fn samples(&self) -> usize {
        self.runs.iter().map(|r| r.positions.len()).sum()
    }

    /// Writes the data in the file format the reader takes (module docs):
    /// `run,t,<coordinates>[,u_<input>…]`, one row per sample, numbers in
    /// Rust's shortest round-trip form (read back bit for bit) and each
    /// time written as t_0 + j·Δt at the decimals of t_0 and Δt
    /// ([`format_time`]: 0.06, not 0.060000000000000005).
    pub fn write_csv<W: io::Write>(&self, writer: W) -> Result<(), io::Error> {
        let mut w = csv::Writer::from_writer(writer);
        let mut header = vec!["run".to_string(), "t".to_string()];
        header.extend(self.coordinates.iter().cloned());
        header.extend(self.inputs.iter().map(|u| format!("u_{u}")));
        w.write_record(&header).map_err(io::Error::other)?;
        for run in &self.runs {
            let dt = run.dt.unwrap_or(0.0);
            for (j, q) in run.positions.iter().enumerate() {
                let mut row = vec![run.name.clone(), format_time(run.t0, dt, j)];
                row.extend(q.entries().iter().map(|x| format!("{x:?}")));
                if let Some(u) = run.inputs.get(j) {
                    row.extend(u.iter().map(|x| format!("{x:?}")));
                }
                w.write_record(&row).map_err(io::Error::other)?;
            }
        }
        w.flush()
    }
}

impl<const N: usize> Dataset<N> {
    /// Reads CSV text (see the module docs) for coordinates `names` of
    /// kinds `kinds`.
    pub fn read_csv<R: io::Read>(
        reader: R,
        names: &[&str; N],
        kinds: &[CoordinateKind; N],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        Self::read_csv_with_inputs(reader, names, kinds, &[], opts)
    }

    /// [`Dataset::read_csv`] for a mechanism with inputs `inputs` (the
    /// actuated joints' names; columns `u_<name>`, module docs).
    pub fn read_csv_with_inputs<R: io::Read>(
        reader: R,
        names: &[&str; N],
        kinds: &[CoordinateKind; N],
        inputs: &[&str],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        Self::read_rows(reader, names, kinds, inputs, opts)
    }

    /// Reads a CSV file ([`Dataset::read_csv`]).
    pub fn read_path(
        path: impl AsRef<Path>,
        names: &[&str; N],
        kinds: &[CoordinateKind; N],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        Self::read_path_with_inputs(path, names, kinds, &[], opts)
    }

    /// [`Dataset::read_path`] for a mechanism with inputs `inputs` (the
    /// actuated joints' names; columns `u_<name>`, module docs).
    pub fn read_path_with_inputs(
        path: impl AsRef<Path>,
        names: &[&str; N],
        kinds: &[CoordinateKind; N],
        inputs: &[&str],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        Self::read_rows(Self::open(path.as_ref())?, names, kinds, inputs, opts)
    }

    /// Reads CSV text with the coordinate names and kinds of mechanism `M`.
    /// Inputs: the `u_<joint>` columns of its actuated joints
    /// (`Dynamics::INPUT_NAMES`).
    pub fn read_for<M: Mechanism<N, C>, const C: usize, R: io::Read>(
        reader: R,
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        Self::read_csv_with_inputs(reader, &M::COORDINATES, &M::KINDS, M::INPUT_NAMES, opts)
    }

    /// Training transitions of every run with three or more samples, each
    /// with its run's time step (see [`crate::learned::transitions`]).
    pub fn transitions(&self) -> Vec<Transition<N>> {
        self.runs
            .iter()
            .filter_map(|r| Some(crate::learned::transitions(&r.positions, r.dt?)))
            .flatten()
            .collect()
    }

    /// Each run's inputs as vectors of the `U` input columns, one per
    /// sample (row k's input, held from t_k; the step from state k is
    /// driven by row k+1's, [`Run::step_input`]); empty for a mechanism
    /// without inputs (`U` = 0). `U` must be the number of input columns
    /// read ([`DataError::InputCount`] otherwise).
    pub fn input_vectors<const U: usize>(&self) -> Result<Vec<Vec<SVector<f64, U>>>, DataError> {
        if self.inputs.len() != U {
            return Err(DataError::InputCount {
                expected: U,
                found: self.inputs.len(),
            });
        }
        Ok(self
            .runs
            .iter()
            .map(|run| {
                run.inputs
                    .iter()
                    .map(|u| SVector::from_column_slice(u))
                    .collect()
            })
            .collect())
    }

    /// Training transitions with their inputs (an actuated mechanism's
    /// data): transition k of a run is driven by [`Run::step_input`]`(k)`,
    /// the input held over the interval of the new discrete velocity, after
    /// row k's input (its `u_prev`, which produced the state's velocity; see
    /// [`crate::learned::forced_transitions`]). `U` must be the number of
    /// input columns read ([`DataError::InputCount`] otherwise).
    pub fn forced_transitions<const U: usize>(
        &self,
    ) -> Result<Vec<ForcedTransition<N, U>>, DataError> {
        let inputs = self.input_vectors::<U>()?;
        let mut out = Vec::new();
        for (run, us) in self.runs.iter().zip(&inputs) {
            let Some(dt) = run.dt else { continue };
            out.extend(crate::learned::forced_transitions(&run.positions, us, dt));
        }
        Ok(out)
    }

    /// A one-run log of a forced rollout, with every input on the row the
    /// reader expects (module docs, **Inputs**): `states` are z_0, …, z_K
    /// (K ≥ 0) of a rollout at step `dt` where step k (z_k → z_{k+1}) was
    /// driven by `inputs[k]` (as [`crate::Variational::rollout_forced`]
    /// takes them), and `previous` is the input held over the start's
    /// velocity interval [t_0, t_1] (zero for a start at rest).
    ///
    /// The log has K + 2 rows at t_0 + j·dt: the positions x_j = q of z_j
    /// for j ≤ K and x_{K+1} = q_K + dt·v_K, the end of the last discrete
    /// velocity. Row 0 holds `previous`, row k + 1 holds `inputs[k]` (held
    /// from t_{k+1} to t_{k+2}, the interval of the velocity step k
    /// produces), so that reading the log back gives transition k driven by
    /// [`Run::step_input`]`(k)` = `inputs[k]`. The last row's input drives
    /// no step of the log; it repeats the row before (the hold goes on).
    /// `U = 0` writes no input columns. Errors: K + 1 states but not K
    /// inputs, names of the wrong count, a non-finite number, or a `dt`
    /// that is not finite and > 0 ([`DataError::Rollout`]).
    pub fn from_rollout<const U: usize>(
        coordinates: &[&str; N],
        input_names: &[&str],
        run: &str,
        (t0, dt): (f64, f64),
        states: &[State<N>],
        (previous, inputs): (SVector<f64, U>, &[SVector<f64, U>]),
    ) -> Result<Self, DataError> {
        if input_names.len() != U {
            return Err(DataError::Rollout(format!(
                "{} input name(s) for {U} input(s)",
                input_names.len()
            )));
        }
        let states: Vec<(&[f64], &[f64])> = states
            .iter()
            .map(|z| (z.q.as_slice(), z.v.as_slice()))
            .collect();
        let inputs: Vec<&[f64]> = inputs.iter().map(|u| u.as_slice()).collect();
        Self::rollout_log(
            coordinates,
            input_names,
            run,
            (t0, dt),
            &states,
            (previous.as_slice(), &inputs),
        )
    }
}

impl DynDataset {
    /// Reads CSV text (module docs) for coordinates `names` of kinds
    /// `kinds` (one per name) and inputs `inputs` (columns `u_<name>`;
    /// empty for none): the reader of [`Dataset::read_csv_with_inputs`]
    /// for a coordinate count known at run time, e.g. a
    /// [`crate::Robot`]'s joints.
    pub fn read_csv_with_inputs<R: io::Read>(
        reader: R,
        names: &[&str],
        kinds: &[CoordinateKind],
        inputs: &[&str],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        if names.len() != kinds.len() {
            return Err(DataError::InvalidOption {
                what: "kinds (one per coordinate name)",
                value: kinds.len() as f64,
            });
        }
        Self::read_rows(reader, names, kinds, inputs, opts)
    }

    /// Reads a CSV file ([`DynDataset::read_csv_with_inputs`]).
    pub fn read_path_with_inputs(
        path: impl AsRef<Path>,
        names: &[&str],
        kinds: &[CoordinateKind],
        inputs: &[&str],
        opts: &ReadOptions,
    ) -> Result<Self, DataError> {
        let reader = Self::open(path.as_ref())?;
        Self::read_csv_with_inputs(reader, names, kinds, inputs, opts)
    }

    /// A one-run log of a rollout of a model whose size is known at run
    /// time, with every input on the row the reader expects: as
    /// [`Dataset::from_rollout`], with each state z_k given as its (q, v)
    /// slices (one entry per coordinate) and each input as a slice (one
    /// entry per input name). Errors: as there, and states or inputs of
    /// the wrong length ([`DataError::Rollout`]).
    pub fn from_rollout(
        coordinates: &[&str],
        input_names: &[&str],
        run: &str,
        (t0, dt): (f64, f64),
        states: &[(&[f64], &[f64])],
        (previous, inputs): (&[f64], &[&[f64]]),
    ) -> Result<Self, DataError> {
        Self::rollout_log(
            coordinates,
            input_names,
            run,
            (t0, dt),
            states,
            (previous, inputs),
        )
    }
}

/// The decimals that print `x` to within 1e-9 of its size (at most 12):
/// 2 for 0.01 even when it was computed as 0.010000000000000002.
fn decimals(x: f64) -> usize {
    let scale = x.abs().max(f64::MIN_POSITIVE);
    (0..=12)
        .find(|&d| {
            let p = 10f64.powi(d as i32);
            ((x * p).round() / p - x).abs() <= 1e-9 * scale
        })
        .unwrap_or(12)
}

/// The time of sample `k` of a run from `t0` at step `dt`, t_0 + k·Δt
/// computed from the integer index and printed at the decimals of t_0 and
/// Δt, without float noise: `format_time(0.0, 0.02, 3)` is `"0.06"`, not
/// `0.060000000000000005`. A one-row run (Δt = 0) prints t_0.
pub fn format_time(t0: f64, dt: f64, k: usize) -> String {
    let d = decimals(t0).max(if dt > 0.0 { decimals(dt) } else { 0 });
    let t = t0 + k as f64 * dt;
    let s = format!("{t:.d$}");
    if d == 0 { format!("{s}.0") } else { s }
}
