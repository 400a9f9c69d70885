//! The leaves traced through an f64 world-to-local map: ellipsoids (a sphere
//! under a map that is not a similarity), cylinders, cones, tori and boxes;
//! and half-spaces, traced against their world plane in f64.
//!
//! Why f64: through the f32 map (each entry rounded, 6e-8 relative) the local
//! line is off by ~6e-8 of its distance from the leaf, which moves the ends
//! of a tangent chord of length `L` by ~6e-8 r^2 / (L/2) (7e-5 of a 4-radii
//! view for a chord of 1e-4 of it), decides by rounding whether a chord of
//! up to ~3e-4 of the view exists, and moves where a ray along a cap's plane
//! crosses it anywhere along the cap (tests/stress_tangent.rs: 0.16-0.26 of
//! the view). In f64 the answer is that of the f32 inputs, rounded once to
//! f32 t, and the f64 ranges need no rescaling of the direction. The same
//! map moved where a ray at a small angle `a` to a box's face or a plane
//! crosses it by ~6e-8 of its distance / sin(a): up to the whole view for
//! rays along a face (tests/stress_grazing.rs).
//!
//! Spans, point classification and normals all read the same f64 local
//! point, so that they agree.

use glam::{DMat3, DVec3, Vec3};

use crate::{
    kernels::{self, sub},
    table::{push_clipped, world_normal, LeafKind, LeafTable},
    Ray, Span, SpanSink, Surf,
};

/// `m v`, summed in a fixed order, ((x_axis v.x + y_axis v.y) + z_axis v.z),
/// which the packet kernels repeat lane by lane (`kernels8`): their answers
/// must be the single-ray path's bit for bit.
#[inline(always)]
pub(crate) fn map64(m: &DMat3, v: DVec3) -> DVec3 {
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    DVec3::new((x.x * v.x + y.x * v.y) + z.x * v.z, (x.y * v.x + y.y * v.y) + z.y * v.z, (x.z * v.x + y.z * v.y) + z.z * v.z)
}

impl LeafTable {
    /// Does leaf kind `k` keep an f64 map in [`LeafTable::maps64`]?
    #[inline(always)]
    pub fn has_map64(k: LeafKind) -> bool {
        matches!(k, LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone | LeafKind::Torus | LeafKind::Cuboid | LeafKind::HalfSpace)
    }

    /// Half-space `iu`'s world plane in f64, `dot(n, p - anchor) <= w`,
    /// kept in its [`LeafTable::maps64`] entry (the normal as the first
    /// column, the offset as the point's x): a plane needs no map.
    #[inline(always)]
    pub(crate) fn plane64(&self, iu: usize) -> (DVec3, f64) {
        let (m, b) = &self.maps64[self.ext[iu] as usize];
        (m.x_axis, b.x)
    }

    /// `p` relative to leaf `iu`'s anchor, in f64 (exact).
    #[inline(always)]
    pub(crate) fn rel64(&self, iu: usize, p: Vec3) -> DVec3 {
        p.as_dvec3() - Vec3::from(self.anchor[iu]).as_dvec3()
    }

