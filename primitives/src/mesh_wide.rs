//! 4-wide BVH for mesh ray traversal: the binary BVH collapsed to nodes of four
//! children (boxes SoA, tested with one SSE op per slab), and the triangles of
//! each leaf (at most 4) in SoA blocks, tested four at a time with the same
//! watertight test (bit-identical arithmetic: no FMA, same operation order) as
//! the scalar [`intersect`](super::intersect). The f32 test only decides where
//! its edge functions are certain: each is compared with a bound of its
//! rounding error ([`TriBlock::bound`]); a lane where no decision is certain
//! (the ray passes within the f32 test's resolution, ~1e-6 of the distance,
//! of an edge line) goes to the f64 test ([`intersect64`](super::intersect64)),
//! which owns the tie-breaking.
//!
//! Measured on the bunny subdivided to 940k triangles (benches/embree/RESULTS.md):
//! the binary pair walk it replaces ran camera rays at ~6 Mrays/s on one core.

use glam::{BVec4A, Vec3, Vec4};
use smallvec::SmallVec;

use super::{intersect64, WoopRay, SLAB_EPS};
use crate::bvh::BvhNode;

/// Child code flag: the child is a leaf (the rest is its block index).
pub(crate) const LEAF: u32 = 1 << 31;

/// Four children: boxes as `[min_x, max_x, min_y, max_y, min_z, max_z]` lanes
/// (empty slots have min = +inf, max = -inf and never hit), child codes.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Node4 {
    b: [[f32; 4]; 6],
    child: [u32; 4],
}

impl Node4 {
    /// The box of slot `s`, `None` for an empty slot.
    #[inline]
    pub(crate) fn slot_box(&self, s: usize) -> Option<crate::aabb::Aabb> {
        let b = &self.b;
        (b[0][s] <= b[1][s]).then(|| crate::aabb::Aabb::new(Vec3::new(b[0][s], b[2][s], b[4][s]), Vec3::new(b[1][s], b[3][s], b[5][s])))
    }

    /// The slots' boxes, SoA: min x, max x, min y, max y, min z, max z.
    #[inline(always)]
    pub(crate) fn rows(&self) -> &[[f32; 4]; 6] {
        &self.b
    }

    /// Sets the child code of slot `s`.
    pub(crate) fn set_child(&mut self, s: usize, code: u32) {
        self.child[s] = code;
    }
}

/// Up to four triangles of one leaf, SoA: `v[corner * 3 + axis]`, lanes past
/// `count` are NaN (never hit, never take the scalar fallback).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct TriBlock {
    v: [[f32; 4]; 9],
    /// A ball around every corner: centre and radius ([`block_ball`]), for
    /// the error bound of the f32 test.
    ball: [f32; 4],
    /// The lanes in use (`count` low bits).
    valid: u32,
    /// First triangle slot (the lanes are slots `first..first + count`).
    first: u32,
    count: u32,
}

/// The wide tree; node 0 is the root.
#[derive(Debug, Default)]
pub(super) struct Wide {
    nodes: Vec<Node4>,
    blocks: Vec<TriBlock>,
}

impl Wide {
    /// Collapses the binary BVH (leaves hold `count <= 4` consecutive slots of `tris`).
    pub(super) fn build(bin: &[BvhNode], tris: &[[Vec3; 3]]) -> Wide {
        let mut w = Wide::default();
        if bin.is_empty() || tris.is_empty() {
            return w;
        }
        let blocks = &mut w.blocks;
        w.nodes = collapse(bin, |n| {
            let ts = &tris[n.first as usize..(n.first + n.count) as usize];
            let mut blk =
                TriBlock { v: [[f32::NAN; 4]; 9], ball: block_ball(ts), valid: (1 << n.count) - 1, first: n.first, count: n.count };
            assert!(n.count <= 4, "mesh BVH leaf with {} triangles", n.count);
            for l in 0..n.count as usize {
                let t = &tris[n.first as usize + l];
                for c in 0..3 {
                    for a in 0..3 {
                        blk.v[c * 3 + a][l] = t[c][a];
                    }
                }
            }
            blocks.push(blk);
            LEAF | (blocks.len() - 1) as u32
        });
        w
    }

    /// Node and leaf counts, mean children per node and triangles per leaf, depth.
    pub(super) fn stats(&self) -> String {
        let kids: usize = self.nodes.iter().map(|n| n.b[0].iter().filter(|x| x.is_finite()).count()).sum();
        let tris: u32 = self.blocks.iter().map(|b| b.count).sum();
        let mut depth = 0;
        let mut st = vec![(0u32, 1)];
        while let Some((i, d)) = st.pop() {
            depth = depth.max(d);
            let n = &self.nodes[i as usize];
            for s in 0..4 {
                if n.b[0][s].is_finite() && n.child[s] & LEAF == 0 {
                    st.push((n.child[s], d + 1));
                }
            }
        }
        format!(
            "{} nodes ({:.2} children each), {} leaves ({:.2} triangles each), depth {depth}",
            self.nodes.len(),
            kids as f64 / self.nodes.len().max(1) as f64,
            self.blocks.len(),
            tris as f64 / self.blocks.len().max(1) as f64
        )
    }

    pub(super) fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
}

