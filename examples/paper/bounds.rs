//! The error bounds in the paper example: for each system and coordinate
//! choice, coverage and tightness (median bound ÷ median error) of the
//! three kinds at δ = 0.05, one step and 20 steps, on held-out trajectories
//! from other seeds, and on trajectories started outside the training
//! region (more energy than any training start); and a figure of a
//! predicted trajectory with its bound tubes against the truth.
//!
//! Protocol per system: the perturbed truth and noisy training pool of the
//! Fig. 2 protocol (one run, N = the largest sample count); calibration and
//! test trajectories (2 s, random configurations at rest, as the training
//! ones) from two further seeds, cut into 20-step windows every 10 samples;
//! the calibration windows calibrate the conformal bound (and give the
//! rigorous kinds their sample states), the test windows are the cases.

use super::{Cli, DT, HORIZON, Rng, SystemSpec, add_noise, ground_truth};
use crate::font::FONT;
use nalgebra::SVector;
use plotters::prelude::*;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use vigp::bound::{
    BoundKind, BoundedPrediction, Calibration, ConformalSettings, ErrorBound, Score, Window,
};
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, Learned, Transition, transitions};
use vigp::prelude::*;
use vigp::projection::consistent_state;

/// Miscoverage of every bound in this evaluation.
pub const DELTA: f64 = 0.05;
/// Samples between the starts of consecutive windows of one trajectory.
const STRIDE: usize = 10;

/// Coverage and tightness of one bound on one set of cases.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BoundRow {
    /// System name.
    pub system: String,
    /// `minimal`, `sincos` or `maximal`.
    pub coords: String,
    /// `conformal`, `conformal-latent` (score normalised by the latent σ,
    /// for noise-free targets such as these), `theorem1` or `rkhs`.
    pub kind: String,
    /// `held-out` (starts like the training ones) or `shifted`.
    pub set: String,
    /// Cases evaluated.
    pub cases: usize,
    /// Predictions that failed (a projection or nominal step), left out.
    pub failed: usize,
    /// Fraction of cases whose start the bound flags as outside its region.
    #[serde(with = "crate::shard::exact")]
    pub flagged: f64,
    /// Fraction of one-step velocity errors within their bound.
    #[serde(with = "crate::shard::exact")]
    pub one_step_coverage: f64,
    /// Median one-step bound ÷ median one-step error.
    #[serde(with = "crate::shard::exact")]
    pub one_step_tightness: f64,
    /// Fraction of 20-step position errors within their bound.
    #[serde(with = "crate::shard::exact")]
    pub k_step_coverage: f64,
    /// Median 20-step bound ÷ median 20-step error.
    #[serde(with = "crate::shard::exact")]
    pub k_step_tightness: f64,
    /// Median 20-step position error.
    #[serde(with = "crate::shard::exact")]
    pub k_step_median_error: f64,
}

/// One predicted window with its bound tubes, for the figure.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Tube {
    /// System name.
    pub system: String,
    /// Coordinate choice.
    pub coords: String,
    /// Name of the first coordinate (the one plotted).
    pub coordinate: String,
    /// Time of each step (s).
    #[serde(with = "crate::shard::exact")]
    pub t: Vec<f64>,
    /// True minus predicted first coordinate at each step.
    #[serde(with = "crate::shard::exact")]
    pub deviation: Vec<f64>,
    /// Per kind: the position bound at each step.
    #[serde(with = "crate::shard::exact")]
    pub bounds: Vec<(String, Vec<f64>)>,
}

