//! Which objects each entity is part of (a change to an entity re-bakes
//! them): a dense table indexed by entity id, with a side map for the rare
//! entity that several trees share. 16 bytes per entity id; the hash map it
//! replaced took about 50 per entity (a union of 10^6 spheres).

use hecs::Entity;
use smallvec::SmallVec;

use crate::entity_hash::EntityMap;

/// Entity -> the roots of the objects whose trees hold it.
#[derive(Default)]
pub(crate) struct Owners {
    /// Per entity id: the entity and one root.
    first: Vec<Option<(Entity, Entity)>>,
    /// Further roots of an entity in several trees (or twice in one).
    more: EntityMap<SmallVec<[Entity; 2]>>,
}

impl Owners {
    /// Forgets everything; room for ids below `n`.
    pub fn reset(&mut self, n: usize) {
        self.first.clear();
        self.first.resize(n, None);
        self.more.clear();
    }

    /// Records that the tree of `root` holds `e`.
    pub fn add(&mut self, e: Entity, root: Entity) {
        let id = e.id() as usize;
        if id >= self.first.len() {
            self.first.resize(id + 1, None);
        }
        match &mut self.first[id] {
            Some((held, _)) if *held == e => self.more.entry(e).or_default().push(root),
            slot => *slot = Some((e, root)),
        }
    }

    /// Forgets one record of `root` holding `e`.
    pub fn remove(&mut self, e: Entity, root: Entity) {
        let Some(slot) = self.first.get_mut(e.id() as usize) else { return };
        if let Some(more) = self.more.get_mut(&e) {
            if let Some(p) = more.iter().position(|&r| r == root) {
                more.swap_remove(p);
            } else if slot.is_some_and(|(h, r)| h == e && r == root) {
                // The first record goes: a further one takes its place.
                *slot = more.pop().map(|r| (e, r));
            }
            if more.is_empty() {
                self.more.remove(&e);
            }
        } else if slot.is_some_and(|(h, r)| h == e && r == root) {
            *slot = None;
        }
    }

    /// The roots whose trees hold `e`.
    pub fn roots(&self, e: Entity) -> impl Iterator<Item = Entity> + '_ {
        let first = self.first.get(e.id() as usize).copied().flatten().filter(|(h, _)| *h == e).map(|(_, r)| r);
        first.into_iter().chain(self.more.get(&e).into_iter().flatten().copied())
    }
}