/// Collapses the binary BVH `bin` (non-empty; inner nodes have children
/// `first` and `first + 1`) into 4-wide nodes, node 0 the root, deeper
/// subtrees laid out after their parent depth first. `leaf(n)` turns a binary
/// leaf into its child code (`LEAF | payload`).
pub(crate) fn collapse(bin: &[BvhNode], mut leaf: impl FnMut(&BvhNode) -> u32) -> Vec<Node4> {
    let empty = Node4 { b: crate::frustum::slot_rows([]), child: [0; 4] };
    let half_area = |n: &BvhNode| {
        let e = n.max - n.min;
        e.x * e.y + e.y * e.z + e.z * e.x
    };
    // (binary nodes whose boxes go into wide node `wi`); a leaf root gets a
    // wide root with that one leaf.
    let mut nodes = vec![empty];
    let mut work: Vec<(SmallVec<[u32; 4]>, usize)> = Vec::new();
    if bin[0].count > 0 {
        work.push((SmallVec::from_slice(&[0]), 0));
    } else {
        work.push((SmallVec::from_slice(&[bin[0].first, bin[0].first + 1]), 0));
    }
    while let Some((mut kids, wi)) = work.pop() {
        // Open the largest inner child until there are four.
        while kids.len() < 4 {
            let best = kids
                .iter()
                .enumerate()
                .filter(|(_, &k)| bin[k as usize].count == 0)
                .max_by(|a, b| half_area(&bin[*a.1 as usize]).total_cmp(&half_area(&bin[*b.1 as usize])))
                .map(|(i, _)| i);
            let Some(i) = best else { break };
            let f = bin[kids[i] as usize].first;
            kids[i] = f;
            kids.push(f + 1);
        }
        // Deeper subtrees are laid out after this node, depth first (popped in
        // reverse so child 0's subtree comes first).
        let mut pending = SmallVec::<[(SmallVec<[u32; 4]>, usize); 4]>::new();
        for (s, &k) in kids.iter().enumerate() {
            let n = &bin[k as usize];
            let bx = [n.min.x, n.max.x, n.min.y, n.max.y, n.min.z, n.max.z];
            for (a, v) in bx.iter().enumerate() {
                nodes[wi].b[a][s] = *v;
            }
            if n.count > 0 {
                nodes[wi].child[s] = leaf(n);
            } else {
                let ni = nodes.len();
                nodes.push(empty);
                nodes[wi].child[s] = ni as u32;
                pending.push((SmallVec::from_slice(&[n.first, n.first + 1]), ni));
            }
        }
        while let Some(p) = pending.pop() {
            work.push(p);
        }
    }
    nodes
}

/// Per-ray constants of the 4-wide slab test.
#[derive(Clone, Copy)]
pub(super) struct Ray4 {
    o: [Vec4; 3],
    inv: [Vec4; 3],
    /// Index of the near plane array per axis (0: min, 1: max).
    near: [usize; 3],
    /// Some direction component is exactly zero (slab parameters may be NaN).
    zero: bool,
}

impl Ray4 {
    #[inline(always)]
    pub(super) fn new(o: Vec3, d: Vec3) -> Ray4 {
        let inv = d.recip();
        Ray4 {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            near: [(inv.x < 0.0) as usize, (inv.y < 0.0) as usize, (inv.z < 0.0) as usize],
            zero: d.cmpeq(Vec3::ZERO).any(),
        }
    }

    /// Which children the ray meets within `[tlo, thi]` (conservatively, as
    /// `RayBox::range`), and their entry parameters.
    #[inline(always)]
    pub(super) fn hit(&self, n: &Node4, tlo: f32, thi: f32) -> (u32, Vec4) {
        let mut t0 = [Vec4::ZERO; 3];
        let mut t1 = [Vec4::ZERO; 3];
        for a in 0..3 {
            let near = Vec4::from_array(n.b[2 * a + self.near[a]]);
            let far = Vec4::from_array(n.b[2 * a + 1 - self.near[a]]);
            t0[a] = (near - self.o[a]) * self.inv[a];
            t1[a] = (far - self.o[a]) * self.inv[a];
        }
        if self.zero {
            for a in 0..3 {
                t0[a] = Vec4::select(t0[a].is_nan_mask(), Vec4::NEG_INFINITY, t0[a]);
                t1[a] = Vec4::select(t1[a].is_nan_mask(), Vec4::INFINITY, t1[a]);
            }
        }
        let lo = t0[0].max(t0[1]).max(t0[2]).max(Vec4::splat(tlo));
        let hi = t1[0].min(t1[1]).min(t1[2]).min(Vec4::splat(thi));
        let eps = Vec4::splat(SLAB_EPS);
        let m = (lo - lo.abs() * eps).cmple(hi + hi.abs() * eps);
        (m.bitmask(), lo)
    }
}

/// Eight rays with one direction and their own origins (a packet of shadow
/// rays toward a directional light), each tested against a node's four
/// boxes exactly as its own [`Ray4`] tests them: the same operations on the
/// same values, the lanes in one AVX register per child where the CPU has
/// AVX, else lane by lane through `Ray4`.
pub(super) struct ParRays8 {
    /// Each lane's own test (the direction's constants are lane 0's).
    one: [Ray4; 8],
    /// Origins per axis.
    o: [[f32; 8]; 3],
    avx: bool,
}

impl ParRays8 {
    /// The rays `o[k] + t d`, tested with AVX when `avx` (which the CPU
    /// must have) else lane by lane.
    pub(super) fn new(o: &[Vec3; 8], d: Vec3, avx: bool) -> ParRays8 {
        let one: [Ray4; 8] = std::array::from_fn(|k| Ray4::new(o[k], d));
        ParRays8 { o: std::array::from_fn(|a| std::array::from_fn(|k| o[k][a])), one, avx }
    }

