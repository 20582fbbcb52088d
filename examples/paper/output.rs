//! Output layer of the paper example: figures (SVG and PNG), CSV files of
//! every plotted number, and a Markdown report.
//!
//! The numerical part of the example hands its results to [`write_all`],
//! which writes everything into one directory:
//!
//! | file | content |
//! |---|---|
//! | `fig1a_energy.svg`, `.png` | energy error over time, log y |
//! | `fig1b_constraint_drift.svg`, `.png` | constraint violation over time, log y |
//! | `fig2_<system>.svg`, `.png` | 20-step position MSE against N, log2 x, log y |
//! | `fig1.csv` | `series,label,t,value` for both panels of Fig. 1 |
//! | `fig2.csv` | every raw point: `system,method,n,run,mse` |
//! | `fig2_summary.csv` | `system,method,n,runs,median,p10,p90` |
//! | `report.md` | settings, both figures with tables, findings |
//!
//! Display conventions (the CSV files always hold the raw values):
//! - NaN and infinite values are not plotted; a line is broken at them.
//! - On log axes, values `<= 0` (e.g. `|E(0) − E(0)|`) are drawn on the
//!   bottom edge of the plot, which then lies one decade below the decade
//!   of the smallest positive value.
//! - Log axes span whole decades, with empty decades on top so that the
//!   legend does not hide data.
//! - Fig. 2 points with `n == 0` cannot sit on a log2 axis and are left out
//!   of the plot (they stay in the CSV files and the tables).
//!
//! Text is rendered with DejaVu Sans, embedded from `assets/fonts/` and
//! registered with `plotters::style::register_font` (plotters' `ttf` feature
//! would need fontconfig).

use crate::figure::{Draw, positive_extent, write_svg_png};
use crate::font::{FONT, register_embedded_font};
use std::collections::{BTreeMap, BTreeSet};
use std::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

/// One point of Fig. 2: a 20-step prediction's position MSE for one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fig2Point {
    /// System name: `"pendulum"`, `"cartpole"`, `"double_pendulum"` or `"fourbar"`
    /// (other names are accepted and plotted with their raw name).
    pub system: String,
    /// Method: `"nominal"`, `"minimal"`, `"sincos"` or `"maximal"` (other names
    /// are accepted and plotted with their raw name and a fallback colour).
    pub method: String,
    /// Number of training samples N.
    pub n: usize,
    /// Index of the run (perturbed system and data set).
    pub run: usize,
    /// 20-step position mean squared error of this run.
    #[serde(with = "crate::shard::exact")]
    pub mse: f64,
}

/// A time series for Fig. 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Series {
    /// Legend label, e.g. `"explicit Euler"`.
    pub label: String,
    /// Time stamps (s); must have the same length as `y`.
    #[serde(with = "crate::shard::exact")]
    pub t: Vec<f64>,
    /// Values at the time stamps.
    #[serde(with = "crate::shard::exact")]
    pub y: Vec<f64>,
}

/// Fig. 1: (a) energy error |E(t) − E(0)| (J) over time, (b) constraint violation |g| over time.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Fig1 {
    /// Panel (a): one series per integrator, energy error in J.
    pub energy: Vec<Series>,
    /// Panel (b): one series per integrator, constraint violation |g|.
    pub drift: Vec<Series>,
}

/// Summary statistics of Fig. 2 per (system, method, n): median, 10th and 90th percentile over runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fig2Summary {
    /// System name.
    pub system: String,
    /// Method name.
    pub method: String,
    /// Number of training samples N.
    pub n: usize,
    /// Number of runs with a finite MSE (the ones the statistics use).
    pub runs: usize,
    /// Median of the finite MSE values (NaN if `runs == 0`).
    pub median: f64,
    /// 10th percentile, linear interpolation (NaN if `runs == 0`).
    pub p10: f64,
    /// 90th percentile, linear interpolation (NaN if `runs == 0`).
    pub p90: f64,
}

/// Methods in the paper's order, with legend label and colour.
const METHODS: [(&str, &str, RGBColor); 4] = [
    ("nominal", "nominal VI", BLACK),
    ("minimal", "learned, minimal", BLUE),
    ("sincos", "learned, sin/cos", RED),
    ("maximal", "learned, maximal", RGBColor(0, 150, 0)),
];

