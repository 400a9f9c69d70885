//! A tile's list of the children of a wide union it keeps whole, each with
//! its shadow on the tile's ray plane ([`RayPlane`]). A packet of the
//! tile's rays visits the children whose shadow meets the box of its own
//! rays' points, instead of walking the union's tree: in a forest of 10 000
//! leaves that walk cost camera and shadow packets some 20 node tests each,
//! where a tile's children are listed and projected once.

use rothray_primitives::glam::Vec3;
use rothray_primitives::ray_plane::{meets_all, RayPlane};
use rothray_primitives::Aabb;

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
}

impl TileList {
    /// Starts the list of node `node`.
    pub(crate) fn reset(&mut self, node: u32) {
        self.node = node;
        self.pos.clear();
        for v in &mut self.shadows {
            v.clear();
        }
        self.boxes.clear();
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
