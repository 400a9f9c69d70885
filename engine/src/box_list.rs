//! A short list of boxes that every ray of a tile tests: the tile's bounded
//! objects. Stored four to a group, struct-of-arrays, and tested four at a
//! time with SSE2 (the x86-64 baseline: no run-time dispatch needed), with
//! the arithmetic of [`Aabb::ray_range`] lane by lane, so a box's entry is the
//! one [`entry`] gives on the scalar path (after [`canonical`]).

use rothray_primitives::{
    aabb::{near_of_key, nearest_first},
    box_wide::BoxTest8,
    Aabb, Ray,
};

/// Four boxes, SoA; lanes past `len` are unused.
#[derive(Clone, Copy, Debug, Default)]
struct Group {
    min: [[f32; 4]; 3],
    max: [[f32; 4]; 3],
    id: [u32; 4],
}

impl Group {
    /// Box `j` of the four.
    #[inline(always)]
    fn aabb(&self, j: usize) -> Aabb {
        Aabb::new(
            glam::Vec3::new(self.min[0][j], self.min[1][j], self.min[2][j]),
            glam::Vec3::new(self.max[0][j], self.max[1][j], self.max[2][j]),
        )
    }
}

/// A packet's box tests ([`BoxList::packet_tests_from`]): its eight rays
/// and their ranges `(tmin, tmax)`.
pub struct PacketBoxes<'a> {
    pub test: &'a BoxTest8,
    pub range: (&'a [f32; 8], &'a [f32; 8]),
}

/// Boxes with ids, tested together against a ray.
#[derive(Clone, Debug)]
pub struct BoxList {
    groups: Vec<Group>,
    len: usize,
    /// Where the rays start, when the boxes are nearest first from there
    /// ([`BoxList::fill`]); else empty.
    origins: Aabb,
    /// Per box, its [`Aabb::near_from`] `origins` (with `origins` empty:
    /// 0).
    near: Vec<f32>,
    /// Scratch of [`BoxList::fill`].
    order: Vec<(Aabb, u32)>,
    keys: Vec<u64>,
}

impl Default for BoxList {
    fn default() -> BoxList {
        BoxList { groups: Vec::new(), len: 0, origins: Aabb::EMPTY, near: Vec::new(), order: Vec::new(), keys: Vec::new() }
    }
}

/// The entry `t0` of a box as the candidates of a ray are ordered by it:
/// `+0.0` for a zero of either sign (the scalar and SIMD `min` / `max` may
/// disagree on the sign of a zero, and `total_cmp` orders the two).
#[inline(always)]
pub fn canonical(t0: f32) -> f32 {
    t0 + 0.0
}

/// The entry of the ray's range into box `b` ([`Aabb::ray_range`]), made
/// [`canonical`]; `None` when it misses.
#[inline(always)]
pub fn entry(b: &Aabb, ray: &Ray) -> Option<f32> {
    b.ray_range(ray.origin, ray.inv_dir, ray.tmin, ray.tmax).map(|(t0, _)| canonical(t0))
}

impl BoxList {
    /// Forgets every box (keeps the memory).
    pub fn clear(&mut self) {
        self.groups.clear();
        self.near.clear();
        self.len = 0;
        self.origins = Aabb::EMPTY;
    }

    /// Makes the list the boxes `boxes` (box, id; by id) nearest first
    /// from `origins` (then by id), the box where the rays that test them start,
    /// so that a packet can stop at the first box farther than its lanes
    /// reach ([`BoxList::packet_tests_from`]).
    pub fn fill(&mut self, origins: Aabb, boxes: impl Iterator<Item = (Aabb, u32)>) {
        self.clear();
        let (mut order, mut keys) = (std::mem::take(&mut self.order), std::mem::take(&mut self.keys));
        order.clear();
        order.extend(boxes);
        nearest_first(&origins, order.iter().map(|(b, _)| b), &mut keys);
        for &k in &keys {
            let (b, id) = order[k as u32 as usize];
            self.push(&b, id);
            *self.near.last_mut().expect("pushed") = near_of_key(k);
        }
        self.origins = origins;
        (self.order, self.keys) = (order, keys);
    }

