//! Analytic leaves solved once per packet of eight rays: the first lane
//! whose evaluation asks a sphere, box, cylinder or half-space for its spans
//! solves it for every lane of the packet with the 8-lane kernels
//! ([`LeafTable::ranges8`]); the other lanes' evaluations then find their
//! range here and only clip it to their own query range, exactly as the
//! leaf's own query would ([`PacketMemo::leaf_lane`]).
//!
//! Why: neighbouring camera rays (and a light's shadow rays from
//! neighbouring hits) ask mostly the same leaves, and one 8-lane solve costs
//! about what one scalar query does.
//!
//! A ring torus is prepared the same way: the first lane that asks makes
//! every lane's [`TorusPrep`] (the line in its frame, the quartic and the
//! roots of its derivative), one step for all lanes before the next, so that
//! the lanes' chains of square roots and divisions overlap; each lane then
//! finishes its own query from its prep ([`PacketMemo::torus_lane`]).

use rothray_primitives::{
    box_wide::BoxTest8,
    glam::Vec3,
    kernels::TorusPrep,
    kernels8::{BesideOdds, Ranges8, Rays8Soa},
    table::{push_clipped, LeafTable},
    Span, SpanSink, Surf,
};

use super::tree_first::TREE_LEAVES;
use super::PacketMemo;
use crate::counts;
use crate::tile_list::TileList;
use rothray_primitives::ray_plane::RayPlane;

/// Cached leaves per packet (a direct-mapped table by leaf index: a
/// collision only costs a second solve).
const SLOTS: usize = 1024;

/// Cached tori per packet (as [`SLOTS`]; a prep is about 1.5 KB for eight lanes).
const TORUS_SLOTS: usize = 8;

/// The packet's rays and the leaves solved for them.
#[derive(Debug, Default)]
pub(crate) struct LeafRecords {
    /// Lanes whose rays are set (0: no packet).
    lanes: u32,
    rays: Rays8Soa,
    /// Tells this packet's slots from earlier packets' (0: never).
    generation: u32,
    /// Per slot: (leaf, generation, its lanes).
    slots: Vec<(u32, u32, Ranges8)>,
    /// Per torus slot: (leaf, generation, its lanes' preps).
    tori: Vec<(u32, u32, [Option<TorusPrep>; 8])>,
    /// The entries of one tile list that the packet's rays meet.
    list_met: ListMet,
    /// Whether the leaves' miss pretests pay (kept from packet to packet).
    odds: [BesideOdds; 2],
}

/// [`PacketMemo::with_list_met`]'s record: one list (a tile's union of
/// subtrees; a packet's lanes ask the same one in turn).
#[derive(Debug, Default)]
struct ListMet {
    /// (Program address, union node) of the list.
    key: (usize, u32),
    generation: u32,
    /// Whether every lane's ray is a ray of the list's plane.
    ok: bool,
    met: Vec<u32>,
    /// Per entry of `met`, where each lane's line enters and leaves its box
    /// ([`BoxTest8::slabs`]), when the rays form a packet; else empty.
    slabs: Vec<Slabs8>,
}

/// Eight lanes' entries and exits of one box ([`BoxTest8::slabs`]).
pub(crate) type Slabs8 = ([f32; 8], [f32; 8]);

impl LeafRecords {
    pub(crate) fn clear(&mut self) {
        self.lanes = 0;
    }
}

impl PacketMemo {
    /// Lets the evaluations of the packet's lanes `lanes` (world rays
    /// `ray(k)`: origin and direction, which must be the rays of the
    /// contexts that carry this memo) share their analytic leaves' solves.
    /// (Read lane by lane into the records: an array of the eight origins
    /// made by the caller and copied here was read back across its 12-byte
    /// stores, a stall on store forwarding that was a fifth of
    /// `intersect_packet_with`'s cycles on benches/scenes/capsules flat, perf.)
    #[inline(always)]
    pub fn solve_leaves_for(&mut self, ray: impl Fn(usize) -> (Vec3, Vec3), lanes: u32) {
        let r = self.leaf_solves.get_mut();
        if r.slots.is_empty() {
            r.slots.resize(SLOTS, (0, 0, Ranges8::default()));
            r.tori.resize(TORUS_SLOTS, (0, 0, [None; 8]));
        }
        r.generation = r.generation.wrapping_add(1).max(1);
        r.lanes = lanes;
        r.rays = Rays8Soa::from_lanes(&ray);
    }

