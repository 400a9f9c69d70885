#!/usr/bin/env python3
"""Generates the benchmark scenes of benches/scenes/ that are not copies of
the examples in scenes/ (logo, cheese, forest, sampler, sweep, bunny).

    python3 benches/scenes/gen.py            # rewrites every generated scene
    python3 benches/scenes/gen.py gear tori  # only these

Deterministic (one seeded random.Random per scene), standard library only.
Every scene has a 1920x1080 camera that frames it and one directional light,
so `benches/compare_povray.sh` can run it flat and lit. Files the scenes read
(bunny.obj, knob.obj) lie in this folder: a scene may only read files inside
its own folder. knob.obj is written here too.
"""
import json
import math
import os
import random
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
LIGHT = [{"direction": [-1, -2, -1.5], "color": [1, 1, 1]}]


# ------------------------------------------------------------------ helpers
def r6(x):
    return round(x, 6)


def v3(v):
    return [r6(c) for c in v]


def sphere(c, r, **kw):
    return dict(sphere={"center": v3(c), "radius": r6(r)}, **kw)


def box(lo, hi, **kw):
    return dict(box={"min": v3(lo), "max": v3(hi)}, **kw)


def cyl(a, b, r, **kw):
    return dict(cylinder={"a": v3(a), "b": v3(b), "radius": r6(r)}, **kw)


def cone(a, b, ra, rb, **kw):
    return dict(cone={"a": v3(a), "b": v3(b), "radius_a": r6(ra),
                      "radius_b": r6(rb)}, **kw)


def torus(c, axis, major, minor, **kw):
    return dict(torus={"center": v3(c), "axis": v3(axis), "major": r6(major),
                       "minor": r6(minor)}, **kw)


def plane(n, off, **kw):
    return dict(plane={"normal": v3(n), "offset": r6(off)}, **kw)


def mesh(path, **kw):
    return dict(mesh={"path": path}, **kw)


def sweep(pts, **kw):
    return dict(swept_sphere={"bezier": [[r6(c) for c in p] for p in pts]},
                **kw)


def U(*c, **kw):
    return dict(union=list(c), **kw)


def I(*c, **kw):
    return dict(intersection=list(c), **kw)


def D(*c, **kw):
    return dict(difference=list(c), **kw)


def X(shape, translate=None, rotate=None, scale=None, **kw):
    t = {"shape": shape}
    if translate is not None:
        t["translate"] = v3(translate)
    if rotate is not None:
        t["rotate_deg"] = v3(rotate)
    if scale is not None:
        t["scale"] = v3(scale) if isinstance(scale, (list, tuple)) else r6(scale)
    return dict(transformed=t, **kw)


def obj(name, shape, color):
    return {"name": name, "color": v3(color), "shape": shape}


def scene(name, eye, target, fov, objects, lights=LIGHT, background=(0, 0, 0)):
    return {"name": name,
            "camera": {"eye": v3(eye), "target": v3(target), "up": [0, 1, 0],
                       "fov_y_deg": fov},
            "image": {"width": 1920, "height": 1080},
            "background": list(background),
            "lights": lights,
            "objects": objects}


def leaves(node):
    k = [k for k in node if k not in ("name", "color")][0]
    v = node[k]
    if k in ("union", "intersection", "difference"):
        return sum(leaves(c) for c in v)
    if k == "transformed":
        return leaves(v["shape"])
    return 1


def depth(node):
    k = [k for k in node if k not in ("name", "color")][0]
    v = node[k]
    if k in ("union", "intersection", "difference"):
        return 1 + max(depth(c) for c in v)
    if k == "transformed":
        return 1 + depth(v["shape"])
    return 0


def norm(a):
    l = math.sqrt(sum(x * x for x in a))
    return [x / l for x in a]


def rot(v, ax, ay, az):
    """M = Rz * Ry * Rx (degrees), as the scene format's rotate_deg."""
    x, y, z = v
    a = math.radians(ax)
    y, z = y * math.cos(a) - z * math.sin(a), y * math.sin(a) + z * math.cos(a)
    a = math.radians(ay)
    x, z = x * math.cos(a) + z * math.sin(a), -x * math.sin(a) + z * math.cos(a)
    a = math.radians(az)
    x, y = x * math.cos(a) - y * math.sin(a), x * math.sin(a) + y * math.cos(a)
    return [x, y, z]


def hsv(h, s=0.6, v=0.9):
    i = int(h * 6) % 6
    f = h * 6 - int(h * 6)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    return [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v),
            (v, p, q)][i]


