//! Nearest and any hits picked for a whole packet among the objects of a
//! tile whose objects are all kernel leaves or small nodes of them
//! ([`Program::packet_first_node`](rothray_csg::Program::packet_first_node)):
//! each object's box tested and first surface found for the eight lanes at
//! once ([`PacketMemo::first_surfaces8`]), instead of each lane visiting its
//! candidates in order and evaluating them one by one
//! ([`RenderScene::nearest_ctx`]).
//!
//! A lane's own visit takes, in the order of box entry then index, each
//! object whose first surface on the range left lies before the best so
//! far: its answer is the smallest first surface, the earlier object on a
//! tie. Here every object the lane's box test passes is asked once on the
//! lane's whole range, and the smallest answer is taken when it is that
//! visit's answer for sure:
//! * no object is [`FirstOf::Unsure`] on the lane;
//! * the next smallest answer lies more than `16 eps` past it (no tie, and
//!   an object asked on the range cut at the best answer, as the visit asks
//!   the later ones, answers the same: a cut changes a first surface only
//!   within a few eps of it, the margin of `RenderScene::redo`);
//! * its box entry is not past it (the visit reaches it).
//!
//! Other lanes go their own way. The same boxes are tested as the lanes'
//! own lists ([`BoxList::packet_entries`]; none for a lone object, which
//! the evaluation takes without a box test).

use rothray_csg::program::cand_key;
use rothray_csg::{FirstOf, LaneRanges, NodeKind, PacketMemo, Program, RayCtx, Scratch};
use rothray_primitives::{
    box_wide::BoxTest8,
    mask8::{le_mask, masked_min},
    LeafTable, Surf,
};

use crate::box_list::BoxList;
use crate::scene::{sure_first, Ray, RenderScene};
use crate::tile::TileView;

/// Is node `n` of `prog` an object root that a packet asks for its lanes'
/// first surfaces: a kernel leaf or a small node of them
/// ([`Program::packet_first_node`]: 8-lane answers), a wide union that
/// packets walk together ([`Program::walks_in_packets`]: each lane's answer
/// read from the packet's record, `RenderScene::union_firsts`), or another
/// leaf but a mesh (each lane's own query, `RenderScene::object_first`, on
/// its whole range: a torus, a sweep)? (A mesh object's packets take the
/// mesh walks of `packet.rs`.)
pub(crate) fn simple_root(prog: &Program, leaves: &LeafTable, n: u32) -> bool {
    prog.packet_first_node(leaves, n)
        || prog.walks_in_packets(n)
        || (prog.kind[n as usize] == NodeKind::Leaf && !leaves.is_mesh(prog.first[n as usize]))
}

/// The lanes' smallest answers so far.
struct Best {
    t: [f32; 8],
    hit: [Option<(u32, Surf)>; 8],
    /// The smallest one's box entry.
    entry: [f32; 8],
    /// The next smallest answer.
    second: [f32; 8],
    /// Some object's answer is not known here.
    unsure: u32,
    /// Some lane has a hit.
    any: u32,
}

impl Best {
    fn new() -> Best {
        let inf = [f32::INFINITY; 8];
        Best { t: inf, hit: [None; 8], entry: inf, second: inf, unsure: 0, any: 0 }
    }

    /// Takes object `oi`'s answers `firsts` on the lanes `lanes`, whose box
    /// entries are `entry`.
    #[inline(always)]
    fn take(&mut self, oi: u32, lanes: u32, firsts: &[FirstOf; 8], entry: &[f32; 8]) {
        let mut m = lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            match firsts[k] {
                FirstOf::Miss => {}
                FirstOf::Unsure => self.unsure |= 1 << k,
                FirstOf::Hit(t, s) => {
                    self.any |= 1 << k;
                    if t < self.t[k] {
                        self.second[k] = self.t[k];
                        (self.t[k], self.hit[k], self.entry[k]) = (t, Some((oi, s)), entry[k]);
                    } else {
                        self.second[k] = self.second[k].min(t);
                    }
                }
            }
        }
    }
}

/// The packet's lanes as the objects are asked about them.
pub(crate) struct PacketRays<'a> {
    pub(crate) rays: &'a [Ray],
    pub(crate) ctx: &'a [RayCtx<'a>; 8],
    pub(crate) memo: &'a PacketMemo,
}

/// An object the packet meets: the smallest of its lanes' box entries,
/// the object, those lanes and their entries.
pub(crate) type Met = (f32, u32, u32, [f32; 8]);

/// Up to this many objects met by a packet are sorted in place.
const FEW_MET: usize = 8;

