//! Structural syncs that only add and remove whole objects (a tool spawns
//! and despawns solids), at a cost that follows the change: no listing of
//! every root, no rebuild of the object tree. The objects keep the fresh
//! bake's order (`ObjectOrder`, then entity id): the new ones are placed by
//! a binary search among the survivors, the survivors renumbered in one
//! pass (their rows stay where they are: only `LeafInfo::object` and the
//! default names of those that shifted change), and the object tree loses
//! and gains leaves in place ([`Refit::remove`], [`Refit::insert`]).
//!
//! Anything else structural (a node's children changed, `Hidden` or
//! `ObjectOrder` changed on an object, a member left behind by a despawned
//! root, a new node over an old entity, a node or solid of no object
//! despawned) takes the general path, which lists the objects again.

use hecs::{Entity, World};
use rothray_primitives::Aabb;

use super::{forget_members, rebake_object, refit_object_tree, release_rows, replace_objects, LiveState, FULL_MIN, REBUILD_AT, SWEEP_MIN};
use crate::bake::{bake_objects, build_object_tree, retry_of, BakeError, Baked};
use crate::changes::Changes;
use crate::components::*;
use crate::entity_hash::EntitySet;
use crate::scene::{ObjectInfo, RenderScene, Retry};

const NONE: u32 = u32::MAX;

/// What a structural sync of births and deaths does.
pub(super) struct Births {
    /// Roots of the objects that are gone.
    dead: Vec<Entity>,
    /// Roots of the new objects, in the fresh bake's order.
    born: Vec<Entity>,
    /// Roots of surviving objects with changed members (none structural),
    /// in object order.
    changed: Vec<Entity>,
}

/// An object's place in the fresh bake's order (`find_objects`).
fn order_key(world: &World, root: Entity) -> (u32, u32) {
    (world.get::<&ObjectOrder>(root).map_or(u32::MAX, |o| o.0), root.id())
}

/// Does `e` hold a solid (what `find_objects` lists when it is no child)?
fn is_solid(world: &World, e: Entity) -> bool {
    let Ok(r) = world.entity(e) else { return false };
    r.has::<CsgNode>()
        || r.has::<Sphere>()
        || r.has::<Cuboid>()
        || r.has::<Cylinder>()
        || r.has::<Cone>()
        || r.has::<Torus>()
        || r.has::<HalfSpace>()
        || r.has::<SweptSphere>()
        || r.has::<GeneralizedCylinder>()
        || r.has::<MeshSolid>()
}

/// The births and deaths in `changes`, or `None` when they need the
/// general path (see the module documentation).
pub(super) fn classify(world: &World, changes: &Changes, live: &LiveState) -> Option<Births> {
    // A hidden tree's entities belong to no object, and an old node may
    // hold them: only a listing tells.
    if world.query::<&Hidden>().iter().next().is_some() {
        return None;
    }
    let structural: EntitySet = changes.structural_entities.iter().copied().collect();
    let (mut dead, mut fresh, mut changed) = (Vec::new(), EntitySet::default(), EntitySet::default());
    for &e in &changes.dirty {
        if !world.contains(e) {
            let mut owners = live.owners.roots(e).peekable();
            if live.index.contains_key(&e) {
                dead.push(e);
            } else if owners.peek().is_none() {
                // A node of no object went (a hidden tree's: its
                // children, nobody's now, may be objects of their own),
                // or a hidden solid: only a listing tells.
                if structural.contains(&e) {
                    return None;
                }
            } else if owners.any(|r| world.contains(r)) {
                return None; // a member of a living object went
            }
            continue;
        }
        let mut owned = false;
        for r in live.owners.roots(e) {
            owned = true;
            if structural.contains(&e) {
                return None;
            }
            changed.insert(r);
        }
        if !owned && !live.index.contains_key(&e) {
            fresh.insert(e);
        }
    }
    dead.sort_unstable_by_key(|e| e.to_bits());
    dead.dedup();
    // A despawned root's members go with it (else they become objects).
    for r in &dead {
        let s = live.slices[live.index[r] as usize];
        if live.members[s.members[0] as usize..s.members[1] as usize].iter().any(|&m| world.contains(m)) {
            return None;
        }
    }
    // New trees are new all the way down.
    let mut child = EntitySet::default();
    for &e in &fresh {
        if let Ok(n) = world.get::<&CsgNode>(e) {
            for c in &n.children {
                if !fresh.contains(c) {
                    return None;
                }
                child.insert(*c);
            }
        }
    }
    let mut born: Vec<Entity> = fresh.iter().copied().filter(|e| !child.contains(e) && is_solid(world, *e)).collect();
    born.sort_unstable_by_key(|&e| order_key(world, e));
    let mut changed: Vec<(u32, Entity)> = changed.into_iter().filter(|r| world.contains(*r)).map(|r| (live.index[&r], r)).collect();
    changed.sort_unstable();
    Some(Births { dead, born, changed: changed.into_iter().map(|(_, r)| r).collect() })
}

/// Is `births` small enough for this path (else a full bake does the same
/// work with fresh trees, as in the general path)?
pub(super) fn small(births: &Births, scene: &RenderScene, live: &LiveState) -> bool {
    let todo = births.born.len() + births.changed.len();
    let many = todo > FULL_MIN && todo * 2 > scene.objects.len();
    let sweep = live.dead_leaves > SWEEP_MIN && live.dead_leaves > scene.leaves.len() - live.dead_leaves;
    !many && !sweep
}

