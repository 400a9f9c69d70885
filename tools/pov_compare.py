#!/usr/bin/env python3
"""Compare rothray's `--aov id` image with POV-Ray 3.7 (the oracle), or time
POV-Ray on a scene.

  python3 tools/pov_compare.py SCENE.json --rothray-id ID.png
          [--width W --height H] [--keep DIR] [--diff DIFF.png]
          [--max-mismatch N] [--band 4|8|0] [--sturm]
  python3 tools/pov_compare.py SCENE.json --pov-only [--width W --height H]
          [--keep DIR]           (just render POV's id image, keep it)
  python3 tools/pov_compare.py SCENE.json --time-only [--width 1920 --height 1080]
          [--threads 2]          (POV benchmark: +Q0 -A +WT2, normal render)
          [--lit]                (lit benchmark: the scene's lights as
                                  parallel light_sources casting shadows,
                                  +Q4 -A +WT<threads>)

Id comparison: both images are mapped pixel by pixel to a leaf index (or
background) by nearest palette colour (palette = rothray's id colours, see
scene2pov.id_color). A pixel is in the edge band if any of its 8 (or 4)
neighbours, in either image, carries a different label than the pixel in
that image. Mismatches off the band are counted; exit status 0 if their
number is <= --max-mismatch (default 0), 1 otherwise, 2 on errors (bad
scene, povray failed, unreadable PNG), 3 if the scene uses something POV-Ray
cannot express (generalized_cylinder, glTF).

Standard library only (PNG read/write via zlib).
"""
import argparse
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scene2pov  # noqa: E402

POVRAY = os.environ.get("POVRAY", "povray")


