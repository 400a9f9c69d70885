//! Axis-aligned boxes and the ray/box slab test.

use glam::{Affine3A, DAffine3, DVec3, Vec3, Vec3A};

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

/// A box's distance from the rays' origins is shrunk by this much before
/// it bounds their entries ([`Aabb::near_from`]): the slab test's entry
/// and the distance each round a few times (relative 1e-7 each). (The
/// tests `distances_bound_entries` of the engine's box list and
/// `near_bounds_every_lanes_entry` of the tile lists fail with `1 + 1e-6`.)
pub const NEAR_SHRINK: f32 = 1.0 - 1e-5;

/// How far from their origins the rays of `lanes` (origins `o`, directions
/// `d`, ranges from `tmin`) go per unit of `t`: a box whose
/// [`Aabb::near_from`] `origins` lies past `t` times this is entered past
/// `t` by every one (`|t| |d|` is at least the distance of the entry from
/// the origin). `None` unless every ray starts in `origins` on its range's
/// side (`tmin >= 0`), or when the length is not positive and finite.
pub fn reach_per_t(origins: &Aabb, (o, d, tmin): (&[Vec3; 8], &[Vec3; 8], &[f32; 8]), lanes: u32) -> Option<f32> {
    let from = (0..8).all(|k| lanes & (1 << k) == 0 || (origins.contains(o[k]) && tmin[k] >= 0.0));
    let s = (0..8).filter(|k| lanes & (1 << k) != 0).fold(0.0f32, |m, k| m.max(d[k].length_squared())).sqrt();
    (from && s > 0.0 && s.is_finite()).then_some(s)
}

/// Keys that put boxes nearest first from `origins` ([`Aabb::near_from`]),
/// then in their given order, into `keys`, sorted: each key is a box's
/// bound in its high 32 bits (not negative, so its bits order as its value;
/// NaN last) and its place among `boxes` in the low 32 ([`near_of_key`],
/// `key as u32`). Why keys: sorting 8-byte integers instead of the boxes.
pub fn nearest_first<'a>(origins: &Aabb, boxes: impl Iterator<Item = &'a Aabb>, keys: &mut Vec<u64>) {
    keys.clear();
    keys.extend(boxes.enumerate().map(|(i, b)| (b.near_from(origins).to_bits() as u64) << 32 | i as u64));
    keys.sort_unstable();
}

