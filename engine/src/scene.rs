//! The baked render scene (plain tables, no `Entity` in the hot path), the bake
//! systems that fill it from a `hecs::World`, and the queries it answers.

use std::cell::RefCell;

use glam::{DAffine3, Vec3};
use hecs::{Entity, World};
use rothray_csg::{first_surface, MemoLanes, Mode, NodeKind, PacketMemo, Program, ProgramBuilder, RayCtx, Scratch};
use rothray_primitives::{
    bvh::FlatBvh,
    gcyl::GenCylData,
    mesh::{NearestRays8, NO_THROUGH},
    sweep::SweptSphereData,
    table::LeafData,
    Aabb, LeafError, LeafShape, LeafTable, Span, Surf,
};
use std::sync::Arc;

use crate::components::*;
use crate::knobs::Knobs;
use crate::tile::TileView;

/// A ray `origin + t * dir`, `t` in `[tmin, tmax]` (t is in units of `dir`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be unit length).
    pub dir: Vec3,
    /// Smallest t.
    pub tmin: f32,
    /// Largest t.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[0, inf)`.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray { origin, dir, tmin: 0.0, tmax: f32::INFINITY }
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

/// The nearest surface a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// Outward unit normal of the solid there.
    pub normal: Vec3,
    /// Index of the object (see [`RenderScene::objects`]).
    pub object: u32,
    /// Index of the leaf whose surface it is (see [`RenderScene::leaf_info`]).
    pub leaf: u32,
    /// Kind-specific sub-surface id.
    pub sub: u32,
}

/// What the scene knows about one top-level object.
#[derive(Clone, Debug)]
pub struct ObjectInfo {
    /// Its entity.
    pub entity: Entity,
    /// Its name (`Name`, else `object<i>`).
    pub name: String,
    /// Root node in the program.
    pub root: u32,
    /// Bounds.
    pub bounds: Aabb,
}

/// What the scene knows about one leaf.
#[derive(Clone, Debug)]
pub struct LeafInfo {
    /// Its entity.
    pub entity: Entity,
    /// Its name (`Name`, else `leaf<i>`).
    pub name: String,
    /// Its colour (own `Material`, else the nearest ancestor's, else grey).
    pub color: Vec3,
    /// Object it belongs to.
    pub object: u32,
}

/// Why a world could not be baked.
#[derive(Debug, Clone, PartialEq)]
pub enum BakeError {
    /// A leaf's numbers are out of range.
    BadShape {
        /// The entity.
        entity: Entity,
        /// Its name, if any.
        name: Option<String>,
        /// Field and message.
        error: rothray_primitives::ShapeError,
    },
    /// A transform (accumulated down the tree) is singular or not finite.
    SingularTransform {
        /// The leaf entity.
        entity: Entity,
        /// Its name, if any.
        name: Option<String>,
    },
    /// A CSG child has neither a shape nor a `CsgNode`, or no longer exists.
    NotASolid {
        /// The entity.
        entity: Entity,
    },
    /// A CSG node with no children, or a cycle.
    BadNode {
        /// The entity.
        entity: Entity,
        /// What is wrong.
        message: String,
    },
}

impl std::fmt::Display for BakeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BakeError::BadShape { entity, name, error } => {
                write!(f, "{}: {}: {}", name.clone().unwrap_or(format!("{entity:?}")), error.field, error.message)
            }
            BakeError::SingularTransform { entity, name } => {
                write!(f, "{}: transform is singular or not finite", name.clone().unwrap_or(format!("{entity:?}")))
            }
            BakeError::NotASolid { entity } => write!(f, "{entity:?} is a CSG child without a shape"),
            BakeError::BadNode { entity, message } => write!(f, "{entity:?}: {message}"),
        }
    }
}
impl std::error::Error for BakeError {}

/// The baked scene: SoA leaf table, CSG program, BVH over objects.
#[derive(Default)]
pub struct RenderScene {
    /// Every leaf, SoA.
    pub leaves: LeafTable,
    /// Every CSG tree.
    pub program: Program,
    /// Top-level objects in order.
    pub objects: Vec<ObjectInfo>,
    /// Per leaf: entity, name, colour, object.
    pub leaf_info: Vec<LeafInfo>,
    objects_bvh: FlatBvh,
    /// A binary tree over the same boxes, for region queries (tiles).
    objects_cull: FlatBvh,
    unbounded: Vec<u32>,
    /// Bounds of the finite objects.
    pub bounds: Aabb,
    /// Length tolerance of the scene (fusing coincident crossings).
    pub eps: f32,
    /// Centre of `bounds` (origin when empty): the tolerance grows with a ray's
    /// distance from it.
    center: Vec3,
    /// How many times [`sync_scene`] rebuilt the tables.
    pub bake_count: u64,
    /// Accuracy knob of the swept-sphere and generalized-cylinder solvers, relative
    /// to each shape's size (default 1e-6; see `rothray bench --tolerances`).
    pub tolerance: f32,
    /// Per-approximation accuracy settings, read by the bake (`None`: defaults).
    pub knobs: Knobs,
    /// The fusing tolerance's growth per unit of a ray origin's distance from
    /// `center` (set by the bake, see [`RenderScene::ray_ctx`]).
    eps_far: f32,
    fingerprint: u64,
    /// Mesh leaves that nearest-hit queries ask in nearest mode, traced ahead for
    /// whole packets by [`RenderScene::intersect_packet`] (empty when there are
    /// more than [`PACKET_MESHES`]).
    packet_meshes: Vec<u32>,
    /// Per object, a packet mesh that contains its whole solid (see
    /// [`containing_leaves`]), when every object has one: a ray whose packet
    /// found all of them empty on its range hits nothing and skips its own
    /// evaluation.
    packet_cover: Option<Vec<u32>>,
    /// Per object, the length past an unsure nearest-mode result that its full
    /// redo tries first (a tenth of its size when it holds a mesh; 0: none).
    redo_window: Vec<f32>,
    /// The packet shortcut (see [`Shortcut`]), for scenes with few leaves.
    shortcut: Option<Shortcut>,
}

/// At most this many leaves besides the packet meshes for the packet shortcut.
const SHORTCUT_LEAVES: usize = 8;

/// Per packet ray, the CSG evaluation reduced to what is already known: when
/// every leaf other than the packet meshes has its box beyond the nearest
/// packet-mesh entry `t` or (a cheap analytic leaf) no span before it, and every
/// other packet mesh is known empty there too,
/// every leaf but that mesh is empty on `[tmin, t + margin]`. Roth's operations
/// act pointwise (fusing and short-span rules reach only a few eps), so each
/// object's diagram there is its tree with those leaves empty: the mesh's own
/// object, when its tree then reduces to the mesh alone ([`reduce_to_leaf`]),
/// begins with the mesh's entry at `t`, and the other objects are empty. That
/// entry is the nearest hit, without evaluating anything.
struct Shortcut {
    /// World boxes of the leaves that are not packet meshes.
    others: Vec<Aabb>,
    /// Their leaf indices, `u32::MAX` for those whose own query is costly (a
    /// ray meeting such a box before the entry goes the full way): the others
    /// are asked for their spans up to the entry.
    exact: Vec<u32>,
    /// Per packet mesh (as in `packet_meshes`): the object whose tree is that
    /// mesh alone when every other leaf is empty, or `u32::MAX`.
    owner: Vec<u32>,
    /// The cheap analytic leaves under an odd number of subtrahend positions
    /// (subtracted), with their boxes: one that covers a mesh's first entry
    /// would cut it away, so the packet walk goes on through it
    /// ([`NearestRays8::through`]) and the evaluation needs no redo.
    cutters: Vec<(u32, Aabb)>,
    /// Per other leaf, its position in `cutters`, or `u32::MAX`.
    cutter_of: Vec<u32>,
}

