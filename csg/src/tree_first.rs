//! The first surface of a small tree of any depth on each lane of a
//! packet, from its leaves' 8-lane solves: a node whose nodes are all
//! narrow and whose leaves are at most [`TREE_LEAVES`] kernel leaves
//! ([`Program::is_small_tree`]), such as a box cut by a sphere minus a
//! union of cylinders (an object's root), or a ball cut by a half-space
//! minus a notch (a child of a forest's wide union).
//!
//! The argument of [`small_first`](super::small_first::small_first)
//! carries over to any depth: where every leaf boundary from `lo - 2 eps`
//! on lies more than `2 eps` from the next one and from `lo`, no `combine`
//! of the tree's evaluation (`small_node`, its full diagram) fuses, merges
//! or drops anything, so its result is the exact set operation's. Its
//! boundaries are the leaves' own, a leaf's surface flipped once for each
//! difference it is subtracted by. So a lane sweeps all the leaves'
//! boundaries in order and reads, at each, whether the set of leaves it is
//! inside is inside the tree: one bit of the tree's truth table, made from
//! the leaves' bit patterns by the tree's own operations (OR, AND, AND NOT
//! on 256 bits).
//!
//! Why: such an object was evaluated lane by lane with span lists and
//! `combine` at every node (benches/scenes/logo: `eval_node` and
//! `small_node` over 60% of its instructions flat, callgrind 480x270), and
//! such a child made the lanes of a forest leave the packet's walk.

use rothray_primitives::{kernels8::Ranges8, LeafKind, LeafTable, Surf};

use super::small_first::{lane_events, sweep, SmallFirst};
use super::{NodeKind, Program};

/// The most leaves of a tree answered here (its truth table has
/// `2^TREE_LEAVES` bits).
pub const TREE_LEAVES: usize = 8;

impl Program {
    /// Is node `n` a small tree of several levels that [`tree_first`]
    /// answers: narrow nodes down to at most [`TREE_LEAVES`] kernel leaves,
    /// not all of them its own operands (those are `small_first`'s)?
    #[inline(always)]
    pub(crate) fn is_small_tree(&self, n: usize) -> bool {
        !self.leafy[n] && self.is_tree(n)
    }

    /// Is inner node `n` a small tree (of one level or more) of at most
    /// [`TREE_LEAVES`] kernel leaves, which [`tree_first`] answers?
    #[inline(always)]
    pub(crate) fn is_tree(&self, n: usize) -> bool {
        self.small[n] != 0 && self.small[n] as usize <= TREE_LEAVES
    }
}

/// Bit `m` of `LEAF[j]` (bit `m % 64` of word `m / 64`) is bit `j` of `m`:
/// the sets of leaves inside leaf `j`.
const LEAF: [[u64; 4]; TREE_LEAVES] = [
    [0xaaaa_aaaa_aaaa_aaaa; 4],
    [0xcccc_cccc_cccc_cccc; 4],
    [0xf0f0_f0f0_f0f0_f0f0; 4],
    [0xff00_ff00_ff00_ff00; 4],
    [0xffff_0000_ffff_0000; 4],
    [0xffff_ffff_0000_0000; 4],
    [0, u64::MAX, 0, u64::MAX],
    [0, 0, u64::MAX, u64::MAX],
];

/// Leaves solved in tree order (`0, 1, 2, ...` in 3 bits each).
const IN_ORDER: u16 = 0o43210;

/// Up to this many leaves, a tree's truth table repeats from word to word.
const PERIODIC: usize = 6;

/// Bit `m` for every set `m` of `count` leaves (`count <= PERIODIC`).
fn low_sets(count: usize) -> u64 {
    if count >= PERIODIC {
        u64::MAX
    } else {
        (1u64 << (1 << count)) - 1
    }
}

