//! Leaf descriptions, their canonical forms, and the SoA leaf table the tracer reads.

use std::sync::Arc;

use glam::{Affine3A, DAffine3, DMat3, DVec3, Vec3, Vec3A, Vec4};

use crate::{
    aabb::Aabb,
    gcyl::GenCylData,
    kernels,
    kernels8::Rays8Soa,
    mesh::{Line64, MeshData, NearestRays8, ParallelRays8},
    ray::{scale_t, ScaledSink},
    sweep::SweptSphereData,
    Ray, Span, SpanSink, Surf,
};

/// Ball.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3,
    /// Radius (> 0).
    pub radius: f32,
}
/// Axis-aligned box (in the node's own frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner (`min <= max` per axis).
    pub max: Vec3,
}
/// Capped cylinder from `a` to `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    /// Centre of the first cap.
    pub a: Vec3,
    /// Centre of the second cap.
    pub b: Vec3,
    /// Radius (> 0).
    pub radius: f32,
}
/// Capped frustum from `a` (radius `radius_a`) to `b` (radius `radius_b`); one radius may be 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Centre of the first cap.
    pub a: Vec3,
    /// Centre of the second cap.
    pub b: Vec3,
    /// Radius at `a` (>= 0).
    pub radius_a: f32,
    /// Radius at `b` (>= 0).
    pub radius_b: f32,
}
/// Ring of points within `minor` of the circle of radius `major` around `axis` through `center`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Torus {
    /// Centre.
    pub center: Vec3,
    /// Axis (any non-zero length).
    pub axis: Vec3,
    /// Radius of the centre circle (> 0).
    pub major: f32,
    /// Radius of the tube (> 0).
    pub minor: f32,
}
/// Half-space of points `p` with `dot(normal, p) <= offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfSpace {
    /// Outward normal (any non-zero length).
    pub normal: Vec3,
    /// Offset along the normal.
    pub offset: f32,
}

/// Any analytic leaf (the cold-path description).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LeafShape {
    /// See [`Sphere`].
    Sphere(Sphere),
    /// See [`Cuboid`].
    Cuboid(Cuboid),
    /// See [`Cylinder`].
    Cylinder(Cylinder),
    /// See [`Cone`].
    Cone(Cone),
    /// See [`Torus`].
    Torus(Torus),
    /// See [`HalfSpace`].
    HalfSpace(HalfSpace),
}

/// The fieldless kind tag the hot path matches on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum LeafKind {
    /// Ball, traced in world space in f64 ([`kernels::ball`]): a sphere
    /// whose transforms are similarities (rotation, uniform scale,
    /// translation). Centre `anchor + p1.xyz`, radius `p0.x + p0.y` (f32 and
    /// its f64 residual).
    Sphere,
    /// Unit sphere under a map that is not a similarity (an ellipsoid in the
    /// world), traced in local space through its f64 map ([`crate::table64`]).
    Ellipsoid,
    /// Box `[p0, p1]` in its own coordinates (the description's f32
    /// numbers), traced through its f64 map ([`crate::table64`]).
    Cuboid,
    /// Unit capped cylinder (f64 map, as the ellipsoid).
    Cylinder,
    /// Frustum, radii (relative to the larger, at z = 0 and z = 1) in
    /// `p0.x + p0.z`, `p0.y + p0.w` (f32 numbers and their f64 residuals;
    /// f64 map, as the ellipsoid).
    Cone,
    /// Torus, minor radius (major = 1) in `p0.x` (f64 map, as the ellipsoid).
    Torus,
    /// Half-space, traced against its world plane in f64 (normal, and
    /// offset relative to the anchor, in its `maps64` entry; see
    /// [`crate::table64`]); its unit local normal in `p0.xyz`, its world normal
    /// (what shading reads) in `p1.xyz`.
    HalfSpace,
    /// Van Wijk swept sphere (`ext` indexes [`LeafTable::sweeps`]).
    SweptSphere,
    /// Generalized cylinder (`ext` indexes [`LeafTable::gcyls`]).
    GenCylinder,
    /// Closed triangle mesh (`ext` indexes [`LeafTable::meshes`]).
    Mesh,
}

impl LeafKind {
    /// A rough cost of one ray query of a leaf of this kind, relative to a
    /// half-space's (instructions per query, order of magnitude, from the
    /// criterion kernels in benches/kernels.rs): what the program builder
    /// orders an intersection's operands by, cheap first.
    pub fn query_cost(self) -> u32 {
        match self {
            LeafKind::HalfSpace => 1,
            LeafKind::Sphere | LeafKind::Ellipsoid | LeafKind::Cuboid => 2,
            LeafKind::Cylinder | LeafKind::Cone => 3,
            LeafKind::Torus => 20,
            LeafKind::Mesh => 30,
            LeafKind::SweptSphere => 40,
            LeafKind::GenCylinder => 60,
        }
    }
}

/// The data of a leaf that is more than a few numbers (shared, immutable).
#[derive(Clone, Debug)]
pub enum LeafData {
    /// A swept sphere.
    SweptSphere(Arc<SweptSphereData>),
    /// A generalized cylinder.
    GenCylinder(Arc<GenCylData>),
    /// A mesh (instancing: many leaves may share one).
    Mesh(Arc<MeshData>),
}

/// A problem with a leaf's numbers: the field and what is wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeError {
    /// Name of the offending field (as in the scene format).
    pub field: &'static str,
    /// What is wrong.
    pub message: String,
}

fn err(field: &'static str, message: impl Into<String>) -> ShapeError {
    ShapeError { field, message: message.into() }
}
fn finite_v(field: &'static str, v: Vec3) -> Result<(), ShapeError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(err(field, "must be finite"))
    }
}
fn positive(field: &'static str, x: f32) -> Result<(), ShapeError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(err(field, format!("must be a positive finite number, got {x}")))
    }
}

/// Two unit vectors completing `w` (unit) to a right-handed orthonormal frame (Duff et al. 2017).
pub fn orthonormal_basis(w: DVec3) -> (DVec3, DVec3) {
    let s = 1.0f64.copysign(w.z);
    let a = -1.0 / (s + w.z);
    let b = w.x * w.y * a;
    (DVec3::new(1.0 + s * w.x * w.x * a, s * b, -s * w.x), DVec3::new(b, s + w.y * w.y * a, -w.y))
}

/// A leaf reduced to its canonical form.
#[derive(Clone, Copy, Debug)]
pub struct Canonical {
    /// Kind tag.
    pub kind: LeafKind,
    /// Maps canonical local space to the shape's own (node) space.
    pub node_from_local: DAffine3,
    /// Kind-specific parameters.
    pub p0: Vec4,
    /// Kind-specific parameters.
    pub p1: Vec4,
}

