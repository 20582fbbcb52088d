//! The mechanisms the tool knows, and how one of them runs a command in
//! its minimal or maximal view.

use std::io::Write;

use super::args::{Command, PriorArg};
use super::export::export;
use super::fit::{fit, set_parameter};
use super::identify::{apply_identified, identify};
use super::predict::predict;
use super::score::score;
use super::{CliError, in_minimal, load, model_and_data, read_saved};
use crate::{Coordinates, Mechanism, Parameters, System, ViewVisitor};

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
    let mut sys = S::default();
    if let Command::Fit(super::args::FitArgs {
        prior: PriorArg::Identified(path),
        ..
    }) = cmd
    {
        apply_identified(&mut sys, S::NAME, path)?;
    }
    match cmd {
        Command::Fit(super::args::FitArgs { set, .. })
        | Command::Simulate(super::args::SimulateArgs { set, .. })
        | Command::Identify(super::args::IdentifyArgs { set, .. }) => {
            for s in set {
                set_parameter(&mut sys, s)?;
            }
            sys.visit(Visit { cmd, out })
        }
        _ => sys.visit(Visit { cmd, out }),
    }
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
        Mn: crate::Inputs<U>,
        Mx: crate::Inputs<U>,
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
            Command::Simulate(a) => super::simulate::simulate::<Mn, N, C, U>(a, minimal, out),
            Command::Identify(a) => identify::<Mn, N, C>(a, minimal, out),
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
