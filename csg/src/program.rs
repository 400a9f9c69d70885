//! CSG programs: every solid of a scene flattened into one node array (children
//! before parents), evaluated per ray without recursion (so a nesting depth of
//! 10 000 is fine) with Roth's early outs and a BVH inside every wide node.

use std::sync::Arc;

use glam::Vec3;
use rothray_primitives::{
    box_wide::BoxWide,
    bvh::FlatBvh,
    polytope::{polytope_box, Plane},
    table::push_clipped,
    wide_node::WideTrees,
    Aabb, LeafKind, LeafTable, Ray, Span, SpanSink, Surf,
};

use crate::counts;
use crate::edits::{Edit, EditLog};
use crate::spans::{combine_into, combine_into_call, Op, SpanList};
use crate::tile_list::TileList;
use rothray_primitives::ray_plane::RayPlane;

/// Nodes with more children than this get a BVH over their children.
pub const WIDE_THRESHOLD: usize = 6;

/// The kind of a program node (fieldless: the evaluator matches on it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum NodeKind {
    /// A leaf solid (`first` is its index in the [`LeafTable`]).
    Leaf,
    /// n-ary union.
    Union,
    /// n-ary intersection.
    Intersection,
    /// First child minus all others.
    Difference,
}

impl NodeKind {
    fn op(self) -> Op {
        match self {
            NodeKind::Union => Op::Union,
            NodeKind::Intersection => Op::Intersection,
            _ => Op::Difference,
        }
    }
}

/// The BVH of a wide node: over its children (union) or its subtrahends (difference).
#[derive(Clone, Debug, Default)]
pub struct Wide {
    /// BVH over the bounded children; primitive ids are positions in the node's child list.
    pub bvh: FlatBvh,
    /// Positions of children with unbounded boxes (always visited).
    pub unbounded: Vec<u32>,
    /// A 4-wide tree over the same boxes, for packets of eight rays
    /// ([`PacketMemo::walk_unions_for`]) and region queries (tiles ask it
    /// which children their rays can meet; the `CwBvh` of `bvh` has no such
    /// query); empty in a tile's own wide nodes.
    pub packet: BoxWide,
    /// The shapes of the children that are small trees, made at bake: a
    /// packet's walk takes such a child by its shape, which cost some 320
    /// instructions a take to make there (3% of
    /// benches/scenes/forest_deep's, callgrind); empty in a tile's own
    /// wide nodes.
    pub(crate) trees: tree_first::TreeShapes,
    /// Some child has a path in a packet's first-entry walk
    /// ([`Program::first_take`]): else packets do not walk the union
    /// (`union_packet.rs`: a union of sweeps stopped that walk at its
    /// first child, and it is no [`Program::is_meet_union`]). False in a
    /// tile's own wide nodes, which packets do not walk.
    pub(crate) first_walk: bool,
}

/// All CSG trees of a scene, SoA, children before parents.
#[derive(Clone, Debug, Default)]
pub struct Program {
    /// Node kind.
    pub kind: Vec<NodeKind>,
    /// Leaf index (leaf) or first position in `children` (inner node).
    pub first: Vec<u32>,
    /// Child count (inner node).
    pub count: Vec<u32>,
    /// Index into `wides`, or `u32::MAX`.
    pub wide: Vec<u32>,
    /// Bounds per node (union: both; intersection: overlap; difference: the positive operand).
    pub bounds: Vec<Aabb>,
    /// Every child is a leaf (evaluated in one loop, without frames).
    pub leafy: Vec<bool>,
    /// Per node, as [`small_tree::small_of`] makes it: nonzero for a leaf
    /// with a packet kernel and for the root of a small tree, which is
    /// evaluated whole ([`Program::small_eval`]).
    pub small: Vec<u8>,
    /// Child node ids of the inner nodes.
    pub children: Vec<u32>,
    /// BVHs of wide nodes, each shared with the per-tile copies of the
    /// program (a live sync replaces the few it re-bakes; a list shared
    /// whole would be cloned whole).
    pub wides: Vec<Arc<Wide>>,
    /// Wide nodes of a tile's own (indices from `wides.len()` on; see
    /// [`crate::TileProgram`]); the first `local_len` are in use.
    pub local_wides: Vec<Wide>,
    /// How many of `local_wides` are in use.
    pub local_len: usize,
    /// A tile's lists of the children of wide unions it keeps whole (see
    /// [`crate::tile_list`]); the first `lists_len` are in use.
    pub lists: Vec<TileList>,
    /// How many of `lists` are in use.
    pub lists_len: usize,
    /// The plane of the tile's rays, which the lists' shadows lie on.
    pub ray_plane: Option<RayPlane>,
    /// Tells bakes apart (per-tile copies follow the program they copy).
    pub id: u64,
    /// Tells the contents of programs apart: new at every build, live
    /// edit and tile copy ([`fresh_serial`]; 0: never set). What a ray's
    /// scratch keeps of a tree (`deep_first.rs`) is made for one serial.
    pub serial: u64,
    /// The rows rewritten in place since the bake (see [`Program::record_edit`]).
    pub edits: EditLog,
    /// A tile's narrow unions of leaves written for wide unions of leaves,
    /// and those wide unions (node ids): a lane's own query of one
    /// evaluates the wide union instead (`Program::leaf_node`); empty in
    /// a baked program.
    pub narrowed_unions: Vec<(u32, u32)>,
}

/// Per-ray constants of an evaluation: the ray (its range is the range
/// evaluated), the fusing tolerance, and the packet memo.
#[derive(Clone, Copy, Debug)]
pub struct RayCtx<'a> {
    /// The ray and the range evaluated.
    pub ray: Ray,
    /// Fusing tolerance in units of t.
    pub eps: f32,
    /// Leaf results computed ahead by a packet query, and this ray's lane in it.
    pub memo: Option<(&'a PacketMemo, usize)>,
}

impl RayCtx<'static> {
    /// A ray context; `eps_world` is the scene's length tolerance.
    #[inline]
    pub fn new(ray: Ray, eps_world: f32) -> Self {
        RayCtx { ray, eps: eps_world / ray.dir.length(), memo: None }
    }
}

impl RayCtx<'_> {
    /// The slack of a leaf query in [`Mode::Nearest`] for a ray of tolerance
    /// `eps` (what [`RayCtx::nearest_slack`] gives it; for packet queries made
    /// before the contexts).
    #[inline]
    pub fn nearest_slack_of(eps: f32) -> f32 {
        4.0 * eps
    }

    /// The slack of a leaf query in [`Mode::Nearest`].
    #[inline]
    pub fn nearest_slack(&self) -> f32 {
        Self::nearest_slack_of(self.eps)
    }

    /// The slack a leaf may stop at past its first entry in `mode` (`None`: all spans).
    #[inline(always)]
    fn nearest(&self, mode: Mode) -> Option<f32> {
        match mode {
            Mode::All => None,
            Mode::Nearest | Mode::Before => Some(self.nearest_slack()),
        }
    }
}

/// What a query wants from an evaluation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// The whole Roth diagram on `[tmin, tmax]`.
    All,
    /// Only the first surface: unions (and meshes) may stop a little past the
    /// first entry they have confirmed (the result is exact on the returned
    /// range, that entry included).
    Nearest,
    /// What a subtrahend of a nearest-mode difference needs: exactness before
    /// its first confirmed entry (the difference cannot start where the
    /// subtrahend starts), so unions stop right at it; one entering within
    /// 2 eps of its range start (the positive operand's entry) stops 4 eps
    /// past it, as in [`Mode::Nearest`], so that the two entries fuse as in
    /// the full diagram (tests/csg_oracle.rs `near_flush_cutter`). Leaves
    /// take the nearest slack. A wide union walks its own tree front to back,
    /// not the canonical order packets share (scenes/cheese's 1000 holes:
    /// +12.5% instructions in that order).
    Before,
}

