//! Helpers shared by the tool's test files: a temporary folder per test,
//! the `vigp` binary and the tool run in-process, and readers of what they
//! write. Each test file uses the subset it needs.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A fresh folder for the test `name` of this test binary and process.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "vigp-{}-{name}-{}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A path as the `&str` an argument list takes.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The `vigp` binary with `args`; its report (stdout), echoed to stderr.
pub fn vigp(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_vigp"))
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "vigp {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("$ vigp {}\n{stdout}", args.join(" "));
    stdout
}

/// The `vigp` binary with `args`, expected to fail: its stderr.
pub fn vigp_fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_vigp"))
        .args(args)
        .output()
        .unwrap();
    assert!(!out.status.success(), "vigp {args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The tool of `systems` run in-process as the program `name`, its report
/// echoed to stderr.
pub fn run_tool(
    systems: &[vigp::cli::SystemEntry],
    name: &str,
    args: &[&str],
) -> Result<String, vigp::cli::CliError> {
    let mut out = Vec::new();
    let mut argv = vec![name];
    argv.extend_from_slice(args);
    let r = vigp::cli::run(systems, argv, &mut out);
    let text = String::from_utf8(out).unwrap();
    eprintln!("$ {name} {}\n{text}", args.join(" "));
    r.map(|()| text)
}

/// The two numbers of `score`'s last line.
pub fn mse_line(report: &str) -> (f64, f64) {
    let last = report.lines().last().expect("a report");
    let (n, l) = last
        .strip_prefix("nominal_mse=")
        .and_then(|r| r.split_once(" learned_mse="))
        .unwrap_or_else(|| panic!("last line {last:?}"));
    (n.parse().unwrap(), l.parse().unwrap())
}

/// The rows of a CSV file, split at commas (header first).
pub fn table(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}