/// Systems in the paper's order.
const SYSTEMS: [&str; 4] = ["pendulum", "cartpole", "double_pendulum", "fourbar"];

/// Colours for Fig. 1 series and for unknown methods, in order of use.
const PALETTE: [RGBColor; 8] = [
    BLACK,
    BLUE,
    RED,
    RGBColor(0, 150, 0),
    RGBColor(230, 120, 0),
    RGBColor(140, 60, 170),
    RGBColor(0, 150, 160),
    RGBColor(120, 120, 120),
];

const FIG_SIZE: (u32, u32) = (960, 640);

/// Sorts the known names in the paper's order, then unknown names alphabetically.
fn rank(known: &[&str], name: &str) -> (usize, String) {
    let i = known.iter().position(|k| *k == name).unwrap_or(known.len());
    (i, name.to_string())
}

fn method_rank(m: &str) -> (usize, String) {
    let names: Vec<&str> = METHODS.iter().map(|(k, _, _)| *k).collect();
    rank(&names, m)
}

fn system_rank(s: &str) -> (usize, String) {
    rank(&SYSTEMS, s)
}

/// Legend label and colour of a method; unknown methods get their raw name
/// and a palette colour after the four paper colours.
fn method_style(method: &str, unknown_index: usize) -> (String, RGBColor) {
    match METHODS.iter().find(|(k, _, _)| *k == method) {
        Some((_, label, colour)) => (label.to_string(), *colour),
        None => (
            method.to_string(),
            PALETTE[4 + unknown_index % (PALETTE.len() - 4)],
        ),
    }
}

/// Percentile of sorted finite data by linear interpolation between closest
/// ranks (numpy's default `method="linear"`); `q` in [0, 1].
fn percentile_sorted(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        len => {
            let h = (len - 1) as f64 * q.clamp(0.0, 1.0);
            let lo = h.floor() as usize;
            let hi = (lo + 1).min(len - 1);
            sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
        }
    }
}

/// Groups Fig. 2 points by (system, method, n) in the paper's order:
/// systems pendulum, cartpole, double_pendulum, fourbar, methods nominal,
/// minimal, sincos, maximal (unknown names after the known ones,
/// alphabetically), then ascending n. Each group holds (finite MSE values,
/// number of non-finite values).
type GroupKey = ((usize, String), (usize, String), usize);

fn group_fig2(points: &[Fig2Point]) -> BTreeMap<GroupKey, (Vec<f64>, usize)> {
    let mut groups: BTreeMap<GroupKey, (Vec<f64>, usize)> = BTreeMap::new();
    for p in points {
        let key = (system_rank(&p.system), method_rank(&p.method), p.n);
        let entry = groups.entry(key).or_default();
        if p.mse.is_finite() {
            entry.0.push(p.mse);
        } else {
            entry.1 += 1;
        }
    }
    groups
}

/// Summarises Fig. 2 per (system, method, n): median, 10th and 90th
/// percentile over runs.
///
/// - Sorted by system, then method, in the paper's order (pendulum,
///   cartpole, double_pendulum, fourbar; nominal, minimal, sincos, maximal;
///   unknown names after the known ones, alphabetically), then ascending `n`.
/// - Percentiles use linear interpolation between closest ranks, numpy's
///   default (`np.percentile(x, [10, 50, 90])`).
/// - NaN and infinite MSE values are excluded from the statistics; `runs`
///   counts only the finite values. The non-finite ones are counted in the
///   report (`report.md`, under each Fig. 2 table). A group with no finite
///   value is kept, with `runs == 0` and NaN statistics.
pub fn summarize_fig2(points: &[Fig2Point]) -> Vec<Fig2Summary> {
    group_fig2(points)
        .into_iter()
        .map(|(((_, system), (_, method), n), (mut values, _))| {
            values.sort_by(f64::total_cmp);
            Fig2Summary {
                system,
                method,
                n,
                runs: values.len(),
                median: percentile_sorted(&values, 0.5),
                p10: percentile_sorted(&values, 0.1),
                p90: percentile_sorted(&values, 0.9),
            }
        })
        .collect()
}

/// Median MSE of a (system, method, n) over runs (NaN runs excluded).
pub fn med(points: &[Fig2Point], system: &str, method: &str, n: usize) -> f64 {
    let mut v: Vec<f64> = points
        .iter()
        .filter(|p| p.system == system && p.method == method && p.n == n && p.mse.is_finite())
        .map(|p| p.mse)
        .collect();
    crate::median::median(&mut v)
}

