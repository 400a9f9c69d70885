//! The first surface of a deep tree on one ray, from a sweep of all its
//! leaves' crossings: the nearest query of an object whose nearest-mode
//! try was not sure, or that is known to leave it unsure (a cut into
//! nested shells, `masked.rs`).
//!
//! The argument of `tree_first.rs` carries over to a tree of any size:
//! where every crossing of the tree's leaves on the range lies more than
//! `2 eps` from the next one and from the range's start, up to the first
//! crossing past the tree's first entry, no `combine` of the tree's full
//! diagram fuses, merges or drops anything there, so the diagram's first
//! span is the exact set operation's. Its entry is a leaf's own crossing,
//! that leaf's surface flipped once for each difference it is subtracted
//! by. Two widenings: crossings before the nearest entry of a leaf no
//! difference subtracts only set the leaves' states (the tree cannot be
//! inside there; `drop_before`), and a cluster of crossings within
//! `2 eps` is harmless where the tree is outside however its leaves are
//! read there (`Sweep::settled`). Elsewhere (an entry in a cluster, the
//! range starting inside) the sweep answers nothing and the caller goes
//! on as before: the masked try, then the redo in full.
//!
//! How: the crossings are sorted once, and the tree's value is made for
//! 64 of the gaps between them at a time: each leaf's inside-ness on those
//! gaps is a 64-bit word (its bits flip at its crossings), and the tree's
//! own operations on those words (OR, AND, AND NOT, in post-order) give
//! the tree's inside-ness on each gap. The first gap inside is the entry.
//!
//! Why: the masked try merged span lists at every level of such a tree
//! (benches/scenes/nesting: 32 shells, 97 leaves; some 26 000
//! instructions a ray, callgrind 480x270 flat), and a full diagram in a
//! window around the entry cost some 19 000 (the frame path's nodes and
//! leaves); here a ray's cost is its leaves' solves and one sort.

use rothray_primitives::{LeafTable, Span, SpanSink, Surf};

use super::{cand_key, cand_of_key, leaf_query, NodeKind, Program, RayCtx, Scratch};
use crate::counts;

/// The most leaves a sweep takes.
pub const DEEP_LEAVES: usize = 1024;

/// The most crossings a sweep takes.
const DEEP_CROSSINGS: usize = 4096;

/// The deepest node a sweep takes.
const DEEP_DEPTH: usize = 512;

/// A post-order step of the tree's value: a leaf's word, or an inner
/// node's operation on the last `count` values.
#[derive(Clone, Copy, Debug)]
enum Step {
    Leaf(u32),
    Node(NodeKind, u32),
}

/// A tree as the sweep reads it, made once per program contents and root
/// ([`Program::serial`]): a ray's own walk of the nodes (a recursion with
/// a call per node) was half of the sweep's instructions.
#[derive(Default)]
struct Shape {
    /// (Program serial, root) it was made for; serial 0: none.
    key: (u64, u32),
    /// Whether the sweep takes the tree.
    fits: bool,
    /// Per leaf slot (post-order).
    leaves: Vec<ShapeLeaf>,
    steps: Vec<Step>,
}

/// What a sweep of a tree's crossings tells ([`Program::deep_first`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DeepFirst {
    /// The full diagram's first surface on the range (`None`: no surface).
    Sure(Option<(f32, Surf)>),
    /// Nothing: crossings within `2 eps` before the entry, the range
    /// starting inside, a tree the sweep does not take. (Not a window to
    /// redo in full around the exact set's entry either: clipped there,
    /// a difference clips its subtrahends to a shorter extent, and that
    /// regularises otherwise, tests/csg_oracle.rs
    /// `near_twin_slivers_from_inside`.)
    Unknown,
}

/// A leaf of a [`Shape`].
#[derive(Clone, Copy, Debug)]
struct ShapeLeaf {
    leaf: u32,
    /// It is subtracted an odd number of times: its surfaces bound the
    /// tree flipped.
    flip: bool,
    /// It is subtracted by no difference: a point inside the tree is
    /// inside one such leaf at least (a union's operand, an
    /// intersection's, a difference's first), so the tree's first entry
    /// is no nearer than theirs.
    positive: bool,
}

