#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
//! The convex analytic kernels (ball, ellipsoid, box, cylinder, cone, half-space) for eight
//! rays at once, struct-of-arrays: a packet's lanes are mapped into the
//! leaf's local space and solved with 8-lane SIMD, AVX where the CPU has it
//! (chosen at run time), two SSE2 halves otherwise.
//!
//! Every lane gets exactly what [`LeafTable::spans_in`] computes for its ray
//! before clipping, bit for bit: the same IEEE operations on the same values
//! in the same order as the scalar map and kernels (no fused multiply-add,
//! whose single rounding would differ), with selects where the scalar code
//! branches. All of them are solved in f64 (four lanes a register with
//! AVX), as the scalar path does: a ball (a sphere under a similarity) from
//! its f32 centre and radius in world space, a half-space against its f64
//! world plane, ellipsoids, cylinders and boxes through their f64 maps
//! ([`crate::table64`]); every lane is done (f64
//! needs no rescaling). Tori, sweeps and meshes have no packet kernel here.

use glam::{DMat3, DVec3, Vec3};

use crate::kernels::{sub, TorusPrep};
use crate::simd8::D8;
#[cfg(target_arch = "x86_64")]
use crate::simd8::{avx512_d, avx_d, sse_d};
use crate::table::{LeafKind, LeafTable};
use crate::torus8::{self, dot3};

/// Per lane, a leaf's unclipped range along the lane's ray (as the scalar
/// kernel's [`crate::kernels::Range`]), where bit k of `hit` is set.
#[derive(Clone, Copy, Debug, Default)]
pub struct Ranges8 {
    /// Lanes computed here (the others go the scalar way).
    pub done: u32,
    /// Lanes (among `done`) whose line meets the leaf.
    pub hit: u32,
    /// Entry parameters.
    pub t0: [f32; 8],
    /// Entry sub-surfaces.
    pub s0: [u32; 8],
    /// Exit parameters.
    pub t1: [f32; 8],
    /// Exit sub-surfaces.
    pub s1: [u32; 8],
}

/// Whether [`LeafTable::ranges8_beside`] pays, per leaf kind, learned from
/// the solves' answers: a score that rises by the time a pretest saves on
/// a solve whose lanes all miss and falls by what it costs on one that some
/// lane meets (their ratio from `cargo bench --bench kernels --
/// "x8 (packet|beside)"`: for a ball it saves ten times what it costs; for
/// a cylinder about as much, and for a cone 3 to 2, both weighed 1 to 1).
/// The pretests run while the score is positive. Either way the answers
/// are the same bits; only the time differs. (The share of solves with
/// every lane missing is 53-80% on a forest's children, 56-61% on the
/// capsules' leaves, 30-45% on logo's and gear's: always on, the pretests
/// cost logo 1-3%; always off, they lose capsules 3%.)
#[derive(Clone, Copy, Debug, Default)]
pub struct BesideOdds([i16; 16]);

impl BesideOdds {
    /// The score's bounds (how long a change of scene takes to turn it).
    const LIMIT: i16 = 64;

    /// Do the pretests run for leaves of `kind` now? (For tests.)
    #[cfg(test)]
    fn pays(&self, kind: LeafKind) -> bool {
        beside_weights(kind).is_some() && self.0[kind as usize & 15] > 0
    }

    /// [`LeafTable::ranges8_beside`] or [`LeafTable::ranges8`] of leaf `i`,
    /// as the score of its kind says, into `out`; then the score learns
    /// from the answer.
    #[inline(always)]
    pub fn solve(&mut self, leaves: &LeafTable, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        let kind = leaves.kind[i as usize];
        let Some((gain, cost)) = beside_weights(kind) else {
            return leaves.ranges8(i, rays, lanes, out);
        };
        let s = &mut self.0[kind as usize & 15];
        if *s > 0 {
            leaves.ranges8_beside(i, rays, lanes, out);
        } else {
            leaves.ranges8(i, rays, lanes, out);
        }
        *s = if out.hit & lanes == 0 { (*s + gain).min(Self::LIMIT) } else { (*s - cost).max(-Self::LIMIT) };
    }
}

/// What a kind's miss pretest saves on a solve whose lanes all miss, and
/// what it costs on another, in the same unit (see [`BesideOdds`]); `None`
/// for the kinds without one.
fn beside_weights(kind: LeafKind) -> Option<(i16, i16)> {
    match kind {
        LeafKind::Sphere => Some((10, 1)),
        LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone => Some((1, 1)),
        _ => None,
    }
}

impl Ranges8 {
    /// The answer where every lane of `lanes` misses the leaf (the
    /// parameters are not read).
    fn missed(lanes: u32) -> Ranges8 {
        let nan = [f32::NAN; 8];
        Ranges8 { done: lanes, hit: 0, t0: nan, s0: [sub::SIDE; 8], t1: nan, s1: [sub::SIDE; 8] }
    }
}

