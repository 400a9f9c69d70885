//! Ray kernels of the analytic leaves, in each leaf's canonical local space.
//!
//! Every kernel takes the ray already mapped into local space (origin `o`,
//! direction `d`, not normalised: t is the caller's t) and reports the full,
//! unclipped parameter range of the line inside the solid; the caller clips it.
//! Canonical forms (see [`crate::table`]): unit sphere at the origin; box
//! `[min, max]`; unit cylinder `x^2+y^2 <= 1, 0 <= z <= 1`; frustum with radius
//! `ra + (rb - ra) z` on `0 <= z <= 1` (max radius 1); torus around z with major
//! radius 1 and minor radius `rho` (f64 quartic); half-space `n . p <= offset`.
//!
//! Boxes and half-spaces are solved in f32; balls ([`ball`]), ellipsoids
//! (`ball` of radius 1), cylinders, cones and tori in f64, from lines mapped
//! in f64 (`crate::table64`), so that tangent chords are those of the f32
//! inputs. [`sphere`] is the f32 unit sphere, a reference for tests.

use glam::{DVec3, Vec3};

use crate::quartic;

/// Sub-surface ids reported with crossings (used to compute normals lazily).
pub mod sub {
    /// Curved side (cylinder, cone) or the only surface (sphere, torus, plane).
    pub const SIDE: u32 = 0;
    /// Cap at z = 0.
    pub const CAP0: u32 = 1;
    /// Cap at z = 1.
    pub const CAP1: u32 = 2;
}

/// A line's range inside a convex leaf: `(t_in, sub_in, t_out, sub_out)`; infinite
/// ends are allowed (the half-space, a cylinder along its axis).
pub type Range = (f32, u32, f32, u32);