/// The lists of a sweep, kept in [`Scratch`] and reused from ray to ray.
#[derive(Default)]
pub(crate) struct DeepLists {
    shape: Shape,
    /// Per leaf slot: its inside-ness on the current 64 gaps.
    words: Vec<u64>,
    /// The crossings as [`cand_key`]s of their place and index into `cross`.
    keys: Vec<u64>,
    /// Per crossing: its leaf slot and its surface as the tree's.
    cross: Vec<(u32, Surf)>,
    values: Vec<u64>,
    /// The leaves' states at the range's start (for [`Sweep::settled`],
    /// which moves them on).
    init: Vec<u64>,
    /// [`Sweep::settled`]'s leaves of unknown state.
    unknown: Vec<u64>,
    /// [`tree_may`]'s stack (two words a value).
    pairs: Vec<u64>,
}

impl Program {
    /// Does [`Program::deep_first`] take node `root`: narrow nodes only, at
    /// most [`DEEP_LEAVES`] leaves, no deeper than [`DEEP_DEPTH`]? (At bake,
    /// per object; a tile's program of it is checked again.)
    pub fn deep_fits(&self, root: u32) -> bool {
        let mut shape = Shape::default();
        self.deep_shape(root, &mut shape);
        shape.fits
    }

    /// Makes `shape` node `root`'s (`fits` false where the sweep does not
    /// take it).
    fn deep_shape(&self, root: u32, shape: &mut Shape) {
        shape.key = (self.serial, root);
        shape.leaves.clear();
        shape.steps.clear();
        // (node, flip, positive, depth, children done)
        let mut stack = vec![(root, false, true, 0usize, false)];
        shape.fits = false;
        while let Some((n, flip, positive, depth, done)) = stack.pop() {
            let nu = n as usize;
            let kind = self.kind[nu];
            if kind == NodeKind::Leaf {
                shape.steps.push(Step::Leaf(shape.leaves.len() as u32));
                shape.leaves.push(ShapeLeaf { leaf: self.first[nu], flip, positive });
                if shape.leaves.len() > DEEP_LEAVES {
                    return;
                }
                continue;
            }
            if done {
                shape.steps.push(Step::Node(kind, self.count[nu]));
                continue;
            }
            // (A node without operands is not one the tree's value can
            // read: its step would take nothing off the stack.)
            if self.wide[nu] != u32::MAX || self.count[nu] == 0 || depth >= DEEP_DEPTH || self.narrowed(n) {
                return;
            }
            stack.push((n, flip, positive, depth, true));
            let first = self.first[nu] as usize;
            let children = &self.children[first..first + self.count[nu] as usize];
            for (k, &c) in children.iter().enumerate().rev() {
                let sub = kind == NodeKind::Difference && k > 0;
                stack.push((c, flip ^ sub, positive && !sub, depth + 1, false));
            }
        }
        shape.fits = true;
    }

    /// The first surface of node `root` on `range` of the ray by a sweep of
    /// its leaves' crossings (see the module's doc and [`DeepFirst`]).
    pub fn deep_first(&self, leaves: &LeafTable, ctx: &RayCtx, root: u32, range: (f32, f32), scratch: &mut Scratch) -> DeepFirst {
        self.deep_sweep(leaves, ctx, root, range, scratch).unwrap_or(DeepFirst::Unknown)
    }