/// A small tree's leaves (in the order of a depth-first walk) and its
/// truth table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct TreeShape {
    /// How many leaves, and which.
    pub(crate) count: usize,
    pub(crate) leaf: [u32; TREE_LEAVES],
    /// Bit `j`: leaf `j`'s surfaces are flipped in the tree's result.
    flip: u32,
    /// Bit `m`: is a point inside exactly the leaves of `m` inside the tree?
    table: [u64; 4],
    /// Up to [`PERIODIC`] leaves, the bits of `table` of the sets of them
    /// (others: 0).
    low: u64,
    /// The order in which a walk solves the first `count - 1` leaves
    /// before the others ([`TreeShape::solve_order`]), 3 bits a leaf.
    order: u16,
}

impl TreeShape {
    /// The shape of small tree `n` of `prog`; `None` when it has more than
    /// [`TREE_LEAVES`] leaves.
    #[inline]
    pub(crate) fn of(prog: &Program, n: usize) -> Option<TreeShape> {
        let mut t = TreeShape { count: 0, leaf: [0; TREE_LEAVES], flip: 0, table: [0; 4], low: 0, order: IN_ORDER };
        // Up to six leaves, every leaf's pattern repeats from word to word
        // (its bit is in the low six of `m`), and so does the table: one
        // word is computed (four were most of `pattern`'s work, which was
        // 1.6% of benches/scenes/forest_deep's instructions flat).
        if (1..=PERIODIC).contains(&(prog.small[n] as usize)) {
            let [w] = t.pattern::<1>(prog, n, false)?;
            t.table = [w; 4];
            if t.count <= PERIODIC {
                t.low = w & low_sets(t.count);
                return Some(t);
            }
            // (`small` counts the leaves: not reached.)
            (t.count, t.flip) = (0, 0);
        }
        t.table = t.pattern::<4>(prog, n, false)?;
        // (A tree of up to six leaves not all kernel leaves, `small` 0:
        // its sets of them, as above.)
        if t.count <= PERIODIC {
            t.low = t.table[0] & low_sets(t.count);
        }
        Some(t)
    }

    /// The truth table of node `c` over the leaves met so far and its own
    /// (added to the list), its first `W` words; `flip`: is `c` subtracted
    /// an odd number of times?
    fn pattern<const W: usize>(&mut self, prog: &Program, c: usize, flip: bool) -> Option<[u64; W]> {
        let kind = prog.kind[c];
        if kind == NodeKind::Leaf {
            let j = self.count;
            if j == TREE_LEAVES {
                return None;
            }
            self.leaf[j] = prog.first[c];
            self.flip |= (flip as u32) << j;
            self.count += 1;
            return Some(std::array::from_fn(|w| LEAF[j][w]));
        }
        let first = prog.first[c] as usize;
        let mut acc = [0u64; W];
        for i in 0..prog.count[c] as usize {
            let sub = kind == NodeKind::Difference && i > 0;
            let p = self.pattern::<W>(prog, prog.children[first + i] as usize, flip ^ sub)?;
            for w in 0..W {
                acc[w] = match kind {
                    _ if i == 0 => p[w],
                    NodeKind::Union => acc[w] | p[w],
                    NodeKind::Intersection => acc[w] & p[w],
                    _ => acc[w] & !p[w],
                };
            }
        }
        Some(acc)
    }

    /// A shape of `count` leaves `leaf` with flips `flip` and truth table
    /// `table` made by `f` of the leaves' patterns (any function: a superset
    /// of trees), for tests.
    #[cfg(test)]
    pub(crate) fn for_tests(count: usize, leaf: [u32; TREE_LEAVES], flip: u32, f: impl FnOnce(&[[u64; 4]]) -> [u64; 4]) -> TreeShape {
        let table = f(&LEAF[..count]);
        let low = if count <= PERIODIC { table[0] & low_sets(count) } else { 0 };
        TreeShape { count, leaf, flip, table, low, order: IN_ORDER }
    }

    /// The `s`-th leaf a walk solves, for `s < count - 1` (see
    /// [`TreeShape::with_order`]).
    #[inline(always)]
    pub(crate) fn solve_order(&self, s: usize) -> usize {
        (self.order >> (3 * s)) as usize & 7
    }

