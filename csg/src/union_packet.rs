//! Wide leaf unions walked once per packet of eight rays: the node's tree
//! ([`BoxWide`](rothray_primitives::box_wide::BoxWide)) is walked for all
//! lanes at once to list each lane's children along its ray; each lane
//! then visits them exactly as its own evaluation ([`Program::leaf_union`])
//! would, in the same canonical order and with its own range. A union is
//! walked when the first lane's evaluation asks for it (a union no lane
//! reaches, behind a nearer object or past a shadow ray's first occluder,
//! costs nothing), for every lane on its whole range; the results wait in
//! the packet's memo, where each lane's evaluation finds them when it asks
//! for the range recorded ([`PacketMemo::union_lane`]).
//!
//! Why: in a union of thousands of small leaves (a forest), camera rays
//! spend most of their time walking the node's tree, and the neighbouring
//! rays of a packet walk mostly the same nodes.
//!
//! A union of analytic leaves is first walked for the lanes' first entries
//! alone (`union_first.rs`): the lanes whose first entry stands clear of
//! every other child's are recorded from it, and only the others visit
//! their children in the canonical order here. A union of small trees
//! ([`Program::is_meet_union`]) is walked for first entries only: the
//! lanes that walk leaves unsettled evaluate it themselves.

use glam::Vec4;
use rothray_primitives::{
    box_wide::{forms_packet, BoxWide, Lanes8, Rays8, Visit8},
    mask8::fill_lanes,
    Aabb, LeafTable, Ray, Span,
};

use super::union_first::{FirstWalk, LaneFirst, PendingList};
use super::{cand_key, cand_of_key, counts, Ask, MemoLeaf, Mode, NodeKind, PacketMemo, Program, RayCtx, UnionLane};
use crate::spans::SpanList;

/// The wide unions walked for the current packet, and what walking one more
/// needs: the packet's rays, and scratch memory reused from packet to packet.
#[derive(Debug, Default)]
pub(crate) struct UnionRecords {
    /// The packet's lanes that take part (0: no packet, nothing is walked).
    lanes: u32,
    rays: Vec<(Ray, f32)>,
    /// Records by node (`leaf` holds the node id), `len` in use.
    recs: Vec<MemoLeaf>,
    len: usize,
    accs: Vec<SpanList>,
    cands: Vec<Vec<u64>>,
    leaf: SpanList,
    tmp: SpanList,
    /// The tile list's children a packet can meet (`TileList::for_rays`).
    met: Vec<u32>,
    /// The first-entry walk's children waiting for their solves.
    pending: PendingList,
}

impl UnionRecords {
    pub(crate) fn clear(&mut self) {
        self.lanes = 0;
        self.len = 0;
    }
}

impl PacketMemo {
    /// Lets the evaluations of the packet of `rays` with tolerances `eps`
    /// (the contexts its lanes evaluate with; its lanes `lanes`, which must
    /// share a direction octant) walk wide leaf unions together: the first
    /// lane to ask for one walks it for all of them.
    pub fn walk_unions_for(&mut self, (rays, eps): (&[Ray; 8], &[f32; 8]), lanes: u32) {
        let u = self.unions.get_mut();
        u.len = 0;
        u.lanes = if forms_packet(&rays.each_ref().map(|r| r.dir)) { lanes } else { 0 };
        u.rays.clear();
        u.rays.extend(rays.iter().zip(eps).map(|(r, &e)| (*r, e)));
    }

    /// Lane `k`'s result of wide leaf union `n` of `prog` in nearest mode on
    /// `range` (appended to `out`) and where it stops being exact, from the
    /// packet's walk of the union (made now if no lane asked before), when
    /// its record answers that query exactly as the lane's own walk would:
    /// the record starts at the range's start, covers its end, and either
    /// became exact-limited before that end (at its first confirmed entry:
    /// the walk on the shorter range confirms the same one, the canonical
    /// order being the same) or found nothing at all. (Inlined into its two
    /// callers: left to the compiler, the second caller made it a call in
    /// the wide union's loop, +0.8% instructions on scenes/forest.)
    #[inline(always)]
    pub(crate) fn union_lane(
        &self,
        prog: &Program,
        leaves: &LeafTable,
        n: u32,
        (k, range): (usize, (f32, f32)),
        out: &mut SpanList,
    ) -> Option<f32> {
        let mut u = self.unions.borrow_mut();
        if u.lanes & (1 << k) == 0 || !prog.walks_in_packets(n) {
            return None;
        }
        let i = u.record_of(self, prog, leaves, n);
        let (spans, v) = lane_answer(&u.recs[i], k, range)?;
        out.append(spans);
        Some(v)
    }

