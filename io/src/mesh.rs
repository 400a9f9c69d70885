//! Mesh import: Wavefront OBJ (via `tobj`) and glTF 2.0 (`.gltf` with external or
//! embedded data-URI buffers, and `.glb`, via `gltf`) into one triangle soup.
//!
//! Everything in a file becomes one solid: all OBJ groups and objects, and every
//! triangle primitive of every mesh instance in the glTF default scene (node
//! transforms applied along the hierarchy). Nothing here panics or allocates in
//! proportion to a number read from the file before checking it against the bytes
//! that are really there.

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{DMat4, DVec3, Vec3};
use rothray_primitives::mesh::{InsideRule, MeshData, MeshError};

use crate::files::{FileError, Files, LoadOptions};
use crate::polygon;

/// At most this many triangles (and vertices) after instancing: a hostile glTF can
/// reference one mesh from many nodes.
pub const MAX_TRIANGLES: usize = 1 << 26;
/// Deepest node hierarchy followed.
const MAX_DEPTH: usize = 256;

/// Why a mesh file could not be loaded. Every message names the file and the place.
#[derive(Debug, thiserror::Error)]
pub enum MeshLoadError {
    /// The file (or an external buffer) cannot be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file, or a file it names, is outside the allowed folders or not a
    /// regular file (see [`crate::files`]); it was not opened.
    #[error("{source}")]
    File {
        /// Why.
        #[from]
        source: FileError,
    },
    /// Not `.obj`, `.gltf` or `.glb`.
    #[error("{path}: unknown mesh format (expected .obj, .gltf or .glb)")]
    UnknownFormat {
        /// File.
        path: PathBuf,
    },
    /// Malformed content (a number, a face, JSON, a GLB chunk...).
    #[error("{path}: {place}: {message}")]
    Malformed {
        /// File.
        path: PathBuf,
        /// `line N`, `mesh M primitive P`, `buffer B`...
        place: String,
        /// What is wrong.
        message: String,
    },
    /// An index refers past the end of the vertex list.
    #[error("{path}: {place}: vertex index {index} out of range ({count} vertices)")]
    IndexOutOfRange {
        /// File.
        path: PathBuf,
        /// Where.
        place: String,
        /// The index (0-based).
        index: u64,
        /// Vertices available.
        count: usize,
    },
    /// A position is NaN or infinite.
    #[error("{path}: {place}: vertex position is NaN or infinite")]
    NonFinite {
        /// File.
        path: PathBuf,
        /// Where.
        place: String,
    },
    /// A buffer the triangles need is absent or shorter than declared.
    #[error("{path}: {place}: missing buffer data: {message}")]
    MissingBuffer {
        /// File.
        path: PathBuf,
        /// Where.
        place: String,
        /// What is missing.
        message: String,
    },
    /// An accessor has the wrong type or component type.
    #[error("{path}: {place}: {message}")]
    WrongType {
        /// File.
        path: PathBuf,
        /// Where.
        place: String,
        /// Expected and found.
        message: String,
    },
    /// A feature the loader does not implement (compression, quantization, sparse...).
    #[error("{path}: {place}: unsupported: {what}")]
    Unsupported {
        /// File.
        path: PathBuf,
        /// Where.
        place: String,
        /// What.
        what: String,
    },
    /// More than [`MAX_TRIANGLES`] after instancing.
    #[error("{path}: more than {MAX_TRIANGLES} triangles or vertices after instancing")]
    TooLarge {
        /// File.
        path: PathBuf,
    },
    /// No triangles at all.
    #[error("{path}: the file holds no triangles")]
    Empty {
        /// File.
        path: PathBuf,
    },
    /// The triangles do not make a solid.
    #[error("{path}: {source}")]
    Mesh {
        /// File.
        path: PathBuf,
        /// Cause.
        source: MeshError,
    },
}

/// Triangles of a mesh file: positions, index triples, warnings.
pub type LoadedMesh = (Vec<Vec3>, Vec<[u32; 3]>, Vec<String>);