    /// The shape with its leaves solved in the order of `leaves`' kinds:
    /// boxes and half-spaces last (they meet most lanes that meet the
    /// child's box, which is mostly their own), the others in tree order.
    pub(crate) fn with_order(mut self, leaves: &LeafTable) -> TreeShape {
        let late = |j: usize| solved_late(leaves, self.leaf[j]);
        let mut order = 0u32;
        let mut s = 0;
        for pass in [false, true] {
            for j in (0..self.count).filter(|&j| late(j) == pass) {
                order |= (j as u32) << (3 * s);
                s += 1;
            }
        }
        // (The last leaf is solved anyway: 15 bits for six leaves.)
        self.order = (order & 0x7fff) as u16;
        self
    }

    /// Is a point inside exactly the leaves `m` inside the tree?
    #[inline(always)]
    pub(crate) fn member(&self, m: u32) -> bool {
        self.table[(m >> 6) as usize & 3] >> (m & 63) & 1 != 0
    }

    /// The truth table as eight 32-bit words (bit `m % 32` of word `m / 32`).
    #[inline(always)]
    pub(crate) fn table_words(&self) -> [u32; 8] {
        std::array::from_fn(|i| (self.table[i / 2] >> (32 * (i % 2))) as u32)
    }

    /// Are leaf `j`'s surfaces flipped in the tree's result?
    #[inline(always)]
    pub(crate) fn flip_of(&self, j: usize) -> bool {
        self.flip & (1 << j) != 0
    }

    /// The lanes of `m` on which the tree may be non-empty, from its leaves'
    /// solves `r`: those that meet every leaf of some set inside the tree
    /// (the lanes [`TreeShape::empty_for`] does not find empty, all at
    /// once; `m` itself for a tree of more than six leaves or of more than
    /// eight such sets). Why: most lanes that take a tree child miss it
    /// (63% on benches/scenes/forest_deep flat), each then asked alone.
    #[inline(always)]
    pub(crate) fn maybe_met(&self, r: &[&Ranges8], m: u32) -> u32 {
        if !self.filters() {
            return m;
        }
        m & self.lanes_meeting(|j| r[j].hit)
    }

    /// Does [`TreeShape::maybe_met`] filter lanes (up to six leaves and
    /// eight sets inside the tree)?
    #[inline(always)]
    pub(crate) fn filters(&self) -> bool {
        self.count <= PERIODIC && self.low.count_ones() <= 8
    }

    /// The lanes that meet every leaf of some set inside the tree, where
    /// `hit(j)` are the lanes that meet leaf `j` (a tree that
    /// [`TreeShape::filters`]).
    #[inline(always)]
    pub(crate) fn lanes_meeting(&self, hit: impl Fn(usize) -> u32) -> u32 {
        let mut lanes = 0;
        let mut sets = self.low;
        while sets != 0 {
            let mut set = sets.trailing_zeros();
            sets &= sets - 1;
            let mut l = u32::MAX;
            while set != 0 {
                l &= hit(set.trailing_zeros() as usize);
                set &= set - 1;
            }
            lanes |= l;
        }
        lanes
    }

    /// Is the tree empty on a whole line that misses the leaves `j` for
    /// which `missed(j)`: is no set of the others (whether or not they
    /// overlap) inside it?
    #[inline(always)]
    pub(crate) fn empty_for(&self, missed: impl Fn(usize) -> bool) -> bool {
        if self.count <= PERIODIC {
            // (The sets of up to six leaves are all in the first word.)
            let mut t = self.low;
            for j in 0..self.count {
                t &= if missed(j) { !LEAF[j][0] } else { u64::MAX };
            }
            return t == 0;
        }
        let mut t = self.table;
        for j in 0..self.count {
            if missed(j) {
                for w in 0..4 {
                    t[w] &= !LEAF[j][w];
                }
            }
        }
        t == [0; 4]
    }
}

