//! `vigp identify`: physical parameters from a log ([`crate::identify`]),
//! written as a parameter file that `vigp fit --prior identified:FILE`
//! takes as its nominal model.

use std::io::Write;
use std::path::Path;

use super::args::{IdentifyArgs, NoiseArg, RuleArg};
use super::{CliError, check_out_dir, io_error, read_log, w};
use crate::data::{DatasetOf, Positions};
use crate::identify::{
    DelRegressor, Identification, IdentifyError, Log, Noise, Options, OutputError, Regressor,
    RobotRegressor, SampleNoise, Status, identify as run_identify,
};
use crate::learned::IdentifiedParameters;
use crate::{Mechanism, Parameters};

/// The `format` field of a parameter file.
const FORMAT: &str = "vigp-identified-parameters";

pub(super) fn identify<Mn, const N: usize, const C: usize>(
    a: &IdentifyArgs,
    minimal: Mn,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy,
{
    check_args(a)?;
    let (data, dt) = read_log::<Mn, N, C>(&a.data, &a.read)?;
    let by_rule = |rule: RuleArg| match rule {
        RuleArg::Midpoint => DelRegressor::midpoint(minimal, dt),
        RuleArg::FirstOrder => DelRegressor::first_order(minimal, dt),
    };
    let (fit, regressor, id) = regress(a, Mn::NAME, &data, dt, RuleArg::Midpoint, by_rule)?;
    let identified = regressor.model_with(&id.estimate).map_err(fail)?;
    let value = |m: &Mn, name: &str| Mn::parameter_index(name).and_then(|i| m.parameter(i));
    let standard = IdentifiedParameters::from_identification::<Mn>(&id).map_err(fail)?;
    write_results(
        a,
        &fit,
        &id,
        |name| Some((value(&minimal, name)?, value(&identified, name)?)),
        standard,
        out,
    )
}

/// `vigp identify --urdf`: the robot's parameters by regression on the
/// tree engine's residual ([`RobotRegressor`]): its first-order rule by
/// default (the rule of the engine `simulate` and `fit` step with), the
/// midpoint rule with `--rule midpoint` (logs of a real, continuous-time
/// robot: bias O(Δt²) instead of O(Δt)).
pub(super) fn identify_robot(
    a: &IdentifyArgs,
    robot: &crate::Robot,
    data: &crate::data::DynDataset,
    dt: f64,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    check_args(a)?;
    let by_rule = |rule: RuleArg| match rule {
        RuleArg::FirstOrder => RobotRegressor::new(robot, dt),
        RuleArg::Midpoint => RobotRegressor::midpoint(robot, dt),
    };
    let (fit, regressor, id) = regress(a, robot.name(), data, dt, RuleArg::FirstOrder, by_rule)?;
    let identified = regressor.tree_with(&id.estimate).map_err(fail)?;
    let standard = IdentifiedParameters::new(
        robot.name(),
        &id.structure.names,
        &id.estimate,
        &id.covariance,
    )
    .map_err(fail)?;
    write_results(
        a,
        &fit,
        &id,
        |name| {
            Some((
                regressor.value(robot.tree(), name)?,
                regressor.value(&identified, name)?,
            ))
        },
        standard,
        out,
    )
}

/// The regression of the mechanism (or robot) `name` on every run of
/// `data` (time step `dt`), with the options of the flags: by the
/// regressor that `by_rule` makes for the rule of `--rule` (`default`
/// without). What was identified from what, the regressor, and its result.
fn regress<'a, R: Regressor, P: Positions>(
    a: &IdentifyArgs,
    name: &'a str,
    data: &DatasetOf<P>,
    dt: f64,
    default: RuleArg,
    by_rule: impl FnOnce(RuleArg) -> Result<R, IdentifyError>,
) -> Result<(Fit<'a>, R, Identification), CliError> {
    let rule = a.rule.unwrap_or(default);
    let regressor = by_rule(rule).map_err(fail)?;
    let logs: Vec<Log> = data.runs.iter().map(Log::from_run).collect();
    let id = run_identify(&regressor, &logs, &options(a)).map_err(fail)?;
    let fit = Fit {
        name,
        runs: data.runs.len(),
        dt,
        rule,
    };
    Ok((fit, regressor, id))
}