/// Eight world rays, struct-of-arrays (built once per packet).
#[derive(Clone, Copy, Debug, Default)]
pub struct Rays8Soa {
    /// Origins per axis.
    o: [[f32; 8]; 3],
    /// Directions per axis.
    d: [[f32; 8]; 3],
}

impl Rays8Soa {
    /// The rays `o[k] + t d[k]`.
    pub fn new(o: &[Vec3; 8], d: &[Vec3; 8]) -> Self {
        Rays8Soa {
            o: std::array::from_fn(|a| std::array::from_fn(|k| o[k][a])),
            d: std::array::from_fn(|a| std::array::from_fn(|k| d[k][a])),
        }
    }

    /// The rays `ray(k)` (origin, direction) of the eight lanes.
    #[inline(always)]
    pub fn from_lanes(ray: impl Fn(usize) -> (Vec3, Vec3)) -> Self {
        let mut r = Rays8Soa::default();
        for k in 0..8 {
            let (o, d) = ray(k);
            for a in 0..3 {
                (r.o[a][k], r.d[a][k]) = (o[a], d[a]);
            }
        }
        r
    }

    /// Ray `k`: origin and direction.
    pub fn lane(&self, k: usize) -> (Vec3, Vec3) {
        (Vec3::new(self.o[0][k], self.o[1][k], self.o[2][k]), Vec3::new(self.d[0][k], self.d[1][k], self.d[2][k]))
    }
}

/// `kernels::ball` (f64, world units) for `o` relative to the centre:
/// where the line meets the ball, and the range (f64).
#[inline(always)]
fn ball<D: D8>(o: &[D; 3], d: &[D; 3], r: f64) -> (D, D, D) {
    let a = dot3(d, d);
    let b = dot3(o, d);
    let s = b.div(a);
    let f = [o[0].sub(d[0].mul(s)), o[1].sub(d[1].mul(s)), o[2].sub(d[2].mul(s))];
    let rr = D::splat(r * r);
    let disc = a.mul(rr.sub(dot3(&f, &f)));
    let zero = D::splat(0.0);
    let hit = disc.ge(zero);
    let c = dot3(o, o).sub(rr);
    let q = b.add(disc.sqrt().copysign(b)).neg();
    let q0 = q.eq(zero);
    let t0 = D::select(q0, zero, c.div(q));
    let t1 = D::select(q0, zero, q.div(a));
    let keep = t0.le(t1);
    (hit, D::select(keep, t0, t1), D::select(keep, t1, t0))
}

/// The lanes sure to miss where `a t^2 + 2 b t + c <= 0` (a cylinder's or
/// cone's side, `a > 0`: a bounded piece of the line, on one nappe) meets
/// the slab `0 <= oz + t dz <= 1`, told without a division or a square
/// root. In `z` the piece is where `F(z) = a (z - oz)^2 + 2 b dz (z - oz) +
/// c dz^2 <= 0`; it misses the slab when `F` is positive at both ends and
/// its vertex lies outside, or `b^2 - a c < 0`. Each test keeps a margin
/// of [`MISS_TOL`] of its terms' magnitudes, far above the rounding of the
/// exact solve, so a lane called a miss here is one the solve misses: its
/// computed roots stray from the true ones by some 1e-8 of their scale
/// at worst (a root near a tangency, through the square root of a
/// cancelled difference).
#[inline(always)]
fn side_slab_miss<D: D8>(a: D, b: D, c: D, (oz, dz): (D, D), lin_tol: D) -> D {
    let zero = D::splat(0.0);
    let tol = D::splat(MISS_TOL);
    let bd = b.mul(dz);
    let cd = c.mul(dz.mul(dz));
    let (e0, e1) = (oz.neg(), D::splat(1.0).sub(oz));
    let (pos0, ae0) = positive_at(a, (bd, cd), e0);
    let (pos1, ae1) = positive_at(a, (bd, cd), e1);
    // The vertex z* = oz - bd / a, against the ends: a e0 <= -bd <= a e1.
    let nbd = bd.neg();
    let below = ae0.sub(nbd).gt(tol.mul(abs8(ae0).add(abs8(bd))));
    let above = nbd.sub(ae1).gt(tol.mul(abs8(ae1).add(abs8(bd))));
    let off_slab = pos0.and(pos1).and(below.or(above)).and(dz.eq(zero).andnot(all_d()));
    let no_line = b.mul(b).sub(a.mul(c)).neg().gt(tol.mul(b.mul(b).add(abs8(a.mul(c)))));
    a.gt(lin_tol).and(off_slab.or(no_line))
}

