//! # rothray-primitives: the leaf solids
//!
//! Every leaf solid of rothray answers four questions about itself, all in world
//! space through its own world-to-local affine map (so non-uniform scales and
//! shears are free):
//!
//! * [`LeafTable::spans`]: the parameter intervals (Roth spans) where a ray
//!   `o + t d` is inside the solid, within `[tmin, tmax]`, sorted and disjoint;
//! * [`LeafTable::contains`]: is a point inside;
//! * [`LeafTable::normal`]: the outward normal at a chosen crossing (computed
//!   lazily, only for the crossing a query finally shows);
//! * its bounds ([`LeafTable::bounds`]).
//!
//! The table is struct-of-arrays; the hot path does one `match` on the fieldless
//! [`LeafKind`]. Kernels live in [`kernels`] (f32 for boxes and half-spaces;
//! f64 for the ball, a sphere under similarities, traced in world space, and
//! for ellipsoids, cylinders, cones and the torus quartic ([`quartic`]),
//! traced through an f64 map ([`table64`]), so that tangent chords are those
//! of their f32 inputs; [`poly`] holds the general root finders). [`bvh::FlatBvh`] is the BVH every level of the
//! engine uses (built with obvhs).
#![warn(missing_docs)]

pub mod aabb;
pub mod box_wide;
pub mod bvh;
pub mod frustum;
pub mod gcyl;
pub mod kernels;
pub mod kernels8;
pub mod mask8;
pub mod mesh;
pub mod poly;
pub mod polytope;
pub mod quartic;
pub mod ray;
pub mod ray_plane;
mod simd8;
pub mod sweep;
pub mod table;
pub mod table64;
mod torus8;
pub mod trim;
pub mod wide_node;

pub use aabb::Aabb;
pub use glam;
pub use ray::Ray;
pub use table::{Cone, Cuboid, Cylinder, HalfSpace, LeafError, LeafKind, LeafShape, LeafTable, ShapeError, Sphere, Torus};

/// Identifies the surface a span boundary lies on: a leaf (index, with
/// [`Surf::FLIP`] set when the surface bounds a subtracted operand, so its normal
/// points the other way) and a kind-specific sub-surface id. [`Surf::NONE`] marks
/// an end made by clipping to `[tmin, tmax]`, which is not a surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Surf {
    /// Leaf index, high bit = flipped; `u32::MAX` = no surface.
    pub leaf: u32,
    /// Sub-surface id (face of a box, cap of a cylinder, triangle of a mesh...).
    pub sub: u32,
}

impl Surf {
    /// The flip bit.
    pub const FLIP: u32 = 1 << 31;
    /// A clipped end.
    pub const NONE: Surf = Surf { leaf: u32::MAX, sub: 0 };
    /// Surface `sub` of leaf `leaf`.
    #[inline(always)]
    pub fn new(leaf: u32, sub: u32) -> Surf {
        Surf { leaf, sub }
    }
    /// Is this a real surface (not a clipped end)?
    #[inline(always)]
    pub fn is_real(self) -> bool {
        self.leaf != u32::MAX
    }
    /// Leaf index without the flip bit.
    #[inline(always)]
    pub fn leaf_index(self) -> u32 {
        self.leaf & !Self::FLIP
    }
    /// Does the normal point the other way (a subtracted surface)?
    #[inline(always)]
    pub fn flipped(self) -> bool {
        self.is_real() && self.leaf & Self::FLIP != 0
    }
    /// The same surface with its orientation reversed (clipped ends stay clipped).
    #[inline(always)]
    pub fn flip(self) -> Surf {
        if self.is_real() {
            Surf { leaf: self.leaf ^ Self::FLIP, sub: self.sub }
        } else {
            self
        }
    }
}

/// A Roth span: the ray is inside the solid for `t0 <= t <= t1`; `s0` / `s1` are the
/// surfaces where it enters and leaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    /// Entry parameter.
    pub t0: f32,
    /// Exit parameter.
    pub t1: f32,
    /// Entry surface.
    pub s0: Surf,
    /// Exit surface.
    pub s1: Surf,
}

/// Where kernels write their spans (in increasing order).
pub trait SpanSink {
    /// Appends a span after all earlier ones.
    fn push_span(&mut self, s: Span);
}

impl SpanSink for Vec<Span> {
    fn push_span(&mut self, s: Span) {
        self.push(s)
    }
}