/// Loads every triangle of an `.obj`, `.gltf` or `.glb` file (chosen by extension).
/// The files it names (glTF buffers) must lie in the mesh's own folder: see
/// [`load_mesh_in`] to allow others.
pub fn load_mesh(path: &Path) -> Result<LoadedMesh, MeshLoadError> {
    let (path, files) = user_mesh(path, &LoadOptions::default())?;
    load_mesh_in(&path, &files)
}

/// The mesh named on the command line (`rothray check MESH`): canonical, so that
/// its folder, where its buffers must lie, is the real one and not a link's; and
/// the [`Files`] that confine what it names to that folder and `opts.allow_paths`.
pub fn user_mesh(path: &Path, opts: &LoadOptions) -> Result<(PathBuf, Files), MeshLoadError> {
    let real = std::fs::canonicalize(path).map_err(|source| MeshLoadError::Io { path: path.into(), source })?;
    let files = Files::new(real.parent().unwrap_or(Path::new("/")), opts);
    Ok((real, files))
}

/// [`load_mesh`], reading only what `files` allows (the mesh file itself too);
/// `files` records what was opened.
pub fn load_mesh_in(path: &Path, files: &Files) -> Result<LoadedMesh, MeshLoadError> {
    // The last line of defence only: every input is meant to end in a typed
    // error; a panic in a reader (ours or a dependency's) becomes a located one.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_mesh_unguarded(path, files))).unwrap_or_else(|_| {
        Err(MeshLoadError::Malformed {
            path: path.into(),
            place: "(unknown)".into(),
            message: "the mesh reader crashed (a bug: please report this file)".into(),
        })
    })
}

fn load_mesh_unguarded(path: &Path, files: &Files) -> Result<LoadedMesh, MeshLoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    // The format is known from the name before anything is opened: a file that is
    // not a mesh is never read (and so never quoted in a message).
    if !matches!(ext.as_deref(), Some("obj" | "gltf" | "glb")) {
        return Err(MeshLoadError::UnknownFormat { path: path.into() });
    }
    let bytes = files.read(path).map_err(|source| MeshLoadError::File { source })?;
    let r = match ext.as_deref() {
        Some("obj") => load_obj(path, &bytes)?,
        _ => load_gltf(path, &bytes, files)?,
    };
    if r.1.is_empty() {
        return Err(MeshLoadError::Empty { path: path.into() });
    }
    Ok(r)
}

/// [`load_mesh`] then [`MeshData::new`]; the warnings of both are returned (also
/// kept in [`MeshData::warnings`] for the second).
pub fn load_mesh_data(path: &Path, rule: InsideRule) -> Result<(MeshData, Vec<String>), MeshLoadError> {
    let (path, files) = user_mesh(path, &LoadOptions::default())?;
    load_mesh_data_in(&path, rule, &files)
}

/// [`load_mesh_in`] then [`MeshData::new`].
pub fn load_mesh_data_in(path: &Path, rule: InsideRule, files: &Files) -> Result<(MeshData, Vec<String>), MeshLoadError> {
    let (pos, tris, mut warnings) = load_mesh_in(path, files)?;
    let m = MeshData::new(pos, tris, rule).map_err(|source| MeshLoadError::Mesh { path: path.into(), source })?;
    warnings.extend(m.warnings().iter().cloned());
    Ok((m, warnings))
}

// ---------------------------------------------------------------- OBJ

