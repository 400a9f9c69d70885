//! The mesh files (OBJ, glTF, GLB) of Debian's assimp-testmodels, found in one
//! place for both suites that run them: the io crate's loader test and the
//! CLI's hostile-input test (which includes this file by path).

use std::path::{Path, PathBuf};

/// The corpus folder and its mesh files, sorted; None when the package is not
/// installed (`apt-get install assimp-testmodels`; scripts/test.sh does it).
pub fn assimp_mesh_files() -> Option<(PathBuf, Vec<PathBuf>)> {
    let roots = ["/usr/share/assimp/models", "/usr/share/assimp-testmodels"];
    let root = roots.iter().map(Path::new).find(|p| p.is_dir())?;
    let mut files = vec![];
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&dir) else { continue };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(
                p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref(),
                Some("obj" | "gltf" | "glb")
            ) {
                files.push(p);
            }
        }
    }
    files.sort();
    Some((root.to_path_buf(), files))
}
