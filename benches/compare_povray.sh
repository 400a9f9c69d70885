#!/usr/bin/env bash
# The benchmark suite beside POV-Ray 3.7, measured in the same run.
#   benches/compare_povray.sh [WIDTH HEIGHT] [scene ...]
# Scenes: every benches/scenes/*.json by default; a name NAME means
# benches/scenes/NAME.json, anything ending in .json is taken as a path.
# Two modes (MODES, default "flat lit"):
#   flat: rothray `bench --no-shadows` against POV-Ray `+Q0 -A` (no lighting);
#   lit:  rothray `bench` (shadow rays on) against POV-Ray `+Q4 -A` with the
#         scene's lights as parallel light_sources that cast shadows
#         (tools/pov_compare.py --time-only --lit).
# rothray: the median of n renders after a warm-up, n = RB_SECONDS (default
# 4) over the time of one probe render, within [3, REPEATS] (REPEATS default
# 15; the first renders after a pause run slow on this shared machine, so
# fast scenes get many). POV-Ray: its reported Trace Time, +WT2.
# ROUNDS (default 3) rounds per scene alternate rothray and POV-Ray (which of
# the two goes first alternates too); the table gives per scene and mode the
# median times over the rounds, the median of the per-round speed-ups
# (POV-Ray time / rothray time) and the per-round speed-ups, then per mode
# the geometric mean and the minimum of the median speed-ups over the suite.
# This machine is shared: single runs move by up to 2x.
# BIN: RB_BIN if set (e.g. RB_BIN=/work/base/rothray), else
# target/release/rothray after `cargo build --release`.
# Prints a Markdown table on standard output, progress on standard error.
set -euo pipefail
cd "$(dirname "$0")/.."
W=${1:-1920}; H=${2:-1080}
if [ $# -ge 2 ]; then shift 2; elif [ $# -eq 1 ]; then shift 1; fi
ROUNDS=${ROUNDS:-3}
REPEATS=${REPEATS:-15}
RB_SECONDS=${RB_SECONDS:-4}
MODES=${MODES:-flat lit}
if ! command -v povray >/dev/null; then
  # As scripts/test.sh does: Debian's POV-Ray 3.7.
  echo "compare_povray.sh: installing povray (Debian package)" >&2
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq || true
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq povray >/dev/null || true
  command -v povray >/dev/null || { echo "povray missing and could not be installed: apt-get install povray" >&2; exit 1; }
fi
if [ -n "${RB_BIN:-}" ]; then
  BIN=$RB_BIN
else
  cargo build --release -q
  BIN=target/release/rothray
fi
SCENES=()
if [ $# -eq 0 ]; then
  for f in benches/scenes/*.json; do SCENES+=("$f"); done
else
  for s in "$@"; do
    case $s in *.json) SCENES+=("$s") ;; *) SCENES+=("benches/scenes/$s.json") ;; esac
  done
fi
for f in "${SCENES[@]}"; do [ -f "$f" ] || { echo "no such scene: $f" >&2; exit 2; }; done

RES=$(mktemp)
trap 'rm -f "$RES"' EXIT
med() { python3 -c "import json,sys; print(json.loads(sys.stdin.read().strip().splitlines()[-1])['trace_s_median'])"; }
rb() {  # rb SCENE MODE [REPEATS] -> seconds
  local extra=()
  [ "$2" = flat ] && extra=(--no-shadows)
  "$BIN" bench "$1" --width "$W" --height "$H" "${extra[@]}" --repeats "${3:-$REPEATS}" --json | med
}
pv() {  # pv SCENE MODE -> "seconds leaves"
  local extra=() out
  [ "$2" = lit ] && extra=(--lit)
  out=$(python3 tools/pov_compare.py "$1" --time-only "${extra[@]}" --width "$W" --height "$H" 2>&1) || { echo "$out" >&2; return 1; }
  echo "$(echo "$out" | tail -1) $(echo "$out" | sed -n 's/.* leaves=\([0-9]*\) .*/\1/p' | tail -1)"
}

echo "| scene | leaves | mode | rothray renders | rothray (s) | POV-Ray (s) | speed-up | per-round speed-ups |"
echo "|---|---|---|---|---|---|---|---|"
for f in "${SCENES[@]}"; do
  s=$(basename "$f" .json)
  for mode in $MODES; do
    rs=(); ps=(); leaves=?
    probe=$(rb "$f" "$mode" 1)
    n=$(python3 -c "import math,sys; print(max(3, min($REPEATS, math.ceil($RB_SECONDS / max($probe, 1e-6)))))")
    for r in $(seq "$ROUNDS"); do
      echo "$s $mode round $r/$ROUNDS" >&2
      if [ $((r % 2)) -eq 1 ]; then
        t=$(rb "$f" "$mode" "$n"); p=$(pv "$f" "$mode") || p="nan ?"
      else
        p=$(pv "$f" "$mode") || p="nan ?"; t=$(rb "$f" "$mode" "$n")
      fi
      rs+=("$t"); ps+=("${p%% *}"); leaves=${p##* }
    done
    python3 - "$s" "$leaves" "$mode" "${rs[*]}" "${ps[*]}" "$RES" "$n" <<'PY'
import math, statistics, sys
s, leaves, mode, rs, ps, res, n = sys.argv[1:]
rs = [float(x) for x in rs.split()]
ps = [float(x) for x in ps.split()]
m = statistics.median
r = [p / t for p, t in zip(ps, rs)]
sp = m(r)
print('| %s | %s | %s | %s | %.4f | %.3f | %.2fx | %s |' % (
    s, leaves, mode, n, m(rs), m(ps), sp, ' '.join('%.2f' % x for x in r)),
    flush=True)
with open(res, 'a') as f:
    f.write('%s %s %r\n' % (mode, s, sp))
PY
  done
done
python3 - "$RES" $MODES <<'PY'
import math, sys
rows = [l.split() for l in open(sys.argv[1])]
print()
print('| mode | scenes | geometric mean speed-up | minimum speed-up (scene) |')
print('|---|---|---|---|')
for mode in sys.argv[2:]:
    v = [(float(x), s) for m, s, x in rows if m == mode and math.isfinite(float(x))]
    if not v:
        continue
    g = math.exp(sum(math.log(x) for x, _ in v) / len(v))
    lo = min(v)
    print('| %s | %d | %.2fx | %.2fx (%s) |' % (mode, len(v), g, lo[0], lo[1]))
PY
