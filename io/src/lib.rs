//! # rothray-io: files in and out
//!
//! * [`scene`]: the JSON scene format, parsed into a `hecs::World` with errors
//!   located by JSON path (`objects[2].shape.difference[1].sphere.radius`);
//! * [`mesh`]: OBJ (tobj) and glTF 2.0 (.gltf / .glb) import of closed meshes;
//! * [`rays`]: the `rothray trace` ray CSV;
//! * [`part`]: part files of a split render and their merge;
//! * [`files`]: which files a scene may read (its folder and `--allow-path`
//!   folders; regular files only), and the record of what a load opened;
//! * images: [`write_png`].
#![warn(missing_docs)]

#[cfg(test)]
mod assimp_corpus;
#[cfg(test)]
mod comb_face;
pub mod files;
pub mod json;
pub mod json_path;
pub mod mesh;
pub mod part;
pub mod polygon;
pub mod rays;
pub mod scene;

pub use files::{FileError, Files, LoadOptions};
pub use mesh::{load_mesh, load_mesh_data, load_mesh_data_in, load_mesh_in, user_mesh, MeshLoadError};
pub use scene::{load_scene, load_scene_recorded, load_scene_with, parse_scene, parse_scene_with, SceneError, SceneFile};

/// Writes an RGB8 image as PNG.
pub fn write_png(path: &std::path::Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), image::ImageError> {
    image::save_buffer_with_format(path, rgb, width, height, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
}