/// The objects a packet meets, taken nearest box first
/// ([`MetList::next_nearest`]).
#[derive(Debug, Default)]
pub(crate) struct MetList {
    items: Vec<Met>,
    /// Past [`FEW_MET`] objects: [`cand_key`]s of their entries and
    /// places, those before `at` taken.
    keys: Vec<u64>,
    at: usize,
}

impl MetList {
    fn clear(&mut self) {
        self.items.clear();
    }

    fn push(&mut self, m: Met) {
        self.items.push(m);
    }

    /// Readies the objects met to be taken nearest entry first: a few
    /// (most packets of most scenes) sorted in place by entry; more keyed
    /// (ties by place: the order met), each found when asked for. Why: a
    /// packet mostly settles every lane with its first few objects, and
    /// sorting all it met (their 44-byte entries) was a sixth of the
    /// cycles of a forest of 40 000 objects flat (some 20 met per packet,
    /// perf).
    fn order(&mut self) {
        self.at = 0;
        if !self.keyed() {
            self.items.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        } else {
            self.keys.clear();
            self.keys.extend(self.items.iter().enumerate().map(|(i, m)| cand_key(i as u32, m.0)));
        }
    }

    /// Are the objects taken by their keys (more than a few)?
    #[inline(always)]
    fn keyed(&self) -> bool {
        self.items.len() > FEW_MET
    }

    /// The nearest object not taken yet (see [`MetList::order`]).
    #[inline(always)]
    fn next_nearest(&mut self) -> Option<Met> {
        let i = self.at;
        if i >= self.items.len() {
            return None;
        }
        self.at += 1;
        if !self.keyed() {
            return Some(self.items[i]);
        }
        let (mut j, mut kj) = (i, self.keys[i]);
        for (q, &k) in self.keys.iter().enumerate().skip(i + 1) {
            if k < kj {
                (j, kj) = (q, k);
            }
        }
        self.keys.swap(i, j);
        Some(self.items[kj as u32 as usize])
    }
}

