#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
//! Eight SIMD lanes of f64 ([`D8`]) for the packet kernels
//! ([`crate::kernels8`], all in f64 since boxes and half-spaces are traced
//! in f64): two AVX registers where the CPU has it, SSE2 registers otherwise, behind one set of operations, so
//! that each kernel is written once and both builds do the same IEEE
//! operations per lane. The AVX types are only used inside functions
//! compiled with AVX (`#[target_feature(enable = "avx")]`), chosen at run
//! time.

/// The 8-lane f64 operations of the kernels (ball, ellipsoid, cylinder,
/// box, half-space); a mask is a vector whose lanes are all ones (true) or
/// all zeros.
pub(crate) trait D8: Copy {
    fn splat(x: f64) -> Self;
    /// Eight f32 lanes, widened (exactly).
    fn widen(a: &[f32; 8]) -> Self;
    /// The lanes rounded to f32 (to nearest, as `as f32`).
    fn narrow(self) -> [f32; 8];
    /// Lanes holding small whole numbers, as integers.
    fn store_u32(self) -> [u32; 8];
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    fn sqrt(self) -> Self;
    fn neg(self) -> Self;
    fn copysign(self, s: Self) -> Self;
    fn le(self, o: Self) -> Self;
    fn ge(self, o: Self) -> Self;
    fn gt(self, o: Self) -> Self;
    fn eq(self, o: Self) -> Self;
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    /// `!self & o`, bitwise.
    fn andnot(self, o: Self) -> Self;
    fn select(m: Self, a: Self, b: Self) -> Self;
    fn bitmask(self) -> u32;
    /// Eight f64 lanes as they are.
    fn load(a: &[f64; 8]) -> Self;
    /// The lanes as they are.
    fn store(self) -> [f64; 8];
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod sse_d {
    use std::arch::x86_64::*;

    /// Four SSE2 pairs.
    #[derive(Clone, Copy)]
    pub(crate) struct SseD(pub(crate) [__m128d; 4]);

    macro_rules! each {
        ($f:ident, $a:expr, $b:expr) => {
            unsafe { SseD(std::array::from_fn(|h| $f($a.0[h], $b.0[h]))) }
        };
    }

    // SAFETY (every method): SSE2 is part of x86_64.
    impl super::D8 for SseD {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            unsafe { SseD([_mm_set1_pd(x); 4]) }
        }
        #[inline(always)]
        fn widen(a: &[f32; 8]) -> Self {
            unsafe {
                let (lo, hi) = (_mm_loadu_ps(a.as_ptr()), _mm_loadu_ps(a.as_ptr().add(4)));
                SseD([_mm_cvtps_pd(lo), _mm_cvtps_pd(_mm_movehl_ps(lo, lo)), _mm_cvtps_pd(hi), _mm_cvtps_pd(_mm_movehl_ps(hi, hi))])
            }
        }
        #[inline(always)]
        fn narrow(self) -> [f32; 8] {
            let mut a = [0.0f32; 8];
            unsafe {
                let lo = _mm_movelh_ps(_mm_cvtpd_ps(self.0[0]), _mm_cvtpd_ps(self.0[1]));
                let hi = _mm_movelh_ps(_mm_cvtpd_ps(self.0[2]), _mm_cvtpd_ps(self.0[3]));
                _mm_storeu_ps(a.as_mut_ptr(), lo);
                _mm_storeu_ps(a.as_mut_ptr().add(4), hi);
            }
            a
        }
        #[inline(always)]
        fn store_u32(self) -> [u32; 8] {
            let mut a = [0u32; 8];
            unsafe {
                let lo = _mm_unpacklo_epi64(_mm_cvttpd_epi32(self.0[0]), _mm_cvttpd_epi32(self.0[1]));
                let hi = _mm_unpacklo_epi64(_mm_cvttpd_epi32(self.0[2]), _mm_cvttpd_epi32(self.0[3]));
                _mm_storeu_si128(a.as_mut_ptr() as *mut __m128i, lo);
                _mm_storeu_si128(a.as_mut_ptr().add(4) as *mut __m128i, hi);
            }
            a
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            each!(_mm_add_pd, self, o)
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            each!(_mm_sub_pd, self, o)
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            each!(_mm_mul_pd, self, o)
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            each!(_mm_div_pd, self, o)
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            unsafe { SseD(std::array::from_fn(|h| _mm_sqrt_pd(self.0[h]))) }
        }
        #[inline(always)]
        fn neg(self) -> Self {
            let m = Self::splat(-0.0);
            each!(_mm_xor_pd, m, self)
        }
        #[inline(always)]
        fn copysign(self, s: Self) -> Self {
            let m = Self::splat(-0.0);
            let sign = each!(_mm_and_pd, s, m);
            let mag = each!(_mm_andnot_pd, m, self);
            each!(_mm_or_pd, sign, mag)
        }
        #[inline(always)]
        fn le(self, o: Self) -> Self {
            each!(_mm_cmple_pd, self, o)
        }
        #[inline(always)]
        fn ge(self, o: Self) -> Self {
            each!(_mm_cmpge_pd, self, o)
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            each!(_mm_cmpgt_pd, self, o)
        }
        #[inline(always)]
        fn eq(self, o: Self) -> Self {
            each!(_mm_cmpeq_pd, self, o)
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            each!(_mm_and_pd, self, o)
        }
        #[inline(always)]
        fn or(self, o: Self) -> Self {
            each!(_mm_or_pd, self, o)
        }
        #[inline(always)]
        fn andnot(self, o: Self) -> Self {
            each!(_mm_andnot_pd, self, o)
        }
        #[inline(always)]
        fn select(m: Self, a: Self, b: Self) -> Self {
            let x = each!(_mm_and_pd, m, a);
            let y = each!(_mm_andnot_pd, m, b);
            each!(_mm_or_pd, x, y)
        }
        #[inline(always)]
        fn bitmask(self) -> u32 {
            let mut m = 0;
            for h in 0..4 {
                m |= (unsafe { _mm_movemask_pd(self.0[h]) } as u32) << (2 * h);
            }
            m
        }
        #[inline(always)]
        fn load(a: &[f64; 8]) -> Self {
            unsafe { SseD(std::array::from_fn(|h| _mm_loadu_pd(a.as_ptr().add(2 * h)))) }
        }
        #[inline(always)]
        fn store(self) -> [f64; 8] {
            let mut a = [0.0; 8];
            for h in 0..4 {
                unsafe { _mm_storeu_pd(a.as_mut_ptr().add(2 * h), self.0[h]) };
            }
            a
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx_d {
    use std::arch::x86_64::*;

    /// Two AVX registers of four f64; only used inside functions compiled with AVX.
    #[derive(Clone, Copy)]
    pub(crate) struct AvxD(pub(crate) [__m256d; 2]);

    macro_rules! each {
        ($f:ident, $a:expr, $b:expr) => {
            unsafe { AvxD([$f($a.0[0], $b.0[0]), $f($a.0[1], $b.0[1])]) }
        };
    }

    // SAFETY (every method): only called from `LeafTable::ranges8_avx` (kernels8.rs), compiled with
    // AVX and reached only when the CPU has it; inlined there.
    impl super::D8 for AvxD {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            unsafe { AvxD([_mm256_set1_pd(x); 2]) }
        }
        #[inline(always)]
        fn widen(a: &[f32; 8]) -> Self {
            unsafe { AvxD([_mm256_cvtps_pd(_mm_loadu_ps(a.as_ptr())), _mm256_cvtps_pd(_mm_loadu_ps(a.as_ptr().add(4)))]) }
        }
        #[inline(always)]
        fn narrow(self) -> [f32; 8] {
            let mut a = [0.0f32; 8];
            unsafe {
                _mm_storeu_ps(a.as_mut_ptr(), _mm256_cvtpd_ps(self.0[0]));
                _mm_storeu_ps(a.as_mut_ptr().add(4), _mm256_cvtpd_ps(self.0[1]));
            }
            a
        }
        #[inline(always)]
        fn store_u32(self) -> [u32; 8] {
            let mut a = [0u32; 8];
            unsafe {
                _mm_storeu_si128(a.as_mut_ptr() as *mut __m128i, _mm256_cvttpd_epi32(self.0[0]));
                _mm_storeu_si128(a.as_mut_ptr().add(4) as *mut __m128i, _mm256_cvttpd_epi32(self.0[1]));
            }
            a
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            each!(_mm256_add_pd, self, o)
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            each!(_mm256_sub_pd, self, o)
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            each!(_mm256_mul_pd, self, o)
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            each!(_mm256_div_pd, self, o)
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            unsafe { AvxD([_mm256_sqrt_pd(self.0[0]), _mm256_sqrt_pd(self.0[1])]) }
        }
        #[inline(always)]
        fn neg(self) -> Self {
            let m = Self::splat(-0.0);
            each!(_mm256_xor_pd, m, self)
        }
        #[inline(always)]
        fn copysign(self, s: Self) -> Self {
            let m = Self::splat(-0.0);
            let sign = each!(_mm256_and_pd, s, m);
            let mag = each!(_mm256_andnot_pd, m, self);
            each!(_mm256_or_pd, sign, mag)
        }
        #[inline(always)]
        fn le(self, o: Self) -> Self {
            unsafe { AvxD([_mm256_cmp_pd::<_CMP_LE_OQ>(self.0[0], o.0[0]), _mm256_cmp_pd::<_CMP_LE_OQ>(self.0[1], o.0[1])]) }
        }
        #[inline(always)]
        fn ge(self, o: Self) -> Self {
            unsafe { AvxD([_mm256_cmp_pd::<_CMP_GE_OQ>(self.0[0], o.0[0]), _mm256_cmp_pd::<_CMP_GE_OQ>(self.0[1], o.0[1])]) }
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            unsafe { AvxD([_mm256_cmp_pd::<_CMP_GT_OQ>(self.0[0], o.0[0]), _mm256_cmp_pd::<_CMP_GT_OQ>(self.0[1], o.0[1])]) }
        }
        #[inline(always)]
        fn eq(self, o: Self) -> Self {
            unsafe { AvxD([_mm256_cmp_pd::<_CMP_EQ_OQ>(self.0[0], o.0[0]), _mm256_cmp_pd::<_CMP_EQ_OQ>(self.0[1], o.0[1])]) }
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            each!(_mm256_and_pd, self, o)
        }
        #[inline(always)]
        fn or(self, o: Self) -> Self {
            each!(_mm256_or_pd, self, o)
        }
        #[inline(always)]
        fn andnot(self, o: Self) -> Self {
            each!(_mm256_andnot_pd, self, o)
        }
        #[inline(always)]
        fn select(m: Self, a: Self, b: Self) -> Self {
            unsafe { AvxD([_mm256_blendv_pd(b.0[0], a.0[0], m.0[0]), _mm256_blendv_pd(b.0[1], a.0[1], m.0[1])]) }
        }
        #[inline(always)]
        fn bitmask(self) -> u32 {
            unsafe { (_mm256_movemask_pd(self.0[0]) | _mm256_movemask_pd(self.0[1]) << 4) as u32 }
        }
        #[inline(always)]
        fn load(a: &[f64; 8]) -> Self {
            unsafe { AvxD([_mm256_loadu_pd(a.as_ptr()), _mm256_loadu_pd(a.as_ptr().add(4))]) }
        }
        #[inline(always)]
        fn store(self) -> [f64; 8] {
            let mut a = [0.0; 8];
            unsafe {
                _mm256_storeu_pd(a.as_mut_ptr(), self.0[0]);
                _mm256_storeu_pd(a.as_mut_ptr().add(4), self.0[1]);
            }
            a
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx512_d {
    use std::arch::x86_64::*;

    /// One AVX-512 register of eight f64; only used inside functions compiled
    /// with AVX-512F. A mask is a vector (all ones or all zeros per lane), as
    /// the trait has it: a compare's mask register is widened to one, and a
    /// select tests it back (one instruction each).
    #[derive(Clone, Copy)]
    pub(crate) struct Avx512D(pub(crate) __m512d);

    #[inline(always)]
    fn bits(a: __m512d) -> __m512i {
        unsafe { _mm512_castpd_si512(a) }
    }

    #[inline(always)]
    fn pd(a: __m512i) -> Avx512D {
        unsafe { Avx512D(_mm512_castsi512_pd(a)) }
    }

    #[inline(always)]
    fn mask(k: __mmask8) -> Avx512D {
        unsafe { pd(_mm512_maskz_set1_epi64(k, -1)) }
    }

    // SAFETY (every method): only called from `LeafTable::ranges8_avx512`
    // (kernels8.rs), compiled with AVX-512F and reached only when the CPU has
    // it; inlined there.
    impl super::D8 for Avx512D {
        #[inline(always)]
        fn splat(x: f64) -> Self {
            unsafe { Avx512D(_mm512_set1_pd(x)) }
        }
        #[inline(always)]
        fn widen(a: &[f32; 8]) -> Self {
            unsafe { Avx512D(_mm512_cvtps_pd(_mm256_loadu_ps(a.as_ptr()))) }
        }
        #[inline(always)]
        fn narrow(self) -> [f32; 8] {
            let mut a = [0.0f32; 8];
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), _mm512_cvtpd_ps(self.0)) };
            a
        }
        #[inline(always)]
        fn store_u32(self) -> [u32; 8] {
            let mut a = [0u32; 8];
            unsafe { _mm256_storeu_si256(a.as_mut_ptr() as *mut __m256i, _mm512_cvttpd_epi32(self.0)) };
            a
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            unsafe { Avx512D(_mm512_add_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            unsafe { Avx512D(_mm512_sub_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            unsafe { Avx512D(_mm512_mul_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            unsafe { Avx512D(_mm512_div_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            unsafe { Avx512D(_mm512_sqrt_pd(self.0)) }
        }
        #[inline(always)]
        fn neg(self) -> Self {
            unsafe { pd(_mm512_xor_si512(bits(self.0), bits(_mm512_set1_pd(-0.0)))) }
        }
        #[inline(always)]
        fn copysign(self, s: Self) -> Self {
            unsafe {
                let m = bits(_mm512_set1_pd(-0.0));
                pd(_mm512_or_si512(_mm512_and_si512(bits(s.0), m), _mm512_andnot_si512(m, bits(self.0))))
            }
        }
        #[inline(always)]
        fn le(self, o: Self) -> Self {
            unsafe { mask(_mm512_cmp_pd_mask::<_CMP_LE_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn ge(self, o: Self) -> Self {
            unsafe { mask(_mm512_cmp_pd_mask::<_CMP_GE_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            unsafe { mask(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn eq(self, o: Self) -> Self {
            unsafe { mask(_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(self.0, o.0)) }
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            unsafe { pd(_mm512_and_si512(bits(self.0), bits(o.0))) }
        }
        #[inline(always)]
        fn or(self, o: Self) -> Self {
            unsafe { pd(_mm512_or_si512(bits(self.0), bits(o.0))) }
        }
        #[inline(always)]
        fn andnot(self, o: Self) -> Self {
            unsafe { pd(_mm512_andnot_si512(bits(self.0), bits(o.0))) }
        }
        #[inline(always)]
        fn select(m: Self, a: Self, b: Self) -> Self {
            unsafe {
                let k = _mm512_test_epi64_mask(bits(m.0), bits(m.0));
                Avx512D(_mm512_mask_blend_pd(k, b.0, a.0))
            }
        }
        #[inline(always)]
        fn bitmask(self) -> u32 {
            unsafe { _mm512_test_epi64_mask(bits(self.0), bits(self.0)) as u32 }
        }
        #[inline(always)]
        fn load(a: &[f64; 8]) -> Self {
            unsafe { Avx512D(_mm512_loadu_pd(a.as_ptr())) }
        }
        #[inline(always)]
        fn store(self) -> [f64; 8] {
            let mut a = [0.0; 8];
            unsafe { _mm512_storeu_pd(a.as_mut_ptr(), self.0) };
            a
        }
    }
}
