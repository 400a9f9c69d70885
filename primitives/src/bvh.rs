//! BVHs over boxes, built by obvhs. Traversal uses obvhs' compressed 8-wide
//! `CwBvh` (SSE node tests, octant-ordered front-to-back walk with a shrinking
//! `tmax`); tiny sets (at most `max_leaf` boxes) skip the tree and are one leaf.
//! House rule 3: the tracer's side sees only boxes and a closure.
//!
//! Measured on `scenes/forest` (10 000 leaves in one union, 1920x1080): the
//! binary node layout this replaced walked ~20 nodes per call and the render took
//! 1.2 s; see the README's benchmark table for the current figure.

use glam::Vec3;
use obvhs::{
    aabb::Aabb as OAabb,
    bvh2::builder::build_bvh2,
    cwbvh::{builder::build_cwbvh, CwBvh},
    ray::{Ray as ORay, RayHit},
    BvhBuildParams,
};
use smallvec::SmallVec;

use crate::aabb::Aabb;

/// One node: a leaf when `count > 0` (primitives `prims[first..first + count]`),
/// otherwise an inner node with children `first` and `first + 1`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct BvhNode {
    /// Box minimum.
    pub min: Vec3,
    /// First child or first primitive slot.
    pub first: u32,
    /// Box maximum.
    pub max: Vec3,
    /// Primitive count (0 for inner nodes).
    pub count: u32,
}

/// A BVH over a set of boxes; `prims` lists primitive ids in leaf order.
#[derive(Clone, Debug, Default)]
pub struct FlatBvh {
    /// Nodes, root first.
    pub nodes: Vec<BvhNode>,
    /// Primitive ids referenced by the leaves (a `CwBvh` holds them in its
    /// `primitive_indices` instead: one copy, 4 bytes per box).
    pub prims: Vec<u32>,
    /// The wide BVH (None for a single-leaf set).
    pub cw: Option<CwBvh>,
    /// The input boxes (kept with a `CwBvh`, which has no point query;
    /// empty in a tree for rays only, [`FlatBvh::build_for_rays`]).
    pub boxes: Vec<Aabb>,
    /// A tree over parts ([`FlatBvh::over_parts`]): `cw`'s primitives are
    /// indices into this list, whose trees hold the primitives.
    pub parts: Vec<FlatBvh>,
}

/// The queue of [`FlatBvh::visit_nearest`] (kept by callers to reuse its
/// memory): entries as (entry parameter in `total_cmp` order, 0 for a node
/// or 1 for a primitive, id), smallest first.
pub type NearestQueue = Vec<std::cmp::Reverse<(u32, u32, u32)>>;

/// obvhs' `CwBvh` culls every box the ray leaves before t = 1e-4 (its
/// EPSILON), whatever `ray.tmin` says. So it walks our ray with t scaled by
/// `T_SCALE`, a power of two: `t' = t * T_SCALE`, the same origin, `inv_d *
/// T_SCALE`. Every slab distance is then exactly ours times `T_SCALE` (no
/// rounding is added), and only boxes left before t = 1e-4 / 2^20 are
/// culled. (An origin moved back along the ray instead was rounded to the
/// f32 grid: 2.4e-4 sideways at 6e3 from the origin, enough to miss boxes
/// that the ray crosses for 7e-4; far_tests below.)
const T_SCALE: f32 = (1u64 << 20) as f32;

/// Largest `|inv_d * T_SCALE|` handed to obvhs (2^70 unscaled: directions
/// of 1e-21 and up keep their inverse). Its node test multiplies it by a
/// power-of-two node extent and 8-bit box offsets, which must stay finite
/// (an infinite inverse times a zero offset is NaN) for node extents up to
/// 2^28.
const INV_LIMIT: f32 = (1u128 << 90) as f32;

