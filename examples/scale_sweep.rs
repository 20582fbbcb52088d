//! The paper's question past N = 512: does the 20-step prediction error of
//! the learned integrator keep falling with more data? (Brüdigam et al. stop
//! at N = 512 because of training time.)
//!
//! Pendulum and cartpole with the nominal VI step as prior (paper eq. 7),
//! minimal coordinates, sin/cos inputs, the data protocol of
//! `examples/paper` (perturbed masses, inertias and damping; trajectories of
//! 2 s from random configurations at rest; σ = 1e-3 noise on q, v and the
//! targets; 20-step windows from held-out noise-free trajectories), exact
//! GPs up to `--exact-max`, the sparse GP (k-means++ inducing points) for
//! larger N. Training samples are drawn **without** replacement from the
//! pool, so a larger N is more information, not repeats.
//!
//! ```text
//! cargo run --release --example scale_sweep                       # defaults below
//! cargo run --release --example scale_sweep -- --n 64,256,1024,4096,16384 --sparse-m 512 --noise 0
//! ```
//!
//! Prints a table (median window MSE of positions over the test windows,
//! per system and N; the nominal model's error; training time and the
//! fitted noise variance in original units) and writes it as CSV to
//! `target/scale_sweep.csv` with a log–log figure `target/scale_sweep.svg`
//! (`--plot some.csv` redraws the figure of a saved CSV as `some.svg`).
//! `--noise 0` trains on noise-free data, which separates the
//! observation-noise floor from the rest. `--sparse-also` trains the sparse
//! GP as well at every N where the exact one runs (N > M), on the same
//! samples, and prints the ratio of their errors:
//!
//! ```text
//! cargo run --release --example scale_sweep -- --n 1024,2048,4096 --exact-max 4096 --sparse-m 256 --sparse-also --restarts 0
//! ```
//!
//! `--out DIR` writes `DIR/scale_sweep.csv` and `.svg` (default `target`).
//! Sharding (docs/sharding.md): the units of work are the two systems
//! (each its own seed; its N values are one chain of warm starts), so
//! `--shard i/N` (0-based) computes every N-th system from the i-th and
//! writes its raw rows (`shard.json`, floats exact) to
//! `target/scale-shards/shard-i-of-N/` (or `--out`); more than two shards
//! leave the extra ones empty. `merge DIR… [--out DIR]` checks the shards
//! and writes the CSV and the figure as an unsharded run does: the figure
//! and every column but `train_s` (the measured training time, wherever
//! the unit ran) are the same bytes.
//!
//! ```text
//! cargo run --release --example scale_sweep -- --shard 0/2   # and 1/2, anywhere
//! cargo run --release --example scale_sweep -- merge target/scale-shards/shard-*-of-2
//! ```

#[path = "common/font.rs"]
mod font;
#[path = "common/windows.rs"]
mod windows;
use windows::test_windows;
#[path = "common/shard.rs"]
mod shard;

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use shard::{Shard, ShardFile};

use nalgebra::SVector;
use rayon::prelude::*;
use vigp::gp::{Method, SparseOptions, TrainOptions};
use vigp::learned::{Encoding, Learned, Prior, Transition, transitions};
use vigp::prelude::*;
use vigp::projection::consistent_state;
use vigp::systems::{Cartpole, Pendulum};

const DT: f64 = 0.01;
const HORIZON: usize = 20;
const TRAJ_SAMPLES: usize = 201;

#[path = "../tests/common/rng.rs"]
mod rng;
use rng::Rng;

/// Settings of a run. All but `out` and `shard` are written into every
/// shard's file, and `merge` requires them equal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Cli {
    n: Vec<usize>,
    exact_max: usize,
    sparse_m: usize,
    #[serde(with = "shard::exact")]
    noise: f64,
    #[serde(with = "shard::exact")]
    gt_dt: f64,
    restarts: usize,
    test_trajectories: usize,
    windows: usize,
    seed: u64,
    /// Also train the sparse GP where the exact one runs (N > M).
    sparse_also: bool,
    /// Output directory.
    #[serde(skip)]
    out: PathBuf,
    /// `--shard i/N`: compute only this shard's systems.
    #[serde(skip)]
    shard: Option<Shard>,
}