/// What was identified from what, for the report's first line.
struct Fit<'a> {
    name: &'a str,
    runs: usize,
    dt: f64,
    rule: RuleArg,
}

/// A usage error of `identify` saying why.
fn fail(e: impl std::fmt::Display) -> CliError {
    CliError::Usage(format!("identify: {e}"))
}

/// The checks made before any data is read.
fn check_args(a: &IdentifyArgs) -> Result<(), CliError> {
    if !(a.prior_sd > 0.0 && a.prior_sd.is_finite()) {
        return Err(CliError::Usage(format!(
            "--prior-sd {}: must be positive and finite",
            a.prior_sd
        )));
    }
    match (a.noise, a.noise_sigma) {
        (NoiseArg::Eiv, Some(sigma)) if sigma > 0.0 && sigma.is_finite() => {}
        (NoiseArg::Eiv, Some(sigma)) => {
            return Err(CliError::Usage(format!(
                "--noise-sigma {sigma}: must be positive and finite"
            )));
        }
        (NoiseArg::Eiv, None) => {
            return Err(CliError::Usage(
                "--noise eiv needs --noise-sigma (the positions' noise)".into(),
            ));
        }
        (_, Some(_)) => {
            return Err(CliError::Usage(
                "--noise-sigma serves --noise eiv only".into(),
            ));
        }
        (_, None) => {}
    }
    check_out_dir(&a.out)
}

/// The identification's options from the flags.
fn options(a: &IdentifyArgs) -> Options {
    let mut options = Options::default();
    options.prior.relative = a.prior_sd;
    options.noise = match a.noise {
        NoiseArg::Ls => Noise::LeastSquares,
        NoiseArg::Iv => Noise::IV,
        NoiseArg::Eiv => {
            Noise::ErrorsInVariables(SampleNoise::independent(a.noise_sigma.unwrap_or(f64::NAN)))
        }
    };
    options.output_error = a.output_error.map(|segment| OutputError {
        segment,
        ..OutputError::default()
    });
    options
}

