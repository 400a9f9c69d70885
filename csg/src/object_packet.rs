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

use rothray_primitives::{glam::Vec4, kernels8::Ranges8, LeafTable, Surf};

use super::small_first::{small_first, SmallFirst, SmallOps};
use super::torus_sweep::torus_operands;
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

/// Eight lanes' first surfaces of an object on their whole ranges, lane
/// by lane in arrays: a lane of `hit` has its first surface at `t[k]` on
/// `surf[k]`, a lane of `unsure` is not known here (it evaluates the object
/// itself), any other lane asked has no surface on its range
/// ([`FirstOf`] per lane). Lanes not asked hold anything.
///
/// Why arrays, not eight [`FirstOf`]: a kernel leaf's answers are made
/// four lanes a step with masks (`leaf_firsts`), and the packet's pick of
/// its nearest hits reads the lanes' masks at once. With the enums, made
/// and matched lane by lane, a scene of one ground box took 8% more
/// instructions flat, benches/scenes/capsules 3%, tori 2% (callgrind
/// 480x270).
#[derive(Clone, Copy, Debug)]
pub struct Firsts8 {
    /// Lanes with a first surface.
    pub hit: u32,
    /// Lanes not known here.
    pub unsure: u32,
    /// Where the first surface lies (lanes of `hit`).
    pub t: [f32; 8],
    /// Which surface it is (lanes of `hit`): its leaf (`Surf::leaf`, with
    /// the flip bit)...
    pub leaf: [u32; 8],
    /// ...and sub-surface. (Two arrays, not one of `Surf`: a lane's `Surf`
    /// read as one 8-byte load from its halves stored apart stalls on
    /// store forwarding.)
    pub sub: [u32; 8],
}

impl Default for Firsts8 {
    fn default() -> Self {
        Firsts8 { hit: 0, unsure: 0, t: [0.0; 8], leaf: [Surf::NONE.leaf; 8], sub: [0; 8] }
    }
}

impl Firsts8 {
    /// Sets lane `k` to `f`.
    #[inline(always)]
    pub fn set(&mut self, k: usize, f: FirstOf) {
        let bit = 1u32 << k;
        self.hit &= !bit;
        self.unsure &= !bit;
        match f {
            FirstOf::Miss => {}
            FirstOf::Unsure => self.unsure |= bit,
            FirstOf::Hit(t, s) => {
                self.hit |= bit;
                (self.t[k], self.leaf[k], self.sub[k]) = (t, s.leaf, s.sub);
            }
        }
    }

    /// Lane `k`'s surface.
    #[inline(always)]
    pub fn surf(&self, k: usize) -> Surf {
        Surf { leaf: self.leaf[k], sub: self.sub[k] }
    }

