//! A plane in which every ray of a region is one point: the rays through
//! one eye (a tile of camera rays) seen in perspective from it, or rays of
//! one direction (a tile's shadow rays to a directional light) seen along
//! it. A box that a ray meets holds a point of the ray, so the ray's point
//! lies in the box's shadow on the plane ([`RayPlane::box2d`], a
//! conservative 2D box); a packet of rays whose points all lie outside that
//! shadow cannot meet the box. Tiles list the children of a wide union with
//! their shadows once, and each packet keeps those whose shadow meets its
//! own points' box, instead of walking the union's tree
//! (see `rothray_csg::tile`).

use glam::{DVec3, Vec3};

use crate::aabb::Aabb;

/// See the module documentation.
#[derive(Clone, Copy, Debug)]
pub struct RayPlane {
    /// Perspective from `at` (rays must start there), or orthographic along
    /// `dir` (rays must have exactly that direction) with `at` a reference
    /// point near the region.
    persp: bool,
    at: Vec3,
    /// Orthographic: how far ray origins lie from `at` at most.
    spread: f64,
    dir: Vec3,
    at64: DVec3,
    /// Orthonormal: `w` along the view (perspective: the region's mid
    /// direction; orthographic: `dir`), `u` and `v` across it.
    u: DVec3,
    v: DVec3,
    w: DVec3,
}

/// A 2D box `[u0, v0, u1, v1]`; all of the plane is `[-inf, -inf, inf, inf]`.
pub type Box2 = [f32; 4];

/// The whole plane.
pub const ALL: Box2 = [f32::NEG_INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::INFINITY];

/// Relative slack on the shadows: an f32 slab test can accept a ray that
/// misses the box by a few ulps of the distances involved (1e-7 relative);
/// the shadows are grown by 100 times that.
const SLACK: f64 = 1e-5;

fn basis(w: DVec3) -> (DVec3, DVec3) {
    let u = w.any_orthonormal_vector();
    (u, w.cross(u))
}

impl RayPlane {
    /// Rays from `eye` with directions `d` where `d . mid > 0`, seen from the eye.
    pub fn perspective(eye: Vec3, mid: Vec3) -> Option<RayPlane> {
        let w = mid.as_dvec3().normalize_or_zero();
        if w == DVec3::ZERO || !eye.is_finite() {
            return None;
        }
        let (u, v) = basis(w);
        Some(RayPlane { persp: true, at: eye, spread: 0.0, dir: Vec3::ZERO, at64: eye.as_dvec3(), u, v, w })
    }

    /// Rays of direction exactly `dir` from points within `spread` of `near`.
    pub fn orthographic(dir: Vec3, near: Vec3, spread: f32) -> Option<RayPlane> {
        let w = dir.as_dvec3().normalize_or_zero();
        if w == DVec3::ZERO || !near.is_finite() {
            return None;
        }
        let (u, v) = basis(w);
        Some(RayPlane { persp: false, at: near, spread: spread as f64, dir, at64: near.as_dvec3(), u, v, w })
    }

    /// The point of the ray `(o, d)`, or `None` when it is not a ray of the
    /// plane (another origin, for a perspective; another direction, for an
    /// orthographic one) or its point is not finite.
    #[inline]
    pub fn point(&self, o: Vec3, d: Vec3) -> Option<[f64; 2]> {
        let p = if self.persp {
            let d = d.as_dvec3();
            let z = d.dot(self.w);
            if o != self.at || !(z > 0.0) {
                return None;
            }
            // One reciprocal, two products (as `lanes_box`): its rounding, a
            // few 1e-16 of the point, is far inside the shadows' slack.
            let r = 1.0 / z;
            [d.dot(self.u) * r, d.dot(self.v) * r]
        } else {
            if d != self.dir {
                return None;
            }
            let q = o.as_dvec3() - self.at64;
            [q.dot(self.u), q.dot(self.v)]
        };
        (p[0].is_finite() && p[1].is_finite()).then_some(p)
    }

