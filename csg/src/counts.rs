//! Counters of what the evaluator did, per thread (for `rothray bench
//! --json`): a thread-local add per event, 0.1% of the instructions of
//! scenes/logo (callgrind, 480x270, warm-up plus one render: 207.48e6 with
//! the adds, 207.27e6 without).

use std::cell::Cell;

thread_local! {
    static LEAVES: Cell<u64> = const { Cell::new(0) };
    static WIDE: Cell<u64> = const { Cell::new(0) };
    static EARLY: Cell<u64> = const { Cell::new(0) };
    static PACKET_SERVED: Cell<u64> = const { Cell::new(0) };
    static PACKET_MISSED: Cell<u64> = const { Cell::new(0) };
    static LEAF_SOLVES: Cell<u64> = const { Cell::new(0) };
    static LEAF_SERVED: Cell<u64> = const { Cell::new(0) };
    static LEAF_SCALAR: Cell<u64> = const { Cell::new(0) };
    static FIRST_SETTLED: Cell<u64> = const { Cell::new(0) };
    static FIRST_WALKED: Cell<u64> = const { Cell::new(0) };
    static LISTED: Cell<u64> = const { Cell::new(0) };
    static OBJ_SETTLED: Cell<u64> = const { Cell::new(0) };
    static OBJ_LEFT: Cell<u64> = const { Cell::new(0) };
    static MASKED_SURE: Cell<u64> = const { Cell::new(0) };
    static MASKED_LEFT: Cell<u64> = const { Cell::new(0) };
    static DEEP_SURE: Cell<u64> = const { Cell::new(0) };
    static DEEP_LEFT: Cell<u64> = const { Cell::new(0) };
    static FULL_REDOS: Cell<u64> = const { Cell::new(0) };
    static PAR_MESH: Cell<u64> = const { Cell::new(0) };
    static PAR_MESH_LEFT: Cell<u64> = const { Cell::new(0) };
    static MESH_WALK: Cell<u64> = const { Cell::new(0) };
    static MESH_WALK_LEFT: Cell<u64> = const { Cell::new(0) };
}

/// What the evaluator did on this thread since the last [`take_eval_counts`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EvalCounts {
    /// Leaf queries (kernel calls and answers from a packet memo).
    pub leaves: u64,
    /// Children of wide nodes visited (through their BVHs).
    pub wide_children: u64,
    /// Roth's early outs taken: an intersection stopped at an empty operand, a
    /// difference at an empty positive operand.
    pub early_outs: u64,
    /// Wide-union evaluations answered by their packet's walk
    /// ([`crate::PacketMemo::walk_unions_for`]).
    pub packet_lanes: u64,
    /// Wide-union evaluations of a packet lane that its packet's record did
    /// not answer (another range: the lane walked on its own).
    pub packet_misses: u64,
    /// Analytic leaves solved for all lanes of a packet at once
    /// ([`crate::PacketMemo::solve_leaves_for`]).
    pub leaf_solves: u64,
    /// Leaf queries of packet lanes answered from those solves.
    pub leaf_lanes: u64,
    /// Leaf queries of packet lanes that a solve left to the scalar kernel
    /// (a local direction out of the kernels' range).
    pub leaf_scalar: u64,
    /// Lanes of packet walks of wide unions answered by their first entries
    /// alone (`union_first.rs`).
    pub first_settled: u64,
    /// Lanes of those walks that walked their children in order instead (a
    /// near tie, a short first span, a ray starting inside a child, a
    /// child without a packet kernel, or an unbounded child).
    pub first_walked: u64,
    /// Wide-union queries whose candidates came from a tile's list instead
    /// of the union's tree (`Program::collect`).
    pub listed_collects: u64,
    /// Lanes of packets of tiles of simple objects whose hit the packet
    /// picked among the objects (`engine/src/packet_first.rs`).
    pub object_settled: u64,
    /// Lanes of those packets left to their own visit of the objects (an
    /// object unsure on the lane, a near tie, a box entered past the hit).
    pub object_left: u64,
    /// Nearest queries whose second try under masks (`csg/src/masked.rs`)
    /// gave a sure answer.
    pub masked_sure: u64,
    /// Second tries under masks that gave none (the query was redone in full).
    pub masked_left: u64,
    /// Nearest queries answered by a sweep of the tree's crossings
    /// (`csg/src/deep_first.rs`).
    pub deep_sure: u64,
    /// Sweeps that gave no answer (crossings within 2 eps, the ray
    /// starting inside, too many crossings).
    pub deep_left: u64,
    /// Nearest queries of an object redone in full ([`crate::Mode::All`]):
    /// neither the first try nor a second one was sure.
    pub full_redos: u64,
    /// Lanes of packets of rays with one direction (shadow rays) whose mesh
    /// spans came from the packet's one walk of the mesh's tree
    /// (`MeshData::spans_parallel8`).
    pub parallel_mesh_lanes: u64,
    /// Lanes of those packets left to their own mesh queries (the point at
    /// `tmin` outside the mesh's bounds, the winding rule).
    pub parallel_mesh_left: u64,
    /// Nearest-mode mesh queries of lanes of packets from one origin
    /// answered by the packet's walk of the mesh made when the first lane
    /// asked (`PacketMemo::walk_meshes_for`).
    pub mesh_walk_lanes: u64,
    /// Those left to the lane's own query (a lane the walk did not do, a
    /// range its record does not cover).
    pub mesh_walk_left: u64,
}