/// The shapes of the children of a wide node that are small trees of up to
/// [`PERIODIC`] leaves ([`Program::is_tree`]), by position, made at bake
/// (kept in the node's [`Wide`](super::Wide), which tile programs share and
/// live syncs copy). Their leaves are stored relative to the first one's:
/// a live sync moves an object's leaves and nodes by one offset each
/// ([`Program`] rows copied with their ids shifted), which leaves the
/// differences as they are; the first leaf is found from the child's node
/// when asked. (24 bytes a child: with the whole shape, 88, and an index,
/// the walk's reads of them missed the caches, and forest_deep gained a
/// fifth of the instructions it saved.)
#[derive(Clone, Debug, Default)]
pub(crate) struct TreeShapes {
    /// Per position (`count == 0`: none); empty when no child is stored.
    shapes: Vec<StoredShape>,
}

/// A [`TreeShape`] of up to [`PERIODIC`] leaves, its leaves relative to the first.
#[derive(Clone, Copy, Debug, Default)]
struct StoredShape {
    /// The truth table's word (periodic: see [`TreeShape::of`]).
    word: u64,
    count: u8,
    flip: u8,
    delta: [i16; PERIODIC],
    order: u16,
}

impl TreeShapes {
    /// The shapes of the children `kids` (node ids) of `prog` that are trees.
    pub(crate) fn of(prog: &Program, leaves: &LeafTable, kids: &[u32]) -> TreeShapes {
        let mut s = TreeShapes::default();
        for (pos, &c) in kids.iter().enumerate() {
            if prog.kind[c as usize] == NodeKind::Leaf || !prog.is_tree(c as usize) {
                continue;
            }
            let Some(t) = TreeShape::of(prog, c as usize) else { continue };
            let t = t.with_order(leaves);
            if t.count > PERIODIC {
                continue;
            }
            let mut delta = [0i16; PERIODIC];
            let offset = |j: usize| i16::try_from(t.leaf[j] as i64 - t.leaf[0] as i64).ok();
            if !(0..t.count).all(|j| offset(j).map(|d| delta[j] = d).is_some()) {
                continue; // (leaves too far apart for an i16: made when asked)
            }
            if s.shapes.is_empty() {
                s.shapes = vec![StoredShape::default(); kids.len()];
            }
            s.shapes[pos] = StoredShape { word: t.table[0], count: t.count as u8, flip: t.flip as u8, delta, order: t.order };
        }
        s
    }

    /// The shape of tree child `c` (node id) at position `pos`: the stored
    /// one with its leaves made absolute, or made here when none is stored.
    #[inline(always)]
    pub(crate) fn get(&self, prog: &Program, pos: u32, c: usize) -> Option<TreeShape> {
        let Some(st) = self.shapes.get(pos as usize).filter(|st| st.count != 0) else {
            return TreeShape::of(prog, c);
        };
        // The first leaf of a depth-first walk: the first operand's, down.
        let mut n = c;
        while prog.kind[n] != NodeKind::Leaf {
            n = prog.children[prog.first[n] as usize] as usize;
        }
        let l0 = prog.first[n];
        let count = st.count as usize;
        let leaf = std::array::from_fn(|j| if j < count { l0.wrapping_add(st.delta[j] as i32 as u32) } else { 0 });
        Some(TreeShape { count, leaf, flip: st.flip as u32, table: [st.word; 4], low: st.word & low_sets(count), order: st.order })
    }
}

/// Is leaf `i` a box or a half-space, which a walk solves after a child's
/// other leaves? (They meet most lanes that meet the child's box, which is
/// mostly their own: they seldom tell that no lane meets the child.)
#[inline(always)]
pub(crate) fn solved_late(leaves: &LeafTable, i: u32) -> bool {
    matches!(leaves.kind.get(i as usize), Some(LeafKind::Cuboid | LeafKind::HalfSpace))
}

/// The lanes that every solve of `r` did.
#[inline(always)]
pub(crate) fn done_by(r: &[&Ranges8]) -> u32 {
    r.iter().fold(u32::MAX, |d, r| d & r.done)
}

