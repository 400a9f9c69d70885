//! # rothray-engine: components, systems, the baked scene, queries, rendering
//!
//! A tool owns a `hecs::World`; rothray's [`components`] sit on its entities
//! (a [`Transform`], one shape component per leaf kind, [`CsgNode`],
//! [`Material`], [`Name`]). The systems are plain functions:
//! [`find_objects`] → [`bake_scene`] (or [`sync_scene`], which skips the bake
//! when nothing changed). The baked [`RenderScene`] holds only tables (SoA
//! leaves in pre-order, the flat CSG program, BVHs) and answers queries on one
//! ray or bundles: nearest hit, any hit, Roth spans per object, point
//! classification. [`render()`] draws a picture in parallel tiles with rayon.
//!
//! ```
//! use rothray_engine::*;
//! use glam::Vec3;
//! let mut world = hecs::World::new();
//! let a = world.spawn((Transform::default(), Cuboid { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) }));
//! let b = world.spawn((Transform::default(), Sphere { center: Vec3::ZERO, radius: 1.2 }));
//! let cut = world.spawn((CsgNode::difference([a, b]), Name::new("cut")));
//! let mut scene = RenderScene::default();
//! sync_scene(&mut world, &mut scene).unwrap();
//! let hit = scene.intersect(&Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z));
//! // Along the z axis the sphere (radius 1.2) covers the whole box depth: the ray
//! // passes through the hole and meets nothing.
//! assert!(hit.is_none());
//! assert!(scene.contains_entity(Vec3::new(0.95, 0.95, 0.95), cut));
//! ```
#![warn(missing_docs)]

pub mod bake;
mod box_list;
mod changes;
pub mod components;
mod entity_hash;
pub mod knobs;
mod light_order;
mod live;
mod live_meshes;
#[cfg(test)]
mod live_tests;
mod owners;
mod packet;
mod packet_first;
pub mod part;
mod refit;
pub mod render;
mod render_tile;
pub mod scene;
pub mod tile;
mod workers;

pub use bake::{bake_scene, find_objects, fingerprint_world, sync_scene, sync_scene_touched, BakeError};
pub use components::*;
pub use glam;
pub use hecs;
pub use knobs::{Knob, Knobs};
pub use packet::{PacketScratch, PACKET_MESHES};
pub use part::{Part, Split};
pub use render::{
    encode_depth, encode_pixel, encode_srgb, leaf_id_color, render, render_raw, tile_size, tile_size_for, Aov, Camera, CameraRays, Light,
    RawPixels, RenderSettings, RenderStats,
};
pub use rothray_csg as csg;
pub use rothray_primitives as primitives;
pub use scene::{Hit, LeafInfo, ObjectInfo, Ray, RenderScene};
pub use tile::{TileScratch, TileStats, TileView};
