//! Print the expansion of a `mechanism!` body read from a file, as the
//! snapshot tests see it.
//!
//! Run: `cargo run -p vigp-codegen --example expand -- path/to/description.txt`
//! (the file holds what goes between `mechanism! {` and `}`).

use std::process::ExitCode;

fn main() -> ExitCode {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: expand <file with a mechanism description>");
        return ExitCode::from(2);
    };
    let src = match std::fs::read_to_string(&path) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("cannot read {path}: {e}");
            return ExitCode::from(2);
        }
    };
    match vigp_codegen::expand_to_string(&src) {
        Ok(code) => {
            println!("{code}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
