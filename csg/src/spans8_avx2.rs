//! [`merge8`](super::merge8)'s steps in AVX2: the portable loop's lane
//! masks as 8-lane compares and blends, one instruction stream for the
//! eight lanes. The arithmetic per lane is the portable loop's (the same
//! subtractions and ordered compares), so both give the same bits.

use std::arch::x86_64::*;

use rothray_primitives::Surf;

use super::{Plan, Spans8, NONE};
use crate::spans::Op;

// SAFETY (every function here): called only from `merge8_avx2`, on a CPU
// with AVX2; the loads and stores are unaligned ones of whole `[_; 8]`
// arrays.

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn ld(p: &[f32; 8]) -> __m256 {
    _mm256_loadu_ps(p.as_ptr())
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn ldi(p: &[u32; 8]) -> __m256i {
    _mm256_loadu_si256(p.as_ptr() as *const __m256i)
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn st(p: &mut [f32; 8], v: __m256) {
    _mm256_storeu_ps(p.as_mut_ptr(), v)
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn sti(p: &mut [u32; 8], v: __m256i) {
    _mm256_storeu_si256(p.as_mut_ptr() as *mut __m256i, v)
}

/// `m ? y : x` per lane (`m`: all ones or zeros per lane).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn sel(x: __m256, y: __m256, m: __m256i) -> __m256 {
    _mm256_blendv_ps(x, y, _mm256_castsi256_ps(m))
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn seli(x: __m256i, y: __m256i, m: __m256i) -> __m256i {
    _mm256_blendv_epi8(x, y, m)
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn cmp<const P: i32>(x: __m256, y: __m256) -> __m256i {
    _mm256_castps_si256(_mm256_cmp_ps::<P>(x, y))
}

#[inline]
#[target_feature(enable = "avx2")]
unsafe fn splat(x: u32) -> __m256i {
    _mm256_set1_epi32(x as i32)
}

/// One event per lane.
#[derive(Clone, Copy)]
struct Ev {
    t: __m256,
    l: __m256i,
    u: __m256i,
}

/// Lane k's event `idx[k]` of `s` (where `idx[k]` is one of its events).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn event<const C: usize>(s: &Spans8<C>, idx: __m256i) -> Ev {
    let mut e = Ev { t: _mm256_set1_ps(f32::INFINITY), l: splat(NONE), u: _mm256_setzero_si256() };
    for j in 0..C {
        let m0 = _mm256_cmpeq_epi32(idx, splat(2 * j as u32));
        let m1 = _mm256_cmpeq_epi32(idx, splat(2 * j as u32 + 1));
        e.t = sel(sel(e.t, ld(&s.t0[j]), m0), ld(&s.t1[j]), m1);
        e.l = seli(seli(e.l, ldi(&s.l0[j]), m0), ldi(&s.l1[j]), m1);
        e.u = seli(seli(e.u, ldi(&s.u0[j]), m0), ldi(&s.u1[j]), m1);
    }
    e
}

/// Runs the plan's steps into `out` (whose lengths are zero); returns the
/// lanes that overflowed.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn steps<const C: usize>(op: Op, a: &Spans8<C>, b: &Spans8<C>, eps: &[f32; 8], plan: &Plan, out: &mut Spans8<C>) -> u32 {
    let (union, diff) = (op == Op::Union, op == Op::Difference);
    let ones = _mm256_set1_epi32(-1);
    let zero = _mm256_setzero_si256();
    let none = splat(NONE);
    let flip = splat(if diff { Surf::FLIP } else { 0 });
    let index = splat(!Surf::FLIP);
    let abs = _mm256_castsi256_ps(splat(0x7fff_ffff));
    let eps = ld(eps);
    let (na, nb) = (ldi(&plan.na), ldi(&plan.nb));
    let (mut ia, mut ib) = (zero, zero);
    let (mut ina, mut inb, mut inr) = (zero, zero, zero);
    let mut start = Ev { t: _mm256_setzero_ps(), l: none, u: zero };
    let mut n = zero;
    let mut overflow = 0u32;
    for _ in 0..plan.steps {
        let a_ok = _mm256_cmpgt_epi32(na, ia);
        let b_ok = _mm256_cmpgt_epi32(nb, ib);
        let ea = event(a, ia);
        let mut eb = event(b, ib);
        let real_b = _mm256_xor_si256(_mm256_cmpeq_epi32(eb.l, none), ones);
        eb.l = _mm256_xor_si256(eb.l, _mm256_and_si256(real_b, flip));
        let real_a = _mm256_xor_si256(_mm256_cmpeq_epi32(ea.l, none), ones);
        // `ta == tb` also fuses two infinite ends (inf - inf is NaN).
        let near = cmp::<_CMP_LE_OQ>(_mm256_and_ps(_mm256_sub_ps(ea.t, eb.t), abs), eps);
        let both = _mm256_and_si256(a_ok, b_ok);
        let fuse = _mm256_and_si256(both, _mm256_or_si256(cmp::<_CMP_EQ_OQ>(ea.t, eb.t), near));
        let a_first = _mm256_or_si256(_mm256_xor_si256(b_ok, ones), cmp::<_CMP_LT_OQ>(ea.t, eb.t));
        let take_a = _mm256_andnot_si256(fuse, _mm256_and_si256(a_ok, a_first));
        let take_b = _mm256_andnot_si256(_mm256_or_si256(fuse, take_a), b_ok);
        let (adv_a, adv_b) = (_mm256_or_si256(fuse, take_a), _mm256_or_si256(fuse, take_b));
        ina = _mm256_xor_si256(ina, adv_a);
        inb = _mm256_xor_si256(inb, adv_b);
        ia = _mm256_sub_epi32(ia, adv_a);
        ib = _mm256_sub_epi32(ib, adv_b);
        // The event's parameter and surface.
        let only_b = _mm256_andnot_si256(real_a, real_b);
        let mut t = sel(eb.t, ea.t, take_a);
        let fused_b = if union {
            let lower = _mm256_cmpgt_epi32(_mm256_and_si256(ea.l, index), _mm256_and_si256(eb.l, index));
            let fb = _mm256_or_si256(_mm256_and_si256(_mm256_and_si256(real_a, real_b), lower), only_b);
            let neither = _mm256_xor_si256(_mm256_or_si256(real_a, real_b), ones);
            let nearer = sel(ea.t, eb.t, cmp::<_CMP_LT_OQ>(eb.t, ea.t));
            t = sel(t, sel(sel(ea.t, eb.t, fb), nearer, neither), fuse);
            fb
        } else {
            t = sel(t, ea.t, fuse);
            only_b
        };
        let use_b = _mm256_or_si256(take_b, _mm256_and_si256(fuse, fused_b));
        let l = seli(ea.l, eb.l, use_b);
        let u = seli(ea.u, eb.u, use_b);
        let r = if union {
            _mm256_or_si256(ina, inb)
        } else if diff {
            _mm256_andnot_si256(inb, ina)
        } else {
            _mm256_and_si256(ina, inb)
        };
        let change = _mm256_and_si256(_mm256_or_si256(adv_a, adv_b), _mm256_xor_si256(r, inr));
        inr = _mm256_xor_si256(inr, change);
        let enter = _mm256_and_si256(change, r);
        let leave = _mm256_andnot_si256(r, change);
        // The last span kept (an entry may merge with it).
        let mut last = Ev { t: _mm256_setzero_ps(), l: none, u: zero };
        let mut last_t1 = _mm256_setzero_ps();
        for j in 0..C {
            let m = _mm256_cmpeq_epi32(n, splat(j as u32 + 1));
            last.t = sel(last.t, ld(&out.t0[j]), m);
            last.l = seli(last.l, ldi(&out.l0[j]), m);
            last.u = seli(last.u, ldi(&out.u0[j]), m);
            last_t1 = sel(last_t1, ld(&out.t1[j]), m);
        }
        let gap_ok = cmp::<_CMP_LE_OQ>(_mm256_sub_ps(t, last_t1), eps);
        let merge = _mm256_and_si256(_mm256_and_si256(enter, _mm256_cmpgt_epi32(n, zero)), gap_ok);
        start.t = sel(sel(start.t, t, enter), last.t, merge);
        start.l = seli(seli(start.l, l, enter), last.l, merge);
        start.u = seli(seli(start.u, u, enter), last.u, merge);
        let keep = _mm256_and_si256(leave, cmp::<_CMP_GT_OQ>(_mm256_sub_ps(t, start.t), eps));
        let room = _mm256_cmpgt_epi32(splat(C as u32), n);
        overflow |= _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_andnot_si256(room, keep))) as u32;
        let push = _mm256_and_si256(keep, room);
        if _mm256_testz_si256(push, push) == 0 {
            for j in 0..C {
                let w = _mm256_and_si256(push, _mm256_cmpeq_epi32(n, splat(j as u32)));
                let v = (ld(&out.t0[j]), ldi(&out.l0[j]), ldi(&out.u0[j]), ld(&out.t1[j]), ldi(&out.l1[j]), ldi(&out.u1[j]));
                st(&mut out.t0[j], sel(v.0, start.t, w));
                sti(&mut out.l0[j], seli(v.1, start.l, w));
                sti(&mut out.u0[j], seli(v.2, start.u, w));
                st(&mut out.t1[j], sel(v.3, t, w));
                sti(&mut out.l1[j], seli(v.4, l, w));
                sti(&mut out.u1[j], seli(v.5, u, w));
            }
        }
        // (Masks are -1: subtracting `push` adds one, adding `merge` pops one.)
        n = _mm256_add_epi32(_mm256_sub_epi32(n, push), merge);
    }
    sti(&mut out.len, n);
    overflow
}
