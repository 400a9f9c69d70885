//! A 4-wide BVH over boxes walked by packets of eight rays at once: the
//! wide CSG nodes' children (a union of 10 000 leaves) for the rays of one
//! packet, each node's four child boxes tested against all eight rays with
//! the mesh walk's node test ([`Packet8`], 8-lane AVX where the CPU has it,
//! two SSE halves otherwise, the same arithmetic per lane). Coherent camera
//! rays visit mostly the same nodes, so one node test serves eight rays
//! instead of one; each ray keeps its own range, which its visits shrink.

use glam::Vec3;
use smallvec::SmallVec;

use crate::aabb::Aabb;
use crate::bvh::BvhNode;
use crate::frustum::Frustum;
use crate::mesh::wide::{axis_signs, collapse, order4, Node4, Packet8, F8, LEAF};
use crate::mesh::SLAB_EPS;

/// The tree; node 0 is the root (no nodes for an empty set).
#[derive(Clone, Debug, Default)]
pub struct BoxWide {
    nodes: Vec<Node4>,
    /// Per leaf, its range in `ids`.
    leaves: Vec<(u32, u32)>,
    /// The payload ids of the leaves' boxes.
    ids: Vec<u32>,
}

/// Eight rays (per lane origin, direction and range start) for [`BoxWide::walk8`].
#[derive(Clone, Copy, Debug)]
pub struct Rays8<'a> {
    /// Origins.
    pub o: &'a [Vec3; 8],
    /// Directions.
    pub d: &'a [Vec3; 8],
    /// Range starts.
    pub tmin: &'a [f32; 8],
}

/// What a packet walk ([`BoxWide::walk8`]) tells its caller.
pub trait Visit8 {
    /// The ranges of the lanes `lanes` meet the leaf box of payload `id`
    /// (`rays` tests the payload's own box exactly).
    fn visit(&mut self, id: u32, lanes: u32, rays: &Lanes8);
    /// [`Visit8::visit`] of payload `id` whose box `b` the caller has at
    /// hand (a list that keeps its payloads' boxes).
    #[inline(always)]
    fn visit_box(&mut self, id: u32, b: &Aabb, lanes: u32, rays: &Lanes8) {
        let _ = b;
        self.visit(id, lanes, rays)
    }
    /// Every box not visited yet is entered at `lower` or later by every
    /// lane (`+inf`: the walk is over); the caller may shrink lanes' range
    /// ends `thi`, which prunes their later boxes.
    fn settle(&mut self, lower: f32, thi: &mut [f32; 8]);
    /// How far the lanes still reach (no box entered past it by every lane
    /// changes anything), and the nearest entry of the boxes visited and
    /// not settled yet: by default unknown (`+inf`, `+inf`: the visits
    /// neither stop nor settle early).
    #[inline(always)]
    fn bounds(&self) -> (f32, f32) {
        (f32::INFINITY, f32::INFINITY)
    }
}

/// The packet's rays, for a visitor's own box tests.
pub struct Lanes8<'a> {
    p: &'a Packet8,
}

impl Lanes8<'_> {
    /// Per lane, what [`Aabb::ray_range`] gives lane k's ray on
    /// `[tmin[k], tmax[k]]` for box `b`, bit for bit: bit k of the mask where
    /// it meets the box, and the entries.
    #[inline]
    pub fn ray_range(&self, b: &Aabb, tmin: &[f32; 8], tmax: &[f32; 8]) -> (u32, [f32; 8]) {
        let (m, e) = self.p.box_range(b, &F8(*tmin), &F8(*tmax));
        (m, e.0)
    }
}

/// The box test of [`Lanes8::ray_range`] for eight rays outside a walk
/// (a tile's list of objects, tested once per packet instead of once per
/// ray).
pub struct BoxTest8(Packet8);

impl BoxTest8 {
    /// `None` unless the rays form a packet ([`forms_packet`]).
    #[inline]
    pub fn new(o: &[Vec3; 8], d: &[Vec3; 8]) -> Option<BoxTest8> {
        Packet8::new(o, d).map(BoxTest8)
    }