    /// [`Program::deep_first`], `None` for [`DeepFirst::Unknown`].
    #[inline(always)]
    fn deep_sweep(&self, leaves: &LeafTable, ctx: &RayCtx, root: u32, range: (f32, f32), scratch: &mut Scratch) -> Option<DeepFirst> {
        let DeepLists { shape, words, keys, cross, values, init, unknown, pairs } = &mut scratch.deep;
        if shape.key != (self.serial, root) || self.serial == 0 {
            self.deep_shape(root, shape);
        }
        if !shape.fits {
            return None;
        }
        words.clear();
        keys.clear();
        cross.clear();
        if values.len() < shape.leaves.len() {
            values.resize(shape.leaves.len(), 0);
        }
        // The nearest place a positive leaf is inside.
        let mut near = f32::INFINITY;
        let mut solves = ctx.memo.and_then(|(m, k)| m.lane_solves(k));
        let mut served = 0;
        for (slot, l) in shape.leaves.iter().enumerate() {
            let at = keys.len();
            let mut sink = Crossings { keys, cross, slot: slot as u32, flip: l.flip, range, inside: false, cut: false };
            // (A kernel leaf from the packet's solve, read here: through
            // `leaf_query`, the memo was borrowed again for every leaf.)
            let read = leaves.has_kernel8(l.leaf) && solves.as_mut().is_some_and(|s| s.spans(leaves, l.leaf, range, &mut sink));
            if read {
                served += 1;
            } else {
                // (Other kinds take the memo's other records.)
                let again = solves.take().is_some();
                leaf_query(leaves, ctx, l.leaf, range, None, &mut sink);
                solves = ctx.memo.filter(|_| again).and_then(|(m, k)| m.lane_solves(k));
            }
            if sink.cut {
                return None;
            }
            let inside = sink.inside;
            if l.positive {
                near = near.min(if inside { range.0 } else { keys.get(at).map_or(f32::INFINITY, |&k| cand_of_key(k).1) });
            }
            words.push(if inside { !0 } else { 0 });
        }
        drop(solves);
        counts::leaf_batch(served, served);
        if near == f32::INFINITY {
            return Some(DeepFirst::Sure(None)); // (no positive leaf on the range)
        }
        let start = drop_before(near - 4.0 * ctx.eps, (keys, cross), words, range.0);
        let range = (start, range.1);
        if cross.len() > DEEP_CROSSINGS {
            return None;
        }
        keys.sort_unstable();
        init.clone_from(words);
        let eps2 = 2.0 * ctx.eps;
        let place = |i: usize| cand_of_key(keys[i]).1;
        // Gap `g` lies between crossings `g - 1` and `g` (gap 0 from the
        // range's start); the words hold gaps `g0..g0 + 64`.
        let gaps = keys.len() + 1;
        let mut g0 = 0;
        loop {
            // Each crossing flips its leaf's bits from its gap on.
            for g in g0 + 1..(g0 + 64).min(gaps) {
                let (slot, _) = cross[cand_of_key(keys[g - 1]).0 as usize];
                words[slot as usize] ^= !0u64 << (g - g0);
            }
            let mut inside = tree_value(&shape.steps, words, values);
            if gaps - g0 < 64 {
                inside &= (1u64 << (gaps - g0)) - 1;
            }
            if g0 == 0 && inside & 1 != 0 {
                return None; // (the range starts inside)
            }
            if inside != 0 {
                let g = g0 + inside.trailing_zeros() as usize;
                // The entry is crossing g - 1; the sweep is exact where the
                // crossings up to the next one are apart (or those before
                // it are in harmless clusters, and it stands alone).
                let last = (g + 1).min(keys.len());
                let alone = |i: usize| {
                    let before = if i == 0 { range.0 } else { place(i - 1) };
                    let after = if i + 1 < keys.len() { place(i + 1) } else { range.1 };
                    place(i) - before > eps2 && !(after - place(i) <= eps2)
                };
                let sweep = Sweep { keys, cross, steps: &shape.steps, range, eps2 };
                if !alone(g - 1) || !sweep.exact(last, last == keys.len(), (init, unknown, pairs)) {
                    return None;
                }
                let (i, _) = cand_of_key(keys[g - 1]);
                return Some(DeepFirst::Sure(Some((place(g - 1), cross[i as usize].1))));
            }
            if g0 + 64 >= gaps {
                break;
            }
            // The next 64 gaps start as the last one here ends, flipped by
            // the crossing between them.
            for w in words.iter_mut() {
                *w = if *w >> 63 != 0 { !0 } else { 0 };
            }
            let (slot, _) = cross[cand_of_key(keys[g0 + 63]).0 as usize];
            words[slot as usize] ^= !0;
            g0 += 64;
        }
        // Never inside: no surface, where every crossing is apart.
        let sweep = Sweep { keys, cross, steps: &shape.steps, range, eps2 };
        sweep.exact(keys.len(), true, (init, unknown, pairs)).then_some(DeepFirst::Sure(None))
    }

    /// Is node `n` a tile's narrow union written for a wide one, which a
    /// lane's own query evaluates as that wide union ([`Program::narrowed_unions`])?
    #[inline]
    fn narrowed(&self, n: u32) -> bool {
        !self.narrowed_unions.is_empty() && self.narrowed_unions.iter().any(|c| c.0 == n)
    }
}