/// Nearest-mode leaf results computed ahead for a packet of eight rays (by
/// [`LeafTable::mesh_nearest8`]), served to each ray's evaluation in place of
/// the leaf's own query where they answer it exactly.
#[derive(Debug, Default)]
pub struct PacketMemo {
    leaves: Vec<MemoLeaf>,
    len: usize,
    /// Wide unions walked for the packet, on demand (see `union_packet.rs`).
    unions: std::cell::RefCell<union_packet::UnionRecords>,
    /// Analytic leaves solved for the packet, on demand (see `leaf_packet.rs`).
    leaf_solves: std::cell::RefCell<leaf_packet::LeafRecords>,
    /// Mesh leaves walked for the packet, on demand (see `mesh_packet.rs`).
    meshes: std::cell::RefCell<mesh_packet::MeshWalks>,
}

/// One leaf's (or one wide union's) record.
#[derive(Debug, Default)]
pub(crate) struct MemoLeaf {
    leaf: u32,
    /// Lanes whose result is here.
    done: u32,
    tmin: [f32; 8],
    tmax: [f32; 8],
    /// Each lane's spans are exact on `[tmin, valid]`.
    valid: [f32; 8],
    spans: [Vec<Span>; 8],
}

impl PacketMemo {
    /// Forgets every leaf and union (keeps the memory); no union is walked
    /// for the packet until [`PacketMemo::walk_unions_for`].
    pub fn clear(&mut self) {
        self.len = 0;
        self.unions.get_mut().clear();
        self.leaf_solves.get_mut().clear();
        self.meshes.get_mut().clear();
    }

    /// Records leaf `leaf` queried on `[tmin[k], tmax[k]]` per lane: `fill` pushes
    /// the lanes' spans and returns the lanes done and where each is exact.
    pub fn add(&mut self, leaf: u32, tmin: &[f32; 8], tmax: &[f32; 8], fill: impl FnOnce(&mut [Vec<Span>; 8]) -> (u32, [f32; 8])) {
        if self.leaves.len() == self.len {
            self.leaves.push(MemoLeaf::default());
        }
        let e = &mut self.leaves[self.len];
        for v in e.spans.iter_mut() {
            v.clear();
        }
        let (done, valid) = fill(&mut e.spans);
        (e.leaf, e.done, e.tmin, e.tmax, e.valid) = (leaf, done, *tmin, *tmax, valid);
        if done != 0 {
            self.len += 1;
        }
    }

    /// Lane `k`'s nearest-mode spans (slack `slack`) on `(lo, hi)` of leaf
    /// `i`, which has neither an 8-lane kernel nor a torus prep (a mesh, a
    /// sweep), appended to `out`, and where they stop being exact, from
    /// the packet's records: the meshes walked ahead, else the mesh walks
    /// made when a lane first asks; `None` when the packet does not answer.
    // (A wrapper of `mesh_lane`'s shape: with the mesh's part folded in,
    // inlined or not, knob_union took 0.3-0.9% more instructions,
    // callgrind 480x270 flat.)
    #[inline(always)]
    pub(crate) fn nearest_lane<S: SpanSink + ?Sized>(
        &self,
        leaves: &LeafTable,
        i: u32,
        (k, (lo, hi)): (usize, (f32, f32)),
        slack: f32,
        out: &mut S,
    ) -> Option<f32> {
        if self.len > 0 {
            if let Some(v) = self.serve(k, i, lo, hi, out) {
                return Some(v);
            }
        }
        if leaves.is_mesh(i) {
            return self.mesh_lane(leaves, i, (k, (lo, hi)), slack, out);
        }
        None
    }

    /// The record of `leaf`, if it was added.
    #[inline]
    fn entry(&self, leaf: u32) -> Option<&MemoLeaf> {
        self.leaves[..self.len].iter().find(|e| e.leaf == leaf)
    }

    /// Which lanes are known to have no span of `leaf` on `[lo[k], hi[k]]`
    /// (their recorded query covers the range, is exact on all of it and found
    /// nothing): bit `k` for lane `k`.
    #[inline]
    pub fn empty8(&self, leaf: u32, lo: &[f32; 8], hi: &[f32; 8]) -> u32 {
        let Some(e) = self.entry(leaf) else { return 0 };
        let mut m = 0;
        for k in 0..8 {
            let empty = lo[k] >= e.tmin[k] && hi[k] <= e.tmax[k] && e.valid[k] >= hi[k] && e.spans[k].is_empty();
            m |= (empty as u32) << k;
        }
        m & e.done
    }

    /// Every lane's record of `leaf` (one lookup for a packet's eight rays).
    #[inline]
    pub fn lanes(&self, leaf: u32) -> Option<MemoLanes<'_>> {
        self.entry(leaf).map(MemoLanes)
    }

    /// Lane `k`'s spans of `leaf` on `[lo, hi]` and where they stop being exact,
    /// when the recorded query covers that range (`None`: ask the leaf).
    #[inline]
    fn serve<S: SpanSink + ?Sized>(&self, k: usize, leaf: u32, lo: f32, hi: f32, out: &mut S) -> Option<f32> {
        serve_record(self.entry(leaf)?, k, (lo, hi), out)
    }
}

/// Lane `k`'s spans from record `e` on `[lo, hi]`, appended to `out`, and
/// where they stop being exact, when its query covers that range.
#[inline]
pub(crate) fn serve_record<S: SpanSink + ?Sized>(e: &MemoLeaf, k: usize, (lo, hi): (f32, f32), out: &mut S) -> Option<f32> {
    let v = e.valid[k];
    if e.done & (1 << k) == 0 || !(lo >= e.tmin[k] && hi <= e.tmax[k] && lo <= v) {
        return None;
    }
    let end = hi.min(v);
    for s in &e.spans[k] {
        push_clipped(out, *s, lo, end);
    }
    Some(if v >= hi { f32::INFINITY } else { v })
}

/// The eight lanes' records of one leaf in a [`PacketMemo`].
#[derive(Clone, Copy, Debug)]
pub struct MemoLanes<'a>(&'a MemoLeaf);

impl<'a> MemoLanes<'a> {
    /// Lane `k`'s spans (on its whole query range) and where they stop being
    /// exact, when that lane is done.
    #[inline]
    pub fn get(self, k: usize) -> Option<(&'a [Span], f32)> {
        let e = self.0;
        (e.done & (1 << k) != 0).then(|| (e.spans[k].as_slice(), e.valid[k]))
    }
}

/// Leaf `i`'s spans on `(lo, hi)` into the empty list `out` (all of them,
/// or with `nearest`, what a nearest query needs); returns where they stop
/// being exact.
#[inline(always)]
fn leaf_spans(leaves: &LeafTable, ctx: &RayCtx, i: u32, (lo, hi): (f32, f32), nearest: Option<f32>, out: &mut SpanList) -> f32 {
    debug_assert!(out.is_empty());
    let v = leaf_query(leaves, ctx, i, (lo, hi), nearest, out);
    if leaf_asks_again(out.as_slice(), (v, hi), ctx.eps) {
        return full_again(leaves, ctx, i, (lo, hi), out);
    }
    v
}

/// Does a leaf's answer `spans` on a range ending at `hi`, exact up to
/// `valid`, need asking again in full ([`full_again`]): a first span no
/// longer than `eps` with the answer stopping before the range's end?
/// (Also read by the engine's per-packet answers of lone tori, which must
/// leave such lanes to their own evaluation.)
#[inline(always)]
pub fn leaf_asks_again(spans: &[Span], (valid, hi): (f32, f32), eps: f32) -> bool {
    valid < hi && spans.first().is_some_and(|s| s.t1 - s.t0 <= eps)
}

/// A leaf that stopped just past a first span no longer than eps (a mesh
/// grazed at an edge), asked again in full: `combine` drops that span once
/// another operand has spans on the range, and the leaf's stop cut them
/// away (tests/csg_oracle.rs `grazed_mesh_operands`). Out of line: rare.
#[inline(never)]
#[cold]
fn full_again(leaves: &LeafTable, ctx: &RayCtx, i: u32, range: (f32, f32), out: &mut SpanList) -> f32 {
    out.clear();
    leaf_query(leaves, ctx, i, range, None, out)
}