    /// Per child slot of `n`, the lanes of `lanes` whose ray meets it within
    /// `[tlo[k], thi[k]]` (as [`Ray4::hit`] of each lane says).
    #[inline(always)]
    pub(super) fn hit(&self, n: &Node4, tlo: &[f32; 8], thi: &[f32; 8], lanes: u32) -> [u32; 4] {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: the CPU has AVX.
            return unsafe { self.hit_avx(n, tlo, thi) }.map(|m| m & lanes);
        }
        self.hit_lanes(n, tlo, thi, lanes)
    }

    /// [`ParRays8::hit`] lane by lane (what CPUs without AVX run).
    #[inline(always)]
    fn hit_lanes(&self, n: &Node4, tlo: &[f32; 8], thi: &[f32; 8], lanes: u32) -> [u32; 4] {
        let mut out = [0u32; 4];
        let mut m = lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let (c, _) = self.one[k].hit(n, tlo[k], thi[k]);
            for (s, o) in out.iter_mut().enumerate() {
                *o |= ((c >> s) & 1) << k;
            }
        }
        out
    }

    /// [`ParRays8::hit`] with the eight lanes in one AVX register per child.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn hit_avx(&self, n: &Node4, tlo: &[f32; 8], thi: &[f32; 8]) -> [u32; 4] {
        use std::arch::x86_64::*;
        let o = [_mm256_loadu_ps(self.o[0].as_ptr()), _mm256_loadu_ps(self.o[1].as_ptr()), _mm256_loadu_ps(self.o[2].as_ptr())];
        let Ray4 { inv, near: near_of, zero, .. } = self.one[0];
        let inv = [_mm256_set1_ps(inv[0].x), _mm256_set1_ps(inv[1].x), _mm256_set1_ps(inv[2].x)];
        let (lo8, hi8) = (_mm256_loadu_ps(tlo.as_ptr()), _mm256_loadu_ps(thi.as_ptr()));
        let eps = _mm256_set1_ps(SLAB_EPS);
        let sign = _mm256_set1_ps(-0.0);
        let (ninf, inf) = (_mm256_set1_ps(f32::NEG_INFINITY), _mm256_set1_ps(f32::INFINITY));
        let mut out = [0u32; 4];
        for (s, o_s) in out.iter_mut().enumerate() {
            let mut t0 = [_mm256_setzero_ps(); 3];
            let mut t1 = [_mm256_setzero_ps(); 3];
            for a in 0..3 {
                let near = _mm256_set1_ps(n.b[2 * a + near_of[a]][s]);
                let far = _mm256_set1_ps(n.b[2 * a + 1 - near_of[a]][s]);
                t0[a] = _mm256_mul_ps(_mm256_sub_ps(near, o[a]), inv[a]);
                t1[a] = _mm256_mul_ps(_mm256_sub_ps(far, o[a]), inv[a]);
                if zero {
                    // As `Vec4::select(is_nan_mask, ..)`.
                    t0[a] = _mm256_blendv_ps(t0[a], ninf, _mm256_cmp_ps::<_CMP_UNORD_Q>(t0[a], t0[a]));
                    t1[a] = _mm256_blendv_ps(t1[a], inf, _mm256_cmp_ps::<_CMP_UNORD_Q>(t1[a], t1[a]));
                }
            }
            // `Vec4::max` / `min` are `_mm_max_ps` / `_mm_min_ps` in this order.
            let lo = _mm256_max_ps(_mm256_max_ps(_mm256_max_ps(t0[0], t0[1]), t0[2]), lo8);
            let hi = _mm256_min_ps(_mm256_min_ps(_mm256_min_ps(t1[0], t1[1]), t1[2]), hi8);
            let a = _mm256_sub_ps(lo, _mm256_mul_ps(_mm256_andnot_ps(sign, lo), eps));
            let b = _mm256_add_ps(hi, _mm256_mul_ps(_mm256_andnot_ps(sign, hi), eps));
            *o_s = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(a, b)) as u32;
        }
        out
    }
}

/// Per-ray constants of the 4-wide watertight test.
#[derive(Clone, Copy)]
pub(super) struct TriRay4 {
    k: [usize; 3],
    o: [Vec4; 3],
    s: [Vec4; 3],
    /// The origin in the axis order `k`, and the shears `sx`, `sy` (for the bound).
    os: [f32; 3],
    sxy: [f32; 2],
    k10: (f32, f32),
}

impl TriRay4 {
    #[inline(always)]
    pub(super) fn new(r: &WoopRay) -> TriRay4 {
        let [kx, ky, kz] = r.k;
        TriRay4 {
            k: r.k,
            o: [Vec4::splat(r.o[kx]), Vec4::splat(r.o[ky]), Vec4::splat(r.o[kz])],
            s: r.s.map(Vec4::splat),
            os: [r.o[kx], r.o[ky], r.o[kz]],
            sxy: [r.s[0], r.s[1]],
            k10: (r.k1, r.k0),
        }
    }
}

/// Result of a block test: the lanes hit for certain (within the range),
/// their t and det (det > 0: front facing), and the lanes the f32 test cannot
/// decide (for [`TriBlock::exact`]).
pub(super) struct Block {
    pub(super) hits: u32,
    pub(super) unsure: u32,
    pub(super) t: Vec4,
    pub(super) det: Vec4,
}

/// Result of [`TriBlock::test8_avx`], per triangle lane `l` and ray bit `k`.
pub(super) struct Block8 {
    /// Rays that hit triangle `l` for certain within their range.
    pub(super) ok: [u32; 4],
    /// Rays for which triangle `l` faces front (det > 0).
    pub(super) front: [u32; 4],
    pub(super) t: [F8; 4],
    /// Rays for which the f32 test cannot decide triangle `l`.
    pub(super) unsure: [u32; 4],
}

/// Result of [`TriBlock::nearest`].
pub(super) enum Near {
    Miss,
    Hit(f32, u32),
    /// Some lane is undecided: the caller takes the lanes in order.
    Unsure(Block),
}

/// The unit roundoff of f32.
const U: f32 = f32::EPSILON * 0.5;
/// The error bound's coefficients ([`TriBlock::bound`]) for an exact f32
/// ray, and for one that rounds an exact line (with `K0_ROUNDED` times the
/// origin's largest coordinate).
pub(super) const K1: f32 = 34.0 * U;
pub(super) const K1_ROUNDED: f32 = 48.0 * U;
pub(super) const K0_ROUNDED: f32 = 12.0 * U;

