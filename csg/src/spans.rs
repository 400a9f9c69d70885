//! Interval lists (Roth diagrams) and the Table-1 combine with regularisation.

use rothray_primitives::{Span, SpanSink, Surf};
use smallvec::SmallVec;
use std::sync::atomic::{AtomicU64, Ordering};

/// Inline capacity of a [`SpanList`]: enough for every analytic leaf and for most
/// CSG results; longer lists spill to the heap (counted by [`spill_count`]).
pub const INLINE_SPANS: usize = 8;

static SPILLS: AtomicU64 = AtomicU64::new(0);

/// How many span lists have spilled to the heap since the process started.
pub fn spill_count() -> u64 {
    SPILLS.load(Ordering::Relaxed)
}

/// A sorted list of disjoint spans with inline storage (no heap per ray).
#[derive(Clone, Debug, Default)]
pub struct SpanList(pub SmallVec<[Span; INLINE_SPANS]>);

impl SpanList {
    /// An empty list.
    #[inline(always)]
    pub fn new() -> Self {
        SpanList(SmallVec::new())
    }
    /// Appends (keeping order is the caller's job).
    #[inline(always)]
    pub fn push(&mut self, s: Span) {
        if self.0.len() == INLINE_SPANS {
            SPILLS.fetch_add(1, Ordering::Relaxed);
        }
        self.0.push(s);
    }
    /// Appends `s` (keeping order is the caller's job), span by span:
    /// `SmallVec::extend_from_slice` (an insert at the end, a call to
    /// `memcpy`) cost ~80 instructions and `extend` ~58 (not inlined) for
    /// the one or two spans usually copied (callgrind, scenes/forest).
    #[inline(always)]
    pub fn append(&mut self, s: &[Span]) {
        for &x in s {
            self.0.push(x);
        }
    }
    /// Removes every span.
    #[inline(always)]
    pub fn clear(&mut self) {
        self.0.clear()
    }
    /// Number of spans.
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.0.len()
    }
    /// True when the ray is inside nowhere.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// The spans.
    #[inline(always)]
    pub fn as_slice(&self) -> &[Span] {
        &self.0
    }
    /// Clips every span to `t <= tmax` (clipped ends lose their surface).
    pub fn truncate_at(&mut self, tmax: f32) {
        while let Some(last) = self.0.last_mut() {
            if last.t0 >= tmax {
                self.0.pop();
            } else {
                if last.t1 > tmax {
                    last.t1 = tmax;
                    last.s1 = Surf::NONE;
                }
                break;
            }
        }
    }
}

impl SpanSink for SpanList {
    #[inline(always)]
    fn push_span(&mut self, s: Span) {
        self.push(s)
    }
}

/// A boolean operation of Table 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Op {
    /// Inside either.
    Union,
    /// Inside both.
    Intersection,
    /// Inside the first, not the second.
    Difference,
}

impl Op {
    /// Table 1 on one point: is the result inside, given inside-ness of the operands?
    #[inline(always)]
    pub fn apply(self, a: bool, b: bool) -> bool {
        match self {
            Op::Union => a | b,
            Op::Intersection => a & b,
            Op::Difference => a & !b,
        }
    }
}

#[inline(always)]
fn event(l: &[Span], k: usize) -> (f32, Surf) {
    let s = &l[k >> 1];
    if k & 1 == 0 {
        (s.t0, s.s0)
    } else {
        (s.t1, s.s1)
    }
}