impl LeafShape {
    /// Checks the numbers (the error names the field).
    pub fn validate(&self) -> Result<(), ShapeError> {
        match *self {
            LeafShape::Sphere(s) => {
                finite_v("center", s.center)?;
                positive("radius", s.radius)
            }
            LeafShape::Cuboid(b) => {
                finite_v("min", b.min)?;
                finite_v("max", b.max)?;
                if b.min.cmpgt(b.max).any() {
                    return Err(err("min", format!("min {:?} is above max {:?}", b.min.to_array(), b.max.to_array())));
                }
                Ok(())
            }
            LeafShape::Cylinder(c) => {
                finite_v("a", c.a)?;
                finite_v("b", c.b)?;
                positive("radius", c.radius)?;
                if c.a == c.b {
                    return Err(err("b", "a and b coincide (zero-length axis)"));
                }
                Ok(())
            }
            LeafShape::Cone(c) => {
                finite_v("a", c.a)?;
                finite_v("b", c.b)?;
                if !(c.radius_a.is_finite() && c.radius_a >= 0.0) {
                    return Err(err("radius_a", format!("must be a finite number >= 0, got {}", c.radius_a)));
                }
                if !(c.radius_b.is_finite() && c.radius_b >= 0.0) {
                    return Err(err("radius_b", format!("must be a finite number >= 0, got {}", c.radius_b)));
                }
                if c.radius_a == 0.0 && c.radius_b == 0.0 {
                    return Err(err("radius_a", "radius_a and radius_b are both 0"));
                }
                if c.a == c.b {
                    return Err(err("b", "a and b coincide (zero-length axis)"));
                }
                Ok(())
            }
            LeafShape::Torus(t) => {
                finite_v("center", t.center)?;
                finite_v("axis", t.axis)?;
                if t.axis.length_squared() == 0.0 {
                    return Err(err("axis", "is the zero vector"));
                }
                positive("major", t.major)?;
                positive("minor", t.minor)
            }
            LeafShape::HalfSpace(h) => {
                finite_v("normal", h.normal)?;
                if h.normal.length_squared() == 0.0 {
                    return Err(err("normal", "is the zero vector"));
                }
                if !h.offset.is_finite() {
                    return Err(err("offset", "must be finite"));
                }
                Ok(())
            }
        }
    }

    /// Canonical form (call [`LeafShape::validate`] first).
    pub fn canonical(&self) -> Canonical {
        let z = Vec4::ZERO;
        match *self {
            LeafShape::Sphere(s) => Canonical {
                kind: LeafKind::Sphere,
                node_from_local: DAffine3::from_scale_rotation_translation(
                    DVec3::splat(s.radius as f64),
                    Default::default(),
                    s.center.as_dvec3(),
                ),
                p0: z,
                p1: z,
            },
            LeafShape::Cuboid(b) => {
                Canonical { kind: LeafKind::Cuboid, node_from_local: DAffine3::IDENTITY, p0: b.min.extend(0.0), p1: b.max.extend(0.0) }
            }
            LeafShape::Cylinder(c) => {
                Canonical { kind: LeafKind::Cylinder, node_from_local: axis_frame(c.a, c.b, c.radius as f64), p0: z, p1: z }
            }
            LeafShape::Cone(c) => {
                let rmax = c.radius_a.max(c.radius_b);
                // The radii relative to the larger, in f64 as f32 numbers and
                // residuals (see `LeafKind::Cone`): rounded to f32, the
                // smaller one moved a frustum's side by 6e-8 of it, which
                // the tangent chords of a frustum of size 1e3 showed (1.5e-4
                // of the view, wrong counts).
                let (ra, rb) = (c.radius_a as f64 / rmax as f64, c.radius_b as f64 / rmax as f64);
                let residual = |x: f64| (x - x as f32 as f64) as f32;
                Canonical {
                    kind: LeafKind::Cone,
                    node_from_local: axis_frame(c.a, c.b, rmax as f64),
                    p0: Vec4::new(ra as f32, rb as f32, residual(ra), residual(rb)),
                    p1: z,
                }
            }
            LeafShape::Torus(t) => {
                let w = t.axis.as_dvec3().normalize();
                let (u, v) = orthonormal_basis(w);
                let r = t.major as f64;
                Canonical {
                    kind: LeafKind::Torus,
                    node_from_local: DAffine3::from_mat3_translation(DMat3::from_cols(u * r, v * r, w * r), t.center.as_dvec3()),
                    p0: Vec4::new(t.minor / t.major, 0.0, 0.0, 0.0),
                    p1: z,
                }
            }
            LeafShape::HalfSpace(h) => {
                let l = h.normal.length();
                Canonical { kind: LeafKind::HalfSpace, node_from_local: DAffine3::IDENTITY, p0: (h.normal / l).extend(h.offset / l), p1: z }
            }
        }
    }
}

/// The scale of `m` when it is a similarity (orthogonal columns of one
/// length, to 1e-10: 1e-3 of f32's resolution), else `None`.
fn similarity_scale(m: &DMat3) -> Option<f64> {
    let (x, y, z) = (m.x_axis, m.y_axis, m.z_axis);
    let l = (x.length() + y.length() + z.length()) / 3.0;
    let tol = 1e-10 * l;
    let same = [x, y, z].iter().all(|c| (c.length() - l).abs() <= tol);
    let square = [x.dot(y), y.dot(z), z.dot(x)].iter().all(|d| d.abs() <= tol * l);
    (same && square && l.is_finite()).then_some(l)
}

fn axis_frame(a: Vec3, b: Vec3, r: f64) -> DAffine3 {
    let a = a.as_dvec3();
    let ax = b.as_dvec3() - a;
    let (u, v) = orthonormal_basis(ax.normalize());
    DAffine3::from_mat3_translation(DMat3::from_cols(u * r, v * r, ax), a)
}

/// Half extents of the image of the unit disk in the local xy plane under `m`.
fn disk_extent(m: &DMat3) -> DVec3 {
    let u = m.x_axis;
    let v = m.y_axis;
    DVec3::new((u.x * u.x + v.x * v.x).sqrt(), (u.y * u.y + v.y * v.y).sqrt(), (u.z * u.z + v.z * v.z).sqrt())
}

/// World bounds of a canonical leaf under `world_from_local`.
pub fn canonical_bounds(c: &Canonical, m: &DAffine3) -> Aabb {
    let a = m.matrix3;
    let t = m.translation;
    // Grown by a margin and rounded outward (Aabb::enclosing).
    let to = Aabb::enclosing;
    match c.kind {
        LeafKind::Sphere | LeafKind::Ellipsoid => {
            let e = DVec3::new(a.row(0).length(), a.row(1).length(), a.row(2).length());
            to(t - e, t + e)
        }
        LeafKind::Cylinder | LeafKind::Cone => {
            let e = disk_extent(&a);
            let (ra, rb) = if c.kind == LeafKind::Cone { (c.p0.x as f64, c.p0.y as f64) } else { (1.0, 1.0) };
            let t1 = t + a.z_axis;
            to((t - e * ra).min(t1 - e * rb), (t + e * ra).max(t1 + e * rb))
        }
        LeafKind::Torus => {
            let rho = c.p0.x as f64;
            let e = disk_extent(&a) + DVec3::new(a.row(0).length(), a.row(1).length(), a.row(2).length()) * rho;
            to(t - e, t + e)
        }
        LeafKind::Cuboid => Aabb::new(c.p0.truncate(), c.p1.truncate()).transformed_f64(m),
        LeafKind::HalfSpace => {
            // Axis-aligned half-spaces are bounded on one side; others are not.
            let n = a.inverse().transpose() * c.p0.truncate().as_dvec3();
            let mut b = Aabb::INFINITE;
            let nn = n.normalize();
            for i in 0..3 {
                if (nn[i].abs() - 1.0).abs() < 1e-12 {
                    // plane through the image of offset * n_local
                    let p = m.transform_point3(c.p0.truncate().as_dvec3() * c.p0.w as f64);
                    // Rounded outward with a margin, as Aabb::enclosing.
                    let margin = crate::aabb::span_margin(0.0, p[i].abs());
                    if nn[i] > 0.0 {
                        b.max[i] = ((p[i] + margin) as f32).next_up()
                    } else {
                        b.min[i] = ((p[i] - margin) as f32).next_down()
                    }
                }
            }
            b
        }
        // Leaves with data get their bounds in `push_data`.
        LeafKind::SweptSphere | LeafKind::GenCylinder | LeafKind::Mesh => Aabb::INFINITE,
    }
}

