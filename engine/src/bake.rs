//! The bake systems: from a `hecs::World` to the [`RenderScene`]'s tables.
//! [`find_objects`] lists the root solids, [`bake_scene`] flattens each
//! tree into the post-order CSG program and the SoA leaf table and builds the
//! object BVHs, [`sync_scene`] re-bakes the objects that changed (see
//! `engine/src/live.rs`).

use glam::{DAffine3, Vec3};
use hecs::{Entity, World};
use rothray_csg::{NodeKind, Program, ProgramBuilder};
use rothray_primitives::{bvh::FlatBvh, gcyl::GenCylData, sweep::SweptSphereData, table::LeafData, Aabb, LeafError, LeafShape, LeafTable};
use std::sync::Arc;

use crate::components::*;
use crate::entity_hash::EntitySet;
use crate::knobs::Knobs;
use crate::packet::bake_packet_paths;
use crate::scene::{LeafInfo, ObjectInfo, RenderScene, Retry};

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
    /// A leaf's size or place is outside the supported range
    /// ([`rothray_primitives::table::MIN_SIZE`], [`rothray_primitives::table::MAX_COORD`]).
    OutOfRange {
        /// The leaf entity.
        entity: Entity,
        /// Its name, if any.
        name: Option<String>,
        /// What is out of range, and the range.
        message: String,
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
                write!(
                    f,
                    "{}: transform is singular or not finite (leaf sizes after transforms from {:e} to {:e} are supported)",
                    name.clone().unwrap_or(format!("{entity:?}")),
                    rothray_primitives::table::MIN_SIZE,
                    rothray_primitives::table::MAX_COORD
                )
            }
            BakeError::OutOfRange { entity, name, message } => {
                write!(f, "{}: leaf out of range: {message}", name.clone().unwrap_or(format!("{entity:?}")))
            }
            BakeError::NotASolid { entity } => write!(f, "{entity:?} is a CSG child without a shape"),
            BakeError::BadNode { entity, message } => write!(f, "{entity:?}: {message}"),
        }
    }
}
impl std::error::Error for BakeError {}

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
    world.entity(e).is_ok_and(|er| {
        er.has::<CsgNode>()
            || er.has::<Sphere>()
            || er.has::<Cuboid>()
            || er.has::<Cylinder>()
            || er.has::<Cone>()
            || er.has::<Torus>()
            || er.has::<HalfSpace>()
            || er.has::<SweptSphere>()
            || er.has::<GeneralizedCylinder>()
            || er.has::<MeshSolid>()
    })
}

/// System: the top-level objects of a world, in order: entities with a shape or a
/// `CsgNode` that are nobody's CSG child and not `Hidden`.
pub fn find_objects(world: &World) -> Vec<Entity> {
    let mut child = EntitySet::default();
    for (_, n) in world.query::<&CsgNode>().iter() {
        child.extend(n.children.iter().copied());
    }
    // One query per solid kind (whole archetypes at a time, no lookup per
    // entity and kind): on 100 000 objects this took 109 ms as lookups.
    let mut roots: Vec<(u32, Entity)> = Vec::new();
    fn collect<T: hecs::Component>(world: &World, child: &EntitySet, roots: &mut Vec<(u32, Entity)>) {
        for (e, o) in world.query::<Option<&ObjectOrder>>().with::<&T>().without::<&Hidden>().iter() {
            if !child.contains(&e) {
                roots.push((o.map_or(u32::MAX, |o| o.0), e));
            }
        }
    }
    collect::<CsgNode>(world, &child, &mut roots);
    collect::<Sphere>(world, &child, &mut roots);
    collect::<Cuboid>(world, &child, &mut roots);
    collect::<Cylinder>(world, &child, &mut roots);
    collect::<Cone>(world, &child, &mut roots);
    collect::<Torus>(world, &child, &mut roots);
    collect::<HalfSpace>(world, &child, &mut roots);
    collect::<SweptSphere>(world, &child, &mut roots);
    collect::<GeneralizedCylinder>(world, &child, &mut roots);
    collect::<MeshSolid>(world, &child, &mut roots);
    // An entity with two kinds was listed twice: its copies sort together.
    roots.sort_unstable_by_key(|&(o, e)| (o, e.id()));
    roots.dedup_by_key(|r| r.1);
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

/// A fingerprint of everything the bake reads (the `Debug` text of every
/// component, hashed: a pass over the whole world). [`sync_scene`] no longer
/// uses it: it compares with copies per component (see `engine/src/live.rs`).
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

/// System: brings `scene` up to date with `world`, re-baking only the objects
/// whose inputs changed since the last call (returns whether anything was
/// baked). The first call bakes everything; see `engine/src/live.rs`.
pub fn sync_scene(world: &mut World, scene: &mut RenderScene) -> Result<bool, BakeError> {
    crate::live::sync_live(world, crate::changes::Scope::All, scene)
}

/// System: [`sync_scene`] for a tool that knows what it touched: `touched`
/// lists every entity it spawned, despawned, or on which it added, changed
/// or removed a rothray component since the last sync. Only those are
/// compared with the last sync's copies, so the cost follows the changes,
/// not the scene (an entity left out of the list is seen at the next
/// [`sync_scene`]). The first sync of a scene looks at every entity.
pub fn sync_scene_touched(world: &mut World, scene: &mut RenderScene, touched: &[Entity]) -> Result<bool, BakeError> {
    crate::live::sync_live(world, crate::changes::Scope::Some(touched), scene)
}

/// Where one object's rows sit in the baked tables (half-open ranges).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Slice {
    /// Program nodes (the root is the last).
    pub nodes: [u32; 2],
    /// Entries of `Program::children`.
    pub children: [u32; 2],
    /// Rows of the leaf table and of `leaf_info`.
    pub leaves: [u32; 2],
    /// Wide-node BVHs.
    pub wides: [u32; 2],
    /// Entities of the tree (in the live state's member list).
    pub members: [u32; 2],
}

