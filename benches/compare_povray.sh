#!/usr/bin/env bash
# Scene benchmark beside POV-Ray 3.7, measured in the same run.
#   benches/compare_povray.sh [WIDTH HEIGHT] [scene ...]
# rothray: `rothray bench --json` (median of 7 renders after a warm-up; with and
# without shadow rays). POV-Ray: `+Q0 -A +WT2` (no shadows at +Q0), its reported
# Trace Time. Prints a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/.."
W=${1:-1920}; H=${2:-1080}
shift $(( $# >= 2 ? 2 : $# )) || true
SCENES=("$@")
[ ${#SCENES[@]} -eq 0 ] && SCENES=(logo cheese forest sampler sweep bunny)
command -v povray >/dev/null || { echo "povray missing: apt-get install povray" >&2; exit 1; }
cargo build --release -q
BIN=target/release/rothray
echo "| scene | rothray no shadows (s) | rothray with shadows (s) | POV-Ray +Q0 (s) | speed-up (no shadows) |"
echo "|---|---|---|---|---|"
for s in "${SCENES[@]}"; do
  f=scenes/$s.json
  ns=$($BIN bench "$f" --width "$W" --height "$H" --no-shadows --json | tail -1 | python3 -c "import json,sys; print(json.load(sys.stdin)['trace_s_median'])")
  ws=$($BIN bench "$f" --width "$W" --height "$H" --json | tail -1 | python3 -c "import json,sys; print(json.load(sys.stdin)['trace_s_median'])")
  pv=$(python3 tools/pov_compare.py "$f" --time-only --width "$W" --height "$H" 2>/dev/null | tail -1)
  python3 -c "print('| $s | %.4f | %.4f | %.3f | %.1fx |' % ($ns, $ws, $pv, $pv/$ns))"
done
