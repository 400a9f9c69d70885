//! Triangle-mesh leaf solids.
//!
//! A [`MeshData`] is the immutable, shareable (`Arc`) part of a mesh leaf: the
//! triangles in BVH leaf order, the BVH, and per-node dipoles for the fast
//! generalized winding number. Rays come in the mesh's own (file) space; `t` is
//! the caller's `t` (the direction is not normalised).
//!
//! # What is inside
//! * [`InsideRule::Orientation`] (default): the mesh must be a closed, consistently
//!   oriented surface (every undirected edge is used as often in one direction as
//!   in the other). A point is inside when the winding count (signed number of
//!   surfaces around it) is positive. Spans come from the running count of signed
//!   crossings along the ray. A mesh whose signed volume is negative (inside out)
//!   is flipped, with a warning.
//! * [`InsideRule::Winding`], and the fallback for open or inconsistent meshes:
//!   inside where the generalized winding number (Jacobson et al. 2013) is at least
//!   0.5, within the mesh's bounding box. The ray is cut at every crossing and each
//!   piece is classified at its midpoint (Barill et al. 2018 dipole approximation
//!   for far BVH nodes, exact solid angles near).
//!
//! # Watertightness
//! Crossings are found with the watertight ray/triangle test of Woop, Benthin and
//! Wald (2013). Its 2D edge functions are exactly antisymmetric for a shared edge,
//! and exact zeros (the ray passes exactly through an edge or vertex) are resolved
//! by a fixed tie-breaking rule that is equivalent to shifting the ray by an
//! infinitesimal `(-1, eps)` in the projected plane (the rasterizer's top-left
//! rule). So exactly one of the triangles that tile a neighbourhood of an edge or
//! vertex reports the crossing: rays never leak through, nor count a crossing twice.
//! The test runs in f32 where its decision is certain (every edge function is
//! compared with a bound of its rounding error) and in f64 for the few
//! triangles where it is not (see [`intersect64`]): decisions that are certain
//! are the exact ones, so the two kinds stay watertight together.

use crate::{Ray, Span};
use std::collections::HashMap;
use std::fmt;
use std::mem::MaybeUninit;

use glam::{DVec3, Vec3, Vec4};
use smallvec::SmallVec;

use crate::{
    aabb::Aabb,
    bvh::{BvhNode, FlatBvh},
    table::push_clipped,
    SpanSink, Surf,
};

/// How a mesh decides what is inside (scene key `inside`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum InsideRule {
    /// Closed, consistently oriented mesh: inside where the winding count is positive.
    #[default]
    Orientation,
    /// Inside where the generalized winding number is >= 0.5 (works on open meshes).
    Winding,
}

/// Why a triangle list cannot be a solid.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshError {
    /// No vertices or no triangles (or none left after dropping degenerate ones).
    Empty,
    /// A triangle refers to a vertex that does not exist.
    IndexOutOfRange {
        /// Triangle index.
        triangle: usize,
        /// The bad index.
        index: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// A vertex position is NaN or infinite.
    NonFinite {
        /// Vertex index.
        vertex: usize,
    },
    /// The triangles enclose no volume (flat, or a closed surface of zero volume).
    NoVolume(String),
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MeshError::Empty => write!(f, "the mesh has no triangles"),
            MeshError::IndexOutOfRange { triangle, index, vertices } => {
                write!(f, "triangle {triangle} refers to vertex {index}, but there are only {vertices} vertices")
            }
            MeshError::NonFinite { vertex } => write!(f, "vertex {vertex} has a NaN or infinite coordinate"),
            MeshError::NoVolume(why) => write!(f, "the mesh encloses no volume: {why}"),
        }
    }
}

impl std::error::Error for MeshError {}

/// What `rothray check` prints about a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshReport {
    /// Triangles kept (degenerate index triples dropped).
    pub triangles: usize,
    /// Distinct vertex positions (exact duplicates welded).
    pub vertices: usize,
    /// Local bounds.
    pub bounds: Aabb,
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Every edge shared by two triangles is used in opposite directions.
    pub consistently_oriented: bool,
    /// Every edge is used as often in one direction as in the other (a closed,
    /// oriented 2-cycle: the winding count is well defined).
    pub closed: bool,
    /// Pairs of triangles that cross each other (not sharing a vertex); `None` when
    /// not computed.
    pub self_intersections: Option<usize>,
    /// Enclosed (signed) volume; meaningful for closed meshes.
    pub volume: f64,
    /// Total surface area.
    pub area: f64,
    /// Can be used with [`InsideRule::Orientation`] (closed, oriented, non-zero volume).
    pub usable_as_solid: bool,
    /// The rule in effect.
    pub rule: InsideRule,
    /// Warnings raised while building.
    pub warnings: Vec<String>,
}

/// Flag in a crossing's `sub`: the triangle faces inward at this crossing, so its
/// geometric normal must be negated to point out of the solid.
pub const SUB_FLIP: u32 = 1 << 31;
/// `sub` (without [`SUB_FLIP`]) of a span end on the mesh's bounding box (only with
/// [`InsideRule::Winding`], where the solid is clipped to the box).
pub const SUB_BOX: u32 = !SUB_FLIP;

/// Dipole of a BVH node for the far-field winding number (Barill et al. 2018,
/// first order): area-weighted centroid, sum of area vectors, radius.
#[derive(Clone, Copy, Debug)]
struct Dipole {
    p: Vec3,
    n: Vec3,
    r2: f32,
}

/// Far-field acceptance: a node is approximated when the query is farther than
/// `BETA` times the node radius from its centroid (the default of
/// [`MeshData::set_far_field`]). Barill et al. use 2 with a second-order
/// expansion; with first order only we take 3, where the `winding` knob's curve
/// (`rothray bench scenes/knobs/winding.json --knob winding`, README) reaches
/// the exact sum's answers on every error ray.
pub const BETA: f32 = 3.0;
/// Triangles per BVH leaf.
const MAX_LEAF: u32 = 4;

/// An immutable triangle mesh solid, shared by all its instances.
#[derive(Debug)]
pub struct MeshData {
    /// Triangle corners, in BVH leaf order (slot order).
    tris: Vec<[Vec3; 3]>,
    /// Unit normals per slot (by the corners' winding), made once: shading
    /// asked for one per hit.
    normals: Vec<Vec3>,
    /// Slot -> triangle index in the input list.
    tri_id: Vec<u32>,
    /// BVH over slots (`prims` is the identity); used by the winding number.
    bvh: FlatBvh,
    /// The same tree for ray traversal: sibling pairs in one 64-byte line each.
    pairs: Vec<NodePair>,
    /// Root node (`first` = its pair when inner).
    root: BvhNode,
    /// The same tree collapsed to 4 children per node, with SoA triangle blocks:
    /// what `closest_hit` and the crossing walk traverse.
    wide: wide::Wide,
    /// Per BVH node (Winding rule only).
    dipoles: Vec<Dipole>,
    /// Far-field acceptance ratio (f32 bits; [`BETA`] unless set by
    /// [`MeshData::set_far_field`]). Atomic because the mesh is shared
    /// (`Arc`) by the scenes that use it, and only a bake sets it.
    beta: std::sync::atomic::AtomicU32,
    rule: InsideRule,
    /// +1, or -1 when an inside-out mesh was flipped.
    orient: f32,
    bounds: Aabb,
    warnings: Vec<String>,
    report: MeshReport,
}

/// The two children of an inner node, in one cache line. Ray traversal is bound
/// by node fetches (measured: ~30% of closest_hit time on the first load of a node
/// box); obvhs puts sibling pairs at odd indices, so with 32-byte nodes every pair
/// straddled two lines. An inner child's `first` is its own children's pair.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct NodePair([BvhNode; 2]);

/// Re-lays the flat BVH as sibling pairs, depth first.
fn build_pairs(nodes: &[BvhNode]) -> (Vec<NodePair>, BvhNode) {
    let empty = BvhNode { min: Vec3::ZERO, first: 0, max: Vec3::ZERO, count: 0 };
    let Some(&root) = nodes.first() else { return (vec![], BvhNode { count: 0, ..empty }) };
    if root.count > 0 {
        return (vec![], root);
    }
    let mut pairs = vec![NodePair([empty; 2])];
    let mut stack = vec![(0usize, 0usize)]; // (old inner node, its pair)
    while let Some((old, pi)) = stack.pop() {
        let f = nodes[old].first as usize;
        for k in 0..2 {
            let mut c = nodes[f + k];
            if c.count == 0 {
                let np = pairs.len();
                pairs.push(NodePair([empty; 2]));
                stack.push((f + k, np));
                c.first = np as u32;
            }
            pairs[pi].0[k] = c;
        }
    }
    (pairs, BvhNode { first: 0, ..root })
}

/// One signed crossing of a ray with the surface.
#[derive(Clone, Copy, Debug)]
struct Crossing {
    t: f32,
    slot: u32,
    /// The triangle's geometric normal points against the ray (det > 0 in Woop's test).
    front: bool,
}

/// What [`MeshData::walk_signed`] needs besides the crossings: the (local)
/// ray, the range it clips to and the leaf id its surfaces carry.
#[derive(Clone, Copy)]
struct Walk {
    /// The exact line (`refine` works on it).
    x: Line64,
    /// 0 where the f32 ray is the line, else its origin's largest
    /// coordinate (how far the rounding may have moved the f32 ray).
    far: f64,
    tmin: f32,
    tmax: f32,
    leaf: u32,
}