impl RenderScene {
    /// The objects' answers for the packet `p` in `tile` (whose objects are
    /// all simple and listed: `tile.simple`, `list`) into `best`, asked
    /// nearest box first, each for the lanes whose best answer so far its
    /// box entry lies within `16 eps` of (an object entered further on
    /// cannot change a lane's answer, nor its settling: its first surface
    /// lies past its entry, and the lane's own visit stops before it);
    /// `false` when the packet solves no leaves.
    fn packet_firsts(
        &self,
        p: &PacketRays,
        (tile, list): (&TileView, &BoxList),
        (met, scratch): (&mut MetList, &mut Scratch),
        best: &mut Best,
    ) -> bool {
        let tmin: [f32; 8] = std::array::from_fn(|k| p.rays[k].tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| p.rays[k].tmax);
        let eps: [f32; 8] = std::array::from_fn(|k| p.ctx[k].eps);
        let ranges = LaneRanges { tmin: &tmin, tmax: &tmax, eps: &eps };
        let mut firsts = [FirstOf::Miss; 8];
        met.clear();
        for &oi in &self.unbounded {
            if tile.root(oi).is_some() {
                met.push((f32::NEG_INFINITY, oi, 0xff, tmin));
            }
        }
        if list.len() == 1 {
            met.push((f32::NEG_INFINITY, list.first_id(), 0xff, tmin));
        } else {
            let o = std::array::from_fn(|k| p.rays[k].origin);
            let Some(test) = BoxTest8::new(&o, &std::array::from_fn(|k| p.rays[k].dir)) else { return false };
            list.packet_tests(&test, (&tmin, &tmax), |oi, hit, t0| {
                if hit != 0 {
                    met.push((masked_min(hit, t0), oi, hit, *t0));
                }
            });
        }
        met.order();
        let many = met.keyed();
        while let Some((nearest, oi, hit, entry)) = met.next_nearest() {
            let near: [f32; 8] = std::array::from_fn(|k| best.t[k] + 16.0 * eps[k]);
            // The objects come by their lanes' smallest entry: once it lies
            // past every lane's bound, so does every later one's (and the
            // bounds only shrink), and no lane asks them. (Checked where
            // many were met: with a few, the check cost more than the
            // visits it saved, benches/scenes/ground +1.3% instructions.)
            if many && nearest > near.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) {
                break;
            }
            let lanes = hit & le_mask(&entry, &near);
            let Some(root) = tile.root(oi) else { continue };
            if lanes == 0 {
                continue;
            }
            if tile.prog.packet_first_node(&self.leaves, root) {
                if !p.memo.first_surfaces8(tile.prog, &self.leaves, root, lanes, ranges, &mut firsts) {
                    return false;
                }
            } else if tile.prog.walks_in_packets(root) {
                self.union_firsts(p, (tile.prog, root), (lanes, ranges), &mut firsts);
            } else if tile.prog.kind[root as usize] == NodeKind::Leaf && self.leaves.has_torus_prep(tile.prog.first[root as usize]) {
                self.torus_firsts(p, tile.prog.first[root as usize], (lanes, ranges), scratch, &mut firsts);
            } else {
                // Each lane's own query of the leaf on its whole range.
                let obj = crate::scene::ObjRef { prog: tile.prog, root, oi };
                for k in 0..8 {
                    if lanes & (1 << k) != 0 {
                        let ctx = RayCtx { memo: Some((p.memo, k)), ..p.ctx[k] };
                        firsts[k] = match self.object_first(obj, &ctx, (tmin[k], tmax[k]), scratch) {
                            Some((t, s)) => FirstOf::Hit(t, s),
                            None => FirstOf::Miss,
                        };
                    }
                }
            }
            best.take(oi, lanes, &firsts, &entry);
        }
        true
    }

    /// The first surfaces on the lanes `lanes` of packet `p` of the object
    /// that is ring torus `leaf`, into `out`: what `RenderScene::object_first`
    /// gives each lane from the same query (the lane's spans from the
    /// packet's preps, `PacketMemo::torus_lane`, read by `sure_first`),
    /// without the evaluator's steps to it; unsure where it would ask again
    /// (a lane outside the packet's preps, a first span no longer than eps
    /// cut short, an answer not sure). Why: those steps were a sixth of a
    /// lone torus's instructions (a torus of benches/scenes/tori alone,
    /// callgrind 960x540: 167 a lane of 1 070 a packet met).
    #[inline(never)]
    fn torus_firsts(&self, p: &PacketRays, leaf: u32, (lanes, ray): (u32, LaneRanges), scratch: &mut Scratch, out: &mut [FirstOf; 8]) {
        let mut m = lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let (tmax, eps) = (ray.tmax[k], ray.eps[k]);
            scratch.out.clear();
            let Some(v) = p.memo.torus_lane(&self.leaves, leaf, k, ((ray.tmin[k], tmax), true), &mut scratch.out) else {
                out[k] = FirstOf::Unsure;
                continue;
            };
            let spans = scratch.out.as_slice();
            // (`leaf_spans` asks again in full here.)
            if rothray_csg::leaf_asks_again(spans, (v, tmax), eps) {
                out[k] = FirstOf::Unsure;
                continue;
            }
            out[k] = match sure_first(spans, (v.min(tmax), tmax), eps) {
                Some(Some((t, s))) => FirstOf::Hit(t, s),
                Some(None) => FirstOf::Miss,
                None => FirstOf::Unsure,
            };
        }
    }

    /// The first surfaces on the lanes `lanes` of packet `p` of the object
    /// whose root is `root`, a wide union that packets walk together, into
    /// `out`: what `RenderScene::object_first` gives each lane, from the
    /// same steps without the lane's walk to them. Its evaluation tests the
    /// root's box, then takes the packet's record of the union
    /// (`PacketMemo::union_lanes`, made by the first lane that asks) and is
    /// done when that record is sure; else the lane is unsure here (its own
    /// visit redoes it). Why: on the forests the lanes' own ways to those
    /// records (candidate lists, object visits, the evaluator's entry) were
    /// some 10% of the cycles (perf, one thread).
    #[inline(never)]
    fn union_firsts(&self, p: &PacketRays, (prog, root): (&Program, u32), (lanes, ranges): (u32, LaneRanges), out: &mut [FirstOf; 8]) {
        let b = &prog.bounds[root as usize];
        // The lanes whose range meets the root's box (the others miss it).
        let mut met = 0u32;
        for k in 0..8 {
            if lanes & (1 << k) != 0 {
                let ray = &p.ctx[k].ray;
                if b.ray_range(ray.origin, ray.inv_dir, ranges.tmin[k], ranges.tmax[k]).is_some() {
                    met |= 1 << k;
                } else {
                    out[k] = FirstOf::Miss;
                }
            }
        }
        p.memo.union_lanes((prog, &self.leaves), root, (met, ranges.tmin, ranges.tmax), |k, rec| {
            out[k] = match rec {
                None => FirstOf::Unsure,
                Some((spans, v)) => {
                    let hi = ranges.tmax[k];
                    match crate::scene::sure_first(spans, (v.min(hi), hi), ranges.eps[k]) {
                        None => FirstOf::Unsure,
                        Some(f) => f.map_or(FirstOf::Miss, |(t, s)| FirstOf::Hit(t, s)),
                    }
                }
            };
        });
    }

    /// The objects' answers for packet `p` when `tile` is one of simple
    /// listed objects and the packet solves its leaves ([`RenderScene::packet_firsts`]),
    /// into `best`; `false` otherwise.
    fn tile_firsts(&self, p: &PacketRays, tile: Option<&TileView>, scratch: (&mut MetList, &mut Scratch), best: &mut Best) -> bool {
        let Some(t) = tile.filter(|t| t.simple) else { return false };
        let Some(list) = t.bounded else { return false };
        self.packet_firsts(p, (t, list), scratch, best)
    }

    /// The nearest hits (object, `t`, surface) of the lanes of packet `p`
    /// that the objects' packet answers settle, into `found`; returns those
    /// lanes (0 when the tile is not one of simple listed objects).
    pub(crate) fn packet_nearest(
        &self,
        p: &PacketRays,
        tile: Option<&TileView>,
        (met, scratch): (&mut MetList, &mut Scratch),
        found: &mut [Option<(u32, f32, Surf)>; 8],
    ) -> u32 {
        let mut best = Best::new();
        if !self.tile_firsts(p, tile, (met, scratch), &mut best) {
            return 0;
        }
        let mut settled = 0u32;
        for k in 0..8 {
            if best.unsure & (1 << k) != 0 {
                continue;
            }
            found[k] = match best.hit[k] {
                None => None,
                Some((oi, s)) => {
                    let tk = best.t[k];
                    if !(best.second[k] > tk + 16.0 * p.ctx[k].eps && best.entry[k] <= tk) {
                        continue;
                    }
                    Some((oi, tk, s))
                }
            };
            settled |= 1 << k;
        }
        rothray_csg::counts::object_lanes(settled.count_ones(), 8 - settled.count_ones());
        settled
    }

    /// Any hits of the lanes of packet `p` that the objects' packet answers
    /// settle (some object has a surface on the lane's range, or none may),
    /// into `out`; returns those lanes.
    pub(crate) fn packet_any(
        &self,
        p: &PacketRays,
        tile: Option<&TileView>,
        (met, scratch): (&mut MetList, &mut Scratch),
        out: &mut [bool],
    ) -> u32 {
        let mut best = Best::new();
        if !self.tile_firsts(p, tile, (met, scratch), &mut best) {
            return 0;
        }
        let settled = (best.any | !best.unsure) & 0xff;
        rothray_csg::counts::object_lanes(settled.count_ones(), 8 - settled.count_ones());
        for k in 0..8 {
            if settled & (1 << k) != 0 {
                out[k] = best.any & (1 << k) != 0;
            }
        }
        settled
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// `MetList::next_nearest` takes the objects met in the order of their entries
    /// (`total_cmp`), ties in the order met past `FEW_MET`: against a
    /// stable sort of the same list, on random lists of 0 to 80 entries
    /// with ties, infinities, zeros of both signs and NaNs.
    #[test]
    fn objects_met_sorted_by_entry() {
        let seed = 0x3e7_5047u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut met = MetList::default();
        let (mut small, mut large) = (0, 0);
        for case in 0..3000 {
            let n = rng.gen_range(0..80);
            let pick = |rng: &mut SmallRng| match rng.gen_range(0..10) {
                0 => f32::NEG_INFINITY,
                1 => 0.0,
                2 => -0.0,
                3 => 1.5,
                4 if case % 7 == 0 => f32::NAN,
                _ => rng.gen_range(-5.0..5.0),
            };
            let items: Vec<Met> = (0..n).map(|i| (pick(&mut rng), i as u32, rng.gen(), [0.0; 8])).collect();
            met.clear();
            for &m in &items {
                met.push(m);
            }
            met.order();
            let taken: Vec<Met> = std::iter::from_fn(|| met.next_nearest()).collect();
            let got: Vec<(u32, u32)> = taken.iter().map(|m| (m.0.to_bits(), m.1)).collect();
            let mut want = items.clone();
            want.sort_by(|x, y| x.0.total_cmp(&y.0));
            if n <= FEW_MET {
                // (In place and unstable: ties in any order.)
                small += 1;
                let entries = |v: &[Met]| v.iter().map(|m| m.0.to_bits()).collect::<Vec<_>>();
                assert_eq!(entries(&taken), entries(&want), "case {case}: entries in order");
                let mut ids: Vec<u32> = taken.iter().map(|m| m.1).collect();
                ids.sort_unstable();
                assert_eq!(ids, (0..n as u32).collect::<Vec<_>>(), "case {case}: a permutation");
            } else {
                large += 1;
                let want: Vec<(u32, u32)> = want.iter().map(|m| (m.0.to_bits(), m.1)).collect();
                assert_eq!(got, want, "case {case}");
            }
        }
        assert!(small > 100 && large > 1000, "{small} short lists, {large} long");
    }
}
