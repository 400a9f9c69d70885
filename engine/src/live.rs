//! The live bake behind [`crate::sync_scene`]: the unit of re-baking is an
//! object (a root solid). A sync detects what changed ([`detect_changes`]),
//! finds the objects those entities belong to (a map from every entity of a
//! baked tree to its root, kept from the last bake), bakes just those objects
//! into small tables and copies them into the scene's tables: over their old
//! rows when the sizes match (a move, a new radius, a colour), else at the
//! end, leaving dead rows that a full bake sweeps away once they outnumber
//! the live ones. The rows written are recorded in the program's edit log
//! (`Program::record_edit`): the renderer's per-thread copies of the program
//! take just those rows. The packet meshes are kept object by object
//! ([`crate::live_meshes`]). The object trees are binary and refit in place
//! ([`crate::refit`]); they are rebuilt when the set or order of objects
//! changes, or when refits have made them worse than [`REBUILD_AT`] times
//! their cost when built.
//!
//! Same answers as a fresh bake: the objects keep the fresh bake's order
//! (`ObjectOrder`, then entity id), an object's rows are what a fresh bake
//! makes of it (offset), and the scene's bounds (hence its tolerance) are
//! the same union. Leaf rows do differ (`Hit::leaf`, `LeafInfo` by index):
//! compare leaves by entity.

use hecs::{Entity, World};
use rothray_csg::{Edit, NodeKind};
use rothray_primitives::{Aabb, LeafKind, LeafTable};

use crate::bake::{
    bake_objects, build_object_tree, find_objects, install_baked, retry_of, scene_bounds, set_scene_bounds, BakeError, BakeSettings, Baked,
    Slice, BIG_BAKE,
};
use crate::changes::{detect_changes, Changes, Scope, Snapshots};
use crate::components::Name;
use crate::entity_hash::{EntityMap, EntitySet};
use crate::live_meshes::MeshObjects;
use crate::owners::Owners;
use crate::packet::set_packet_paths;
use crate::refit::Refit;
use crate::scene::{ObjectInfo, RenderScene};

/// The object trees are rebuilt once refits have made their summed node
/// area this many times that of the fresh build. With 1.5, 10 000 objects
/// after 2 000 frames of 100 moves (`examples/live.rs --frames 1000`) traced
/// 1.40x as long as with a fresh tree; with 1.2, 1.04-1.18x, for a rebuild
/// (a few ms at 10 000 objects) every few hundred frames.
pub const REBUILD_AT: f64 = 1.2;

/// What a live scene keeps between syncs.
#[derive(Default)]
pub(crate) struct LiveState {
    snaps: Snapshots,
    /// Per object (parallel to `RenderScene::objects`), its rows.
    slices: Vec<Slice>,
    /// Member entities of the objects' trees, by `Slice::members` (dead
    /// ranges included).
    members: Vec<Entity>,
    /// Entity -> the roots of the objects it is part of.
    owners: Owners,
    /// Root entity -> object index.
    index: EntityMap<u32>,
    /// Links of `RenderScene::objects_cull` for refits.
    tree: Refit,
    /// The objects' packet meshes.
    meshes: MeshObjects,
    /// Rows of objects that were re-baked elsewhere or are gone.
    dead_leaves: usize,
    settings: BakeSettings,
    /// What the syncs did (the tests check that each path ran).
    pub counts: LiveCounts,
}

/// What the syncs of a live scene did.
#[derive(Default, Debug, Clone, Copy)]
pub(crate) struct LiveCounts {
    /// Syncs that baked everything.
    pub full: u64,
    /// Syncs that re-baked some objects.
    pub partial: u64,
    /// Objects re-baked over their old rows.
    pub in_place: u64,
    /// Objects re-baked at the end of the tables.
    pub appended: u64,
    /// Object tree rebuilds after a partial sync (not counting full bakes).
    pub rebuilds: u64,
    /// Structural syncs that only added and removed objects
    /// ([`births`]: no listing of the objects, the tree edited in place).
    pub births: u64,
}

#[path = "live_births.rs"]
mod births;

/// Dead rows are swept by a full bake once there are more of them than this
/// and than live rows.
const SWEEP_MIN: usize = if cfg!(test) { 64 } else { 4096 };

/// A sync that re-bakes more than this many objects, and more than half of
/// them, bakes everything (same work, and fresh trees).
const FULL_MIN: usize = 256;

