//! Wide leaf unions walked once per packet of eight rays: the node's tree
//! ([`BoxWide`](rothray_primitives::box_wide::BoxWide)) is walked for all
//! lanes at once to list each lane's children along its ray; each lane
//! then visits them exactly as its own evaluation ([`Program::leaf_union`])
//! would, in the same canonical order and with its own range. The results
//! wait in the packet's memo, where each lane's evaluation finds them
//! ([`PacketMemo::serve_union`]).
//!
//! Why: in a union of thousands of small leaves (a forest), camera rays
//! spend most of their time walking the node's tree, and the neighbouring
//! rays of a packet walk mostly the same nodes.

use rothray_primitives::{
    box_wide::{forms_packet, Lanes8, Rays8, Visit8},
    LeafTable,
};

use super::{sort_cands, Ask, Mode, NodeKind, PacketMemo, Program, RayCtx, Scratch, UnionLane, UNION_KEY};
use crate::spans::SpanList;

impl Program {
    /// Is node `n` a wide union of leaves with a packet tree (what
    /// [`Program::record_union8`] walks)?
    pub fn is_packet_union(&self, n: u32) -> bool {
        let nu = n as usize;
        self.kind[nu] == NodeKind::Union && self.leafy[nu] && (self.wide[nu] as usize) < self.wides.len()
    }

    /// Evaluates wide leaf union `n` ([`Program::is_packet_union`]) in
    /// nearest mode for the lanes `lanes` of the packet `ctx`, each on its
    /// ray's whole range, and records the results in `memo` (nothing when
    /// the rays do not form a packet: they then walk one by one).
    pub fn record_union8(&self, leaves: &LeafTable, n: u32, ctx: &[RayCtx; 8], lanes: u32, memo: &mut PacketMemo, scratch: &mut Scratch) {
        let nu = n as usize;
        let d: [_; 8] = std::array::from_fn(|k| ctx[k].ray.dir);
        if !self.is_packet_union(n) || lanes == 0 || !forms_packet(&d) {
            return;
        }
        let w = self.wide_of(nu);
        let o: [_; 8] = std::array::from_fn(|k| ctx[k].ray.origin);
        let tmin: [f32; 8] = std::array::from_fn(|k| ctx[k].ray.tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| ctx[k].ray.tmax);
        let Scratch { lanes: accs, lane_cands, leaf, tmp, .. } = scratch;
        accs.resize_with(8, SpanList::new);
        lane_cands.resize_with(8, Vec::new);
        let mut walk = LaneWalks {
            prog: self,
            n: nu,
            leaves,
            ctx,
            lanes,
            st: std::array::from_fn(|k| UnionLane { hi: tmax[k], valid: f32::INFINITY }),
            first: [f32::INFINITY; 8],
            tmin,
            tmax,
            cands: lane_cands,
            accs,
            lists: (leaf, tmp),
        };
        for k in 0..8 {
            walk.accs[k].clear();
            walk.cands[k].clear();
            if lanes & (1 << k) != 0 && !w.unbounded.is_empty() {
                walk.cands[k].extend(w.unbounded.iter().map(|&pos| (pos, tmin[k])));
                walk.first[k] = tmin[k];
            }
        }
        let mut thi = tmax;
        w.packet.walk8(&Rays8 { o: &o, d: &d, tmin: &tmin }, lanes, &mut thi, &mut walk);
        let valid = walk.st.map(|s| s.valid);
        let accs = walk.accs;
        memo.add(UNION_KEY | n, &tmin, &tmax, |sp| {
            for k in 0..8 {
                if lanes & (1 << k) != 0 {
                    sp[k].extend_from_slice(accs[k].as_slice());
                }
            }
            (lanes, valid)
        });
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
    /// Per lane, the children listed and not visited yet.
    cands: &'s mut [Vec<(u32, f32)>],
    accs: &'s mut [SpanList],
    lists: (&'s mut SpanList, &'s mut SpanList),
}

impl Visit8 for LaneWalks<'_, '_, '_> {
    #[inline]
    fn visit(&mut self, pos: u32, lanes: u32, rays: &Lanes8) {
        // Each lane's entry into the child's own box, as `child_entry` gives it.
        let c = self.prog.children[(self.prog.first[self.n] + pos) as usize];
        let (hit, t0) = rays.ray_range(&self.prog.bounds[c as usize], &self.tmin, &self.tmax);
        let mut m = hit & lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            if t0[k] <= self.st[k].hi {
                self.cands[k].push((pos, t0[k]));
                self.first[k] = self.first[k].min(t0[k]);
            }
        }
    }

    /// Visits, per lane, the children listed that enter before `lower`
    /// (strictly: a later one may tie), nearest first; the lane's range
    /// end follows its walk.
    fn settle(&mut self, lower: f32, thi: &mut [f32; 8]) {
        let mut m = self.lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            if self.first[k] >= lower {
                continue; // nothing listed can be taken yet
            }
            let cand = &mut self.cands[k];
            sort_cands(cand);
            let st = &mut self.st[k];
            let ask = Ask { leaves: self.leaves, ctx: &self.ctx[k], mode: Mode::Nearest };
            let tmin = self.ctx[k].ray.tmin;
            let mut used = 0;
            for &(pos, t0) in cand.iter() {
                if t0 >= lower || t0 > st.hi {
                    break;
                }
                used += 1;
                let (leaf, tmp) = (&mut *self.lists.0, &mut *self.lists.1);
                self.prog.union_visit(self.n, pos, ask, tmin, st, (leaf, tmp, &mut self.accs[k]));
            }
            if used < cand.len() && cand[used].1 > st.hi {
                cand.clear(); // sorted: the rest lies past the lane's end
            } else {
                cand.drain(..used);
            }
            self.first[k] = cand.first().map_or(f32::INFINITY, |c| c.1);
            thi[k] = thi[k].min(st.hi);
        }
    }
}
