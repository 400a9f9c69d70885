#!/bin/bash
# Two rothray binaries on every suite scene, flat and lit, in rounds that
# alternate their order (ABBA: the one run second read 1-3% slow on a
# shared machine): per scene the median trace times and B/A, then the
# geometric mean of B/A per mode.
#   benches/ab_suite.sh A_BINARY B_BINARY [ROUNDS] [W H]
# Defaults: 2 rounds, 1920x1080, rayon's threads (RAYON_NUM_THREADS to set).
set -euo pipefail
cd "$(dirname "$0")/.."
A=$1; B=$2; R=${3:-2}; W=${4:-1920}; H=${5:-1080}
for f in benches/scenes/*.json; do
  s=$(basename "$f" .json)
  for mode in flat lit; do
    extra=(); [ "$mode" = flat ] && extra=(--no-shadows)
    rep=5; [ "$s" = nesting ] && rep=1
    for i in $(seq "$R"); do
      if [ $((i % 2)) -eq 1 ]; then order="A B"; else order="B A"; fi
      for x in $order; do
        bin=${!x}
        t=$("$bin" bench "$f" --width "$W" --height "$H" --repeats "$rep" "${extra[@]}" --json | tail -1 |
          python3 -c "import json,sys; print(json.load(sys.stdin)['trace_s_median'])")
        echo "$s $mode $x $t"
      done
    done
  done
done | python3 -c '
import math, statistics, sys
d = {}
for l in sys.stdin:
    s, m, x, t = l.split()
    d.setdefault((s, m), {}).setdefault(x, []).append(float(t))
g = {"flat": [], "lit": []}
for (s, m), v in sorted(d.items()):
    a, b = statistics.median(v["A"]), statistics.median(v["B"])
    g[m].append(b / a)
    print("%-15s %-4s A %.4f B %.4f  B/A %.3f" % (s, m, a, b, b / a))
for m, r in g.items():
    print(m, "geometric mean B/A %.4f" % math.exp(sum(map(math.log, r)) / len(r)))
'
