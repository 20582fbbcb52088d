//! Output: CSV files of every measured number, log-log figures (SVG and
//! PNG) and a Markdown report, all in one directory.
//!
//! | file | content |
//! |---|---|
//! | `error.csv` | one row per (system, integrator, dt): error at T, cost, status |
//! | `summary.csv` | one row per (system, integrator): fitted order, cost to 1e-3 and 1e-6 |
//! | `reference.csv` | the reference solutions' accuracy and independent checks |
//! | `energy.csv` | one row per (system, integrator, dt) of the long energy runs |
//! | `work_precision.svg`, `.png` | error at T against cost per simulated second |
//! | `convergence.svg`, `.png` | error at T against dt (the observed orders) |
//! | `energy.svg`, `.png` | max energy error over the long run against cost |
//! | `report.md` | settings, machine load, tables |
//!
//! Runs that diverged or failed have no number: their CSV rows say
//! `diverged` or `failed` (with the solver's message) and leave the value
//! columns empty; the plots leave them out and say how many there were.
//! Text is rendered with DejaVu Sans, embedded from `assets/fonts/` and
//! registered with `plotters::style::register_font` (as in the paper example).

use crate::figure::{Draw, positive_extent, write_svg_png};
use crate::font::{FONT, register_embedded_font};
use std::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::analysis::{self, FitWindow, Reach, ms, reach_cell, sci};
use crate::run::{EnergyPoint, Failure, Method, SweepPoint};

/// What is known about one system's reference solution.
#[derive(Clone, Debug)]
pub struct ReferenceSummary {
    /// Coarsest reference step h (s); the reference is the midpoint VI at
    /// h/2 and h/4, Richardson-extrapolated.
    pub h: f64,
    /// max |q_mid(h/2) − q_mid(h/4)|.
    pub raw_difference: f64,
    /// max |R(h, h/2) − R(h/2, h/4)|, the reference's error estimate.
    pub error_estimate: f64,
    /// Independent checks: (description, max difference to the reference).
    pub checks: Vec<(String, Result<f64, Failure>)>,
    /// Wall time (s).
    pub seconds: f64,
}

/// Everything measured for one system.
#[derive(Clone, Debug)]
pub struct SystemResult {
    /// File-name friendly name (`double_pendulum`).
    pub name: String,
    /// Display name (`double pendulum`).
    pub label: String,
    /// The initial condition, in words.
    pub start: String,
    /// The reference solution.
    pub reference: ReferenceSummary,
    /// The work-precision sweep.
    pub sweep: Vec<SweepPoint>,
    /// Which errors enter the order fit.
    pub fit_window: FitWindow,
    /// The long energy runs.
    pub energy: Vec<EnergyPoint>,
}

/// Settings and circumstances of the run, for the report.
#[derive(Clone, Debug)]
pub struct RunInfo {
    /// The command line.
    pub command: String,
    /// End time T of the error measurement (s).
    pub t_end: f64,
    /// Horizon of the energy runs (s).
    pub energy_horizon: f64,
    /// Timing repetitions: minimum count and minimum total time (s).
    pub min_reps: usize,
    /// Minimum total time of the repetitions of one point (s).
    pub min_total: f64,
    /// Logical CPUs.
    pub cpus: usize,
    /// `/proc/loadavg` at the start.
    pub load_start: String,
    /// `/proc/loadavg` at the end.
    pub load_end: String,
    /// Wall time of the whole run (s).
    pub seconds: f64,
}

/// Error targets of the summary table.
pub const TARGETS: [f64; 2] = [1e-3, 1e-6];

/// The energy dt quoted in the summary table: the one closest to 0.01 s.
fn summary_energy_dt(energy: &[EnergyPoint]) -> Option<f64> {
    energy
        .iter()
        .map(|p| p.dt)
        .min_by(|a, b| (a / 0.01).ln().abs().total_cmp(&(b / 0.01).ln().abs()))
}