/// [`leaf_spans`] as the leaf answers it (in nearest modes it may stop just
/// past its first entry), from the ray's packet memo when it has the answer.
#[inline(always)]
fn leaf_query<S: SpanSink + ?Sized>(
    leaves: &LeafTable,
    ctx: &RayCtx,
    i: u32,
    (lo, hi): (f32, f32),
    nearest: Option<f32>,
    out: &mut S,
) -> f32 {
    counts::leaf();
    if let Some((memo, k)) = ctx.memo {
        // An analytic leaf from the packet's solve; a mesh from its walk.
        if leaves.has_kernel8(i) {
            if let Some(v) = memo.leaf_lane(leaves, i, k, (lo, hi), out) {
                return v;
            }
        } else if leaves.has_torus_prep(i) {
            if let Some(v) = memo.torus_lane(leaves, i, k, ((lo, hi), nearest.is_some()), out) {
                return v;
            }
        } else if let Some(slack) = nearest {
            if let Some(v) = memo.nearest_lane(leaves, i, (k, (lo, hi)), slack, out) {
                return v;
            }
        }
    }
    leaves.spans_for(i, &ctx.ray, (lo, hi), nearest, out)
}

/// What a frameless evaluation reads: the leaves, the ray and the mode.
#[derive(Clone, Copy)]
pub(crate) struct Ask<'a, 'm> {
    leaves: &'a LeafTable,
    ctx: &'a RayCtx<'m>,
    mode: Mode,
}

/// The span lists a frameless evaluation works in: one leaf's spans,
/// `combine`'s scratch, and the result; and a wide union's candidates
/// (pushed past the current end and truncated back).
pub(crate) struct Lists<'s> {
    pub(crate) leaf: &'s mut SpanList,
    pub(crate) tmp: &'s mut SpanList,
    pub(crate) acc: &'s mut SpanList,
    pub(crate) cand: &'s mut Vec<(u32, f32)>,
}

/// One leaf's spans, `combine`'s scratch and the result (see [`Lists`]).
pub(crate) type ListsRef<'a> = (&'a mut SpanList, &'a mut SpanList, &'a mut SpanList);

/// Candidate `(pos, t0)` of a wide union as one integer whose order is the
/// candidates' canonical order: the entry (as `total_cmp` orders it), then
/// the position (also the engine's order of a tile's objects along a ray).
#[inline(always)]
pub fn cand_key(pos: u32, t0: f32) -> u64 {
    let b = t0.to_bits();
    (((b ^ (((b as i32) >> 31) as u32 | 0x8000_0000)) as u64) << 32) | pos as u64
}

/// Sorts a few keys ([`cand_key`]s, boundaries) by insertion: a lane's
/// boundaries and a walk's pending children are a handful most times, for
/// which `sort_unstable` was a call each (`small_first::sweep`,
/// `union_first::PendingList`).
#[inline(always)]
pub(crate) fn sort_few(keys: &mut [u64]) {
    for i in 1..keys.len() {
        let x = keys[i];
        let mut j = i;
        while j > 0 && keys[j - 1] > x {
            keys[j] = keys[j - 1];
            j -= 1;
        }
        keys[j] = x;
    }
}

/// The candidate `(pos, t0)` that [`cand_key`] made `k` of.
#[inline(always)]
pub(crate) fn cand_of_key(k: u64) -> (u32, f32) {
    let o = (k >> 32) as u32;
    let b = if o & 0x8000_0000 != 0 { o ^ 0x8000_0000 } else { !o };
    (k as u32, f32::from_bits(b))
}

/// Sorts candidates by entry, then position: a total order, so they are
/// taken in the same order whichever tree listed them.
#[inline]
pub(crate) fn sort_cands(s: &mut [(u32, f32)]) {
    // One integer key per candidate ([`cand_key`]): one compare instead of
    // two chained ones.
    sort_short_by_key(s, |c| cand_key(c.0, c.1));
}

/// Sorts `s` by `key`; short lists, which the walks list nearly in order,
/// by insertion.
#[inline(always)]
fn sort_short_by_key<T: Copy, K: Ord>(s: &mut [T], key: impl Fn(&T) -> K) {
    if s.len() > 16 {
        s.sort_unstable_by_key(key);
        return;
    }
    for i in 1..s.len() {
        let c = s[i];
        let kc = key(&c);
        let mut j = i;
        while j > 0 && key(&s[j - 1]) > kc {
            s[j] = s[j - 1];
            j -= 1;
        }
        s[j] = c;
    }
}

/// One ray's walk through a wide leaf union: the end of its working range,
/// and where its result stops being exact.
#[derive(Clone, Copy, Debug)]
pub(crate) struct UnionLane {
    pub(crate) hi: f32,
    pub(crate) valid: f32,
}

struct Frame {
    node: u32,
    /// Next position in the child list (no BVH) or in the candidate list.
    next: u32,
    /// Candidate range in `Scratch::cand` (wide nodes), else 0..0.
    cand_lo: u32,
    cand_hi: u32,
    tmin: f32,
    tmax: f32,
    /// The result is exact up to here (a nearest-mode union may stop early);
    /// infinity when nothing was cut short.
    valid: f32,
    /// Length of `Scratch::cand` when the frame was pushed.
    cand_base: u32,
    done: bool,
    /// How this node is evaluated (see [`Program::child_mode`]).
    mode: Mode,
}

/// Per-thread scratch memory, reused across rays (no allocation per ray once warm).
#[derive(Default)]
pub struct Scratch {
    frames: Vec<Frame>,
    /// Accumulator of the frame at each depth (kept in place: frames are pushed
    /// and popped without moving span lists).
    accs: Vec<SpanList>,
    cand: Vec<(u32, f32)>,
    leaf: SpanList,
    /// Result of a bottom-level node evaluated without a frame.
    sub: SpanList,
    tmp: SpanList,
    /// Result of the last evaluation.
    pub out: SpanList,
    /// Point-classification values (post-order).
    bools: Vec<bool>,
    /// A caller's candidate list, `(entry t, id)` (the engine's objects along
    /// a ray), kept here so that it too is reused from ray to ray.
    pub cands: Vec<(f32, u32)>,
    /// A caller's queue for [`rothray_primitives::bvh::FlatBvh::visit_nearest`].
    pub queue: rothray_primitives::bvh::NearestQueue,
    /// The entries of a tile's list that a ray meets ([`TileList::for_rays`]).
    met: Vec<u32>,
    /// Accumulators of a small tree's pass, one per depth.
    small: Vec<SpanList>,
    /// The lists of a nearest query's second try ([`Program::eval_masked`]).
    masked: masked::MaskLists,
    /// The lists of a sweep of a tree's crossings ([`Program::deep_first`]).
    deep: deep_first::DeepLists,
}

/// A serial no program has had ([`Program::serial`]).
pub(crate) fn fresh_serial() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// Builds a [`Program`] bottom-up.
pub struct ProgramBuilder<'a> {
    /// The program being built.
    pub program: Program,
    leaves: &'a LeafTable,
}

impl<'a> ProgramBuilder<'a> {
    /// A builder over the leaves of `leaves`.
    pub fn new(leaves: &'a LeafTable) -> Self {
        ProgramBuilder { program: Program::default(), leaves }
    }

    /// Adds a leaf node for leaf `leaf` (its bounds from the leaf table).
    pub fn leaf(&mut self, leaf: u32) -> u32 {
        self.leaf_with_bounds(leaf, self.leaves.bounds[leaf as usize])
    }

    /// Adds a leaf node for leaf `leaf` whose bounds are `bounds` (a bake
    /// moves the leaf table's bounds out and keeps one copy, the program's).
    pub fn leaf_with_bounds(&mut self, leaf: u32, bounds: Aabb) -> u32 {
        let p = &mut self.program;
        let id = p.kind.len() as u32;
        p.kind.push(NodeKind::Leaf);
        p.first.push(leaf);
        p.count.push(0);
        p.wide.push(u32::MAX);
        p.bounds.push(bounds);
        p.leafy.push(false);
        p.small.push(self.leaves.has_kernel8(leaf) as u8);
        id
    }

