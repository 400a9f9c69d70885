#!/usr/bin/env python3
"""Convert a rothray JSON scene (see scene-format.md) to POV-Ray 3.7 SDL.

    python3 tools/scene2pov.py SCENE.json OUT.pov [--id | --lit] [--width W --height H]

Standard library only.

Conventions (verified against povray 3.7.0.10 with tools/testscenes/):
  * Geometry is written in the scene's own right-handed y-up coordinates;
    every transform (transformed nodes, torus axis) is emitted as an explicit
    POV `matrix`, so no POV rotate/handedness convention is involved.
  * The camera is written with explicit location/direction/right/up vectors
    (no look_at), right = the scene's image-right direction, so the picture is
    not mirrored: POV simply shoots direction + sx*right + sy*up.
  * --id: every leaf gets the flat colour of rothray's `--aov id`
    (leaf i in pre-order: h = ((i+1)*2654435761) mod 2**32,
    rgb = bytes 3,2,1 of h), ambient/emission only, no lights, background
    black, assumed_gamma 1.0 (render with File_Gamma=1.0, see pov_compare.py).
  * Lights (not --id): each of the scene's directional lights (or the
    default one over the camera's shoulder) is a `parallel` light_source at
    a far point opposite its direction, `point_at` the camera target, so
    its rays travel along `direction` everywhere. Without --lit the lights
    are `shadowless` (the flat benchmark renders at +Q0, which ignores
    lights anyway); with --lit they cast shadows, for the lit benchmark at
    +Q4 against rothray with shadow rays.

Exit status: 0 ok, 2 bad input, 3 feature POV-Ray cannot express
(generalized_cylinder, glTF meshes).
"""
import json
import math
import os
import sys

LEAVES = ("sphere", "box", "cylinder", "cone", "torus", "plane",
          "swept_sphere", "generalized_cylinder", "mesh")
INNER = ("union", "intersection", "difference", "transformed")
DEFAULT_COLOR = [0.8, 0.8, 0.8]


class Unsupported(Exception):
    pass


class BadScene(Exception):
    pass


def id_color(i):
    """rothray --aov id colour (0..255 ints) of leaf i (0-based, pre-order)."""
    h = ((i + 1) * 2654435761) % (1 << 32)
    return ((h >> 24) & 255, (h >> 16) & 255, (h >> 8) & 255)


# ----------------------------------------------------------------- vectors
def sub(a, b): return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
def add(a, b): return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
def mul(a, s): return [a[0] * s, a[1] * s, a[2] * s]
def dot(a, b): return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0]]
def norm(a):
    l = math.sqrt(dot(a, a))
    if l == 0 or not math.isfinite(l):
        raise BadScene("zero or non-finite vector %r" % (a,))
    return [a[0] / l, a[1] / l, a[2] / l]


def fmt(x):
    x = float(x)
    if not math.isfinite(x):
        raise BadScene("non-finite number")
    r = repr(x)
    return r[:-2] if r.endswith(".0") else r


def vec(v):
    return "<%s, %s, %s>" % (fmt(v[0]), fmt(v[1]), fmt(v[2]))


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)]
            for i in range(4)]


def pov_matrix(m):
    """Column-vector 4x4 m (m[row][col]) -> POV `matrix <12 numbers>`.

    POV transforms a point as the row vector [x y z 1] times
    [[v00 v01 v02 0] [v10 v11 v12 0] [v20 v21 v22 0] [v30 v31 v32 1]],
    i.e. x' = v00 x + v10 y + v20 z + v30: so v_ij = m[j][i] (transpose),
    and the translation row v3j = m[j][3]."""
    vals = []
    for i in range(3):
        for j in range(3):
            vals.append(m[j][i])
    for j in range(3):
        vals.append(m[j][3])
    return "matrix <%s>" % ", ".join(fmt(v) for v in vals)


