//! The first entry of a wide union of convex analytic leaves (or of small
//! trees of them) for all lanes
//! of a packet at once, without each lane's ordered visit of its children.
//!
//! A lane's own walk ([`Program::leaf_union`]) visits the children in the
//! canonical order (box entry, then position), merges each one's span into
//! its result with the regularising union (`combine`) and stops a little past
//! the first entry it confirms ([`stop_at_first_entry`](super::stop_at_first_entry)).
//! When one child's span starts clearly before every other child's (by more
//! than the merge's tolerances) and is not short, that walk ends with
//! exactly that span cut at `v = max(a + 4 eps, next_up(a))`, whatever the
//! order: every other span is cut away or starts past `v`, and nothing is
//! fused at `a`. So the packet only needs, per lane, the smallest span start,
//! the second smallest, and the first span's end and surfaces: one 8-lane
//! box test and (where some lane's box test passes) one 8-lane solve per
//! child, with no per-lane candidate lists, merges or memo look-ups. Lanes
//! where the conditions do not hold (a near tie, a short first span, a ray
//! starting inside a child) are left to the lane walks
//! (`union_packet.rs`), which give what each lane's own walk gives.
//!
//! Why: on a forest of 10 000 small leaves the lanes' ordered visits (their
//! candidate lists, merges and memo look-ups) were most of the trace's
//! cycles while the leaves' solves were an eighth (perf, `LaneWalks::take`).
//!
//! A ring torus among the children has no 8-lane solve: each lane reads
//! its nearest query from the packet's preps, the answer its own walk reads
//! (`FirstWalk::take_leaf_lanes`); a child node of kernel leaves and tori is
//! swept as an object of that node is (`FirstWalk::take_torus_node`), and
//! a small tree of them by its truth table (`FirstWalk::take_torus_tree`).
//! A mesh child's lanes read their answers from the packet's walk of the
//! mesh (`FirstWalk::take_leaf_lanes`). Any other child without a packet path (a
//! sweep, a larger tree) makes the lanes whose reach it lies within leave
//! the walk: they walk in order, or evaluate the union alone. A union none
//! of whose children has one ([`Program::first_take`], asked at bake:
//! meshes each minus a ball) is not walked at all, and a tile that meets
//! such a child writes a narrow union of the few children it meets
//! instead of a list (`tile.rs`).
//!
//! A wide union of small trees ([`Program::is_meet_union`]: a forest of
//! trees cut by half-spaces, of rounded or hollowed pieces) is walked the
//! same way when its children are kernel leaves, intersections and
//! differences of a few of them ([`Program::small_leafy`]), or small trees
//! of up to eight kernel leaves at any depth ([`Program::is_tree`], answered
//! lane by lane by `tree_first`, with the same argument). Such a
//! child's spans come from its operands' 8-lane solves by the exact set
//! operation where no two of their boundaries lie within `2 eps` of each
//! other (then `combine` fuses, merges and drops nothing; see
//! [`small_first`]); elsewhere only a lower bound of its start is known,
//! which keeps a lane from settling when that child may come first. The
//! argument above holds for children with several spans when the second
//! smallest start counts each child's later spans too. The lane walk of
//! such a union is the evaluator's frames (`Program::collect`, one frame
//! per union and an evaluation per child), so a lane the walk does not
//! settle evaluates the union itself. On benches/scenes/forest_cut
//! (10 000 such trees) 98% of the union's lane evaluations were answered
//! here (`rothray bench benches/scenes/forest_cut.json --no-shadows
//! --json`: `union_first_entry_lanes` against `union_listed_collects`).

use rothray_primitives::{
    box_wide::{Lanes8, Visit8},
    kernels8::{Ranges8, Rays8Soa},
    mask8::{le_mask, masked_max, masked_min},
    Aabb, LeafTable, Span, SpanSink, Surf,
};

use super::small_first::{small_first, Clipped, SmallFirst, SmallOps};
use super::small_first8::{small_first8, First8, Ranges, Two};
use super::torus_sweep::torus_operands;
use super::tree_first::{done_by, solved_late, tree_first, TreeShape, TREE_LEAVES};
use super::{cand_key, entry_stop, sort_few, NodeKind, PacketMemo, Program, RayCtx};
use crate::counts;

/// Past the first entry `a`, the other children's boxes entered beyond
/// `a + PRUNE * eps` cannot change a lane's answer (their spans start
/// there or later, up to the rounding of the box test and of the solve: a
/// few ulps, and a lane is settled only where 4 eps is at least an ulp, so
/// that rounding stays well inside the margin down to `v + APART * eps`)
/// and are not solved.
const PRUNE: f32 = 64.0;

/// The second smallest span start must lie beyond `v + APART * eps`: then
/// no boundary of another child is fused with the first span's (within eps)
/// or merged across a gap (below eps), and the cut at `v` removes the rest.
/// Both paths compare the same floats, and the differences `combine` takes
/// of two such nearby floats are exact (Sterbenz); only `v + APART * eps`
/// rounds, by at most half an ulp, and a lane is settled only where
/// `4 eps` is an ulp or more: so every other boundary lies at least `2 eps`
/// past `v`. (12 settled 1.3% fewer of benches/scenes/forest_deep's lanes,
/// which each evaluated the union alone: forest_deep, forest_cut -2.4% wall
/// flat, forest -1.5%. With 0 or more the tile tests still pass; below -4,
/// a first entry fused with another's, they fail.)
const APART: f32 = 4.0;

