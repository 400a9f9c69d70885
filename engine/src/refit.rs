//! Refitting a binary object tree in place: when an object moves, the boxes
//! from its leaf to the root grow or shrink to fit, and the walk stops at the
//! first ancestor whose box did not change. The tree's quality is followed as
//! the sum of its nodes' surface areas (the SAH cost without its constants),
//! so the caller can rebuild once it has degraded. Objects that come and go
//! are removed from and inserted into the tree in place ([`Refit::remove`],
//! [`Refit::insert`]), and a sync that renumbers objects renames the
//! tree's primitives ([`Refit::renumber`]).

use glam::Vec3;
use rothray_primitives::{
    bvh::{BvhNode, FlatBvh},
    Aabb,
};

const NONE: u32 = u32::MAX;

/// A node slot not in use yet.
const UNUSED: BvhNode = BvhNode { min: Vec3::ZERO, first: 0, max: Vec3::ZERO, count: 0 };

/// Parent links and primitive positions of one binary [`FlatBvh`] (built by
/// `build_binary` / `build_cull`: an inner node's children are `first` and
/// `first + 1`).
#[derive(Default)]
pub(crate) struct Refit {
    parent: Vec<u32>,
    /// Per primitive id, the leaf node holding it (`NONE`: not in the tree).
    leaf_of: Vec<u32>,
    /// Sum of the nodes' surface areas now, and right after the build.
    cost: f64,
    built_cost: f64,
    /// Pairs of node slots (by their first) that removals left unused.
    free: Vec<u32>,
}

fn area(n: &BvhNode) -> f64 {
    let d = (n.max - n.min).max(Vec3::ZERO).as_dvec3();
    d.x * d.y + d.y * d.z + d.z * d.x
}

fn set_box(n: &mut BvhNode, b: &Aabb) -> bool {
    let same = n.min.to_array().map(f32::to_bits) == b.min.to_array().map(f32::to_bits)
        && n.max.to_array().map(f32::to_bits) == b.max.to_array().map(f32::to_bits);
    (n.min, n.max) = (b.min, b.max);
    !same
}

impl Refit {
    /// Links for `bvh` over primitive ids `0..n_prims`, whose boxes `box_of`
    /// gives; recomputes every node's box as the exact union of its children
    /// (so a refit that changes nothing stops at once, and the root is the
    /// union of the primitives, bit for bit).
    pub fn new(bvh: &mut FlatBvh, n_prims: usize, box_of: impl Fn(u32) -> Aabb) -> Refit {
        assert!(bvh.cw.is_none(), "a refit needs a binary tree");
        let mut r =
            Refit { parent: vec![NONE; bvh.nodes.len()], leaf_of: vec![NONE; n_prims], cost: 0.0, built_cost: 0.0, free: Vec::new() };
        if bvh.nodes.is_empty() {
            return r;
        }
        // Post-order by an explicit stack (children may sit anywhere).
        let mut stack = vec![(0u32, false)];
        while let Some((ni, done)) = stack.pop() {
            let n = bvh.nodes[ni as usize];
            if n.count > 0 {
                let mut b = Aabb::EMPTY;
                for k in n.first..n.first + n.count {
                    let p = bvh.prims[k as usize];
                    r.leaf_of[p as usize] = ni;
                    b = b.union(&box_of(p));
                }
                set_box(&mut bvh.nodes[ni as usize], &b);
            } else if !done {
                r.parent[n.first as usize] = ni;
                r.parent[n.first as usize + 1] = ni;
                stack.push((ni, true));
                stack.push((n.first, false));
                stack.push((n.first + 1, false));
            } else {
                let (a, c) = (&bvh.nodes[n.first as usize], &bvh.nodes[n.first as usize + 1]);
                let b = Aabb::new(a.min, a.max).union(&Aabb::new(c.min, c.max));
                set_box(&mut bvh.nodes[ni as usize], &b);
            }
        }
        r.cost = bvh.nodes.iter().map(area).sum();
        r.built_cost = r.cost;
        r
    }