    /// Adds an inner node over already-added `children` (at least one). Nested
    /// nodes of the same associative kind are flattened into this one (a union of
    /// unions is one n-ary union; a difference whose first operand is a
    /// difference absorbs it), which keeps programs shallow and BVHs wide.
    pub fn op(&mut self, op: Op, children: &[u32]) -> u32 {
        let kind = match op {
            Op::Union => NodeKind::Union,
            Op::Intersection => NodeKind::Intersection,
            Op::Difference => NodeKind::Difference,
        };
        if children.len() == 1 {
            return children[0];
        }
        let mut flat: Vec<u32> = Vec::with_capacity(children.len());
        for (i, &c) in children.iter().enumerate() {
            let p = &self.program;
            let absorb = p.kind[c as usize] == kind && (kind != NodeKind::Difference || i == 0);
            if absorb {
                let (f, n) = (p.first[c as usize] as usize, p.count[c as usize] as usize);
                flat.extend_from_slice(&p.children[f..f + n]);
            } else {
                flat.push(c);
            }
        }
        if kind == NodeKind::Intersection {
            // Cheap operands first: an operand empty on the ray ends the
            // intersection (Roth's early out) before the costly ones are
            // asked, and a non-empty one narrows their range. (The order of
            // an intersection's operands does not change the solid.)
            flat.sort_by_cached_key(|&c| self.subtree_cost(c, 3));
        }
        let bounds = self.node_bounds(kind, &flat);
        let p = &mut self.program;
        let first = p.children.len() as u32;
        p.children.extend_from_slice(&flat);
        // A BVH for wide unions (all children) and wide differences (subtrahends).
        let skip = if kind == NodeKind::Difference { 1 } else { 0 };
        let mut wide = u32::MAX;
        if kind != NodeKind::Intersection && flat.len() - skip > WIDE_THRESHOLD {
            // The bounded children's positions (their boxes are read where
            // they are: see `WideTrees::build`).
            let mut ids = Vec::new();
            let mut unbounded = Vec::new();
            for (pos, &c) in flat.iter().enumerate().skip(skip) {
                let b = p.bounds[c as usize];
                if b.is_empty() {
                    continue; // contributes nothing
                }
                if b.is_finite() {
                    ids.push(pos as u32);
                } else {
                    unbounded.push(pos as u32);
                }
            }
            let (bounds, children) = (&p.bounds, &flat);
            let WideTrees { rays: bvh, packet } =
                WideTrees::build(ids.len(), |i| bounds[children[ids[i as usize] as usize] as usize], |i| ids[i as usize]);
            drop(ids);
            wide = p.wides.len() as u32;
            let trees = tree_first::TreeShapes::of(p, self.leaves, &flat);
            let first_walk = flat.iter().any(|&c| p.first_walk_takes(self.leaves, c as usize));
            p.wides.push(Arc::new(Wide { bvh, unbounded, packet, trees, first_walk }));
        }
        let id = p.kind.len() as u32;
        p.kind.push(kind);
        p.first.push(first);
        p.count.push(flat.len() as u32);
        p.wide.push(wide);
        p.bounds.push(bounds);
        let leafy = flat.iter().all(|&c| p.kind[c as usize] == NodeKind::Leaf);
        p.leafy.push(leafy);
        let small = small_tree::small_of(kind, wide != u32::MAX, flat.iter().map(|&c| p.small[c as usize]));
        p.small.push(small);
        id
    }

    /// A rough cost of asking node `c` about a ray: its leaves' query costs
    /// ([`LeafKind::query_cost`]) summed, looked at `depth` levels down (a
    /// deeper node counts 10 per operand).
    fn subtree_cost(&self, c: u32, depth: u32) -> u64 {
        let p = &self.program;
        let cu = c as usize;
        if p.kind[cu] == NodeKind::Leaf {
            return self.leaves.kind[p.first[cu] as usize].query_cost() as u64;
        }
        let (f, n) = (p.first[cu] as usize, p.count[cu] as usize);
        if depth == 0 {
            return 10 * n as u64;
        }
        p.children[f..f + n].iter().map(|&k| self.subtree_cost(k, depth - 1)).sum()
    }

    /// Bounds of a new node over `flat` by Roth's rules: a union encloses its
    /// operands, an intersection is their overlap, a difference its positive
    /// operand. Half-spaces and boxes (under any affine map) among the operands
    /// of an intersection are kept as planes, and so are half-spaces subtracted
    /// from a difference (as their complements): the box is then that of the
    /// polytope they cut from the other operands' box ([`polytope_box`]), so an
    /// intersection of half-spaces alone gets a finite box.
    fn node_bounds(&self, kind: NodeKind, flat: &[u32]) -> Aabb {
        let p = &self.program;
        let mut planes = Vec::new();
        let leaf_planes = |c: u32, flip: bool, planes: &mut Vec<Plane>| -> (bool, bool) {
            if p.kind[c as usize] != NodeKind::Leaf {
                return (false, false);
            }
            let at = planes.len();
            let leaf = p.first[c as usize];
            let is_half = self.leaves.kind[leaf as usize] == LeafKind::HalfSpace;
            if flip && !is_half {
                return (false, false); // a box's complement is not convex
            }
            let poly = self.leaves.world_planes(leaf, planes);
            if flip {
                for q in &mut planes[at..] {
                    *q = q.flipped();
                }
            }
            (poly, is_half)
        };
        let bounds = match kind {
            NodeKind::Union => flat.iter().fold(Aabb::EMPTY, |b, &c| b.union(&p.bounds[c as usize])),
            NodeKind::Intersection => {
                // Worth it with a half-space, or with two boxes (rotated boxes
                // overlap in less than the overlap of their boxes).
                let (mut half, mut polys) = (false, 0);
                for &c in flat {
                    let (poly, h) = leaf_planes(c, false, &mut planes);
                    half |= h;
                    polys += poly as u32;
                }
                let clip = flat.iter().fold(Aabb::INFINITE, |b, &c| b.intersection(&p.bounds[c as usize]));
                if half || polys >= 2 {
                    polytope_box(&planes, &clip)
                } else {
                    clip
                }
            }
            _ => {
                let mut half = false;
                for &c in &flat[1..] {
                    half |= leaf_planes(c, true, &mut planes).1;
                }
                let clip = p.bounds[flat[0] as usize];
                if half {
                    leaf_planes(flat[0], false, &mut planes);
                    polytope_box(&planes, &clip)
                } else {
                    clip
                }
            }
        };
        if bounds.is_empty() {
            Aabb::EMPTY
        } else {
            bounds
        }
    }

    /// Finishes.
    pub fn finish(mut self) -> Program {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        self.program.id = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.program.serial = fresh_serial();
        self.program
    }
}

impl Program {
    /// Records that the rows of `e` were rewritten or appended (a live
    /// sync's re-baked object): copies of the program take just those rows
    /// ([`crate::TileProgram::begin`]).
    pub fn record_edit(&mut self, e: Edit) {
        self.serial = fresh_serial();
        let size = self.kind.len() + self.children.len() + self.wides.len();
        self.edits.record(e, size);
    }

    /// The tile's list of wide union `n`'s children, if it made one.
    #[inline]
    pub(crate) fn list_of(&self, n: u32) -> Option<(&TileList, &RayPlane)> {
        let l = self.lists[..self.lists_len].iter().find(|l| l.node == n)?;
        Some((l, self.ray_plane.as_ref()?))
    }

    /// The BVH of wide node `n`.
    #[inline(always)]
    fn wide_of(&self, n: usize) -> &Wide {
        let w = self.wide[n] as usize;
        match self.wides.get(w) {
            Some(x) => x,
            None => &self.local_wides[w - self.wides.len()],
        }
    }

    /// Evaluates node `root` on the ray over `[tmin, tmax]`; the spans land in
    /// `scratch.out`. Returns the parameter up to which the result is exact
    /// (`tmax` unless [`Mode::Nearest`] let a union stop early). A boundary
    /// within a few eps of that limit is not sure: an operand cut short there
    /// ends its span with no surface, and `combine` may fuse that end with a
    /// real boundary of another operand.
    pub fn eval(&self, leaves: &LeafTable, root: u32, ctx: &RayCtx, mode: Mode, scratch: &mut Scratch) -> f32 {
        self.eval_in(leaves, root, ctx, (ctx.ray.tmin, ctx.ray.tmax), mode, scratch)
    }

