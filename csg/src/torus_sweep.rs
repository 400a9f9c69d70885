//! A lane's first span of a small node or tree whose leaves are kernel
//! leaves and ring tori: the kernel leaves' boundaries from the packet's
//! 8-lane solves, the tori's from each lane's query of the packet's preps
//! ([`PacketMemo::torus_lane`]: up to three spans a torus), swept as
//! [`small_first`](super::small_first::small_first) sweeps (where no two
//! boundaries from `lo - 2 eps` on lie within `2 eps` of each other,
//! nothing fuses: the exact set operation's spans). A node of such leaves
//! ([`Program::torus_node`]) is swept with its kind's membership; a tree
//! of several levels ([`Program::is_torus_tree`]) with its truth table
//! ([`TreeShape`]), as `tree_first` sweeps a tree of kernel leaves.
//!
//! First with the tori's nearest queries (each polishes one root of a
//! torus a line meets, and says where its answer stops being exact); when
//! the first entry does not lie before the nearest such place, again with
//! their whole spans (the scalar evaluation's two steps). Where a place
//! stays (`known`), the answer is bounded by it: a span open past it ends
//! there at the earliest, and a next span may start there.
//!
//! Why: such objects (a ring cut by a half-space, minus a ball) were
//! evaluated lane by lane, and such a child of a wide union stopped its
//! first-entry walk for every lane (400 such objects: 3.9x POV-Ray's speed
//! flat).

use rothray_primitives::{kernels8::Ranges8, LeafTable, Span, SpanSink, Surf};

use super::object_packet::OBJECT_OPS;
use super::small_first::{lane_events, sweep, SmallFirst, SmallOps};
use super::tree_first::{TreeShape, TREE_LEAVES};
use super::{cand_key, cand_of_key, NodeKind, PacketMemo, Program};

/// Room for a lane's boundaries: the kernel leaves' two each and the tori's
/// spans', and a stand-in (a lane with more is unsure; room for every case
/// would be a `memset` per lane).
const EVENTS: usize = 16;

/// What a lane's sweep reads of a node or tree of kernel leaves and tori.
pub(crate) struct TorusOperands<'a, M, E> {
    /// Its leaves, their solves (a torus's: none), which are tori (bits).
    pub(crate) leaf: &'a [u32],
    pub(crate) r: &'a [Ranges8],
    pub(crate) tori: u32,
    /// Is a point inside exactly the leaves of a set (bits) inside it?
    pub(crate) member: M,
    /// Is it empty on a whole line that misses the leaves of a set (bits)?
    pub(crate) empty: E,
    /// Leaf `j`'s surfaces are flipped in its result (bits).
    pub(crate) flip: u32,
    /// Per lane, the kernel leaves its line misses (bits), made once for
    /// the packet (lane by lane, from the solves, they were 2% of
    /// benches/scenes/tori's instructions flat).
    missed: [u32; 8],
}

impl<'a, M: Fn(u32) -> bool, E: Fn(u32) -> bool> TorusOperands<'a, M, E> {
    /// The leaves `leaf` (solves `r`; tori: the bits `tori`) of a node or
    /// tree whose `member`, `empty` and `flip` are as the fields say.
    #[inline(always)]
    pub(crate) fn new((leaf, r, tori): (&'a [u32], &'a [Ranges8], u32), member: M, empty: E, flip: u32) -> Self {
        let mut missed = [0u32; 8];
        for (j, r) in r.iter().enumerate() {
            let miss = if tori & (1 << j) != 0 { 0 } else { !r.hit };
            for (k, m) in missed.iter_mut().enumerate() {
                *m |= (miss >> k & 1) << j;
            }
        }
        TorusOperands { leaf, r, tori, member, empty, flip, missed }
    }