/// Writes everything into `dir` (created if missing) and returns the list of files written.
///
/// Files: `fig1a_energy.{svg,png}`, `fig1b_constraint_drift.{svg,png}`,
/// `fig2_<system>.{svg,png}` per system present in `fig2`, `fig1.csv`,
/// `fig2.csv`, `fig2_summary.csv` and `report.md` (see the module docs).
/// `settings_md` is inserted verbatim under a `## Settings` heading and
/// `findings_md` verbatim under `## Findings`.
///
/// Fig. 1 is always drawn, with "no data" on an empty panel. The input is
/// checked before anything is written: a [`Series`] whose `t` and `y`
/// differ in length, or two systems whose names map to the same file name,
/// are errors.
pub fn write_all(
    dir: &Path,
    settings_md: &str,
    fig1: &Fig1,
    fig2: &[Fig2Point],
    findings_md: &str,
) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    for s in fig1.energy.iter().chain(&fig1.drift) {
        if s.t.len() != s.y.len() {
            return Err(format!(
                "Fig. 1 series {:?}: {} time stamps but {} values",
                s.label,
                s.t.len(),
                s.y.len()
            )
            .into());
        }
    }
    let systems = systems_with_files(&summarize_fig2(fig2))?;
    let (mut written, summary) = write_fig2(dir, fig2)?;

    let panels = [
        (
            "fig1a_energy",
            "Fig. 1a — energy error (pendulum, maximal coordinates)",
            "|E − E₀| (J)",
            &fig1.energy,
            SeriesLabelPosition::UpperRight,
        ),
        (
            "fig1b_constraint_drift",
            "Fig. 1b — constraint drift (double pendulum, maximal coordinates)",
            "constraint violation |g|",
            &fig1.drift,
            SeriesLabelPosition::UpperRight,
        ),
    ];
    for (stem, title, y_label, series, legend) in panels {
        let plot = Plot {
            title: title.to_string(),
            x_label: "time (s)".to_string(),
            y_label: y_label.to_string(),
            x_log2: false,
            legend,
            lines: series
                .iter()
                .enumerate()
                .map(|(i, s)| Line {
                    label: s.label.clone(),
                    colour: PALETTE[i % PALETTE.len()],
                    points: s.t.iter().copied().zip(s.y.iter().copied()).collect(),
                    band: Vec::new(),
                    markers: s.t.len() == 1,
                })
                .collect(),
        };
        written.extend(plot.write(dir, stem)?);
    }

    written.push(write_fig1_csv(dir, fig1)?);

    let report = report_md(settings_md, fig1, fig2, &summary, &systems, findings_md);
    let report_path = dir.join("report.md");
    std::fs::write(&report_path, report)?;
    written.push(report_path);
    Ok(written)
}

/// Writes Fig. 2 alone into `dir` (created if missing): `fig2_<system>.{svg,png}`
/// per system, `fig2.csv` and `fig2_summary.csv`, as [`write_all`] does, for
/// any method names (unknown ones are plotted with their raw name). Returns
/// the files written and the summary.
pub fn write_fig2(
    dir: &Path,
    fig2: &[Fig2Point],
) -> Result<(Vec<PathBuf>, Vec<Fig2Summary>), Box<dyn Error>> {
    let summary = summarize_fig2(fig2);
    let systems = systems_with_files(&summary)?;
    std::fs::create_dir_all(dir)?;
    register_embedded_font()?;
    let mut written = Vec::new();
    for (system, stem) in &systems {
        let plot = fig2_plot(system, &summary);
        written.extend(plot.write(dir, stem)?);
    }
    written.push(write_csv(&dir.join("fig2.csv"), fig2)?);
    written.push(write_csv(&dir.join("fig2_summary.csv"), &summary)?);
    Ok((written, summary))
}

/// The systems present, in the paper's order, with their file stems
/// `fig2_<system>` (characters other than ASCII letters, digits, `-` and `_`
/// become `_`).
fn systems_with_files(summary: &[Fig2Summary]) -> Result<Vec<(String, String)>, Box<dyn Error>> {
    let mut systems: Vec<(String, String)> = Vec::new();
    for s in summary {
        if systems.iter().any(|(name, _)| *name == s.system) {
            continue;
        }
        let safe: String = s
            .system
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let stem = format!("fig2_{safe}");
        if let Some((other, _)) = systems.iter().find(|(_, st)| *st == stem) {
            return Err(format!(
                "systems {other:?} and {:?} would both be written to {stem}.svg",
                s.system
            )
            .into());
        }
        systems.push((s.system.clone(), stem));
    }
    Ok(systems)
}

