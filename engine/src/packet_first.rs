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
//! tie. Here the objects the lane's box test passes are asked once each on
//! the lane's whole range, nearest box entry first, those whose entry lies
//! within `16 eps` past the lane's best so far (the others' first surfaces
//! lie past that too), and the smallest answer is taken when it is that
//! visit's answer for sure:
//! * no object is [`FirstOf::Unsure`] on the lane;
//! * the next smallest answer lies more than `16 eps` past it (no tie, and
//!   an object asked on the range cut at the best answer, as the visit asks
//!   the later ones, answers the same: a cut changes a first surface only
//!   within a few eps of it, the margin of `RenderScene::redo`);
//! * its box entry is not past it (the visit reaches it).
//!
//! Other lanes go their own way.
//!
//! The tile lists its boxes nearest first from where its rays start
//! ([`BoxList::fill`]), and a box's distance from there, over a ray's
//! length, is at most the ray's entry into it. So a packet tests the boxes
//! in that order only while the next may be entered before the nearest
//! object met and not asked yet, and before every open lane's reach (its
//! bound, or its range's end): a packet whose lanes all hit near stops
//! early; one with a lane that meets nothing tests every box, as the
//! lanes' own lists do ([`BoxList::packet_entries`]). A lone object is
//! taken without a box test. Any-hit (shadow) lanes stop asking at their
//! first hit.

use rothray_csg::{FirstOf, Firsts8, LaneRanges, NodeKind, PacketMemo, Program, RayCtx, Scratch};
use rothray_primitives::{
    box_wide::BoxTest8,
    glam::Vec3,
    mask8::{fill_lanes, gt_mask, le_mask, masked_max, masked_min},
    LeafTable, Surf,
};

use crate::box_list::{BoxList, PacketBoxes};
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
    /// The lanes with a smallest answer, and whose it is: the object, its
    /// surface's leaf and sub-surface (arrays: see `Firsts8`).
    has: u32,
    oi: [u32; 8],
    leaf: [u32; 8],
    sub: [u32; 8],
    /// The smallest one's box entry.
    entry: [f32; 8],
    /// The next smallest answer.
    second: [f32; 8],
    /// Some object's answer is not known here.
    unsure: u32,
    /// Some lane has a hit.
    any: u32,
    /// The lanes still asking: all for nearest hits; for any hits, those
    /// without one yet.
    open: u32,
    /// Does a lane stop asking at its first hit?
    any_hit: bool,
}

impl Best {
    fn new(any_hit: bool) -> Best {
        let inf = [f32::INFINITY; 8];
        Best { t: inf, has: 0, oi: [0; 8], leaf: [0; 8], sub: [0; 8], entry: inf, second: inf, unsure: 0, any: 0, open: 0xff, any_hit }
    }

    /// How far along the open lanes any object can still change an
    /// answer: the largest of their `near` ([`Best::near`]) cut at their
    /// ranges' ends `tmax` (`-inf` with no lane open).
    #[inline(always)]
    fn reach(&self, near: &[f32; 8], tmax: &[f32; 8]) -> f32 {
        masked_max(self.open, &std::array::from_fn(|k| if near[k] < tmax[k] { near[k] } else { tmax[k] }))
    }

    /// Per lane, the entry past which no object can change its answer
    /// (see [`RenderScene::packet_firsts`]).
    #[inline(always)]
    fn near(&self, eps: &[f32; 8]) -> [f32; 8] {
        std::array::from_fn(|k| self.t[k] + 16.0 * eps[k])
    }

    /// The lanes whose nearest hit is settled (tolerances `eps`): all but
    /// those some object was unsure on, and those whose smallest answer
    /// has another within `16 eps` past it or its box entry past it. (All
    /// lanes at once: lane by lane, with the answers in options, this took
    /// 4% more instructions on a scene of one ground box, 1.3% on
    /// benches/scenes/capsules and logo, callgrind 480x270 flat.)
    #[inline(always)]
    fn settled(&self, eps: &[f32; 8]) -> u32 {
        let near = self.near(eps);
        let sure = gt_mask(&self.second, &near) & le_mask(&self.entry, &self.t);
        !self.unsure & (!self.has | sure) & 0xff
    }