    /// Lane `k` as a [`FirstOf`] (for the tests: the packet reads the
    /// masks and arrays).
    #[cfg(test)]
    fn get(&self, k: usize) -> FirstOf {
        if self.hit & (1 << k) != 0 {
            FirstOf::Hit(self.t[k], self.surf(k))
        } else if self.unsure & (1 << k) != 0 {
            FirstOf::Unsure
        } else {
            FirstOf::Miss
        }
    }
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
            _ if self.leafy[nu] => {
                (self.wide[nu] == u32::MAX && self.count[nu] as usize <= OBJECT_OPS && self.small[nu] != 0) || self.torus_node(leaves, nu)
            }
            _ => self.is_small_tree(nu) || self.is_torus_tree(leaves, nu),
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
    pub fn first_surfaces8(&self, prog: &Program, leaves: &LeafTable, n: u32, lanes: u32, ray: LaneRanges, out: &mut Firsts8) -> bool {
        let nu = n as usize;
        if prog.kind[nu] == NodeKind::Leaf {
            let leaf = prog.first[nu];
            return self.with_solve::<false, _>(leaves, leaf, |r| leaf_firsts(r, leaf, lanes, ray, out)).is_some();
        }
        if !prog.leafy[nu] && !prog.is_small_tree(nu) {
            // A tree with tori (`Program::is_torus_tree`).
            let Some(tt) = self.torus_tree::<false>(prog, leaves, nu) else { return false };
            let done = lanes & tt.done & self.packet_lanes();
            let ops = tt.operands();
            firsts_of(done, lanes, ray, out, |k| ops.first(self, leaves, k, (ray.tmin[k], ray.eps[k])));
            return true;
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
        if prog.small[nu] == 0 {
            return self.torus_node_firsts(prog, leaves, nu, lanes, ray, out);
        }
        // Room for as many operands as the node has, about: the solves'
        // array is set up and each lane's boundaries cleared whole (with
        // room for eight operands, a capsule of three took 3% more
        // instructions, callgrind).
        if prog.count[nu] as usize <= SMALL_FEW {
            self.small_firsts::<SMALL_FEW, { 2 * SMALL_FEW }>(prog, leaves, nu, (lanes, ray), out)
        } else {
            self.small_firsts::<OBJECT_OPS, { 2 * OBJECT_OPS }>(prog, leaves, nu, (lanes, ray), out)
        }
    }

    /// [`PacketMemo::first_surfaces8`] of small node `nu` of at most `N`
    /// operands (`E = 2 N`), lane by lane ([`small_first`]).
    #[inline(always)]
    fn small_firsts<const N: usize, const E: usize>(
        &self,
        prog: &Program,
        leaves: &LeafTable,
        nu: usize,
        (lanes, ray): (u32, LaneRanges),
        out: &mut Firsts8,
    ) -> bool {
        let mut ops = SmallOps::<N>::of(prog, nu);
        if !ops.gather(prog, nu, |leaf| self.with_solve::<false, _>(leaves, leaf, |r| *r)) {
            return false;
        }
        firsts_of(lanes & ops.done, lanes, ray, out, |k| small_first::<N, E>(&ops, k, (ray.tmin[k], ray.eps[k])));
        true
    }
}

/// Up to this many operands, a small object's solves are kept in arrays of
/// this size ([`PacketMemo::first_surfaces8`]).
const SMALL_FEW: usize = 4;

impl PacketMemo {
    /// [`PacketMemo::first_surfaces8`] of leafy node `nu`, whose operands
    /// are kernel leaves and ring tori ([`Program::torus_node`]): each
    /// lane's first span swept as [`small_first`] sweeps it, from the
    /// kernel leaves' solves and the tori's spans on the lane's range from
    /// `lo - 2 eps` on (from the packet's preps, each lane its own query:
    /// a torus has up to three spans on a line, all its boundaries the one
    /// surface). The sweep's argument holds for operands of several spans:
    /// where no two boundaries lie within `2 eps`, nothing fuses. Lanes
    /// outside the packet's preps are unsure. Why: such objects (a torus
    /// cut by a box, a torus minus another) were evaluated lane by lane,
    /// 60% of benches/scenes/tori's instructions flat.
    #[inline(never)]
    fn torus_node_firsts(&self, prog: &Program, leaves: &LeafTable, nu: usize, lanes: u32, ray: LaneRanges, out: &mut Firsts8) -> bool {
        let Some((ops, tori)) = self.torus_node_ops::<false>(prog, leaves, nu) else { return false };
        let done = lanes & ops.done & self.packet_lanes();
        let node = torus_operands(&ops, tori);
        firsts_of(done, lanes, ray, out, |k| node.first(self, leaves, k, (ray.tmin[k], ray.eps[k])));
        true
    }
}

/// The first surfaces on the lanes `lanes` (those of `done` from `first`,
/// a lane's first span of the node; the others unsure) into `out`.
#[inline(always)]
fn firsts_of(done: u32, lanes: u32, ray: LaneRanges, out: &mut Firsts8, first: impl Fn(usize) -> SmallFirst) {
    for k in 0..8 {
        if lanes & (1 << k) == 0 {
            continue;
        }
        out.set(
            k,
            if done & (1 << k) == 0 {
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
            },
        );
    }
}

/// A kernel leaf's first surfaces from its solve `r`: its span clipped to
/// each lane's range as `push_clipped` clips it, and the first real
/// boundary of what is left (`first_surface`).
#[inline(always)]
fn leaf_firsts(r: &Ranges8, leaf: u32, lanes: u32, ray: LaneRanges, out: &mut Firsts8) {
    // Four lanes at a time, picked by masks (`Clipped::lane`'s clip: the
    // SSE2 `max` and `min` give `f32::max`'s and `min`'s values wherever
    // they are taken, a lane outside the range or at an infinite or NaN
    // end, with no zero compared to a zero): a lane the solve did not do
    // is unsure; one it did that misses the leaf, or whose clipped span is
    // empty or has no real boundary, misses; else its first real boundary.
    let mut real = 0u32;
    for h in [0, 4] {
        let (t0, t1) = (Vec4::from_slice(&r.t0[h..]), Vec4::from_slice(&r.t1[h..]));
        let (lo, hi) = (Vec4::from_slice(&ray.tmin[h..]), Vec4::from_slice(&ray.tmax[h..]));
        let real0 = t0.cmpge(lo) & t0.is_finite_mask();
        let real1 = t1.cmple(hi) & t1.is_finite_mask();
        let c0 = Vec4::select(real0, t0, t0.max(lo));
        let c1 = Vec4::select(real1, t1, t1.min(hi));
        real |= (c1.cmpgt(c0) & (real0 | real1)).bitmask() << h;
        Vec4::select(real0, c0, c1).write_to_slice(&mut out.t[h..]);
        // The entry's or the exit's sub-surface, picked as bits (a select
        // moves bits; no float operation touches them).
        let bits = |s: &[u32; 8]| Vec4::from_array(std::array::from_fn(|i| f32::from_bits(s[h + i])));
        let sub = Vec4::select(real0, bits(&r.s0), bits(&r.s1)).to_array();
        for i in 0..4 {
            out.sub[h + i] = sub[i].to_bits();
        }
    }
    out.leaf = [leaf; 8];
    out.hit = (out.hit & !lanes) | (lanes & r.done & r.hit & real);
    out.unsure = (out.unsure & !lanes) | (lanes & !r.done);
}

#[cfg(test)]
mod tests {
    use super::super::small_first::Clipped;
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// The lane-by-lane definition `leaf_firsts` replaced: each lane's
    /// span clipped by `Clipped::lane`, then its first real boundary.
    fn leaf_first_lane(r: &Ranges8, leaf: u32, k: usize, (lo, hi): (f32, f32)) -> FirstOf {
        if r.done & (1 << k) == 0 {
            return FirstOf::Unsure;
        }
        if r.hit & (1 << k) == 0 {
            return FirstOf::Miss;
        }
        let Clipped { c0, c1, real0, real1 } = Clipped::lane(r, k, (lo, hi));
        if !(c1 > c0) {
            FirstOf::Miss
        } else if real0 {
            FirstOf::Hit(c0, Surf::new(leaf, r.s0[k]))
        } else if real1 {
            FirstOf::Hit(c1, Surf::new(leaf, r.s1[k]))
        } else {
            FirstOf::Miss
        }
    }