/// The obvhs ray of our ray `o + t / inv_d` on `[tmin, tmax]`, t scaled by
/// `T_SCALE`; `None` for a ray that meets nothing.
fn scaled_ray(o: Vec3, inv_d: Vec3, tmin: f32, tmax: f32) -> Option<ORay> {
    // A zero direction (every inverse infinite) meets nothing.
    if !o.is_finite() || inv_d.is_nan() || inv_d.abs().cmpeq(Vec3::INFINITY).all() {
        return None;
    }
    // obvhs picks each slab's near side by `direction < 0`, so a zero
    // component (either sign) gets a positive inverse.
    let lane = |inv: f32| if inv.is_infinite() { INV_LIMIT } else { (inv * T_SCALE).clamp(-INV_LIMIT, INV_LIMIT) };
    let inv = Vec3::new(lane(inv_d.x), lane(inv_d.y), lane(inv_d.z));
    let dir = Vec3::new(
        if inv_d.x.is_infinite() { 0.0 } else { inv_d.x.recip() },
        if inv_d.y.is_infinite() { 0.0 } else { inv_d.y.recip() },
        if inv_d.z.is_infinite() { 0.0 } else { inv_d.z.recip() },
    );
    Some(ORay { origin: o.into(), direction: dir.into(), inv_direction: inv.into(), tmin: tmin * T_SCALE, tmax: tmax * T_SCALE })
}

