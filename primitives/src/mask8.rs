//! Reductions over the eight f32 lanes of a packet under a lane mask, in
//! SSE2 (part of x86_64; a scalar loop elsewhere).
//!
//! Why: written as scalar loops (`key = if m & (1 << k) != 0 {
//! key.min(t[k]) } else { key }`), the compiler keeps them scalar, with
//! `f32::min`'s NaN handling per lane: the masked minimum of a child's box
//! entries was some 120 instructions per child met in a wide union's packet
//! walk (benches/scenes/forest flat, callgrind), where the SSE2 form is
//! about fifteen.
//!
//! The lanes these are asked about hold no NaN (box entries of lanes that
//! met the box, range ends): on them every form gives the same value
//! (`f32::min` and `minps` differ only on NaNs and on the sign of a zero
//! minimum).

use glam::Vec4;

/// The smallest of the lanes `m` (bit `k` for lane `k`) of `t`; `+inf`
/// when `m` holds none of the eight.
#[inline(always)]
pub fn masked_min(m: u32, t: &[f32; 8]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of x86_64; `LANES` rows are 16 bytes and
        // aligned, `t` is 8 floats (unaligned loads).
        unsafe {
            let inf = _mm_set1_ps(f32::INFINITY);
            let pick = |x: __m128, bits: u32| {
                let keep = _mm_load_ps(LANES.0[(bits & 15) as usize].as_ptr() as *const f32);
                _mm_or_ps(_mm_and_ps(keep, x), _mm_andnot_ps(keep, inf))
            };
            let a = pick(_mm_loadu_ps(t.as_ptr()), m);
            let b = pick(_mm_loadu_ps(t.as_ptr().add(4)), m >> 4);
            let x = _mm_min_ps(a, b);
            let x = _mm_min_ps(x, _mm_movehl_ps(x, x));
            let x = _mm_min_ss(x, _mm_shuffle_ps(x, x, 1));
            _mm_cvtss_f32(x)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut key = f32::INFINITY;
        for k in 0..8 {
            if m & (1 << k) != 0 {
                key = key.min(t[k]);
            }
        }
        key
    }
}

/// The largest of the lanes `m` of `t` ([`masked_min`] of the negated
/// lanes, negated: the same bits); `-inf` when `m` holds none of the eight.
#[inline(always)]
pub fn masked_max(m: u32, t: &[f32; 8]) -> f32 {
    -masked_min(m, &t.map(|x| -x))
}

/// The lanes `k` where `a[k] <= b[k]` (bit `k`; false where either is NaN).
#[inline(always)]
pub fn le_mask(a: &[f32; 8], b: &[f32; 8]) -> u32 {
    // (glam's compares: SSE2 on x86_64, lane by lane elsewhere.)
    let half = |h: usize| Vec4::from_slice(&a[4 * h..]).cmple(Vec4::from_slice(&b[4 * h..])).bitmask();
    half(0) | half(1) << 4
}

/// The lanes `k` where `a[k] > b[k]` (bit `k`; false where either is NaN).
#[inline(always)]
pub fn gt_mask(a: &[f32; 8], b: &[f32; 8]) -> u32 {
    let half = |h: usize| Vec4::from_slice(&a[4 * h..]).cmpgt(Vec4::from_slice(&b[4 * h..])).bitmask();
    half(0) | half(1) << 4
}

/// Sets the eight lanes of `a` to `f(0)..f(7)` in place, by a plain loop:
/// an array made by `std::array::from_fn` (or returned by value) was made
/// aside and moved with 16-byte loads across its lanes' narrower stores,
/// which stalled on store forwarding (a packet's rays' origins, 12 bytes
/// each, were some 12% of `tile_firsts`'s cycles on
/// benches/scenes/forest_objects flat, perf).
#[inline(always)]
pub fn fill_lanes<T>(a: &mut [T; 8], f: impl Fn(usize) -> T) {
    for (k, x) in a.iter_mut().enumerate() {
        *x = f(k);
    }
}

/// Per 4-bit lane set, the lanes as all-ones words.
#[cfg(target_arch = "x86_64")]
#[repr(align(16))]
struct Lanes([[u32; 4]; 16]);

#[cfg(target_arch = "x86_64")]
static LANES: Lanes = Lanes({
    let mut t = [[0u32; 4]; 16];
    let mut i = 0;
    while i < 16 {
        let mut j = 0;
        while j < 4 {
            if i & (1 << j) != 0 {
                t[i][j] = u32::MAX;
            }
            j += 1;
        }
        i += 1;
    }
    t
});

#[cfg(test)]
mod tests {
    use super::*;

    /// The helpers against their scalar definitions, for every mask, with
    /// infinities, zeros and (in lanes outside the mask, or compared) NaNs.
    #[test]
    fn masked_reductions_match_scalar_loops() {
        let seed = 7u32;
        println!("seed {seed}");
        let mut s = seed;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s
        };
        let vals = [0.0f32, 1.0, -1.0, 2.5, f32::INFINITY, f32::NEG_INFINITY, 1e-30, -3e30];
        for case in 0..20_000 {
            let m = next() & 0xff;
            let mut t: [f32; 8] = std::array::from_fn(|_| vals[(next() % 8) as usize]);
            let u: [f32; 8] = std::array::from_fn(|_| if next() % 9 == 0 { f32::NAN } else { vals[(next() % 8) as usize] });
            for k in 0..8 {
                if m & (1 << k) == 0 && next() % 3 == 0 {
                    t[k] = f32::NAN;
                }
            }
            let mut want = f32::INFINITY;
            let (mut le, mut gt) = (0, 0);
            for k in 0..8 {
                if m & (1 << k) != 0 {
                    want = want.min(t[k]);
                }
                le |= ((t[k] <= u[k]) as u32) << k;
                gt |= ((t[k] > u[k]) as u32) << k;
            }
            assert_eq!(masked_min(m, &t), want, "case {case}: mask {m:#x} of {t:?}");
            assert_eq!(le_mask(&t, &u), le, "case {case}: {t:?} <= {u:?}");
            assert_eq!(gt_mask(&t, &u), gt, "case {case}: {t:?} > {u:?}");
        }
    }
}