    /// The spans of a box (its local line through the f64 map, its own f32
    /// bounds) or a half-space (its f64 world plane) along the world ray.
    #[inline(always)]
    pub(crate) fn flat_spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, (tmin, tmax): (f32, f32), out: &mut S) {
        let iu = i as usize;
        let r = if self.kind[iu] == LeafKind::Cuboid {
            let (lo, ld) = self.line64(iu, ray);
            kernels::cuboid64(lo, ld, self.p0[iu].truncate().as_dvec3(), self.p1[iu].truncate().as_dvec3())
        } else {
            let (n, w) = self.plane64(iu);
            kernels::half_space64(self.rel64(iu, ray.origin), ray.dir.as_dvec3(), n, w)
        };
        if let Some(r) = r {
            let (t0, s0, t1, s1) = kernels::narrow(r);
            push_clipped(out, Span { t0, s0: Surf::new(i, s0), t1, s1: Surf::new(i, s1) }, tmin, tmax);
        }
    }

    /// Is world point `p` inside box or half-space `iu` (boundary included)?
    #[inline]
    pub(crate) fn flat_contains(&self, iu: usize, p: Vec3) -> bool {
        if self.kind[iu] == LeafKind::Cuboid {
            let l = self.local64(iu, p);
            return l.cmpge(self.p0[iu].truncate().as_dvec3()).all() && l.cmple(self.p1[iu].truncate().as_dvec3()).all();
        }
        let (n, w) = self.plane64(iu);
        kernels::dot64(n, self.rel64(iu, p)) <= w
    }

    /// Cone `iu`'s radii at z = 0 and z = 1 (relative to the larger), in f64.
    #[inline(always)]
    pub(crate) fn cone_radii(&self, iu: usize) -> (f64, f64) {
        let p0 = self.p0[iu];
        (p0.x as f64 + p0.z as f64, p0.y as f64 + p0.w as f64)
    }

    /// The local point of world point `p` in leaf `iu`'s f64 frame: relative
    /// to the anchor first (exact in f64), then the linear map, then the
    /// anchor's local point.
    #[inline(always)]
    pub(crate) fn local64(&self, iu: usize, p: Vec3) -> DVec3 {
        let (m, b) = &self.maps64[self.ext[iu] as usize];
        map64(m, p.as_dvec3() - Vec3::from(self.anchor[iu]).as_dvec3()) + *b
    }

    /// The world ray as a local line `(origin, direction)` in leaf `iu`'s f64 frame.
    #[inline(always)]
    pub(crate) fn line64(&self, iu: usize, ray: &Ray) -> (DVec3, DVec3) {
        self.line64_of(iu, ray.origin, ray.dir)
    }

    /// [`LeafTable::line64`] of the world line `o + t d`.
    #[inline(always)]
    pub(crate) fn line64_of(&self, iu: usize, o: Vec3, d: Vec3) -> (DVec3, DVec3) {
        (self.local64(iu, o), map64(&self.maps64[self.ext[iu] as usize].0, d.as_dvec3()))
    }

    /// The spans of an ellipsoid, cylinder or cone along the world ray.
    #[inline(always)]
    pub(crate) fn quadric_spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, (tmin, tmax): (f32, f32), out: &mut S) {
        let iu = i as usize;
        let (lo, ld) = self.line64(iu, ray);
        let r = match self.kind[iu] {
            LeafKind::Ellipsoid => kernels::ball(lo, ld, 1.0).map(|(t0, t1)| (t0, sub::SIDE, t1, sub::SIDE)),
            LeafKind::Cylinder => kernels::cylinder(lo, ld),
            _ => {
                let (ra, rb) = self.cone_radii(iu);
                kernels::cone(lo, ld, ra, rb)
            }
        };
        if let Some(r) = r {
            let (t0, s0, t1, s1) = kernels::narrow(r);
            push_clipped(out, Span { t0, s0: Surf::new(i, s0), t1, s1: Surf::new(i, s1) }, tmin, tmax);
        }
    }

    /// Is world point `p` inside ellipsoid, cylinder or cone `iu` (boundary included)?
    #[inline]
    pub(crate) fn quadric_contains(&self, iu: usize, p: Vec3) -> bool {
        let l = self.local64(iu, p);
        match self.kind[iu] {
            LeafKind::Ellipsoid => l.length_squared() <= 1.0,
            LeafKind::Cylinder => l.x * l.x + l.y * l.y <= 1.0 && (0.0..=1.0).contains(&l.z),
            _ => {
                let (ra, rb) = self.cone_radii(iu);
                let r = ra + (rb - ra) * l.z;
                l.x * l.x + l.y * l.y <= r * r && (0.0..=1.0).contains(&l.z)
            }
        }
    }

    /// The outward unit world normal of ellipsoid, cylinder or cone `iu` at
    /// `t` on the world ray, on sub-surface `sub`. The local normal is made
    /// at the f64 local point; once made it is a plain direction, which the
    /// f32 map carries to 6e-8.
    ///
    /// The local normal is not normalised here: [`world_normal`] normalises
    /// its image anyway, and it is never tiny (an ellipsoid's local point
    /// lies on the unit sphere; a side's is a unit vector plus a slope along
    /// z). A second normalisation in f64 was a square root and a division in
    /// the chain of every hit's shading (forest: 8.9% of its lit cycles in
    /// `LeafTable::normal`, perf).
    pub(crate) fn quadric_normal(&self, iu: usize, sub: u32, ray: &Ray, t: f32) -> Vec3 {
        // The local point (an f64 map) only where the normal depends on it:
        // not on a cap.
        let point = || {
            let (lo, ld) = self.line64(iu, ray);
            lo + ld * t as f64
        };
        let nl = match (self.kind[iu], sub) {
            (LeafKind::Ellipsoid, _) => point(),
            (_, sub::CAP0) => DVec3::NEG_Z,
            (_, sub::CAP1) => DVec3::Z,
            (LeafKind::Cylinder, _) => {
                // The gradient of |xy| - 1 times |xy|: no square root or
                // division for a direction that `world_normal` normalises.
                let l = point();
                if l.x == 0.0 && l.y == 0.0 {
                    DVec3::X
                } else {
                    DVec3::new(l.x, l.y, 0.0)
                }
            }
            (_, _) => {
                let l = point();
                let (ra, rb) = self.cone_radii(iu);
                let r = ra + (rb - ra) * l.z;
                let side = (rb - ra) * if r >= 0.0 { 1.0 } else { -1.0 };
                // The gradient of |xy| - r(z) times |xy| (no division:
                // `world_normal` normalises; on the axis, that gradient at
                // |xy| = 1).
                let rho = (l.x * l.x + l.y * l.y).sqrt();
                if rho == 0.0 {
                    DVec3::new(1.0, 0.0, -side)
                } else {
                    DVec3::new(l.x, l.y, -side * rho)
                }
            }
        };
        world_normal(&self.to_local[iu], nl.as_vec3())
    }
}