fn load_obj(path: &Path, bytes: &[u8]) -> Result<LoadedMesh, MeshLoadError> {
    let malformed = |line: usize, message: String| MeshLoadError::Malformed { path: path.into(), place: format!("line {line}"), message };
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let line = bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count() + 1;
        malformed(line, "not UTF-8 text".into())
    })?;
    // tobj reports no line numbers: a pre-scan counts what it skips and, on an
    // error, finds the line (see `locate_obj_error`).
    let mut skipped = (0usize, 0usize);
    // Lines of the faces tobj keeps (3 or more vertices), in order: tobj's faces
    // come out in file order, so the k-th is on face_lines[k].
    let mut face_lines: Vec<usize> = Vec::new();
    let mut short_faces: Vec<usize> = Vec::new();
    for (i, l) in text.lines().enumerate() {
        let mut w = l.split_whitespace();
        match w.next() {
            Some("p") => skipped.0 += 1,
            Some("l") => skipped.1 += 1,
            Some("f") => match w.count() {
                0..=2 => short_faces.push(i + 1),
                _ => face_lines.push(i + 1),
            },
            _ => {}
        }
    }
    // Faces are triangulated here, not by tobj: see `polygon`.
    let opts = tobj::LoadOptions { triangulate: false, single_index: false, ignore_points: true, ignore_lines: true };
    let (models, _materials) =
        tobj::load_obj_buf(&mut std::io::Cursor::new(text.as_bytes()), &opts, |_| Err(tobj::LoadError::OpenFileFailed)).map_err(|e| {
            let (line, msg) = locate_obj_error(text, &e);
            match line {
                Some(line) => malformed(line, msg),
                None => MeshLoadError::Malformed { path: path.into(), place: "OBJ".into(), message: msg },
            }
        })?;
    let mut warnings = vec![];
    if skipped.0 > 0 || skipped.1 > 0 {
        warnings.push(format!("{}: skipped {} point and {} line elements", path.display(), skipped.0, skipped.1));
    }
    // A face of one or two vertices bounds nothing: skipped, like `l` lines, and
    // said so with its line (the first few, then a count).
    if !short_faces.is_empty() {
        let shown: Vec<String> = short_faces.iter().take(5).map(|l| l.to_string()).collect();
        let more = if short_faces.len() > 5 { format!(" and {} more", short_faces.len() - 5) } else { String::new() };
        warnings.push(format!(
            "{}: line {}{more}: skipped {} face(s) with fewer than 3 vertices",
            path.display(),
            shown.join(", "),
            short_faces.len()
        ));
    }
    let mut forced: Vec<String> = Vec::new();
    let mut face_no = 0usize;
    let mut pos: Vec<Vec3> = vec![];
    let mut tris: Vec<[u32; 3]> = vec![];
    for m in &models {
        let mesh = &m.mesh;
        let base = pos.len();
        if base + mesh.positions.len() / 3 > MAX_TRIANGLES {
            return Err(MeshLoadError::TooLarge { path: path.into() });
        }
        for p in mesh.positions.chunks_exact(3) {
            let v = Vec3::new(p[0], p[1], p[2]);
            if !v.is_finite() {
                let line = first_non_finite_vertex_line(text);
                return Err(MeshLoadError::NonFinite {
                    path: path.into(),
                    place: line.map(|l| format!("line {l}")).unwrap_or_else(|| "OBJ".into()),
                });
            }
            pos.push(v);
        }
        let n = mesh.positions.len() / 3;
        if let Some(&k) = mesh.indices.iter().find(|&&k| k as usize >= n) {
            return Err(MeshLoadError::IndexOutOfRange {
                path: path.into(),
                place: format!("object {:?}", m.name),
                index: k as u64,
                count: n,
            });
        }
        // face_arities is empty when every face is a triangle.
        let all_tris;
        let arities: &[u32] = if mesh.face_arities.is_empty() {
            all_tris = vec![3u32; mesh.indices.len() / 3];
            &all_tris
        } else {
            &mesh.face_arities
        };
        let local = &pos[base..];
        let mut at = 0usize;
        let mut face_tris = Vec::new();
        for &a in arities {
            let a = a as usize;
            let Some(face) = mesh.indices.get(at..at + a) else { break };
            at += a;
            face_tris.clear();
            if polygon::triangulate(local, face, &mut face_tris) == polygon::Method::Forced {
                let line = face_lines.get(face_no).map_or_else(|| format!("face {face_no}"), |l| format!("line {l}"));
                forced.push(format!("{line} ({a} vertices)"));
            }
            face_no += 1;
            if tris.len() + face_tris.len() > MAX_TRIANGLES {
                return Err(MeshLoadError::TooLarge { path: path.into() });
            }
            tris.extend(face_tris.iter().map(|t| t.map(|k| k + base as u32)));
        }
    }
    if !forced.is_empty() {
        let more = if forced.len() > 5 { format!(" and {} more", forced.len() - 5) } else { String::new() };
        warnings.push(format!(
            "{}: {}{more}: face(s) not simple in their plane (an edge crosses or touches another, or two vertices coincide), split by halving; triangles may lie outside the face",
            path.display(),
            forced.iter().take(5).cloned().collect::<Vec<_>>().join(", "),
        ));
    }
    Ok((pos, tris, warnings))
}