# ------------------------------------------------------------------ PNG I/O
def read_png(path):
    """Returns (width, height, rows) with rows[y] = bytes of RGB triples
    (8 bit). Handles colour types 0, 2, 3, 4, 6, bit depths 8 and 16
    (and 1/2/4 for grey/palette), non-interlaced."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("%s: not a PNG file" % path)
    pos, idat, plte, trns = 8, [], None, None
    W = H = depth = ctype = interlace = None
    while pos < len(data):
        ln, typ = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + ln]
        pos += 12 + ln
        if typ == b"IHDR":
            W, H, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB",
                                                                 chunk)
        elif typ == b"PLTE":
            plte = chunk
        elif typ == b"IDAT":
            idat.append(chunk)
        elif typ == b"IEND":
            break
    if W is None:
        raise ValueError("%s: no IHDR" % path)
    if interlace:
        raise ValueError("%s: interlaced PNG not supported" % path)
    chans = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[ctype]
    bpp_bits = chans * depth
    stride = (W * bpp_bits + 7) // 8
    bpp = max(1, bpp_bits // 8)
    raw = zlib.decompress(b"".join(idat))
    rows = []
    prev = bytearray(stride)
    p = 0
    for y in range(H):
        ft = raw[p]
        cur = bytearray(raw[p + 1:p + 1 + stride])
        p += 1 + stride
        if ft == 0:
            pass
        elif ft == 1:
            for i in range(bpp, stride):
                cur[i] = (cur[i] + cur[i - bpp]) & 255
        elif ft == 2:
            cur = bytearray((a + b) & 255 for a, b in zip(cur, prev))
        elif ft == 3:
            for i in range(stride):
                left = cur[i - bpp] if i >= bpp else 0
                cur[i] = (cur[i] + ((left + prev[i]) >> 1)) & 255
        elif ft == 4:
            for i in range(stride):
                a = cur[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                pr = a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
                cur[i] = (cur[i] + pr) & 255
        else:
            raise ValueError("%s: bad PNG filter %d" % (path, ft))
        rows.append(bytes(cur))
        prev = cur
    out = []
    for r in rows:
        if depth == 16:
            r = r[0::2]          # keep high bytes
        elif depth < 8:
            vals = []
            per = 8 // depth
            mask = (1 << depth) - 1
            for byte in r:
                for k in range(per):
                    vals.append((byte >> (8 - depth * (k + 1))) & mask)
            vals = vals[:W]
            if ctype == 0:
                vals = [v * 255 // mask for v in vals]
            r = bytes(vals)
        if ctype == 2:
            rgb = r
        elif ctype == 6:
            rgb = bytes(b for i in range(W) for b in r[4 * i:4 * i + 3])
        elif ctype == 0:
            rgb = bytes(v for v in r for _ in range(3))
        elif ctype == 4:
            rgb = bytes(v for v in r[0::2] for _ in range(3))
        else:  # palette
            rgb = b"".join(plte[3 * v:3 * v + 3] for v in r)
        out.append(rgb)
    return W, H, out


def write_png(path, W, H, rows):
    """rows[y]: bytes/bytearray of W RGB triples."""
    raw = b"".join(b"\x00" + bytes(r) for r in rows)

    def chunk(t, d):
        c = struct.pack(">I", len(d)) + t + d
        return c + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 6)))
        f.write(chunk(b"IEND", b""))


# ------------------------------------------------------------------ povray
def povray_version():
    try:
        r = subprocess.run([POVRAY, "--version"], capture_output=True,
                           text=True)
        for ln in (r.stdout + r.stderr).splitlines():
            if ln.startswith("POV-Ray"):
                return ln.strip()
    except OSError:
        pass
    return "unknown"


def run_povray(pov_path, png_path, W, H, opts, threads):
    """Runs povray in the directory of the .pov (POV's default I/O security
    allows writing to '.'); returns (argv, stderr)."""
    d = os.path.dirname(os.path.abspath(pov_path))
    argv = [POVRAY, "+I" + os.path.basename(pov_path),
            "+O" + os.path.basename(png_path), "+W%d" % W, "+H%d" % H,
            "+FN8", "-D", "-P", "-V", "+WT%d" % threads] + opts
    r = subprocess.run(argv, cwd=d, capture_output=True, text=True)
    if r.returncode != 0 or not os.path.exists(png_path):
        sys.stderr.write(r.stderr[-4000:])
        raise RuntimeError("povray failed (status %d): %s"
                           % (r.returncode, " ".join(argv)))
    return argv, r.stderr


ID_OPTS = ["-A", "+Q9", "File_Gamma=1.0", "Display_Gamma=1.0"]
BENCH_OPTS = ["+Q0", "-A"]
LIT_OPTS = ["+Q4", "-A"]


def parse_seconds(stderr, label):
    """POV 3.7 statistics: '  Trace Time:  0 hours  0 minutes  1 seconds
    (1.234 seconds)'. Returns float seconds or None."""
    m = re.search(label + r"\s*Time:[^\n(]*\(([0-9.]+) seconds\)", stderr)
    return float(m.group(1)) if m else None


# ------------------------------------------------------------------ labels
class Palette:
    def __init__(self, nleaves):
        self.exact = {(0, 0, 0): -1}
        self.colors = [((0, 0, 0), -1)]
        self.collisions = 0
        for i in range(nleaves):
            c = scene2pov.id_color(i)
            if c in self.exact:
                self.collisions += 1
                continue
            self.exact[c] = i
            self.colors.append((c, i))
        self.cache = {}
        self.offpalette = 0

    def label(self, c):
        l = self.exact.get(c)
        if l is not None:
            return l
        if c in self.cache:
            l, d = self.cache[c]
        else:
            best, l = None, -1
            for q, i in self.colors:
                d = ((q[0] - c[0]) ** 2 + (q[1] - c[1]) ** 2 +
                     (q[2] - c[2]) ** 2)
                if best is None or d < best:
                    best, l = d, i
            d = best
            self.cache[c] = (l, d)
        if d > 3 * 6 * 6:
            self.offpalette += 1
        return l


def labels_of(rows, W, H, pal):
    lab = []
    for r in rows:
        lab.append([pal.label((r[3 * x], r[3 * x + 1], r[3 * x + 2]))
                    for x in range(W)])
    return lab


