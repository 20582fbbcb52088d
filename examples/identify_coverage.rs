//! Coverage of the identification's 95 % intervals over many noisy logs.
//!
//! ```text
//! cargo run --release --example identify_coverage [-- --seeds 200 --sigma 1e-4 --steps 1500]
//! ```
//!
//! One "true" driven, sprung double pendulum (masses and inertias
//! perturbed, centres of mass moved, random damping; the fixture of
//! `cargo test --test learn identify::`), logged by the midpoint rule at
//! 10 ms under two sums of sines; every seed adds independent position
//! noise σ. For the regression (instrumental variables, position-noise
//! intervals) and for the regression refined by output error, the table
//! gives the fraction of (seed, base parameter) pairs whose 95 % interval
//! holds the truth, per base parameter and overall, and the median of the
//! largest relative base-parameter error. Seeds run in parallel (rayon).

#[path = "../tests/learn/fixtures.rs"]
mod fixtures;
#[path = "../tests/common/rng.rs"]
mod rng;

use clap::Parser;
use fixtures::{DT, base_error, coverage_case, covers, noisy};
use rayon::prelude::*;
use rng::Rng;
use vigp::identify::{DelRegressor, Identification, Noise, Options, OutputError, identify};

/// Command line.
#[derive(Parser)]
struct Args {
    /// Noisy logs (seeds).
    #[arg(long, default_value_t = 200)]
    seeds: u64,
    /// Position noise (standard deviation).
    #[arg(long, default_value_t = 1e-4)]
    sigma: f64,
    /// Steps per log (10 ms each).
    #[arg(long, default_value_t = 1500)]
    steps: usize,
}

/// Per seed: for each base parameter whether the interval holds the
/// truth, and the largest relative error.
fn score(id: &Identification, truth: &[f64]) -> (Vec<bool>, f64) {
    (covers(id, truth), base_error(id, truth))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let case = coverage_case(args.steps);
    let (clean, t) = (&case.clean, &case.truth);
    let r = DelRegressor::midpoint(case.declared, DT)?;
    let first = Options {
        noise: Noise::IV,
        ..Options::default()
    };
    let second = Options {
        output_error: Some(OutputError::default()),
        ..first
    };
    let runs: Vec<_> = (0..args.seeds)
        .into_par_iter()
        .map(|seed| {
            let log = noisy(clean, args.sigma, &mut Rng(1000 + seed));
            let a = identify(&r, std::slice::from_ref(&log), &first)?;
            let b = identify(&r, &[log], &second)?;
            Ok((score(&a, t), score(&b, t), a.base_names))
        })
        .collect::<Result<_, vigp::identify::IdentifyError>>()?;
    let names = &runs[0].2;
    println!(
        "driven sprung double pendulum, midpoint rule, {} steps at {DT} s, σ = {:e}, {} seeds",
        args.steps, args.sigma, args.seeds
    );
    println!("| base parameter | regression (IV) | + output error |");
    println!("|---|---|---|");
    let frac = |pick: &dyn Fn(usize) -> bool| {
        (0..runs.len()).filter(|s| pick(*s)).count() as f64 / runs.len() as f64
    };
    for (i, name) in names.iter().enumerate() {
        println!(
            "| {name} | {:.3} | {:.3} |",
            frac(&|s| runs[s].0.0[i]),
            frac(&|s| runs[s].1.0[i])
        );
    }
    let overall = |m: usize| {
        let hits: usize = runs
            .iter()
            .map(|r| {
                let v = if m == 0 { &r.0.0 } else { &r.1.0 };
                v.iter().filter(|h| **h).count()
            })
            .sum();
        hits as f64 / (runs.len() * names.len()) as f64
    };
    let median = |m: usize| {
        let mut e: Vec<f64> = runs
            .iter()
            .map(|r| if m == 0 { r.0.1 } else { r.1.1 })
            .collect();
        e.sort_by(f64::total_cmp);
        e[e.len() / 2]
    };
    println!("| **all** | {:.3} | {:.3} |", overall(0), overall(1));
    println!(
        "| median max relative error | {:.2e} | {:.2e} |",
        median(0),
        median(1)
    );
    Ok(())
}