/// `side_slab_miss`'s `F` at `z = oz + e`, `a e^2 + 2 bd e + cd`: is it
/// positive past the margin? And `a e`. (A function, not a closure: see
/// `quadrics8`.)
#[inline(always)]
fn positive_at<D: D8>(a: D, (bd, cd): (D, D), e: D) -> (D, D) {
    let ae = a.mul(e);
    let aee = ae.mul(e);
    let two_bd_e = D::splat(2.0).mul(bd).mul(e);
    let f = aee.add(two_bd_e).add(cd);
    let m = abs8(aee).add(abs8(two_bd_e)).add(abs8(cd));
    (f.gt(D::splat(MISS_TOL).mul(m)), ae)
}

/// The margin of the miss pretests, relative to the magnitude of the
/// terms compared (see [`side_slab_miss`]).
const MISS_TOL: f64 = 1e-6;

/// The lanes sure to miss the ball of radius squared `rr` about the origin
/// (`o` relative to its centre), told without a division or a square root:
/// `a (|o|^2 - rr) - b^2 > 0` (the line's distance from the centre, squared,
/// past `rr`, times `a`), with the margin of [`side_slab_miss`].
#[inline(always)]
fn ball_miss<D: D8>(o: &[D; 3], d: &[D; 3], rr: D) -> D {
    let (a, b, oo) = (dot3(d, d), dot3(o, d), dot3(o, o));
    let (aoo, arr, bb) = (a.mul(oo), a.mul(rr), b.mul(b));
    aoo.sub(arr).sub(bb).gt(D::splat(MISS_TOL).mul(aoo.add(arr).add(bb)))
}

/// Row `a` of `m v` in `map64`'s order: (x_axis v.x + y_axis v.y) + z_axis v.z.
#[inline(always)]
fn map_row<D: D8>(m: &DMat3, a: usize, v: &[D; 3]) -> D {
    D::splat(m.x_axis[a]).mul(v[0]).add(D::splat(m.y_axis[a]).mul(v[1])).add(D::splat(m.z_axis[a]).mul(v[2]))
}

/// The all-true f64 mask.
#[inline(always)]
fn all_d<D: D8>() -> D {
    D::splat(f64::from_bits(u64::MAX))
}

/// `kernels::slab01` (f64): the range of the slab `0 <= z <= 1`.
#[inline(always)]
fn slab01<D: D8>(oz: D, dz: D) -> R8<D> {
    let zero = D::splat(0.0);
    let one = D::splat(1.0);
    let sd = |id: u32| D::splat(id as f64);
    let flat = dz.eq(zero);
    let ta = oz.neg().div(dz);
    let tb = one.sub(oz).div(dz);
    let ord = ta.le(tb);
    let (inf, ninf) = (D::splat(f64::INFINITY), D::splat(f64::NEG_INFINITY));
    R8 {
        hit: D::select(flat, zero.le(oz).and(oz.le(one)), all_d()),
        t0: D::select(flat, ninf, D::select(ord, ta, tb)),
        s0: D::select(flat, sd(sub::CAP0), D::select(ord, sd(sub::CAP0), sd(sub::CAP1))),
        t1: D::select(flat, inf, D::select(ord, tb, ta)),
        s1: D::select(flat, sd(sub::CAP1), D::select(ord, sd(sub::CAP1), sd(sub::CAP0))),
    }
}

/// `kernels::and` (f64) of two ranges in lanes: the later entry and the
/// earlier exit, each tied to `a`; `hit` where both hit and the entry is
/// not past the exit.
#[inline(always)]
fn and8<D: D8>(a: R8<D>, b: R8<D>) -> R8<D> {
    let e = a.t0.ge(b.t0);
    let x = a.t1.le(b.t1);
    let t0 = D::select(e, a.t0, b.t0);
    let t1 = D::select(x, a.t1, b.t1);
    R8 { hit: a.hit.and(b.hit).and(t0.le(t1)), t0, s0: D::select(e, a.s0, b.s0), t1, s1: D::select(x, a.s1, b.s1) }
}

/// `kernels::cylinder` (f64, in the cylinder's frame).
#[inline(always)]
fn cylinder<D: D8>(o: &[D; 3], d: &[D; 3]) -> R8<D> {
    let zero = D::splat(0.0);
    let one = D::splat(1.0);
    let (a, b, rr) = cylinder_quad(o, d);
    let axial = a.eq(zero);
    let r = b.div(a);
    let fx = o[0].sub(d[0].mul(r));
    let fy = o[1].sub(d[1].mul(r));
    let disc = a.mul(one.sub(fx.mul(fx).add(fy.mul(fy))));
    let c = rr.sub(one);
    let q = b.add(disc.sqrt().copysign(b)).neg();
    let q0 = q.eq(zero);
    let t0 = D::select(q0, zero, c.div(q));
    let t1 = D::select(q0, zero, q.div(a));
    let keep = t0.le(t1);
    let axial_hit = rr.gt(one).andnot(all_d());
    let side_id = D::splat(sub::SIDE as f64);
    let side = R8 {
        hit: D::select(axial, axial_hit, disc.ge(zero)),
        t0: D::select(axial, D::splat(f64::NEG_INFINITY), D::select(keep, t0, t1)),
        s0: side_id,
        t1: D::select(axial, D::splat(f64::INFINITY), D::select(keep, t1, t0)),
        s1: side_id,
    };
    and8(side, slab01(o[2], d[2]))
}