/// Writes all files into `dir` (created if needed) and returns their paths.
pub fn write_all(
    dir: &Path,
    systems: &[SystemResult],
    info: &RunInfo,
) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    std::fs::create_dir_all(dir)?;
    register_embedded_font()?;
    let mut files = vec![
        write_error_csv(dir, systems)?,
        write_summary_csv(dir, systems)?,
        write_reference_csv(dir, systems)?,
        write_energy_csv(dir, systems)?,
    ];
    files.extend(work_precision_figure(systems).write(dir, "work_precision")?);
    files.extend(convergence_figure(systems).write(dir, "convergence")?);
    files.extend(energy_figure(systems, info).write(dir, "energy")?);
    let report = dir.join("report.md");
    std::fs::write(&report, report_md(systems, info))?;
    files.push(report);
    Ok(files)
}

// ---------------------------------------------------------------- CSV

fn opt(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

fn write_rows(
    path: PathBuf,
    header: &[&str],
    rows: &[Vec<String>],
) -> Result<PathBuf, Box<dyn Error>> {
    let mut w = csv::Writer::from_path(&path)?;
    w.write_record(header)?;
    for r in rows {
        w.write_record(r)?;
    }
    w.flush()?;
    Ok(path)
}

/// A point's columns from `status` to `note`: `ok`, the `measured`
/// columns that `ok` gives and an empty note for a point that ran, else
/// the failure's status, `measured` empty columns and its message.
fn outcome_columns<M>(
    outcome: &Result<M, Failure>,
    measured: usize,
    ok: impl FnOnce(&M) -> Vec<String>,
) -> Vec<String> {
    match outcome {
        Ok(m) => {
            let mut r = vec!["ok".to_string()];
            r.extend(ok(m));
            debug_assert_eq!(r.len(), 1 + measured);
            r.push(String::new());
            r
        }
        Err(f) => {
            let mut r = vec![f.status().to_string()];
            r.extend(std::iter::repeat_n(String::new(), measured));
            r.push(f.message.clone());
            r
        }
    }
}

fn write_error_csv(dir: &Path, systems: &[SystemResult]) -> Result<PathBuf, Box<dyn Error>> {
    let header = [
        "system",
        "integrator",
        "dt",
        "steps",
        "status",
        "error_inf",
        "above_reference_floor",
        "solver_error",
        "above_solver_floor",
        "above_roundoff_floor",
        "constraint_violation_end",
        "cost_s_per_sim_s",
        "cost_min",
        "cost_max",
        "us_per_step",
        "reps",
        "note",
    ];
    let mut rows = Vec::new();
    for s in systems {
        for p in &s.sweep {
            let base = vec![
                s.name.clone(),
                p.method.id().to_string(),
                p.dt.to_string(),
                p.steps.to_string(),
            ];
            let rest = outcome_columns(&p.outcome, 11, |m| {
                vec![
                    m.error.to_string(),
                    (m.error >= s.fit_window.lo).to_string(),
                    opt(m.solver_error),
                    m.solver_error
                        .is_none_or(|e| m.error >= 10.0 * e)
                        .to_string(),
                    (m.error >= 10.0 * p.steps as f64 * s.fit_window.roundoff).to_string(),
                    m.constraint_violation.to_string(),
                    m.cost.to_string(),
                    m.cost_min.to_string(),
                    m.cost_max.to_string(),
                    (m.cost * p.dt * 1e6).to_string(),
                    m.reps.to_string(),
                ]
            });
            rows.push(base.into_iter().chain(rest).collect());
        }
    }
    write_rows(dir.join("error.csv"), &header, &rows)
}

fn reach_columns(r: &Reach) -> [String; 2] {
    match r {
        Reach::Interpolated(c) => ["interpolated".into(), c.to_string()],
        Reach::AtMost(c) => ["at_most".into(), c.to_string()],
        Reach::NotReached { .. } => ["not_reached".into(), String::new()],
        Reach::NoData => ["no_data".into(), String::new()],
    }
}

fn write_summary_csv(dir: &Path, systems: &[SystemResult]) -> Result<PathBuf, Box<dyn Error>> {
    let header = [
        "system",
        "integrator",
        "expected_order",
        "fitted_order",
        "fit_points",
        "fit_dt_min",
        "fit_dt_max",
        "fit_max_residual_decades",
        "fit_local_slopes",
        "fit_error_lo",
        "fit_error_hi",
        "fit_max_points",
        "reach_1e-3",
        "cost_1e-3_s_per_sim_s",
        "reach_1e-6",
        "cost_1e-6_s_per_sim_s",
        "best_error",
        "best_error_cost_s_per_sim_s",
        "ok_points",
        "diverged_points",
        "failed_points",
    ];
    let mut rows = Vec::new();
    for s in systems {
        for method in Method::ALL {
            let c = analysis::curve(&s.sweep, method);
            if c.is_empty() {
                continue;
            }
            let fit = analysis::fit_order(&c, s.fit_window);
            let fit = fit.as_ref();
            let best = c
                .iter()
                .filter_map(|p| p.outcome.as_ref().ok())
                .min_by(|a, b| a.error.total_cmp(&b.error));
            let mut r = vec![
                s.name.clone(),
                method.id().to_string(),
                method.order().to_string(),
                opt(fit.map(|f| f.slope)),
                fit.map(|f| f.points.to_string()).unwrap_or_default(),
                opt(fit.map(|f| f.dt_min)),
                opt(fit.map(|f| f.dt_max)),
                opt(fit.map(|f| f.max_residual)),
                fit.map(|f| local_slopes(&f.local, " ")).unwrap_or_default(),
                s.fit_window.lo.to_string(),
                s.fit_window.hi.to_string(),
                s.fit_window.max_points.to_string(),
            ];
            for t in TARGETS {
                r.extend(reach_columns(&analysis::cost_to_reach(&c, t)));
            }
            r.push(opt(best.map(|m| m.error)));
            r.push(opt(best.map(|m| m.cost)));
            let count = |f: &dyn Fn(&SweepPoint) -> bool| c.iter().filter(|p| f(p)).count();
            r.push(count(&|p| p.outcome.is_ok()).to_string());
            r.push(count(&|p| p.outcome.as_ref().is_err_and(|f| f.diverged)).to_string());
            r.push(count(&|p| p.outcome.as_ref().is_err_and(|f| !f.diverged)).to_string());
            rows.push(r);
        }
    }
    write_rows(dir.join("summary.csv"), &header, &rows)
}

fn write_reference_csv(dir: &Path, systems: &[SystemResult]) -> Result<PathBuf, Box<dyn Error>> {
    let header = [
        "system",
        "h",
        "midpoint_h2_vs_h4",
        "error_estimate",
        "check",
        "check_difference",
        "check_status",
        "seconds",
    ];
    let mut rows = Vec::new();
    for s in systems {
        let r = &s.reference;
        for (name, check) in &r.checks {
            rows.push(vec![
                s.name.clone(),
                r.h.to_string(),
                r.raw_difference.to_string(),
                r.error_estimate.to_string(),
                name.clone(),
                check.as_ref().map(|d| d.to_string()).unwrap_or_default(),
                match check {
                    Ok(_) => "ok".to_string(),
                    Err(f) => format!("{}: {}", f.status(), f.message),
                },
                r.seconds.to_string(),
            ]);
        }
    }
    write_rows(dir.join("reference.csv"), &header, &rows)
}

fn write_energy_csv(dir: &Path, systems: &[SystemResult]) -> Result<PathBuf, Box<dyn Error>> {
    let header = [
        "system",
        "integrator",
        "dt",
        "steps",
        "horizon_s",
        "status",
        "max_abs_de",
        "max_abs_de_first_tenth",
        "max_abs_de_last_tenth",
        "max_constraint_violation",
        "cost_s_per_sim_s",
        "us_per_step",
        "note",
    ];
    let mut rows = Vec::new();
    for s in systems {
        for p in &s.energy {
            let horizon = p.dt * p.steps as f64;
            let base = vec![
                s.name.clone(),
                p.method.id().to_string(),
                p.dt.to_string(),
                p.steps.to_string(),
                horizon.to_string(),
            ];
            let rest = outcome_columns(&p.outcome, 6, |m| {
                vec![
                    m.max_de.to_string(),
                    m.max_de_first_tenth.to_string(),
                    m.max_de_last_tenth.to_string(),
                    m.max_constraint_violation.to_string(),
                    m.cost.to_string(),
                    (m.cost * p.dt * 1e6).to_string(),
                ]
            });
            rows.push(base.into_iter().chain(rest).collect());
        }
    }
    write_rows(dir.join("energy.csv"), &header, &rows)
}

// ---------------------------------------------------------------- plots

const FIG_SIZE: (u32, u32) = (1400, 1080);

fn colour(m: Method) -> RGBColor {
    match m {
        Method::ExplicitEuler => RGBColor(214, 39, 40),
        Method::SymplecticEuler => RGBColor(255, 127, 14),
        Method::Rk4 => RGBColor(31, 119, 180),
        Method::Vi1 => RGBColor(44, 160, 44),
        Method::Vi2 => RGBColor(148, 103, 189),
        Method::Vi4 => RGBColor(140, 86, 75),
    }
}

/// A point of a line: (x, y, filled marker); `None` breaks the line.
type Pt = Option<(f64, f64, bool)>;

/// One integrator's line in a panel.
struct Line {
    method: Method,
    points: Vec<Pt>,
}

/// One log-log panel.
struct Panel {
    title: String,
    x_label: String,
    y_label: String,
    lines: Vec<Line>,
}

/// A figure: a title, a legend strip and up to 2×2 panels.
struct Figure {
    title: String,
    subtitle: String,
    panels: Vec<Panel>,
}

/// Decade-aligned log range of the finite positive `values`, at least one decade.
fn decades(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = positive_extent(values)?;
    let mut lo_e = (lo.log10() - 0.05).floor();
    let mut hi_e = (hi.log10() + 0.05).ceil();
    if hi_e <= lo_e {
        lo_e -= 1.0;
        hi_e += 1.0;
    }
    Some((10f64.powf(lo_e), 10f64.powf(hi_e)))
}

impl Figure {
    /// Writes `<stem>.svg` and `<stem>.png` into `dir`.
    fn write(&self, dir: &Path, stem: &str) -> Result<Vec<PathBuf>, Box<dyn Error>> {
        write_svg_png(self, FIG_SIZE, dir, stem)
    }
}

impl Draw for Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let (top, body) = root.split_vertically(110);
        top.draw(&Text::new(
            self.title.clone(),
            (20, 10),
            (FONT, 26).into_font().color(&BLACK),
        ))?;
        top.draw(&Text::new(
            self.subtitle.clone(),
            (20, 44),
            (FONT, 16).into_font().color(&RGBColor(80, 80, 80)),
        ))?;
        // shared legend
        let mut x = 20;
        for m in Method::ALL {
            let c = colour(m);
            top.draw(&PathElement::new(
                [(x, 86), (x + 30, 86)],
                c.stroke_width(3),
            ))?;
            top.draw(&Circle::new((x + 15, 86), 5, c.filled()))?;
            top.draw(&Text::new(
                m.label(),
                (x + 38, 77),
                (FONT, 17).into_font().color(&BLACK),
            ))?;
            x += 70 + 9 * m.label().chars().count() as i32;
        }
        for (area, panel) in body.split_evenly((2, 2)).iter().zip(&self.panels) {
            panel.draw(area)?;
        }
        Ok(())
    }
}

