//! A nearest query's second try, for an object whose first try
//! ([`Mode::Nearest`]) found nothing sure: the unions under its differences
//! stop at their first entry that the differences above keep, not at their
//! first entry.
//!
//! Why: in nearest mode a union stops a little past its first confirmed
//! entry, and a difference then asks its subtrahends only up to there.
//! Where a subtrahend covers that entry (a cut into nested shells: the
//! ray enters the outer shell inside the cut) the result is empty up to
//! the stop, and the query was redone in full ([`Mode::All`]): every leaf
//! of the object over the whole ray, every span merged (scenes/nesting:
//! 83% of its instructions, callgrind 480x270 flat).
//!
//! How: a difference asks its subtrahends first, in full over the range
//! its positive operand's box covers, and hands their union down to its
//! positive operand as a mask, together with the masks from above. A
//! union under a mask stops a little past the first place where its
//! spans leave the mask, the first place the differences above can
//! keep. The spans are then combined in the frame path's order (the
//! positive operand, then each subtrahend, each clipped to the
//! accumulator's extent as the frame path asks it), so the result is the
//! full diagram up to where it is exact, bit for bit: nearest hits are
//! the full diagram's first surfaces (tests/csg_oracle.rs
//! `second_tries_under_masks_give_the_full_diagrams_first_surface`).
//! Nodes of other kinds, and the frame path's own shortcuts (leafy nodes,
//! small trees, wide nodes), are evaluated by [`Program::eval_in`]: in
//! full under a mask, else in nearest mode as the first try did.
//!
//! A stop in the wrong place cannot give a wrong answer, only a slower
//! one: the result is exact up to where it says, and the caller judges
//! its first surface as after the first try; an unsure one is redone in
//! full as before.
//!
//! Spans wholly inside the mask are kept, though the differences above
//! remove them: dropped, they no longer merged at every level above
//! (scenes/nesting 0.144 s -> 0.103 s at 480x270 flat), but a list's
//! extent moved, and with it where the subtrahends above are clipped,
//! and a clip within eps of a boundary fuses it otherwise (4 pixels of
//! scenes/nesting at 320x180 took another surface than the full
//! diagram's).
//!
//! An object whose root is such a difference takes this try at once
//! (`engine/src/scene.rs`, `Retry::masked_first`): its first try in nearest
//! mode was mostly unsure (benches/scenes/nesting, sweep_csg: -7.4% and
//! -7.3% instructions, callgrind 480x270 flat; the check cost scenes
//! without such objects up to +0.5%: logo +0.48%, fill +0.40%, gear
//! +0.32%). Other objects take it second, when their first try was not
//! sure. [`Program::masks_help`] says which: a union must lie under a
//! difference's positive operand, the only place a mask changes a stop.
//!
//! The recursion is bounded ([`MASKED_DEPTH`]): a deeper node is
//! evaluated in full by the frame path, which has no recursion.

use rothray_primitives::{table::push_clipped, Span};

use super::{leaf_spans, Ask, Mode, NodeKind, Program, Scratch};
use crate::spans::{combine_into, Op, SpanList};

/// Inner nodes deeper than this below the root are evaluated in full by
/// the frame path instead.
pub const MASKED_DEPTH: usize = 96;

/// The span lists one level of the recursion may use: a union 2, a
/// difference 3 plus one per subtrahend (a narrow difference has at most
/// [`super::WIDE_THRESHOLD`] of them).
const LEVEL_LISTS: usize = 3 + super::WIDE_THRESHOLD;

/// How many nodes [`Program::masks_help`] looks at, at most.
const HELP_WALK: usize = 64;

/// The lists of a masked evaluation, one group per depth (kept in
/// [`Scratch`] and reused from ray to ray).
#[derive(Default)]
pub(crate) struct MaskLists {
    lists: Vec<SpanList>,
}

impl Program {
    /// Does the masked try ([`Program::eval_masked`]) differ from the full
    /// redo at `root`? Only where a union (one that is not a small tree or
    /// wide) lies under a narrow difference's positive operand, reached
    /// from the root through narrow unions and differences: masks change
    /// only where unions stop. (A walk of at most [`HELP_WALK`] nodes,
    /// without allocating; past that it answers yes.)
    pub fn masks_help(&self, root: u32) -> bool {
        if !self.masked_node(root as usize) {
            return false;
        }
        // (node, under a difference's positive operand)
        let mut stack = [(0u32, false); HELP_WALK];
        stack[0] = (root, false);
        let mut len = 1;
        let mut seen = 0;
        while len > 0 {
            len -= 1;
            let (n, under) = stack[len];
            let n = n as usize;
            let union = self.kind[n] == NodeKind::Union && self.wide[n] == u32::MAX && !self.small_root(n);
            if union && under {
                return true;
            }
            if !self.masked_node(n) {
                continue;
            }
            let (first, count) = (self.first[n] as usize, self.count[n] as usize);
            // A difference's subtrahends are asked in full: only its
            // positive operand matters.
            let (ch, under) = match self.kind[n] {
                NodeKind::Difference => (&self.children[first..first + 1], true),
                _ => (&self.children[first..first + count], under),
            };
            seen += 1;
            if seen > HELP_WALK || len + ch.len() > HELP_WALK {
                return true;
            }
            for &c in ch {
                stack[len] = (c, under);
                len += 1;
            }
        }
        false
    }

