//! Interval lists (Roth diagrams) and the Table-1 combine with regularisation.

use rothray_primitives::{Span, SpanSink, Surf};
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
///
/// Its own inline array and spill vector rather than a `SmallVec`: every
/// `SmallVec` access branches on where the data lives and reads the length
/// out of the capacity word, which cost ~7% of scenes/logo's instructions
/// (callgrind, the `smallvec` lines inlined into the evaluator); here the
/// inline path of `push`, `as_slice`, `last` and `pop` is one test.
#[derive(Clone)]
pub struct SpanList {
    /// Spans in use: `inline[..len]`, or all of `heap` once spilled.
    len: usize,
    spilled: bool,
    inline: [Span; INLINE_SPANS],
    heap: Vec<Span>,
}

/// What unused inline slots hold.
const NO_SPAN: Span = Span { t0: 0.0, t1: 0.0, s0: Surf::NONE, s1: Surf::NONE };

impl Default for SpanList {
    fn default() -> Self {
        SpanList::new()
    }
}

impl std::fmt::Debug for SpanList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl SpanList {
    /// An empty list.
    #[inline(always)]
    pub fn new() -> Self {
        SpanList { len: 0, spilled: false, inline: [NO_SPAN; INLINE_SPANS], heap: Vec::new() }
    }
    /// Appends (keeping order is the caller's job).
    #[inline(always)]
    pub fn push(&mut self, s: Span) {
        if !self.spilled && self.len < INLINE_SPANS {
            // Field by field: a span made in registers (a kernel's, clipped)
            // was stored to the stack in pieces and copied here with wider
            // loads, which stalled on store forwarding (27% of the cycles of
            // `object_first` on benches/scenes/ground, perf).
            let d = &mut self.inline[self.len];
            d.t0 = s.t0;
            d.t1 = s.t1;
            d.s0 = s.s0;
            d.s1 = s.s1;
            self.len += 1;
        } else {
            self.push_spilled(s);
        }
    }
    /// [`SpanList::push`] past the inline capacity: the spans move to the
    /// heap (once per list), and go there from then on.
    #[inline(never)]
    fn push_spilled(&mut self, s: Span) {
        if !self.spilled {
            SPILLS.fetch_add(1, Ordering::Relaxed);
            self.heap.clear();
            self.heap.extend_from_slice(&self.inline[..self.len]);
            self.spilled = true;
        }
        self.heap.push(s);
        self.len += 1;
    }
    /// Appends `s` (keeping order is the caller's job), span by span (the
    /// one or two spans usually copied; a bulk copy is a call to `memcpy`).
    #[inline(always)]
    pub fn append(&mut self, s: &[Span]) {
        for &x in s {
            self.push(x);
        }
    }
    /// Removes every span.
    #[inline(always)]
    pub fn clear(&mut self) {
        self.len = 0;
        if self.spilled {
            self.spilled = false;
            self.heap.clear();
        }
    }
    /// Number of spans.
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.len
    }
    /// True when the ray is inside nowhere.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The spans.
    #[inline(always)]
    pub fn as_slice(&self) -> &[Span] {
        if self.spilled {
            &self.heap
        } else {
            &self.inline[..self.len]
        }
    }
    /// The last span.
    #[inline(always)]
    pub fn last(&self) -> Option<&Span> {
        self.as_slice().last()
    }
    /// The last span, to change it.
    #[inline(always)]
    fn last_mut(&mut self) -> Option<&mut Span> {
        if self.spilled {
            self.heap.last_mut()
        } else {
            self.inline[..self.len].last_mut()
        }
    }
    /// Removes the last span.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<Span> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        if self.spilled {
            self.heap.pop()
        } else {
            Some(self.inline[self.len])
        }
    }
    /// Clips every span to `t <= tmax` (clipped ends lose their surface).
    pub fn truncate_at(&mut self, tmax: f32) {
        while let Some(last) = self.last_mut() {
            if last.t0 >= tmax {
                self.pop();
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

/// A span list read as its sequence of boundaries (events), for the merge.
trait Events: Copy {
    /// How many events (twice the spans).
    fn count(self) -> usize;
    /// Event `k` (`k < count()`): a span's start at even `k`, its end at odd.
    fn event(self, k: usize) -> (f32, Surf);
}

impl Events for &[Span] {
    #[inline(always)]
    fn count(self) -> usize {
        self.len() * 2
    }

    #[inline(always)]
    fn event(self, k: usize) -> (f32, Surf) {
        let s = &self[k >> 1];
        if k & 1 == 0 {
            (s.t0, s.s0)
        } else {
            (s.t1, s.s1)
        }
    }
}

/// A list of exactly one span, its events in registers: the merge of two
/// such lists (an intersection of half-spaces, a leaf against a one-span
/// result) is most of what `combine` does on scenes/polytopes.
#[derive(Clone, Copy)]
struct One([f32; 2], [Surf; 2]);

impl One {
    #[inline(always)]
    fn of(s: &Span) -> One {
        One([s.t0, s.t1], [s.s0, s.s1])
    }
}

impl Events for One {
    #[inline(always)]
    fn count(self) -> usize {
        2
    }

    #[inline(always)]
    fn event(self, k: usize) -> (f32, Surf) {
        (self.0[k & 1], self.1[k & 1])
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
    // One copy of the merge per operation: Table 1, the fusing rule and the
    // flip of b's surfaces are then fixed in each copy's event loop.
    match op {
        Op::Union => combine_op::<UNION>(a, b, eps, out),
        Op::Intersection => combine_op::<INTERSECTION>(a, b, eps, out),
        Op::Difference => combine_op::<DIFFERENCE>(a, b, eps, out),
    }
}

const UNION: u8 = Op::Union as u8;
const INTERSECTION: u8 = Op::Intersection as u8;
const DIFFERENCE: u8 = Op::Difference as u8;

/// The operation of code `op` (`Op as u8`: a const generic parameter).
#[inline(always)]
const fn op_of(op: u8) -> Op {
    match op {
        UNION => Op::Union,
        INTERSECTION => Op::Intersection,
        _ => Op::Difference,
    }
}

/// [`combine`] for the operation `OP` (`Op as u8`).
#[inline(always)]
fn combine_op<const OP: u8>(a: &[Span], b: &[Span], eps: f32, out: &mut SpanList) {
    let op = op_of(OP);
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
    if let ([x], [y]) = (a, b) {
        return merge_one::<OP>(One::of(x), One::of(y), eps, out);
    }
    merge_events::<OP, _, _>(a, b, eps, out)
}

/// [`merge_events`] of two one-span lists (`out` cleared); an intersection
/// or a difference in closed form:
/// the loop's path through at most four events, with the loop's own tests
/// (fusing within eps, `<`) in the loop's order and its rules for entering
/// (merge with the previous span across a gap below eps) and leaving (drop
/// a span below eps), so the same answers for every input (ends within eps,
/// equal, infinite, NaN, inverted spans: `one_span_merge_is_the_general_loop`).
#[inline(always)]
fn merge_one<const OP: u8>(a: One, b: One, eps: f32, out: &mut SpanList) {
    if OP == UNION {
        // (In closed form too, a union cost scenes/cheese 1.3% more
        // instructions than through the loop; measured while the wide
        // union's visits still inlined the merge, not since.)
        return merge_events::<OP, _, _>(a, b, eps, out);
    }
    let span = |o: One| Span { t0: o.0[0], t1: o.0[1], s0: o.1[0], s1: o.1[1] };
    let (a, b) = (span(a), span(b));
    let fuse = |x: f32, y: f32| x == y || (x - y).abs() <= eps;
    // One surface for two fused boundaries (not a union's): a's, unless
    // only b's is real.
    let pick = |sa: Surf, sb: Surf| if !sa.is_real() && sb.is_real() { sb } else { sa };
    let mut o = Emit { out, eps };
    match OP {
        INTERSECTION => {
            let start = if fuse(a.t0, b.t0) {
                (a.t0, pick(a.s0, b.s0))
            } else if a.t0 < b.t0 {
                // a enters first; b must enter before a leaves (a leaving
                // with b entering, fused, is no overlap).
                if fuse(a.t1, b.t0) || a.t1 < b.t0 {
                    return;
                }
                (b.t0, b.s0)
            } else {
                if fuse(a.t0, b.t1) || !(a.t0 < b.t1) {
                    return;
                }
                (a.t0, a.s0)
            };
            let end = if fuse(a.t1, b.t1) {
                (a.t1, pick(a.s1, b.s1))
            } else if a.t1 < b.t1 {
                (a.t1, a.s1)
            } else {
                (b.t1, b.s1)
            };
            o.leave(start, end);
        }
        _ => {
            // a minus b: b's boundaries bound the result flipped.
            let (b0, b1) = ((b.t0, b.s0.flip()), (b.t1, b.s1.flip()));
            // Both inside: the result starts again where b leaves before a.
            let b_leaves_first = |o: &mut Emit| {
                if !fuse(a.t1, b.t1) && !(a.t1 < b.t1) {
                    let st = o.enter(b1);
                    o.leave(st, (a.t1, a.s1));
                }
            };
            if fuse(a.t0, b.t0) {
                b_leaves_first(&mut o);
            } else if a.t0 < b.t0 {
                let st = o.enter((a.t0, a.s0));
                if fuse(a.t1, b.t0) {
                    o.leave(st, (a.t1, pick(a.s1, b0.1)));
                } else if a.t1 < b.t0 {
                    o.leave(st, (a.t1, a.s1));
                } else {
                    o.leave(st, b0);
                    b_leaves_first(&mut o);
                }
            } else if fuse(a.t0, b.t1) {
                let st = o.enter((a.t0, pick(a.s0, b1.1)));
                o.leave(st, (a.t1, a.s1));
            } else if a.t0 < b.t1 {
                b_leaves_first(&mut o);
            } else {
                let st = o.enter((a.t0, a.s0));
                o.leave(st, (a.t1, a.s1));
            }
        }
    }
}

/// The result list being written by [`merge_one`], with the event loop's
/// rules for entering and leaving.
struct Emit<'a> {
    out: &'a mut SpanList,
    eps: f32,
}

impl Emit<'_> {
    /// The result enters at `at`: returns where its span starts (the
    /// previous span's start when the gap to its end is below eps).
    #[inline(always)]
    fn enter(&mut self, at: (f32, Surf)) -> (f32, Surf) {
        if let Some(last) = self.out.last() {
            if at.0 - last.t1 <= self.eps {
                let st = (last.t0, last.s0);
                self.out.pop();
                return st;
            }
        }
        at
    }

    /// The result leaves at `end`: its span from `start` is kept when
    /// longer than eps.
    #[inline(always)]
    fn leave(&mut self, start: (f32, Surf), end: (f32, Surf)) {
        if end.0 - start.0 > self.eps {
            self.out.push(Span { t0: start.0, t1: end.0, s0: start.1, s1: end.1 });
        }
    }
}

/// The event loop of [`combine`] for the operation `OP` on two non-empty
/// lists (`out` cleared).
#[inline(always)]
fn merge_events<const OP: u8, A: Events, B: Events>(a: A, b: B, eps: f32, out: &mut SpanList) {
    let op = op_of(OP);
    let na = a.count();
    let nb = b.count();
    let (mut ia, mut ib) = (0usize, 0usize);
    let (mut ina, mut inb, mut inr) = (false, false, false);
    let mut start = (0.0f32, Surf::NONE);
    let flip_b = op == Op::Difference;
    while ia < na || ib < nb {
        let (ta, sa) = if ia < na { a.event(ia) } else { (f32::INFINITY, Surf::NONE) };
        let (tb, sb) = if ib < nb { b.event(ib) } else { (f32::INFINITY, Surf::NONE) };
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
            if let Some(last) = out.last() {
                if t - last.t1 <= eps {
                    start = (last.t0, last.s0);
                    out.pop();
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

/// [`combine_into`], never inlined: for callers whose own code is large and
/// register-bound (a wide union's tree walk, whose visits inlined the merge
/// at +1.4% instructions on scenes/cheese).
#[inline(never)]
pub fn combine_into_call(op: Op, acc: &mut SpanList, b: &[Span], eps: f32, tmp: &mut SpanList) {
    combine_into(op, acc, b, eps, tmp)
}

/// In-place `acc = acc op b` using `tmp` as scratch.
#[inline(always)]
pub fn combine_into(op: Op, acc: &mut SpanList, b: &[Span], eps: f32, tmp: &mut SpanList) {
    if let ([x], [y]) = (acc.as_slice(), b) {
        // Both spans are read into registers first: the result can go
        // straight into `acc`, with no copy back from `tmp`.
        let (x, y) = (One::of(x), One::of(y));
        acc.clear();
        match op {
            Op::Union => merge_one::<UNION>(x, y, eps, acc),
            Op::Intersection => merge_one::<INTERSECTION>(x, y, eps, acc),
            Op::Difference => merge_one::<DIFFERENCE>(x, y, eps, acc),
        }
        return;
    }
    combine(op, acc.as_slice(), b, eps, tmp);
    // Copy back the few spans in use; swapping moved two whole inline arrays
    // (2 x 200 bytes) and was ~10% of the logo scene's trace time. A spilled
    // result (deep nesting: scenes/nesting has up to 80 spans) is swapped:
    // its spans are on the heap, and a copy would push them one by one: its
    // heap vector is taken, not the whole list (a swap of the lists moved
    // their inline arrays, and was not always inlined: +1% instructions on
    // scenes/nesting after unrelated changes to the crate).
    if tmp.spilled {
        std::mem::swap(&mut acc.heap, &mut tmp.heap);
        (acc.len, acc.spilled) = (tmp.len, true);
        tmp.len = 0;
        tmp.spilled = false;
        tmp.heap.clear();
        return;
    }
    acc.clear();
    acc.append(tmp.as_slice());
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// A `SpanList` against a `Vec` model under random pushes, appends, pops,
    /// clears, `truncate_at` and `combine_into` (whose spilled results are
    /// swapped in), across the inline capacity both ways.
    #[test]
    fn span_list_behaves_as_a_vec() {
        let seed = 0x5a11_0001u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let span = |t: f32| Span { t0: t, t1: t + 0.5, s0: Surf::new(1, 0), s1: Surf::new(1, 1) };
        let (mut list, mut model, mut tmp) = (SpanList::new(), Vec::<Span>::new(), SpanList::new());
        let mut next = 0.0f32;
        let mut longest = 0;
        for step in 0..20_000 {
            match rng.gen_range(0..10) {
                0..=3 => {
                    list.push(span(next));
                    model.push(span(next));
                    next += 1.0;
                }
                4 => {
                    let n = rng.gen_range(0..12);
                    let s: Vec<Span> = (0..n).map(|k| span(next + k as f32)).collect();
                    next += n as f32;
                    list.append(&s);
                    model.extend_from_slice(&s);
                }
                5 | 6 => assert_eq!(list.pop(), model.pop(), "step {step}"),
                7 => {
                    let t = rng.gen_range(0.0..next.max(1.0));
                    list.truncate_at(t);
                    while model.last().is_some_and(|l| l.t0 >= t) {
                        model.pop();
                    }
                    if let Some(l) = model.last_mut() {
                        if l.t1 > t {
                            (l.t1, l.s1) = (t, Surf::NONE);
                        }
                    }
                }
                8 => {
                    // A union with a list past every span: the result is both.
                    let b: Vec<Span> = (0..rng.gen_range(1..12)).map(|k| span(next + 1.0 + k as f32)).collect();
                    next += 13.0;
                    combine_into(Op::Union, &mut list, &b, 1e-3, &mut tmp);
                    model.extend_from_slice(&b);
                }
                _ => {
                    if rng.gen_bool(0.2) {
                        list.clear();
                        model.clear();
                        next = 0.0;
                    }
                }
            }
            longest = longest.max(model.len());
            assert_eq!(list.as_slice(), &model[..], "step {step}");
            assert_eq!((list.len(), list.is_empty(), list.last()), (model.len(), model.is_empty(), model.last()), "step {step}");
        }
        assert!(longest > 2 * INLINE_SPANS, "the lists should spill ({longest} spans at most)");
    }

    /// `combine` and `combine_into` of two one-span lists (their `One` and
    /// closed-form paths) against the general event loop on the same spans as slices, for every operation,
    /// on spans built to meet every rule: shared and eps-near boundaries,
    /// short spans and gaps, infinite and NaN ends, ends without surface,
    /// flipped surfaces. Mutations that fail it: the `One` end read as its
    /// start, the accumulator not cleared before an in-place merge, a's
    /// surface taken at a fused intersection start or where a leaves as b
    /// enters in a difference.
    #[test]
    fn one_span_merge_is_the_general_loop() {
        let seed = 0x0e5a_0001u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let pool = [0.0f32, 1.0, 1.5, 2.0, f32::INFINITY, f32::NEG_INFINITY];
        let param = |rng: &mut SmallRng, eps: f32| {
            let t = pool[rng.gen_range(0..pool.len())];
            match rng.gen_range(0..10) {
                0 => rng.gen_range(-1.0..3.0f32),
                1 => f32::NAN,
                2..=4 => t + [0.5, 1.0, -1.0, 2.0][rng.gen_range(0..4)] * eps,
                _ => t,
            }
        };
        let surf = |rng: &mut SmallRng| match rng.gen_range(0..6) {
            0 => Surf::NONE,
            1 => Surf::new(rng.gen_range(0..4), 1).flip(),
            _ => Surf::new(rng.gen_range(0..4), rng.gen_range(0..3)),
        };
        let (mut got, mut want) = (SpanList::new(), SpanList::new());
        let mut merged = 0;
        for case in 0..200_000 {
            let eps = [0.0, 1e-3, 0.25][rng.gen_range(0..3)];
            let span = |rng: &mut SmallRng| {
                let (mut t0, mut t1) = (param(rng, eps), param(rng, eps));
                if rng.gen_bool(0.8) && t1 < t0 {
                    std::mem::swap(&mut t0, &mut t1);
                }
                Span { t0, t1, s0: surf(rng), s1: surf(rng) }
            };
            let (a, b) = (span(&mut rng), span(&mut rng));
            for op in [Op::Union, Op::Intersection, Op::Difference] {
                combine(op, &[a], &[b], eps, &mut got);
                want.clear();
                let (x, y): (&[Span], &[Span]) = (&[a], &[b]);
                match op {
                    Op::Union => merge_events::<UNION, _, _>(x, y, eps, &mut want),
                    Op::Intersection => merge_events::<INTERSECTION, _, _>(x, y, eps, &mut want),
                    Op::Difference => merge_events::<DIFFERENCE, _, _>(x, y, eps, &mut want),
                }
                let bits = |l: &SpanList| l.as_slice().iter().map(|s| (s.t0.to_bits(), s.t1.to_bits(), s.s0, s.s1)).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "seed {seed:#x} case {case} {op:?}: {a:?} {b:?} eps {eps}");
                // In place, as the evaluator merges into its accumulator.
                let (mut acc, mut tmp) = (SpanList::new(), SpanList::new());
                acc.push(a);
                combine_into(op, &mut acc, &[b], eps, &mut tmp);
                assert_eq!(bits(&acc), bits(&want), "seed {seed:#x} case {case} {op:?} in place: {a:?} {b:?} eps {eps}");
                merged += got.len();
            }
        }
        assert!(merged > 100_000, "the cases should give spans ({merged})");
    }
}
