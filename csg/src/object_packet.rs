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
//! and the caller evaluates it alone. A small tree of several levels
//! (at most eight kernel leaves) is answered the same way from
//! its truth table (`tree_first.rs`).
//!
//! Why: on benches/scenes/forest_objects (10 000 leaves as objects) a
//! lane's visit of its candidates and its per-object evaluations were a
//! third of the cycles (perf, `nearest_ctx` and `object_first`).

use rothray_primitives::{kernels8::Ranges8, LeafTable, Surf};

use super::small_first::{small_first, Clipped, SmallFirst, SmallOps};
use super::tree_first::{done_by, TreeShape};
use super::tree_first8::{tree_first8, LaneStarts};
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
    /// a narrow union, intersection or difference of at most
    /// [`OBJECT_OPS`] kernel leaves, or a small tree of at most
    /// eight of them (`tree_first.rs`)?
    #[inline]
    pub fn packet_first_node(&self, leaves: &LeafTable, n: u32) -> bool {
        let nu = n as usize;
        match self.kind[nu] {
            NodeKind::Leaf => leaves.has_kernel8(self.first[nu]),
            _ if self.leafy[nu] => self.wide[nu] == u32::MAX && self.small[nu] != 0 && self.count[nu] as usize <= OBJECT_OPS,
            _ => self.is_small_tree(nu),
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
            return self.with_solve::<false, _>(leaves, leaf, |r| leaf_firsts(r, leaf, lanes, ray, out)).is_some();
        }
        if !prog.leafy[nu] {
            let Some(t) = TreeShape::of(prog, nu) else { return false };
            return self
                .with_solves_n::<false, _>(leaves, &t.leaf[..t.count], |r| {
                    let done = lanes & done_by(r);
                    let mut f = [SmallFirst::Empty; 8];
                    tree_first8(&t, r, done, &LaneStarts { lo: ray.tmin, eps: ray.eps }, &mut f);
                    firsts_of(done, lanes, ray, out, |k| f[k])
                })
                .is_some();
        }
        let mut ops = SmallOps::<OBJECT_OPS>::of(prog, nu);
        if !ops.gather(prog, nu, |leaf| self.with_solve::<false, _>(leaves, leaf, |r| *r)) {
            return false;
        }
        firsts_of(lanes & ops.done, lanes, ray, out, |k| small_first::<OBJECT_OPS, { 2 * OBJECT_OPS }>(&ops, k, (ray.tmin[k], ray.eps[k])));
        true
    }
}

/// The first surfaces on the lanes `lanes` (those of `done` from `first`,
/// a lane's first span of the node; the others unsure) into `out`.
#[inline(always)]
fn firsts_of(done: u32, lanes: u32, ray: LaneRanges, out: &mut [FirstOf; 8], first: impl Fn(usize) -> SmallFirst) {
    for k in 0..8 {
        if lanes & (1 << k) == 0 {
            continue;
        }
        out[k] = if done & (1 << k) == 0 {
            FirstOf::Unsure
        } else {
            match first(k) {
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
        let Clipped { c0, c1, real0, real1 } = Clipped::lane(r, k, (ray.tmin[k], ray.tmax[k]));
        out[k] = if !(c1 > c0) {
            FirstOf::Miss
        } else if real0 {
            FirstOf::Hit(c0, Surf::new(leaf, r.s0[k]))
        } else if real1 {
            FirstOf::Hit(c1, Surf::new(leaf, r.s1[k]))
        } else {
            FirstOf::Miss
        };
    }
}