    /// Refits the boxes from primitive `p`'s leaf up, after its box changed.
    pub fn update(&mut self, bvh: &mut FlatBvh, p: u32, box_of: impl Fn(u32) -> Aabb) {
        let mut ni = self.leaf_of[p as usize];
        let n = bvh.nodes[ni as usize];
        let mut b = Aabb::EMPTY;
        for k in n.first..n.first + n.count {
            b = b.union(&box_of(bvh.prims[k as usize]));
        }
        loop {
            let node = &mut bvh.nodes[ni as usize];
            let old = area(node);
            if !set_box(node, &b) {
                return;
            }
            self.cost += area(node) - old;
            ni = self.parent[ni as usize];
            if ni == NONE {
                return;
            }
            let n = bvh.nodes[ni as usize];
            let (a, c) = (&bvh.nodes[n.first as usize], &bvh.nodes[n.first as usize + 1]);
            b = Aabb::new(a.min, a.max).union(&Aabb::new(c.min, c.max));
        }
    }

    /// Recomputes node `ni`'s box as the exact union of its children (or
    /// primitives), and its ancestors' up to the first that does not change.
    fn fix_up(&mut self, bvh: &mut FlatBvh, mut ni: u32, box_of: &impl Fn(u32) -> Aabb) {
        loop {
            let n = bvh.nodes[ni as usize];
            let b = if n.count > 0 {
                (n.first..n.first + n.count).fold(Aabb::EMPTY, |b, k| b.union(&box_of(bvh.prims[k as usize])))
            } else {
                let (a, c) = (&bvh.nodes[n.first as usize], &bvh.nodes[n.first as usize + 1]);
                Aabb::new(a.min, a.max).union(&Aabb::new(c.min, c.max))
            };
            let node = &mut bvh.nodes[ni as usize];
            let old = area(node);
            if !set_box(node, &b) {
                return;
            }
            self.cost += area(node) - old;
            ni = self.parent[ni as usize];
            if ni == NONE {
                return;
            }
        }
    }

    /// Takes primitive `p` out of the tree (if it is in). A leaf left empty
    /// goes, and its sibling takes its parent's place.
    pub fn remove(&mut self, bvh: &mut FlatBvh, p: u32, box_of: impl Fn(u32) -> Aabb) {
        let Some(&l) = self.leaf_of.get(p as usize).filter(|&&l| l != NONE) else { return };
        self.leaf_of[p as usize] = NONE;
        let n = bvh.nodes[l as usize];
        if n.count > 1 {
            // The last primitive of the leaf takes `p`'s slot.
            let (first, last) = (n.first as usize, (n.first + n.count - 1) as usize);
            let k = (first..=last).find(|&k| bvh.prims[k] == p).expect("the primitive is in its leaf");
            bvh.prims[k] = bvh.prims[last];
            bvh.nodes[l as usize].count -= 1;
            self.fix_up(bvh, l, &box_of);
            return;
        }
        let parent = self.parent[l as usize];
        if parent == NONE {
            // The root leaf: the tree is empty now.
            bvh.nodes.clear();
            bvh.prims.clear();
            self.parent.clear();
            self.free.clear();
            self.cost = 0.0;
            return;
        }
        let pair = bvh.nodes[parent as usize].first;
        let sibling = pair + (l == pair) as u32;
        self.cost -= area(&bvh.nodes[l as usize]) + area(&bvh.nodes[parent as usize]);
        let s = bvh.nodes[sibling as usize];
        bvh.nodes[parent as usize] = s;
        if s.count > 0 {
            for k in s.first..s.first + s.count {
                self.leaf_of[bvh.prims[k as usize] as usize] = parent;
            }
        } else {
            self.parent[s.first as usize] = parent;
            self.parent[s.first as usize + 1] = parent;
        }
        self.free.push(pair);
        let up = self.parent[parent as usize];
        if up != NONE {
            self.fix_up(bvh, up, &box_of);
        }
    }