/// Applies `births`: the changed objects re-baked in place, the dead ones
/// dropped, the new ones baked and placed in order.
pub(super) fn apply(world: &World, scene: &mut RenderScene, live: &mut LiveState, births: Births) -> Result<(), BakeError> {
    // Both bakes before any edit: an error leaves the scene as it was.
    let changed = bake_objects(world, &births.changed, live.settings)?;
    let born = bake_objects(world, &births.born, live.settings)?;
    if !births.changed.is_empty() {
        let moved = replace_objects(world, scene, live, &changed);
        refit_object_tree(scene, live, &moved);
    }
    let dead: Vec<u32> = births.dead.iter().map(|r| live.index[r]).collect();
    for (&r, &oi) in births.dead.iter().zip(&dead) {
        let s = live.slices[oi as usize];
        forget_members(live, r, s);
        release_rows(scene, live, s);
        live.index.remove(&r);
        let objects = &scene.objects;
        live.tree.remove(&mut scene.objects_cull, oi, |p| objects[p as usize].bounds);
    }
    let map = renumber(world, scene, live, &dead, &born);
    live.meshes.renumber(&map);
    let n = scene.objects.len();
    live.tree.renumber(&mut scene.objects_cull, &map, n);
    scene.unbounded = scene.unbounded.iter().map(|&oi| map[oi as usize]).filter(|&oi| oi != NONE).collect();
    for (k, &root) in births.born.iter().enumerate() {
        let oi = live.index[&root];
        let (info, slice) = rebake_object(world, scene, live, &born, k, oi, None);
        let b = info.bounds;
        scene.objects[oi as usize] = info;
        live.slices[oi as usize] = slice;
        scene.retry[oi as usize] = retry_of(&scene.program, &scene.leaves, &scene.objects[oi as usize]);
        live.meshes.update(scene, oi);
        if b.is_empty() {
            continue;
        }
        if b.is_finite() {
            let objects = &scene.objects;
            live.tree.insert(&mut scene.objects_cull, oi, |p| objects[p as usize].bounds);
        } else {
            scene.unbounded.push(oi);
        }
    }
    scene.unbounded.sort_unstable();
    if live.tree.degradation() > REBUILD_AT {
        live.counts.rebuilds += 1;
        build_object_tree(scene);
        super::link_object_tree(scene, live);
    }
    live.counts.births += 1;
    Ok(())
}

/// Lays the objects out anew: the survivors in their order with the new
/// roots `born` (in order) placed among them by key, each new one as an
/// empty stand-in for [`apply`] to fill. Returns each old object's new
/// index (`NONE` for the dead ones, `dead`).
fn renumber(world: &World, scene: &mut RenderScene, live: &mut LiveState, dead: &[u32], born: &Baked) -> Vec<u32> {
    let n_old = scene.objects.len();
    let mut is_dead = vec![false; n_old];
    for &oi in dead {
        is_dead[oi as usize] = true;
    }
    let survivors: Vec<u32> = (0..n_old as u32).filter(|&oi| !is_dead[oi as usize]).collect();
    // Where each new root goes among the survivors (keys ascending).
    let at: Vec<usize> = born
        .objects
        .iter()
        .map(|o| {
            let k = order_key(world, o.entity);
            survivors.partition_point(|&s| order_key(world, scene.objects[s as usize].entity) < k)
        })
        .collect();
    let old_objects = std::mem::take(&mut scene.objects);
    let old_slices = std::mem::take(&mut live.slices);
    let old_retry = std::mem::take(&mut scene.retry);
    let n_new = survivors.len() + at.len();
    scene.objects.reserve(n_new);
    live.slices.reserve(n_new);
    scene.retry.reserve(n_new);
    let mut map = vec![NONE; n_old];
    let mut old_objects: Vec<Option<ObjectInfo>> = old_objects.into_iter().map(Some).collect();
    let mut k = 0;
    let place_born = |scene: &mut RenderScene, live: &mut LiveState, k: usize| {
        let oi = scene.objects.len() as u32;
        let o = &born.objects[k];
        live.index.insert(o.entity, oi);
        scene.objects.push(ObjectInfo { entity: o.entity, name: String::new(), root: 0, bounds: Aabb::EMPTY });
        live.slices.push(born.slices[k]);
        scene.retry.push(Retry::default());
    };
    for (j, &s) in survivors.iter().enumerate() {
        while k < at.len() && at[k] <= j {
            place_born(scene, live, k);
            k += 1;
        }
        let oi = scene.objects.len() as u32;
        map[s as usize] = oi;
        let mut o = old_objects[s as usize].take().expect("each survivor once");
        let slice = old_slices[s as usize];
        if oi != s {
            for l in &mut scene.leaf_info[slice.leaves[0] as usize..slice.leaves[1] as usize] {
                l.object = oi;
            }
            if o.name.starts_with("object") && world.get::<&Name>(o.entity).is_err() {
                o.name = format!("object{oi}");
            }
            live.index.insert(o.entity, oi);
        }
        scene.objects.push(o);
        live.slices.push(slice);
        scene.retry.push(old_retry[s as usize]);
    }
    while k < at.len() {
        place_born(scene, live, k);
        k += 1;
    }
    map
}