/// `t`'s bits as an integer in `f32::total_cmp` order.
fn ordered(t: f32) -> u32 {
    let b = t.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// The inverse of [`ordered`].
fn unordered(k: u32) -> f32 {
    f32::from_bits(if k & 0x8000_0000 != 0 { k & 0x7fff_ffff } else { !k })
}

impl FlatBvh {
    /// Builds over `boxes` (all must be finite and non-empty). `max_leaf` primitives per leaf at most.
    pub fn build(boxes: &[Aabb], max_leaf: u32) -> FlatBvh {
        let mut t = Self::build_for_rays(boxes, max_leaf);
        if t.cw.is_some() {
            t.boxes = boxes.to_vec();
        }
        t
    }

    /// [`FlatBvh::build`] for ray walks only: the boxes are not kept (24
    /// bytes per box), so [`FlatBvh::cull`] and [`FlatBvh::point_query`]
    /// find nothing in the `CwBvh` (a wide CSG node's children, whose region
    /// queries go to its [`crate::box_wide::BoxWide`]).
    pub fn build_for_rays(boxes: &[Aabb], max_leaf: u32) -> FlatBvh {
        if boxes.is_empty() {
            return FlatBvh::default();
        }
        if boxes.len() <= max_leaf as usize {
            let mut b = Aabb::EMPTY;
            for x in boxes {
                b = b.union(x);
            }
            return FlatBvh {
                nodes: vec![BvhNode { min: b.min, first: 0, max: b.max, count: boxes.len() as u32 }],
                prims: (0..boxes.len() as u32).collect(),
                ..FlatBvh::default()
            };
        }
        // Each box grown by 8 ulps of its largest coordinate: obvhs tests a
        // child as `q * extent * inv + (p - o) * inv` from its node's corner
        // `p`, rounded otherwise than `Aabb::ray_range`'s `(max - o) * inv`,
        // and a ray that grazes a box by `ray_range` must not miss it here.
        let oboxes: Vec<OAabb> = boxes
            .iter()
            .map(|b| {
                let pad = b.min.abs().max(b.max.abs()).max_element() * (1.0 / (1u32 << 20) as f32);
                OAabb::new((b.min - Vec3::splat(pad)).into(), (b.max + Vec3::splat(pad)).into())
            })
            .collect();
        // The highest-quality preset: on `scenes/forest` (10 000 leaves in one
        // union) it traced 12% faster than `medium_build` (1.39 -> 1.23 s, one
        // thread, no shadows) for a bake of 25 ms. Its pre-splitting applies to
        // triangles only, so no primitive is listed twice.
        let mut params = BvhBuildParams::very_slow_build();
        params.max_prims_per_leaf = max_leaf.clamp(1, 3);
        let mut t = std::time::Duration::ZERO;
        let mut cw = build_cwbvh(&oboxes, params, &mut t);
        // obvhs leaves room for a node per box: 80 bytes per box, of which a
        // union of 10^6 spheres used 11.
        cw.nodes.shrink_to_fit();
        let b = cw.total_aabb;
        FlatBvh { nodes: vec![BvhNode { min: b.min.into(), first: 0, max: b.max.into(), count: 0 }], cw: Some(cw), ..FlatBvh::default() }
    }

    /// A tree for rays over the trees `parts` (each built for rays, its
    /// primitive ids already final), whose bounds are `bounds`.
    pub fn over_parts(bounds: &[Aabb], parts: Vec<FlatBvh>) -> FlatBvh {
        let mut top = Self::build_for_rays(bounds, 1);
        if top.cw.is_none() {
            // One part (or none): it is the tree.
            return parts.into_iter().next().unwrap_or_default();
        }
        top.parts = parts;
        top
    }

    /// Replaces every primitive id `p` by `f(p)`.
    pub fn map_prims(&mut self, f: &impl Fn(u32) -> u32) {
        if !self.parts.is_empty() {
            self.parts.iter_mut().for_each(|p| p.map_prims(f));
            return;
        }
        let ids = match &mut self.cw {
            Some(cw) => &mut cw.primitive_indices,
            None => &mut self.prims,
        };
        for x in ids.iter_mut() {
            *x = f(*x);
        }
    }

    /// Builds a binary BVH (obvhs `Bvh2`: PLOC, reinsertion, collapse) and keeps its
    /// nodes in `nodes` (inner nodes have children `first` and `first + 1`), for
    /// callers with a traversal of their own (meshes); `traverse` walks it too.
    pub fn build_binary(boxes: &[Aabb], max_leaf: u32) -> FlatBvh {
        Self::binary_with(boxes, max_leaf, BvhBuildParams::medium_build())
    }

    /// [`FlatBvh::build_binary`] with obvhs' fastest preset: for region
    /// queries (tiles), where a looser tree costs little. The bake of
    /// `scenes/forest` (10 000 boxes) takes 33.6 ms with these trees, 30.5 ms
    /// without (`rothray bench --json` bake_s, medians of 5).
    pub fn build_cull(boxes: &[Aabb], max_leaf: u32) -> FlatBvh {
        Self::binary_with(boxes, max_leaf, BvhBuildParams::fastest_build())
    }

    fn binary_with(boxes: &[Aabb], max_leaf: u32, mut params: BvhBuildParams) -> FlatBvh {
        if boxes.len() <= max_leaf as usize {
            return FlatBvh::build(boxes, max_leaf);
        }
        let oboxes: Vec<OAabb> = boxes.iter().map(|b| OAabb::new(b.min.into(), b.max.into())).collect();
        params.max_prims_per_leaf = max_leaf.max(1);
        let mut t = std::time::Duration::ZERO;
        let mut b2 = build_bvh2(&oboxes, params, &mut t);
        drop(oboxes);
        let nodes = b2
            .nodes
            .iter()
            .map(|n| {
                let a = n.aabb();
                BvhNode { min: a.min.into(), first: n.first_index, max: a.max.into(), count: n.prim_count }
            })
            .collect();
        FlatBvh { nodes, prims: std::mem::take(&mut b2.primitive_indices), ..FlatBvh::default() }
    }

    /// Root box (empty for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map(|n| Aabb::new(n.min, n.max)).unwrap_or(Aabb::EMPTY)
    }

    /// Visits, roughly nearest first, every primitive whose leaf box the ray
    /// segment `[tmin, tmax]` touches. `f(prim, t_enter_box)` returns the new `tmax`
    /// (return the current one to keep going; a smaller one prunes farther nodes;
    /// a value below `tmin` stops the walk).
    #[inline]
    pub fn traverse(&self, o: Vec3, inv_d: Vec3, tmin: f32, mut tmax: f32, mut f: impl FnMut(u32, f32) -> f32) {
        if self.nodes.is_empty() {
            return;
        }
        if let Some(cw) = &self.cw {
            let Some(ray) = scaled_ray(o, inv_d, tmin, tmax) else { return };
            let to_w = |t: f32| t * T_SCALE;
            let mut hit = RayHit::none();
            let prims = &cw.primitive_indices;
            if !self.parts.is_empty() {
                // Each part met is walked with the range left so far (parts
                // hold more than two boxes each: each has its `CwBvh`).
                let mut cur = tmax;
                cw.ray_traverse(ray, &mut hit, |_, slot| {
                    let Some(pcw) = &self.parts[prims[slot] as usize].cw else { return to_w(cur) };
                    let pprims = &pcw.primitive_indices;
                    let mut stop = false;
                    let mut phit = RayHit::none();
                    let pray = ORay { tmax: to_w(cur), ..ray };
                    pcw.ray_traverse(pray, &mut phit, |_, s| {
                        let nt = f(pprims[s], tmin);
                        if nt < tmin {
                            stop = true;
                            return f32::NEG_INFINITY;
                        }
                        cur = nt;
                        to_w(nt)
                    });
                    if stop {
                        return f32::NEG_INFINITY;
                    }
                    to_w(cur)
                });
                return;
            }
            cw.ray_traverse(ray, &mut hit, |_, slot| {
                let nt = f(prims[slot], tmin);
                if nt < tmin {
                    // Stop: a tmax below every box's entry culls every remaining node.
                    return f32::NEG_INFINITY;
                }
                to_w(nt)
            });
            return;
        }
        let root = &self.nodes[0];
        let Some((t0, _)) = Aabb::new(root.min, root.max).ray_range(o, inv_d, tmin, tmax) else { return };
        if root.count > 0 {
            // One leaf (a scene of one object, a small node): no stack.
            for k in root.first..root.first + root.count {
                tmax = f(self.prims[k as usize], t0);
                if tmax < tmin {
                    return;
                }
            }
            return;
        }
        let mut stack: SmallVec<[(u32, f32); 64]> = SmallVec::new();
        stack.push((0, t0));
        while let Some((ni, tenter)) = stack.pop() {
            if tenter > tmax {
                continue;
            }
            let n = &self.nodes[ni as usize];
            if n.count > 0 {
                for k in n.first..n.first + n.count {
                    tmax = f(self.prims[k as usize], tenter);
                    if tmax < tmin {
                        return;
                    }
                }
                continue;
            }
            let a = &self.nodes[n.first as usize];
            let b = &self.nodes[n.first as usize + 1];
            let ra = Aabb::new(a.min, a.max).ray_range(o, inv_d, tmin, tmax);
            let rb = Aabb::new(b.min, b.max).ray_range(o, inv_d, tmin, tmax);
            match (ra, rb) {
                (Some((ta, _)), Some((tb, _))) => {
                    if ta <= tb {
                        stack.push((n.first + 1, tb));
                        stack.push((n.first, ta));
                    } else {
                        stack.push((n.first, ta));
                        stack.push((n.first + 1, tb));
                    }
                }
                (Some((ta, _)), None) => stack.push((n.first, ta)),
                (None, Some((tb, _))) => stack.push((n.first + 1, tb)),
                _ => {}
            }
        }
    }

    /// Visits every primitive of a leaf whose box, and every ancestor's box,
    /// passes `test` (a superset of the primitives whose own box passes: callers
    /// test those themselves). Binary trees ([`FlatBvh::build_binary`]) walk
    /// their nodes; a `CwBvh` tests its input boxes one by one and, like
    /// [`FlatBvh::point_query`], reports input positions.
    pub fn cull(&self, mut test: impl FnMut(&Aabb) -> bool, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        if self.cw.is_some() {
            for (i, b) in self.boxes.iter().enumerate() {
                if test(b) {
                    f(i as u32);
                }
            }
            return;
        }
        let mut stack: SmallVec<[u32; 64]> = SmallVec::new();
        stack.push(0);
        while let Some(ni) = stack.pop() {
            let n = &self.nodes[ni as usize];
            if !test(&Aabb::new(n.min, n.max)) {
                continue;
            }
            if n.count > 0 {
                for k in n.first..n.first + n.count {
                    f(self.prims[k as usize]);
                }
            } else {
                stack.push(n.first + 1);
                stack.push(n.first);
            }
        }
    }

    /// Visits the primitives whose own entry (`entry(prim)`, `None` when
    /// the ray misses the primitive's box) is at most the limit, in
    /// increasing (entry in `total_cmp` order, id) order: the order of
    /// sorting them all, without listing those past the limit. `f(prim,
    /// entry)` returns the new limit (`limit` at first). Best-first by
    /// node entry: a node's box holds its primitives' boxes and the slab
    /// test is monotone in the box, so a node enters no later than its
    /// primitives, and a node is opened before a primitive of the same
    /// entry. Node boxes are tested on `[tmin, tmax]`, as
    /// [`FlatBvh::traverse`] does. (A wide tree lists and sorts.)
    pub fn visit_nearest(
        &self,
        (o, inv_d, tmin, tmax): (Vec3, Vec3, f32, f32),
        limit: f32,
        queue: &mut NearestQueue,
        entry: impl Fn(u32) -> Option<f32>,
        mut f: impl FnMut(u32, f32) -> f32,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let mut limit = limit;
        if self.cw.is_some() {
            let mut all: Vec<(f32, u32)> = Vec::new();
            self.traverse(o, inv_d, tmin, tmax, |p, _| {
                if let Some(t) = entry(p) {
                    all.push((t, p));
                }
                tmax
            });
            all.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for (t, p) in all {
                if t > limit {
                    break;
                }
                limit = f(p, t);
            }
            return;
        }
        let mut heap = std::collections::BinaryHeap::from(std::mem::take(queue));
        heap.clear();
        let node_entry = |n: &BvhNode| Aabb::new(n.min, n.max).ray_range(o, inv_d, tmin, tmax).map(|r| r.0);
        if let Some(t) = node_entry(&self.nodes[0]) {
            heap.push(std::cmp::Reverse((ordered(t), 0, 0)));
        }
        while let Some(std::cmp::Reverse((k, kind, id))) = heap.pop() {
            let t = unordered(k);
            if t > limit {
                break;
            }
            if kind == 1 {
                limit = f(id, t);
                continue;
            }
            let n = &self.nodes[id as usize];
            if n.count > 0 {
                for &p in &self.prims[n.first as usize..(n.first + n.count) as usize] {
                    if let Some(tp) = entry(p).filter(|&tp| tp <= limit) {
                        heap.push(std::cmp::Reverse((ordered(tp), 1, p)));
                    }
                }
            } else {
                for c in [n.first, n.first + 1] {
                    if let Some(tc) = node_entry(&self.nodes[c as usize]).filter(|&tc| tc <= limit) {
                        heap.push(std::cmp::Reverse((ordered(tc), 0, c)));
                    }
                }
            }
        }
        *queue = heap.into_vec();
    }

    /// Visits every primitive whose leaf box contains `p` (a superset is fine:
    /// callers test the primitive itself). A `CwBvh` has no point query (and a
    /// zero-length ray finds nothing in it: it culls boxes left before t =
    /// 1e-4), so [`FlatBvh::cull`] tests its boxes themselves.
    pub fn point_query(&self, p: Vec3, f: impl FnMut(u32)) {
        self.cull(|b| b.contains(p), f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// `visit_nearest` visits exactly the boxes the ray meets, in the order
    /// of sorting them by (entry, id), and stops where the limit says: on
    /// random boxes (many with equal entries: shared faces), random rays,
    /// limits from the visited entries.
    #[test]
    fn nearest_visits_match_a_sorted_list() {
        let seed = 0x9ea7u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut queue = NearestQueue::new();
        for round in 0..300 {
            let n = rng.gen_range(1..200);
            // Integer corners: coincident faces and equal entries.
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(rng.gen_range(-8..8) as f32, rng.gen_range(-8..8) as f32, rng.gen_range(-8..8) as f32);
                    Aabb::new(c, c + Vec3::new(rng.gen_range(1..4) as f32, rng.gen_range(1..4) as f32, rng.gen_range(1..4) as f32))
                })
                .collect();
            let bvh = FlatBvh::build_cull(&boxes, 2);
            let o = Vec3::new(rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0), -30.0);
            let d = Vec3::new(rng.gen_range(-0.4..0.4), rng.gen_range(-0.4..0.4), 1.0);
            let (inv, tmin) = (d.recip(), if round % 3 == 0 { 10.0 } else { 0.0 });
            let entry = |p: u32| boxes[p as usize].ray_range(o, inv, tmin, f32::INFINITY).map(|r| r.0);
            let mut want: Vec<(f32, u32)> = (0..n as u32).filter_map(|p| entry(p).map(|t| (t, p))).collect();
            want.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            // A limit that falls at the k-th entry (or none).
            let stop = rng.gen_range(0..want.len() + 1);
            let cut = want.get(stop).map_or(f32::INFINITY, |w| w.0);
            let mut got = Vec::new();
            bvh.visit_nearest((o, inv, tmin, f32::INFINITY), f32::INFINITY, &mut queue, entry, |p, t| {
                got.push((t, p));
                if got.len() > stop {
                    cut
                } else {
                    f32::INFINITY
                }
            });
            let expect: Vec<(f32, u32)> =
                want.iter().copied().enumerate().take_while(|&(i, w)| i <= stop || w.0 <= cut).map(|x| x.1).collect();
            assert_eq!(got, expect, "round {round}: {n} boxes, stop after {stop}");
        }
    }

    #[test]
    fn traversal_matches_brute_force() {
        let seed = 7u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let boxes: Vec<Aabb> = (0..500)
            .map(|_| {
                let c = Vec3::new(rng.gen_range(-10.0..10.0), rng.gen_range(-10.0..10.0), rng.gen_range(-10.0..10.0));
                let h = Vec3::splat(rng.gen_range(0.05..1.0));
                Aabb::new(c - h, c + h)
            })
            .collect();
        let bvh = FlatBvh::build(&boxes, 4);
        for _ in 0..2000 {
            let o = Vec3::new(rng.gen_range(-15.0..15.0), rng.gen_range(-15.0..15.0), rng.gen_range(-15.0..15.0));
            let d = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
            let inv = d.recip();
            let mut got = vec![];
            bvh.traverse(o, inv, 0.0, 30.0, |p, _| {
                got.push(p);
                30.0
            });
            for (i, b) in boxes.iter().enumerate() {
                if b.ray_range(o, inv, 0.0, 30.0).is_some() {
                    assert!(got.contains(&(i as u32)), "missed box {i}");
                }
            }
        }
    }
}

