//! An object's first surface for all lanes of a packet at once, when its
//! root is a kernel leaf or a small node of a few of them: what the engine
//! needs to pick a packet's nearest hits among such objects without each
//! lane's ordered visit and evaluation of every object
//! (`RenderScene::nearest_ctx`).
//!
//! A kernel leaf's answer is exact on every lane: its one span, clipped to
//! the lane's range, and its first real boundary (what `object_first` reads
//! from `Program::eval_in`). A small node's is exact where no two of its
//! operands' boundaries lie within `2 eps` ([`small_first`]); elsewhere,
//! and where the range starts inside it, the lane is [`FirstOf::Unsure`]
//! and the caller evaluates it alone. A small tree of several levels
//! (at most eight kernel leaves) is answered the same way from
//! its truth table (`tree_first.rs`).
//!
//! Why: on benches/scenes/forest_objects (10 000 leaves as objects) a
//! lane's visit of its candidates and its per-object evaluations were a
//! third of the cycles (perf, `nearest_ctx` and `object_first`).

use rothray_primitives::{kernels8::Ranges8, LeafTable, Span, SpanSink, Surf};

use super::small_first::{lane_events, small_first, sweep, Clipped, SmallFirst, SmallOps};
use super::tree_first::{done_by, TreeShape};
use super::tree_first8::{tree_first8, LaneStarts};
use super::{cand_key, cand_of_key};
use super::{NodeKind, PacketMemo, Program};

/// The most operands of an object's root that [`PacketMemo::first_surfaces8`]
/// takes (a capsule of a tile: a union of up to six spheres).
pub const OBJECT_OPS: usize = 8;

/// A lane's first surface of an object on its whole range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FirstOf {
    /// No surface on the range.
    Miss,
    /// The first surface: `t` and which.
    Hit(f32, Surf),
    /// Not known here: the lane evaluates the object itself.
    Unsure,
}

impl Program {
    /// Can [`PacketMemo::first_surfaces8`] answer node `n`: a kernel leaf,
    /// a narrow union, intersection or difference of at most
    /// [`OBJECT_OPS`] kernel leaves, or a small tree of at most
    /// eight of them (`tree_first.rs`)?
    #[inline]
    pub fn packet_first_node(&self, leaves: &LeafTable, n: u32) -> bool {
        let nu = n as usize;
        match self.kind[nu] {
            NodeKind::Leaf => leaves.has_kernel8(self.first[nu]),
            _ if self.leafy[nu] => {
                self.wide[nu] == u32::MAX && self.count[nu] as usize <= OBJECT_OPS && (self.small[nu] != 0 || self.torus_node(leaves, nu))
            }
            _ => self.is_small_tree(nu),
        }
    }

    /// Are the operands of leafy node `nu` kernel leaves and ring tori
    /// ([`LeafTable::has_torus_prep`]), at least one a torus (a node
    /// [`PacketMemo::first_surfaces8`] answers with each lane's torus spans
    /// from the packet's preps)?
    fn torus_node(&self, leaves: &LeafTable, nu: usize) -> bool {
        let kids = &self.children[self.first[nu] as usize..][..self.count[nu] as usize];
        let leaf = |c: &u32| self.first[*c as usize];
        kids.iter().all(|c| leaves.has_kernel8(leaf(c)) || leaves.has_torus_prep(leaf(c)))
            && kids.iter().any(|c| leaves.has_torus_prep(leaf(c)))
    }
}

/// The lanes' ranges and tolerances of a packet.
#[derive(Clone, Copy, Debug)]
pub struct LaneRanges<'a> {
    /// Each lane's range: from here...
    pub tmin: &'a [f32; 8],
    /// ...to here.
    pub tmax: &'a [f32; 8],
    /// Each lane's length tolerance (`RayCtx::eps`).
    pub eps: &'a [f32; 8],
}

impl PacketMemo {
    /// Node `n`'s ([`Program::packet_first_node`]) first surface on each
    /// lane `k` of `lanes` (on `[tmin[k], tmax[k]]`) into `out[k]`, from the
    /// packet's solves of its leaves; the other lanes are left as they are.
    /// `false` when the packet solves no leaves (nothing is written).
    pub fn first_surfaces8(&self, prog: &Program, leaves: &LeafTable, n: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8]) -> bool {
        let nu = n as usize;
        if prog.kind[nu] == NodeKind::Leaf {
            let leaf = prog.first[nu];
            return self.with_solve::<false, _>(leaves, leaf, |r| leaf_firsts(r, leaf, lanes, ray, out)).is_some();
        }
        if !prog.leafy[nu] {
            let Some(t) = TreeShape::of(prog, nu) else { return false };
            return self
                .with_solves_n::<false, _>(leaves, &t.leaf[..t.count], |r| {
                    let done = lanes & done_by(r);
                    let mut f = [SmallFirst::Empty; 8];
                    tree_first8(&t, r, done, &LaneStarts { lo: ray.tmin, eps: ray.eps }, &mut f);
                    firsts_of(done, lanes, ray, out, |k| f[k])
                })
                .is_some();
        }
        if prog.small[nu] == 0 {
            return self.torus_node_firsts(prog, leaves, nu, lanes, ray, out);
        }
        let mut ops = SmallOps::<OBJECT_OPS>::of(prog, nu);
        if !ops.gather(prog, nu, |leaf| self.with_solve::<false, _>(leaves, leaf, |r| *r)) {
            return false;
        }
        firsts_of(lanes & ops.done, lanes, ray, out, |k| small_first::<OBJECT_OPS, { 2 * OBJECT_OPS }>(&ops, k, (ray.tmin[k], ray.eps[k])));
        true
    }
}

