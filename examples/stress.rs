//! The stress suite at heavy sizes (issue 8): 10^6-step horizons, longer
//! sweeps, every corruption of a saved GP. Prints the outcome table that the
//! README's "Numerical stability" section records, and exits non-zero if an
//! expectation failed.
//!
//! ```text
//! cargo run --release --example stress            # heavy (minutes on 2 cores)
//! cargo run --release --example stress -- --quick # the test suite's sizes
//! ```

#[path = "../tests/stress_cases/mod.rs"]
mod stress_cases;

use stress_cases::Size;

fn main() {
    let size = if std::env::args().any(|a| a == "--quick") {
        Size::Test
    } else {
        Size::Heavy
    };
    let start = std::time::Instant::now();
    let rows = stress_cases::all(size);
    println!("{}", stress_cases::table(&rows));
    let failed: Vec<_> = rows.iter().filter(|r| r.verdict.is_err()).collect();
    for r in &failed {
        eprintln!("FAILED {}: {}", r.case, r.verdict.as_ref().unwrap_err());
    }
    eprintln!(
        "{} cases, {} failed, {:.0} s ({size:?})",
        rows.len(),
        failed.len(),
        start.elapsed().as_secs_f64()
    );
    if !failed.is_empty() {
        std::process::exit(1);
    }
}