    /// Puts primitive `p` (box `box_of(p)`) into the tree: down from the
    /// root towards the child whose box grows least, the leaf reached
    /// becoming the parent of itself and a new leaf of `p`.
    pub fn insert(&mut self, bvh: &mut FlatBvh, p: u32, box_of: impl Fn(u32) -> Aabb) {
        let b = box_of(p);
        if self.leaf_of.len() <= p as usize {
            self.leaf_of.resize(p as usize + 1, NONE);
        }
        let leaf = |first: u32| BvhNode { min: b.min, first, max: b.max, count: 1 };
        if bvh.nodes.is_empty() {
            bvh.nodes.push(leaf(bvh.prims.len() as u32));
            bvh.prims.push(p);
            self.parent = vec![NONE];
            self.leaf_of[p as usize] = 0;
            self.cost = area(&bvh.nodes[0]);
            return;
        }
        let grown = |n: &BvhNode| {
            let u = Aabb::new(n.min, n.max).union(&b);
            area(&BvhNode { min: u.min, first: 0, max: u.max, count: 0 }) - area(n)
        };
        let mut ni = 0u32;
        while bvh.nodes[ni as usize].count == 0 {
            let f = bvh.nodes[ni as usize].first;
            ni = if grown(&bvh.nodes[f as usize + 1]) < grown(&bvh.nodes[f as usize]) { f + 1 } else { f };
        }
        let pair = self.free.pop().unwrap_or_else(|| {
            let at = bvh.nodes.len() as u32;
            bvh.nodes.extend([UNUSED, UNUSED]);
            self.parent.extend([NONE, NONE]);
            at
        });
        let old = bvh.nodes[ni as usize];
        bvh.nodes[pair as usize] = old;
        for k in old.first..old.first + old.count {
            self.leaf_of[bvh.prims[k as usize] as usize] = pair;
        }
        bvh.nodes[pair as usize + 1] = leaf(bvh.prims.len() as u32);
        bvh.prims.push(p);
        self.leaf_of[p as usize] = pair + 1;
        bvh.nodes[ni as usize].first = pair;
        bvh.nodes[ni as usize].count = 0;
        self.parent[pair as usize] = ni;
        self.parent[pair as usize + 1] = ni;
        self.cost += area(&bvh.nodes[pair as usize]) + area(&bvh.nodes[pair as usize + 1]);
        self.fix_up(bvh, ni, &box_of);
    }

    /// Renames the primitives: `map[p]` is `p`'s new id (every primitive in
    /// the tree must have one); `n` ids after.
    pub fn renumber(&mut self, bvh: &mut FlatBvh, map: &[u32], n: usize) {
        let mut leaf_of = vec![NONE; n];
        for (p, &l) in self.leaf_of.iter().enumerate() {
            if l != NONE {
                leaf_of[map[p] as usize] = l;
            }
        }
        self.leaf_of = leaf_of;
        // Slots of removed primitives (unreachable) may hold ids without one.
        for p in bvh.prims.iter_mut() {
            *p = map.get(*p as usize).copied().unwrap_or(NONE);
        }
    }

