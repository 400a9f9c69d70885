//! Span lists of eight rays at once (SoA, at most `C` spans per lane) and
//! Table 1 on all eight lanes together ([`merge8`]): each lane gets exactly
//! what [`combine`](crate::spans::combine) gives its own lists, bit for bit
//! (same fusing, same regularisation, same surfaces).
//!
//! Why SoA and lane-parallel: a packet's rays meet mostly the same leaves,
//! so their lists have the same few spans; stepping through the events of
//! all lanes in lock step turns `combine`'s branches into compares and
//! selects over eight lanes (AVX2, chosen at run time; without it each lane
//! goes through `combine`). A lane whose result would need more than `C`
//! spans is reported in the overflow mask and left for the scalar path.
//!
//! How the loop stays branch-free: each step looks at every lane's next
//! event of `a` and of `b` (picked out of the `C` slots by compares), and
//! every decision of `combine` (fuse, take `a`, take `b`, enter, leave,
//! merge with the previous span, drop a short span) becomes a lane mask.
//! The loop runs as many steps as the busiest lane has events.
//!
//! What it is worth (`cargo bench --bench kernels -- combine/`, 256 pairs
//! of random lists, ns per pair): about 15% faster than `combine` with one
//! span per list, 1.2 to 1.4 times slower with two, 1.6 to 3 times slower
//! with four or eight: the picks by compare cost `C` blends per list and
//! step. So the render path keeps `combine`; see the README.

use rothray_primitives::{Span, Surf};

use crate::spans::{combine, Op, SpanList};

/// No surface ([`Surf::NONE`]'s leaf).
pub(super) const NONE: u32 = u32::MAX;

/// Span lists of eight lanes; lane `k`'s span `j < len[k]` is
/// `(t0[j][k], t1[j][k])` with entry surface `(l0[j][k], u0[j][k])` (leaf,
/// sub) and exit surface `(l1[j][k], u1[j][k])`. Slots past `len` hold
/// anything.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spans8<const C: usize> {
    /// Entries.
    pub t0: [[f32; 8]; C],
    /// Exits.
    pub t1: [[f32; 8]; C],
    /// Entry surfaces' leaves ([`Surf::leaf`]).
    pub l0: [[u32; 8]; C],
    /// Entry surfaces' sub-surfaces.
    pub u0: [[u32; 8]; C],
    /// Exit surfaces' leaves.
    pub l1: [[u32; 8]; C],
    /// Exit surfaces' sub-surfaces.
    pub u1: [[u32; 8]; C],
    /// Spans per lane.
    pub len: [u32; 8],
}

impl<const C: usize> Default for Spans8<C> {
    fn default() -> Self {
        Spans8 { t0: [[0.0; 8]; C], t1: [[0.0; 8]; C], l0: [[0; 8]; C], u0: [[0; 8]; C], l1: [[0; 8]; C], u1: [[0; 8]; C], len: [0; 8] }
    }
}

impl<const C: usize> Spans8<C> {
    /// Lane `k`'s spans.
    pub fn lane(&self, k: usize) -> SpanList {
        let mut out = SpanList::new();
        for j in 0..(self.len[k] as usize).min(C) {
            out.push(Span {
                t0: self.t0[j][k],
                t1: self.t1[j][k],
                s0: Surf { leaf: self.l0[j][k], sub: self.u0[j][k] },
                s1: Surf { leaf: self.l1[j][k], sub: self.u1[j][k] },
            });
        }
        out
    }

    /// Sets lane `k` to `spans`; `false` (lane left empty) when they do not fit.
    pub fn set_lane(&mut self, k: usize, spans: &[Span]) -> bool {
        if spans.len() > C {
            self.len[k] = 0;
            return false;
        }
        for (j, s) in spans.iter().enumerate() {
            (self.t0[j][k], self.t1[j][k]) = (s.t0, s.t1);
            (self.l0[j][k], self.u0[j][k], self.l1[j][k], self.u1[j][k]) = (s.s0.leaf, s.s0.sub, s.s1.leaf, s.s1.sub);
        }
        self.len[k] = spans.len() as u32;
        true
    }
}