/// Finds the line tobj choked on (tobj's errors carry no position).
fn locate_obj_error(text: &str, e: &tobj::LoadError) -> (Option<usize>, String) {
    use tobj::LoadError as E;
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    let total_v = text.lines().filter(|l| l.split_whitespace().next() == Some("v")).count() as i64;
    let bad_float = |s: &str| s.parse::<f32>().is_err();
    for (i, l) in text.lines().enumerate() {
        let mut w = l.split_whitespace();
        let Some(tag) = w.next() else { continue };
        let args: Vec<&str> = w.collect();
        let line = Some(i + 1);
        match (tag, e) {
            ("v", E::PositionParseError) | ("v", E::ScalingByZeroError)
                if args.len() < 3 || args.iter().any(|a| bad_float(a)) || (args.len() == 4 && args[3].parse::<f32>() == Ok(0.0)) =>
            {
                return (line, format!("malformed vertex position {l:?} ({e})"));
            }
            ("vn", E::NormalParseError) if args.len() < 3 || args.iter().any(|a| bad_float(a)) => {
                return (line, format!("malformed normal {l:?} ({e})"));
            }
            ("vt", E::TexcoordParseError) if args.is_empty() || args.iter().any(|a| bad_float(a)) => {
                return (line, format!("malformed texture coordinate {l:?} ({e})"));
            }
            ("f" | "l" | "p", E::FaceParseError | E::FaceVertexOutOfBounds | E::InvalidPolygon) => {
                for a in &args {
                    let mut parts = a.split('/');
                    let v = parts.next().unwrap_or("");
                    match v.parse::<i64>() {
                        Err(_) => return (line, format!("malformed face element {a:?} ({e})")),
                        Ok(k) if k == 0 || k > total_v || (k < 0 && -k > nv) => {
                            return (line, format!("face refers to vertex {k}, but there are {total_v} vertices ({nv} so far)"));
                        }
                        _ => {}
                    }
                    if parts.any(|p| !p.is_empty() && p.parse::<i64>().is_err()) {
                        return (line, format!("malformed face element {a:?} ({e})"));
                    }
                }
                if tag == "f" && args.len() < 3 && matches!(e, E::InvalidPolygon) {
                    return (line, format!("face with fewer than 3 vertices ({e})"));
                }
            }
            ("usemtl" | "mtllib", E::MaterialParseError) if args.is_empty() => {
                return (line, format!("{tag} without a name ({e})"));
            }
            ("o" | "g", E::InvalidObjectName) if args.is_empty() => {
                return (line, format!("{tag} without a name ({e})"));
            }
            ("f", E::FaceTexCoordOutOfBounds | E::FaceNormalOutOfBounds) => {
                let (slot, n) = if matches!(e, E::FaceTexCoordOutOfBounds) { (1, nvt) } else { (2, nvn) };
                for a in &args {
                    if let Some(Ok(k)) = a.split('/').nth(slot).filter(|s| !s.is_empty()).map(|s| s.parse::<i64>()) {
                        if k == 0 || k > n || (k < 0 && -k > n) {
                            return (line, format!("face element {a:?} is out of range ({e})"));
                        }
                    }
                }
            }
            _ => {}
        }
        match tag {
            "v" => nv += 1,
            "vt" => nvt += 1,
            "vn" => nvn += 1,
            _ => {}
        }
    }
    (None, e.to_string())
}

fn first_non_finite_vertex_line(text: &str) -> Option<usize> {
    text.lines().enumerate().find_map(|(i, l)| {
        let mut w = l.split_whitespace();
        (w.next() == Some("v") && w.take(3).any(|a| a.parse::<f32>().map(|x| !x.is_finite()).unwrap_or(false))).then_some(i + 1)
    })
}