/// A ball around every corner of `tris`: the centre of their box and a radius
/// rounded up, `[x, y, z, r]`.
pub(super) fn block_ball(tris: &[[Vec3; 3]]) -> [f32; 4] {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for v in tris.iter().flatten() {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let q = (lo + hi) * 0.5;
    let r = (hi.as_dvec3() - q.as_dvec3()).max(q.as_dvec3() - lo.as_dvec3()).max_element();
    let r32 = r as f32;
    [q.x, q.y, q.z, if (r32 as f64) < r { r32.next_up() } else { r32 }]
}

impl Wide {
    #[inline(always)]
    pub(super) fn node(&self, i: u32) -> &Node4 {
        // SAFETY-free: plain indexing (codes come from the builder).
        &self.nodes[i as usize]
    }

    #[inline(always)]
    pub(super) fn block(&self, i: u32) -> &TriBlock {
        &self.blocks[(i & !LEAF) as usize]
    }
}

impl Node4 {
    #[inline(always)]
    pub(crate) fn child(&self, s: u32) -> u32 {
        self.child[s as usize]
    }
}

impl TriBlock {
    #[inline(always)]
    pub(super) fn slots(&self) -> std::ops::Range<u32> {
        self.first..self.first + self.count
    }

    /// A block of the one triangle `tri` in lane 0, with the ball `ball`.
    #[inline(always)]
    pub(super) fn single(tri: &[Vec3; 3], ball: [f32; 4]) -> TriBlock {
        let mut v = [[f32::NAN; 4]; 9];
        for c in 0..3 {
            for a in 0..3 {
                v[c * 3 + a][0] = tri[c][a];
            }
        }
        TriBlock { v, ball, valid: 1, first: 0, count: 1 }
    }

    /// A bound of the rounding error of the f32 edge functions of every
    /// triangle of the block for one ray (origin `o` and shears `sx`, `sy`
    /// in the ray's axis order `k`): an edge function larger in magnitude has
    /// the sign of the exact one. From the block's ball (centre q, radius r):
    /// every corner lies within M = |q - o|_inf + r of the origin along each
    /// axis, so each projected corner coordinate is off by at most ~6.1 u M
    /// (u = 2^-24; the subtraction of the origin, the shear, its product and
    /// difference), and lies within P = |projected q|_inf + 2r of the ray
    /// (|sx|, |sy| <= 1). An edge function, a difference of two products of
    /// such coordinates, is then off by at most u P' (24.4 M + 4 P') with P'
    /// = P + 18.3 u M <= 2.0001 M: at most 32.5 u M P'; with `k1` = [`K1`]
    /// (34 u) and `k0` = 0 the bound is (k1 M + k0) P'. Where the f32 ray
    /// is a rounding of the exact line ([`super::Line64`]), each projected
    /// corner moves by up to 2 u |o|_inf more (the origin) and 2.01 u M (the
    /// shears): `k1` = [`K1_ROUNDED`], `k0` = [`K0_ROUNDED`] |o|_inf, also
    /// added to P'. [`test8_avx`](Self::test8_avx) makes the same bits.
    #[inline(always)]
    pub(super) fn bound(&self, k: [usize; 3], o: [f32; 3], (sx, sy): (f32, f32), (k1, k0): (f32, f32)) -> f32 {
        let q = &self.ball;
        let (qx, qy, qz) = (q[k[0]] - o[0], q[k[1]] - o[1], q[k[2]] - o[2]);
        let m = qx.abs().max(qy.abs()).max(qz.abs()) + q[3];
        let px = qx - sx * qz;
        let py = qy - sy * qz;
        let p = px.abs().max(py.abs()) + (q[3] + q[3] + m * (20.0 * U) + k0);
        // Below the smallest normal f32 the products lose their relative precision.
        ((m * k1 + k0) * p).max(f32::MIN_POSITIVE)
    }

    /// The watertight test on the four lanes, within `[tlo, thi]`.
    #[inline(always)]
    pub(super) fn test(&self, r: &TriRay4, tlo: f32, thi: f32) -> Block {
        let [kx, ky, kz] = r.k;
        let [ox, oy, oz] = r.o;
        let [sx, sy, sz] = r.s;
        let v = |c: usize, a: usize| Vec4::from_array(self.v[c * 3 + a]);
        let (az, bz, cz) = (v(0, kz) - oz, v(1, kz) - oz, v(2, kz) - oz);
        let ax = (v(0, kx) - ox) - sx * az;
        let ay = (v(0, ky) - oy) - sy * az;
        let bx = (v(1, kx) - ox) - sx * bz;
        let by = (v(1, ky) - oy) - sy * bz;
        let cx = (v(2, kx) - ox) - sx * cz;
        let cy = (v(2, ky) - oy) - sy * cz;
        let u = cx * by - cy * bx;
        let vv = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let b = Vec4::splat(self.bound(r.k, r.os, (r.sxy[0], r.sxy[1]), r.k10));
        let nb = -b;
        // Certain: a miss where two edge functions have opposite signs, a hit
        // where all three share theirs (padding lanes are masked off).
        let (hi, lo) = (u.max(vv).max(w), u.min(vv).min(w));
        let miss = hi.cmpgt(b) & lo.cmplt(nb);
        let hit = lo.cmpgt(b) | hi.cmplt(nb);
        let unsure = !(miss | hit).bitmask() & self.valid;
        let z = Vec4::ZERO;
        if hit.bitmask() == 0 {
            return Block { hits: 0, unsure, t: z, det: z };
        }
        let det = u + vv + w;
        let t = (u * (sz * az) + vv * (sz * bz) + w * (sz * cz)) / det;
        let ok = hit & t.cmpge(Vec4::splat(tlo)) & t.cmple(Vec4::splat(thi));
        Block { hits: ok.bitmask(), unsure, t, det }
    }

    /// The watertight test of every triangle of the block against eight rays
    /// from one origin that share the projection axes `k` (per-ray shear `s`,
    /// origin `o` in the `k` order), one 8-lane AVX step per triangle. Per
    /// (ray, triangle) the operations are those of [`test`](Self::test) in the
    /// same order (the bound's too), so the hits, `t`s, facings and undecided
    /// lanes are the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub(super) fn test8_avx(&self, k: [usize; 3], o: [f32; 3], s: &[F8; 3], k10: &[F8; 2], (tlo, thi): (&F8, &F8)) -> Block8 {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = k;
        let [ox, oy, oz] = o;
        let (sx, sy, sz) = (F8::load(&s[0]), F8::load(&s[1]), F8::load(&s[2]));
        let (tlo, thi) = (F8::load(tlo), F8::load(thi));
        let mut out = Block8 { ok: [0; 4], front: [0; 4], t: [F8([0.0; 8]); 4], unsure: [0; 4] };
        // The bound of `bound`, lane by lane (its scalar part is shared: one origin).
        let q = &self.ball;
        let (qx, qy, qz) = (q[kx] - ox, q[ky] - oy, q[kz] - oz);
        let m = qx.abs().max(qy.abs()).max(qz.abs()) + q[3];
        let sign = _mm256_set1_ps(-0.0);
        let px = _mm256_andnot_ps(sign, _mm256_sub_ps(_mm256_set1_ps(qx), _mm256_mul_ps(sx, _mm256_set1_ps(qz))));
        let py = _mm256_andnot_ps(sign, _mm256_sub_ps(_mm256_set1_ps(qy), _mm256_mul_ps(sy, _mm256_set1_ps(qz))));
        let (k1, k0) = (F8::load(&k10[0]), F8::load(&k10[1]));
        let p = _mm256_add_ps(_mm256_max_ps(px, py), _mm256_add_ps(_mm256_set1_ps(q[3] + q[3] + m * (20.0 * U)), k0));
        let b = _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(m), k1), k0), p);
        let b = _mm256_max_ps(b, _mm256_set1_ps(f32::MIN_POSITIVE));
        let nb = _mm256_xor_ps(b, sign);
        let n = (self.count as usize).min(4);
        for l in 0..n {
            let v = |c: usize, a: usize| self.v[c * 3 + a][l];
            let (az, bz, cz) = (v(0, kz) - oz, v(1, kz) - oz, v(2, kz) - oz);
            // Macros, not closures: closures do not inherit `target_feature`.
            macro_rules! lane {
                ($p:expr, $q:expr, $r:expr) => {
                    _mm256_sub_ps(_mm256_set1_ps($p), _mm256_mul_ps($q, _mm256_set1_ps($r)))
                };
            }
            macro_rules! bits {
                ($op:ident, $a:expr, $b:expr) => {
                    _mm256_movemask_ps(_mm256_cmp_ps::<$op>($a, $b)) as u32
                };
            }
            let ax = lane!(v(0, kx) - ox, sx, az);
            let ay = lane!(v(0, ky) - oy, sy, az);
            let bx = lane!(v(1, kx) - ox, sx, bz);
            let by = lane!(v(1, ky) - oy, sy, bz);
            let cx = lane!(v(2, kx) - ox, sx, cz);
            let cy = lane!(v(2, ky) - oy, sy, cz);
            let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
            let vv = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
            let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
            // Operand order as `test`'s `max` / `min` (the same lanes on NaN).
            let hi = _mm256_max_ps(_mm256_max_ps(u, vv), w);
            let lo = _mm256_min_ps(_mm256_min_ps(u, vv), w);
            let miss = bits!(_CMP_GT_OQ, hi, b) & bits!(_CMP_LT_OQ, lo, nb);
            let hit = bits!(_CMP_GT_OQ, lo, b) | bits!(_CMP_LT_OQ, hi, nb);
            out.unsure[l] = !(miss | hit) & 0xff;
            if hit == 0 {
                continue;
            }
            let det = _mm256_add_ps(_mm256_add_ps(u, vv), w);
            let num = _mm256_add_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(u, _mm256_mul_ps(sz, _mm256_set1_ps(az))),
                    _mm256_mul_ps(vv, _mm256_mul_ps(sz, _mm256_set1_ps(bz))),
                ),
                _mm256_mul_ps(w, _mm256_mul_ps(sz, _mm256_set1_ps(cz))),
            );
            let t = _mm256_div_ps(num, det);
            out.ok[l] = hit & bits!(_CMP_GE_OQ, t, tlo) & bits!(_CMP_LE_OQ, t, thi);
            out.front[l] = bits!(_CMP_GT_OQ, det, _mm256_setzero_ps());
            // SAFETY: F8 is 32-byte aligned and 8 lanes long.
            unsafe { _mm256_store_ps(out.t[l].0.as_mut_ptr(), t) };
        }
        out
    }

    /// The nearest lane hit within `[tlo, thi]`: its `t` and lane (on equal `t`
    /// the last lane, as taking the lanes in order with `t <= thi` would), or
    /// [`Near::Unsure`] when some lane is for the f64 test.
    #[inline(always)]
    pub(super) fn nearest(&self, r: &TriRay4, tlo: f32, thi: f32) -> Near {
        let b = self.test(r, tlo, thi);
        if b.unsure != 0 {
            return Near::Unsure(b);
        }
        let m = b.hits;
        if m == 0 {
            return Near::Miss;
        }
        let lanes = BVec4A::new(m & 1 != 0, m & 2 != 0, m & 4 != 0, m & 8 != 0);
        let t = Vec4::select(lanes, b.t, Vec4::INFINITY);
        let tm = t.min_element();
        let last = 31 - (t.cmpeq(Vec4::splat(tm)).bitmask() & m).leading_zeros();
        Near::Hit(tm, last)
    }

    /// The f64 test of one lane (for the lanes the f32 test leaves undecided).
    #[inline(never)]
    pub(super) fn exact(tris: &[[Vec3; 3]], slot: u32, r: &WoopRay, tlo: f32, thi: f32) -> Option<(f32, bool)> {
        intersect64(r, &tris[slot as usize], tlo, thi)
    }
}

