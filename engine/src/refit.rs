//! Refitting a binary object tree in place: when an object moves, the boxes
//! from its leaf to the root grow or shrink to fit, and the walk stops at the
//! first ancestor whose box did not change. The tree's quality is followed as
//! the sum of its nodes' surface areas (the SAH cost without its constants),
//! so the caller can rebuild once it has degraded.

use glam::Vec3;
use rothray_primitives::{
    bvh::{BvhNode, FlatBvh},
    Aabb,
};

const NONE: u32 = u32::MAX;

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
        let mut r = Refit { parent: vec![NONE; bvh.nodes.len()], leaf_of: vec![NONE; n_prims], cost: 0.0, built_cost: 0.0 };
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

    /// The tree's cost relative to right after its build.
    pub fn degradation(&self) -> f64 {
        if self.built_cost > 0.0 {
            self.cost / self.built_cost
        } else {
            1.0
        }
    }
}