# ------------------------------------------------------------------ scenes
def polytopes():
    """Eight convex polytopes, each an intersection of 6 to 12 half-spaces
    (cube, octahedron, dodecahedron, prisms, chamfered and random-cut
    cubes), three of them minus a torus."""
    rng = random.Random(11)
    phi = (1 + 5 ** 0.5) / 2
    cube = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1],
            [0, 0, -1]]
    octa = [[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]
    dode = []
    for s1 in (1, -1):
        for s2 in (1, -1):
            dode += [[0, s1, s2 * phi], [s1, s2 * phi, 0], [s2 * phi, 0, s1]]
    hexp = [[math.cos(math.radians(60 * i)), 0, math.sin(math.radians(60 * i))]
            for i in range(6)] + [[0, 1, 0], [0, -1, 0]]
    octp = [[math.cos(math.radians(45 * i + 22.5)), 0,
             math.sin(math.radians(45 * i + 22.5))] for i in range(8)] + \
        [[0, 1, 0], [0, -1, 0]]
    chamf = cube + [[sx, 1, sz] for sx in (1, -1) for sz in (1, -1)]
    rcut = cube + [[rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)]
                   for _ in range(6)]
    tri = [[math.cos(math.radians(120 * i)), 0, math.sin(math.radians(120 * i))]
           for i in range(3)] + [[0, 1, 0], [0, -1, 0], [0.3, 1, 0.2]]
    kinds = [("cube", cube, 0.85, True), ("octahedron", octa, 0.95, False),
             ("dodecahedron", dode, 0.85, True), ("hexprism", hexp, 0.8, False),
             ("octprism", octp, 0.8, True), ("chamfered", chamf, 0.8, False),
             ("randomcut", rcut, 0.8, False), ("triprism", tri, 0.55, False)]
    objs = []
    for i, (nm, normals, r, cut) in enumerate(kinds):
        c = [-3.3 + 2.2 * (i % 4), 1.15 if i < 4 else -1.15, 0]
        ang = [rng.uniform(-40, 40), rng.uniform(-60, 60), rng.uniform(-30, 30)]
        hs = []
        for n in normals:
            n = norm(rot(norm(n), *ang))
            rr = r if nm != "randomcut" or len(hs) < 6 else r * 0.8
            hs.append(plane(n, sum(a * b for a, b in zip(n, c)) + rr))
        shape = I(*hs)
        if cut:
            ax = norm([rng.uniform(-1, 1), 1, rng.uniform(-1, 1)])
            shape = D(shape, torus(c, ax, 0.9 * r, 0.3 * r,
                                   color=[0.95, 0.85, 0.3]))
        objs.append(obj(nm, shape, hsv(i / 8)))
    return scene("polytopes", [0, 1.2, 9], [0, 0, 0], 40, objs)


def nesting():
    """32 concentric spherical shells, nested 64 nodes deep: level k is
    (shell_k union level k+1) minus a box wedge turned 4 degrees further
    than the one above it, so the cut-away wedge winds down like a stair.
    (40 levels took 9.5 s a frame in rothray and 80 s in POV-Ray at
    1920x1080 on this machine: every ray that enters sees every shell.)"""
    return onion("nesting", 32, (0.056, 0.03), (4, 0.015))


def onion(name, n, shells, wedges):
    """`n` nested levels as scenes/nesting has them: shell k of radius
    2 - k d and thickness w (`shells` = (d, w)), its wedge turned a degrees
    a level, its floor raised h a level (`wedges` = (a, h))."""
    (d, w), (a, h) = shells, wedges
    node = sphere([0, 0, 0], 0.2, color=[1, 0.9, 0.3])
    for k in reversed(range(n)):
        r = 2.0 - k * d
        shell = D(sphere([0, 0, 0], r), sphere([0, 0, 0], r - w))
        wedge = X(box([0, -0.5 + h * k, 0], [3, 3, 3]),
                  rotate=[0, -a * k, 0], color=[0.3, 0.6, 0.9])
        node = D(U(shell, node), wedge, color=hsv(k / n, 0.5, 0.95))
    return scene(name, [3.6, 2.8, 4.4], [0, -0.1, 0], 42,
                 [obj("onion", node, [0.8, 0.8, 0.8])])


def capsules():
    """300 separate objects, each a capsule (cylinder and two spheres) under
    a random rotation and non-uniform scale, filling the view."""
    return capsule_field("capsules", 300, 300, 1.0)


def capsule_field(name, n, seed, s):
    """`n` capsules (cylinder and two spheres) as objects, each under a
    random rotation and non-uniform scale (times `s`), in capsules' volume."""
    rng = random.Random(seed)
    objs = []
    for i in range(n):
        h, r = 0.28, 0.12
        cap = U(cyl([0, -h, 0], [0, h, 0], r), sphere([0, -h, 0], r),
                sphere([0, h, 0], r))
        t = X(cap, translate=[rng.uniform(-6, 6), rng.uniform(-3.3, 3.3),
                              rng.uniform(-3, 1.5)],
              rotate=[rng.uniform(0, 360), rng.uniform(0, 360),
                      rng.uniform(0, 360)],
              scale=[s * rng.uniform(0.6, 1.6), s * rng.uniform(0.6, 1.6),
                     s * rng.uniform(0.6, 1.6)])
        objs.append(obj("capsule%d" % i, t, hsv(rng.random(), 0.55, 0.9)))
    return scene(name, [0, 0, 10], [0, 0, -1], 40, objs)


def gear_shape(c, R, n, w, phase, rng):
    disc = U(cyl([0, 0, -w], [0, 0, w], R),
             cyl([0, 0, -1.8 * w], [0, 0, 1.8 * w], 0.42 * R,
                 color=[0.75, 0.75, 0.8]))
    tw = math.pi * R / n * 0.5
    teeth = [X(box([R - 0.22, -tw, -3 * w], [R + 1, tw, 3 * w]),
               rotate=[0, 0, phase + 360.0 * i / n]) for i in range(n)]
    holes = [cyl([0, 0, -3 * w], [0, 0, 3 * w], 0.16 * R)]
    m = 5 if n >= 16 else 4
    for j in range(m):
        a = math.radians(phase + 360.0 * (j + 0.5) / m)
        holes.append(cyl([0.64 * R * math.cos(a), 0.64 * R * math.sin(a),
                          -3 * w], [0.64 * R * math.cos(a),
                                    0.64 * R * math.sin(a), 3 * w],
                         0.15 * R))
    g = D(disc, *teeth, *holes, color=[0.9, 0.4, 0.3])
    return X(g, translate=c, rotate=[rng.uniform(-12, 12),
                                     rng.uniform(-25, 25), 0])