    /// The lanes of the packet whose leaves this memo solves (0: none).
    #[inline(always)]
    pub(crate) fn packet_lanes(&self) -> u32 {
        self.leaf_solves.borrow().lanes
    }

    /// Lane `k`'s spans of ring torus `i` on `range` (with `first_only`, what
    /// a nearest query needs), from the lane's prep made with every lane's
    /// when the first lane asked, appended to `out`; returns where they stop
    /// being exact, as [`LeafTable::spans_for`] does, or `None` when the lane
    /// is not in the packet. The caller checks [`LeafTable::has_torus_prep`].
    // Inlined into the evaluator like `leaf_lane` (the preps are made out
    // of line, `torus_prep8`): tori -2.2% instructions flat, -2.0% lit
    // (callgrind, 480x270).
    #[inline(always)]
    pub fn torus_lane<S: SpanSink + ?Sized>(
        &self,
        leaves: &LeafTable,
        i: u32,
        k: usize,
        (range, first_only): ((f32, f32), bool),
        out: &mut S,
    ) -> Option<f32> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, generation, rays, tori, .. } = &mut *guard;
        if *lanes & (1 << k) == 0 {
            return None;
        }
        let preps = record(tori, i, *generation, |p| leaves.torus_prep8(i, rays, *lanes, p));
        counts::leaf_lane(true);
        Some(leaves.torus_spans_prepped(i, preps[k].as_ref(), range, first_only, out))
    }

    /// Lane `k`'s spans of leaf `i` on `range`, from the packet's solve of
    /// the leaf (made now when no lane asked before), appended to `out`:
    /// `Some(f32::INFINITY)` (exact everywhere, as the leaf's own query),
    /// or `None` when the packet does not answer (no packet kernel for the
    /// leaf's kind, the lane is not in the packet, or its local direction
    /// needs rescaling). The caller checks [`LeafTable::has_kernel8`].
    #[inline(always)]
    pub(crate) fn leaf_lane<S: SpanSink + ?Sized>(
        &self,
        leaves: &LeafTable,
        i: u32,
        k: usize,
        range: (f32, f32),
        out: &mut S,
    ) -> Option<f32> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, rays, generation, slots, odds, .. } = &mut *guard;
        if *lanes & (1 << k) == 0 {
            return None;
        }
        let e = &*record(slots, i, *generation, |e| solve8::<false>(leaves, i, rays, *lanes, e, odds));
        let done = e.done & (1 << k) != 0;
        counts::leaf_lane(done);
        if !done {
            return None;
        }
        if e.hit & (1 << k) != 0 {
            let span = Span { t0: e.t0[k], s0: Surf::new(i, e.s0[k]), t1: e.t1[k], s1: Surf::new(i, e.s1[k]) };
            push_clipped(out, span, range.0, range.1);
        }
        Some(f32::INFINITY)
    }
}

/// One lane's reads of the packet's solves, the records borrowed once
/// for many leaves ([`PacketMemo::lane_solves`]).
pub(crate) struct LaneSolves<'m> {
    records: std::cell::RefMut<'m, LeafRecords>,
    k: usize,
}

impl PacketMemo {
    /// Lane `k`'s reads of the packet's leaf solves, or `None` when the
    /// lane is not in the packet. (For a lane that asks many leaves in a
    /// row, `deep_first.rs`: a borrow per leaf was a fifth of its time.)
    #[inline(always)]
    pub(crate) fn lane_solves(&self, k: usize) -> Option<LaneSolves<'_>> {
        let records = self.leaf_solves.borrow_mut();
        (records.lanes & (1 << k) != 0).then_some(LaneSolves { records, k })
    }
}

impl LaneSolves<'_> {
    /// [`PacketMemo::leaf_lane`] without the borrow: lane's spans of kernel
    /// leaf `i` on `range` into `out`; `false` when the solve did not do the
    /// lane (the caller asks the leaf itself).
    #[inline(always)]
    pub(crate) fn spans<S: SpanSink + ?Sized>(&mut self, leaves: &LeafTable, i: u32, range: (f32, f32), out: &mut S) -> bool {
        let k = self.k;
        let LeafRecords { lanes, rays, generation, slots, odds, .. } = &mut *self.records;
        let e = &*record(slots, i, *generation, |e| solve8::<false>(leaves, i, rays, *lanes, e, odds));
        if e.done & (1 << k) == 0 {
            return false;
        }
        if e.hit & (1 << k) != 0 {
            let span = Span { t0: e.t0[k], s0: Surf::new(i, e.s0[k]), t1: e.t1[k], s1: Surf::new(i, e.s1[k]) };
            push_clipped(out, span, range.0, range.1);
        }
        true
    }
}

