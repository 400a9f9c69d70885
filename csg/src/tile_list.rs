//! A tile's list of the children of a wide union it keeps whole, each with
//! its shadow on the tile's ray plane ([`RayPlane`]). A packet of the
//! tile's rays visits the children whose shadow meets the box of its own
//! rays' points, instead of walking the union's tree: in a forest of 10 000
//! leaves that walk cost camera and shadow packets some 20 node tests each,
//! where a tile's children are listed and projected once.

use rothray_primitives::glam::Vec3;
use rothray_primitives::ray_plane::{meets, Box2, RayPlane};
use rothray_primitives::Aabb;

/// See the module documentation.
#[derive(Clone, Debug, Default)]
pub struct TileList {
    /// The union's node.
    pub node: u32,
    /// Positions of the children listed (bounded ones whose box the tile's
    /// region touches), their shadows, and their boxes: a copy, so that a
    /// packet reads its children's boxes one after the other instead of
    /// looking each one up through the union's children (a load that waits
    /// on a load: the walk's hottest lines on forest, perf).
    pos: Vec<u32>,
    /// The shadows' sides, one array each (`[x0, y0, x1, y1]` of a
    /// [`Box2`]): a packet tests four at a time.
    shadows: [Vec<f32>; 4],
    boxes: Vec<Aabb>,
}

impl TileList {
    /// Starts the list of node `node`.
    pub(crate) fn reset(&mut self, node: u32) {
        self.node = node;
        self.pos.clear();
        for v in &mut self.shadows {
            v.clear();
        }
        self.boxes.clear();
    }

    /// Lists child position `pos`, of box `b`.
    pub(crate) fn push(&mut self, plane: &RayPlane, pos: u32, b: &Aabb) {
        self.pos.push(pos);
        let s = plane.box2d(b);
        for (v, x) in self.shadows.iter_mut().zip(s) {
            v.push(x);
        }
        self.boxes.push(*b);
    }

    /// How many children are listed.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// Is the list empty?
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// The children that the rays `(o[k], d[k])` of the lanes `lanes` can
    /// meet, with their boxes, or `None` when a lane's ray is not a ray of
    /// `plane` (or its point is not finite: [`RayPlane::point`]). `met` is
    /// scratch: the indices of those children in the list, written without
    /// a branch per child (whether a child's shadow meets the packet's box
    /// is hard to predict; the list is filtered first, then walked).
    #[inline]
    pub(crate) fn for_rays<'a>(
        &'a self,
        plane: &RayPlane,
        rays: (&[Vec3; 8], &[Vec3; 8]),
        lanes: u32,
        met: &'a mut Vec<u32>,
    ) -> Option<impl Iterator<Item = (u32, &'a Aabb)> + 'a> {
        if !self.met_by(plane, rays, lanes, met) {
            return None;
        }
        Some(met.iter().map(move |&i| self.entry(i)))
    }

    /// [`TileList::for_rays`]'s entries as indices into the list (into
    /// `met`, for [`TileList::entry`]); `false` when a lane's ray is not a
    /// ray of `plane`.
    pub(crate) fn met_by(&self, plane: &RayPlane, (o, d): (&[Vec3; 8], &[Vec3; 8]), lanes: u32, met: &mut Vec<u32>) -> bool {
        let Some(pb) = plane.lanes_box((o, d), lanes) else { return false };
        let pb = pb.unwrap_or([f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY]);
        met.clear();
        met.resize(self.pos.len(), 0);
        let m = meets_all(&pb, &self.shadows, met);
        met.truncate(m);
        true
    }

    /// Entry `i` of the list: the child's position and its box.
    #[inline(always)]
    pub(crate) fn entry(&self, i: u32) -> (u32, &Aabb) {
        (self.pos[i as usize], &self.boxes[i as usize])
    }
}

/// Writes to `met` (as long as the shadows) the indices of the shadows
/// `[x0, y0, x1, y1]` that meet `pb` ([`meets`]), in order; returns how
/// many: sixteen shadows a step in AVX-512 where the CPU has it, four in
/// SSE2 otherwise ([`meets_all_sse2`]). Either way the same compares, so
/// the same indices.
fn meets_all(pb: &Box2, sides: &[Vec<f32>; 4], met: &mut [u32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F.
            return unsafe { meets_all_avx512(pb, sides, met) };
        }
    }
    meets_all_sse2(pb, sides, met)
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

    /// `meets_all` (the AVX-512 build where the CPU has it) and its SSE2
    /// build list exactly the shadows `meets` accepts, in order, for every
    /// length (whole steps of 16 and of 4, and the tails), with infinite
    /// and NaN sides and shared edges.
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
        }
    }
}