    /// [`RayPlane::points_box`] of the points of the lanes `lanes` (bit `k`
    /// for lane `k`) of the rays `(o[k], d[k])`: `None` when one of them
    /// is not a ray of the plane or its point is not finite
    /// ([`RayPlane::point`]), `Some(None)` when `lanes` is empty. The same
    /// numbers, all lanes at once (lane by lane, through `point`, it was
    /// some 500 instructions per packet walk of scenes/forest's union,
    /// callgrind).
    pub fn lanes_box(&self, (o, d): (&[Vec3; 8], &[Vec3; 8]), lanes: u32) -> Option<Option<Box2>> {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F.
                return unsafe { self.lanes_box_avx512((o, d), lanes) };
            }
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the CPU has AVX.
                return unsafe { self.lanes_box_avx((o, d), lanes) };
            }
        }
        self.lanes_box_in((o, d), lanes)
    }

    /// [`RayPlane::lanes_box`] compiled for AVX-512F: the eight lanes' f64
    /// products and divisions in one register each (the same IEEE
    /// operations in the same order as the baseline, so the same numbers;
    /// in SSE2, two lanes a division, it was 4.9% of
    /// benches/scenes/forest_deep's cycles lit, perf, one thread).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn lanes_box_avx512(&self, rays: (&[Vec3; 8], &[Vec3; 8]), lanes: u32) -> Option<Option<Box2>> {
        self.lanes_box_in(rays, lanes)
    }

    /// [`RayPlane::lanes_box`] compiled for AVX (four lanes a register).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn lanes_box_avx(&self, rays: (&[Vec3; 8], &[Vec3; 8]), lanes: u32) -> Option<Option<Box2>> {
        self.lanes_box_in(rays, lanes)
    }

    /// [`RayPlane::lanes_box`] with the instructions of the caller's target
    /// (the SSE2 baseline, for tests too: the same answers).
    #[doc(hidden)]
    #[inline(always)]
    pub fn lanes_box_in(&self, (o, d): (&[Vec3; 8], &[Vec3; 8]), lanes: u32) -> Option<Option<Box2>> {
        let mut pu = [0.0f64; 8];
        let mut pv = [0.0f64; 8];
        let mut bad = 0u32;
        let (u, v, w) = (self.u, self.v, self.w);
        // (`&`, not `&&`, and selects, not `f64::min`: branch-free lanes.)
        let same = |a: Vec3, b: Vec3| (a.x == b.x) & (a.y == b.y) & (a.z == b.z);
        if self.persp {
            // In arrays, lane after lane, so that the compiler does the
            // lanes' divisions together (sixteen scalar divisions were most
            // of this function's cycles: 4% of benches/scenes/forest_deep
            // flat, perf); each lane's numbers are `point`'s.
            let (x, y, z): ([f64; 8], [f64; 8], [f64; 8]) =
                (std::array::from_fn(|k| d[k].x as f64), std::array::from_fn(|k| d[k].y as f64), std::array::from_fn(|k| d[k].z as f64));
            let depth: [f64; 8] = std::array::from_fn(|k| x[k] * w.x + y[k] * w.y + z[k] * w.z);
            let nu: [f64; 8] = std::array::from_fn(|k| x[k] * u.x + y[k] * u.y + z[k] * u.z);
            let nv: [f64; 8] = std::array::from_fn(|k| x[k] * v.x + y[k] * v.y + z[k] * v.z);
            // (One division a lane, as `point`: with two, forest_deep flat
            // took 1.2% longer, one thread.)
            let r: [f64; 8] = std::array::from_fn(|k| 1.0 / depth[k]);
            for k in 0..8 {
                pu[k] = nu[k] * r[k];
                pv[k] = nv[k] * r[k];
            }
            for k in 0..8 {
                bad |= (!same(o[k], self.at) | !(depth[k] > 0.0)) as u32 * (1 << k);
            }
        } else {
            for k in 0..8 {
                let (x, y, z) = (o[k].x as f64 - self.at64.x, o[k].y as f64 - self.at64.y, o[k].z as f64 - self.at64.z);
                pu[k] = x * u.x + y * u.y + z * u.z;
                pv[k] = x * v.x + y * v.y + z * v.z;
                bad |= !same(d[k], self.dir) as u32 * (1 << k);
            }
        }
        let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for k in 0..8 {
            let (x, y) = (pu[k], pv[k]);
            let on = lanes & (1 << k) != 0;
            bad |= ((on & !(x.is_finite() & y.is_finite())) as u32) << k;
            b[0] = if on & (x < b[0]) { x } else { b[0] };
            b[1] = if on & (y < b[1]) { y } else { b[1] };
            b[2] = if on & (x > b[2]) { x } else { b[2] };
            b[3] = if on & (y > b[3]) { y } else { b[3] };
        }
        if bad & lanes != 0 {
            return None;
        }
        Some(Self::grown(b))
    }

    /// The 2D box of the points of the rays of `pts` (none: `None`), grown
    /// by the rounding of their computation ([`SLACK`] of their size).
    pub fn points_box(pts: impl Iterator<Item = [f64; 2]>) -> Option<Box2> {
        let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for p in pts {
            b = [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])];
        }
        Self::grown(b)
    }

    /// [`RayPlane::points_box`] of the points whose box is `b` (`None`
    /// when it is empty).
    #[inline(always)]
    fn grown(b: [f64; 4]) -> Option<Box2> {
        if !(b[0] <= b[2]) {
            return None;
        }
        let s = SLACK * (b[0].abs().max(b[1].abs()).max(b[2].abs()).max(b[3].abs()));
        Some(outward([b[0] - s, b[1] - s, b[2] + s, b[3] + s]))
    }

    /// A 2D box holding the point of every ray of the plane that an f32
    /// slab test ([`Aabb::ray_range`]) says meets `b` ([`ALL`] when the box
    /// reaches the eye's side plane, or is not finite).
    pub fn box2d(&self, b: &Aabb) -> Box2 {
        if !b.is_finite() || b.is_empty() {
            return ALL;
        }
        let c = (b.min.as_dvec3() + b.max.as_dvec3()) * 0.5 - self.at64;
        let h = (b.max.as_dvec3() - b.min.as_dvec3()) * 0.5;
        // The box's extent along each plane axis (the sum of its half
        // extents' projections), and how far it lies from `at`, for the slack.
        let ext = |a: DVec3| a.abs().dot(h);
        let (cu, cv, cw) = (c.dot(self.u), c.dot(self.v), c.dot(self.w));
        let (hu, hv, hw) = (ext(self.u), ext(self.v), ext(self.w));
        let size = c.abs().max_element() + h.max_element();
        if !self.persp {
            // A ray origin's distance to the box's planes, which the slab
            // test's rounding is relative to, is at most `size` plus its own
            // distance to `at`.
            let s = SLACK * (size + self.spread);
            return outward([cu - hu - s, cv - hv - s, cu + hu + s, cv + hv + s]);
        }
        // Perspective: every point of the box has depth in [cw - hw, cw + hw]
        // and plane coordinates in [cu - hu, cu + hu] (resp. v), so its
        // projection lies in the quotients' interval.
        let z0 = cw - hw;
        if z0 <= SLACK * size {
            return ALL;
        }
        let z1 = cw + hw;
        // Two reciprocals, not eight divisions (box2d runs for every child a
        // tile lists): a product's rounding, a few 1e-16 of the quotient,
        // is far inside the slack below (1e-5 of the size over the depth).
        let (r0, r1) = (1.0 / z0, 1.0 / z1);
        let div = |n0: f64, n1: f64| {
            let q = [n0 * r0, n0 * r1, n1 * r0, n1 * r1];
            (q[0].min(q[1]).min(q[2]).min(q[3]), q[0].max(q[1]).max(q[2]).max(q[3]))
        };
        let (u0, u1) = div(cu - hu, cu + hu);
        let (v0, v1) = div(cv - hv, cv + hv);
        let s = SLACK * size / z0;
        outward([u0 - s, v0 - s, u1 + s, v1 + s])
    }
}