/// One line of a plot.
struct Line {
    label: String,
    colour: RGBColor,
    /// (x, y) points; non-finite ones are skipped and break the line.
    points: Vec<(f64, f64)>,
    /// Shaded band (x, low, high), drawn under the line.
    band: Vec<(f64, f64, f64)>,
    markers: bool,
}

/// A plot with a log y-axis and a linear or log2 x-axis.
struct Plot {
    title: String,
    x_label: String,
    y_label: String,
    x_log2: bool,
    legend: SeriesLabelPosition,
    lines: Vec<Line>,
}

/// Log-axis display value: `v <= 0` goes to `floor`, the bottom of the axis.
fn floor_log(v: f64, floor: f64) -> f64 {
    if v > floor { v } else { floor }
}

/// Decade-aligned log axis for finite `values`, at least one decade wide.
/// If some values are `<= 0`, one more decade below is added and its bottom
/// is where they are drawn (see [`floor_log`]). Empty decades are added on
/// top for a legend of `legend_entries` lines (about 22 px each on a plot
/// area of about 500 px).
fn log_axis(values: impl Iterator<Item = f64>, legend_entries: usize) -> (f64, f64) {
    let mut any_non_positive = false;
    let mut range: Option<(f64, f64)> = None;
    for v in values.filter(|v| v.is_finite()) {
        if v <= 0.0 {
            any_non_positive = true;
        } else {
            range = Some(range.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
        }
    }
    let (mut lo_e, mut hi_e) = match range {
        // A value within 5 % of a decade of the axis end gets another decade,
        // so that no data sit on the frame.
        Some((lo, hi)) => ((lo.log10() - 0.05).floor(), (hi.log10() + 0.05).ceil()),
        None if any_non_positive => (-16.0, -15.0),
        None => (-3.0, 0.0),
    };
    if hi_e <= lo_e {
        lo_e -= 1.0;
        hi_e += 1.0;
    }
    if any_non_positive {
        lo_e -= 1.0;
    }
    if legend_entries > 0 {
        let frac = ((legend_entries * 22 + 20) as f64 / 500.0).min(0.5);
        hi_e += ((hi_e - lo_e) * frac / (1.0 - frac)).ceil();
    }
    (10f64.powf(lo_e), 10f64.powf(hi_e))
}

/// Linear range covering finite `values` with no padding, widened if all equal.
fn lin_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold(None, |acc: Option<(f64, f64)>, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })?;
    if hi > lo {
        Some((lo, hi))
    } else {
        let w = if lo == 0.0 { 1.0 } else { 0.5 * lo.abs() };
        Some((lo - w, hi + w))
    }
}

/// Log2 range for N values: one half power of two padding each side.
fn log2_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = positive_extent(values)?;
    let pad = if hi > lo { 2f64.sqrt() } else { 2.0 };
    Some((lo / pad, hi * pad))
}

/// Formats a tick value on a log axis: `1e-4`, `3e-4`, `1e0`, ….
fn log_tick(v: f64) -> String {
    format!("{v:.0e}")
}

/// Splits points at non-finite values into finite runs, with y floored for the log axis.
fn finite_runs(points: &[(f64, f64)], x_log: bool, floor: f64) -> Vec<Vec<(f64, f64)>> {
    let mut runs = vec![Vec::new()];
    for &(x, y) in points {
        let ok = x.is_finite() && y.is_finite() && (!x_log || x > 0.0);
        match runs.last_mut() {
            Some(run) if ok => run.push((x, floor_log(y, floor))),
            Some(run) if !run.is_empty() => runs.push(Vec::new()),
            _ => {}
        }
    }
    runs.retain(|r| !r.is_empty());
    runs
}

impl Plot {
    /// Writes `<stem>.svg` and `<stem>.png` into `dir`.
    fn write(&self, dir: &Path, stem: &str) -> Result<Vec<PathBuf>, Box<dyn Error>> {
        write_svg_png(self, FIG_SIZE, dir, stem)
    }

