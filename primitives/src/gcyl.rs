//! Generalized cylinders (Bronsvoort and Klok 1985): a 2D profile swept along a
//! cubic Bezier chain `C(s)`, `s in [0, 1]` over the whole chain, capped at both
//! ends.
//!
//! The profile point `(x, y)` sits at `C(s) + x X(s) + y Y(s)`, `(X, Y, T)` a
//! right-handed frame, `T` the unit tangent. The solid is *every point on some
//! profile copy*: when the profile reaches farther than the radius of curvature
//! the copies overlap and the solid is still their union (its boundary then
//! includes the envelope of the cross-section planes, the "fold"). At a corner of
//! the path (a tangent discontinuity at a joint) the copies on both sides are
//! kept as they are: the outside of the corner gets a wedge-shaped notch.
//!
//! # Frames
//! * `RotationMinimizing` (default): `X(0)` is `normal` (default `[0, 1, 0]`, or
//!   `[1, 0, 0]` when that is within 8 degrees of `T(0)`) made perpendicular to
//!   `T(0)`; it is carried along the path by double reflection (Wang, Juttler,
//!   Zheng, Liu 2008) at `N` samples per segment (`N` from the tolerance, 64 at
//!   the default). Between samples the frame is one more double reflection from
//!   the sample below (continuous; exact at the samples). Global error `O(N^-4)`.
//! * `Frenet`: `X` is the principal normal where the curvature is defined
//!   (dimensionless curvature `|C' x C''| L / |C'|^3 > 1e-6`, `L` the segment's
//!   control polygon length), with its sign kept continuous (at an inflection
//!   the textbook Frenet normal flips by 180 degrees; we do not flip, since that
//!   would turn the profile half a turn within one sample step). Through
//!   straight runs and inflections the last defined normal is carried by double
//!   reflection (rotation minimizing); a path that starts straight gets the first
//!   defined normal carried backwards; a path with no curvature at all uses the
//!   rotation-minimizing frame with `normal`. Between samples the extra rotation
//!   about `T` is interpolated linearly. No NaN is produced anywhere.
//! * `twist_deg`: the profile is turned about `T` by `twist_deg * s` degrees.
//!
//! # Ray method (per segment, f64)
//! With the ray `q(sigma) = o' + sigma n` (`n` unit, `o'` near the segment), the
//! ray crosses the cross-section plane at u where
//! `(o' + sigma n - C(u)) . C'(u) = 0`, i.e. `sigma(u) = B(u) / A(u)` with
//! `A = n . C'` (degree 2) and `B = (C - o') . C'` (degree 5): the ray's path
//! through the "straightened" space `(x, y, u)` is exact and rational. The local
//! point there is `q(u) = B/A n - (C - o')`, and `|q|^2 <= R^2` (R the profile's
//! bounding radius) is the polynomial condition `H(u) = |B n - A (C - o')|^2 -
//! R^2 A^2 <= 0` (degree 10, no poles). Its roots give the u-ranges where the
//! ray can meet a copy at all (for a circle, the exact inside ranges). For a
//! polygon, each range is marched in u with steps bounded by the signed distance
//! to the polygon divided by an upper bound of the speed of `(x(u), y(u))`
//! (sphere tracing in the profile plane, minimum step `sqrt(tolerance) R`) and
//! every inside/outside change is bisected until sigma is known to
//! `tolerance * size`. Each inside u-run maps to one span `[min sigma, max sigma]`
//! (sigma is continuous on a run: a pole `A = 0` has `H > 0`); the extrema are at
//! the run ends or at the roots of `B'A - BA'` (degree 6: fold points). Spans of
//! all runs and segments are merged.
//!
//! Errors: circle profiles are exact up to f64 root polishing (the frame does
//! not matter for a circle, except for normals); polygons carry the frame error
//! (`O(N^-4)`) and the bisection tolerance; grazing chords through a polygon
//! shorter than about `sqrt(tolerance) R` may be missed. A ray lying exactly in
//! a cross-section plane of a straight or planar path (`A = 0` everywhere) is
//! handled by intersecting it with that copy of the profile in its plane.
//!
//! The roots of `H` and of `B'A - BA'` are isolated by Bernstein subdivision
//! ([`crate::poly::bern_roots`]); its extra candidate points are harmless here
//! (a candidate of `H` is polished or stays a breakpoint between pieces
//! classified at their midpoints; one of `B'A - BA'` only adds a sigma
//! evaluation inside the run). The planar case and the foot points keep
//! [`crate::poly::roots_in_tol`], where every root found is used as a root.
//!
//! Cost (test `gcyl_bench`, `cargo test -p rothray-primitives --release
//! gcyl_bench -- --ignored --nocapture`, the benchmark scene's camera at 960x540
//! on that scene's path, twist 45 degrees, ~6% of the rays hit; one thread on a
//! shared 2-core machine, +-10%): circle r = 0.3, 105-115 ns/ray on average
//! (460-510 with the derivative-chain isolation of `roots_in_tol`); square
//! 0.25, 660-690 ns/ray at tolerance 1e-6 (920) and 360-380 ns/ray at 1e-3
//! (820), where the coarser marching step already loses about 0.8% of the hit
//! rays (grazing chords): keep the default for polygons.

use glam::{DVec2, DVec3, Vec3};
use smallvec::SmallVec;

use crate::{
    aabb::Aabb,
    bvh::FlatBvh,
    poly::{bern_roots, cubic_range, roots_bern, roots_in_tol, to_bernstein},
    sweep::{f32_down, f32_up, push_union_slack, BVH_MIN_SEGMENTS},
    Ray, ShapeError, SpanSink,
};

/// Default [`GenCylData::new`] tolerance.
pub const DEFAULT_TOLERANCE: f32 = 1e-6;

/// Cross-section of a generalized cylinder.
#[derive(Clone, Debug, PartialEq)]
pub enum Profile {
    /// A circle of this radius centred on the path.
    Circle(f32),
    /// A simple polygon (counter-clockwise; clockwise is accepted too).
    Polygon(Vec<[f32; 2]>),
}

/// How the profile is oriented along the path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Frame {
    /// Rotation-minimizing frame (double reflection), starting from `normal`.
    #[default]
    RotationMinimizing,
    /// Principal normal (see the module doc for where the curvature vanishes).
    Frenet,
}

/// A generalized cylinder as described in a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneralizedCylinder {
    /// `3n + 1` control points of the cubic Bezier chain.
    pub path: Vec<[f32; 3]>,
    /// Cross-section.
    pub profile: Profile,
    /// Frame kind.
    pub frame: Frame,
    /// Start direction of the profile's x axis (rotation-minimizing frames).
    pub normal: Option<Vec3>,
    /// Twist of the profile about the tangent over the whole path, in degrees.
    pub twist_deg: f32,
}

/// Sub-surface ids are `segment << 2 | kind`, kind one of these.
pub mod sub {
    /// The copy at the start (u = 0) of the segment: the cap at s = 0 on the
    /// first segment, the face of the notch at a corner of the path elsewhere.
    pub const CAP0: u32 = 0;
    /// The copy at the end (u = 1) of the segment (the cap at s = 1 on the last).
    pub const CAP1: u32 = 1;
    /// Side (a profile boundary point swept along the path).
    pub const SIDE: u32 = 2;
    /// Fold: envelope of the cross-section planes (self-overlapping sweeps).
    pub const FOLD: u32 = 3;
}

fn err(field: &'static str, message: impl Into<String>) -> ShapeError {
    ShapeError { field, message: message.into() }
}

