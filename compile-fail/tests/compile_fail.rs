//! Invalid `mechanism!` descriptions are compile errors with spans that point
//! at the offending token. One case per file in `tests/ui`: one kind of
//! mistake, or a description carrying several that are all reported at once
//! (`planar_link_errors.rs`, …); the expected compiler output sits next to it
//! in `NAME.stderr`. Regenerate with
//! `TRYBUILD=overwrite cargo test -p vigp-compile-fail` and review the diff.

use std::path::Path;

#[test]
fn invalid_descriptions() {
    // `urdf:` paths are relative to the manifest directory of the crate
    // that invokes the macro: trybuild's project, in the target directory
    // (`<target>/tests/trybuild/<crate>`; CARGO_TARGET_TMPDIR is
    // `<target>/tmp`). The cases' URDF files go there as `urdf/…`.
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).parent().unwrap();
    let dest = target.join("tests/trybuild/vigp-compile-fail/urdf");
    std::fs::create_dir_all(&dest).unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/urdf");
    for entry in std::fs::read_dir(src).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dest.join(path.file_name().unwrap())).unwrap();
    }
    trybuild::TestCases::new().compile_fail("tests/ui/*.rs");
}
