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

/// The file `name` in `dir`, written with `contents`: its path.
pub fn write_file(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, contents).unwrap();
    path
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

/// Asserts that the file at `path` holds exactly `expected`.
pub fn assert_file_is(path: &Path, expected: &str) {
    assert_eq!(std::fs::read_to_string(path).unwrap(), expected);
}

/// The rows of a CSV file, split at commas (header first).
pub fn table(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// The words of `line`, each `{}` replaced by the next of `values` (every
/// one of them used): an argument list written as on a command line.
pub fn argv<'a>(line: &'a str, values: &[&'a str]) -> Vec<&'a str> {
    let mut values = values.iter().copied();
    let args = line
        .split_whitespace()
        .map(|w| match w {
            "{}" => values.next().expect("a value for every {}"),
            _ => w,
        })
        .collect();
    assert_eq!(values.next(), None, "a {{}} for every value");
    args
}

/// `score --model MODEL --data DATA --steps STEPS` (without the program name).
pub fn score_args<'a>(model: &'a str, data: &'a str, steps: &'a str) -> [&'a str; 7] {
    ["score", "--model", model, "--data", data, "--steps", steps]
}

/// `predict --model MODEL --data DATA --steps STEPS --out OUT` (without the
/// program name).
pub fn predict_args<'a>(
    model: &'a str,
    data: &'a str,
    steps: &'a str,
    out: &'a str,
) -> Vec<&'a str> {
    vec![
        "predict", "--model", model, "--data", data, "--steps", steps, "--out", out,
    ]
}

/// `vigp::cli::run` of `systems` on `args` (after the program name `vigp`),
/// expected to fail: its error message.
pub fn run_error(systems: &[vigp::cli::SystemEntry], args: &[&str]) -> String {
    let argv = std::iter::once("vigp").chain(args.iter().copied());
    vigp::cli::run(systems, argv, &mut Vec::new())
        .unwrap_err()
        .to_string()
}

/// The JSON file at `path`, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The row of parameter `name` in a parameter file of `vigp identify`.
pub fn parameter_row(file: &serde_json::Value, name: &str) -> serde_json::Value {
    file["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"] == name)
        .unwrap_or_else(|| panic!("no row {name} in {file}"))
        .clone()
}

/// The first line of `text` that starts with `start`.
pub fn line_starting<'a>(text: &'a str, start: &str) -> &'a str {
    text.lines()
        .find(|l| l.starts_with(start))
        .unwrap_or_else(|| panic!("{text}"))
}

/// The number right after `after` in `line` (up to a comma or a space).
pub fn number_after(line: &str, after: &str) -> f64 {
    let rest = &line[line.find(after).unwrap() + after.len()..];
    let end = rest.find([',', ' ']).unwrap_or(rest.len());
    rest[..end].parse().unwrap()
}

/// The rows of a CSV file (as `table`), its header line asserted to be
/// `header`.
pub fn table_with_header(path: &Path, header: &str) -> Vec<Vec<String>> {
    let rows = table(path);
    assert_eq!(rows[0].join(","), header);
    rows
}

/// The number in column `i` of a table row.
pub fn cell(row: &[String], i: usize) -> f64 {
    row[i].parse().unwrap()
}

/// Asserts that a nominal MSE of `score` is the mean `want` computed here
/// (positive), to 1e-9 relative (the same sums in another order).
pub fn assert_same_mean(got: f64, want: f64) {
    assert!(want > 1e-12, "{want:e}");
    assert!((got - want).abs() <= 1e-9 * want, "{got:e} vs {want:e}");
}