impl PacketMemo {
    /// `f` of the entries of `list` (of union `key`: program address and
    /// node) whose shadows meet the box of the packet's rays' points on
    /// `plane` ([`TileList::met_by`], made when the first lane asks), for
    /// lane `k`; `None` when the packet does not answer (no rays set, the
    /// lane is not in the packet, or a ray is not a ray of the plane). A
    /// superset of the entries lane `k`'s own point meets. With them, the
    /// lanes' entries and exits of each one's box (one 8-lane test per box
    /// instead of one test per lane), when the rays form a packet.
    #[inline]
    pub(crate) fn with_list_met<R>(
        &self,
        key: (usize, u32),
        (list, plane): (&TileList, &RayPlane),
        k: usize,
        f: impl FnOnce(&TileList, &[u32], &[Slabs8]) -> R,
    ) -> Option<R> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, rays, generation, list_met, .. } = &mut *guard;
        if *lanes & (1 << k) == 0 {
            return None;
        }
        if list_met.key != key || list_met.generation != *generation {
            // (The rays back in lanes here, for this rare list only: kept
            // beside the packet's SoA rays, their copies were some 64
            // instructions a packet, callgrind.)
            let (mut o, mut d) = ([Vec3::ZERO; 8], [Vec3::ZERO; 8]);
            for k in 0..8 {
                (o[k], d[k]) = rays.lane(k);
            }
            list_met.ok = list.met_by(plane, (&o, &d), *lanes, &mut list_met.met);
            (list_met.key, list_met.generation) = (key, *generation);
            met_slabs(list, list_met, (&o, &d));
        }
        list_met.ok.then(|| f(list, &list_met.met, &list_met.slabs))
    }

    /// `f` of the packet's solve of analytic leaf `i` (which must have a
    /// packet kernel) for every lane, from its record (made now when no lane
    /// asked before), or `None` when the packet solves no leaves.
    #[inline(always)]
    pub(crate) fn with_solve<const BESIDE: bool, R>(&self, leaves: &LeafTable, i: u32, f: impl FnOnce(&Ranges8) -> R) -> Option<R> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, rays, generation, slots, odds, .. } = &mut *guard;
        if *lanes == 0 {
            return None;
        }
        Some(f(record(slots, i, *generation, |e| solve8::<BESIDE>(leaves, i, rays, *lanes, e, odds))))
    }
}

impl PacketMemo {
    /// [`PacketMemo::with_solve`] of two leaves `i` and `j` at once: `f`
    /// reads both records where they lie (copying them out was 2% of
    /// benches/scenes/forest_cut's cycles, in `memmove`, perf).
    #[inline(always)]
    pub(crate) fn with_solves2<const BESIDE: bool, R>(
        &self,
        leaves: &LeafTable,
        (i, j): (u32, u32),
        f: impl FnOnce(&Ranges8, &Ranges8) -> R,
    ) -> Option<R> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, rays, generation, slots, odds, .. } = &mut *guard;
        if *lanes == 0 {
            return None;
        }
        let (lanes, generation) = (*lanes, *generation);
        let mask = slots.len() - 1;
        if i as usize & mask == j as usize & mask && i != j {
            // One slot for both (rare): the first one copied.
            let a = *record(slots, i, generation, |e| solve8::<BESIDE>(leaves, i, rays, lanes, e, odds));
            return Some(f(&a, record(slots, j, generation, |e| solve8::<BESIDE>(leaves, j, rays, lanes, e, odds))));
        }
        record(slots, i, generation, |e| solve8::<BESIDE>(leaves, i, rays, lanes, e, odds));
        record(slots, j, generation, |e| solve8::<BESIDE>(leaves, j, rays, lanes, e, odds));
        Some(f(&slots[i as usize & mask].2, &slots[j as usize & mask].2))
    }
}