/// One leaf's spans (as `push_clipped` clips them to `range`) taken as
/// crossings.
struct Crossings<'a> {
    keys: &'a mut Vec<u64>,
    cross: &'a mut Vec<(u32, Surf)>,
    slot: u32,
    flip: bool,
    range: (f32, f32),
    /// A span starts at the range's start (cut there).
    inside: bool,
    /// A span ends without a surface inside the range (the sweep cannot
    /// read it).
    cut: bool,
}

impl SpanSink for Crossings<'_> {
    #[inline(always)]
    fn push_span(&mut self, s: Span) {
        for (t, surf, end) in [(s.t0, s.s0, self.range.0), (s.t1, s.s1, self.range.1)] {
            if surf.is_real() {
                let surf = if self.flip { surf.flip() } else { surf };
                self.keys.push(cand_key(self.cross.len() as u32, t));
                self.cross.push((self.slot, surf));
            } else if t != end {
                self.cut = true;
            }
        }
        if !s.s0.is_real() {
            self.inside = true;
        }
    }
}

/// The tree's inside-ness on 64 gaps from its leaves' `words`, by its
/// post-order `steps`, on the stack `values` (room for one value per leaf).
fn tree_value(steps: &[Step], words: &[u64], values: &mut [u64]) -> u64 {
    let mut sp = 0;
    for &s in steps {
        match s {
            Step::Leaf(slot) => {
                values[sp] = words[slot as usize];
                sp += 1;
            }
            Step::Node(kind, 2) => {
                sp -= 1;
                let (a, b) = (values[sp - 1], values[sp]);
                values[sp - 1] = match kind {
                    NodeKind::Union => a | b,
                    NodeKind::Intersection => a & b,
                    _ => a & !b,
                };
            }
            Step::Node(kind, count) => {
                let base = sp - count as usize;
                let ops = &values[base..sp];
                values[base] = match kind {
                    NodeKind::Union => ops.iter().fold(0, |a, &b| a | b),
                    NodeKind::Intersection => ops.iter().fold(!0, |a, &b| a & b),
                    _ => ops[0] & !ops[1..].iter().fold(0, |a, &b| a | b),
                };
                sp = base + 1;
            }
        }
    }
    if sp == 0 {
        0
    } else {
        values[0]
    }
}

/// Drops the crossings before `cut` (nothing there can be inside the
/// tree: no positive leaf is), each flipping its leaf's word, which then
/// tells whether the leaf is inside at `cut`; returns the last place
/// dropped (`lo` when none). Past it, the crossings kept decide: what
/// `combine` fuses or drops among the dropped ones stays before it.
/// (benches/scenes/nesting: the wedges a ray enters before the onion's
/// outer shell.)
fn drop_before(cut: f32, (keys, cross): (&mut Vec<u64>, &[(u32, Surf)]), words: &mut [u64], lo: f32) -> f32 {
    if !(cut > lo) {
        return lo;
    }
    let mut last = lo;
    keys.retain(|&k| {
        let (i, t) = cand_of_key(k);
        if t < cut {
            words[cross[i as usize].0 as usize] ^= !0;
            last = last.max(t);
        }
        t >= cut
    });
    last
}

/// The sorted crossings of a sweep, read for [`Sweep::settled`].
struct Sweep<'a> {
    keys: &'a [u64],
    cross: &'a [(u32, Surf)],
    steps: &'a [Step],
    range: (f32, f32),
    eps2: f32,
}