/// Why a leaf could not be added to the table.
#[derive(Clone, Debug, PartialEq)]
pub enum LeafError {
    /// A field is out of range.
    Shape(ShapeError),
    /// The accumulated transform cannot be inverted (or is not finite).
    SingularTransform,
    /// The leaf's size or place is outside what the table supports
    /// ([`MIN_SIZE`], [`MAX_COORD`]); the message says which and by how much.
    OutOfRange(String),
}

/// The largest coordinate of a leaf's bounds (and of a half-space's point)
/// that the table accepts, in magnitude. Beyond it the f32 sums and squares
/// of bounds, tolerances and BVH costs come within a few binades of
/// overflow (a sphere of radius 3e38 at 3e38 had infinite bounds); 1e30
/// leaves the supported 1e20 of the format ten binades of margin.
pub const MAX_COORD: f64 = 1e30;

/// The range of a leaf's size: the lengths of its local-to-world map's axes
/// (a sphere's radius, a cylinder's radius and length, times the scales of
/// the transforms above it) must lie in [`MIN_SIZE`, `MAX_COORD`]. A sphere
/// of radius 1e30 under `scale` 1e30 had a world-to-local map of 1e-60,
/// which is 0 in f32: it vanished without an error.
pub const MIN_SIZE: f64 = 1e-30;

/// Slack of the range checks: the bounds are written in f32 (1e30 read as
/// f32 is 1.0000000150e30) and grown by `aabb::span_margin` (at most 4e-5
/// of their reach).
const RANGE_SLACK: f64 = 1.0 + 1e-4;

/// The supported range of a torus's minor-to-major radius ratio, as far as
/// it is measured (tests/stress.rs `torus_ratios`: with rays mapped to the
/// torus's frame in f64, span ends within 4.9e-6 of a view of 4 tube radii
/// at 1e-4, 1.6e-7 at 1e-3; through the former f32 map they were 2.6e-3 at
/// 1e-4, with wrong counts at 1e-5). Fatter tori than 1e20 are measured no
/// further (and are spheres to f64 precision).
pub const TORUS_RATIO: (f64, f64) = (1e-4, 1e20);

/// Checks the sizes of a leaf's own parameters that the map's axes do not
/// carry: a box's half extents along its (mapped) local axes (0, a flat and
/// empty box, is accepted), a torus's minor-to-major ratio and its minor
/// radius after transforms.
fn check_own_sizes(shape: &LeafShape, m: &DMat3) -> Result<(), LeafError> {
    let axes = [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()];
    let size_range = MIN_SIZE / RANGE_SLACK..=MAX_COORD * RANGE_SLACK;
    match *shape {
        LeafShape::Cuboid(b) => {
            for k in 0..3 {
                let h = 0.5 * (b.max[k] as f64 - b.min[k] as f64) * axes[k];
                if h != 0.0 && !size_range.contains(&h) {
                    return Err(LeafError::OutOfRange(format!(
                        "its half extent along its local axis {k} is {h:.3e} after transforms, outside the supported {MIN_SIZE:e} to {MAX_COORD:e} (0, a flat box, is accepted)"
                    )));
                }
            }
        }
        LeafShape::Torus(t) => {
            let ratio = t.minor as f64 / t.major as f64;
            let (lo, hi) = TORUS_RATIO;
            // (The slack of the f32 numbers: 1e-4 in f32 is 0.99999997e-4.)
            if !(lo / RANGE_SLACK..=hi * RANGE_SLACK).contains(&ratio) {
                return Err(LeafError::OutOfRange(format!(
                    "its minor-to-major radius ratio is {ratio:.3e}, outside the supported {lo:e} to {hi:e}"
                )));
            }
            // (`axes` are the canonical map's: the major radius after transforms.)
            let minor = axes.iter().fold(f64::INFINITY, |a, &l| a.min(l)) * ratio;
            if !size_range.contains(&minor) {
                return Err(LeafError::OutOfRange(format!(
                    "its minor radius is {minor:.3e} after transforms, outside the supported {MIN_SIZE:e} to {MAX_COORD:e}"
                )));
            }
        }
        _ => {}
    }
    Ok(())
}

/// Checks the supported range of a leaf placed by `m` (local to world), with
/// world bounds `bounds` (`None` for a half-space, whose bounds may be
/// infinite; every other kind's must be finite) and anchor `anchor`.
fn check_range(m: &DMat3, bounds: Option<&Aabb>, anchor: Vec3) -> Result<(), LeafError> {
    for (k, c) in [m.x_axis, m.y_axis, m.z_axis].iter().enumerate() {
        let l = c.length();
        // (RANGE_SLACK: f32 bounds with a margin.)
        if !(MIN_SIZE / RANGE_SLACK..=MAX_COORD * RANGE_SLACK).contains(&l) {
            return Err(LeafError::OutOfRange(format!(
                "its size (radius, length or scale along its local axis {k}) is {l:.3e} after transforms, outside the supported {MIN_SIZE:e} to {MAX_COORD:e}"
            )));
        }
    }
    let far = |v: Vec3| v.abs().max_element() as f64;
    // NaN (an infinite box) fails the test below as infinity does.
    let reach = far(anchor).max(bounds.map_or(0.0, |b| if b.is_finite() { far(b.min).max(far(b.max)) } else { f64::INFINITY }));
    if !(reach <= MAX_COORD * RANGE_SLACK) {
        return Err(LeafError::OutOfRange(format!(
            "it reaches a coordinate of {reach:.3e}, outside the supported -{MAX_COORD:e} to {MAX_COORD:e}"
        )));
    }
    Ok(())
}

/// The SoA table of every leaf of a baked scene. Leaf `i` is described by the
/// `i`-th element of every column; the hot path matches once on `kind[i]`.
#[derive(Clone, Debug, Default)]
pub struct LeafTable {
    /// Kind tag per leaf.
    pub kind: Vec<LeafKind>,
    /// World-to-local affine map per leaf, applied to points *relative to the
    /// leaf's anchor* (`to_local[i].transform_point3(p - anchor[i])`; rays'
    /// directions are mapped, not normalised).
    pub to_local: Vec<Affine3A>,
    /// A world point near each leaf (f32). Points are taken relative to it
    /// before the linear map: the difference of nearby f32 values is exact, and
    /// the map's translation stays small. With the translation of the whole
    /// map instead, a unit cylinder 1e5 from the origin lost 3e-3 of the view
    /// distance to cancellation (tests/stress.rs).
    /// (`Vec3A`: the subtraction is one SIMD operation on the hot path.)
    pub anchor: Vec<Vec3A>,
    /// Kind-specific parameters.
    pub p0: Vec<Vec4>,
    /// Kind-specific parameters.
    pub p1: Vec<Vec4>,
    /// World bounds per leaf, as pushed. A bake moves them into its CSG
    /// program (each leaf node's bounds) and leaves this empty: one copy,
    /// 24 bytes per leaf.
    pub bounds: Vec<Aabb>,
    /// Index into the kind's own table (sweeps, gcyls, meshes); 0 for analytic leaves.
    pub ext: Vec<u32>,
    /// Swept spheres.
    pub sweeps: Vec<Arc<SweptSphereData>>,
    /// Generalized cylinders.
    pub gcyls: Vec<Arc<GenCylData>>,
    /// Distinct meshes (a mesh under many transforms is stored once).
    pub meshes: Vec<Arc<MeshData>>,
    /// Per leaf traced in f64 (tori, ellipsoids, cylinders, cones, boxes: see
    /// [`LeafTable::has_map64`]; indexed by `ext`), its world-to-local map in
    /// f64: the linear part and the anchor's local point ([`crate::table64`]);
    /// per half-space, its f64 world plane relative to the anchor instead.
    pub maps64: Vec<(DMat3, DVec3)>,
    /// Per leaf, for a mesh: its entry in `mesh_maps`; for a box: its entry
    /// in `box_normals`; 0 for other kinds.
    pub mesh_map: Vec<u32>,
    /// Per mesh leaf: its f64 world-to-local map, through which its rays
    /// are mapped ([`LeafTable::mesh_line`]).
    pub mesh_maps: Vec<MeshMap>,
    /// Per box leaf: its faces' world normals by sub-surface, made once
    /// ([`LeafTable::normal`] reads them; made at every hit, the map and the
    /// normalisation were a few % of lit scenes of boxes, perf).
    pub box_normals: Vec<[Vec3; 6]>,
    /// Polish tolerance of the torus roots, relative to the minor radius (see
    /// [`kernels::torus_tol`]; a bake sets [`kernels::TORUS_TOLERANCE`] unless
    /// the `torus` knob says otherwise; 0 is full f64 precision).
    pub torus_tol: f64,
}