def transformed_matrix(t, where):
    if "matrix" in t:
        m = t["matrix"]
        if len(m) != 16:
            raise BadScene("%s.matrix: need 16 numbers" % where)
        M = [[float(m[4 * r + c]) for c in range(4)] for r in range(4)]
        return M
    tr = t.get("translate", [0, 0, 0])
    rd = t.get("rotate_deg", [0, 0, 0])
    sc = t.get("scale", 1)
    if isinstance(sc, (int, float)):
        sc = [sc, sc, sc]
    S = [[sc[0], 0, 0, 0], [0, sc[1], 0, 0], [0, 0, sc[2], 0], [0, 0, 0, 1]]
    ax, ay, az = (math.radians(a) for a in rd)
    cx, sx = math.cos(ax), math.sin(ax)
    cy, sy = math.cos(ay), math.sin(ay)
    cz, sz = math.cos(az), math.sin(az)
    Rx = [[1, 0, 0, 0], [0, cx, -sx, 0], [0, sx, cx, 0], [0, 0, 0, 1]]
    Ry = [[cy, 0, sy, 0], [0, 1, 0, 0], [-sy, 0, cy, 0], [0, 0, 0, 1]]
    Rz = [[cz, -sz, 0, 0], [sz, cz, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    T = [[1, 0, 0, tr[0]], [0, 1, 0, tr[1]], [0, 0, 1, tr[2]], [0, 0, 0, 1]]
    return matmul(T, matmul(Rz, matmul(Ry, matmul(Rx, S))))


# ----------------------------------------------------------------- meshes
def load_obj(path):
    verts, faces = [], []
    with open(path, "r", errors="replace") as f:
        for ln in f:
            p = ln.split()
            if not p:
                continue
            if p[0] == "v":
                verts.append([float(p[1]), float(p[2]), float(p[3])])
            elif p[0] == "f":
                idx = []
                for tok in p[1:]:
                    k = int(tok.split("/")[0])
                    idx.append(k - 1 if k > 0 else len(verts) + k)
                for j in range(1, len(idx) - 1):       # fan triangulation
                    faces.append((idx[0], idx[j], idx[j + 1]))
    if not verts or not faces:
        raise BadScene("%s: no triangles" % path)
    for fc in faces:
        for k in fc:
            if not 0 <= k < len(verts):
                raise BadScene("%s: face index out of range" % path)
    return verts, faces


# ----------------------------------------------------------------- emitter
class Converter:
    def __init__(self, scene, scene_dir, id_mode, sturm=False, inflate=0.0,
                 lit=False):
        self.scene = scene
        self.lit = lit
        self.inflate = inflate
        self.dir = scene_dir
        self.id_mode = id_mode
        self.sturm = sturm
        self.leaf_count = 0
        self.leaf_paths = []        # JSON path of leaf i
        self.notes = []
        self.out = []

    def texture(self, color):
        if self.id_mode:
            c = id_color(self.leaf_count)
            return ("texture { pigment { rgb <%d/255, %d/255, %d/255> } "
                    "finish { ambient 0 emission 1 diffuse 0 specular 0 "
                    "phong 0 reflection 0 } }" % c)
        return ("texture { pigment { rgb %s } finish { ambient 0.12 "
                "diffuse 0.88 specular 0 phong 0 } }" % vec(color))

    def shape(self, node, color, path, ind):
        if not isinstance(node, dict):
            raise BadScene("%s: shape must be an object" % path)
        color = node.get("color", color)
        kinds = [k for k in node if k not in ("name", "color")]
        if len(kinds) != 1:
            raise BadScene("%s: need exactly one shape kind, got %r"
                           % (path, kinds))
        kind = kinds[0]
        v = node[kind]
        p = "%s.%s" % (path, kind)
        pad = "  " * ind
        if kind in ("union", "intersection", "difference"):
            if not isinstance(v, list) or not v:
                raise BadScene("%s: need a non-empty array" % p)
            word = kind if len(v) > 1 else "object"
            s = pad + word + " {\n"
            for i, ch in enumerate(v):
                s += self.shape(ch, color, "%s[%d]" % (p, i), ind + 1)
            return s + pad + "}\n"
        if kind == "transformed":
            M = transformed_matrix(v, p)
            s = pad + "object {\n"
            s += self.shape(v["shape"], color, p + ".shape", ind + 1)
            return s + pad + "  " + pov_matrix(M) + "\n" + pad + "}\n"
        if kind not in LEAVES:
            raise BadScene("%s: unknown shape kind %r" % (path, kind))
        try:
            body = self.leaf(kind, v, p, pad)
        except KeyError as e:
            raise BadScene("%s.%s: missing field" % (p, e.args[0]))
        except (TypeError, IndexError, ValueError) as e:
            raise BadScene("%s: malformed (%s)" % (p, e))
        tex = self.texture(color)
        self.leaf_paths.append(p)
        self.leaf_count += 1
        return body.replace("@TEX@", tex)

    def leaf(self, kind, v, p, pad):
        if kind == "sphere":
            return "%ssphere { %s, %s @TEX@ }\n" % (
                pad, vec(v["center"]), fmt(v["radius"]))
        if kind == "box":
            return "%sbox { %s, %s @TEX@ }\n" % (pad, vec(v["min"]),
                                                  vec(v["max"]))
        if kind == "cylinder":
            return "%scylinder { %s, %s, %s @TEX@ }\n" % (
                pad, vec(v["a"]), vec(v["b"]), fmt(v["radius"]))
        if kind == "cone":
            ra, rb = float(v["radius_a"]), float(v["radius_b"])
            if ra == rb:
                return "%scylinder { %s, %s, %s @TEX@ }\n" % (
                    pad, vec(v["a"]), vec(v["b"]), fmt(ra))
            return "%scone { %s, %s, %s, %s @TEX@ }\n" % (
                pad, vec(v["a"]), fmt(ra), vec(v["b"]), fmt(rb))
        if kind == "torus":
            Y = norm(v["axis"])
            a = [1, 0, 0] if abs(Y[0]) < 0.9 else [0, 0, 1]
            X = norm(cross(a, Y))
            Z = cross(X, Y)
            c = v["center"]
            M = [[X[0], Y[0], Z[0], c[0]], [X[1], Y[1], Z[1], c[1]],
                 [X[2], Y[2], Z[2], c[2]], [0, 0, 0, 1]]
            return "%storus { %s, %s %s@TEX@ %s }\n" % (
                pad, fmt(v["major"]), fmt(v["minor"]),
                "sturm " if self.sturm else "", pov_matrix(M))
        if kind == "plane":
            n = v["normal"]
            if dot(n, n) == 0:
                raise BadScene("%s.normal: zero" % p)
            # POV: plane { N, D } is the surface dot(N/|N|, p) = D (POV
            # normalises N but does NOT rescale D; verified), interior
            # dot(N, p) < D (the side opposite the normal): the contract's
            # half-space once N is unit and D = offset/|N|.
            ln = math.sqrt(dot(n, n))
            return "%splane { %s, %s @TEX@ }\n" % (
                pad, vec(mul(n, 1 / ln)), fmt(float(v["offset"]) / ln))
        if kind == "swept_sphere":
            return self.sweep(v, p, pad)
        if kind == "mesh":
            return self.mesh(v, p, pad)
        if kind == "generalized_cylinder":
            raise Unsupported("%s: generalized_cylinder has no POV-Ray "
                              "equivalent" % p)
        raise BadScene("%s: unknown kind" % p)

    def sweep(self, v, p, pad):
        pts = v["bezier"]
        if len(pts) < 4 or (len(pts) - 1) % 3:
            raise BadScene("%s.bezier: length %d is not 3n+1" % (p, len(pts)))
        segs = []
        for i in range(0, len(pts) - 1, 3):
            B = [[float(x) for x in pts[i + k]] for k in range(4)]
            # Uniform cubic B-spline P0..P3 has Bezier points
            #   B0=(P0+4P1+P2)/6, B1=(2P1+P2)/3, B2=(P1+2P2)/3,
            #   B3=(P1+4P2+P3)/6; invert (component-wise, radius too).
            P1 = [2 * B[1][k] - B[2][k] for k in range(4)]
            P2 = [2 * B[2][k] - B[1][k] for k in range(4)]
            P0 = [6 * B[0][k] - 4 * P1[k] - P2[k] for k in range(4)]
            P3 = [6 * B[3][k] - P1[k] - 4 * P2[k] for k in range(4)]
            body = ", ".join("%s, %s" % (vec(P[:3]), fmt(P[3]))
                             for P in (P0, P1, P2, P3))
            segs.append("%s  sphere_sweep { b_spline 4, %s tolerance 1e-4 }\n"
                        % (pad, body))
        if len(segs) == 1:
            return "%sobject {\n%s%s  @TEX@\n%s}\n" % (pad, segs[0], pad, pad)
        return "%sunion {\n%s%s  @TEX@\n%s}\n" % (pad, "".join(segs), pad, pad)

    def mesh(self, v, p, pad):
        path = os.path.join(self.dir, v["path"])
        ext = os.path.splitext(path)[1].lower()
        if ext in (".gltf", ".glb"):
            raise Unsupported("%s.path: glTF meshes are not converted "
                              "(only .obj)" % p)
        if ext != ".obj":
            raise BadScene("%s.path: unknown mesh type %r" % (p, ext))
        try:
            verts, faces = load_obj(path)
        except OSError as e:
            raise BadScene("%s.path: %s" % (p, e))
        s = [pad + "mesh2 {\n", pad + "  vertex_vectors { %d" % len(verts)]
        for k, q in enumerate(verts):
            s.append("," + ("\n" + pad + "    " if k % 4 == 0 else " ")
                     + vec(q))
        s.append("\n" + pad + "  }\n" + pad + "  face_indices { %d" % len(faces))
        for k, f in enumerate(faces):
            s.append("," + ("\n" + pad + "    " if k % 6 == 0 else " ")
                     + "<%d, %d, %d>" % f)
        # POV decides inside/outside by ray parity along inside_vector:
        # equals rothray's "orientation"/"winding" for closed meshes only.
        s.append("\n" + pad + "  }\n" + pad +
                 "  inside_vector <0.2718, 0.8182, 0.5066>\n" + pad +
                 "  @TEX@\n" + pad + "}\n")
        return "".join(s)

    # ------------------------------------------------------------- camera
    def camera(self, W, H):
        cam = self.scene["camera"]
        eye, tgt = cam["eye"], cam["target"]
        up = cam.get("up", [0, 1, 0])
        fov = float(cam["fov_y_deg"])
        f = norm(sub(tgt, eye))
        r = norm(cross(f, up))          # image right (right-handed world)
        u = cross(r, f)                 # image up
        h = 2 * math.tan(math.radians(fov) / 2)   # full height at distance 1
        aspect = W / H
        hfov = 2 * math.degrees(math.atan(math.tan(math.radians(fov) / 2)
                                          * aspect))
        return ("// vertical fov %.6g deg = horizontal (POV angle) %.6g deg\n"
                "camera {\n  perspective\n  location %s\n  direction %s\n"
                "  right %s\n  up %s\n}\n" % (
                    fov, hfov, vec(eye), vec(f), vec(mul(r, h * aspect)),
                    vec(mul(u, h))))

    def lights(self):
        cam = self.scene["camera"]
        lights = self.scene.get("lights")
        if lights is None:   # default: over the camera's shoulder
            f = norm(sub(cam["target"], cam["eye"]))
            r = norm(cross(f, cam.get("up", [0, 1, 0])))
            u = cross(r, f)
            lights = [{"direction": add(f, add(mul(u, -0.6), mul(r, -0.4))),
                       "color": [1, 1, 1]}]
        s = ""
        tgt = cam["target"]
        far = 1e4
        for L in lights:
            d = norm(L["direction"])
            s += ("light_source { %s, rgb %s parallel point_at %s%s }\n"
                  % (vec(sub(tgt, mul(d, far))), vec(L.get("color", [1, 1, 1])),
                     vec(tgt), "" if self.lit else " shadowless"))
        return s

    def convert(self, W, H):
        sc = self.scene
        hdr = ["// generated by tools/scene2pov.py%s\n"
               % (" --id" if self.id_mode else " --lit" if self.lit else ""),
               "#version 3.7;\n",
               "global_settings { assumed_gamma 1.0 max_trace_level 5 }\n",
               self.camera(W, H)]
        if self.id_mode:
            hdr.append("background { rgb <0, 0, 0> }\n")
        else:
            hdr.append("background { rgb %s }\n"
                       % vec(sc.get("background", [0, 0, 0])))
            hdr.append(self.lights())
        body = []
        for i, o in enumerate(sc["objects"]):
            color = o.get("color", DEFAULT_COLOR)
            body.append("// objects[%d] %s\n" % (i, o.get("name", "")))
            shp = o["shape"]
            if self.inflate:
                shp = inflate_cuts(shp, self.inflate, False, self.notes)
            body.append(self.shape(shp, color, "objects[%d].shape" % i, 0))
        if self.notes:
            hdr.append("// --inflate-cuts not applied to: %s\n"
                       % ", ".join(sorted(set(self.notes))))
        hdr.append("// %d leaves\n" % self.leaf_count)
        return "".join(hdr + body)


def inflate_cuts(node, eps, neg, notes):
    """Copy of `node` in which every leaf that is subtracted (an odd number
    of times: difference operands after the first) is grown outward by about
    eps in its own coordinates. POV-Ray leaves coincident faces of A - B
    (e.g. a notch cut by a box sharing faces with A) speckled or filled;
    growing B by eps gives the regularised result. Meshes are left alone."""
    kinds = [k for k in node if k not in ("name", "color")]
    if len(kinds) != 1:
        return node
    k = kinds[0]
    v = node[k]
    out = dict(node)
    if k in ("union", "intersection"):
        out[k] = [inflate_cuts(c, eps, neg, notes) for c in v]
        return out
    if k == "difference":
        out[k] = [inflate_cuts(c, eps, neg if i == 0 else not neg, notes)
                  for i, c in enumerate(v)]
        return out
    if k == "transformed":
        t = dict(v)
        t["shape"] = inflate_cuts(v["shape"], eps, neg, notes)
        out[k] = t
        return out
    if not neg:
        return node
    v = dict(v)
    if k == "sphere":
        v["radius"] = v["radius"] + eps
    elif k == "box":
        v["min"] = [c - eps for c in v["min"]]
        v["max"] = [c + eps for c in v["max"]]
    elif k in ("cylinder", "cone"):
        d = norm(sub(v["b"], v["a"]))
        v["a"] = sub(v["a"], mul(d, eps))
        v["b"] = add(v["b"], mul(d, eps))
        for r in ("radius", "radius_a", "radius_b"):
            if r in v and v[r] > 0:
                v[r] = v[r] + eps
        if k == "cone" and (v["radius_a"] == 0 or v["radius_b"] == 0):
            notes.append("cone tips")
    elif k == "torus":
        v["minor"] = v["minor"] + eps
    elif k == "plane":
        v["offset"] = v["offset"] + eps * math.sqrt(dot(v["normal"],
                                                        v["normal"]))
    elif k == "swept_sphere":
        v["bezier"] = [list(q[:3]) + [q[3] + eps] for q in v["bezier"]]
    else:
        notes.append(k)
        return node
    out[k] = v
    return out


def image_size(scene, width=None, height=None):
    img = scene.get("image", {})
    W = width or img.get("width", 800)
    H = height or img.get("height", 600)
    return int(W), int(H)


def convert_file(scene_path, out_path, id_mode=False, width=None, height=None,
                 sturm=False, inflate=0.0, lit=False):
    """Returns (W, H, leaf_paths). Raises BadScene / Unsupported."""
    try:
        with open(scene_path) as f:
            scene = json.load(f)
    except (OSError, ValueError) as e:
        raise BadScene("%s: %s" % (scene_path, e))
    W, H = image_size(scene, width, height)
    conv = Converter(scene, os.path.dirname(os.path.abspath(scene_path)),
                     id_mode, sturm, inflate, lit)
    try:
        text = conv.convert(W, H)
    except BadScene as e:
        raise BadScene("%s: %s" % (scene_path, e))
    except Unsupported as e:
        raise Unsupported("%s: %s" % (scene_path, e))
    except (KeyError, TypeError, IndexError, ValueError) as e:
        raise BadScene("%s: malformed scene (%s: %s)"
                       % (scene_path, type(e).__name__, e))
    with open(out_path, "w") as f:
        f.write(text)
    return W, H, conv.leaf_paths


def main(argv):
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("--id", action="store_true",
                    help="flat per-leaf colours of rothray --aov id")
    ap.add_argument("--lit", action="store_true",
                    help="lights cast shadows (parallel light_source per "
                    "scene light; for POV-Ray +Q4)")
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    ap.add_argument("--sturm", action="store_true",
                    help="use POV's sturm root solver for tori")
    ap.add_argument("--inflate-cuts", type=float, default=0.0, metavar="EPS",
                    help="grow subtracted leaves by EPS (fixes POV-Ray's "
                    "handling of coincident faces in differences)")
    a = ap.parse_args(argv)
    try:
        W, H, leaves = convert_file(a.scene, a.out, a.id, a.width, a.height,
                                    a.sturm, a.inflate_cuts,
                                    a.lit and not a.id)
    except Unsupported as e:
        print("scene2pov: unsupported: %s" % e, file=sys.stderr)
        return 3
    except BadScene as e:
        print("scene2pov: error: %s" % e, file=sys.stderr)
        return 2
    print("scene2pov: wrote %s (%dx%d, %d leaves)" % (a.out, W, H,
                                                       len(leaves)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