/// The unit cylinder's side along the lanes' lines: `a t^2 + 2 b t + rr
/// - 1 <= 0` inside (`a = |d_xy|^2`, `b = o_xy . d_xy`, `rr = |o_xy|^2`).
#[inline(always)]
fn cylinder_quad<D: D8>(o: &[D; 3], d: &[D; 3]) -> (D, D, D) {
    let a = d[0].mul(d[0]).add(d[1].mul(d[1]));
    let b = o[0].mul(d[0]).add(o[1].mul(d[1]));
    let rr = o[0].mul(o[0]).add(o[1].mul(o[1]));
    (a, b, rr)
}

/// `|x|` in lanes.
#[inline(always)]
fn abs8<D: D8>(x: D) -> D {
    x.copysign(D::splat(0.0))
}

/// A piece of a cone cut to the slab, dropped where its midpoint (its
/// finite end, or 0) has a negative radius `w0 + wd t` (the other nappe),
/// as `kernels::cone` does.
#[inline(always)]
fn on_nappe<D: D8>(r: R8<D>, w0: D, wd: D) -> R8<D> {
    let inf = D::splat(f64::INFINITY);
    let (f0, f1) = (inf.gt(abs8(r.t0)), inf.gt(abs8(r.t1)));
    let mid = D::splat(0.5).mul(r.t0.add(r.t1));
    let tm = D::select(f0, D::select(f1, mid, r.t0), D::select(f1, r.t1, D::splat(0.0)));
    let low = D::splat(-1e-6).gt(w0.add(wd.mul(tm)));
    R8 { hit: low.andnot(r.hit), ..r }
}

/// A cone's quadratic along the lanes' lines (`kernels::cone_pieces`):
/// `a t^2 + 2 b t + c <= 0` inside the double cone of radius `w0 + wd t`,
/// linear where `|a| <= lin_tol`.
struct ConeQuad<D> {
    w0: D,
    wd: D,
    a: D,
    b: D,
    c: D,
    lin_tol: D,
}

impl<D: D8> ConeQuad<D> {
    #[inline(always)]
    fn new(o: &[D; 3], d: &[D; 3], ra: f64, rb: f64) -> Self {
        let k = D::splat(rb - ra);
        let w0 = D::splat(ra).add(k.mul(o[2]));
        let wd = k.mul(d[2]);
        let dxy = d[0].mul(d[0]).add(d[1].mul(d[1]));
        let a = dxy.sub(wd.mul(wd));
        let b = o[0].mul(d[0]).add(o[1].mul(d[1])).sub(w0.mul(wd));
        let c = o[0].mul(o[0]).add(o[1].mul(o[1])).sub(w0.mul(w0));
        let norm = dxy.add(wd.mul(wd));
        ConeQuad { w0, wd, a, b, c, lin_tol: D::splat(1e-12).mul(norm) }
    }
}

