#!/usr/bin/env bash
# End-to-end check of `--shard i/N` and `merge` (docs/sharding.md): a small
# `paper` sweep (with every kind of unit: Fig. 1, runs, error bounds) and a
# small `scale_sweep`, each once unsharded and once as shards run side by
# side and merged; the merged report must equal the unsharded one byte for
# byte (`diff -r`; for the scale sweep every column but the measured
# training time `train_s`, and the figure). Exits non-zero on a difference.
#   bash scripts/shard_check.sh            # the small configurations below
#   bash scripts/shard_check.sh default    # also the paper's default (docs/paper/)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --example paper --example scale_sweep
paper=target/release/examples/paper
sweep=target/release/examples/scale_sweep
work=target/shard-check
rm -rf "$work"
mkdir -p "$work"

# paper: 2 systems × 3 runs, N = 2, 8, bounds on 6 trajectories
small=(--systems pendulum,fourbar --n 2,8 --runs 3 --train-trajectories 3
    --test-trajectories 2 --windows 2 --restarts 1 --bound-trajectories 6)
"$paper" "${small[@]}" --out "$work/paper-whole" > "$work/paper-whole.log"
# the shards with 1, 2, 3 and 1 worker threads: the results do not depend on it
for i in 0 1 2 3; do
    RAYON_NUM_THREADS=$((i % 3 + 1)) "$paper" "${small[@]}" --shard "$i/4" \
        --out "$work/paper-shards/shard-$i" > "$work/paper-shard-$i.log" &
done
wait
"$paper" merge "$work"/paper-shards/shard-* --out "$work/paper-merged" > "$work/paper-merge.log"
diff -r "$work/paper-whole" "$work/paper-merged"
echo "paper (small): 4 shards merged = unsharded ($(ls "$work/paper-whole" | wc -l) files)"

if [ "${1:-}" = default ]; then
    "$paper" --out "$work/default-whole" > "$work/default-whole.log"
    for i in 0 1 2 3; do
        "$paper" --shard "$i/4" --out "$work/default-shards/shard-$i" \
            > "$work/default-shard-$i.log" &
    done
    wait
    "$paper" merge "$work"/default-shards/shard-* --out "$work/default-merged" \
        > "$work/default-merge.log"
    diff -r "$work/default-whole" "$work/default-merged"
    diff -r docs/paper "$work/default-merged"
    echo "paper (default): 4 shards merged = unsharded = docs/paper/"
fi

# scale sweep: both systems, N = 16, 40 (exact), 80 (sparse, M = 24)
tiny=(--n 16,40,80 --exact-max 40 --sparse-m 24 --restarts 0 --test-trajectories 2
    --windows 3)
"$sweep" "${tiny[@]}" --out "$work/scale-whole" > "$work/scale-whole.log"
for i in 0 1; do
    "$sweep" "${tiny[@]}" --shard "$i/2" --out "$work/scale-shards/shard-$i" \
        > "$work/scale-shard-$i.log" &
done
wait
"$sweep" merge "$work"/scale-shards/shard-* --out "$work/scale-merged" > "$work/scale-merge.log"
cmp "$work/scale-whole/scale_sweep.svg" "$work/scale-merged/scale_sweep.svg"
without_time() { cut -d, -f1-5,7 "$1"; }
diff <(without_time "$work/scale-whole/scale_sweep.csv") \
    <(without_time "$work/scale-merged/scale_sweep.csv")
echo "scale_sweep: 2 shards merged = unsharded (figure; CSV but train_s)"
