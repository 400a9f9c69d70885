//! Programs specialised to a region of rays (a tile of camera rays): a leaf
//! whose bounds the region misses is empty there, and Roth's rules simplify
//! what remains. A union drops it; an intersection with it is empty; a
//! difference drops it as a subtrahend and is empty without its positive
//! operand. A wide node asks its region tree once per tile: with no child in
//! the region it is empty, else it stays as baked (its per-ray BVH walk keeps
//! the order in which children are combined, so no answer changes).
//!
//! The specialised nodes are appended to a per-thread copy of the baked
//! program, so they refer to baked nodes and tables by index and the rays of
//! the tile evaluate them with the ordinary evaluator ([`Program::eval`]).
//! Nodes keep their operands' order, so every ray gets exactly the answer of
//! the whole program: the operands dropped give no span on any ray of the
//! region.

use rothray_primitives::{frustum::Frustum, polytope::Plane, LeafKind, LeafTable};

use crate::program::{NodeKind, Program};

/// Below this depth nodes are kept as baked (the specialisation recurses).
const MAX_DEPTH: u32 = 64;

/// What the specialisation of one tile did (summed over its objects).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TileCounts {
    /// Leaves found empty in the tile (each leaf counted where the walk met it;
    /// a subtree dropped whole counts its node only).
    pub leaves_pruned: u64,
    /// Leaves kept.
    pub leaves_kept: u64,
    /// Wide nodes asked with the region.
    pub wide_queries: u64,
    /// Nodes written (specialised copies).
    pub nodes_written: u64,
}

/// A per-thread copy of a baked program with the nodes of the current tile
/// appended. Reused from tile to tile (no allocation once warm).
#[derive(Default)]
pub struct TileProgram {
    /// The baked program followed by the tile's nodes: what the tile's rays
    /// evaluate.
    pub prog: Program,
    base_nodes: usize,
    base_children: usize,
    kids: Vec<u32>,
    planes: Vec<Plane>,
    /// Counts since the last [`TileProgram::take_counts`].
    counts: TileCounts,
}

impl TileProgram {
    /// Starts a tile of `base`: forgets the previous tile's nodes (and copies
    /// `base` when it is not the program copied last).
    pub fn begin(&mut self, base: &Program) {
        if self.prog.id != base.id || self.prog.id == 0 {
            self.prog = base.clone();
            self.base_nodes = base.kind.len();
            self.base_children = base.children.len();
        }
        let p = &mut self.prog;
        let n = self.base_nodes;
        p.kind.truncate(n);
        p.first.truncate(n);
        p.count.truncate(n);
        p.wide.truncate(n);
        p.bounds.truncate(n);
        p.leafy.truncate(n);
        p.children.truncate(self.base_children);
    }

    /// The counts so far, reset.
    pub fn take_counts(&mut self) -> TileCounts {
        std::mem::take(&mut self.counts)
    }

    /// Node `root` of `base` specialised to the rays of `region`: `None` when
    /// it is empty for all of them, else the node to evaluate in
    /// [`TileProgram::prog`] (`root` itself when nothing changed).
    pub fn specialise(&mut self, base: &Program, leaves: &LeafTable, root: u32, region: &Frustum) -> Option<u32> {
        debug_assert_eq!(self.prog.id, base.id, "begin() first");
        let mut s = Spec { base, leaves, region, tp: self };
        s.node(root, 0)
    }
}

struct Spec<'a> {
    base: &'a Program,
    leaves: &'a LeafTable,
    region: &'a Frustum,
    tp: &'a mut TileProgram,
}