    fn draw_lines<'a, DB: DrawingBackend + 'a, X, Y>(
        &self,
        chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        empty: bool,
        floor: f64,
    ) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
        X: Ranged<ValueType = f64>,
        Y: Ranged<ValueType = f64>,
    {
        if empty {
            let area = chart.plotting_area();
            let (x, y) = (area.get_x_range(), area.get_y_range());
            let x_mid = if self.x_log2 {
                (x.start * x.end).sqrt()
            } else {
                (x.start + x.end) / 2.0
            };
            let centre = (x_mid, (y.start * y.end).sqrt());
            area.draw(&Text::new(
                "no data",
                centre,
                (FONT, 28).into_font().color(&RGBColor(150, 150, 150)),
            ))?;
        }
        let x_log = self.x_log2;
        for line in &self.lines {
            // Band (x, low, high) as one polygon per finite run.
            let mut band_run: Vec<(f64, f64, f64)> = Vec::new();
            let mut bands = Vec::new();
            for &(x, lo, hi) in &line.band {
                if x.is_finite() && lo.is_finite() && hi.is_finite() && (!x_log || x > 0.0) {
                    band_run.push((x, floor_log(lo, floor), floor_log(hi, floor)));
                } else if !band_run.is_empty() {
                    bands.push(std::mem::take(&mut band_run));
                }
            }
            bands.push(band_run);
            for b in bands.iter().filter(|b| !b.is_empty()) {
                let polygon: Vec<(f64, f64)> = b
                    .iter()
                    .map(|p| (p.0, p.2))
                    .chain(b.iter().rev().map(|p| (p.0, p.1)))
                    .collect();
                chart.draw_series(std::iter::once(Polygon::new(
                    polygon,
                    line.colour.mix(0.15).filled(),
                )))?;
            }

            // dense, jagged series (Fig. 1) at width 1: plotters joins thick
            // segments with miters, which draw spikes far beyond the data at
            // sharp turns on a log axis
            let width = if line.points.len() > 200 { 1 } else { 2 };
            let style = line.colour.stroke_width(width);
            let runs = finite_runs(&line.points, x_log, floor);
            // The first run carries the legend entry (an empty series if the line has no finite point).
            let first = runs.first().cloned().unwrap_or_default();
            let colour = line.colour;
            chart
                .draw_series(LineSeries::new(first, style))?
                .label(&line.label)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 24, y)], colour.stroke_width(2))
                });
            for run in runs.iter().skip(1) {
                chart.draw_series(LineSeries::new(run.iter().copied(), style))?;
            }
            if line.markers {
                chart.draw_series(
                    runs.iter()
                        .flatten()
                        .map(|&p| Circle::new(p, 4, line.colour.filled())),
                )?;
            }
        }
        if !self.lines.is_empty() {
            chart
                .configure_series_labels()
                .position(self.legend.clone())
                .label_font((FONT, 16))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(160, 160, 160))
                .draw()?;
        }
        Ok(())
    }
}

impl Draw for Plot {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let xs = || self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.0));
        // Only points that can be drawn: finite x (and x > 0 on the log2 axis).
        let drawable = |x: f64| x.is_finite() && (!self.x_log2 || x > 0.0);
        let ys = || {
            self.lines.iter().flat_map(move |l| {
                l.points
                    .iter()
                    .filter(move |p| drawable(p.0))
                    .map(|p| p.1)
                    .chain(
                        l.band
                            .iter()
                            .filter(move |b| drawable(b.0))
                            .flat_map(|b| [b.1, b.2]),
                    )
                    .filter(|v| v.is_finite())
            })
        };
        let empty = ys().next().is_none();
        let (y0, y1) = log_axis(ys(), self.lines.len());
        let mut builder = ChartBuilder::on(root);
        builder
            .caption(&self.title, (FONT, 24))
            .margin(16)
            .x_label_area_size(56)
            .y_label_area_size(84);
        if self.x_log2 {
            let (x0, x1) = log2_range(xs()).unwrap_or((1.0, 4.0));
            let mut chart =
                builder.build_cartesian_2d((x0..x1).log_scale().base(2.0), (y0..y1).log_scale())?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&|v| log_tick(*v))
                .label_style((FONT, 15))
                .axis_desc_style((FONT, 18))
                .light_line_style(RGBColor(242, 242, 242))
                .draw()?;
            self.draw_lines(&mut chart, empty, y0)?;
        } else {
            let (x0, x1) = lin_range(xs()).unwrap_or((0.0, 1.0));
            let mut chart = builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale())?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .y_label_formatter(&|v| log_tick(*v))
                .label_style((FONT, 15))
                .axis_desc_style((FONT, 18))
                .light_line_style(RGBColor(242, 242, 242))
                .draw()?;
            self.draw_lines(&mut chart, empty, y0)?;
        }
        Ok(())
    }
}