def gear():
    """Three gears: a disc (with hub) minus 12, 16 and 24 rotated box teeth
    and lightening holes."""
    rng = random.Random(12)
    objs = [obj("gear24", gear_shape([-2.7, 0.3, 0], 1.75, 24, 0.2, 0, rng),
                [0.8, 0.7, 0.3]),
            obj("gear16", gear_shape([0.45, -0.55, 0.2], 1.4, 16, 0.22, 7, rng),
                [0.5, 0.7, 0.9]),
            obj("gear12", gear_shape([3.35, 0.9, -0.2], 1.2, 12, 0.25, 3, rng),
                [0.6, 0.85, 0.5])]
    return scene("gear", [0.8, 2.0, 8.5], [0.2, 0.1, 0], 40, objs)


def tori():
    """A chain of 7 interlocking tori on tilted axes, and below it tori
    intersected with a box and a sphere, minus a torus and minus spheres."""
    objs = []
    for i in range(7):
        ax = [0, 0.25, 1] if i % 2 == 0 else [0.1, 1, -0.2]
        objs.append(obj("link%d" % i, torus([-3.45 + 1.15 * i, 1.2, 0], ax,
                                            0.8, 0.15), hsv(i / 7)))
    y = -1.1
    objs.append(obj("half", I(torus([-3.6, y, 0], [0.3, 1, 0.4], 0.9, 0.3),
                              box([-5, y - 0.2, -2], [-2, y + 2, 2],
                                  color=[0.9, 0.9, 0.5])), [0.9, 0.4, 0.4]))
    objs.append(obj("grooved", D(torus([-1.2, y, 0], [0, 0.6, 1], 0.9, 0.32),
                                 torus([-1.2, y, 0], [1, 0.2, 0], 0.9, 0.18,
                                       color=[0.3, 0.9, 0.9])),
                    [0.4, 0.9, 0.4]))
    beads = [sphere([1.2 + 0.9 * math.cos(a), y + 0.9 * math.sin(a) * 0.8,
                     0.9 * math.sin(a) * 0.6], 0.28, color=[0.9, 0.5, 0.9])
             for a in (2 * math.pi * j / 8 for j in range(8))]
    objs.append(obj("bitten", D(torus([1.2, y, 0], [0, -0.6, 0.8], 0.9, 0.3),
                                *beads), [0.4, 0.5, 0.95]))
    objs.append(obj("lens", I(torus([3.6, y, 0], [0.5, 1, 0.3], 0.85, 0.4),
                              sphere([3.6, y + 0.3, 0.3], 1.0,
                                     color=[0.95, 0.7, 0.3])),
                    [0.95, 0.95, 0.95]))
    return scene("tori", [0, 1.0, 9], [0, 0, 0], 40, objs)


def fill():
    """Most pixels hit: the camera is close to a large slab (minus 160
    sphere dimples and 24 through-holes) in front of a back plate, both
    larger than the view."""
    rng = random.Random(160)
    dimples = []
    for j in range(10):
        for i in range(16):
            dimples.append(sphere([-7.5 + i + rng.uniform(-0.2, 0.2),
                                   -4.5 + j + rng.uniform(-0.2, 0.2),
                                   0.5 + rng.uniform(0.05, 0.2)],
                                  rng.uniform(0.28, 0.42),
                                  color=[0.9, 0.6, 0.3]))
    holes = []
    for j in range(4):
        for i in range(6):
            x, y = -5 + 2 * i, -3 + 2 * j
            holes.append(cyl([x, y, -1], [x, y, 1], 0.22,
                             color=[0.3, 0.6, 0.9]))
    slab = D(box([-8, -5, -0.5], [8, 5, 0.5]), *dimples, *holes)
    back = box([-12, -8, -3.2], [12, 8, -2.8])
    return scene("fill", [1.5, 1.0, 4.5], [0, 0, 0], 60,
                 [obj("slab", slab, [0.85, 0.85, 0.8]),
                  obj("back", back, [0.4, 0.4, 0.5])])


def ground():
    """An infinite ground plane (a half-space) under seven CSG objects that
    cast shadows on it."""
    objs = [obj("ground", plane([0, 1, 0], 0), [0.55, 0.6, 0.5])]
    objs.append(obj("logo", X(D(I(box([-1, -1, -1], [1, 1, 1]),
                                   sphere([0, 0, 0], 1.35)),
                                 U(cyl([-2, 0, 0], [2, 0, 0], 0.6),
                                   cyl([0, -2, 0], [0, 2, 0], 0.6),
                                   cyl([0, 0, -2], [0, 0, 2], 0.6),
                                   color=[0.3, 0.5, 0.9])),
                              translate=[0, 0.75, 0], scale=0.75,
                              rotate=[0, 30, 0]), [1, 0.5, 0.2]))
    objs.append(obj("pierced", D(cone([-2.6, 0, 0.5], [-2.6, 1.8, 0.5], 0.9,
                                      0.15),
                                 cyl([-4, 0.6, 0.5], [-1, 0.6, 0.5], 0.25)),
                    [0.3, 0.9, 0.3]))
    objs.append(obj("ball", D(sphere([2.4, 0.7, 0.8], 0.7),
                              sphere([2.0, 1.0, 1.3], 0.45)), [0.9, 0.3, 0.3]))
    objs.append(obj("arch", D(box([-1.2, 0, -2.8], [1.2, 1.6, -2.2]),
                              cyl([0, 0, -3], [0, 0, -2], 0.7)),
                    [0.8, 0.8, 0.6]))
    objs.append(obj("ring", I(torus([3.8, 0.9, -1.5], [1, 0, 0.3], 0.7, 0.2),
                              plane([0, -1, 0], -0.05)), [0.6, 0.4, 0.9]))
    objs.append(obj("pillar", U(cyl([-4.5, 0, -2], [-4.5, 2.4, -2], 0.3),
                                sphere([-4.5, 2.4, -2], 0.45)),
                    [0.9, 0.9, 0.9]))
    objs.append(obj("slab", X(D(box([-0.6, 0, -0.4], [0.6, 0.3, 0.4]),
                                sphere([0, 0.35, 0], 0.3)),
                              translate=[1.0, 0, 2.3], rotate=[0, 25, 0]),
                    [0.3, 0.8, 0.8]))
    lights = [{"direction": [-0.7, -1.6, -0.9], "color": [1, 1, 1]}]
    return scene("ground", [0.5, 2.6, 8], [0, 0.6, 0], 45, objs, lights,
                 background=(0.5, 0.65, 0.9))