/// The tag of this example's shard files.
const SHARD_FORMAT: &str = "vigp-scale-sweep-shard/1";

/// The systems, in order: the sweep's units of work.
const SYSTEMS: [&str; 2] = ["pendulum", "cartpole"];

/// The result of one unit: a system's rows.
#[derive(Debug, Serialize, Deserialize)]
struct SystemRows {
    system: String,
    rows: Vec<Row>,
}

impl shard::UnitResult for SystemRows {
    type Key = String;
    fn key(&self) -> String {
        self.system.clone()
    }
}

/// The sweep's units (they do not depend on the options).
fn units(_: &Cli) -> Vec<String> {
    SYSTEMS.iter().map(|s| s.to_string()).collect()
}

fn parse() -> Result<Cli, String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let num = |name: &str, d: f64| -> Result<f64, String> {
        get(name).map_or(Ok(d), |v| v.parse().map_err(|_| format!("bad {name}")))
    };
    let n = match get("--n") {
        Some(v) => v
            .split(',')
            .map(|s| s.parse().map_err(|_| format!("bad --n entry {s}")))
            .collect::<Result<Vec<usize>, _>>()?,
        None => vec![64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384],
    };
    let shard: Option<Shard> = get("--shard")
        .map(|s| s.parse())
        .transpose()
        .map_err(|e: shard::ShardError| e.to_string())?;
    let out = match (get("--out"), shard) {
        (Some(dir), _) => PathBuf::from(dir),
        (None, Some(shard)) => Path::new("target/scale-shards").join(shard.dir_name()),
        (None, None) => PathBuf::from("target"),
    };
    Ok(Cli {
        n,
        exact_max: num("--exact-max", 4096.0)? as usize,
        sparse_m: num("--sparse-m", 512.0)? as usize,
        noise: num("--noise", 1e-3)?,
        gt_dt: num("--gt-dt", 1e-3)?,
        restarts: num("--restarts", 2.0)? as usize,
        test_trajectories: num("--test-trajectories", 20.0)? as usize,
        windows: num("--windows", 10.0)? as usize,
        seed: num("--seed", 1.0)? as u64,
        sparse_also: args.iter().any(|a| a == "--sparse-also"),
        out,
        shard,
    })
}

fn ground_truth<M: Mechanism<N, C> + Copy, const N: usize, const C: usize>(
    m: M,
    q0: &SVector<f64, N>,
    gt_dt: f64,
) -> Result<Vec<SVector<f64, N>>, StepError> {
    let sub = (DT / gt_dt).round().max(1.0) as usize;
    let h = DT / sub as f64;
    let q = consistent_state(&m, q0, &SVector::zeros(), h)?.q;
    let v = vigp::dynamics::discrete_velocity(&m, &q, &SVector::zeros(), h)?;
    let mut z = State { q, v };
    let vi = Variational::midpoint(m, h)?;
    let mut out = vec![z.q];
    for _ in 1..TRAJ_SAMPLES {
        for _ in 0..sub {
            z = vi.step(&z)?;
        }
        out.push(z.q);
    }
    Ok(out)
}

/// One trained model's result.
#[derive(Debug, Serialize, Deserialize)]
struct Row {
    system: String,
    n: usize,
    method: String,
    #[serde(with = "shard::exact")]
    mse: f64,
    #[serde(with = "shard::exact")]
    nominal_mse: f64,
    /// Measured training time (s): the one value that differs from run to run.
    #[serde(with = "shard::exact")]
    train_s: f64,
    #[serde(with = "shard::exact")]
    noise_var: f64,
}