    /// Appends box `b` with id `id`.
    pub fn push(&mut self, b: &Aabb, id: u32) {
        self.near.push(0.0);
        let lane = self.len % 4;
        if lane == 0 {
            self.groups.push(Group::default());
        }
        let g = self.groups.last_mut().expect("a group");
        for a in 0..3 {
            g.min[a][lane] = b.min[a];
            g.max[a][lane] = b.max[a];
        }
        g.id[lane] = id;
        self.len += 1;
    }

    /// How many boxes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// The id of the first box (the list must not be empty).
    pub fn first_id(&self) -> u32 {
        self.groups[0].id[0]
    }

    /// Appends `(entry, id)` for every box the ray's range meets, in list
    /// order, with the entries [`entry`] gives.
    #[inline]
    pub fn entries(&self, ray: &Ray, out: &mut Vec<(f32, u32)>) {
        for (gi, g) in self.groups.iter().enumerate() {
            let lanes = (self.len - 4 * gi).min(4);
            let (t0, hit) = group_entries(g, ray);
            for k in 0..lanes {
                if hit & (1 << k) != 0 {
                    out.push((t0[k], g.id[k]));
                }
            }
        }
    }

    /// [`BoxList::entries`] for the eight rays of a packet (`test`, their
    /// ranges `tmin`, `tmax`) at once, lane `k`'s into `out[k]` (cleared
    /// first) for the lanes `lanes`: the same entries bit for bit
    /// ([`BoxTest8::ray_range`] is [`Aabb::ray_range`] lane by lane, then
    /// [`canonical`]), in the same order. One 8-lane test per box instead of
    /// a 4-box test per group and ray: a tile's list of objects was 9% of
    /// the instructions of benches/scenes/capsules (callgrind, 480x270).
    pub fn packet_entries(&self, test: &BoxTest8, range: (&[f32; 8], &[f32; 8]), lanes: u32, out: &mut [Vec<(f32, u32)>; 8]) {
        for v in out.iter_mut() {
            v.clear();
        }
        self.packet_tests(test, range, |id, hit, t0| {
            let mut m = hit & lanes;
            while m != 0 {
                let k = m.trailing_zeros() as usize;
                m &= m - 1;
                out[k].push((canonical(t0[k]), id));
            }
        });
    }

