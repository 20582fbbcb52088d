#!/usr/bin/env bash
# Times `cargo build` of a crate that declares a URDF robot with
# `mechanism! { urdf: … }` (default: the 29-joint G1 humanoid of
# tests/fixtures/robots/g1.urdf) and steps it once, after its dependencies
# are built: the crate's own compile, macro expansion included.
#
#   bash scripts/urdf_build_time.sh [robot.urdf] [--release]
#
# It builds in a temporary directory with this checkout's Cargo.lock and
# a target directory of its own (kept in $TARGET, default
# target/urdf-build-time, so that a second run reuses the dependencies).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
urdf="${1:-$here/tests/fixtures/robots/g1.urdf}"
profile="${2:-}"
target="${TARGET:-$here/target/urdf-build-time}"
crate="$(mktemp -d)"
trap 'rm -rf "$crate"' EXIT
mkdir -p "$crate/src"
cp "$urdf" "$crate/robot.urdf"
cp "$here/Cargo.lock" "$crate/"
n=$(python3 - "$urdf" <<'PY'
import sys, xml.etree.ElementTree as ET
r = ET.parse(sys.argv[1]).getroot()
print(sum(1 for j in r.iter("joint") if j.get("type") in ("revolute", "continuous", "prismatic")))
PY
)
cat > "$crate/Cargo.toml" <<TOML
[package]
name = "urdf-build-time"
version = "0.1.0"
edition = "2024"

[dependencies]
vigp = { path = "$here" }

[workspace]
TOML
cat > "$crate/src/main.rs" <<RS
use vigp::prelude::*;

vigp::mechanism! {
    /// The robot of the URDF file.
    pub Robot { urdf: "robot.urdf" }
}

fn main() {
    let m = Robot::default().minimal();
    let z0 = m.state([0.1; $n], [0.0; $n]);
    let z1 = Variational::new(m, 0.002).step(&z0).expect("step");
    println!("{} coordinates, q1[0] = {}", $n, z1.q[0]);
}
RS
cd "$crate"
echo "dependencies (not timed):"
CARGO_TARGET_DIR="$target" cargo build $profile 2>&1 | tail -1
touch src/main.rs
start=$(date +%s.%N)
CARGO_TARGET_DIR="$target" cargo build $profile 2>&1 | tail -1
end=$(date +%s.%N)
echo "the crate alone: $(python3 -c "print(f'{$end - $start:.1f}')") s (load average $(cut -d' ' -f1-3 /proc/loadavg))"
CARGO_TARGET_DIR="$target" cargo run $profile 2>/dev/null || echo "the step failed (exit $?)"