#[allow(clippy::too_many_arguments)]
fn sweep<S, Mn, const N: usize>(
    name: &'static str,
    cli: &Cli,
    perturb: impl Fn(&mut S, &mut Rng),
    minimal: impl Fn(&S) -> Mn,
    sample_q0: impl Fn(&mut Rng) -> SVector<f64, N>,
    rows: &mut Vec<Row>,
) -> Result<(), Box<dyn std::error::Error>>
where
    S: Default,
    Mn: Mechanism<N, 0> + vigp::Parameters + Copy + Send + Sync,
{
    let mut rng = Rng(cli.seed ^ name.len() as u64);
    let mut truth = S::default();
    perturb(&mut truth, &mut rng);
    let (tmin, nmin) = (minimal(&truth), minimal(&S::default()));
    let nmax = cli.n.iter().copied().max().unwrap_or(0);
    // enough training trajectories for the largest N without repeats
    let train_traj = nmax.div_ceil(TRAJ_SAMPLES - 2) + 1;
    let starts: Vec<_> = (0..train_traj + cli.test_trajectories)
        .map(|_| sample_q0(&mut rng))
        .collect();
    let t0 = Instant::now();
    let trajs: Vec<Vec<SVector<f64, N>>> = starts
        .par_iter()
        .map(|q0| ground_truth(tmin, q0, cli.gt_dt))
        .collect::<Result<_, _>>()?;
    eprintln!(
        "{name}: {} ground-truth trajectories in {:.1} s",
        trajs.len(),
        t0.elapsed().as_secs_f64()
    );
    let (train, test) = trajs.split_at(train_traj);
    let mut pool: Vec<Transition<N>> = Vec::new();
    for traj in train {
        for t in transitions(traj, DT) {
            let mut t = t;
            t.z.q += SVector::from_fn(|_, _| cli.noise * rng.normal());
            t.z.v += SVector::from_fn(|_, _| cli.noise * rng.normal());
            t.v_next += SVector::from_fn(|_, _| cli.noise * rng.normal());
            pool.push(t);
        }
    }
    // a fixed random order: the first N of it are the N training samples
    for i in (1..pool.len()).rev() {
        pool.swap(i, rng.below(i + 1));
    }
    let windows = test_windows(test, cli.windows, TRAJ_SAMPLES, HORIZON, DT, &mut rng);
    let mse = |roll: &(dyn Fn(&State<N>) -> Result<Vec<State<N>>, StepError> + Sync)| -> f64 {
        let v: Vec<f64> = windows
            .par_iter()
            .filter_map(|(z, truth)| {
                let p = roll(z).ok()?;
                let s: f64 = p
                    .iter()
                    .zip(truth)
                    .skip(1)
                    .map(|(a, b)| (a.q - b).norm_squared() / N as f64)
                    .sum();
                Some(s / HORIZON as f64)
            })
            .collect();
        let mut v = v;
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            f64::NAN
        } else {
            v[v.len() / 2]
        }
    };
    let nominal_vi = Variational::new(nmin, DT)?;
    let nominal_mse = mse(&|z| nominal_vi.rollout(z, HORIZON));
    // Warm starts: one chain for the main method at each N, one for the
    // sparse GP trained beside the exact one (`--sparse-also`).
    let (mut warm, mut warm_also) = (None, None);
    for &n in &cli.n {
        let n = n.min(pool.len());
        let sparse = n > cli.exact_max;
        let also = cli.sparse_also && !sparse && n > cli.sparse_m;
        let mut exact_mse = None;
        for sparse in std::iter::once(sparse).chain(also.then_some(true)) {
            let warm = if sparse && also {
                &mut warm_also
            } else {
                &mut warm
            };
            let opts = TrainOptions {
                restarts: cli.restarts,
                seed: cli.seed ^ n as u64,
                method: if sparse {
                    Method::Sparse(SparseOptions::kmeans(cli.sparse_m.min(n)))
                } else {
                    Method::Exact
                },
                warm_start: warm.clone(),
                ..TrainOptions::default()
            };
            let t0 = Instant::now();
            let (l, _) = Learned::train(
                nmin,
                DT,
                &pool[..n],
                Encoding::SinCos,
                Prior::Nominal,
                &opts,
            )?;
            let train_s = t0.elapsed().as_secs_f64();
            *warm = Some(l.gp().warm_start());
            let m = mse(&|z| l.rollout(z, HORIZON));
            let noise_var = l.gp().output(0).hyperparameters_original().noise_variance;
            let method = if sparse {
                format!("sparse M={}", cli.sparse_m.min(n))
            } else {
                "exact".into()
            };
            println!(
                "{name:9} N {n:6} {method:13} 20-step MSE {m:.4e} (nominal {nominal_mse:.3e}), trained in {train_s:.1} s, σ_n² {noise_var:.3e}{}",
                if l.gp().is_sparse() {
                    " (sparse model)"
                } else {
                    ""
                }
            );
            match exact_mse {
                None => exact_mse = Some(m),
                Some(e) => println!("{name:9} N {n:6} sparse / exact 20-step MSE: {:.3}", m / e),
            }
            rows.push(Row {
                system: name.into(),
                n,
                method,
                mse: m,
                nominal_mse,
                train_s,
                noise_var,
            });
        }
    }
    Ok(())
}

