#!/usr/bin/env bash
# The balance of `render --tile I/N`: for each scene, the trace time of every
# part (`rothray bench --tile I/N`: process CPU time, the least of R runs after
# a warm-up, bake excluded, one thread: the least disturbed by other load on a
# shared machine; ROTHRAY_BALANCE_CLOCK=wall takes wall time instead)
# and the imbalance max/mean, for the interleaved split (the default) and
# contiguous bands. `whole_s` is the whole image's time the same way; the sum
# of the parts over it is the split's overhead.
#
#   scripts/split-balance.sh [N] [WIDTHxHEIGHT] [REPEATS] [SCENE.json...]
#   (defaults: 8, 1920x1080, 5, scenes/*.json; RAYON_NUM_THREADS overrides the 1)
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-8}
size=${2:-1920x1080}
reps=${3:-5}
export RAYON_NUM_THREADS=${RAYON_NUM_THREADS:-1}
key=trace_cpu_s_all
[ "${ROTHRAY_BALANCE_CLOCK:-cpu}" = wall ] && key=trace_s_all
shift $(($# < 3 ? $# : 3))
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(scenes/*.json)
bin=${CARGO_TARGET_DIR:-target}/release/rothray
cargo build --release -q
w=${size%x*}
h=${size#*x}
printf '%-12s %-12s %9s %9s %9s %9s %9s\n' scene split whole_s sum/whole mean_s max_s max/mean
for sc in "${scenes[@]}"; do
  whole=$("$bin" bench "$sc" --width "$w" --height "$h" --repeats "$reps" --json | tail -n 1 |
    python3 -c 'import json,sys; print(min(json.load(sys.stdin)[sys.argv[1]]))' "$key")
  for split in interleaved bands; do
    ts=()
    for ((i = 0; i < n; i++)); do
      ts+=("$("$bin" bench "$sc" --width "$w" --height "$h" --repeats "$reps" --json --tile "$i/$n" --split "$split" | tail -n 1 |
        python3 -c 'import json,sys; print(min(json.load(sys.stdin)[sys.argv[1]]))' "$key")")
    done
    python3 - "$(basename "$sc" .json)" "$split" "$whole" "${ts[@]}" <<'PY'
import sys
name, split, whole, *ts = sys.argv[1:]
ts = [float(t) for t in ts]
mean = sum(ts) / len(ts)
print(f"{name:<12} {split:<12} {float(whole):9.4f} {sum(ts) / float(whole):9.2f} {mean:9.4f} {max(ts):9.4f} {max(ts) / mean:9.2f}")
PY
  done
done