/// `b` in f32, rounded outwards: a conversion rounds to nearest, and one
/// ulp more always covers it (taken whether or not the conversion rounded
/// inwards: which way it rounded was a branch no predictor learns, for
/// every child a tile lists); [`ALL`] if a bound is NaN (an overflow on the
/// way: a NaN bound would meet nothing and drop the box).
fn outward(b: [f64; 4]) -> Box2 {
    if b.iter().any(|x| x.is_nan()) {
        return ALL;
    }
    [(b[0] as f32).next_down(), (b[1] as f32).next_down(), (b[2] as f32).next_up(), (b[3] as f32).next_up()]
}

/// Do the 2D boxes meet?
#[inline(always)]
pub fn meets(a: &Box2, b: &Box2) -> bool {
    // `&`, not `&&`: one branch on the four compares instead of four hard
    // to predict ones (a packet filters a tile's list with it).
    (a[0] <= b[2]) & (b[0] <= a[2]) & (a[1] <= b[3]) & (b[1] <= a[3])
}

/// Writes to `met` (as long as the shadows) the indices of the shadows
/// `[x0, y0, x1, y1]` that meet `pb` ([`meets`]), in order; returns how
/// many: sixteen shadows a step in AVX-512 where the CPU has it, eight in
/// AVX2 ([`meets_all_avx2`]), four in SSE2 otherwise ([`meets_all_sse2`]).
/// Either way the same compares, so the same indices.
pub fn meets_all(pb: &Box2, sides: &[Vec<f32>; 4], met: &mut [u32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F.
            return unsafe { meets_all_avx512(pb, sides, met) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { meets_all_avx2(pb, sides, met) };
        }
    }
    meets_all_sse2(pb, sides, met)
}