/// Rows back from a CSV written by this example (for `--plot`).
fn read_csv(path: &str) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    let text = std::fs::read_to_string(path)?;
    let mut rows = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 7 {
            return Err(format!("bad CSV line: {line}").into());
        }
        rows.push(Row {
            system: match f[0] {
                s if SYSTEMS.contains(&s) => s.into(),
                other => return Err(format!("unknown system {other}").into()),
            },
            n: f[1].parse()?,
            method: f[2].into(),
            mse: f[3].parse()?,
            nominal_mse: f[4].parse()?,
            train_s: f[5].parse()?,
            noise_var: f[6].parse()?,
        });
    }
    Ok(rows)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `--plot CSV`: only redraw the figure of an earlier run.
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--plot") {
        let csv = args.get(i + 1).ok_or("--plot needs a CSV path")?;
        let rows = read_csv(csv)?;
        let svg = csv.trim_end_matches(".csv").to_string() + ".svg";
        figure(&rows, &svg)?;
        println!("wrote {svg}");
        return Ok(());
    }
    // `merge DIR… [--out DIR]`: the report of the shards' rows.
    if args.get(1).map(String::as_str) == Some("merge") {
        let mut dirs = Vec::new();
        let mut out = PathBuf::from("target");
        let mut rest = args[2..].iter();
        while let Some(a) = rest.next() {
            if a == "--out" {
                out = rest.next().ok_or("--out needs a directory")?.into();
            } else {
                dirs.push(PathBuf::from(a));
            }
        }
        let files = dirs
            .iter()
            .map(|d| shard::read::<Cli, SystemRows>(d))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        let (_, units) = shard::merge(files, SHARD_FORMAT, units).map_err(|e| e.to_string())?;
        println!("merged {} shards", dirs.len());
        return report(units, &out);
    }
    let cli = parse()?;
    println!(
        "scale sweep: N {:?}, exact up to {}, sparse M = {}, noise σ = {:e}, ground truth dt {:e}, {} restarts, seed {}",
        cli.n, cli.exact_max, cli.sparse_m, cli.noise, cli.gt_dt, cli.restarts, cli.seed
    );
    let whole = cli.shard.unwrap_or(Shard::WHOLE);
    let mut done = Vec::new();
    for (k, system) in units(&cli).into_iter().enumerate() {
        if !whole.owns(k) {
            continue;
        }
        let mut rows = Vec::new();
        match system.as_str() {
            "pendulum" => sweep(
                "pendulum",
                &cli,
                |s: &mut Pendulum, r| {
                    s.links.rod.mass *= r.uniform(0.9, 1.1);
                    s.links.rod.inertia *= r.uniform(0.9, 1.1);
                    s.joints.pivot.damping = r.uniform(0.0, 1.0);
                },
                Pendulum::minimal,
                |r| SVector::from([r.uniform(-PI, PI)]),
                &mut rows,
            )?,
            "cartpole" => sweep(
                "cartpole",
                &cli,
                |s: &mut Cartpole, r| {
                    for l in [&mut s.links.cart, &mut s.links.pole] {
                        l.mass *= r.uniform(0.9, 1.1);
                        l.inertia *= r.uniform(0.9, 1.1);
                    }
                    s.joints.rail.damping = r.uniform(0.0, 0.5);
                    s.joints.hinge.damping = r.uniform(0.0, 1.0);
                },
                Cartpole::minimal,
                |r| SVector::from([r.uniform(-1.0, 1.0), r.uniform(-PI, PI)]),
                &mut rows,
            )?,
            other => return Err(format!("unknown system {other}").into()),
        }
        done.push(SystemRows { system, rows });
    }
    let this = ShardFile {
        format: SHARD_FORMAT.into(),
        shard: whole,
        options: cli.clone(),
        units: done,
    };
    match cli.shard {
        Some(shard) => {
            let path = shard::write(&cli.out, SHARD_FORMAT, shard, &cli, &this.units)
                .map_err(|e| e.to_string())?;
            println!("shard {shard}: wrote {}", path.display());
            Ok(())
        }
        // the unsharded run is the one shard 0/1, checked as `merge` checks
        None => {
            let (_, units) = shard::merge(vec![("this run".into(), this)], SHARD_FORMAT, units)
                .map_err(|e| e.to_string())?;
            report(units, &cli.out)
        }
    }
}

