#!/usr/bin/env bash
# Regenerates the exported-learned-model fixture of tests/learn/embedded_learned.rs:
# a small cart-pole model fitted by `vigp fit` on smooth synthetic
# trajectories (written here by Python's standard library), saved as JSON and
# exported by `vigp export` as Rust source. The test includes the source and
# checks it against the JSON loaded by the std runtime. The same for a model
# with inputs (learned_drive_cartpole.*, examples/learned_forced_fixture.rs).
#   bash scripts/learned_fixture.sh
set -euo pipefail
cd "$(dirname "$0")/.."
dir=tests/fixtures
python3 - "$dir/learned_cartpole_data.csv" <<'PY'
import math, sys
with open(sys.argv[1], "w") as f:
    f.write("run,t,rail,hinge\n")
    for run, (a, w) in enumerate([(0.2, 2.0), (0.1, 3.0)]):
        for k in range(30):
            t = k * 0.01
            rail = a * math.sin(w * t)
            hinge = 0.5 * math.cos(3.0 * t + run) * math.exp(-0.1 * t)
            f.write(f"r{run},{t:.2f},{rail!r},{hinge!r}\n")
PY
cargo run --release --bin vigp -- fit --system cartpole --data "$dir/learned_cartpole_data.csv" \
    --out "$dir/learned_cartpole.json" --max-samples 24 --restarts 0
cargo run --release --bin vigp -- export --model "$dir/learned_cartpole.json" \
    --out "$dir/learned_cartpole.rs"
# The forced model (an actuated cart-pole trained with inputs): trained in
# Rust (`vigp fit` reads no inputs), exported through `vigp export`.
cargo run --release --features cli --example learned_forced_fixture -- "$dir"