#[cfg(test)]
mod cw_regressions {
    use super::*;

    fn grid() -> (Vec<Aabb>, FlatBvh) {
        let boxes: Vec<Aabb> = (0..64)
            .map(|i| {
                let c = Vec3::new((i % 4) as f32, ((i / 4) % 4) as f32, (i / 16) as f32);
                Aabb::new(c, c + Vec3::splat(0.5))
            })
            .collect();
        let bvh = FlatBvh::build(&boxes, 1);
        assert!(bvh.cw.is_some());
        (boxes, bvh)
    }

    #[test]
    fn point_query_finds_every_box_holding_the_point() {
        // Regression: the CwBvh point query walked a zero-length ray and found nothing.
        let (boxes, bvh) = grid();
        for (i, b) in boxes.iter().enumerate() {
            let mut got = vec![];
            bvh.point_query(b.center(), |k| got.push(k));
            assert_eq!(got, vec![i as u32]);
        }
    }

    #[test]
    fn long_directions_and_origins_inside_boxes() {
        // Regression: obvhs culls boxes left before t = 1e-4, which with |d| = 1e4
        // is a whole unit of length.
        let (boxes, bvh) = grid();
        for (i, b) in boxes.iter().enumerate() {
            for d in [Vec3::new(1e4, 3.0, 7.0), Vec3::new(-2e-3, 1e-3, 5e-4), Vec3::new(0.3, -1.0, 0.2)] {
                let o = b.max - Vec3::splat(1e-3); // just inside, about to leave
                let mut got = vec![];
                bvh.traverse(o, d.recip(), 0.0, f32::INFINITY, |k, _| {
                    got.push(k);
                    f32::INFINITY
                });
                assert!(got.contains(&(i as u32)), "box {i} holding the origin missed with d {d}");
            }
        }
    }
}

