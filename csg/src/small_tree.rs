//! Small trees evaluated whole: an inner node whose subtree has only
//! narrow nodes and at most [`SMALL_LEAVES`] leaves, every one an analytic
//! leaf with a packet kernel ([`LeafTable::has_kernel8`]), is evaluated in
//! one recursive pass for its full diagram (what [`Mode::All`] gives, bit
//! for bit), whatever mode its caller asks for.
//!
//! Why: for such a tree the modes hardly differ. These leaves answer a
//! nearest query with all their spans (one each), so a nearest evaluation
//! saves only the stops of its unions at their first entries, while its
//! frames (push, pick the next child, absorb, pop) and their mode and
//! exactness bookkeeping cost several times the spans' own work
//! (scenes/logo, a difference of two such nodes: the frame path and the
//! leaf loop were half of its cycles, perf, one thread).
//!
//! Why the full diagram is a right answer for every mode: it is exact
//! everywhere (`valid` is infinite), which [`Mode::Nearest`] and
//! [`Mode::Before`] only ask up to their stops; and the nearest answer is
//! its first surface (tests/csg_oracle.rs checks nearest hits against the
//! full diagram's first surfaces over random trees).
//!
//! The pass takes the same steps as the frame path in [`Mode::All`] (the
//! same box tests of inner nodes' operands, the same narrowing of an
//! intersection's or difference's range to its accumulator's extent, the
//! same first operand taken as it is), so the diagrams are the same bits:
//! `small_trees_are_their_full_diagrams` in this crate's tests compares
//! them.

use rothray_primitives::LeafTable;

use super::{counts, Ask, NodeKind, Program, RayCtx};
use crate::spans::{combine_into, Op, SpanList};

/// At most this many leaves in a small tree: a nearest evaluation of a
/// larger one may save more by its stops than the frames cost.
pub const SMALL_LEAVES: u32 = 16;

/// What [`Program::small`] holds for a node: for a leaf, 1 when it has a
/// packet kernel; for an inner node, its leaf count when it is a small
/// tree's root (narrow, and every operand a small tree or such a leaf,
/// [`SMALL_LEAVES`] at most); else 0.
pub(crate) fn small_of(kind: NodeKind, wide: bool, kids: impl Iterator<Item = u8>) -> u8 {
    if kind == NodeKind::Leaf || wide {
        return 0;
    }
    let mut sum = 0u32;
    for s in kids {
        if s == 0 {
            return 0;
        }
        sum += s as u32;
    }
    if sum <= SMALL_LEAVES {
        sum as u8
    } else {
        0
    }
}

/// The span lists of a pass: the result, one accumulator per depth below
/// it, a leaf's spans and `combine`'s scratch.
pub(crate) struct SmallLists<'s> {
    pub(crate) out: &'s mut SpanList,
    pub(crate) deeper: &'s mut Vec<SpanList>,
    pub(crate) leaf: &'s mut SpanList,
    pub(crate) tmp: &'s mut SpanList,
}

impl Program {
    /// Is inner node `n` a small tree's root evaluated by [`Program::small_eval`]?
    /// (A node whose operands are all leaves keeps its own loop,
    /// `leaf_node`, which in nearest mode stops a union at its first entry.)
    #[inline(always)]
    pub fn small_root(&self, n: usize) -> bool {
        self.small[n] != 0 && !self.leafy[n]
    }

    /// The full diagram of small tree `n` on `range` into `lists.out`
    /// (`n`'s own box is the caller's to test).
    pub(crate) fn small_eval(&self, n: usize, ask: Ask, range: (f32, f32), lists: SmallLists) {
        // Depth is below the leaf count.
        if lists.deeper.len() < SMALL_LEAVES as usize {
            lists.deeper.resize_with(SMALL_LEAVES as usize, SpanList::new);
        }
        let SmallLists { out, deeper, leaf, tmp } = lists;
        self.small_node(n, ask, range, out, (deeper, leaf, tmp));
    }

    /// Node `n`'s full diagram on `(lo, hi)` into `acc` (`deeper` holds
    /// its operands' results, one list per depth).
    fn small_node(
        &self,
        n: usize,
        ask: Ask,
        (mut lo, mut hi): (f32, f32),
        acc: &mut SpanList,
        (deeper, leaf, tmp): (&mut [SpanList], &mut SpanList, &mut SpanList),
    ) {
        let Ask { leaves, ctx, .. } = ask;
        acc.clear();
        let kind = self.kind[n];
        let op = kind.op();
        let (first, count) = (self.first[n] as usize, self.count[n] as usize);
        // The frame path tests each operand's box (on the narrowed range);
        // the leaf loop (`leaf_node`) does not: its operands are leaves.
        let tests = !self.leafy[n];
        let ray = &ctx.ray;
        for k in 0..count {
            let c = self.children[first + k] as usize;
            if tests && self.bounds[c].ray_range(ray.origin, ray.inv_dir, lo, hi).is_none() {
                match kind {
                    NodeKind::Intersection => {
                        acc.clear();
                        counts::early_out();
                        return;
                    }
                    NodeKind::Difference if k == 0 => {
                        counts::early_out();
                        return;
                    }
                    _ => continue,
                }
            }
            // The first operand (or a union's first non-empty one) is taken as
            // it is, unregularised, as in both paths of the evaluator.
            let direct = k == 0 || (kind == NodeKind::Union && acc.is_empty());
            if self.kind[c] == NodeKind::Leaf {
                if direct {
                    acc.clear();
                    kernel_leaf(leaves, ctx, self.first[c], (lo, hi), acc);
                } else {
                    leaf.clear();
                    kernel_leaf(leaves, ctx, self.first[c], (lo, hi), leaf);
                    join(op, acc, leaf, ctx.eps, tmp);
                }
            } else {
                let (r, rest) = deeper.split_first_mut().expect("a list per depth");
                self.small_node(c, ask, (lo, hi), r, (rest, &mut *leaf, &mut *tmp));
                if direct {
                    acc.clear();
                    acc.append(r.as_slice());
                } else {
                    join(op, acc, r, ctx.eps, tmp);
                }
            }
            if kind != NodeKind::Union {
                let s = acc.as_slice();
                if s.is_empty() {
                    counts::early_out();
                    return;
                }
                lo = lo.max(s[0].t0);
                hi = hi.min(s[s.len() - 1].t1);
            }
        }
    }
}

/// Leaf `i`'s spans on `(lo, hi)` into `out`, for a leaf with a packet
/// kernel (every leaf of a small tree): what `leaf_spans` gives it in full
/// mode (from the packet's solve when the ray has one, else its own query;
/// exact everywhere), without the branches for the other kinds.
#[inline(always)]
fn kernel_leaf(leaves: &LeafTable, ctx: &RayCtx, i: u32, (lo, hi): (f32, f32), out: &mut SpanList) {
    debug_assert!(leaves.has_kernel8(i) && out.is_empty());
    counts::leaf();
    if let Some((memo, k)) = ctx.memo {
        if memo.leaf_lane(leaves, i, k, (lo, hi), out).is_some() {
            return;
        }
    }
    leaves.spans_for(i, &ctx.ray, (lo, hi), None, out);
}

/// `acc = acc op r` for a later operand `r`: an empty one leaves a union or
/// difference as it is and empties an intersection (as `combine` would).
#[inline(always)]
fn join(op: Op, acc: &mut SpanList, r: &SpanList, eps: f32, tmp: &mut SpanList) {
    if !r.is_empty() {
        combine_into(op, acc, r.as_slice(), eps, tmp);
    } else if op == Op::Intersection {
        acc.clear();
    }
}