impl PacketMemo {
    /// [`PacketMemo::with_solve`] of the leaves `ids` (at most
    /// [`TREE_LEAVES`]) at once: `f` reads their records where they lie
    /// (copies where two of them share a slot); `None` when the packet
    /// solves no leaves. (Copied out one by one, the records of a forest's
    /// two-level trees were 5% of its cycles in `memmove`, perf.)
    #[inline(always)]
    pub(crate) fn with_solves_n<const BESIDE: bool, R>(
        &self,
        leaves: &LeafTable,
        ids: &[u32],
        f: impl FnOnce(&[&Ranges8]) -> R,
    ) -> Option<R> {
        let mut guard = self.leaf_solves.borrow_mut();
        let LeafRecords { lanes, rays, generation, slots, odds, .. } = &mut *guard;
        if *lanes == 0 {
            return None;
        }
        let (lanes, generation) = (*lanes, *generation);
        let n = ids.len().min(TREE_LEAVES);
        if n == 0 {
            return Some(f(&[]));
        }
        for &i in &ids[..n] {
            record(slots, i, generation, |e| solve8::<BESIDE>(leaves, i, rays, lanes, e, odds));
        }
        let mask = slots.len() - 1;
        let at = |i: u32| &slots[i as usize & mask];
        if ids[..n].iter().all(|&i| at(i).0 == i && at(i).1 == generation) {
            // (A plain loop: through `std::array::from_fn` the compiler made
            // it eight calls in `first_surfaces8`.)
            let mut r: [&Ranges8; TREE_LEAVES] = [&at(ids[0]).2; TREE_LEAVES];
            for (r, &i) in r.iter_mut().zip(&ids[..n]) {
                *r = &at(i).2;
            }
            return Some(f(&r[..n]));
        }
        // Two leaves in one slot (rare): each solve copied.
        let mut copies = [Ranges8::default(); TREE_LEAVES];
        for (c, &i) in copies.iter_mut().zip(&ids[..n]) {
            *c = *record(slots, i, generation, |e| solve8::<BESIDE>(leaves, i, rays, lanes, e, odds));
        }
        let mut r: [&Ranges8; TREE_LEAVES] = [&copies[0]; TREE_LEAVES];
        for (r, c) in r.iter_mut().zip(&copies) {
            *r = c;
        }
        Some(f(&r[..n]))
    }
}

/// The 8-lane box tests of the entries `rec.met` of `list` into `rec.slabs`
/// (left empty when the rays `(o, d)` do not form a packet). Out of line:
/// once per packet and list.
#[inline(never)]
fn met_slabs(list: &TileList, rec: &mut ListMet, (o, d): (&[Vec3; 8], &[Vec3; 8])) {
    rec.slabs.clear();
    if !rec.ok {
        return;
    }
    if let Some(test) = BoxTest8::new(o, d) {
        rec.slabs.extend(rec.met.iter().map(|&i| test.slabs(list.entry(i).1)));
    }
}

/// The packet's solve of leaf `i`, out of line so that the look-up
/// ([`PacketMemo::leaf_lane`]) is small enough to inline into the evaluator:
/// inlined there with the solve (and the kernels' SSE2 fallback) inside, it
/// stayed a call of a large function per lane and leaf, about 60
/// instructions of entry, exit and look-up each (callgrind, 480x270, flat:
/// logo -1.3%, capsules -1.4%, fill -1.6%, ground -2.7%; lit -1.1% to
/// -1.8% on those; forest, meshes and sweeps within 0.3%).
///
/// With the odds of the solve's callers: `BESIDE` for a wide union's
/// children, the others for objects and single lanes (their shares of
/// solves with every lane missing differ; see [`BesideOdds`]).
#[inline(never)]
fn solve8<const BESIDE: bool>(leaves: &LeafTable, i: u32, rays: &Rays8Soa, lanes: u32, e: &mut Ranges8, odds: &mut [BesideOdds; 2]) {
    odds[BESIDE as usize].solve(leaves, i, rays, lanes, e)
}

/// Leaf `i`'s record for this packet in the direct-mapped `table` (of a
/// power-of-two length), made by `fill` when its slot holds another leaf's
/// record or an earlier packet's.
#[inline(always)]
fn record<T>(table: &mut [(u32, u32, T)], i: u32, generation: u32, fill: impl FnOnce(&mut T)) -> &mut T {
    debug_assert!(table.len().is_power_of_two());
    let e = &mut table[i as usize & (table.len() - 1)];
    if e.0 != i || e.1 != generation {
        counts::leaf_solve();
        fill(&mut e.2);
        (e.0, e.1) = (i, generation);
    }
    &mut e.2
}