// ---------------------------------------------------------------- glTF

/// Extensions that change no geometry: allowed even when required.
const HARMLESS_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_pbrSpecularGlossiness",
    "KHR_materials_unlit",
    "KHR_texture_transform",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "MSFT_texture_dds",
];

struct GltfCtx<'a> {
    path: &'a Path,
    files: &'a Files,
    doc: &'a gltf::Document,
    blob: Option<&'a [u8]>,
    buffers: Vec<Option<Vec<u8>>>,
    pos: Vec<Vec3>,
    tris: Vec<[u32; 3]>,
    warnings: Vec<String>,
}

fn load_gltf(path: &Path, bytes: &[u8], files: &Files) -> Result<LoadedMesh, MeshLoadError> {
    let malformed = |place: &str, message: String| MeshLoadError::Malformed { path: path.into(), place: place.into(), message };
    if bytes.starts_with(b"glTF") && bytes.get(4..8) == Some(&1u32.to_le_bytes()[..]) {
        return Err(MeshLoadError::Unsupported { path: path.into(), place: "GLB header".into(), what: "glTF 1.0".into() });
    }
    if let Ok(v) = peek_version(bytes) {
        if !v.starts_with("2.") {
            return Err(MeshLoadError::Unsupported {
                path: path.into(),
                place: "asset.version".into(),
                what: format!("glTF {v} (only 2.x)"),
            });
        }
    }
    // Required extensions first, so that the message names them (the validator
    // would only say "invalid glTF").
    if let Ok(root) = peek_required_extensions(bytes) {
        for (i, ext) in root.iter().enumerate() {
            if !HARMLESS_EXTENSIONS.contains(&ext.as_str()) {
                return Err(MeshLoadError::Unsupported {
                    path: path.into(),
                    place: format!("extensionsRequired[{i}]"),
                    what: format!("extension {ext}"),
                });
            }
        }
    }
    let g = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| match e {
        gltf::Error::Binary(_) => malformed("GLB container", e.to_string()),
        _ => malformed("JSON", e.to_string()),
    })?;
    // gltf's validation, minus one rule: POSITION accessors without min/max are
    // common in the wild and harmless here (we compute bounds ourselves). Every
    // other error (notably out-of-range references, which would make gltf's
    // iterators panic) is kept.
    {
        use gltf::json::validation::{Error as VError, Validate};
        let root = g.document.as_json();
        check_mesh_accessor_indices(path, root)?;
        let mut errors = Vec::new();
        root.validate(root, gltf::json::Path::new, &mut |path, error| errors.push((path(), error)));
        errors.retain(|(p, e)| !(*e == VError::Missing && (p.as_str().ends_with(".min") || p.as_str().ends_with(".max"))));
        if !errors.is_empty() {
            return Err(malformed("JSON", gltf::Error::Validation(errors).to_string()));
        }
    }
    let doc = &g.document;
    let mut ctx = GltfCtx {
        path,
        files,
        doc,
        blob: g.blob.as_deref(),
        buffers: vec![None; doc.buffers().len()],
        pos: vec![],
        tris: vec![],
        warnings: vec![],
    };
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let identity = DMat4::IDENTITY;
    match scene {
        Some(s) => {
            for n in s.nodes() {
                ctx.node(n, identity, &mut Vec::new())?;
            }
        }
        None if doc.nodes().len() > 0 => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            for n in doc.nodes().filter(|n| !is_child[n.index()]) {
                ctx.node(n, identity, &mut Vec::new())?;
            }
        }
        None => {
            if doc.meshes().len() > 0 {
                ctx.warnings.push(format!("{}: no scene and no nodes: every mesh is used untransformed", path.display()));
            }
            for m in doc.meshes() {
                ctx.mesh(&m, &identity)?;
            }
        }
    }
    Ok((ctx.pos, ctx.tris, ctx.warnings))
}

