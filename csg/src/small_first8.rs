//! [`small_first`](super::small_first::small_first) for a node of two
//! operands (an intersection or a difference of two kernel leaves: every
//! tree of a forest cut by half-spaces, of rounded or hollowed pieces), for
//! the eight lanes of a packet at once, with lane masks and selects instead
//! of each lane's sort and sweep of its boundaries.
//!
//! Why: on benches/scenes/forest_cut the first-entry walk's lane loop over
//! `small_first` was the trace's hottest function, 17% of its cycles
//! (perf, one thread, 1920x1080 `--no-shadows`): a call per child and lane
//! whose short sorts and branches mispredict.
//!
//! Each lane's answer is `small_first`'s, bit for bit: the same boundaries
//! (an operand's ends before `lo - 2 eps` set its state at the range's
//! start, the others are events), the same sure test (consecutive events
//! more than `2 eps` apart, the first more than `2 eps` past `lo`, events
//! at infinity left out) on the events sorted by a network instead of an
//! insertion sort (they differ only in the order of equal events, which
//! make the lane unsure, whose answer reads the smallest event alone: the
//! same value, though of -0 and +0 either may be taken, which the walk's
//! compares do not tell apart), and
//! the same sweep. Events at infinity are left out of the sweep too: a span
//! starting there starts past every range, and one ending there ends past
//! every range's clipped end, which is what the walk keeps of them. A lane
//! with a NaN end is left to `small_first`.

use rothray_primitives::{kernels8::Ranges8, Surf};

use super::small_first::SmallOps;
use super::NodeKind;

/// Per lane, what a two-operand node's result on the lane's range tells the
/// first-entry walk (its `take_small`), as `small_first` and the walk's
/// reading of it give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct First8 {
    /// Lanes that cannot be settled by the walk: the range may start
    /// inside the node, or a bound of its start lies before the range.
    pub(crate) kill: u32,
    /// Lanes with a first span to put: its start, its end clipped to the
    /// range's end, and their surfaces (`Surf::NONE` at a clipped end).
    pub(crate) span: u32,
    pub(crate) t0: [f32; 8],
    pub(crate) t1: [f32; 8],
    pub(crate) s0: [Surf; 8],
    pub(crate) s1: [Surf; 8],
    /// Per lane, where any other span of the node starts or later
    /// (infinity: none), for the walk's second smallest start.
    pub(crate) next: [f32; 8],
    /// Lanes left to `small_first` (a NaN end).
    pub(crate) odd: u32,
}

impl First8 {
    /// Every lane's node empty on its whole line.
    const EMPTY: First8 = First8 {
        kill: 0,
        span: 0,
        t0: [f32::INFINITY; 8],
        t1: [f32::INFINITY; 8],
        s0: [Surf::NONE; 8],
        s1: [Surf::NONE; 8],
        next: [f32::INFINITY; 8],
        odd: 0,
    };
}

/// The lanes' ranges: starts, ends, tolerances.
pub(crate) struct Ranges<'a> {
    pub(crate) lo: &'a [f32; 8],
    pub(crate) hi: &'a [f32; 8],
    pub(crate) eps: &'a [f32; 8],
}

/// A two-operand node's kind, leaves and their solves.
#[derive(Clone, Copy)]
pub(crate) struct Two<'a> {
    pub(crate) kind: NodeKind,
    pub(crate) leaf: [u32; 2],
    pub(crate) r: [&'a Ranges8; 2],
}

impl<'a> Two<'a> {
    /// The node of `ops` (two operands).
    pub(crate) fn of(ops: &'a SmallOps<2>) -> Self {
        Two { kind: ops.kind, leaf: ops.leaf, r: [&ops.r[0], &ops.r[1]] }
    }
}

/// The answers of the two-operand node `ops` (an intersection or
/// difference) for the lanes `lanes` (done by both solves) on `ranges`.
pub(crate) fn small_first8(ops: &Two, lanes: u32, ranges: &Ranges) -> First8 {
    debug_assert!(matches!(ops.kind, NodeKind::Intersection | NodeKind::Difference));
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { small_first8_avx2(ops, lanes, ranges) };
    }
    small_first8_base(ops, lanes, ranges)
}

/// [`small_first8`] compiled for AVX2 (the lane loop in 8-lane registers).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[doc(hidden)]
pub(crate) unsafe fn small_first8_avx2(ops: &Two, lanes: u32, ranges: &Ranges) -> First8 {
    lanes8(ops, lanes, ranges)
}

/// [`small_first8`] for the baseline (SSE2: the lane loop in two halves).
#[doc(hidden)]
pub(crate) fn small_first8_base(ops: &Two, lanes: u32, ranges: &Ranges) -> First8 {
    lanes8(ops, lanes, ranges)
}