BUNNY = 0.15      # bunny.obj is 10 units wide; this makes it 1.5


def mesh_cut():
    """Meshes cut by analytic solids: the bunny drilled by three cylinders,
    sliced by a box and a half-space, bitten by spheres; a lumpy mesh minus a
    box corner."""
    b = X(mesh("bunny.obj"), scale=BUNNY)
    hole = [0.3, 0.6, 0.9]
    drilled = X(D(b, cyl([-1, 0.5, 0], [1, 0.5, 0], 0.16, color=hole),
                  cyl([0.15, -0.5, -0.3], [0.15, 2, 0.1], 0.12, color=hole),
                  cyl([-0.2, 0.8, -1], [-0.2, 0.8, 1], 0.14, color=hole)),
                translate=[-2.1, 0, 0],
                rotate=[0, 20, 0])
    sliced = X(I(b, box([-0.55, -0.1, -0.6], [0.6, 1.6, 0.6],
                        color=[0.9, 0.8, 0.3]),
                 plane([0.3, 1, 0.2], 0.85, color=[0.4, 0.9, 0.6])),
               translate=[0, 0, 0], rotate=[0, -25, 0])
    rng = random.Random(3)
    bites = [sphere([rng.uniform(-0.6, 0.6), rng.uniform(0.2, 1.3),
                     rng.uniform(0.1, 0.6)], rng.uniform(0.1, 0.2),
                    color=[0.9, 0.3, 0.3]) for _ in range(8)]
    bitten = X(D(b, *bites), translate=[2.1, 0, 0], rotate=[0, -40, 0])
    knob = D(X(mesh("knob.obj"), translate=[0, 2.05, -1.5], scale=0.65),
             box([0, 2.05, -1.5], [2, 4, 0.5], color=[0.3, 0.9, 0.5]))
    return scene("mesh_cut", [0, 1.6, 6.2], [0, 0.9, 0], 40,
                 [obj("drilled", drilled, [0.85, 0.8, 0.7]),
                  obj("sliced", sliced, [0.85, 0.8, 0.7]),
                  obj("bitten", bitten, [0.85, 0.8, 0.7]),
                  obj("knob", knob, [0.8, 0.5, 0.9])])


def mesh_mold():
    """Analytic solids cut by meshes: a block minus a bunny (a mould), a
    sphere minus the lumpy mesh, a cylinder intersected with a bunny, and a
    slab minus a row of small bunnies."""
    b = mesh("bunny.obj")
    mold = D(box([-3.4, 0, -0.8], [-1.2, 1.4, 0.6]),
             X(b, translate=[-2.3, 0.25, 0.35], scale=BUNNY * 0.9,
               rotate=[0, 15, 0], color=[0.9, 0.8, 0.4]))
    holed = D(sphere([0, 0.8, 0], 0.85),
              X(mesh("knob.obj"), translate=[0.35, 1.05, 0.6], scale=0.6,
                color=[0.3, 0.8, 0.9]))
    core = I(cyl([2.3, -0.1, 0], [2.3, 1.7, 0], 0.55),
             X(b, translate=[2.3, 0, 0], scale=BUNNY * 1.1, rotate=[0, -30, 0],
               color=[0.95, 0.6, 0.3]))
    small = [X(b, translate=[-2.4 + 1.2 * i, -0.6, 1.4], scale=BUNNY * 0.5,
               rotate=[0, 40 * i, 0], color=[0.9, 0.4, 0.5])
             for i in range(5)]
    slab = D(box([-3.2, -0.8, 0.9], [3.2, -0.2, 1.9]), *small)
    return scene("mesh_mold", [0, 2.0, 6.5], [0, 0.4, 0], 40,
                 [obj("mould", mold, [0.7, 0.75, 0.8]),
                  obj("holed", holed, [0.9, 0.4, 0.4]),
                  obj("core", core, [0.5, 0.8, 0.5]),
                  obj("slab", slab, [0.8, 0.8, 0.6])])


def bez(p0, p1, p2, p3, r0, r1):
    """One cubic segment with radius linear from r0 to r1."""
    pts = [p0, p1, p2, p3]
    return [list(p) + [r0 + (r1 - r0) * k / 3] for k, p in enumerate(pts)]