    /// `f(id, lanes hit, entries)` for every box in list order: the
    /// packet's 8-lane test of it (entries not yet [`canonical`]), with AVX
    /// where the CPU has it ([`BoxList::packet_tests_avx`]).
    #[inline(always)]
    pub fn packet_tests(&self, test: &BoxTest8, range: (&[f32; 8], &[f32; 8]), f: impl FnMut(u32, u32, &[f32; 8])) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.packet_tests_avx(test, range, f) };
        }
        self.packet_tests_in(test, range, f)
    }

    /// [`BoxList::packet_tests`] with each box's test in one 8-lane AVX
    /// register ([`BoxTest8::ray_range_avx`]: the same bits) instead of two
    /// SSE halves: the box tests were most of a packet's pick among a tile's
    /// objects, a quarter of benches/scenes/forest_objects' time flat (perf).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn packet_tests_avx(&self, test: &BoxTest8, range: (&[f32; 8], &[f32; 8]), mut f: impl FnMut(u32, u32, &[f32; 8])) {
        let (tmin, tmax) = range;
        for (gi, g) in self.groups.iter().enumerate() {
            for j in 0..(self.len - 4 * gi).min(4) {
                let b = g.aabb(j);
                // SAFETY: the CPU has AVX (this function's feature).
                let (hit, t0) = unsafe { test.ray_range_avx(&b, tmin, tmax) };
                f(g.id[j], hit, &t0);
            }
        }
    }

    /// The id of box `i` (in list order).
    #[cfg(test)]
    fn id(&self, i: usize) -> u32 {
        self.groups[i / 4].id[i % 4]
    }

    /// How many groups of four boxes ([`BoxList::packet_tests_from`]).
    #[inline(always)]
    pub fn groups(&self) -> usize {
        self.groups.len()
    }

    /// `f(id, lanes hit, entries)` for the boxes of groups `g`, `g + 1`
    /// and so on (four boxes a group, the list's last group maybe fewer),
    /// as [`BoxList::packet_tests`] makes them for packet `p`, while the
    /// first box of the next group lies within the limit
    /// ([`BoxList::near`] at most `limit`, then what `f` returns); returns
    /// the first group not tested.
    #[inline(always)]
    pub fn packet_tests_from(&self, g: usize, p: &PacketBoxes, limit: f32, f: impl FnMut(u32, u32, &[f32; 8]) -> f32) -> usize {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.packet_tests_from_avx(g, p, limit, f) };
        }
        self.packet_tests_from_in(g, p, limit, f, |t, b, r| t.ray_range(b, r.0, r.1))
    }

    /// [`BoxList::packet_tests_from`] with AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn packet_tests_from_avx(&self, g: usize, p: &PacketBoxes, limit: f32, f: impl FnMut(u32, u32, &[f32; 8]) -> f32) -> usize {
        // SAFETY: the CPU has AVX (this function's feature).
        self.packet_tests_from_in(g, p, limit, f, |t, b, r| unsafe { t.ray_range_avx(b, r.0, r.1) })
    }

    /// [`BoxList::packet_tests_from`] with the box test `box_test`.
    #[inline(always)]
    fn packet_tests_from_in(
        &self,
        mut g: usize,
        p: &PacketBoxes,
        mut limit: f32,
        mut f: impl FnMut(u32, u32, &[f32; 8]) -> f32,
        box_test: impl Fn(&BoxTest8, &Aabb, (&[f32; 8], &[f32; 8])) -> (u32, [f32; 8]),
    ) -> usize {
        while g < self.groups.len() && self.near[4 * g] <= limit {
            let gr = &self.groups[g];
            for j in 0..(self.len - 4 * g).min(4) {
                let (hit, t0) = box_test(p.test, &gr.aabb(j), p.range);
                limit = f(gr.id[j], hit, &t0);
            }
            g += 1;
        }
        g
    }

    /// [`reach_per_t`](rothray_primitives::aabb::reach_per_t) of the
    /// packet's rays (origins `o`, directions `d`, ranges from `tmin`) from
    /// where the list was filled for: `None` (the distances bound nothing)
    /// unless every ray starts there, on its range's side.
    pub fn reach_per_t(&self, o: &[glam::Vec3; 8], d: &[glam::Vec3; 8], tmin: &[f32; 8]) -> Option<f32> {
        rothray_primitives::aabb::reach_per_t(&self.origins, (o, d, tmin), 0xff)
    }

    /// Box `i`'s [`Aabb::near_from`] the list's origins: at most where a
    /// ray from there enters the box, in units of its direction's length
    /// (0 when not filled by [`BoxList::fill`]).
    pub fn near(&self, i: usize) -> f32 {
        self.near[i]
    }

    /// [`BoxList::packet_tests`] with the SSE2 baseline (also for tests: the same answers).
    #[doc(hidden)]
    #[inline(always)]
    pub fn packet_tests_in(&self, test: &BoxTest8, range: (&[f32; 8], &[f32; 8]), mut f: impl FnMut(u32, u32, &[f32; 8])) {
        for (gi, g) in self.groups.iter().enumerate() {
            for j in 0..(self.len - 4 * gi).min(4) {
                let b = g.aabb(j);
                let (hit, t0) = test.ray_range(&b, range.0, range.1);
                f(g.id[j], hit, &t0);
            }
        }
    }
}

/// The four lanes' entries and the mask of lanes hit.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn group_entries(g: &Group, ray: &Ray) -> ([f32; 4], u32) {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86-64 baseline; loads and stores are unaligned.
    unsafe {
        let o = ray.origin.to_array();
        let inv = ray.inv_dir.to_array();
        let mut tn = [_mm_setzero_ps(); 3];
        let mut tf = [_mm_setzero_ps(); 3];
        for a in 0..3 {
            let oa = _mm_set1_ps(o[a]);
            let ia = _mm_set1_ps(inv[a]);
            let t1 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(g.min[a].as_ptr()), oa), ia);
            let t2 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(g.max[a].as_ptr()), oa), ia);
            // 0 * inf is NaN when a ray parallel to a slab starts on it: the
            // ray touches the box, so NaN widens the range (as `ray_range`).
            let nan = _mm_cmpunord_ps(t1, t2);
            let lo = _mm_min_ps(t1, t2);
            let hi = _mm_max_ps(t1, t2);
            tn[a] = _mm_or_ps(_mm_and_ps(nan, _mm_set1_ps(f32::NEG_INFINITY)), _mm_andnot_ps(nan, lo));
            tf[a] = _mm_or_ps(_mm_and_ps(nan, _mm_set1_ps(f32::INFINITY)), _mm_andnot_ps(nan, hi));
        }
        let t0 = _mm_max_ps(_mm_max_ps(_mm_max_ps(tn[0], tn[1]), tn[2]), _mm_set1_ps(ray.tmin));
        let t1 = _mm_min_ps(_mm_min_ps(_mm_min_ps(tf[0], tf[1]), tf[2]), _mm_set1_ps(ray.tmax));
        let hit = _mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32;
        let mut out = [0.0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), _mm_add_ps(t0, _mm_setzero_ps()));
        (out, hit)
    }
}