/// Per mask of eight lanes, the set lanes' numbers first, in order (the
/// rest 0): the permutation that packs the lanes a mask selects.
#[cfg(target_arch = "x86_64")]
const PACK8: [[u8; 8]; 256] = {
    let mut t = [[0u8; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut k, mut j) = (0, 0);
        while k < 8 {
            if m & (1 << k) != 0 {
                t[m][j] = k as u8;
                j += 1;
            }
            k += 1;
        }
        m += 1;
    }
    t
};

/// [`meets_all`] eight shadows a step in AVX2: one mask of the four
/// compares, and the indices it selects packed by one permutation from a
/// table ([`PACK8`]) and stored at once, instead of a loop over the set
/// bits (AVX2 has no compress). `_CMP_LE_OQ` is `<=` (false with a NaN),
/// as [`meets`] and the SSE2 `cmpleps` compare.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[doc(hidden)]
pub unsafe fn meets_all_avx2(pb: &Box2, [x0, y0, x1, y1]: &[Vec<f32>; 4], met: &mut [u32]) -> usize {
    use std::arch::x86_64::*;
    let n = x0.len();
    assert!(met.len() >= n && y0.len() == n && x1.len() == n && y1.len() == n);
    let (a0, a1, a2, a3) = (_mm256_set1_ps(pb[0]), _mm256_set1_ps(pb[1]), _mm256_set1_ps(pb[2]), _mm256_set1_ps(pb[3]));
    let mut idx = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let step = _mm256_set1_epi32(8);
    let mut m = 0;
    let mut i = 0;
    while i + 8 <= n {
        // SAFETY: eight floats from `i`, with `i + 8 <= n` in arrays of length `n`.
        let (vx0, vy0, vx1, vy1) = unsafe {
            let p = |v: &Vec<f32>| v.as_ptr().add(i);
            (_mm256_loadu_ps(p(x0)), _mm256_loadu_ps(p(y0)), _mm256_loadu_ps(p(x1)), _mm256_loadu_ps(p(y1)))
        };
        let c = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(a0, vx1), _mm256_cmp_ps::<_CMP_LE_OQ>(vx0, a2)),
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(a1, vy1), _mm256_cmp_ps::<_CMP_LE_OQ>(vy0, a3)),
        );
        let bits = _mm256_movemask_ps(c) as usize;
        // SAFETY: a table row is eight bytes; eight u32 stored from `m`, with
        // `m <= i` and `i + 8 <= n <= met.len()` (lanes past the set ones
        // are written over by the next step or lie past the count).
        unsafe {
            let perm = _mm256_cvtepu8_epi32(_mm_loadl_epi64(PACK8[bits].as_ptr().cast()));
            _mm256_storeu_si256(met.as_mut_ptr().add(m).cast(), _mm256_permutevar8x32_epi32(idx, perm));
        }
        m += bits.count_ones() as usize;
        idx = _mm256_add_epi32(idx, step);
        i += 8;
    }
    for j in i..n {
        met[m] = j as u32;
        m += meets(pb, &[x0[j], y0[j], x1[j], y1[j]]) as usize;
    }
    m
}

