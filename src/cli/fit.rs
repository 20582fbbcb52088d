//! `vigp fit`: train a learned model on measured trajectories and save it.

use std::io::Write;
use std::time::Instant;

use super::args::{EncodingArg, FitArgs, PriorArg};
use super::identify::read_identified;
use super::{CliError, check_out_dir, data_error, read_log, spinner, w};
use crate::data::Dataset;
use crate::gp::{Method, Screening, SparseOptions, TrainOptions, TrainReport};
use crate::learned::{
    Encoding, ForcedTransition, LearnError, Learned, Prior, Transition, forced_transitions,
    transitions,
};
use crate::{Coordinates, Mechanism, Parameters, SVector, State, Variational};

pub(super) fn set_parameter<P: Parameters>(p: &mut P, assignment: &str) -> Result<(), CliError> {
    let bad = |why: String| CliError::Usage(format!("--set {assignment}: {why}"));
    let (name, value) = assignment
        .split_once('=')
        .ok_or_else(|| bad("expected NAME=VALUE".into()))?;
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| bad(format!("{value:?} is not a number")))?;
    if !value.is_finite() {
        return Err(bad("the value must be finite".into()));
    }
    let i = P::parameter_index(name.trim()).ok_or_else(|| {
        bad(format!(
            "no parameter `{name}`; the parameters are {}",
            P::PARAMETER_NAMES.join(", ")
        ))
    })?;
    if let Some(slot) = p.parameter_mut(i) {
        *slot = value;
    }
    Ok(())
}

/// `--max-samples` of the exact GP when none is given (training is O(N³)).
const DEFAULT_MAX_SAMPLES: usize = 512;

/// Evenly spaced selection of at most `max` items.
fn spread<T: Clone>(all: &[T], max: usize) -> Vec<T> {
    if all.len() <= max {
        return all.to_vec();
    }
    (0..max).map(|i| all[i * all.len() / max].clone()).collect()
}

/// The transitions `fit` trains on: at most `--max-samples` of `all`,
/// evenly spaced (default [`DEFAULT_MAX_SAMPLES`], all with `--sparse`),
/// at least one, and no fewer than `--sparse`'s inducing points.
pub(super) fn choose<T: Clone>(a: &FitArgs, all: &[T]) -> Result<Vec<T>, CliError> {
    let max = match (a.max_samples, a.sparse) {
        (Some(max), _) => max,
        (None, Some(_)) => usize::MAX,
        (None, None) => DEFAULT_MAX_SAMPLES,
    };
    let chosen = spread(all, max);
    if chosen.is_empty() {
        return Err(CliError::Usage(format!(
            "{}: no run has three samples: no transition to train on",
            a.data.display()
        )));
    }
    if let Some(m) = a.sparse.filter(|&m| m > chosen.len()) {
        return Err(CliError::Usage(format!(
            "--sparse {m}: more inducing points than the {} training transitions",
            chosen.len()
        )));
    }
    Ok(chosen)
}

/// What every view's training starts from: the data read with the
/// mechanism's columns, and how the views train.
pub(super) struct Prepared<const N: usize> {
    data: Dataset<N>,
    training: Training,
}

/// How every view of `fit` trains: the data's time step, the prior and the
/// GP training options.
struct Training {
    dt: f64,
    prior: Prior,
    opts: TrainOptions,
}

/// The checks, the data and the options of `fit`, before a view trains:
/// usage errors before the data are read (a long log takes a while), the
/// nominal parameters first (`--set` may have made a mass negative;
/// `maximal`: the check of the maximal view, or why it cannot be used).
/// `U`: the mechanism's inputs; with inputs the data carries `u_<joint>`
/// columns and the model learns on state and input (GP input: the encoded
/// state, then the previous and the current input; prior: the forced
/// nominal step).
pub(super) fn prepare<Mn, const N: usize, const C: usize, const U: usize>(
    a: &FitArgs,
    minimal: Mn,
    maximal: Result<(), CliError>,
    out: &mut dyn Write,
) -> Result<Prepared<N>, CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy,
    Mn: crate::Inputs<U>,
{
    if let Err(e) = minimal.constants() {
        return Err(nominal_invalid(e));
    }
    maximal?;
    let prior = resolve_prior(a, Mn::NAME, out)?;
    let opts = train_options(a)?;
    // before the training, which the write would otherwise waste
    check_out_dir(&a.out)?;
    let (data, dt) = read_log::<Mn, N, C>(&a.data, &a.read)?;
    report_data(&a.data, &data, dt, out)?;
    if U > 0 {
        input_shift_check::<Mn, N, C, U>(minimal, dt, &data, &a.data, out)?;
    }
    Ok(Prepared {
        data,
        training: Training { dt, prior, opts },
    })
}

