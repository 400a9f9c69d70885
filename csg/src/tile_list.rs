//! A tile's list of the children of a wide union it keeps whole, each with
//! its shadow on the tile's ray plane ([`RayPlane`]). A packet of the
//! tile's rays visits the children whose shadow meets the box of its own
//! rays' points, instead of walking the union's tree: in a forest of 10 000
//! leaves that walk cost camera and shadow packets some 20 node tests each,
//! where a tile's children are listed and projected once.

use rothray_primitives::glam::Vec3;
use rothray_primitives::ray_plane::{meets_all, RayPlane};
use rothray_primitives::{
    aabb::{near_of_key, nearest_first, reach_per_t},
    Aabb,
};

/// See the module documentation.
#[derive(Clone, Debug, Default)]
pub struct TileList {
    /// The union's node.
    pub node: u32,
    /// Positions of the children listed (bounded ones whose box the tile's
    /// region touches), their shadows, and their boxes: a copy, so that a
    /// packet reads its children's boxes one after the other instead of
    /// looking each one up through the union's children (a load that waits
    /// on a load: the walk's hottest lines on forest, perf).
    pos: Vec<u32>,
    /// The shadows' sides, one array each (`[x0, y0, x1, y1]` of a
    /// [`Box2`](rothray_primitives::ray_plane::Box2)): a packet tests
    /// sixteen or four at a time ([`meets_all`]).
    shadows: [Vec<f32>; 4],
    boxes: Vec<Aabb>,
    /// Where the tile's rays start ([`TileList::finish`]: the children
    /// come nearest first from there), and per child its box's distance
    /// from there ([`Aabb::near_from`]).
    origins: Aabb,
    near: Vec<f32>,
    /// Scratch of [`TileList::finish`].
    order: Vec<u64>,
    was: Unordered,
}

/// The list's arrays before [`TileList::finish`] orders them.
#[derive(Clone, Debug, Default)]
struct Unordered {
    pos: Vec<u32>,
    shadows: [Vec<f32>; 4],
    boxes: Vec<Aabb>,
}

/// From this many children a packet meets, it visits them nearest first
/// with the stops of `BoxWide::visit_listed_near`; fewer are all visited,
/// then settled (the stops' checks cost benches/scenes/forest, forest_cut
/// and forest_deep 1-1.5% flat with any number).
const NEAR_WALK: usize = 24;

impl TileList {
    /// Starts the list of node `node`.
    pub(crate) fn reset(&mut self, node: u32) {
        self.node = node;
        self.pos.clear();
        for v in &mut self.shadows {
            v.clear();
        }
        self.boxes.clear();
        self.near.clear();
        self.origins = Aabb::EMPTY;
    }

    /// Orders the children listed nearest first from `origins`, the box
    /// where the tile's rays start (then in the order listed), so that a
    /// packet's walk can settle as it goes and stop where every lane's
    /// reach ends ([`TileList::for_rays_near`]).
    pub(crate) fn finish(&mut self, origins: Aabb) {
        let n = self.pos.len();
        let mut order = std::mem::take(&mut self.order);
        nearest_first(&origins, self.boxes.iter(), &mut order);
        // (Into the scratch copies, then swapped: no allocation per tile.)
        let mut was = std::mem::take(&mut self.was);
        was.pos.clear();
        was.boxes.clear();
        self.near.clear();
        for &k in &order {
            let i = k as u32 as usize;
            was.pos.push(self.pos[i]);
            was.boxes.push(self.boxes[i]);
            self.near.push(near_of_key(k));
        }
        for (a, v) in self.shadows.iter_mut().enumerate() {
            was.shadows[a].clear();
            was.shadows[a].extend(order.iter().map(|&k| v[k as u32 as usize]));
            std::mem::swap(v, &mut was.shadows[a]);
        }
        std::mem::swap(&mut self.pos, &mut was.pos);
        std::mem::swap(&mut self.boxes, &mut was.boxes);
        debug_assert_eq!(self.near.len(), n);
        self.origins = origins;
        (self.order, self.was) = (order, was);
    }

    /// Lists child position `pos`, of box `b`.
    pub(crate) fn push(&mut self, plane: &RayPlane, pos: u32, b: &Aabb) {
        self.pos.push(pos);
        let s = plane.box2d(b);
        for (v, x) in self.shadows.iter_mut().zip(s) {
            v.push(x);
        }
        self.boxes.push(*b);
    }