    /// [`Program::eval`] over `range` instead of the ray's own range (the
    /// objects of one ray are asked on shrinking ranges: a copy of the ray
    /// context per object, read back by the kernels right after it is
    /// written, stalled on store forwarding; see `LeafTable::spans_in`).
    #[inline(always)]
    pub fn eval_in(&self, leaves: &LeafTable, root: u32, ctx: &RayCtx, range: (f32, f32), mode: Mode, scratch: &mut Scratch) -> f32 {
        let (tmin, tmax) = range;
        scratch.out.clear();
        if self.kind[root as usize] == NodeKind::Leaf {
            let v = leaf_spans(leaves, ctx, self.first[root as usize], (tmin, tmax), ctx.nearest(mode), &mut scratch.out);
            return v.min(tmax);
        }
        self.eval_node(leaves, root, ctx, range, mode, scratch)
    }

    /// [`Program::eval_in`] of an inner node (`scratch.out` cleared). Out of
    /// line, with the leaf case inlined at the callers: an object that is one
    /// leaf (a torus, a ground box) no longer pays the call and register saves
    /// of the whole evaluator (callgrind 480x270 flat: ground -6.1%, sampler
    /// -3.1%, capsules -2.3%, tori -2.3%; nesting +0.4%).
    #[inline(never)]
    fn eval_node(&self, leaves: &LeafTable, root: u32, ctx: &RayCtx, range: (f32, f32), mode: Mode, scratch: &mut Scratch) -> f32 {
        let (tmin, tmax) = range;
        let r = root as usize;
        if self.bounds[r].ray_range(ctx.ray.origin, ctx.ray.inv_dir, tmin, tmax).is_none() {
            return tmax;
        }
        let ask = Ask { leaves, ctx, mode };
        if self.frameless(r) {
            let Scratch { out, leaf, tmp, cand, .. } = scratch;
            return self.eval_frameless(r, ask, (tmin, tmax), Lists { leaf, tmp, acc: out, cand }).min(tmax);
        }
        if self.small_root(r) {
            let Scratch { out, leaf, tmp, small, .. } = scratch;
            self.small_eval(r, Ask { mode: Mode::All, ..ask }, (tmin, tmax), SmallLists { out, deeper: small, leaf, tmp });
            return tmax;
        }
        if self.kind[r] == NodeKind::Union && mode == Mode::Nearest && ctx.memo.is_some() {
            if let Some(v) = self.meet_union_lane(r, ask, (tmin, tmax), &mut scratch.out) {
                return v.min(tmax);
            }
        }
        let base = scratch.frames.len();
        // (The root's box was tested just above, on the same range.)
        self.push_frame(root, (tmin, tmax), ctx, (mode, true), scratch);
        loop {
            // Pick the next child of the top frame.
            let top = scratch.frames.len() - 1;
            let child = self.next_child(top, ctx, scratch);
            match child {
                Some((c, tested)) => {
                    let f = &scratch.frames[top];
                    let (ct0, ct1) = (f.tmin, f.tmax);
                    let mode = self.child_mode(f.node as usize, f.next, f.mode);
                    // (Read beside `child_mode`'s read of the same kind.)
                    let in_union = self.kind[f.node as usize] == NodeKind::Union;
                    if self.kind[c as usize] == NodeKind::Leaf {
                        let Scratch { frames, accs, tmp, leaf, .. } = scratch;
                        leaf.clear();
                        // A leaf's spans are exact on the range it was asked for (up to
                        // `v` in nearest mode).
                        let v = leaf_spans(leaves, ctx, self.first[c as usize], (ct0, ct1), ctx.nearest(mode), leaf);
                        self.absorb(&mut frames[top], &mut accs[top], tmp, (leaf.as_slice(), v), ctx.eps);
                    } else if self.frameless(c as usize) || self.small_root(c as usize) {
                        // Bottom-level inner node or small tree: evaluate in place, no frame.
                        let cu = c as usize;
                        let Scratch { frames, accs, tmp, leaf, sub, cand, small, .. } = scratch;
                        sub.clear();
                        let valid = if !tested && self.bounds[cu].ray_range(ctx.ray.origin, ctx.ray.inv_dir, ct0, ct1).is_none() {
                            f32::INFINITY
                        } else if self.frameless(cu) {
                            let ask = Ask { leaves, ctx, mode };
                            let v = self.eval_frameless(cu, ask, (ct0, ct1), Lists { leaf, tmp: &mut *tmp, acc: &mut *sub, cand });
                            if in_union && mode == Mode::Nearest && v < ct1 && sub.is_empty() {
                                // Empty up to where it stopped (a mesh's first
                                // span cut away by a ball): asked again in full
                                // here, or it would cut the whole union there
                                // and the object be redone in full. (The check
                                // costs scenes/cheese 0.18% of its instructions,
                                // gear_field 0.22%; out of line, the same.)
                                self.eval_frameless(
                                    cu,
                                    Ask { mode: Mode::All, ..ask },
                                    (ct0, ct1),
                                    Lists { leaf, tmp: &mut *tmp, acc: &mut *sub, cand },
                                )
                            } else {
                                v
                            }
                        } else {
                            let ask = Ask { leaves, ctx, mode: Mode::All };
                            let lists = SmallLists { out: &mut *sub, deeper: small, leaf: &mut *leaf, tmp: &mut *tmp };
                            self.small_eval(cu, ask, (ct0, ct1), lists);
                            f32::INFINITY
                        };
                        self.absorb(&mut frames[top], &mut accs[top], tmp, (sub.as_slice(), valid), ctx.eps);
                    } else {
                        self.push_frame(c, (ct0, ct1), ctx, (mode, tested), scratch);
                    }
                }
                None => {
                    let f = scratch.frames.pop().expect("frame");
                    scratch.cand.truncate(f.cand_base as usize);
                    let depth = scratch.frames.len();
                    if depth == base {
                        std::mem::swap(&mut scratch.out, &mut scratch.accs[depth]);
                        return f.valid.min(tmax);
                    }
                    let (parents, rest) = scratch.accs.split_at_mut(depth);
                    self.absorb(
                        &mut scratch.frames[depth - 1],
                        &mut parents[depth - 1],
                        &mut scratch.tmp,
                        (rest[0].as_slice(), f.valid),
                        ctx.eps,
                    );
                    rest[0].clear();
                }
            }
        }
    }

    /// Root `n`'s result for a nearest query on `range` (into the empty
    /// `out`) and where it stops being exact, from its packet's walk when
    /// `n` is a [`Program::is_meet_union`] and that walk settled the lane
    /// (`union_first.rs`); `None`: the caller evaluates it. (Only at an
    /// object's root, where a forest is: the test in the frame loop, for
    /// such unions deeper in a tree, cost scenes without them 0.5-1.2% of
    /// their instructions, callgrind 480x270 flat.) Out of line: the
    /// evaluator's loop keeps its registers.
    #[inline(never)]
    fn meet_union_lane(&self, n: usize, ask: Ask, range: (f32, f32), out: &mut SpanList) -> Option<f32> {
        let Ask { leaves, ctx, .. } = ask;
        let (memo, k) = ctx.memo?;
        if !self.is_meet_union(n as u32) {
            return None;
        }
        memo.union_lane(self, leaves, n as u32, (k, range), out)
    }

    /// The mode of the operand of node `n` at position `next - 1` when `n` is
    /// evaluated in `mode`. A subtrahend is needed only up to its first entry
    /// ([`Mode::Before`]). An intersection's first operand needs all its spans:
    /// cut short at its first entry it would leave the others nothing to meet and
    /// the whole query would be redone; the later operands are evaluated from the
    /// first one's entry on (one that covers it has no real entry there and is
    /// not cut short).
    #[inline(always)]
    fn child_mode(&self, n: usize, next: u32, mode: Mode) -> Mode {
        match (mode, self.kind[n]) {
            (Mode::All, _) => Mode::All,
            (_, NodeKind::Intersection) if next == 1 => Mode::All,
            (_, NodeKind::Difference) if next > 1 => Mode::Before,
            _ => mode,
        }
    }