/// [`meets_all`] sixteen shadows a step: one mask of the four compares,
/// and the indices it selects stored packed by one compress (in SSE2 the
/// loop over the set bits of each four, with its mispredicted exits, was
/// most of this filter's cycles: 3-5% of benches/scenes/forest_deep flat
/// and forest lit, perf). `_CMP_LE_OQ` is `<=` (false with a NaN), as
/// [`meets`] and the SSE2 `cmpleps` compare.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn meets_all_avx512(pb: &Box2, [x0, y0, x1, y1]: &[Vec<f32>; 4], met: &mut [u32]) -> usize {
    use std::arch::x86_64::*;
    let n = x0.len();
    assert!(met.len() >= n && y0.len() == n && x1.len() == n && y1.len() == n);
    let (a0, a1, a2, a3) = (_mm512_set1_ps(pb[0]), _mm512_set1_ps(pb[1]), _mm512_set1_ps(pb[2]), _mm512_set1_ps(pb[3]));
    let mut idx = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let step = _mm512_set1_epi32(16);
    let mut m = 0;
    let mut i = 0;
    while i < n {
        // The last step loads only the lanes left (masked loads read nothing past `n`).
        let live: __mmask16 = if n - i >= 16 { 0xffff } else { (1u16 << (n - i)) - 1 };
        // SAFETY: lanes of `live` lie below `n` in arrays of length `n`.
        let ld = |v: &Vec<f32>| unsafe { _mm512_maskz_loadu_ps(live, v.as_ptr().add(i)) };
        let c = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, a0, ld(x1))
            & _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, ld(x0), a2)
            & _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, a1, ld(y1))
            & _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, ld(y0), a3);
        // SAFETY: `m` plus the set bits of `c` (indices below `n`, each
        // counted once) is at most `n <= met.len()`.
        unsafe { _mm512_mask_compressstoreu_epi32(met.as_mut_ptr().add(m).cast(), c, idx) };
        m += c.count_ones() as usize;
        idx = _mm512_add_epi32(idx, step);
        i += 16;
    }
    m
}