/// Both builds' body: a loop over the lanes without a branch, for the
/// compiler to vectorise (selects, compares, min and max; no calls).
#[inline(always)]
fn lanes8(ops: &Two, lanes: u32, ranges: &Ranges) -> First8 {
    let inter = ops.kind == NodeKind::Intersection;
    let (r0, r1): (&Ranges8, &Ranges8) = (ops.r[0], ops.r[1]);
    // The lanes whose result may not be empty on the whole line (see
    // `small_first`: an intersection needs both operands, a difference its
    // first). Packets of coherent rays often have none.
    let lanes = lanes & r0.hit & if inter { r1.hit } else { u32::MAX };
    if lanes == 0 {
        return First8::EMPTY;
    }
    // The flip of the subtrahend's surfaces, on the leaf word.
    let flip1 = if inter { 0 } else { Surf::FLIP };
    let inf = f32::INFINITY;
    let mut kill = [false; 8];
    let mut span = [false; 8];
    let mut odd = [false; 8];
    let mut t0 = [inf; 8];
    let mut t1 = [inf; 8];
    let mut ix0 = [0u32; 8];
    let mut ix1 = [0u32; 8];
    let mut next = [inf; 8];
    for k in 0..8 {
        let on = lanes & (1 << k) != 0;
        let (lo, hi, e) = (ranges.lo[k], ranges.hi[k], ranges.eps[k]);
        let near = lo - 2.0 * e;
        let h = [r0.hit & (1 << k) != 0, r1.hit & (1 << k) != 0];
        // Boundaries: 0 and 1 the first operand's entry and exit, 2 and 3
        // the second's.
        let tb = [r0.t0[k], r0.t1[k], r1.t0[k], r1.t1[k]];
        let nan = (h[0] & (tb[0].is_nan() | tb[1].is_nan())) | (h[1] & (tb[2].is_nan() | tb[3].is_nan()));
        // State at the range's start, and the events (infinity: none).
        let inside = [h[0] & (tb[0] < near) & !(tb[1] < near), h[1] & (tb[2] < near) & !(tb[3] < near)];
        let mut v = [inf; 4];
        let mut ix = [0u32, 1, 2, 3];
        for i in 0..4 {
            v[i] = if h[i / 2] & !(tb[i] < near) { tb[i] } else { inf };
        }
        // Sorting network on (v, ix).
        for (a, b) in [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)] {
            let swap = v[a] > v[b];
            let (va, vb, ia, ib) = (v[a], v[b], ix[a], ix[b]);
            v[a] = if swap { vb } else { va };
            v[b] = if swap { va } else { vb };
            ix[a] = if swap { ib } else { ia };
            ix[b] = if swap { ia } else { ib };
        }
        let member = |i0: bool, i1: bool| if inter { i0 & i1 } else { i0 & !i1 };
        let mut unsure = false;
        let mut prev = lo;
        for &t in &v {
            unsure |= (t != inf) & !(t - prev > 2.0 * e);
            prev = t;
        }
        let starts_inside = member(inside[0], inside[1]);
        // The sweep: the first change enters the first span, the second
        // leaves it, the third enters the next.
        let mut st = inside;
        let mut was = false;
        let mut changes = 0u32;
        let (mut a, mut b, mut nx) = (inf, inf, inf);
        let (mut ia, mut ib) = (0u32, 0u32);
        for i in 0..4 {
            let real = v[i] != inf;
            let j = (ix[i] >> 1) as usize;
            let entering = ix[i] & 1 == 0;
            let s0n = if real & (j == 0) { entering } else { st[0] };
            let s1n = if real & (j == 1) { entering } else { st[1] };
            st = [s0n, s1n];
            let now = member(s0n, s1n);
            let ch = now != was;
            was = now;
            changes += ch as u32;
            let first = ch & (changes == 1);
            let second = ch & (changes == 2);
            let third = ch & (changes == 3);
            a = if first { v[i] } else { a };
            ia = if first { ix[i] } else { ia };
            b = if second { v[i] } else { b };
            ib = if second { ix[i] } else { ib };
            nx = if third { v[i] } else { nx };
        }
        // The walk's reading: a span no longer than 8 eps counts as a bound
        // at its start (its cut might not reach past its exit).
        let has = changes >= 1;
        let long = b - a > 8.0 * e;
        let bound = if unsure { v[0] - e } else { a };
        let is_bound = !starts_inside & (unsure | (has & !long));
        let is_span = !starts_inside & !unsure & has & long & (a < hi);
        kill[k] = on & !nan & (starts_inside | (is_bound & (bound < lo)));
        next[k] = if on & !nan & is_bound & !(bound < lo) {
            bound
        } else if on & !nan & is_span {
            nx
        } else {
            inf
        };
        span[k] = on & !nan & is_span;
        let real1 = (b <= hi) & (b != inf);
        t0[k] = a;
        t1[k] = if real1 { b } else { b.min(hi) };
        ix0[k] = ia;
        ix1[k] = if real1 { ib } else { u32::MAX };
        odd[k] = on & nan;
    }
    let mask = |m: [bool; 8]| m.iter().enumerate().fold(0u32, |acc, (k, &x)| acc | (x as u32) << k);
    // The surfaces of the spans' ends, by lane (only where a span is put).
    let surf = |k: usize, i: u32| {
        if i == u32::MAX {
            return Surf::NONE;
        }
        let r = if i < 2 { r0 } else { r1 };
        let sub = if i & 1 == 0 { r.s0[k] } else { r.s1[k] };
        let leaf = ops.leaf[(i >> 1) as usize];
        Surf::new(if i < 2 { leaf } else { leaf ^ flip1 }, sub)
    };
    let span = mask(span);
    let mut s0 = [Surf::NONE; 8];
    let mut s1 = [Surf::NONE; 8];
    let mut m = span;
    while m != 0 {
        let k = m.trailing_zeros() as usize;
        m &= m - 1;
        s0[k] = surf(k, ix0[k]);
        s1[k] = surf(k, ix1[k]);
    }
    First8 { kill: mask(kill), span, t0, t1, s0, s1, next, odd: mask(odd) }
}

#[cfg(test)]
#[path = "small_first8_tests.rs"]
mod tests;