/// Per leaf, whether it lies under an odd number of subtrahend positions of
/// its tree (marks `out[leaf]`).
fn mark_subtracted(program: &Program, n: u32, odd: bool, out: &mut [bool]) {
    let nu = n as usize;
    let first = program.first[nu] as usize;
    match program.kind[nu] {
        NodeKind::Leaf => out[first] = odd,
        kind => {
            for (i, &c) in program.children[first..first + program.count[nu] as usize].iter().enumerate() {
                mark_subtracted(program, c, odd ^ (kind == NodeKind::Difference && i > 0), out);
            }
        }
    }
}

/// A span sink that keeps only the first span.
struct First(Option<Span>);

impl rothray_primitives::SpanSink for First {
    #[inline]
    fn push_span(&mut self, s: Span) {
        if self.0.is_none() {
            self.0 = Some(s);
        }
    }
}

/// What node `n` becomes when every leaf but `keep` is empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reduced {
    Empty,
    Keep,
    /// Anything else (`keep` combined with itself).
    Other,
}

fn reduce_to_leaf(program: &Program, n: u32, keep: u32) -> Reduced {
    let nu = n as usize;
    let first = program.first[nu] as usize;
    if program.kind[nu] == NodeKind::Leaf {
        return if first as u32 == keep { Reduced::Keep } else { Reduced::Empty };
    }
    let ch = &program.children[first..first + program.count[nu] as usize];
    let red = |c: &u32| reduce_to_leaf(program, *c, keep);
    let one = |mut it: std::vec::IntoIter<Reduced>| match (it.next(), it.next()) {
        (None, _) => Reduced::Empty,
        (Some(r), None) => r,
        _ => Reduced::Other,
    };
    match program.kind[nu] {
        NodeKind::Leaf => unreachable!(),
        NodeKind::Union => one(ch.iter().map(red).filter(|&r| r != Reduced::Empty).collect::<Vec<_>>().into_iter()),
        NodeKind::Intersection => {
            let rs: Vec<Reduced> = ch.iter().map(red).collect();
            if rs.is_empty() || rs.contains(&Reduced::Empty) {
                Reduced::Empty
            } else {
                one(rs.into_iter())
            }
        }
        NodeKind::Difference => match ch.first().map(red) {
            None | Some(Reduced::Empty) => Reduced::Empty,
            Some(r) => {
                if ch[1..].iter().map(red).all(|s| s == Reduced::Empty) {
                    r
                } else {
                    Reduced::Other
                }
            }
        },
    }
}

/// At most this many mesh leaves are traced ahead per packet; scenes with more
/// go ray by ray.
pub const PACKET_MESHES: usize = 4;

/// Per-thread memory of [`RenderScene::intersect_packet`].
#[derive(Default)]
pub struct PacketScratch {
    /// The single-ray scratch (also for shading).
    pub scratch: Scratch,
    memo: PacketMemo,
    /// Rays answered by the packet shortcut so far (for tests).
    pub shortcuts: u64,
    /// Packet rays given an interval to walk on through (they meet a
    /// subtracted cheap leaf; the walk holds on only where the first mesh
    /// crossing lies inside it) so far (for tests).
    pub throughs: u64,
    /// Per cutter (see `Shortcut::cutters`) and lane, its first span on the
    /// ray's range, where `cut_done` has the lane's bit.
    cut_spans: Vec<Option<Span>>,
    cut_done: Vec<u8>,
}

/// The mesh leaves of `roots` that a nearest-hit evaluation queries in nearest
/// mode: those with no intersection's first operand on their path (that operand
/// is evaluated in full, see `Program::child_mode`).
fn nearest_mode_meshes(program: &Program, leaves: &LeafTable, roots: impl Iterator<Item = u32>) -> Vec<u32> {
    let mut found = Vec::new();
    let mut stack: Vec<u32> = roots.collect();
    while let Some(n) = stack.pop() {
        let nu = n as usize;
        let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
        match program.kind[nu] {
            NodeKind::Leaf => {
                if leaves.is_mesh(first as u32) && !found.contains(&(first as u32)) {
                    found.push(first as u32);
                }
            }
            NodeKind::Intersection => stack.extend_from_slice(&program.children[first + 1..first + count]),
            _ => stack.extend_from_slice(&program.children[first..first + count]),
        }
    }
    found
}

/// Leaves whose solid contains the whole solid of node `n`: the node itself
/// when a leaf, the leaves of any operand of an intersection, those of a
/// difference's first operand; none through a union. Boolean operations on
/// Roth spans never produce a span where such a leaf has none, so a ray that
/// misses one of them misses the node.
fn containing_leaves(program: &Program, n: u32, out: &mut Vec<u32>) {
    let nu = n as usize;
    let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
    match program.kind[nu] {
        NodeKind::Leaf => out.push(first as u32),
        NodeKind::Intersection => {
            for &c in &program.children[first..first + count] {
                containing_leaves(program, c, out);
            }
        }
        NodeKind::Difference if count > 0 => containing_leaves(program, program.children[first], out),
        _ => {}
    }
}

/// Is some leaf under node `n` a mesh?
fn subtree_has_mesh(program: &Program, leaves: &LeafTable, n: u32) -> bool {
    let nu = n as usize;
    let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
    match program.kind[nu] {
        NodeKind::Leaf => leaves.is_mesh(first as u32),
        _ => program.children[first..first + count].iter().any(|&c| subtree_has_mesh(program, leaves, c)),
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// What a leaf entity holds.
enum LeafDesc {
    Analytic(LeafShape),
    Swept(SweptSphere),
    GenCyl(GeneralizedCylinder),
    Mesh(Arc<MeshData>),
}

fn leaf_desc(world: &World, e: Entity) -> Option<LeafDesc> {
    if let Some(s) = leaf_shape(world, e) {
        return Some(LeafDesc::Analytic(s));
    }
    let er = world.entity(e).ok()?;
    if let Some(s) = er.get::<&SweptSphere>() {
        return Some(LeafDesc::Swept((*s).clone()));
    }
    if let Some(s) = er.get::<&GeneralizedCylinder>() {
        return Some(LeafDesc::GenCyl((*s).clone()));
    }
    if let Some(s) = er.get::<&MeshSolid>() {
        return Some(LeafDesc::Mesh(s.0.clone()));
    }
    None
}

fn is_leaf(world: &World, e: Entity) -> bool {
    leaf_shape(world, e).is_some()
        || world.get::<&SweptSphere>(e).is_ok()
        || world.get::<&GeneralizedCylinder>(e).is_ok()
        || world.get::<&MeshSolid>(e).is_ok()
}

fn leaf_shape(world: &World, e: Entity) -> Option<LeafShape> {
    let er = world.entity(e).ok()?;
    if let Some(s) = er.get::<&Sphere>() {
        return Some(LeafShape::Sphere(*s));
    }
    if let Some(s) = er.get::<&Cuboid>() {
        return Some(LeafShape::Cuboid(*s));
    }
    if let Some(s) = er.get::<&Cylinder>() {
        return Some(LeafShape::Cylinder(*s));
    }
    if let Some(s) = er.get::<&Cone>() {
        return Some(LeafShape::Cone(*s));
    }
    if let Some(s) = er.get::<&Torus>() {
        return Some(LeafShape::Torus(*s));
    }
    if let Some(s) = er.get::<&HalfSpace>() {
        return Some(LeafShape::HalfSpace(*s));
    }
    None
}

fn is_solid(world: &World, e: Entity) -> bool {
    world.get::<&CsgNode>(e).is_ok() || is_leaf(world, e)
}

fn name_of(world: &World, e: Entity) -> Option<String> {
    world.get::<&Name>(e).ok().map(|n| n.0.clone())
}

/// System: the top-level objects of a world, in order: entities with a shape or a
/// `CsgNode` that are nobody's CSG child and not `Hidden`.
pub fn find_objects(world: &World) -> Vec<Entity> {
    let mut child = std::collections::HashSet::new();
    for (_, n) in world.query::<&CsgNode>().iter() {
        child.extend(n.children.iter().copied());
    }
    let mut roots: Vec<(u32, Entity)> = world
        .iter()
        .map(|er| er.entity())
        .filter(|&e| !child.contains(&e) && world.get::<&Hidden>(e).is_err() && is_solid(world, e))
        .map(|e| (world.get::<&ObjectOrder>(e).map(|o| o.0).unwrap_or(u32::MAX), e))
        .collect();
    roots.sort_by_key(|&(o, e)| (o, e.id()));
    roots.into_iter().map(|(_, e)| e).collect()
}

/// Feeds formatted text into a hasher.
struct HashWriter<'a, H: std::hash::Hasher>(&'a mut H);

impl<H: std::hash::Hasher> std::fmt::Write for HashWriter<'_, H> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0.write(s.as_bytes());
        Ok(())
    }
}