#[cfg(test)]
mod small_tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    #[test]
    fn small_sets_and_inside_origins() {
        let seed = 11u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for n in [2usize, 3, 5, 8, 9, 17, 40, 300] {
            for _ in 0..50 {
                let boxes: Vec<Aabb> = (0..n)
                    .map(|_| {
                        let c = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                        let mut h = Vec3::new(rng.gen_range(0.01..0.6), rng.gen_range(0.01..0.6), rng.gen_range(0.01..0.6));
                        if rng.gen_bool(0.2) {
                            h[rng.gen_range(0..3)] = 0.0;
                        }
                        if rng.gen_bool(0.1) {
                            h *= 1e-4;
                        }
                        Aabb::new(c - h, c + h)
                    })
                    .collect();
                let bvh = FlatBvh::build(&boxes, 1);
                for _ in 0..200 {
                    let o = Vec3::new(rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0))
                        * if rng.gen_bool(0.3) { 100.0 } else { 1.0 };
                    let d = (Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)) - o * 0.01)
                        * if rng.gen_bool(0.3) { 1e-3 } else { 1.0 };
                    let (tmin, tmax) = (0.0, if rng.gen_bool(0.5) { 10.0 } else { f32::INFINITY });
                    let mut got = vec![];
                    bvh.traverse(o, d.recip(), tmin, tmax, |p, _| {
                        got.push(p);
                        tmax
                    });
                    let mut sorted = got.clone();
                    sorted.sort();
                    sorted.dedup();
                    assert_eq!(sorted.len(), got.len(), "n {n}: a primitive visited twice: {got:?}");
                    for (i, b) in boxes.iter().enumerate() {
                        if b.ray_range(o, d.recip(), tmin, tmax).is_some() {
                            assert!(got.contains(&(i as u32)), "n {n}: missed box {i} of {boxes:?} o {o} d {d} tmax {tmax}; got {got:?}");
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod far_tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    #[test]
    fn far_from_origin_traversal_finds_every_box_the_ray_meets() {
        let seed = 5u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let off = Vec3::new(3072.0, -2048.0, 5120.0);
        let boxes: Vec<Aabb> = (0..300)
            .map(|_| {
                let c = off + Vec3::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0));
                let h = Vec3::new(rng.gen_range(0.01..0.5), rng.gen_range(0.01..0.5), rng.gen_range(0.01..0.5));
                Aabb::new(c - h, c + h)
            })
            .collect();
        let bvh = FlatBvh::build_for_rays(&boxes, 1);
        let mut missed = 0;
        let mut met = 0;
        for _ in 0..20000 {
            // Rays from among the boxes and from 60 units away.
            let r = if rng.gen_bool(0.3) { 60.0 } else { 5.0 };
            let o = off + Vec3::new(rng.gen_range(-r..r), rng.gen_range(-r..r), rng.gen_range(-r..r));
            let b = &boxes[rng.gen_range(0..boxes.len())];
            // Aim at a corner of a box: short spans.
            let corner = Vec3::new(
                if rng.gen_bool(0.5) { b.min.x } else { b.max.x },
                if rng.gen_bool(0.5) { b.min.y } else { b.max.y },
                if rng.gen_bool(0.5) { b.min.z } else { b.max.z },
            ) + Vec3::new(rng.gen_range(-1e-3..1e-3), rng.gen_range(-1e-3..1e-3), rng.gen_range(-1e-3..1e-3));
            let d = (corner - o).normalize();
            let inv = d.recip();
            let mut got = vec![];
            bvh.traverse(o, inv, 0.0, f32::INFINITY, |p, _| {
                got.push(p);
                f32::INFINITY
            });
            for (i, b) in boxes.iter().enumerate() {
                if let Some((t0, t1)) = b.ray_range(o, inv, 0.0, f32::INFINITY) {
                    met += 1;
                    if !got.contains(&(i as u32)) {
                        missed += 1;
                        if missed < 10 {
                            println!("missed box {i} {b:?} o {o} d {d} span {t0} {t1} len {}", t1 - t0);
                        }
                    }
                }
            }
        }
        assert_eq!(missed, 0, "missed {missed} of {met}");
    }
}