impl Sweep<'_> {
    /// Are the crossings before `upto` (and the range's end, with
    /// `to_end`) apart, or in clusters that cannot change the answer
    /// ([`Sweep::settled`])?
    #[inline(always)]
    fn exact(&self, upto: usize, to_end: bool, bufs: (&mut [u64], &mut Vec<u64>, &mut Vec<u64>)) -> bool {
        apart((0..upto).map(|i| cand_of_key(self.keys[i]).1), self.range, self.eps2, to_end) || self.settled(upto, to_end, bufs)
    }

    /// `state` holds the leaves' states at the range's start, and is moved
    /// on crossing by crossing (a sweep asks this once).
    ///
    /// Where crossings are within `2 eps` of one another (or of the
    /// range's ends), `combine` may fuse them, merge or drop what lies
    /// between them: each node's result there is its operation on its
    /// operands' values a little before or after, so each leaf crossed in
    /// such a cluster may be read inside or outside. The tree cannot be
    /// inside there when it is outside for every way of reading them:
    /// its value in three-valued logic, those leaves unknown, is
    /// "outside" (exact for a tree, where each leaf is read once). Are
    /// all clusters among the crossings before `upto` (and at the end,
    /// with `to_end`) such? Then the exact set's answer is the full
    /// diagram's. (Slow path: only where crossings are not apart;
    /// benches/scenes/nesting's shadow rays leave every wedge's box at
    /// once, through the plane of their tops.)
    #[inline(never)]
    fn settled(&self, upto: usize, to_end: bool, (state, unknown, pairs): (&mut [u64], &mut Vec<u64>, &mut Vec<u64>)) -> bool {
        let place = |i: usize| cand_of_key(self.keys[i]).1;
        let slot = |i: usize| self.cross[cand_of_key(self.keys[i]).0 as usize].0 as usize;
        unknown.clear();
        unknown.resize(state.len(), 0);
        let mut i = 0;
        while i < upto {
            // The cluster from crossing i: crossings (and the range's
            // start) each within 2 eps of the one before.
            let near_start = i == 0 && !(place(0) - self.range.0 > self.eps2);
            let mut j = i + 1;
            while j < self.keys.len() && !(place(j) - place(j - 1) > self.eps2) {
                j += 1;
            }
            let near_end = j == self.keys.len() && to_end && !(self.range.1 - place(j - 1) > self.eps2);
            if j - i > 1 || near_start || near_end {
                for k in i..j {
                    unknown[slot(k)] = !0;
                }
                let may = tree_may(self.steps, (state, unknown), pairs);
                for k in i..j {
                    unknown[slot(k)] = 0;
                }
                if may {
                    return false;
                }
            }
            for k in i..j {
                state[slot(k)] ^= !0;
            }
            i = j;
        }
        true
    }
}

/// May the tree be inside where its leaves are inside as `state` says,
/// except those `unknown` says may be either? (Three-valued logic: each
/// value a pair, certainly inside and possibly inside, on the stack
/// `pairs`, two words a value.)
fn tree_may(steps: &[Step], (state, unknown): (&[u64], &[u64]), pairs: &mut Vec<u64>) -> bool {
    pairs.clear();
    for &s in steps {
        match s {
            Step::Leaf(slot) => {
                let (st, un) = (state[slot as usize], unknown[slot as usize]);
                pairs.extend([st & !un, st | un]);
            }
            Step::Node(kind, count) => {
                let base = pairs.len() - 2 * count as usize;
                let ops = &pairs[base..];
                let sure = |k: usize| ops[2 * k];
                let may = |k: usize| ops[2 * k + 1];
                let (mut lo, mut hi) = (0u64, 0u64);
                match kind {
                    NodeKind::Union => {
                        for k in 0..count as usize {
                            (lo, hi) = (lo | sure(k), hi | may(k));
                        }
                    }
                    NodeKind::Intersection => {
                        (lo, hi) = (!0, !0);
                        for k in 0..count as usize {
                            (lo, hi) = (lo & sure(k), hi & may(k));
                        }
                    }
                    _ => {
                        (lo, hi) = (sure(0), may(0));
                        for k in 1..count as usize {
                            (lo, hi) = (lo & !may(k), hi & !sure(k));
                        }
                    }
                }
                pairs.truncate(base);
                pairs.extend([lo, hi]);
            }
        }
    }
    pairs.get(1).is_some_and(|&hi| hi != 0)
}