/// The sync: see the module documentation.
pub(crate) fn sync_live(world: &World, scope: Scope, scene: &mut RenderScene) -> Result<bool, BakeError> {
    let settings = scene.bake_settings();
    let full = scene.live.as_ref().is_none_or(|l| l.settings != settings);
    let mut live = scene.live.take().unwrap_or_default();
    let changes = detect_changes(world, if full { Scope::All } else { scope }, &mut live.snaps);
    let result = if full {
        drop(changes); // 8 bytes per entity, at the peak of a first bake
        if world.len() as usize >= BIG_BAKE {
            // The scan's freed blocks, before a large bake's peak.
            rothray_primitives::trim::release_free_memory();
        }
        bake_all(world, scene, &mut live, settings).map(|_| true)
    } else if changes.dirty.is_empty() {
        Ok(false)
    } else {
        sync_changes(world, scene, &mut live, &changes).map(|_| true)
    };
    if result.is_ok() {
        scene.live = Some(live);
    }
    result
}

/// Bakes every object and remembers who owns what.
fn bake_all(world: &World, scene: &mut RenderScene, live: &mut LiveState, settings: BakeSettings) -> Result<(), BakeError> {
    let roots = find_objects(world);
    let mut baked = bake_objects(world, &roots, settings)?;
    live.slices = std::mem::take(&mut baked.slices);
    live.members = std::mem::take(&mut baked.members);
    live.owners.reset(live.members.iter().map(|e| e.id() as usize + 1).max().unwrap_or(0));
    live.index = EntityMap::with_capacity_and_hasher(roots.len(), Default::default());
    for (oi, (s, &root)) in live.slices.iter().zip(&roots).enumerate() {
        live.index.insert(root, oi as u32);
        for &e in &live.members[s.members[0] as usize..s.members[1] as usize] {
            live.owners.add(e, root);
        }
    }
    live.dead_leaves = 0;
    live.settings = settings;
    live.counts.full += 1;
    install_baked(scene, baked);
    link_object_tree(scene, live);
    live.meshes.rebuild(scene);
    Ok(())
}

/// Re-bakes the objects that `changes` touch.
fn sync_changes(world: &World, scene: &mut RenderScene, live: &mut LiveState, changes: &Changes) -> Result<(), BakeError> {
    if changes.structural {
        if let Some(b) = births::classify(world, changes, live).filter(|b| births::small(b, scene, live)) {
            live.counts.partial += 1;
            births::apply(world, scene, live, b)?;
            update_scene_bounds(scene);
            set_packet_paths(scene, live.meshes.packet_meshes());
            scene.bake_count += 1;
            return Ok(());
        }
    }
    let dirty = find_dirty_objects(changes, live);
    // Structural: the objects are listed again (in the fresh bake's order),
    // the new ones baked; else only the dirty ones, in object order.
    let roots = if changes.structural { find_objects(world) } else { Vec::new() };
    let todo: Vec<Entity> = if changes.structural {
        roots.iter().copied().filter(|r| dirty.contains(r) || !live.index.contains_key(r)).collect()
    } else {
        let mut by_index: Vec<(u32, Entity)> = dirty.iter().map(|r| (live.index[r], *r)).collect();
        by_index.sort_unstable();
        by_index.into_iter().map(|(_, r)| r).collect()
    };
    // Many objects or many dead rows: bake everything.
    let many = todo.len() > FULL_MIN && todo.len() * 2 > scene.objects.len();
    let sweep = live.dead_leaves > SWEEP_MIN && live.dead_leaves > scene.leaves.len() - live.dead_leaves;
    if many || sweep {
        return bake_all(world, scene, live, live.settings);
    }
    let baked = bake_objects(world, &todo, live.settings)?;
    live.counts.partial += 1;
    if changes.structural {
        place_objects(world, scene, live, &baked, &roots);
        live.counts.rebuilds += 1;
        build_object_tree(scene);
        link_object_tree(scene, live);
        scene.retry = scene.objects.iter().map(|o| retry_of(&scene.program, &scene.leaves, o)).collect();
        live.meshes.rebuild(scene);
    } else {
        let moved = replace_objects(world, scene, live, &baked);
        refit_object_tree(scene, live, &moved);
    }
    update_scene_bounds(scene);
    set_packet_paths(scene, live.meshes.packet_meshes());
    scene.bake_count += 1;
    Ok(())
}

