//! A small node's spans on one lane from its operands' 8-lane solves: a
//! union, intersection or difference of a few kernel leaves, each of whose
//! spans on a line is one span at most. Used by the first-entry walk of
//! wide unions (`union_first.rs`, the node a union's child) and by the
//! packets' answers for objects (`object_packet.rs`, the node an object's
//! root).

use rothray_primitives::{kernels8::Ranges8, Surf};

use super::{cand_key, cand_of_key, sort_few, NodeKind, Program};

/// A kernel leaf's span on lane `k` of its solve, clipped to `(lo, hi)` as
/// `push_clipped` clips it: its ends, and whether each is the leaf's own
/// boundary (else the range's end, no surface).
pub(crate) struct Clipped {
    pub(crate) c0: f32,
    pub(crate) c1: f32,
    pub(crate) real0: bool,
    pub(crate) real1: bool,
}

impl Clipped {
    /// Lane `k` of `r` (a lane the solve hit) on `(lo, hi)`.
    #[inline(always)]
    pub(crate) fn lane(r: &Ranges8, k: usize, (lo, hi): (f32, f32)) -> Clipped {
        let (t0, t1) = (r.t0[k], r.t1[k]);
        let real0 = t0 >= lo && t0.is_finite();
        let real1 = t1 <= hi && t1.is_finite();
        Clipped { c0: if real0 { t0 } else { t0.max(lo) }, c1: if real1 { t1 } else { t1.min(hi) }, real0, real1 }
    }
}

/// The solves of a small node's operands (kernel leaves), at most `N`.
pub(crate) struct SmallOps<const N: usize> {
    pub(crate) kind: NodeKind,
    pub(crate) count: usize,
    pub(crate) leaf: [u32; N],
    pub(crate) r: [Ranges8; N],
    /// The lanes every solve did.
    pub(crate) done: u32,
}

impl<const N: usize> SmallOps<N> {
    /// Room for the operands of node `c` of `prog` (none solved yet).
    #[inline(always)]
    pub(crate) fn of(prog: &Program, c: usize) -> Self {
        SmallOps { kind: prog.kind[c], count: prog.count[c] as usize, leaf: [0; N], r: [Ranges8::default(); N], done: u32::MAX }
    }

    /// Solves the operands of node `c` of `prog` (at most `N` kernel
    /// leaves) by `solve`, in place (made and returned whole, the solves
    /// were copied once more: capsules +4.5% instructions); `false` when a
    /// solve is not to be had.
    #[inline(always)]
    pub(crate) fn gather(&mut self, prog: &Program, c: usize, mut solve: impl FnMut(u32) -> Option<Ranges8>) -> bool {
        let first = prog.first[c] as usize;
        for j in 0..self.count {
            let leaf = prog.first[prog.children[first + j] as usize];
            self.leaf[j] = leaf;
            let Some(r) = solve(leaf) else { return false };
            self.r[j] = r;
            self.done &= r.done;
        }
        true
    }
}

impl<const N: usize> SmallOps<N> {
    /// Is the node empty on lane `k`'s whole line by Roth's rules, an
    /// intersection with an operand the line misses or a difference whose
    /// positive operand it misses (the operands of `unknown`, bits, not
    /// counted: their solves are not in `r`)?
    #[inline(always)]
    pub(crate) fn missed_on(&self, k: usize, unknown: u32) -> bool {
        let missed = |j: usize| unknown & (1 << j) == 0 && self.r[j].hit & (1 << k) == 0;
        match self.kind {
            NodeKind::Intersection => (0..self.count).any(missed),
            NodeKind::Difference => missed(0),
            _ => false,
        }
    }

    /// Is a point inside exactly the operands `m` (bits; others ignored)
    /// inside the node? `(m & all == want) != union`: one compare per
    /// boundary, no match on the kind.
    #[inline(always)]
    pub(crate) fn member(&self) -> impl Fn(u32) -> bool {
        let all = (1u32 << self.count) - 1;
        let (want, union) = match self.kind {
            NodeKind::Difference => (1, false),
            NodeKind::Intersection => (all, false),
            _ => (0, true),
        };
        move |m: u32| (m & all == want) != union
    }

    /// Operand `j`'s surface `s` as the node's: flipped for a subtrahend
    /// (the kind read once, as `member` reads it).
    #[inline(always)]
    pub(crate) fn node_surf(&self) -> impl Fn(usize, Surf) -> Surf {
        let subtract = self.kind == NodeKind::Difference;
        move |j: usize, s: Surf| if subtract && j > 0 { s.flip() } else { s }
    }

    /// Operand `j`'s own surface at its entry or `exit` on lane `k` (from its solve).
    #[inline(always)]
    pub(crate) fn lane_surf(&self, k: usize, (j, exit): (usize, bool)) -> Surf {
        let r = &self.r[j];
        Surf::new(self.leaf[j], if exit { r.s1[k] } else { r.s0[k] })
    }
}

/// What a small node's result on a lane's range is known to be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum SmallFirst {
    /// No span.
    Empty,
    /// The range may start inside it.
    Inside,
    /// Not known exactly: any span starts at this place or later.
    From(f32),
    /// Its first span (with a real entry) and where its next span starts
    /// (infinity: none).
    Span { t: (f32, f32), s: (Surf, Surf), next: f32 },
}