/// Eight lanes, aligned for one 256-bit load (or two 128-bit ones).
#[derive(Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct F8(pub(crate) [f32; 8]);

impl F8 {
    #[inline(always)]
    fn half(&self, h: usize) -> Vec4 {
        Vec4::from_slice(&self.0[4 * h..4 * h + 4])
    }

    /// The eight lanes as one AVX register.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    fn load(&self) -> std::arch::x86_64::__m256 {
        // SAFETY: F8 is 32-byte aligned and 8 lanes long.
        unsafe { std::arch::x86_64::_mm256_load_ps(self.0.as_ptr()) }
    }

    /// The lanes (bit k = lane k) whose range end `self` reaches a deferred
    /// subtree entered at `t` (the smallest entry among the lanes that met
    /// it, so at most each one's own; with the slab test's slack): the
    /// lanes of a packet walk that still need that subtree.
    #[inline(always)]
    pub(crate) fn reaching(&self, t: f32) -> u32 {
        let tt = Vec4::splat(t - t.abs() * super::SLAB_EPS);
        tt.cmple(self.half(0)).bitmask() | tt.cmple(self.half(1)).bitmask() << 4
    }

    /// Bit k set where lane k of `self` >= lane k of `other` (false on NaN).
    #[inline(always)]
    pub(crate) fn ge_mask(&self, other: &F8) -> u32 {
        self.half(0).cmpge(other.half(0)).bitmask() | self.half(1).cmpge(other.half(1)).bitmask() << 4
    }
}