def sweep_csg():
    """Swept spheres inside CSG: a block with a winding groove, a sphere
    intersected with a tube, a tube minus beads, two crossing tubes minus a
    box, and a sweep intersected with a half-space."""
    g = bez([-1.2, 0.75, -0.9], [-0.2, 0.75, -1.4], [0.2, 0.75, 1.4],
            [1.2, 0.75, 0.9], 0.25, 0.25)
    g += bez([1.2, 0.75, 0.9], [1.6, 0.75, 0.7], [1.6, 0.75, -0.2],
             [1.3, 0.75, -0.7], 0.25, 0.15)[1:]
    groove = X(D(box([-1.4, -0.5, -1.2], [1.4, 0.6, 1.2]),
                 sweep(g, color=[0.3, 0.6, 0.9])),
               translate=[-2.6, 0.2, -0.5], rotate=[0, 20, 0])
    t = bez([-1, -1, 0.2], [-0.3, 1.6, 0.5], [0.3, -1.6, -0.5], [1, 1, -0.2],
            0.35, 0.35)
    ball = I(sphere([0, 0, 0], 1.0, color=[0.9, 0.8, 0.3]), sweep(t))
    ball = X(ball, translate=[0.2, 1.4, -0.3])
    tt = bez([-1.3, 0, 0], [-0.5, 1, 0.6], [0.5, -1, -0.6], [1.3, 0, 0],
             0.3, 0.22)
    beads = [sphere([-1.1 + 0.55 * j, 0.35 * math.sin(2 * j), 0.45], 0.22,
                    color=[0.9, 0.3, 0.5]) for j in range(5)]
    beaded = X(D(sweep(tt), *beads), translate=[0.3, -1.2, 0.4])
    a = bez([-1, -0.8, 0], [-0.3, 0.8, 0.6], [0.3, 0.8, -0.6], [1, -0.8, 0],
            0.22, 0.3)
    bb = bez([0, -0.8, -1], [0.6, 0.8, -0.3], [-0.6, 0.8, 0.3], [0, -0.8, 1],
             0.3, 0.22)
    cross = X(D(U(sweep(a), sweep(bb, color=[0.5, 0.9, 0.5])),
                box([-2, -2, 0.2], [2, 2, 2], color=[0.95, 0.95, 0.6])),
              translate=[2.9, 0.6, -0.3], rotate=[0, -35, 0])
    h = bez([-0.8, -1.4, 0], [1.5, -0.6, 0.4], [-1.5, 0.6, -0.4],
            [0.8, 1.4, 0], 0.28, 0.4)
    cut = I(sweep(h), plane([0.4, -0.3, 1], 0.15, color=[0.6, 0.9, 0.95]))
    cut = X(cut, translate=[3.1, -1.2, 0.6])
    return scene("sweep_csg", [0, 3.2, 7.6], [0.3, 0.0, 0], 40,
                 [obj("groove", groove, [0.85, 0.8, 0.7]),
                  obj("ball", ball, [0.4, 0.8, 0.9]),
                  obj("beaded", beaded, [0.9, 0.6, 0.3]),
                  obj("cross", cross, [0.8, 0.5, 0.9]),
                  obj("cut", cut, [0.9, 0.9, 0.4])])