/// A cheap fingerprint of everything the bake reads, so [`sync_scene`] can skip
/// work when nothing changed.
pub fn fingerprint_world(world: &World) -> u64 {
    use std::fmt::Write;
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for er in world.iter() {
        let e = er.entity();
        if !is_solid(world, e) {
            continue;
        }
        e.hash(&mut h);
        // The descriptions' Debug text goes straight into the hasher (no String per
        // entity: tools call `sync_scene` every frame).
        let _ = match leaf_desc(world, e) {
            Some(LeafDesc::Mesh(m)) => {
                (Arc::as_ptr(&m) as usize).hash(&mut h);
                Ok(())
            }
            Some(LeafDesc::Analytic(s)) => write!(HashWriter(&mut h), "{s:?}"),
            Some(LeafDesc::Swept(s)) => write!(HashWriter(&mut h), "{s:?}"),
            Some(LeafDesc::GenCyl(s)) => write!(HashWriter(&mut h), "{s:?}"),
            None => Ok(()),
        };
        if let Ok(t) = world.get::<&Transform>(e) {
            for v in t.0.to_cols_array() {
                v.to_bits().hash(&mut h);
            }
        }
        if let Ok(n) = world.get::<&CsgNode>(e) {
            (n.op as u8).hash(&mut h);
            n.children.hash(&mut h);
        }
        if let Ok(m) = world.get::<&Material>(e) {
            m.color.to_array().map(f32::to_bits).hash(&mut h);
        }
        if let Ok(n) = world.get::<&Name>(e) {
            n.0.hash(&mut h);
        }
        if let Ok(o) = world.get::<&ObjectOrder>(e) {
            o.0.hash(&mut h);
        }
        world.get::<&Hidden>(e).is_ok().hash(&mut h);
    }
    h.finish()
}

/// System: re-bakes `scene` from `world` if anything it reads changed since the
/// last call (returns whether it baked).
pub fn sync_scene(world: &mut World, scene: &mut RenderScene) -> Result<bool, BakeError> {
    let fp = fingerprint_world(world);
    if scene.bake_count > 0 && fp == scene.fingerprint {
        return Ok(false);
    }
    bake_scene(world, scene)?;
    scene.fingerprint = fp;
    Ok(true)
}

enum Visit {
    Enter(Entity, DAffine3, Option<Vec3>),
    Exit(Entity, Op, usize),
}

/// The generalized cylinder of `d` at the scene's tolerance and knobs: the
/// `gcyl` knob changes the marching and bisection tolerance only, the frame
/// samples follow the `frame` knob or else the scene tolerance.
fn gcyl_data(d: &rothray_primitives::gcyl::GeneralizedCylinder, scene: &RenderScene) -> Result<GenCylData, rothray_primitives::ShapeError> {
    let tol = scene.tolerance_or_default();
    let samples = match (scene.knobs.frame, scene.knobs.gcyl) {
        (Some(n), _) => Some(n as usize),
        (None, Some(_)) => Some(rothray_primitives::gcyl::frame_samples(tol)),
        (None, None) => None,
    };
    GenCylData::with_frame_samples(d, scene.knobs.gcyl.unwrap_or(tol), samples)
}

