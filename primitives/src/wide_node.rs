//! The trees of a wide CSG node's children: a `CwBvh` for single rays
//! ([`FlatBvh::build_for_rays`]) and a 4-wide tree for packets and region
//! queries ([`BoxWide`]). Above [`PART`] boxes they are built part by part
//! (spatially coherent parts, each tree built and its build's scratch
//! freed before the next), under a small tree over the parts: obvhs' builds
//! take some 250-290 bytes of scratch per box at their peak, which on a
//! union of 10^6 spheres was more than the baked scene keeps.

use crate::aabb::Aabb;
use crate::box_wide::BoxWide;
use crate::bvh::FlatBvh;

/// The most boxes one obvhs build sees.
pub const PART: usize = 1 << 16;

/// A wide node's trees; primitive ids are those given to [`WideTrees::build`].
#[derive(Clone, Debug, Default)]
pub struct WideTrees {
    /// For single rays.
    pub rays: FlatBvh,
    /// For packets of eight rays and for region queries.
    pub packet: BoxWide,
}

impl WideTrees {
    /// Builds over `n` boxes, box `i` being `box_of(i)` (finite, non-empty)
    /// and carrying the id `id_of(i)`. Above [`PART`] boxes only a part's
    /// boxes are copied at a time (a copy of all of them was 24 bytes per
    /// box at the bake's peak).
    pub fn build(n: usize, box_of: impl Fn(u32) -> Aabb, id_of: impl Fn(u32) -> u32) -> WideTrees {
        if n <= PART {
            let boxes: Vec<Aabb> = (0..n as u32).map(&box_of).collect();
            return Self::build_part(&boxes, &id_of);
        }
        let (order, ranges) = split(n, &box_of, PART);
        let part_bounds = |&(a, b): &(u32, u32)| order[a as usize..b as usize].iter().fold(Aabb::EMPTY, |u, &i| u.union(&box_of(i)));
        let bounds: Vec<Aabb> = ranges.iter().map(part_bounds).collect();
        // The packet tree grows part by part behind its top (a merge of
        // all parts at the end held the parts and the whole tree at once,
        // and the tree's doublings: 111 MB at the peak of a union of 10^6
        // spheres' bake).
        let top = FlatBvh::build_cull(&bounds, 1);
        let mut packet = BoxWide::top_of_parts(&top.nodes, &top.prims);
        let top_len = packet.sizes().0;
        drop(top);
        let mut roots = Vec::with_capacity(ranges.len());
        let mut rays = Vec::with_capacity(ranges.len());
        for (k, &(a, b)) in ranges.iter().enumerate() {
            let part = &order[a as usize..b as usize];
            let pb: Vec<Aabb> = part.iter().map(|&i| box_of(i)).collect();
            let t = Self::build_part(&pb, &|j| id_of(part[j as usize]));
            drop(pb);
            rays.push(t.rays);
            if k == 0 {
                // The parts are alike (median splits): room for all of them
                // at the first one's size, and a little more.
                let (nn, nl, ni) = t.packet.sizes();
                let more = |x: usize| x * (ranges.len() - 1) + x * ranges.len() / 8;
                packet.reserve(nn + more(nn), nl + more(nl), ni + more(ni));
            }
            roots.push(packet.push_part(t.packet));
            // The part's build scratch (some 24 MB for 65 536 boxes) goes
            // back to the system: glibc would keep it to the end of the bake.
            crate::trim::release_free_memory();
        }
        drop(order);
        packet.link_parts(top_len, &roots);
        packet.shrink_lists_to_fit();
        WideTrees { rays: FlatBvh::over_parts(&bounds, rays), packet }
    }

    /// One part: both trees over `boxes`, box `i` carrying `id(i)`. The
    /// region tree is obvhs' fastest binary build collapsed (a tree of its
    /// medium quality instead cost scenes/forest 6% more instructions), its
    /// binary nodes dropped once collapsed.
    fn build_part(boxes: &[Aabb], id: &impl Fn(u32) -> u32) -> WideTrees {
        let mut rays = FlatBvh::build_for_rays(boxes, 2);
        rays.map_prims(id);
        let mut cull = FlatBvh::build_cull(boxes, 4);
        cull.map_prims(id);
        let mut packet = BoxWide::from_binary(&cull.nodes, &cull.prims);
        drop(cull);
        packet.shrink_to_fit();
        WideTrees { rays, packet }
    }
}