/// Lane `k`'s first span of the tree `t` on the range starting at `lo`,
/// from its leaves' solves `r` (in `t`'s order), as
/// [`small_first`](super::small_first::small_first) gives it for a node of
/// leaves (see the module's notes).
#[inline(always)]
pub(crate) fn tree_first(t: &TreeShape, r: &[&Ranges8], k: usize, (lo, eps): (f32, f32)) -> SmallFirst {
    if t.empty_for(|j| r[j].hit & (1 << k) == 0) {
        return SmallFirst::Empty;
    }
    let mut ev = [0u64; 2 * TREE_LEAVES];
    let (n, inside) = lane_events((t.count, |j| r[j]), k, lo - 2.0 * eps, &mut ev);
    let surf = |(j, exit): (usize, bool)| {
        let s = Surf::new(t.leaf[j], if exit { r[j].s1[k] } else { r[j].s0[k] });
        if t.flip_of(j) {
            s.flip()
        } else {
            s
        }
    };
    sweep(&mut ev[..n], inside, (lo, eps), |m| t.member(m), surf)
}

#[cfg(test)]
mod tests {
    use super::super::ProgramBuilder;
    use super::*;
    use crate::spans::Op;
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    use rothray_primitives::glam::{DAffine3, Vec3};
    use rothray_primitives::{Cuboid, HalfSpace, LeafShape, LeafTable, Sphere};

    /// `maybe_met` keeps exactly the lanes `empty_for` does not find empty
    /// (or all of them, past six leaves or eight sets), on random tables
    /// of one to eight leaves and random hits.
    #[test]
    fn maybe_met_is_not_empty_for_lane_by_lane() {
        let seed = 0x3e7_u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut filtered = 0;
        for case in 0..20_000 {
            let count = rng.gen_range(1..=TREE_LEAVES);
            let sparse = rng.gen_bool(0.7);
            let t = TreeShape::for_tests(count, [0; TREE_LEAVES], 0, |p| {
                let mut acc = p[0];
                for q in &p[1..] {
                    for w in 0..4 {
                        acc[w] = match rng.gen_range(0..3) {
                            0 if !sparse => acc[w] | q[w],
                            1 | 0 => acc[w] & q[w],
                            _ => acc[w] & !q[w],
                        };
                    }
                }
                acc
            });
            let solves: Vec<Ranges8> = (0..count).map(|_| Ranges8 { hit: rng.gen::<u32>() & 0xff, ..Ranges8::default() }).collect();
            let r: Vec<&Ranges8> = solves.iter().collect();
            let m = rng.gen::<u32>() & 0xff;
            let got = t.maybe_met(&r, m);
            if t.count > PERIODIC || t.low.count_ones() > 8 {
                assert_eq!(got, m, "case {case}: unfiltered");
                continue;
            }
            filtered += 1;
            for k in 0..8 {
                let want = m & (1 << k) != 0 && !t.empty_for(|j| r[j].hit & (1 << k) == 0);
                assert_eq!(
                    got & (1 << k) != 0,
                    want,
                    "case {case} lane {k}: {t:?}, hits {:?}",
                    solves.iter().map(|s| s.hit).collect::<Vec<_>>()
                );
            }
        }
        assert!(filtered > 5_000, "too few cases filtered: {filtered}");
    }