/// System: bakes every object of `world` into `scene` (leaf table in pre-order of
/// the trees, CSG program, BVHs). Iterative, so any nesting depth works.
pub fn bake_scene(world: &World, scene: &mut RenderScene) -> Result<(), BakeError> {
    let roots = find_objects(world);
    let mut leaves =
        LeafTable { torus_tol: scene.knobs.torus.unwrap_or(rothray_primitives::kernels::TORUS_TOLERANCE) as f64, ..LeafTable::default() };
    let mut leaf_info = Vec::new();
    let mut objects = Vec::new();
    // Program nodes reference leaves by index; build leaves first in a pass that
    // also emits the program, via a builder that borrows the leaf table lazily.
    let mut ops: Vec<ProgOp> = Vec::new();
    let mut on_path = std::collections::HashSet::new();
    for (oi, &root) in roots.iter().enumerate() {
        let mut stack = vec![Visit::Enter(root, DAffine3::IDENTITY, None)];
        while let Some(v) = stack.pop() {
            match v {
                Visit::Enter(e, parent, color) => {
                    let Ok(er) = world.entity(e) else { return Err(BakeError::NotASolid { entity: e }) };
                    let global = parent * er.get::<&Transform>().map(|t| t.0).unwrap_or(DAffine3::IDENTITY);
                    let color = er.get::<&Material>().map(|m| m.color).or(color);
                    if let Some(desc) = leaf_desc(world, e) {
                        let bad = |error: rothray_primitives::ShapeError| BakeError::BadShape { entity: e, name: name_of(world, e), error };
                        let pushed = match desc {
                            LeafDesc::Analytic(shape) => leaves.push(&shape, &global),
                            LeafDesc::Swept(d) => {
                                let data =
                                    SweptSphereData::new(&d, scene.knobs.sweep.unwrap_or(scene.tolerance_or_default())).map_err(bad)?;
                                leaves.push_data(&LeafData::SweptSphere(Arc::new(data)), &global)
                            }
                            LeafDesc::GenCyl(d) => {
                                let data = gcyl_data(&d, scene).map_err(bad)?;
                                leaves.push_data(&LeafData::GenCylinder(Arc::new(data)), &global)
                            }
                            LeafDesc::Mesh(m) => {
                                m.set_far_field(scene.knobs.winding.unwrap_or(rothray_primitives::mesh::BETA));
                                leaves.push_data(&LeafData::Mesh(m), &global)
                            }
                        };
                        let idx = pushed.map_err(|err| match err {
                            LeafError::Shape(error) => BakeError::BadShape { entity: e, name: name_of(world, e), error },
                            LeafError::SingularTransform => BakeError::SingularTransform { entity: e, name: name_of(world, e) },
                        })?;
                        leaf_info.push(LeafInfo {
                            entity: e,
                            name: name_of(world, e).unwrap_or_else(|| format!("leaf{idx}")),
                            color: color.unwrap_or(Vec3::splat(0.8)),
                            object: oi as u32,
                        });
                        ops.push(ProgOp::Leaf(idx));
                    } else if let Some(node) = er.get::<&CsgNode>() {
                        if node.children.is_empty() {
                            return Err(BakeError::BadNode { entity: e, message: "CSG node without children".into() });
                        }
                        if !on_path.insert(e) {
                            return Err(BakeError::BadNode { entity: e, message: "CSG node is its own ancestor".into() });
                        }
                        stack.push(Visit::Exit(e, node.op, node.children.len()));
                        for &c in node.children.iter().rev() {
                            if !is_solid(world, c) {
                                return Err(BakeError::NotASolid { entity: c });
                            }
                            stack.push(Visit::Enter(c, global, color));
                        }
                    } else {
                        return Err(BakeError::NotASolid { entity: e });
                    }
                }
                Visit::Exit(e, op, n) => {
                    on_path.remove(&e);
                    ops.push(ProgOp::Op(op, n as u32));
                }
            }
        }
        ops.push(ProgOp::Root(oi as u32));
        objects.push(ObjectInfo {
            entity: root,
            name: name_of(world, root).unwrap_or_else(|| format!("object{oi}")),
            root: 0,
            bounds: Aabb::EMPTY,
        });
    }
    let program = replay(&ops, &leaves, &mut objects);
    // A half-space keeps its offset relative to a point near its object (its
    // plane's point nearest the object's centre), not near the world origin.
    for (li, info) in leaf_info.iter().enumerate() {
        let b = objects[info.object as usize].bounds;
        if b.is_finite() && !b.is_empty() {
            leaves.reanchor(li as u32, b.center());
        }
    }
    // Objects BVH over the bounded objects.
    let mut boxes = Vec::new();
    let mut ids = Vec::new();
    let mut unbounded = Vec::new();
    let mut bounds = Aabb::EMPTY;
    for (i, o) in objects.iter().enumerate() {
        if o.bounds.is_empty() {
            continue;
        }
        if o.bounds.is_finite() {
            boxes.push(o.bounds);
            ids.push(i as u32);
            bounds = bounds.union(&o.bounds);
        } else {
            unbounded.push(i as u32);
        }
    }
    let mut bvh = FlatBvh::build(&boxes, 1);
    for p in bvh.prims.iter_mut() {
        *p = ids[*p as usize];
    }
    let mut cull = FlatBvh::build_cull(&boxes, 2);
    for p in cull.prims.iter_mut() {
        *p = ids[*p as usize];
    }
    if bounds.is_empty() {
        // Only unbounded solids (or none): take the leaves' finite parts.
        for lb in &leaves.bounds {
            if lb.is_finite() {
                bounds = bounds.union(lb);
            }
        }
    }
    // No floor on the size: a floor of 1e-3 made the fusing tolerance 1% of a
    // scene 1e-6 across (tests/stress.rs, octahedron at scale 1e-6).
    let diag = if bounds.is_empty() { 1.0 } else { bounds.diagonal_length() };
    let diag = if diag > 0.0 && diag.is_finite() { diag } else { 1.0 };
    scene.leaves = leaves;
    scene.program = program;
    scene.objects = objects;
    scene.leaf_info = leaf_info;
    scene.objects_bvh = bvh;
    scene.objects_cull = cull;
    scene.unbounded = unbounded;
    let mut pm = nearest_mode_meshes(&scene.program, &scene.leaves, scene.objects.iter().map(|o| o.root));
    if pm.len() > PACKET_MESHES {
        pm.clear();
    }
    scene.packet_cover = scene
        .objects
        .iter()
        .map(|o| {
            let mut c = Vec::new();
            containing_leaves(&scene.program, o.root, &mut c);
            c.into_iter().find(|l| pm.contains(l))
        })
        .collect();
    scene.shortcut = if pm.is_empty() || scene.leaves.len() > pm.len() + SHORTCUT_LEAVES {
        None
    } else {
        let rest: Vec<u32> = (0..scene.leaves.len() as u32).filter(|l| !pm.contains(l)).collect();
        let others: Vec<Aabb> = rest.iter().map(|&l| scene.leaves.bounds[l as usize]).collect();
        let exact: Vec<u32> = rest
            .iter()
            .map(|&l| {
                use rothray_primitives::table::LeafKind::*;
                let cheap = matches!(scene.leaves.kind[l as usize], Sphere | Cuboid | Cylinder | Cone | HalfSpace);
                if cheap {
                    l
                } else {
                    u32::MAX
                }
            })
            .collect();
        let owner: Vec<u32> = pm
            .iter()
            .map(|&m| {
                let oi = scene.leaf_info[m as usize].object;
                let keep = reduce_to_leaf(&scene.program, scene.objects[oi as usize].root, m) == Reduced::Keep;
                if keep {
                    oi
                } else {
                    u32::MAX
                }
            })
            .collect();
        let mut sub = vec![false; scene.leaves.len()];
        for o in &scene.objects {
            mark_subtracted(&scene.program, o.root, false, &mut sub);
        }
        let subtracted: Vec<bool> = rest.iter().map(|&l| sub[l as usize]).collect();
        let cutters: Vec<(u32, Aabb)> =
            exact.iter().zip(&subtracted).zip(&others).filter(|((&l, &s), _)| s && l != u32::MAX).map(|((&l, _), b)| (l, *b)).collect();
        let cutter_of: Vec<u32> = rest.iter().map(|l| cutters.iter().position(|c| c.0 == *l).map_or(u32::MAX, |p| p as u32)).collect();
        owner.iter().any(|&o| o != u32::MAX).then_some(Shortcut { others, exact, owner, cutters, cutter_of })
    };
    scene.packet_meshes = pm;
    scene.redo_window = scene
        .objects
        .iter()
        .map(|o| {
            let b = &o.bounds;
            let useful = subtree_has_mesh(&scene.program, &scene.leaves, o.root) && b.is_finite() && !b.is_empty();
            if useful {
                0.1 * b.diagonal_length()
            } else {
                0.0
            }
        })
        .collect();
    scene.bounds = bounds;
    // The fusing tolerance: 1e-5 of the scene's size, and 2e-6 of a ray origin's
    // distance from it (f32 rounding of the crossings grows with both); the
    // `fuse` knob scales both (README: the curve on scenes/coincident.json).
    let fuse = scene.knobs.fuse.unwrap_or(1e-5);
    scene.eps = fuse * diag;
    scene.eps_far = 0.2 * fuse;
    scene.center = if bounds.is_empty() { Vec3::ZERO } else { bounds.center() };
    scene.bake_count += 1;
    Ok(())
}

/// An object as one query evaluates it: its root in a program (the baked one
/// or a tile's), and its index.
#[derive(Clone, Copy)]
struct ObjRef<'a> {
    prog: &'a Program,
    root: u32,
    oi: u32,
}

enum ProgOp {
    Leaf(u32),
    Op(Op, u32),
    Root(u32),
}