impl Panel {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
    {
        let all = || self.lines.iter().flat_map(|l| l.points.iter().flatten());
        let xr = decades(all().map(|p| p.0));
        let yr = decades(all().map(|p| p.1));
        let (Some((x0, x1)), Some((y0, y1))) = (xr, yr) else {
            area.titled(&self.title, (FONT, 20))?.draw(&Text::new(
                "no data",
                (200, 150),
                (FONT, 28).into_font().color(&RGBColor(150, 150, 150)),
            ))?;
            return Ok(());
        };
        let mut chart = ChartBuilder::on(area)
            .caption(&self.title, (FONT, 20))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .light_line_style(RGBColor(242, 242, 242))
            .draw()?;
        for line in &self.lines {
            let c = colour(line.method);
            let mut run: Vec<(f64, f64)> = Vec::new();
            let mut runs = Vec::new();
            for p in &line.points {
                match p {
                    Some((x, y, _)) => run.push((*x, *y)),
                    None if !run.is_empty() => runs.push(std::mem::take(&mut run)),
                    None => {}
                }
            }
            runs.push(run);
            for r in runs.into_iter().filter(|r| r.len() > 1) {
                chart.draw_series(LineSeries::new(r, c.stroke_width(2)))?;
            }
            chart.draw_series(line.points.iter().flatten().map(|&(x, y, filled)| {
                if filled {
                    Circle::new((x, y), 5, c.filled())
                } else {
                    Circle::new((x, y), 5, c.stroke_width(2))
                }
            }))?;
        }
        Ok(())
    }
}

