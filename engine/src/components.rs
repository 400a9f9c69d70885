//! Components: plain data a tool puts on its own entities.

use glam::{DAffine3, DMat4, DVec3, Vec3};
use hecs::Entity;
pub use rothray_csg::Op;
pub use rothray_primitives::gcyl::{Frame, GeneralizedCylinder, Profile};
pub use rothray_primitives::mesh::{InsideRule, MeshData};
pub use rothray_primitives::sweep::SweptSphere;
pub use rothray_primitives::{Cone, Cuboid, Cylinder, HalfSpace, Sphere, Torus};

/// A closed triangle mesh leaf. Clone the `Arc` onto many entities to instance
/// one mesh under many transforms: the baked scene stores it once.
#[derive(Clone, Debug)]
pub struct MeshSolid(pub std::sync::Arc<MeshData>);

/// Placement of a node relative to its parent CSG node (or the world for an
/// object). Any invertible affine map: non-uniform scale and shear included.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform(pub DAffine3);

impl Default for Transform {
    fn default() -> Self {
        Transform(DAffine3::IDENTITY)
    }
}

impl Transform {
    /// A translation.
    pub fn from_translation(t: Vec3) -> Self {
        Transform(DAffine3::from_translation(t.as_dvec3()))
    }
    /// A scale (non-uniform allowed).
    pub fn from_scale(s: Vec3) -> Self {
        Transform(DAffine3::from_scale(s.as_dvec3()))
    }
    /// The scene format's `M = T * Rz * Ry * Rx * S` (angles in degrees).
    pub fn from_trs_deg(translate: DVec3, rotate_deg: DVec3, scale: DVec3) -> Self {
        let r = DAffine3::from_rotation_z(rotate_deg.z.to_radians())
            * DAffine3::from_rotation_y(rotate_deg.y.to_radians())
            * DAffine3::from_rotation_x(rotate_deg.x.to_radians());
        Transform(DAffine3::from_translation(translate) * r * DAffine3::from_scale(scale))
    }
    /// From a 4x4 matrix with last row `0 0 0 1` (column vectors).
    pub fn from_mat4(m: DMat4) -> Self {
        Transform(DAffine3::from_mat4(m))
    }
}

/// A CSG node: `op` over `children` (entities holding a shape or another
/// `CsgNode`). A difference is the first child minus all the others. Children
/// are parts of this solid, not objects of their own.
#[derive(Clone, Debug, PartialEq)]
pub struct CsgNode {
    /// The boolean operation.
    pub op: Op,
    /// Operands, in order.
    pub children: Vec<Entity>,
}

impl CsgNode {
    /// Union of the children.
    pub fn union(children: impl IntoIterator<Item = Entity>) -> Self {
        CsgNode { op: Op::Union, children: children.into_iter().collect() }
    }
    /// Intersection of the children.
    pub fn intersection(children: impl IntoIterator<Item = Entity>) -> Self {
        CsgNode { op: Op::Intersection, children: children.into_iter().collect() }
    }
    /// First child minus the others.
    pub fn difference(children: impl IntoIterator<Item = Entity>) -> Self {
        CsgNode { op: Op::Difference, children: children.into_iter().collect() }
    }
}

/// Surface colour (linear RGB, 0..1) of a node; inner nodes pass it down to leaves without one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Linear RGB.
    pub color: Vec3,
}

/// A name (objects and leaves are reported by it).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Name(pub String);

impl Name {
    /// A name.
    pub fn new(s: impl Into<String>) -> Self {
        Name(s.into())
    }
}

/// Order of top-level objects (lower first); objects without it follow, by entity id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct ObjectOrder(pub u32);

/// Hides an entity tree from the baked scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hidden;
