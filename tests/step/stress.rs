//! Stress suite (issue 8): long horizons, large steps and fast motion,
//! singular configurations, extreme parameters, GP edge cases, projection
//! from far off the manifold, and bad input. Every case must end without a
//! panic or a NaN, and every failure must be a typed error that says what
//! happened; where a remedy exists it is used and checked. The cases live in
//! `stress_cases/` and are shared with `examples/stress.rs`, which runs the
//! heavy sizes (10^6 steps) and prints the README's table; here they run at
//! test size (run with `-- --nocapture` to see the rows).

#[path = "../stress_cases/mod.rs"]
mod stress_cases;

use stress_cases::{Row, Size};

fn assert_rows(rows: Vec<Row>) {
    eprintln!("{}", stress_cases::table(&rows));
    let failed: Vec<String> = rows
        .iter()
        .filter_map(|r| r.verdict.as_ref().err().map(|e| format!("{}: {e}", r.case)))
        .collect();
    assert!(failed.is_empty(), "failed cases:\n{}", failed.join("\n"));
}

#[test]
fn long_horizon_energy_stays_bounded() {
    assert_rows(stress_cases::long_horizon(Size::Test));
}

#[test]
fn large_steps_fail_typed_or_run_with_substeps() {
    let mut rows = vec![stress_cases::pendulum_fast(Size::Test)];
    rows.extend(stress_cases::large_steps(Size::Test));
    assert_rows(rows);
}

#[test]
fn singular_configurations() {
    assert_rows(stress_cases::singular(Size::Test));
}

#[test]
fn extreme_parameters() {
    assert_rows(stress_cases::extreme_parameters(Size::Test));
}

#[test]
fn gp_edge_cases() {
    assert_rows(stress_cases::gp_cases(Size::Test));
}

#[test]
fn projection_from_far_off_the_manifold() {
    assert_rows(stress_cases::projection_cases(Size::Test));
}

#[test]
fn bad_input_gives_typed_errors() {
    assert_rows(stress_cases::bad_input(Size::Test));
}
