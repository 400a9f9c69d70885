//! # rothray-io: files in and out
//!
//! * [`scene`]: the JSON scene format, parsed into a `hecs::World` with errors
//!   located by JSON path (`objects[2].shape.difference[1].sphere.radius`);
//! * [`mesh`]: OBJ (tobj) and glTF 2.0 (.gltf / .glb) import of closed meshes;
//! * [`rays`]: the `rothray trace` ray CSV;
//! * [`part`]: part files of a split render and their merge;
//! * [`write_png`]: images.
#![warn(missing_docs)]

pub mod mesh;
pub mod part;
pub mod rays;
pub mod scene;

pub use mesh::{load_mesh, load_mesh_data, MeshLoadError};
pub use scene::{load_scene, parse_scene, SceneError, SceneFile};

/// Writes an RGB8 image as PNG.
pub fn write_png(path: &std::path::Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), image::ImageError> {
    image::save_buffer_with_format(path, rgb, width, height, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
}