/// Fig. 2 plot of one system: per method the median line with markers and
/// the 10th–90th percentile band.
fn fig2_plot(system: &str, summary: &[Fig2Summary]) -> Plot {
    let mut methods: Vec<&str> = Vec::new();
    for s in summary.iter().filter(|s| s.system == system) {
        if !methods.contains(&s.method.as_str()) {
            methods.push(&s.method);
        }
    }
    let mut unknown = 0;
    let lines = methods
        .iter()
        .map(|&m| {
            let (label, colour) = method_style(m, unknown);
            if !METHODS.iter().any(|(k, _, _)| *k == m) {
                unknown += 1;
            }
            let rows: Vec<&Fig2Summary> = summary
                .iter()
                .filter(|s| s.system == system && s.method == m && s.runs > 0)
                .collect();
            Line {
                label,
                colour,
                points: rows.iter().map(|s| (s.n as f64, s.median)).collect(),
                band: rows.iter().map(|s| (s.n as f64, s.p10, s.p90)).collect(),
                markers: true,
            }
        })
        .collect();
    Plot {
        title: format!("Fig. 2 — {}", system.replace('_', " ")),
        x_label: "training samples N".to_string(),
        y_label: "20-step position MSE".to_string(),
        x_log2: true,
        legend: SeriesLabelPosition::UpperRight,
        lines,
    }
}

#[derive(Serialize)]
struct Fig1Row<'a> {
    series: &'a str,
    label: &'a str,
    t: f64,
    value: f64,
}

fn write_fig1_csv(dir: &Path, fig1: &Fig1) -> Result<PathBuf, Box<dyn Error>> {
    let mut rows = Vec::new();
    for (panel, list) in [("energy", &fig1.energy), ("constraint_drift", &fig1.drift)] {
        for s in list {
            for (&t, &value) in s.t.iter().zip(&s.y) {
                rows.push(Fig1Row {
                    series: panel,
                    label: &s.label,
                    t,
                    value,
                });
            }
        }
    }
    write_csv(&dir.join("fig1.csv"), &rows)
}

/// Writes serialisable rows with a header row (written even if `rows` is empty).
fn write_csv<T: Serialize + HeaderNames>(
    path: &Path,
    rows: &[T],
) -> Result<PathBuf, Box<dyn Error>> {
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_path(path)?;
    w.write_record(T::HEADER)?;
    for r in rows {
        w.serialize(r)?;
    }
    w.flush()?;
    Ok(path.to_path_buf())
}

/// Column names of a CSV row type, so that empty files still get a header.
trait HeaderNames {
    const HEADER: &'static [&'static str];
}

impl HeaderNames for Fig1Row<'_> {
    const HEADER: &'static [&'static str] = &["series", "label", "t", "value"];
}

impl HeaderNames for Fig2Point {
    const HEADER: &'static [&'static str] = &["system", "method", "n", "run", "mse"];
}

impl HeaderNames for Fig2Summary {
    const HEADER: &'static [&'static str] =
        &["system", "method", "n", "runs", "median", "p10", "p90"];
}

/// Three significant digits: `1.23e-4`; `NaN`, `inf` as such.
fn sig3(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2e}")
    } else {
        format!("{v}")
    }
}

/// Escapes text for a Markdown table cell.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