/// Each lane `k` of `lanes`: `out` gets `combine(op, a_k, b_k, eps[k])`.
/// Returns the lanes whose result has more than `C` spans (their `out` is
/// not their result). Lanes outside `lanes` get empty lists.
pub fn merge8<const C: usize>(op: Op, a: &Spans8<C>, b: &Spans8<C>, eps: &[f32; 8], lanes: u32, out: &mut Spans8<C>) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { merge8_avx2(op, a, b, eps, lanes, out) };
    }
    merge8_by_lane(op, a, b, eps, lanes, out)
}

/// [`merge8`] without AVX2: [`combine`] lane by lane. (The AVX2 steps
/// written as plain per-lane loops, for the compiler to vectorise, ran
/// 3.5 to 20 times slower than this: `cargo bench --bench kernels --
/// combine/`, before this file's AVX2 module.) Public for tests and
/// benchmarks: both paths give the same lists.
#[doc(hidden)]
pub fn merge8_by_lane<const C: usize>(op: Op, a: &Spans8<C>, b: &Spans8<C>, eps: &[f32; 8], lanes: u32, out: &mut Spans8<C>) -> u32 {
    let mut overflow = 0;
    let mut r = SpanList::new();
    for k in 0..8 {
        out.len[k] = 0;
        if lanes & (1 << k) == 0 {
            continue;
        }
        combine(op, a.lane(k).as_slice(), b.lane(k).as_slice(), eps[k], &mut r);
        if !out.set_lane(k, r.as_slice()) {
            overflow |= 1 << k;
        }
    }
    overflow
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn merge8_avx2<const C: usize>(op: Op, a: &Spans8<C>, b: &Spans8<C>, eps: &[f32; 8], lanes: u32, out: &mut Spans8<C>) -> u32 {
    let plan = Plan::new(op, a, b, lanes);
    out.len = [0; 8];
    let overflow = avx2::steps(op, a, b, eps, &plan, out);
    plan.copy(a, b, out);
    overflow & lanes
}

/// What each lane does: `combine`'s fast paths copy an operand
/// unregularised (those lanes are copies), the other lanes step through
/// `na[k] + nb[k]` events (0 for a lane whose result is empty).
pub(super) struct Plan {
    pub(super) na: [u32; 8],
    pub(super) nb: [u32; 8],
    copy_a: [bool; 8],
    copy_b: [bool; 8],
    /// Steps of the busiest lane.
    pub(super) steps: u32,
}

impl Plan {
    #[inline(always)]
    fn new<const C: usize>(op: Op, a: &Spans8<C>, b: &Spans8<C>, lanes: u32) -> Plan {
        let mut p = Plan { na: [0; 8], nb: [0; 8], copy_a: [false; 8], copy_b: [false; 8], steps: 0 };
        for k in 0..8 {
            let on = lanes & (1 << k) != 0;
            let (ea, eb) = (a.len[k] == 0, b.len[k] == 0);
            let (ca, cb, none) = match op {
                Op::Union => (eb, ea && !eb, false),
                Op::Intersection => (false, false, ea || eb),
                Op::Difference => (!ea && eb, false, ea),
            };
            p.copy_a[k] = on & ca;
            p.copy_b[k] = on & cb;
            let run = on & !ca & !cb & !none;
            p.na[k] = if run { 2 * a.len[k] } else { 0 };
            p.nb[k] = if run { 2 * b.len[k] } else { 0 };
            p.steps = p.steps.max(p.na[k] + p.nb[k]);
        }
        p
    }

    /// Writes the copied lanes.
    #[inline(always)]
    fn copy<const C: usize>(&self, a: &Spans8<C>, b: &Spans8<C>, out: &mut Spans8<C>) {
        for k in 0..8 {
            if self.copy_a[k] | self.copy_b[k] {
                let s = if self.copy_a[k] { a } else { b };
                let n = s.len[k] as usize;
                for j in 0..n.min(C) {
                    (out.t0[j][k], out.t1[j][k]) = (s.t0[j][k], s.t1[j][k]);
                    (out.l0[j][k], out.u0[j][k], out.l1[j][k], out.u1[j][k]) = (s.l0[j][k], s.u0[j][k], s.l1[j][k], s.u1[j][k]);
                }
                out.len[k] = n as u32;
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[path = "spans8_avx2.rs"]
mod avx2;

#[cfg(test)]
#[path = "spans8_tests.rs"]
mod tests;