/// Which ops of `ops` (post-order) the builder would flatten into their parent:
/// an operand of the same associative kind (a union in a union, an
/// intersection in an intersection, a difference as the first operand of a
/// difference), as [`ProgramBuilder::op`] does. A one-operand op is no node
/// (its operand passes through), so the kind that counts is its operand's.
fn absorbed_ops(ops: &[ProgOp]) -> Vec<bool> {
    let mut absorbed = vec![false; ops.len()];
    // Per value: the op that made it (`usize::MAX` for a leaf) and its kind.
    let mut st: Vec<(usize, Option<Op>)> = Vec::new();
    for (k, op) in ops.iter().enumerate() {
        match *op {
            ProgOp::Leaf(_) => st.push((usize::MAX, None)),
            ProgOp::Op(_, 1) => {}
            ProgOp::Op(op, n) => {
                let at = st.len() - n as usize;
                for (i, &(o, kind)) in st[at..].iter().enumerate() {
                    if o != usize::MAX && kind == Some(op) && (op != Op::Difference || i == 0) {
                        absorbed[o] = true;
                    }
                }
                st.truncate(at);
                st.push((k, Some(op)));
            }
            ProgOp::Root(_) => {
                st.pop();
            }
        }
    }
    absorbed
}

/// Replays the post-order ops into a program (sets the objects' roots and
/// bounds). An op that its parent flattens ([`absorbed_ops`]) is not built:
/// its flattened operand list is kept as a linked list that the parent
/// splices in O(1), and only the parent is built, from the whole list. The
/// builder would make the same node, but from copies: a chain of `d` nested
/// intersections copied each level's list into the next (d^2 / 2 child
/// entries and bounds folds: 2.2 GB and 6 s at 100 000 levels), and a chain
/// of unions rebuilt a BVH per level. The program is the same but for the
/// ids of the nodes that were never read (children still come before
/// parents, and a subtree's ids are still contiguous).
fn replay(ops: &[ProgOp], leaves: &LeafTable, objects: &mut [ObjectInfo]) -> Program {
    #[derive(Clone, Copy)]
    enum Val {
        Node(u32),
        /// A flattened operand list: first and last cell in `cells`.
        List(u32, u32),
    }
    const END: u32 = u32::MAX;
    let absorbed = absorbed_ops(ops);
    let mut b = ProgramBuilder::new(leaves);
    let mut vals: Vec<Val> = Vec::new();
    // Linked list cells: (node, next cell).
    let mut cells: Vec<(u32, u32)> = Vec::new();
    let mut flat: Vec<u32> = Vec::new();
    for (k, op) in ops.iter().enumerate() {
        match *op {
            ProgOp::Leaf(i) => {
                let n = b.leaf(i);
                vals.push(Val::Node(n));
            }
            ProgOp::Op(_, 1) => {} // the operand passes through (as `ProgramBuilder::op` does)
            ProgOp::Op(op, n) => {
                let at = vals.len() - n as usize;
                let v = if absorbed[k] {
                    let (mut head, mut tail) = (END, END);
                    for &v in &vals[at..] {
                        let (h, t) = match v {
                            Val::Node(c) => {
                                cells.push((c, END));
                                let c = cells.len() as u32 - 1;
                                (c, c)
                            }
                            Val::List(h, t) => (h, t),
                        };
                        if head == END {
                            head = h;
                        } else {
                            cells[tail as usize].1 = h;
                        }
                        tail = t;
                    }
                    Val::List(head, tail)
                } else {
                    flat.clear();
                    for &v in &vals[at..] {
                        match v {
                            Val::Node(c) => flat.push(c),
                            Val::List(mut c, _) => {
                                while c != END {
                                    flat.push(cells[c as usize].0);
                                    c = cells[c as usize].1;
                                }
                            }
                        }
                    }
                    Val::Node(b.op(op, &flat))
                };
                vals.truncate(at);
                vals.push(v);
            }
            ProgOp::Root(oi) => {
                let Some(Val::Node(r)) = vals.pop() else { unreachable!("a root is built, never flattened into a parent") };
                objects[oi as usize].root = r;
                objects[oi as usize].bounds = b.program.bounds[r as usize];
            }
        }
    }
    b.finish()
}

impl RenderScene {
    fn tolerance_or_default(&self) -> f32 {
        if self.tolerance > 0.0 {
            self.tolerance
        } else {
            rothray_primitives::sweep::DEFAULT_TOLERANCE
        }
    }

    /// Bakes a world into a new scene.
    pub fn from_world(world: &World) -> Result<RenderScene, BakeError> {
        let mut s = RenderScene::default();
        bake_scene(world, &mut s)?;
        Ok(s)
    }