fn report_md(
    settings_md: &str,
    fig1: &Fig1,
    fig2: &[Fig2Point],
    summary: &[Fig2Summary],
    systems: &[(String, String)],
    findings_md: &str,
) -> String {
    let mut md = String::new();
    // `write!` into a String cannot fail.
    let _ = writeln!(md, "# vigp — paper evaluation\n");
    let _ = writeln!(md, "## Settings\n\n{}\n", settings_md.trim_end());

    let _ = writeln!(md, "## Fig. 1\n");
    let _ = writeln!(
        md,
        "Values ≤ 0 (such as the energy error at t = 0) are drawn on the bottom edge of the \
         log axes; `fig1.csv` holds the raw values.\n"
    );
    let _ = writeln!(
        md,
        "![Fig. 1a: energy error](fig1a_energy.png)\n\n![Fig. 1b: constraint drift](fig1b_constraint_drift.png)\n"
    );
    let _ = writeln!(md, "| panel | series | points | final value | max value |");
    let _ = writeln!(md, "|---|---|---:|---:|---:|");
    for (panel, list) in [
        ("(a) energy error (J)", &fig1.energy),
        ("(b) constraint violation", &fig1.drift),
    ] {
        if list.is_empty() {
            let _ = writeln!(md, "| {panel} | (no series) | 0 | — | — |");
        }
        for s in list {
            let finite: Vec<f64> = s.y.iter().copied().filter(|v| v.is_finite()).collect();
            let last = finite.last().map_or("—".to_string(), |v| sig3(*v));
            let max = finite
                .iter()
                .copied()
                .reduce(f64::max)
                .map_or("—".to_string(), sig3);
            let _ = writeln!(
                md,
                "| {panel} | {} | {} | {last} | {max} |",
                md_cell(&s.label),
                s.y.len()
            );
        }
    }
    let _ = writeln!(md);

    let _ = writeln!(md, "## Fig. 2\n");
    let _ = writeln!(
        md,
        "20-step position MSE: median [10th, 90th percentile] over runs (linear interpolation, as numpy). \
         Raw points in `fig2.csv`, statistics in `fig2_summary.csv`.\n"
    );
    if systems.is_empty() {
        let _ = writeln!(md, "No Fig. 2 data.\n");
    }
    let groups = group_fig2(fig2);
    for (system, stem) in systems {
        let rows: Vec<&Fig2Summary> = summary.iter().filter(|s| s.system == *system).collect();
        let mut methods: Vec<&str> = Vec::new();
        for s in &rows {
            if !methods.contains(&s.method.as_str()) {
                methods.push(&s.method);
            }
        }
        let ns: BTreeSet<usize> = rows.iter().map(|s| s.n).collect();
        let _ = writeln!(md, "### {}\n", system.replace('_', " "));
        let _ = writeln!(md, "![Fig. 2: {system}]({stem}.png)\n");
        let mut header = "| N |".to_string();
        let mut rule = "|---:|".to_string();
        for (i, m) in methods.iter().enumerate() {
            let (label, _) = method_style(m, i);
            let _ = write!(header, " {} |", md_cell(&label));
            rule.push_str("---|");
        }
        let _ = writeln!(md, "{header}\n{rule}");
        for n in &ns {
            let _ = write!(md, "| {n} |");
            for m in &methods {
                let cell = rows.iter().find(|s| s.n == *n && s.method == *m).map_or(
                    "—".to_string(),
                    |s| {
                        if s.runs == 0 {
                            "no finite value".to_string()
                        } else {
                            format!("{} [{}, {}]", sig3(s.median), sig3(s.p10), sig3(s.p90))
                        }
                    },
                );
                let _ = write!(md, " {cell} |");
            }
            let _ = writeln!(md);
        }
        let runs: BTreeSet<usize> = rows.iter().map(|s| s.runs).collect();
        let (lo, hi) = (runs.first().copied(), runs.last().copied());
        match (lo, hi) {
            (Some(lo), Some(hi)) if lo == hi => {
                let _ = writeln!(md, "\nRuns per cell: {lo}.");
            }
            (Some(lo), Some(hi)) => {
                let _ = writeln!(md, "\nRuns per cell: {lo} to {hi} (finite values only).");
            }
            _ => {}
        }
        let excluded: Vec<String> = groups
            .iter()
            .filter(|(((_, s), _, _), (_, bad))| s == system && *bad > 0)
            .map(|((_, (_, m), n), (_, bad))| format!("{m} N={n}: {bad}"))
            .collect();
        if !excluded.is_empty() {
            let _ = writeln!(
                md,
                "\nNon-finite MSE values excluded from the statistics: {}.",
                excluded.join(", ")
            );
        }
        let zero_n = rows.iter().any(|s| s.n == 0);
        if zero_n {
            let _ = writeln!(md, "\nN = 0 is not drawn on the log2 axis.");
        }
        let _ = writeln!(md);
    }

    let _ = writeln!(md, "## Findings\n\n{}", findings_md.trim_end());
    md
}