    /// [`PacketMemo::union_lane`] for every lane `k` of `lanes` on
    /// `(tmin[k], tmax[k])`, with one look-up of the record: `f(k, Some((spans,
    /// v)))` where `union_lane` would append `spans` and return `Some(v)`,
    /// `f(k, None)` where it would return `None`. (Lane by lane, the look-ups
    /// and copies were most of the packets' picks of union roots, perf.)
    #[inline(always)]
    pub fn union_lanes(
        &self,
        (prog, leaves): (&Program, &LeafTable),
        n: u32,
        (lanes, tmin, tmax): (u32, &[f32; 8], &[f32; 8]),
        mut f: impl FnMut(usize, Option<(&[Span], f32)>),
    ) {
        let mut u = self.unions.borrow_mut();
        let walked = lanes & u.lanes;
        let i = (walked != 0 && prog.walks_in_packets(n)).then(|| u.record_of(self, prog, leaves, n));
        for k in 0..8 {
            if lanes & (1 << k) != 0 {
                let rec = i.filter(|_| walked & (1 << k) != 0).and_then(|i| lane_answer(&u.recs[i], k, (tmin[k], tmax[k])));
                f(k, rec);
            }
        }
    }
}

/// Lane `k`'s answer from union record `e` for a nearest query on `(lo,
/// hi)`, counted: its spans and where they stop being exact, when the
/// record answers that query exactly as the lane's own walk would (see
/// [`PacketMemo::union_lane`]).
#[inline(always)]
fn lane_answer(e: &MemoLeaf, k: usize, (lo, hi): (f32, f32)) -> Option<(&[Span], f32)> {
    let (v, spans) = (e.valid[k], e.spans[k].as_slice());
    let ok = e.done & (1 << k) != 0 && lo == e.tmin[k] && hi <= e.tmax[k] && (v <= hi || (spans.is_empty() && v == f32::INFINITY));
    counts::packet_lane(ok);
    ok.then_some((spans, v))
}

impl UnionRecords {
    /// The place of the packet's record of wide union `n` of `prog`, walked
    /// now when no lane asked for it before.
    #[inline(always)]
    fn record_of(&mut self, memo: &PacketMemo, prog: &Program, leaves: &LeafTable, n: u32) -> usize {
        match self.recs[..self.len].iter().position(|e| e.leaf == n) {
            Some(i) => i,
            None => self.walk(memo, prog, leaves, n),
        }
    }

