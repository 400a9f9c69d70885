//! The one ray type of every layer: primitives, CSG evaluation, the engine's
//! queries and the packet and tile levels all take a [`Ray`] rather than
//! loose `o, d, tmin, tmax` parameters.

use glam::Vec3;

use crate::{Span, SpanSink};

/// The largest direction component that queries and kernels take as given
/// (2^32; the smallest is its inverse). Inside this range the kernels' f32
/// squares of a direction (|d|^2 of the sphere and cylinder, the length in
/// the fusing tolerance) stay normal and finite with room to spare; outside
/// it (|d| = 1e-24 squared underflows to 0, 1e20 squared overflows) the
/// line is traced with its direction scaled by a power of two
/// ([`Ray::dir_rescale`]), which is exact, and t scaled back.
pub const DIR_SAFE_MAX: f32 = 4294967296.0;

/// A ray `origin + t * dir` over `t` in `[tmin, tmax]` (t is in units of
/// `dir`, which need not be unit length), with `1 / dir` made once for the
/// box tests of every BVH it walks.
///
/// Build it with [`Ray::new`] or [`Ray::segment`] (they set `inv_dir`); a ray
/// whose `dir` is changed in place must get `inv_dir` again
/// ([`Ray::segment`] with the new direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be unit length).
    pub dir: Vec3,
    /// `1 / dir` per component (infinite where `dir` is zero).
    pub inv_dir: Vec3,
    /// Smallest t.
    pub tmin: f32,
    /// Largest t.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[0, inf)`.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self::segment(origin, dir, 0.0, f32::INFINITY)
    }

    /// A ray over `[tmin, tmax]`.
    #[inline]
    pub fn segment(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray { origin, dir, inv_dir: dir.recip(), tmin, tmax }
    }

    /// The same line over `[tmin, tmax]` (no division: `inv_dir` is kept).
    #[inline(always)]
    pub fn with_range(&self, tmin: f32, tmax: f32) -> Self {
        Ray { tmin, tmax, ..*self }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// The power of two `k` that brings `dir`'s largest component into
    /// [1, 2) when that component lies outside [1 / [`DIR_SAFE_MAX`],
    /// [`DIR_SAFE_MAX`]] (`None` inside: the common case costs one pair of
    /// comparisons). In f64, since the factor for a subnormal direction
    /// (up to 2^149) does not fit in f32.
    #[inline(always)]
    pub fn dir_rescale(dir: Vec3) -> Option<f64> {
        let m = dir.abs().max_element();
        if (1.0 / DIR_SAFE_MAX..=DIR_SAFE_MAX).contains(&m) {
            return None;
        }
        dir_scale_slow(m)
    }

    /// The same line with its direction multiplied by `k` (a power of two from
    /// [`Ray::dir_rescale`]) and its range divided by it: t on it times `k` is
    /// t on `self` ([`scale_t`]). Exact, unless the range's ends leave f32.
    pub fn rescaled(&self, k: f64) -> Ray {
        let dir = (self.dir.as_dvec3() * k).as_vec3();
        Ray::segment(self.origin, dir, scale_t(self.tmin, 1.0 / k), scale_t(self.tmax, 1.0 / k))
    }

    /// Is the ray usable (finite origin, finite non-zero direction, tmin <= tmax)?
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && !self.tmin.is_nan()
            && !self.tmax.is_nan()
            && self.tmin <= self.tmax
    }

    /// Is the ray usable ([`Ray::is_valid`]) with a direction the kernels
    /// take as given ([`Ray::dir_rescale`] is `None`)? The same tests
    /// combined with `&`, without a branch: a packet asks it of its eight
    /// rays (short-circuiting, they were a sixth of
    /// `intersect_packet_with`'s cycles on benches/scenes/capsules flat, perf).
    #[inline(always)]
    pub fn is_plain(&self) -> bool {
        let (o, d) = (self.origin, self.dir);
        let finite = o.x.is_finite() & o.y.is_finite() & o.z.is_finite() & d.x.is_finite() & d.y.is_finite() & d.z.is_finite();
        let range = !self.tmin.is_nan() & !self.tmax.is_nan() & (self.tmin <= self.tmax);
        // (A largest component of at least 2^-32 is a direction other than zero.)
        let m = d.x.abs().max(d.y.abs()).max(d.z.abs());
        finite & range & (1.0 / DIR_SAFE_MAX..=DIR_SAFE_MAX).contains(&m)
    }
}

#[cold]
#[inline(never)]
fn dir_scale_slow(m: f32) -> Option<f64> {
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    // 2^-e for m = 1.x * 2^e (m as f64 is normal even when m is subnormal).
    let e = ((m as f64).to_bits() >> 52) as i64 - 1023;
    Some(f64::from_bits(((1023 - e) as u64) << 52))
}

/// `t * k` rounded to f32 (`k` a power of two: exact unless it leaves f32's range).
#[inline]
pub fn scale_t(t: f32, k: f64) -> f32 {
    (t as f64 * k) as f32
}

/// A sink that takes spans in t of a rescaled ray ([`Ray::rescaled`] with `k`)
/// and passes them on in t of the original ray; a span whose ends meet once
/// scaled (f32's range exceeded) is dropped, as zero-length spans are.
pub struct ScaledSink<'a, S: SpanSink + ?Sized> {
    /// Where the spans go.
    pub out: &'a mut S,
    /// The factor of [`Ray::rescaled`].
    pub k: f64,
}

impl<S: SpanSink + ?Sized> SpanSink for ScaledSink<'_, S> {
    fn push_span(&mut self, s: Span) {
        let (t0, t1) = (scale_t(s.t0, self.k), scale_t(s.t1, self.k));
        if t1 > t0 {
            self.out.push_span(Span { t0, t1, ..s });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `is_plain` is `is_valid` and `dir_rescale` being `None`: rays with
    /// zero, tiny, huge, infinite and NaN components and ranges.
    #[test]
    fn is_plain_is_valid_and_in_range() {
        let seed = 0x51a7u64;
        println!("seed {seed}");
        let mut s = seed;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let odd = [
            0.0f32,
            -0.0,
            1e-12,
            2.3283064e-10,
            2.3283063e-10,
            4294967296.0,
            4294967300.0,
            1e30,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -1.5,
        ];
        // A plain number, or one time in three an odd one.
        let mut pick = move || {
            let r = next();
            if r % 3 != 0 {
                (r % 2001) as f32 / 1000.0 - 1.0
            } else {
                odd[((r >> 8) % odd.len() as u64) as usize]
            }
        };
        let mut plain = 0;
        for case in 0..100_000 {
            let mut r = Ray::new(Vec3::new(pick(), pick(), pick()), Vec3::new(pick(), pick(), pick()));
            (r.tmin, r.tmax) = (pick(), pick());
            let want = r.is_valid() && Ray::dir_rescale(r.dir).is_none();
            assert_eq!(r.is_plain(), want, "case {case}: {r:?}");
            plain += want as u32;
        }
        assert!(plain > 1000 && plain < 99_000, "too one-sided to mean anything: {plain}");
    }
}