impl EvalCounts {
    /// Adds `o` to these counts.
    pub fn add(&mut self, o: &EvalCounts) {
        self.leaves += o.leaves;
        self.wide_children += o.wide_children;
        self.early_outs += o.early_outs;
        self.packet_lanes += o.packet_lanes;
        self.packet_misses += o.packet_misses;
        self.leaf_solves += o.leaf_solves;
        self.leaf_lanes += o.leaf_lanes;
        self.leaf_scalar += o.leaf_scalar;
        self.first_settled += o.first_settled;
        self.first_walked += o.first_walked;
        self.listed_collects += o.listed_collects;
        self.object_settled += o.object_settled;
        self.object_left += o.object_left;
        self.masked_sure += o.masked_sure;
        self.masked_left += o.masked_left;
        self.deep_sure += o.deep_sure;
        self.deep_left += o.deep_left;
        self.full_redos += o.full_redos;
        self.parallel_mesh_lanes += o.parallel_mesh_lanes;
        self.parallel_mesh_left += o.parallel_mesh_left;
        self.mesh_walk_lanes += o.mesh_walk_lanes;
        self.mesh_walk_left += o.mesh_walk_left;
    }
}

#[inline(always)]
fn bump(c: &'static std::thread::LocalKey<Cell<u64>>) {
    c.with(|x| x.set(x.get() + 1));
}

#[inline(always)]
pub(crate) fn leaf() {
    bump(&LEAVES);
}

#[inline(always)]
pub(crate) fn wide_child() {
    bump(&WIDE);
}

#[inline(always)]
pub(crate) fn wide_children(n: u32) {
    WIDE.with(|x| x.set(x.get() + n as u64));
}

#[inline(always)]
pub(crate) fn early_out() {
    bump(&EARLY);
}

// (A branch per key, not a key chosen by a branch: with the key chosen,
// the compiler once made the access a call through a pointer to one of
// two accessor functions, per leaf query.)
#[inline(always)]
pub(crate) fn packet_lane(served: bool) {
    if served {
        bump(&PACKET_SERVED)
    } else {
        bump(&PACKET_MISSED)
    }
}

#[inline(always)]
pub(crate) fn leaf_solve() {
    bump(&LEAF_SOLVES);
}

/// `n` leaf queries, `served` of them answered from packet solves (a
/// lane's batch: `deep_first.rs`).
#[inline(always)]
pub(crate) fn leaf_batch(n: u64, served: u64) {
    LEAVES.with(|x| x.set(x.get() + n));
    LEAF_SERVED.with(|x| x.set(x.get() + served));
}