/// [`meets_all`] four shadows a step in SSE2 (one at a time, the compares
/// and their branches were 7% of benches/scenes/forest's cycles, perf),
/// each as [`meets`] tests it.
fn meets_all_sse2(pb: &Box2, [x0, y0, x1, y1]: &[Vec<f32>; 4], met: &mut [u32]) -> usize {
    let n = x0.len();
    let mut m = 0;
    let mut i = 0;
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of x86_64; unaligned loads of four floats
        // from `i`, with `i + 4 <= n` for arrays of length `n`.
        unsafe {
            let (a0, a1, a2, a3) = (_mm_set1_ps(pb[0]), _mm_set1_ps(pb[1]), _mm_set1_ps(pb[2]), _mm_set1_ps(pb[3]));
            while i + 4 <= n {
                let ld = |v: &Vec<f32>| _mm_loadu_ps(v.as_ptr().add(i));
                // (a[0] <= b[2]) & (b[0] <= a[2]) & (a[1] <= b[3]) & (b[1] <= a[3])
                let c = _mm_and_ps(
                    _mm_and_ps(_mm_cmple_ps(a0, ld(x1)), _mm_cmple_ps(ld(x0), a2)),
                    _mm_and_ps(_mm_cmple_ps(a1, ld(y1)), _mm_cmple_ps(ld(y0), a3)),
                );
                // (Most children of a tile's list miss a packet's points:
                // only the set bits are written.)
                let mut bits = _mm_movemask_ps(c) as u32;
                while bits != 0 {
                    met[m] = (i as u32) + bits.trailing_zeros();
                    m += 1;
                    bits &= bits - 1;
                }
                i += 4;
            }
        }
    }
    for j in i..n {
        met[m] = j as u32;
        m += meets(pb, &[x0[j], y0[j], x1[j], y1[j]]) as usize;
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// Every ray that the f32 slab test says meets a box has its point in
    /// the box's shadow: random boxes and rays grazing them, perspective and
    /// orthographic, near and far from the origin.
    #[test]
    fn a_ray_meeting_a_box_lies_in_its_shadow() {
        let seed = 41u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut met = 0;
        for i in 0..200_000 {
            let far = [0.0f32, 1e3, 1e5][i % 3];
            let c = Vec3::new(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0)) + Vec3::splat(far);
            let h = Vec3::new(rng.gen_range(0.001..2.0), rng.gen_range(0.001..2.0), rng.gen_range(0.001..2.0));
            let b = Aabb::new(c - h, c + h);
            // Aim at a point near a corner or face of the box.
            let mut target = c + h * Vec3::new(rng.gen_range(-1.02..1.02), rng.gen_range(-1.02..1.02), rng.gen_range(-1.02..1.02));
            if rng.gen_bool(0.5) {
                target[i % 3] = if rng.gen_bool(0.5) { b.min[i % 3] } else { b.max[i % 3] };
            }
            let (o, d, plane) = if i % 2 == 0 {
                let eye = c + Vec3::new(rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0));
                let d = target - eye;
                let mid = d + Vec3::new(rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1)) * d.length();
                (eye, d, RayPlane::perspective(eye, mid).unwrap())
            } else {
                let dir = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                let o = target - dir * rng.gen_range(0.0..20.0);
                let at = c + Vec3::splat(rng.gen_range(-3.0..3.0));
                (o, dir, RayPlane::orthographic(dir, at, (o - at).length()).unwrap())
            };
            if b.ray_range(o, d.recip(), 0.0, f32::INFINITY).is_none() {
                continue;
            }
            met += 1;
            let p = plane.point(o, d).expect("a ray of the plane");
            let pb = RayPlane::points_box(std::iter::once(p)).unwrap();
            assert!(meets(&pb, &plane.box2d(&b)), "case {i}: ray {o} {d} meets {b:?} outside its shadow");
        }
        assert!(met > 50_000, "too few rays met their boxes: {met}");
    }

    /// `lanes_box` (the AVX-512 or AVX build where the CPU has it, and the
    /// SSE2 baseline) gives what `point` lane by lane and `points_box` give,
    /// for random masks, with lanes that are not rays of the plane (another
    /// origin or direction, a direction behind the eye, zero or infinite)
    /// inside and outside the mask.
    #[test]
    fn lanes_box_is_points_box_of_the_points() {
        let seed = 43u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let v3 = |rng: &mut SmallRng, r: f32| Vec3::new(rng.gen_range(-r..r), rng.gen_range(-r..r), rng.gen_range(-r..r));
        let (mut some, mut none) = (0, 0);
        for case in 0..20_000 {
            let eye = v3(&mut rng, [1.0, 1e3, 1e5][case % 3]);
            let dir = v3(&mut rng, 1.0);
            let persp = case % 2 == 0;
            let plane = if persp { RayPlane::perspective(eye, dir) } else { RayPlane::orthographic(dir, eye, 10.0) };
            let Some(plane) = plane else { continue };
            let mut o = [eye; 8];
            let mut d = [dir; 8];
            for k in 0..8 {
                if persp {
                    d[k] = dir + v3(&mut rng, 0.3);
                } else {
                    o[k] = eye + v3(&mut rng, 5.0);
                }
                match rng.gen_range(0..40) {
                    0 => o[k] += Vec3::X * 1e-3,
                    1 => d[k] = -d[k],
                    2 => d[k] = Vec3::ZERO,
                    3 => d[k].y += 1e-6,
                    // (An infinite direction: a point that is not finite.)
                    4 => d[k].x = f32::INFINITY,
                    _ => {}
                }
            }
            let lanes = rng.gen_range(0..256u32);
            let mut pts = Vec::new();
            let mut want = Some(());
            for k in 0..8 {
                if lanes & (1 << k) != 0 {
                    match plane.point(o[k], d[k]) {
                        Some(p) => pts.push(p),
                        None => want = None,
                    }
                }
            }
            let want = want.map(|_| RayPlane::points_box(pts.into_iter()));
            let got = plane.lanes_box((&o, &d), lanes);
            assert_eq!(got, want, "case {case}: lanes {lanes:#x} of {o:?} {d:?}");
            // The baseline build gives the same as the one this CPU takes.
            assert_eq!(plane.lanes_box_in((&o, &d), lanes), got, "case {case}: baseline");
            if got.is_some() {
                some += 1;
            } else {
                none += 1;
            }
        }
        assert!(some > 5000 && none > 2000, "cases: {some} with a box, {none} without");
    }

    /// Out of range: a shadow that would overflow or be NaN covers the whole
    /// plane, and a ray whose point is not finite is not a ray of the plane
    /// (its packet walks the tree instead).
    #[test]
    fn overflows_cover_everything() {
        let p = RayPlane::perspective(Vec3::ZERO, Vec3::Z).unwrap();
        let huge = Aabb::new(Vec3::new(-3e38, -3e38, 1e-30), Vec3::new(3e38, 3e38, 3e38));
        assert!(meets(&p.box2d(&huge), &[0.0, 0.0, 0.0, 0.0]));
        assert_eq!(p.box2d(&Aabb::new(Vec3::splat(-1.0), Vec3::splat(f32::INFINITY))), ALL);
        assert!(p.point(Vec3::ZERO, Vec3::new(1.0, 0.0, 1e-45)).is_none_or(|q| q[0].is_finite()));
        assert!(p.point(Vec3::ONE, Vec3::Z).is_none(), "another origin");
        let o = RayPlane::orthographic(Vec3::Y, Vec3::ZERO, 1.0).unwrap();
        assert!(o.point(Vec3::ZERO, Vec3::new(0.0, 1.0, 1e-7)).is_none(), "another direction");
        let far = Aabb::new(Vec3::splat(-3e38), Vec3::splat(3e38));
        assert!(meets(&o.box2d(&far), &[0.0, 0.0, 0.0, 0.0]));
    }

    /// `meets_all` (the AVX-512 build where the CPU has it), its AVX2 build
    /// and its SSE2 build list exactly the shadows `meets` accepts, in
    /// order, for every length (whole steps of 16, 8 and 4, and the tails),
    /// with infinite and NaN sides and shared edges.
    #[test]
    fn meets_all_lists_what_meets_accepts() {
        let mut s = 0x2545f491u32;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s
        };
        let vals = [0.0f32, -0.0, 0.5, 1.0, -1.0, 2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-30];
        for case in 0..3000 {
            let mut pick = || if next() % 4 == 0 { vals[(next() % 10) as usize] } else { (next() % 2000) as f32 / 500.0 - 2.0 };
            let pb = [pick(), pick(), pick(), pick()];
            let n = (case % 41) as usize;
            let boxes: Vec<Box2> = (0..n).map(|_| [pick(), pick(), pick(), pick()]).collect();
            let sides: [Vec<f32>; 4] = std::array::from_fn(|c| boxes.iter().map(|b| b[c]).collect());
            let want: Vec<u32> = (0..n as u32).filter(|&i| meets(&pb, &boxes[i as usize])).collect();
            let mut met = vec![0; n];
            let m = meets_all(&pb, &sides, &mut met);
            assert_eq!(&met[..m], &want[..], "case {case}: {pb:?} against {boxes:?}");
            let mut met = vec![0; n];
            let m = meets_all_sse2(&pb, &sides, &mut met);
            assert_eq!(&met[..m], &want[..], "case {case}, SSE2: {pb:?} against {boxes:?}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut met = vec![0; n];
                // SAFETY: the CPU has AVX2.
                let m = unsafe { meets_all_avx2(&pb, &sides, &mut met) };
                assert_eq!(&met[..m], &want[..], "case {case}, AVX2: {pb:?} against {boxes:?}");
            }
        }
    }
}