    /// The nodes the masked recursion takes apart itself: narrow unions and
    /// differences that the frame path does not evaluate in one piece.
    #[inline]
    fn masked_node(&self, n: usize) -> bool {
        matches!(self.kind[n], NodeKind::Union | NodeKind::Difference)
            && self.wide[n] == u32::MAX
            && !self.frameless(n)
            && !self.small_root(n)
    }

    /// Node `root`'s result for a nearest query on `range`, into
    /// `scratch.out`, tried with masks (see the module's doc); returns
    /// where the result stops being exact. The caller judges the first
    /// surface as after [`Mode::Nearest`].
    pub fn eval_masked(
        &self,
        ask: (&rothray_primitives::LeafTable, &super::RayCtx),
        root: u32,
        range: (f32, f32),
        scratch: &mut Scratch,
    ) -> f32 {
        let (leaves, ctx) = ask;
        let mut lists = std::mem::take(&mut scratch.masked);
        if lists.lists.len() < LEVEL_LISTS * MASKED_DEPTH {
            lists.lists.resize_with(LEVEL_LISTS * MASKED_DEPTH, SpanList::new);
        }
        let (out, free) = lists.lists.split_first_mut().expect("lists");
        let ask = Ask { leaves, ctx, mode: Mode::Nearest };
        let valid = self.masked(root as usize, ask, range, (&[], out, free), scratch, 0);
        scratch.out.clear();
        scratch.out.append(out.as_slice());
        scratch.masked = lists;
        valid.min(range.1)
    }

    /// Node `n` on `(lo, hi)` under `mask` into `out` (`free`: the lists of
    /// the levels below); returns where `out` stops being exact.
    fn masked(
        &self,
        n: usize,
        ask: Ask,
        (lo, hi): (f32, f32),
        (mask, out, free): (&[Span], &mut SpanList, &mut [SpanList]),
        scratch: &mut Scratch,
        depth: usize,
    ) -> f32 {
        out.clear();
        let ctx = ask.ctx;
        if self.kind[n] == NodeKind::Leaf {
            let nearest = if mask.is_empty() { Some(ctx.nearest_slack()) } else { None };
            return leaf_spans(ask.leaves, ctx, self.first[n], (lo, hi), nearest, out);
        }
        if depth >= MASKED_DEPTH || !self.masked_node(n) || free.len() < LEVEL_LISTS {
            // What the frame path gives: in full under a mask (a nearest
            // stop could fall where the mask hides it).
            let mode = if mask.is_empty() { Mode::Nearest } else { Mode::All };
            let v = self.eval_in(ask.leaves, n as u32, ctx, (lo, hi), mode, scratch);
            out.append(scratch.out.as_slice());
            return v;
        }
        if self.bounds[n].ray_range(ctx.ray.origin, ctx.ray.inv_dir, lo, hi).is_none() {
            return f32::INFINITY;
        }
        if self.kind[n] == NodeKind::Union {
            self.masked_union(n, ask, (lo, hi), (mask, out, free), scratch, depth)
        } else {
            self.masked_difference(n, ask, (lo, hi), (mask, out, free), scratch, depth)
        }
    }

    /// A narrow union under `mask`: its operands in order, on a range that
    /// ends a little past the first place its spans leave the mask.
    fn masked_union(
        &self,
        n: usize,
        ask: Ask,
        (lo, mut hi): (f32, f32),
        (mask, acc, free): (&[Span], &mut SpanList, &mut [SpanList]),
        scratch: &mut Scratch,
        depth: usize,
    ) -> f32 {
        let eps = ask.ctx.eps;
        let (first, count) = (self.first[n] as usize, self.count[n] as usize);
        let (lists, deeper) = free.split_at_mut(2);
        let [res, tmp] = lists else { unreachable!() };
        let mut valid = f32::INFINITY;
        for k in 0..count {
            let c = self.children[first + k] as usize;
            if self.kind[c] != NodeKind::Leaf && self.bounds[c].ray_range(ask.ctx.ray.origin, ask.ctx.ray.inv_dir, lo, hi).is_none() {
                continue;
            }
            let v = self.masked(c, ask, (lo, hi), (mask, res, deeper), scratch, depth + 1);
            if v < valid {
                valid = v;
                hi = hi.min(v);
                acc.truncate_at(v);
            }
            if acc.is_empty() {
                acc.append(res.as_slice());
                acc.truncate_at(hi);
            } else if !res.is_empty() {
                combine_into(Op::Union, acc, res.as_slice(), eps, tmp);
            }
            if let Some(t) = first_unmasked(acc.as_slice(), mask, eps) {
                let v = super::entry_stop(t, eps);
                if v < hi {
                    acc.truncate_at(v);
                    hi = v;
                    valid = v;
                }
            }
        }
        valid
    }