    /// Lane `k`'s first span on the range from `lo` (see the module's
    /// notes); `Inside` (unsure) for a lane outside the packet's preps.
    #[inline(always)]
    pub(crate) fn first(&self, memo: &PacketMemo, leaves: &LeafTable, k: usize, (lo, eps): (f32, f32)) -> SmallFirst {
        // (By the kernel leaves' misses alone.)
        let missed = self.missed[k];
        if (self.empty)(missed) {
            return SmallFirst::Empty;
        }
        match self.sweep(memo, leaves, (k, missed), (lo, eps), true) {
            Some(f) => f,
            None => self.sweep(memo, leaves, (k, missed), (lo, eps), false).unwrap_or(SmallFirst::Inside),
        }
    }

    /// The sweep of [`TorusOperands::first`] with the tori's nearest
    /// queries (`first_only`) or their whole spans: `None` when the first
    /// entry is not known before the place the tori's answers are exact to
    /// (the boundaries past it are left out, and a stand-in boundary there,
    /// of no leaf, makes the sweep's gap test keep `2 eps` from it).
    #[inline(always)]
    fn sweep(
        &self,
        memo: &PacketMemo,
        leaves: &LeafTable,
        (k, mut missed): (usize, u32),
        (lo, eps): (f32, f32),
        first_only: bool,
    ) -> Option<SmallFirst> {
        let near = lo - 2.0 * eps;
        let mut ev = [0u64; EVENTS];
        let (mut n, mut inside) = lane_events((self.r.len(), |j| &self.r[j]), k, near, &mut ev);
        let mut known = f32::INFINITY;
        let mut t = self.tori;
        while t != 0 {
            let j = t.trailing_zeros() as usize;
            t &= t - 1;
            let mut spans = TorusSpans::default();
            let Some(v) = memo.torus_lane(leaves, self.leaf[j], k, ((near, f32::INFINITY), first_only), &mut spans) else {
                return Some(SmallFirst::Inside);
            };
            if spans.n == 0 && v == f32::INFINITY {
                // Roth's early outs, as the lane's evaluation takes them (an
                // intersection with an empty operand, a difference with an
                // empty positive one), and any set the tree needs.
                missed |= 1 << j;
                if (self.empty)(missed) {
                    return Some(SmallFirst::Empty);
                }
            }
            if n + 2 * spans.n + 1 > EVENTS {
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
            // The stand-in: leaf 31, outside every set `member` reads.
            ev[m] = cand_key(2 * 31, known);
            n = m + 1;
        }
        // (A torus's boundaries are all its one surface.)
        let surf = |(j, exit): (usize, bool)| {
            let r = &self.r[j];
            let s = Surf::new(
                self.leaf[j],
                if self.tori & (1 << j) != 0 {
                    0
                } else if exit {
                    r.s1[k]
                } else {
                    r.s0[k]
                },
            );
            if self.flip & (1 << j) != 0 {
                s.flip()
            } else {
                s
            }
        };
        let f = sweep(&mut ev[..n], inside, (lo, eps), |m| (self.member)(m & !(1 << 31)), surf);
        // (No entry before `known` says nothing of the line past it.)
        (known == f32::INFINITY || f != SmallFirst::Empty).then(|| bounded(f, known))
    }
}

/// `f` made of the boundaries up to `known` alone: a span open past it (an
/// end left out) ends there at the earliest, with no surface; a next span
/// may start there.
#[inline(always)]
fn bounded(f: SmallFirst, known: f32) -> SmallFirst {
    match f {
        SmallFirst::Span { t: (t0, t1), s: (s0, s1), next } if known < f32::INFINITY => {
            let open = t1 > known;
            SmallFirst::Span { t: (t0, if open { known } else { t1 }), s: (s0, if open { Surf::NONE } else { s1 }), next: next.min(known) }
        }
        f => f,
    }
}

impl Program {
    /// Is node `nu` a narrow node of at most [`OBJECT_OPS`] operands, kernel
    /// leaves and ring tori ([`LeafTable::has_torus_prep`]), at least one a
    /// torus (a ring cut by a half-space, a torus minus a ball)?
    #[inline(always)]
    pub(crate) fn torus_node(&self, leaves: &LeafTable, nu: usize) -> bool {
        if !self.leafy[nu] || self.wide[nu] != u32::MAX || self.count[nu] as usize > OBJECT_OPS {
            return false;
        }
        let kids = &self.children[self.first[nu] as usize..][..self.count[nu] as usize];
        let leaf = |c: &u32| self.first[*c as usize];
        kids.iter().all(|c| leaves.has_kernel8(leaf(c)) || leaves.has_torus_prep(leaf(c)))
            && kids.iter().any(|c| leaves.has_torus_prep(leaf(c)))
    }