/// Axis `a` of eight directions as two 4-lane halves, and the lanes (bit
/// `k` for lane `k`) where it is negative and where it is positive: one
/// octant on the axis, without a zero or NaN, is `neg == 0xff || pos ==
/// 0xff`. (Four lanes at a time: counted lane by lane, the signs were
/// some 80 instructions a packet walk of benches/scenes/forest's union,
/// and ~5% of the renderer's mesh walk, callgrind.)
#[inline(always)]
pub(crate) fn axis_signs(d: &[Vec3; 8], a: usize) -> ([Vec4; 2], u32, u32) {
    axis_signs_of(|k| d[k], a)
}

/// [`axis_signs`] of the directions `d(0)..d(7)`.
#[inline(always)]
pub(crate) fn axis_signs_of(d: impl Fn(usize) -> Vec3, a: usize) -> ([Vec4; 2], u32, u32) {
    let h0 = Vec4::new(d(0)[a], d(1)[a], d(2)[a], d(3)[a]);
    let h1 = Vec4::new(d(4)[a], d(5)[a], d(6)[a], d(7)[a]);
    let neg = h0.cmplt(Vec4::ZERO).bitmask() | h1.cmplt(Vec4::ZERO).bitmask() << 4;
    let pos = h0.cmpgt(Vec4::ZERO).bitmask() | h1.cmpgt(Vec4::ZERO).bitmask() << 4;
    ([h0, h1], neg, pos)
}

/// Eight rays sharing a direction octant, SoA, for the packet walk: each child
/// box is tested against all eight rays at once (two 4-lane halves, or one
/// 8-lane AVX op per step with [`hit_avx`](Self::hit_avx); the arithmetic of a
/// lane is the same in both).
pub(crate) struct Packet8 {
    o: [F8; 3],
    inv: [F8; 3],
    near: [usize; 3],
}

impl Packet8 {
    /// `None` when the rays do not share an octant or some direction component is
    /// zero (the caller traces them one by one).
    #[inline(always)]
    pub(crate) fn new(o: &[Vec3; 8], d: &[Vec3; 8]) -> Option<Packet8> {
        Packet8::from_lanes(|k| o[k], |k| d[k])
    }

    /// [`Packet8::new`] of the rays `o(k) + t d(k)`, read lane by lane
    /// where they are (an array of the origins made just before and read
    /// here with wider loads stalled on store forwarding).
    #[inline(always)]
    pub(crate) fn from_lanes(o: impl Fn(usize) -> Vec3, d: impl Fn(usize) -> Vec3) -> Option<Packet8> {
        let mut near = [0usize; 3];
        let mut inv = [F8([0.0; 8]); 3];
        for a in 0..3 {
            let ([h0, h1], neg, pos) = axis_signs_of(&d, a);
            // One octant, no zero component.
            if !(neg == 0xff || pos == 0xff) {
                return None;
            }
            near[a] = (neg == 0xff) as usize;
            // (`recip` is `1 / x`, lane by lane the same division.)
            let (i0, i1) = (h0.recip(), h1.recip());
            i0.write_to_slice(&mut inv[a].0[..4]);
            i1.write_to_slice(&mut inv[a].0[4..]);
        }
        let mut po = [F8([0.0; 8]); 3];
        for (a, pa) in po.iter_mut().enumerate() {
            for k in 0..8 {
                pa.0[k] = o(k)[a];
            }
        }
        Some(Packet8 { o: po, inv, near })
    }

    /// Per child: the rays (bit k = ray k) whose `[tlo, thi]` meets its box, and
    /// the smallest entry parameter among them.
    #[inline(always)]
    pub(crate) fn hit(&self, n: &Node4, tlo: &F8, thi: &F8) -> [(u32, f32); 4] {
        let eps = Vec4::splat(SLAB_EPS);
        // (A plain loop: through `std::array::from_fn` the compiler made the
        // four children four calls.)
        let mut out = [(0u32, 0.0f32); 4];
        for (s, o) in out.iter_mut().enumerate() {
            let mut mask = 0u32;
            let mut tmin = f32::INFINITY;
            for h in 0..2 {
                let mut lo = tlo.half(h);
                let mut hi = thi.half(h);
                for a in 0..3 {
                    let near = Vec4::splat(n.b[2 * a + self.near[a]][s]);
                    let far = Vec4::splat(n.b[2 * a + 1 - self.near[a]][s]);
                    lo = lo.max((near - self.o[a].half(h)) * self.inv[a].half(h));
                    hi = hi.min((far - self.o[a].half(h)) * self.inv[a].half(h));
                }
                let m = (lo - lo.abs() * eps).cmple(hi + hi.abs() * eps);
                mask |= m.bitmask() << (4 * h);
                tmin = tmin.min(Vec4::select(m, lo, Vec4::INFINITY).min_element());
            }
            *o = (mask, tmin);
        }
        out
    }