/// Number of sweep points without a number, as a caption suffix.
fn missing_note(points: impl Iterator<Item = Option<bool>>) -> String {
    let (mut diverged, mut failed) = (0, 0);
    for p in points.flatten() {
        if p {
            diverged += 1;
        } else {
            failed += 1;
        }
    }
    match (diverged, failed) {
        (0, 0) => String::new(),
        (d, 0) => format!(" ({d} diverged, not shown)"),
        (0, f) => format!(" ({f} failed, not shown)"),
        (d, f) => format!(" ({d} diverged, {f} failed, not shown)"),
    }
}

fn sweep_missing(s: &SystemResult) -> String {
    missing_note(
        s.sweep
            .iter()
            .map(|p| p.outcome.as_ref().err().map(|f| f.diverged)),
    )
}

fn sweep_line(s: &SystemResult, m: Method, x: impl Fn(&SweepPoint) -> f64) -> Line {
    Line {
        method: m,
        points: analysis::curve(&s.sweep, m)
            .iter()
            .map(|p| {
                let e = p.outcome.as_ref().ok()?;
                let (px, py) = (x(p), e.error);
                (px.is_finite() && px > 0.0 && py.is_finite() && py > 0.0).then_some((
                    px,
                    py,
                    s.fit_window.above_floor(e, p.steps),
                ))
            })
            .collect(),
    }
}

