//! Trains (or conditions) an exact GP on a CSV file, for the scikit-learn
//! comparison campaign (`scripts/gp_campaign.py`).
//!
//! The CSV has one sample per line, the d inputs then the output, comma
//! separated; lines starting with `#` are skipped.
//!
//! ```text
//! cargo run --release --example gp_csv -- --csv data.csv [--restarts 10] [--seed 0]
//!     [--raw] [--bounds LO HI] [--screen auto|off|M] [--memory K] [--theta t1,…,t(d+2)]
//!     [--test test.csv]
//! ```
//!
//! * default: vigp's defaults (inputs standardised, `Bounds::default()`,
//!   start 0 at ℓ = 1, σ_f² = 1, σ_n² = 0.01), constant prior mean,
//!   outputs normalised (scikit-learn's `normalize_y=True`);
//! * `--raw`: inputs as given (no standardisation), uniform bounds
//!   [1e-5, 1e5] on every hyperparameter and start 0 at ℓ = σ_f² = σ_n² = 1,
//!   i.e. scikit-learn's `ConstantKernel(1) * RBF([1] * d) + WhiteKernel(1)`
//!   with bounds (1e-5, 1e5) and `normalize_y=True`;
//! * `--bounds LO HI`: other uniform bounds (normalised units);
//! * `--screen auto|off|M`: [`Screening`] of the starts (default auto:
//!   from N = 512 on a subset; `off` is scikit-learn's procedure);
//! * `--memory K`: L-BFGS-B curvature pairs (`TrainOptions::memory`;
//!   default 10, scipy's `maxcor`);
//! * `--start t1,…,t(d+2)`: start 0 at this θ (normalised units, vigp's
//!   order, clamped into the bounds) instead; with `--restarts 0` this runs
//!   the optimiser from one given point (e.g. one of scikit-learn's starts).
//!
//! Without `--theta` it trains with 1 + `restarts` starts and prints one
//! JSON line: the best LML in normalised units (scikit-learn's
//! `log_marginal_likelihood_value_` with `normalize_y=True`), θ = (ln ℓ_1..
//! ln ℓ_d, ln σ_f², ln σ_n²) in normalised units, every start's final LML
//! and evaluations, the winning start, convergence, jitter and wall time.
//!
//! With `--theta` (same order and units) it conditions the GP at those
//! hyperparameters instead and prints the LML, its gradient with respect
//! to θ, and, for the points of `--test` (CSV of inputs only), the
//! posterior mean and the variance of a new observation (latent variance
//! plus noise, original units: scikit-learn's `predict(return_std=True)`
//! squared).

use std::time::Instant;

use vigp::gp::{
    Bounds, Gp, Hyperparameters, PriorMean, Screening, TrainOptions, log_marginal_likelihood,
};

#[path = "common/args.rs"]
mod args;
use args::str_arg;

/// The two command-line words after `name`, if any.
fn pair_arg(name: &str) -> Option<(String, String)> {
    let args: Vec<String> = std::env::args().collect();
    let i = args.iter().position(|a| a == name)?;
    Some((args.get(i + 1)?.clone(), args.get(i + 2)?.clone()))
}

fn flag(name: &str) -> bool {
    std::env::args().any(|a| a == name)
}

/// Rows of a comma-separated numeric file (skipping blank and `#` lines).
fn read_csv(path: &str) -> Result<Vec<Vec<f64>>, Box<dyn std::error::Error>> {
    let text = std::fs::read_to_string(path)?;
    let mut rows = Vec::new();
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let row: Result<Vec<f64>, _> = line.split(',').map(|v| v.trim().parse::<f64>()).collect();
        rows.push(row?);
    }
    if rows.is_empty() {
        return Err(format!("{path}: no rows").into());
    }
    Ok(rows)
}

