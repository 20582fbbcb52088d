//! `vigp excite`: an input that excites the mechanism for identification
//! ([`crate::identify::excitation`]), written as a plan that `vigp
//! simulate --inputs` reads.

use std::io::Write;

use super::args::{ExciteArgs, RuleArg};
use super::{CliError, check_out_dir, io_error, w};
use crate::identify::DelRegressor;
use crate::identify::excitation::{Excitation, Problem};
use crate::{Inputs, Mechanism, Parameters};

pub(super) fn excite<Mn, const N: usize, const C: usize, const U: usize>(
    a: &ExciteArgs,
    minimal: Mn,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy + Inputs<U>,
{
    let usage = |why: String| Err(CliError::Usage(why));
    if U == 0 {
        return usage(format!(
            "{} has no inputs (no `actuated` joint): nothing to excite",
            Mn::NAME
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
        1 => vec![a.amplitude[0]; U],
        n if n == U => a.amplitude.clone(),
        n => {
            return usage(format!(
                "--amplitude has {n} value(s); {} has {U} input(s): {} (or give one for all)",
                Mn::NAME,
                Mn::INPUT_NAMES.join(", ")
            ));
        }
    };
    let q = if a.q.is_empty() {
        vec![0.0; N]
    } else if a.q.len() == N {
        a.q.clone()
    } else {
        return usage(format!(
            "--q has {} value(s); {} has {N} coordinates: {}",
            a.q.len(),
            Mn::NAME,
            Mn::COORDINATES.join(", ")
        ));
    };
    if let Some(path) = &a.out {
        check_out_dir(path)?;
    }
    let fail = |e: crate::identify::IdentifyError| CliError::Usage(format!("excite: {e}"));
    let regressor = match a.rule {
        RuleArg::Midpoint => DelRegressor::midpoint(minimal, a.dt),
        RuleArg::FirstOrder => DelRegressor::first_order(minimal, a.dt),
    }
    .map_err(fail)?;
    let mut problem = Problem::new(q, steps, a.harmonics, amplitude);
    problem.seed = a.seed;
    problem.starts = a.starts;
    let ex = Excitation::<_, N, C, U>::new(&regressor, &problem).map_err(fail)?;
    let d = ex.design().map_err(fail)?;
    let random = ex
        .evaluate(&ex.random(a.seed.wrapping_add(0x5EED)))
        .map_err(fail)?;
    w(
        out,
        format_args!(
            "excite: {} over {} steps of {} s, {} harmonic(s) of period {} s, |u| ≤ {:?}; {} base parameters",
            Mn::NAME,
            steps,
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
    if let Some(path) = &a.out {
        let mut text = String::from("t");
        for n in Mn::INPUT_NAMES {
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
        w(
            out,
            format_args!(
                "wrote {}: {} rows, row j drives step j (`vigp simulate --dt {} --steps {} --inputs {}`)",
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