/// A child whose box some lanes meet, waiting to be solved: the smallest
/// of their entries, its position, the lanes and their entries.
type Pending = (f32, u32, u32, [f32; 8]);

/// The children waiting to be solved, and room for their sort keys
/// ([`cand_key`] of the smallest entry among their lanes and of their
/// place in `items`): a walk sorts eight-byte keys, not the 44-byte
/// entries (that sort was 3.6% of scenes/forest's cycles, perf, one
/// thread, 1920x1080 flat), in a list kept from walk to walk (a stack
/// array of 64 keys cleared per `settle`, and `sort_unstable`, were some
/// 100 instructions a walk of benches/scenes/forest's union, callgrind).
#[derive(Debug)]
pub(crate) struct PendingList {
    items: Vec<Pending>,
    order: Vec<u64>,
    /// The smallest entry of `items` (`+inf` with none).
    nearest: f32,
}

impl Default for PendingList {
    fn default() -> PendingList {
        PendingList { items: Vec::new(), order: Vec::new(), nearest: f32::INFINITY }
    }
}

impl PendingList {
    fn clear(&mut self) {
        self.items.clear();
        self.order.clear();
        self.nearest = f32::INFINITY;
    }

    /// The smallest entry waiting (`+inf` with none).
    #[inline(always)]
    fn nearest(&self) -> f32 {
        self.nearest
    }

    fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    #[inline(always)]
    fn push(&mut self, p: Pending) {
        self.nearest = self.nearest.min(p.0);
        self.items.push(p);
    }

    /// The places in `items` into `order`, nearest first (by key, then
    /// place).
    fn sort(&mut self) {
        self.order.clear();
        self.order.extend(self.items.iter().enumerate().map(|(i, p)| cand_key(i as u32, p.0)));
        if self.order.len() <= 16 {
            sort_few(&mut self.order);
        } else {
            self.order.sort_unstable();
        }
    }
}

/// A lane's answer: its span list on the union (none or one span), and
/// where it stops being exact.
pub(crate) type LaneFirst = (Option<Span>, f32);

/// Per lane, the nearest span start among the children solved so far and
/// what is needed to check that it is the lane walk's answer.
pub(crate) struct FirstWalk<'a> {
    prog: &'a Program,
    n: usize,
    leaves: &'a LeafTable,
    memo: &'a PacketMemo,
    /// The rays (made SoA only where a leaf is solved here: the packet's
    /// memo mostly solves them, and transposing them for every walk was
    /// some 170 instructions a walk of benches/scenes/forest's union).
    rays: (&'a [glam::Vec3; 8], &'a [glam::Vec3; 8]),
    /// The lanes walked, and those still answered here.
    lanes: u32,
    live: u32,
    tmin: [f32; 8],
    tmax: [f32; 8],
    eps: [f32; 8],
    /// Box entries past this are not solved.
    reach: [f32; 8],
    /// The smallest span start (clipped to the range), its end, surfaces,
    /// and its child's box entry.
    a: [f32; 8],
    b: [f32; 8],
    s0: [Surf; 8],
    s1: [Surf; 8],
    boxt: [f32; 8],
    /// The second smallest span start.
    second: [f32; 8],
    /// Children met and not solved yet, solved nearest first at each
    /// `settle` (a tile's list comes in no particular order: solved as
    /// listed, forest's camera rays solved 38% more leaves).
    pending: &'a mut PendingList,
}