/// Positions every DT for 2 s from (q0, q̇0), by the ground truth's
/// integrator at its step.
fn ground_truth_moving<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    q0: &SVector<f64, N>,
    qd0: &SVector<f64, N>,
    gt: super::Gt,
) -> Result<Vec<SVector<f64, N>>, String> {
    let sub = (DT / gt.dt).round().max(1.0) as usize;
    let h = DT / sub as f64;
    let mut z = consistent_state(&m, q0, qd0, h).map_err(|e| e.to_string())?;
    // samples every DT from z by `sub` steps of `vi` each
    let run = |vi: &dyn Fn(&State<N>) -> Result<State<N>, StepError>, mut z: State<N>| {
        let samples = super::TRAJ_SAMPLES;
        let mut out = Vec::with_capacity(samples);
        out.push(z.q);
        for _ in 1..samples {
            for _ in 0..sub {
                z = vi(&z).map_err(|e| e.to_string())?;
            }
            out.push(z.q);
        }
        Ok::<_, String>(out)
    };
    match gt.method {
        super::GtMethod::Midpoint => {
            let vi = Variational::midpoint(m, h).map_err(|e| e.to_string())?;
            run(&|z| vi.step(z), z)
        }
        super::GtMethod::Vi4 => {
            // continuous velocity: q̇0 projected onto the tangent space
            // G(q)·q̇ = 0, v = q̇0 − Gᵀ(GGᵀ)⁻¹G q̇0
            if C > 0 {
                let g = m.constraint_jacobian(&z.q);
                let g = nalgebra::DMatrix::from_column_slice(C, N, g.as_slice());
                let lam = (&g * g.transpose())
                    .lu()
                    .solve(&(&g * nalgebra::DVector::from_column_slice(qd0.as_slice())))
                    .ok_or("singular constraint Jacobian at a start")?;
                let correction = g.transpose() * lam;
                z.v = qd0 - SVector::<f64, N>::from_column_slice(correction.as_slice());
            } else {
                z.v = *qd0;
            }
            let vi = Composition::new(m, h)
                .and_then(|c| c.options(super::GT_SOLVER))
                .map_err(|e| e.to_string())?;
            run(&|z| vi.step(z), z)
        }
    }
}