/// A figure with one panel a system, each with the sweep's line a method
/// of error at T against `x` (labelled `x_label`).
fn sweep_figure(
    systems: &[SystemResult],
    title: &str,
    subtitle: &str,
    x_label: &str,
    x: impl Fn(&SweepPoint) -> f64 + Copy,
) -> Figure {
    Figure {
        title: title.into(),
        subtitle: subtitle.into(),
        panels: systems
            .iter()
            .map(|s| Panel {
                title: format!("{}{}", s.label, sweep_missing(s)),
                x_label: x_label.into(),
                y_label: "error at T".into(),
                lines: Method::ALL.iter().map(|&m| sweep_line(s, m, x)).collect(),
            })
            .collect(),
    }
}

fn work_precision_figure(systems: &[SystemResult]) -> Figure {
    sweep_figure(
        systems,
        "Work-precision: position error at t = T against compute time",
        "error = max_i |q_i(T) − q_ref,i(T)| in minimal coordinates; cost = median wall time of the steps per simulated second; hollow: under 10× the reference, solver or round-off floor",
        "cost (s per simulated s)",
        |p| p.outcome.as_ref().map(|e| e.cost).unwrap_or(f64::NAN),
    )
}

fn convergence_figure(systems: &[SystemResult]) -> Figure {
    sweep_figure(
        systems,
        "Convergence: position error at t = T against the time step",
        "slopes are the observed orders (summary.csv); hollow: under 10× the reference, solver or round-off floor (not fitted)",
        "dt (s)",
        |p| p.dt,
    )
}

fn energy_figure(systems: &[SystemResult], info: &RunInfo) -> Figure {
    Figure {
        title: format!(
            "Long-horizon energy error over {} s against compute time",
            info.energy_horizon
        ),
        subtitle: "max_k |E_k − E(q0, q̇0)| (J), one point per dt; cost = wall time of the steps per simulated second (one run)".into(),
        panels: systems
            .iter()
            .map(|s| Panel {
                title: format!(
                    "{}{}",
                    s.label,
                    missing_note(
                        s.energy
                            .iter()
                            .map(|p| p.outcome.as_ref().err().map(|f| f.diverged))
                    )
                ),
                x_label: "cost (s per simulated s)".into(),
                y_label: "max |ΔE| (J)".into(),
                lines: Method::ALL
                    .iter()
                    .map(|&m| {
                        let mut pts: Vec<&EnergyPoint> =
                            s.energy.iter().filter(|p| p.method == m).collect();
                        pts.sort_by(|a, b| b.dt.total_cmp(&a.dt));
                        Line {
                            method: m,
                            points: pts
                                .iter()
                                .map(|p| {
                                    let e = p.outcome.as_ref().ok()?;
                                    (e.cost > 0.0 && e.max_de > 0.0 && e.max_de.is_finite())
                                        .then_some((e.cost, e.max_de, true))
                                })
                                .collect(),
                        }
                    })
                    .collect(),
            })
            .collect(),
    }
}