    /// Where the lines of lanes `4h..4h+4` enter and leave box `b` before any
    /// range clips them (the near plane per axis is the one `min` picks in
    /// [`Aabb::ray_range`](crate::Aabb::ray_range)): the part of the box
    /// test that [`Packet8::box_range`] and [`Packet8::box_slabs`] share.
    #[inline(always)]
    fn half_slabs(&self, (bmin, bmax): ([f32; 3], [f32; 3]), h: usize) -> (Vec4, Vec4) {
        let mut lo = [Vec4::ZERO; 3];
        let mut hi = [Vec4::ZERO; 3];
        for a in 0..3 {
            let (near, far) = if self.near[a] == 0 { (bmin[a], bmax[a]) } else { (bmax[a], bmin[a]) };
            lo[a] = (Vec4::splat(near) - self.o[a].half(h)) * self.inv[a].half(h);
            hi[a] = (Vec4::splat(far) - self.o[a].half(h)) * self.inv[a].half(h);
        }
        (lo[0].max(lo[1]).max(lo[2]), hi[0].min(hi[1]).min(hi[2]))
    }

    /// Per lane, where the line of that lane's ray enters and leaves box `b`
    /// before any range clips it: [`Packet8::box_range`] without `tlo` and
    /// `thi` (its `t0` and `t1` are these, then `max(tlo)` and `min(thi)`).
    #[inline(always)]
    pub(crate) fn box_slabs(&self, b: &crate::Aabb) -> (F8, F8) {
        let planes = (b.min.to_array(), b.max.to_array());
        let (mut enter, mut leave) = (F8([0.0; 8]), F8([0.0; 8]));
        for h in 0..2 {
            let (t0, t1) = self.half_slabs(planes, h);
            enter.0[4 * h..4 * h + 4].copy_from_slice(&t0.to_array());
            leave.0[4 * h..4 * h + 4].copy_from_slice(&t1.to_array());
        }
        (enter, leave)
    }

    /// Per lane, what [`Aabb::ray_range`](crate::Aabb::ray_range) gives that
    /// lane's ray on `[tlo, thi]` for box `b` (the same operations on the
    /// same values):
    /// bit k set where lane k meets the box, and the entries.
    #[inline(always)]
    pub(crate) fn box_range(&self, b: &crate::Aabb, tlo: &F8, thi: &F8) -> (u32, F8) {
        let planes = (b.min.to_array(), b.max.to_array());
        let mut mask = 0u32;
        let mut entry = F8([0.0; 8]);
        for h in 0..2 {
            let (enter, leave) = self.half_slabs(planes, h);
            let t0 = enter.max(tlo.half(h));
            let t1 = leave.min(thi.half(h));
            mask |= t0.cmple(t1).bitmask() << (4 * h);
            entry.0[4 * h..4 * h + 4].copy_from_slice(&t0.to_array());
        }
        (mask, entry)
    }

    /// [`box_range`](Self::box_range) with 8-lane AVX ops: per lane the same
    /// operations in the same order (`Vec4::max` / `min` are `_mm_max_ps` /
    /// `_mm_min_ps`, operands in this order), so the same masks and entries.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn box_range_avx(&self, b: &crate::Aabb, tlo: &[f32; 8], thi: &[f32; 8]) -> (u32, [f32; 8]) {
        use std::arch::x86_64::*;
        // SAFETY: eight lanes each, unaligned loads.
        let (tlo, thi) = unsafe { (_mm256_loadu_ps(tlo.as_ptr()), _mm256_loadu_ps(thi.as_ptr())) };
        let (bmin, bmax) = (b.min.to_array(), b.max.to_array());
        let mut lo = [_mm256_setzero_ps(); 3];
        let mut hi = [_mm256_setzero_ps(); 3];
        for a in 0..3 {
            let (near, far) = if self.near[a] == 0 { (bmin[a], bmax[a]) } else { (bmax[a], bmin[a]) };
            let (o, inv) = (self.o[a].load(), self.inv[a].load());
            lo[a] = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(near), o), inv);
            hi[a] = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(far), o), inv);
        }
        let t0 = _mm256_max_ps(_mm256_max_ps(_mm256_max_ps(lo[0], lo[1]), lo[2]), tlo);
        let t1 = _mm256_min_ps(_mm256_min_ps(_mm256_min_ps(hi[0], hi[1]), hi[2]), thi);
        let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(t0, t1)) as u32;
        let mut entry = [0.0f32; 8];
        // SAFETY: eight lanes, an unaligned store.
        unsafe { _mm256_storeu_ps(entry.as_mut_ptr(), t0) };
        (mask, entry)
    }

    /// [`hit`](Self::hit) with 8-lane AVX ops: the same operations in the same
    /// order per lane (max/min keep their operand order, so NaN lanes behave
    /// alike), hence the same masks and entry parameters.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn hit_avx(&self, n: &Node4, tlo: &F8, thi: &F8) -> [(u32, f32); 4] {
        use std::arch::x86_64::*;
        let eps = _mm256_set1_ps(SLAB_EPS);
        let sign = _mm256_set1_ps(-0.0);
        let (tlo, thi) = (F8::load(tlo), F8::load(thi));
        let o = [F8::load(&self.o[0]), F8::load(&self.o[1]), F8::load(&self.o[2])];
        let inv = [F8::load(&self.inv[0]), F8::load(&self.inv[1]), F8::load(&self.inv[2])];
        // Near and far plane rows per axis, picked once per node.
        let mut rows: [(&[f32; 4], &[f32; 4]); 3] = [(&n.b[0], &n.b[1]), (&n.b[2], &n.b[3]), (&n.b[4], &n.b[5])];
        for (a, r) in rows.iter_mut().enumerate() {
            if self.near[a] != 0 {
                *r = (r.1, r.0);
            }
        }
        // A loop, not a closure: closures do not inherit `target_feature`, and the
        // intrinsics would not be inlined into one.
        let mut out = [(0u32, 0.0f32); 4];
        for (s, slot) in out.iter_mut().enumerate() {
            let mut lo = tlo;
            let mut hi = thi;
            for a in 0..3 {
                let near = _mm256_set1_ps(rows[a].0[s]);
                let far = _mm256_set1_ps(rows[a].1[s]);
                lo = _mm256_max_ps(lo, _mm256_mul_ps(_mm256_sub_ps(near, o[a]), inv[a]));
                hi = _mm256_min_ps(hi, _mm256_mul_ps(_mm256_sub_ps(far, o[a]), inv[a]));
            }
            let l = _mm256_sub_ps(lo, _mm256_mul_ps(_mm256_andnot_ps(sign, lo), eps));
            let h = _mm256_add_ps(hi, _mm256_mul_ps(_mm256_andnot_ps(sign, hi), eps));
            let m = _mm256_cmp_ps::<_CMP_LE_OQ>(l, h);
            let mask = _mm256_movemask_ps(m) as u32;
            // Smallest entry among the lanes hit (the others become +inf).
            let v = _mm256_blendv_ps(_mm256_set1_ps(f32::INFINITY), lo, m);
            let v = _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let v = _mm_min_ps(v, _mm_movehl_ps(v, v));
            let v = _mm_min_ss(v, _mm_shuffle_ps::<1>(v, v));
            *slot = (mask, _mm_cvtss_f32(v));
        }
        out
    }
}