/// A mesh leaf's f64 world-to-local map, `inv (p - anchor) + b`.
#[derive(Clone, Copy, Debug)]
pub struct MeshMap {
    /// The linear part.
    pub inv: DMat3,
    /// The anchor's local point.
    pub b: DVec3,
}

impl LeafTable {
    /// Number of leaves.
    pub fn len(&self) -> usize {
        self.kind.len()
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.kind.is_empty()
    }
    /// Removes every leaf.
    pub fn clear(&mut self) {
        self.kind.clear();
        self.to_local.clear();
        self.anchor.clear();
        self.p0.clear();
        self.p1.clear();
        self.bounds.clear();
        self.ext.clear();
        self.mesh_map.clear();
        self.mesh_maps.clear();
        self.box_normals.clear();
        self.sweeps.clear();
        self.gcyls.clear();
        self.meshes.clear();
        self.maps64.clear();
    }

    /// The f32 world-to-local map of `world_from_local` relative to `anchor`
    /// (see [`LeafTable::anchor`]), and the local point of the anchor in f64
    /// (its translation before rounding).
    fn inverse32(m: &DAffine3, anchor: Vec3) -> Result<(Affine3A, DVec3), LeafError> {
        let det = m.matrix3.determinant();
        if !det.is_finite() || det.abs() <= 1e-300 || !m.translation.is_finite() {
            return Err(LeafError::SingularTransform);
        }
        let inv = m.inverse();
        // The anchor relative to the map's origin first (both near the leaf):
        // through the inverse's translation, the anchor's local point lost
        // 1e-16 of the offset from the origin to cancellation, and a ray at
        // 3e-8 rad to a cylinder's cap 1e3 out crossed it 2.3e-6 of the
        // view off (tests/stress_tangent.rs).
        let b = inv.matrix3 * (anchor.as_dvec3() - m.translation);
        let inv32 = Affine3A::from_mat3_translation(inv.matrix3.as_mat3(), b.as_vec3());
        if !(inv32.matrix3.is_finite() && inv32.translation.is_finite()) {
            return Err(LeafError::SingularTransform);
        }
        Ok((inv32, b))
    }

    /// The local point of world point `p` in leaf `i`'s frame.
    #[inline(always)]
    fn local_point(&self, i: usize, p: Vec3) -> Vec3 {
        self.to_local[i].transform_point3a(Vec3A::from(p) - self.anchor[i]).into()
    }

    /// Adds a leaf with shared data, placed by `world_from_node`; returns its index.
    pub fn push_data(&mut self, data: &LeafData, world_from_node: &DAffine3) -> Result<u32, LeafError> {
        // Swept spheres, generalized cylinders and meshes keep their own
        // coordinates (their local bounds can lie anywhere): anchor at the node's origin.
        let anchor = world_from_node.translation.as_vec3();
        let (inv32, b) = Self::inverse32(world_from_node, anchor)?;
        // The node's own scale (the data's coordinates are checked as bounds below).
        let (kind, ext, local) = match data {
            LeafData::SweptSphere(d) => {
                self.sweeps.push(d.clone());
                (LeafKind::SweptSphere, self.sweeps.len() - 1, d.local_bounds())
            }
            LeafData::GenCylinder(d) => {
                self.gcyls.push(d.clone());
                (LeafKind::GenCylinder, self.gcyls.len() - 1, d.local_bounds())
            }
            LeafData::Mesh(d) => {
                let ext = match self.meshes.iter().position(|m| Arc::ptr_eq(m, d)) {
                    Some(i) => i,
                    None => {
                        self.meshes.push(d.clone());
                        self.meshes.len() - 1
                    }
                };
                (LeafKind::Mesh, ext, d.local_bounds())
            }
        };
        let bounds = local.transformed_f64(world_from_node);
        check_range(&world_from_node.matrix3, Some(&bounds), anchor)?;
        let i = self.kind.len() as u32;
        self.kind.push(kind);
        self.to_local.push(inv32);
        self.anchor.push(anchor.into());
        self.p0.push(Vec4::ZERO);
        self.p1.push(Vec4::ZERO);
        self.bounds.push(bounds);
        self.ext.push(ext as u32);
        let mut map = 0;
        if kind == LeafKind::Mesh {
            // Through the f32 map a mesh's rays moved by ~6e-8 of the
            // origin's distance: rays grazing a face of a rotated
            // octahedron crossed 46 to 65 of 400 times wrongly, ends up to
            // 0.23 of the view off (tests/stress_grazing.rs).
            self.mesh_maps.push(MeshMap { inv: world_from_node.matrix3.inverse(), b });
            map = self.mesh_maps.len() - 1;
        }
        self.mesh_map.push(map as u32);
        Ok(i)
    }

    /// Adds a leaf placed by `world_from_node`; returns its index.
    pub fn push(&mut self, shape: &LeafShape, world_from_node: &DAffine3) -> Result<u32, LeafError> {
        shape.validate().map_err(LeafError::Shape)?;
        let c = shape.canonical();
        let m = *world_from_node * c.node_from_local;
        let bounds = canonical_bounds(&c, &m);
        // The anchor: a point of the solid (the centre of a sphere or torus, the
        // axis midpoint of a cylinder or cone, a box's centre), or the plane's
        // point nearest the node's origin (re-anchored near its object by
        // `reanchor` once the object's bounds are known).
        let local_anchor = match c.kind {
            LeafKind::Cylinder | LeafKind::Cone => DVec3::new(0.0, 0.0, 0.5),
            LeafKind::Cuboid => (c.p0.truncate().as_dvec3() + c.p1.truncate().as_dvec3()) * 0.5,
            LeafKind::HalfSpace => c.p0.truncate().as_dvec3() * c.p0.w as f64,
            _ => DVec3::ZERO,
        };
        let anchor = m.transform_point3(local_anchor).as_vec3();
        let (inv32, b) = Self::inverse32(&m, anchor)?;
        check_range(&m.matrix3, (c.kind != LeafKind::HalfSpace).then_some(&bounds), anchor)?;
        check_own_sizes(shape, &m.matrix3)?;
        // Planes take the anchor's local point into their offset, in f64 (a
        // plane 1e5 from the origin keeps its offset relative to the
        // anchor); the map is then linear. (The f32 map only carries
        // normals now: boxes and planes are traced in f64, crate::table64.)
        let (kind, (inv32, p0, p1)) = match c.kind {
            LeafKind::Sphere => match similarity_scale(&m.matrix3) {
                // The ball's centre and radius in f64, kept as f32 numbers
                // and residuals (see `LeafKind::Sphere`): with no transform
                // both are the description's own f32 numbers, exactly.
                Some(r) => {
                    let e = (m.translation - anchor.as_dvec3()).as_vec3();
                    let r32 = r as f32;
                    (LeafKind::Sphere, (inv32, Vec4::new(r32, (r - r32 as f64) as f32, 0.0, 0.0), e.extend(0.0)))
                }
                None => (LeafKind::Ellipsoid, (inv32, c.p0, c.p1)),
            },
            LeafKind::HalfSpace => {
                // From the description's f32 numbers in f64: the canonical
                // offset / |normal| rounded in f32 had already lost 3e-3 of a
                // plane 1e5 from the origin.
                let LeafShape::HalfSpace(h) = shape else { unreachable!() };
                let n = h.normal.as_dvec3();
                let w = (h.offset as f64 - n.dot(b)) / n.length();
                let z = Affine3A::from_mat3_translation(inv32.matrix3.into(), Vec3::ZERO);
                // `p1`: the world normal, as `normal` would make it at every
                // hit (a plane under a scene is most of its hits: the map and
                // normalisation were 8% of benches/scenes/ground lit, perf).
                (c.kind, (z, c.p0.truncate().extend(w as f32), world_normal(&z, c.p0.truncate()).extend(0.0)))
            }
            _ => (c.kind, (inv32, c.p0, c.p1)),
        };
        let i = self.kind.len() as u32;
        self.kind.push(kind);
        self.to_local.push(inv32);
        self.anchor.push(anchor.into());
        self.p0.push(p0);
        self.p1.push(p1);
        self.bounds.push(bounds);
        let mut ext = 0;
        if Self::has_map64(kind) {
            // The f64 map (crate::table64): the f32 one (6e-8 relative) moved
            // a thin tube's surface by a large part of it, tangent chords'
            // ends by ~6e-8 r^2 / (L/2), and where a ray at angle a to a flat
            // face crosses it by ~6e-8 of its distance / sin(a).
            self.maps64.push(Self::map64_of(shape, kind, &m.matrix3.inverse(), b));
            ext = self.maps64.len() - 1;
        }
        self.ext.push(ext as u32);
        let mut map = 0;
        if kind == LeafKind::Cuboid {
            self.box_normals.push(std::array::from_fn(|sub| world_normal(&inv32, box_face_normal(sub as u32))));
            map = self.box_normals.len() - 1;
        }
        self.mesh_map.push(map as u32);
        Ok(i)
    }