/// Combines two span lists by `op` into `out` (cleared first), regularised:
///
/// * boundaries of `a` and `b` closer than `eps` are fused into one event at `a`'s
///   parameter (so coincident faces of different operands never leave slivers
///   or speckle; when both change the result at once, `a`'s surface wins, so the
///   choice is the same on every pixel; a union keeps one of the two
///   boundaries by a rule that does not look at which operand it came from,
///   see `union_fuse`, so that its result does not depend on the order of
///   its operands);
/// * spans shorter than `eps` are dropped and spans closer than `eps` are merged;
/// * surfaces of `b` that bound a difference are flipped.
pub fn combine(op: Op, a: &[Span], b: &[Span], eps: f32, out: &mut SpanList) {
    out.clear();
    // Fast paths: nothing to merge.
    match op {
        Op::Union => {
            if b.is_empty() {
                out.append(a);
                return;
            }
            if a.is_empty() {
                out.append(b);
                return;
            }
        }
        Op::Intersection => {
            if a.is_empty() || b.is_empty() {
                return;
            }
        }
        Op::Difference => {
            if a.is_empty() {
                return;
            }
            if b.is_empty() {
                out.append(a);
                return;
            }
        }
    }
    let na = a.len() * 2;
    let nb = b.len() * 2;
    let (mut ia, mut ib) = (0usize, 0usize);
    let (mut ina, mut inb, mut inr) = (false, false, false);
    let mut start = (0.0f32, Surf::NONE);
    let flip_b = op == Op::Difference;
    while ia < na || ib < nb {
        let (ta, sa) = if ia < na { event(a, ia) } else { (f32::INFINITY, Surf::NONE) };
        let (tb, sb) = if ib < nb { event(b, ib) } else { (f32::INFINITY, Surf::NONE) };
        let sb = if flip_b { sb.flip() } else { sb };
        let (t, surf);
        let (a_ok, b_ok) = (ia < na, ib < nb);
        // `ta == tb` also fuses two infinite ends (inf - inf is NaN).
        if a_ok && b_ok && (ta == tb || (ta - tb).abs() <= eps) {
            ina = !ina;
            inb = !inb;
            ia += 1;
            ib += 1;
            // One surface for both: a's, unless only b's is real. A union
            // takes the lower leaf index's instead (the earlier operand in
            // the tree's order), which makes its result independent of the
            // order operands are combined in: a wide union's BVH walk and a
            // tile's short list of the same children agree.
            (t, surf) = if op == Op::Union {
                union_fuse((ta, sa), (tb, sb))
            } else if !sa.is_real() && sb.is_real() {
                (ta, sb)
            } else {
                (ta, sa)
            };
        } else if a_ok && (!b_ok || ta < tb) {
            ina = !ina;
            ia += 1;
            t = ta;
            surf = sa;
        } else {
            inb = !inb;
            ib += 1;
            t = tb;
            surf = sb;
        }
        let r = op.apply(ina, inb);
        if r == inr {
            continue;
        }
        inr = r;
        if r {
            // Entering: merge with the previous span when the gap is below eps.
            if let Some(last) = out.0.last() {
                if t - last.t1 <= eps {
                    start = (last.t0, last.s0);
                    out.0.pop();
                    continue;
                }
            }
            start = (t, surf);
        } else if t - start.0 > eps {
            out.push(Span { t0: start.0, t1: t, s0: start.1, s1: surf });
        }
    }
}

/// The one boundary a union keeps of two it fuses, the same whichever
/// operand each comes from, so that a union's result does not depend on
/// the order its operands are combined in (a wide union's BVH walk, a
/// tile's short list and a packet's walk of the same children agree): a
/// real surface over a range end (no surface), of two real ones the lower
/// leaf index's (the earlier operand in the tree's order), of two range
/// ends the nearer.
#[inline(always)]
fn union_fuse(a: (f32, Surf), b: (f32, Surf)) -> (f32, Surf) {
    match (a.1.is_real(), b.1.is_real()) {
        (true, true) if b.1.leaf_index() < a.1.leaf_index() => b,
        (true, _) => a,
        (false, true) => b,
        // (`<`, not `f32::min`, whose choice between -0 and +0 is not
        // specified: the packet merge (`spans8`) must pick the same.)
        (false, false) => (if b.0 < a.0 { b.0 } else { a.0 }, a.1),
    }
}

/// In-place `acc = acc op b` using `tmp` as scratch.
#[inline]
pub fn combine_into(op: Op, acc: &mut SpanList, b: &[Span], eps: f32, tmp: &mut SpanList) {
    combine(op, acc.as_slice(), b, eps, tmp);
    // Copy back the few spans in use; swapping moved two whole inline arrays
    // (2 x 200 bytes) and was ~10% of the logo scene's trace time.
    acc.0.clear();
    acc.append(tmp.as_slice());
}