    /// Is node `n` a tree of several levels of narrow nodes down to at most
    /// [`TREE_LEAVES`] leaves, kernel leaves and ring tori, at least one a
    /// torus ([`TorusTree`])? (A node of such leaves alone is
    /// [`Program::torus_node`]'s; a tree of kernel leaves alone,
    /// `tree_first`'s.)
    #[inline]
    pub(crate) fn is_torus_tree(&self, leaves: &LeafTable, n: usize) -> bool {
        if self.kind[n] == NodeKind::Leaf || self.leafy[n] || self.small[n] != 0 {
            return false;
        }
        let (mut count, mut tori) = (0, false);
        self.torus_tree_walk(leaves, n, (&mut count, &mut tori)) && tori
    }

    /// Counts the leaves below node `n` into `count` (stopping past
    /// [`TREE_LEAVES`]); `false` when one is neither a kernel leaf nor a
    /// ring torus, or a node is wide.
    fn torus_tree_walk(&self, leaves: &LeafTable, n: usize, (count, tori): (&mut usize, &mut bool)) -> bool {
        if self.kind[n] == NodeKind::Leaf {
            let i = self.first[n];
            *count += 1;
            *tori |= leaves.has_torus_prep(i);
            return *count <= TREE_LEAVES && (leaves.has_kernel8(i) || leaves.has_torus_prep(i));
        }
        if self.wide[n] != u32::MAX {
            return false;
        }
        let f = self.first[n] as usize;
        (0..self.count[n] as usize).all(|j| self.torus_tree_walk(leaves, self.children[f + j] as usize, (&mut *count, &mut *tori)))
    }
}

/// A tree of kernel leaves and ring tori ([`Program::is_torus_tree`]): its
/// shape, its kernel leaves' solves, which leaves are tori.
pub(crate) struct TorusTree {
    t: TreeShape,
    r: [Ranges8; TREE_LEAVES],
    tori: u32,
    /// The lanes every solve did.
    pub(crate) done: u32,
}

impl TorusTree {
    /// What a lane's sweep reads of the tree ([`TorusOperands::first`] by
    /// its truth table).
    #[inline(always)]
    pub(crate) fn operands(&self) -> TorusOperands<'_, impl Fn(u32) -> bool + '_, impl Fn(u32) -> bool + '_> {
        let t = &self.t;
        TorusOperands::new(
            (&t.leaf[..t.count], &self.r[..t.count], self.tori),
            |m: u32| t.member(m),
            |missed: u32| t.empty_for(|j| missed & (1 << j) != 0),
            (0..t.count).fold(0, |f, j| f | (t.flip_of(j) as u32) << j),
        )
    }
}

impl PacketMemo {
    /// The operands of leafy node `nu` ([`Program::torus_node`]) with the
    /// packet's solves of its kernel leaves (`BESIDE`: with the miss
    /// pretests, see `LeafTable::ranges8_beside`), and the bits of its
    /// tori (whose lanes' spans [`torus_operands`]' sweeps ask); `None`
    /// when the packet solves no leaves.
    #[inline(always)]
    pub(crate) fn torus_node_ops<const BESIDE: bool>(
        &self,
        prog: &Program,
        leaves: &LeafTable,
        nu: usize,
    ) -> Option<(SmallOps<OBJECT_OPS>, u32)> {
        let mut ops = SmallOps::<OBJECT_OPS>::of(prog, nu);
        let first = prog.first[nu] as usize;
        for j in 0..ops.count {
            ops.leaf[j] = prog.first[prog.children[first + j] as usize];
        }
        let (tori, done) = self.solves_with_tori::<BESIDE>(leaves, &ops.leaf[..ops.count], &mut ops.r[..ops.count])?;
        ops.done = done;
        Some((ops, tori))
    }