/// Prints the report and writes the parameter file. `values(name)`: the
/// declared and the identified value of a parameter the report names.
fn write_results(
    a: &IdentifyArgs,
    fit: &Fit<'_>,
    id: &Identification,
    values: impl Fn(&str) -> Option<(f64, f64)>,
    standard: IdentifiedParameters,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let report = id.report();
    let dt = fit.dt;
    w(
        out,
        format_args!(
            "identify: {} from {} ({} runs, {} transitions, {}, dt = {dt} s), {} rule, prior ±{} of the declared values",
            fit.name,
            a.data.display(),
            fit.runs,
            id.transitions,
            if id.instrumented == id.transitions && id.instrumented > 0 {
                "instrumental variables".to_string()
            } else if id.instrumented == 0 {
                "least squares".to_string()
            } else {
                format!(
                    "instrumental variables on {} (the rest from runs too short for them by least squares)",
                    id.instrumented
                )
            },
            match fit.rule {
                RuleArg::Midpoint => "midpoint",
                RuleArg::FirstOrder => "first-order",
            },
            a.prior_sd
        ),
    )?;
    if let Some(r) = &id.refinement {
        w(
            out,
            format_args!(
                "output error: {} segments, {} samples, {} iterations{}; rms simulation error {:.3e} → {:.3e}, position noise σ ≈ {:.3e}",
                r.segments,
                r.samples,
                r.iterations,
                if r.converged {
                    ""
                } else {
                    " (iteration limit)"
                },
                r.rms_start,
                r.rms,
                r.position_sigma
            ),
        )?;
    }
    w(out, format_args!("{report}"))?;
    // every parameter the identification sets, as the report's DSL rows
    // say (a 3-D inertia's lower entries name the upper entry they
    // mirror); the values are the declared and the identified model's
    let mut parameters = Vec::new();
    for row in &report.dsl {
        let name = row.parameter.as_str();
        let Some((declared, value)) = values(name) else {
            return Err(CliError::Usage(format!(
                "identify: `{name}` in the report is not a parameter of `{}`",
                fit.name
            )));
        };
        let mut entry = serde_json::json!({
            "name": name,
            "declared": declared,
            "identified": value,
            "status": status_name(row.status),
        });
        if let Some(upper) = &row.mirror_of {
            entry["mirror_of"] = serde_json::json!(upper);
        }
        parameters.push(entry);
    }
    let base: Vec<_> = report
        .base
        .iter()
        .map(|r| {
            serde_json::json!({
                "name": r.parameter,
                "declared": r.declared,
                "identified": r.identified,
                "half_width_95": r.half_width,
                "status": status_name(r.status),
            })
        })
        .collect();
    // the standard parameters and their covariance, as a model file's
    // identified prior records them: `standard`
    let file = serde_json::json!({
        "format": FORMAT,
        "mechanism": fit.name,
        "dt": dt,
        "transitions": id.transitions,
        "instrumented": id.instrumented,
        "parameters": parameters,
        "base": base,
        "identified": standard,
    });
    let text = serde_json::to_string_pretty(&file).map_err(fail)?;
    std::fs::write(&a.out, text + "\n").map_err(io_error(&a.out))?;
    w(
        out,
        format_args!(
            "wrote {}: {} parameters; `vigp fit --prior identified:{}` takes them as the nominal model",
            a.out.display(),
            parameters.len(),
            a.out.display()
        ),
    )
}

fn status_name(s: Status) -> &'static str {
    match s {
        Status::Identified => "identified",
        Status::Uninformed => "uninformed",
        Status::NotIdentifiable => "not identifiable",
    }
}

/// The identified standard parameters and their covariance (the file's
/// `identified` section) of a parameter file of `vigp identify` for the
/// mechanism `name`.
pub(super) fn read_identified(path: &Path, name: &str) -> Result<IdentifiedParameters, CliError> {
    let bad =
        |why: String| CliError::Usage(format!("--prior identified:{}: {why}", path.display()));
    let text = std::fs::read_to_string(path).map_err(io_error(path))?;
    let file: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    if file["format"] != FORMAT {
        return Err(bad(format!(
            "not a parameter file of `vigp identify` (\"format\": \"{FORMAT}\")"
        )));
    }
    if file["mechanism"] != name {
        return Err(bad(format!(
            "identified for `{}`, not `{name}`",
            file["mechanism"].as_str().unwrap_or("?")
        )));
    }
    let section = file.get("identified").ok_or_else(|| {
        bad(
            "no \"identified\" section (the standard parameters and their covariance): \
             write the file again with `vigp identify`"
                .into(),
        )
    })?;
    let identified = serde_json::from_value::<IdentifiedParameters>(section.clone())
        .map_err(|e| bad(format!("\"identified\": {e}")))?;
    identified
        .validate()
        .map_err(|e| bad(format!("\"identified\": {e}")))?;
    Ok(identified)
}

/// Writes the identified parameters of the parameter file `path` into
/// `p` (the mechanism `name`), so that every view of it carries them.
pub(super) fn apply_identified<P: Parameters>(
    p: &mut P,
    name: &str,
    path: &Path,
) -> Result<IdentifiedParameters, CliError> {
    let identified = read_identified(path, name)?;
    identified
        .write_to(p)
        .map_err(|e| CliError::Usage(format!("--prior identified:{}: {e}", path.display())))?;
    Ok(identified)
}