/// The roots of the objects that hold a changed entity.
fn find_dirty_objects(changes: &Changes, live: &LiveState) -> EntitySet {
    let mut dirty = EntitySet::default();
    for e in &changes.dirty {
        dirty.extend(live.owners.roots(*e));
    }
    dirty
}

/// Puts object `k` of `baked` into the scene's tables as object `oi` (over
/// or instead of the rows of `old`); returns its info and rows.
fn rebake_object(
    world: &World,
    scene: &mut RenderScene,
    live: &mut LiveState,
    baked: &Baked,
    k: usize,
    oi: u32,
    old: Option<Slice>,
) -> (ObjectInfo, Slice) {
    let root = baked.objects[k].entity;
    if let Some(s) = old {
        forget_members(live, root, s);
    }
    let slice = place_object(scene, live, baked, k, old);
    own_members(live, root, slice);
    let b = &baked.objects[k];
    let root_node = b.root - baked.slices[k].nodes[0] + slice.nodes[0];
    for l in &mut scene.leaf_info[slice.leaves[0] as usize..slice.leaves[1] as usize] {
        l.object = oi;
    }
    (ObjectInfo { entity: root, name: object_name(world, root, oi), root: root_node, bounds: b.bounds }, slice)
}

/// Puts the re-baked objects of `baked` over the old ones (same set, same
/// order); returns the objects whose bounds changed, with their old bounds.
fn replace_objects(world: &World, scene: &mut RenderScene, live: &mut LiveState, baked: &Baked) -> Vec<(u32, Aabb)> {
    let mut moved = Vec::new();
    for k in 0..baked.objects.len() {
        let oi = live.index[&baked.objects[k].entity];
        let old = live.slices[oi as usize];
        let (info, slice) = rebake_object(world, scene, live, baked, k, oi, Some(old));
        let old_bounds = std::mem::replace(&mut scene.objects[oi as usize], info).bounds;
        scene.retry[oi as usize] = retry_of(&scene.program, &scene.leaves, &scene.objects[oi as usize]);
        if !same_box(&old_bounds, &scene.objects[oi as usize].bounds) {
            moved.push((oi, old_bounds));
        }
        live.slices[oi as usize] = slice;
        live.meshes.update(scene, oi);
    }
    moved
}

/// Lays the objects out in `roots` order: the re-baked ones of `baked` (in
/// `roots` order) into the scene's tables, the others where they were; the
/// rows of objects that are gone die.
fn place_objects(world: &World, scene: &mut RenderScene, live: &mut LiveState, baked: &Baked, roots: &[Entity]) {
    let mut old_objects = std::mem::take(&mut scene.objects);
    let old_slices = std::mem::take(&mut live.slices);
    let mut kept = vec![false; old_objects.len()];
    let mut next = 0usize; // next object of `baked`
    for (oi, &root) in roots.iter().enumerate() {
        let oi = oi as u32;
        let old = live.index.get(&root).map(|&i| i as usize);
        if let Some(i) = old {
            kept[i] = true;
        }
        let (info, slice) = if baked.objects.get(next).is_some_and(|o| o.entity == root) {
            next += 1;
            rebake_object(world, scene, live, baked, next - 1, oi, old.map(|i| old_slices[i]))
        } else {
            let i = old.expect("an object not re-baked was baked before");
            let o = &mut old_objects[i];
            let name = if i as u32 == oi { std::mem::take(&mut o.name) } else { object_name(world, root, oi) };
            let slice = old_slices[i];
            for l in &mut scene.leaf_info[slice.leaves[0] as usize..slice.leaves[1] as usize] {
                l.object = oi;
            }
            (ObjectInfo { entity: root, name, root: o.root, bounds: o.bounds }, slice)
        };
        scene.objects.push(info);
        live.slices.push(slice);
    }
    for (i, o) in old_objects.iter().enumerate() {
        if !kept[i] {
            forget_members(live, o.entity, old_slices[i]);
            release_rows(scene, live, old_slices[i]);
        }
    }
    live.index = roots.iter().enumerate().map(|(i, &r)| (r, i as u32)).collect();
}

fn same_box(a: &Aabb, b: &Aabb) -> bool {
    let bits = |v: glam::Vec3| v.to_array().map(f32::to_bits);
    bits(a.min) == bits(b.min) && bits(a.max) == bits(b.max)
}