    /// Walks wide leaf union `n` of `prog` in nearest mode for the packet's
    /// lanes, each on its ray's whole range, into a new record; returns its
    /// place.
    ///
    /// (The lanes' leaf queries going through the packet's solves,
    /// `PacketMemo::leaf_lane`, saved scenes/forest 0.3% of its instructions
    /// and cost scenes/nesting 1%: `leaf_lane` was no longer inlined where
    /// the evaluator calls it.)
    fn walk(&mut self, memo: &PacketMemo, prog: &Program, leaves: &LeafTable, n: u32) -> usize {
        let nu = n as usize;
        let lanes = self.lanes;
        // (Filled in place: see `fill_lanes`.)
        let (mut o, mut d) = ([glam::Vec3::ZERO; 8], [glam::Vec3::ZERO; 8]);
        let (mut tmin, mut tmax) = ([0.0f32; 8], [0.0f32; 8]);
        fill_lanes(&mut o, |k| self.rays[k].0.origin);
        fill_lanes(&mut d, |k| self.rays[k].0.dir);
        fill_lanes(&mut tmin, |k| self.rays[k].0.tmin);
        fill_lanes(&mut tmax, |k| self.rays[k].0.tmax);
        let rays = Rays8 { o: &o, d: &d, tmin: &tmin };
        // The lanes whose first entry stands clear of every other child's
        // are answered at once (`union_first.rs`); the others walk.
        let mut first: [Option<LaneFirst>; 8] = [None; 8];
        let mut starts = [f32::INFINITY; 8];
        let w = prog.wide_of(nu);
        if w.unbounded.is_empty() && w.first_walk {
            let mut eps = [0.0f32; 8];
            fill_lanes(&mut eps, |k| self.rays[k].1);
            let mut fw = FirstWalk::new((prog, nu, leaves, memo), (&o, &d), (tmin, tmax, eps), lanes, &mut self.pending);
            let mut thi = tmax;
            traverse(prog, nu, (&rays, lanes, &mut thi), &mut self.met, &mut fw);
            starts = fw.nearest_starts();
            first = fw.finish();
        }
        let mut answered = 0u32;
        for (k, f) in first.iter().enumerate() {
            answered |= (f.is_some() as u32) << k;
        }
        // A union of subtrees answers only the lanes its first-entry walk
        // settles (its lane walks take leaves only); the others evaluate it
        // themselves.
        let walked = if prog.leafy[nu] { lanes & !answered } else { 0 };
        counts::first_entries(answered.count_ones(), walked.count_ones());
        let (valid, walk_starts) = if walked != 0 {
            self.walk_in_order(memo, (prog, nu, leaves), &rays, walked)
        } else {
            ([f32::INFINITY; 8], [f32::INFINITY; 8])
        };
        if self.recs.len() == self.len {
            self.recs.push(MemoLeaf::default());
        }
        let e = &mut self.recs[self.len];
        let mut unsure = 0u32;
        for k in 0..8 {
            e.spans[k].clear();
            e.valid[k] = valid[k];
            if let Some((span, v)) = first[k] {
                e.spans[k].extend(span);
                e.valid[k] = v;
            } else if walked & (1 << k) != 0 {
                let acc = self.accs[k].as_slice();
                e.spans[k].extend_from_slice(acc);
                // A child's span that starts before the result's first one
                // was dropped by a later child (`combine` drops a span no
                // longer than eps when another operand has spans on the
                // range): on a range cut before that later child, as an
                // object's query is cut at a nearer object's answer, it
                // stays. Such a lane's record answers only its own range:
                // left to the lane (its query on its range is its own).
                // The children's spans are those the first-entry walk
                // solved and those the in-order walk visited (seed 0x3e40
                // of the walk test: a union with a half-space among its
                // children, which the first-entry walk does not take).
                let first_start = acc.first().map_or(f32::INFINITY, |s| s.t0);
                if starts[k].min(walk_starts[k]) < first_start {
                    unsure |= 1 << k;
                }
            }
        }
        (e.leaf, e.done, e.tmin, e.tmax) = (n, (answered | walked) & !unsure, tmin, tmax);
        self.len += 1;
        self.len - 1
    }

    /// Walks wide leaf union `n` of `prog` for the lanes `walked` of the
    /// packet, each visiting the children along its ray in the canonical
    /// order, into `accs`; returns where each lane's result stops being
    /// exact, and the smallest start of a child's span each lane visited.
    fn walk_in_order(
        &mut self,
        memo: &PacketMemo,
        (prog, n, leaves): (&Program, usize, &LeafTable),
        rays: &Rays8,
        walked: u32,
    ) -> ([f32; 8], [f32; 8]) {
        let w = prog.wide_of(n);
        let ctx: [RayCtx; 8] = std::array::from_fn(|k| RayCtx { ray: self.rays[k].0, eps: self.rays[k].1, memo: Some((memo, k)) });
        let tmin = *rays.tmin;
        let tmax: [f32; 8] = std::array::from_fn(|k| ctx[k].ray.tmax);
        self.accs.resize_with(8, SpanList::new);
        self.cands.resize_with(8, Vec::new);
        let mut walk = LaneWalks {
            prog,
            n,
            leaves,
            ctx: &ctx,
            lanes: walked,
            st: std::array::from_fn(|k| UnionLane { hi: tmax[k], valid: f32::INFINITY }),
            first: [f32::INFINITY; 8],
            tmin,
            tmax,
            cands: &mut self.cands,
            accs: &mut self.accs,
            lists: (&mut self.leaf, &mut self.tmp),
            starts: [f32::INFINITY; 8],
        };
        for k in 0..8 {
            walk.accs[k].clear();
            walk.cands[k].clear();
            if walked & (1 << k) != 0 && !w.unbounded.is_empty() {
                walk.cands[k].extend(w.unbounded.iter().map(|&pos| cand_key(pos, tmin[k])));
                walk.first[k] = tmin[k];
            }
        }
        let mut thi = tmax;
        traverse(prog, n, (rays, walked, &mut thi), &mut self.met, &mut walk);
        (walk.st.map(|s| s.valid), walk.starts)
    }
}

