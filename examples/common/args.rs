//! Reading a word of the command line, shared by `#[path]` between the
//! examples that take a few named options without clap (`gp_csv`,
//! `gp_train`).

/// The command-line word after `name`, if any.
pub fn str_arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}