/// The GP training options of `fit`'s flags, checked.
pub(super) fn train_options(a: &FitArgs) -> Result<TrainOptions, CliError> {
    if a.max_samples == Some(0) {
        return Err(CliError::Usage("--max-samples must be at least 1".into()));
    }
    if a.sparse == Some(0) {
        return Err(CliError::Usage(
            "--sparse needs at least 1 inducing point".into(),
        ));
    }
    if a.restarts > vigp_runtime::gp::MAX_RESTARTS {
        return Err(CliError::Usage(format!(
            "--restarts must be at most {}",
            vigp_runtime::gp::MAX_RESTARTS
        )));
    }
    if !(1..=vigp_runtime::gp::MAX_MEMORY).contains(&a.memory) {
        return Err(CliError::Usage(format!(
            "--memory must be from 1 to {}",
            vigp_runtime::gp::MAX_MEMORY
        )));
    }
    let mut opts = TrainOptions {
        restarts: a.restarts,
        seed: a.seed,
        memory: a.memory,
        method: match a.sparse {
            Some(m) => Method::Sparse(SparseOptions {
                optimise_inducing: a.optimise_inducing,
                ..SparseOptions::kmeans(m)
            }),
            None => Method::Exact,
        },
        screening: if a.no_screen {
            Screening::Off
        } else {
            Screening::Auto
        },
        ..TrainOptions::default()
    };
    if let Some(floor) = a.noise_floor {
        let upper = opts.bounds.noise_variance.1;
        if !(floor.is_finite() && floor > 0.0 && floor < upper) {
            return Err(CliError::Usage(format!(
                "--noise-floor must be finite and in (0, {upper}): {floor}"
            )));
        }
        opts.bounds.noise_variance.0 = floor;
    }
    Ok(opts)
}

/// The prior of `--prior` for the mechanism (or robot) `name`: an
/// identified one is read from its parameter file, and the report says so.
pub(super) fn resolve_prior(
    a: &FitArgs,
    name: &str,
    out: &mut dyn Write,
) -> Result<Prior, CliError> {
    Ok(match &a.prior {
        PriorArg::Nominal => Prior::Nominal,
        PriorArg::Constant => Prior::Constant,
        PriorArg::Identified(path) => {
            w(
                out,
                format_args!(
                    "prior: the nominal step with the parameters identified in {}",
                    path.display()
                ),
            )?;
            Prior::Identified(read_identified(path, name)?)
        }
    })
}

/// The report's line on the training data, and a note naming the runs too
/// short to give a transition.
pub(super) fn report_data<P: crate::data::Positions>(
    path: &std::path::Path,
    data: &crate::data::DatasetOf<P>,
    dt: f64,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    w(
        out,
        format_args!(
            "data: {}: {} runs, {} samples, dt = {dt} s",
            path.display(),
            data.runs.len(),
            data.samples()
        ),
    )?;
    let short: Vec<&str> = data.short_runs().map(|r| r.name.as_str()).collect();
    if !short.is_empty() {
        w(
            out,
            format_args!(
                "note: {} run(s) with fewer than 3 samples give no transitions: {}",
                short.len(),
                short.join(", ")
            ),
        )?;
    }
    Ok(())
}

/// The usage error of a nominal model whose parameters (with `--set`) no
/// integrator takes.
pub(super) fn nominal_invalid(e: impl std::fmt::Display) -> CliError {
    CliError::Usage(format!("the nominal model (with --set): {e}"))
}