    /// Pushes the frame of `node` on `[tmin, tmax]`; `tested`: its box is
    /// known to meet that range (the caller tested it on the same range:
    /// a second test of the same box was ~5% of scenes/logo's instructions).
    fn push_frame(&self, node: u32, (tmin, tmax): (f32, f32), ctx: &RayCtx, (mode, tested): (Mode, bool), scratch: &mut Scratch) {
        let mut frame = Frame {
            node,
            next: 0,
            cand_lo: 0,
            cand_hi: 0,
            tmin,
            tmax,
            valid: f32::INFINITY,
            cand_base: scratch.cand.len() as u32,
            done: false,
            mode,
        };
        let depth = scratch.frames.len();
        if scratch.accs.len() <= depth {
            scratch.accs.resize_with(depth + 1, SpanList::new);
        }
        scratch.accs[depth].clear();
        let n = node as usize;
        if !tested && self.bounds[n].ray_range(ctx.ray.origin, ctx.ray.inv_dir, tmin, tmax).is_none() {
            frame.done = true;
        } else if self.kind[n] == NodeKind::Union && self.wide[n] != u32::MAX {
            let lo = scratch.cand.len();
            self.collect(n, 0, ctx, (tmin, tmax), scratch);
            frame.cand_lo = lo as u32;
            frame.cand_hi = scratch.cand.len() as u32;
        }
        scratch.frames.push(frame);
    }

    /// Nodes evaluated in one loop over their leaf operands, without frames:
    /// narrow nodes and wide unions whose operands are all leaves.
    #[inline(always)]
    fn frameless(&self, n: usize) -> bool {
        self.leafy[n] && (self.wide[n] == u32::MAX || self.kind[n] == NodeKind::Union)
    }

    /// Evaluates a [`Program::frameless`] node into `acc`; returns where the result
    /// stops being exact.
    #[inline(always)]
    fn eval_frameless(&self, n: usize, ask: Ask, range: (f32, f32), lists: Lists) -> f32 {
        if self.wide[n] == u32::MAX {
            self.leaf_node(n, ask, range, lists)
        } else {
            self.leaf_union(n, ask, range, lists)
        }
    }

    /// A narrow node whose operands are all leaves, in one loop with the same
    /// early outs as the general path (measured on `scenes/logo`, whose two inner
    /// nodes are like this: frames and their copies were ~40% of the trace time).
    fn leaf_node(&self, n: usize, ask: Ask, (tmin, tmax): (f32, f32), lists: Lists) -> f32 {
        if !self.narrowed_unions.is_empty() {
            if let Some(&(_, wide)) = self.narrowed_unions.iter().find(|c| c.0 == n as u32) {
                return self.baked_union(wide as usize, ask, (tmin, tmax), lists);
            }
        }
        let Ask { leaves, ctx, mode } = ask;
        let Lists { leaf, tmp, acc, .. } = lists;
        let kind = self.kind[n];
        let op = kind.op();
        let (first, count) = (self.first[n] as usize, self.count[n] as usize);
        let (mut lo, mut hi) = (tmin, tmax);
        let mut valid = f32::INFINITY;
        acc.clear();
        for k in 0..count {
            let c = self.children[first + k] as usize;
            // No box test first: for a leaf the kernel is about as cheap, and a miss
            // gives no span, which has the same effect (measured with callgrind on
            // scenes/logo: the box tests were ~8% of the instructions).
            let nearest = ctx.nearest(self.child_mode(n, k as u32 + 1, mode));
            let v = if k == 0 || (kind == NodeKind::Union && acc.is_empty()) {
                leaf_spans(leaves, ctx, self.first[c], (lo, hi), nearest, acc)
            } else {
                leaf.clear();
                let v = leaf_spans(leaves, ctx, self.first[c], (lo, hi), nearest, leaf);
                if !leaf.is_empty() {
                    combine_into(op, acc, leaf.as_slice(), ctx.eps, tmp);
                } else if op == Op::Intersection {
                    acc.clear();
                } // else: an empty union operand or subtrahend changes nothing
                v
            };
            if v < valid {
                // The operand stopped early: so does the result.
                valid = v;
                hi = hi.min(v);
                acc.truncate_at(v);
            }
            match kind {
                NodeKind::Union => {
                    if mode != Mode::All {
                        if let Some(t) = stop_at_first_entry(acc, (lo, hi), mode, ctx.eps) {
                            hi = t;
                            valid = t;
                        }
                    }
                }
                _ => {
                    let s = acc.as_slice();
                    if s.is_empty() {
                        counts::early_out();
                        return valid;
                    }
                    lo = lo.max(s[0].t0);
                    hi = hi.min(operands_end(s, mode, ctx.eps));
                }
            }
        }
        valid
    }

    /// A lane's own query of a tile's narrow union of leaves
    /// ([`Program::narrowed_unions`]): the wide union `wide` it was written for,
    /// evaluated as the baked program evaluates it. Why: the regularised
    /// union of boundaries that lie within eps of one another in a chain
    /// depends on the order it meets them in, and the wide union takes its
    /// children by box entry or in its tree's order, not in the operands'
    /// order: three near-twin balls (two 0.3 eps apart, the third 1.3 eps
    /// past) gave one ball through a tile and another through the baked
    /// union (tests/tiles.rs `packets_take_near_twins_in_the_baked_order`).
    /// The packets' sweeps of the narrow union still answer the lanes
    /// where every boundary stands 2 eps clear, which is order-free.
    #[inline(never)]
    fn baked_union(&self, wide: usize, ask: Ask, range: (f32, f32), lists: Lists) -> f32 {
        lists.acc.clear();
        self.leaf_union(wide, ask, range, lists)
    }

    /// A wide union of leaves, its children visited while their boxes start
    /// before the working range's end; in nearest mode that end shrinks to
    /// the first confirmed entry, which ends the walk. A union that packets
    /// may walk ([`Program::is_packet_union`]) takes its children in one
    /// canonical order (by box entry, then position: [`Program::union_cands`]),
    /// which does not depend on the tree that listed them: regularisation
    /// (short spans dropped, boundaries fused) is not associative, so a walk
    /// in another order could end a few eps differently from the packet's.
    /// A packet that walked the union for this ray already
    /// ([`PacketMemo::walk_unions_for`]) answers from its memo where its record
    /// covers the query.
    fn leaf_union(&self, n: usize, ask: Ask, (tmin, tmax): (f32, f32), lists: Lists) -> f32 {
        let Lists { leaf, tmp, acc, cand } = lists;
        if let (Some((memo, k)), Mode::Nearest) = (ask.ctx.memo, ask.mode) {
            if let Some(v) = memo.union_lane(self, ask.leaves, n as u32, (k, (tmin, tmax)), acc) {
                return v;
            }
        }
        let mut st = UnionLane { hi: tmax, valid: f32::INFINITY };
        if ask.mode != Mode::Nearest || !self.is_packet_union(n as u32) {
            // No packet walks this union: the tree's own front-to-back order,
            // pruned as the range shrinks (the canonical order collects the
            // children along the whole range first: +22% instructions on
            // scenes/cheese, whose 1000 holes are a union asked for its first
            // entry only).
            let w = self.wide_of(n);
            let ray = &ask.ctx.ray;
            for &pos in &w.unbounded {
                self.union_visit(n, pos, ask, tmin, &mut st, (&mut *leaf, &mut *tmp, &mut *acc));
            }
            w.bvh.traverse(ray.origin, ray.inv_dir, tmin, st.hi, |pos, _| {
                self.union_visit(n, pos, ask, tmin, &mut st, (&mut *leaf, &mut *tmp, &mut *acc));
                st.hi
            });
            return st.valid;
        }
        let base = cand.len();
        self.union_cands(n, &ask.ctx.ray.with_range(tmin, tmax), cand);
        for i in base..cand.len() {
            let (pos, t0) = cand[i];
            if t0 > st.hi {
                break;
            }
            self.union_visit(n, pos, ask, tmin, &mut st, (&mut *leaf, &mut *tmp, &mut *acc));
        }
        cand.truncate(base);
        st.valid
    }

    /// Appends the children of wide union `n` whose boxes `ray`'s range
    /// meets, with their box entries, sorted by entry, then position (the
    /// unbounded ones enter at `tmin`).
    fn union_cands(&self, n: usize, ray: &Ray, cand: &mut Vec<(u32, f32)>) {
        let w = self.wide_of(n);
        let base = cand.len();
        for &pos in &w.unbounded {
            cand.push((pos, ray.tmin));
        }
        w.bvh.traverse(ray.origin, ray.inv_dir, ray.tmin, ray.tmax, |pos, _| {
            if let Some(t0) = self.child_entry(n, pos, ray) {
                cand.push((pos, t0));
            }
            ray.tmax
        });
        sort_cands(&mut cand[base..]);
    }