def edge_mask(lab, W, H, conn):
    if conn == 0:
        return [[False] * W for _ in range(H)]
    nb = [(-1, 0), (1, 0), (0, -1), (0, 1)]
    if conn == 8:
        nb += [(-1, -1), (1, -1), (-1, 1), (1, 1)]
    m = []
    for y in range(H):
        row = lab[y]
        mr = [False] * W
        for x in range(W):
            v = row[x]
            for dx, dy in nb:
                xx, yy = x + dx, y + dy
                if 0 <= xx < W and 0 <= yy < H and lab[yy][xx] != v:
                    mr[x] = True
                    break
        m.append(mr)
    return m


def compare(scene, rothray_png, W, H, keep, diff_path, max_mismatch, band,
            sturm, threads, inflate=0.0):
    rw, rh, rrows = read_png(rothray_png)
    if W is None:
        W, H = rw, rh
    if (rw, rh) != (W, H):
        raise RuntimeError("%s is %dx%d, expected %dx%d"
                           % (rothray_png, rw, rh, W, H))
    pov_png, leaves, argv = render_id(scene, W, H, keep, sturm, threads,
                                      inflate)
    pw, ph, prows = read_png(pov_png)
    pal = Palette(len(leaves))
    lp = labels_of(prows, W, H, pal)
    off_pov = pal.offpalette
    pal.offpalette = 0
    lr = labels_of(rrows, W, H, pal)
    off_rr = pal.offpalette
    ep = edge_mask(lp, W, H, band)
    er = edge_mask(lr, W, H, band)
    total = W * H
    mism = off = nband = 0
    pairs = {}
    drows = []
    for y in range(H):
        d = bytearray(3 * W)
        for x in range(W):
            a, b = lp[y][x], lr[y][x]
            inband = ep[y][x] or er[y][x]
            nband += inband
            if a != b:
                mism += 1
                if not inband:
                    off += 1
                    pairs[(a, b)] = pairs.get((a, b), 0) + 1
                    d[3 * x:3 * x + 3] = b"\xff\x00\x00"
                else:
                    d[3 * x:3 * x + 3] = b"\x80\x80\x00"
            else:
                r = prows[y]
                d[3 * x:3 * x + 3] = bytes(v * 3 // 10 for v in
                                           r[3 * x:3 * x + 3])
        drows.append(d)
    if diff_path:
        write_png(diff_path, W, H, drows)

    def name(i):
        return "background" if i < 0 else "%d:%s" % (i, leaves[i])
    verdict = "PASS" if off <= max_mismatch else "FAIL"
    print("pov_compare %s %s: %dx%d leaves=%d mismatch=%d (%.4f%%) "
          "off_band=%d (%.4f%%) band=%d (%.2f%%) offpalette_pov=%d "
          "offpalette_rothray=%d"
          % (verdict, os.path.basename(scene), W, H, len(leaves), mism,
             100.0 * mism / total, off, 100.0 * off / total, nband,
             100.0 * nband / total, off_pov, off_rr))
    if pal.collisions:
        print("  note: %d leaves share an id colour with an earlier leaf"
              % pal.collisions)
    for (a, b), n in sorted(pairs.items(), key=lambda t: -t[1])[:8]:
        print("  %7d px  pov=%s  rothray=%s" % (n, name(a), name(b)))
    if diff_path:
        print("  diff image: %s (red: mismatch off band, olive: mismatch "
              "in band)" % diff_path)
    return 0 if off <= max_mismatch else 1


def workdir(keep):
    if keep:
        os.makedirs(keep, exist_ok=True)
        return os.path.abspath(keep), False
    return tempfile.mkdtemp(prefix="pov_compare_"), True


def render_id(scene, W, H, keep, sturm, threads, inflate=0.0):
    d, _ = workdir(keep)
    base = os.path.splitext(os.path.basename(scene))[0]
    pov = os.path.join(d, base + "_id.pov")
    png = os.path.join(d, base + "_pov_id.png")
    W, H, leaves = scene2pov.convert_file(scene, pov, True, W, H, sturm,
                                          inflate)
    argv, _ = run_povray(pov, png, W, H, ID_OPTS, threads)
    print("povray: (cwd %s) %s" % (d, " ".join(argv)))
    return png, leaves, argv