    /// `leaf_firsts` (four lanes a step, picked by masks) gives every lane
    /// asked what the lane-by-lane clip gives, bit for bit, on random
    /// solves with ends at, inside and outside the ranges, infinities,
    /// NaNs and zeros of both signs, and leaves the other lanes' answers
    /// alone.
    #[test]
    fn leaf_firsts_are_each_lanes_clip() {
        let seed = 0x1eaf_f175u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let vals = [0.0f32, -0.0, 1.0, -1.0, 2.5, 7.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-30, 3e30];
        let pick = |rng: &mut SmallRng| if rng.gen_bool(0.3) { vals[rng.gen_range(0..vals.len())] } else { rng.gen_range(-10.0..10.0) };
        let (mut hits, mut misses, mut unsure) = (0, 0, 0);
        for case in 0..20_000 {
            let mut r = Ranges8 { done: rng.gen::<u32>() | rng.gen::<u32>(), hit: rng.gen(), ..Ranges8::default() };
            let (mut lo, mut hi) = ([0.0f32; 8], [0.0f32; 8]);
            for k in 0..8 {
                (r.t0[k], r.t1[k]) = (pick(&mut rng), pick(&mut rng));
                (r.s0[k], r.s1[k]) = (rng.gen_range(0..6), rng.gen_range(0..6));
                // Ranges as queries have them: no NaN, `lo <= hi`, from
                // minus infinity or zero on, to infinity or a finite end;
                // sometimes at a span's end exactly.
                lo[k] = match rng.gen_range(0..4) {
                    0 => 0.0,
                    1 if !r.t0[k].is_nan() => r.t0[k].clamp(-1e3, 1e3),
                    _ => rng.gen_range(-5.0..5.0),
                };
                hi[k] = match rng.gen_range(0..4) {
                    0 => f32::INFINITY,
                    1 if !r.t1[k].is_nan() => r.t1[k].clamp(lo[k], 1e3),
                    _ => lo[k] + rng.gen_range(0.0..10.0),
                };
            }
            let lanes = rng.gen::<u32>() & 0xff;
            let eps = [1e-6f32; 8];
            let ray = LaneRanges { tmin: &lo, tmax: &hi, eps: &eps };
            let mut out = Firsts8::default();
            let before: [FirstOf; 8] = std::array::from_fn(|k| match k % 3 {
                0 => FirstOf::Miss,
                1 => FirstOf::Unsure,
                _ => FirstOf::Hit(k as f32, Surf::new(9, 9)),
            });
            for (k, &f) in before.iter().enumerate() {
                out.set(k, f);
            }
            leaf_firsts(&r, 5, lanes, ray, &mut out);
            for k in 0..8 {
                let got = out.get(k);
                if lanes & (1 << k) == 0 {
                    // (Their `t` and surface may be overwritten; their kind is kept.)
                    assert_eq!(std::mem::discriminant(&got), std::mem::discriminant(&before[k]), "case {case} lane {k} not asked");
                    continue;
                }
                let want = leaf_first_lane(&r, 5, k, (lo[k], hi[k]));
                match (got, want) {
                    (FirstOf::Hit(a, s), FirstOf::Hit(b, u)) => {
                        assert_eq!((a.to_bits(), s), (b.to_bits(), u), "case {case} lane {k}: {r:?} on ({}, {})", lo[k], hi[k]);
                        hits += 1;
                    }
                    (g, w) => {
                        assert_eq!(g, w, "case {case} lane {k}: {r:?} on ({}, {})", lo[k], hi[k]);
                        if g == FirstOf::Miss {
                            misses += 1;
                        } else {
                            unsure += 1;
                        }
                    }
                }
            }
        }
        println!("{hits} hits, {misses} misses, {unsure} unsure");
        assert!(hits > 5_000 && misses > 5_000 && unsure > 5_000, "{hits} hits, {misses} misses, {unsure} unsure");
    }
}