impl<'a> FirstWalk<'a> {
    /// A walk of wide union `n` of `prog` for the lanes `lanes` of rays
    /// `o[k] + t d[k]` on `[tmin[k], tmax[k]]` with tolerances `eps[k]`
    /// (the rays of `memo`'s packet).
    #[inline(always)]
    pub(crate) fn new(
        (prog, n, leaves, memo): (&'a Program, usize, &'a LeafTable, &'a PacketMemo),
        (o, d): (&'a [glam::Vec3; 8], &'a [glam::Vec3; 8]),
        (tmin, tmax, eps): ([f32; 8], [f32; 8], [f32; 8]),
        lanes: u32,
        pending: &'a mut PendingList,
    ) -> Self {
        pending.clear();
        let inf = [f32::INFINITY; 8];
        FirstWalk {
            prog,
            n,
            leaves,
            memo,
            rays: (o, d),
            lanes,
            live: lanes,
            tmin,
            tmax,
            eps,
            reach: tmax,
            a: inf,
            b: inf,
            s0: [Surf::NONE; 8],
            s1: [Surf::NONE; 8],
            boxt: inf,
            second: inf,
            pending,
        }
    }

    /// Per lane, the smallest span start among the children solved
    /// (infinite where none was).
    pub(crate) fn nearest_starts(&self) -> [f32; 8] {
        self.a
    }

    /// Solves what the traversal left pending (it ends with a `settle`,
    /// which solves them: this is for safety), then gives each lane's
    /// answer where the walk settles it.
    // Inlined into the walk, its one caller, as `new`: left to the
    // compiler, both became calls once the crate grew (scenes/forest +0.5%
    // instructions, callgrind 480x270).
    #[inline(always)]
    pub(crate) fn finish(mut self) -> [Option<LaneFirst>; 8] {
        if !self.pending.is_empty() {
            self.solve_pending();
        }
        // All lanes' conditions at once (lane by lane, with `next_up`,
        // they were some 70 instructions a lane on benches/scenes/forest,
        // callgrind). With `e > 0`, `a + 4 e >= next_up(a)` is
        // `a + 4 e > a` (a float past `a` is at least `next_up(a)`), and
        // then `v = max(a + 4 e, next_up(a))` is `a + 4 e`.
        let (mut settled, mut empty) = (0u32, 0u32);
        let mut v = [0.0f32; 8];
        for k in 0..8 {
            let (a, e) = (self.a[k], self.eps[k]);
            let vk = a + 4.0 * e;
            let ok = (vk > a) & (vk < self.tmax[k]) & (self.second[k] > vk + APART * e) & (self.b[k] - a > 2.0 * e) & (self.boxt[k] <= vk);
            settled |= (ok as u32) << k;
            // (A child not sure of its span may still have one.)
            empty |= (((a == f32::INFINITY) & (self.second[k] == f32::INFINITY)) as u32) << k;
            v[k] = vk;
        }
        let on = self.live & self.lanes;
        std::array::from_fn(|k| {
            if on & (1 << k) == 0 {
                None
            } else if empty & (1 << k) != 0 {
                Some((None, f32::INFINITY))
            } else if settled & (1 << k) != 0 {
                Some((Some(self.span(k, v[k])), v[k]))
            } else {
                None
            }
        })
    }

    /// Lane `k`'s span on the union when the walk settles it at `v` (see
    /// the module's notes): its first span, cut at `v`.
    #[inline(always)]
    fn span(&self, k: usize, v: f32) -> Span {
        let (a, b) = (self.a[k], self.b[k]);
        let cut = b > v;
        Span { t0: a, s0: self.s0[k], t1: if cut { v } else { b }, s1: if cut { Surf::NONE } else { self.s1[k] } }
    }

    /// Takes the solve `r` of child leaf `leaf` for the lanes `m`, whose
    /// boxes' entries are `tbox`.
    #[inline(always)]
    fn take(&mut self, leaf: u32, m: u32, r: &Ranges8, tbox: &[f32; 8]) {
        // A lane that the solve left undone goes the walk's way.
        self.live &= !(m & !r.done);
        let mut m = m & r.done;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            counts::wide_child();
            if r.hit & (1 << k) == 0 {
                continue;
            }
            let Clipped { c0, c1, real0, real1 } = Clipped::lane(r, k, (self.tmin[k], self.tmax[k]));
            if !(c1 > c0) {
                continue;
            }
            if !real0 {
                // Inside at the range's start.
                self.live &= !(1 << k);
                continue;
            }
            let s1 = if real1 { Surf::new(leaf, r.s1[k]) } else { Surf::NONE };
            self.put(k, (c0, c1), (Surf::new(leaf, r.s0[k]), s1), tbox[k]);
        }
    }
}

/// How the first-entry walk takes a child node of its union
/// ([`Program::first_take`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Take {
    /// A leaf with an 8-lane kernel, solved for the packet.
    Kernel,
    /// A ring torus: each lane's answer from the packet's preps.
    Torus,
    /// A mesh: each lane's answer from the packet's walk of it.
    Mesh,
    /// A narrow intersection or difference of a few kernel leaves.
    Small,
    /// A small tree of kernel leaves, by its shape.
    Tree,
    /// A node of kernel leaves and tori, swept.
    TorusNode,
    /// A small tree of kernel leaves and tori, by its truth table.
    TorusTree,
    /// No packet path (a sweep, a mesh minus a ball, a larger tree): the
    /// lanes that reach it leave the walk.
    Stop,
}

impl Program {
    /// How the first-entry walk takes child node `c`. Asked by the walk
    /// for each child it solves, and at bake for each wide union's
    /// children: a union none of whose children the walk takes is not
    /// walked ([`Wide::first_walk`](super::Wide::first_walk)).
    #[inline(always)]
    pub(crate) fn first_take(&self, leaves: &LeafTable, c: usize) -> Take {
        match self.kind[c] {
            NodeKind::Leaf => {
                let leaf = self.first[c];
                if leaves.has_kernel8(leaf) {
                    Take::Kernel
                } else if leaves.has_torus_prep(leaf) {
                    Take::Torus
                } else if leaves.is_mesh(leaf) {
                    Take::Mesh
                } else {
                    Take::Stop
                }
            }
            _ if self.small_leafy(c) => Take::Small,
            // (Of several levels, or one of more operands than `take_small`'s.)
            _ if self.is_tree(c) => Take::Tree,
            _ if self.torus_node(leaves, c) => Take::TorusNode,
            _ if self.is_torus_tree(leaves, c) => Take::TorusTree,
            _ => Take::Stop,
        }
    }