    /// The [`LeafTable::maps64`] entry of a leaf of `kind`: its f64
    /// world-to-local map `inv` and the anchor's local point `b`; for a
    /// half-space its world plane relative to the anchor instead (see
    /// [`LeafTable::plane64`]): `dot(n, x) <= offset` with
    /// `x = inv (p - anchor) + b` is `dot(inv^T n, p - anchor) <= offset - dot(n, b)`.
    fn map64_of(shape: &LeafShape, kind: LeafKind, inv: &DMat3, b: DVec3) -> (DMat3, DVec3) {
        match shape {
            LeafShape::HalfSpace(h) if kind == LeafKind::HalfSpace => {
                let n = h.normal.as_dvec3();
                (DMat3::from_cols(inv.transpose() * n, DVec3::ZERO, DVec3::ZERO), DVec3::new(h.offset as f64 - n.dot(b), 0.0, 0.0))
            }
            _ => (*inv, b),
        }
    }

    /// Pushes the spans of leaf `i` along the (world) ray, clipped to its range,
    /// into `out` (sorted, disjoint). Clipped ends carry [`Surf::NONE`].
    #[inline]
    pub fn spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, out: &mut S) {
        self.spans_in(i, ray, (ray.tmin, ray.tmax), out)
    }

    /// [`LeafTable::spans`] on `range` instead of the ray's own range. The
    /// evaluator asks each leaf on a range of its own: a copy of the ray per
    /// leaf query, written just before the kernel loads its origin as one
    /// 16-byte vector, stalled on store forwarding (scenes/nesting traced
    /// 12-17% slower at the same instruction count).
    #[inline]
    pub fn spans_in<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, (tmin, tmax): (f32, f32), out: &mut S) {
        let (o, d) = (ray.origin, ray.dir);
        let iu = i as usize;
        match self.kind[iu] {
            LeafKind::Sphere => return self.ball_spans(i, ray, (tmin, tmax), out),
            LeafKind::Torus => {
                self.torus_spans(i, ray, (tmin, tmax), false, out);
                return;
            }
            LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone => return self.quadric_spans(i, ray, (tmin, tmax), out),
            LeafKind::Cuboid | LeafKind::HalfSpace => return self.flat_spans(i, ray, (tmin, tmax), out),
            _ => {}
        }
        if self.kind[iu] == LeafKind::Mesh {
            self.mesh_spans(i, ray, (tmin, tmax), None, out);
            return;
        }
        let m = &self.to_local[iu];
        let lo: Vec3 = m.transform_point3a(Vec3A::from(o) - self.anchor[iu]).into();
        let ld = m.transform_vector3(d);
        // The range check costs scenes/logo 1.5% of its instructions
        // (callgrind, 480x270 flat: 209.7e6 -> 212.8e6, with the queries'
        // check); its wall time moved within noise.
        if let Some(k) = Ray::dir_rescale(ld) {
            return self.spans_rescaled(i, (lo, ld), (tmin, tmax), k, out);
        }
        self.spans_local(i, (lo, ld), (tmin, tmax), out)
    }

    /// The world point `p` relative to ball `iu`'s centre, in f64 (the f32
    /// difference to the anchor is exact in f64), and its radius.
    #[inline(always)]
    fn ball_frame(&self, iu: usize, p: Vec3) -> (DVec3, f64) {
        let q = (p.as_dvec3() - Vec3::from(self.anchor[iu]).as_dvec3()) - self.p1[iu].truncate().as_dvec3();
        (q, self.p0[iu].x as f64 + self.p0[iu].y as f64)
    }

    /// The spans of torus `i` along the world ray, its line mapped to the
    /// torus's frame in f64 (a direction of any f32 length needs no
    /// rescaling there).
    /// With `first_only` (a nearest query) the spans may stop after the
    /// first one the range keeps; returns where they stop being exact.
    #[inline(always)]
    fn torus_spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, range: (f32, f32), first_only: bool, out: &mut S) -> f32 {
        let iu = i as usize;
        let (lo, ld) = self.line64(iu, ray);
        let mut buf = [(0.0f32, 0.0f32); 3];
        let ask = kernels::TorusAsk { range, first_only };
        let (n, valid) = kernels::torus_query(lo, ld, (self.p0[iu].x, self.torus_tol), ask, &mut buf);
        push_torus_spans(i, &buf[..n], range, out);
        valid
    }

    /// Is leaf `i` a ring torus, whose queries a packet can prepare for its
    /// eight lanes at once ([`LeafTable::torus_prep8`])?
    #[inline]
    pub fn has_torus_prep(&self, i: u32) -> bool {
        self.kind[i as usize] == LeafKind::Torus && self.p0[i as usize].x < 1.0
    }

    /// The [`kernels::TorusPrep`] of ring torus `i` (see
    /// [`LeafTable::has_torus_prep`]) for the world rays of the lanes in
    /// `lanes`; `None` where a lane's line misses it. Bit for bit what
    /// [`kernels::TorusPrep::new`] makes from the lane's `line64`, in 8-lane
    /// SIMD (two AVX registers or four SSE2 ones, chosen at run time:
    /// `torus8.rs`), with the entry of each lane's first run polished.
    pub fn torus_prep8(&self, i: u32, rays: &Rays8Soa, lanes: u32, out: &mut [Option<kernels::TorusPrep>; 8]) {
        #[cfg(target_arch = "x86_64")]
        {
            // Two AVX registers even where the CPU has AVX-512F: one AVX-512
            // register per value traced tori 4-5% slower (0.0319-0.0326 s
            // against 0.0304-0.0310 s, 960x540 flat, one thread, three
            // alternating rounds): the divisions and square roots dominate.
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the CPU has AVX.
                return unsafe { self.torus_prep8_avx(i, rays, lanes, out) };
            }
            self.torus_prep8_sse(i, rays, lanes, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let iu = i as usize;
            for k in 0..8 {
                out[k] = None;
                if lanes & (1 << k) != 0 {
                    let (o, d) = rays.lane(k);
                    let (lo, ld) = self.line64_of(iu, o, d);
                    out[k] = kernels::TorusPrep::new(lo, ld, self.p0[iu].x as f64);
                }
            }
        }
    }

    /// [`LeafTable::torus_spans`] of ring torus `i` from the ray's
    /// [`kernels::TorusPrep`] (`None`: the line misses it): the same spans
    /// and the same return value.
    pub fn torus_spans_prepped<S: SpanSink + ?Sized>(
        &self,
        i: u32,
        prep: Option<&kernels::TorusPrep>,
        range: (f32, f32),
        first_only: bool,
        out: &mut S,
    ) -> f32 {
        let Some(prep) = prep else { return f32::INFINITY };
        let iu = i as usize;
        let mut buf = [(0.0f32, 0.0f32); 3];
        let ask = kernels::TorusAsk { range, first_only };
        let (n, valid) = kernels::torus_query_prepped(prep, (self.p0[iu].x, self.torus_tol), ask, &mut buf);
        push_torus_spans(i, &buf[..n], range, out);
        valid
    }

    /// The spans of ball `i` (kind [`LeafKind::Sphere`]) along the world ray.
    #[inline(always)]
    fn ball_spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, (tmin, tmax): (f32, f32), out: &mut S) {
        let (o, r) = self.ball_frame(i as usize, ray.origin);
        if let Some((t0, t1)) = kernels::ball(o, ray.dir.as_dvec3(), r) {
            let s = Surf::new(i, kernels::sub::SIDE);
            push_clipped(out, Span { t0: t0 as f32, s0: s, t1: t1 as f32, s1: s }, tmin, tmax);
        }
    }

    /// [`LeafTable::spans_local`] for a local direction out of the kernels'
    /// range (a leaf 1e23 across seen along a unit direction: |d|^2 = 1e-46
    /// is 0 in f32, and the sphere vanished), traced with the direction scaled
    /// by the power of two `k` and t scaled back.
    #[cold]
    #[inline(never)]
    fn spans_rescaled<S: SpanSink + ?Sized>(&self, i: u32, (lo, ld): (Vec3, Vec3), range: (f32, f32), k: f64, out: &mut S) {
        let local = Ray::new(lo, ld).rescaled(k);
        let range = (scale_t(range.0, 1.0 / k), scale_t(range.1, 1.0 / k));
        self.spans_local(i, (lo, local.dir), range, &mut ScaledSink { out, k })
    }

    /// The spans of leaf `i` along the local line `lo + t ld` on `(tmin, tmax)`.
    #[inline(always)]
    fn spans_local<S: SpanSink + ?Sized>(&self, i: u32, (lo, ld): (Vec3, Vec3), (tmin, tmax): (f32, f32), out: &mut S) {
        let iu = i as usize;
        let local = Ray::segment(lo, ld, tmin, tmax);
        match self.kind[iu] {
            LeafKind::SweptSphere => self.sweeps[self.ext[iu] as usize].spans(&local, i, out),
            LeafKind::GenCylinder => self.gcyls[self.ext[iu] as usize].spans(&local, i, out),
            _ => unreachable!("traced in f64 (ball_spans, quadric_spans, torus_spans, flat_spans, mesh_spans)"),
        }
    }

    /// [`LeafTable::spans_in`], or, when `nearest` is `Some(slack)`, what a
    /// nearest-hit query needs: leaves whose full span list is costly (meshes)
    /// may stop `slack` (in t) past their first entry. The spans pushed are exact
    /// on `[tmin, v]` and none lies past `v`, the value returned (infinity when
    /// the answer is the full one).
    #[inline(always)]
    pub fn spans_for<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, range: (f32, f32), nearest: Option<f32>, out: &mut S) -> f32 {
        if let Some(slack) = nearest {
            match self.kind[i as usize] {
                LeafKind::Mesh => return self.mesh_nearest(i, ray, range, slack, out),
                // Its first span suffices (the roots past it are not polished).
                LeafKind::Torus => return self.torus_nearest(i, ray, range, out),
                _ => {}
            }
        }
        self.spans_in(i, ray, range, out);
        f32::INFINITY
    }

    /// A torus's spans for a nearest query (out of line, as `mesh_nearest`:
    /// inlined, it made every leaf query's code bigger).
    #[inline(never)]
    fn torus_nearest<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, range: (f32, f32), out: &mut S) -> f32 {
        self.torus_spans(i, ray, range, true, out)
    }

    #[inline(never)]
    fn mesh_nearest<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, range: (f32, f32), slack: f32, out: &mut S) -> f32 {
        self.mesh_spans(i, ray, range, Some(slack), out)
    }

    /// The exact line of the world ray `(o, d)` in mesh leaf `iu`'s frame
    /// (its f64 map; `o - anchor` is exact in f64), and that line rounded
    /// to f32: the ray the mesh's walks trace.
    #[inline(always)]
    fn mesh_line(&self, iu: usize, o: Vec3, d: Vec3) -> (Vec3, Vec3, Line64) {
        let MeshMap { inv: a, b, .. } = &self.mesh_maps[self.mesh_map[iu] as usize];
        let x = Line64 { o: *a * (o.as_dvec3() - Vec3::from(self.anchor[iu]).as_dvec3()) + *b, d: *a * d.as_dvec3(), rounded: true };
        (x.o.as_vec3(), x.d.as_vec3(), x)
    }

    /// The spans of mesh leaf `i` along the world ray on `(tmin, tmax)`:
    /// all of them, or, with `Some(slack)`, what a nearest query needs
    /// (see [`LeafTable::spans_for`]; returns where they stop being exact).
    #[inline(always)]
    fn mesh_spans<S: SpanSink + ?Sized>(&self, i: u32, ray: &Ray, (tmin, tmax): (f32, f32), slack: Option<f32>, out: &mut S) -> f32 {
        let iu = i as usize;
        let mesh = &self.meshes[self.ext[iu] as usize];
        let (lo, ld, x) = self.mesh_line(iu, ray.origin, ray.dir);
        let local = Ray::segment(lo, ld, tmin, tmax);
        if let Some(k) = Ray::dir_rescale(local.dir) {
            // As in `spans_in`: the walk in units of a direction near 1, its
            // slack and result scaled back (k a power of two: exact).
            let (local, x) = (local.rescaled(k), Line64 { d: x.d * k, ..x });
            let out = &mut ScaledSink { out, k };
            return match slack {
                Some(s) => scale_t(mesh.spans_nearest_on(&local, x, scale_t(s, 1.0 / k), i, out), k),
                None => {
                    mesh.spans_on(&local, x, i, out);
                    f32::INFINITY
                }
            };
        }
        match slack {
            Some(s) => mesh.spans_nearest_on(&local, x, s, i, out),
            None => {
                mesh.spans_on(&local, x, i, out);
                f32::INFINITY
            }
        }
    }

    /// Appends the world planes of leaf `i` when it is a polytope (a half-space:
    /// one plane; a box under any affine map: six) and says whether it is one.
    /// For bounds at bake: the planes come from the f64 maps the spans use.
    pub fn world_planes(&self, i: u32, out: &mut Vec<crate::polytope::Plane>) -> bool {
        use crate::polytope::Plane;
        let iu = i as usize;
        let c = Vec3::from(self.anchor[iu]).as_dvec3();
        match self.kind[iu] {
            LeafKind::HalfSpace => {
                let (n, w) = self.plane64(iu);
                out.extend(Plane::new(n, w + n.dot(c)));
                true
            }
            LeafKind::Cuboid => {
                let (a, b) = &self.maps64[self.ext[iu] as usize];
                let (lo, hi) = (self.p0[iu].truncate().as_dvec3(), self.p1[iu].truncate().as_dvec3());
                // Local plane dot(nl, x) <= w with x = A (p - c) + b:
                // dot(A^T nl, p) <= w - dot(nl, b) + dot(A^T nl, c).
                let mut push = |nl: DVec3, w: f64| {
                    let n = a.transpose() * nl;
                    out.extend(Plane::new(n, w - nl.dot(*b) + n.dot(c)));
                };
                for k in 0..3 {
                    push(DVec3::AXES[k], hi[k]);
                    push(-DVec3::AXES[k], -lo[k]);
                }
                true
            }
            _ => false,
        }
    }

    /// Moves the anchor of half-space leaf `i` to the point of its plane
    /// nearest `near` (the centre of its object's bounds, at bake): the
    /// plane's offset is kept relative to a point near where it matters
    /// (in f64, from its f64 plane). Other kinds keep their anchor.
    pub fn reanchor(&mut self, i: u32, near: Vec3) {
        let iu = i as usize;
        if self.kind[iu] != LeafKind::HalfSpace || !near.is_finite() {
            return;
        }
        let (n, w) = self.plane64(iu);
        let c = Vec3::from(self.anchor[iu]).as_dvec3();
        // World plane: dot(n, p - c) <= w.
        let nn = n.length_squared();
        if !(nn > 0.0 && nn.is_finite()) {
            return;
        }
        let q = near.as_dvec3();
        let c2 = (q - n * ((n.dot(q - c) - w) / nn)).as_vec3();
        if !c2.is_finite() {
            return;
        }
        // c2 - c is exact in f64 (two f32 points).
        self.maps64[self.ext[iu] as usize].1.x = w - n.dot(c2.as_dvec3() - c);
        self.anchor[iu] = c2.into();
    }

    /// Is leaf `i` a triangle mesh?
    pub fn is_mesh(&self, i: u32) -> bool {
        self.kind[i as usize] == LeafKind::Mesh
    }

    /// The nearest-mode query of mesh leaf `i` ([`LeafTable::spans_for`] with
    /// `nearest = Some(slack[k])`) for eight world rays from one origin `o`, traced
    /// as one packet ([`MeshData::spans_nearest8`]). Returns the rays done (their
    /// spans in `out[k]`, exact on `[tmin[k], valid[k]]`) and the `valid` ends;
    /// the others are left to `spans_for`.
    pub fn mesh_nearest8(&self, i: u32, q: &NearestRays8, active: u32, out: &mut [Vec<Span>; 8]) -> (u32, [f32; 8]) {
        let iu = i as usize;
        if self.kind[iu] != LeafKind::Mesh {
            return (0, [f32::INFINITY; 8]);
        }
        let MeshMap { inv: a, b, .. } = &self.mesh_maps[self.mesh_map[iu] as usize];
        // The rays' lines through the f64 map (as `mesh_line`).
        let xo = *a * (q.o.as_dvec3() - Vec3::from(self.anchor[iu]).as_dvec3()) + *b;
        let xd: [DVec3; 8] = std::array::from_fn(|k| *a * q.d[k].as_dvec3());
        let dl: [Vec3; 8] = std::array::from_fn(|k| xd[k].as_vec3());
        // A lane whose local direction is out of the kernels' range (see
        // `spans_in`) is left to the single-ray query, which rescales it.
        let active = (0..8).filter(|&k| Ray::dir_rescale(dl[k]).is_none()).fold(0, |a, k| a | (1 << k)) & active;
        let local = NearestRays8 { o: xo.as_vec3(), d: &dl, exact: Some((xo, &xd)), ..*q };
        self.meshes[self.ext[iu] as usize].spans_nearest8(&local, active, i, out)
    }

    /// The spans of mesh leaf `i` for eight world rays with one direction
    /// `d` and their own origins `o[k]` on `[tmin[k], tmax[k]]` (a packet of
    /// shadow rays toward a directional light), in one walk of the tree
    /// ([`MeshData::spans_parallel8`]): the lanes of `active` whose own
    /// query walks the mesh to its box exit get exactly its spans, and with
    /// nearest-mode slacks `slack` those starting outside the mesh's bounds
    /// get exactly their nearest queries' spans. Returns those lanes and
    /// where each one's spans stop being exact; the others are left to
    /// `spans_for`.
    pub fn mesh_parallel8(
        &self,
        i: u32,
        (o, d): (&[Vec3; 8], Vec3),
        (tmin, tmax, slack): (&[f32; 8], &[f32; 8], Option<&[f32; 8]>),
        active: u32,
        out: &mut [Vec<Span>; 8],
    ) -> (u32, [f32; 8]) {
        let iu = i as usize;
        if self.kind[iu] != LeafKind::Mesh {
            return (0, [f32::INFINITY; 8]);
        }
        // The rays' lines through the f64 map (as `mesh_spans`): one local
        // direction for all.
        let lines: [(Vec3, Vec3, Line64); 8] = std::array::from_fn(|k| self.mesh_line(iu, o[k], d));
        let ld = lines[0].1;
        if Ray::dir_rescale(ld).is_some() {
            return (0, [f32::INFINITY; 8]);
        }
        let lo: [Vec3; 8] = std::array::from_fn(|k| lines[k].0);
        let x: [Line64; 8] = std::array::from_fn(|k| lines[k].2);
        let q = ParallelRays8 { o: &lo, d: ld, tmin, tmax, x: &x, slack };
        self.meshes[self.ext[iu] as usize].spans_parallel8(&q, active, i, out)
    }

    /// Is the world point inside leaf `i` (boundary included)?
    pub fn contains(&self, i: u32, p: Vec3) -> bool {
        let iu = i as usize;
        if self.kind[iu] == LeafKind::Sphere {
            let (q, r) = self.ball_frame(iu, p);
            return q.length_squared() <= r * r;
        }
        if self.kind[iu] == LeafKind::Torus {
            return kernels::torus_contains(self.local64(iu, p), self.p0[iu].x as f64);
        }
        if matches!(self.kind[iu], LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone) {
            return self.quadric_contains(iu, p);
        }
        if matches!(self.kind[iu], LeafKind::Cuboid | LeafKind::HalfSpace) {
            return self.flat_contains(iu, p);
        }
        let l = self.local_point(iu, p);
        match self.kind[iu] {
            LeafKind::Sphere
            | LeafKind::Ellipsoid
            | LeafKind::Cylinder
            | LeafKind::Cone
            | LeafKind::Torus
            | LeafKind::Cuboid
            | LeafKind::HalfSpace => {
                unreachable!("classified in f64 (ball_frame, local64, flat_contains)")
            }
            LeafKind::SweptSphere => self.sweeps[self.ext[iu] as usize].contains(l),
            LeafKind::GenCylinder => self.gcyls[self.ext[iu] as usize].contains(l),
            LeafKind::Mesh => self.meshes[self.ext[iu] as usize].contains(l),
        }
    }

    /// Outward unit normal (world space) of leaf `i` at parameter `t` of the (world) ray, on
    /// sub-surface `sub` (as reported with the crossing). Cold path: called once per
    /// shown pixel.
    pub fn normal(&self, i: u32, sub: u32, ray: &Ray, t: f32) -> Vec3 {
        let (o, d) = (ray.origin, ray.dir);
        let iu = i as usize;
        if self.kind[iu] == LeafKind::Sphere {
            // The point relative to the centre in f64 (a small ball far out is
            // a small difference of world points), then normalised in f32
            // like any local normal (f32 keeps its direction to 6e-8).
            let (q, _) = self.ball_frame(iu, o);
            return unit((q + d.as_dvec3() * t as f64).as_vec3());
        }
        if self.kind[iu] == LeafKind::Torus {
            // The local point in f64, as its spans: the tube of a thin torus is
            // a small difference of local points. Its offset from the tube's
            // core circle, once made, is a plain local normal for the f32 map
            // (the f64 map and normalisation cost tori 3% of its time).
            let (lo, ld) = self.line64(iu, ray);
            let l = lo + ld * t as f64;
            let xy = DVec3::new(l.x, l.y, 0.0).try_normalize().unwrap_or(DVec3::X);
            return world_normal(&self.to_local[iu], (l - xy).as_vec3());
        }
        if matches!(self.kind[iu], LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone) {
            return self.quadric_normal(iu, sub, ray, t);
        }
        if self.kind[iu] == LeafKind::HalfSpace {
            // Made once (`push`): `world_normal` of the local normal.
            return self.p1[iu].truncate();
        }
        if self.kind[iu] == LeafKind::Cuboid {
            // Made once (`push`): `world_normal` of the face's local normal.
            return self.box_normals[self.mesh_map[iu] as usize][sub as usize % 6];
        }
        let m = &self.to_local[iu];
        if self.kind[iu] == LeafKind::Mesh && !self.meshes[self.ext[iu] as usize].normal_needs_point(sub) {
            // A triangle's normal does not depend on the point: skip transforming it.
            let nl = self.meshes[self.ext[iu] as usize].normal(sub, Vec3::ZERO);
            return world_normal(m, nl);
        }
        // The local point only for the kinds whose normal depends on it (a
        // box's face and a half-space's plane give theirs without it).
        let l = || self.local_point(iu, o) + m.transform_vector3(d) * t;
        let nl = match self.kind[iu] {
            LeafKind::Cuboid => unreachable!("made at push (box_normals)"),
            LeafKind::Sphere | LeafKind::Ellipsoid | LeafKind::Cylinder | LeafKind::Cone | LeafKind::Torus => {
                unreachable!("made in f64 (ball_frame, quadric_normal, line64)")
            }
            LeafKind::HalfSpace => unreachable!("made at push (p1)"),
            LeafKind::SweptSphere => self.sweeps[self.ext[iu] as usize].normal(sub, l()),
            LeafKind::GenCylinder => self.gcyls[self.ext[iu] as usize].normal(sub, l()),
            LeafKind::Mesh => self.meshes[self.ext[iu] as usize].normal(sub, l()),
        };
        world_normal(m, nl)
    }
}