/// The four lanes' entries and the mask of lanes hit (scalar, other targets).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn group_entries(g: &Group, ray: &Ray) -> ([f32; 4], u32) {
    let mut out = [0.0f32; 4];
    let mut hit = 0;
    for k in 0..4 {
        let b = g.aabb(k);
        if let Some(t0) = entry(&b, ray) {
            out[k] = t0;
            hit |= 1 << k;
        }
    }
    (out, hit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// The smallest entry of the lanes hit.
    fn masked_min_of(hit: u32, t0: &[f32; 8]) -> f32 {
        (0..8).filter(|k| hit & (1 << k) != 0).map(|k| t0[k]).fold(f32::INFINITY, f32::min)
    }

    /// A coordinate: 0, 1 or -1 (faces at rays' origins, rays along slabs)
    /// or any in [-3, 3).
    fn pick(rng: &mut SmallRng) -> f32 {
        match rng.gen_range(0..6) {
            0 => 0.0,
            1 => 1.0,
            2 => -1.0,
            _ => rng.gen_range(-3.0..3.0),
        }
    }

    /// The grouped SIMD test gives every box the scalar entry, bit for bit,
    /// and the same hits, on random boxes and rays, rays parallel to slabs
    /// and starting on faces included.
    #[test]
    fn simd_entries_are_the_scalar_ones() {
        let seed = 0xb0c5;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut hits, mut n) = (0, 0);
        for _ in 0..2000 {
            let mut list = BoxList::default();
            let mut boxes = Vec::new();
            for id in 0..rng.gen_range(1..11) {
                let a = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
                let b = a + Vec3::new(rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0));
                let bx = Aabb::new(a, b);
                list.push(&bx, id);
                boxes.push(bx);
            }
            let o = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
            // Aimed at a box's centre, or along the axes (parallel to slabs).
            let aim = boxes[rng.gen_range(0..boxes.len())].center() - o;
            let d = if rng.gen_bool(0.7) { aim } else { Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng)) };
            if d == Vec3::ZERO || !d.is_finite() {
                continue;
            }
            let tmin = if rng.gen_bool(0.5) { 0.0 } else { rng.gen_range(-2.0..1.0) };
            let ray = Ray::segment(o, d, tmin, if rng.gen_bool(0.5) { f32::INFINITY } else { rng.gen_range(1.0..4.0) });
            let mut got = Vec::new();
            list.entries(&ray, &mut got);
            let want: Vec<(f32, u32)> = boxes.iter().enumerate().filter_map(|(i, b)| entry(b, &ray).map(|t| (t, i as u32))).collect();
            let bits = |v: &[(f32, u32)]| v.iter().map(|&(t, i)| (t.to_bits(), i)).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "{ray:?} {boxes:?}");
            hits += got.len();
            n += boxes.len();
        }
        assert!(hits * 10 > n && hits < n, "{hits} of {n} boxes hit: too few or all");
    }

    /// A list filled for some origins comes nearest first (then by id),
    /// and each box's [`BoxList::near`] is at most a ray's entry into it
    /// times the length [`BoxList::reach_per_t`] gives, for rays from
    /// anywhere in the origins on ranges from 0 or later: rays aimed at a
    /// box's nearest point (where the two meet but for rounding), at
    /// random points of it, and anywhere; boxes near and far from the
    /// world's origin, small and large. (A shrink of `1 + 1e-6` instead of
    /// `1 - 1e-5` fails here.)
    #[test]
    fn distances_bound_entries() {
        let seed = 0xb0c7;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut hits, mut tight) = (0, 0);
        for case in 0..1500 {
            let scale = 10f32.powi(rng.gen_range(-3..4));
            let shift = if rng.gen_bool(0.3) { Vec3::splat(rng.gen_range(-1e4..1e4)) } else { Vec3::ZERO };
            let point = |rng: &mut SmallRng| shift + Vec3::new(pick(rng), pick(rng), pick(rng)) * scale;
            let a = point(&mut rng);
            let origins = if rng.gen_bool(0.5) {
                Aabb::new(a, a)
            } else {
                Aabb::new(a, a + Vec3::new(rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0)) * scale)
            };
            let boxes: Vec<Aabb> = (0..rng.gen_range(1..20))
                .map(|_| {
                    let lo = point(&mut rng);
                    Aabb::new(lo, lo + Vec3::new(rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0)) * scale)
                })
                .collect();
            let mut list = BoxList::default();
            list.fill(origins, boxes.iter().enumerate().map(|(i, b)| (*b, i as u32)));
            assert_eq!(list.len(), boxes.len());
            for i in 1..list.len() {
                let (p, q) = (list.near(i - 1), list.near(i));
                assert!(p < q || (p == q && list.id(i - 1) < list.id(i)), "case {case}: place {i} out of order");
            }
            for _ in 0..20 {
                let o = origins.min
                    + (origins.max - origins.min) * Vec3::new(rng.gen_range(0.0..=1.0), rng.gen_range(0.0..=1.0), rng.gen_range(0.0..=1.0));
                let o = o.clamp(origins.min, origins.max);
                let b = &boxes[rng.gen_range(0..boxes.len())];
                let aim = match rng.gen_range(0..3) {
                    0 => o.clamp(b.min, b.max),
                    1 => b.min + (b.max - b.min) * Vec3::new(rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0)),
                    _ => o + Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng)),
                };
                let d = (aim - o) * 10f32.powi(rng.gen_range(-2..3));
                if d == Vec3::ZERO || !d.is_finite() {
                    continue;
                }
                let tmin = if rng.gen_bool(0.7) { 0.0 } else { rng.gen_range(0.0..2.0) };
                let ray = Ray::segment(o, d, tmin, f32::INFINITY);
                let s = list.reach_per_t(&[o; 8], &[d; 8], &[tmin; 8]).expect("rays from the origins");
                for i in 0..list.len() {
                    let Some(t0) = entry(&boxes[list.id(i) as usize], &ray) else { continue };
                    hits += 1;
                    assert!(
                        list.near(i) <= t0 * s,
                        "case {case}: box {} near {} past entry {t0} x {s} of {ray:?}",
                        list.id(i),
                        list.near(i)
                    );
                    tight += (list.near(i) > 0.0 && list.near(i) > t0 * s * 0.9999) as u32;
                }
            }
            // Rays that start elsewhere, or behind their ranges, get no bound.
            assert!(list.reach_per_t(&[origins.max + Vec3::splat(scale); 8], &[Vec3::X; 8], &[0.0; 8]).is_none());
            assert!(list.reach_per_t(&[origins.min; 8], &[Vec3::X; 8], &[-1.0; 8]).is_none());
        }
        println!("{hits} entries, {tight} within 1e-4 of the bound");
        assert!(hits > 10_000 && tight > 1000, "{hits} entries, {tight} tight: too few to mean anything");
    }

    /// A packet's entries are each lane's own, bit for bit, in the same
    /// order: packets of eight rays of one octant (from one point, or
    /// parallel, or scattered), ranges of every kind, boxes with faces at
    /// the rays' origins; its box tests are the same bits in AVX and SSE2,
    /// whole and group by group to a limit ([`BoxList::packet_tests_from`]).
    #[test]
    fn packet_entries_are_each_rays() {
        let seed = 0xb0c6;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut hits, mut n, mut packets, mut stopped) = (0, 0, 0, 0);
        for _ in 0..2000 {
            let mut list = BoxList::default();
            let mut boxes = Vec::new();
            for id in 0..rng.gen_range(1..14) {
                let a = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
                let b = a + Vec3::new(rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0), rng.gen_range(0.0..2.0));
                list.push(&Aabb::new(a, b), id);
                boxes.push(Aabb::new(a, b));
            }
            // From one point, from points near one, or parallel, aimed near
            // a box's centre.
            let base = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng)) * 2.0;
            let aim = boxes[rng.gen_range(0..boxes.len())].center();
            let kind = rng.gen_range(0..3);
            let rays: [Ray; 8] = std::array::from_fn(|_| {
                let jitter = |rng: &mut SmallRng, s: f32| Vec3::new(rng.gen_range(-s..s), rng.gen_range(-s..s), rng.gen_range(-s..s));
                let o = if kind == 0 { base } else { base + jitter(&mut rng, 0.3) };
                let d = if kind == 1 { aim - base } else { aim + jitter(&mut rng, 0.5) - o };
                let tmin = if rng.gen_bool(0.6) { 0.0 } else { rng.gen_range(-2.0..1.0) };
                Ray::segment(o, d, tmin, if rng.gen_bool(0.5) { f32::INFINITY } else { rng.gen_range(1.0..4.0) })
            });
            let Some(test) = BoxTest8::new(&rays.map(|r| r.origin), &rays.map(|r| r.dir)) else { continue };
            packets += 1;
            let lanes = rng.gen_range(1..256u32);
            // The build the CPU takes tests each box as the SSE2 baseline does.
            let range = (&rays.map(|r| r.tmin), &rays.map(|r| r.tmax));
            let (mut fast, mut base) = (Vec::new(), Vec::new());
            list.packet_tests(&test, range, |id, hit, t0| fast.push((id, hit, t0.map(f32::to_bits))));
            list.packet_tests_in(&test, range, |id, hit, t0| base.push((id, hit, t0.map(f32::to_bits))));
            assert_eq!(fast, base, "{rays:?}");
            // And group by group from the nearest, to a limit that shrinks
            // with the entries met: the same boxes, bits and stop; every
            // group tested starts within the limit so far, the first one
            // not tested past it.
            let mut near_list = BoxList::default();
            near_list.fill(Aabb::new(rays[0].origin, rays[0].origin), boxes.iter().enumerate().map(|(i, b)| (*b, i as u32)));
            let g0 = rng.gen_range(0..near_list.groups());
            let limit0 = if rng.gen_bool(0.3) { f32::INFINITY } else { rng.gen_range(0.0..6.0) };
            let shrink = |limit: f32, hit: u32, t0: &[f32; 8]| if hit != 0 { limit.min(masked_min_of(hit, t0) * 2.0) } else { limit };
            let (mut fast, mut base_seen) = (Vec::new(), Vec::new());
            let mut lim = limit0;
            let pb = PacketBoxes { test: &test, range };
            let end = near_list.packet_tests_from(g0, &pb, limit0, |id, hit, t0| {
                fast.push((id, hit, t0.map(f32::to_bits), lim));
                lim = shrink(lim, hit, t0);
                lim
            });
            let mut lim = limit0;
            let end_in = near_list.packet_tests_from_in(
                g0,
                &pb,
                limit0,
                |id, hit, t0| {
                    base_seen.push((id, hit, t0.map(f32::to_bits), lim));
                    lim = shrink(lim, hit, t0);
                    lim
                },
                |t, b, r| t.ray_range(b, r.0, r.1),
            );
            assert_eq!((end, &fast), (end_in, &base_seen), "{rays:?}");
            assert!(end == near_list.groups() || near_list.near(4 * end) > lim, "stopped at group {end} within the limit {lim}");
            assert_eq!(fast.len(), (4 * end).min(near_list.len()) - 4 * g0, "whole groups tested");
            stopped += (end < near_list.groups()) as u32;
            let mut got: [Vec<(f32, u32)>; 8] = Default::default();
            list.packet_entries(&test, (&rays.map(|r| r.tmin), &rays.map(|r| r.tmax)), lanes, &mut got);
            let bits = |v: &[(f32, u32)]| v.iter().map(|&(t, i)| (t.to_bits(), i)).collect::<Vec<_>>();
            for (k, ray) in rays.iter().enumerate() {
                let mut want = Vec::new();
                if lanes & (1 << k) != 0 {
                    list.entries(ray, &mut want);
                    n += list.len();
                }
                assert_eq!(bits(&got[k]), bits(&want), "lane {k} of {rays:?}");
                hits += want.len();
            }
        }
        assert!(packets > 500, "{packets} packets");
        println!("{stopped} group walks stopped short of the list's end");
        assert!(stopped > 100, "{stopped} group walks stopped short");
        println!("{packets} packets, {hits} of {n} boxes hit");
        assert!(hits * 10 > n && hits < n, "{hits} of {n} boxes hit: too few or all");
    }
}