/// `kernels::cone` (f64, in the frustum's frame, radius `ra + (rb - ra) z`
/// over `0 <= z <= 1`): the slab, the double cone's up to two pieces
/// (`cone_pieces`, its branches as selects in the same order), each cut to
/// the slab and dropped on the other nappe, then their hull. (No closures:
/// see `quadrics8`.)
#[inline(always)]
fn cone<D: D8>(o: &[D; 3], d: &[D; 3], ra: f64, rb: f64) -> R8<D> {
    let zero = D::splat(0.0);
    let (inf, ninf) = (D::splat(f64::INFINITY), D::splat(f64::NEG_INFINITY));
    let side = D::splat(sub::SIDE as f64);
    let slab = slab01(o[2], d[2]);
    let ConeQuad { w0, wd, a, b, c, lin_tol } = ConeQuad::new(o, d, ra, rb);
    // `cone_pieces`: linear within 1e-12 of `norm`.
    let lin = lin_tol.ge(abs8(a));
    let b0 = b.eq(zero);
    // Two divisions only where a lane reads them (a line near a generator,
    // a root at 0: rare): each one's result is read under its own mask
    // below. Division is the kernels' bottleneck (f64 `vdivpd`: some 16
    // cycles a register).
    let tl = if lin.bitmask() != 0 { c.neg().div(D::splat(2.0).mul(b)) } else { zero };
    let bpos = b.gt(zero);
    // Linear: b = 0 gives the whole line where c <= 0; else one half-line.
    let lin_hit = D::select(b0, c.le(zero), all_d());
    let lin_t0 = D::select(b0, ninf, D::select(bpos, ninf, tl));
    let lin_t1 = D::select(b0, inf, D::select(bpos, tl, inf));
    // Quadratic.
    let disc = b.mul(b).sub(a.mul(c));
    let neg_disc = zero.gt(disc);
    let aneg = zero.gt(a);
    let q = b.add(disc.sqrt().copysign(b)).neg();
    let q0 = q.eq(zero);
    let mb = if q0.bitmask() != 0 { b.neg().div(a) } else { zero };
    let r0 = D::select(q0, mb, c.div(q));
    let r1 = D::select(q0, mb, q.div(a));
    let sw = r0.gt(r1);
    let (u0, u1) = (D::select(sw, r1, r0), D::select(sw, r0, r1));
    let apos = a.gt(zero);
    // Piece 0: the whole line (disc < 0, a < 0), [u0, u1] (a > 0), or
    // (-inf, u0] (else); piece 1 only in that last case: [u1, inf).
    let quad0_t0 = D::select(neg_disc, ninf, D::select(apos, u0, ninf));
    let quad0_t1 = D::select(neg_disc, inf, D::select(apos, u1, u0));
    let quad0_hit = D::select(neg_disc, aneg, all_d());
    let quad1_hit = neg_disc.andnot(apos.andnot(all_d()));
    let p0 = R8 {
        hit: D::select(lin, lin_hit, quad0_hit),
        t0: D::select(lin, lin_t0, quad0_t0),
        s0: side,
        t1: D::select(lin, lin_t1, quad0_t1),
        s1: side,
    };
    let p1 = R8 { hit: lin.andnot(quad1_hit), t0: u1, s0: side, t1: inf, s1: side };
    let c0 = on_nappe(and8(p0, slab), w0, wd);
    let c1 = on_nappe(and8(p1, slab), w0, wd);
    // The hull: piece 0 alone, piece 1 alone, or both (ties to piece 0).
    let both = c0.hit.and(c1.hit);
    let e = D::select(both, c0.t0.le(c1.t0), c0.hit);
    let x = D::select(both, c0.t1.ge(c1.t1), c0.hit);
    R8 {
        hit: D::select(c0.hit, all_d(), c1.hit),
        t0: D::select(e, c0.t0, c1.t0),
        s0: D::select(e, c0.s0, c1.s0),
        t1: D::select(x, c0.t1, c1.t1),
        s1: D::select(x, c0.s1, c1.s1),
    }
}

/// The lanes' origins relative to point `c` (exact in f64) and their
/// directions, in f64.
#[inline(always)]
fn rel_lines<D: D8>(rays: &Rays8Soa, c: DVec3) -> ([D; 3], [D; 3]) {
    let o = [D::widen(&rays.o[0]).sub(D::splat(c.x)), D::widen(&rays.o[1]).sub(D::splat(c.y)), D::widen(&rays.o[2]).sub(D::splat(c.z))];
    (o, [D::widen(&rays.d[0]), D::widen(&rays.d[1]), D::widen(&rays.d[2])])
}

/// A kernel's answer for the lanes `lanes`, every one of them done.
#[inline(always)]
fn record<D: D8>(r: R8<D>, lanes: u32) -> Ranges8 {
    Ranges8 { done: lanes, hit: r.hit.bitmask() & lanes, t0: r.t0.narrow(), s0: r.s0.store_u32(), t1: r.t1.narrow(), s1: r.s1.store_u32() }
}

/// A kernel's answer in lanes: where the line meets the solid, and the range.
#[derive(Clone, Copy)]
struct R8<V> {
    hit: V,
    t0: V,
    s0: V,
    t1: V,
    s1: V,
}

/// `kernels::cuboid64` on `[mn, mx]` (f64, in the box's frame).
#[inline(always)]
fn cuboid<D: D8>(o: &[D; 3], d: &[D; 3], mn: [f64; 3], mx: [f64; 3]) -> R8<D> {
    let zero = D::splat(0.0);
    let mut t_in = D::splat(f64::NEG_INFINITY);
    let mut t_out = D::splat(f64::INFINITY);
    let (mut s_in, mut s_out) = (zero, zero);
    let mut ok = all_d::<D>();
    for a in 0..3 {
        let flat = d[a].eq(zero);
        let (lo, hi) = (D::splat(mn[a]), D::splat(mx[a]));
        // A ray parallel to the slab misses when outside it, else skips the axis.
        ok = ok.and(D::select(flat, o[a].ge(lo).and(hi.ge(o[a])), all_d()));
        let inv = D::splat(1.0).div(d[a]);
        let ta = lo.sub(o[a]).mul(inv);
        let tb = hi.sub(o[a]).mul(inv);
        let ord = ta.le(tb);
        let tn = D::select(ord, ta, tb);
        let tf = D::select(ord, tb, ta);
        let sd = |id: u32| D::splat(id as f64);
        let sn = D::select(ord, sd(a as u32 * 2), sd(a as u32 * 2 + 1));
        let sf = D::select(ord, sd(a as u32 * 2 + 1), sd(a as u32 * 2));
        let up_in = flat.andnot(tn.gt(t_in));
        t_in = D::select(up_in, tn, t_in);
        s_in = D::select(up_in, sn, s_in);
        let up_out = flat.andnot(t_out.gt(tf));
        t_out = D::select(up_out, tf, t_out);
        s_out = D::select(up_out, sf, s_out);
    }
    R8 { hit: ok.and(t_in.le(t_out)), t0: t_in, s0: s_in, t1: t_out, s1: s_out }
}

