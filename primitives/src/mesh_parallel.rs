//! A mesh's spans for eight rays with one direction and their own origins
//! (a packet of shadow rays toward a directional light), each exactly what
//! its own query gives it: [`MeshData::spans_on`] for a lane whose point at
//! `tmin` lies inside the bounds (a shadow ray leaves a surface of the mesh
//! it starts on: its nearest query cannot prune, it must know the winding
//! count at `tmin`), and, with slacks given, [`MeshData::spans_nearest`]
//! for a lane starting outside them (a shadow ray passing another mesh).
//!
//! The tree is walked once for the packet: each node's four boxes are
//! tested against the eight rays at once ([`ParRays8`], each lane exactly as
//! its own `Ray4` test), and a child is entered with the lanes that meet
//! it, in the order of a lane's own walk (the last child met first), so
//! each lane meets its leaves in its own walk's order and collects the
//! same crossings in the same order (their sort keeps the order of ties).
//! The leaves' triangle tests and each lane's sort and walk of its
//! crossings are its own walk's. A nearest lane tests each leaf on
//! `[tmin, cut]` with its cut so far (the nearest crossing plus the slack),
//! as its own front-to-back walk does: every crossing up to the final cut
//! is found either way, and the walk of the sorted crossings reads none
//! past it. (Its own walk meets leaves in another order, so crossings
//! that tie in `t` and sign may come in another order: a mesh whose
//! surface overlaps itself.)
//!
//! Why: such shadow rays went one by one through the whole tree: on
//! benches/scenes/bunny a shadow ray cost eight times a camera ray (which
//! walks with its packet), half of the lit frame. Those starting outside
//! a mesh still did (60 knob meshes in a union: 14% of the lit frame's
//! instructions, callgrind).

use glam::Vec3;
use smallvec::SmallVec;

use super::wide::ParRays8;
use super::{stop_past, wide, Crossing, InsideRule, Line64, MeshData, Walk, WoopRay, STACK};
use crate::Span;

/// Eight rays `o[k] + t d` on `[tmin[k], tmax[k]]`, each the rounding of
/// the exact line `x[k]` (as [`MeshData::spans_on`] takes them).
pub struct ParallelRays8<'a> {
    /// Origins.
    pub o: &'a [Vec3; 8],
    /// The shared direction.
    pub d: Vec3,
    /// Range starts.
    pub tmin: &'a [f32; 8],
    /// Range ends.
    pub tmax: &'a [f32; 8],
    /// The exact lines.
    pub x: &'a [Line64; 8],
    /// Each lane's nearest-mode slack, for the lanes starting outside the
    /// bounds (`None`: those are left to their own queries).
    pub slack: Option<&'a [f32; 8]>,
}

impl MeshData {
    /// The spans of the lanes of `active` that [`MeshData::spans_on`] walks
    /// to the box exit (orientation rule, `tmin <= tmax`, the point at
    /// `tmin` inside the padded bounds), pushed to `out[k]` exactly as it
    /// pushes them, and with `q.slack` those of the lanes starting outside
    /// the bounds as [`MeshData::spans_nearest`] gives them; returns those
    /// lanes and where each one's spans stop being exact (the others are
    /// left to the single-ray queries).
    pub fn spans_parallel8(&self, q: &ParallelRays8, active: u32, leaf: u32, out: &mut [Vec<Span>; 8]) -> (u32, [f32; 8]) {
        #[cfg(target_arch = "x86_64")]
        let avx = std::arch::is_x86_feature_detected!("avx");
        #[cfg(not(target_arch = "x86_64"))]
        let avx = false;
        self.spans_parallel8_in(q, (active, avx), leaf, out)
    }