/// A world (or some of its objects) baked into tables, before they go into
/// a scene.
#[derive(Default)]
pub(crate) struct Baked {
    pub leaves: LeafTable,
    pub leaf_info: Vec<LeafInfo>,
    pub objects: Vec<ObjectInfo>,
    pub program: Program,
    /// Per object, its rows.
    pub slices: Vec<Slice>,
    /// Per object, the entities of its tree (a shared child once per use).
    pub members: Vec<Entity>,
}

enum Visit<'a> {
    Enter(Entity, DAffine3, Option<Vec3>),
    /// A node's children from `next` on, under its transform and colour:
    /// one entry per node, not one per child (a union of 10^6 spheres held
    /// 120 MB of pending children at the bake's peak).
    Children {
        kids: &'a [Entity],
        next: usize,
        global: DAffine3,
        color: Option<Vec3>,
    },
    Exit(Entity, Op, usize),
}

/// What a bake's leaves depend on besides the World: the swept-sphere and
/// generalized-cylinder tolerance and the accuracy knobs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BakeSettings {
    pub tolerance: f32,
    pub knobs: Knobs,
}

/// Where [`bake_object`] writes.
struct ObjectSink<'a> {
    baked: &'a mut Baked,
    ops: &'a mut Vec<ProgOp>,
    on_path: &'a mut EntitySet,
    settings: BakeSettings,
}

/// The generalized cylinder of `d` at the bake's tolerance and knobs: the
/// `gcyl` knob changes the marching and bisection tolerance only, the frame
/// samples follow the `frame` knob or else the scene tolerance.
fn gcyl_data(d: &GeneralizedCylinder, settings: &BakeSettings) -> Result<GenCylData, rothray_primitives::ShapeError> {
    let (tol, knobs) = (settings.tolerance, &settings.knobs);
    let samples = match (knobs.frame, knobs.gcyl) {
        (Some(n), _) => Some(n as usize),
        (None, Some(_)) => Some(rothray_primitives::gcyl::frame_samples(tol)),
        (None, None) => None,
    };
    GenCylData::with_frame_samples(d, knobs.gcyl.unwrap_or(tol), samples)
}

/// The shape components of an entity.
type ShapeQuery<'a> = (
    Option<&'a Sphere>,
    Option<&'a Cuboid>,
    Option<&'a Cylinder>,
    Option<&'a Cone>,
    Option<&'a Torus>,
    Option<&'a HalfSpace>,
    Option<&'a SweptSphere>,
    Option<&'a GeneralizedCylinder>,
    Option<&'a MeshSolid>,
);