/// `kernels::half_space64` for `n . (q + t d) <= w` (f64, world units
/// relative to the plane's anchor; `dot64`'s order).
#[inline(always)]
fn half_space<D: D8>(q: &[D; 3], d: &[D; 3], n: [f64; 3], w: f64) -> R8<D> {
    let nv = [D::splat(n[0]), D::splat(n[1]), D::splat(n[2])];
    let dot = |a: &[D; 3]| nv[0].mul(a[0]).add(nv[1].mul(a[1])).add(nv[2].mul(a[2]));
    let den = dot(d);
    let num = D::splat(w).sub(dot(q));
    let zero = D::splat(0.0);
    let flat = den.eq(zero);
    let t = num.div(den);
    let up = den.gt(zero);
    let (inf, ninf) = (D::splat(f64::INFINITY), D::splat(f64::NEG_INFINITY));
    let side = D::splat(sub::SIDE as f64);
    R8 {
        hit: D::select(flat, num.ge(zero), all_d()),
        t0: D::select(flat, ninf, D::select(up, ninf, t)),
        s0: side,
        t1: D::select(flat, inf, D::select(up, t, inf)),
        s1: side,
    }
}

impl LeafTable {
    /// Does leaf `i` have a packet kernel ([`LeafTable::ranges8`])?
    #[inline]
    pub fn has_kernel8(&self, i: u32) -> bool {
        matches!(
            self.kind[i as usize],
            LeafKind::Sphere | LeafKind::Ellipsoid | LeafKind::Cuboid | LeafKind::Cylinder | LeafKind::Cone | LeafKind::HalfSpace
        )
    }

    /// Per lane k of `lanes`, the unclipped range of leaf `i` (which must
    /// have a packet kernel) along the world line of ray k of `rays`, into
    /// `out`: what [`LeafTable::spans_in`] computes before clipping, bit for
    /// bit, for the lanes it marks done.
    #[inline]
    pub fn ranges8(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        self.ranges8_with::<false>(i, rays, lanes, out)
    }

    /// [`LeafTable::ranges8`] for lanes likely to pass beside the leaf (a
    /// wide union's child or a small object whose box they meet): the same
    /// answers, told at once without solving when the miss pretests
    /// ([`side_slab_miss`], [`ball_miss`]) find every lane a miss. Those
    /// cost a cylinder's solve a third more where some lane is solved
    /// (`cargo bench --bench kernels -- "leaf/cylinder x8"`), and save a
    /// third to a half where none is: [`BesideOdds`] tells when they pay.
    #[inline]
    pub fn ranges8_beside(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        self.ranges8_with::<true>(i, rays, lanes, out)
    }