/// An object's name: its `Name`, else `object<i>` (as a fresh bake names it).
fn object_name(world: &World, root: Entity, oi: u32) -> String {
    world.get::<&Name>(root).map(|n| n.0.clone()).unwrap_or_else(|_| format!("object{oi}"))
}

fn forget_members(live: &mut LiveState, root: Entity, s: Slice) {
    for &e in &live.members[s.members[0] as usize..s.members[1] as usize] {
        live.owners.remove(e, root);
    }
}

fn own_members(live: &mut LiveState, root: Entity, s: Slice) {
    for &e in &live.members[s.members[0] as usize..s.members[1] as usize] {
        live.owners.add(e, root);
    }
}

/// Marks an object's rows dead (no live root reaches them).
fn release_rows(scene: &mut RenderScene, live: &mut LiveState, s: Slice) {
    for l in &mut scene.leaf_info[s.leaves[0] as usize..s.leaves[1] as usize] {
        l.object = u32::MAX;
    }
    live.dead_leaves += (s.leaves[1] - s.leaves[0]) as usize;
}

fn len(r: [u32; 2]) -> u32 {
    r[1] - r[0]
}

/// Copies object `k` of `baked` into the scene's tables, over the rows of
/// `old` when the sizes match, else at the end (and `old` dies); returns
/// where it went.
fn place_object(scene: &mut RenderScene, live: &mut LiveState, baked: &Baked, k: usize, old: Option<Slice>) -> Slice {
    let s = baked.slices[k];
    let fits = old.filter(|o| {
        len(o.nodes) == len(s.nodes)
            && len(o.children) == len(s.children)
            && len(o.leaves) == len(s.leaves)
            && len(o.wides) == len(s.wides)
            && len(o.members) == len(s.members)
    });
    let p = &scene.program;
    let end = |at: usize, r: [u32; 2]| [at as u32, at as u32 + len(r)];
    let at = fits.unwrap_or(Slice {
        nodes: end(p.kind.len(), s.nodes),
        children: end(p.children.len(), s.children),
        leaves: end(scene.leaves.len(), s.leaves),
        wides: end(p.wides.len(), s.wides),
        members: end(live.members.len(), s.members),
    });
    if fits.is_some() {
        live.counts.in_place += 1;
    } else {
        live.counts.appended += 1;
        if let Some(o) = old {
            release_rows(scene, live, o);
        }
    }
    copy_leaves(scene, baked, s, at);
    copy_nodes(scene, baked, s, at);
    let m = &baked.members[s.members[0] as usize..s.members[1] as usize];
    if fits.is_some() {
        live.members[at.members[0] as usize..at.members[1] as usize].copy_from_slice(m);
    } else {
        live.members.extend_from_slice(m);
    }
    at
}

/// Writes row `at` of `v` (`at == v.len()`: appends).
fn put<T>(v: &mut Vec<T>, at: usize, x: T) {
    if at == v.len() {
        v.push(x);
    } else {
        v[at] = x;
    }
}

/// Copies the leaf rows (and `leaf_info`) of slice `s` of `baked` to `at`.
fn copy_leaves(scene: &mut RenderScene, baked: &Baked, s: Slice, at: Slice) {
    let (src, dst) = (&baked.leaves, &mut scene.leaves);
    for i in 0..len(s.leaves) as usize {
        let (a, b) = (s.leaves[0] as usize + i, at.leaves[0] as usize + i);
        let ext = match src.kind[a] {
            LeafKind::SweptSphere => {
                dst.sweeps.push(src.sweeps[src.ext[a] as usize].clone());
                dst.sweeps.len() - 1
            }
            LeafKind::GenCylinder => {
                dst.gcyls.push(src.gcyls[src.ext[a] as usize].clone());
                dst.gcyls.len() - 1
            }
            LeafKind::Mesh => {
                let m = &src.meshes[src.ext[a] as usize];
                match dst.meshes.iter().position(|x| std::sync::Arc::ptr_eq(x, m)) {
                    Some(i) => i,
                    None => {
                        dst.meshes.push(m.clone());
                        dst.meshes.len() - 1
                    }
                }
            }
            k if LeafTable::has_map64(k) => {
                dst.maps64.push(src.maps64[src.ext[a] as usize]);
                dst.maps64.len() - 1
            }
            _ => 0,
        };
        put(&mut dst.kind, b, src.kind[a]);
        put(&mut dst.to_local, b, src.to_local[a]);
        put(&mut dst.anchor, b, src.anchor[a]);
        put(&mut dst.p0, b, src.p0[a]);
        put(&mut dst.p1, b, src.p1[a]);
        put(&mut dst.ext, b, ext as u32);
        let map = match src.kind[a] {
            LeafKind::Mesh => {
                dst.mesh_maps.push(src.mesh_maps[src.mesh_map[a] as usize]);
                dst.mesh_maps.len() - 1
            }
            LeafKind::Cuboid => {
                dst.box_normals.push(src.box_normals[src.mesh_map[a] as usize]);
                dst.box_normals.len() - 1
            }
            _ => 0,
        };
        put(&mut dst.mesh_map, b, map as u32);
        put(&mut scene.leaf_info, b, baked.leaf_info[a].clone());
    }
}