/// Orders the boxes into spatially coherent runs of at most `most`
/// (median splits of their centres along the longest axis): the order (box
/// indices) and the runs (half-open ranges of it).
fn split(n: usize, box_of: &impl Fn(u32) -> Aabb, most: usize) -> (Vec<u32>, Vec<(u32, u32)>) {
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut ranges = Vec::new();
    let mut stack = vec![(0usize, n)];
    while let Some((a, b)) = stack.pop() {
        if b - a <= most {
            ranges.push((a as u32, b as u32));
            continue;
        }
        let c = |i: u32| box_of(i).center();
        let ext = order[a..b].iter().fold(Aabb::EMPTY, |u, &i| u.union(&Aabb::new(c(i), c(i))));
        let d = ext.max - ext.min;
        let axis = if d.x >= d.y && d.x >= d.z {
            0
        } else if d.y >= d.z {
            1
        } else {
            2
        };
        let mid = (b - a) / 2;
        order[a..b].select_nth_unstable_by(mid, |&i, &j| c(i)[axis].total_cmp(&c(j)[axis]));
        // Pushed second half first: the runs come out left to right.
        stack.push((a + mid, b));
        stack.push((a, a + mid));
    }
    (order, ranges)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// Above `PART` boxes (built in parts): a ray visits every box it
    /// meets, once, with its own id; a region query finds every box it
    /// touches; below, the trees are those of one build.
    #[test]
    fn parts_walk_and_cull_every_box() {
        let seed = 31u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for n in [PART / 3, 2 * PART + 77] {
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(rng.gen_range(0.0..100.0), rng.gen_range(0.0..100.0), rng.gen_range(0.0..100.0));
                    Aabb::new(c, c + Vec3::splat(rng.gen_range(0.05..1.0)))
                })
                .collect();
            let ids: Vec<u32> = (0..n as u32).map(|i| 3 * i + 1).collect();
            let t = WideTrees::build(n, |i| boxes[i as usize], |i| ids[i as usize]);
            assert_eq!(t.rays.parts.is_empty(), n <= PART, "n {n}");
            for _ in 0..300 {
                let o = Vec3::new(rng.gen_range(-10.0..110.0), rng.gen_range(-10.0..110.0), -5.0);
                let d = Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), 1.0);
                let tmax = if rng.gen_bool(0.5) { rng.gen_range(10.0..200.0) } else { f32::INFINITY };
                let mut got = Vec::new();
                t.rays.traverse(o, d.recip(), 0.0, tmax, |p, _| {
                    got.push(p);
                    tmax
                });
                let mut sorted = got.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(sorted.len(), got.len(), "n {n}: a box visited twice");
                for (i, b) in boxes.iter().enumerate() {
                    if b.ray_range(o, d.recip(), 0.0, tmax).is_some() {
                        assert!(sorted.binary_search(&ids[i]).is_ok(), "n {n}: the ray missed box {i}");
                    }
                }
                // A stop ends the walk once obvhs has finished the node's
                // group of leaves it came from (8 children of up to 2 boxes),
                // in a part as in one tree.
                let mut calls = 0;
                t.rays.traverse(o, d.recip(), 0.0, tmax, |_, _| {
                    calls += 1;
                    -1.0
                });
                assert!(calls <= 16, "n {n}: {calls} visits after a stop");
            }
            for _ in 0..50 {
                let c = Vec3::new(rng.gen_range(0.0..100.0), rng.gen_range(0.0..100.0), rng.gen_range(0.0..100.0));
                let region = Aabb::new(c, c + Vec3::splat(rng.gen_range(0.5..20.0)));
                let touches = |b: &Aabb| b.min.cmple(region.max).all() && region.min.cmple(b.max).all();
                let mut got = Vec::new();
                t.packet.cull(touches, |p| got.push(p));
                got.sort_unstable();
                for (i, b) in boxes.iter().enumerate() {
                    if touches(b) {
                        assert!(got.binary_search(&ids[i]).is_ok(), "n {n}: the region missed box {i}");
                    }
                }
            }
        }
    }
}
