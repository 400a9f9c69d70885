//! An object's first surface for all lanes of a packet at once, when its
//! root is a kernel leaf or a small node of a few of them: what the engine
//! needs to pick a packet's nearest hits among such objects without each
//! lane's ordered visit and evaluation of every object
//! (`RenderScene::nearest_ctx`).
//!
//! A kernel leaf's answer is exact on every lane: its one span, clipped to
//! the lane's range, and its first real boundary (what `object_first` reads
//! from `Program::eval_in`). A small node's is exact where no two of its
//! operands' boundaries lie within `2 eps` ([`small_first`]); elsewhere,
//! and where the range starts inside it, the lane is [`FirstOf::Unsure`]
//! and the caller evaluates it alone.
//!
//! Why: on benches/scenes/forest_objects (10 000 leaves as objects) a
//! lane's visit of its candidates and its per-object evaluations were a
//! third of the cycles (perf, `nearest_ctx` and `object_first`).

use rothray_primitives::{kernels8::Ranges8, LeafTable, Surf};

use super::union_first::{small_first, SmallFirst, SmallOps};
use super::{NodeKind, PacketMemo, Program};

/// The most operands of an object's root that [`PacketMemo::first_surfaces8`]
/// takes (a capsule of a tile: a union of up to six spheres).
pub const OBJECT_OPS: usize = 8;

/// A lane's first surface of an object on its whole range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FirstOf {
    /// No surface on the range.
    Miss,
    /// The first surface: `t` and which.
    Hit(f32, Surf),
    /// Not known here: the lane evaluates the object itself.
    Unsure,
}

impl Program {
    /// Can [`PacketMemo::first_surfaces8`] answer node `n`: a kernel leaf,
    /// or a narrow union, intersection or difference of at most
    /// [`OBJECT_OPS`] kernel leaves?
    #[inline]
    pub fn packet_first_node(&self, leaves: &LeafTable, n: u32) -> bool {
        let nu = n as usize;
        match self.kind[nu] {
            NodeKind::Leaf => leaves.has_kernel8(self.first[nu]),
            _ => self.leafy[nu] && self.wide[nu] == u32::MAX && self.small[nu] != 0 && self.count[nu] as usize <= OBJECT_OPS,
        }
    }
}

/// The lanes' ranges and tolerances of a packet.
#[derive(Clone, Copy, Debug)]
pub struct LaneRanges<'a> {
    /// Each lane's range: from here...
    pub tmin: &'a [f32; 8],
    /// ...to here.
    pub tmax: &'a [f32; 8],
    /// Each lane's length tolerance (`RayCtx::eps`).
    pub eps: &'a [f32; 8],
}

impl PacketMemo {
    /// Node `n`'s ([`Program::packet_first_node`]) first surface on each
    /// lane `k` of `lanes` (on `[tmin[k], tmax[k]]`) into `out[k]`, from the
    /// packet's solves of its leaves; the other lanes are left as they are.
    /// `false` when the packet solves no leaves (nothing is written).
    pub fn first_surfaces8(&self, prog: &Program, leaves: &LeafTable, n: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8]) -> bool {
        let nu = n as usize;
        if prog.kind[nu] == NodeKind::Leaf {
            let leaf = prog.first[nu];
            return self.with_solve(leaves, leaf, |r| leaf_firsts(r, leaf, lanes, ray, out)).is_some();
        }
        let (first, count) = (prog.first[nu] as usize, prog.count[nu] as usize);
        let mut ops = SmallOps::<OBJECT_OPS> { kind: prog.kind[nu], count, leaf: [0; OBJECT_OPS], r: [Ranges8::default(); OBJECT_OPS] };
        let mut done = lanes;
        for j in 0..count {
            let leaf = prog.first[prog.children[first + j] as usize];
            ops.leaf[j] = leaf;
            let Some(r) = self.with_solve(leaves, leaf, |r| *r) else { return false };
            ops.r[j] = r;
            done &= r.done;
        }
        for k in 0..8 {
            if lanes & (1 << k) == 0 {
                continue;
            }
            out[k] = if done & (1 << k) == 0 {
                FirstOf::Unsure
            } else {
                match small_first::<OBJECT_OPS, { 2 * OBJECT_OPS }>(&ops, k, (ray.tmin[k], ray.eps[k])) {
                    SmallFirst::Empty => FirstOf::Miss,
                    SmallFirst::Span { t: (t0, _), s: (s0, _), .. } => {
                        // Past the range's end nothing is asked; near it the
                        // evaluation's clip may fuse (its redo's margin).
                        if t0 >= ray.tmax[k] {
                            FirstOf::Miss
                        } else if t0 < ray.tmax[k] - 16.0 * ray.eps[k] {
                            FirstOf::Hit(t0, s0)
                        } else {
                            FirstOf::Unsure
                        }
                    }
                    SmallFirst::Inside | SmallFirst::From(_) => FirstOf::Unsure,
                }
            };
        }
        true
    }
}

/// A kernel leaf's first surfaces from its solve `r`: its span clipped to
/// each lane's range as `push_clipped` clips it, and the first real
/// boundary of what is left (`first_surface`).
fn leaf_firsts(r: &Ranges8, leaf: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8]) {
    for k in 0..8 {
        if lanes & (1 << k) == 0 {
            continue;
        }
        if r.done & (1 << k) == 0 {
            out[k] = FirstOf::Unsure;
            continue;
        }
        if r.hit & (1 << k) == 0 {
            out[k] = FirstOf::Miss;
            continue;
        }
        let (t0, t1, lo, hi) = (r.t0[k], r.t1[k], ray.tmin[k], ray.tmax[k]);
        let real0 = t0 >= lo && t0.is_finite();
        let real1 = t1 <= hi && t1.is_finite();
        let c0 = if real0 { t0 } else { t0.max(lo) };
        let c1 = if real1 { t1 } else { t1.min(hi) };
        out[k] = if !(c1 > c0) {
            FirstOf::Miss
        } else if real0 {
            FirstOf::Hit(t0, Surf::new(leaf, r.s0[k]))
        } else if real1 {
            FirstOf::Hit(t1, Surf::new(leaf, r.s1[k]))
        } else {
            FirstOf::Miss
        };
    }
}