    /// The per-ray context: the fusing tolerance grows with the distance from the
    /// scene, since f32 rounding of the crossings does.
    #[inline]
    pub fn ray_ctx(&self, o: Vec3, d: Vec3) -> RayCtx<'static> {
        RayCtx::new(o, d, self.eps_at(o))
    }

    /// The length tolerance of rays from `o` (see [`RenderScene::ray_ctx`]).
    #[inline]
    fn eps_at(&self, o: Vec3) -> f32 {
        let far = (o - self.center).length();
        self.eps + self.eps_far * if far.is_finite() { far } else { 0.0 }
    }

    /// True when every object has finite bounds (no half-space reaches infinity).
    pub fn all_bounded(&self) -> bool {
        self.unbounded.is_empty()
    }

    /// The objects without finite bounds.
    pub(crate) fn unbounded_objects(&self) -> &[u32] {
        &self.unbounded
    }

    /// A binary tree over the bounded objects' boxes (ids: object indices).
    pub(crate) fn objects_cull(&self) -> &FlatBvh {
        &self.objects_cull
    }

    /// Object index of an entity (a top-level object).
    pub fn object_of(&self, e: Entity) -> Option<u32> {
        self.objects.iter().position(|o| o.entity == e).map(|i| i as u32)
    }

    /// Nearest hit (uses a thread-local scratch).
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        SCRATCH.with(|s| self.intersect_with(ray, &mut s.borrow_mut()))
    }

    /// Is anything hit along the ray (shadow rays)?
    pub fn occluded(&self, ray: &Ray) -> bool {
        SCRATCH.with(|s| self.occluded_with(ray, &mut s.borrow_mut()))
    }

    /// First surface of object `oi` within `[tmin, tmax]`: `(t, surface)`.
    #[inline]
    fn object_first(&self, obj: ObjRef, ctx: &RayCtx, tmin: f32, tmax: f32, scratch: &mut Scratch) -> Option<(f32, Surf)> {
        let ObjRef { prog, root, oi } = obj;
        let valid = prog.eval(&self.leaves, root, ctx, tmin, tmax, Mode::Nearest, scratch);
        let f = first_surface(scratch.out.as_slice());
        // An exit (the ray starts inside) close to where the result stops being
        // exact is not sure (see `Program::eval`; found by a packet-against-
        // single-ray fuzz: a union's exit at its first operand's end while the
        // second went on). An entry there cannot be: a span starting at the
        // limit has no length.
        let unsure_exit =
            f.is_some_and(|(t, _)| scratch.out.as_slice().first().is_some_and(|s| !s.s0.is_real()) && t >= valid - 16.0 * ctx.eps);
        if (f.is_none() || unsure_exit) && valid < tmax {
            // Nothing sure before `valid` (a union's entry covered by another
            // operand, a mesh's first span cut away by a difference): redo in
            // full. With meshes, first up to a tenth of the object's size past
            // `valid` (their walks then collect only the crossings up to there).
            // Measured on scenes/bunny (callgrind, 480x270): 206.4e6 -> 200.7e6
            // instructions; windows of 0.05-0.25 gave 213e6-204e6.
            let w = self.redo_window[oi as usize];
            let t1 = if w > 0.0 { valid + w / ctx.d.length() } else { tmax };
            return self.redo(obj, ctx, (tmin, t1, tmax), scratch);
        }
        f
    }

    /// The first surface of node `root` on `[tmin, tmax]` from its full
    /// diagram: first over `[tmin, t1]`, accepted when that first surface is
    /// clear of `t1` (16 eps: clipping at `t1` changes the result only within a
    /// few eps of it, where boundaries fuse and short spans are dropped), else
    /// over the whole range.
    fn redo(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32, f32), scratch: &mut Scratch) -> Option<(f32, Surf)> {
        let ObjRef { prog, root, .. } = obj;
        let (tmin, t1, tmax) = range;
        if t1 < tmax {
            prog.eval(&self.leaves, root, ctx, tmin, t1, Mode::All, scratch);
            if let Some((t, s)) = first_surface(scratch.out.as_slice()) {
                if t < t1 - 16.0 * ctx.eps {
                    return Some((t, s));
                }
            }
        }
        prog.eval(&self.leaves, root, ctx, tmin, tmax, Mode::All, scratch);
        first_surface(scratch.out.as_slice())
    }

    /// Object `oi` as the rays of `tile` see it (`None`: they cannot meet it),
    /// or as baked without a tile.
    #[inline(always)]
    fn obj_ref<'a>(&'a self, oi: u32, tile: Option<&TileView<'a>>) -> Option<ObjRef<'a>> {
        match tile {
            Some(t) => t.root(oi).map(|root| ObjRef { prog: t.prog, root, oi }),
            None => Some(ObjRef { prog: &self.program, root: self.objects[oi as usize].root, oi }),
        }
    }

    /// Nearest hit with caller-provided scratch (no thread-local access).
    pub fn intersect_with(&self, ray: &Ray, scratch: &mut Scratch) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let ctx = self.ray_ctx(ray.origin, ray.dir);
        self.intersect_ctx(ray, &ctx, scratch, true, None)
    }

    /// Nearest hits of up to eight rays (`out[k]` for `rays[k]`), the same as
    /// [`RenderScene::intersect_with`] ray by ray. Eight valid rays from one origin
    /// (camera rays through neighbouring pixels) go as a packet: the scene's
    /// nearest-mode meshes are traced once for all eight
    /// ([`LeafTable::mesh_nearest8`], going on through subtracted analytic
    /// leaves where a ray's first crossing lies inside one); then each ray is
    /// settled from those results where they decide it (a miss of every
    /// containing mesh, or the packet shortcut of the README), else its CSG is
    /// evaluated with them.
    pub fn intersect_packet(&self, rays: &[Ray], ps: &mut PacketScratch, out: &mut [Option<Hit>]) {
        self.intersect_packet_with(rays, ps, out, true, None);
    }

    /// [`RenderScene::intersect_packet`]; without `normals` every hit's `normal`
    /// is left zero (a picture without lights does not read it: the normal of
    /// a mesh triangle was ~6% of a frame of scenes/bunny). With `tile`, the
    /// rays (all inside the region it was prepared for) evaluate the tile's
    /// programs, with the same answers.
    #[doc(hidden)]
    pub fn intersect_packet_with(
        &self,
        rays: &[Ray],
        ps: &mut PacketScratch,
        out: &mut [Option<Hit>],
        normals: bool,
        tile: Option<&TileView>,
    ) {
        let n = rays.len().min(out.len());
        if n == 0 {
            return;
        }
        let o = rays[0].origin;
        // `is_valid` for each ray, with the shared origin checked once.
        let packet = n == 8
            && !self.packet_meshes.is_empty()
            && o.is_finite()
            && rays.iter().all(|r| r.origin == o && r.dir.is_finite() && r.dir != Vec3::ZERO && r.tmin <= r.tmax);
        if !packet {
            for k in 0..n {
                out[k] = if rays[k].is_valid() {
                    self.intersect_ctx(&rays[k], &self.ray_ctx(rays[k].origin, rays[k].dir), &mut ps.scratch, normals, tile)
                } else {
                    None
                };
            }
            return;
        }
        // What `ray_ctx` gives each ray (the same bits), its origin's share once.
        let ew = self.eps_at(o);
        let d: [Vec3; 8] = std::array::from_fn(|k| rays[k].dir);
        let eps: [f32; 8] = std::array::from_fn(|k| ew / d[k].length());
        let tmin: [f32; 8] = std::array::from_fn(|k| rays[k].tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| rays[k].tmax);
        let slack: [f32; 8] = std::array::from_fn(|k| RayCtx::nearest_slack_of(eps[k]));
        // A ray through a subtracted analytic leaf keeps walking the meshes to
        // where that leaf ends when their first crossing lies inside it (the
        // nearest-mode answer would be cut away there: with the crossings up to
        // the leaf's end, the evaluation needs no redo).
        let mut through = NO_THROUGH;
        let inv_d: [Vec3; 8] = std::array::from_fn(|k| d[k].recip());
        if let Some(sc) = self.shortcut.as_ref().filter(|sc| !sc.cutters.is_empty()) {
            ps.cut_spans.resize(8 * sc.cutters.len(), None);
            ps.cut_done.resize(sc.cutters.len(), 0);
            for (ci, &(l, ref b)) in sc.cutters.iter().enumerate() {
                // Only a guess (a ray without it is redone, exactly): a box
                // that the packet's corner rays both miss is taken as missed.
                ps.cut_done[ci] = 0;
                if b.ray_range(o, inv_d[0], tmin[0], tmax[0]).is_none() && b.ray_range(o, inv_d[7], tmin[7], tmax[7]).is_none() {
                    continue;
                }
                ps.cut_done[ci] = 0xff;
                for k in 0..8 {
                    ps.cut_spans[8 * ci + k] = None;
                    if b.ray_range(o, inv_d[k], tmin[k], tmax[k]).is_none() {
                        continue;
                    }
                    let mut first = First(None);
                    self.leaves.spans(l, o, d[k], tmin[k], tmax[k], &mut first);
                    ps.cut_spans[8 * ci + k] = first.0;
                    if let Some(f) = first.0 {
                        if f.t0 < through[k][0] {
                            ps.throughs += (through[k][0] == f32::INFINITY) as u64;
                            through[k] = [f.t0, f.t1 + 64.0 * eps[k]];
                        }
                    }
                }
            }
        }
        ps.memo.clear();
        let q = NearestRays8 { o, d: &d, tmin: &tmin, tmax: &tmax, slack: &slack, through: &through };
        for &i in &self.packet_meshes {
            ps.memo.add(i, &tmin, &tmax, |sp| self.leaves.mesh_nearest8(i, &q, 0xff, sp));
        }
        // Rays for which every object lies inside a mesh they miss: no hit. A
        // packet of such rays only (background) is done.
        let mut left = 0xffu32;
        if let Some(cover) = &self.packet_cover {
            let mut missed = 0xffu32;
            for &l in cover {
                missed &= ps.memo.empty8(l, &tmin, &tmax);
            }
            for (k, o) in out.iter_mut().enumerate().take(8) {
                if missed & (1 << k) != 0 {
                    *o = None;
                }
            }
            left &= !missed;
            if left == 0 {
                return;
            }
        }
        // All eight contexts are written before the first is read: reading one
        // just built (its fields written piecewise, read with wider loads) stalls
        // on store forwarding.
        let memo = &ps.memo;
        // The packet meshes' records, looked up once for the eight rays.
        let mut lanes: [Option<MemoLanes>; PACKET_MESHES] = [None; PACKET_MESHES];
        for (j, &m) in self.packet_meshes.iter().enumerate() {
            lanes[j] = memo.lanes(m);
        }
        let ctx: [RayCtx; 8] = std::array::from_fn(|k| RayCtx { o, d: d[k], inv_d: inv_d[k], eps: eps[k], memo: Some((memo, k)) });
        for k in 0..8 {
            if left & (1 << k) == 0 {
                continue;
            }
            if let Some(sc) = &self.shortcut {
                let cut = (ps.cut_spans.as_slice(), ps.cut_done.as_slice());
                if let Some(h) = self.shortcut_hit(sc, &rays[k], &ctx[k], &lanes, cut, k, normals) {
                    out[k] = h;
                    ps.shortcuts += 1;
                    continue;
                }
            }
            out[k] = self.intersect_ctx(&rays[k], &ctx[k], &mut ps.scratch, normals, tile);
        }
    }

    /// Does every object lie inside a packet mesh (so that packet rays missing
    /// those meshes skip their evaluation)? For tests.
    #[doc(hidden)]
    pub fn packet_covered(&self) -> bool {
        !self.packet_meshes.is_empty() && self.packet_cover.is_some()
    }

    fn intersect_ctx(&self, ray: &Ray, ctx: &RayCtx, scratch: &mut Scratch, normals: bool, tile: Option<&TileView>) -> Option<Hit> {
        let mut best_t = ray.tmax;
        let mut best: Option<(u32, Surf)> = None;
        // Objects in the same order with or without a tile: ties go the same way.
        for &oi in &self.unbounded {
            let Some(obj) = self.obj_ref(oi, tile) else { continue };
            if let Some((t, s)) = self.object_first(obj, ctx, ray.tmin, best_t, scratch) {
                if t < best_t || best.is_none() {
                    best_t = t;
                    best = Some((oi, s));
                }
            }
        }
        self.objects_bvh.traverse(ctx.o, ctx.inv_d, ray.tmin, best_t, |oi, _| {
            let Some(obj) = self.obj_ref(oi, tile) else { return best_t };
            if let Some((t, s)) = self.object_first(obj, ctx, ray.tmin, best_t, scratch) {
                if t < best_t || best.is_none() {
                    best_t = t;
                    best = Some((oi, s));
                }
            }
            best_t
        });
        let (oi, s) = best?;
        Some(self.hit_at(ray, oi, best_t, s, normals))
    }

    /// The hit of object `oi` at `t` on surface `s` (its normal made when
    /// `normals`, else zero).
    #[inline]
    fn hit_at(&self, ray: &Ray, oi: u32, t: f32, s: Surf, normals: bool) -> Hit {
        let leaf = s.leaf_index();
        let mut n = Vec3::ZERO;
        if normals {
            n = self.leaves.normal(leaf, s.sub, ray.origin, ray.dir, t);
            if s.flipped() {
                n = -n;
            }
        }
        Hit { t, normal: n, object: oi, leaf, sub: s.sub }
    }

    /// The nearest hit of packet lane `k` by the [`Shortcut`], when it applies
    /// (`Some(None)`: no hit at all, every leaf is empty on the ray's range).
    /// `cut`: the cutters' first spans made before the packet walk.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn shortcut_hit(
        &self,
        sc: &Shortcut,
        ray: &Ray,
        ctx: &RayCtx,
        lanes: &[Option<MemoLanes>; PACKET_MESHES],
        cut: (&[Option<Span>], &[u8]),
        k: usize,
        normals: bool,
    ) -> Option<Option<Hit>> {
        // The nearest packet-mesh entry, and up to where each mesh is known empty.
        let mut best: Option<(f32, Surf, usize)> = None;
        let mut clear = [f32::INFINITY; PACKET_MESHES];
        for (j, l) in lanes[..self.packet_meshes.len()].iter().enumerate() {
            let (spans, valid) = l.and_then(|l| l.get(k))?;
            match spans.first() {
                // Inside at `tmin`: the shortcut does not reason about that.
                Some(s) if !s.s0.is_real() => return None,
                // A first span no longer than eps is dropped by `combine` when
                // the evaluation meets any other operand, however far: the full
                // evaluation decides it.
                Some(s) if s.t1 - s.t0 <= 2.0 * ctx.eps => return None,
                Some(s) => {
                    clear[j] = s.t0;
                    if best.is_none_or(|b| s.t0 < b.0) {
                        best = Some((s.t0, s.s0, j));
                    }
                }
                None if valid < ray.tmax => clear[j] = valid,
                None => {}
            }
        }
        // Everything else must be empty on [tmin, reach]: 16 eps past the entry
        // (as for the redo window: what lies further cannot fuse with it or cut
        // it short), or the whole range when there is no entry.
        let (reach, j_best) = match best {
            Some((t, _, j)) => (t + 16.0 * ctx.eps, j),
            None => (ray.tmax, usize::MAX),
        };
        for (j, &c) in clear[..self.packet_meshes.len()].iter().enumerate() {
            if j != j_best && c <= reach {
                return None;
            }
        }
        for (i, (b, &l)) in sc.others.iter().zip(&sc.exact).enumerate() {
            let ci = sc.cutter_of[i] as usize;
            if ci != u32::MAX as usize && cut.1[ci] & (1 << k) != 0 {
                // Its first span is known: any before `reach`?
                if cut.0[8 * ci + k].is_some_and(|f| f.t0 < reach) {
                    return None;
                }
                continue;
            }
            if let Some((t0, _)) = b.ray_range(ctx.o, ctx.inv_d, ray.tmin, ray.tmax) {
                if t0 <= reach {
                    // The box reaches the entry: does the leaf itself?
                    let mut first = First(None);
                    if l != u32::MAX {
                        self.leaves.spans(l, ctx.o, ctx.d, ray.tmin, reach, &mut first);
                    }
                    if l == u32::MAX || first.0.is_some() {
                        return None;
                    }
                }
            }
        }
        let Some((t, s, j)) = best else { return Some(None) };
        let oi = sc.owner[j];
        if oi == u32::MAX {
            return None;
        }
        Some(Some(self.hit_at(ray, oi, t, s, normals)))
    }

    /// Any-hit with caller-provided scratch.
    pub fn occluded_with(&self, ray: &Ray, scratch: &mut Scratch) -> bool {
        self.occluded_in(ray, scratch, None)
    }

    /// [`RenderScene::occluded_with`]; with `tile`, the ray (inside the region
    /// the tile was prepared for) evaluates the tile's programs, with the same
    /// answer.
    pub fn occluded_in(&self, ray: &Ray, scratch: &mut Scratch, tile: Option<&TileView>) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let ctx = self.ray_ctx(ray.origin, ray.dir);
        for &oi in &self.unbounded {
            let Some(obj) = self.obj_ref(oi, tile) else { continue };
            if self.object_first(obj, &ctx, ray.tmin, ray.tmax, scratch).is_some() {
                return true;
            }
        }
        let mut hit = false;
        self.objects_bvh.traverse(ctx.o, ctx.inv_d, ray.tmin, ray.tmax, |oi, _| {
            let Some(obj) = self.obj_ref(oi, tile) else { return ray.tmax };
            if self.object_first(obj, &ctx, ray.tmin, ray.tmax, scratch).is_some() {
                hit = true;
                return f32::NEG_INFINITY;
            }
            ray.tmax
        });
        hit
    }

    /// The Roth diagram of object `oi` along the ray, clipped to `[tmin, tmax]`.
    pub fn spans(&self, ray: &Ray, oi: u32) -> Vec<Span> {
        SCRATCH.with(|s| {
            let s = &mut *s.borrow_mut();
            if !ray.is_valid() || oi as usize >= self.objects.len() {
                return Vec::new();
            }
            let ctx = self.ray_ctx(ray.origin, ray.dir);
            self.program.eval(&self.leaves, self.objects[oi as usize].root, &ctx, ray.tmin, ray.tmax, Mode::All, s);
            s.out.as_slice().to_vec()
        })
    }

    /// The Roth diagram of the solid an entity stands for (an object).
    pub fn spans_of(&self, ray: &Ray, e: Entity) -> Vec<Span> {
        self.object_of(e).map(|oi| self.spans(ray, oi)).unwrap_or_default()
    }

    /// Is the point inside object `oi` (boundary included)?
    pub fn contains(&self, p: Vec3, oi: u32) -> bool {
        if oi as usize >= self.objects.len() || !p.is_finite() {
            return false;
        }
        SCRATCH.with(|s| self.program.contains(&self.leaves, self.objects[oi as usize].root, p, &mut s.borrow_mut()))
    }

    /// Is the point inside the object entity `e`?
    pub fn contains_entity(&self, p: Vec3, e: Entity) -> bool {
        self.object_of(e).map(|oi| self.contains(p, oi)).unwrap_or(false)
    }

    /// The objects containing `p`.
    pub fn classify(&self, p: Vec3) -> Vec<u32> {
        (0..self.objects.len() as u32).filter(|&oi| self.contains(p, oi)).collect()
    }

    /// Nearest hits of a bundle of rays (in parallel for large bundles).
    pub fn intersect_bundle(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len());
        if rays.len() < 256 {
            SCRATCH.with(|s| {
                let s = &mut *s.borrow_mut();
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    *o = self.intersect_with(r, s);
                }
            });
            return;
        }
        rays.par_chunks(64).zip(out.par_chunks_mut(64)).for_each_init(Scratch::default, |s, (rs, os)| {
            for (r, o) in rs.iter().zip(os.iter_mut()) {
                *o = self.intersect_with(r, s);
            }
        });
    }

    /// Any-hit of a bundle of rays.
    pub fn occluded_bundle(&self, rays: &[Ray], out: &mut [bool]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len());
        rays.par_chunks(64).zip(out.par_chunks_mut(64)).for_each_init(Scratch::default, |s, (rs, os)| {
            for (r, o) in rs.iter().zip(os.iter_mut()) {
                *o = self.occluded_with(r, s);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    use rothray_primitives::table::{LeafShape, Sphere};

    fn object() -> ObjectInfo {
        ObjectInfo { entity: Entity::DANGLING, name: String::new(), root: 0, bounds: Aabb::EMPTY }
    }

    /// The replay as it was: every op through `ProgramBuilder::op`, which
    /// flattens by copying.
    fn replay_by_copies(ops: &[ProgOp], leaves: &LeafTable, objects: &mut [ObjectInfo]) -> Program {
        let mut b = ProgramBuilder::new(leaves);
        let mut vals: Vec<u32> = Vec::new();
        for op in ops {
            match *op {
                ProgOp::Leaf(i) => vals.push(b.leaf(i)),
                ProgOp::Op(op, n) => {
                    let at = vals.len() - n as usize;
                    let node = b.op(op, &vals[at..]);
                    vals.truncate(at);
                    vals.push(node);
                }
                ProgOp::Root(oi) => objects[oi as usize].root = vals.pop().unwrap(),
            }
        }
        b.finish()
    }

    /// Random trees (chains of one kind, mixed kinds, one-operand nodes):
    /// the spliced replay gives every ray the spans of the copying one, and
    /// its children table stays linear in the leaves on a 1 000-deep chain.
    #[test]
    fn replay_flattens_like_the_builder_in_linear_memory() {
        let seed = 14u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for case in 0..40 {
            let mut leaves = LeafTable::default();
            let mut ops = Vec::new();
            let depth = if case == 0 { 1000 } else { rng.gen_range(1..200) };
            let same = case < 4;
            let kinds = [Op::Union, Op::Intersection, Op::Difference];
            let k0 = kinds[case % 3];
            // A chain: each level combines the level below (at a random
            // position) with new leaves.
            fn level(rng: &mut SmallRng, leaves: &mut LeafTable, ops: &mut Vec<ProgOp>, depth: usize, kind: Option<Op>) {
                if depth == 0 {
                    let c = Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5));
                    let s = LeafShape::Sphere(Sphere { center: c, radius: rng.gen_range(0.3..2.0) });
                    ops.push(ProgOp::Leaf(leaves.push(&s, &DAffine3::IDENTITY).unwrap()));
                    return;
                }
                let op = kind.unwrap_or([Op::Union, Op::Intersection, Op::Difference][rng.gen_range(0..3)]);
                let n = if kind.is_some() { 2 } else { rng.gen_range(1..4) };
                let at = rng.gen_range(0..n);
                for i in 0..n {
                    level(rng, leaves, ops, if i == at { depth - 1 } else { 0 }, kind);
                }
                ops.push(ProgOp::Op(op, n as u32));
            }
            level(&mut rng, &mut leaves, &mut ops, depth, same.then_some(k0));
            ops.push(ProgOp::Root(0));
            let (mut a, mut b) = ([object()], [object()]);
            let pa = replay(&ops, &leaves, &mut a);
            let pb = replay_by_copies(&ops, &leaves, &mut b);
            if case == 0 {
                assert!(pa.children.len() <= 2 * leaves.len(), "{} children for {} leaves", pa.children.len(), leaves.len());
            }
            let (ra, rb) = (a[0].root as usize, b[0].root as usize);
            assert_eq!((pa.kind[ra], pa.count[ra], pa.bounds[ra]), (pb.kind[rb], pb.count[rb], pb.bounds[rb]), "case {case}");
            let (mut sa, mut sb) = (Scratch::default(), Scratch::default());
            for _ in 0..50 {
                let o = Vec3::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0), 5.0);
                let d = Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), -1.0);
                let ctx = RayCtx::new(o, d, 1e-5);
                for mode in [Mode::All, Mode::Nearest] {
                    let va = pa.eval(&leaves, a[0].root, &ctx, 0.0, f32::INFINITY, mode, &mut sa);
                    let vb = pb.eval(&leaves, b[0].root, &ctx, 0.0, f32::INFINITY, mode, &mut sb);
                    assert_eq!(format!("{va:?} {:?}", sa.out.as_slice()), format!("{vb:?} {:?}", sb.out.as_slice()), "case {case}");
                }
                let p = o + d * rng.gen_range(0.0..8.0);
                assert_eq!(pa.contains(&leaves, a[0].root, p, &mut sa), pb.contains(&leaves, b[0].root, p, &mut sb), "case {case}");
            }
        }
    }
}
