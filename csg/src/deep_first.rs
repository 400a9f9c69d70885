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
//! by. (Elsewhere the sweep answers nothing and the caller goes on as
//! before: the masked try, then the redo in full.)
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
        // (node, flip, depth, children done)
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
            if self.wide[nu] != u32::MAX || depth >= DEEP_DEPTH || self.narrowed(n) {
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
        let DeepLists { shape, words, keys, cross, values } = &mut scratch.deep;
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
                // crossings up to the next one are apart.
                let last = (g + 1).min(keys.len());
                if !apart((0..last).map(place), range, eps2, last == keys.len()) {
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
        apart((0..keys.len()).map(place), range, eps2, true).then_some(DeepFirst::Sure(None))
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
