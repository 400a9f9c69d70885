#!/usr/bin/env python3
"""Where a frame's instructions go, per scene of the benchmark suite.

Runs `rothray bench` under callgrind (one thread, 480x270, shadows on unless
--flat), counting only what `render_tile` runs (tile preparation, camera
rays, shadow rays, shading: not loading or baking), and sums each function's
own instructions into a few parts of the trace path:

  tiles      preparing tiles: specialised programs, frusta, tile lists
  kernels    leaf kernels: the packet and scalar solves, the torus's
             quartic, sweeps, generalized cylinders, mesh triangle walks
  walks      wide nodes' and objects' trees walked (box tests, candidate
             lists: per packet in wide unions, per ray elsewhere)
  merge      span lists merged by Table 1 (`combine`), one ray at a time
  lanes      the rest of the per-lane evaluation: object loops, the
             program's frames, packet memo look-ups, visits in canonical
             order (the work a packet-major evaluator would share)
  hits       camera rays, normals, shading, pixel encoding
  other      the rest (allocation, copies)

Usage: scripts/where-time-goes.py BIN [--flat] [SCENE ...]
(default: every scene in benches/scenes). Needs valgrind.
"""

import os
import re
import subprocess
import sys
import tempfile

PARTS = [
    ("tiles", r"rothray_csg::tile|tile_list|prepare_tile|frustum|ray_plane|RayPlane|cull_region|follow::|Follower|TileProgram|TileScratch|BoxList::push"),
    ("kernels", r"kernels8|kernels::|quartic|poly::|table64|ranges8|torus|sweep|gcyl|Gcyl|mesh|Mesh|LeafTable::spans|spans_for|spans_in|cuboid|Marks|RunEnd|cbrt|libm|sincos|acos"),
    ("walks", r"box_wide|BoxWide|LaneWalks::visit|UnionRecords::walk|Program::collect|union_cands|FlatBvh|bvh::|CwBvh|traverse|visit_nearest"),
    ("merge", r"rothray_csg::spans::|SpanList|combine|spans8"),
    ("lanes", r"rothray_csg::program|union_packet|leaf_packet|PacketMemo|scene::RenderScene|packet::<impl|ready_memo|Wrapped<T,A,F>|call_once|first_surface"),
    ("hits", r"normal|render_tile|shade|encode|CameraRays|render::"),
]


def parts_of(cg_out):
    ann = subprocess.run(["callgrind_annotate", "--auto=no", "--threshold=100", cg_out], capture_output=True, text=True).stdout
    sums = {name: 0 for name, _ in PARTS}
    sums["other"] = 0
    for line in ann.splitlines():
        m = re.match(r"^\s*([0-9,]+) \([^)]*\)\s+(.*)$", line)
        if not m or "PROGRAM TOTALS" in line:
            continue
        v = int(m.group(1).replace(",", ""))
        fn = m.group(2).split(":", 1)[-1]
        for name, pat in PARTS:
            if re.search(pat, fn):
                sums[name] += v
                break
        else:
            sums["other"] += v
    return sums


def main():
    args = sys.argv[1:]
    if not args:
        print(__doc__)
        sys.exit(2)
    binary, rest = args[0], args[1:]
    flat = "--flat" in rest
    scenes = [s for s in rest if s != "--flat"]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    sdir = os.path.join(root, "benches", "scenes")
    if not scenes:
        scenes = sorted(f[:-5] for f in os.listdir(sdir) if f.endswith(".json"))
    names = [n for n, _ in PARTS] + ["other"]
    print("| scene | instructions per camera ray | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    for s in scenes:
        with tempfile.NamedTemporaryFile(prefix="wtg.", delete=False) as f:
            out = f.name
        cmd = ["valgrind", "--tool=callgrind", "--toggle-collect=*render_tile*", f"--callgrind-out-file={out}", binary, "bench",
               os.path.join(sdir, s + ".json"), "--repeats", "1", "--width", "480", "--height", "270"]
        if flat:
            cmd.append("--no-shadows")
        subprocess.run(cmd, env=env, capture_output=True, check=True)
        sums = parts_of(out)
        os.unlink(out)
        total = sum(sums.values())
        # Warm-up plus one render: two frames of 480x270 camera rays.
        per_ray = total / (2 * 480 * 270)
        cells = " | ".join(f"{100 * sums[n] / total:.0f}%" for n in names)
        print(f"| {s} | {per_ray:.0f} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
