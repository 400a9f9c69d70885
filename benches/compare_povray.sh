#!/usr/bin/env bash
# Scene benchmark beside POV-Ray 3.7, measured in the same run.
#   benches/compare_povray.sh [WIDTH HEIGHT] [scene ...]
# rothray: `rothray bench --json --repeats 15` (median of 15 renders after a
# warm-up, about as long as one POV-Ray trace; with and without shadow rays). POV-Ray: `+Q0 -A +WT2` (no shadows at +Q0), its reported
# Trace Time. ROUNDS (default 3) rounds alternate the two on each scene; the
# table gives the medians over the rounds, their ratio, and the range of the
# per-round ratios (this machine is shared: single runs move by up to 2x).
# Prints a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/.."
W=${1:-1920}; H=${2:-1080}
shift $(( $# >= 2 ? 2 : $# )) || true
SCENES=("$@")
ROUNDS=${ROUNDS:-3}
[ ${#SCENES[@]} -eq 0 ] && SCENES=(logo cheese forest sampler sweep bunny)
command -v povray >/dev/null || { echo "povray missing: apt-get install povray" >&2; exit 1; }
cargo build --release -q
BIN=target/release/rothray
med() { python3 -c "import json,sys; print(json.load(sys.stdin)['trace_s_median'])"; }
echo "| scene | rothray no shadows (s) | rothray with shadows (s) | POV-Ray +Q0 (s) | speed-up (no shadows) | per-round speed-ups |"
echo "|---|---|---|---|---|---|"
for s in "${SCENES[@]}"; do
  f=scenes/$s.json
  ns=(); ws=(); pv=()
  for _ in $(seq "$ROUNDS"); do
    ns+=("$($BIN bench "$f" --width "$W" --height "$H" --no-shadows --repeats 15 --json | tail -1 | med)")
    ws+=("$($BIN bench "$f" --width "$W" --height "$H" --repeats 15 --json | tail -1 | med)")
    pv+=("$(python3 tools/pov_compare.py "$f" --time-only --width "$W" --height "$H" 2>/dev/null | tail -1)")
  done
  python3 - "$s" "${ns[*]}" "${ws[*]}" "${pv[*]}" <<'PY'
import statistics, sys
s, ns, ws, pv = sys.argv[1], *[[float(x) for x in a.split()] for a in sys.argv[2:]]
m = statistics.median
r = sorted(p / n for p, n in zip(pv, ns))
print('| %s | %.4f | %.4f | %.3f | %.1fx | %s |' % (s, m(ns), m(ws), m(pv), m(pv) / m(ns), ' '.join('%.1f' % x for x in r)))
PY
done
