#!/bin/sh
# Run time against error of every approximation (README, "Run time against
# error"): one `rothray bench --knob` curve per knob, plots in docs/knobs/,
# each curve's JSON row list in docs/knobs/K.json.
set -e
cd "$(dirname "$0")/.."
B=${ROTHRAY:-target/release/rothray}
W="--width 480 --height 270 --repeats 5"
run() { # knob scene [extra flags]
    k=$1; scene=$2; shift 2
    $B bench "$scene" --knob "$k" "$@" --plot "docs/knobs/$k.svg" --json | tee /dev/stderr | tail -n 1 > "docs/knobs/$k.json"
}
run sweep scenes/sweep.json $W
run gcyl scenes/knob_gcyl.json $W
run frame scenes/knob_gcyl.json $W
run torus benches/scenes/tori.json $W
run winding scenes/knob_winding.json --tolerances 1,1.5,2,3,4,6 --width 960 --height 540 --repeats 3
run fuse scenes/coincident.json $W