/// Everything the bake reads of an entity, fetched through one `hecs` view:
/// an entity lookup per entity instead of a lookup and a borrow per
/// component (15 of them per entity made the bake of 100 000 objects take
/// 184 ms).
type BakeQuery<'a> = (Option<&'a Transform>, Option<&'a Material>, Option<&'a Name>, Option<&'a CsgNode>, ShapeQuery<'a>);

/// A leaf entity's shape, borrowed.
enum LeafRef<'a> {
    Analytic(LeafShape),
    Swept(&'a SweptSphere),
    GenCyl(&'a GeneralizedCylinder),
    Mesh(&'a Arc<MeshData>),
}

fn leaf_ref<'a>(s: &ShapeQuery<'a>) -> Option<LeafRef<'a>> {
    let analytic = match *s {
        (Some(x), ..) => Some(LeafShape::Sphere(*x)),
        (_, Some(x), ..) => Some(LeafShape::Cuboid(*x)),
        (_, _, Some(x), ..) => Some(LeafShape::Cylinder(*x)),
        (_, _, _, Some(x), ..) => Some(LeafShape::Cone(*x)),
        (_, _, _, _, Some(x), ..) => Some(LeafShape::Torus(*x)),
        (_, _, _, _, _, Some(x), ..) => Some(LeafShape::HalfSpace(*x)),
        _ => None,
    };
    if let Some(a) = analytic {
        return Some(LeafRef::Analytic(a));
    }
    match *s {
        (.., Some(x), _, _) => Some(LeafRef::Swept(x)),
        (.., Some(x), _) => Some(LeafRef::GenCyl(x)),
        (.., Some(x)) => Some(LeafRef::Mesh(&x.0)),
        _ => None,
    }
}