/// The exact line of a ray in the mesh's frame, `o + t d` in f64: the f32
/// ray the walks trace is this line rounded (a mesh under a transform is
/// given its rays through an f64 map, rounded once).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line64 {
    /// Origin.
    pub o: DVec3,
    /// Direction.
    pub d: DVec3,
    /// The f32 ray traced may be a rounding of this line (else it is the
    /// line itself).
    pub rounded: bool,
}

impl Line64 {
    /// The line of an f32 ray (exact).
    #[inline(always)]
    pub fn of(o: Vec3, d: Vec3) -> Line64 {
        Line64 { o: o.as_dvec3(), d: d.as_dvec3(), rounded: false }
    }
}

impl Walk {
    #[inline(always)]
    fn new(x: Line64, tmin: f32, tmax: f32, leaf: u32) -> Walk {
        let far = if x.rounded { x.o.abs().max_element() } else { 0.0 };
        Walk { x, far, tmin, tmax, leaf }
    }
}

/// Per-ray constants of the watertight test.
#[derive(Clone, Copy)]
struct WoopRay {
    o: Vec3,
    k: [usize; 3],
    s: [f32; 3],
    /// The exact line (the f64 test's and `refine`'s).
    x: Line64,
    /// The error bound's coefficients ([`wide::TriBlock::bound`]): larger
    /// where the f32 ray is a rounding of `x`.
    k1: f32,
    k0: f32,
}

impl WoopRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> WoopRay {
        WoopRay::on(o, d, Line64::of(o, d))
    }

    /// The constants of the f32 ray `(o, d)`, a rounding of the line `x`.
    #[inline(always)]
    fn on(o: Vec3, d: Vec3, x: Line64) -> WoopRay {
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keeps the projected frame's handedness, so det's sign means the same for every ray.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        // A rounded ray moves each projected corner by up to 2 u |o|_inf
        // (the origin) and 2 u M (the shears): see `TriBlock::bound`.
        let (k1, k0) = if x.rounded { (wide::K1_ROUNDED, wide::K0_ROUNDED * o.abs().max_element()) } else { (wide::K1, 0.0) };
        WoopRay { o, k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]], x, k1, k0 }
    }
}

/// Eight rays from one origin for [`MeshData::spans_nearest8`] (camera rays
/// through neighbouring pixels): directions, ranges and per-ray slacks.
#[derive(Clone, Copy, Debug)]
pub struct NearestRays8<'a> {
    /// The common origin.
    pub o: Vec3,
    /// Directions (t is in their units).
    pub d: &'a [Vec3; 8],
    /// Start of each ray's range.
    pub tmin: &'a [f32; 8],
    /// End of each ray's range.
    pub tmax: &'a [f32; 8],
    /// How far past its nearest crossing each ray's walk keeps collecting.
    pub slack: &'a [f32; 8],
    /// Per ray `[a, b]`: a nearest crossing within it keeps the ray's walk
    /// collecting up to `b` (a CSG difference whose subtrahend covers `[a, b]`
    /// needs the crossings up to where it ends); empty (`a > b`) for none.
    pub through: &'a [[f32; 2]; 8],
    /// The exact lines the f32 rays round (common origin, directions), for
    /// a mesh under a transform (see [`MeshData::spans_on`]); `None`: the
    /// f32 rays are exact.
    pub exact: Option<(DVec3, &'a [DVec3; 8])>,
}

/// No [`NearestRays8::through`] intervals.
pub const NO_THROUGH: [[f32; 2]; 8] = [[f32::INFINITY, f32::NEG_INFINITY]; 8];

/// Per-ray constants of the conservative slab test.
#[derive(Clone, Copy)]
struct RayBox {
    o: Vec3,
    inv: Vec3,
    /// Some direction component is exactly zero (its slab parameters may be NaN).
    zero: bool,
}

/// Relative slack of the slab test: each slab parameter carries a few ulps of
/// rounding, and a ray through a box corner (a mesh vertex) must not miss the box
/// of the triangle that owns the crossing there.
pub(crate) const SLAB_EPS: f32 = 1e-6;

/// Traversal stack entries of the fixed-size walks (a 4-wide tree pushes at most
/// three per level).
const STACK: usize = 64;

/// The stack of the single-ray front-to-back walks (`closest_hit`,
/// `spans_nearest`): a plain array (SmallVec's checks were 18% of the nearest
/// walk on `scenes/bunny`, callgrind) of `(child code, entry parameter)`.
struct OrderedStack {
    items: [MaybeUninit<(u32, f32)>; STACK],
    len: usize,
}

impl OrderedStack {
    #[inline(always)]
    fn new() -> Self {
        OrderedStack { items: [const { MaybeUninit::uninit() }; STACK], len: 0 }
    }

    /// The children `m` (not empty) of `n` that the ray meets, entering at `tn`:
    /// returns the nearest and pushes the others far first, without branching
    /// on which were hit. `Err` when they might not fit (a degenerate tree
    /// deeper than the stack).
    #[inline(always)]
    fn descend(&mut self, n: &wide::Node4, m: u32, tn: Vec4) -> Result<(u32, f32), ()> {
        debug_assert!(m & 0xf != 0);
        if m & (m - 1) == 0 {
            let s = m.trailing_zeros();
            return Ok((n.child(s), tn[s as usize]));
        }
        let (order, ne) = wide::order4(tn.to_array(), m);
        if self.len + 3 > STACK {
            return Err(());
        }
        // The writes past `ne - 1` are scratch above the new top.
        for i in 0..3 {
            let s = order[(ne - 1).saturating_sub(i)];
            self.items[self.len + i].write((n.child(s), tn[s as usize]));
        }
        self.len += ne - 1;
        Ok((n.child(order[0]), tn[order[0] as usize]))
    }

    /// The next pushed child whose entry is not past `limit` (boxes beyond it are
    /// dropped), or `None` when the walk is over.
    #[inline(always)]
    fn pop_within(&mut self, limit: f32) -> Option<(u32, f32)> {
        while self.len > 0 {
            self.len -= 1;
            // SAFETY: slots below `len` were written when pushed.
            let (c, t) = unsafe { self.items[self.len].assume_init() };
            if t - t.abs() * SLAB_EPS <= limit {
                return Some((c, t));
            }
        }
        None
    }
}

impl RayBox {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> RayBox {
        RayBox { o, inv: d.recip(), zero: d.cmpeq(Vec3::ZERO).any() }
    }

    /// Entry parameter of the ray into the node's box within `[tlo, thi]`, conservatively.
    #[inline(always)]
    fn hit(&self, n: &BvhNode, tlo: f32, thi: f32) -> Option<f32> {
        self.range(n, tlo, thi).map(|r| r.0)
    }

    /// Parameter range of the ray in the node's box within `[tlo, thi]` (exact
    /// slab values; the acceptance test is conservative).
    #[inline(always)]
    fn range(&self, n: &BvhNode, tlo: f32, thi: f32) -> Option<(f32, f32)> {
        let mut t1 = (n.min - self.o) * self.inv;
        let mut t2 = (n.max - self.o) * self.inv;
        if self.zero {
            // 0 * inf: the origin lies on the slab plane of a parallel ray, which is
            // inside the slab for every t (f32::min would make it a miss).
            t1 = Vec3::select(t1.is_nan_mask(), Vec3::NEG_INFINITY, t1);
            t2 = Vec3::select(t2.is_nan_mask(), Vec3::INFINITY, t2);
        }
        let t0 = t1.min(t2).max_element().max(tlo);
        let t1 = t1.max(t2).min_element().min(thi);
        if t0 - t0.abs() * SLAB_EPS <= t1 + t1.abs() * SLAB_EPS {
            Some((t0, t1))
        } else {
            None
        }
    }
}

/// Does a triangle own an edge its point lies exactly on? `(dx, dy)` is the edge
/// direction in the projected plane, in the triangle's cyclic order; `det` the
/// triangle's determinant (its interior is to the left of the edge when `det < 0`).
/// Equivalent to shifting the point by an infinitesimal `(-1, eps)`.
#[inline(always)]
fn owns_edge(dx: f64, dy: f64, det: f64) -> bool {
    let upward = dy > 0.0 || (dy == 0.0 && dx > 0.0);
    upward == (det < 0.0)
}

/// Watertight ray/triangle test (Woop, Benthin, Wald 2013) as the mesh
/// walks make it, for one triangle: the f32 test where its decision is
/// certain (see [`wide::TriBlock::bound`]; `ball` bounds the corners of the
/// triangle's block), else [`intersect64`]. Returns `(t, det > 0)` for `t`
/// in `[tlo, thi]`. The same bits as the lane of the block test.
#[inline]
fn intersect_in(r: &WoopRay, tri: &[Vec3; 3], ball: [f32; 4], tlo: f32, thi: f32) -> Option<(f32, bool)> {
    let blk = wide::TriBlock::single(tri, ball);
    let b = blk.test(&wide::TriRay4::new(r), tlo, thi);
    if b.unsure != 0 {
        return intersect64(r, tri, tlo, thi);
    }
    (b.hits != 0).then(|| (b.t.x, b.det.x > 0.0))
}

/// Where a nearest-mode walk may stop once it has met a crossing at `t`:
/// `slack` past it, and past `t` at least. Every nearest walk of a mesh
/// (one ray, a packet from one origin, a packet with one direction) cuts
/// there, and a CSG union's nearest query cuts its first entry there too
/// (`rothray_csg`'s `entry_stop`): the same bits, so a packet's answer is
/// the ray's own.
#[inline(always)]
pub fn stop_past(t: f32, slack: f32) -> f32 {
    (t + slack).max(t.next_up())
}