// ---------------------------------------------------------------- report

/// The summary table (Markdown): per system and integrator the observed
/// order, the cost to reach 1e-3 and 1e-6, the best error, and the energy
/// result at the dt closest to 0.01 s.
pub fn summary_table(systems: &[SystemResult], info: &RunInfo) -> String {
    let mut out = format!(
        "| system | integrator | order (fit) | ms/s to 1e-3 | ms/s to 1e-6 | max \\|ΔE\\| over {} s at dt = 0.01 (ms/s) |\n|---|---|---|---|---|---|\n",
        info.energy_horizon
    );
    for s in systems {
        let edt = summary_energy_dt(&s.energy);
        for m in Method::ALL {
            let c = analysis::curve(&s.sweep, m);
            if c.is_empty() {
                continue;
            }
            let fit = analysis::fit_order(&c, s.fit_window)
                .map(|f| format!("{:.2}", f.slope))
                .unwrap_or_else(|| "—".into());
            let energy = s
                .energy
                .iter()
                .find(|p| p.method == m && Some(p.dt) == edt)
                .map(|p| match &p.outcome {
                    Ok(e) => format!("{} ({})", sci(e.max_de), ms(e.cost)),
                    Err(f) => f.status().to_string(),
                })
                .unwrap_or_else(|| "—".into());
            let _ = writeln!(
                out,
                "| {} | {} | {} (exp. {}) | {} | {} | {} |",
                s.label,
                m.label(),
                fit,
                m.order(),
                reach_cell(&analysis::cost_to_reach(&c, TARGETS[0])),
                reach_cell(&analysis::cost_to_reach(&c, TARGETS[1])),
                energy
            );
        }
    }
    out
}

/// Local slopes as text, two decimals.
fn local_slopes(local: &[f64], sep: &str) -> String {
    local
        .iter()
        .map(|s| format!("{s:.2}"))
        .collect::<Vec<_>>()
        .join(sep)
}

/// What the investigation of a disagreeing order found (see the README's
/// work-precision section); empty if nothing is known.
fn known_cause(system: &str, m: Method) -> &'static str {
    match (system, m) {
        ("pendulum", Method::Vi1) => {
            "Known cause: with a constant mass matrix (the pendulum in its joint angle) the paper's VI is q_(k+1) − 2q_k + q_(k−1) = −Δt²·M⁻¹∂U/∂q(q_k), i.e. Störmer–Verlet in positions, second order when started from the half-step velocity v₀ = q̇₀ + ½Δt·q̈₀ (started from v₀ = q̇₀ it is first order). With a configuration-dependent mass matrix (cartpole, double pendulum, fourbar) it is first order."
        }
        ("fourbar", Method::Rk4) => {
            "Known cause: the trajectory passes the folded pose, where the loop Jacobian loses rank; the classical integrators solve the acceleration-level KKT system without position projection, and the step that straddles the fold injects an error that does not shrink with dt (smaller steps land closer to the singular pose); with the constraint drift that follows, a later crossing can continue on the other (folded) branch."
        }
        _ => "",
    }
}