/// A box's local normal on face `sub` (`2 axis + side`: -axis, then +axis).
fn box_face_normal(sub: u32) -> Vec3 {
    let mut n = Vec3::ZERO;
    n[(sub / 2) as usize] = if sub % 2 == 1 { 1.0 } else { -1.0 };
    n
}

/// The unit world normal of local normal `nl` under the world-to-local map `m`
/// (its transpose). The map of a leaf 1e22 across has entries near 1e-22:
/// the image's squared length, 1e-44, is subnormal in f32 (normals came out
/// 1.0097 long) and from 1e23 on it is 0 (every normal became +y); such
/// lengths (and huge ones, from tiny leaves) are normalised in f64.
#[inline]
pub(crate) fn world_normal(m: &Affine3A, nl: Vec3) -> Vec3 {
    let n = m.matrix3.transpose() * Vec3A::from(nl);
    let l2 = n.length_squared();
    if (1e-30..=1e30).contains(&l2) {
        return n.normalize_or(Vec3A::Y).into();
    }
    let n = m.matrix3.as_dmat3().transpose() * nl.as_dvec3();
    n.try_normalize().map_or(Vec3::Y, |n| n.as_vec3())
}

/// `n` normalised (`+y` for a zero vector): in f32 where its squared
/// length is in f32's comfortable range, else in f64 (as [`world_normal`]).
#[inline]
fn unit(n: Vec3) -> Vec3 {
    let l2 = n.length_squared();
    if (1e-30..=1e30).contains(&l2) {
        return n.normalize_or(Vec3::Y);
    }
    n.as_dvec3().try_normalize().map_or(Vec3::Y, |n| n.as_vec3())
}