/// [`intersect_in`] for a triangle alone (its own ball).
#[cfg(test)]
fn intersect(r: &WoopRay, tri: &[Vec3; 3], tlo: f32, thi: f32) -> Option<(f32, bool)> {
    intersect_in(r, tri, wide::block_ball(std::slice::from_ref(tri)), tlo, thi)
}

/// The watertight test in f64, for the triangles the f32 test cannot
/// decide: a ray that passes within that test's resolution (~1e-6 of its
/// distance) of an edge line, or runs nearly in a face's plane (the f32
/// decisions there made whole spans appear or vanish: tests/stress_grazing.rs).
/// The corners relative to the origin are exact in f64; the shear, edge
/// functions and t are rounded to f64, the same way for every triangle that
/// shares an edge, so the decisions stay watertight among themselves, and
/// exact zeros are resolved by the tie-breaking rule. Its decisions agree
/// with the f32 test's certain ones (those hold by a margin of ~1e-6 of the
/// distance, this test's error is ~1e-15 of it).
#[inline(never)]
fn intersect64(r: &WoopRay, tri: &[Vec3; 3], tlo: f32, thi: f32) -> Option<(f32, bool)> {
    let [kx, ky, kz] = r.k;
    let (o, d) = (r.x.o, r.x.d);
    let (sx, sy) = (d[kx] / d[kz], d[ky] / d[kz]);
    let a = tri[0].as_dvec3() - o;
    let b = tri[1].as_dvec3() - o;
    let c = tri[2].as_dvec3() - o;
    let ax = a[kx] - sx * a[kz];
    let ay = a[ky] - sy * a[kz];
    let bx = b[kx] - sx * b[kz];
    let by = b[ky] - sy * b[kz];
    let cx = c[kx] - sx * c[kz];
    let cy = c[ky] - sy * c[kz];
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    if (u == 0.0 && !owns_edge(cx - bx, cy - by, det))
        || (v == 0.0 && !owns_edge(ax - cx, ay - cy, det))
        || (w == 0.0 && !owns_edge(bx - ax, by - ay, det))
    {
        return None;
    }
    let t = ((u * a[kz] + v * b[kz] + w * c[kz]) / (det * d[kz])) as f32;
    if t >= tlo && t <= thi {
        Some((t, det > 0.0))
    } else {
        None
    }
}

/// Solid angle of triangle `(a, b, c)` seen from the origin (Van Oosterom and
/// Strackee 1983); positive when the triangle's normal (counter-clockwise corners)
/// points away from the origin.
#[inline]
fn solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let la = a.length();
    let lb = b.length();
    let lc = c.length();
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * num.atan2(den)
}

fn key(p: Vec3) -> [u32; 3] {
    // +0.0 and -0.0 are the same point.
    [(p.x + 0.0).to_bits(), (p.y + 0.0).to_bits(), (p.z + 0.0).to_bits()]
}