def main(argv):
    ap = argparse.ArgumentParser(
        description="POV-Ray oracle for rothray --aov id; see module doc.")
    ap.add_argument("scene")
    ap.add_argument("--rothray-id", help="rothray `render --aov id` PNG")
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    ap.add_argument("--keep", help="directory for the .pov and POV's PNGs")
    ap.add_argument("--diff", help="write a diff PNG here")
    ap.add_argument("--max-mismatch", type=int, default=0)
    ap.add_argument("--band", type=int, choices=(0, 4, 8), default=8,
                    help="edge band neighbourhood (0: no band)")
    ap.add_argument("--sturm", action="store_true",
                    help="POV sturm solver for tori")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--inflate-cuts", type=float, default=0.0, metavar="EPS",
                    help="grow subtracted leaves by EPS so POV-Ray gets "
                    "differences with coincident faces right (e.g. 1e-4)")
    ap.add_argument("--pov-only", action="store_true",
                    help="only render POV's id image (use with --keep)")
    ap.add_argument("--time-only", action="store_true",
                    help="time POV-Ray: normal render, +Q0 -A +WT<threads>")
    ap.add_argument("--lit", action="store_true",
                    help="with --time-only: lights cast shadows, +Q4 -A")
    a = ap.parse_args(argv)
    if (a.width is None) != (a.height is None):
        ap.error("give both --width and --height")
    tmp = None
    try:
        if a.time_only:
            d, is_tmp = workdir(a.keep)
            tmp = d if is_tmp else None
            base = os.path.splitext(os.path.basename(a.scene))[0]
            pov = os.path.join(d, base + ".pov")
            png = os.path.join(d, base + "_pov.png")
            W, H, leaves = scene2pov.convert_file(a.scene, pov, False,
                                                  a.width, a.height, a.sturm,
                                                  lit=a.lit)
            cmd, err = run_povray(pov, png, W, H,
                                  LIT_OPTS if a.lit else BENCH_OPTS,
                                  a.threads)
            t = parse_seconds(err, "Trace")
            p = parse_seconds(err, "Parse")
            b = parse_seconds(err, "Bounding")
            if t is None:
                sys.stderr.write(err[-3000:])
                raise RuntimeError("no 'Trace Time' in povray's output")
            print("povray: (cwd %s) %s" % (d, " ".join(cmd)))
            m = re.search(r"Trace Time:[^\n]*\n\s*using (\d+) thread\(s\) "
                          r"with ([0-9.]+) CPU-seconds", err)
            cpu = "threads=%s cpu_s=%s " % m.groups() if m else ""
            print("pov_time %s%s %dx%d leaves=%d parse_s=%s bounding_s=%s "
                  "%strace_s=%.3f  (%s)" % (os.path.basename(a.scene),
                                           " lit" if a.lit else "", W, H,
                                           len(leaves), p, b, cpu, t,
                                           povray_version()))
            print(t)
            return 0
        if a.pov_only:
            if not a.keep:
                ap.error("--pov-only needs --keep DIR")
            png, leaves, _ = render_id(a.scene, a.width, a.height, a.keep,
                                       a.sturm, a.threads, a.inflate_cuts)
            print("pov id image: %s (%d leaves)" % (png, len(leaves)))
            return 0
        if not a.rothray_id:
            ap.error("need --rothray-id PNG (or --time-only / --pov-only)")
        if not a.keep:
            tmp = tempfile.mkdtemp(prefix="pov_compare_")
        return compare(a.scene, a.rothray_id, a.width, a.height,
                       a.keep or tmp, a.diff, a.max_mismatch, a.band,
                       a.sturm, a.threads, a.inflate_cuts)
    except scene2pov.Unsupported as e:
        print("pov_compare: SKIP (unsupported by POV-Ray): %s" % e)
        return 3
    except (scene2pov.BadScene, RuntimeError, ValueError, OSError) as e:
        print("pov_compare: error: %s" % e, file=sys.stderr)
        return 2
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