    /// Takes object `oi`'s answers `firsts` on the lanes `lanes`, whose box
    /// entries are `entry`.
    #[inline(always)]
    fn take(&mut self, oi: u32, lanes: u32, firsts: &Firsts8, entry: &[f32; 8]) {
        let hit = firsts.hit & lanes;
        self.unsure |= firsts.unsure & lanes;
        self.any |= hit;
        let mut m = hit;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let t = firsts.t[k];
            if t < self.t[k] {
                self.second[k] = self.t[k];
                (self.t[k], self.oi[k], self.entry[k]) = (t, oi, entry[k]);
                (self.leaf[k], self.sub[k]) = (firsts.leaf[k], firsts.sub[k]);
                self.has |= 1 << k;
            } else {
                self.second[k] = self.second[k].min(t);
            }
        }
        if self.any_hit {
            self.open &= !self.any;
        }
    }
}

/// The packet's lanes as the objects are asked about them.
pub(crate) struct PacketRays<'a> {
    pub(crate) rays: &'a [Ray; 8],
    /// Each lane's tolerance (its context's `eps`, `RenderScene::eps8`).
    pub(crate) eps: &'a [f32; 8],
    pub(crate) memo: &'a PacketMemo,
}

impl PacketRays<'_> {
    /// Lane `k`'s context, with the packet's memo.
    #[inline(always)]
    fn lane(&self, k: usize) -> RayCtx<'_> {
        RayCtx { ray: self.rays[k], eps: self.eps[k], memo: Some((self.memo, k)) }
    }
}

/// An object the packet meets: the smallest of its lanes' box entries,
/// the object, those lanes and their entries.
pub(crate) type Met = (f32, u32, u32, [f32; 8]);

/// Up to this many groups of four boxes, a packet tests all its tile's
/// boxes before it asks any object, and asks every object its lanes'
/// bounds let through (the reach's stops cost more than they saved:
/// benches/scenes/ground, a few objects a tile, +2.2% instructions).
const FEW_GROUPS: usize = 2;

/// The objects a packet has met and not asked yet, taken nearest box
/// entry first ([`MetList::pop`]).
#[derive(Debug, Default)]
pub(crate) struct MetList {
    /// In no order.
    items: Vec<Met>,
    /// Where the nearest is (when there are any).
    min_at: usize,
}

impl MetList {
    fn clear(&mut self) {
        self.items.clear();
        self.min_at = 0;
    }

    /// Adds object `m`.
    #[inline(always)]
    fn push(&mut self, m: Met) {
        if self.items.get(self.min_at).is_none_or(|n| m.0 < n.0) {
            self.min_at = self.items.len();
        }
        self.items.push(m);
    }

    /// The nearest entry of the objects not taken (infinite with none).
    #[inline(always)]
    fn nearest(&self) -> f32 {
        self.items.get(self.min_at).map_or(f32::INFINITY, |m| m.0)
    }

    /// Takes the nearest object. Why not keep them sorted: a packet mostly
    /// settles its lanes with its first few, and a scan of the rest per
    /// take cost less than a sort of all (sorting some 20 met a packet, 44
    /// bytes each, was a sixth of the cycles of a forest of 40 000 objects
    /// flat, perf).
    #[inline(always)]
    fn pop(&mut self) -> Option<Met> {
        if self.items.is_empty() {
            return None;
        }
        let m = self.items.swap_remove(self.min_at);
        self.min_at = 0;
        for (q, n) in self.items.iter().enumerate().skip(1) {
            if n.0 < self.items[self.min_at].0 {
                self.min_at = q;
            }
        }
        Some(m)
    }
}

/// Asks the objects of a tile for the first surfaces of a packet's lanes.
struct Asker<'s, 'p> {
    scene: &'s RenderScene,
    p: &'p PacketRays<'p>,
    tile: &'p TileView<'p>,
    ranges: LaneRanges<'p>,
    scratch: &'p mut Scratch,
    firsts: Firsts8,
}