/// Copies the program nodes, children and wide BVHs of slice `s` of `baked`
/// to `at`, moving the ids they hold.
fn copy_nodes(scene: &mut RenderScene, baked: &Baked, s: Slice, at: Slice) {
    let (src, dst) = (&baked.program, &mut scene.program);
    let shift = |x: u32, from: [u32; 2], to: [u32; 2]| x - from[0] + to[0];
    for i in 0..len(s.nodes) as usize {
        let (a, b) = (s.nodes[0] as usize + i, at.nodes[0] as usize + i);
        let first = if src.kind[a] == NodeKind::Leaf {
            shift(src.first[a], s.leaves, at.leaves)
        } else {
            shift(src.first[a], s.children, at.children)
        };
        let wide = if src.wide[a] == u32::MAX { u32::MAX } else { shift(src.wide[a], s.wides, at.wides) };
        put(&mut dst.kind, b, src.kind[a]);
        put(&mut dst.first, b, first);
        put(&mut dst.count, b, src.count[a]);
        put(&mut dst.wide, b, wide);
        put(&mut dst.bounds, b, src.bounds[a]);
        put(&mut dst.leafy, b, src.leafy[a]);
        put(&mut dst.small, b, src.small[a]);
    }
    for i in 0..len(s.children) as usize {
        let c = shift(src.children[s.children[0] as usize + i], s.nodes, at.nodes);
        put(&mut dst.children, at.children[0] as usize + i, c);
    }
    for i in 0..len(s.wides) as usize {
        put(&mut dst.wides, at.wides[0] as usize + i, src.wides[s.wides[0] as usize + i].clone());
    }
    // The tile programs' copies take these rows only.
    dst.record_edit(Edit { nodes: at.nodes, children: at.children, wides: at.wides });
}

/// Links the freshly built object tree for refits.
fn link_object_tree(scene: &mut RenderScene, live: &mut LiveState) {
    let objects = &scene.objects;
    live.tree = Refit::new(&mut scene.objects_cull, objects.len(), |p| objects[p as usize].bounds);
}

/// Refits the object tree over the objects whose bounds changed; rebuilds
/// it when an object's box became or stopped being finite, or when it has
/// degraded past [`REBUILD_AT`].
fn refit_object_tree(scene: &mut RenderScene, live: &mut LiveState, moved: &[(u32, Aabb)]) {
    let bounded = |b: &Aabb| !b.is_empty() && b.is_finite();
    let objects = &scene.objects;
    let rebuild = moved.iter().any(|(oi, old)| bounded(old) != bounded(&objects[*oi as usize].bounds) || !bounded(old));
    if !rebuild {
        for &(oi, _) in moved {
            live.tree.update(&mut scene.objects_cull, oi, |p| objects[p as usize].bounds);
        }
    }
    if rebuild || live.tree.degradation() > REBUILD_AT {
        live.counts.rebuilds += 1;
        build_object_tree(scene);
        link_object_tree(scene, live);
    }
}

/// The scene's bounds (hence its tolerance) from the refit tree's root: the
/// same union of the finite objects' boxes that a fresh bake takes.
fn update_scene_bounds(scene: &mut RenderScene) {
    let bounds = if scene.objects_cull.nodes.is_empty() { scene_bounds(scene) } else { scene.objects_cull.bounds() };
    set_scene_bounds(scene, bounds);
}
