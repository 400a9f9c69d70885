//! The one ray type of every layer: primitives, CSG evaluation, the engine's
//! queries and the packet and tile levels all take a [`Ray`] rather than
//! loose `o, d, tmin, tmax` parameters.

use glam::Vec3;

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

    /// Is the ray usable (finite origin, finite non-zero direction, tmin <= tmax)?
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && !self.tmin.is_nan()
            && !self.tmax.is_nan()
            && self.tmin <= self.tmax
    }
}