    /// [`MeshData::spans_parallel8`], the boxes tested with AVX when `avx`
    /// (the CPU must have it), else lane by lane (tests run both).
    pub(super) fn spans_parallel8_in(
        &self,
        q: &ParallelRays8,
        (active, avx): (u32, bool),
        leaf: u32,
        out: &mut [Vec<Span>; 8],
    ) -> (u32, [f32; 8]) {
        let mut valid = [f32::INFINITY; 8];
        if self.wide.is_empty() || self.rule != InsideRule::Orientation {
            return (0, valid);
        }
        let ParallelRays8 { o, d, tmin, tmax, x, slack } = *q;
        // The lanes taken, and those among them starting outside the
        // bounds (nearest lanes); each one's cut so far.
        let (mut lanes, mut near) = (0u32, 0u32);
        let mut cut = [f32::INFINITY; 8];
        for k in 0..8 {
            let outside = self.outside_at(o[k], d, tmin[k]);
            let take = active & (1 << k) != 0 && tmax[k] >= tmin[k] && (!outside || slack.is_some());
            lanes |= (take as u32) << k;
            near |= ((take && outside) as u32) << k;
            if take && outside {
                cut[k] = tmax[k];
            }
        }
        if lanes == 0 {
            return (0, valid);
        }
        let slack = slack.copied().unwrap_or([0.0; 8]);
        let rays = ParRays8::new(o, d, avx);
        // Each lane's triangle-test constants, made when it first reaches a leaf.
        let mut tri: [Option<(WoopRay, wide::TriRay4)>; 8] = [None; 8];
        let mut xs: [SmallVec<[Crossing; 32]>; 8] = Default::default();
        let mut stack = [(0u32, 0u32); STACK];
        let mut sp = 0usize;
        let (mut cur, mut m) = (0u32, lanes);
        loop {
            if cur & wide::LEAF != 0 {
                let blk = self.wide.block(cur);
                // (The lanes to the box exit, then the nearest lanes: one
                // loop with a branch per lane cost bunny's shadow packets
                // 0.6% of the lit frame's instructions.)
                let mut l = m & !near;
                while l != 0 {
                    let k = l.trailing_zeros() as usize;
                    l &= l - 1;
                    let (r, r4) = *tri[k].get_or_insert_with(|| tri_ray(o[k], d, x[k]));
                    let b = blk.test(&r4, tmin[k], f32::INFINITY);
                    let xk = &mut xs[k];
                    self.block_crossings(blk, &b, &r, (tmin[k], f32::INFINITY), &mut |c: Crossing| xk.push(c));
                }
                let mut l = m & near;
                while l != 0 {
                    let k = l.trailing_zeros() as usize;
                    l &= l - 1;
                    let (r, r4) = *tri[k].get_or_insert_with(|| tri_ray(o[k], d, x[k]));
                    let (xk, ck, sk) = (&mut xs[k], &mut cut[k], slack[k]);
                    let b = blk.test(&r4, tmin[k], *ck);
                    self.block_crossings(blk, &b, &r, (tmin[k], *ck), &mut |c: Crossing| {
                        xk.push(c);
                        *ck = ck.min(stop_past(c.t, sk));
                    });
                }
            } else {
                let n = self.wide.node(cur);
                // (A nearest lane's cut prunes as its own walk's does.)
                let hit = rays.hit(n, tmin, &cut, m);
                // A lane's own walk pushes the children it meets from the
                // first slot on and enters the last at once: children in
                // decreasing slot order, each with the lanes that meet it.
                let Some(last) = (0..4).rev().find(|&s| hit[s] != 0) else {
                    match pop(&stack, &mut sp) {
                        Some(c) => {
                            (cur, m) = c;
                            continue;
                        }
                        None => break,
                    }
                };
                for s in 0..last {
                    if hit[s] != 0 {
                        if sp == STACK {
                            // Deeper than a lane's own stack holds (its
                            // spill would change the order): lane by lane.
                            return (0, valid);
                        }
                        stack[sp] = (n.child(s as u32), hit[s]);
                        sp += 1;
                    }
                }
                (cur, m) = (n.child(last as u32), hit[last]);
                continue;
            }
            match pop(&stack, &mut sp) {
                Some(c) => (cur, m) = c,
                None => break,
            }
        }
        let mut l = lanes;
        while l != 0 {
            let k = l.trailing_zeros() as usize;
            l &= l - 1;
            self.sort_signed(&mut xs[k]);
            if near & (1 << k) != 0 {
                // (As `spans_nearest_on` ends: zero crossings before `tmin`.)
                self.walk_signed(&xs[k], 0, Walk::new(x[k], tmin[k], cut[k].min(tmax[k]), leaf), &mut out[k]);
                valid[k] = cut[k];
            } else {
                let count: i32 = xs[k].iter().map(|c| -self.sign(c)).sum();
                self.walk_signed(&xs[k], count, Walk::new(x[k], tmin[k], tmax[k], leaf), &mut out[k]);
            }
        }
        (lanes, valid)
    }
}

/// A lane's triangle-test constants.
#[inline(always)]
fn tri_ray(o: Vec3, d: Vec3, x: Line64) -> (WoopRay, wide::TriRay4) {
    let r = WoopRay::on(o, d, x);
    (r, wide::TriRay4::new(&r))
}

/// The top of the walk's stack (node, lanes), popped.
#[inline(always)]
fn pop(stack: &[(u32, u32); STACK], sp: &mut usize) -> Option<(u32, u32)> {
    if *sp == 0 {
        return None;
    }
    *sp -= 1;
    Some(stack[*sp])
}