/// Lane `k`'s first span of a small node (a union, intersection or
/// difference of at most `N` kernel leaves; `E = 2 N`) from its operands'
/// spans on the range starting at `lo`, each operand one span at most
/// (kernel leaves are convex).
///
/// Where every boundary of the operands from `lo - 2 eps` on lies more than
/// `2 eps` from the next one and from `lo`, `combine` fuses, merges and
/// drops nothing (its tolerances are eps), and `leaf_node`, which narrows
/// each operand's range to the result so far (and stops a union in nearest
/// mode a little past its first entry), gives the exact set operation's
/// spans up to where it stops: their boundaries are the operands', those
/// of a subtrahend flipped. Otherwise each result boundary is one of the
/// operands' boundaries or fused with one within eps, so no span starts
/// before the first boundary past `lo - 2 eps` less eps.
// (Inlined into its callers' lane loops: out of line it was a call per
// lane and child, forest_cut +2.2% instructions.)
#[inline(always)]
pub(crate) fn small_first<const N: usize, const E: usize>(ops: &SmallOps<N>, k: usize, (lo, eps): (f32, f32)) -> SmallFirst {
    debug_assert!(E == 2 * N);
    if ops.missed_on(k, 0) {
        return SmallFirst::Empty;
    }
    let mut ev = [0u64; E];
    let (n, inside) = lane_events((ops.count, |j| &ops.r[j]), k, lo - 2.0 * eps, &mut ev);
    let node_surf = ops.node_surf();
    let surf = |(j, exit): (usize, bool)| node_surf(j, ops.lane_surf(k, (j, exit)));
    sweep(&mut ev[..n], inside, (lo, eps), ops.member(), surf)
}

/// A boundary of a lane as one integer: [`cand_key`] of its place and of
/// `2 j + exit` (operand `j`, an exit or an entry), so that integer order is
/// the places' `total_cmp` order, then the operands' order, entry first:
/// the order in which a stable sort of the boundaries as they are listed
/// leaves them. (Sorted as 16-byte tuples, the swaps were most of the
/// sort's work.)
pub(crate) type Event = u64;

/// The place of boundary `e`.
#[inline(always)]
fn place(e: Event) -> f32 {
    cand_of_key(e).1
}

/// The operand of boundary `e`, and whether it is its exit.
#[inline(always)]
fn operand(e: Event) -> (usize, bool) {
    let id = e as u32;
    ((id >> 1) as usize, id & 1 != 0)
}

/// Lane `k`'s boundaries ([`Event`]) of the `count` operands whose solves
/// `r(j)` gives, from `near` on, into `ev` (room for two per operand);
/// returns their number and the operands the range starts inside (bit `j`
/// for operand `j`). (Written in place: returned, the array was a `memcpy`
/// per lane, capsules +3.9% instructions.)
#[inline(always)]
pub(crate) fn lane_events<'r, const E: usize>(
    (count, r): (usize, impl Fn(usize) -> &'r Ranges8),
    k: usize,
    near: f32,
    ev: &mut [Event; E],
) -> (usize, u32) {
    let mut n = 0;
    let mut inside = 0u32;
    for j in 0..count {
        let r = r(j);
        if r.hit & (1 << k) == 0 {
            continue;
        }
        for (t, exit) in [(r.t0[k], false), (r.t1[k], true)] {
            if t < near {
                inside = if exit { inside & !(1 << j) } else { inside | (1 << j) };
            } else {
                ev[n] = cand_key((2 * j) as u32 | exit as u32, t);
                n += 1;
            }
        }
    }
    (n, inside)
}

/// The sweep of [`small_first`] over the boundaries `ev` (in any order;
/// sorted here) of a lane whose range starts at `lo` inside the operands
/// `inside` (bit per operand): `member` tells whether a set of operands
/// (bit per operand) the line is inside is inside the node, `surf` the
/// node's surface at a boundary (operand, exit).
#[inline(always)]
pub(crate) fn sweep(
    ev: &mut [Event],
    mut inside: u32,
    (lo, eps): (f32, f32),
    member: impl Fn(u32) -> bool,
    surf: impl Fn((usize, bool)) -> Surf,
) -> SmallFirst {
    // (At most sixteen.)
    sort_few(ev);
    let mut sure = true;
    let mut prev = lo;
    for &e in ev.iter() {
        let t = place(e);
        if t == f32::INFINITY {
            break; // (ends at infinity bound nothing the range keeps)
        }
        if !(t - prev > 2.0 * eps) {
            sure = false;
            break;
        }
        prev = t;
    }
    if member(inside) {
        return SmallFirst::Inside;
    }
    if !sure {
        return match ev.first() {
            Some(&e) => SmallFirst::From(place(e) - eps),
            None => SmallFirst::Empty,
        };
    }
    let mut span: Option<((f32, Surf), (f32, Surf))> = None;
    let mut start = None;
    let mut was = false;
    for &e in ev.iter() {
        let (j, exit) = operand(e);
        inside = if exit { inside & !(1 << j) } else { inside | (1 << j) };
        let now = member(inside);
        if now == was {
            continue;
        }
        was = now;
        let t = place(e);
        match (now, start, span) {
            (true, None, None) => start = Some((t, surf((j, exit)))),
            (false, Some(s0), None) => span = Some((s0, (t, surf((j, exit))))),
            (true, _, Some(((t0, s0), (t1, s1)))) => {
                return SmallFirst::Span { t: (t0, t1), s: (s0, s1), next: t };
            }
            _ => {}
        }
    }
    match (start, span) {
        (_, Some(((t0, s0), (t1, s1)))) => SmallFirst::Span { t: (t0, t1), s: (s0, s1), next: f32::INFINITY },
        // Open to the end (an exit at infinity left out above).
        (Some((t0, s0)), None) => SmallFirst::Span { t: (t0, f32::INFINITY), s: (s0, Surf::NONE), next: f32::INFINITY },
        _ => SmallFirst::Empty,
    }
}
