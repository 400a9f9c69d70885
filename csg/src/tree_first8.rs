//! [`tree_first`] for the eight lanes of a packet at once: the boundaries
//! of every lane in slots side by side (`[slot][lane]`), sorted by one
//! network for all lanes, swept in lock step with the tree's truth table,
//! each step a loop over the eight lanes without a branch (the compiler
//! makes it 8-lane AVX2, or two SSE2 halves in the baseline build).
//!
//! Why: lane by lane, the sort and the sweep of the boundaries were the
//! hottest code of the scenes whose objects or forest trees are small trees
//! of several levels (benches/scenes/logo flat: 44% of its instructions,
//! callgrind 480x270).
//!
//! Each lane's answer is `tree_first`'s, with the same boundaries, the same
//! sure test and the same sweep, except where no caller can tell: the
//! network orders equal boundaries otherwise than the insertion sort (equal
//! finite ones make the lane unsure, whose answer reads the smallest one's
//! value alone), and boundaries at infinity are left out of the sweep (a
//! span starting there starts past every range; one ending there ends past
//! every range's clipped end, whose surface nobody reads), as in
//! `small_first8`. A lane with a NaN boundary is left to `tree_first`.

use rothray_primitives::{kernels8::Ranges8, Surf};

use super::small_first::SmallFirst;
use super::tree_first::{tree_first, TreeShape, TREE_LEAVES};

/// Boundary slots: two per leaf.
const SLOTS: usize = 2 * TREE_LEAVES;

/// The id of an empty slot (its leaf, `ABSENT >> 1`, has no bit).
const ABSENT: u32 = 255;

/// Batcher's odd-even merge sort of 16 slots: its 63 compare-exchanges.
const NET: [(u8, u8); 63] = batcher16();

const fn batcher16() -> [(u8, u8); 63] {
    let n = 16usize;
    let mut out = [(0u8, 0u8); 63];
    let mut m = 0;
    let mut p = 1;
    while p < n {
        let mut k = p;
        while k >= 1 {
            let mut j = k % p;
            while j + k < n {
                let mut i = 0;
                while i < k && i + j + k < n {
                    if (i + j) / (2 * p) == (i + j + k) / (2 * p) {
                        out[m] = ((i + j) as u8, (i + j + k) as u8);
                        m += 1;
                    }
                    i += 1;
                }
                j += 2 * k;
            }
            k /= 2;
        }
        p *= 2;
    }
    assert!(m == 63);
    out
}

/// The lanes' range starts and tolerances.
pub(crate) struct LaneStarts<'a> {
    pub(crate) lo: &'a [f32; 8],
    pub(crate) eps: &'a [f32; 8],
}

/// [`tree_first`] of the tree `t` (its leaves' solves `r`) for every lane
/// of `lanes` into `out` (the other lanes' answers are left as they are).
pub(crate) fn tree_first8(t: &TreeShape, r: &[&Ranges8], lanes: u32, ranges: &LaneStarts, out: &mut [SmallFirst; 8]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { tree_first8_avx2(t, r, lanes, ranges, out) };
    }
    tree_first8_base(t, r, lanes, ranges, out)
}