def knob_obj(path):
    """A closed lumpy ball (subdivided icosahedron, radius modulated by a
    few seeded bumps), unit size, outward-oriented triangles."""
    rng = random.Random(5)
    t = (1 + 5 ** 0.5) / 2
    vs = [norm(v) for v in [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
                            [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                            [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]]
    fs = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
          (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
          (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
          (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(3):
        mid = {}

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                vs.append(norm([(vs[a][i] + vs[b][i]) / 2 for i in range(3)]))
                mid[k] = len(vs) - 1
            return mid[k]
        nf = []
        for a, b, c in fs:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        fs = nf
    bumps = [(norm([rng.gauss(0, 1) for _ in range(3)]),
              rng.uniform(0.1, 0.25)) for _ in range(7)]
    out = []
    for v in vs:
        r = 1.0
        for d, a in bumps:
            c = sum(x * y for x, y in zip(v, d))
            r += a * max(0.0, c) ** 6
        out.append([x * r for x in v])
    # orientation: make every face's normal point outward (star-shaped)
    fixed = []
    for a, b, c in fs:
        A, B, C = out[a], out[b], out[c]
        e1 = [B[i] - A[i] for i in range(3)]
        e2 = [C[i] - A[i] for i in range(3)]
        n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
             e1[0] * e2[1] - e1[1] * e2[0]]
        fixed.append((a, b, c) if sum(n[i] * A[i] for i in range(3)) > 0
                     else (a, c, b))
    with open(path, "w") as f:
        f.write("# knob.obj: generated by benches/scenes/gen.py "
                "(%d vertices, %d triangles)\n" % (len(out), len(fixed)))
        for v in out:
            f.write("v %.6f %.6f %.6f\n" % tuple(v))
        for a, b, c in fixed:
            f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))


def forest_with(name, tree):
    """scenes/forest (the example) named `name`, each of its trees (a
    ball, cone or cylinder leaf) replaced by `tree(leaf)`."""
    with open(os.path.join(HERE, "forest.json")) as f:
        base = json.load(f)
    base["name"] = name
    u = base["objects"][1]["shape"]
    u["union"] = [tree(t) for t in u["union"]]
    return base


def forest_cut():
    """A forest of 10 000 cut trees: scenes/forest (the example) with every
    leaf made a small CSG subtree (a ball with its bottom cut off by a
    half-space, a cone cut to a box, a trunk minus a notch): a wide union
    whose children are not leaves."""
    def cut(t):
        if "sphere" in t:
            c, r = t["sphere"]["center"], t["sphere"]["radius"]
            return I(t, plane([0, -1, 0], -(c[1] - 0.3 * r)))
        if "cone" in t:
            a, b = t["cone"]["a"], t["cone"]["b"]
            ra = t["cone"]["radius_a"]
            h = b[1] - a[1]
            return I(t, box([a[0] - ra, a[1] + 0.05 * h, a[2] - ra],
                            [a[0] + ra, b[1], a[2] + ra]))
        b, r = t["cylinder"]["b"], t["cylinder"]["radius"]
        return D(t, sphere([b[0] + r, b[1], b[2]], 0.6 * r))
    return forest_with("forest_cut", cut)


def forest_deep():
    """A forest of 10 000 trees two levels deep: scenes/forest (the example)
    with every leaf made a small CSG tree of two or three kernel leaves (a
    ball cut by a half-space minus a notch, a cone and its trunk cut to a
    box, a trunk minus two notches): a wide union of deeper subtrees."""
    def deep(t):
        if "sphere" in t:
            c, r = t["sphere"]["center"], t["sphere"]["radius"]
            return D(I(t, plane([0, -1, 0], -(c[1] - 0.3 * r))),
                     sphere([c[0] + r, c[1] + 0.5 * r, c[2]], 0.4 * r))
        if "cone" in t:
            a, b = t["cone"]["a"], t["cone"]["b"]
            ra = t["cone"]["radius_a"]
            h = b[1] - a[1]
            trunk = cyl([a[0], a[1] - 0.2 * h, a[2]], [a[0], a[1] + 0.1 * h, a[2]], 0.25 * ra)
            return I(U(t, trunk), box([a[0] - ra, a[1] - 0.15 * h, a[2] - ra],
                                      [a[0] + ra, b[1], a[2] + ra]))
        b, r = t["cylinder"]["b"], t["cylinder"]["radius"]
        return D(t, U(sphere([b[0] + r, b[1], b[2]], 0.6 * r),
                      sphere([b[0] - r, b[1], b[2]], 0.5 * r)))
    return forest_with("forest_deep", deep)


def forest_objects():
    """A forest of 10 000 objects: scenes/forest (the example) with every
    tree its own object instead of a child of one union (the objects' tree
    and the tiles' object lists, not a wide CSG node)."""
    with open(os.path.join(HERE, "forest.json")) as f:
        base = json.load(f)
    objs = [base["objects"][0]]
    for i, t in enumerate(base["objects"][1]["shape"]["union"]):
        objs.append(obj("tree%d" % i, t, base["objects"][1]["color"]))
    base["name"] = "forest_objects"
    base["objects"] = objs
    return base


def forest_pitted():
    """A forest whose balls are each pitted by five spheres: scenes/forest
    (the example) with every ball a difference of six leaves (more operands
    than the packets' two-to-four-operand pass takes). Not in the suite:
    `gen.py --out DIR forest_pitted` writes it to DIR."""
    pits = [(1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1), (0, 1, 0)]

    def pitted(t):
        if "sphere" not in t:
            return t
        c, r = t["sphere"]["center"], t["sphere"]["radius"]
        return D(t, *[sphere([c[0] + r * x, c[1] + r * y, c[2] + r * z], 0.3 * r) for x, y, z in pits])
    return forest_with("forest_pitted", pitted)


SCENES = {f.__name__: f for f in (polytopes, nesting, capsules, gear, tori,
                                  fill, ground, mesh_cut, mesh_mold,
                                  sweep_csg, forest_cut, forest_objects,
                                  forest_deep)}


def forest_objects4():
    """A forest of 40 000 objects: forest_objects with each tree copied
    three more times, shifted a little (denser: some 50 objects a tile).
    Not in the suite: `gen.py --out DIR forest_objects4`."""
    base = forest_objects()
    shifts = [(0.37, 0.21), (-0.29, 0.41), (0.13, -0.47)]

    def shifted(shape, dx, dz):
        t = json.loads(json.dumps(shape))
        for k, v in t.items():
            pts = ["center"] if k == "sphere" else ["a", "b"]
            for p in pts:
                v[p] = [v[p][0] + dx, v[p][1], v[p][2] + dz]
        return t
    trees = base["objects"][1:]
    for i, (dx, dz) in enumerate(shifts):
        for o in trees:
            base["objects"].append(dict(o, name="%s_%d" % (o["name"], i + 1),
                                        shape=shifted(o["shape"], dx, dz)))
    base["name"] = "forest_objects4"
    return base


def shifted_shape(shape, dx, dz):
    """A copy of CSG `shape` moved by (dx, 0, dz): every leaf's points, and
    a plane's offset along its normal."""
    t = json.loads(json.dumps(shape))

    def move(node):
        for k, v in node.items():
            if k in ("union", "intersection", "difference"):
                for c in v:
                    move(c)
            elif k == "sphere":
                v["center"] = [v["center"][0] + dx, v["center"][1], v["center"][2] + dz]
            elif k in ("cone", "cylinder"):
                for p in ("a", "b"):
                    v[p] = [v[p][0] + dx, v[p][1], v[p][2] + dz]
            elif k == "box":
                for p in ("min", "max"):
                    v[p] = [v[p][0] + dx, v[p][1], v[p][2] + dz]
            elif k == "plane":
                n = v["normal"]
                v["offset"] = r6(v["offset"] + n[0] * dx + n[2] * dz)
    move(t)
    return t


def union4(base, name):
    """Scene `base` (a forest: object 1 a wide union of trees) with each
    tree copied three more times, shifted as in forest_objects4, named
    `name`."""
    u = base["objects"][1]["shape"]["union"]
    shifts = [(0.37, 0.21), (-0.29, 0.41), (0.13, -0.47)]
    u.extend([shifted_shape(t, dx, dz) for dx, dz in shifts for t in list(u)])
    base["name"] = name
    return base


def forest_deep4():
    """forest_deep with each tree copied three more times, shifted as in
    forest_objects4: a wide union of 40 000 subtrees two levels deep. Not
    in the suite: `gen.py --out DIR forest_deep4`."""
    return union4(forest_deep(), "forest_deep4")


def forest4():
    """scenes/forest (the example) with each tree copied three more times,
    shifted as in forest_objects4: a wide union of 40 000 leaves. Not in
    the suite: `gen.py --out DIR forest4`."""
    return union4(forest_with("forest4", lambda t: t), "forest4")


def capsules3000():
    """3 000 capsules in capsules' volume, each scaled by (1/10)^(1/3)
    (as many capsules' volume as capsules' 300). Not in the suite:
    `gen.py --out DIR capsules3000`."""
    return capsule_field("capsules3000", 3000, 301, (300 / 3000) ** (1 / 3))


def forest_tori():
    """scenes/forest (the example) with every trunk (a cylinder) made a
    ring torus lying around its foot: a wide union of balls, cones and
    tori. Not in the suite: `gen.py --out DIR forest_tori`."""
    def ring(t):
        if "cylinder" not in t:
            return t
        a, r = t["cylinder"]["a"], t["cylinder"]["radius"]
        return torus([a[0], a[1] + r, a[2]], [0, 1, 0], 2.0 * r, 0.6 * r)
    return forest_with("forest_tori", ring)


def forest_arches():
    """scenes/forest (the example) with every trunk made an arch, a ring
    torus standing upright cut by the ground's half-space: a wide union
    whose children are nodes of a torus and a half-space. Not in the
    suite: `gen.py --out DIR forest_arches`."""
    def arch(t):
        if "cylinder" not in t:
            return t
        a, r = t["cylinder"]["a"], t["cylinder"]["radius"]
        return I(torus(a, [0, 0, 1], 2.0 * r, 0.6 * r), plane([0, -1, 0], -a[1]))
    return forest_with("forest_arches", arch)


def tori_deep():
    """400 objects, each a tree two levels deep with a ring torus: a ring
    cut by a half-space minus a ball, or a ring cut by a box joined to a
    ball; on a ground box. Not in the suite: `gen.py --out DIR tori_deep`."""
    rng = random.Random(11)
    objs = [obj("ground", box([-12, -1.2, -12], [12, -1, 12]), [0.6, 0.6, 0.6])]
    for i in range(400):
        c = [rng.uniform(-10, 10), rng.uniform(-0.6, 0.6), rng.uniform(-10, 6)]
        ax = [rng.uniform(-1, 1), 1, rng.uniform(-1, 1)]
        R = rng.uniform(0.2, 0.5)
        r = R * rng.uniform(0.15, 0.4)
        t = torus(c, ax, R, r)
        if i % 2 == 0:
            s = D(I(t, plane([0, -1, 0], -c[1])), sphere([c[0] + R, c[1], c[2]], r * 1.5))
        else:
            s = U(I(t, box([c[0] - R, c[1] - R, c[2] - R], [c[0] + R, c[1] + 0.3 * R, c[2] + R])),
                  sphere(c, r * 2))
        objs.append(obj("ring%d" % i, s, hsv(i / 400)))
    return scene("tori_deep", [0, 4, 14], [0, 0, 0], 50, objs)


def knob_union():
    """60 knob meshes (knob.obj, 1 280 triangles), turned and scaled, in
    one union: more mesh leaves than the packet path walks ahead. Not in
    the suite: `gen.py --out DIR knob_union` (copies knob.obj to DIR)."""
    rng = random.Random(4)
    kids = [X(mesh("knob.obj"), translate=[rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-3, 0)],
              rotate=[rng.uniform(0, 360), rng.uniform(0, 360), 0], scale=rng.uniform(0.5, 0.9))
            for _ in range(60)]
    return scene("knob_union", [0, 0, 10], [0, 0, -1], 40, [obj("knobs", U(*kids), [0.7, 0.6, 0.9])])


def knob_cut_field():
    """60 objects, each a knob mesh (turned and scaled) minus a ball. Not
    in the suite: `gen.py --out DIR knob_cut_field` (copies knob.obj to
    DIR)."""
    rng = random.Random(5)
    objs = [obj("k%d" % i, cut_knob(rng), hsv(rng.random())) for i in range(60)]
    return scene("knob_cut_field", [0, 0, 10], [0, 0, -1], 40, objs)


def cut_knob(rng):
    """A knob mesh placed, turned and scaled at random, minus a ball near
    its centre (knob_cut_field's objects, knob_cut_union's children)."""
    c = [rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-3, 0)]
    k = X(mesh("knob.obj"), translate=c, rotate=[rng.uniform(0, 360), rng.uniform(0, 360), 0],
          scale=rng.uniform(0.5, 0.9))
    return D(k, sphere([c[0] + 0.3, c[1] + 0.3, c[2] + 0.3], 0.35))