/// Comma-separated numbers.
fn parse_list(s: &str) -> Result<Vec<f64>, std::num::ParseFloatError> {
    s.split(',').map(|v| v.trim().parse::<f64>()).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = str_arg("--csv").ok_or("--csv PATH is required")?;
    let rows = read_csv(&path)?;
    let d = rows[0].len() - 1;
    if d == 0 || rows.iter().any(|r| r.len() != d + 1) {
        return Err("every row needs the same number (≥ 2) of columns".into());
    }
    let x: Vec<f64> = rows.iter().flat_map(|r| r[..d].to_vec()).collect();
    let y: Vec<f64> = rows.iter().map(|r| r[d]).collect();
    let raw = flag("--raw");
    let restarts = str_arg("--restarts").map_or(Ok(10), |s| s.parse())?;
    let seed = str_arg("--seed").map_or(Ok(0), |s| s.parse())?;
    let mut opts = TrainOptions {
        mean: PriorMean::Constant,
        normalise_inputs: !raw,
        normalise_outputs: true,
        restarts,
        seed,
        ..Default::default()
    };
    if raw {
        opts.bounds = Bounds::uniform(1e-5, 1e5);
        opts.initial = Some(Hyperparameters::isotropic(d, 1.0, 1.0, 1.0));
    }
    opts.screening = match str_arg("--screen").as_deref() {
        None | Some("auto") => Screening::Auto,
        Some("off") => Screening::Off,
        Some(m) => Screening::Subset(m.parse()?),
    };
    if let Some(m) = str_arg("--memory") {
        opts.memory = m.parse()?;
    }
    if let Some((lo, hi)) = pair_arg("--bounds") {
        opts.bounds = Bounds::uniform(lo.parse()?, hi.parse()?);
    }
    if let Some(start) = str_arg("--start") {
        opts.initial = Some(Hyperparameters::from_log(&parse_list(&start)?)?);
    }
    if let Some(theta) = str_arg("--theta") {
        let t = parse_list(&theta)?;
        let hp = Hyperparameters::from_log(&t)?;
        let gp = Gp::fit(&x, d, &y, 1, std::slice::from_ref(&hp), &opts)?;
        let out = gp.output(0);
        // The gradient at θ on the model's own normalised inputs and residual.
        let norm = gp.input_normaliser();
        let mut xn = vec![0.0; x.len()];
        for (o, r) in xn.chunks_exact_mut(d).zip(x.chunks_exact(d)) {
            norm.apply(r, o);
        }
        let (v, g) = log_marginal_likelihood(&xn, d, out.residual_normalised(), &t, false)?;
        let (mean, var) = match str_arg("--test") {
            Some(p) => {
                let xt: Vec<f64> = read_csv(&p)?.into_iter().flatten().collect();
                let pred = gp.predict(&xt)?;
                let noise = out.hyperparameters_original().noise_variance;
                let var: Vec<f64> = pred.variance.iter().map(|v| v + noise).collect();
                (pred.mean, var)
            }
            None => (Vec::new(), Vec::new()),
        };
        let json = serde_json::json!({
            "lml": out.log_marginal_likelihood(),
            "lml_raw_function": v,
            "gradient": g,
            "jitter": out.jitter(),
            "mean": mean,
            "var_with_noise": var,
        });
        println!("{json}");
        return Ok(());
    }
    let t0 = Instant::now();
    let res = Gp::train(&x, d, &y, 1, &opts);
    let secs = t0.elapsed().as_secs_f64();
    let json = match res {
        Ok((gp, rep)) => {
            let o = &rep.outputs[0];
            let theta = gp.output(0).hyperparameters().to_log();
            serde_json::json!({
                "ok": true,
                "n": y.len(),
                "d": d,
                "lml": o.log_marginal_likelihood,
                "theta": theta,
                "best_start": o.best_start,
                "start_lmls": o.start_lmls.iter().map(|v| if v.is_finite() { Some(*v) } else { None }).collect::<Vec<_>>(),
                "start_evaluations": o.start_evaluations,
                "evaluations": o.evaluations,
                "iterations": o.iterations,
                "converged": o.converged,
                "jitter": o.jitter,
                "seconds": secs,
                "screening": o.screening.as_ref().map(|s| serde_json::json!({
                    "subset": s.subset,
                    "evaluations": s.evaluations,
                    "refined": s.refined,
                    "fell_back": s.fell_back,
                })),
            })
        }
        Err(e) => serde_json::json!({"ok": false, "error": e.to_string(), "seconds": secs}),
    };
    println!("{json}");
    Ok(())
}
