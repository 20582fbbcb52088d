//! Invalid `mechanism!` descriptions are compile errors with spans that point
//! at the offending token. One case per file in `tests/ui`; the
//! expected compiler output sits next to it in `NAME.stderr`. Regenerate with
//! `TRYBUILD=overwrite cargo test -p vigp-compile-fail` and review the diff.

#[test]
fn invalid_descriptions() {
    trybuild::TestCases::new().compile_fail("tests/ui/*.rs");
}