def knob_cut_union():
    """60 knob meshes (turned and scaled), each minus a ball, in one union:
    a wide union of subtrees with meshes. Not in the suite: `gen.py --out
    DIR knob_cut_union` (copies knob.obj to DIR)."""
    rng = random.Random(9)
    kids = [cut_knob(rng) for _ in range(60)]
    return scene("knob_cut_union", [0, 0, 10], [0, 0, -1], 40, [obj("knobs", U(*kids), [0.7, 0.6, 0.9])])


def knob_mixed_union():
    """40 knob meshes and 200 balls in one union, over a ground plane. Not
    in the suite: `gen.py --out DIR knob_mixed_union` (copies knob.obj to
    DIR)."""
    rng = random.Random(10)
    kids = []
    for _ in range(40):
        c = [rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-3, 0)]
        kids.append(X(mesh("knob.obj"), translate=c, rotate=[rng.uniform(0, 360), rng.uniform(0, 360), 0],
                      scale=rng.uniform(0.4, 0.8)))
    for _ in range(200):
        c = [rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-3, 0)]
        kids.append(sphere(c, rng.uniform(0.1, 0.3)))
    return scene("knob_mixed_union", [0, 0, 10], [0, 0, -1], 40,
                 [obj("things", U(*kids), [0.7, 0.6, 0.9]), obj("ground", plane([0, 1, 0], -3.5), [0.8, 0.8, 0.8])])


def knob_mixed_cut_union():
    """knob_mixed_union with its 40 knobs replaced by knob_cut_union's
    pieces (a knob minus a ball, placed anew): a wide union of balls, which
    the packets' first-entry walk takes, and pieces it cannot take. Not in the suite: `gen.py --out DIR
    knob_mixed_cut_union` (copies knob.obj to DIR)."""
    sc = knob_mixed_union()
    sc["objects"][0]["name"] = "cut things"
    rng = random.Random(10)
    kids = sc["objects"][0]["shape"]["union"]
    sc["objects"][0]["shape"] = U(*[cut_knob(rng) if "mesh" in json.dumps(k) else k for k in kids])
    return sc