impl PacketMemo {
    /// [`PacketMemo::first_surfaces8`] of leafy node `nu`, whose operands
    /// are kernel leaves and ring tori ([`Program::torus_node`]): each
    /// lane's first span swept as [`small_first`] sweeps it, from the
    /// kernel leaves' solves and the tori's spans on the lane's range from
    /// `lo - 2 eps` on (from the packet's preps, each lane its own query:
    /// a torus has up to three spans on a line, all its boundaries the one
    /// surface). The sweep's argument holds for operands of several spans:
    /// where no two boundaries lie within `2 eps`, nothing fuses. Lanes
    /// outside the packet's preps are unsure. Why: such objects (a torus
    /// cut by a box, a torus minus another) were evaluated lane by lane,
    /// 60% of benches/scenes/tori's instructions flat.
    #[inline(never)]
    fn torus_node_firsts(
        &self,
        prog: &Program,
        leaves: &LeafTable,
        nu: usize,
        lanes: u32,
        ray: LaneRanges,
        out: &mut [FirstOf; 8],
    ) -> bool {
        let mut ops = SmallOps::<OBJECT_OPS>::of(prog, nu);
        let first = prog.first[nu] as usize;
        let mut tori = 0u32;
        for j in 0..ops.count {
            let leaf = prog.first[prog.children[first + j] as usize];
            ops.leaf[j] = leaf;
            if leaves.has_kernel8(leaf) {
                let Some(r) = self.with_solve::<false, _>(leaves, leaf, |r| *r) else { return false };
                ops.done &= r.done;
                ops.r[j] = r;
            } else {
                // (No lane's solve: its spans are asked below.)
                tori |= 1 << j;
                ops.r[j] = Ranges8 { done: u32::MAX, hit: 0, ..Ranges8::default() };
            }
        }
        let done = lanes & ops.done & self.packet_lanes();
        firsts_of(done, lanes, ray, out, |k| self.torus_node_first(leaves, &ops, tori, k, (ray.tmin[k], ray.eps[k])));
        true
    }

    /// Lane `k`'s first span of the node of `ops` whose operands `tori`
    /// (bits) are ring tori, on the range from `lo` (see
    /// [`PacketMemo::torus_node_firsts`]): first from the tori's nearest
    /// queries (their first spans, exact up to where each says), then,
    /// when the node's first entry does not lie before that, from their
    /// whole spans (the scalar evaluation's two steps: the nearest queries
    /// polish one root of a torus a line meets, the whole ones all). With
    /// the whole spans asked at once, benches/scenes/tori traced 9% slower
    /// than lane by lane. `Inside` (unsure) for a lane outside the preps.
    #[inline(always)]
    fn torus_node_first(&self, leaves: &LeafTable, ops: &SmallOps<OBJECT_OPS>, tori: u32, k: usize, (lo, eps): (f32, f32)) -> SmallFirst {
        // (As `small_first`, by the kernel operands' misses.)
        if ops.missed_on(k, tori) {
            return SmallFirst::Empty;
        }
        match self.torus_node_sweep(leaves, (ops, tori), k, (lo, eps), true) {
            Some(f) => f,
            None => self.torus_node_sweep(leaves, (ops, tori), k, (lo, eps), false).unwrap_or(SmallFirst::Inside),
        }
    }