/// [`tree_first8`] in AVX2: each step one 8-lane operation.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[doc(hidden)]
pub(crate) unsafe fn tree_first8_avx2(t: &TreeShape, r: &[&Ranges8], lanes: u32, ranges: &LaneStarts, out: &mut [SmallFirst; 8]) {
    use std::arch::x86_64::*;
    let n = t.count.min(r.len());
    let e = 2 * n;
    let inf = _mm256_set1_ps(f32::INFINITY);
    let absent = _mm256_set1_epi32(ABSENT as i32);
    let one = _mm256_set1_epi32(1);
    let (lo, eps) = (_mm256_loadu_ps(ranges.lo.as_ptr()), _mm256_loadu_ps(ranges.eps.as_ptr()));
    let two_eps = _mm256_mul_ps(_mm256_set1_ps(2.0), eps);
    let near = _mm256_sub_ps(lo, two_eps);
    let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    // The boundaries from `near` on (the others set the state at the
    // start), with ids `2 j` (entry of leaf j) and `2 j + 1` (exit).
    let mut key = [inf; SLOTS];
    let mut id = [absent; SLOTS];
    let mut inside = _mm256_setzero_si256();
    let mut hits = _mm256_setzero_si256();
    let mut nan = _mm256_setzero_ps();
    for j in 0..n {
        let rj = r[j];
        let h = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(rj.hit as i32), lane_bit), lane_bit);
        let hf = _mm256_castsi256_ps(h);
        let (a, b) = (_mm256_loadu_ps(rj.t0.as_ptr()), _mm256_loadu_ps(rj.t1.as_ptr()));
        let ea = _mm256_and_ps(hf, _mm256_cmp_ps::<_CMP_LT_OQ>(a, near));
        let xb = _mm256_and_ps(hf, _mm256_cmp_ps::<_CMP_LT_OQ>(b, near));
        let bit = _mm256_set1_epi32(1 << j);
        let set = _mm256_or_si256(inside, _mm256_and_si256(_mm256_castps_si256(ea), bit));
        inside = _mm256_andnot_si256(_mm256_and_si256(_mm256_castps_si256(xb), bit), set);
        hits = _mm256_or_si256(hits, _mm256_and_si256(h, bit));
        let odd = _mm256_or_ps(_mm256_cmp_ps::<_CMP_UNORD_Q>(a, a), _mm256_cmp_ps::<_CMP_UNORD_Q>(b, b));
        nan = _mm256_or_ps(nan, _mm256_and_ps(hf, odd));
        let (pa, pb) = (_mm256_andnot_ps(ea, hf), _mm256_andnot_ps(xb, hf));
        key[2 * j] = _mm256_blendv_ps(inf, a, pa);
        id[2 * j] = _mm256_blendv_epi8(absent, _mm256_set1_epi32(2 * j as i32), _mm256_castps_si256(pa));
        key[2 * j + 1] = _mm256_blendv_ps(inf, b, pb);
        id[2 * j + 1] = _mm256_blendv_epi8(absent, _mm256_set1_epi32(2 * j as i32 + 1), _mm256_castps_si256(pb));
    }
    // The network (equal keys are not exchanged; slots past `e` hold
    // infinity throughout, so their exchanges are skipped).
    for &(a, b) in NET.iter() {
        let (a, b) = (a as usize, b as usize);
        if b >= e {
            continue;
        }
        let (ka, kb, ia, ib) = (key[a], key[b], id[a], id[b]);
        let sw = _mm256_cmp_ps::<_CMP_LT_OQ>(kb, ka);
        let swi = _mm256_castps_si256(sw);
        key[a] = _mm256_blendv_ps(ka, kb, sw);
        key[b] = _mm256_blendv_ps(kb, ka, sw);
        id[a] = _mm256_blendv_epi8(ia, ib, swi);
        id[b] = _mm256_blendv_epi8(ib, ia, swi);
    }
    // The sure test: consecutive finite boundaries more than 2 eps apart,
    // the first more than 2 eps past the range's start.
    let mut unsure = _mm256_setzero_ps();
    let mut prev = lo;
    for &x in key.iter().take(e) {
        let finite = _mm256_cmp_ps::<_CMP_NEQ_UQ>(x, inf);
        let apart = _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_sub_ps(x, prev), two_eps);
        unsure = _mm256_or_ps(unsure, _mm256_andnot_ps(apart, finite));
        prev = x;
    }
    // Membership: bit `m` of the truth table, as eight 32-bit words.
    let table = _mm256_loadu_si256(t.table_words().as_ptr() as *const __m256i);
    let thirty_one = _mm256_set1_epi32(31);
    let member = |m: __m256i| {
        let word = _mm256_permutevar8x32_epi32(table, _mm256_srli_epi32::<5>(m));
        _mm256_and_si256(_mm256_srlv_epi32(word, _mm256_and_si256(m, thirty_one)), one)
    };
    let start_in = member(inside);
    // The sweep: the first change enters the first span, the second leaves
    // it, the third enters the next (boundaries at infinity left out).
    let mut st = inside;
    let mut was = _mm256_setzero_si256();
    let mut changes = _mm256_setzero_si256();
    let (mut a, mut b, mut nx) = (inf, inf, inf);
    let (mut ia, mut ib) = (absent, absent);
    let (c1, c2, c3) = (one, _mm256_set1_epi32(2), _mm256_set1_epi32(3));
    for i in 0..e {
        let (x, d) = (key[i], id[i]);
        let real = _mm256_andnot_si256(_mm256_cmpeq_epi32(d, absent), _mm256_castps_si256(_mm256_cmp_ps::<_CMP_NEQ_UQ>(x, inf)));
        let bit = _mm256_and_si256(_mm256_sllv_epi32(one, _mm256_and_si256(_mm256_srli_epi32::<1>(d), _mm256_set1_epi32(7))), real);
        let exit = _mm256_cmpeq_epi32(_mm256_and_si256(d, one), one);
        st = _mm256_blendv_epi8(_mm256_or_si256(st, bit), _mm256_andnot_si256(bit, st), exit);
        let now = member(st);
        let ch = _mm256_xor_si256(now, was);
        was = now;
        changes = _mm256_add_epi32(changes, ch);
        let chm = _mm256_cmpeq_epi32(ch, one);
        let (m1, m2, m3) = (
            _mm256_and_si256(chm, _mm256_cmpeq_epi32(changes, c1)),
            _mm256_and_si256(chm, _mm256_cmpeq_epi32(changes, c2)),
            _mm256_and_si256(chm, _mm256_cmpeq_epi32(changes, c3)),
        );
        a = _mm256_blendv_ps(a, x, _mm256_castsi256_ps(m1));
        ia = _mm256_blendv_epi8(ia, d, m1);
        b = _mm256_blendv_ps(b, x, _mm256_castsi256_ps(m2));
        ib = _mm256_blendv_epi8(ib, d, m2);
        nx = _mm256_blendv_ps(nx, x, _mm256_castsi256_ps(m3));
    }
    let f32s = |v: __m256| {
        let mut o = [0f32; 8];
        _mm256_storeu_ps(o.as_mut_ptr(), v);
        o
    };
    let u32s = |v: __m256i| {
        let mut o = [0u32; 8];
        _mm256_storeu_si256(o.as_mut_ptr() as *mut __m256i, v);
        o
    };
    let swept = Sweep8 {
        first: f32s(key[0]),
        unsure: _mm256_movemask_ps(unsure) as u32,
        nan: _mm256_movemask_ps(nan) as u32,
        inside: _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(start_in, one))) as u32,
        hits: u32s(hits),
        changes: u32s(changes),
        a: f32s(a),
        b: f32s(b),
        nx: f32s(nx),
        ia: u32s(ia),
        ib: u32s(ib),
    };
    swept.answer(t, r, lanes, ranges, out);
}