impl Asker<'_, '_> {
    /// Object `oi`'s answers on the lanes `lanes` (box entries `entry`)
    /// taken into `best`; `false` when the packet does not solve its leaves.
    #[inline(always)]
    fn take(&mut self, oi: u32, lanes: u32, entry: &[f32; 8], best: &mut Best) -> bool {
        let Some(root) = self.tile.root(oi) else { return true };
        let (scene, p, prog, ranges) = (self.scene, self.p, self.tile.prog, self.ranges);
        let firsts = &mut self.firsts;
        if prog.packet_first_node(&scene.leaves, root) {
            if !p.memo.first_surfaces8(prog, &scene.leaves, root, lanes, ranges, firsts) {
                return false;
            }
        } else if prog.walks_in_packets(root) {
            scene.union_firsts(p, (prog, root), (lanes, ranges), firsts);
        } else if prog.kind[root as usize] == NodeKind::Leaf && scene.leaves.has_torus_prep(prog.first[root as usize]) {
            scene.torus_firsts(p, prog.first[root as usize], (lanes, ranges), self.scratch, firsts);
        } else {
            // Each lane's own query of the leaf on its whole range.
            let obj = crate::scene::ObjRef { prog, root, oi };
            for k in 0..8 {
                if lanes & (1 << k) != 0 {
                    let ctx = p.lane(k);
                    let f = match scene.object_first(obj, &ctx, (ranges.tmin[k], ranges.tmax[k]), self.scratch) {
                        Some((t, s)) => FirstOf::Hit(t, s),
                        None => FirstOf::Miss,
                    };
                    firsts.set(k, f);
                }
            }
        }
        best.take(oi, lanes, firsts, entry);
        true
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
        let (mut tmin, mut tmax) = ([0.0; 8], [0.0; 8]);
        fill_lanes(&mut tmin, |k| p.rays[k].tmin);
        fill_lanes(&mut tmax, |k| p.rays[k].tmax);
        let ranges = LaneRanges { tmin: &tmin, tmax: &tmax, eps: p.eps };
        let mut ask = Asker { scene: self, p, tile, ranges, scratch, firsts: Firsts8::default() };
        for &oi in &self.unbounded {
            if tile.root(oi).is_some() && best.open != 0 && !ask.take(oi, best.open, &tmin, best) {
                return false;
            }
        }
        if list.len() == 1 {
            return best.open == 0 || ask.take(list.first_id(), best.open, &tmin, best);
        }
        let Some(test) = BoxTest8::from_lanes(|k| p.rays[k].origin, |k| p.rays[k].dir) else { return false };
        // The boxes come nearest first from the rays' origins, and a box's
        // distance bounds its entries (`BoxList::reach_per_t`): boxes are
        // tested only while the next could be entered before both the
        // nearest met and every open lane's reach (its bound, or its
        // range's end), and the objects met are asked nearest entry first.
        // Past the reach no lane asks any (the bounds only shrink).
        let (groups, mut g) = (list.groups(), 0);
        met.clear();
        let open = best.open;
        let tests = |g: usize, met: &mut MetList, upto: f32, s: f32| {
            let mut upto = upto;
            list.packet_tests_from(g, &PacketBoxes { test: &test, range: (&tmin, &tmax) }, upto, |oi, hit, entry| {
                if hit & open != 0 {
                    let m = masked_min(hit, entry);
                    met.push((m, oi, hit, *entry));
                    upto = upto.min(m * s);
                }
                upto
            })
        };
        // Past the reach (in distance from the origins, `s` per unit of
        // `t`) no lane asks any object.
        let bound = if groups > FEW_GROUPS {
            let (mut o, mut d) = ([Vec3::ZERO; 8], [Vec3::ZERO; 8]);
            fill_lanes(&mut o, |k| p.rays[k].origin);
            fill_lanes(&mut d, |k| p.rays[k].dir);
            list.reach_per_t(&o, &d, &tmin)
        } else {
            None
        };
        let s = bound.unwrap_or_else(|| {
            // No bound from the boxes' distances, or a few boxes: all
            // tested first (with a NaN scale the limit stays infinite:
            // `min` ignores a NaN).
            g = tests(0, met, f32::INFINITY, f32::NAN);
            1.0
        });
        let mut near = best.near(p.eps);
        let mut lim = if bound.is_some() { best.reach(&near, &tmax) * s } else { f32::INFINITY };
        loop {
            if g < groups {
                // Boxes tested while the next may come before the nearest
                // met, within the reach.
                let upto = lim.min(met.nearest() * s);
                if list.near(4 * g) <= upto {
                    g = tests(g, met, upto, s);
                    continue;
                }
                if list.near(4 * g) > lim {
                    // (Every later box lies past the reach too.)
                    g = groups;
                }
            }
            let Some((nearest, oi, hit, entry)) = met.pop() else { break };
            if nearest * s > lim {
                break;
            }
            let lanes = hit & le_mask(&entry, &near) & best.open;
            if lanes != 0 {
                if !ask.take(oi, lanes, &entry, best) {
                    return false;
                }
                near = best.near(p.eps);
                if bound.is_some() {
                    lim = best.reach(&near, &tmax) * s;
                }
            }
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
    fn torus_firsts(&self, p: &PacketRays, leaf: u32, (lanes, ray): (u32, LaneRanges), scratch: &mut Scratch, out: &mut Firsts8) {
        let mut m = lanes;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let (tmax, eps) = (ray.tmax[k], ray.eps[k]);
            scratch.out.clear();
            let Some(v) = p.memo.torus_lane(&self.leaves, leaf, k, ((ray.tmin[k], tmax), true), &mut scratch.out) else {
                out.set(k, FirstOf::Unsure);
                continue;
            };
            let spans = scratch.out.as_slice();
            // (`leaf_spans` asks again in full here.)
            if rothray_csg::leaf_asks_again(spans, (v, tmax), eps) {
                out.set(k, FirstOf::Unsure);
                continue;
            }
            let f = match sure_first(spans, (v.min(tmax), tmax), eps) {
                Some(Some((t, s))) => FirstOf::Hit(t, s),
                Some(None) => FirstOf::Miss,
                None => FirstOf::Unsure,
            };
            out.set(k, f);
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
    fn union_firsts(&self, p: &PacketRays, (prog, root): (&Program, u32), (lanes, ranges): (u32, LaneRanges), out: &mut Firsts8) {
        let b = &prog.bounds[root as usize];
        // The lanes whose range meets the root's box (the others miss it).
        let mut met = 0u32;
        for k in 0..8 {
            if lanes & (1 << k) != 0 {
                let ray = &p.rays[k];
                if b.ray_range(ray.origin, ray.inv_dir, ranges.tmin[k], ranges.tmax[k]).is_some() {
                    met |= 1 << k;
                } else {
                    out.set(k, FirstOf::Miss);
                }
            }
        }
        p.memo.union_lanes((prog, &self.leaves), root, (met, ranges.tmin, ranges.tmax), |k, rec| {
            let f = match rec {
                None => FirstOf::Unsure,
                Some((spans, v)) => {
                    let hi = ranges.tmax[k];
                    match crate::scene::sure_first(spans, (v.min(hi), hi), ranges.eps[k]) {
                        None => FirstOf::Unsure,
                        Some(f) => f.map_or(FirstOf::Miss, |(t, s)| FirstOf::Hit(t, s)),
                    }
                }
            };
            out.set(k, f);
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
        let mut best = Best::new(false);
        if !self.tile_firsts(p, tile, (met, scratch), &mut best) {
            return 0;
        }
        let settled = best.settled(p.eps);
        for k in 0..8 {
            if settled & (1 << k) != 0 {
                found[k] = (best.has & (1 << k) != 0).then(|| (best.oi[k], best.t[k], Surf { leaf: best.leaf[k], sub: best.sub[k] }));
            }
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
        let mut best = Best::new(true);
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

    /// `Best::settled` (masks over all lanes) settles the lanes the
    /// lane-by-lane rule settles: no object unsure on the lane, and no
    /// answer or one whose next answer lies more than `16 eps` past it and
    /// whose box entry is not past it; on random answers with ties,
    /// margins at the boundary, infinities and NaN entries.
    #[test]
    fn best_settles_lanes_by_the_lane_rule() {
        let seed = 0x5e771e5u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut yes, mut no) = (0, 0);
        for case in 0..20_000 {
            let mut best = Best::new(false);
            let eps: [f32; 8] = std::array::from_fn(|_| [1e-6f32, 1e-3, 0.0, 0.25][rng.gen_range(0..4)]);
            for k in 0..8 {
                let t = rng.gen_range(-2.0f32..10.0);
                best.t[k] = t;
                best.second[k] = match rng.gen_range(0..5) {
                    0 => f32::INFINITY,
                    1 => t + 16.0 * eps[k],
                    2 => t,
                    _ => t + rng.gen_range(0.0..1.0),
                };
                best.entry[k] = match rng.gen_range(0..5) {
                    0 => t,
                    1 => f32::NAN,
                    2 => t + rng.gen_range(0.0..0.01),
                    _ => t - rng.gen_range(0.0..3.0),
                };
            }
            best.has = rng.gen::<u32>() & 0xff;
            best.unsure = rng.gen::<u32>() & rng.gen::<u32>() & 0xff;
            for k in 0..8 {
                if best.has & (1 << k) == 0 {
                    best.t[k] = f32::INFINITY;
                }
            }
            let got = best.settled(&eps);
            for k in 0..8 {
                let bit = 1 << k;
                let (t, e) = (best.t[k], eps[k]);
                let want = best.unsure & bit == 0 && (best.has & bit == 0 || (best.second[k] > t + 16.0 * e && best.entry[k] <= t));
                assert_eq!(got & bit != 0, want, "case {case} lane {k}: t {t} second {} entry {} eps {e}", best.second[k], best.entry[k]);
                if want {
                    yes += 1;
                } else {
                    no += 1;
                }
            }
        }
        assert!(yes > 30_000 && no > 30_000, "{yes} settled, {no} not");
    }

    /// `MetList::pop` takes the nearest object met and not taken yet, and
    /// `MetList::nearest` tells its entry, as pushes and takes alternate
    /// (as a packet tests boxes and asks objects in turns): against the
    /// smallest of a plain list, on random runs of entries with ties,
    /// infinities and zeros of both signs (box entries are never NaN).
    #[test]
    fn objects_met_taken_nearest_first() {
        let seed = 0x3e7_5048u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut met = MetList::default();
        let (mut pops, mut pushes) = (0, 0);
        for case in 0..3000 {
            met.clear();
            let mut want: Vec<Met> = Vec::new();
            for step in 0..rng.gen_range(0..80) {
                if rng.gen_bool(0.6) {
                    let t = match rng.gen_range(0..10) {
                        0 => f32::NEG_INFINITY,
                        1 => f32::INFINITY,
                        2 => 0.0,
                        3 => -0.0,
                        4 => 1.5,
                        _ => rng.gen_range(-5.0..5.0),
                    };
                    let m = (t, step, rng.gen(), [0.0; 8]);
                    met.push(m);
                    want.push(m);
                    pushes += 1;
                }
                let least = want.iter().map(|m| m.0).fold(f32::INFINITY, f32::min);
                assert_eq!(met.nearest(), least, "case {case} step {step}: nearest");
                if rng.gen_bool(0.4) {
                    let got = met.pop();
                    assert_eq!(got.is_none(), want.is_empty(), "case {case} step {step}");
                    if let Some(m) = got {
                        assert_eq!(m.0, least, "case {case} step {step}: the nearest taken");
                        let at = want.iter().position(|w| w.1 == m.1).expect("a met object");
                        want.swap_remove(at);
                        pops += 1;
                    }
                }
            }
        }
        assert!(pops > 10_000 && pushes > 30_000, "{pops} takes, {pushes} pushes");
    }
}