impl Spec<'_> {
    fn leaf_touched(&mut self, leaf: u32) -> bool {
        if self.leaves.kind[leaf as usize] != LeafKind::HalfSpace {
            return true; // its box was tested
        }
        let planes = &mut self.tp.planes;
        planes.clear();
        self.leaves.world_planes(leaf, planes);
        planes.first().is_none_or(|p| self.region.touches_plane(p))
    }

    fn node(&mut self, n: u32, depth: u32) -> Option<u32> {
        let b = self.base;
        let nu = n as usize;
        let kind = b.kind[nu];
        if !self.region.touches_box(&b.bounds[nu]) || (kind == NodeKind::Leaf && !self.leaf_touched(b.first[nu])) {
            self.tp.counts.leaves_pruned += 1;
            return None;
        }
        if kind == NodeKind::Leaf {
            self.tp.counts.leaves_kept += 1;
            return Some(n);
        }
        if depth >= MAX_DEPTH {
            return Some(n);
        }
        let (first, count) = (b.first[nu] as usize, b.count[nu] as usize);
        if b.wide[nu] != u32::MAX {
            return self.wide(n, depth);
        }
        let at = self.tp.kids.len();
        let mut changed = false;
        for (pos, &c) in b.children[first..first + count].iter().enumerate() {
            let r = self.node(c, depth + 1);
            match (kind, r) {
                // An empty operand of an intersection, or an empty positive
                // operand of a difference: the node is empty.
                (NodeKind::Intersection, None) => return self.drop_kids(at),
                (NodeKind::Difference, None) if pos == 0 => return self.drop_kids(at),
                (_, None) => changed = true,
                (_, Some(x)) => {
                    changed |= x != c;
                    self.tp.kids.push(x);
                }
            }
        }
        let k = self.tp.kids.len() - at;
        let out = match k {
            0 => None,
            1 => Some(self.tp.kids[at]),
            _ if !changed => Some(n),
            _ => Some(self.write(kind, n, at)),
        };
        self.tp.kids.truncate(at);
        out
    }

    fn drop_kids(&mut self, at: usize) -> Option<u32> {
        self.tp.kids.truncate(at);
        None
    }

    /// A wide union or difference: empty when the region meets none of its
    /// (union) children, the positive operand alone when it meets none of the
    /// subtrahends, else the node as baked.
    fn wide(&mut self, n: u32, depth: u32) -> Option<u32> {
        let b = self.base;
        let nu = n as usize;
        let w = &b.wides[b.wide[nu] as usize];
        self.tp.counts.wide_queries += 1;
        let kind = b.kind[nu];
        let skip = (kind == NodeKind::Difference) as u32;
        let mut met = w.unbounded.iter().any(|&p| p >= skip);
        if !met {
            let region = self.region;
            let children = &b.children[b.first[nu] as usize..];
            let bounds = &b.bounds;
            let found = std::cell::Cell::new(false);
            w.cull.cull(
                |bx| !found.get() && region.touches_box(bx),
                |pos| found.set(found.get() || region.touches_box(&bounds[children[pos as usize] as usize])),
            );
            met = found.get();
        }
        match kind {
            NodeKind::Difference => {
                let pos = self.node(b.children[b.first[nu] as usize], depth + 1)?;
                if met { Some(n) } else { Some(pos) }
            }
            _ => met.then_some(n),
        }
    }

    /// Writes a node of `kind` over `kids[at..]` (the operands kept, in order).
    fn write(&mut self, kind: NodeKind, like: u32, at: usize) -> u32 {
        let tp = &mut *self.tp;
        let p = &mut tp.prog;
        let kids = &tp.kids[at..];
        let first = p.children.len() as u32;
        p.children.extend_from_slice(kids);
        let bounds = match kind {
            NodeKind::Union => kids.iter().fold(rothray_primitives::Aabb::EMPTY, |a, &c| a.union(&p.bounds[c as usize])),
            NodeKind::Difference => p.bounds[kids[0] as usize],
            _ => self.base.bounds[like as usize],
        };
        let leafy = kids.iter().all(|&c| p.kind[c as usize] == NodeKind::Leaf);
        let id = p.kind.len() as u32;
        p.kind.push(kind);
        p.first.push(first);
        p.count.push(kids.len() as u32);
        p.wide.push(u32::MAX);
        p.bounds.push(bounds);
        p.leafy.push(leafy);
        tp.counts.nodes_written += 1;
        id
    }
}