    /// [`BoxTest8::new`] of the rays `o(k) + t d(k)`, read where they are.
    #[inline]
    pub fn from_lanes(o: impl Fn(usize) -> Vec3, d: impl Fn(usize) -> Vec3) -> Option<BoxTest8> {
        Packet8::from_lanes(o, d).map(BoxTest8)
    }

    /// [`Lanes8::ray_range`]: per lane what [`Aabb::ray_range`] gives, bit
    /// for bit.
    #[inline(always)]
    pub fn ray_range(&self, b: &Aabb, tmin: &[f32; 8], tmax: &[f32; 8]) -> (u32, [f32; 8]) {
        Lanes8 { p: &self.0 }.ray_range(b, tmin, tmax)
    }

    /// [`BoxTest8::ray_range`] with 8-lane AVX ops, for loops compiled with
    /// AVX: per lane the same operations in the same order, so the same bits.
    ///
    /// # Safety
    /// The CPU must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub unsafe fn ray_range_avx(&self, b: &Aabb, tmin: &[f32; 8], tmax: &[f32; 8]) -> (u32, [f32; 8]) {
        self.0.box_range_avx(b, tmin, tmax)
    }

    /// Per lane, where the line enters and leaves box `b` before any range
    /// clips it: [`Aabb::clip_slabs`] of these on lane k's `[tmin, tmax]`
    /// is what [`Aabb::ray_range`] gives lane k's ray there, bit for bit
    /// (one test of a box for eight rays whose ranges are not known yet).
    #[inline(always)]
    pub fn slabs(&self, b: &Aabb) -> ([f32; 8], [f32; 8]) {
        let (enter, leave) = self.0.box_slabs(b);
        (enter.0, leave.0)
    }
}

/// Do eight rays of directions `d` form a packet for [`BoxWide::walk8`]
/// (one direction octant, no zero component)?
// (The test of `Packet8::new`, without the packet: making one for the
// answer divided 24 components, 1.5% of benches/scenes/forest lit, perf.)
pub fn forms_packet(d: &[Vec3; 8]) -> bool {
    (0..3).all(|a| {
        let (_, neg, pos) = axis_signs(d, a);
        neg == 0xff || pos == 0xff
    })
}

impl BoxWide {
    /// Collapses the binary tree `bin` (inner nodes have children `first`
    /// and `first + 1`, leaves list `prims[first..first + count]`), whose
    /// primitive `p` carries the payload `p` itself.
    pub fn from_binary(bin: &[BvhNode], prims: &[u32]) -> BoxWide {
        let mut w = BoxWide::default();
        if bin.is_empty() {
            return w;
        }
        let (leaves, ids) = (&mut w.leaves, &mut w.ids);
        w.nodes = collapse(bin, |n| {
            leaves.push((ids.len() as u32, n.count));
            ids.extend_from_slice(&prims[n.first as usize..(n.first + n.count) as usize]);
            LEAF | (leaves.len() - 1) as u32
        });
        w
    }

    /// The top of a tree over parts: the binary tree `top` (leaves of one
    /// primitive each, the index of a part) collapsed. Append the parts, in
    /// order, with [`BoxWide::push_part`] (each part's memory is freed as
    /// soon as it is in, so the whole tree is never held twice), then
    /// [`BoxWide::link_parts`] puts their roots in the top's leaves.
    pub fn top_of_parts(top: &[BvhNode], top_prims: &[u32]) -> BoxWide {
        BoxWide { nodes: collapse(top, |n| LEAF | top_prims[n.first as usize]), ..BoxWide::default() }
    }

    /// Appends the nodes, leaves and ids of part `p` (its payload ids
    /// already final); returns where its root lands.
    pub fn push_part(&mut self, p: BoxWide) -> u32 {
        let (node0, leaf0, id0) = (self.nodes.len() as u32, self.leaves.len() as u32, self.ids.len() as u32);
        for mut n in p.nodes {
            for s in 0..4 {
                if n.slot_box(s).is_some() {
                    let c = n.child(s as u32);
                    n.set_child(s, if c & LEAF != 0 { LEAF | ((c & !LEAF) + leaf0) } else { c + node0 });
                }
            }
            self.nodes.push(n);
        }
        self.leaves.extend(p.leaves.iter().map(|&(f, c)| (f + id0, c)));
        self.ids.extend_from_slice(&p.ids);
        node0
    }

