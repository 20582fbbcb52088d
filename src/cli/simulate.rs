//! `vigp simulate`: a log of the nominal model, with the inputs on the
//! rows the data reader expects.

use std::io::Write;
use std::path::Path;

use super::args::SimulateArgs;
use super::{CliError, check_out_dir, io_error, read_plan, w};
use crate::data::{Dataset, DatasetOf, Positions};
use crate::{Mechanism, Parameters, SVector, State};

/// Rolls the nominal (minimal) model out from `--q`, `--v` under the
/// planned or zero inputs and writes the log with
/// [`Dataset::from_rollout`]: row k's input is held from t_k to t_{k+1},
/// so step k (from row k to row k + 1) is driven by row k + 1's input.
pub(super) fn simulate<Mn, const N: usize, const C: usize, const U: usize>(
    a: &SimulateArgs,
    minimal: Mn,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy,
    Mn: crate::Inputs<U>,
{
    let usage = |why: String| Err(CliError::Usage(why));
    if let Err(e) = minimal.constants() {
        return usage(format!("the nominal model (with --set): {e}"));
    }
    check_start(a, Mn::NAME, &Mn::COORDINATES)?;
    check_out_dir(&a.out)?;
    let z0 = State {
        q: SVector::<f64, N>::from_column_slice(&a.q),
        v: if a.v.is_empty() {
            SVector::zeros()
        } else {
            SVector::from_column_slice(&a.v)
        },
    };
    // the inputs of steps 0..K: the plan's first K rows, or zeros
    let mut us: Vec<SVector<f64, U>> = Vec::new();
    if U > 0 {
        if us.try_reserve_exact(a.steps).is_err() {
            return usage(format!("--steps {}: too many steps to store", a.steps));
        }
        match &a.inputs {
            Some(path) => {
                let plans = read_plan::<U>(path, Mn::INPUT_NAMES)?;
                us.extend_from_slice(one_plan(path, &plans, a.steps)?);
            }
            None => us.resize(a.steps, SVector::zeros()),
        }
    } else {
        if let Some(path) = &a.inputs {
            // refused with the reason
            read_plan::<U>(path, Mn::INPUT_NAMES)?;
        }
        // the log takes one (empty) input per step
        us.resize(a.steps, SVector::zeros());
    }
    let vi = a.stepping.integrator(minimal, a.dt)?;
    let (states, report) = if U > 0 {
        vi.rollout_forced_with_report(&z0, &us)?
    } else {
        vi.rollout_with_report(&z0, a.steps)?
    };
    let log = Dataset::from_rollout(
        &Mn::COORDINATES,
        Mn::INPUT_NAMES,
        &a.run,
        (a.t0, a.dt),
        &states,
        (SVector::<f64, U>::zeros(), &us),
    )
    .map_err(|e| CliError::Usage(e.to_string()))?;
    write_log(&log, &a.out)?;
    w(
        out,
        format_args!(
            "wrote {}: run `{}`, {} rows at dt = {} s ({} steps of {}; {}){}",
            a.out.display(),
            a.run,
            a.steps + 2,
            a.dt,
            a.steps,
            Mn::NAME,
            subdivided(&report),
            if U > 0 { INPUT_ROWS } else { "" }
        ),
    )
}

/// Writes a simulated `log` to the file `path` (CSV).
pub(super) fn write_log<P: Positions>(log: &DatasetOf<P>, path: &Path) -> Result<(), CliError> {
    let file = std::fs::File::create(path).map_err(io_error(path))?;
    log.write_csv(std::io::BufWriter::new(file))
        .map_err(io_error(path))
}

/// The end of `simulate`'s report on a log with inputs: on which rows they
/// stand.
pub(super) const INPUT_ROWS: &str = "; row k's input is held from t_k to t_{k+1}, so the step \
     from row k to row k + 1 is driven by row k + 1's input (row 0's, zero, is held over the \
     start velocity; the last row's repeats the one before)";

/// The first `steps` rows of the one plan in `plans` (of the file
/// `path`): `simulate` takes one plan of at least `--steps` rows.
pub(super) fn one_plan<'p, T>(
    path: &Path,
    plans: &'p [(Option<String>, Vec<T>)],
    steps: usize,
) -> Result<&'p [T], CliError> {
    if plans.len() > 1 {
        return Err(CliError::Usage(format!(
            "{}: {} runs of inputs; simulate takes one plan",
            path.display(),
            plans.len()
        )));
    }
    let plan = &plans[0].1;
    if plan.len() < steps {
        return Err(CliError::Usage(format!(
            "{}: {} input row(s), --steps {steps} needs {steps}",
            path.display(),
            plan.len(),
        )));
    }
    Ok(&plan[..steps])
}

/// The checks of `simulate`'s start and steps, before any work: `--q`
/// has one value per coordinate (`coordinates` of `name`), `--v` as many
/// or none, both finite; `--dt` finite and > 0, `--t0` finite, `--steps`
/// at least 1.
pub(super) fn check_start(
    a: &SimulateArgs,
    name: &str,
    coordinates: &[&str],
) -> Result<(), CliError> {
    let usage = |why: String| Err(CliError::Usage(why));
    let n = coordinates.len();
    if a.q.len() != n {
        return usage(format!(
            "--q has {} value(s); {name} has {n} coordinates: {}",
            a.q.len(),
            coordinates.join(", ")
        ));
    }
    if !a.v.is_empty() && a.v.len() != n {
        return usage(format!(
            "--v has {} value(s), expected {n} (or none for a start at rest)",
            a.v.len()
        ));
    }
    if a.q.iter().chain(&a.v).any(|x| !x.is_finite()) {
        return usage("--q and --v must be finite".into());
    }
    if !(a.dt.is_finite() && a.dt > 0.0) {
        return usage(format!("--dt must be finite and > 0: {}", a.dt));
    }
    if !a.t0.is_finite() {
        return usage(format!("--t0 must be finite: {}", a.t0));
    }
    if a.steps == 0 {
        return usage("--steps must be at least 1".into());
    }
    Ok(())
}

/// How many steps of a rollout subdivided themselves, in words.
pub(super) fn subdivided(report: &crate::variational::RolloutReport) -> String {
    if report.subdivided == 0 {
        "no step subdivided itself".into()
    } else {
        format!(
            "{} of {} steps subdivided {}, the deepest {} time{}",
            report.subdivided,
            report.steps,
            if report.subdivided == 1 {
                "itself"
            } else {
                "themselves"
            },
            report.deepest,
            if report.deepest == 1 { "" } else { "s" }
        )
    }
}
