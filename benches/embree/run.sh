#!/bin/sh
# End to end: Embree check/compile, then the Rust harness (which writes the mesh
# and rays, runs the Embree program and traces the same rays with rothray).
# usage: benches/embree/run.sh   (env: RB_THREADS=2 RB_REPEATS=7 RB_SUBDIV=4 RB_RANDOM=1000000)
set -eu
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
export RB_DIR=${RB_DIR:-$TARGET/embree-bench}
mkdir -p "$RB_DIR"
if [ ! -f /usr/include/embree3/rtcore.h ]; then
    echo "Embree 3 headers missing: install them with" >&2
    echo "  apt-get update && apt-get install -y libembree-dev" >&2
    exit 1
fi
gcc -O2 -Wall -o "$RB_DIR/embree_bench" "$ROOT/benches/embree/embree_bench.c" -lembree3 -lpthread -lm
export RB_EMBREE="$RB_DIR/embree_bench"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg)"
cd "$ROOT"
cargo bench --bench mesh_vs_embree
echo "summary: $RB_DIR/summary.txt"