    /// The node of child `pos` of node `n`.
    #[inline(always)]
    pub(crate) fn child_at(&self, n: usize, pos: u32) -> u32 {
        self.children[(self.first[n] + pos) as usize]
    }

    /// Where `ray` enters the box of child `pos` of node `n` within its range.
    #[inline(always)]
    pub(crate) fn child_entry(&self, n: usize, pos: u32, ray: &Ray) -> Option<f32> {
        let c = self.child_at(n, pos);
        self.bounds[c as usize].ray_range(ray.origin, ray.inv_dir, ray.tmin, ray.tmax).map(|r| r.0)
    }

    /// Visits child `pos` of wide leaf union `n` for one ray: its spans on
    /// `[tmin, st.hi]` join the ray's result `lists.acc`; `st.hi` shrinks to
    /// the first confirmed entry (nearest modes) and `st.valid` to where the
    /// result stops being exact.
    #[inline(always)]
    pub(crate) fn union_visit(&self, n: usize, pos: u32, ask: Ask, tmin: f32, st: &mut UnionLane, lists: ListsRef) {
        let Ask { leaves, ctx, mode } = ask;
        let (leaf, tmp, acc) = lists;
        counts::wide_child();
        let c = self.child_at(n, pos);
        leaf.clear();
        let v = leaf_spans(leaves, ctx, self.first[c as usize], (tmin, st.hi), ctx.nearest(mode), leaf);
        if v < st.valid {
            st.valid = v;
            st.hi = st.hi.min(v);
            acc.truncate_at(v);
        }
        if leaf.is_empty() {
            return;
        }
        if acc.is_empty() {
            acc.append(leaf.as_slice());
        } else {
            combine_into_call(Op::Union, acc, leaf.as_slice(), ctx.eps, tmp);
        }
        if mode != Mode::All {
            if let Some(t) = stop_at_first_entry(acc, (tmin, st.hi), mode, ctx.eps) {
                st.hi = t;
                st.valid = t;
            }
        }
    }

    /// Candidates of wide node `n` (children at positions >= `skip`) along `[tmin, tmax]`,
    /// sorted by box entry.
    fn collect(&self, n: usize, skip: u32, ctx: &RayCtx, (tmin, tmax): (f32, f32), scratch: &mut Scratch) {
        let ray = &ctx.ray;
        let w = self.wide_of(n);
        let lo = scratch.cand.len();
        // A union of subtrees that the tile listed takes its candidates
        // from the list; anything else walks the node's tree.
        let listed = skip == 0 && self.lists_len > 0 && !self.leafy[n] && self.collect_listed(n, ctx, (tmin, tmax), scratch);
        if !listed {
            let cand = &mut scratch.cand;
            w.bvh.traverse(ray.origin, ray.inv_dir, tmin, tmax, |pos, _| {
                let c = self.child_at(n, pos);
                if let Some((t0, _)) = self.bounds[c as usize].ray_range(ray.origin, ray.inv_dir, tmin, tmax) {
                    cand.push((pos, t0));
                    counts::wide_child();
                }
                tmax
            });
        }
        let cand = &mut scratch.cand;
        for &pos in &w.unbounded {
            if pos >= skip {
                cand.push((pos, tmin));
            }
        }
        // The same order whichever tree listed them (a tile's short list or
        // the baked BVH).
        sort_cands(&mut cand[lo..]);
    }

    /// [`Program::collect`]'s candidates of wide union `n` (of subtrees:
    /// not leafy) from the tile's list of its bounded children, if the tile
    /// made one and the ray is a ray of its plane; `false` when not (the
    /// caller walks the tree). The list holds every child whose box the
    /// tile's region touches, filtered by their shadows on the tile's ray
    /// plane: the same candidates as the tree's (a forest of 10 000 trees
    /// cut by half-spaces walked the union's tree along every ray, 45% of
    /// its cycles, perf). Out of line: the tree walk's caller stays as it
    /// was (callgrind: fill +0.8% instructions inlined).
    #[inline(never)]
    fn collect_listed(&self, n: usize, ctx: &RayCtx, (tmin, tmax): (f32, f32), scratch: &mut Scratch) -> bool {
        let Some(listed) = self.list_of(n as u32) else { return false };
        let ray = &ctx.ray;
        let cand = &mut scratch.cand;
        let push = |cand: &mut Vec<(u32, f32)>, (pos, b): (u32, &Aabb)| {
            if let Some((t0, _)) = b.ray_range(ray.origin, ray.inv_dir, tmin, tmax) {
                cand.push((pos, t0));
                counts::wide_child();
            }
        };
        // In a packet, the entries its rays' points meet, found once for
        // all lanes (each lane then tests their boxes: the same candidates).
        let key = (self as *const Program as usize, n as u32);
        let packet = ctx.memo.and_then(|(memo, k)| {
            memo.with_list_met(key, listed, k, |list, met, slabs| {
                if slabs.len() == met.len() {
                    // The packet's box tests, clipped to this lane's range.
                    for (&i, (enter, leave)) in met.iter().zip(slabs) {
                        if let Some((t0, _)) = Aabb::clip_slabs((enter[k], leave[k]), tmin, tmax) {
                            cand.push((list.entry(i).0, t0));
                            counts::wide_child();
                        }
                    }
                } else {
                    for &i in met {
                        push(cand, list.entry(i));
                    }
                }
            })
        });
        if packet.is_none() {
            let (list, plane) = listed;
            let Some(met) = list.for_rays(plane, (&[ray.origin; 8], &[ray.dir; 8]), 1, &mut scratch.met) else { return false };
            for e in met {
                push(cand, e);
            }
        }
        counts::listed_collect();
        true
    }

    /// The next child node to evaluate for frame `top`, or `None` when it is
    /// finished; with whether its box was tested on the frame's current range
    /// (a narrow node's children are; a wide node's come from its candidate
    /// list, made on the range of the time).
    fn next_child(&self, top: usize, ctx: &RayCtx, scratch: &mut Scratch) -> Option<(u32, bool)> {
        let f = &scratch.frames[top];
        if f.done {
            return None;
        }
        let n = f.node as usize;
        let kind = self.kind[n];
        let (first, count) = (self.first[n], self.count[n]);
        let wide = self.wide[n] != u32::MAX;
        loop {
            let f = &mut scratch.frames[top];
            if (kind == NodeKind::Union && wide) || (kind == NodeKind::Difference && wide && f.next > 0) {
                if kind == NodeKind::Difference && f.next == 1 {
                    // Positive operand done: collect the subtrahends along its extent.
                    f.next = 2;
                    let (t0, t1) = (f.tmin, f.tmax);
                    let lo = scratch.cand.len() as u32;
                    self.collect(n, 1, ctx, (t0, t1), scratch);
                    let f = &mut scratch.frames[top];
                    f.cand_lo = lo;
                    f.cand_hi = scratch.cand.len() as u32;
                    continue;
                }
                if f.cand_lo >= f.cand_hi {
                    return None;
                }
                let (pos, tenter) = scratch.cand[f.cand_lo as usize];
                f.cand_lo += 1;
                if tenter > f.tmax {
                    // Sorted by entry: nothing further can matter.
                    f.cand_lo = f.cand_hi;
                    continue;
                }
                return Some((self.children[(first + pos) as usize], false));
            }
            if f.next >= count || (kind == NodeKind::Difference && wide && f.next > 0) {
                return None;
            }
            let c = self.children[(first + f.next) as usize];
            f.next += 1;
            if self.bounds[c as usize].ray_range(ctx.ray.origin, ctx.ray.inv_dir, f.tmin, f.tmax).is_none() {
                // An empty child: the union skips it, the intersection is empty,
                // the difference skips a subtrahend and ends on an empty positive.
                match kind {
                    NodeKind::Union => continue,
                    NodeKind::Intersection => {
                        scratch.accs[top].clear();
                        scratch.frames[top].done = true;
                        counts::early_out();
                        return None;
                    }
                    _ => {
                        if f.next == 1 {
                            f.done = true;
                            counts::early_out();
                            return None;
                        }
                        continue;
                    }
                }
            }
            return Some((c, true));
        }
    }