/// Trains and saves a model in the minimal coordinates (`--encoding sincos`
/// or `minimal`).
pub(super) fn fit_minimal<Mn, const N: usize, const C: usize, const U: usize>(
    a: &FitArgs,
    minimal: Mn,
    p: &Prepared<N>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Parameters + Copy + Send + Sync + 'static,
    Mn: crate::Inputs<U>,
{
    let encoding = if a.encoding == EncodingArg::Sincos {
        Encoding::SinCos
    } else {
        Encoding::Raw
    };
    let all = if U == 0 {
        ViewTransitions::Plain(p.data.transitions())
    } else {
        let forced = p.data.forced_transitions::<U>();
        ViewTransitions::Forced(forced.map_err(data_error(&a.data))?)
    };
    fit_transitions::<Mn, N, C, U>(a, minimal, encoding, all, &p.training, out)
}

/// Trains and saves a model in a planar mechanism's maximal coordinates
/// (`--encoding maximal`): each run's transitions in the maximal
/// coordinates, with its inputs when the mechanism has some.
pub(super) fn fit_maximal<
    Mn,
    Mx,
    const N: usize,
    const NM: usize,
    const CM: usize,
    const U: usize,
>(
    a: &FitArgs,
    minimal: Mn,
    maximal: Mx,
    p: &Prepared<N>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Coordinates<N, NM>,
    Mx: Mechanism<NM, CM> + Parameters + Copy + Send + Sync + 'static,
    Mx: crate::Inputs<U>,
{
    let data = &p.data;
    let inputs = data.input_vectors::<U>().map_err(data_error(&a.data))?;
    let (mut plain, mut forced) = (Vec::new(), Vec::new());
    for (run, us) in data.runs.iter().zip(&inputs) {
        let Some(run_dt) = run.dt else { continue };
        let xs: Vec<SVector<f64, NM>> = run
            .positions
            .iter()
            .map(|q| minimal.maximal_positions(q))
            .collect();
        if U == 0 {
            plain.extend(transitions(&xs, run_dt));
        } else {
            forced.extend(forced_transitions(&xs, us, run_dt));
        }
    }
    let all = if U == 0 {
        ViewTransitions::Plain(plain)
    } else {
        ViewTransitions::Forced(forced)
    };
    fit_transitions::<Mx, NM, CM, U>(a, maximal, Encoding::Raw, all, &p.training, out)
}

/// A view's training transitions: of a mechanism without inputs, or with
/// the `U` inputs that drove them.
enum ViewTransitions<const N: usize, const U: usize> {
    Plain(Vec<Transition<N>>),
    Forced(Vec<ForcedTransition<N, U>>),
}

/// Trains `model` (a mechanism's minimal or maximal view) in `encoding` on
/// at most `--max-samples` of `all`, the plain or the forced way, then
/// reports and saves ([`fit_view`]).
fn fit_transitions<M, const N: usize, const C: usize, const U: usize>(
    a: &FitArgs,
    model: M,
    encoding: Encoding,
    all: ViewTransitions<N, U>,
    training: &Training,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Copy,
    M: crate::Inputs<U>,
{
    let Training { dt, prior, opts } = training;
    match all {
        ViewTransitions::Plain(all) => {
            let train = |chosen: &[Transition<N>]| {
                Learned::train(model, *dt, chosen, encoding, prior.clone(), opts)
            };
            fit_view(a, &all, encoding, training, 0, train, out)
        }
        ViewTransitions::Forced(all) => {
            let train = |chosen: &[ForcedTransition<N, U>]| {
                Learned::train_forced(model, *dt, chosen, encoding, prior.clone(), opts)
            };
            fit_view(a, &all, encoding, training, 2 * U, train, out)
        }
    }
}

/// A fitted noise variance below this fraction of the signal variance
/// leaves the posterior variance σ_f² − kᵀ(K + σ_n²I)⁻¹k at the level of
/// its rounding error near the data (≈ N·ε·σ_f² ≈ 1e-13·σ_f² at N = 512,
/// with a margin of 10³): `fit` then says so and names a floor.
const VARIANCE_RESOLVED: f64 = 1e-10;

/// Trains on at most `--max-samples` of `all` (`train`: the plain or the
/// forced training of one view, in `encoding`, as `training` says),
/// reports and saves. `u_dim`: the GP inputs that are control inputs,
/// after the `encoding`'s state inputs (2·U for a forced model: the
/// previous and the current input).
fn fit_view<M, T, const N: usize, const C: usize>(
    a: &FitArgs,
    all: &[T],
    encoding: Encoding,
    training: &Training,
    u_dim: usize,
    train: impl FnOnce(&[T]) -> Result<(Learned<M, N, C>, TrainReport), LearnError>,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    M: Mechanism<N, C> + Parameters + Clone,
    T: Copy,
{
    let opts = &training.opts;
    let chosen = choose(a, all)?;
    let d = encoding.dim(&M::KINDS) + u_dim;
    w(
        out,
        format_args!(
            "fit: {} in coordinates [{}]{}, {encoding:?} encoding ({d} inputs), {} prior: \
             N = {} of {} transitions, {} restarts{}",
            M::NAME,
            M::COORDINATES.join(", "),
            if u_dim > 0 {
                format!(" with inputs [{}]", M::INPUT_NAMES.join(", "))
            } else {
                String::new()
            },
            super::prior_name(&training.prior),
            chosen.len(),
            all.len(),
            opts.restarts,
            match a.sparse {
                Some(m) => format!(
                    ", sparse GP with {m} inducing points{}",
                    if a.optimise_inducing {
                        " (optimised)"
                    } else {
                        ""
                    }
                ),
                None => String::new(),
            }
        ),
    )?;
    let (learned, report) =
        train_timed(N, chosen.len(), opts.restarts, out, || Ok(train(&chosen)?))?;
    for (j, o) in report.outputs.iter().enumerate() {
        w(
            out,
            format_args!(
                "  v_{}: log marginal likelihood {:.4e}, best start {}, jitter {:.1e}{}{}",
                M::COORDINATES[j],
                o.log_marginal_likelihood,
                o.best_start,
                o.jitter,
                if o.converged { "" } else { " (iteration cap)" },
                match &o.screening {
                    Some(s) if s.fell_back => format!(
                        " (screened on {} transitions; refit on all as white noise won)",
                        s.subset
                    ),
                    Some(s) => format!(
                        " (screened on {} transitions, {} {} refined on all)",
                        s.subset,
                        s.refined.len(),
                        if s.refined.len() == 1 {
                            "optimum"
                        } else {
                            "optima"
                        }
                    ),
                    None => String::new(),
                }
            ),
        )?;
    }
    if let Some(z) = &report.inducing {
        w(
            out,
            format_args!(
                "  inducing points optimised: summed bound {:.4e} -> {:.4e} in {} iterations{}",
                z.bound_before,
                z.bound_after,
                z.iterations,
                if z.converged { "" } else { " (iteration cap)" }
            ),
        )?;
    }
    if a.sparse.is_none() {
        for (j, o) in learned.gp().outputs().iter().enumerate() {
            let hp = o.hyperparameters();
            let ratio = hp.noise_variance / hp.signal_variance;
            // the smallest power of ten at or above the resolvable floor
            // (the 1e-9 keeps an exact power of ten from rounding up)
            let floor =
                10f64.powf(((VARIANCE_RESOLVED * hp.signal_variance).log10() - 1e-9).ceil());
            if hp.noise_variance < 0.5 * floor {
                w(
                    out,
                    format_args!(
                        "note: v_{}: noise variance {:.1e} is {ratio:.0e} of the signal variance \
                         {:.1e} (normalised units): the posterior variance can be lost to rounding \
                         and `predict --bound rkhs|theorem1` refuse such states; refit with \
                         --noise-floor {floor:e} or bound with --calibration",
                        M::COORDINATES[j],
                        hp.noise_variance,
                        hp.signal_variance,
                    ),
                )?;
            }
        }
    }
    learned.save(&a.out).map_err(|source| CliError::Model {
        path: a.out.clone(),
        source,
    })?;
    report_saved(&a.out, out)
}

/// Runs `train` behind a spinner that says what trains (`gps` GPs on `n`
/// transitions, each from 1 + `restarts` starts), then reports how long it
/// took (a view of `fit`, or a robot).
pub(super) fn train_timed<T>(
    gps: usize,
    n: usize,
    restarts: usize,
    out: &mut dyn Write,
    train: impl FnOnce() -> Result<T, CliError>,
) -> Result<T, CliError> {
    let pb = spinner(format!(
        "training {gps} GPs on N = {n} ({} starts each)",
        1 + restarts
    ));
    let start = Instant::now();
    let result = train();
    pb.finish_and_clear();
    let trained = result?;
    w(
        out,
        format_args!("trained in {:.1} s", start.elapsed().as_secs_f64()),
    )?;
    Ok(trained)
}

/// The report's last line on a model saved to `path`: its size.
pub(super) fn report_saved(path: &std::path::Path, out: &mut dyn Write) -> Result<(), CliError> {
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    w(
        out,
        format_args!("wrote {} ({bytes} bytes)", path.display()),
    )
}

/// How much better a one-row shift of the inputs must fit the data than
/// the inputs as logged before `fit` warns ([`input_shift_check`]).
const SHIFT_FACTOR: f64 = 10.0;

/// Transitions the shift check steps at most (evenly spaced).
const SHIFT_SAMPLES: usize = 400;

/// Warns when the inputs fit the data markedly better shifted by one row:
/// the nominal (first-order) model's one-step position error
/// |x_{k+2} − (x_{k+1} + Δt·v_{k+1})|², averaged over up to 400
/// transitions, with each step driven by row k + 1's input as logged
/// (the reader's convention) and by row k's or row k + 2's instead. A
/// shift whose error is below 1/10 of the logged one (and the logged
/// one above 1e-20, rounding) gets a warning naming the direction. A
/// model far from the truth fits every alignment about equally badly and
/// is not flagged.
fn input_shift_check<Mn, const N: usize, const C: usize, const U: usize>(
    nominal: Mn,
    dt: f64,
    data: &Dataset<N>,
    path: &std::path::Path,
    out: &mut dyn Write,
) -> Result<(), CliError>
where
    Mn: Mechanism<N, C> + Copy,
    Mn: crate::Inputs<U>,
{
    let inputs = data.input_vectors::<U>().map_err(data_error(path))?;
    // transitions k of each run with rows k .. k + 2 for every shift
    let mut cases: Vec<(usize, usize)> = Vec::new();
    for (r, run) in data.runs.iter().enumerate() {
        if run.dt.is_some() && run.positions.len() >= 4 {
            cases.extend((1..run.positions.len() - 2).map(|k| (r, k)));
        }
    }
    let cases = spread(&cases, SHIFT_SAMPLES);
    let vi = Variational::new(nominal, dt)?;
    let mut sums = [0.0f64; 3];
    let mut used = 0usize;
    for (r, k) in cases {
        let run = &data.runs[r];
        let Some(z) = run.state(k) else { continue };
        let errors: Option<Vec<f64>> = [k, k + 1, k + 2]
            .iter()
            .map(|&row| {
                let z1: State<N> = vi.step_forced(&z, &inputs[r][row]).ok()?;
                let x2 = z1.q + z1.v * dt;
                Some((x2 - run.positions[k + 2]).norm_squared() / N as f64)
            })
            .collect();
        if let Some(e) = errors {
            for (sum, e) in sums.iter_mut().zip(e) {
                *sum += e;
            }
            used += 1;
        }
    }
    if used == 0 {
        return Ok(());
    }
    let [early, logged, late] = sums.map(|s| s / used as f64);
    let (best, which) = if early <= late {
        (early, "early")
    } else {
        (late, "late")
    };
    if logged > 1e-20 && best * SHIFT_FACTOR < logged {
        w(
            out,
            format_args!(
                "warning: {}: the inputs look logged one row {which}: the nominal model's one-step \
                 position error (mean square over {used} transitions) is {logged:.2e} with the \
                 inputs as logged and {best:.2e} with each taken from the row {} (≥ {SHIFT_FACTOR}× \
                 better). The reader holds row k's input from t_k to t_(k+1): the step from row k \
                 to row k + 1 is driven by row k + 1's input",
                path.display(),
                if which == "early" { "before" } else { "after" }
            ),
        )?;
    }
    Ok(())
}