/// Unit sphere in f32 (a reference for tests: the leaf table traces
/// spheres and ellipsoids with [`ball`]). Uses the closest-approach form of
/// the discriminant (Ray Tracing Gems, ch. 7), which keeps small, distant
/// spheres accurate in f32.
#[inline(always)]
pub fn sphere(o: Vec3, d: Vec3) -> Option<Range> {
    let a = d.length_squared();
    let b = o.dot(d);
    let f = o - d * (b / a);
    let disc = a * (1.0 - f.length_squared());
    if !(disc >= 0.0) {
        return None;
    }
    let c = o.length_squared() - 1.0;
    if c == f32::INFINITY {
        // |o| > 1.8e19 radii: the chord (at most 2 radii) is below f32's
        // resolution of t (about 6e-8 of |o| radii), so the span has no
        // length; c / q would make it [t, inf] (a ray from 1e20 to the unit
        // sphere was inside it forever).
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
    let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    Some((t0, sub::SIDE, t1, sub::SIDE))
}

/// Ball of radius `r` around the origin, for the line `o + t d` with `o`
/// relative to the centre, in f64 (world units: no map, no rescaling).
///
/// Why f64: a chord of length `L` of a ball of radius `r` lies `L^2 / (8 r)`
/// inside the surface, 2e-8 r for a chord of 1e-4 of a view of 4 radii; the
/// f32 closest approach of a line from 4 radii away is off by ~4 eps r =
/// 5e-7 r, and the f32 map of [`sphere`] (1/r rounded) by 6e-8 r, so in f32
/// whether such a chord exists at all was decided by rounding (the stress
/// table's wrong span counts). In f64 both are ~1e-15 r: the answer is that
/// of the f32 inputs, rounded once to f32 t. The f64 ranges need no
/// rescaling: |o|^2 <= 1e61, |d|^2 within 1e-90..1e77.
#[inline(always)]
pub fn ball(o: DVec3, d: DVec3, r: f64) -> Option<(f64, f64)> {
    let a = d.length_squared();
    let b = o.dot(d);
    let f = o - d * (b / a);
    let disc = a * (r * r - f.length_squared());
    if !(disc >= 0.0) {
        return None;
    }
    let c = o.length_squared() - r * r;
    let q = -(b + disc.sqrt().copysign(b));
    let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
    Some(if t0 <= t1 { (t0, t1) } else { (t1, t0) })
}

/// Axis-aligned box `[mn, mx]` (sub = axis * 2 + 1 for the max face), in
/// f64, on the local line of a box traced through its f64 map
/// ([`crate::table64`]); the packet kernel (`kernels8`) repeats its
/// operations lane by lane.
#[inline(always)]
pub fn cuboid64(o: DVec3, d: DVec3, mn: DVec3, mx: DVec3) -> Option<Range64> {
    let mut t_in = f64::NEG_INFINITY;
    let mut t_out = f64::INFINITY;
    let mut s_in = 0;
    let mut s_out = 0;
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < mn[a] || o[a] > mx[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let ta = (mn[a] - o[a]) * inv;
        let tb = (mx[a] - o[a]) * inv;
        let (tn, sn, tf, sf) = if ta <= tb { (ta, a as u32 * 2, tb, a as u32 * 2 + 1) } else { (tb, a as u32 * 2 + 1, ta, a as u32 * 2) };
        if tn > t_in {
            t_in = tn;
            s_in = sn;
        }
        if tf < t_out {
            t_out = tf;
            s_out = sf;
        }
    }
    if t_in <= t_out {
        Some((t_in, s_in, t_out, s_out))
    } else {
        None
    }
}

/// `n . v` in a fixed order, ((n.x v.x + n.y v.y) + n.z v.z), which
/// the packet kernels repeat.
#[inline(always)]
pub fn dot64(n: DVec3, v: DVec3) -> f64 {
    (n.x * v.x + n.y * v.y) + n.z * v.z
}

/// [`half_space`] in f64 for `dot(n, q + t d) <= w`: `q` is the ray's origin
/// relative to the plane's anchor, `n` its world normal, `w` its offset
/// there ([`crate::table64`]).
#[inline(always)]
pub fn half_space64(q: DVec3, d: DVec3, n: DVec3, w: f64) -> Option<Range64> {
    let den = dot64(n, d);
    let num = w - dot64(n, q);
    if den == 0.0 {
        return if num >= 0.0 { Some((f64::NEG_INFINITY, sub::SIDE, f64::INFINITY, sub::SIDE)) } else { None };
    }
    let t = num / den;
    Some(if den > 0.0 { (f64::NEG_INFINITY, sub::SIDE, t, sub::SIDE) } else { (t, sub::SIDE, f64::INFINITY, sub::SIDE) })
}

/// [`Range`] in f64: what the f64 kernels ([`cylinder`], [`cone`]) return,
/// rounded to f32 once, at the end, by [`narrow`].
pub type Range64 = (f64, u32, f64, u32);

/// `r` with its ends rounded to f32 (the one rounding of an f64 kernel).
#[inline(always)]
pub fn narrow(r: Range64) -> Range {
    (r.0 as f32, r.1, r.2 as f32, r.3)
}

/// Range of the slab `0 <= z <= 1`.
#[inline(always)]
fn slab01(oz: f64, dz: f64) -> Option<Range64> {
    if dz == 0.0 {
        return if (0.0..=1.0).contains(&oz) { Some((f64::NEG_INFINITY, sub::CAP0, f64::INFINITY, sub::CAP1)) } else { None };
    }
    let ta = -oz / dz;
    let tb = (1.0 - oz) / dz;
    Some(if ta <= tb { (ta, sub::CAP0, tb, sub::CAP1) } else { (tb, sub::CAP1, ta, sub::CAP0) })
}

#[inline(always)]
fn and(a: Range64, b: Range64) -> Option<Range64> {
    let (t0, s0) = if a.0 >= b.0 { (a.0, a.1) } else { (b.0, b.1) };
    let (t1, s1) = if a.2 <= b.2 { (a.2, a.3) } else { (b.2, b.3) };
    if t0 <= t1 {
        Some((t0, s0, t1, s1))
    } else {
        None
    }
}

/// Unit capped cylinder, for a line mapped to its frame in f64 (as [`ball`]
/// and for the same reason: through an f32 map and an f32 closest approach a
/// tangent chord's ends moved by ~6e-8 r^2 / (L/2), 7e-5 of the view for a
/// chord of 1e-4 of it, and a ray along a cap's plane crossed it wherever
/// rounding said; tests/stress_tangent.rs). No rescaling is needed in f64:
/// |o|^2 <= 1e122, |d|^2 >= 1e-136.
#[inline(always)]
pub fn cylinder(o: DVec3, d: DVec3) -> Option<Range64> {
    let slab = slab01(o.z, d.z)?;
    let a = d.x * d.x + d.y * d.y;
    let side = if a == 0.0 {
        if o.x * o.x + o.y * o.y > 1.0 {
            return None;
        }
        (f64::NEG_INFINITY, sub::SIDE, f64::INFINITY, sub::SIDE)
    } else {
        let b = o.x * d.x + o.y * d.y;
        let fx = o.x - d.x * (b / a);
        let fy = o.y - d.y * (b / a);
        let disc = a * (1.0 - (fx * fx + fy * fy));
        if !(disc >= 0.0) {
            return None;
        }
        let c = o.x * o.x + o.y * o.y - 1.0;
        let q = -(b + disc.sqrt().copysign(b));
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
        if t0 <= t1 {
            (t0, sub::SIDE, t1, sub::SIDE)
        } else {
            (t1, sub::SIDE, t0, sub::SIDE)
        }
    };
    and(side, slab)
}

/// Frustum with radius `ra + (rb - ra) z` over `0 <= z <= 1`, for a line
/// mapped to its frame in f64 (see [`cylinder`]; the quadratic's
/// cancellation near the apex put span ends 1.3e-5 of the view off in f32).
#[inline(always)]
pub fn cone(o: DVec3, d: DVec3, ra: f64, rb: f64) -> Option<Range64> {
    let slab = slab01(o.z, d.z)?;
    let k = rb - ra;
    let w0 = ra + k * o.z; // radius at the origin's height
    let wd = k * d.z;
    // q(t) = |xy(t)|^2 - (w0 + wd t)^2 = A t^2 + 2 B t + C
    let a = d.x * d.x + d.y * d.y - wd * wd;
    let b = o.x * d.x + o.y * d.y - w0 * wd;
    let c = o.x * o.x + o.y * o.y - w0 * w0;
    let mut out: Option<Range64> = None;
    // Within the slab only the nappe with a non-negative radius remains, so at
    // most one piece survives (both only through rounding next to the apex: the
    // frustum is convex, so take their hull).
    for p in cone_pieces([a, b, c], d.x * d.x + d.y * d.y + wd * wd).into_iter().flatten() {
        let Some(r) = and(p, slab) else { continue };
        // The other nappe: reject pieces whose midpoint has negative radius.
        let tm = match (r.0.is_finite(), r.2.is_finite()) {
            (true, true) => 0.5 * (r.0 + r.2),
            (true, false) => r.0,
            (false, true) => r.2,
            _ => 0.0,
        };
        if w0 + wd * tm < -1e-6 {
            continue;
        }
        out = Some(match out {
            None => r,
            Some(q) => {
                let (t0, s0) = if q.0 <= r.0 { (q.0, q.1) } else { (r.0, r.1) };
                let (t1, s1) = if q.2 >= r.2 { (q.2, q.3) } else { (r.2, r.3) };
                (t0, s0, t1, s1)
            }
        });
    }
    out
}

/// Where `A t^2 + 2 B t + C <= 0` (the double cone's inside), as up to two
/// pieces of the side; `A` is taken as 0 within 1e-12 of `norm` (the sum of
/// its terms' magnitudes).
#[inline(always)]
fn cone_pieces([a, b, c]: [f64; 3], norm: f64) -> [Option<Range64>; 2] {
    let full = (f64::NEG_INFINITY, sub::SIDE, f64::INFINITY, sub::SIDE);
    let mut pieces: [Option<Range64>; 2] = [None, None];
    if a.abs() <= 1e-12 * norm {
        // Linear: 2 B t + C <= 0 (ray parallel to a generator).
        if b == 0.0 {
            if c <= 0.0 {
                pieces[0] = Some(full);
            }
        } else {
            let t = -c / (2.0 * b);
            pieces[0] = Some(if b > 0.0 { (f64::NEG_INFINITY, sub::SIDE, t, sub::SIDE) } else { (t, sub::SIDE, f64::INFINITY, sub::SIDE) });
        }
        return pieces;
    }
    let disc = b * b - a * c;
    if disc < 0.0 {
        if a < 0.0 {
            pieces[0] = Some(full);
        }
        return pieces;
    }
    let q = -(b + disc.sqrt().copysign(b));
    let (mut t0, mut t1) = if q == 0.0 { (-b / a, -b / a) } else { (c / q, q / a) };
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if a > 0.0 {
        pieces[0] = Some((t0, sub::SIDE, t1, sub::SIDE));
    } else {
        pieces[0] = Some((f64::NEG_INFINITY, sub::SIDE, t0, sub::SIDE));
        pieces[1] = Some((t1, sub::SIDE, f64::INFINITY, sub::SIDE));
    }
    pieces
}

/// Half-space `n . p <= offset` (n unit length).
#[inline(always)]
pub fn half_space(o: Vec3, d: Vec3, n: Vec3, offset: f32) -> Option<Range> {
    let den = n.dot(d);
    let num = offset - n.dot(o);
    if den == 0.0 {
        return if num >= 0.0 { Some((f32::NEG_INFINITY, sub::SIDE, f32::INFINITY, sub::SIDE)) } else { None };
    }
    let t = num / den;
    Some(if den > 0.0 { (f32::NEG_INFINITY, sub::SIDE, t, sub::SIDE) } else { (t, sub::SIDE, f32::INFINITY, sub::SIDE) })
}

/// Is the local point inside the torus (major 1, minor `rho`, axis z)?
#[inline]
pub fn torus_contains(p: DVec3, rho: f64) -> bool {
    let q = (p.x * p.x + p.y * p.y).sqrt() - 1.0;
    q * q + p.z * p.z <= rho * rho
}

/// Torus around z, major radius 1, minor `rho` (a spindle torus when rho > 1).
/// Pushes up to two spans `(t_in, t_out)` (unclipped), in increasing order;
/// returns how many. The quartic is solved in f64 after moving the origin to the
/// ray's closest approach to the centre and normalising the direction (small,
/// well-scaled coefficients, no cubic term), roots are isolated through the
/// derivative, a depressed cubic solved in closed form (so grazing pairs are
/// not lost; [`quartic::negative_runs`]) and polished by Newton; a ring
/// torus's spans are the runs where the quartic is negative, a spindle
/// torus's come from classifying the midpoints between roots (see
/// [`torus_query`]).
pub fn torus(o: Vec3, d: Vec3, rho: f32, out: &mut [(f32, f32); 3]) -> usize {
    torus_tol(o, d, (rho, 0.0), out)
}

/// The torus polish tolerance a bake uses (the `torus` knob's default),
/// relative to the minor radius: on `benches/scenes/tori.json` (README, "Run
/// time against error") 1e-4 already gives the nearest hits of full f64
/// polishing on every error ray; the default keeps two decades of margin
/// (full polishing traces 32% slower: 0.0092 s against 0.0069 s at 480x270).
pub const TORUS_TOLERANCE: f32 = 1e-6;

/// [`torus`] with the roots polished only to `tol` times the minor radius
/// `rho` (the tube's size: a thin tube's roots are as good relative to it
/// as a fat one's; 0 polishes to full f64 precision): `shape` is
/// `(rho, tol)`. The `torus` knob of `rothray bench --knob`.
pub fn torus_tol(o: Vec3, d: Vec3, shape: (f32, f64), out: &mut [(f32, f32); 3]) -> usize {
    torus_tol64(o.as_dvec3(), d.as_dvec3(), shape, out)
}

/// [`torus_tol`] for a line given in f64 (the leaf table maps a torus's rays
/// in f64: see [`crate::LeafTable::spans_in`]).
pub fn torus_tol64(o: DVec3, d: DVec3, shape: (f32, f64), out: &mut [(f32, f32); 3]) -> usize {
    torus_query(o, d, shape, TorusAsk { range: (f32::NEG_INFINITY, f32::INFINITY), first_only: false }, out).0
}

/// What a torus query needs: spans on `range` (spans reaching past it may
/// come unclipped), and only the first one that `range` keeps, or all.
#[derive(Clone, Copy, Debug)]
pub struct TorusAsk {
    /// The ray's range in `t`.
    pub range: (f32, f32),
    /// A nearest-hit query: the first span that `range` keeps suffices.
    pub first_only: bool,
}

/// The line `o + t d` in the torus' frame as the quartic sees it: origin at
/// the closest approach `oc` to the centre, unit direction `dn`, `s = t |d| - tc`.
#[derive(Clone, Copy, Debug)]
struct TorusLine {
    dl: f64,
    dn: DVec3,
    tc: f64,
    oc: DVec3,
    /// Half the chord of the bounding sphere, slightly widened.
    h: f64,
}

/// Does the line `oc + s dn` (`oc` its point nearest the centre, `dn`
/// unit) pass through the hole of the ring torus of minor radius `rho` (in
/// its frame: major radius 1, axis z; `rho < 1`, else there is no hole)
/// without meeting it: does every point with `|s| <= h` (inside the
/// bounding sphere) and `|z| <= rho` (inside the slab, both with the slack
/// of [`TorusLine::new`]) lie nearer the axis
/// than `1 - rho`, within a relative margin of 1e-6? Then the quartic has no
/// root there. Over that chord the squared distance to the axis is convex,
/// so its ends decide. (Rays through the rings of a chain of tori, seen at
/// an angle, pass the sphere and slab tests and solved a quartic each.)
/// `torus8.rs` makes the same test on eight lanes, bit for bit.
#[inline(always)]
pub(crate) fn through_hole(oc: DVec3, dn: DVec3, (rho, h): (f64, f64)) -> bool {
    if !(rho < 1.0) {
        // A spindle or horn torus has no hole: near its axis is inside.
        return false;
    }
    // (Compares and picks, not `min` / `max`: the eight-lane version picks
    // the same way, NaN included.)
    let slab = rho * (1.0 + 1e-9);
    let (sa, sb) = ((-slab - oc.z) / dn.z, (slab - oc.z) / dn.z);
    let (s0, s1) = if sa < sb { (sa, sb) } else { (sb, sa) };
    let flat = dn.z == 0.0;
    let lo = if flat || !(s0 > -h) { -h } else { s0 };
    let hi = if flat || !(s1 < h) { h } else { s1 };
    let q = |s: f64| {
        let (x, y) = (oc.x + s * dn.x, oc.y + s * dn.y);
        x * x + y * y
    };
    let inner = (1.0 - rho) * (1.0 - rho) * (1.0 - 1e-6);
    q(lo) < inner && q(hi) < inner
}

impl TorusLine {
    /// `None` when the line misses the torus's bounding sphere or slab, or
    /// passes through its hole ([`through_hole`]).
    #[inline(always)]
    fn new(o: DVec3, d: DVec3, rho: f64) -> Option<TorusLine> {
        let dl = d.length();
        if !(dl > 0.0) {
            return None;
        }
        let dn = d / dl;
        let tc = -o.dot(dn);
        let oc = o + dn * tc;
        let rb = 1.0 + rho;
        let h2 = rb * rb - oc.length_squared();
        if h2 <= 0.0 {
            return None;
        }
        let h = h2.sqrt() * (1.0 + 1e-9) + 1e-12;
        // The solid lies in the slab |z| <= rho: a chord of the bounding sphere
        // that stays outside it meets nothing (no root, no inside), so the quartic
        // is skipped. (A thin torus fills little of its sphere.)
        let zr = dn.z.abs() * h;
        if oc.z - zr > rho * (1.0 + 1e-9) || oc.z + zr < -rho * (1.0 + 1e-9) {
            return None;
        }
        if through_hole(oc, dn, (rho, h)) {
            return None;
        }
        Some(TorusLine { dl, dn, tc, oc, h })
    }

    /// q(s) = (s^2 + e)^2 - 4 (a2 s^2 + 2 a1 s + a0), s = distance from oc,
    /// as `[c0, c1, c2]` of the depressed quartic.
    #[inline(always)]
    fn quartic(&self, rho: f64) -> [f64; 3] {
        let (oc, dn) = (self.oc, self.dn);
        let e = oc.length_squared() + 1.0 - rho * rho;
        let a2 = dn.x * dn.x + dn.y * dn.y;
        let a1 = oc.x * dn.x + oc.y * dn.y;
        let a0 = oc.x * oc.x + oc.y * oc.y;
        [e * e - 4.0 * a0, -8.0 * a1, 2.0 * e - 4.0 * a2]
    }

    #[inline(always)]
    fn t(&self, s: f64) -> f32 {
        ((s + self.tc) / self.dl) as f32
    }

    /// The window in `s` whose roots can matter on the `t` range: a root
    /// outside it lands outside the range once converted to f32 (the margin,
    /// 1e-6 of the range end's distance plus 1e-12 of the line's scale, is
    /// above f32 rounding and f64 error), so clipping makes any stand-in
    /// beyond it give the same span as the exact root would. (Against the
    /// root polished to the tolerance, the same up to that tolerance: near
    /// `t = 0` the margin is smaller than it.)
    #[inline(always)]
    fn window(&self, (tmin, tmax): (f32, f32)) -> (f64, f64) {
        let slack = |t: f32| 1e-6 * (t.abs() as f64 * self.dl) + 1e-12 * (self.tc.abs() + self.h);
        let lo = tmin as f64 * self.dl - self.tc - slack(tmin);
        let hi = tmax as f64 * self.dl - self.tc + slack(tmax);
        // Infinite or NaN ends: no window on that side.
        (if lo >= -f64::MAX { lo } else { f64::NEG_INFINITY }, if hi <= f64::MAX { hi } else { f64::INFINITY })
    }
}

/// The torus's spans for `ask`, with the place up to which they are exact:
/// `f32::INFINITY`, or with `first_only` the end of the first span the range
/// keeps that starts in the range, when later spans were left out, or where
/// the piece holding its skipped exit starts (the span then reads as ending
/// at infinity: past the exact place nothing is sure). Spans may reach past
/// the range (the caller clips).
///
/// A ring torus (`rho < 1`) is inside exactly where the quartic is negative
/// (q factors into `((r-1)^2 + z^2 - rho^2) ((r+1)^2 + z^2 - rho^2)`, whose
/// second factor is then positive), so its spans are the quartic's negative
/// runs, and only the roots that the range and `first_only` need are
/// polished: a shadow ray leaving the surface skips the roots behind it, a
/// nearest query the pair past its first span. A spindle torus also
/// contains the lemon where both factors are negative: its spans come from
/// every root, by classifying the points between them.
pub fn torus_query(o: DVec3, d: DVec3, shape: (f32, f64), ask: TorusAsk, out: &mut [(f32, f32); 3]) -> (usize, f32) {
    let rho = shape.0 as f64;
    if rho >= 1.0 {
        return (torus_by_midpoints(o, d, shape, out), f32::INFINITY);
    }
    match TorusPrep::new(o, d, rho) {
        Some(prep) => torus_query_prepped(&prep, shape, ask, out),
        None => (0, f32::INFINITY),
    }
}

/// What a ring torus's query computes before it looks at the query's range:
/// the line in the torus's frame, the quartic and its marks (the roots of
/// its derivative, a cubic). A packet makes it for its eight lanes together
/// in SIMD ([`crate::LeafTable::torus_prep8`], `torus8.rs`), bit for bit
/// as [`TorusPrep::new`]; each lane's query then finishes from its own
/// prep. The same numbers as [`torus_query`], which makes and uses it the
/// same way.
#[derive(Clone, Copy, Debug)]
pub struct TorusPrep {
    line: TorusLine,
    c: [f64; 3],
    marks: quartic::Marks,
    /// The entry of the first negative run, polished, when it is a root
    /// (a packet's prep polishes its lanes' entries together: `torus8.rs`).
    entry: Option<f64>,
}

impl TorusPrep {
    /// `None` when the line misses the torus's bounding sphere or slab
    /// (no spans). For a ring torus (`rho < 1`) only.
    #[inline(always)]
    pub fn new(o: DVec3, d: DVec3, rho: f64) -> Option<TorusPrep> {
        let line = TorusLine::new(o, d, rho)?;
        let c = line.quartic(rho);
        Some(TorusPrep { line, c, marks: quartic::Marks::new(&c, line.h), entry: None })
    }

    /// A prep made elsewhere the same way (`torus8.rs`: eight lanes at
    /// once): the line `(dl, dn, tc, oc, h)`, the quartic and its marks.
    #[inline(always)]
    pub(crate) fn from_parts((dl, dn, tc, oc, h): (f64, DVec3, f64, DVec3, f64), c: [f64; 3], marks: quartic::Marks) -> TorusPrep {
        TorusPrep { line: TorusLine { dl, dn, tc, oc, h }, c, marks, entry: None }
    }

    /// The quartic `[c0, c1, c2]` and its marks.
    #[inline(always)]
    pub(crate) fn quartic(&self) -> (&[f64; 3], &quartic::Marks) {
        (&self.c, &self.marks)
    }

    /// Where the line's `t = 0` lies in the quartic's `s`.
    #[inline(always)]
    pub(crate) fn line_start(&self) -> f64 {
        -self.line.tc
    }

    /// The polished entry of the first negative run, when known.
    #[cfg(test)]
    pub(crate) fn entry(&self) -> Option<f64> {
        self.entry
    }

    /// The prep with its first run's entry (`Some`: polished to the
    /// query's `eps`, exactly as `RunEnd::polish` gives it).
    #[cfg(test)]
    pub(crate) fn with_entry(self, entry: Option<f64>) -> TorusPrep {
        TorusPrep { entry, ..self }
    }

    /// Sets the first run's entry, polished to the query's `eps` exactly as
    /// `RunEnd::polish` gives it (in place: the prep is 200 bytes; made
    /// anew, tori traced 1-2% slower).
    #[inline(always)]
    pub(crate) fn set_entry(&mut self, x: f64) {
        self.entry = Some(x);
    }
}

/// [`torus_query`] of a ring torus from its [`TorusPrep`].
pub fn torus_query_prepped(prep: &TorusPrep, shape: (f32, f64), ask: TorusAsk, out: &mut [(f32, f32); 3]) -> (usize, f32) {
    let rho = shape.0 as f64;
    let (line, c) = (&prep.line, prep.c);
    let eps = shape.1 * rho;
    let mut runs = [(quartic::RunEnd::Exact(0.0), quartic::RunEnd::Exact(0.0)); 3];
    let nr = quartic::negative_runs(&prep.marks, &mut runs);
    let (w_lo, w_hi) = line.window(ask.range);
    let (tmin, tmax) = ask.range;
    let mut count = 0;
    for (k, &(e0, e1)) in runs[..nr].iter().enumerate() {
        if e1.hi() < w_lo {
            continue; // wholly before the range
        }
        if e0.lo() > w_hi {
            break; // this run and the rest lie past it
        }
        // A root whose piece straddles an end of the window lies on the side
        // the quartic's sign there says (the piece is monotone): a shadow
        // ray leaving the surface skips the root at its origin this way.
        let inside_at = |s: f64| quartic::q(&c, s) < 0.0;
        if e1.lo() < w_lo && !inside_at(w_lo) {
            continue; // the run ends before the window
        }
        if e0.hi() > w_hi && !inside_at(w_hi) {
            break; // the run starts past the window
        }
        let need0 = e0.hi() >= w_lo && !(e0.lo() < w_lo && inside_at(w_lo));
        let need1 = e1.lo() <= w_hi && !(e1.hi() > w_hi && inside_at(w_hi));
        // An end outside the window is not polished: it lies beyond the
        // range's end, and infinity says so to the caller's clip whatever
        // the rounding (a stand-in converted to t could round onto tmin).
        if ask.first_only && need0 && need1 && matches!(e1, quartic::RunEnd::Root(_)) {
            // A nearest query needs this span's exit only where it lies
            // before the limit the answer is exact to: with the entry in the
            // range and the exit's piece starting well past it (1% of the
            // tube's radius: not a grazing chord), the exit's polish is
            // skipped and the answer is exact up to where that piece starts
            // (tori: one polish of two per hit; the entry is polished as
            // `polish_pair` would, bit for bit).
            let x0 = polish_entry(prep, k, e0, eps);
            let (t0, lo1) = (line.t(x0), e1.lo());
            let t_lo = line.t(lo1);
            if t0 >= tmin && t0 < tmax && lo1 - x0 > 0.01 * rho && t_lo > t0 {
                out[count] = (t0, f32::INFINITY);
                return (count + 1, t_lo);
            }
            let x1 = e1.polish(&c, eps);
            out[count] = (t0, line.t(x1));
            count += 1;
            let t1 = line.t(x1);
            if t1.min(tmax) > t0.max(tmin) && t0 >= tmin {
                let more = runs[k + 1..nr].iter().any(|r| r.0.lo() <= w_hi);
                return (count, if more { t1 } else { f32::INFINITY });
            }
            continue;
        }
        let (x0, x1) = match (need0, need1) {
            (true, true) if k == 0 && prep.entry.is_some() => (polish_entry(prep, k, e0, eps), e1.polish(&c, eps)),
            (true, true) => quartic::RunEnd::polish_pair(&c, e0, e1, eps),
            (true, false) => (polish_entry(prep, k, e0, eps), f64::INFINITY),
            (false, true) => (f64::NEG_INFINITY, e1.polish(&c, eps)),
            (false, false) => (f64::NEG_INFINITY, f64::INFINITY),
        };
        let (t0, t1) = (line.t(x0), line.t(x1));
        out[count] = (t0, t1);
        count += 1;
        // A span the range starts inside of does not stop the query: its exit
        // at the place the result stops being exact would not be sure to a
        // caller (which redoes the query in full).
        if ask.first_only && t1.min(tmax) > t0.max(tmin) && t0 >= tmin {
            let more = runs[k + 1..nr].iter().any(|r| r.0.lo() <= w_hi);
            return (count, if more { t1 } else { f32::INFINITY });
        }
    }
    (count, f32::INFINITY)
}

/// Run `k`'s entry `e0`, polished to `eps`: the prep's when `k` is the first
/// run and the prep has it (the same bits: `polish_pair` gives each root as
/// `polish` does).
#[inline(always)]
fn polish_entry(prep: &TorusPrep, k: usize, e0: quartic::RunEnd, eps: f64) -> f64 {
    match prep.entry {
        Some(x) if k == 0 => x,
        _ => e0.polish(&prep.c, eps),
    }
}

/// The spans from every root, the pieces between them classified by their
/// midpoints: the spindle torus's path, and for a ring torus the reference
/// its lazy path is tested against.
#[doc(hidden)]
pub fn torus_by_midpoints(o: DVec3, d: DVec3, shape: (f32, f64), out: &mut [(f32, f32); 3]) -> usize {
    let rho = shape.0 as f64;
    let Some(line) = TorusLine::new(o, d, rho) else { return 0 };
    let c = line.quartic(rho);
    spindle_spans(&line, &c, (rho, shape.1 * rho), out)
}

/// A spindle torus's spans: every root, the pieces between them classified
/// by their midpoints.
fn spindle_spans(line: &TorusLine, c: &[f64; 3], (rho, eps): (f64, f64), out: &mut [(f32, f32); 3]) -> usize {
    let h = line.h;
    let mut roots = [0.0; 4];
    let n = quartic::depressed_quartic_roots(c, h, eps, &mut roots);
    // Breakpoints: -h, roots..., h; classify each piece by its midpoint.
    let mut pts = [0.0f64; 8];
    pts[0] = -h;
    let mut np = 1;
    for &r in &roots[..n.min(4)] {
        if r > pts[np - 1] {
            pts[np] = r;
            np += 1;
        }
    }
    if h > pts[np - 1] {
        pts[np] = h;
        np += 1;
    }
    let mut count = 0;
    let mut open: Option<f64> = None;
    for i in 0..np - 1 {
        let m = 0.5 * (pts[i] + pts[i + 1]);
        let inside = torus_contains(line.oc + line.dn * m, rho);
        match (inside, open) {
            (true, None) => open = Some(pts[i]),
            (false, Some(s)) => {
                if count < out.len() {
                    out[count] = (line.t(s), line.t(pts[i]));
                    count += 1;
                }
                open = None;
            }
            _ => {}
        }
    }
    if let Some(s) = open {
        if count < out.len() {
            out[count] = (line.t(s), line.t(pts[np - 1]));
            count += 1;
        }
    }
    count
}

/// f64 reference for tests: the torus crossings by dense sampling plus bisection.
#[doc(hidden)]
pub fn torus_reference(o: DVec3, d: DVec3, rho: f64, t0: f64, t1: f64, samples: usize) -> Vec<f64> {
    let mut res = Vec::new();
    let f = |t: f64| torus_contains(o + d * t, rho);
    let mut prev_t = t0;
    let mut prev = f(t0);
    for i in 1..=samples {
        let t = t0 + (t1 - t0) * i as f64 / samples as f64;
        let cur = f(t);
        if cur != prev {
            let (mut a, mut b) = (prev_t, t);
            for _ in 0..80 {
                let m = 0.5 * (a + b);
                if f(m) == prev {
                    a = m
                } else {
                    b = m
                }
            }
            res.push(0.5 * (a + b));
        }
        prev = cur;
        prev_t = t;
    }
    res
}