    /// [`LeafTable::ranges8`], with the miss pretests when `BESIDE`.
    #[inline(always)]
    fn ranges8_with<const BESIDE: bool>(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F.
                return unsafe { self.ranges8_avx512::<BESIDE>(i, rays, lanes, out) };
            }
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the CPU has AVX.
                return unsafe { self.ranges8_avx::<BESIDE>(i, rays, lanes, out) };
            }
            self.ranges8_in::<sse_d::SseD, BESIDE>(i, rays, lanes, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            // No packet kernels here: every lane goes the scalar way.
            let _ = (i, rays, lanes);
            *out = Ranges8::default();
        }
    }

    /// [`LeafTable::ranges8`] with the SSE2 baseline, for tests: the same answers.
    #[doc(hidden)]
    #[cfg(target_arch = "x86_64")]
    pub fn ranges8_sse(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        self.ranges8_in::<sse_d::SseD, false>(i, rays, lanes, out)
    }

    /// [`LeafTable::ranges8`] with two AVX registers per value, for tests
    /// (on a CPU with AVX): the same answers.
    #[doc(hidden)]
    #[cfg(target_arch = "x86_64")]
    pub fn ranges8_avx2(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) -> bool {
        if !std::arch::is_x86_feature_detected!("avx") {
            return false;
        }
        // SAFETY: the CPU has AVX.
        unsafe { self.ranges8_avx::<false>(i, rays, lanes, out) };
        true
    }

    /// [`LeafTable::ranges8`] with one AVX-512 register per value (where
    /// the CPU has AVX-512F: half the instructions of two AVX registers).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn ranges8_avx512<const BESIDE: bool>(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        self.ranges8_in::<avx512_d::Avx512D, BESIDE>(i, rays, lanes, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn ranges8_avx<const BESIDE: bool>(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        self.ranges8_in::<avx_d::AvxD, BESIDE>(i, rays, lanes, out)
    }

    /// [`LeafTable::torus_prep8`] with two AVX registers per value.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    pub(crate) unsafe fn torus_prep8_avx(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut [Option<TorusPrep>; 8]) {
        self.torus_prep8_in::<avx_d::AvxD>(i, rays, lanes, out)
    }

    /// [`LeafTable::torus_prep8`] with the SSE2 baseline (also for tests:
    /// the same preps as the wider builds).
    #[doc(hidden)]
    #[cfg(target_arch = "x86_64")]
    pub fn torus_prep8_sse(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut [Option<TorusPrep>; 8]) {
        self.torus_prep8_in::<sse_d::SseD>(i, rays, lanes, out)
    }

    /// [`LeafTable::torus_prep8`] with two AVX registers per value, for
    /// tests (`false`: the CPU has no AVX).
    #[doc(hidden)]
    #[cfg(target_arch = "x86_64")]
    pub fn torus_prep8_avx2(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut [Option<TorusPrep>; 8]) -> bool {
        if !std::arch::is_x86_feature_detected!("avx") {
            return false;
        }
        // SAFETY: the CPU has AVX.
        unsafe { self.torus_prep8_avx(i, rays, lanes, out) };
        true
    }

    /// The lanes mapped to torus `i`'s frame as `line64` maps them (as
    /// [`LeafTable::ranges8`]'s quadrics), then [`torus8::torus_prep8_in`].
    #[inline(always)]
    fn torus_prep8_in<D: D8>(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut [Option<TorusPrep>; 8]) {
        let iu = i as usize;
        let (lo, ld) = self.local_lines::<D>(iu, rays);
        torus8::torus_prep8_in(&lo, &ld, (self.p0[iu].x as f64, self.torus_tol), lanes, out);
    }

    #[inline(always)]
    fn ranges8_in<D: D8, const BESIDE: bool>(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        let iu = i as usize;
        match self.kind[iu] {
            LeafKind::Sphere => self.balls8::<D, BESIDE>(iu, rays, lanes, out),
            LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone | LeafKind::Cuboid => {
                self.quadrics8::<D, BESIDE>(iu, rays, lanes, out)
            }
            LeafKind::HalfSpace => self.planes8::<D>(iu, rays, lanes, out),
            _ => unreachable!("no packet kernel for {:?}", self.kind[iu]),
        }
    }

    /// [`LeafTable::ranges8`] of a half-space, as the scalar path's
    /// `flat_spans`: the lanes relative to the anchor in f64 (`rel64`),
    /// against the f64 world plane (`plane64`).
    #[inline(always)]
    fn planes8<D: D8>(&self, iu: usize, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        let (n, w) = self.plane64(iu);
        let c = Vec3::from(self.anchor[iu]).as_dvec3();
        let (q, d) = rel_lines::<D>(rays, c);
        let r = half_space(&q, &d, [n.x, n.y, n.z], w);
        *out = record(r, lanes);
    }

    /// The lines `lo + t ld` (leaf `iu`'s frame) sure to miss it, for an
    /// ellipsoid, a cylinder or a cone (none for a box): see
    /// [`side_slab_miss`] and [`ball_miss`].
    #[inline(always)]
    fn quadric_misses<D: D8>(&self, iu: usize, lo: &[D; 3], ld: &[D; 3]) -> D {
        match self.kind[iu] {
            LeafKind::Cylinder => {
                let (a, b, rr) = cylinder_quad(lo, ld);
                side_slab_miss(a, b, rr.sub(D::splat(1.0)), (lo[2], ld[2]), D::splat(0.0))
            }
            LeafKind::Cone => {
                let (ra, rb) = self.cone_radii(iu);
                let q = ConeQuad::new(lo, ld, ra, rb);
                side_slab_miss(q.a, q.b, q.c, (lo[2], ld[2]), q.lin_tol)
            }
            LeafKind::Ellipsoid => ball_miss(lo, ld, D::splat(1.0)),
            _ => D::splat(0.0),
        }
    }

    /// The lanes' lines in leaf `iu`'s frame (f64), as `line64` maps them:
    /// `(p - anchor)`, then ((x_axis x + y_axis y) + z_axis z), then the
    /// anchor's local point.
    #[inline(always)]
    fn local_lines<D: D8>(&self, iu: usize, rays: &Rays8Soa) -> ([D; 3], [D; 3]) {
        let (m, b) = &self.maps64[self.ext[iu] as usize];
        let c = Vec3::from(self.anchor[iu]).as_dvec3();
        let (o, d) = rel_lines::<D>(rays, c);
        let lo = [map_row(m, 0, &o).add(D::splat(b.x)), map_row(m, 1, &o).add(D::splat(b.y)), map_row(m, 2, &o).add(D::splat(b.z))];
        let ld = [map_row(m, 0, &d), map_row(m, 1, &d), map_row(m, 2, &d)];
        (lo, ld)
    }

    /// The lanes of `rays` that the miss pretests ([`side_slab_miss`],
    /// [`ball_miss`]) find sure to miss leaf `i` (SSE2), for tests: the
    /// packet kernels answer "no lane meets it" without solving when
    /// these are all their lanes.
    #[cfg(all(test, target_arch = "x86_64"))]
    fn sure_misses8(&self, i: u32, rays: &Rays8Soa) -> u32 {
        let iu = i as usize;
        match self.kind[iu] {
            LeafKind::Sphere => {
                let (o, d, r) = self.ball_lines::<sse_d::SseD>(iu, rays);
                ball_miss(&o, &d, D8::splat(r * r)).bitmask()
            }
            LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone => {
                let (lo, ld) = self.local_lines::<sse_d::SseD>(iu, rays);
                self.quadric_misses(iu, &lo, &ld).bitmask()
            }
            _ => 0,
        }
    }

    /// [`LeafTable::ranges8`] of an ellipsoid, a cylinder, a cone or a box, as the
    /// scalar path's `quadric_spans` and `flat_spans`: the lanes mapped to the leaf's frame in f64
    /// (`local64`, `map64`: `(p - anchor)`, then ((x_axis x + y_axis y) +
    /// z_axis z), then the anchor's local point), solved in f64. (No
    /// closures here: one compiled apart from this AVX function made every
    /// AVX operation a call, 10x the instructions.)
    #[inline(always)]
    fn quadrics8<D: D8, const BESIDE: bool>(&self, iu: usize, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        let (lo, ld) = self.local_lines::<D>(iu, rays);
        // Most solves in a forest have no lane meeting the leaf (those that
        // meet its box pass beside it): told here without the divisions
        // and square root the solve waits on (see `ranges8_beside`).
        if BESIDE && self.quadric_misses(iu, &lo, &ld).bitmask() & lanes == lanes {
            *out = Ranges8::missed(lanes);
            return;
        }
        let r = if self.kind[iu] == LeafKind::Cylinder {
            cylinder(&lo, &ld)
        } else if self.kind[iu] == LeafKind::Cone {
            let (ra, rb) = self.cone_radii(iu);
            cone(&lo, &ld, ra, rb)
        } else if self.kind[iu] == LeafKind::Cuboid {
            let (p0, p1) = (self.p0[iu], self.p1[iu]);
            cuboid(&lo, &ld, [p0.x as f64, p0.y as f64, p0.z as f64], [p1.x as f64, p1.y as f64, p1.z as f64])
        } else {
            let (hit, t0, t1) = ball(&lo, &ld, 1.0);
            let side = D::splat(sub::SIDE as f64);
            R8 { hit, t0, s0: side, t1, s1: side }
        };
        *out = record(r, lanes);
    }

    /// The lanes' lines relative to ball `iu`'s centre, as `ball_frame`
    /// makes them: `(p - anchor) - p1`, in f64; and its radius, `p0.x +
    /// p0.y`.
    #[inline(always)]
    fn ball_lines<D: D8>(&self, iu: usize, rays: &Rays8Soa) -> ([D; 3], [D; 3], f64) {
        let (p0, p1) = (self.p0[iu], self.p1[iu]);
        let (c, e) = (Vec3::from(self.anchor[iu]).as_dvec3(), p1.truncate().as_dvec3());
        let o = [
            D::widen(&rays.o[0]).sub(D::splat(c.x)).sub(D::splat(e.x)),
            D::widen(&rays.o[1]).sub(D::splat(c.y)).sub(D::splat(e.y)),
            D::widen(&rays.o[2]).sub(D::splat(c.z)).sub(D::splat(e.z)),
        ];
        let d = [D::widen(&rays.d[0]), D::widen(&rays.d[1]), D::widen(&rays.d[2])];
        (o, d, p0.x as f64 + p0.y as f64)
    }

    /// [`LeafTable::ranges8`] of a ball (`LeafKind::Sphere`), as the scalar
    /// path's `ball_spans`: in f64 from the f32 world ray and the ball's f32
    /// centre and radius (no map, no rescaling: every lane is done).
    #[inline(always)]
    fn balls8<D: D8, const BESIDE: bool>(&self, iu: usize, rays: &Rays8Soa, lanes: u32, out: &mut Ranges8) {
        let (o, d, r) = self.ball_lines::<D>(iu, rays);
        if BESIDE && ball_miss(&o, &d, D::splat(r * r)).bitmask() & lanes == lanes {
            *out = Ranges8::missed(lanes);
            return;
        }
        let (hit, t0, t1) = ball(&o, &d, r);
        let side = [sub::SIDE; 8];
        *out = Ranges8 { done: lanes, hit: hit.bitmask() & lanes, t0: t0.narrow(), s0: side, t1: t1.narrow(), s1: side };
    }
}

#[cfg(test)]
#[path = "kernels8_tests.rs"]
mod tests;
