//! The mechanisms the tool knows, and how one of them runs a command in
//! its minimal or maximal view: the commands are written once, generic over
//! the minimal view and over what the mechanism has as maximal view
//! ([`MaximalView`]: a planar mechanism's, or none for a 3-D mechanism).

use std::io::Write;
use std::path::Path;

use super::args::{
    Command, EncodingArg, ExportArgs, FitArgs, IdentifyArgs, PredictArgs, PriorArg, ReadArgs,
    ScoreArgs, SimulateArgs,
};
use super::export::export;
use super::fit::{Prepared, fit_maximal, fit_minimal, nominal_invalid, prepare, set_parameter};
use super::identify::{apply_identified, identify};
use super::predict::predict;
use super::score::score;
use super::{CliError, in_minimal, load, model_and_data, read_saved};
use crate::data::Dataset;
use crate::learned::SavedLearned;
use crate::{Coordinates, Inputs, Mechanism, Parameters, System, ViewVisitor};

/// One mechanism the tool knows (see [`system`]).
#[derive(Clone, Copy)]
pub struct SystemEntry {
    pub(super) name: &'static str,
    pub(super) run: fn(&Command, &mut dyn Write) -> Result<(), CliError>,
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

/// The entry of mechanism `S` for [`main_with`](super::main_with) /
/// [`run`](super::run): any `mechanism!`, planar or 3-D (a 3-D one in its
/// minimal coordinates).
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

/// The 3-D example systems (`vigp::systems::spatial`), as the `vigp` binary
/// has them after the paper's four: the tool learns them in their minimal
/// coordinates (joint angles and slides; a ball joint's quaternion as four
/// columns `<joint>.w`, `.x`, `.y`, `.z`, a free joint's position and
/// quaternion as seven, velocities differenced as for every coordinate).
pub fn spatial_systems() -> Vec<SystemEntry> {
    use crate::systems::spatial::{
        DoublePendulum3d, Furuta, SpatialSliderCrank, SphericalPendulum, Tumbler,
    };
    vec![
        system::<Furuta>(),
        system::<SphericalPendulum>(),
        system::<DoublePendulum3d>(),
        system::<SpatialSliderCrank>(),
        system::<Tumbler>(),
    ]
}

pub(super) fn names(systems: &[SystemEntry]) -> String {
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

pub(super) fn find(systems: &[SystemEntry], name: &str) -> Result<SystemEntry, CliError> {
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

fn run_system<S: System>(cmd: &Command, out: &mut dyn Write) -> Result<(), CliError> {
    // the nominal parameters: declared, then an identified prior's, then
    // each `--set`
    let mut sys = S::default();
    let mut identified = None;
    let set: &[String] = match cmd {
        Command::Fit(FitArgs { set, prior, .. }) => {
            if let PriorArg::Identified(path) = prior {
                identified = Some((apply_identified(&mut sys, S::NAME, path)?, path));
            }
            set
        }
        Command::Simulate(SimulateArgs { set, .. })
        | Command::Identify(IdentifyArgs { set, .. })
        | Command::Excite(super::args::ExciteArgs { set, .. }) => set,
        _ => &[],
    };
    for s in set {
        set_parameter(&mut sys, s)?;
    }
    // the identified prior sets its parameters again when it trains: a
    // `--set` of one of them would be lost
    if let Some((identified, path)) = identified {
        let mut again = sys;
        identified
            .write_to(&mut again)
            .map_err(|e| CliError::Usage(format!("--prior identified:{}: {e}", path.display())))?;
        if let Some(i) = (0..S::PARAMETER_NAMES.len())
            .find(|&i| again.parameter(i).map(f64::to_bits) != sys.parameter(i).map(f64::to_bits))
        {
            return Err(CliError::Usage(format!(
                "--set {}: the identified prior (--prior identified:{}) sets this parameter",
                S::PARAMETER_NAMES[i],
                path.display()
            )));
        }
    }
    sys.visit(Visit { cmd, out })
}

struct Visit<'a> {
    cmd: &'a Command,
    out: &'a mut dyn Write,
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
        Mn: Inputs<U>,
        Mx: Inputs<U>,
    {
        dispatch::<Mn, _, N, C, U>(self.cmd, minimal, Planar::<Mx, NM, CM>(maximal), self.out)
    }

    fn visit_minimal<Mn, const N: usize, const C: usize, const U: usize>(
        self,
        minimal: Mn,
    ) -> Self::Output
    where
        Mn: Mechanism<N, C> + Parameters + Copy + Send + Sync + 'static,
        Mn: Inputs<U>,
    {
        dispatch::<Mn, _, N, C, U>(self.cmd, minimal, NoMaximal, self.out)
    }
}

/// Runs one command on a mechanism's minimal view `minimal` and its
/// maximal view (if any), the same code for planar and 3-D mechanisms.
fn dispatch<Mn, X, const N: usize, const C: usize, const U: usize>(
    cmd: &Command,
    minimal: Mn,
    maximal: X,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy + Send + Sync + 'static,
    Mn: Inputs<U>,
    X: MaximalView<Mn, N, C, U>,
{
    match cmd {
        Command::Fit(a) => {
            let p = prepare::<Mn, N, C, U>(a, minimal, maximal.check_fit(a), out)?;
            if a.encoding == EncodingArg::Maximal {
                maximal.fit(a, minimal, &p, out)
            } else {
                fit_minimal::<Mn, N, C, U>(a, minimal, &p, out)
            }
        }
        Command::Score(a) => on_data::<Mn, X, N, C, U>(OnData::Score(a), minimal, maximal, out),
        Command::Predict(a) => on_data::<Mn, X, N, C, U>(OnData::Predict(a), minimal, maximal, out),
        Command::Simulate(a) => super::simulate::simulate::<Mn, N, C, U>(a, minimal, out),
        Command::Identify(a) => identify::<Mn, N, C>(a, minimal, out),
        Command::Excite(a) => super::excite::excite::<Mn, N, C, U>(a, minimal, out),
        Command::Export(a) => {
            let saved = read_saved(&a.model)?;
            if in_minimal::<Mn, N, C>(&a.model, &saved, maximal.coordinates())? {
                export(a, &load(&a.model, &saved, minimal)?, out)
            } else {
                maximal.export(a, &saved, out)
            }
        }
    }
}

/// `score` or `predict`: a saved model run on a data file.
#[derive(Clone, Copy)]
enum OnData<'a> {
    Score(&'a ScoreArgs),
    Predict(&'a PredictArgs),
}

impl OnData<'_> {
    /// The model file, the data file and how to read it.
    fn files(&self) -> (&Path, &Path, &ReadArgs) {
        match self {
            OnData::Score(a) => (&a.model, &a.data, &a.read),
            OnData::Predict(a) => (&a.model, &a.data, &a.read),
        }
    }
}

/// `score` or `predict` in the view that the model file is in.
fn on_data<Mn, X, const N: usize, const C: usize, const U: usize>(
    cmd: OnData<'_>,
    minimal: Mn,
    maximal: X,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy + Send + Sync + 'static,
    Mn: Inputs<U>,
    X: MaximalView<Mn, N, C, U>,
{
    let (model, data, read) = cmd.files();
    let (saved, nominal, data) = model_and_data(model, data, read, minimal)?;
    if !in_minimal::<Mn, N, C>(model, &saved, maximal.coordinates())? {
        return maximal.on_data(cmd, &saved, nominal, &data, out);
    }
    let l = load(model, &saved, minimal)?;
    match cmd {
        OnData::Score(a) => {
            score::<_, _, N, C, N, C, U>(a, &l, nominal, &data, |z| *z, |q| *q, out)
        }
        OnData::Predict(a) => {
            let coords = (&Mn::COORDINATES, &Mn::KINDS, Mn::INPUT_NAMES);
            predict::<_, N, N, C, U>(a, &l, &data, coords, |z| *z, |z| *z, out)
        }
    }
}

/// What the commands need of a mechanism's maximal view, besides its
/// minimal view `Mn` (`N` coordinates, `C` constraints, `U` inputs): the
/// parts of `fit`, `score`, `predict` and `export` that run in it.
trait MaximalView<Mn, const N: usize, const C: usize, const U: usize> {
    /// The view's coordinate names (a model file in them is in this view);
    /// `None` when the tool takes no maximal view of the mechanism.
    fn coordinates(&self) -> Option<&'static [&'static str]>;
    /// Whether `fit` can run as asked: the view's parameters (after
    /// `--set`) and, for `--encoding maximal`, the view itself.
    fn check_fit(&self, a: &FitArgs) -> Result<(), CliError>;
    /// `fit --encoding maximal`.
    fn fit(
        &self,
        a: &FitArgs,
        minimal: Mn,
        p: &Prepared<N>,
        out: &mut dyn Write,
    ) -> Result<(), CliError>;
    /// `score` or `predict` of a model in maximal coordinates (`nominal`:
    /// the minimal view with the model's parameters).
    fn on_data(
        &self,
        cmd: OnData<'_>,
        saved: &SavedLearned,
        nominal: Mn,
        data: &Dataset<N>,
        out: &mut dyn Write,
    ) -> Result<(), CliError>;
    /// `export` of a model in maximal coordinates.
    fn export(
        &self,
        a: &ExportArgs,
        saved: &SavedLearned,
        out: &mut dyn Write,
    ) -> Result<(), CliError>;
}

/// A planar mechanism's maximal view: a [`Mechanism`] in each link's x, y,
/// θ (`NM` coordinates, `CM` joint equations).
struct Planar<Mx, const NM: usize, const CM: usize>(Mx);

impl<Mn, Mx, const N: usize, const C: usize, const NM: usize, const CM: usize, const U: usize>
    MaximalView<Mn, N, C, U> for Planar<Mx, NM, CM>
where
    Mn: Mechanism<N, C> + Coordinates<N, NM> + Parameters + Copy + Send + Sync + 'static,
    Mx: Mechanism<NM, CM> + Parameters + Copy + Send + Sync + 'static,
    Mn: Inputs<U>,
    Mx: Inputs<U>,
{
    fn coordinates(&self) -> Option<&'static [&'static str]> {
        Some(&Mx::COORDINATES)
    }

    fn check_fit(&self, _a: &FitArgs) -> Result<(), CliError> {
        self.0.constants().map(|_| ()).map_err(nominal_invalid)
    }

    fn fit(
        &self,
        a: &FitArgs,
        minimal: Mn,
        p: &Prepared<N>,
        out: &mut dyn Write,
    ) -> Result<(), CliError> {
        fit_maximal::<Mn, Mx, N, NM, CM, U>(a, minimal, self.0, p, out)
    }

    fn on_data(
        &self,
        cmd: OnData<'_>,
        saved: &SavedLearned,
        nominal: Mn,
        data: &Dataset<N>,
        out: &mut dyn Write,
    ) -> Result<(), CliError> {
        let l = load(cmd.files().0, saved, self.0)?;
        let dt = saved.dt;
        match cmd {
            OnData::Score(a) => score::<_, _, N, C, NM, CM, U>(
                a,
                &l,
                nominal,
                data,
                |z| nominal.to_maximal(z, dt),
                |x| nominal.minimal_positions(x),
                out,
            ),
            OnData::Predict(a) => predict::<_, N, NM, CM, U>(
                a,
                &l,
                data,
                (&Mn::COORDINATES, &Mn::KINDS, Mn::INPUT_NAMES),
                |z| nominal.to_maximal(z, dt),
                |z| nominal.to_minimal(z, dt),
                out,
            ),
        }
    }

    fn export(
        &self,
        a: &ExportArgs,
        saved: &SavedLearned,
        out: &mut dyn Write,
    ) -> Result<(), CliError> {
        export(a, &load(&a.model, saved, self.0)?, out)
    }
}

/// A 3-D mechanism's maximal view, which the tool does not take (each
/// link's position and orientation: a Lie group, not a [`Mechanism`]):
/// `fit --encoding maximal` is refused before the data are read, and a
/// model file in other than the minimal coordinates by
/// [`in_minimal`], so the command parts below only say why.
struct NoMaximal;

impl NoMaximal {
    fn refuse<Mn: Parameters>(what: &'static str) -> Result<(), CliError> {
        Err(CliError::SpatialMaximal {
            mechanism: Mn::NAME,
            what,
        })
    }
}

/// What a model file in maximal coordinates asks for.
const MAXIMAL_MODEL: &str = "a model in maximal coordinates";

impl<Mn: Parameters, const N: usize, const C: usize, const U: usize> MaximalView<Mn, N, C, U>
    for NoMaximal
{
    fn coordinates(&self) -> Option<&'static [&'static str]> {
        None
    }

    fn check_fit(&self, a: &FitArgs) -> Result<(), CliError> {
        if a.encoding == EncodingArg::Maximal {
            Self::refuse::<Mn>("--encoding maximal")
        } else {
            Ok(())
        }
    }

    fn fit(&self, _: &FitArgs, _: Mn, _: &Prepared<N>, _: &mut dyn Write) -> Result<(), CliError> {
        Self::refuse::<Mn>("--encoding maximal")
    }

    fn on_data(
        &self,
        _: OnData<'_>,
        _: &SavedLearned,
        _: Mn,
        _: &Dataset<N>,
        _: &mut dyn Write,
    ) -> Result<(), CliError> {
        Self::refuse::<Mn>(MAXIMAL_MODEL)
    }

    fn export(&self, _: &ExportArgs, _: &SavedLearned, _: &mut dyn Write) -> Result<(), CliError> {
        Self::refuse::<Mn>(MAXIMAL_MODEL)
    }
}