def sweep_union():
    """80 short swept-sphere tubes in one union, over a ground plane. Not in
    the suite: `gen.py --out DIR sweep_union`."""
    rng = random.Random(7)
    kids = []
    for _ in range(80):
        c = [rng.uniform(-6, 6), rng.uniform(-3, 3), rng.uniform(-4, 0)]
        s = rng.uniform(0.4, 0.9)
        p0 = [c[0] - s, c[1], c[2]]
        p3 = [c[0] + s, c[1] + rng.uniform(-s, s), c[2] + rng.uniform(-s, s)]
        p1 = [c[0] - s / 3, c[1] + rng.uniform(-s, s), c[2] + rng.uniform(-s, s)]
        p2 = [c[0] + s / 3, c[1] + rng.uniform(-s, s), c[2] + rng.uniform(-s, s)]
        r = rng.uniform(0.05, 0.15)
        kids.append(sweep(bez(p0, p1, p2, p3, r, r * rng.uniform(0.5, 1.5))))
    return scene("sweep_union", [0, 0, 10], [0, 0, -1], 40,
                 [obj("tubes", U(*kids), [0.6, 0.8, 0.5]), obj("ground", plane([0, 1, 0], -3.5), [0.8, 0.8, 0.8])])


def sweep_cut_union():
    """sweep_union's 80 tubes, each minus a ball at its middle, in one
    union over a ground plane: a wide union of pieces the packets'
    first-entry walk cannot take. Not in the suite: `gen.py --out DIR
    sweep_cut_union`."""
    sc = sweep_union()
    sc["objects"][0]["name"] = "bitten tubes"
    tubes = sc["objects"][0]["shape"]["union"]
    rng = random.Random(8)
    cut = []
    for t in tubes:
        pts = t["swept_sphere"]["bezier"]
        mid = [(a + b) / 2 for a, b in zip(pts[0][:3], pts[-1][:3])]
        cut.append(D(t, sphere(mid, rng.uniform(0.1, 0.2))))
    sc["objects"][0]["shape"] = U(*cut)
    return sc


# Scenes made on request only (`--out DIR NAME`), for measurements outside
# the suite.
def nesting_deep():
    """scenes/nesting 100 levels deep (301 leaves): thinner shells, the
    wedge turned 2.4 degrees a level. Not in the suite:
    `gen.py --out DIR nesting_deep`."""
    return onion("nesting_deep", 100, (0.018, 0.009), (2.4, 0.005))


def nesting_bites():
    """Nested boxes and balls, each level cut by a ball on a spiral
    instead of a wedge, and by a half-space every fourth level: 32
    levels of (shell union deeper levels) minus a bite. Not in the
    suite: `gen.py --out DIR nesting_bites`."""
    n = 32
    node = box([-0.2, -0.2, -0.2], [0.2, 0.2, 0.2], color=[1, 0.9, 0.3])
    for k in reversed(range(n)):
        r = 2.0 - k * 0.056
        if k % 2 == 0:
            shell = D(sphere([0, 0, 0], r), sphere([0, 0, 0], r - 0.03))
        else:
            h = r * 0.8
            shell = D(box([-h, -h, -h], [h, h, h]),
                      box([-h + 0.03, -h + 0.03, -h + 0.03], [h - 0.03, h - 0.03, h - 0.03]))
        a = math.radians(37 * k)
        bite = sphere([r * math.cos(a), 0.9 - 0.05 * k, r * math.sin(a)], 0.45 * r,
                      color=[0.3, 0.6, 0.9])
        cut = [bite, plane([0, 1, 0], 1.2 - 0.03 * k)] if k % 4 == 3 else [bite]
        node = D(U(shell, node), *cut, color=hsv(k / n, 0.5, 0.95))
    return scene("nesting_bites", [3.6, 2.8, 4.4], [0, -0.1, 0], 42,
                 [obj("onion", node, [0.8, 0.8, 0.8])])


EXTRA = {f.__name__: f for f in (forest_pitted, forest_objects4, capsules3000,
                                 forest_deep4, forest4, forest_tori,
                                 forest_arches, tori_deep, knob_union,
                                 knob_cut_field, knob_cut_union,
                                 knob_mixed_union, knob_mixed_cut_union,
                                 sweep_union, sweep_cut_union, nesting_deep,
                                 nesting_bites)}


def main(argv):
    out_dir = HERE
    if argv[:1] == ["--out"]:
        out_dir, argv = argv[1], argv[2:]
        os.makedirs(out_dir, exist_ok=True)
    names = argv or list(SCENES)
    if out_dir == HERE:
        knob_obj(os.path.join(HERE, "knob.obj"))
    for n in names:
        sc = {**SCENES, **EXTRA}[n]()
        if n.startswith("knob_") and out_dir != HERE:
            # (Its mesh beside it: a scene reads files in its own folder.)
            knob = os.path.join(out_dir, "knob.obj")
            if not os.path.exists(knob):
                knob_obj(knob)
        nl = sum(leaves(o["shape"]) for o in sc["objects"])
        dp = max(depth(o["shape"]) for o in sc["objects"])
        path = os.path.join(out_dir, n + ".json")
        with open(path, "w") as f:
            json.dump(sc, f, indent=1)
            f.write("\n")
        print("%-10s %3d objects %5d leaves depth %2d  %s"
              % (n, len(sc["objects"]), nl, dp, sc_doc(n)))


def sc_doc(n):
    return {**SCENES, **EXTRA}[n].__doc__.split("\n")[0]


if __name__ == "__main__":
    main(sys.argv[1:])