/// The children to visit, near to far, without branching on which were hit:
/// the slots of the `hit` bits (bit s = slot s) sorted by their `t` (ties and
/// the order past the count are arbitrary), and how many there are. The sort
/// key is `t`'s order-preserving bit pattern with its two low bits replaced by
/// the slot, so the order may differ from exact for `t`s a few ulps apart; it
/// only steers the walk, the pruning uses the exact `t`.
#[inline(always)]
pub(crate) fn order4(t: [f32; 4], hit: u32) -> ([u32; 4], usize) {
    let mut k: [u32; 4] = std::array::from_fn(|s| {
        let b = t[s].to_bits();
        let ord = b ^ (((b as i32) >> 31) as u32 | 0x8000_0000);
        let key = (ord & !3) | s as u32;
        if hit & (1 << s) != 0 {
            key
        } else {
            !3 | s as u32
        }
    });
    let mut cx = |i: usize, j: usize| {
        let (a, b) = (k[i], k[j]);
        k[i] = a.min(b);
        k[j] = a.max(b);
    };
    cx(0, 1);
    cx(2, 3);
    cx(0, 2);
    cx(1, 3);
    cx(1, 2);
    (k.map(|x| x & 3), (hit & 0xf).count_ones() as usize)
}

/// Eight rays from one origin whose directions share an octant, as an interval
/// packet for the nearest-crossing walk: per axis, the smallest and largest
/// inverse direction component. Rounding is monotone, so each ray's own slab
/// parameter `(plane - o) * inv` lies between the two products with the bounds,
/// and one 4-wide test per node (about the cost of one ray's) is conservative
/// for every ray of the packet.
pub(super) struct Frustum8 {
    o: [Vec4; 3],
    inv_lo: [Vec4; 3],
    inv_hi: [Vec4; 3],
    near: [usize; 3],
}

impl Frustum8 {
    /// `None` when the rays of `active` do not share an octant or some direction
    /// component is zero.
    #[inline(always)]
    pub(super) fn new(o: Vec3, d: &[Vec3; 8], active: u32) -> Option<Frustum8> {
        // Per axis, four rays at a time and without branches (the per-ray loop
        // it replaces was ~5% of the renderer's walk): each inactive lane takes
        // an active lane's direction, which changes no minimum, maximum or sign.
        let k0 = active.trailing_zeros() as usize;
        if k0 >= 8 {
            return None;
        }
        let dir = |k: usize| if active & (1 << k) != 0 { d[k] } else { d[k0] };
        let dd: [Vec3; 8] = std::array::from_fn(dir);
        let mut inv_lo = [Vec4::ZERO; 3];
        let mut inv_hi = [Vec4::ZERO; 3];
        let mut near = [0usize; 3];
        for a in 0..3 {
            let ([h0, h1], neg, pos) = axis_signs(&dd, a);
            // One octant, no zero component.
            if !(neg == 0xff || pos == 0xff) {
                return None;
            }
            let (i0, i1) = (h0.recip(), h1.recip());
            let (lo, hi) = (i0.min(i1).min_element(), i0.max(i1).max_element());
            if !lo.is_finite() || !hi.is_finite() {
                return None;
            }
            inv_lo[a] = Vec4::splat(lo);
            inv_hi[a] = Vec4::splat(hi);
            near[a] = (neg == 0xff) as usize;
        }
        Some(Frustum8 { o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)], inv_lo, inv_hi, near })
    }

    /// The children some ray of the packet may meet within `[tlo, thi]` (the
    /// smallest start and largest end over the rays), with a lower bound of
    /// every ray's entry parameter per child.
    #[inline(always)]
    pub(super) fn hit(&self, n: &Node4, tlo: f32, thi: f32) -> (u32, Vec4) {
        let mut lo = Vec4::splat(tlo);
        let mut hi = Vec4::splat(thi);
        for a in 0..3 {
            let dn = Vec4::from_array(n.b[2 * a + self.near[a]]) - self.o[a];
            let df = Vec4::from_array(n.b[2 * a + 1 - self.near[a]]) - self.o[a];
            lo = lo.max((dn * self.inv_lo[a]).min(dn * self.inv_hi[a]));
            hi = hi.min((df * self.inv_lo[a]).max(df * self.inv_hi[a]));
        }
        let eps = Vec4::splat(SLAB_EPS);
        let m = (lo - lo.abs() * eps).cmple(hi + hi.abs() * eps);
        (m.bitmask(), lo)
    }
}