    /// The packet's solves of the kernel leaves among `leaf` (kernel leaves
    /// and ring tori) into `r` (a torus's: none, its lanes' spans are asked
    /// lane by lane); returns the tori (bits) and the lanes every solve
    /// did, or `None` when the packet solves no leaves. (Indexed, each solve
    /// read into a local and stored: assigned through the zipped iterator,
    /// each was a `memcpy` call, +0.4% instructions on tori_deep.)
    #[inline(always)]
    fn solves_with_tori<const BESIDE: bool>(&self, leaves: &LeafTable, leaf: &[u32], r: &mut [Ranges8]) -> Option<(u32, u32)> {
        let (mut tori, mut done) = (0u32, u32::MAX);
        for j in 0..leaf.len() {
            if leaves.has_kernel8(leaf[j]) {
                let s = self.with_solve::<BESIDE, _>(leaves, leaf[j], |s| *s)?;
                done &= s.done;
                r[j] = s;
            } else {
                tori |= 1 << j;
                r[j] = Ranges8 { done: u32::MAX, hit: 0, ..Ranges8::default() };
            }
        }
        Some((tori, done))
    }

    /// Tree `n` ([`Program::is_torus_tree`]) with the packet's solves of its
    /// kernel leaves (`BESIDE`: with the miss pretests, see
    /// `LeafTable::ranges8_beside`); `None` when the packet solves no
    /// leaves.
    #[inline(always)]
    pub(crate) fn torus_tree<const BESIDE: bool>(&self, prog: &Program, leaves: &LeafTable, n: usize) -> Option<TorusTree> {
        // (Solved in place: made aside and moved in, the solves' kilobyte
        // was copied once more.)
        let mut tt = TorusTree { t: TreeShape::of(prog, n)?, r: [Ranges8::default(); TREE_LEAVES], tori: 0, done: 0 };
        let count = tt.t.count;
        (tt.tori, tt.done) = self.solves_with_tori::<BESIDE>(leaves, &tt.t.leaf[..count], &mut tt.r[..count])?;
        Some(tt)
    }
}

/// What a lane's sweep reads of the node of `ops` whose operands `tori`
/// (bits) are ring tori ([`TorusOperands::first`], from the kernel leaves'
/// solves and the tori's queries). (With the tori's whole
/// spans asked at once, not first their nearest queries,
/// benches/scenes/tori traced 9% slower than lane by lane.)
#[inline(always)]
pub(crate) fn torus_operands(ops: &SmallOps<OBJECT_OPS>, tori: u32) -> TorusOperands<'_, impl Fn(u32) -> bool, impl Fn(u32) -> bool> {
    let count = ops.count;
    let all = (1u32 << count) - 1;
    let kind = ops.kind;
    TorusOperands::new(
        (&ops.leaf[..count], &ops.r[..count], tori),
        ops.member(),
        // Roth's early outs: an intersection with an empty operand, a
        // difference with an empty positive one (a union: all empty).
        move |missed: u32| match kind {
            NodeKind::Intersection => missed != 0,
            NodeKind::Difference => missed & 1 != 0,
            _ => missed == all,
        },
        if kind == NodeKind::Difference { all & !1 } else { 0 },
    )
}

/// A lane's spans of a torus (at most three on a line).
pub(crate) struct TorusSpans {
    pub(crate) s: [Span; 3],
    pub(crate) n: usize,
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