/// gltf-json's own validation indexes `accessors` with a primitive's POSITION
/// index unchecked (gltf-json 1.4.1, mesh.rs: `&root.accessors[...]`), so a file
/// with `"POSITION": 99` panics inside it. Every accessor index of every
/// primitive (attributes, indices, morph targets) is checked here first.
fn check_mesh_accessor_indices(path: &Path, root: &gltf::json::Root) -> Result<(), MeshLoadError> {
    let n = root.accessors.len();
    let bad = |place: String, index: usize| MeshLoadError::Malformed {
        path: path.into(),
        place,
        message: format!("accessor {index} does not exist ({n} accessors)"),
    };
    for (mi, mesh) in root.meshes.iter().enumerate() {
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            let place = format!("JSON at meshes[{mi}].primitives[{pi}]");
            for (sem, a) in &prim.attributes {
                if a.value() >= n {
                    let name = match sem {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".into(),
                    };
                    return Err(bad(format!("{place}.attributes.{name}"), a.value()));
                }
            }
            if let Some(a) = &prim.indices {
                if a.value() >= n {
                    return Err(bad(format!("{place}.indices"), a.value()));
                }
            }
            for (ti, t) in prim.targets.iter().flatten().enumerate() {
                for (k, a) in [("POSITION", &t.positions), ("NORMAL", &t.normals), ("TANGENT", &t.tangents)] {
                    if let Some(a) = a.filter(|a| a.value() >= n) {
                        return Err(bad(format!("{place}.targets[{ti}].{k}"), a.value()));
                    }
                }
            }
        }
    }
    Ok(())
}

/// `asset.version` of a .gltf (glTF 1.0 files fail to parse as 2.0 with a confusing message).
fn peek_version(bytes: &[u8]) -> Result<String, ()> {
    let v: serde_json::Value = serde_json::from_slice(bytes).map_err(|_| ())?;
    Ok(v.get("asset").and_then(|a| a.get("version")).ok_or(())?.as_str().ok_or(())?.to_string())
}

fn peek_required_extensions(bytes: &[u8]) -> Result<Vec<String>, ()> {
    #[derive(serde::Deserialize)]
    struct Root {
        #[serde(default, rename = "extensionsRequired")]
        required: Vec<String>,
    }
    let r: Root = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(bytes).map_err(|_| ())?;
        serde_json::from_slice(&glb.json).map_err(|_| ())?
    } else {
        serde_json::from_slice(bytes).map_err(|_| ())?
    };
    Ok(r.required)
}