fn median(v: &[f64]) -> f64 {
    let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The errors and bounds of one predicted window.
struct Case {
    one_error: f64,
    one_bound: f64,
    k_error: f64,
    k_bound: f64,
    flagged: bool,
}

#[allow(clippy::too_many_arguments)]
fn row(
    system: &str,
    coords: &'static str,
    kind: &'static str,
    set: &'static str,
    results: &[Option<Case>],
) -> BoundRow {
    let ok: Vec<&Case> = results.iter().flatten().collect();
    let n = ok.len().max(1) as f64;
    let frac = |f: &dyn Fn(&Case) -> bool| ok.iter().filter(|c| f(c)).count() as f64 / n;
    let med = |f: &dyn Fn(&Case) -> f64| median(&ok.iter().map(|c| f(c)).collect::<Vec<_>>());
    BoundRow {
        system: system.into(),
        coords: coords.into(),
        kind: kind.into(),
        set: set.into(),
        cases: ok.len(),
        failed: results.len() - ok.len(),
        flagged: frac(&|c| c.flagged),
        one_step_coverage: frac(&|c| c.one_error <= c.one_bound),
        one_step_tightness: med(&|c| c.one_bound) / med(&|c| c.one_error),
        k_step_coverage: frac(&|c| c.k_error <= c.k_bound),
        k_step_tightness: med(&|c| c.k_bound) / med(&|c| c.k_error),
        k_step_median_error: med(&|c| c.k_error),
    }
}

/// Every kind at [`DELTA`] for one trained model: rows for the held-out and
/// shifted cases, and the tube of one held-out window.
#[allow(clippy::type_complexity)]
fn evaluate_model<Mo: Mechanism<P, Q> + Clone + Sync, const P: usize, const Q: usize>(
    system: &str,
    coords: &'static str,
    learned: &Learned<Mo, P, Q>,
    cal: &Calibration<P>,
    sets: [(&'static str, &[Window<P>]); 2],
) -> Result<(Vec<BoundRow>, Tube), Box<dyn Error>> {
    let mut rows = Vec::new();
    let tube_window = &sets[0].1[sets[0].1.len() / 2];
    let mut tube = Tube {
        system: system.into(),
        coords: coords.into(),
        coordinate: Mo::COORDINATES[0].into(),
        t: (0..=HORIZON).map(|k| k as f64 * DT).collect(),
        deviation: Vec::new(),
        bounds: Vec::new(),
    };
    let kinds = [
        ("conformal", BoundKind::conformal(DELTA)),
        (
            "conformal-latent",
            BoundKind::Conformal(ConformalSettings {
                score: Score::LatentStd,
                ..ConformalSettings::default()
            }),
        ),
        ("theorem1", BoundKind::theorem1(DELTA)),
        ("rkhs", BoundKind::rkhs(DELTA)),
    ];
    let bounds = kinds
        .iter()
        .map(|(_, kind)| learned.error_bound(kind, cal))
        .collect::<Result<Vec<_>, _>>()?;
    let refs: Vec<&ErrorBound> = bounds.iter().collect();
    // every kind on the same predictions (`predict_bounds` shares the
    // states, variances and Jacobians); a window whose joint prediction
    // fails is retried kind by kind, so that one kind's failure (e.g. a
    // non-finite bound) does not drop the others' cases
    let predict_all = |start: &State<P>| -> Vec<Option<BoundedPrediction<P>>> {
        match learned.predict_bounds(start, HORIZON, &refs) {
            Ok(all) => all.into_iter().map(Some).collect(),
            Err(_) => refs
                .iter()
                .map(|b| learned.predict(start, HORIZON, b).ok())
                .collect(),
        }
    };
    let predicted: Vec<Vec<Vec<Option<BoundedPrediction<P>>>>> = sets
        .iter()
        .map(|(_, windows)| windows.par_iter().map(|w| predict_all(&w.start)).collect())
        .collect();
    let tube_predictions = predict_all(&tube_window.start);
    for (k, (name, _)) in kinds.iter().enumerate() {
        for ((set, windows), per_window) in sets.iter().zip(&predicted) {
            let results: Vec<Option<Case>> = windows
                .iter()
                .zip(per_window)
                .map(|(w, all)| {
                    let p = all[k].as_ref()?;
                    let v1 = (w.positions[1] - w.positions[0]) / DT;
                    Some(Case {
                        one_error: (p.states[1].v - v1).norm(),
                        one_bound: p.one_step_bounds[0],
                        k_error: (p.states[HORIZON].q - w.positions[HORIZON - 1]).norm(),
                        k_bound: p.position_bounds[HORIZON],
                        flagged: p.outside[0],
                    })
                })
                .collect();
            rows.push(row(system, coords, name, set, &results));
        }
        if *name == "conformal-latent" {
            continue;
        }
        let p = match &tube_predictions[k] {
            Some(p) => p.clone(),
            // the error itself, as before
            None => learned.predict(&tube_window.start, HORIZON, &bounds[k])?,
        };
        if tube.deviation.is_empty() {
            tube.deviation = std::iter::once(0.0)
                .chain(
                    p.states[1..]
                        .iter()
                        .zip(&tube_window.positions)
                        .map(|(z, q)| q[0] - z.q[0]),
                )
                .collect();
        }
        tube.bounds.push((name.to_string(), p.position_bounds));
    }
    Ok((rows, tube))
}

fn windows_of<const P: usize>(
    trajs: &[Vec<SVector<f64, P>>],
) -> Result<Vec<Window<P>>, Box<dyn Error>> {
    Ok(Calibration::from_trajectories(trajs, DT, HORIZON, STRIDE)?
        .windows()
        .to_vec())
}

/// Draws a configuration at rest.
pub type Start<'a, const N: usize> = dyn Fn(&mut Rng) -> SVector<f64, N> + Sync + 'a;
/// Draws a configuration and a velocity.
pub type MovingStart<'a, const N: usize> =
    dyn Fn(&mut Rng) -> (SVector<f64, N>, SVector<f64, N>) + Sync + 'a;

/// The bound evaluation of one system (all three coordinate choices).
pub fn evaluate<S, Mn, Mx, const N: usize, const C: usize, const M: usize, const K: usize>(
    spec: &SystemSpec<S, Mn, Mx>,
    sample_q0: &Start<'_, N>,
    shifted_start: &MovingStart<'_, N>,
    cli: &Cli,
) -> Result<(Vec<BoundRow>, Vec<Tube>), Box<dyn Error>>
where
    S: Default + Copy + Send + Sync,
    Mn: Mechanism<N, C> + Coordinates<N, M> + vigp::Parameters + Copy + Send + Sync,
    Mx: Mechanism<M, K> + vigp::Parameters + Copy + Send + Sync,
{
    let seed = cli.protocol.seed ^ 0xB0D5_0000 ^ spec.name.len() as u64;
    let mut rng = Rng(seed);
    let (tmin, nmin, nmax) = spec.models(&mut rng);
    let at_rest = |seed: u64, count: usize| -> Result<Vec<Vec<SVector<f64, N>>>, StepError> {
        let mut r = Rng(seed);
        let starts: Vec<SVector<f64, N>> = (0..count).map(|_| sample_q0(&mut r)).collect();
        starts
            .par_iter()
            .map(|q0| ground_truth(tmin, q0, cli.protocol.gt()))
            .collect()
    };
    let train = at_rest(seed ^ 1, cli.protocol.train_trajectories)?;
    let cal = at_rest(seed ^ 2, cli.bound_trajectories)?;
    let test = at_rest(seed ^ 3, cli.bound_trajectories)?;
    let shifted: Vec<Vec<SVector<f64, N>>> = {
        let mut r = Rng(seed ^ 4);
        let starts: Vec<_> = (0..cli.bound_trajectories / 3 + 1)
            .map(|_| shifted_start(&mut r))
            .collect();
        starts
            .par_iter()
            .map(|(q0, qd0)| ground_truth_moving(tmin, q0, qd0, cli.protocol.gt()))
            .collect::<Result<_, _>>()?
    };
    let to_max = |trajs: &[Vec<SVector<f64, N>>]| -> Vec<Vec<SVector<f64, M>>> {
        trajs
            .iter()
            .map(|t| t.iter().map(|q| tmin.maximal_positions(q)).collect())
            .collect()
    };
    let mut pool_min: Vec<Transition<N>> = Vec::new();
    let mut pool_max: Vec<Transition<M>> = Vec::new();
    for (tn, tm) in train.iter().zip(to_max(&train)) {
        for (a, b) in transitions(tn, DT).iter().zip(transitions(&tm, DT).iter()) {
            pool_min.push(add_noise(a, &mut rng));
            pool_max.push(add_noise(b, &mut rng));
        }
    }
    let n = cli
        .protocol
        .n
        .iter()
        .copied()
        .max()
        .unwrap_or(64)
        .min(pool_min.len());
    let idx: Vec<usize> = (0..n).map(|_| rng.below(pool_min.len())).collect();
    let dmin: Vec<_> = idx.iter().map(|&i| pool_min[i]).collect();
    let dmax: Vec<_> = idx.iter().map(|&i| pool_max[i]).collect();
    let opts = TrainOptions {
        restarts: cli.protocol.restarts,
        seed: cli.protocol.seed ^ n as u64,
        screening: cli.screening(),
        memory: cli.protocol.memory,
        ..TrainOptions::default()
    };
    let (cal_min, test_min, shift_min) =
        (windows_of(&cal)?, windows_of(&test)?, windows_of(&shifted)?);
    let cal_min = Calibration::new(DT, cal_min)?;
    let (cal_max, test_max, shift_max) = (
        windows_of(&to_max(&cal))?,
        windows_of(&to_max(&test))?,
        windows_of(&to_max(&shifted))?,
    );
    let cal_max = Calibration::new(DT, cal_max)?;
    let mut rows = Vec::new();
    let mut tubes = Vec::new();
    for (coords, enc) in [("minimal", Encoding::Raw), ("sincos", Encoding::SinCos)] {
        let (l, _) = Learned::train(nmin, DT, &dmin, enc, spec.prior.clone(), &opts)?;
        let (r, t) = evaluate_model(
            spec.name,
            coords,
            &l,
            &cal_min,
            [("held-out", &test_min), ("shifted", &shift_min)],
        )?;
        rows.extend(r);
        tubes.push(t);
    }
    let (l, _) = Learned::train(nmax, DT, &dmax, Encoding::Raw, spec.prior.clone(), &opts)?;
    let (r, t) = evaluate_model(
        spec.name,
        "maximal",
        &l,
        &cal_max,
        [("held-out", &test_max), ("shifted", &shift_max)],
    )?;
    rows.extend(r);
    tubes.push(t);
    Ok((rows, tubes))
}

/// The Markdown section of the report.
pub fn report(rows: &[BoundRow], cli: &Cli) -> String {
    let mut md = String::new();
    // `write!` into a String cannot fail.
    let _ = writeln!(
        md,
        "# Error bounds\n\nδ = {DELTA}; per system one perturbed truth, N = {} noisy training samples (σ = 1e-3), {} calibration and {} test trajectories (2 s, random configurations at rest, as the training ones, from two further seeds) cut into 20-step windows every {STRIDE} samples, and {} trajectories started with more energy than any training start (\"shifted\"). Coverage: fraction of cases whose error is within the bound; tightness: median bound ÷ median error. One step: the velocity error ‖v₁ − v₁,true‖; 20 steps: the position error ‖q₂₀ − q₂₀,true‖ in the model's coordinates. Flagged: starts the bound marks as outside its region (for the conformal bound, those get the RKHS fallback). `conformal` is the default (scores normalised by the GP's predictive σ, for noisy targets); `conformal-latent` normalises by the latent σ (`Score::LatentStd`), the choice for noise-free targets such as these.\n",
        cli.protocol.n.iter().copied().max().unwrap_or(0),
        cli.bound_trajectories,
        cli.bound_trajectories,
        cli.bound_trajectories / 3 + 1
    );
    let _ = writeln!(
        md,
        "| system | coordinates | kind | starts | cases | flagged | one-step coverage | tightness | 20-step coverage | tightness | median 20-step error |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {}{} | {:.3} | {:.3} | {:.2} | {:.3} | {:.2} | {:.2e} |",
            r.system,
            r.coords,
            r.kind,
            r.set,
            r.cases,
            if r.failed > 0 {
                format!(" ({} failed)", r.failed)
            } else {
                String::new()
            },
            r.flagged,
            r.one_step_coverage,
            r.one_step_tightness,
            r.k_step_coverage,
            r.k_step_tightness,
            r.k_step_median_error
        );
    }
    md
}

const COLOURS: [RGBColor; 3] = [
    RGBColor(0, 90, 200),
    RGBColor(220, 60, 30),
    RGBColor(0, 150, 0),
];

/// Writes `bounds.csv`, `bounds.md`, `bounds_tube.csv` and the tube figure
/// `bounds_tube.svg`/`.png` (the `tube` argument: one window, three panels,
/// one per kind) into `dir`.
pub fn write(
    dir: &Path,
    rows: &[BoundRow],
    tube: Option<&Tube>,
    cli: &Cli,
) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    let path = dir.join("bounds.csv");
    let mut w = csv::Writer::from_path(&path)?;
    for r in rows {
        w.serialize(r)?;
    }
    w.flush()?;
    written.push(path);
    let mut md = report(rows, cli);
    if let Some(t) = tube {
        let path = dir.join("bounds_tube.csv");
        let mut w = csv::Writer::from_path(&path)?;
        w.write_record(["kind", "t", "deviation", "bound"])?;
        for (kind, b) in &t.bounds {
            for ((t, d), b) in t.t.iter().zip(&t.deviation).zip(b) {
                w.write_record([
                    kind.to_string(),
                    t.to_string(),
                    d.to_string(),
                    b.to_string(),
                ])?;
            }
        }
        w.flush()?;
        written.push(path);
        crate::font::register_embedded_font()?;
        for (ext, path) in [
            ("svg", dir.join("bounds_tube.svg")),
            ("png", dir.join("bounds_tube.png")),
        ] {
            if ext == "svg" {
                let root = SVGBackend::new(&path, (1440, 520)).into_drawing_area();
                draw_tube(&root, t)?;
                root.present()?;
            } else {
                let root = BitMapBackend::new(&path, (1440, 520)).into_drawing_area();
                draw_tube(&root, t)?;
                root.present()?;
            }
            written.push(path);
        }
        let _ = writeln!(
            md,
            "\n![bound tubes](bounds_tube.svg)\n\nThe figure: one held-out 20-step prediction ({}, {} coordinates): the truth minus the prediction in `{}` (line) and the ± position bound of each kind (band; the bound is on the norm of the whole position error, so it bounds each coordinate).",
            t.system, t.coords, t.coordinate
        );
    }
    let path = dir.join("bounds.md");
    std::fs::write(&path, md)?;
    written.push(path);
    Ok(written)
}

fn draw_tube<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    tube: &Tube,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(48);
    title.draw(&Text::new(
        format!(
            "Bound tubes of one 20-step prediction: {}, {} coordinates (δ = {DELTA})",
            tube.system, tube.coords
        ),
        (16, 12),
        (FONT, 22).into_font(),
    ))?;
    let panels = body.split_evenly((1, tube.bounds.len().max(1)));
    for (i, ((kind, bound), area)) in tube.bounds.iter().zip(panels.iter()).enumerate() {
        let top = bound
            .iter()
            .chain(
                tube.deviation
                    .iter()
                    .map(|d| d.abs())
                    .collect::<Vec<_>>()
                    .iter(),
            )
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            .max(1e-300)
            * 1.15;
        let t1 = tube.t.last().copied().unwrap_or(1.0);
        let mut chart = ChartBuilder::on(area)
            .caption(kind.as_str(), (FONT, 20))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(84)
            .build_cartesian_2d(0.0..t1, -top..top)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(format!("true − predicted {} ", tube.coordinate))
            .y_label_formatter(&|v| {
                if v.abs() < 1e-9 * top {
                    "0".to_string()
                } else {
                    format!("{v:.1e}")
                }
            })
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .light_line_style(RGBColor(242, 242, 242))
            .draw()?;
        let colour = COLOURS[i % COLOURS.len()];
        let band: Vec<(f64, f64)> = tube
            .t
            .iter()
            .zip(bound)
            .map(|(t, b)| (*t, *b))
            .chain(tube.t.iter().zip(bound).rev().map(|(t, b)| (*t, -*b)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                band,
                colour.mix(0.2).filled(),
            )))?
            .label(format!("± {kind} position bound"))
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], colour.mix(0.4).filled())
            });
        chart
            .draw_series(LineSeries::new(
                tube.t.iter().copied().zip(tube.deviation.iter().copied()),
                BLACK.stroke_width(2),
            ))?
            .label("truth − prediction")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .draw()?;
    }
    Ok(())
}
