//! `vigp predict`: learned trajectories with error bounds.

use std::io::Write;

use super::args::{BoundArg, PredictArgs};
use super::{CliError, bar, check_out_dir, data_error, io_error, read_data, w, window_place};
use crate::bound::{BoundKind, Calibration};
use crate::data::Dataset;
use crate::learned::Learned;
use crate::{Integrator, Mechanism, SVector, State};

/// `U`: the mechanism's inputs (0 for none; with inputs each run's logged
/// inputs drive its prediction).
pub(super) fn predict<L, const N: usize, const K: usize, const CK: usize, const U: usize>(
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
