//! Programs specialised to a region of rays (a tile of camera rays): a leaf
//! whose bounds the region misses is empty there, and Roth's rules simplify
//! what remains. A union drops it; an intersection with it is empty; a
//! difference drops it as a subtrahend and is empty without its positive
//! operand. A wide node asks its region tree once per tile: with no child in
//! the region a union is empty; with few, it becomes a narrow node of those
//! or a difference with a short list of them; with many it stays as baked.
//! (The regularised union `combine` makes does not depend on the order of
//! its operands except for chains of boundaries within eps of one another:
//! a lane's own query of a narrow union of leaves evaluates the baked union,
//! [`Program::narrowed_unions`]; the README's Known limitations lists the
//! narrow nodes that still take the tile's order.)
//!
//! The specialised nodes are appended to a per-thread copy of the baked
//! program (which follows a live program's edits row by row, see
//! [`crate::EditLog`]), so they refer to baked nodes and tables by index and the rays of
//! the tile evaluate them with the ordinary evaluator ([`Program::eval`]).
//! Nodes keep their operands' order, so every ray gets exactly the answer of
//! the whole program: the operands dropped give no span on any ray of the
//! region.

use rothray_primitives::{frustum::Frustum, polytope::Plane, LeafKind, LeafTable};

use rothray_primitives::bvh::BvhNode;

use crate::follow::{FollowCounts, Follower};
use crate::program::{NodeKind, Program, Wide};
use crate::tile_list::TileList;

/// Below this depth nodes are kept as baked (the specialisation recurses).
const MAX_DEPTH: u32 = 64;

/// A wide difference whose subtrahends the tile meets at most this many of
/// gets a list of just those (a one-leaf tree, which its rays sort by entry
/// exactly as they sort what the baked BVH gives them).
const SHORT_LIST: usize = 16;

/// A wide difference whose subtrahends the tile meets at most this many of
/// becomes a narrow difference of those: its operands then fit the packets'
/// small nodes (`object_packet.rs`, at most eight operands), a ring torus
/// among them too (benches/scenes/tori's torus bitten by eight balls).
const NARROW_DIFFERENCE: usize = 6;

/// A wide union whose children the tile meets at most this many of becomes a
/// narrow union of those: the baked threshold for a BVH. (Measured with
/// callgrind on scenes/forest at 480x270: 1 487e6 instructions with 6,
/// 1 514e6 with 16, where its rays asked 4.1 leaves each instead of 3.5:
/// a narrow union asks every operand's kernel.)
const NARROW_UNION: usize = crate::program::WIDE_THRESHOLD;

/// A packet union (`Program::is_packet_union`) whose children the tile meets
/// more than [`NARROW_UNION`] and at most this many of gets a list of them
/// ([`crate::tile_list`]); with more, its packets walk its tree. (128 left
/// most shadow bundles of the forests walking the tree: with 512,
/// benches/scenes/forest lit 2.487e9 -> 2.459e9 instructions, forest_cut
/// lit 3.375e9 -> 3.339e9, flat 0.5% fewer; callgrind 960x540, warm-up
/// plus one render. 2048 gave the same.)
const LIST_MAX: usize = 512;

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
    /// Lists of wide unions' children made ([`crate::tile_list`]).
    pub lists: u64,
    /// Children those lists hold.
    pub listed: u64,
}

/// A per-thread copy of a baked program with the nodes of the current tile
/// appended. Reused from tile to tile (no allocation once warm) and from
/// sync to sync: the copy takes only the rows a live sync rewrote.
#[derive(Default)]
pub struct TileProgram {
    /// The baked program followed by the tile's nodes: what the tile's rays
    /// evaluate.
    pub prog: Program,
    /// Which version of which program the first rows of `prog` copy.
    base: Follower,
    follow_counts: FollowCounts,
    kids: Vec<u32>,
    planes: Vec<Plane>,
    /// Counts since the last [`TileProgram::take_counts`].
    counts: TileCounts,
    /// See [`TileProgram::kernels8`].
    kernels8: bool,
    /// See [`TileProgram::meshes`].
    meshes: bool,
    /// Is `prog.ray_plane` the current tile's (made when a list first needs it)?
    plane_set: bool,
}