impl MeshData {
    /// Validates the triangles, welds exactly coincident vertices, analyses the
    /// topology, picks the inside rule (Orientation falls back to Winding, with a
    /// warning, when the mesh is open or inconsistently oriented) and builds the BVH.
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>, rule: InsideRule) -> Result<MeshData, MeshError> {
        if positions.is_empty() || triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        let nv = positions.len();
        for (i, t) in triangles.iter().enumerate() {
            for &k in t {
                if k as usize >= nv {
                    return Err(MeshError::IndexOutOfRange { triangle: i, index: k, vertices: nv });
                }
            }
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinite { vertex: i });
        }
        let mut warnings = Vec::new();

        // Weld exact duplicates: files split vertices at UV seams and normal creases,
        // which would make a closed surface look open.
        let mut remap = Vec::with_capacity(nv);
        let mut pos: Vec<Vec3> = Vec::with_capacity(nv);
        {
            let mut seen: HashMap<[u32; 3], u32> = HashMap::with_capacity(nv);
            for p in &positions {
                let id = *seen.entry(key(*p)).or_insert_with(|| {
                    pos.push(*p);
                    pos.len() as u32 - 1
                });
                remap.push(id);
            }
        }
        let mut tris_idx: Vec<[u32; 3]> = Vec::with_capacity(triangles.len());
        let mut ids: Vec<u32> = Vec::with_capacity(triangles.len());
        let mut dropped = 0usize;
        for (i, t) in triangles.iter().enumerate() {
            let t = [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]];
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                dropped += 1;
                continue;
            }
            tris_idx.push(t);
            ids.push(i as u32);
        }
        if dropped > 0 {
            warnings.push(format!("{dropped} degenerate triangles (a repeated vertex) were dropped"));
        }
        if tris_idx.is_empty() {
            return Err(MeshError::Empty);
        }

        let mut bounds = Aabb::EMPTY;
        for t in &tris_idx {
            for &k in t {
                bounds.grow(pos[k as usize]);
            }
        }
        let ext = bounds.max - bounds.min;
        if ext.min_element() <= 0.0 {
            return Err(MeshError::NoVolume(format!(
                "all triangles lie in an axis plane (bounds {:?} .. {:?})",
                bounds.min.to_array(),
                bounds.max.to_array()
            )));
        }

        // Flat (in any plane, not only an axis plane): nothing inside, even by winding number.
        {
            let (mut best, mut bn, mut bp) = (0.0f64, DVec3::ZERO, DVec3::ZERO);
            for t in &tris_idx {
                let a = pos[t[0] as usize].as_dvec3();
                let n = (pos[t[1] as usize].as_dvec3() - a).cross(pos[t[2] as usize].as_dvec3() - a);
                if n.length_squared() > best {
                    (best, bn, bp) = (n.length_squared(), n.normalize(), a);
                }
            }
            let tol = 1e-6 * ext.length() as f64;
            if best > 0.0 && tris_idx.iter().all(|t| t.iter().all(|&k| bn.dot(pos[k as usize].as_dvec3() - bp).abs() <= tol)) {
                return Err(MeshError::NoVolume("all triangles lie in one plane".into()));
            }
        }

        // Topology: sort the 3n directed edges by their undirected key.
        let mut edges: Vec<(u64, bool)> = Vec::with_capacity(tris_idx.len() * 3);
        for t in &tris_idx {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                let (lo, hi, fwd) = if a < b { (a, b, true) } else { (b, a, false) };
                edges.push(((lo as u64) << 32 | hi as u64, fwd));
            }
        }
        edges.sort_unstable_by_key(|e| e.0);
        let (mut boundary, mut non_manifold, mut consistent, mut closed) = (0usize, 0usize, true, true);
        let mut i = 0;
        while i < edges.len() {
            let mut j = i;
            let mut fwd = 0usize;
            while j < edges.len() && edges[j].0 == edges[i].0 {
                fwd += edges[j].1 as usize;
                j += 1;
            }
            let n = j - i;
            match n {
                1 => boundary += 1,
                2 => consistent &= fwd == 1,
                _ => non_manifold += 1,
            }
            closed &= 2 * fwd == n;
            i = j;
        }

        // Signed volume and area, about the box centre (f64) for precision.
        let c = bounds.center().as_dvec3();
        let (mut vol, mut area) = (0.0f64, 0.0f64);
        for t in &tris_idx {
            let a = pos[t[0] as usize].as_dvec3() - c;
            let b = pos[t[1] as usize].as_dvec3() - c;
            let d = pos[t[2] as usize].as_dvec3() - c;
            vol += a.dot(b.cross(d)) / 6.0;
            area += (b - a).cross(d - a).length() * 0.5;
        }
        if !(area > 0.0) {
            return Err(MeshError::NoVolume("every triangle has zero area".into()));
        }
        let box_vol = ext.as_dvec3().element_product();
        let has_volume = vol.abs() > 1e-9 * box_vol;
        let mut orient = 1.0f32;
        let mut eff = rule;
        if rule == InsideRule::Orientation {
            if !closed {
                eff = InsideRule::Winding;
                warnings.push(format!(
                    "mesh is not closed and consistently oriented ({boundary} boundary edges, {non_manifold} non-manifold edges, consistently oriented: {consistent}); using the generalized winding number instead"
                ));
            } else if !has_volume {
                return Err(MeshError::NoVolume(format!("closed surface with volume {vol:e}")));
            }
        }
        if vol < 0.0 && has_volume {
            orient = -1.0;
            warnings.push(format!("mesh is inside out (signed volume {vol:e}); its orientation was flipped"));
        }

        // BVH, then the triangles in leaf order.
        let boxes: Vec<Aabb> = tris_idx
            .iter()
            .map(|t| {
                let mut b = Aabb::EMPTY;
                for &k in t {
                    b.grow(pos[k as usize]);
                }
                b
            })
            .collect();
        let mut bvh = FlatBvh::build_binary(&boxes, MAX_LEAF);
        let tris: Vec<[Vec3; 3]> = bvh
            .prims
            .iter()
            .map(|&p| {
                let t = tris_idx[p as usize];
                [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]]
            })
            .collect();
        let tri_id: Vec<u32> = bvh.prims.iter().map(|&p| ids[p as usize]).collect();
        for (k, p) in bvh.prims.iter_mut().enumerate() {
            *p = k as u32;
        }
        let (pairs, root) = build_pairs(&bvh.nodes);
        let wide = wide::Wide::build(&bvh.nodes, &tris);
        let normals = tris.iter().map(|t| (t[1] - t[0]).cross(t[2] - t[0]).normalize_or(Vec3::Y)).collect();
        let mut m = MeshData {
            wide,
            tris,
            normals,
            tri_id,
            bvh,
            pairs,
            root,
            dipoles: Vec::new(),
            beta: std::sync::atomic::AtomicU32::new(BETA.to_bits()),
            rule: eff,
            orient,
            bounds,
            warnings: Vec::new(),
            report: MeshReport {
                triangles: tris_idx.len(),
                vertices: pos.len(),
                bounds,
                boundary_edges: boundary,
                non_manifold_edges: non_manifold,
                consistently_oriented: consistent,
                closed,
                self_intersections: None,
                volume: vol,
                area,
                usable_as_solid: closed && has_volume,
                rule: eff,
                warnings: Vec::new(),
            },
        };
        m.build_dipoles();
        m.warnings = warnings.clone();
        m.report.warnings = warnings;
        Ok(m)
    }

    fn build_dipoles(&mut self) {
        let n = self.bvh.nodes.len();
        self.dipoles = vec![Dipole { p: Vec3::ZERO, n: Vec3::ZERO, r2: 0.0 }; n];
        if n == 0 {
            return;
        }
        // Post-order over an explicit stack (children follow their parent in obvhs' layout,
        // but do not rely on it).
        let mut stack: Vec<(u32, bool)> = vec![(0, false)];
        let mut acc: Vec<(DVec3, DVec3, f64)> = vec![(DVec3::ZERO, DVec3::ZERO, 0.0); n]; // sum(area*centroid), sum(area vec), sum(area)
        while let Some((ni, done)) = stack.pop() {
            let node = self.bvh.nodes[ni as usize];
            if node.count > 0 {
                let (mut pc, mut nv, mut aw) = (DVec3::ZERO, DVec3::ZERO, 0.0);
                for k in node.first..node.first + node.count {
                    let t = self.tris[k as usize];
                    let (a, b, c) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
                    let av = (b - a).cross(c - a) * 0.5;
                    let ar = av.length();
                    pc += (a + b + c) / 3.0 * ar;
                    nv += av;
                    aw += ar;
                }
                acc[ni as usize] = (pc, nv, aw);
            } else if !done {
                stack.push((ni, true));
                stack.push((node.first, false));
                stack.push((node.first + 1, false));
            } else {
                let a = acc[node.first as usize];
                let b = acc[node.first as usize + 1];
                acc[ni as usize] = (a.0 + b.0, a.1 + b.1, a.2 + b.2);
            }
        }
        // Centroids, then radii over each node's triangles' corners (exact, via leaf ranges).
        for ni in 0..n {
            let (pc, nv, aw) = acc[ni];
            let node = self.bvh.nodes[ni];
            let center = Vec3::new(node.min.x + node.max.x, node.min.y + node.max.y, node.min.z + node.max.z) * 0.5;
            let p = if aw > 0.0 { (pc / aw).as_vec3() } else { center };
            // The farthest box corner bounds the distance to every corner of the node's triangles.
            let r = (p - node.min).abs().max((p - node.max).abs()).length();
            self.dipoles[ni] = Dipole { p, n: nv.as_vec3(), r2: r * r };
        }
    }

    /// Warnings raised while building (fallback to the winding rule, dropped triangles...).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Bounds in the mesh's own space.
    pub fn local_bounds(&self) -> Aabb {
        self.bounds
    }

    /// The rule in effect (may differ from the one asked for).
    pub fn rule(&self) -> InsideRule {
        self.rule
    }

    /// Number of triangles kept.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// The input triangle index of a crossing's `sub` (as reported in [`Surf::sub`]).
    /// `None` for [`SUB_BOX`].
    pub fn triangle_id(&self, sub: u32) -> Option<u32> {
        self.tri_id.get((sub & !SUB_FLIP) as usize).copied()
    }

    /// Calls `f` for every triangle crossing in `[tlo, thi]`, in no particular order.
    #[inline]
    fn for_each_crossing(&self, (o, d, x): (Vec3, Vec3, Line64), tlo: f32, thi: f32, mut f: impl FnMut(Crossing)) {
        if self.wide.is_empty() {
            return;
        }
        let r = WoopRay::on(o, d, x);
        let r4 = wide::TriRay4::new(&r);
        let rb = wide::Ray4::new(o, d);
        // All hits: no ordering, no pruning. A plain array for the stack
        // (SmallVec's checks on every push and pop were ~3% of the lit
        // bunny's and mesh_mold's instructions, callgrind), spilling to the heap only for a
        // tree deeper than it holds; the child met last is visited at once
        // (the order a push of every child then a pop gives).
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        let mut spill: Vec<u32> = Vec::new();
        let mut cur = 0u32;
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                let b = blk.test(&r4, tlo, thi);
                self.block_crossings(blk, &b, &r, (tlo, thi), &mut f);
            } else {
                let n = self.wide.node(cur);
                let (mut m, _) = rb.hit(n, tlo, thi);
                if m != 0 {
                    while m & (m - 1) != 0 {
                        let c = n.child(m.trailing_zeros());
                        m &= m - 1;
                        if sp < STACK {
                            stack[sp] = c;
                            sp += 1;
                        } else {
                            spill.push(c);
                        }
                    }
                    cur = n.child(m.trailing_zeros());
                    continue;
                }
            }
            if sp > 0 {
                sp -= 1;
                cur = stack[sp];
            } else if let Some(c) = spill.pop() {
                cur = c;
            } else {
                return;
            }
        }
    }

    /// The crossings of one block test `b` (of `blk`, for the ray `r` on
    /// `[tlo, thi]`): the certain hits lane by lane, then the f64 test's
    /// answers for the undecided lanes (the order every walk keeps).
    #[inline(always)]
    fn block_crossings(&self, blk: &wide::TriBlock, b: &wide::Block, r: &WoopRay, (tlo, thi): (f32, f32), f: &mut impl FnMut(Crossing)) {
        let mut m = b.hits;
        while m != 0 {
            let l = m.trailing_zeros();
            m &= m - 1;
            f(Crossing { t: b.t[l as usize], slot: blk.slots().start + l, front: b.det[l as usize] > 0.0 });
        }
        let mut m = b.unsure;
        while m != 0 {
            let slot = blk.slots().start + m.trailing_zeros();
            m &= m - 1;
            if let Some((t, front)) = wide::TriBlock::exact(&self.tris, slot, r, tlo, thi) {
                f(Crossing { t, slot, front });
            }
        }
    }

    /// Every crossing of the line with the triangles in `[tlo, thi]`: `(t, sub,
    /// facing)`, sorted by `t`; `facing` is +1 when the triangle's geometric normal
    /// points against the ray. For tests and diagnostics (allocates).
    pub fn crossings(&self, o: Vec3, d: Vec3, tlo: f32, thi: f32) -> Vec<(f32, u32, i32)> {
        let mut v = Vec::new();
        self.for_each_crossing((o, d, Line64::of(o, d)), tlo, thi, |c| v.push((c.t, c.slot, if c.front { 1 } else { -1 })));
        // Entering first on ties (a ray grazing an edge touches it in and out at one t).
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.2.cmp(&a.2)));
        v
    }

    /// The nearest triangle crossing in `[tmin, tmax]`: `(t, sub)` (`sub` as in spans,
    /// without the facing flag). For a closed mesh that is not self-intersecting this
    /// is where the ray first meets the solid's surface. Prunes the BVH as it goes.
    pub fn closest_hit(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, u32)> {
        if self.wide.is_empty() || !(tmax >= tmin) {
            return None;
        }
        let r = WoopRay::new(o, d);
        let r4 = wide::TriRay4::new(&r);
        let rb = wide::Ray4::new(o, d);
        let mut best: Option<(f32, u32)> = None;
        let mut thi = tmax;
        // Front to back: the nearest hit child is visited next, the others pushed
        // far first; popped entries beyond the best hit so far are skipped.
        let mut stack = OrderedStack::new();
        let mut cur = 0u32;
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                self.leaf_nearest(blk, (&r, &r4), tmin, &mut thi, &mut best);
            } else {
                let n = self.wide.node(cur);
                let (m, tn) = rb.hit(n, tmin, thi);
                if m != 0 {
                    match stack.descend(n, m, tn) {
                        Ok((c, _)) => {
                            cur = c;
                            continue;
                        }
                        // A degenerate tree deeper than the stack: the binary walk.
                        Err(()) => return self.closest_hit_pairs(o, d, tmin, tmax),
                    }
                }
            }
            match stack.pop_within(thi) {
                Some((c, _)) => cur = c,
                None => return best,
            }
        }
    }

    /// The nearest hit of one ray in one leaf block within `[tmin, *thi]`: a hit
    /// at `t <= *thi` becomes `best` and the new `*thi` (so on equal `t` the
    /// later triangle wins, in every walk alike).
    #[inline(always)]
    fn leaf_nearest(
        &self,
        blk: &wide::TriBlock,
        (r, r4): (&WoopRay, &wide::TriRay4),
        tmin: f32,
        thi: &mut f32,
        best: &mut Option<(f32, u32)>,
    ) {
        match blk.nearest(r4, tmin, *thi) {
            wide::Near::Miss => {}
            wide::Near::Hit(t, l) => {
                if t <= *thi {
                    *thi = t;
                    *best = Some((t, blk.slots().start + l));
                }
            }
            wide::Near::Unsure(b) => {
                // The lanes in order, on the range the block was tested on:
                // the nearest, the last of equals (as `Hit`).
                let t0 = *thi;
                self.block_crossings(blk, &b, r, (tmin, t0), &mut |c: Crossing| {
                    if c.t <= *thi {
                        *thi = c.t;
                        *best = Some((c.t, c.slot));
                    }
                });
            }
        }
    }

    /// Shape of the traversal tree (for benchmarks).
    #[doc(hidden)]
    pub fn bvh_stats(&self) -> String {
        self.wide.stats()
    }

    /// The binary pair walk `closest_hit` used before the 4-wide tree (kept for
    /// the before/after benchmark and as a test oracle).
    #[doc(hidden)]
    pub fn closest_hit_pairs(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<(f32, u32)> {
        let r = WoopRay::new(o, d);
        let rb = RayBox::new(o, d);
        let mut best: Option<(f32, u32)> = None;
        let mut thi = tmax;
        let mut leaf = |n: &BvhNode, thi: &mut f32| {
            // The ball of the leaf's block (the same leaves: see `wide::Wide::build`).
            let ball = wide::block_ball(&self.tris[n.first as usize..(n.first + n.count) as usize]);
            let t0 = *thi;
            for slot in n.first..n.first + n.count {
                if let Some((t, _)) = intersect_in(&r, &self.tris[slot as usize], ball, tmin, t0) {
                    if t <= *thi {
                        best = Some((t, slot));
                        *thi = t;
                    }
                }
            }
        };
        if self.tris.is_empty() {
            return None;
        }
        let t_root = rb.hit(&self.root, tmin, thi)?;
        if self.root.count > 0 {
            leaf(&self.root, &mut thi);
            return best;
        }
        // Front to back; leaves are tested as soon as their box is hit (nearer one
        // first), inner nodes are pushed far first, and entries beyond the best hit
        // so far are skipped when popped.
        let mut stack: SmallVec<[(u32, f32); 64]> = SmallVec::new();
        stack.push((0, t_root));
        while let Some((pi, tenter)) = stack.pop() {
            if tenter - tenter.abs() * SLAB_EPS > thi {
                continue;
            }
            let [a, b] = &self.pairs[pi as usize].0;
            let ha = rb.hit(a, tmin, thi);
            let hb = rb.hit(b, tmin, thi);
            let (near, far, hn, hf) = match (ha, hb) {
                (Some(ta), Some(tb)) if tb < ta => (b, a, hb, ha),
                _ => (a, b, ha, hb),
            };
            if let Some(t) = hn {
                if near.count > 0 {
                    leaf(near, &mut thi);
                } else if hf.is_none() || far.count > 0 {
                    stack.push((near.first, t));
                }
            }
            if let Some(t) = hf {
                if far.count > 0 {
                    if t - t.abs() * SLAB_EPS <= thi {
                        leaf(far, &mut thi);
                    }
                } else {
                    stack.push((far.first, t));
                }
            }
            // both inner: the far one was pushed above, push the near one last (popped first)
            if let (Some(t), Some(_)) = (hn, hf) {
                if near.count == 0 && far.count == 0 {
                    stack.push((near.first, t));
                }
            }
        }
        best
    }

    /// [`closest_hit`](Self::closest_hit) for a bundle of 8 rays, traversed
    /// together when they share a direction octant (coherent camera rays): each
    /// node is fetched once for the bundle and its four boxes are tested against
    /// all eight rays; leaves test each ray that reached them. Otherwise (or
    /// when a direction component is zero) the rays go one by one. Where the CPU
    /// has AVX the node test runs 8 rays per step (chosen at run time; same
    /// answers as the SSE2 walk, [`closest_hit8_sse`](Self::closest_hit8_sse)).
    pub fn closest_hit8(&self, o: &[Vec3; 8], d: &[Vec3; 8], tmin: &[f32; 8], tmax: &[f32; 8]) -> [Option<(f32, u32)>; 8] {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.closest_hit8_avx(o, d, tmin, tmax) };
        }
        self.closest_hit8_in::<false>(o, d, tmin, tmax)
    }

    /// [`closest_hit8`](Self::closest_hit8) without the AVX node test (the
    /// baseline SSE2 path, which machines without AVX take), for tests and
    /// benchmarks: both give the same answers.
    #[doc(hidden)]
    pub fn closest_hit8_sse(&self, o: &[Vec3; 8], d: &[Vec3; 8], tmin: &[f32; 8], tmax: &[f32; 8]) -> [Option<(f32, u32)>; 8] {
        self.closest_hit8_in::<false>(o, d, tmin, tmax)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn closest_hit8_avx(&self, o: &[Vec3; 8], d: &[Vec3; 8], tmin: &[f32; 8], tmax: &[f32; 8]) -> [Option<(f32, u32)>; 8] {
        self.closest_hit8_in::<true>(o, d, tmin, tmax)
    }

    /// The packet walk; `AVX` (only instantiated inside a function compiled
    /// with AVX) tests the nodes with 8-lane ops.
    #[inline(always)]
    fn closest_hit8_in<const AVX: bool>(&self, o: &[Vec3; 8], d: &[Vec3; 8], tmin: &[f32; 8], tmax: &[f32; 8]) -> [Option<(f32, u32)>; 8] {
        let mut best = [None; 8];
        if self.wide.is_empty() {
            return best;
        }
        let Some(p) = wide::Packet8::new(o, d) else {
            return std::array::from_fn(|k| self.closest_hit(o[k], d[k], tmin[k], tmax[k]));
        };
        let tlo = wide::F8(*tmin);
        let mut thi = wide::F8(*tmax);
        let active = thi.ge_mask(&tlo);
        // Each ray's triangle-test constants, set up when it first reaches a leaf
        // (most camera rays miss the mesh and never do).
        let mut rays: [MaybeUninit<(WoopRay, wide::TriRay4)>; 8] = [const { MaybeUninit::uninit() }; 8];
        let mut ready = 0u32;
        // (child code, rays that reached it, their smallest entry parameter)
        let mut stack = [MaybeUninit::<(u32, u32, f32)>::uninit(); STACK];
        let mut sp = 0usize;
        let (mut cur, mut mask) = (0u32, active);
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                let mut mm = mask;
                while mm != 0 {
                    let k = mm.trailing_zeros() as usize;
                    mm &= mm - 1;
                    if ready & (1 << k) == 0 {
                        let r = WoopRay::new(o[k], d[k]);
                        rays[k].write((r, wide::TriRay4::new(&r)));
                        ready |= 1 << k;
                    }
                    // SAFETY: written above (bit k of `ready`).
                    let (r, r4) = unsafe { rays[k].assume_init_ref() };
                    self.leaf_nearest(blk, (r, r4), tmin[k], &mut thi.0[k], &mut best[k]);
                }
            } else {
                let n = self.wide.node(cur);
                #[cfg(target_arch = "x86_64")]
                // SAFETY: AVX is only true in `closest_hit8_avx`, compiled with AVX.
                let h = if AVX { unsafe { p.hit_avx(n, &tlo, &thi) } } else { p.hit(n, &tlo, &thi) };
                #[cfg(not(target_arch = "x86_64"))]
                let h = p.hit(n, &tlo, &thi);
                let mut hm = 0u32;
                for (s, &(m, _)) in h.iter().enumerate() {
                    hm |= ((m & mask != 0) as u32) << s;
                }
                let (order, ne) = wide::order4(h.map(|x| x.1), hm);
                if ne > 0 {
                    if sp + 3 > STACK {
                        // A degenerate tree deeper than the stack: ray by ray.
                        return std::array::from_fn(|k| self.closest_hit(o[k], d[k], tmin[k], tmax[k]));
                    }
                    let entry = |s: u32| (n.child(s), h[s as usize].0 & mask, h[s as usize].1);
                    // Far to near, so the nearest is popped first; the writes past
                    // `ne - 1` are scratch above the new top.
                    for i in 0..3 {
                        stack[sp + i].write(entry(order[(ne - 1).saturating_sub(i)]));
                    }
                    sp += ne - 1;
                    (cur, mask) = (n.child(order[0]), h[order[0] as usize].0 & mask);
                    continue;
                }
            }
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: slots below `sp` were written when pushed.
                let (c, m, t) = unsafe { stack[sp].assume_init() };
                // Rays whose best hit is nearer drop out.
                let m2 = thi.reaching(t) & m;
                if m2 != 0 {
                    (cur, mask) = (c, m2);
                    break;
                }
            }
        }
    }

    /// Pushes the spans of the ray `o + t d` inside the solid, clipped to
    /// `[tmin, tmax]` (sorted, disjoint; clipped ends carry [`Surf::NONE`]). Span ends
    /// carry `Surf { leaf, sub }` with `sub` = triangle slot, `| SUB_FLIP` when the
    /// triangle faces inward there.
    pub fn spans<S: SpanSink + ?Sized>(&self, ray: &Ray, leaf: u32, out: &mut S) {
        self.spans_on(ray, Line64::of(ray.origin, ray.dir), leaf, out)
    }

    /// [`MeshData::spans`] of the f32 ray `ray`, a rounding of the exact line
    /// `x`: the crossings are decided and the ends refined for `x`.
    pub fn spans_on<S: SpanSink + ?Sized>(&self, ray: &Ray, x: Line64, leaf: u32, out: &mut S) {
        let Ray { origin: o, dir: d, tmin, tmax, .. } = *ray;
        if !(tmax >= tmin) {
            return;
        }
        let mut xs: SmallVec<[Crossing; 32]> = SmallVec::new();
        match self.rule {
            InsideRule::Orientation => {
                if self.outside_at(o, d, tmin) {
                    // The count at tmin is zero: only the crossings up to tmax matter.
                    self.for_each_crossing((o, d, x), tmin, tmax, |c| xs.push(c));
                    self.sort_signed(&mut xs);
                    self.walk_signed(&xs, 0, Walk::new(x, tmin, tmax, leaf), out);
                    return;
                }
                // Collect to the box exit: the crossings past tmax tell how deep inside
                // the ray is at tmin (the signed count over the whole line is zero).
                self.for_each_crossing((o, d, x), tmin, f32::INFINITY, |c| xs.push(c));
                self.sort_signed(&mut xs);
                let count: i32 = xs.iter().map(|c| -self.sign(c)).sum();
                self.walk_signed(&xs, count, Walk::new(x, tmin, tmax, leaf), out);
            }
            InsideRule::Winding => {
                let Some(&root) = self.bvh.nodes.first() else { return };
                let Some((lo, hi)) = RayBox::new(o, d).range(&root, tmin, tmax) else { return };
                // [tmin, tmax], not [lo, hi]: the box's slab parameters and a triangle's t
                // round differently; pieces outside [lo, hi] are empty.
                self.for_each_crossing((o, d, x), tmin, tmax, |c| xs.push(c));
                sort_crossings(&mut xs, |_| true);
                let end_surf = |t: f32, clip: f32| {
                    if t == clip {
                        Surf::NONE
                    } else {
                        Surf::new(leaf, SUB_BOX)
                    }
                };
                // Walk the pieces between consecutive crossings (decided by
                // the f32 t; the ends pushed refined as `walk_signed`'s).
                let w = Walk::new(x, tmin, tmax, leaf);
                let mut floor = tmin;
                let mut inside = false;
                let mut start = (lo, end_surf(lo, tmin));
                // (start of the current piece, the crossing there if any)
                let mut prev = (lo, None::<Crossing>);
                let n = xs.len();
                for k in 0..=n {
                    let (t_end, cross) = if k < n { (xs[k].t, Some(xs[k])) } else { (hi, None) };
                    if t_end > prev.0 {
                        // On the f64 line the crossings were decided for:
                        // an f32 midpoint of a grazing piece may round
                        // across the face it runs along.
                        let mid = x.o + x.d * (0.5 * (prev.0 as f64 + t_end as f64));
                        let now = self.winding_number_at(mid) >= 0.5;
                        if now != inside {
                            if now {
                                start = match prev.1 {
                                    Some(c) => (self.refine(&c, &w, floor), self.surf(leaf, &c, true)),
                                    None => (prev.0, end_surf(prev.0, tmin)),
                                };
                            } else {
                                // Never at `lo`: the walk starts outside.
                                let (t1, s1) = match prev.1 {
                                    Some(c) => (self.refine(&c, &w, start.0), self.surf(leaf, &c, false)),
                                    None => (prev.0, Surf::NONE),
                                };
                                push_clipped(out, Span { t0: start.0, s0: start.1, t1, s1 }, tmin, tmax);
                                floor = t1;
                            }
                            inside = now;
                        }
                    }
                    prev = (t_end, cross);
                }
                if inside {
                    push_clipped(out, Span { t0: start.0, s0: start.1, t1: hi, s1: end_surf(hi, tmax) }, tmin, tmax);
                }
            }
        }
    }

    /// +1 where a crossing enters the solid (orientation rule), -1 where it leaves.
    #[inline(always)]
    fn sign(&self, c: &Crossing) -> i32 {
        if c.front == (self.orient > 0.0) {
            1
        } else {
            -1
        }
    }

    /// Sorts crossings by t, entering first on ties (touching pieces merge
    /// instead of splitting).
    #[inline]
    fn sort_signed(&self, xs: &mut [Crossing]) {
        sort_crossings(xs, |c| self.sign(c) > 0);
    }

    /// Spans of sorted signed crossings, given the winding count at
    /// `w.tmin`, clipped to `[w.tmin, w.tmax]`. The crossings are chosen and
    /// ordered by their f32 t; the ends pushed are refined in f64
    /// ([`MeshData::refine`]).
    fn walk_signed<S: SpanSink + ?Sized>(&self, xs: &[Crossing], mut count: i32, w: Walk, out: &mut S) {
        let mut start = (w.tmin, Surf::NONE);
        // The last end pushed: refined ends never go back past it.
        let mut floor = w.tmin;
        for c in xs {
            if c.t > w.tmax {
                break;
            }
            let next = count + self.sign(c);
            if count <= 0 && next > 0 {
                start = (self.refine(c, &w, floor), self.surf(w.leaf, c, true));
            } else if count > 0 && next <= 0 {
                let t1 = self.refine(c, &w, start.0);
                push_clipped(out, Span { t0: start.0, s0: start.1, t1, s1: self.surf(w.leaf, c, false) }, w.tmin, w.tmax);
                floor = t1;
            }
            count = next;
        }
        if count > 0 {
            push_clipped(out, Span { t0: start.0, s0: start.1, t1: w.tmax, s1: Surf::NONE }, w.tmin, w.tmax);
        }
    }

    /// Crossing `c`'s t refined in f64 from its triangle's plane, `n . (v0 -
    /// o) / n . d` with the f32 vertices and ray exact in f64, rounded once,
    /// then clamped to `[lo, w.tmax]` (`lo` at least `w.tmin`, and past `lo`
    /// where the f32 t was): the f32
    /// watertight test works relative to the ray's origin, and put an end
    /// where the ray runs at angle `a` to the face ~1e-8 of the origin's
    /// distance / sin(a) off (tests/stress_data.rs). The clamp keeps the
    /// spans sorted, in range, and no entry past the limit a nearest query
    /// returns; the crossing's f32 t is kept where its plane is parallel to
    /// the ray.
    #[inline]
    fn refine(&self, c: &Crossing, w: &Walk, lo: f32) -> f32 {
        let [a, b, e] = self.tris[c.slot as usize].map(|v| v.as_dvec3());
        let (n, dd) = ((b - a).cross(e - a), w.x.d);
        let den = n.dot(dd);
        let ao = a - w.x.o;
        // No further than the f32 test itself may be off (8 f32 epsilons of
        // the vertex's distance from the origin, and of the origin's own
        // size where the f32 ray is a rounding of the line, stretched by 1 /
        // sin), nor than the triangle's size along the ray: where the ray
        // runs so close to the plane that the test's choice of triangle is
        // itself rounding, the plane's crossing may lie far off the triangle.
        let size = (b - a).abs().max((e - a).abs()).max_element();
        let reach = ao.abs().max_element() + w.far;
        let tol = ((8.0 * f32::EPSILON as f64) * reach * n.abs().element_sum() / den.abs()).min(size / dd.abs().max_element());
        let t = n.dot(ao) / den;
        // (max / min, not clamp: no panic whatever the bounds.)
        let t = if t.is_finite() { t.max(c.t as f64 - tol).min(c.t as f64 + tol) as f32 } else { c.t };
        // Strictly after `lo` where the f32 t was: a span or gap the f32
        // walk kept keeps a positive length.
        let lo = if c.t > lo { lo.next_up() } else { lo };
        t.max(lo.max(w.tmin)).min(w.tmax)
    }

    /// [`MeshData::spans`] for a nearest-hit query: only the first entry is sure to
    /// be reported. The BVH is walked front to back like [`MeshData::closest_hit`],
    /// pruned at `v` = the nearest crossing so far plus `slack` (the caller's fusing
    /// tolerance, in t); every crossing up to `v` is found, so the spans pushed are
    /// exact on `[tmin, v]` (none lies past it) and `v` is returned. Falls back to
    /// the full query (returning infinity) where the count at `tmin` is not known
    /// to be zero (the point at `tmin` inside the bounds) or for the winding rule.
    pub fn spans_nearest<S: SpanSink + ?Sized>(&self, ray: &Ray, slack: f32, leaf: u32, out: &mut S) -> f32 {
        self.spans_nearest_on(ray, Line64::of(ray.origin, ray.dir), slack, leaf, out)
    }

    /// [`MeshData::spans_nearest`] of the f32 ray `ray`, a rounding of the
    /// exact line `x` (as [`MeshData::spans_on`]).
    pub fn spans_nearest_on<S: SpanSink + ?Sized>(&self, ray: &Ray, x: Line64, slack: f32, leaf: u32, out: &mut S) -> f32 {
        let Ray { origin: o, dir: d, tmin, tmax, .. } = *ray;
        if !(tmax >= tmin) || self.wide.is_empty() {
            return f32::INFINITY;
        }
        if self.rule != InsideRule::Orientation || !self.outside_at(o, d, tmin) {
            self.spans_on(ray, x, leaf, out);
            return f32::INFINITY;
        }
        let r = WoopRay::on(o, d, x);
        let r4 = wide::TriRay4::new(&r);
        let rb = wide::Ray4::new(o, d);
        let mut xs: SmallVec<[Crossing; 32]> = SmallVec::new();
        // `cut`: the nearest crossing so far plus the slack (only decreases).
        let mut cut = tmax;
        let mut stack = OrderedStack::new();
        let mut cur = 0u32;
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                let b = blk.test(&r4, tmin, cut);
                self.block_crossings(blk, &b, &r, (tmin, cut), &mut |c: Crossing| {
                    xs.push(c);
                    cut = cut.min(stop_past(c.t, slack));
                });
            } else {
                let n = self.wide.node(cur);
                let (m, tn) = rb.hit(n, tmin, cut);
                if m != 0 {
                    match stack.descend(n, m, tn) {
                        Ok((c, _)) => {
                            cur = c;
                            continue;
                        }
                        Err(()) => {
                            // A degenerate tree deeper than the stack: the unpruned walk.
                            self.spans_on(ray, x, leaf, out);
                            return f32::INFINITY;
                        }
                    }
                }
            }
            match stack.pop_within(cut) {
                Some((c, _)) => cur = c,
                None => {
                    // Crossings found before `cut` shrank may lie past it: not all
                    // of their neighbours were seen.
                    self.sort_signed(&mut xs);
                    self.walk_signed(&xs, 0, Walk::new(x, tmin, cut.min(tmax), leaf), out);
                    return cut;
                }
            }
        }
    }

    /// [`MeshData::spans_nearest`] for eight rays from one origin `o` at once
    /// (camera rays through neighbouring pixels): the BVH is walked once for the
    /// packet with interval bounds of the rays' slab parameters
    /// (`Frustum8`), pruned at the largest cut among the rays, and each
    /// leaf that some ray may still need is tested with that ray alone, within
    /// its own `[tmin, cut]`. Every crossing a ray's own walk would keep is
    /// found, so each ray gets the spans and cut that `spans_nearest` gives it.
    ///
    /// Rays of `active` go in. Returns the rays done (their spans are pushed to
    /// `out[k]`, exact on `[tmin[k], cut[k]]`) and the cuts; the others (no
    /// common octant, a zero direction component, a point at `tmin` inside the
    /// bounds, the winding rule) are left to the single-ray query. Where the
    /// CPU has AVX (chosen at run time) a leaf that three or more rays with the
    /// same projection axes need is tested a triangle at a time against all of
    /// them ([`spans_nearest8_sse`](Self::spans_nearest8_sse) never does; both
    /// give the same answers).
    pub fn spans_nearest8(&self, q: &NearestRays8, active: u32, leaf: u32, out: &mut [Vec<Span>; 8]) -> (u32, [f32; 8]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            return unsafe { self.spans_nearest8_avx(q, active, leaf, out) };
        }
        self.spans_nearest8_in::<false>(q, active, leaf, out)
    }

    /// [`spans_nearest8`](Self::spans_nearest8) without the AVX leaf test (what
    /// CPUs without AVX run), for tests: both give the same answers.
    #[doc(hidden)]
    pub fn spans_nearest8_sse(&self, q: &NearestRays8, active: u32, leaf: u32, out: &mut [Vec<Span>; 8]) -> (u32, [f32; 8]) {
        self.spans_nearest8_in::<false>(q, active, leaf, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn spans_nearest8_avx(&self, q: &NearestRays8, active: u32, leaf: u32, out: &mut [Vec<Span>; 8]) -> (u32, [f32; 8]) {
        self.spans_nearest8_in::<true>(q, active, leaf, out)
    }

    /// The packet walk; with `AVX` (only instantiated inside a function compiled
    /// with AVX) a leaf that three or more rays sharing their projection axes
    /// need is tested one triangle at a time against all of them.
    #[inline(always)]
    fn spans_nearest8_in<const AVX: bool>(
        &self,
        q: &NearestRays8,
        mut active: u32,
        leaf: u32,
        out: &mut [Vec<Span>; 8],
    ) -> (u32, [f32; 8]) {
        let NearestRays8 { o, d, tmin, tmax, slack, through, exact } = *q;
        let line = |k: usize| exact.map_or(Line64::of(o, d[k]), |(xo, xd)| Line64 { o: xo, d: xd[k], rounded: true });
        // Where ray `k`'s walk may stop once it has met a crossing at `t`.
        let stop = |k: usize, t: f32| {
            let c = stop_past(t, slack[k]);
            let [a, b] = through[k];
            if t >= a && t <= b {
                c.max(b)
            } else {
                c
            }
        };
        let mut cut = [f32::INFINITY; 8];
        if self.wide.is_empty() || self.rule != InsideRule::Orientation {
            return (0, cut);
        }
        for k in 0..8 {
            if !(tmax[k] >= tmin[k]) {
                active &= !(1 << k);
            }
        }
        if active == 0 {
            return (0, cut);
        }
        let Some(fr) = wide::Frustum8::new(o, d, active) else { return (0, cut) };
        let mut tlo = f32::INFINITY;
        for k in 0..8 {
            if active & (1 << k) != 0 {
                cut[k] = tmax[k];
                tlo = tlo.min(tmin[k]);
            }
        }
        // The packet's pruning bound: the largest cut among its rays.
        // Branch-free (a select per lane, then a tree of maxima): the filtered
        // fold it replaces was ~2% of this walk's samples.
        let far = |cut: &[f32; 8], active: u32| {
            let c: [f32; 8] = std::array::from_fn(|k| if active & (1 << k) != 0 { cut[k] } else { f32::NEG_INFINITY });
            let m4 = [c[0].max(c[4]), c[1].max(c[5]), c[2].max(c[6]), c[3].max(c[7])];
            m4[0].max(m4[2]).max(m4[1].max(m4[3]))
        };
        let mut thi = far(&cut, active);
        // Most packets of a frame miss the mesh: no ray meets any box of the root
        // within its range, so every ray's answer is exact and empty.
        let (root_mask, root_t) = fr.hit(self.wide.node(0), tlo, thi);
        if root_mask == 0 {
            return (active, cut);
        }
        for k in 0..8 {
            if !self.outside_at(o, d[k], tmin[k]) {
                active &= !(1 << k);
                cut[k] = f32::INFINITY;
            }
        }
        if active == 0 {
            return (0, cut);
        }
        // Per-ray constants of the triangle test, made when a ray first reaches a leaf.
        let mut rays: [MaybeUninit<WoopRay>; 8] = [const { MaybeUninit::uninit() }; 8];
        // Set up on the first leaf: `ready` (the active rays), their shears by
        // axis, whether they share the projection axes `axes`, their starts.
        let mut ready = 0u32;
        let mut shear = [wide::F8([0.0; 8]); 3];
        let mut k10 = [wide::F8([0.0; 8]); 2];
        let mut shared = true;
        let mut axes = [0usize, 1, 2];
        let mut tlo8 = wide::F8([0.0; 8]);
        let mut xs: [SmallVec<[Crossing; 16]>; 8] = Default::default();
        let mut stack = OrderedStack::new();
        // The root's children were tested above.
        let (mut cur, mut entry) = match stack.descend(self.wide.node(0), root_mask, root_t) {
            Ok(c) => c,
            Err(()) => return (0, [f32::INFINITY; 8]),
        };
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                let te = entry - entry.abs() * SLAB_EPS;
                // `entry` bounds every ray's own entry into this leaf's box from below.
                let mut need = 0u32;
                for (k, &c) in cut.iter().enumerate() {
                    need |= ((te <= c) as u32) << k;
                }
                need &= active;
                if ready == 0 && need != 0 {
                    // First leaf: every active ray's triangle-test constants, and
                    // whether they share their projection axes (coherent rays do).
                    let mut m = active;
                    let mut k0 = None;
                    while m != 0 {
                        let k = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let r = WoopRay::on(o, d[k], line(k));
                        for a in 0..3 {
                            shear[a].0[k] = r.s[a];
                        }
                        (k10[0].0[k], k10[1].0[k]) = (r.k1, r.k0);
                        // Compared as one small code: comparing the arrays loaded
                        // them back wider than they were just stored (a
                        // store-forwarding stall, ~5% of this walk's samples).
                        let code = r.k[0] | r.k[1] << 2 | r.k[2] << 4;
                        match k0 {
                            None => k0 = Some((code, r.k)),
                            Some((c, _)) if c != code => shared = false,
                            _ => {}
                        }
                        // The 4-wide test's splatted constants are made where that test runs
                        // (the AVX test, the common case, does not use them).
                        rays[k].write(r);
                    }
                    ready = active;
                    axes = k0.map_or([0, 1, 2], |(_, k)| k);
                    tlo8 = wide::F8(*tmin);
                }
                let mut shrunk = false;
                #[cfg(target_arch = "x86_64")]
                if AVX && shared && need.count_ones() >= 3 {
                    let ok = o.to_array();
                    let cut8 = wide::F8(cut);
                    // SAFETY: AVX is only true in `spans_nearest8_avx`, compiled with AVX.
                    let b = unsafe { blk.test8_avx(axes, [ok[axes[0]], ok[axes[1]], ok[axes[2]]], &shear, &k10, (&tlo8, &cut8)) };
                    // Each ray's crossings in the order of `block_crossings`:
                    // the certain hits lane by lane, then the undecided lanes.
                    for l in 0..blk.slots().len() {
                        let mut m = b.ok[l] & need;
                        while m != 0 {
                            let k = m.trailing_zeros() as usize;
                            m &= m - 1;
                            let t = b.t[l].0[k];
                            xs[k].push(Crossing { t, slot: blk.slots().start + l as u32, front: b.front[l] & (1 << k) != 0 });
                            cut[k] = cut[k].min(stop(k, t));
                            shrunk = true;
                        }
                    }
                    let mut mm = (b.unsure[0] | b.unsure[1] | b.unsure[2] | b.unsure[3]) & need;
                    while mm != 0 {
                        let k = mm.trailing_zeros() as usize;
                        mm &= mm - 1;
                        // SAFETY: every active lane was written on the first leaf.
                        let r = unsafe { rays[k].assume_init_ref() };
                        for l in 0..blk.slots().len() {
                            if b.unsure[l] & (1 << k) == 0 {
                                continue;
                            }
                            let slot = blk.slots().start + l as u32;
                            if let Some((t, front)) = wide::TriBlock::exact(&self.tris, slot, r, tmin[k], cut8.0[k]) {
                                xs[k].push(Crossing { t, slot, front });
                                cut[k] = cut[k].min(stop(k, t));
                                shrunk = true;
                            }
                        }
                    }
                    need = 0;
                }
                let mut mm = need;
                while mm != 0 {
                    let k = mm.trailing_zeros() as usize;
                    mm &= mm - 1;
                    // SAFETY: every active lane was written on the first leaf.
                    let r = unsafe { rays[k].assume_init_ref() };
                    let ck = cut[k];
                    let b = blk.test(&wide::TriRay4::new(r), tmin[k], ck);
                    self.block_crossings(blk, &b, r, (tmin[k], ck), &mut |c: Crossing| {
                        xs[k].push(c);
                        cut[k] = cut[k].min(stop(k, c.t));
                        shrunk = true;
                    });
                }
                if shrunk {
                    thi = far(&cut, active);
                }
            } else {
                let n = self.wide.node(cur);
                let (m, tn) = fr.hit(n, tlo, thi);
                if m != 0 {
                    match stack.descend(n, m, tn) {
                        Ok(c) => {
                            (cur, entry) = c;
                            continue;
                        }
                        // A degenerate tree deeper than the stack: ray by ray.
                        Err(()) => return (0, [f32::INFINITY; 8]),
                    }
                }
            }
            match stack.pop_within(thi) {
                Some((c, t)) => (cur, entry) = (c, t),
                None => break,
            }
        }
        let mut m = active;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            // No crossing, no span (the count at tmin is zero).
            if xs[k].is_empty() {
                continue;
            }
            self.sort_signed(&mut xs[k]);
            self.walk_signed(&xs[k], 0, Walk::new(line(k), tmin[k], cut[k].min(tmax[k]), leaf), &mut out[k]);
        }
        (active, cut)
    }

    /// Is the point at `t` on the ray finite and clearly outside the bounds (so
    /// that the signed crossing count there is zero)?
    #[inline]
    fn outside_at(&self, o: Vec3, d: Vec3, t: f32) -> bool {
        let p = o + d * t;
        let pad = (self.bounds.max - self.bounds.min) * 1e-4;
        let outside = p.cmplt(self.bounds.min - pad).any() || p.cmpgt(self.bounds.max + pad).any();
        outside && p.is_finite()
    }

    /// The surface id of a crossing that enters (`entering`) or leaves the solid.
    #[inline(always)]
    fn surf(&self, leaf: u32, c: &Crossing, entering: bool) -> Surf {
        // The geometric normal points against the ray when `front`; outward at an entry.
        let flip = c.front != entering;
        Surf::new(leaf, c.slot | if flip { SUB_FLIP } else { 0 })
    }

    /// Is the point inside the solid? Orientation rule: the signed crossing count of
    /// a ray from `p` (exact for closed meshes). Winding rule: generalized winding
    /// number >= 0.5 within the bounds.
    pub fn contains(&self, p: Vec3) -> bool {
        if !self.bounds.contains(p) {
            return false;
        }
        match self.rule {
            InsideRule::Orientation => {
                // An irrational-looking direction keeps exact edge/vertex ties rare
                // (they are handled either way).
                let d = Vec3::new(0.5773503, 0.5773491, 0.5773515);
                let mut count = 0.0f32;
                self.for_each_crossing((p, d, Line64::of(p, d)), 0.0, f32::INFINITY, |c| {
                    count -= if c.front { self.orient } else { -self.orient }
                });
                count > 0.5
            }
            InsideRule::Winding => self.winding_number(p) >= 0.5,
        }
    }

    /// Generalized winding number at `p` (Jacobson et al. 2013), with far BVH nodes
    /// replaced by their dipoles (Barill et al. 2018). About 1 inside, 0 outside.
    pub fn winding_number(&self, p: Vec3) -> f32 {
        self.winding_number_at(p.as_dvec3()) as f32
    }

    /// [`MeshData::winding_number`] at an f64 point. The differences to the
    /// corners are taken in f64: at a point within f32 rounding of a face
    /// (a grazing ray's piece between two crossings, or any point far from
    /// the origin) an f32 difference can put it on the face's other side,
    /// where its solid angle jumps by 4 pi and the number by 1 (grazing
    /// rays under the winding rule crossed wrongly 20 to 88 times of 400,
    /// `stress_grazing`).
    pub fn winding_number_at(&self, p: DVec3) -> f64 {
        if self.bvh.nodes.is_empty() {
            return 0.0;
        }
        let mut sum = 0.0f64;
        let beta = f32::from_bits(self.beta.load(std::sync::atomic::Ordering::Relaxed)) as f64;
        let mut stack: SmallVec<[u32; 64]> = SmallVec::new();
        stack.push(0);
        while let Some(ni) = stack.pop() {
            let dp = self.dipoles[ni as usize];
            let v = dp.p.as_dvec3() - p;
            let l2 = v.length_squared();
            if l2 > beta * beta * dp.r2 as f64 {
                let l = l2.sqrt();
                sum += dp.n.as_dvec3().dot(v) / (l2 * l);
                continue;
            }
            let node = &self.bvh.nodes[ni as usize];
            if node.count > 0 {
                for k in node.first..node.first + node.count {
                    let t = &self.tris[k as usize];
                    sum += solid_angle(t[0].as_dvec3() - p, t[1].as_dvec3() - p, t[2].as_dvec3() - p);
                }
            } else {
                stack.push(node.first);
                stack.push(node.first + 1);
            }
        }
        sum / (4.0 * std::f64::consts::PI) * self.orient as f64
    }

    /// Sets the far-field acceptance ratio of [`MeshData::winding_number`]: a BVH
    /// node is replaced by its dipole when the query point is farther than
    /// `beta` node radii from it (default [`BETA`]; infinity sums every
    /// triangle). The accuracy knob `winding` of `rothray bench --knob`.
    pub fn set_far_field(&self, beta: f32) {
        self.beta.store(beta.to_bits(), std::sync::atomic::Ordering::Relaxed);
    }

    /// Exact generalized winding number (sum over every triangle; slow oracle).
    pub fn winding_number_exact(&self, p: Vec3) -> f64 {
        let p = p.as_dvec3();
        let s: f64 = self.tris.iter().map(|t| solid_angle(t[0].as_dvec3() - p, t[1].as_dvec3() - p, t[2].as_dvec3() - p)).sum();
        s / (4.0 * std::f64::consts::PI) * self.orient as f64
    }

    /// Does [`normal`](Self::normal) use its point for this surface id (only the
    /// bounding-box faces of the winding rule do)?
    #[inline]
    pub fn normal_needs_point(&self, sub: u32) -> bool {
        sub & !SUB_FLIP == SUB_BOX
    }

    /// Outward unit normal (local space) of the crossing `sub` (from a span end).
    pub fn normal(&self, sub: u32, p: Vec3) -> Vec3 {
        let slot = sub & !SUB_FLIP;
        if slot == SUB_BOX {
            let b = &self.bounds;
            let dmin = p - b.min;
            let dmax = b.max - p;
            let mut best = (f32::INFINITY, Vec3::Y);
            for a in 0..3 {
                let mut e = Vec3::ZERO;
                e[a] = 1.0;
                if dmin[a] < best.0 {
                    best = (dmin[a], -e);
                }
                if dmax[a] < best.0 {
                    best = (dmax[a], e);
                }
            }
            return best.1;
        }
        let Some(&n) = self.normals.get(slot as usize) else { return Vec3::Y };
        if sub & SUB_FLIP != 0 {
            -n
        } else {
            n
        }
    }

    /// Topology and volume summary for `rothray check`, with the number of
    /// self-intersecting triangle pairs (computed here, on demand: see
    /// `mesh_selfx.rs`).
    pub fn report(&self) -> MeshReport {
        let mut r = self.report.clone();
        r.self_intersections = Some(self.count_self_intersections());
        r
    }

    /// Pairs of triangles that share no vertex and whose interiors cross (an edge
    /// of one passes through the other). Coplanar overlaps are not counted.
    pub fn count_self_intersections(&self) -> usize {
        selfx::count(&self.bvh.nodes, &self.tris)
    }
}

/// Insertion sort for the common short lists; `first(c)` breaks ties in `t`.
#[inline]
fn sort_crossings(xs: &mut [Crossing], first: impl Fn(&Crossing) -> bool) {
    let less = |a: &Crossing, b: &Crossing| a.t < b.t || (a.t == b.t && first(a) && !first(b));
    if xs.len() > 24 {
        xs.sort_by(|a, b| {
            if less(a, b) {
                std::cmp::Ordering::Less
            } else if less(b, a) {
                std::cmp::Ordering::Greater
            } else {
                std::cmp::Ordering::Equal
            }
        });
        return;
    }
    for i in 1..xs.len() {
        let mut j = i;
        while j > 0 && less(&xs[j], &xs[j - 1]) {
            xs.swap(j, j - 1);
            j -= 1;
        }
    }
}

#[path = "mesh_wide.rs"]
pub(crate) mod wide;

#[path = "mesh_selfx.rs"]
mod selfx;

#[path = "mesh_parallel.rs"]
mod parallel;
pub use parallel::ParallelRays8;

#[cfg(test)]
#[path = "mesh_tests.rs"]
mod tests;
