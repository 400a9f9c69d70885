#!/usr/bin/env bash
# Wall time of N parts run one after another (`rothray render --tile I/N`,
# each a whole process: load, bake, trace, write the part) plus the merge,
# against one `rothray render`, for N = 1, 4, 16; the overhead per part is
# (parts + merge - render) / N. Best of R rounds (shared machines are noisy).
#
#   scripts/split-overhead.sh [WIDTHxHEIGHT] [ROUNDS] [SCENE.json...]
#   (defaults: 1920x1080, 3, scenes/sampler.json scenes/forest.json)
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-1920x1080}
rounds=${2:-3}
shift $(($# < 2 ? $# : 2))
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(scenes/sampler.json scenes/forest.json)
bin=${CARGO_TARGET_DIR:-target}/release/rothray
cargo build --release -q
w=${size%x*}
h=${size#*x}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
now() { date +%s.%N; }
best() { python3 -c 'import sys; print(min(float(x) for x in sys.argv[1:]))' "$@"; }
printf '%-10s %3s %10s %12s %14s\n' scene N render_s parts+merge_s overhead/part_s
for sc in "${scenes[@]}"; do
  name=$(basename "$sc" .json)
  rs=()
  for ((r = 0; r < rounds; r++)); do
    t0=$(now); "$bin" render "$sc" --width "$w" --height "$h" -o "$tmp/one.png" 2>/dev/null; t1=$(now)
    rs+=("$(python3 -c "print($t1 - $t0)")")
  done
  one=$(best "${rs[@]}")
  for n in 1 4 16; do
    ps=()
    for ((r = 0; r < rounds; r++)); do
      rm -f "$tmp"/p-*.part
      t0=$(now)
      for ((i = 0; i < n; i++)); do
        "$bin" render "$sc" --width "$w" --height "$h" --tile "$i/$n" -o "$tmp/p-$i.part" 2>/dev/null
      done
      "$bin" merge "$tmp"/p-*.part -o "$tmp/merged.png"
      t1=$(now)
      cmp -s "$tmp/one.png" "$tmp/merged.png" || { echo "merge differs for $sc N=$n" >&2; exit 1; }
      ps+=("$(python3 -c "print($t1 - $t0)")")
    done
    all=$(best "${ps[@]}")
    python3 -c "print(f'{\"$name\":<10} {$n:3d} {$one:10.3f} {$all:12.3f} {($all - $one) / $n:14.4f}')"
  done
done