    /// Has child node `c` a path in the first-entry walk ([`Program::first_take`])?
    #[inline]
    pub(crate) fn first_walk_takes(&self, leaves: &LeafTable, c: usize) -> bool {
        self.first_take(leaves, c) != Take::Stop
    }
}

impl Visit8 for FirstWalk<'_> {
    #[inline(always)]
    fn visit(&mut self, pos: u32, lanes: u32, rays: &Lanes8) {
        let c = self.prog.child_at(self.n, pos);
        self.visit_box(pos, &self.prog.bounds[c as usize], lanes, rays)
    }

    #[inline(always)]
    fn visit_box(&mut self, pos: u32, b: &Aabb, lanes: u32, rays: &Lanes8) {
        let (hit, tbox) = rays.ray_range(b, &self.tmin, &self.reach);
        let m = hit & lanes & self.live;
        if m != 0 {
            self.pending.push((masked_min(m, &tbox), pos, m, tbox));
        }
    }

    #[inline(always)]
    fn bounds(&self) -> (f32, f32) {
        (masked_max(self.live, &self.reach), self.pending.nearest())
    }

    #[inline(always)]
    fn settle(&mut self, _lower: f32, thi: &mut [f32; 8]) {
        if !self.pending.is_empty() {
            self.solve_pending();
        }
        for k in 0..8 {
            thi[k] = thi[k].min(self.reach[k]);
        }
    }
}