/// The bound a key of [`nearest_first`] holds.
#[inline(always)]
pub fn near_of_key(k: u64) -> f32 {
    f32::from_bits((k >> 32) as u32)
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
    /// The distance between the nearest points of this box and `o` (0
    /// where they touch or overlap; both non-empty).
    pub fn distance_to(&self, o: &Aabb) -> f32 {
        (o.min - self.max).max(self.min - o.max).max(Vec3::ZERO).length()
    }

    /// A bound for rays that start in `origins`: at most `|d|` times the
    /// entry into this box of any ray `o + t d` from there on a range from
    /// `t >= 0`, as the slab test computes it. Lists of boxes ordered by it
    /// let a packet stop at the first box past its lanes' reach
    /// ([`reach_per_t`]).
    pub fn near_from(&self, origins: &Aabb) -> f32 {
        origins.distance_to(self) * NEAR_SHRINK
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
    /// The f32 box holding the f64 box `[lo, hi]` grown by [`span_margin`]
    /// (infinite sides stay infinite). A leaf's bounds rounded to the
    /// nearest f32 lost up to half an ulp: 2.4e-4 at 5e3 from the origin,
    /// and a ray crossing a box's corner there for 1e-3 missed it in the
    /// whole program's box tests while a tile's kernels found the span
    /// (tests/tiles.rs, `packets_walk_wide_unions_together_far_from_origin`).
    pub fn enclosing(lo: DVec3, hi: DVec3) -> Aabb {
        if !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z) {
            return Aabb::EMPTY;
        }
        let finite = lo.is_finite() && hi.is_finite();
        let size = if finite { (hi - lo).length() } else { 0.0 };
        let reach = lo.abs().max(hi.abs()).max_element();
        let margin = span_margin(size, if reach.is_finite() { reach } else { 0.0 });
        let mut out = Aabb::EMPTY;
        for i in 0..3 {
            let (l, h) = ((lo[i] - margin) as f32, (hi[i] + margin) as f32);
            out.min[i] = if l.is_finite() { l.next_down() } else { l };
            out.max[i] = if h.is_finite() { h.next_up() } else { h };
        }
        out
    }

    /// [`Aabb::transformed`] in f64, enclosed by [`Aabb::enclosing`]: the
    /// f32 sums of the transform rounded the corners to the nearest f32.
    pub fn transformed_f64(&self, m: &DAffine3) -> Aabb {
        if self.is_empty() {
            return Aabb::EMPTY;
        }
        if !self.is_finite() {
            return Aabb::INFINITE;
        }
        let (mut lo, mut hi) = (m.translation, m.translation);
        for (j, c) in [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis].iter().enumerate() {
            let a = *c * self.min[j] as f64;
            let b = *c * self.max[j] as f64;
            lo += a.min(b);
            hi += a.max(b);
        }
        Aabb::enclosing(lo, hi)
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
    /// [`Aabb::ray_range`] from the line's entry and exit of the box
    /// (`(t0, t1)` as [`crate::box_wide::BoxTest8::slabs`] gives them), on
    /// `[tmin, tmax]`: the same operations in the same order, so the same bits.
    #[inline(always)]
    pub fn clip_slabs((t0, t1): (f32, f32), tmin: f32, tmax: f32) -> Option<(f32, f32)> {
        let (t0, t1) = (max_ps(t0, tmin), min_ps(t1, tmax));
        if t0 <= t1 {
            Some((t0, t1))
        } else {
            None
        }
    }

    /// The parametric range `[t0, t1]` of the ray inside the box, clipped to
    /// `[tmin, tmax]`; `None` when it misses. `inv_d` is `1 / d` per component.
    #[inline(always)]
    pub fn ray_range(&self, o: Vec3, inv_d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32)> {
        // In 4-lane registers (`Vec3A`): `Vec3::select` picked each component
        // by its own test and branch, a third of the cycles of
        // `Program::eval_node` on benches/scenes/logo (perf). The same
        // operations per component (`min` / `max` keep their operand order,
        // so NaN and signed zeros come out alike), so the same results.
        let o = Vec3A::from(o);
        let inv_d = Vec3A::from(inv_d);
        let t1 = (Vec3A::from(self.min) - o) * inv_d;
        let t2 = (Vec3A::from(self.max) - o) * inv_d;
        // 0 * inf is NaN when a ray parallel to a slab starts exactly on it: that
        // ray touches the box, so NaN must widen the range, not empty it.
        let nan1 = t1.cmpne(t1);
        let nan2 = t2.cmpne(t2);
        let tn = Vec3A::select(nan1 | nan2, Vec3A::NEG_INFINITY, t1.min(t2));
        let tf = Vec3A::select(nan1 | nan2, Vec3A::INFINITY, t1.max(t2));
        // `maxss` / `minss` alone, in the packet box tests' order
        // (`Vec4::max` there): `f32::max` adds a NaN test and a blend to
        // each, a third of the cycles of `Program::eval_node` on
        // benches/scenes/logo (perf).
        let t0 = max_ps(max_ps(max_ps(tn.x, tn.y), tn.z), tmin);
        let t1 = min_ps(min_ps(min_ps(tf.x, tf.y), tf.z), tmax);
        if t0 <= t1 {
            Some((t0, t1))
        } else {
            None
        }
    }
}

/// How far leaf bounds reach past a solid of diagonal `size` whose farthest
/// coordinate from the origin is `reach`: the f32 rounding of the leaves'
/// own spans and of the box tests is a few ulps of the coordinates
/// involved; 1e-5 of the size plus 1e-6 of the reach (8 ulps) covers it
/// with room to spare.
pub fn span_margin(size: f64, reach: f64) -> f64 {
    1e-5 * size + 1e-6 * reach + 1e-30
}

/// `a > b ? a : b`, as `maxps` (and so glam's SSE `Vec4::max`) computes
/// it: `b` when they are equal (signed zeros) or either is NaN.
#[inline(always)]
pub(crate) fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// `a < b ? a : b`, as `minps` computes it.
#[inline(always)]
pub(crate) fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slab test one component at a time, as it was written with `Vec3`
    /// (the reference for the 4-lane one).
    fn ray_range_scalar(b: &Aabb, o: Vec3, inv_d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32)> {
        let mut tn = [0.0f32; 3];
        let mut tf = [0.0f32; 3];
        for a in 0..3 {
            let x = (b.min[a] - o[a]) * inv_d[a];
            let y = (b.max[a] - o[a]) * inv_d[a];
            let nan = x.is_nan() || y.is_nan();
            tn[a] = if nan {
                f32::NEG_INFINITY
            } else if x < y {
                x
            } else {
                y
            };
            tf[a] = if nan {
                f32::INFINITY
            } else if x > y {
                x
            } else {
                y
            };
        }
        // `maxps` / `minps` semantics, in the packet box tests' order: those
        // give the same bits (signed zeros included: `f32::max` of +0 and
        // -0 may give either).
        let t0 = max_ps(max_ps(max_ps(tn[0], tn[1]), tn[2]), tmin);
        let t1 = min_ps(min_ps(min_ps(tf[0], tf[1]), tf[2]), tmax);
        (t0 <= t1).then_some((t0, t1))
    }

    /// Bit for bit the component-wise slab test, on boxes and rays with
    /// coincident planes, zero and infinite inverse directions (NaN where a
    /// ray parallel to a slab starts on it), signed zeros and infinite boxes.
    #[test]
    fn ray_range_is_the_componentwise_test() {
        let seed = 0xaabb_u64;
        println!("seed {seed:#x}");
        let mut x = seed;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let pick = |r: u64| -> f32 {
            match r % 9 {
                0 => 0.0,
                1 => -0.0,
                2 => 1.0,
                3 => -1.0,
                4 => f32::INFINITY,
                5 => f32::NEG_INFINITY,
                _ => ((r >> 8) % 2000) as f32 / 500.0 - 2.0,
            }
        };
        let (mut hits, mut n) = (0, 0);
        for _ in 0..200_000 {
            let v = |next: &mut dyn FnMut() -> u64| Vec3::new(pick(next()), pick(next()), pick(next()));
            let (a, c) = (v(&mut next), v(&mut next));
            let b = Aabb::new(a.min(c), a.max(c));
            let o = v(&mut next);
            let inv = v(&mut next);
            let (tmin, tmax) = (pick(next()).min(0.5), pick(next()).max(-0.5));
            let bits = |r: Option<(f32, f32)>| r.map(|(p, q)| (p.to_bits(), q.to_bits()));
            let want = ray_range_scalar(&b, o, inv, tmin, tmax);
            assert_eq!(bits(b.ray_range(o, inv, tmin, tmax)), bits(want), "{b:?} {o} {inv} {tmin} {tmax}");
            hits += want.is_some() as u32;
            n += 1;
        }
        println!("{hits} of {n} rays meet their box");
        assert!(hits > n / 20 && hits < n - n / 20);
    }

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