fn seg_cross(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let o = |p: DVec2, q: DVec2, r: DVec2| (q - p).perp_dot(r - p);
    let (d1, d2, d3, d4) = (o(c, d, a), o(c, d, b), o(a, b, c), o(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return true;
    }
    let on = |p: DVec2, q: DVec2, r: DVec2, v: f64| {
        v == 0.0 && r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    on(c, d, a, d1) || on(c, d, b, d2) || on(a, b, c, d3) || on(a, b, d, d4)
}

impl GeneralizedCylinder {
    /// Checks the numbers: path length `3n + 1` of finite points, no segment of
    /// zero length, positive radius or a simple polygon of non-zero area, finite
    /// non-zero `normal`, finite `twist_deg`.
    pub fn validate(&self) -> Result<(), ShapeError> {
        let n = self.path.len();
        if n < 4 || !(n - 1).is_multiple_of(3) {
            return Err(err("path", format!("length {n} is not 3n+1 (n >= 1)")));
        }
        for (i, p) in self.path.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(err("path", format!("point {i} {p:?} has a NaN or infinite number")));
            }
        }
        for i in 0..(n - 1) / 3 {
            let s = &self.path[3 * i..3 * i + 4];
            if s.iter().all(|p| *p == s[0]) {
                return Err(err("path", format!("segment {i} has zero length (all 4 points coincide)")));
            }
        }
        match &self.profile {
            Profile::Circle(r) => {
                if !(r.is_finite() && *r > 0.0) {
                    return Err(err("profile", format!("circle radius must be a positive finite number, got {r}")));
                }
            }
            Profile::Polygon(p) => {
                if p.len() < 3 {
                    return Err(err("profile", format!("polygon has {} points, needs at least 3", p.len())));
                }
                if !p.iter().flatten().all(|x| x.is_finite()) {
                    return Err(err("profile", "polygon has a NaN or infinite number"));
                }
                let v: Vec<DVec2> = p.iter().map(|q| DVec2::new(q[0] as f64, q[1] as f64)).collect();
                let m = v.len();
                let area: f64 = (0..m).map(|i| v[i].perp_dot(v[(i + 1) % m])).sum::<f64>() * 0.5;
                // Self-intersection first: a bow tie's signed area can cancel to 0,
                // and "self-intersecting" is the message that explains it.
                for i in 0..m {
                    for j in i + 1..m {
                        let adjacent = j == i + 1 || (i == 0 && j == m - 1);
                        let (a, b, c, d) = (v[i], v[(i + 1) % m], v[j], v[(j + 1) % m]);
                        if adjacent {
                            // adjacent edges may only share their common vertex
                            let (shared, other_a, other_b) = if j == i + 1 { (b, a, d) } else { (a, b, c) };
                            let (ea, eb) = (other_a - shared, other_b - shared);
                            if ea.perp_dot(eb) == 0.0 && ea.dot(eb) > 0.0 {
                                return Err(err("profile", format!("polygon edges {i} and {j} overlap")));
                            }
                        } else if seg_cross(a, b, c, d) {
                            return Err(err("profile", format!("polygon is self-intersecting (edges {i} and {j})")));
                        }
                    }
                }
                if area == 0.0 {
                    return Err(err("profile", "polygon has zero area"));
                }
            }
        }
        if let Some(nv) = self.normal {
            if !nv.is_finite() {
                return Err(err("normal", "must be finite"));
            }
            if nv.length_squared() == 0.0 {
                return Err(err("normal", "is the zero vector"));
            }
        }
        if !self.twist_deg.is_finite() {
            return Err(err("twist_deg", "must be finite"));
        }
        Ok(())
    }
}

#[derive(Clone, Debug)]
enum Prof {
    Circle(f64),
    /// Vertices (CCW) and unit outward edge normals.
    Polygon(Vec<DVec2>, Vec<DVec2>),
}