    /// Points the leaves of the top (its first `top_len` nodes) at the
    /// parts' roots (`roots[k]`: part `k`'s, from [`BoxWide::push_part`]).
    pub fn link_parts(&mut self, top_len: usize, roots: &[u32]) {
        for n in self.nodes[..top_len].iter_mut() {
            for s in 0..4 {
                if n.slot_box(s).is_some() {
                    n.set_child(s, roots[(n.child(s as u32) & !LEAF) as usize]);
                }
            }
        }
    }

    /// Room for `nodes`, `leaves` and `ids` more (the parts still to come).
    pub fn reserve(&mut self, nodes: usize, leaves: usize, ids: usize) {
        self.nodes.reserve(nodes);
        self.leaves.reserve(leaves);
        self.ids.reserve(ids);
    }

    /// Sizes: nodes, leaves, ids.
    pub fn sizes(&self) -> (usize, usize, usize) {
        (self.nodes.len(), self.leaves.len(), self.ids.len())
    }

    /// Frees the room left over in the leaf and id lists only. The nodes
    /// are 64-byte aligned, and the system allocator shrinks (or grows)
    /// such a block by a copy: on a tree built part by part the whole node
    /// list twice (51 MB at the peak of a union of 10^6 spheres' bake),
    /// while its room past the end, never written, costs no memory.
    pub fn shrink_lists_to_fit(&mut self) {
        self.leaves.shrink_to_fit();
        self.ids.shrink_to_fit();
    }

    /// Frees the room the build left over.
    pub fn shrink_to_fit(&mut self) {
        self.nodes.shrink_to_fit();
        self.leaves.shrink_to_fit();
        self.ids.shrink_to_fit();
    }

    /// Visits the payload of every leaf whose box, and every ancestor's
    /// box, passes `test` (a superset of the payloads whose own box passes:
    /// callers test those themselves); a region query.
    pub fn cull(&self, mut test: impl FnMut(&Aabb) -> bool, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: SmallVec<[u32; 64]> = SmallVec::new();
        stack.push(0);
        while let Some(ni) = stack.pop() {
            let n = &self.nodes[ni as usize];
            for s in 0..4 {
                let Some(b) = n.slot_box(s) else { continue };
                if !test(&b) {
                    continue;
                }
                let c = n.child(s as u32);
                if c & LEAF != 0 {
                    let (first, count) = self.leaves[(c & !LEAF) as usize];
                    for &id in &self.ids[first as usize..(first + count) as usize] {
                        f(id);
                    }
                } else {
                    stack.push(c);
                }
            }
        }
    }

    /// [`BoxWide::cull`] with `region`'s box test ([`Frustum::touches_box`],
    /// four slots at a time), while `more()` says to go on.
    pub fn cull_region(&self, region: &Frustum, mut more: impl FnMut() -> bool, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: SmallVec<[u32; 64]> = SmallVec::new();
        stack.push(0);
        while let Some(ni) = stack.pop() {
            if !more() {
                return;
            }
            let n = &self.nodes[ni as usize];
            let mut m = region.touches_slots(n.rows());
            while m != 0 {
                let s = m.trailing_zeros();
                m &= m - 1;
                let c = n.child(s);
                if c & LEAF != 0 {
                    let (first, count) = self.leaves[(c & !LEAF) as usize];
                    for &id in &self.ids[first as usize..(first + count) as usize] {
                        f(id);
                    }
                } else {
                    stack.push(c);
                }
            }
        }
    }

    /// Heap bytes held (capacity of the node, leaf and id arrays).
    pub fn heap_bytes(&self) -> [usize; 3] {
        [
            self.nodes.capacity() * std::mem::size_of::<Node4>(),
            self.leaves.capacity() * std::mem::size_of::<(u32, u32)>(),
            self.ids.capacity() * 4,
        ]
    }