    /// Folds a child's result into frame `top`.
    fn absorb(&self, f: &mut Frame, acc: &mut SpanList, tmp: &mut SpanList, (r, r_valid): (&[Span], f32), eps: f32) {
        let mode = f.mode;
        let kind = self.kind[f.node as usize];
        if r_valid < f.valid {
            f.valid = r_valid;
            f.tmax = f.tmax.min(r_valid);
            acc.truncate_at(r_valid);
        }
        let first = acc.is_empty() && is_first(f, kind);
        if first {
            acc.clear();
            acc.append(r);
            acc.truncate_at(f.tmax);
        } else {
            combine_into(kind.op(), acc, r, eps, tmp);
        }
        match kind {
            NodeKind::Union => {
                if mode != Mode::All {
                    if let Some(t) = stop_at_first_entry(acc, (f.tmin, f.tmax), mode, eps) {
                        f.valid = t;
                        f.tmax = t;
                    }
                }
            }
            NodeKind::Intersection | NodeKind::Difference => {
                if acc.is_empty() {
                    f.done = true;
                    counts::early_out();
                } else {
                    // Later operands only matter over the current extent.
                    let s = acc.as_slice();
                    f.tmin = f.tmin.max(s[0].t0);
                    f.tmax = f.tmax.min(operands_end(s, mode, eps));
                }
            }
            NodeKind::Leaf => {}
        }
    }

    /// Classifies a point against node `root` (boundary counts as inside).
    pub fn contains(&self, leaves: &LeafTable, root: u32, p: Vec3, scratch: &mut Scratch) -> bool {
        // Post-order: a node's subtree occupies a contiguous id range ending at it,
        // except for absorbed (flattened) nodes, which are simply never read.
        let r = root as usize;
        let lo = self.subtree_start(root) as usize;
        scratch.bools.clear();
        scratch.bools.resize(r - lo + 1, false);
        for n in lo..=r {
            let v = match self.kind[n] {
                NodeKind::Leaf => leaves.contains(self.first[n], p),
                k => {
                    let (f, c) = (self.first[n] as usize, self.count[n] as usize);
                    let ch = &self.children[f..f + c];
                    if !self.bounds[n].contains(p) && self.bounds[n].is_finite() {
                        false
                    } else {
                        match k {
                            NodeKind::Union => ch.iter().any(|&c| scratch.bools[c as usize - lo]),
                            NodeKind::Intersection => ch.iter().all(|&c| scratch.bools[c as usize - lo]),
                            _ => scratch.bools[ch[0] as usize - lo] && !ch[1..].iter().any(|&c| scratch.bools[c as usize - lo]),
                        }
                    }
                }
            };
            scratch.bools[n - lo] = v;
        }
        scratch.bools[r - lo]
    }

    /// Smallest node id in the subtree of `root` (iterative).
    pub fn subtree_start(&self, root: u32) -> u32 {
        let mut lo = root;
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            lo = lo.min(n);
            if self.kind[n as usize] != NodeKind::Leaf {
                let (f, c) = (self.first[n as usize] as usize, self.count[n as usize] as usize);
                stack.extend_from_slice(&self.children[f..f + c]);
            }
        }
        lo
    }
}

/// Where the later operands of an intersection or difference whose result
/// so far is `s` (not empty) are asked up to: the result's end; in the
/// nearest modes 4 eps past it. (There the result may end early, at the
/// first span's end: an operand clipped exactly there gets a boundary
/// within eps of that end which the full diagram does not have, and
/// `combine`'s fusing of boundaries within eps of each other then differs:
/// tests/csg_oracle.rs `near_twin_slivers_from_inside`.)
#[inline(always)]
fn operands_end(s: &[Span], mode: Mode, eps: f32) -> f32 {
    let end = s[s.len() - 1].t1;
    if mode == Mode::All {
        end
    } else {
        end + 4.0 * eps
    }
}

/// Where a nearest query stops past a first entry at `t` with tolerance
/// `eps`: `4 eps` on (the nearest-mode slack, [`RayCtx::nearest_slack_of`],
/// as a mesh's nearest walk stops past its first crossing), and past `t`
/// at least ([`rothray_primitives::mesh::stop_past`], where every mesh
/// walk stops). A union's walk ([`stop_at_first_entry`]), a masked second
/// try and the first-entry walk's reading of a mesh's answer
/// (`union_first.rs`) all cut there: one place, the same bits.
#[inline(always)]
pub(crate) fn entry_stop(t: f32, eps: f32) -> f32 {
    rothray_primitives::mesh::stop_past(t, RayCtx::nearest_slack_of(eps))
}

/// A union in [`Mode::Nearest`] is needed only a little past its first confirmed
/// entry `t0` (the query's answer is there or before): truncates `acc` at
/// `v = t0 + 4 eps` and returns `v` when that is before `hi`. The result stays
/// exact on `[tmin, v]`, and the first span `[t0, v]` keeps its real entry and is
/// long enough to survive the short-span rule of `combine`. (Truncating at `t0`
/// itself dropped that span: every such ray came back empty and was evaluated a
/// second time in full, half the rays of `scenes/forest`.) [`Mode::Before`]
/// (a subtrahend, asked from the positive operand's first entry `lo` on)
/// stops at the same place when `t0` is within 2 eps of `lo`, where the
/// full diagram fuses the two entries; further on, at `t0` itself (the
/// positive operand's first span ends there; keeping `[t0, v]` made the
/// difference merge it: +4.6% instructions on scenes/logo).
#[inline(always)]
fn stop_at_first_entry(acc: &mut SpanList, (lo, hi): (f32, f32), mode: Mode, eps: f32) -> Option<f32> {
    let s = *acc.as_slice().first()?;
    if !s.s0.is_real() {
        return None;
    }
    let v = match mode {
        Mode::All => return None,
        // A span no longer than eps is not sure: `combine` drops it if a
        // later operand has spans anywhere on the range, and cut short here
        // the range would leave them nothing to show.
        Mode::Nearest | Mode::Before if s.t1 - s.t0 <= eps => return None,
        Mode::Before if s.t0 - lo > 2.0 * eps => s.t0,
        Mode::Nearest | Mode::Before => entry_stop(s.t0, eps),
    };
    if v < hi {
        acc.truncate_at(v);
        Some(v)
    } else {
        None
    }
}

/// Is the operand just taken the first one of the frame (it initialises the
/// accumulator of an intersection or difference; for a union an empty
/// accumulator is the identity anyway)?
#[inline(always)]
fn is_first(f: &Frame, kind: NodeKind) -> bool {
    match kind {
        NodeKind::Intersection | NodeKind::Difference => f.next == 1,
        NodeKind::Union | NodeKind::Leaf => true,
    }
}

/// The first real surface of a span list within `[tmin, valid]`: the nearest-hit
/// answer. Returns `(t, surface)`.
#[inline]
pub fn first_surface(spans: &[Span]) -> Option<(f32, Surf)> {
    let s = spans.first()?;
    if s.s0.is_real() {
        Some((s.t0, s.s0))
    } else if s.s1.is_real() {
        Some((s.t1, s.s1))
    } else {
        None
    }
}

#[path = "deep_first.rs"]
pub(crate) mod deep_first;
pub use deep_first::DeepFirst;
#[cfg(test)]
#[path = "lane_ends.rs"]
mod lane_ends;
#[path = "leaf_packet.rs"]
mod leaf_packet;
#[path = "masked.rs"]
mod masked;
#[path = "mesh_packet.rs"]
mod mesh_packet;
#[path = "object_packet.rs"]
pub mod object_packet;
#[path = "small_first.rs"]
mod small_first;
#[path = "small_first8.rs"]
mod small_first8;
#[path = "small_tree.rs"]
pub(crate) mod small_tree;
use small_tree::SmallLists;
#[path = "torus_sweep.rs"]
mod torus_sweep;
#[path = "tree_first.rs"]
pub(crate) mod tree_first;
#[path = "tree_first8.rs"]
mod tree_first8;
#[path = "union_first.rs"]
mod union_first;
#[path = "union_packet.rs"]
mod union_packet;