/// What the 8-lane sweep found, per lane.
struct Sweep8 {
    /// The smallest boundary.
    first: [f32; 8],
    /// Lane masks: not sure, a NaN boundary, starting inside the tree.
    unsure: u32,
    nan: u32,
    inside: u32,
    /// The leaves the line meets (bit per leaf).
    hits: [u32; 8],
    /// How many times membership changed, and where: the first span's
    /// ends (with their boundary ids) and the next span's start.
    changes: [u32; 8],
    a: [f32; 8],
    b: [f32; 8],
    nx: [f32; 8],
    ia: [u32; 8],
    ib: [u32; 8],
}

impl Sweep8 {
    /// Each lane's answer into `out`, as `tree_first` gives it.
    fn answer(&self, t: &TreeShape, r: &[&Ranges8], lanes: u32, ranges: &LaneStarts, out: &mut [SmallFirst; 8]) {
        let inf = f32::INFINITY;
        let surf = |k: usize, d: u32| {
            let j = (d >> 1) as usize;
            let s = Surf::new(t.leaf[j], if d & 1 != 0 { r[j].s1[k] } else { r[j].s0[k] });
            if t.flip_of(j) {
                s.flip()
            } else {
                s
            }
        };
        let mut m = lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let on = |mask: u32| mask & (1 << k) != 0;
            out[k] = if on(self.nan) {
                tree_first(t, r, k, (ranges.lo[k], ranges.eps[k]))
            } else if t.empty_for(|j| self.hits[k] & (1 << j) == 0) {
                SmallFirst::Empty
            } else if on(self.inside) {
                SmallFirst::Inside
            } else if on(self.unsure) {
                SmallFirst::From(self.first[k] - ranges.eps[k])
            } else {
                match self.changes[k] {
                    0 => SmallFirst::Empty,
                    1 => SmallFirst::Span { t: (self.a[k], inf), s: (surf(k, self.ia[k]), Surf::NONE), next: inf },
                    c => SmallFirst::Span {
                        t: (self.a[k], self.b[k]),
                        s: (surf(k, self.ia[k]), surf(k, self.ib[k])),
                        next: if c >= 3 { self.nx[k] } else { inf },
                    },
                }
            };
        }
    }
}

/// [`tree_first8`] for the baseline: `tree_first` lane by lane.
#[doc(hidden)]
pub(crate) fn tree_first8_base(t: &TreeShape, r: &[&Ranges8], lanes: u32, ranges: &LaneStarts, out: &mut [SmallFirst; 8]) {
    let mut m = lanes;
    while m != 0 {
        let k = m.trailing_zeros() as usize;
        m &= m - 1;
        out[k] = tree_first(t, r, k, (ranges.lo[k], ranges.eps[k]));
    }
}

#[cfg(test)]
#[path = "tree_first8_tests.rs"]
mod tests;
