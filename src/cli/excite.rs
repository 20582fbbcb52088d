//! `vigp excite`: an input that excites the mechanism or robot for
//! identification ([`crate::identify::excitation`]), written as a plan that
//! `vigp simulate --inputs` reads.

use std::io::Write;

use super::args::{ExciteArgs, RuleArg};
use super::{CliError, check_out_dir, io_error, w};
use crate::identify::excitation::{Excitation, Problem};
use crate::identify::{DelRegressor, IdentifyError, Regressor, RobotRegressor};
use crate::robot::Robot;
use crate::{Inputs, Mechanism, Parameters};

fn fail(e: IdentifyError) -> CliError {
    CliError::Usage(format!("excite: {e}"))
}

/// `excite --system`: the design on the mechanism's own variational
/// integrator, the rule of `--rule` (default midpoint).
pub(super) fn excite<Mn, const N: usize, const C: usize, const U: usize>(
    a: &ExciteArgs,
    minimal: Mn,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy + Inputs<U>,
{
    let problem = problem(a, Mn::NAME, &Mn::COORDINATES, Mn::INPUT_NAMES)?;
    let regressor = match a.rule.unwrap_or(RuleArg::Midpoint) {
        RuleArg::Midpoint => DelRegressor::midpoint(minimal, a.dt),
        RuleArg::FirstOrder => DelRegressor::first_order(minimal, a.dt),
    }
    .map_err(fail)?;
    let ex = Excitation::new::<U>(&regressor, &problem).map_err(fail)?;
    design(a, Mn::NAME, &ex, &problem, Mn::INPUT_NAMES, out)
}

/// `excite --urdf`: the design on the robot's tree engine, within the
/// URDF's joint position and velocity limits (`<limit>`; a continuous
/// joint has none), the regressor's rule that of `--rule` (default first
/// order, the engine's).
pub(super) fn excite_robot(
    a: &ExciteArgs,
    robot: &Robot,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let joints: Vec<&str> = robot.joint_names().iter().map(String::as_str).collect();
    let inputs = robot.input_names();
    let mut problem = problem(a, robot.name(), &joints, &inputs)?;
    let limits: Vec<_> = robot.tree().bodies.iter().map(|b| b.limits).collect();
    if limits
        .iter()
        .any(|l| l.lower.is_finite() || l.upper.is_finite())
    {
        problem.position_limits = limits.iter().map(|l| (l.lower, l.upper)).collect();
    }
    if limits.iter().any(|l| l.velocity.is_finite()) {
        problem.velocity_limits = limits.iter().map(|l| l.velocity).collect();
    }
    let regressor = match a.rule.unwrap_or(RuleArg::FirstOrder) {
        RuleArg::Midpoint => RobotRegressor::midpoint(robot, a.dt),
        RuleArg::FirstOrder => RobotRegressor::new(robot, a.dt),
    }
    .map_err(fail)?;
    let ex = Excitation::robot(&regressor, &problem).map_err(fail)?;
    design(a, robot.name(), &ex, &problem, &inputs, out)
}

/// The problem of the arguments: steps, amplitudes and start checked
/// against the mechanism's coordinates and inputs.
fn problem(
    a: &ExciteArgs,
    name: &str,
    coordinates: &[&str],
    inputs: &[&str],
) -> Result<Problem, CliError> {
    let usage = |why: String| Err(CliError::Usage(why));
    let (n, u) = (coordinates.len(), inputs.len());
    if u == 0 {
        return usage(format!(
            "{name} has no inputs (no `actuated` joint): nothing to excite"
        ));
    }
    if !(a.dt.is_finite() && a.dt > 0.0) {
        return usage(format!("--dt must be finite and > 0: {}", a.dt));
    }
    if !(a.duration.is_finite() && a.duration >= a.dt) {
        return usage(format!(
            "--duration must be finite and at least --dt: {}",
            a.duration
        ));
    }
    let steps = (a.duration / a.dt).round();
    if steps > 1e7 {
        return usage(format!("--duration / --dt = {steps} steps: too many"));
    }
    let steps = steps as usize;
    let amplitude = match a.amplitude.len() {
        1 => vec![a.amplitude[0]; u],
        k if k == u => a.amplitude.clone(),
        k => {
            return usage(format!(
                "--amplitude has {k} value(s); {name} has {u} input(s): {} (or give one for all)",
                inputs.join(", ")
            ));
        }
    };
    let q = if a.q.is_empty() {
        vec![0.0; n]
    } else if a.q.len() == n {
        a.q.clone()
    } else {
        return usage(format!(
            "--q has {} value(s); {name} has {n} coordinates: {}",
            a.q.len(),
            coordinates.join(", ")
        ));
    };
    if let Some(path) = &a.out {
        check_out_dir(path)?;
    }
    let mut problem = Problem::new(q, steps, a.harmonics, amplitude);
    problem.seed = a.seed;
    problem.starts = a.starts;
    Ok(problem)
}

/// Designs, reports against a random input of the same amplitude and
/// writes the plan.
fn design<R: Regressor>(
    a: &ExciteArgs,
    name: &str,
    ex: &Excitation<'_, R>,
    problem: &Problem,
    inputs: &[&str],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let steps = problem.steps;
    let d = ex.design().map_err(fail)?;
    let random = ex
        .evaluate(&ex.random(a.seed.wrapping_add(0x5EED)))
        .map_err(fail)?;
    w(
        out,
        format_args!(
            "excite: {name} over {steps} steps of {} s, {} harmonic(s) of period {} s, |u| ≤ {:?}; {} base parameters",
            a.dt,
            a.harmonics,
            ex.period(),
            problem.amplitude,
            ex.base().len()
        ),
    )?;
    w(
        out,
        format_args!(
            "log det information: design {:.4}, best of {} random starts {:.4}, a random input of the same amplitude {:.4} ({} iterations, {} evaluations)",
            d.evaluation.log_det,
            a.starts,
            d.start_log_det,
            random.log_det,
            d.iterations,
            d.evaluations
        ),
    )?;
    if !problem.position_limits.is_empty() || !problem.velocity_limits.is_empty() {
        w(
            out,
            format_args!(
                "joint limits (the URDF's): largest excess of the design {:.3e}, of the random input {:.3e}",
                d.evaluation.violation, random.violation
            ),
        )?;
    }
    if let Some(path) = &a.out {
        let mut text = String::from("t");
        for n in inputs {
            text.push_str(&format!(",u_{n}"));
        }
        text.push('\n');
        for (j, u) in d.input.sample(steps, a.dt).iter().enumerate() {
            text.push_str(&crate::data::format_time(0.0, a.dt, j));
            for v in u {
                text.push_str(&format!(",{v:?}"));
            }
            text.push('\n');
        }
        std::fs::write(path, text).map_err(io_error(path))?;
        let source = if a.mechanism.urdf.is_some() {
            "--urdf … --actuated …"
        } else {
            "--system …"
        };
        w(
            out,
            format_args!(
                "wrote {}: {} rows, row j drives step j (`vigp simulate {source} --dt {} --steps {} --inputs {}`)",
                path.display(),
                steps,
                a.dt,
                steps,
                path.display()
            ),
        )?;
    }
    Ok(())
}