impl FirstWalk<'_> {
    /// Solves the children met since the last `settle`, nearest box first,
    /// for the lanes whose reach their box entry is still within.
    #[inline(never)]
    fn solve_pending(&mut self) {
        let mut pending = std::mem::take(self.pending);
        // Nearest first, by their keys (see `PendingList`). Ties stay in
        // the order met: a settled lane's answer does not depend on the
        // order anyway (see the module's notes).
        pending.sort();
        for &key in &pending.order {
            let (_, pos, m, tbox) = pending.items[key as u32 as usize];
            let m = m & self.live & le_mask(&tbox, &self.reach);
            if m == 0 {
                continue;
            }
            let c = self.prog.child_at(self.n, pos) as usize;
            match self.prog.first_take(self.leaves, c) {
                Take::Kernel => {
                    let leaf = self.prog.first[c];
                    let (memo, leaves) = (self.memo, self.leaves);
                    let solved = memo.with_solve::<true, _>(leaves, leaf, |r| self.take(leaf, m, r, &tbox));
                    if solved.is_none() {
                        let r = self.solve_here(leaf);
                        self.take(leaf, m, &r, &tbox);
                    }
                }
                Take::Torus => self.take_leaf_lanes::<false>(self.prog.first[c], m, &tbox),
                Take::Mesh => self.take_leaf_lanes::<true>(self.prog.first[c], m, &tbox),
                Take::Small => self.take_small(c, m, &tbox),
                Take::Tree => self.take_tree(pos, c, m, &tbox),
                Take::TorusNode => self.take_torus_node(c, m, &tbox),
                Take::TorusTree => self.take_torus_tree(c, m, &tbox),
                Take::Stop => self.leave(m),
            }
        }
        pending.clear();
        *self.pending = pending;
    }

    /// The lanes `m` are not answered here (a child without a packet
    /// path lies within their reach): they leave the walk, and the others
    /// go on. (The whole walk used to end there: a union of 200 balls and
    /// 40 knob meshes each minus a ball settled 2% of its lanes.)
    fn leave(&mut self, m: u32) {
        self.live &= !m;
    }

    /// Kernel leaf `leaf` solved here for the live lanes (the packet's memo
    /// solves no leaves).
    #[inline(never)]
    fn solve_here(&mut self, leaf: u32) -> Ranges8 {
        counts::leaf_solve();
        let mut r = Ranges8::default();
        self.leaves.ranges8_beside(leaf, &Rays8Soa::new(self.rays.0, self.rays.1), self.live, &mut r);
        r
    }

    /// Takes child leaf `leaf`, a ring torus (no 8-lane solve) or a mesh
    /// (`MESH`), for the lanes `m` whose box entries are `tbox`: each
    /// lane's nearest query on its whole range, the answer its lane walk
    /// reads, from the packet's preps ([`PacketMemo::torus_lane`]) or its
    /// walk of the mesh ([`PacketMemo::nearest_lane`], clipped to a shorter
    /// range), taken by `take_answer`. A lane the packet does not answer is
    /// left to its walk. Why: one torus among a union's children stopped
    /// the walk for every lane (a forest whose trunks were rings: 4.0x
    /// POV-Ray's speed flat, against 5.9x for the forest), and a mesh did
    /// (60 knob meshes in a union: each lane walked the children in order,
    /// 4.5x flat).
    #[inline(never)]
    fn take_leaf_lanes<const MESH: bool>(&mut self, leaf: u32, m: u32, tbox: &[f32; 8]) {
        let (memo, leaves) = (self.memo, self.leaves);
        if !MESH {
            self.take_lanes::<false>(m, tbox, |k, range, _, spans| memo.torus_lane(leaves, leaf, k, (range, true), spans));
        } else if let Some((w, at)) = memo.mesh_walk(leaves, leaf) {
            // The packet's walk, looked up once for all the lanes (per
            // lane, in the loop, knob_union read 0.7% more instructions).
            self.take_lanes::<true>(m, tbox, |k, range, slack, spans| w.serve_lane(at, (k, range), slack, spans));
        } else {
            // (A mesh walked ahead for every packet.)
            self.take_lanes::<true>(m, tbox, |k, range, slack, spans| memo.nearest_lane(leaves, leaf, (k, range), slack, spans));
        }
    }

    /// [`FirstWalk::take_leaf_lanes`]'s loop over the lanes `m`, each
    /// lane's answer on its whole range (with its nearest-mode slack) from
    /// `answer`.
    #[inline(always)]
    fn take_lanes<const MESH: bool>(
        &mut self,
        m: u32,
        tbox: &[f32; 8],
        mut answer: impl FnMut(usize, (f32, f32), f32, &mut FirstSpans) -> Option<f32>,
    ) {
        let mut m = m;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            counts::wide_child();
            let mut spans = FirstSpans::default();
            let v = answer(k, (self.tmin[k], self.tmax[k]), RayCtx::nearest_slack_of(self.eps[k]), &mut spans);
            self.take_answer(k, v, &spans, (tbox[k], MESH));
        }
    }

    /// Takes lane `k`'s nearest-mode answer of a leaf child on its whole
    /// range, exact up to `v` (`None`: the packet does not answer; the lane
    /// is left to its walk), whose box entry is `tbox`; a lane starting
    /// inside the leaf is left to its walk, and later spans bound the
    /// second start. For a torus, the first span counts only where it is
    /// longer than `8 eps` (as a small tree's, [`FirstWalk::take_first`]):
    /// then its entry is the one polished root a shorter range's query
    /// gives too, and a settled lane's answer is that entry cut at `v` (its
    /// exit never read); a short first span (which the lane's walk may ask
    /// again in full, `leaf_asks_again`) and the place the answer stops
    /// being exact (the next span may start there) bound the second start,
    /// so no lane settles where the torus might come first or fuse
    /// (margins: a nearest query's later span, or its stop, lies past its
    /// first span's exit). A mesh's answer stops at `v_m`, `4 eps` past its
    /// first crossing (`MeshData::spans_nearest`): its first span `[a_m,
    /// v_m]` is cut there, where a lane's walk that takes it first is cut
    /// too (`stop_at_first_entry`: the same `a + 4 eps`), so `v_m` bounds
    /// the second start only where it comes earlier; no `8 eps` rule (a
    /// shorter range's answer is the same record clipped; a short first
    /// span settles no lane, `FirstWalk::finish`).
    #[inline(always)]
    fn take_answer(&mut self, k: usize, v: Option<f32>, spans: &FirstSpans, (tbox, mesh): (f32, bool)) {
        let Some(v) = v else {
            self.live &= !(1 << k);
            return;
        };
        let eps = self.eps[k];
        let Some(first) = spans.first else {
            self.second[k] = self.second[k].min(v);
            return;
        };
        if !first.s0.is_real() {
            // Inside at the range's start.
            self.live &= !(1 << k);
            return;
        }
        self.second[k] = self.second[k].min(spans.rest);
        if mesh {
            if v < entry_stop(first.t0, eps) {
                self.second[k] = self.second[k].min(v);
            }
            self.put(k, (first.t0, first.t1), (first.s0, first.s1), tbox);
        } else if first.t1 - first.t0 > 8.0 * eps {
            self.second[k] = self.second[k].min(v);
            self.put(k, (first.t0, first.t1), (first.s0, first.s1), tbox);
        } else {
            self.second[k] = self.second[k].min(v).min(first.t0);
        }
    }

    /// Takes child `c`, a node of kernel leaves and ring tori
    /// ([`Program::torus_node`]: a ring cut by a half-space, a torus minus
    /// a ball), for the lanes `m` whose box entries
    /// are `tbox`: each lane's first span as an object of that node gets it
    /// (`torus_sweep.rs`: swept as [`small_first`] sweeps,
    /// from the kernel leaves' solves and each lane's nearest queries of
    /// the tori), taken as a small tree's. A lane outside the packet's
    /// solves is left to its walk. Why: such a child stopped the walk for
    /// every lane (a forest whose trunks were arches, a ring cut by a
    /// half-space: 3.2x POV-Ray's speed flat).
    #[inline(never)]
    fn take_torus_node(&mut self, c: usize, m: u32, tbox: &[f32; 8]) {
        let (memo, leaves) = (self.memo, self.leaves);
        let Some((ops, tori)) = memo.torus_node_ops::<true>(self.prog, leaves, c) else {
            self.live &= !m;
            return;
        };
        let node = torus_operands(&ops, tori);
        self.take_swept((m, ops.done), tbox, |k, lo_eps| node.first(memo, leaves, k, lo_eps));
    }

    /// Takes the lanes of `m` that the solves `done` did, each with its
    /// first span `first(k, (tmin, eps))` of a child whose box entries are
    /// `tbox`; the others (and those outside the packet's solves) go the
    /// walk's way.
    #[inline(always)]
    fn take_swept(&mut self, (m, done): (u32, u32), tbox: &[f32; 8], first: impl Fn(usize, (f32, f32)) -> SmallFirst) {
        let mut lanes = m & done & self.memo.packet_lanes();
        self.live &= !(m & !lanes);
        while lanes != 0 {
            let k = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            counts::wide_child();
            let f = first(k, (self.tmin[k], self.eps[k]));
            self.take_first(k, f, tbox);
        }
    }

    /// Takes child `c`, a tree of several levels of kernel leaves and ring
    /// tori ([`Program::is_torus_tree`]), for the lanes `m` whose box
    /// entries are `tbox`: each lane's first span swept by the tree's truth
    /// table (`torus_sweep.rs`), taken as a small tree's. A lane outside
    /// the packet's solves is left to its walk.
    #[inline(never)]
    fn take_torus_tree(&mut self, c: usize, m: u32, tbox: &[f32; 8]) {
        let (memo, leaves) = (self.memo, self.leaves);
        let Some(tt) = memo.torus_tree::<true>(self.prog, leaves, c) else {
            self.live &= !m;
            return;
        };
        let ops = tt.operands();
        self.take_swept((m, tt.done), tbox, |k, lo_eps| ops.first(memo, leaves, k, lo_eps));
    }

    /// Takes child `c`, an intersection or difference of a few kernel
    /// leaves ([`Program::small_leafy`]), for the lanes `m` whose box
    /// entries are `tbox`, from its operands' solves ([`small_first`]).
    /// (Two operands, the common child, in arrays of two: a third less
    /// work per child on forest_cut, whose trees all have two.)
    #[inline(never)]
    fn take_small(&mut self, c: usize, m: u32, tbox: &[f32; 8]) {
        if self.prog.count[c] == 2 {
            self.take_small2(c, m, tbox)
        } else {
            self.take_small_n::<SMALL_OPS, { 2 * SMALL_OPS }>(c, m, tbox)
        }
    }

    /// [`FirstWalk::take_small`] for two operands: all lanes at once
    /// ([`small_first8`]) on the solves where the packet's memo keeps them,
    /// a lane with a NaN end as `take_small_n`'s.
    #[inline(always)]
    fn take_small2(&mut self, c: usize, m: u32, tbox: &[f32; 8]) {
        let (prog, memo, leaves) = (self.prog, self.memo, self.leaves);
        let first = prog.first[c] as usize;
        let leaf = [0, 1].map(|j| prog.first[prog.children[first + j] as usize]);
        let kind = prog.kind[c];
        if !self.two_may_meet(kind, leaf, m) {
            return;
        }
        let taken =
            memo.with_solves2::<true, _>(leaves, (leaf[0], leaf[1]), |r0, r1| self.take_two(&Two { kind, leaf, r: [r0, r1] }, m, tbox));
        if taken.is_none() {
            let mut ops = SmallOps::<2>::of(prog, c);
            ops.gather(prog, c, |leaf| Some(self.solve_here(leaf)));
            self.take_two(&Two::of(&ops), m, tbox);
        }
    }

    /// May the intersection or difference `kind` of leaves `leaf` be
    /// non-empty on some lane of `m`? One operand solved first (a
    /// difference's positive one; an intersection's first but a box or
    /// half-space): where no lane of `m` meets it (and the solve did them
    /// all), the other is not solved ([`FirstWalk::tree_may_meet`]'s
    /// argument).
    #[inline(always)]
    fn two_may_meet(&self, kind: NodeKind, leaf: [u32; 2], m: u32) -> bool {
        let leaves = self.leaves;
        let late = |i: u32| solved_late(leaves, i);
        let gate = match kind {
            NodeKind::Difference => leaf[0],
            NodeKind::Intersection if late(leaf[0]) && !late(leaf[1]) => leaf[1],
            NodeKind::Intersection => leaf[0],
            _ => return true,
        };
        let met = self.memo.with_solve::<true, _>(leaves, gate, |r| r.hit | !r.done);
        met.is_none_or(|h| m & h != 0)
    }

    /// [`FirstWalk::take_small2`] of the node `ops`.
    #[inline(always)]
    fn take_two(&mut self, ops: &Two, m: u32, tbox: &[f32; 8]) {
        let lanes = m & ops.r[0].done & ops.r[1].done;
        // A lane that a solve left undone goes the walk's way.
        self.live &= !(m & !lanes);
        counts::wide_children(lanes.count_ones());
        // An intersection is empty on a lane that misses an operand, a
        // difference on one that misses its positive operand: with no lane
        // left, nothing to take (`small_first8` would find every lane empty).
        let met = match ops.kind {
            NodeKind::Intersection => ops.r[0].hit & ops.r[1].hit,
            NodeKind::Difference => ops.r[0].hit,
            _ => u32::MAX,
        };
        if lanes & met == 0 {
            return;
        }
        let f = small_first8(ops, lanes, &Ranges { lo: &self.tmin, hi: &self.tmax, eps: &self.eps });
        self.live &= !f.kill;
        self.put8(&f, tbox);
        let mut odd = f.odd;
        if odd != 0 {
            let ops = SmallOps::<2> { kind: ops.kind, count: 2, leaf: ops.leaf, r: [*ops.r[0], *ops.r[1]], done: lanes };
            while odd != 0 {
                let k = odd.trailing_zeros() as usize;
                odd &= odd - 1;
                self.take_small_lane::<2, 4>(&ops, k, tbox);
            }
        }
    }

    /// [`FirstWalk::put`] of the spans of `f` on its lanes `f.span`, and
    /// its bounds `f.next` on every lane, without a branch per lane.
    #[inline(always)]
    fn put8(&mut self, f: &First8, tbox: &[f32; 8]) {
        let min = |x: f32, y: f32| if y < x { y } else { x };
        for k in 0..8 {
            let p = f.span & (1 << k) != 0;
            let repl = p & (f.t0[k] < self.a[k]);
            let lost = if repl {
                self.a[k]
            } else if p {
                f.t0[k]
            } else {
                f32::INFINITY
            };
            self.second[k] = min(min(self.second[k], lost), f.next[k]);
            self.a[k] = if repl { f.t0[k] } else { self.a[k] };
            self.b[k] = if repl { f.t1[k] } else { self.b[k] };
            self.s0[k] = if repl { f.s0[k] } else { self.s0[k] };
            self.s1[k] = if repl { f.s1[k] } else { self.s1[k] };
            self.boxt[k] = if repl { tbox[k] } else { self.boxt[k] };
            let r = f.t0[k] + PRUNE * self.eps[k];
            self.reach[k] = if repl { min(self.reach[k], r) } else { self.reach[k] };
        }
    }

    /// [`FirstWalk::take_small`] for at most `N` operands (`E = 2 N`).
    #[inline(always)]
    fn take_small_n<const N: usize, const E: usize>(&mut self, c: usize, m: u32, tbox: &[f32; 8]) {
        let (prog, memo, leaves) = (self.prog, self.memo, self.leaves);
        let mut ops = SmallOps::<N>::of(prog, c);
        ops.gather(prog, c, |leaf| Some(memo.with_solve::<true, _>(leaves, leaf, |r| *r).unwrap_or_else(|| self.solve_here(leaf))));
        let mut lanes = m & ops.done;
        // A lane that a solve left undone goes the walk's way.
        self.live &= !(m & !lanes);
        while lanes != 0 {
            let k = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            counts::wide_child();
            self.take_small_lane::<N, E>(&ops, k, tbox);
        }
    }

    /// Takes child `c` (at position `pos`), a small tree of several levels,
    /// or of one of more than [`SMALL_OPS`] operands ([`Program::is_tree`]),
    /// for the lanes `m` whose box entries are `tbox`, from its leaves'
    /// solves ([`tree_first`]), by its shape made at bake. (A forest whose
    /// trees are two levels deep, a ball cut by a half-space minus a notch,
    /// had every lane leave the walk: 2.8 times forest_cut's time.)
    #[inline(never)]
    fn take_tree(&mut self, pos: u32, c: usize, m: u32, tbox: &[f32; 8]) {
        let Some(t) = self.prog.wide_of(self.n).trees.get(self.prog, pos, c) else {
            self.leave(m);
            return;
        };
        let (memo, leaves) = (self.memo, self.leaves);
        if !self.tree_may_meet(&t, m) {
            return;
        }
        let taken = memo.with_solves_n::<true, _>(leaves, &t.leaf[..t.count], |r| self.take_tree_solved(&t, r, m, tbox));
        if taken.is_none() {
            let mut solves = [Ranges8::default(); TREE_LEAVES];
            for (r, &leaf) in solves.iter_mut().zip(&t.leaf[..t.count]) {
                *r = self.solve_here(leaf);
            }
            let r: [&Ranges8; TREE_LEAVES] = std::array::from_fn(|j| &solves[j]);
            self.take_tree_solved(&t, &r[..t.count], m, tbox);
        }
    }

    /// May tree `t` be non-empty on some lane of `m`? Its leaves solved
    /// one by one from the packet's memo, in the order made at bake
    /// ([`TreeShape::with_order`]: boxes and half-spaces last), all but the
    /// last, until no lane can meet every leaf of a set inside the tree
    /// ([`TreeShape::lanes_meeting`]; a lane a solve left undone may). Then
    /// the others are not solved: the tree is empty on every lane of `m`
    /// that the solves did, and a lane walk finds it empty too. Why: on
    /// benches/scenes/forest_deep a packet that met a tree's box mostly
    /// missed its ball or trunk, and its three leaves were solved all the
    /// same.
    #[inline(always)]
    fn tree_may_meet(&self, t: &TreeShape, m: u32) -> bool {
        if !t.filters() {
            return true;
        }
        let (memo, leaves) = (self.memo, self.leaves);
        let mut hit = [u32::MAX; TREE_LEAVES];
        for s in 0..t.count - 1 {
            let j = t.solve_order(s);
            let Some(h) = memo.with_solve::<true, _>(leaves, t.leaf[j], |r| r.hit | !r.done) else { return true };
            hit[j] = h;
            if m & t.lanes_meeting(|j| hit[j]) == 0 {
                return false;
            }
        }
        true
    }

    /// [`FirstWalk::take_tree`] of the tree `t` whose leaves' solves are `r`.
    #[inline(always)]
    fn take_tree_solved(&mut self, t: &TreeShape, r: &[&Ranges8], m: u32, tbox: &[f32; 8]) {
        let lanes = m & done_by(r);
        // A lane that a solve left undone goes the walk's way.
        self.live &= !(m & !lanes);
        // Lane by lane: a tree child is mostly met by a few lanes, for which
        // the 8-lane sweep (`tree_first8`) cost more (forest_deep 480x270
        // flat, callgrind: +1.3% instructions when 6 lanes or more took it,
        // +4.1% when all did).
        // (A lane on which the tree is empty would take nothing.)
        let mut m = t.maybe_met(r, lanes);
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            counts::wide_child();
            let first = tree_first(t, r, k, (self.tmin[k], self.eps[k]));
            self.take_first(k, first, tbox);
        }
    }

    /// Lane `k` of [`FirstWalk::take_small_n`].
    #[inline(always)]
    fn take_small_lane<const N: usize, const E: usize>(&mut self, ops: &SmallOps<N>, k: usize, tbox: &[f32; 8]) {
        let first = small_first::<N, E>(ops, k, (self.tmin[k], self.eps[k]));
        self.take_first(k, first, tbox);
    }

    /// Lane `k`'s first span `first` of a child whose box entries are `tbox`.
    #[inline(always)]
    fn take_first(&mut self, k: usize, first: SmallFirst, tbox: &[f32; 8]) {
        let (lo, hi) = (self.tmin[k], self.tmax[k]);
        let first = match first {
            // A span no longer than 8 eps: the lane's cut at `v` might
            // not reach past its exit (see `small_first`).
            SmallFirst::Span { t: (t0, t1), .. } if !(t1 - t0 > 8.0 * self.eps[k]) => SmallFirst::From(t0),
            f => f,
        };
        match first {
            SmallFirst::Empty => {}
            SmallFirst::Inside => self.live &= !(1 << k),
            SmallFirst::From(t) => {
                if t < lo {
                    self.live &= !(1 << k);
                } else {
                    self.second[k] = self.second[k].min(t);
                }
            }
            SmallFirst::Span { t: (t0, t1), s: (s0, s1), next } => {
                if t0 >= hi {
                    return;
                }
                let real1 = t1 <= hi && t1.is_finite();
                let c1 = if real1 { t1 } else { t1.min(hi) };
                self.put(k, (t0, c1), (s0, if real1 { s1 } else { Surf::NONE }), tbox[k]);
                self.second[k] = self.second[k].min(next);
            }
        }
    }

    /// Lane `k`'s child span `t = (start, end)` (clipped to the range, the
    /// start a real entry), `s` its surfaces, `tbox` its box entry.
    #[inline(always)]
    fn put(&mut self, k: usize, (c0, c1): (f32, f32), (s0, s1): (Surf, Surf), tbox: f32) {
        if c0 < self.a[k] {
            // (`second` may hold a child's bound below `a`: see `take_small`.)
            self.second[k] = self.second[k].min(self.a[k]);
            self.a[k] = c0;
            self.b[k] = c1;
            self.s0[k] = s0;
            self.s1[k] = s1;
            self.boxt[k] = tbox;
            self.reach[k] = self.reach[k].min(c0 + PRUNE * self.eps[k]);
        } else {
            self.second[k] = self.second[k].min(c0);
        }
    }
}

