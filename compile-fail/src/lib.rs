//! No code: this package holds the compile-fail tests of `vigp::mechanism!`
//! (`tests/compile_fail.rs`, one case per file in `tests/ui/`). Run them with
//! `cargo test -p vigp-compile-fail`.
