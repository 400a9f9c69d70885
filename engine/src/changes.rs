//! Change detection for the live bake: which entities had a component that
//! the bake reads added, changed or removed (despawns included) since the last
//! sync.
//!
//! One snapshot per component type, a dense vector indexed by entity id
//! holding the entity and a copy of the value (or a key: a mesh by its `Arc`
//! pointer, a transform by its bits, a name by its text). A sync walks each
//! type's query and compares with the copy: a plain pass over plain data, with
//! no hashing and no formatting. hecs's own `ChangeTracker<T>` keeps its copy
//! as a `Previous<T>` component inserted into the tool's entities (an
//! archetype move per entity and per tracked type on the first sync, and a
//! second archetype for every combination) and does not report despawns, so
//! the engine keeps its copies to itself.

use hecs::{Component, Entity, World};

use crate::components::*;

/// What changed since the last sync.
#[derive(Default, Debug)]
pub struct Changes {
    /// Entities whose bake input changed (each at most once per type).
    pub dirty: Vec<Entity>,
    /// A change to which objects exist or to their order: a solid appeared or
    /// vanished, a `CsgNode`'s children, `Hidden` or `ObjectOrder` changed.
    pub structural: bool,
}

/// The last seen value (or key) of one component type, per entity id.
struct Snap<K> {
    slots: Vec<Option<(Entity, K)>>,
    /// Occupied slots.
    live: usize,
}

impl<K> Default for Snap<K> {
    fn default() -> Self {
        Snap { slots: Vec::new(), live: 0 }
    }
}

/// How a type's changes count: does adding, removing or changing it change
/// which objects exist (or their order)?
#[derive(Clone, Copy)]
struct Kind {
    /// Adding or removing it is structural (it makes or unmakes a solid, a
    /// node, a hidden root, an ordered root).
    presence: bool,
    /// A changed value is structural too.
    value: bool,
}

impl<K> Snap<K> {
    /// Compares every `T` of `world` with the copy (`same`) and brings the copy
    /// up to date (`key`, called only for what changed); records the entities
    /// whose `T` was added, changed or removed.
    fn scan<T: Component>(&mut self, world: &World, kind: Kind, same: impl Fn(&K, &T) -> bool, key: impl Fn(&T) -> K, out: &mut Changes) {
        let before = self.live;
        let mut matched = 0usize;
        let mut replaced = Vec::new();
        for (e, v) in world.query::<&T>().iter() {
            let i = e.id() as usize;
            if i >= self.slots.len() {
                self.slots.resize_with(i + 1, || None);
            }
            match &mut self.slots[i] {
                Some((pe, pk)) if *pe == e => {
                    matched += 1;
                    if !same(pk, v) {
                        *pk = key(v);
                        out.dirty.push(e);
                        out.structural |= kind.value;
                    }
                }
                slot => {
                    if let Some((old, _)) = slot.take() {
                        // The id was reused: the old entity lost its `T`.
                        replaced.push(old);
                    } else {
                        self.live += 1;
                    }
                    *slot = Some((e, key(v)));
                    out.dirty.push(e);
                    out.structural |= kind.presence;
                }
            }
        }
        // Entries neither matched nor replaced lost their component (or their
        // entity): only then is the whole vector swept.
        let gone = before - matched - replaced.len();
        if !replaced.is_empty() {
            out.structural |= kind.presence;
            out.dirty.extend(replaced);
        }
        if gone > 0 {
            out.structural |= kind.presence;
            for slot in self.slots.iter_mut() {
                if let Some((e, _)) = slot {
                    let e = *e;
                    if world.get::<&T>(e).is_err() {
                        *slot = None;
                        self.live -= 1;
                        out.dirty.push(e);
                    }
                }
            }
        }
    }

}

impl<T: Component + Clone + PartialEq> Snap<T> {
    /// [`Snap::scan`] for a type compared by `PartialEq` with a copy of itself.
    fn scan_copy(&mut self, world: &World, kind: Kind, out: &mut Changes) {
        self.scan(world, kind, |k: &T, v: &T| k == v, T::clone, out);
    }
}

/// The snapshots of every component the bake reads.
#[derive(Default)]
pub struct Snapshots {
    transform: Snap<[u64; 12]>,
    sphere: Snap<Sphere>,
    cuboid: Snap<Cuboid>,
    cylinder: Snap<Cylinder>,
    cone: Snap<Cone>,
    torus: Snap<Torus>,
    half_space: Snap<HalfSpace>,
    swept: Snap<SweptSphere>,
    gcyl: Snap<GeneralizedCylinder>,
    mesh: Snap<usize>,
    node_op: Snap<Op>,
    node_children: Snap<Vec<Entity>>,
    material: Snap<[u32; 3]>,
    name: Snap<String>,
    hidden: Snap<()>,
    order: Snap<u32>,
}

/// System: the entities whose bake input changed since the last call (the
/// first call reports every entity with a component the bake reads).
pub fn detect_changes(world: &World, snaps: &mut Snapshots) -> Changes {
    let mut c = Changes::default();
    // A value change of a shape or transform re-bakes the objects holding it;
    // adding or removing a shape makes or unmakes a solid.
    let shape = Kind { presence: true, value: false };
    let attribute = Kind { presence: false, value: false };
    let order = Kind { presence: true, value: true };
    let bits = |t: &Transform| t.0.to_cols_array().map(f64::to_bits);
    snaps.transform.scan(world, attribute, |k, t| *k == bits(t), bits, &mut c);
    snaps.sphere.scan_copy(world, shape, &mut c);
    snaps.cuboid.scan_copy(world, shape, &mut c);
    snaps.cylinder.scan_copy(world, shape, &mut c);
    snaps.cone.scan_copy(world, shape, &mut c);
    snaps.torus.scan_copy(world, shape, &mut c);
    snaps.half_space.scan_copy(world, shape, &mut c);
    snaps.swept.scan_copy(world, shape, &mut c);
    snaps.gcyl.scan_copy(world, shape, &mut c);
    let ptr = |m: &MeshSolid| std::sync::Arc::as_ptr(&m.0) as usize;
    snaps.mesh.scan(world, shape, |k, m| *k == ptr(m), ptr, &mut c);
    // An op change re-bakes one object; a children change can make or unmake
    // objects (a child is no object of its own).
    snaps.node_op.scan(world, shape, |k, n: &CsgNode| *k == n.op, |n| n.op, &mut c);
    snaps.node_children.scan(world, order, |k, n: &CsgNode| *k == n.children, |n| n.children.clone(), &mut c);
    let rgb = |m: &Material| m.color.to_array().map(f32::to_bits);
    snaps.material.scan(world, attribute, |k, m| *k == rgb(m), rgb, &mut c);
    snaps.name.scan(world, attribute, |k, n: &Name| *k == n.0, |n| n.0.clone(), &mut c);
    snaps.hidden.scan(world, order, |_, _: &Hidden| true, |_| (), &mut c);
    snaps.order.scan(world, order, |k, o: &ObjectOrder| *k == o.0, |o| o.0, &mut c);
    c
}