    /// The tree's cost relative to right after its build.
    pub fn degradation(&self) -> f64 {
        if self.built_cost > 0.0 {
            self.cost / self.built_cost
        } else {
            1.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// The reachable primitives of `bvh`, checking on the way that every
    /// node's box is the exact union of its children's (or primitives') and
    /// that the links agree with the layout.
    fn walk(bvh: &FlatBvh, r: &Refit, boxes: &[Aabb]) -> Vec<u32> {
        let mut out = Vec::new();
        if bvh.nodes.is_empty() {
            return out;
        }
        let bits = |b: &Aabb| (b.min.to_array().map(f32::to_bits), b.max.to_array().map(f32::to_bits));
        let mut stack = vec![0u32];
        while let Some(ni) = stack.pop() {
            let n = bvh.nodes[ni as usize];
            let b = if n.count > 0 {
                let mut b = Aabb::EMPTY;
                for k in n.first..n.first + n.count {
                    let p = bvh.prims[k as usize];
                    assert_eq!(r.leaf_of[p as usize], ni, "leaf_of of primitive {p}");
                    b = b.union(&boxes[p as usize]);
                    out.push(p);
                }
                b
            } else {
                for c in [n.first, n.first + 1] {
                    assert_eq!(r.parent[c as usize], ni, "parent of node {c}");
                    stack.push(c);
                }
                let (a, c) = (&bvh.nodes[n.first as usize], &bvh.nodes[n.first as usize + 1]);
                Aabb::new(a.min, a.max).union(&Aabb::new(c.min, c.max))
            };
            assert_eq!(bits(&Aabb::new(n.min, n.max)), bits(&b), "node {ni}: not the union of its parts");
        }
        out.sort_unstable();
        out
    }

    /// Random removals, insertions and renumberings of a built tree keep
    /// exactly the primitives present (each once), with exact boxes, the
    /// root's box the union of the present boxes bit for bit (what a fresh
    /// build's root is), and rays finding what a brute-force test finds.
    #[test]
    fn inserts_removals_and_renumbering_keep_an_exact_tree() {
        let seed = 0x7e1ee5u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let random_box = |rng: &mut SmallRng| {
            let c = Vec3::new(rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0));
            let h = Vec3::new(rng.gen_range(0.1..2.0), rng.gen_range(0.1..2.0), rng.gen_range(0.1..2.0));
            Aabb::new(c - h, c + h)
        };
        for round in 0..20 {
            let n0 = [0, 1, 2, 3, 40, 300][round % 6];
            let mut boxes: Vec<Aabb> = (0..n0).map(|_| random_box(&mut rng)).collect();
            let mut bvh = FlatBvh::build_cull(&boxes, 2);
            let mut r = Refit::new(&mut bvh, boxes.len(), |p| boxes[p as usize]);
            // Present ids are 0..boxes.len() throughout (removal renumbers the last one into the hole).
            for step in 0..400 {
                if rng.gen_bool(0.5) && !boxes.is_empty() {
                    let p = rng.gen_range(0..boxes.len() as u32);
                    r.remove(&mut bvh, p, |q| boxes[q as usize]);
                    let last = boxes.len() as u32 - 1;
                    let map: Vec<u32> = (0..=last).map(|q| if q == last { p } else { q }).collect();
                    boxes.swap_remove(p as usize);
                    if p != last {
                        r.renumber(&mut bvh, &map, boxes.len());
                    } else {
                        r.leaf_of.truncate(boxes.len());
                    }
                } else {
                    boxes.push(random_box(&mut rng));
                    r.insert(&mut bvh, boxes.len() as u32 - 1, |q| boxes[q as usize]);
                }
                let got = walk(&bvh, &r, &boxes);
                assert_eq!(got, (0..boxes.len() as u32).collect::<Vec<_>>(), "round {round} step {step}: the primitives present");
                let all = boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(b));
                let bits = |b: &Aabb| (b.min.to_array().map(f32::to_bits), b.max.to_array().map(f32::to_bits));
                if !boxes.is_empty() {
                    assert_eq!(bits(&bvh.bounds()), bits(&all), "round {round} step {step}: the root box");
                }
                let o = Vec3::new(rng.gen_range(-30.0..30.0), rng.gen_range(-30.0..30.0), 40.0);
                let d = Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), -1.0);
                let mut found = Vec::new();
                bvh.traverse(o, d.recip(), 0.0, f32::INFINITY, |p, _| {
                    if boxes[p as usize].ray_range(o, d.recip(), 0.0, f32::INFINITY).is_some() {
                        found.push(p);
                    }
                    f32::INFINITY
                });
                found.sort_unstable();
                let want: Vec<u32> =
                    (0..boxes.len() as u32).filter(|&p| boxes[p as usize].ray_range(o, d.recip(), 0.0, f32::INFINITY).is_some()).collect();
                assert_eq!(found, want, "round {round} step {step}: a ray's boxes");
            }
            println!("round {round}: {} primitives at the end, cost {:.2} of the build's", boxes.len(), r.degradation());
        }
    }
}