impl GltfCtx<'_> {
    fn node(&mut self, n: gltf::Node, parent: DMat4, on_path: &mut Vec<usize>) -> Result<(), MeshLoadError> {
        if on_path.contains(&n.index()) || on_path.len() >= MAX_DEPTH {
            return Err(MeshLoadError::Malformed {
                path: self.path.into(),
                place: format!("node {}", n.index()),
                message: "node hierarchy has a cycle or is too deep".into(),
            });
        }
        let local = DMat4::from_cols_array_2d(&n.transform().matrix().map(|c| c.map(|x| x as f64)));
        let m = parent * local;
        if let Some(mesh) = n.mesh() {
            self.mesh(&mesh, &m)?;
        }
        on_path.push(n.index());
        for c in n.children() {
            self.node(c, m, on_path)?;
        }
        on_path.pop();
        Ok(())
    }

    fn mesh(&mut self, mesh: &gltf::Mesh, m: &DMat4) -> Result<(), MeshLoadError> {
        // A mirroring transform turns counter-clockwise (outward) into clockwise.
        let mirror = m.determinant() < 0.0;
        for prim in mesh.primitives() {
            let place = format!("mesh {} primitive {}", mesh.index(), prim.index());
            use gltf::mesh::Mode;
            let mode = prim.mode();
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                self.warnings.push(format!("{}: {place}: skipped ({mode:?} primitive)", self.path.display()));
                continue;
            }
            let Some(pa) = prim.get(&gltf::Semantic::Positions) else {
                self.warnings.push(format!("{}: {place}: skipped (no POSITION attribute)", self.path.display()));
                continue;
            };
            let pplace = format!("{place} POSITION accessor {}", pa.index());
            if pa.data_type() != gltf::accessor::DataType::F32 || pa.dimensions() != gltf::accessor::Dimensions::Vec3 {
                return Err(MeshLoadError::WrongType {
                    path: self.path.into(),
                    place: pplace,
                    message: format!("POSITION must be VEC3 of FLOAT, found {:?} of {:?}", pa.dimensions(), pa.data_type()),
                });
            }
            let (bi, start, count, stride) = self.accessor(&pa, &pplace)?;
            let data = &self.buffers[bi].as_deref().unwrap_or(&[])[start..];
            if self.pos.len() + count > MAX_TRIANGLES {
                return Err(MeshLoadError::TooLarge { path: self.path.into() });
            }
            let base = self.pos.len();
            for i in 0..count {
                let o = i * stride;
                let f = |k: usize| f32::from_le_bytes(data[o + 4 * k..o + 4 * k + 4].try_into().unwrap());
                let p = DVec3::new(f(0) as f64, f(1) as f64, f(2) as f64);
                let q = m.transform_point3(p).as_vec3();
                if !q.is_finite() {
                    return Err(MeshLoadError::NonFinite { path: self.path.into(), place: format!("{pplace} element {i}") });
                }
                self.pos.push(q);
            }
            // Indices (or 0..count).
            let idx: Vec<u32> = match prim.indices() {
                None => (0..count as u32).collect(),
                Some(ia) => {
                    let iplace = format!("{place} indices accessor {}", ia.index());
                    use gltf::accessor::DataType as D;
                    let size = match (ia.dimensions(), ia.data_type()) {
                        (gltf::accessor::Dimensions::Scalar, D::U8) => 1,
                        (gltf::accessor::Dimensions::Scalar, D::U16) => 2,
                        (gltf::accessor::Dimensions::Scalar, D::U32) => 4,
                        (d, t) => {
                            return Err(MeshLoadError::WrongType {
                                path: self.path.into(),
                                place: iplace,
                                message: format!("indices must be SCALAR of UNSIGNED_BYTE/SHORT/INT, found {d:?} of {t:?}"),
                            })
                        }
                    };
                    let (bi, start, n, stride) = self.accessor(&ia, &iplace)?;
                    let data = &self.buffers[bi].as_deref().unwrap_or(&[])[start..];
                    if n > 3 * MAX_TRIANGLES {
                        return Err(MeshLoadError::TooLarge { path: self.path.into() });
                    }
                    let mut v = Vec::with_capacity(n);
                    for i in 0..n {
                        let o = i * stride;
                        let k = match size {
                            1 => data[o] as u32,
                            2 => u16::from_le_bytes([data[o], data[o + 1]]) as u32,
                            _ => u32::from_le_bytes(data[o..o + 4].try_into().unwrap()),
                        };
                        if k as usize >= count {
                            return Err(MeshLoadError::IndexOutOfRange {
                                path: self.path.into(),
                                place: format!("{iplace} element {i}"),
                                index: k as u64,
                                count,
                            });
                        }
                        v.push(k);
                    }
                    v
                }
            };
            let n = idx.len();
            let mut push = |a: u32, b: u32, c: u32| {
                let (b, c) = if mirror { (c, b) } else { (b, c) };
                self.tris.push([base as u32 + a, base as u32 + b, base as u32 + c]);
            };
            match mode {
                Mode::Triangles => {
                    for t in idx.chunks_exact(3) {
                        push(t[0], t[1], t[2]);
                    }
                }
                // glTF 2.0, section 3.7.2.1: strip p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2-i%2)}}
                Mode::TriangleStrip => {
                    for i in 0..n.saturating_sub(2) {
                        push(idx[i], idx[i + 1 + i % 2], idx[i + 2 - i % 2]);
                    }
                }
                // fan p_i = {v_{i+1}, v_{i+2}, v_0}
                _ => {
                    for i in 0..n.saturating_sub(2) {
                        push(idx[i + 1], idx[i + 2], idx[0]);
                    }
                }
            }
            if self.tris.len() > MAX_TRIANGLES {
                return Err(MeshLoadError::TooLarge { path: self.path.into() });
            }
        }
        Ok(())
    }

    /// Where an accessor's elements are: `(buffer, byte offset of element 0, count,
    /// stride)`, after loading the buffer and checking that every element lies
    /// inside the buffer view and the view inside the buffer.
    fn accessor(&mut self, a: &gltf::Accessor, place: &str) -> Result<(usize, usize, usize, usize), MeshLoadError> {
        let err = |message: String| MeshLoadError::Malformed { path: self.path.into(), place: place.into(), message };
        if a.sparse().is_some() {
            return Err(MeshLoadError::Unsupported { path: self.path.into(), place: place.into(), what: "sparse accessors".into() });
        }
        let Some(view) = a.view() else {
            return Err(MeshLoadError::Unsupported {
                path: self.path.into(),
                place: place.into(),
                what: "accessor without a bufferView".into(),
            });
        };
        let elem = a.size();
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(err(format!("byteStride {stride} is smaller than the element size {elem}")));
        }
        let count = a.count();
        let vstart = view.offset();
        let vlen = view.length();
        let need = if count == 0 {
            Some(0)
        } else {
            (count - 1).checked_mul(stride).and_then(|x| x.checked_add(elem)).and_then(|x| x.checked_add(a.offset()))
        };
        match need {
            Some(need) if need <= vlen => {}
            _ => {
                return Err(err(format!(
                    "{count} elements of {elem} bytes (stride {stride}, offset {}) do not fit in bufferView {} of {vlen} bytes",
                    a.offset(),
                    view.index()
                )))
            }
        }
        let buffer = view.buffer();
        let bi = buffer.index();
        let vend = vstart
            .checked_add(vlen)
            .filter(|&e| e <= buffer.length())
            .ok_or_else(|| err(format!("bufferView {} ends past the end of buffer {bi} ({} bytes)", view.index(), buffer.length())))?;
        self.load_buffer(bi)?;
        let data = self.buffers[bi].as_deref().unwrap_or(&[]);
        if data.len() < vend {
            return Err(MeshLoadError::MissingBuffer {
                path: self.path.into(),
                place: format!("buffer {bi}"),
                message: format!("{} bytes available, bufferView {} needs {vend}", data.len(), view.index()),
            });
        }
        Ok((bi, vstart + a.offset(), count, stride))
    }

    fn load_buffer(&mut self, bi: usize) -> Result<(), MeshLoadError> {
        if self.buffers[bi].is_some() {
            return Ok(());
        }
        let buffer = self.doc.buffers().nth(bi).expect("validated buffer index");
        let place = format!("buffer {bi}");
        let missing = |message: String| MeshLoadError::MissingBuffer { path: self.path.into(), place: place.clone(), message };
        let data: Vec<u8> = match buffer.source() {
            gltf::buffer::Source::Bin => match self.blob {
                Some(b) => b.to_vec(),
                None => return Err(missing("the GLB has no BIN chunk".into())),
            },
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let Some((_, b64)) = rest.split_once(";base64,") else {
                        return Err(MeshLoadError::Unsupported { path: self.path.into(), place, what: "data URI without ;base64,".into() });
                    };
                    base64::engine::general_purpose::STANDARD.decode(b64.trim_end()).map_err(|e| MeshLoadError::Malformed {
                        path: self.path.into(),
                        place: place.clone(),
                        message: format!("bad base64 in data URI: {e}"),
                    })?
                } else if uri.contains("://") {
                    return Err(MeshLoadError::Unsupported {
                        path: self.path.into(),
                        place,
                        what: format!("buffer URI {uri:?} (only relative files and data URIs)"),
                    });
                } else {
                    // Decoded first, so that `..%2F` is a `..` that the folder check sees.
                    let file = self.path.parent().unwrap_or(Path::new(".")).join(percent_decode(uri));
                    self.files.read_prefix(&file, buffer.length() as u64).map_err(|e| missing(e.to_string()))?
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(missing(format!("declared {} bytes, found {}", buffer.length(), data.len())));
        }
        self.buffers[bi] = Some(data);
        Ok(())
    }
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
#[path = "mesh_tests.rs"]
mod tests;
