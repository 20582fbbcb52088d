#!/usr/bin/env bash
# Regenerates the exported-learned-model fixture of tests/learn/embedded_learned.rs:
# a small cart-pole model fitted by `vigp fit` on smooth synthetic
# trajectories (written here by Python's standard library), saved as JSON and
# exported by `vigp export` as Rust source. The test includes the source and
# checks it against the JSON loaded by the std runtime. The same for a model
# with inputs (learned_drive_cartpole.*, examples/learned_forced_fixture.rs),
# for a learned robot from URDF (learned_arm3.*),
# and for a 3-D mechanism (learned_furuta.*: the Furuta pendulum in its
# minimal coordinates, logged by `vigp simulate` with pivot friction).
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
# The 3-D model: two runs of `vigp simulate --system furuta` with friction
# on the pivot, fitted in minimal coordinates and exported.
for run in "r0 0.3,1.2 1.0,-2.0" "r1 -0.5,-0.8 -1.5,3.0"; do
    set -- $run
    cargo run --release --bin vigp -- simulate --system furuta --q "$2" --v "$3" --dt 0.01 \
        --steps 30 --run "$1" --out "$dir/furuta_$1.csv" --set joints.pivot.damping=0.002
done
{ cat "$dir/furuta_r0.csv"; tail -n +2 "$dir/furuta_r1.csv"; } > "$dir/learned_furuta_data.csv"
rm "$dir/furuta_r0.csv" "$dir/furuta_r1.csv"
cargo run --release --bin vigp -- fit --system furuta --data "$dir/learned_furuta_data.csv" \
    --out "$dir/learned_furuta.json" --max-samples 24 --restarts 0
cargo run --release --bin vigp -- export --model "$dir/learned_furuta.json" \
    --out "$dir/learned_furuta.rs"
# A learned robot (learned_arm3.*): the test arm of tests/fixtures/robots/arm3.urdf
# with its elbow j2 actuated, logged by `vigp simulate --urdf` from an arm
# with three times the elbow's damping, fitted over the declared arm with
# `vigp fit --urdf` and exported for `vigp::embedded::tree::LearnedTreeStepper`.
sed 's/damping="0.1"/damping="0.3"/' tests/fixtures/robots/arm3.urdf > "$dir/arm3_truth.urdf"
python3 - "$dir/arm3_plan.csv" <<'PY'
import math, sys
with open(sys.argv[1], "w") as f:
    f.write("u_j2\n")
    for k in range(40):
        f.write(f"{3.0 + 1.5 * math.sin(7.0 * k * 0.002)!r}\n")
PY
for run in "r0 0.1,-0.2,0.05" "r1 -0.2,0.3,0.0"; do
    set -- $run
    cargo run --release --bin vigp -- simulate --urdf "$dir/arm3_truth.urdf" --actuated j2 \
        --q "$2" --dt 0.002 --steps 40 --inputs "$dir/arm3_plan.csv" --run "$1" \
        --out "$dir/arm3_$1.csv"
done
{ cat "$dir/arm3_r0.csv"; tail -n +2 "$dir/arm3_r1.csv"; } > "$dir/learned_arm3_data.csv"
rm "$dir/arm3_r0.csv" "$dir/arm3_r1.csv" "$dir/arm3_plan.csv" "$dir/arm3_truth.urdf"
cargo run --release --bin vigp -- fit --urdf tests/fixtures/robots/arm3.urdf --actuated j2 \
    --data "$dir/learned_arm3_data.csv" --out "$dir/learned_arm3.json" --max-samples 40 \
    --restarts 0
cargo run --release --bin vigp -- export --model "$dir/learned_arm3.json" \
    --out "$dir/learned_arm3.rs" --name LEARNED_ARM