/// A leaf's first span on a lane's range and the smallest start of its
/// later spans (`+inf` with none): all a union's first-entry walk reads of
/// a torus's or a mesh's answer.
struct FirstSpans {
    first: Option<Span>,
    rest: f32,
}

impl Default for FirstSpans {
    fn default() -> Self {
        FirstSpans { first: None, rest: f32::INFINITY }
    }
}

impl SpanSink for FirstSpans {
    #[inline(always)]
    fn push_span(&mut self, s: Span) {
        if self.first.is_none() {
            self.first = Some(s);
        } else {
            self.rest = self.rest.min(s.t0);
        }
    }
}

/// The most operands of a child that [`FirstWalk::take_small`] takes.
pub(crate) const SMALL_OPS: usize = 4;

#[cfg(test)]
mod tests {
    use super::super::cand_key;

    /// `cand_key`'s order (by which the walk sorts its pending children)
    /// is `f32::total_cmp`'s, then the place (zeros, infinities,
    /// subnormals, NaNs of both signs included).
    #[test]
    fn cand_keys_order_as_total_cmp() {
        let mut xs =
            vec![0.0f32, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, 1e-45, -1e-45, f32::MAX, f32::MIN];
        let mut s = 0x9e3779b9u32;
        for _ in 0..2000 {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            xs.push(f32::from_bits(s));
        }
        for (i, &a) in xs.iter().enumerate() {
            for (j, &b) in xs.iter().enumerate().step_by(7) {
                let want = a.total_cmp(&b).then(i.cmp(&j));
                assert_eq!(
                    cand_key(i as u32, a).cmp(&cand_key(j as u32, b)),
                    want,
                    "{a:e} ({:#x}) against {b:e} ({:#x})",
                    a.to_bits(),
                    b.to_bits()
                );
            }
        }
    }
}