fn report_md(systems: &[SystemResult], info: &RunInfo) -> String {
    let mut r = String::new();
    let _ = writeln!(r, "# Work-precision report\n");
    let _ = writeln!(
        r,
        "Command: `{}`. Wall time {:.0} s on {} logical CPUs; load average (1, 5, 15 min) {} at the start, {} at the end. The machine is shared: timings are medians, but absolute numbers are noisy.\n",
        info.command, info.seconds, info.cpus, info.load_start, info.load_end
    );
    let _ = writeln!(
        r,
        "**Error**: max_i |q_i(T) − q_ref,i(T)| over the minimal coordinates (rad for joint angles, m for the cart's slide) at T = {} s. Positions only: the first-order and midpoint VIs carry a discrete velocity (q_(k+1) − q_k)/Δt, the classical integrators and the fourth-order VI q̇. \
**Cost**: median wall time of the stepping loop per simulated second over ≥ {} repetitions and ≥ {} s per point (initial discrete velocity not included), release build, one thread. \
**Fourbar**: all integrators in the same minimal coordinates (4 joint angles, 2 loop equations). The variational integrators solve the constraint g(q_(k+1)) = 0 at position level every step (the fourth-order VI at each of its five midpoint sub-steps); the classical ones integrate the index-1 DAE (acceleration-level constraint G q̈ + Ġ q̇ = 0 in a KKT solve, `vigp::dynamics::acceleration`) with no projection, so their positions drift off g = 0 (the `constraint_violation_end` column). \
**Reference**: midpoint VI at h/2 and h/4, Richardson-extrapolated (the midpoint rule is symmetric, its error expands in h²); its error is estimated by the difference to the extrapolation from h and h/2.\n",
        info.t_end, info.min_reps, info.min_total
    );
    let _ = writeln!(r, "## Systems and references\n");
    let _ = writeln!(
        r,
        "| system | start (at rest) | h | \\|mid(h/2) − mid(h/4)\\| | reference error estimate | independent checks: max \\|q − q_ref\\| | fit window (errors; points) |\n|---|---|---|---|---|---|---|"
    );
    for s in systems {
        let rf = &s.reference;
        let checks: Vec<String> = rf
            .checks
            .iter()
            .map(|(n, c)| match c {
                Ok(d) => format!("{n}: {}", sci(*d)),
                Err(f) => format!("{n}: {} ({})", f.status(), f.message),
            })
            .collect();
        let _ = writeln!(
            r,
            "| {} | {} | {:.0e} | {} | {} | {} | [{}, {}]; ≤ {} |",
            s.label,
            s.start,
            rf.h,
            sci(rf.raw_difference),
            sci(rf.error_estimate),
            checks.join("; "),
            sci(s.fit_window.lo),
            sci(s.fit_window.hi),
            s.fit_window.max_points
        );
    }
    let _ = writeln!(r, "\n## Summary\n");
    let _ = writeln!(
        r,
        "Costs in ms of compute per simulated second, log-log interpolated between the two measured points around the crossing; \"≤\": already reached at the largest dt measured; \"—\": not reached (best error and its cost instead). A target counts as reached only if every smaller dt also stays below it. Orders: least-squares slope of log error against log dt over the smallest time steps whose errors lie inside the fit window (the smallest max(4, a quarter of the time steps) of them; no fit with fewer than 3) and, for the variational integrators, at least 10× the run's solver error (the difference to the same run solved to a relative Newton residual of {:e} instead of the default 1e-12: it accumulates over the steps and does not shrink with dt, `solver_error` in `error.csv`), and at least 10× the accumulated round-off n·ε·max(1, ‖q_ref‖∞) of a run of n steps.\n",
        crate::run::REFERENCE_TOLERANCE
    );
    r += &summary_table(systems, info);
    let _ = writeln!(r, "\n![work-precision](work_precision.png)\n");
    let _ = writeln!(r, "![convergence](convergence.png)\n");
    let _ = writeln!(r, "## Fitted orders\n");
    let _ = writeln!(
        r,
        "| system | integrator | expected | fitted | points | dt range | max residual (decades) | local slopes (large → small dt) |\n|---|---|---|---|---|---|---|---|"
    );
    for s in systems {
        for m in Method::ALL {
            let c = analysis::curve(&s.sweep, m);
            match analysis::fit_order(&c, s.fit_window) {
                Some(f) => {
                    let _ = writeln!(
                        r,
                        "| {} | {} | {} | {:.2} | {} | {} … {} | {:.2} | {} |",
                        s.label,
                        m.label(),
                        m.order(),
                        f.slope,
                        f.points,
                        sci(f.dt_max),
                        sci(f.dt_min),
                        f.max_residual,
                        local_slopes(&f.local, ", ")
                    );
                }
                None => {
                    let _ = writeln!(
                        r,
                        "| {} | {} | {} | — | < 3 points in the window | | | |",
                        s.label,
                        m.label(),
                        m.order()
                    );
                }
            }
        }
    }
    let _ = writeln!(
        r,
        "\n### Orders that differ from the expected one by more than 0.3\n"
    );
    let mut any = false;
    for s in systems {
        for m in Method::ALL {
            let c = analysis::curve(&s.sweep, m);
            if let Some(f) = analysis::fit_order(&c, s.fit_window)
                && (f.slope - m.order()).abs() > 0.3
            {
                any = true;
                let (first, last) = (f.local.first(), f.local.last());
                let trend = match (first, last) {
                    // the local slopes move towards the expected order, by
                    // at least 0.1 overall and never away from it
                    (Some(a), Some(b))
                        if (b - m.order()).abs() < (a - m.order()).abs() - 0.1
                            && f.local.windows(2).all(|w| {
                                (w[1] - m.order()).abs() <= (w[0] - m.order()).abs() + 1e-9
                            }) =>
                    {
                        format!(
                            " The local slopes ({}) approach {} as dt shrinks: pre-asymptotic.",
                            local_slopes(&f.local, ", "),
                            m.order()
                        )
                    }
                    _ => format!(" Local slopes: {}.", local_slopes(&f.local, ", ")),
                };
                let _ = writeln!(
                    r,
                    "- {}, {}: fitted {:.2}, expected {} (max residual {:.2} decades).{} {}",
                    s.label,
                    m.label(),
                    f.slope,
                    m.order(),
                    f.max_residual,
                    trend,
                    known_cause(&s.name, m)
                );
            }
        }
    }
    if !any {
        let _ = writeln!(r, "None.");
    }
    let _ = writeln!(r, "\n## Long-horizon energy\n");
    let _ = writeln!(
        r,
        "max_k |E_k − E(q₀, q̇₀)| over {} s; E_k is E(q, q̇) for the classical integrators and the fourth-order VI (whose state is continuous), and E(q + αΔt·v, v) (`Variational::energy`) for the first-order and midpoint VIs. First/last tenth: the same maximum over the first and last tenth of the steps (growth shows as last ≫ first). Cost from the one long run.\n",
        info.energy_horizon
    );
    let _ = writeln!(
        r,
        "| system | integrator | dt | max \\|ΔE\\| (J) | first tenth | last tenth | max \\|g\\| | ms/s |\n|---|---|---|---|---|---|---|---|"
    );
    for s in systems {
        for p in &s.energy {
            match &p.outcome {
                Ok(e) => {
                    let _ = writeln!(
                        r,
                        "| {} | {} | {} | {} | {} | {} | {} | {} |",
                        s.label,
                        p.method.label(),
                        sci(p.dt),
                        sci(e.max_de),
                        sci(e.max_de_first_tenth),
                        sci(e.max_de_last_tenth),
                        sci(e.max_constraint_violation),
                        ms(e.cost)
                    );
                }
                Err(f) => {
                    let _ = writeln!(
                        r,
                        "| {} | {} | {} | {}: {} | | | | |",
                        s.label,
                        p.method.label(),
                        sci(p.dt),
                        f.status(),
                        f.message
                    );
                }
            }
        }
    }
    let _ = writeln!(r, "\n![energy](energy.png)\n");
    let failures: Vec<String> = systems
        .iter()
        .flat_map(|s| {
            s.sweep.iter().filter_map(move |p| {
                p.outcome.as_ref().err().map(|f| {
                    format!(
                        "- {}, {}, dt = {}: {} ({})",
                        s.label,
                        p.method.label(),
                        sci(p.dt),
                        f.status(),
                        f.message
                    )
                })
            })
        })
        .collect();
    let _ = writeln!(r, "## Runs without a number (error sweep)\n");
    if failures.is_empty() {
        let _ = writeln!(r, "None.");
    } else {
        r += &failures.join("\n");
        r.push('\n');
    }
    r
}