/// Walks the children of wide union `n` of `prog` whose boxes the lanes
/// `lanes` of `rays` meet (on ranges ending at `thi`) with `v`: through the
/// tile's list when it made one and the lanes' rays are its own (it lists
/// every child whose box they can meet), else through the node's tree.
fn traverse(prog: &Program, n: usize, (rays, lanes, thi): (&Rays8, u32, &mut [f32; 8]), met: &mut Vec<u32>, v: &mut impl Visit8) {
    let listed = prog.list_of(n as u32).and_then(|(l, plane)| l.for_rays_near(plane, (rays.o, rays.d, rays.tmin), lanes, met));
    match listed {
        Some((ids, Some(per_t))) => BoxWide::visit_listed_near(rays, lanes, thi, (ids, per_t), v),
        Some((ids, _)) => BoxWide::visit_listed(rays, lanes, thi, ids.map(|(id, b, _)| (id, b)), v),
        None => prog.wide_of(n).packet.walk8(rays, lanes, thi, v),
    };
}

/// Unions of fewer leaves go ray by ray: a packet's walk lists every
/// child along each lane's whole range before the lanes settle, which a
/// small tree does not repay (300 unions of 8 spheres: +4% instructions
/// flat, +6% lit with packets, callgrind 480x270).
pub const PACKET_UNION_MIN: u32 = 32;

impl Program {
    /// Do packets walk wide union `n` for their lanes' nearest queries: a
    /// [`Program::is_packet_union`], or a [`Program::is_meet_union`]?
    #[inline(always)]
    pub fn walks_in_packets(&self, n: u32) -> bool {
        self.is_packet_union(n) || self.is_meet_union(n)
    }

    /// Is node `n` a wide union of at least [`PACKET_UNION_MIN`] subtrees
    /// (not all leaves), none unbounded, with a packet tree? Packets find
    /// their lanes' first entries in it (`union_first.rs`) when its
    /// children are kernel leaves or small trees of them
    /// ([`Program::small_leafy`], `Program::is_tree`; a walk that meets
    /// another kind answers no lane). A forest of trees cut by half-spaces
    /// is one. A union none of whose children that walk takes
    /// ([`Wide::first_walk`](super::Wide::first_walk) false: meshes each
    /// minus a ball) is not: tiles then write a narrow union of the few
    /// children they meet instead of keeping it whole with a list, and its
    /// objects are asked lane by lane. (60 such pieces in a union: one
    /// thread at 1920x1080, 0.83 of the time flat and 0.82 lit; callgrind
    /// 480x270 flat -14% instructions.)
    #[inline]
    pub fn is_meet_union(&self, n: u32) -> bool {
        let nu = n as usize;
        self.kind[nu] == NodeKind::Union
            && !self.leafy[nu]
            && self.count[nu] >= PACKET_UNION_MIN
            && (self.wide[nu] as usize) < self.wides.len()
            && self.wides[self.wide[nu] as usize].unbounded.is_empty()
            && self.wides[self.wide[nu] as usize].first_walk
    }

    /// Is node `c` an intersection or difference of at most
    /// [`SMALL_OPS`](super::union_first::SMALL_OPS) kernel leaves, evaluated
    /// in one loop (`leaf_node`)? (A union of a few kernel leaves as a
    /// child of a union is absorbed into it at bake.)
    #[inline(always)]
    pub(crate) fn small_leafy(&self, c: usize) -> bool {
        matches!(self.kind[c], NodeKind::Intersection | NodeKind::Difference)
            && self.leafy[c]
            && self.wide[c] == u32::MAX
            && self.small[c] != 0
            && self.count[c] as usize <= super::union_first::SMALL_OPS
    }

    /// Is node `n` a wide union of at least [`PACKET_UNION_MIN`] leaves with
    /// a packet tree (what [`PacketMemo::walk_unions_for`] lets packets walk
    /// together)? (Asked by every lane's every union query: inlined.)
    #[inline]
    pub fn is_packet_union(&self, n: u32) -> bool {
        let nu = n as usize;
        self.kind[nu] == NodeKind::Union
            && self.leafy[nu]
            && self.count[nu] >= PACKET_UNION_MIN
            && (self.wide[nu] as usize) < self.wides.len()
    }
}