/// Are the sorted `places` more than `eps2` apart, the first from the
/// range's start, and (with `to_end`) the last from its end?
fn apart(places: impl Iterator<Item = f32>, range: (f32, f32), eps2: f32, to_end: bool) -> bool {
    let mut prev = range.0;
    for t in places {
        if !(t - prev > eps2) {
            return false;
        }
        prev = t;
    }
    !to_end || range.1 == f32::INFINITY || range.1 - prev > eps2
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sorted crossings `(place, slot)` as a sweep keeps them.
    fn crossings(c: &[(f32, u32)]) -> (Vec<u64>, Vec<(u32, Surf)>) {
        let keys = c.iter().enumerate().map(|(i, &(t, _))| cand_key(i as u32, t)).collect();
        let cross = c.iter().map(|&(_, slot)| (slot, Surf::new(slot, 0))).collect();
        (keys, cross)
    }

    /// `(settled, exact)` of the crossings `c` before `upto` of the tree
    /// `steps`, every leaf outside at the start, eps2 = 0.1.
    fn judge(steps: &[Step], c: &[(f32, u32)], upto: usize) -> (bool, bool) {
        let (keys, cross) = crossings(c);
        let init = vec![0u64; steps.iter().filter(|s| matches!(s, Step::Leaf(_))).count()];
        let (mut unknown, mut pairs) = (Vec::new(), Vec::new());
        let sweep = Sweep { keys: &keys, cross: &cross, steps, range: (0.0, 20.0), eps2: 0.1 };
        let settled = sweep.settled(upto, false, (&mut init.clone(), &mut unknown, &mut pairs));
        (settled, sweep.exact(upto, false, (&mut init.clone(), &mut unknown, &mut pairs)))
    }

    #[test]
    fn clusters_settle_only_where_no_reading_is_inside() {
        // L0 minus (L1 union L2). L0 from 1 to 9; L1 and L2 cross within
        // 0.1 of each other.
        let steps = [Step::Leaf(0), Step::Leaf(1), Step::Leaf(2), Step::Node(NodeKind::Union, 2), Step::Node(NodeKind::Difference, 2)];
        // Before L0 enters: outside L0 every reading is outside the tree.
        assert_eq!(judge(&steps, &[(0.50, 1), (0.55, 2), (1.0, 0), (3.0, 1), (4.0, 2), (9.0, 0)], 3), (true, true));
        // Inside L0: L1 leaves as L2 enters, a gap under 0.1 in the
        // subtrahend that a reading may leave open.
        assert_eq!(judge(&steps, &[(1.0, 0), (2.0, 1), (3.0, 1), (3.05, 2), (4.0, 2), (9.0, 0)], 5), (false, false));
        // Apart crossings need no cluster test.
        assert_eq!(judge(&steps, &[(1.0, 0), (2.0, 1), (3.0, 2), (4.0, 1), (5.0, 2), (9.0, 0)], 6), (true, true));
        // A crossing within 0.1 of the range's start is a cluster with it.
        assert_eq!(judge(&steps, &[(0.05, 1), (1.0, 0), (2.0, 1), (9.0, 0)], 2), (true, true));
        assert_eq!(judge(&steps, &[(0.05, 0), (1.0, 1), (2.0, 1), (9.0, 0)], 2), (false, false));
        // L0 minus eight leaves that all end in one cluster: inside L0,
        // where a reading may open a gap, not settled; past L0 (the wedges'
        // tops above benches/scenes/nesting), settled.
        let eight: Vec<Step> = (0..9).map(Step::Leaf).chain([Step::Node(NodeKind::Difference, 9)]).collect();
        let mut c: Vec<(f32, u32)> = vec![(0.2, 0), (9.0, 0)];
        c.extend((1..9).map(|j| (0.5 + 0.3 * j as f32, j)));
        c.extend((1..9).map(|j| (5.0 + 0.01 * j as f32, j)));
        c.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(judge(&eight, &c, c.len()), (false, false), "a cluster inside L0");
        let mut c: Vec<(f32, u32)> = vec![(0.2, 0), (9.0, 0)];
        c.extend((1..9).map(|j| (0.5 + 0.3 * j as f32, j)));
        c.extend((1..9).map(|j| (12.0 + 0.01 * j as f32, j)));
        c.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(judge(&eight, &c, c.len()), (true, true), "a cluster past L0");
        // A union of eight leaves entering in one cluster may be inside.
        let union: Vec<Step> = (0..8).map(Step::Leaf).chain([Step::Node(NodeKind::Union, 8)]).collect();
        let c: Vec<(f32, u32)> = (0..8).map(|j| (5.0 + 0.01 * j as f32, j)).collect();
        assert_eq!(judge(&union, &c, 8), (false, false));
    }
}