/// Flattens the tree of `root` (object `oi`) into leaf rows, `leaf_info`
/// rows, member entities and post-order ops (ending with its `Root`).
/// Iterative, so any nesting depth works.
fn bake_object<'a>(view: &'a hecs::ViewBorrow<BakeQuery>, root: Entity, oi: u32, sink: &mut ObjectSink) -> Result<(), BakeError> {
    let ObjectSink { baked, ops, on_path, settings } = sink;
    let (leaves, leaf_info) = (&mut baked.leaves, &mut baked.leaf_info);
    let mut stack: Vec<Visit<'a>> = vec![Visit::Enter(root, DAffine3::IDENTITY, None)];
    while let Some(v) = stack.pop() {
        match v {
            Visit::Children { kids, next, global, color } => {
                if let Some(&c) = kids.get(next) {
                    stack.push(Visit::Children { kids, next: next + 1, global, color });
                    stack.push(Visit::Enter(c, global, color));
                }
            }
            Visit::Enter(e, parent, color) => {
                let Some((transform, material, name, node, shapes)) = view.get(e) else { return Err(BakeError::NotASolid { entity: e }) };
                baked.members.push(e);
                let global = parent * transform.map(|t| t.0).unwrap_or(DAffine3::IDENTITY);
                let color = material.map(|m| m.color).or(color);
                let name_of = || name.map(|n| n.0.clone());
                if let Some(desc) = leaf_ref(&shapes) {
                    let bad = |error: rothray_primitives::ShapeError| BakeError::BadShape { entity: e, name: name_of(), error };
                    let pushed = match desc {
                        LeafRef::Analytic(shape) => leaves.push(&shape, &global),
                        LeafRef::Swept(d) => {
                            let data = SweptSphereData::new(d, settings.knobs.sweep.unwrap_or(settings.tolerance)).map_err(bad)?;
                            leaves.push_data(&LeafData::SweptSphere(Arc::new(data)), &global)
                        }
                        LeafRef::GenCyl(d) => {
                            let data = gcyl_data(d, settings).map_err(bad)?;
                            leaves.push_data(&LeafData::GenCylinder(Arc::new(data)), &global)
                        }
                        LeafRef::Mesh(m) => {
                            m.set_far_field(settings.knobs.winding.unwrap_or(rothray_primitives::mesh::BETA));
                            leaves.push_data(&LeafData::Mesh(m.clone()), &global)
                        }
                    };
                    let idx = pushed.map_err(|err| match err {
                        LeafError::Shape(error) => BakeError::BadShape { entity: e, name: name_of(), error },
                        LeafError::SingularTransform => BakeError::SingularTransform { entity: e, name: name_of() },
                        LeafError::OutOfRange(message) => BakeError::OutOfRange { entity: e, name: name_of(), message },
                    })?;
                    // No default text per leaf (`RenderScene::leaf_name` makes
                    // it): 32 bytes per leaf on a union of 10^6 spheres.
                    let name = name_of().unwrap_or_default();
                    leaf_info.push(LeafInfo { entity: e, name, color: color.unwrap_or(Vec3::splat(0.8)), object: oi });
                    ops.push(ProgOp::Leaf(idx));
                } else if let Some(node) = node {
                    if node.children.is_empty() {
                        return Err(BakeError::BadNode { entity: e, message: "CSG node without children".into() });
                    }
                    if !on_path.insert(e) {
                        return Err(BakeError::BadNode { entity: e, message: "CSG node is its own ancestor".into() });
                    }
                    stack.push(Visit::Exit(e, node.op, node.children.len()));
                    for &c in node.children.iter().rev() {
                        let solid = view.get(c).is_some_and(|(_, _, _, n, s)| n.is_some() || leaf_ref(&s).is_some());
                        if !solid {
                            return Err(BakeError::NotASolid { entity: c });
                        }
                    }
                    stack.push(Visit::Children { kids: &node.children, next: 0, global, color });
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
    ops.push(ProgOp::Root(oi));
    Ok(())
}

/// Bakes the trees of `roots` (as objects `0..`) into fresh tables: leaves in
/// pre-order of the trees, the CSG program, each object's rows.
pub(crate) fn bake_objects(world: &World, roots: &[Entity], settings: BakeSettings) -> Result<Baked, BakeError> {
    let torus_tol = settings.knobs.torus.unwrap_or(rothray_primitives::kernels::TORUS_TOLERANCE) as f64;
    let mut baked = Baked { leaves: LeafTable { torus_tol, ..LeafTable::default() }, ..Baked::default() };
    // Program nodes reference leaves by index: the leaves are pushed first, in
    // a pass that also records the program's ops, replayed afterwards.
    let mut ops: Vec<ProgOp> = Vec::new();
    let mut on_path = EntitySet::default();
    let view = world.view::<BakeQuery>();
    for (oi, &root) in roots.iter().enumerate() {
        let (l0, m0) = (baked.leaves.len() as u32, baked.members.len() as u32);
        let mut sink = ObjectSink { baked: &mut baked, ops: &mut ops, on_path: &mut on_path, settings };
        bake_object(&view, root, oi as u32, &mut sink)?;
        let (l1, m1) = (baked.leaves.len() as u32, baked.members.len() as u32);
        baked.slices.push(Slice { leaves: [l0, l1], members: [m0, m1], ..Slice::default() });
        baked.objects.push(ObjectInfo {
            entity: root,
            name: view.get(root).and_then(|q| q.2).map_or_else(|| format!("object{oi}"), |n| n.0.clone()),
            root: 0,
            bounds: Aabb::EMPTY,
        });
    }
    // One copy of the leaves' bounds: the program's (24 bytes per leaf).
    let leaf_bounds = std::mem::take(&mut baked.leaves.bounds);
    baked.program = replay(&ops, (&baked.leaves, leaf_bounds), &mut baked.objects, &mut baked.slices);
    // A half-space keeps its offset relative to a point near its object (its
    // plane's point nearest the object's centre), not near the world origin.
    for (li, info) in baked.leaf_info.iter().enumerate() {
        let b = baked.objects[info.object as usize].bounds;
        if b.is_finite() && !b.is_empty() {
            baked.leaves.reanchor(li as u32, b.center());
        }
    }
    Ok(baked)
}

/// System: bakes every object of `world` into `scene` (leaf table in pre-order of
/// the trees, CSG program, BVHs).
pub fn bake_scene(world: &World, scene: &mut RenderScene) -> Result<(), BakeError> {
    let roots = find_objects(world);
    let baked = bake_objects(world, &roots, scene.bake_settings())?;
    install_baked(scene, baked);
    Ok(())
}

/// Moves baked tables into `scene` and builds what depends on all objects:
/// the object tree, the packet paths, the scene's bounds and tolerance.
pub(crate) fn install_baked(scene: &mut RenderScene, baked: Baked) {
    let Baked { leaves, leaf_info, objects, program, .. } = baked;
    scene.leaves = leaves;
    scene.program = program;
    scene.objects = objects;
    scene.leaf_info = leaf_info;
    build_object_tree(scene);
    bake_packet_paths(scene);
    scene.retry = scene.objects.iter().map(|o| retry_of(&scene.program, &scene.leaves, o)).collect();
    let bounds = scene_bounds(scene);
    set_scene_bounds(scene, bounds);
    scene.bake_count += 1;
    if scene.leaves.len() >= BIG_BAKE {
        // The bake's freed blocks (glibc keeps them): with the trims, a
        // union of 10^6 spheres keeps 291 bytes per leaf instead of 359.
        rothray_primitives::trim::release_free_memory();
    }
}

/// From this many leaves (or entities) a full bake hands its freed memory
/// back to the system: trimming costs a few ms.
pub(crate) const BIG_BAKE: usize = 1 << 16;

/// How an object's unsure nearest queries are tried again (see
/// [`Retry`]).
pub(crate) fn retry_of(program: &Program, leaves: &LeafTable, o: &ObjectInfo) -> Retry {
    let masked_first = program.kind[o.root as usize] == rothray_csg::NodeKind::Difference && program.masks_help(o.root);
    let b = &o.bounds;
    let useful = subtree_has_mesh(program, leaves, o.root) && b.is_finite() && !b.is_empty();
    // (A lone leaf's first try is sure, or its own packet answers: the
    // sweep is for trees the masked try or the redo would take apart.)
    let deep = program.kind[o.root as usize] != rothray_csg::NodeKind::Leaf && program.deep_fits(o.root);
    Retry { window: if useful { 0.1 * b.diagonal_length() } else { 0.0 }, masked_first, deep }
}

/// Builds the objects' tree (binary: tiles cull with it, rays take their
/// candidates from it, a live scene refits it) over the bounded objects, and
/// lists the unbounded ones.
pub(crate) fn build_object_tree(scene: &mut RenderScene) {
    let mut boxes = Vec::new();
    let mut ids = Vec::new();
    let mut unbounded = Vec::new();
    for (i, o) in scene.objects.iter().enumerate() {
        if o.bounds.is_empty() {
            continue;
        }
        if o.bounds.is_finite() {
            boxes.push(o.bounds);
            ids.push(i as u32);
        } else {
            unbounded.push(i as u32);
        }
    }
    let mut cull = FlatBvh::build_cull(&boxes, 2);
    for p in cull.prims.iter_mut() {
        *p = ids[*p as usize];
    }
    scene.objects_cull = cull;
    scene.unbounded = unbounded;
}

/// The bounds of the finite objects; with none, the finite parts of the
/// leaves (of live objects only: a live scene's tables hold dead rows).
pub(crate) fn scene_bounds(scene: &RenderScene) -> Aabb {
    let mut bounds = Aabb::EMPTY;
    for o in &scene.objects {
        if o.bounds.is_finite() && !o.bounds.is_empty() {
            bounds = bounds.union(&o.bounds);
        }
    }
    if bounds.is_empty() {
        // Only unbounded solids (or none): take the leaves' finite parts
        // (their program nodes' bounds).
        let p = &scene.program;
        for (n, lb) in p.bounds.iter().enumerate().filter(|&(n, _)| p.kind[n] == NodeKind::Leaf) {
            let live = scene.leaf_info[p.first[n] as usize].object != u32::MAX;
            if live && lb.is_finite() {
                bounds = bounds.union(lb);
            }
        }
    }
    bounds
}

/// Sets the scene's bounds and the tolerances that follow them.
pub(crate) fn set_scene_bounds(scene: &mut RenderScene, bounds: Aabb) {
    // No floor on the size: a floor of 1e-3 made the fusing tolerance 1% of a
    // scene 1e-6 across (tests/stress.rs, octahedron at scale 1e-6).
    let diag = if bounds.is_empty() { 1.0 } else { bounds.diagonal_length() };
    let diag = if diag > 0.0 && diag.is_finite() { diag } else { 1.0 };
    scene.bounds = bounds;
    // The fusing tolerance: 1e-5 of the scene's size, and 2e-6 of a ray origin's
    // distance from it (f32 rounding of the crossings grows with both); the
    // `fuse` knob scales both (README: the curve on scenes/coincident.json).
    let fuse = scene.knobs.fuse.unwrap_or(1e-5);
    scene.eps = fuse * diag;
    scene.eps_far = 0.2 * fuse;
    scene.center = if bounds.is_empty() { Vec3::ZERO } else { bounds.center() };
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
fn replay(ops: &[ProgOp], (leaves, leaf_bounds): (&LeafTable, Vec<Aabb>), objects: &mut [ObjectInfo], slices: &mut [Slice]) -> Program {
    #[derive(Clone, Copy)]
    enum Val {
        Node(u32),
        /// A flattened operand list: first and last cell in `cells`.
        List(u32, u32),
    }
    const END: u32 = u32::MAX;
    let absorbed = absorbed_ops(ops);
    let mut b = ProgramBuilder::new(leaves);
    // Freed after the last leaf, before the ops that build wide nodes' trees
    // (the bake's peak).
    let mut leaf_bounds = Some(leaf_bounds);
    let last_leaf = ops.iter().rposition(|op| matches!(op, ProgOp::Leaf(_)));
    let mut vals: Vec<Val> = Vec::new();
    // Linked list cells: (node, next cell).
    let mut cells: Vec<(u32, u32)> = Vec::new();
    let mut flat: Vec<u32> = Vec::new();
    // Where the current object's rows start.
    let mut start = [0u32; 3];
    for (k, op) in ops.iter().enumerate() {
        match *op {
            ProgOp::Leaf(i) => {
                let bounds = leaf_bounds.as_ref().expect("leaves come before the last leaf")[i as usize];
                vals.push(Val::Node(b.leaf_with_bounds(i, bounds)));
                if Some(k) == last_leaf {
                    leaf_bounds = None;
                }
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
                let p = &b.program;
                let end = [p.kind.len() as u32, p.children.len() as u32, p.wides.len() as u32];
                let s = &mut slices[oi as usize];
                (s.nodes, s.children, s.wides) = ([start[0], end[0]], [start[1], end[1]], [start[2], end[2]]);
                start = end;
            }
        }
    }
    b.finish()
}

fn subtree_has_mesh(program: &Program, leaves: &LeafTable, n: u32) -> bool {
    let nu = n as usize;
    let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
    match program.kind[nu] {
        NodeKind::Leaf => leaves.is_mesh(first as u32),
        _ => program.children[first..first + count].iter().any(|&c| subtree_has_mesh(program, leaves, c)),
    }
}

impl RenderScene {
    /// What the bake's leaves depend on besides the World.
    pub(crate) fn bake_settings(&self) -> BakeSettings {
        BakeSettings { tolerance: self.tolerance_or_default(), knobs: self.knobs }
    }

    /// The swept-sphere / generalized-cylinder tolerance the bake uses.
    pub(crate) fn tolerance_or_default(&self) -> f32 {
        if self.tolerance > 0.0 {
            self.tolerance
        } else {
            rothray_primitives::sweep::DEFAULT_TOLERANCE
        }
    }

    /// The name of leaf `leaf`: its `Name`, else `leaf<i>`.
    pub fn leaf_name(&self, leaf: u32) -> std::borrow::Cow<'_, str> {
        match self.leaf_info.get(leaf as usize) {
            Some(l) if !l.name.is_empty() => l.name.as_str().into(),
            _ => format!("leaf{leaf}").into(),
        }
    }

    /// Bakes a world into a new scene.
    pub fn from_world(world: &World) -> Result<RenderScene, BakeError> {
        let mut s = RenderScene::default();
        bake_scene(world, &mut s)?;
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    use rothray_csg::{Mode, RayCtx, Scratch};
    use rothray_primitives::table::{LeafShape, Sphere};
    use rothray_primitives::Ray;

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
            let pa = replay(&ops, (&leaves, leaves.bounds.clone()), &mut a, &mut [Slice::default()]);
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
                let ctx = RayCtx::new(Ray::new(o, d), 1e-5);
                for mode in [Mode::All, Mode::Nearest] {
                    let va = pa.eval(&leaves, a[0].root, &ctx, mode, &mut sa);
                    let vb = pb.eval(&leaves, b[0].root, &ctx, mode, &mut sb);
                    assert_eq!(format!("{va:?} {:?}", sa.out.as_slice()), format!("{vb:?} {:?}", sb.out.as_slice()), "case {case}");
                }
                let p = o + d * rng.gen_range(0.0..8.0);
                assert_eq!(pa.contains(&leaves, a[0].root, p, &mut sa), pb.contains(&leaves, b[0].root, p, &mut sb), "case {case}");
            }
        }
    }
}