    /// A narrow difference under `mask`: its subtrahends first, in full on
    /// the range its positive operand's box covers; its positive operand
    /// under `mask` and their union; then the frame path's subtractions.
    fn masked_difference(
        &self,
        n: usize,
        ask: Ask,
        (lo, hi): (f32, f32),
        (mask, acc, free): (&[Span], &mut SpanList, &mut [SpanList]),
        scratch: &mut Scratch,
        depth: usize,
    ) -> f32 {
        let (leaves, ctx) = (ask.leaves, ask.ctx);
        let eps = ctx.eps;
        let (first_child, count) = (self.first[n] as usize, self.count[n] as usize);
        let pos = self.children[first_child] as usize;
        let Some((p0, p1)) = self.bounds[pos].ray_range(ctx.ray.origin, ctx.ray.inv_dir, lo, hi) else { return f32::INFINITY };
        let (subs, rest) = free.split_at_mut(count - 1);
        let (lists, deeper) = rest.split_at_mut(3);
        let [joint, res, tmp] = lists else { unreachable!() };
        joint.clear();
        joint.append(mask);
        for (k, sub) in subs.iter_mut().enumerate() {
            let c = self.children[first_child + 1 + k];
            self.eval_in(leaves, c, ctx, (p0, p1), Mode::All, scratch);
            sub.clear();
            sub.append(scratch.out.as_slice());
            if !sub.is_empty() {
                if joint.is_empty() {
                    joint.append(sub.as_slice());
                } else {
                    combine_into(Op::Union, joint, sub.as_slice(), eps, tmp);
                }
            }
        }
        let valid = self.masked(pos, ask, (lo, hi), (joint.as_slice(), res, deeper), scratch, depth + 1);
        acc.append(res.as_slice());
        for (k, sub) in subs.iter().enumerate() {
            let (Some(first), Some(last)) = (acc.as_slice().first(), acc.last()) else { break };
            // The frame path asks each subtrahend on the accumulator's
            // extent, and a clipped end is no surface: a leaf's spans
            // clipped to it are the same bits; another node is asked again.
            let range = (lo.max(first.t0), hi.min(last.t1));
            let c = self.children[first_child + 1 + k];
            res.clear();
            if self.kind[c as usize] == NodeKind::Leaf {
                for &s in sub.as_slice() {
                    push_clipped(res, s, range.0, range.1);
                }
            } else if self.bounds[c as usize].ray_range(ctx.ray.origin, ctx.ray.inv_dir, range.0, range.1).is_some() {
                self.eval_in(leaves, c, ctx, range, Mode::All, scratch);
                res.append(scratch.out.as_slice());
            }
            if !res.is_empty() {
                combine_into(Op::Difference, acc, res.as_slice(), eps, tmp);
            }
        }
        valid
    }
}

/// The first place where `spans` have a real boundary and then go on
/// outside `mask` for more than 2 eps (a shorter piece may be dropped by
/// the differences' regularisation): where a difference above may keep
/// them. `None` when there is no such place.
fn first_unmasked(spans: &[Span], mask: &[Span], eps: f32) -> Option<f32> {
    let mut j = 0;
    for s in spans {
        // Where the span starts, and whether a real surface is there.
        let (mut x, mut real) = (s.t0, s.s0.is_real());
        while j < mask.len() && mask[j].t1 <= x {
            j += 1;
        }
        let mut m = j;
        while x < s.t1 {
            let gap_end = if m < mask.len() { mask[m].t0.min(s.t1) } else { s.t1 };
            if gap_end - x > 2.0 * eps && real {
                return Some(x);
            }
            if m >= mask.len() || mask[m].t0 >= s.t1 {
                break;
            }
            // Past this mask span: its end is the subtrahend's exit.
            x = x.max(mask[m].t1);
            real = mask[m].s1.is_real();
            m += 1;
        }
    }
    None
}