    /// Is the tree empty?
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Walks the tree for the lanes in `active` of `rays`, nearest boxes
    /// first: `v.visit(id, lanes, ..)` for every payload `id` of a leaf
    /// whose box the ranges `[tmin[k], thi[k]]` of `lanes` meet (conservatively, as
    /// [`Aabb::ray_range`] with a relative slack of `SLAB_EPS`), and
    /// `v.settle` whenever the walk takes up a deferred subtree (with the
    /// smallest entry of what is left: no box is listed out of that order)
    /// and at the end. Returns
    /// `false`, having visited nothing, when the rays do not share a
    /// direction octant or a direction component is zero (the caller then
    /// goes ray by ray).
    pub fn walk8(&self, rays: &Rays8, active: u32, thi: &mut [f32; 8], v: &mut impl Visit8) -> bool {
        if self.nodes.is_empty() || active == 0 {
            return true;
        }
        let Some(p) = Packet8::new(rays.o, rays.d) else { return false };
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            unsafe { self.walk8_avx(&p, rays.tmin, active, thi, v) };
            return true;
        }
        self.walk8_in::<false>(&p, rays.tmin, active, thi, v);
        true
    }

    /// Instead of a walk: `v.visit(id, active, ..)` for every id of `ids`
    /// (a list holding every payload whose box a lane of `active` can meet,
    /// such as a tile's list filtered by [`crate::ray_plane`]), then
    /// `v.settle(+inf)`. The visitor's own exact box tests make the same
    /// visits count as a walk's. Returns `false`, having visited nothing,
    /// where [`walk8`](Self::walk8) would.
    pub fn visit_listed<'b>(
        rays: &Rays8,
        active: u32,
        thi: &mut [f32; 8],
        ids: impl Iterator<Item = (u32, &'b Aabb)>,
        v: &mut impl Visit8,
    ) -> bool {
        let Some(p) = Packet8::new(rays.o, rays.d) else { return false };
        if active != 0 {
            let lanes = Lanes8 { p: &p };
            for (id, b) in ids {
                v.visit_box(id, b, active, &lanes);
            }
        }
        v.settle(f32::INFINITY, thi);
        true
    }

    /// [`BoxWide::visit_listed`] of a list nearest first: `(id, box,
    /// near)` with `near` at most `per_t` times every lane's entry into the
    /// box, and not decreasing. The visitor settles before a box whose
    /// `near` lies past the nearest entry waiting (so it solves a few
    /// children at a time, and its reach shrinks before the farther boxes
    /// are tested), and the visits stop at the first box past every lane's
    /// reach ([`Visit8::bounds`]). Why: a tile of a dense forest lists
    /// some 100 children, and each packet tested every box the ray-plane
    /// filter left and sorted every child met.
    pub fn visit_listed_near<'b>(
        rays: &Rays8,
        active: u32,
        thi: &mut [f32; 8],
        (ids, per_t): (impl Iterator<Item = (u32, &'b Aabb, f32)>, f32),
        v: &mut impl Visit8,
    ) -> bool {
        let Some(p) = Packet8::new(rays.o, rays.d) else { return false };
        if active != 0 {
            let lanes = Lanes8 { p: &p };
            for (id, b, near) in ids {
                let (reach, waiting) = v.bounds();
                if near > reach * per_t {
                    break;
                }
                if near > waiting * per_t {
                    v.settle(near / per_t, thi);
                    if near > v.bounds().0 * per_t {
                        break;
                    }
                }
                v.visit_box(id, b, active, &lanes);
            }
        }
        v.settle(f32::INFINITY, thi);
        true
    }

    /// [`walk8`](Self::walk8) with the baseline SSE2 node test, for tests:
    /// both visit the same payloads in the same order.
    #[doc(hidden)]
    pub fn walk8_sse(&self, rays: &Rays8, active: u32, thi: &mut [f32; 8], v: &mut impl Visit8) -> bool {
        if self.nodes.is_empty() || active == 0 {
            return true;
        }
        let Some(p) = Packet8::new(rays.o, rays.d) else { return false };
        self.walk8_in::<false>(&p, rays.tmin, active, thi, v);
        true
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn walk8_avx(&self, p: &Packet8, tmin: &[f32; 8], active: u32, thi: &mut [f32; 8], v: &mut impl Visit8) {
        self.walk8_in::<true>(p, tmin, active, thi, v)
    }

    /// The walk; `AVX` (only instantiated inside a function compiled with
    /// AVX) tests the nodes with 8-lane ops.
    #[inline(always)]
    fn walk8_in<const AVX: bool>(&self, p: &Packet8, tmin: &[f32; 8], active: u32, thi: &mut [f32; 8], v: &mut impl Visit8) {
        let tlo = F8(*tmin);
        let mut hi = F8(*thi);
        // (child code, lanes that reached it, their smallest entry parameter,
        // the smallest of those parameters from the bottom of the stack up to
        // this entry: what is left is entered no earlier, read at every pop
        // without a pass over the stack)
        let mut stack: SmallVec<[(u32, u32, f32, f32); 64]> = SmallVec::new();
        let (mut cur, mut mask) = (0u32, active & hi.ge_mask(&tlo));
        if mask == 0 {
            return;
        }
        loop {
            if cur & LEAF != 0 {
                let (first, count) = self.leaves[(cur & !LEAF) as usize];
                let lanes = Lanes8 { p };
                for &id in &self.ids[first as usize..(first + count) as usize] {
                    v.visit(id, mask, &lanes);
                }
            } else {
                let n = &self.nodes[cur as usize];
                #[cfg(target_arch = "x86_64")]
                // SAFETY: AVX is only true in `walk8_avx`, compiled with AVX.
                let h = if AVX { unsafe { p.hit_avx(n, &tlo, &hi) } } else { p.hit(n, &tlo, &hi) };
                #[cfg(not(target_arch = "x86_64"))]
                let h = p.hit(n, &tlo, &hi);
                let mut hm = 0u32;
                for (s, &(m, _)) in h.iter().enumerate() {
                    hm |= ((m & mask != 0) as u32) << s;
                }
                if hm.is_power_of_two() {
                    // One child met: no order to sort out (`order4` would put
                    // it first).
                    let s = hm.trailing_zeros() as usize;
                    (cur, mask) = (n.child(s as u32), h[s].0 & mask);
                    continue;
                }
                // None met: nothing to sort either, on to the deferred subtrees.
                if hm != 0 {
                    let (order, ne) = order4(h.map(|x| x.1), hm);
                    // Far to near, so the nearest is taken first.
                    for i in (1..ne).rev() {
                        let s = order[i] as usize;
                        let t = h[s].1;
                        let below = stack.last().map_or(t, |e| e.3.min(t));
                        stack.push((n.child(s as u32), h[s].0 & mask, t, below));
                    }
                    let s = order[0] as usize;
                    (cur, mask) = (n.child(s as u32), h[s].0 & mask);
                    continue;
                }
            }
            loop {
                let Some(&(_, _, _, lower)) = stack.last() else {
                    v.settle(f32::INFINITY, &mut hi.0);
                    *thi = hi.0;
                    return;
                };
                // Every entry left is at least the smallest deferred one.
                // (A child's entry is at least its node's: the same arithmetic
                // on planes inside the node's. The margin is for safety only.)
                v.settle(lower - lower.abs() * SLAB_EPS, &mut hi.0);
                let (c, m, t, _) = stack.pop().expect("not empty");
                // Lanes whose range now ends before it drop out.
                let m2 = hi.reaching(t) & m;
                if m2 != 0 {
                    (cur, mask) = (c, m2);
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::FlatBvh;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// `forms_packet` answers what making a packet answers: one octant per
    /// axis, no zero or NaN component (random signs, zeros and NaNs).
    #[test]
    fn forms_packet_is_whether_a_packet_forms() {
        let seed = 0xf0a7u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut formed = 0;
        for round in 0..20_000 {
            let base: [f32; 3] = std::array::from_fn(|_| if rng.gen_bool(0.5) { 1.0 } else { -1.0 });
            let d: [Vec3; 8] = std::array::from_fn(|_| {
                Vec3::from_array(std::array::from_fn(|a| match rng.gen_range(0..40) {
                    0 => 0.0,
                    1 => -0.0,
                    2 => f32::NAN,
                    3 => -base[a],
                    _ => base[a] * rng.gen_range(1e-3..2.0),
                }))
            });
            let want = Packet8::new(&d, &d).is_some();
            assert_eq!(forms_packet(&d), want, "round {round}: {d:?}");
            formed += want as u32;
        }
        println!("{formed} of 20000 formed packets");
        assert!(formed > 500 && formed < 19_500);
    }

    /// Records the visits; shrinks each lane's range to its cut at the
    /// first settle (as a nearest-hit walk would); checks that no box
    /// listed after a settle is entered before its bound.
    struct Rec<'a> {
        got: Vec<(usize, u32)>,
        cut: [f32; 8],
        order_ok: bool,
        boxes: &'a [Aabb],
        rays: &'a Rays8<'a>,
        lower: f32,
    }

    impl Visit8 for Rec<'_> {
        fn visit(&mut self, id: u32, lanes: u32, rays: &Lanes8) {
            let r = self.rays;
            let b = &self.boxes[id as usize];
            let (m, e) = rays.ray_range(b, r.tmin, &[f32::INFINITY; 8]);
            for k in 0..8 {
                if lanes & (1 << k) == 0 {
                    continue;
                }
                // The exact test is `Aabb::ray_range`'s, bit for bit.
                let one = b.ray_range(r.o[k], r.d[k].recip(), r.tmin[k], f32::INFINITY);
                assert_eq!(one.map(|x| x.0.to_bits()), (m & (1 << k) != 0).then(|| e[k].to_bits()), "lane {k} box {id}");
                if let Some((t0, _)) = one {
                    // (The slab slack lets a walk list a box a hair early.)
                    if t0 < self.lower - self.lower.abs() * 1e-5 {
                        self.order_ok = false;
                    }
                }
                self.got.push((k, id));
            }
        }
        fn settle(&mut self, lower: f32, thi: &mut [f32; 8]) {
            self.lower = self.lower.max(lower.min(1e30));
            for k in 0..8 {
                thi[k] = thi[k].min(self.cut[k]);
            }
        }
    }

    /// `BoxTest8::slabs` clipped by `Aabb::clip_slabs` to each lane's range
    /// is `Aabb::ray_range` bit for bit: random boxes (flat ones too, and
    /// boxes touching the origin's planes), rays in one octant with
    /// components down to 1e-6, ranges before, around and past the box.
    #[test]
    fn packet_slabs_clip_to_the_single_ray_test() {
        let seed = 0x51ab5u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut hits = 0;
        for case in 0..20_000 {
            let c = Vec3::new(rng.gen_range(-4.0..4.0), rng.gen_range(-4.0..4.0), rng.gen_range(-4.0..4.0));
            let mut h = Vec3::new(rng.gen_range(0.0..1.5), rng.gen_range(0.0..1.5), rng.gen_range(0.0..1.5));
            if case % 7 == 0 {
                h.y = 0.0;
            }
            let b = Aabb { min: c - h, max: c + h };
            let sign = Vec3::new(
                if rng.gen_bool(0.5) { 1.0 } else { -1.0 },
                if rng.gen_bool(0.5) { 1.0 } else { -1.0 },
                if rng.gen_bool(0.5) { 1.0 } else { -1.0 },
            );
            // Behind the box in the rays' octant, most lanes aim near it.
            let back = Vec3::new(rng.gen_range(0.0..3.0), rng.gen_range(0.0..3.0), rng.gen_range(0.0..3.0));
            let o = [c - sign * back; 8];
            let d: [Vec3; 8] = std::array::from_fn(|_| {
                let mut v = Vec3::new(rng.gen_range(1e-6..1.0), rng.gen_range(1e-6..1.0), rng.gen_range(1e-6..1.0));
                if rng.gen_bool(0.1) {
                    v.x = 1e-6;
                }
                v * sign
            });
            let Some(test) = BoxTest8::new(&o, &d) else { panic!("one octant, no zero component: a packet") };
            let (enter, leave) = test.slabs(&b);
            for k in 0..8 {
                let tmin = if rng.gen_bool(0.3) { 0.0 } else { rng.gen_range(-2.0..20.0) };
                let tmax = if rng.gen_bool(0.3) { f32::INFINITY } else { tmin + rng.gen_range(0.0..20.0) };
                let want = b.ray_range(o[k], d[k].recip(), tmin, tmax);
                let got = Aabb::clip_slabs((enter[k], leave[k]), tmin, tmax);
                let bits = |r: Option<(f32, f32)>| r.map(|(a, b)| (a.to_bits(), b.to_bits()));
                assert_eq!(bits(got), bits(want), "case {case} lane {k}: box {b:?} ray {:?} + t {:?} on [{tmin}, {tmax}]", o[k], d[k]);
                hits += want.is_some() as u32;
            }
        }
        println!("{hits} of 160000 lanes meet their box");
        assert!(hits > 10_000);
    }

    /// Every box a lane's range meets is visited for that lane (against a
    /// brute-force slab test), the AVX and SSE walks visit the same payloads
    /// in the same order, and a visit that shrinks a lane's range prunes only
    /// boxes beyond it.
    #[test]
    fn packet_walk_visits_every_box_each_lane_meets() {
        let seed = 23u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for n in [1usize, 3, 4, 5, 17, 200, 1500] {
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(rng.gen_range(-10.0..10.0), rng.gen_range(-10.0..10.0), rng.gen_range(-10.0..10.0));
                    let h = Vec3::new(rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0));
                    Aabb::new(c - h, c + h)
                })
                .collect();
            let bin = FlatBvh::build_cull(&boxes, 4);
            let w = BoxWide::from_binary(&bin.nodes, &bin.prims);
            for _ in 0..100 {
                let base =
                    Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)).normalize() + Vec3::splat(0.01);
                let shared = rng.gen_bool(0.5);
                let o0 = Vec3::new(rng.gen_range(-15.0..15.0), rng.gen_range(-15.0..15.0), rng.gen_range(-15.0..15.0));
                let o: [Vec3; 8] = std::array::from_fn(|_| if shared { o0 } else { o0 + Vec3::splat(rng.gen_range(-1.0..1.0)) });
                let d: [Vec3; 8] = std::array::from_fn(|_| base + Vec3::splat(rng.gen_range(-0.005..0.005)));
                let tmin: [f32; 8] = std::array::from_fn(|_| rng.gen_range(0.0..2.0));
                let cut: [f32; 8] = std::array::from_fn(|_| if rng.gen_bool(0.5) { rng.gen_range(5.0..30.0) } else { f32::INFINITY });
                let active = rng.gen_range(1..256u32);
                let rays = Rays8 { o: &o, d: &d, tmin: &tmin };
                let mut runs = Vec::new();
                for sse in [false, true] {
                    let mut thi = [40.0f32; 8];
                    let mut rec = Rec { got: Vec::new(), cut, order_ok: true, boxes: &boxes, rays: &rays, lower: f32::NEG_INFINITY };
                    let ok = if sse { w.walk8_sse(&rays, active, &mut thi, &mut rec) } else { w.walk8(&rays, active, &mut thi, &mut rec) };
                    assert!(rec.order_ok, "n {n}: a box entered before a settled bound was listed after it");
                    let got = rec.got;
                    if !ok {
                        continue;
                    }
                    for k in 0..8 {
                        for (i, b) in boxes.iter().enumerate() {
                            let hi = 40.0f32.min(cut[k]);
                            // Boxes entered before the lane's cut are surely visited.
                            let want = active & (1 << k) != 0 && b.ray_range(o[k], d[k].recip(), tmin[k], hi).is_some();
                            if want {
                                assert!(got.contains(&(k, i as u32)), "n {n}: lane {k} missed box {i}");
                            }
                        }
                    }
                    assert!(got.iter().all(|&(k, _)| active & (1 << k) != 0), "an inactive lane was visited");
                    runs.push(got);
                }
                if runs.len() == 2 {
                    assert_eq!(runs[0], runs[1], "AVX and SSE walks differ");
                }
            }
        }
    }
}
