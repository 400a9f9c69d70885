//! Axis-aligned boxes and the ray/box slab test.

use glam::{Affine3A, Vec3};

/// An axis-aligned bounding box. `Aabb::EMPTY` has `min > max`; an unbounded solid
/// (a half-space) has infinite components.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb::EMPTY
    }
}

impl Aabb {
    /// The empty box (union identity).
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };
    /// All of space.
    pub const INFINITE: Aabb = Aabb { min: Vec3::splat(f32::NEG_INFINITY), max: Vec3::splat(f32::INFINITY) };

    /// A box from its corners.
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Aabb { min, max }
    }
    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }
    /// True when every component is finite (the box can go into a BVH).
    pub fn is_finite(&self) -> bool {
        self.min.is_finite() && self.max.is_finite()
    }
    /// Smallest box holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    /// The overlap of both (possibly empty).
    pub fn intersection(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.max(o.min), max: self.max.min(o.max) }
    }
    /// Grows the box to hold `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    /// Is `p` inside (boundary included)?
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }
    /// Centre of a finite box.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }
    /// Length of the diagonal (0 for an empty box).
    pub fn diagonal_length(&self) -> f32 {
        if self.is_empty() {
            0.0
        } else {
            (self.max - self.min).length()
        }
    }
    /// The box of the image of this box under `m` (all eight corners). Infinite boxes
    /// stay infinite.
    pub fn transformed(&self, m: &Affine3A) -> Aabb {
        if self.is_empty() {
            return Aabb::EMPTY;
        }
        if !self.is_finite() {
            return Aabb::INFINITE;
        }
        // Arvo's method: exact box of a transformed box.
        let mut out = Aabb { min: Vec3::from(m.translation), max: Vec3::from(m.translation) };
        let cols = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
        for (j, c) in cols.iter().enumerate() {
            let c = Vec3::from(*c);
            let a = c * self.min[j];
            let b = c * self.max[j];
            out.min += a.min(b);
            out.max += a.max(b);
        }
        out
    }
    /// The parametric range `[t0, t1]` of the ray inside the box, clipped to
    /// `[tmin, tmax]`; `None` when it misses. `inv_d` is `1 / d` per component.
    #[inline(always)]
    pub fn ray_range(&self, o: Vec3, inv_d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32)> {
        let t1 = (self.min - o) * inv_d;
        let t2 = (self.max - o) * inv_d;
        // 0 * inf is NaN when a ray parallel to a slab starts exactly on it: that
        // ray touches the box, so NaN must widen the range, not empty it.
        let nan1 = t1.cmpne(t1);
        let nan2 = t2.cmpne(t2);
        let tn = Vec3::select(nan1 | nan2, Vec3::NEG_INFINITY, t1.min(t2));
        let tf = Vec3::select(nan1 | nan2, Vec3::INFINITY, t1.max(t2));
        let t0 = tn.x.max(tn.y).max(tn.z).max(tmin);
        let t1 = tf.x.min(tf.y).min(tf.z).min(tmax);
        if t0 <= t1 {
            Some((t0, t1))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_on_a_face_plane_touches_the_box() {
        // Regression: origin exactly on the min-x face, direction parallel to it.
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let o = Vec3::new(0.0, 0.5, -1.0);
        let d = Vec3::Z;
        assert!(b.ray_range(o, d.recip(), 0.0, 10.0).is_some());
        let o = Vec3::new(-1e-3, 0.5, -1.0);
        assert!(b.ray_range(o, d.recip(), 0.0, 10.0).is_none());
    }
}