/// The lanes of a packet walking one wide leaf union: each lane's children
/// are listed as the tree walk meets them, and visited in the canonical
/// order (by box entry, then position, as [`Program::leaf_union`] takes
/// them) once the walk has settled that nothing entered earlier is left.
struct LaneWalks<'p, 'c, 's> {
    prog: &'p Program,
    n: usize,
    leaves: &'p LeafTable,
    ctx: &'c [RayCtx<'c>; 8],
    lanes: u32,
    st: [UnionLane; 8],
    /// The lanes' ranges.
    tmin: [f32; 8],
    tmax: [f32; 8],
    /// Per lane, the smallest entry among its `cands`.
    first: [f32; 8],
    /// Per lane, the children listed and not visited yet, as keys
    /// ([`cand_key`]: their order is that of integers).
    cands: &'s mut [Vec<u64>],
    accs: &'s mut [SpanList],
    lists: (&'s mut SpanList, &'s mut SpanList),
    /// Per lane, the smallest start of a child's span visited (see
    /// [`UnionRecords::walk`]).
    starts: [f32; 8],
}

impl Visit8 for LaneWalks<'_, '_, '_> {
    // Inlined into the walk: one call less per leaf box, and the box test
    // is compiled with the walk's AVX.
    #[inline(always)]
    fn visit(&mut self, pos: u32, lanes: u32, rays: &Lanes8) {
        let c = self.prog.child_at(self.n, pos);
        self.visit_box(pos, &self.prog.bounds[c as usize], lanes, rays)
    }

    #[inline(always)]
    fn visit_box(&mut self, pos: u32, b: &Aabb, lanes: u32, rays: &Lanes8) {
        // Each lane's entry into the child's own box, as `child_entry` gives it.
        let (hit, t0) = rays.ray_range(b, &self.tmin, &self.tmax);
        let mut m = hit & lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            if t0[k] <= self.st[k].hi {
                self.cands[k].push(cand_key(pos, t0[k]));
                self.first[k] = self.first[k].min(t0[k]);
            }
        }
    }

    /// Visits, per lane, the children listed that enter before `lower`
    /// (strictly: a later one may tie), nearest first; the lane's range
    /// end follows its walk.
    // Most settles find nothing to take: the lanes that can take a child are
    // picked in one pass of compares, inlined into the walk, and the lanes'
    // visits are a call only when some lane takes one.
    #[inline(always)]
    fn settle(&mut self, lower: f32, thi: &mut [f32; 8]) {
        let l = Vec4::splat(lower);
        let ge = |h: usize| Vec4::from_slice(&self.first[4 * h..4 * h + 4]).cmpge(l).bitmask();
        let m = !(ge(0) | ge(1) << 4) & self.lanes;
        if m != 0 {
            self.take(m, lower, thi);
        }
    }
}

impl LaneWalks<'_, '_, '_> {
    /// [`settle`](Visit8::settle) for the lanes `m`, each of which has a
    /// child listed that enters before `lower`.
    #[inline(never)]
    fn take(&mut self, mut m: u32, lower: f32, thi: &mut [f32; 8]) {
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let cand = &mut self.cands[k];
            let st = &mut self.st[k];
            let ask = Ask { leaves: self.leaves, ctx: &self.ctx[k], mode: Mode::Nearest };
            let tmin = self.ctx[k].ray.tmin;
            // The smallest key each time, not a sort of them all: a lane
            // visits a few of its candidates before its end comes nearer
            // than the rest, and the scan has no branch on the keys (an
            // insertion sort of every candidate was a fifth of the walk's
            // cycles on forest, perf). Visited in the same order.
            let first = loop {
                let (mut best, mut at) = (u64::MAX, usize::MAX);
                for (i, &x) in cand.iter().enumerate() {
                    let less = x < best;
                    best = if less { x } else { best };
                    at = if less { i } else { at };
                }
                if at == usize::MAX {
                    break f32::INFINITY;
                }
                let (pos, t0) = cand_of_key(best);
                if t0 > st.hi {
                    cand.clear(); // every other one enters past the lane's end too
                    break f32::INFINITY;
                }
                if t0 >= lower {
                    break t0;
                }
                cand.swap_remove(at);
                let (leaf, tmp) = (&mut *self.lists.0, &mut *self.lists.1);
                self.prog.union_visit(self.n, pos, ask, tmin, st, (leaf, tmp, &mut self.accs[k]));
                if let Some(sp) = leaf.as_slice().first() {
                    self.starts[k] = self.starts[k].min(sp.t0);
                }
            };
            self.first[k] = first;
            thi[k] = thi[k].min(st.hi);
        }
    }
}
