//! The packet meshes of a live scene (`RenderScene::packet_meshes`: the mesh
//! leaves that nearest-hit queries ask in nearest mode), kept object by
//! object, so that a sync finds them by walking the trees of the objects it
//! re-baked, not of every object. The scene's list is the objects' lists
//! from the last object to the first, as one walk of every tree meets them
//! (`packet::nearest_mode_meshes`), and empty past [`PACKET_MESHES`].

use std::collections::BTreeMap;

use crate::packet::{nearest_mode_meshes, PACKET_MESHES};
use crate::scene::RenderScene;

/// Per object, its nearest-mode mesh leaves.
#[derive(Default)]
pub(crate) struct MeshObjects {
    /// The objects that have some (by index), with their leaves in the order
    /// a walk of the object's tree meets them.
    lists: BTreeMap<u32, Vec<u32>>,
    /// Leaves in all the lists.
    total: usize,
}

impl MeshObjects {
    /// Walks every object's tree (after a full bake, or when objects were
    /// renumbered). A scene without mesh leaves has nothing to walk for.
    pub(crate) fn rebuild(&mut self, scene: &RenderScene) {
        *self = MeshObjects::default();
        if !scene.leaves.meshes.is_empty() {
            for oi in 0..scene.objects.len() as u32 {
                self.update(scene, oi);
            }
        }
    }

    /// The objects were renumbered (`map[old]`, `u32::MAX` for the ones
    /// gone): their lists follow them.
    pub(crate) fn renumber(&mut self, map: &[u32]) {
        let lists = std::mem::take(&mut self.lists);
        self.total = 0;
        for (oi, l) in lists {
            let to = map[oi as usize];
            if to != u32::MAX {
                self.total += l.len();
                self.lists.insert(to, l);
            }
        }
    }

    /// Object `oi` was re-baked: walks its tree.
    pub(crate) fn update(&mut self, scene: &RenderScene, oi: u32) {
        let root = scene.objects[oi as usize].root;
        let found = nearest_mode_meshes(&scene.program, &scene.leaves, std::iter::once(root));
        let old = if found.is_empty() { self.lists.remove(&oi) } else { self.lists.insert(oi, found) };
        self.total -= old.map_or(0, |l| l.len());
        self.total += self.lists.get(&oi).map_or(0, |l| l.len());
    }

    /// The scene's packet meshes: the objects' lists from the last object to
    /// the first; none when there are more than [`PACKET_MESHES`].
    pub(crate) fn packet_meshes(&self) -> Vec<u32> {
        if self.total > PACKET_MESHES {
            return Vec::new();
        }
        self.lists.values().rev().flatten().copied().collect()
    }
}