/// Torus `i`'s spans `(t0, t1)` (its one surface at both ends), clipped to `range`.
#[inline(always)]
fn push_torus_spans<S: SpanSink + ?Sized>(i: u32, spans: &[(f32, f32)], range: (f32, f32), out: &mut S) {
    for &(t0, t1) in spans {
        push_clipped(out, Span { t0, s0: Surf::new(i, 0), t1, s1: Surf::new(i, 0) }, range.0, range.1);
    }
}

/// Clips `[t0, t1]` to `[tmin, tmax]` and pushes it if it keeps a positive length.
#[inline(always)]
pub fn push_clipped<S: SpanSink + ?Sized>(out: &mut S, span: Span, tmin: f32, tmax: f32) {
    let Span { t0, t1, s0, s1 } = span;
    // Ends beyond the range, or at infinity (a half-space), are not surfaces.
    let (t0, s0) = if t0 < tmin || !t0.is_finite() { (t0.max(tmin), Surf::NONE) } else { (t0, s0) };
    let (t1, s1) = if t1 > tmax || !t1.is_finite() { (t1.min(tmax), Surf::NONE) } else { (t1, s1) };
    if t1 > t0 {
        out.push_span(Span { t0, t1, s0, s1 });
    }
}

#[cfg(test)]
mod bounds_tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// Leaf bounds hold the solid's extreme points computed in f64, also
    /// 5e3 from the origin where an f32 is 4.9e-4 apart (rounded to the
    /// nearest f32 they lost up to half of that).
    #[test]
    fn leaf_bounds_hold_the_f64_solid_far_from_the_origin() {
        let seed = 0xb0u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut v = |s: f32| Vec3::new(rng.gen_range(-s..s), rng.gen_range(-s..s), rng.gen_range(-s..s));
        for i in 0..2000 {
            let (c, h, off) =
                (v(3.0), v(0.5).abs() + Vec3::splat(0.01), v(1.0).as_dvec3() + DVec3::new(3072.0, -2048.0, 5120.0) * (i % 3) as f64);
            let m = DAffine3::from_translation(off);
            let mut t = LeafTable::default();
            // Extreme points in f64 of a sphere and a box.
            let (shape, extremes): (LeafShape, Vec<DVec3>) = if i % 2 == 0 {
                let r = h.x;
                let cc = c.as_dvec3() + off;
                let e = [DVec3::X, DVec3::Y, DVec3::Z, -DVec3::X, -DVec3::Y, -DVec3::Z].map(|a| cc + a * r as f64).to_vec();
                (LeafShape::Sphere(Sphere { center: c, radius: r }), e)
            } else {
                let (lo, hi) = (c - h, c + h);
                let e = (0..8)
                    .map(|k| {
                        let p = Vec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][(k >> 1) & 1], [lo.z, hi.z][(k >> 2) & 1]);
                        p.as_dvec3() + off
                    })
                    .collect();
                (LeafShape::Cuboid(Cuboid { min: lo, max: hi }), e)
            };
            t.push(&shape, &m).expect("valid leaf");
            let b = t.bounds[0];
            for p in extremes {
                assert!(
                    b.min.as_dvec3().cmplt(p).all() && p.cmplt(b.max.as_dvec3()).all(),
                    "case {i}: {shape:?} at {off}: point {p} outside {b:?}"
                );
            }
        }
    }
}
