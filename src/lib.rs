//! # rothray
//!
//! A data-oriented scene engine that ray traces solids built by constructive
//! solid geometry with Roth's method. This crate is the façade: it re-exports
//! the workspace crates.
//!
//! * [`primitives`]: leaf solids (ray → Roth spans, bounds, point-inside, normals);
//! * [`csg`]: interval lists, Table-1 combine, CSG programs with early outs;
//! * [`engine`]: hecs components and systems, the baked [`engine::RenderScene`], queries, rendering;
//! * [`io`]: the JSON scene format, ray files, PNG output.
//!
//! ```
//! use rothray::engine::*;
//! use glam::Vec3;
//! let mut world = hecs::World::new();
//! let a = world.spawn((Transform::from_translation(Vec3::new(0.5, 0.0, 0.0)),
//!                      Cuboid { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) }));
//! let b = world.spawn((Transform::default(), Sphere { center: Vec3::ZERO, radius: 1.2 }));
//! let cut = world.spawn((CsgNode::difference([a, b]), Name::new("cut")));
//! let mut scene = RenderScene::default();
//! sync_scene(&mut world, &mut scene).unwrap();          // bakes (again only if something changed)
//! let hit = scene.intersect(&Ray::new(Vec3::new(1.2, 0.9, 5.0), Vec3::NEG_Z)).unwrap();
//! assert!((hit.t - 4.0).abs() < 1e-4);                   // the box's front face at z = 1
//! let spans = scene.spans_of(&Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z), cut);
//! assert!(spans.is_empty());                             // straight through the hole
//! assert!(scene.contains_entity(Vec3::new(1.4, 0.9, 0.9), cut));
//! ```
#![warn(missing_docs)]

pub use rothray_csg as csg;
pub use rothray_engine as engine;
pub use rothray_io as io;
pub use rothray_primitives as primitives;

/// The README's Rust examples, compiled and run as doctests.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