/// Writes `scale_sweep.csv` and `scale_sweep.svg` into `dir`.
fn report(units: Vec<SystemRows>, dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let rows: Vec<Row> = units.into_iter().flat_map(|u| u.rows).collect();
    let mut csv = String::from("system,n,method,mse,nominal_mse,train_s,noise_variance\n");
    for r in &rows {
        csv.push_str(&format!(
            "{},{},{},{:e},{:e},{:.3},{:e}\n",
            r.system, r.n, r.method, r.mse, r.nominal_mse, r.train_s, r.noise_var
        ));
    }
    std::fs::create_dir_all(dir)?;
    let (csv_path, svg_path) = (dir.join("scale_sweep.csv"), dir.join("scale_sweep.svg"));
    std::fs::write(&csv_path, csv)?;
    let svg = svg_path.to_str().ok_or("output path is not UTF-8")?;
    figure(&rows, svg)?;
    println!("wrote {} and {}", csv_path.display(), svg_path.display());
    Ok(())
}

/// Log–log figure: median 20-step MSE against N, one line per system, the
/// nominal model's error dashed.
fn figure(rows: &[Row], path: &str) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    font::register_embedded_font()?;
    let ok = |v: f64| v.is_finite() && v > 0.0;
    let ys: Vec<f64> = rows
        .iter()
        .flat_map(|r| [r.mse, r.nominal_mse])
        .filter(|v| ok(*v))
        .collect();
    let (ylo, yhi) = ys
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(*v), b.max(*v)));
    let (xlo, xhi) = rows.iter().fold((f64::INFINITY, 0.0f64), |(a, b), r| {
        (a.min(r.n as f64), b.max(r.n as f64))
    });
    if ys.is_empty() || xlo >= xhi || xlo.is_nan() {
        return Ok(());
    }
    let root = SVGBackend::new(path, (800, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "20-step position MSE vs training samples N",
            ("sans-serif", 22),
        )
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (xlo / 1.3..xhi * 1.3).log_scale(),
            (ylo / 3.0..yhi * 3.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("N (exact up to --exact-max, sparse beyond)")
        .y_desc("median window MSE [rad², m²]")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    // A sparse row at an N where the exact GP also ran (`--sparse-also`)
    // is drawn apart, as hollow markers.
    let beside_exact = |r: &Row| {
        r.method != "exact"
            && rows
                .iter()
                .any(|e| e.system == r.system && e.n == r.n && e.method == "exact")
    };
    for (system, colour) in [("pendulum", BLUE), ("cartpole", RED)] {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.system == system && ok(r.mse) && !beside_exact(r))
            .map(|r| (r.n as f64, r.mse))
            .collect();
        let also: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.system == system && ok(r.mse) && beside_exact(r))
            .map(|r| (r.n as f64, r.mse))
            .collect();
        if !also.is_empty() {
            chart
                .draw_series(
                    also.iter()
                        .map(|p| Circle::new(*p, 6, colour.stroke_width(2))),
                )?
                .label(format!("{system}, sparse GP at the same N"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.stroke_width(2)));
        }
        chart
            .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))?
            .label(format!("{system}, learned (nominal VI prior)"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
        chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, colour.filled())))?;
        if let Some(nom) = rows
            .iter()
            .find(|r| r.system == system)
            .map(|r| r.nominal_mse)
        {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(xlo, nom), (xhi, nom)],
                    6,
                    4,
                    colour.mix(0.5).stroke_width(1),
                ))?
                .label(format!("{system}, nominal model"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.mix(0.5)));
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