impl Prof {
    /// Signed distance to the profile boundary (negative inside).
    fn sd(&self, p: DVec2) -> f64 {
        match self {
            Prof::Circle(r) => p.length() - r,
            Prof::Polygon(v, _) => {
                let m = v.len();
                let mut d2 = f64::INFINITY;
                let mut inside = false;
                for i in 0..m {
                    let (a, b) = (v[i], v[(i + 1) % m]);
                    let e = b - a;
                    let h = ((p - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
                    d2 = d2.min((p - a - e * h).length_squared());
                    if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                        inside = !inside;
                    }
                }
                if inside {
                    -d2.sqrt()
                } else {
                    d2.sqrt()
                }
            }
        }
    }
    fn contains(&self, p: DVec2) -> bool {
        self.sd(p) <= 0.0
    }
    /// Outward unit normal of the boundary point nearest `p`, and the boundary's
    /// unit tangent there (counter-clockwise).
    fn boundary_frame(&self, p: DVec2) -> (DVec2, DVec2) {
        match self {
            Prof::Circle(_) => {
                let n = p.try_normalize().unwrap_or(DVec2::X);
                (n, n.perp())
            }
            Prof::Polygon(v, nr) => {
                let m = v.len();
                let mut best = (f64::INFINITY, 0);
                for i in 0..m {
                    let (a, b) = (v[i], v[(i + 1) % m]);
                    let e = b - a;
                    let h = ((p - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
                    let d = (p - a - e * h).length_squared();
                    if d < best.0 {
                        best = (d, i);
                    }
                }
                let n = nr[best.1];
                (n, n.perp())
            }
        }
    }
    /// The `[s0, s1]` ranges of the 2D line `p + s e` inside the profile.
    fn chord(&self, p: DVec2, e: DVec2, out: &mut SmallVec<[(f64, f64); 4]>) {
        match self {
            Prof::Circle(r) => {
                let a = e.length_squared();
                if a == 0.0 {
                    return;
                }
                let b = p.dot(e);
                let disc = b * b - a * (p.length_squared() - r * r);
                if disc > 0.0 {
                    out.push(((-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a));
                }
            }
            Prof::Polygon(v, _) => {
                let m = v.len();
                let mut ts: SmallVec<[f64; 16]> = SmallVec::new();
                for i in 0..m {
                    let (a, b) = (v[i], v[(i + 1) % m]);
                    let den = e.perp_dot(b - a);
                    if den == 0.0 {
                        continue;
                    }
                    let s = (a - p).perp_dot(b - a) / den;
                    let h = (a - p).perp_dot(e) / den;
                    if (0.0..1.0).contains(&h) {
                        ts.push(s);
                    }
                }
                ts.sort_by(|a, b| a.total_cmp(b));
                for w in ts.chunks(2) {
                    if w.len() == 2 && w[1] > w[0] {
                        out.push((w[0], w[1]));
                    }
                }
            }
        }
    }
}

/// One segment: monomial coefficients of C, C', C''.
#[derive(Clone, Debug)]
struct GSeg {
    c: [[f64; 4]; 3],
    center: DVec3,
}

impl GSeg {
    fn at(&self, u: f64) -> DVec3 {
        DVec3::new(eval(&self.c[0], u), eval(&self.c[1], u), eval(&self.c[2], u))
    }
    fn d1(&self, u: f64) -> DVec3 {
        let f = |c: &[f64; 4]| c[1] + u * (2.0 * c[2] + u * 3.0 * c[3]);
        DVec3::new(f(&self.c[0]), f(&self.c[1]), f(&self.c[2]))
    }
    fn d2(&self, u: f64) -> DVec3 {
        let f = |c: &[f64; 4]| 2.0 * c[2] + 6.0 * u * c[3];
        DVec3::new(f(&self.c[0]), f(&self.c[1]), f(&self.c[2]))
    }
    /// Unit tangent; where `C' = 0` (coincident control points at an end) the
    /// limit direction from `C''`, else the chord.
    /// `C(u1) - C(u0)`, accurate to its own size however close `u0` and `u1`
    /// are (the difference of two evaluations would carry the rounding of the
    /// points themselves, ~1e-16 of the coefficients, as a chord of any direction).
    fn chord(&self, u0: f64, u1: f64) -> DVec3 {
        let (s1, s2) = (u0 + u1, u0 * u0 + u0 * u1 + u1 * u1);
        let f = |c: &[f64; 4]| (c[1] + c[2] * s1 + c[3] * s2) * (u1 - u0);
        DVec3::new(f(&self.c[0]), f(&self.c[1]), f(&self.c[2]))
    }
    fn tangent(&self, u: f64) -> DVec3 {
        let d = self.d1(u);
        let scale = (self.at(1.0) - self.at(0.0)).length_squared().max(1e-300);
        if d.length_squared() > 1e-20 * scale {
            return d.normalize();
        }
        let dd = if u < 0.5 { self.d2(u) } else { -self.d2(u) };
        dd.try_normalize().or_else(|| (self.at(1.0) - self.at(0.0)).try_normalize()).unwrap_or(DVec3::Z)
    }
}

#[inline]
fn eval(c: &[f64], x: f64) -> f64 {
    crate::poly::eval(c, x)
}

/// One frame sample: segment parameter, tangent, x axis, and the extra rotation
/// (radians about T) from the double-reflected x axis to the next sample's x axis.
#[derive(Clone, Copy, Debug)]
struct FrameSample {
    u: f64,
    t: DVec3,
    x: DVec3,
    phi: f64,
}

/// Double reflection (Wang et al. 2008): carries `x0` at tangent `t0` along the
/// chord `v1` (from [`GSeg::chord`]) to tangent `t1`. The chord must be exact
/// to its own size: the first reflection's plane is normal to it, and a chord
/// of rounding noise (two separately rounded points a zero-length step apart,
/// as at a joint) turns the frame by up to 180 degrees about the tangent
/// (issue 15: 0.46 rad after the first joint of a two-segment path). A zero
/// chord is a zero-length step: the minimal rotation from `t0` to `t1`.
fn double_reflect(v1: DVec3, t0: DVec3, x0: DVec3, t1: DVec3) -> DVec3 {
    let c1l = v1.length_squared();
    if c1l == 0.0 {
        return min_rotate(x0, t0, t1);
    }
    let (xl, tl) = (x0 - v1 * (2.0 / c1l * v1.dot(x0)), t0 - v1 * (2.0 / c1l * v1.dot(t0)));
    let v2 = t1 - tl;
    let c2 = v2.length_squared();
    let x = if c2 > 1e-300 { xl - v2 * (2.0 / c2 * v2.dot(xl)) } else { xl };
    // re-orthonormalise against rounding
    (x - t1 * x.dot(t1)).try_normalize().unwrap_or_else(|| t1.any_orthonormal_vector())
}

/// `x` turned by the smallest rotation that takes the unit `t0` to the unit
/// `t1` (about `t0 x t1`), made perpendicular to `t1`: the rotation-minimizing
/// transport across a zero-length step, i.e. a joint of the path (the limit of
/// a bend of vanishing length; at a tangent-continuous joint it is the identity
/// up to rounding). Opposite tangents (a cusp) keep `x`.
fn min_rotate(x: DVec3, t0: DVec3, t1: DVec3) -> DVec3 {
    let v = t0.cross(t1);
    let c = t0.dot(t1);
    let x = if c > -1.0 + 1e-12 { x + v.cross(x) + v.cross(v.cross(x)) / (1.0 + c) } else { x };
    (x - t1 * x.dot(t1)).try_normalize().unwrap_or_else(|| t1.any_orthonormal_vector())
}

fn rotate_about(x: DVec3, t: DVec3, ang: f64) -> DVec3 {
    let (s, c) = ang.sin_cos();
    x * c + t.cross(x) * s
}

/// The local frame at a point of the path.
#[derive(Clone, Copy, Debug)]
pub struct FrameAt {
    /// Path point.
    pub c: DVec3,
    /// Unit tangent.
    pub t: DVec3,
    /// Profile x axis.
    pub x: DVec3,
    /// Profile y axis (`t x x`).
    pub y: DVec3,
}

/// Frame samples per segment at a tolerance: `clamp(2 tolerance^(-1/4), 8,
/// 512)` (the frame error is `O(N^-4)`), 64 at the default.
pub fn frame_samples(tolerance: f32) -> usize {
    let tol = (tolerance as f64).clamp(1e-12, 1e-2);
    ((2.0 * tol.powf(-0.25)).ceil() as usize).clamp(8, 512)
}

/// A baked generalized cylinder. Immutable, `Send + Sync`.
#[derive(Clone, Debug)]
pub struct GenCylData {
    segs: Vec<GSeg>,
    boxes: Vec<Aabb>,
    bounds: Aabb,
    bvh: Option<FlatBvh>,
    prof: Prof,
    /// Bounding radius of the profile (around the path point).
    rp: f64,
    /// Frame samples per segment.
    nsamp: usize,
    /// `segs.len() * (nsamp + 1)` samples (the joint sample is repeated).
    frames: Vec<FrameSample>,
    /// Twist in radians over the whole path.
    twist: f64,
    tol: f64,
    size: f64,
}

impl GenCylData {
    /// Bakes `desc` (validated here). `tolerance` (relative to the shape's size)
    /// sets the frame sampling (`N = clamp(2 tolerance^(-1/4), 8, 512)` per
    /// segment), the bisection accuracy of polygon crossings (`tolerance * size`
    /// in distance along the ray) and the minimum marching step
    /// (`sqrt(tolerance) * R`).
    pub fn new(desc: &GeneralizedCylinder, tolerance: f32) -> Result<Self, ShapeError> {
        Self::with_frame_samples(desc, tolerance, None)
    }

    /// [`GenCylData::new`] with `samples` frame samples per segment (2 to
    /// 65536) instead of the tolerance's: the `frame` knob of `rothray bench
    /// --knob`.
    pub fn with_frame_samples(desc: &GeneralizedCylinder, tolerance: f32, samples: Option<usize>) -> Result<Self, ShapeError> {
        desc.validate()?;
        if samples.is_some_and(|n| !(2..=65536).contains(&n)) {
            return Err(err("frame_samples", format!("must be 2 to 65536, got {}", samples.unwrap_or(0))));
        }
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(err("tolerance", format!("must be positive, got {tolerance}")));
        }
        let tol = (tolerance as f64).clamp(1e-12, 1e-2);
        let nseg = (desc.path.len() - 1) / 3;
        let prof = match &desc.profile {
            Profile::Circle(r) => Prof::Circle(*r as f64),
            Profile::Polygon(p) => {
                let mut v: Vec<DVec2> = p.iter().map(|q| DVec2::new(q[0] as f64, q[1] as f64)).collect();
                let m = v.len();
                let area: f64 = (0..m).map(|i| v[i].perp_dot(v[(i + 1) % m])).sum();
                if area < 0.0 {
                    v.reverse();
                }
                let nr = (0..m).map(|i| -(v[(i + 1) % m] - v[i]).perp().normalize()).collect();
                Prof::Polygon(v, nr)
            }
        };
        let rp = match &prof {
            Prof::Circle(r) => *r,
            Prof::Polygon(v, _) => v.iter().map(|p| p.length()).fold(0.0, f64::max) * (1.0 + 1e-9),
        };
        let mut segs = Vec::with_capacity(nseg);
        let mut boxes = Vec::with_capacity(nseg);
        let mut bounds = Aabb::EMPTY;
        for i in 0..nseg {
            let p = &desc.path[3 * i..3 * i + 4];
            let comp = |k: usize| {
                let q = [p[0][k] as f64, p[1][k] as f64, p[2][k] as f64, p[3][k] as f64];
                [q[0], 3.0 * (q[1] - q[0]), 3.0 * (q[0] - 2.0 * q[1] + q[2]), -q[0] + 3.0 * (q[1] - q[2]) + q[3]]
            };
            let c = [comp(0), comp(1), comp(2)];
            let mut lo = [0.0f32; 3];
            let mut hi = [0.0f32; 3];
            for k in 0..3 {
                let (l, h) = cubic_range(&c[k]);
                lo[k] = f32_down(l - rp);
                hi[k] = f32_up(h + rp);
            }
            let b = Aabb::new(Vec3::from(lo), Vec3::from(hi));
            bounds = bounds.union(&b);
            segs.push(GSeg { c, center: b.center().as_dvec3() });
            boxes.push(b);
        }
        let size = bounds.diagonal_length() as f64;
        let nsamp = samples.unwrap_or_else(|| frame_samples(tolerance));
        let frames = build_frames(&segs, nsamp, desc.frame, desc.normal);
        let bvh = (nseg > BVH_MIN_SEGMENTS).then(|| FlatBvh::build(&boxes, 1));
        Ok(GenCylData { segs, boxes, bounds, bvh, prof, rp, nsamp, frames, twist: (desc.twist_deg as f64).to_radians(), tol, size })
    }

    /// Local bounds: the path's exact box grown by the profile's bounding radius.
    pub fn local_bounds(&self) -> Aabb {
        self.bounds
    }

    /// Number of Bezier segments.
    pub fn segment_count(&self) -> usize {
        self.segs.len()
    }

    /// The frame at parameter `u` of segment `i` (twist included).
    pub fn frame_at(&self, i: usize, u: f64) -> FrameAt {
        let seg = &self.segs[i];
        let n = self.nsamp;
        let k = ((u * n as f64).floor() as usize).min(n - 1);
        let lam = u * n as f64 - k as f64;
        let fs = &self.frames[i * (n + 1) + k];
        let c = seg.at(u);
        let t = seg.tangent(u);
        let mut x = double_reflect(seg.chord(fs.u, u), fs.t, fs.x, t);
        if fs.phi != 0.0 {
            x = rotate_about(x, t, lam * fs.phi);
        }
        if self.twist != 0.0 {
            let s = (i as f64 + u) / self.segs.len() as f64;
            x = rotate_about(x, t, self.twist * s);
        }
        FrameAt { c, t, x, y: t.cross(x) }
    }

    /// Pushes the spans of `o + t d` inside the solid, clipped to `[tmin, tmax]`,
    /// sorted and disjoint; real crossings carry `Surf::new(leaf, seg << 2 | kind)`
    /// (kinds in [`sub`]).
    pub fn spans<S: SpanSink + ?Sized>(&self, ray: &Ray, leaf: u32, out: &mut S) {
        let Ray { origin: o, dir: d, inv_dir: inv, tmin, tmax } = *ray;
        if self.bounds.ray_range(o, inv, tmin, tmax).is_none() {
            return;
        }
        let od = o.as_dvec3();
        let dd = d.as_dvec3();
        let dl = dd.length();
        if !(dl > 0.0 && dl.is_finite()) {
            return;
        }
        let dn = dd / dl;
        let mut iv: SmallVec<[(f32, u32, f32, u32); 16]> = SmallVec::new();
        match &self.bvh {
            Some(b) => b.traverse(o, inv, tmin, tmax, |k, _| {
                self.seg_spans(k as usize, od, dn, dl, &mut iv);
                tmax
            }),
            None => {
                for i in 0..self.segs.len() {
                    if self.boxes[i].ray_range(o, inv, tmin, tmax).is_some() {
                        self.seg_spans(i, od, dn, dl, &mut iv);
                    }
                }
            }
        }
        // Runs that continue across a joint meet at the same plane: close the
        // rounding gap there.
        let slack = (self.size * 1e-7 / dl) as f32;
        push_union_slack(&mut iv, slack, tmin, tmax, leaf, out);
    }

    fn sub_at(&self, i: usize, u: f64, fold: bool) -> u32 {
        let kind = if fold {
            sub::FOLD
        } else if u == 0.0 {
            sub::CAP0
        } else if u == 1.0 {
            sub::CAP1
        } else {
            sub::SIDE
        };
        (i as u32) << 2 | kind
    }
}

/// The ray in the terms of segment `i`: `op`, its point nearest the
/// segment's centre, its unit direction `dn`, and the pencil polynomials
/// `A = dn . C'` (degree 2) and `B = (C - op) . C'` (degree 5): the ray
/// crosses the cross-section plane at `u` at distance `B(u) / A(u)` from `op`.
#[derive(Clone, Copy)]
struct SegRay {
    i: usize,
    op: DVec3,
    dn: DVec3,
    a: [f64; 3],
    b: [f64; 6],
}

impl GenCylData {
    fn seg_spans(&self, i: usize, od: DVec3, dn: DVec3, dl: f64, out: &mut SmallVec<[(f32, u32, f32, u32); 16]>) {
        let seg = &self.segs[i];
        let tc = (seg.center - od).dot(dn);
        let op = od + dn * tc;
        // w = C - o' (cubic per axis), C' (quadratic per axis)
        let mut w = seg.c;
        for ax in 0..3 {
            w[ax][0] -= op[ax];
        }
        let dc: [[f64; 3]; 3] = std::array::from_fn(|ax| [seg.c[ax][1], 2.0 * seg.c[ax][2], 3.0 * seg.c[ax][3]]);
        // A = n . C' (deg 2), B = w . C' (deg 5)
        let mut a = [0.0f64; 3];
        let mut b = [0.0f64; 6];
        for ax in 0..3 {
            for j in 0..3 {
                a[j] += dn[ax] * dc[ax][j];
                for k in 0..4 {
                    b[j + k] += w[ax][k] * dc[ax][j];
                }
            }
        }
        let cscale = dc.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        if a.iter().all(|x| x.abs() <= 1e-12 * cscale) {
            self.planar_chords(&SegRay { i, op, dn, a, b }, (tc, dl), out);
            return;
        }
        // H = |B n - A w|^2 - R^2 A^2 (deg 10)
        let mut h = [0.0f64; 11];
        for ax in 0..3 {
            let mut v = [0.0f64; 6];
            for k in 0..6 {
                v[k] += b[k] * dn[ax];
            }
            for j in 0..3 {
                for k in 0..4 {
                    v[j + k] -= a[j] * w[ax][k];
                }
            }
            for j in 0..6 {
                for k in 0..6 {
                    h[j + k] += v[j] * v[k];
                }
            }
        }
        let r2 = self.rp * self.rp;
        for j in 0..3 {
            for k in 0..3 {
                h[j + k] -= r2 * a[j] * a[k];
            }
        }
        let bh = to_bernstein(&h);
        if bh.iter().all(|&x| x > 0.0) {
            return;
        }
        let utol = 1e-14;
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        // Extra candidate points are harmless: each is polished below (or stays
        // a breakpoint between pieces classified at their midpoints).
        let nr = bern_roots(&bh, &h, 0.0, 1.0, utol, &mut roots);
        let mut pts: SmallVec<[f64; 12]> = SmallVec::new();
        pts.push(0.0);
        for &x in &roots[..nr] {
            if x > *pts.last().unwrap() && x < 1.0 {
                pts.push(x);
            }
        }
        pts.push(1.0);
        // The expanded H loses its relative accuracy where A is tiny (rays almost
        // in the cross-section planes: H ~ A^2 (|q|^2 - R^2) is far below the
        // rounding of its O(1) coefficients). The polynomial isolates the
        // roots; every root is then polished on the unexpanded
        // |B n - A w|^2 - R^2 A^2, which keeps ~1e-9 relative accuracy.
        let hd = |u: f64| {
            let c = seg.at(u) - op;
            let d1 = seg.d1(u);
            let (av, bv) = (dn.dot(d1), c.dot(d1));
            (dn * bv - c * av).length_squared() - r2 * av * av
        };
        for k in 1..pts.len() - 1 {
            let (lo_lim, hi_lim) = (pts[k - 1], pts[k + 1]);
            let x = pts[k];
            let mut dlt = 1e-12;
            while dlt < 1e-2 {
                let (a0, a1) = ((x - dlt).max(lo_lim), (x + dlt).min(hi_lim));
                let (f0, f1) = (hd(a0), hd(a1));
                if (f0 < 0.0) != (f1 < 0.0) {
                    let (mut p, mut q) = (a0, a1);
                    for _ in 0..80 {
                        let m = 0.5 * (p + q);
                        if m <= p || m >= q {
                            break;
                        }
                        if (hd(m) < 0.0) == (f0 < 0.0) {
                            p = m
                        } else {
                            q = m
                        }
                    }
                    pts[k] = 0.5 * (p + q);
                    break;
                }
                dlt *= 8.0;
            }
        }
        let mut ranges: SmallVec<[(f64, f64); 4]> = SmallVec::new();
        for k in 0..pts.len() - 1 {
            let (u0, u1) = (pts[k], pts[k + 1]);
            if u1 > u0 && hd(0.5 * (u0 + u1)) < 0.0 {
                match ranges.last_mut() {
                    Some(l) if l.1 == u0 => l.1 = u1,
                    _ => ranges.push((u0, u1)),
                }
            }
        }
        if ranges.is_empty() {
            return;
        }
        // sigma' numerator: B'A - BA' (deg 6)
        let da = [a[1], 2.0 * a[2]];
        let db: [f64; 5] = std::array::from_fn(|k| b[k + 1] * (k + 1) as f64);
        let mut sp = [0.0f64; 7];
        for j in 0..5 {
            for k in 0..3 {
                sp[j + k] += db[j] * a[k];
            }
        }
        for j in 0..6 {
            for k in 0..2 {
                sp[j + k] -= b[j] * da[k];
            }
        }
        let sigma = |u: f64| eval(&b, u) / eval(&a, u);
        let mut runs: SmallVec<[(f64, f64); 4]> = SmallVec::new();
        for &(u0, u1) in &ranges {
            match self.prof {
                Prof::Circle(_) => runs.push((u0, u1)),
                Prof::Polygon(..) => self.march(&SegRay { i, op, dn, a, b }, (u0, u1), &mut runs),
            }
        }
        for &(u0, u1) in &runs {
            let (s0, s1) = (sigma(u0), sigma(u1));
            let (mut lo, mut lo_sub) = (s0, self.sub_at(i, u0, false));
            let (mut hi, mut hi_sub) = (s0, lo_sub);
            let s1_sub = self.sub_at(i, u1, false);
            if s1 < lo {
                (lo, lo_sub) = (s1, s1_sub);
            }
            if s1 > hi {
                (hi, hi_sub) = (s1, s1_sub);
            }
            // Candidates only add sigma evaluations inside the run.
            let n = roots_bern(&sp, u0, u1, utol, &mut roots);
            for &u in &roots[..n] {
                if u <= u0 || u >= u1 {
                    continue;
                }
                let s = sigma(u);
                if s < lo {
                    (lo, lo_sub) = (s, self.sub_at(i, u, true));
                }
                if s > hi {
                    (hi, hi_sub) = (s, self.sub_at(i, u, true));
                }
            }
            out.push((((tc + lo) / dl) as f32, lo_sub, ((tc + hi) / dl) as f32, hi_sub));
        }
    }

    /// Local profile coordinates of the ray's crossing with the plane at u.
    #[inline]
    fn local_at(&self, r: &SegRay, u: f64) -> (DVec2, FrameAt, f64) {
        let f = self.frame_at(r.i, u);
        let s = eval(&r.b, u) / eval(&r.a, u);
        let q = r.op + r.dn * s - f.c;
        (DVec2::new(q.dot(f.x), q.dot(f.y)), f, s)
    }

    /// Inside u-runs of a polygon profile within `[u0, u1]` (a range where the
    /// crossing lies within the bounding circle).
    fn march(&self, r: &SegRay, (u0, u1): (f64, f64), runs: &mut SmallVec<[(f64, f64); 4]>) {
        let (i, dn, a, b) = (r.i, r.dn, &r.a, &r.b);
        let seg = &self.segs[i];
        let omega = (self.twist / self.segs.len() as f64).abs()
            + self.frames[i * (self.nsamp + 1)..(i + 1) * (self.nsamp + 1)].iter().fold(0.0f64, |m, f| m.max(f.phi.abs()))
                * self.nsamp as f64;
        // state: (u, local point, signed distance, speed bound of the local point)
        let state = |u: f64| {
            let (p, f, s) = self.local_at(r, u);
            let av = eval(a, u);
            let ap = a[1] + 2.0 * a[2] * u;
            let bp = b[1] + u * (2.0 * b[2] + u * (3.0 * b[3] + u * (4.0 * b[4] + u * 5.0 * b[5])));
            let sprime = (bp * av - eval(b, u) * ap) / (av * av);
            let d1 = seg.d1(u);
            let qp = dn * sprime - d1;
            let d2 = seg.d2(u);
            let tprime = (d2 - f.t * d2.dot(f.t)).length() / d1.length().max(1e-300);
            let speed = qp.length() + p.length() * (tprime + omega);
            (u, p, self.prof.sd(p), speed, s)
        };
        let hmin = self.rp * self.tol.sqrt();
        let stol = self.tol * self.size;
        let mut cur = state(u0);
        let mut inside = cur.2 <= 0.0;
        let mut start = if inside { Some(u0) } else { None };
        let mut iters = 0;
        while cur.0 < u1 && iters < 4000 {
            iters += 1;
            let mut h = (cur.2.abs().max(hmin) / cur.3.max(1e-300)) * 0.8;
            h = h.min(u1 - cur.0).max(1e-15);
            let mut nxt = state((cur.0 + h).min(u1));
            while nxt.3 > 2.0 * cur.3 && h > 1e-13 {
                h *= 0.5;
                nxt = state(cur.0 + h);
            }
            if (nxt.2 <= 0.0) != inside {
                // bisect the change
                let (mut lo, mut hi) = (cur, nxt);
                for _ in 0..200 {
                    if (hi.4 - lo.4).abs() <= stol || hi.0 - lo.0 <= 1e-15 {
                        break;
                    }
                    let m = state(0.5 * (lo.0 + hi.0));
                    if (m.2 <= 0.0) == inside {
                        lo = m
                    } else {
                        hi = m
                    }
                }
                if inside {
                    runs.push((start.take().unwrap_or(u0), lo.0));
                } else {
                    start = Some(hi.0);
                }
                inside = !inside;
            }
            cur = nxt;
        }
        if let Some(s) = start {
            runs.push((s, u1));
        }
    }

    /// The ray lies in the cross-section planes' pencil (`A = 0` on the whole
    /// segment): it meets the copies only where `B = 0`, in the plane itself.
    fn planar_chords(&self, r: &SegRay, (tc, dl): (f64, f64), out: &mut SmallVec<[(f32, u32, f32, u32); 16]>) {
        let SegRay { i, op, dn, ref b, .. } = *r;
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        let n = roots_in_tol(b, 0.0, 1.0, 1e-14, &mut roots);
        for &u in &roots[..n] {
            let f = self.frame_at(i, u);
            let q = op - f.c;
            let mut ch: SmallVec<[(f64, f64); 4]> = SmallVec::new();
            self.prof.chord(DVec2::new(q.dot(f.x), q.dot(f.y)), DVec2::new(dn.dot(f.x), dn.dot(f.y)), &mut ch);
            let s = self.sub_at(i, u, false);
            for (s0, s1) in ch {
                out.push((((tc + s0) / dl) as f32, s, ((tc + s1) / dl) as f32, s));
            }
        }
    }

    /// Is the local point inside (boundary included)? The foot points of `p`
    /// (roots of `(p - C(u)) . C'(u)`, degree 5, per segment) within the bounding
    /// radius are classified in their frames.
    pub fn contains(&self, p: Vec3) -> bool {
        self.contains_d(p.as_dvec3())
    }

    /// [`GenCylData::contains`] for an f64 point.
    pub fn contains_d(&self, pd: DVec3) -> bool {
        let p = pd.as_vec3();
        if !self.bounds.contains(p) {
            return false;
        }
        let test = |i: usize| self.boxes[i].contains(p) && self.seg_contains(i, pd);
        match &self.bvh {
            Some(b) => {
                let mut hit = false;
                b.point_query(p, |k| {
                    if !hit {
                        hit = test(k as usize);
                    }
                });
                hit
            }
            None => (0..self.segs.len()).any(test),
        }
    }

    fn foot_points(&self, i: usize, p: DVec3, out: &mut [f64; crate::poly::MAX_DEGREE]) -> usize {
        let seg = &self.segs[i];
        let mut f = [0.0f64; 6];
        for ax in 0..3 {
            let mut w = seg.c[ax];
            w[0] -= p[ax];
            let dc = [seg.c[ax][1], 2.0 * seg.c[ax][2], 3.0 * seg.c[ax][3]];
            for j in 0..3 {
                for k in 0..4 {
                    f[j + k] += w[k] * dc[j];
                }
            }
        }
        roots_in_tol(&f, 0.0, 1.0, 1e-14, out)
    }

    fn seg_contains(&self, i: usize, p: DVec3) -> bool {
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        let n = self.foot_points(i, p, &mut roots);
        roots[..n].iter().any(|&u| {
            let f = self.frame_at(i, u);
            let q = p - f.c;
            q.length_squared() <= self.rp * self.rp * (1.0 + 1e-9) && self.prof.contains(DVec2::new(q.dot(f.x), q.dot(f.y)))
        })
    }

    /// Outward unit normal at the surface point `p` on sub-surface `sub`.
    pub fn normal(&self, sub: u32, p: Vec3) -> Vec3 {
        let i = ((sub >> 2) as usize).min(self.segs.len() - 1);
        let kind = sub & 3;
        let pd = p.as_dvec3();
        match kind {
            sub::CAP0 => return (-self.segs[i].tangent(0.0)).as_vec3(),
            sub::CAP1 => return self.segs[i].tangent(1.0).as_vec3(),
            _ => {}
        }
        // The foot point whose local point is nearest the profile boundary (on
        // this segment or a neighbour: a crossing next to a joint may have its
        // foot point just across it).
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        let mut best: Option<(usize, f64, f64)> = None;
        for j in i.saturating_sub(1)..(i + 2).min(self.segs.len()) {
            let n = self.foot_points(j, pd, &mut roots);
            for &u in &roots[..n] {
                let f = self.frame_at(j, u);
                let q = pd - f.c;
                let e = self.prof.sd(DVec2::new(q.dot(f.x), q.dot(f.y))).abs() + if j == i { 0.0 } else { 1e-9 };
                if best.is_none_or(|b| e < b.2) {
                    best = Some((j, u, e));
                }
            }
        }
        let Some((i, u, _)) = best else { return self.segs[i].tangent(0.5).any_orthonormal_vector().as_vec3() };
        let f = self.frame_at(i, u);
        if kind == sub::FOLD {
            // envelope of the planes: the normal is the plane's; pick the side
            // that leaves the solid
            let step = 1e-4 * self.size;
            let nn = if self.contains((pd + f.t * step).as_vec3()) { -f.t } else { f.t };
            return nn.as_vec3();
        }
        let q = pd - f.c;
        let l = DVec2::new(q.dot(f.x), q.dot(f.y));
        let (m2, e2) = self.prof.boundary_frame(l);
        // S_lambda: the profile boundary direction; S_u by central differences
        let s_l = f.x * e2.x + f.y * e2.y;
        let h = 1e-5;
        let (ua, ub) = ((u - h).max(0.0), (u + h).min(1.0));
        let fa = self.frame_at(i, ua);
        let fb = self.frame_at(i, ub);
        let s_u = ((fb.c + fb.x * l.x + fb.y * l.y) - (fa.c + fa.x * l.x + fa.y * l.y)) / (ub - ua);
        let m3 = f.x * m2.x + f.y * m2.y;
        let nn = s_u.cross(s_l);
        let nn = if nn.dot(m3) < 0.0 { -nn } else { nn };
        nn.try_normalize().unwrap_or(m3).as_vec3()
    }
}

/// Frame samples for all segments (see the module doc).
fn build_frames(segs: &[GSeg], n: usize, kind: Frame, normal: Option<Vec3>) -> Vec<FrameSample> {
    let mut fr: Vec<FrameSample> = Vec::with_capacity(segs.len() * (n + 1));
    for s in segs {
        for k in 0..=n {
            let u = k as f64 / n as f64;
            fr.push(FrameSample { u, t: s.tangent(u), x: DVec3::ZERO, phi: 0.0 });
        }
    }
    // The chord between samples g and h (zero across a joint: the repeated sample).
    let chord = |g: usize, h: usize| {
        let u = |g: usize| (g % (n + 1)) as f64 / n as f64;
        if g / (n + 1) == h / (n + 1) {
            segs[g / (n + 1)].chord(u(g), u(h))
        } else {
            DVec3::ZERO
        }
    };
    // Frenet normal per sample where the curvature is defined.
    let frenet: Vec<Option<DVec3>> = if kind == Frame::Frenet {
        segs.iter()
            .flat_map(|s| {
                let l = (0..3).map(|k| (s.at_ctrl(k + 1) - s.at_ctrl(k)).length()).sum::<f64>();
                (0..=n).map(move |k| {
                    let u = k as f64 / n as f64;
                    let (d1, d2) = (s.d1(u), s.d2(u));
                    let dl = d1.length();
                    if dl == 0.0 {
                        return None;
                    }
                    let kappa_l = d1.cross(d2).length() / (dl * dl * dl) * l;
                    if kappa_l > 1e-6 {
                        (d2 - d1 * (d2.dot(d1) / (dl * dl))).try_normalize()
                    } else {
                        None
                    }
                })
            })
            .collect()
    } else {
        vec![None; fr.len()]
    };
    let t0 = fr[0].t;
    let start_rmf = || {
        let nv = normal.map(|v| v.as_dvec3().normalize()).unwrap_or_else(|| {
            if DVec3::Y.dot(t0).abs() > 8f64.to_radians().cos() {
                DVec3::X
            } else {
                DVec3::Y
            }
        });
        (nv - t0 * nv.dot(t0)).try_normalize().unwrap_or_else(|| t0.any_orthonormal_vector())
    };
    let first = frenet.iter().position(|x| x.is_some());
    let g0 = first.unwrap_or(0);
    fr[g0].x = match first {
        Some(g) => frenet[g].unwrap(),
        None => start_rmf(),
    };
    // carry backwards to the start (a path that starts straight)
    for g in (0..g0).rev() {
        let (a, b) = (fr[g + 1], fr[g]);
        fr[g].x = double_reflect(chord(g + 1, g), a.t, a.x, b.t);
    }
    for g in g0 + 1..fr.len() {
        let (a, b) = (fr[g - 1], fr[g]);
        let xd = double_reflect(chord(g - 1, g), a.t, a.x, b.t);
        let x = match frenet[g] {
            Some(nv) => {
                if nv.dot(xd) < 0.0 {
                    -nv
                } else {
                    nv
                }
            }
            None => xd,
        };
        fr[g].x = x;
    }
    // The extra rotation between samples (zero up to rounding for the RMF), so that
    // the interpolated frame meets every sample exactly. The joint sample is
    // repeated: there is no interval from a segment's last sample to the next.
    for g in 0..fr.len() - 1 {
        if (g + 1) % (n + 1) == 0 {
            continue;
        }
        let (a, b) = (fr[g], fr[g + 1]);
        let xd = double_reflect(chord(g, g + 1), a.t, a.x, b.t);
        fr[g].phi = xd.cross(b.x).dot(b.t).atan2(xd.dot(b.x));
    }
    fr
}

impl GSeg {
    /// Control point k, recovered from the monomial form.
    fn at_ctrl(&self, k: usize) -> DVec3 {
        let f = |c: &[f64; 4]| match k {
            0 => c[0],
            1 => c[0] + c[1] / 3.0,
            2 => c[0] + 2.0 * c[1] / 3.0 + c[2] / 3.0,
            _ => c[0] + c[1] + c[2] + c[3],
        };
        DVec3::new(f(&self.c[0]), f(&self.c[1]), f(&self.c[2]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{kernels, table::LeafShape, Span};
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    fn rand_unit(rng: &mut SmallRng) -> DVec3 {
        loop {
            let v = DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
            let l = v.length_squared();
            if l > 1e-4 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }

    fn straight(a: Vec3, b: Vec3) -> Vec<[f32; 3]> {
        [a, a + (b - a) / 3.0, a + (b - a) * (2.0 / 3.0), b].iter().map(|p| p.to_array()).collect()
    }

    fn gc(path: &[[f32; 3]], profile: Profile, frame: Frame, twist_deg: f32) -> GeneralizedCylinder {
        GeneralizedCylinder { path: path.to_vec(), profile, frame, normal: None, twist_deg }
    }

    const ARC: [[f32; 3]; 4] = [[1.0, 0.0, 0.0], [1.0, 0.55, 0.0], [0.55, 1.0, 0.0], [0.0, 1.0, 0.0]];
    const BENCH_PATH: [[f32; 3]; 7] = [
        [-1.5, 0.0, 0.0],
        [-0.8333, 1.1667, 0.5833],
        [-0.1667, 0.8333, 0.4167],
        [0.1667, -0.8333, -0.4167],
        [0.8333, -1.1667, -0.5833],
        [1.1667, -0.3333, -0.0833],
        [1.5, 0.0, 0.0],
    ];

    fn shapes() -> Vec<(&'static str, GeneralizedCylinder)> {
        let sq = |a: f32| Profile::Polygon(vec![[-a, -a], [a, -a], [a, a], [-a, a]]);
        let ell = Profile::Polygon(vec![[-0.2, -0.2], [0.25, -0.2], [0.25, -0.05], [-0.05, -0.05], [-0.05, 0.3], [-0.2, 0.3]]);
        let helix: Vec<[f32; 3]> =
            vec![[1.0, 0.0, 0.0], [1.0, 0.6, 0.3], [0.6, 1.0, 0.6], [0.0, 1.0, 0.9], [-0.6, 1.0, 1.2], [-1.0, 0.6, 1.5], [-1.0, 0.0, 1.8]];
        vec![
            ("arc circle", gc(&ARC, Profile::Circle(0.2), Frame::RotationMinimizing, 0.0)),
            ("helix square twist", gc(&helix, sq(0.15), Frame::RotationMinimizing, 90.0)),
            ("bench L frenet", gc(&BENCH_PATH, ell.clone(), Frame::Frenet, 0.0)),
            (
                "bench triangle",
                gc(&BENCH_PATH, Profile::Polygon(vec![[0.0, 0.3], [-0.25, -0.15], [0.25, -0.15]]), Frame::RotationMinimizing, 30.0),
            ),
            // profile larger than the radius of curvature: the sweep folds over itself
            (
                "folding circle",
                gc(
                    &[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 0.2]],
                    Profile::Circle(0.35),
                    Frame::RotationMinimizing,
                    0.0,
                ),
            ),
            (
                "folding square",
                gc(&[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 0.2]], sq(0.3), Frame::RotationMinimizing, 0.0),
            ),
        ]
    }

    /// f64 reference: dense sampling of t with `contains_d` (exact foot points),
    /// then bisection.
    fn reference(g: &GenCylData, o: DVec3, d: DVec3, t0: f64, t1: f64, n: usize) -> Vec<f64> {
        let mut out = vec![];
        let mut prev = g.contains_d(o + d * t0);
        let mut pt = t0;
        for k in 1..=n {
            let t = t0 + (t1 - t0) * k as f64 / n as f64;
            let cur = g.contains_d(o + d * t);
            if cur != prev {
                let (mut a, mut b) = (pt, t);
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if g.contains_d(o + d * m) == prev {
                        a = m
                    } else {
                        b = m
                    }
                }
                out.push(0.5 * (a + b));
            }
            prev = cur;
            pt = t;
        }
        out
    }

    fn sym_diff(a: &[f64], b: &[f64]) -> f64 {
        let inside = |l: &[f64], t: f64| l.chunks(2).any(|c| c.len() == 2 && t >= c[0] && t <= c[1]);
        let mut pts: Vec<f64> = a.iter().chain(b.iter()).copied().collect();
        pts.sort_by(|x, y| x.total_cmp(y));
        pts.windows(2).filter(|w| inside(a, 0.5 * (w[0] + w[1])) != inside(b, 0.5 * (w[0] + w[1]))).map(|w| w[1] - w[0]).sum()
    }

    #[test]
    fn spans_match_f64_reference() {
        let seed = 0x9c71_0001u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for (name, desc) in shapes() {
            let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
            let b = g.local_bounds();
            let size = b.diagonal_length() as f64;
            let c = b.center().as_dvec3();
            let (mut max_end, mut max_sd, mut same, mut mism, mut hits) = (0.0f64, 0.0f64, 0, 0, 0);
            let nrays = 360;
            for k in 0..nrays {
                let (o, d) = if k % 4 == 3 {
                    // along the path (near-tangent rays)
                    let i = rng.gen_range(0..g.segment_count());
                    let f = g.frame_at(i, rng.gen());
                    let v = (f.t + rand_unit(&mut rng) * 0.05).normalize();
                    (f.c + (f.x * rng.gen_range(-1.0..1.0) + f.y * rng.gen_range(-1.0..1.0)) * g.rp - v * size, v)
                } else if k % 4 == 2 {
                    // nearly perpendicular to the path's plane (steep sigma(u))
                    let tgt = b.min.as_dvec3() + (b.max - b.min).as_dvec3() * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                    let v = (DVec3::new(0.0, 0.0, -1.0) + rand_unit(&mut rng) * 10f64.powf(rng.gen_range(-6.0..-1.0))).normalize();
                    (tgt - v * size, v)
                } else {
                    let o = c + rand_unit(&mut rng) * size;
                    let tgt = b.min.as_dvec3() + (b.max - b.min).as_dvec3() * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                    (o, (tgt - o).normalize())
                };
                let d = d * rng.gen_range(0.3..3.0);
                let (of, df) = (o.as_vec3(), d.as_vec3());
                let (o, d) = (of.as_dvec3(), df.as_dvec3());
                let Some((ta, tb)) = b.ray_range(of, df.recip(), -1e30, 1e30) else { continue };
                let pad = 0.01 * size / d.length();
                let (t0, t1) = (ta as f64 - pad, tb as f64 + pad);
                let mut got: Vec<Span> = vec![];
                g.spans(&Ray::segment(of, df, t0 as f32, t1 as f32), 0, &mut got);
                for w in got.windows(2) {
                    assert!(w[0].t1 < w[1].t0, "{name}: not sorted/disjoint {got:?}");
                }
                let gv: Vec<f64> = got.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
                let r = reference(&g, o, d, t0, t1, 1500);
                hits += (!gv.is_empty() || !r.is_empty()) as usize;
                if gv.len() == r.len() {
                    same += 1;
                    for (x, y) in gv.iter().zip(&r) {
                        let e = (x - y).abs() * d.length() / size;
                        if e > 1e-5 {
                            println!("{name}: large end error {e:e} o={of:?} d={df:?} spans {got:?} reference {r:?}");
                        }
                        max_end = max_end.max(e);
                    }
                } else {
                    mism += 1;
                    println!("{name}: count mismatch o={of:?} d={df:?} spans {gv:?} reference {r:?}");
                }
                let sd = sym_diff(&gv, &r) * d.length() / size;
                max_sd = max_sd.max(sd);
                assert!(sd < 2e-3, "{name}: o={of:?} d={df:?} spans {gv:?} reference {r:?}");
            }
            println!("{name:20} rays {nrays} hits {hits} same count {same} mismatches {mism} max end err {max_end:e} max symdiff {max_sd:e} (relative to size)");
            assert!(max_end < 1e-5, "{name}");
        }
    }

    #[test]
    fn straight_circle_is_kernels_cylinder() {
        let seed = 0x9c71_0002u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut max_err = 0.0f64;
        let mut hits = 0;
        for _ in 0..20 {
            let a = (rand_unit(&mut rng) * rng.gen_range(0.0..2.0)).as_vec3();
            let b = a + (rand_unit(&mut rng) * rng.gen_range(0.2..3.0)).as_vec3();
            let r = rng.gen_range(0.05..1.0f32);
            let g = GenCylData::new(&gc(&straight(a, b), Profile::Circle(r), Frame::RotationMinimizing, 0.0), DEFAULT_TOLERANCE).unwrap();
            let size = g.local_bounds().diagonal_length() as f64;
            let canon = LeafShape::Cylinder(crate::Cylinder { a, b, radius: r }).canonical();
            let inv = canon.node_from_local.inverse();
            for _ in 0..200 {
                let c = ((a + b) * 0.5).as_dvec3() + rand_unit(&mut rng) * rng.gen_range(0.0..size * 0.4);
                let v = rand_unit(&mut rng) * rng.gen_range(0.3..3.0);
                let (o, d) = ((c - v * 3.0).as_vec3(), v.as_vec3());
                let mut got: Vec<Span> = vec![];
                g.spans(&Ray::segment(o, d, -1e9, 1e9), 0, &mut got);
                let lo = inv.transform_point3(o.as_dvec3());
                let ld = inv.transform_vector3(d.as_dvec3());
                match kernels::cylinder(lo, ld).map(kernels::narrow) {
                    Some((t0, s0, t1, s1)) if (t1 - t0) as f64 * v.length() > 1e-4 * size => {
                        hits += 1;
                        assert_eq!(got.len(), 1, "{got:?} vs {t0} {t1}");
                        let e = ((got[0].t0 - t0).abs().max((got[0].t1 - t1).abs())) as f64 * v.length() / size;
                        max_err = max_err.max(e);
                        // caps map to caps, side to side
                        let kind = |s: u32| match s {
                            kernels::sub::CAP0 => sub::CAP0,
                            kernels::sub::CAP1 => sub::CAP1,
                            _ => sub::SIDE,
                        };
                        assert_eq!(got[0].s0.sub & 3, kind(s0));
                        assert_eq!(got[0].s1.sub & 3, kind(s1));
                        let n = g.normal(got[0].s0.sub, o + d * got[0].t0);
                        assert!(n.dot(d) < 0.0, "entry normal {n:?}");
                    }
                    Some(_) => {}
                    None => assert!(got.is_empty(), "{got:?}"),
                }
            }
        }
        println!("straight circle vs kernels::cylinder: {hits} hits, max span end error {max_err:e} (relative to size)");
        assert!(max_err < 5e-6);
    }

    #[test]
    fn straight_rectangle_is_kernels_cuboid() {
        let seed = 0x9c71_0003u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        // Path along +z, default normal y: X = +y, Y = z x y = -x.
        let (ha, hb, l) = (0.3f32, 0.7f32, 2.0f32);
        let desc = gc(
            &straight(Vec3::ZERO, Vec3::new(0.0, 0.0, l)),
            Profile::Polygon(vec![[-ha, -hb], [ha, -hb], [ha, hb], [-ha, hb]]),
            Frame::RotationMinimizing,
            0.0,
        );
        let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
        let (mn, mx) = (Vec3::new(-hb, -ha, 0.0), Vec3::new(hb, ha, l));
        let size = (mx - mn).length() as f64;
        let mut max_err = 0.0f64;
        let mut hits = 0;
        for _ in 0..3000 {
            let c = DVec3::new(0.0, 0.0, 1.0) + rand_unit(&mut rng) * rng.gen_range(0.0..1.2);
            let v = rand_unit(&mut rng) * rng.gen_range(0.3..3.0);
            let (o, d) = ((c - v * 3.0).as_vec3(), v.as_vec3());
            let mut got: Vec<Span> = vec![];
            g.spans(&Ray::segment(o, d, -1e9, 1e9), 0, &mut got);
            match kernels::cuboid64(o.as_dvec3(), d.as_dvec3(), mn.as_dvec3(), mx.as_dvec3()).map(kernels::narrow) {
                Some((t0, _, t1, _)) if (t1 - t0) as f64 * v.length() > 1e-4 * size => {
                    hits += 1;
                    assert_eq!(got.len(), 1, "{got:?} vs {t0} {t1}");
                    let e = ((got[0].t0 - t0).abs().max((got[0].t1 - t1).abs())) as f64 * v.length() / size;
                    max_err = max_err.max(e);
                    let n = g.normal(got[0].s0.sub, o + d * got[0].t0);
                    assert!(n.dot(d) < 0.0, "entry normal {n:?}");
                    let axis_aligned = n.abs().max_element() > 0.9999;
                    assert!(axis_aligned, "box normal {n:?}");
                }
                Some(_) => {}
                None => assert!(got.is_empty(), "{got:?}"),
            }
        }
        println!("straight rectangle vs kernels::cuboid64: {hits} hits, max span end error {max_err:e} (relative to size)");
        assert!(max_err < 5e-6);
    }

    #[test]
    fn circle_side_matches_constant_radius_sweep() {
        let seed = 0x9c71_0004u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let r = 0.2f32;
        let desc = gc(&BENCH_PATH, Profile::Circle(r), Frame::RotationMinimizing, 0.0);
        let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
        let sw = crate::sweep::SweptSphereData::new(
            &crate::sweep::SweptSphere { bezier: BENCH_PATH.iter().map(|p| [p[0], p[1], p[2], r]).collect() },
            crate::sweep::DEFAULT_TOLERANCE,
        )
        .unwrap();
        let size = g.local_bounds().diagonal_length() as f64;
        let (mut n, mut max_err) = (0, 0.0f64);
        for _ in 0..3000 {
            let i = rng.gen_range(0..2);
            let u: f64 = rng.gen_range(0.15..0.85);
            let f = g.frame_at(i, u);
            let nrm = rotate_about(f.x, f.t, rng.gen_range(0.0..std::f64::consts::TAU));
            let v = (-nrm + rand_unit(&mut rng) * 0.5).normalize() * rng.gen_range(0.3..3.0);
            let o = (f.c + nrm * (r as f64) - v * 2.0).as_vec3();
            let d = v.as_vec3();
            let (mut a, mut b): (Vec<Span>, Vec<Span>) = (vec![], vec![]);
            g.spans(&Ray::segment(o, d, 0.0, 1e9), 0, &mut a);
            sw.spans(&Ray::segment(o, d, 0.0, 1e9), 0, &mut b);
            let (Some(a0), Some(b0)) = (a.first(), b.first()) else { continue };
            if a0.s0.sub & 3 != sub::SIDE {
                continue;
            }
            let ends = [BENCH_PATH[0], BENCH_PATH[6]].map(|q| Vec3::from(q).as_dvec3());
            let near_end = |t: f32| {
                let p = (o + d * t).as_dvec3();
                ends.iter().any(|e| (p - *e).length() < 2.0 * r as f64)
            };
            if near_end(a0.t0) || near_end(b0.t0) {
                continue;
            }
            n += 1;
            max_err = max_err.max((a0.t0 - b0.t0).abs() as f64 * v.length() / size);
        }
        println!("circle gcyl vs constant-radius sweep, side entries: {n} rays, max difference {max_err:e} (relative to size)");
        assert!(n > 1000);
        assert!(max_err < 5e-6);
    }

    #[test]
    fn contains_agrees_with_spans() {
        let seed = 0x9c71_0005u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut checked = 0;
        for (name, desc) in shapes() {
            let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
            let b = g.local_bounds();
            let size = b.diagonal_length();
            let c = b.center().as_dvec3();
            for _ in 0..400 {
                let o = c + rand_unit(&mut rng) * size as f64;
                let tgt = b.min.as_dvec3() + (b.max - b.min).as_dvec3() * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                let (o, d) = (o.as_vec3(), (tgt - o).as_vec3());
                let mut got: Vec<Span> = vec![];
                g.spans(&Ray::segment(o, d, 0.0, 10.0), 0, &mut got);
                for (k, s) in got.iter().enumerate() {
                    if (s.t1 - s.t0) * d.length() > 1e-4 * size {
                        assert!(g.contains(o + d * (0.5 * (s.t0 + s.t1))), "{name}: span midpoint outside {s:?}");
                        checked += 1;
                    }
                    if let Some(nx) = got.get(k + 1) {
                        if (nx.t0 - s.t1) * d.length() > 1e-4 * size {
                            assert!(!g.contains(o + d * (0.5 * (s.t1 + nx.t0))), "{name}: gap midpoint inside");
                        }
                    }
                    if s.s0.is_real() {
                        let n = g.normal(s.s0.sub, o + d * s.t0);
                        assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-4);
                        if !name.contains("folding") {
                            assert!(n.dot(d) <= 1e-3 * d.length(), "{name}: entry normal {n:?} d {d:?} sub {}", s.s0.sub);
                        }
                    }
                }
            }
        }
        println!("checked {checked} span midpoints");
    }

    #[test]
    fn frames_have_no_nan_and_rmf_is_orthonormal_and_untwisted() {
        let sq = Profile::Polygon(vec![[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]]);
        let cases: Vec<(&str, Vec<[f32; 3]>)> = vec![
            ("straight", straight(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0))),
            ("straight along y", straight(Vec3::ZERO, Vec3::Y)),
            ("inflection", vec![[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, -1.0, 0.0], [3.0, 0.0, 0.0]]),
            (
                "starts straight",
                vec![[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.5], [1.0, 2.0, 1.0]],
            ),
            ("coincident end controls", vec![[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0]]),
            ("helix", vec![[1.0, 0.0, 0.0], [1.0, 0.6, 0.3], [0.6, 1.0, 0.6], [0.0, 1.0, 0.9]]),
        ];
        let mut worst_ortho = 0.0f64;
        let mut worst_twist = 0.0f64;
        for (name, path) in &cases {
            for frame in [Frame::RotationMinimizing, Frame::Frenet] {
                let g = GenCylData::new(&gc(path, sq.clone(), frame, 0.0), DEFAULT_TOLERANCE).unwrap();
                for i in 0..g.segment_count() {
                    for k in 0..=400 {
                        let u = k as f64 / 400.0;
                        let f = g.frame_at(i, u);
                        assert!(f.c.is_finite() && f.t.is_finite() && f.x.is_finite() && f.y.is_finite(), "{name} {frame:?} u={u}");
                        let e = (f.x.length() - 1.0)
                            .abs()
                            .max((f.y.length() - 1.0).abs())
                            .max((f.t.length() - 1.0).abs())
                            .max(f.x.dot(f.t).abs())
                            .max(f.x.dot(f.y).abs())
                            .max(f.y.dot(f.t).abs())
                            .max((f.x.cross(f.y) - f.t).length());
                        worst_ortho = worst_ortho.max(e);
                        if frame == Frame::RotationMinimizing && k > 0 && k < 400 {
                            // no rotation about T: X' . Y = 0
                            let h = 1e-5;
                            let (a, b) = (g.frame_at(i, u - h), g.frame_at(i, u + h));
                            let w = ((b.x - a.x) / (2.0 * h)).dot(f.y);
                            let tp = ((b.t - a.t) / (2.0 * h)).length().max(1e-3);
                            worst_twist = worst_twist.max(w.abs() / tp);
                        }
                    }
                }
                // spans of a few rays are finite
                for k in 0..50 {
                    let o = Vec3::new(-1.0 + 0.1 * k as f32, 3.0, 0.3);
                    let mut got: Vec<Span> = vec![];
                    g.spans(&Ray::segment(o, Vec3::new(0.3, -1.0, 0.1), 0.0, 100.0), 0, &mut got);
                    assert!(got.iter().all(|s| s.t0.is_finite() && s.t1.is_finite()));
                }
            }
        }
        println!("frames: worst orthonormality error {worst_ortho:e}, worst RMF rotation rate |X'.Y|/|T'| {worst_twist:e}");
        assert!(worst_ortho < 1e-12);
        assert!(worst_twist < 1e-3);
    }

    #[test]
    fn exact_perpendicular_ray_on_planar_path() {
        // A ray exactly perpendicular to the plane of a planar path (A = 0):
        // it lies in the cross-section planes' pencil only where it crosses the path.
        let g = GenCylData::new(&gc(&ARC, Profile::Circle(0.2), Frame::RotationMinimizing, 0.0), DEFAULT_TOLERANCE).unwrap();
        let p = g.frame_at(0, 0.5).c.as_vec3();
        let mut got: Vec<Span> = vec![];
        g.spans(&Ray::segment(p + Vec3::Z * 2.0, -Vec3::Z, 0.0, 10.0), 0, &mut got);
        println!("{got:?}");
        assert_eq!(got.len(), 1);
        assert!((got[0].t0 - 1.8).abs() < 1e-5 && (got[0].t1 - 2.2).abs() < 1e-5);
    }

    #[test]
    fn validate_rejects_bad_input() {
        let ok = gc(&ARC, Profile::Circle(0.2), Frame::RotationMinimizing, 0.0);
        assert!(ok.validate().is_ok());
        let mut e = ok.clone();
        e.path.pop();
        assert!(e.validate().unwrap_err().message.contains("length 3 is not 3n+1"));
        let mut e = ok.clone();
        e.profile = Profile::Circle(-1.0);
        assert_eq!(e.validate().unwrap_err().field, "profile");
        let mut e = ok.clone();
        e.profile = Profile::Polygon(vec![[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 1.0]]);
        assert!(e.validate().unwrap_err().message.contains("self-intersecting"));
        let mut e = ok.clone();
        e.normal = Some(Vec3::ZERO);
        assert_eq!(e.validate().unwrap_err().field, "normal");
        let mut e = ok.clone();
        e.path = vec![[1.0, 1.0, 1.0]; 4];
        assert!(e.validate().unwrap_err().message.contains("zero length"));
        let mut e = ok.clone();
        e.twist_deg = f32::NAN;
        assert_eq!(e.validate().unwrap_err().field, "twist_deg");
    }

    /// Camera of /work/shared/scenes/sweep.json looking at gcyls along that
    /// scene's path: ns per ray (all rays, most miss the bounds).
    /// `cargo test -p rothray-primitives --release gcyl_bench -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn gcyl_bench() {
        let path: Vec<[f32; 3]> = crate::sweep::tests::bench_shape().bezier.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let (w, h) = (960usize, 540usize);
        let half_h = (50f32.to_radians() * 0.5).tan();
        let eye = Vec3::new(0.0, 0.0, 6.0);
        let rays: Vec<Vec3> = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
                Vec3::new((2.0 * x / w as f32 - 1.0) * half_h * w as f32 / h as f32, (1.0 - 2.0 * y / h as f32) * half_h, -1.0)
            })
            .collect();
        let profiles = [
            ("circle 0.3", Profile::Circle(0.3)),
            ("square 0.25", Profile::Polygon(vec![[-0.25, -0.25], [0.25, -0.25], [0.25, 0.25], [-0.25, 0.25]])),
        ];
        for (name, prof) in profiles {
            for tol in [1e-3f32, 1e-6] {
                let g = GenCylData::new(&gc(&path, prof.clone(), Frame::RotationMinimizing, 45.0), tol).unwrap();
                let t = std::time::Instant::now();
                let mut hits = 0;
                for d in &rays {
                    let mut v: Vec<Span> = vec![];
                    g.spans(&Ray::segment(eye, *d, 0.0, f32::INFINITY), 0, &mut v);
                    hits += (!v.is_empty()) as usize;
                }
                let ns = t.elapsed().as_secs_f64() * 1e9 / rays.len() as f64;
                println!("{name} tolerance {tol:e}: {ns:.0} ns/ray over {} rays ({hits} hit)", rays.len());
            }
        }
    }
}

#[cfg(test)]
#[path = "gcyl_rmf_tests.rs"]
mod rmf_tests;