    /// The sweep of [`PacketMemo::torus_node_first`] with the tori's
    /// nearest queries (`first_only`) or their whole spans: `None` when
    /// the node's first entry is not known before the place the tori's
    /// answers are exact to (the boundaries past it are left out, and a
    /// stand-in boundary there, of no operand, makes the sweep's gap test
    /// keep `2 eps` from it).
    #[inline(always)]
    fn torus_node_sweep(
        &self,
        leaves: &LeafTable,
        (ops, tori): (&SmallOps<OBJECT_OPS>, u32),
        k: usize,
        (lo, eps): (f32, f32),
        first_only: bool,
    ) -> Option<SmallFirst> {
        let near = lo - 2.0 * eps;
        let mut ev = [0u64; TORUS_NODE_EVENTS];
        let (mut n, mut inside) = lane_events((ops.count, |j| &ops.r[j]), k, near, &mut ev);
        let mut known = f32::INFINITY;
        let mut t = tori;
        while t != 0 {
            let j = t.trailing_zeros() as usize;
            t &= t - 1;
            let mut spans = TorusSpans::default();
            let Some(v) = self.torus_lane(leaves, ops.leaf[j], k, ((near, f32::INFINITY), first_only), &mut spans) else {
                return Some(SmallFirst::Inside);
            };
            // Roth's early outs, as the lane's evaluation takes them: an
            // intersection with an empty operand, a difference with an
            // empty positive one.
            let gate = ops.kind == NodeKind::Intersection || (ops.kind == NodeKind::Difference && j == 0);
            if spans.n == 0 && v == f32::INFINITY && gate {
                return Some(SmallFirst::Empty);
            }
            if n + 2 * spans.n + 1 > TORUS_NODE_EVENTS {
                return Some(SmallFirst::Inside); // (more boundaries than room: unsure)
            }
            known = known.min(v);
            for s in &spans.s[..spans.n] {
                // A span cut at `near` (or from minus infinity) starts before it.
                if s.s0.is_real() {
                    ev[n] = cand_key((2 * j) as u32, s.t0);
                    n += 1;
                } else {
                    inside |= 1 << j;
                }
                // (An exit at infinity, as a half-space's: see `sweep`.)
                ev[n] = cand_key((2 * j) as u32 | 1, if s.s1.is_real() { s.t1 } else { f32::INFINITY });
                n += 1;
            }
        }
        if known < f32::INFINITY {
            let mut m = 0;
            for i in 0..n {
                if cand_of_key(ev[i]).1 <= known {
                    ev[m] = ev[i];
                    m += 1;
                }
            }
            // The stand-in: operand 31, outside every set `member` reads.
            ev[m] = cand_key(2 * 31, known);
            n = m + 1;
        }
        // (A torus's boundaries are all its one surface.)
        let node_surf = ops.node_surf();
        let surf = |(j, exit): (usize, bool)| {
            node_surf(j, if tori & (1 << j) != 0 { Surf::new(ops.leaf[j], 0) } else { ops.lane_surf(k, (j, exit)) })
        };
        let f = sweep(&mut ev[..n], inside, (lo, eps), ops.member(), surf);
        // (No entry before `known` says nothing of the line past it.)
        (known == f32::INFINITY || f != SmallFirst::Empty).then_some(f)
    }
}

/// Room for a lane's boundaries in [`PacketMemo::torus_node_first`]: the
/// kernel leaves' two each and the tori's spans', and a stand-in (a lane
/// with more is unsure; at 49, room for every case, zeroing the array was
/// a `memset` per lane).
const TORUS_NODE_EVENTS: usize = 16;

/// A lane's spans of a torus (at most three on a line).
struct TorusSpans {
    s: [Span; 3],
    n: usize,
}

impl Default for TorusSpans {
    fn default() -> Self {
        let none = Span { t0: 0.0, t1: 0.0, s0: Surf::NONE, s1: Surf::NONE };
        TorusSpans { s: [none; 3], n: 0 }
    }
}

impl SpanSink for TorusSpans {
    fn push_span(&mut self, s: Span) {
        // (A fourth is not made: `torus_query_prepped` gives three at most.)
        if self.n < 3 {
            self.s[self.n] = s;
            self.n += 1;
        }
    }
}

/// The first surfaces on the lanes `lanes` (those of `done` from `first`,
/// a lane's first span of the node; the others unsure) into `out`.
#[inline(always)]
fn firsts_of(done: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8], first: impl Fn(usize) -> SmallFirst) {
    for k in 0..8 {
        if lanes & (1 << k) == 0 {
            continue;
        }
        out[k] = if done & (1 << k) == 0 {
            FirstOf::Unsure
        } else {
            match first(k) {
                SmallFirst::Empty => FirstOf::Miss,
                SmallFirst::Span { t: (t0, _), s: (s0, _), .. } => {
                    // Past the range's end nothing is asked; near it the
                    // evaluation's clip may fuse (its redo's margin).
                    if t0 >= ray.tmax[k] {
                        FirstOf::Miss
                    } else if t0 < ray.tmax[k] - 16.0 * ray.eps[k] {
                        FirstOf::Hit(t0, s0)
                    } else {
                        FirstOf::Unsure
                    }
                }
                SmallFirst::Inside | SmallFirst::From(_) => FirstOf::Unsure,
            }
        };
    }
}

/// A kernel leaf's first surfaces from its solve `r`: its span clipped to
/// each lane's range as `push_clipped` clips it, and the first real
/// boundary of what is left (`first_surface`).
fn leaf_firsts(r: &Ranges8, leaf: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8]) {
    for k in 0..8 {
        if lanes & (1 << k) == 0 {
            continue;
        }
        if r.done & (1 << k) == 0 {
            out[k] = FirstOf::Unsure;
            continue;
        }
        if r.hit & (1 << k) == 0 {
            out[k] = FirstOf::Miss;
            continue;
        }
        let Clipped { c0, c1, real0, real1 } = Clipped::lane(r, k, (ray.tmin[k], ray.tmax[k]));
        out[k] = if !(c1 > c0) {
            FirstOf::Miss
        } else if real0 {
            FirstOf::Hit(c0, Surf::new(leaf, r.s0[k]))
        } else if real1 {
            FirstOf::Hit(c1, Surf::new(leaf, r.s1[k]))
        } else {
            FirstOf::Miss
        };
    }
}