impl TileProgram {
    /// Starts a tile of `base`: forgets the previous tile's nodes, and
    /// brings the copy of `base` up to date (the rows a live sync rewrote,
    /// or all of them for another program).
    pub fn begin(&mut self, base: &Program) {
        self.base.follow(&mut self.prog, base, &mut self.follow_counts);
        self.kernels8 = false;
        self.meshes = false;
        self.plane_set = false;
    }

    /// What bringing the copy up to date cost so far (for tests: a sync that
    /// re-bakes a few objects is followed without a whole copy).
    pub fn follow_counts(&self) -> FollowCounts {
        self.follow_counts
    }

    /// Has a leaf with a packet kernel ([`LeafTable::has_kernel8`]) or a
    /// packet prep (a ring torus, [`LeafTable::has_torus_prep`]) been kept
    /// since [`TileProgram::begin`] (or a node kept whole, whose leaves
    /// were not looked at)?
    pub fn kernels8(&self) -> bool {
        self.kernels8
    }

    /// May a mesh leaf have been kept since [`TileProgram::begin`] (one
    /// was, or a node was kept whole in a scene with meshes)? Then a
    /// packet's rays may walk meshes together (`PacketMemo::walk_meshes_for`).
    pub fn meshes(&self) -> bool {
        self.meshes
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
        s.node(root, 0, true)
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

    /// Node `n` specialised; `nearest`: its evaluation is in nearest mode
    /// (as an object's root is; see `Program::child_mode`), where packets
    /// walk wide unions together.
    fn node(&mut self, n: u32, depth: u32, nearest: bool) -> Option<u32> {
        let b = self.base;
        let nu = n as usize;
        let kind = b.kind[nu];
        if !self.region.touches_box(&b.bounds[nu]) || (kind == NodeKind::Leaf && !self.leaf_touched(b.first[nu])) {
            self.tp.counts.leaves_pruned += 1;
            return None;
        }
        if kind == NodeKind::Leaf {
            self.tp.counts.leaves_kept += 1;
            self.tp.kernels8 |= self.leaves.has_kernel8(b.first[nu]) || self.leaves.has_torus_prep(b.first[nu]);
            self.tp.meshes |= self.leaves.is_mesh(b.first[nu]);
            return Some(n);
        }
        if depth >= MAX_DEPTH {
            self.tp.kernels8 = true;
            self.tp.meshes |= !self.leaves.meshes.is_empty();
            return Some(n);
        }
        let (first, count) = (b.first[nu] as usize, b.count[nu] as usize);
        if b.wide[nu] != u32::MAX {
            return self.wide(n, depth, nearest);
        }
        let at = self.tp.kids.len();
        let mut changed = false;
        for (pos, &c) in b.children[first..first + count].iter().enumerate() {
            let child_nearest = nearest
                && match kind {
                    NodeKind::Intersection => pos > 0,
                    NodeKind::Difference => pos == 0,
                    _ => true,
                };
            let r = self.node(c, depth + 1, child_nearest);
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

    /// A wide union or difference. A union that the region meets few children
    /// of becomes a narrow union of those (none: empty; one: that child). A
    /// difference is its positive operand alone when the region meets no
    /// subtrahend, and gets a short list of the subtrahends met when there are
    /// few. Either stays as baked when the region meets many.
    fn wide(&mut self, n: u32, depth: u32, nearest: bool) -> Option<u32> {
        let b = self.base;
        let nu = n as usize;
        let w = &b.wides[b.wide[nu] as usize];
        self.tp.counts.wide_queries += 1;
        // (Its children are not looked at one by one.)
        self.tp.kernels8 = true;
        self.tp.meshes |= !self.leaves.meshes.is_empty();
        let kind = b.kind[nu];
        let skip = (kind == NodeKind::Difference) as u32;
        let first = b.first[nu] as usize;
        // The positions met, up to one past the most a short list takes.
        let at = self.tp.kids.len();
        let mut many = false;
        for &p in &w.unbounded {
            if p >= skip {
                self.tp.kids.push(p);
            }
        }
        // A packet union the tile meets many children of gets a list of
        // them (up to LIST_MAX), so count that far; only where packets walk
        // it (in nearest mode: cheese's union of 1000 holes, a subtrahend,
        // paid 2-3% of its instructions for lists no packet read).
        // So does a wide union of subtrees, in either mode, whose rays
        // collect their candidates from the list (`Program::collect`; a
        // leafy union that packets do not walk reads no list: its rays walk
        // its tree).
        let listing = kind == NodeKind::Union && ((nearest && b.is_packet_union(n)) || !b.leafy[nu]) && self.ray_plane();
        // (A union of subtrees keeps the box test: with 6 children met or
        // fewer it becomes a narrow union of just those.)
        let packet_list = listing && b.is_packet_union(n);
        let unbounded = self.tp.kids.len() - at;
        {
            // The children of the tree's leaves whose boxes the region
            // touches, each tested on its own box too (a leaf may hold a
            // few), except for a list: an extra child there costs a packet a
            // box test at most, and the tests cost scenes/forest 2% of its
            // instructions lit. (Counted without them, scenes/cheese's
            // differences passed SHORT_LIST more often: +2% instructions.)
            let region = self.region;
            let (children, bounds) = (&b.children[first..], &b.bounds);
            let kids = std::cell::RefCell::new(&mut self.tp.kids);
            let most = match kind {
                NodeKind::Difference => SHORT_LIST,
                _ if listing => LIST_MAX,
                _ => NARROW_UNION,
            };
            let limit = at + most + 1;
            w.packet.cull_region(
                region,
                || kids.borrow().len() < limit,
                |pos| {
                    let mut k = kids.borrow_mut();
                    if k.len() < limit && (packet_list || region.touches_box(&bounds[children[pos as usize] as usize])) {
                        k.push(pos);
                    }
                },
            );
            many = many || kids.borrow().len() > at + most;
        }
        let met = self.tp.kids.len() - at;
        match kind {
            NodeKind::Difference => {
                let Some(pos) = self.node(b.children[first], depth + 1, nearest) else { return self.drop_kids(at) };
                if met == 0 {
                    return self.drop_kids(at).or(Some(pos));
                }
                if many {
                    self.tp.kids.truncate(at);
                    return Some(n);
                }
                if met <= NARROW_DIFFERENCE {
                    return self.write_narrow_difference(n, pos, at, (depth, nearest));
                }
                Some(self.write_short_difference(n, pos, at))
            }
            _ => {
                if many {
                    self.tp.kids.truncate(at);
                    return Some(n);
                }
                if met > NARROW_UNION {
                    // (Only when `listing`: else `many`.)
                    self.write_list(n, at + unbounded);
                    self.tp.kids.truncate(at);
                    return Some(n);
                }
                if listing
                    && met >= 2
                    && b.is_meet_union(n)
                    && !self.narrow_is_tree(n, &self.tp.kids[at..])
                    && self.walk_takes_all(n, &self.tp.kids[at + unbounded..])
                {
                    // Kept whole with a list: packets walk it together, as
                    // they would not a narrow union of subtrees that is not
                    // one small tree (each lane evaluated it alone: 4% of
                    // benches/scenes/forest_deep's instructions flat, in
                    // tiles that meet a few of its trees).
                    self.write_list(n, at + unbounded);
                    self.tp.kids.truncate(at);
                    return Some(n);
                }
                if listing && met >= 2 && b.is_packet_union(n) && !self.narrow_is_packet_node(n, &self.tp.kids[at..]) {
                    // Kept whole with a list for the same reason: a narrow
                    // union of meshes (or sweeps) is no packet node, and
                    // each lane collected the baked union's candidates
                    // along its whole ray (60 knob meshes in a union: a
                    // quarter of the instructions flat, callgrind 480x270).
                    self.write_list(n, at + unbounded);
                    self.tp.kids.truncate(at);
                    return Some(n);
                }
                // A narrow union of the children met, leaves in the tree's
                // order, subtrees nearest first (the order `combine` meets
                // them in matters only for chains of near twins: see the
                // module's notes).
                let mut pos: smallvec::SmallVec<[u32; NARROW_UNION]> = self.tp.kids[at..].iter().copied().collect();
                self.tp.kids.truncate(at);
                if b.leafy[nu] {
                    pos.sort_unstable();
                } else {
                    // Subtrees nearest first from the tile's origins (ties in
                    // the tree's order): a lane that finds its entry in a
                    // near one skips the boxes beyond it, and a packet walks
                    // fewer meshes.
                    let o = self.region.origins();
                    let near = |p: u32| b.bounds[b.children[first + p as usize] as usize].near_from(&o);
                    pos.sort_by(|&p, &q| near(p).total_cmp(&near(q)).then(p.cmp(&q)));
                }
                for p in pos {
                    if let Some(x) = self.node(b.children[first + p as usize], depth + 1, nearest) {
                        self.tp.kids.push(x);
                    }
                }
                let out = match self.tp.kids.len() - at {
                    0 => None,
                    1 => Some(self.tp.kids[at]),
                    _ => {
                        let u = self.write(NodeKind::Union, n, at);
                        if b.leafy[nu] {
                            // (Its lanes' own queries evaluate `n`.)
                            self.tp.prog.narrowed_unions.push((u, n));
                        }
                        Some(u)
                    }
                };
                self.tp.kids.truncate(at);
                out
            }
        }
    }

    /// Would a narrow union of the children at positions `pos` of baked
    /// union `n` be one small tree that packets answer
    /// ([`Program::is_tree`]: their leaves, at most
    /// [`TREE_LEAVES`](crate::program::tree_first::TREE_LEAVES), all
    /// kernel leaves)?
    fn narrow_is_tree(&self, n: u32, pos: &[u32]) -> bool {
        let b = self.base;
        let first = b.first[n as usize] as usize;
        let small = crate::program::small_tree::small_of(
            NodeKind::Union,
            false,
            pos.iter().map(|&p| b.small[b.children[first + p as usize] as usize]),
        );
        small != 0 && small as usize <= crate::program::tree_first::TREE_LEAVES
    }

    /// Does the packets' first-entry walk take every child at positions
    /// `pos` of baked wide union `n` ([`Program::first_take`])? A lane
    /// whose reach meets one it does not take leaves the walk and
    /// evaluates the union alone, from the tile's list: where a tile meets
    /// such a child, a narrow union of the few children met, nearest first,
    /// costs its lanes less (200 balls and 40 knob meshes each minus a
    /// ball in one union: callgrind 480x270 flat -18% instructions).
    fn walk_takes_all(&self, n: u32, pos: &[u32]) -> bool {
        let b = self.base;
        let first = b.first[n as usize] as usize;
        pos.iter().all(|&p| b.first_walk_takes(self.leaves, b.children[first + p as usize] as usize))
    }

    /// Would a narrow union of the children at positions `pos` of baked
    /// leafy union `n` be a node packets answer ([`Program::packet_first_node`]:
    /// its leaves kernel leaves, or ring tori among them)?
    fn narrow_is_packet_node(&self, n: u32, pos: &[u32]) -> bool {
        let b = self.base;
        let first = b.first[n as usize] as usize;
        pos.iter().all(|&p| {
            let leaf = b.first[b.children[first + p as usize] as usize];
            self.leaves.has_kernel8(leaf) || self.leaves.has_torus_prep(leaf)
        })
    }

    /// Has the tile's region a ray plane (`prog.ray_plane`, made on first
    /// need: every object of a tile is specialised to the same region, and
    /// most tiles list nothing)?
    fn ray_plane(&mut self) -> bool {
        let tp = &mut *self.tp;
        if !tp.plane_set {
            tp.prog.ray_plane = self.region.ray_plane();
            tp.plane_set = true;
        }
        tp.prog.ray_plane.is_some()
    }

    /// The tile's list of wide union `n`'s bounded children at the
    /// positions `kids[from..]` (see [`crate::tile_list`]).
    fn write_list(&mut self, n: u32, from: usize) {
        let b = self.base;
        let first = b.first[n as usize] as usize;
        let tp = &mut *self.tp;
        let p = &mut tp.prog;
        let Some(plane) = p.ray_plane else { return };
        if p.lists_len == p.lists.len() {
            p.lists.push(TileList::default());
        }
        let l = &mut p.lists[p.lists_len];
        l.reset(n);
        for &pos in &tp.kids[from..] {
            l.push(&plane, pos, &b.bounds[b.children[first + pos as usize] as usize]);
        }
        l.finish(self.region.origins());
        p.lists_len += 1;
        tp.counts.lists += 1;
        tp.counts.listed += l.len() as u64;
    }

    /// A difference of `positive` minus the subtrahends of baked node `like`
    /// at the positions `kids[at..]`, with a one-leaf tree listing them in
    /// position order (its rays collect and sort them by entry, then position,
    /// as they do from the baked tree).
    fn write_short_difference(&mut self, like: u32, positive: u32, at: usize) -> u32 {
        let b = self.base;
        let first = b.first[like as usize] as usize;
        let tp = &mut *self.tp;
        tp.kids[at..].sort_unstable();
        let p = &mut tp.prog;
        let cfirst = p.children.len() as u32;
        p.children.push(positive);
        if p.local_len == p.local_wides.len() {
            p.local_wides.push(Wide::default());
        }
        let w = &mut p.local_wides[p.local_len];
        w.unbounded.clear();
        w.bvh.prims.clear();
        w.bvh.nodes.clear();
        w.bvh.cw = None;
        // As baked: bounded subtrahends in the tree, unbounded ones beside it.
        let mut bounds = rothray_primitives::Aabb::EMPTY;
        for (k, &pos) in tp.kids[at..].iter().enumerate() {
            let c = b.children[first + pos as usize];
            p.children.push(c);
            let cb = b.bounds[c as usize];
            if cb.is_finite() {
                bounds = bounds.union(&cb);
                w.bvh.prims.push(k as u32 + 1);
            } else {
                w.unbounded.push(k as u32 + 1);
            }
        }
        let count = tp.kids.len() - at;
        if !w.bvh.prims.is_empty() {
            w.bvh.nodes.push(BvhNode { min: bounds.min, first: 0, max: bounds.max, count: w.bvh.prims.len() as u32 });
        }
        let wide = (p.wides.len() + p.local_len) as u32;
        p.local_len += 1;
        tp.kids.truncate(at);
        let id = p.kind.len() as u32;
        p.kind.push(NodeKind::Difference);
        p.first.push(cfirst);
        p.count.push(count as u32 + 1);
        p.wide.push(wide);
        p.bounds.push(p.bounds[positive as usize]);
        p.leafy.push(false);
        p.small.push(0);
        tp.counts.nodes_written += 1;
        id
    }

    /// A wide difference's positive operand `positive` (specialised) minus
    /// the subtrahends at the positions `kids[at..]`, specialised, as a
    /// narrow difference in their baked order (or the positive operand
    /// alone when the tile has none of them). A difference's result does
    /// not depend on the order of its subtrahends (see `combine`) except
    /// for chains of near-twin boundaries, where the baked difference's
    /// per-ray order may give another (see the module's notes).
    fn write_narrow_difference(&mut self, like: u32, positive: u32, at: usize, (depth, nearest): (u32, bool)) -> Option<u32> {
        let b = self.base;
        let first = b.first[like as usize] as usize;
        let mut pos: smallvec::SmallVec<[u32; NARROW_DIFFERENCE]> = self.tp.kids[at..].iter().copied().collect();
        self.tp.kids.truncate(at);
        pos.sort_unstable();
        self.tp.kids.push(positive);
        for p in pos {
            if let Some(x) = self.node(b.children[first + p as usize], depth + 1, nearest) {
                self.tp.kids.push(x);
            }
        }
        let out = if self.tp.kids.len() - at == 1 { positive } else { self.write(NodeKind::Difference, like, at) };
        self.tp.kids.truncate(at);
        Some(out)
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
        let small = crate::program::small_tree::small_of(kind, false, kids.iter().map(|&c| p.small[c as usize]));
        p.small.push(small);
        tp.counts.nodes_written += 1;
        id
    }
}