#[inline(always)]
pub(crate) fn leaf_lane(served: bool) {
    if served {
        bump(&LEAF_SERVED)
    } else {
        bump(&LEAF_SCALAR)
    }
}

#[inline(always)]
pub(crate) fn first_entries(settled: u32, walked: u32) {
    FIRST_SETTLED.with(|x| x.set(x.get() + settled as u64));
    FIRST_WALKED.with(|x| x.set(x.get() + walked as u64));
}

#[inline(always)]
pub(crate) fn listed_collect() {
    bump(&LISTED);
}

/// A packet's lanes settled among its tile's objects (`settled` of them)
/// and left to their own visits (`left`).
#[inline(always)]
pub fn object_lanes(settled: u32, left: u32) {
    OBJ_SETTLED.with(|x| x.set(x.get() + settled as u64));
    OBJ_LEFT.with(|x| x.set(x.get() + left as u64));
}

/// A second try under masks: it gave a sure answer, or not.
#[inline(always)]
pub fn masked_try(sure: bool) {
    if sure {
        bump(&MASKED_SURE)
    } else {
        bump(&MASKED_LEFT)
    }
}

/// A sweep of a tree's crossings: it gave an answer, or not.
#[inline(always)]
pub fn deep_try(sure: bool) {
    if sure {
        bump(&DEEP_SURE)
    } else {
        bump(&DEEP_LEFT)
    }
}

/// A nearest query redone in full.
#[inline(always)]
pub fn full_redo() {
    bump(&FULL_REDOS)
}

/// A packet mesh walked for eight rays with one direction: `done` lanes
/// got their spans from the walk, `left` are left to their own queries.
#[inline(always)]
pub fn parallel_mesh_lanes(done: u32, left: u32) {
    PAR_MESH.with(|x| x.set(x.get() + done as u64));
    PAR_MESH_LEFT.with(|x| x.set(x.get() + left as u64));
}

/// A lane's nearest-mode mesh query asked of its packet's walk: answered
/// from it or not.
#[inline(always)]
pub(crate) fn mesh_walk_lane(answered: bool) {
    bump(if answered { &MESH_WALK } else { &MESH_WALK_LEFT })
}

/// This thread's counts since the last call, reset.
pub fn take_eval_counts() -> EvalCounts {
    EvalCounts {
        leaves: LEAVES.with(|c| c.replace(0)),
        wide_children: WIDE.with(|c| c.replace(0)),
        early_outs: EARLY.with(|c| c.replace(0)),
        packet_lanes: PACKET_SERVED.with(|c| c.replace(0)),
        packet_misses: PACKET_MISSED.with(|c| c.replace(0)),
        leaf_solves: LEAF_SOLVES.with(|c| c.replace(0)),
        leaf_lanes: LEAF_SERVED.with(|c| c.replace(0)),
        leaf_scalar: LEAF_SCALAR.with(|c| c.replace(0)),
        first_settled: FIRST_SETTLED.with(|c| c.replace(0)),
        first_walked: FIRST_WALKED.with(|c| c.replace(0)),
        listed_collects: LISTED.with(|c| c.replace(0)),
        object_settled: OBJ_SETTLED.with(|c| c.replace(0)),
        object_left: OBJ_LEFT.with(|c| c.replace(0)),
        masked_sure: MASKED_SURE.with(|c| c.replace(0)),
        masked_left: MASKED_LEFT.with(|c| c.replace(0)),
        deep_sure: DEEP_SURE.with(|c| c.replace(0)),
        deep_left: DEEP_LEFT.with(|c| c.replace(0)),
        full_redos: FULL_REDOS.with(|c| c.replace(0)),
        parallel_mesh_lanes: PAR_MESH.with(|c| c.replace(0)),
        parallel_mesh_left: PAR_MESH_LEFT.with(|c| c.replace(0)),
        mesh_walk_lanes: MESH_WALK.with(|c| c.replace(0)),
        mesh_walk_left: MESH_WALK_LEFT.with(|c| c.replace(0)),
    }
}