    /// A wide union's stored shapes ([`TreeShapes::get`]) are the shapes
    /// [`TreeShape::of`] makes of its children, for random small trees of
    /// one to eight leaves (two levels, operands in any order), whether
    /// stored (up to six leaves) or made when asked.
    #[test]
    fn stored_shapes_are_the_shapes_made_when_asked() {
        let seed = 0x5eed_7eee_u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut leaves = LeafTable::default();
        for i in 0..1200 {
            // (Boxes and half-spaces among them: solved last.)
            let c = Vec3::new(i as f32, 0.0, 0.0);
            let shape = match rng.gen_range(0..4) {
                0 => LeafShape::Cuboid(Cuboid { min: c - 0.3, max: c + 0.3 }),
                1 => LeafShape::HalfSpace(HalfSpace { normal: Vec3::Y, offset: 0.1 }),
                _ => LeafShape::Sphere(Sphere { center: c, radius: 0.4 }),
            };
            leaves.push(&shape, &DAffine3::IDENTITY).unwrap();
        }
        let ops = [Op::Union, Op::Intersection, Op::Difference];
        let (mut stored, mut made) = (0, 0);
        for case in 0..40 {
            let mut b = ProgramBuilder::new(&leaves);
            let mut next = rng.gen_range(0..100u32);
            let kids: Vec<u32> = (0..40)
                .map(|_| {
                    // Leaf ids a few apart (a live sync's rows keep them so).
                    let mut leaf = |rng: &mut SmallRng| {
                        next += rng.gen_range(1..4);
                        next
                    };
                    let n = rng.gen_range(1..5);
                    let inner: Vec<u32> = (0..n).map(|_| b.leaf(leaf(&mut rng))).collect();
                    let inner = b.op(ops[rng.gen_range(0..3)], &inner);
                    let m = rng.gen_range(1..5);
                    let mut all: Vec<u32> = (0..m).map(|_| b.leaf(leaf(&mut rng))).collect();
                    all.insert(rng.gen_range(0..=m), inner);
                    b.op(ops[rng.gen_range(1..3)], &all)
                })
                .collect();
            let root = b.op(Op::Union, &kids);
            let prog = b.finish();
            let n = root as usize;
            assert!(prog.wide[n] != u32::MAX, "case {case}: the union is wide");
            let wide = prog.wide_of(n);
            for pos in 0..prog.count[n] {
                let c = prog.child_at(n, pos) as usize;
                if prog.kind[c] == NodeKind::Leaf || !prog.is_tree(c) {
                    continue;
                }
                let want = TreeShape::of(&prog, c).map(|t| if t.count <= PERIODIC { t.with_order(&leaves) } else { t });
                assert_eq!(wide.trees.get(&prog, pos, c), want, "case {case}: child {pos}");
                if want.as_ref().is_some_and(|t| t.count <= PERIODIC) {
                    stored += 1;
                } else {
                    made += 1;
                }
            }
        }
        println!("{stored} stored, {made} made when asked");
        // The order: every leaf but the last once, boxes and half-spaces after the others.
        let kinds = [LeafKind::Sphere, LeafKind::Sphere, LeafKind::Cuboid, LeafKind::HalfSpace, LeafKind::Sphere, LeafKind::Cuboid];
        let mut mixed = LeafTable::default();
        for k in kinds {
            let c = Vec3::ZERO;
            let shape = match k {
                LeafKind::Cuboid => LeafShape::Cuboid(Cuboid { min: c - 0.3, max: c + 0.3 }),
                LeafKind::HalfSpace => LeafShape::HalfSpace(HalfSpace { normal: Vec3::Y, offset: 0.1 }),
                _ => LeafShape::Sphere(Sphere { center: c, radius: 0.4 }),
            };
            mixed.push(&shape, &DAffine3::IDENTITY).unwrap();
        }
        let t = TreeShape::for_tests(6, [5, 4, 3, 2, 1, 0, 0, 0], 0, |p| p[0]).with_order(&mixed);
        let order: Vec<usize> = (0..5).map(|s| t.solve_order(s)).collect();
        assert_eq!(order, [1, 4, 5, 0, 2], "leaves 1, 4, 5 are balls, 0 and 3 boxes, 2 a half-space");
        assert!(stored > 100 && made > 20, "both kinds ran: {stored} stored, {made} made");
    }

    /// `LEAF[j]`'s bit `m` is bit `j` of `m`, for every `m` and `j`.
    #[test]
    fn leaf_patterns_hold_their_bit() {
        for (j, p) in LEAF.iter().enumerate() {
            for m in 0..256u32 {
                assert_eq!(p[(m / 64) as usize] >> (m % 64) & 1, (m >> j) as u64 & 1, "leaf {j} set {m:#b}");
            }
        }
    }
}