    /// How many children are listed.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// Is the list empty?
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// The children that the rays `(o[k], d[k])` of the lanes `lanes` can
    /// meet, with their boxes, or `None` when a lane's ray is not a ray of
    /// `plane` (or its point is not finite: [`RayPlane::point`]). `met` is
    /// scratch: the indices of those children in the list, written without
    /// a branch per child (whether a child's shadow meets the packet's box
    /// is hard to predict; the list is filtered first, then walked).
    #[inline]
    pub(crate) fn for_rays<'a>(
        &'a self,
        plane: &RayPlane,
        rays: (&[Vec3; 8], &[Vec3; 8]),
        lanes: u32,
        met: &'a mut Vec<u32>,
    ) -> Option<impl Iterator<Item = (u32, &'a Aabb)> + 'a> {
        if !self.met_by(plane, rays, lanes, met) {
            return None;
        }
        Some(met.iter().map(move |&i| self.entry(i)))
    }

    /// [`TileList::for_rays`] with each child's distance bound
    /// ([`TileList::finish`]), and how far from their origins the rays go
    /// per unit of `t` (a child whose distance lies past `t` times that is
    /// entered past `t` by every lane): `None` for that unless every ray
    /// starts where the list was made for, on its range's side (`tmin >= 0`).
    #[inline]
    #[allow(clippy::type_complexity)]
    pub(crate) fn for_rays_near<'a>(
        &'a self,
        plane: &RayPlane,
        rays: (&[Vec3; 8], &[Vec3; 8], &[f32; 8]),
        lanes: u32,
        met: &'a mut Vec<u32>,
    ) -> Option<(impl Iterator<Item = (u32, &'a Aabb, f32)> + 'a, Option<f32>)> {
        let (o, d, tmin) = rays;
        if !self.met_by(plane, (o, d), lanes, met) {
            return None;
        }
        let from = met.len() >= NEAR_WALK && self.near.len() == self.pos.len();
        let per_t = if from { reach_per_t(&self.origins, (o, d, tmin), lanes) } else { None };
        let near = &self.near;
        Some((
            met.iter().map(move |&i| (self.pos[i as usize], &self.boxes[i as usize], near.get(i as usize).copied().unwrap_or(0.0))),
            per_t,
        ))
    }

    /// [`TileList::for_rays`]'s entries as indices into the list (into
    /// `met`, for [`TileList::entry`]); `false` when a lane's ray is not a
    /// ray of `plane`.
    pub(crate) fn met_by(&self, plane: &RayPlane, (o, d): (&[Vec3; 8], &[Vec3; 8]), lanes: u32, met: &mut Vec<u32>) -> bool {
        let Some(pb) = plane.lanes_box((o, d), lanes) else { return false };
        let pb = pb.unwrap_or([f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY]);
        met.clear();
        met.resize(self.pos.len(), 0);
        let m = meets_all(&pb, &self.shadows, met);
        met.truncate(m);
        true
    }

    /// Entry `i` of the list: the child's position and its box.
    #[inline(always)]
    pub(crate) fn entry(&self, i: u32) -> (u32, &Aabb) {
        (self.pos[i as usize], &self.boxes[i as usize])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// A list made for an eye comes nearest first, and each child's
    /// distance bound is at most a packet lane's entry into its box times
    /// the length [`TileList::for_rays_near`] gives: random boxes in front
    /// of eyes near and far from the origin, packets aimed at a box's
    /// nearest point and around it. Packets from elsewhere, behind their
    /// ranges, or meeting few children get no bound. (A shrink of
    /// `1 + 1e-6` instead of `1 - 1e-5` fails here.)
    #[test]
    fn near_bounds_every_lanes_entry() {
        let seed = 0x7117u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut checked, mut tight, mut bounded) = (0, 0, 0);
        let mut met = Vec::new();
        for case in 0..300 {
            let far = [0.0f32, 1e3, 1e4][case % 3];
            let eye = Vec3::new(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0)) + Vec3::splat(far);
            let fwd = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 1.0);
            let plane = RayPlane::perspective(eye, fwd).expect("a plane");
            let mut list = TileList::default();
            list.reset(0);
            let mut boxes = Vec::new();
            for pos in 0..rng.gen_range(30..80) {
                let c = eye
                    + fwd * rng.gen_range(1.0..20.0)
                    + Vec3::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0));
                let h = Vec3::new(rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0));
                let b = Aabb::new(c - h, c + h);
                list.push(&plane, pos, &b);
                boxes.push(b);
            }
            list.finish(Aabb::new(eye, eye));
            for i in 1..list.len() {
                assert!(list.near[i - 1] <= list.near[i], "case {case}: out of order at {i}");
            }
            for _ in 0..20 {
                let b = &boxes[rng.gen_range(0..boxes.len())];
                let aim = if rng.gen_bool(0.8) { eye.clamp(b.min, b.max) } else { b.center() };
                let spread = rng.gen_range(0.0..0.3);
                // Lane 0 straight at the aim, the others around it.
                let d: [Vec3; 8] = std::array::from_fn(|k| {
                    let v = aim - eye;
                    let off = if k == 0 {
                        Vec3::ZERO
                    } else {
                        Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0))
                    };
                    (v + off * spread * v.length()) * rng.gen_range(0.1..3.0)
                });
                let tmin = [0.0f32; 8];
                let Some((ids, per_t)) = list.for_rays_near(&plane, (&[eye; 8], &d, &tmin), 0xff, &mut met) else { continue };
                let ids: Vec<(u32, Aabb, f32)> = ids.map(|(p, b, n)| (p, *b, n)).collect();
                let Some(s) = per_t else {
                    assert!(ids.len() < NEAR_WALK, "case {case}: {} met and no bound", ids.len());
                    continue;
                };
                bounded += 1;
                for (pos, bx, near) in ids {
                    assert_eq!(bx, boxes[pos as usize]);
                    for dk in d {
                        let inv = dk.recip();
                        if let Some((t0, _)) = bx.ray_range(eye, inv, 0.0, f32::INFINITY) {
                            checked += 1;
                            assert!(near <= t0 * s, "case {case}: child {pos} near {near} past entry {t0} x {s}");
                            tight += (near > 0.0 && near > t0 * s * 0.9999) as u32;
                        }
                    }
                }
                // From elsewhere, or behind its range: no bound.
                let moved = list.for_rays_near(&plane, (&[eye + Vec3::X; 8], &d, &tmin), 0xff, &mut met).map(|(_, p)| p);
                assert!(moved.is_none_or(|p| p.is_none()), "case {case}: a bound for rays from elsewhere");
                let behind = list.for_rays_near(&plane, (&[eye; 8], &d, &[-1.0; 8]), 0xff, &mut met).map(|(_, p)| p);
                assert!(behind.is_none_or(|p| p.is_none()), "case {case}: a bound for ranges from behind");
            }
        }
        println!("{bounded} packets bounded, {checked} entries checked, {tight} within 1e-4 of the bound");
        assert!(bounded > 500 && checked > 10_000 && tight > 100, "too few to mean anything");
    }
}
