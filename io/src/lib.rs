// placeholder
pub mod mesh;
pub use mesh::{load_mesh, load_mesh_data, MeshLoadError};
