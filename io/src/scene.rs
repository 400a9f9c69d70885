//! The JSON scene format (see `docs/scene-format.md`): parsed into a `hecs::World`
//! with errors located by JSON path.

use std::path::{Path, PathBuf};

use crate::json::{Map, Value};
use glam::{DMat4, DVec3, Vec3};
use hecs::{Entity, World};
use rothray_engine::{
    Camera, Cone, CsgNode, Cuboid, Cylinder, Frame, GeneralizedCylinder, HalfSpace, InsideRule, Light, Material, MeshData, MeshSolid, Name,
    ObjectOrder, Op, Profile, Sphere, SweptSphere, Torus, Transform,
};
use rothray_primitives::{table::MAX_COORD, LeafShape};
use serde::Deserialize;
use std::collections::HashMap;
use std::sync::Arc;

use crate::files::{read_user_text, FileError, Files, LoadOptions};
use crate::json_path::At;

/// A scene file, loaded: settings plus a World holding its solids.
pub struct SceneFile {
    /// The file it came from.
    pub path: PathBuf,
    /// The scene's `name` (if any).
    pub name: Option<String>,
    /// Camera.
    pub camera: Camera,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Background colour.
    pub background: Vec3,
    /// Lights.
    pub lights: Vec<Light>,
    /// Objects (and their parts) as entities.
    pub world: World,
    /// Top-level object entities, in file order.
    pub objects: Vec<Entity>,
    /// Warnings (e.g. from mesh import).
    pub warnings: Vec<String>,
    /// Every file the load opened (canonical), the scene file first: the record
    /// that shows no file outside the allowed folders was touched.
    pub files_read: Vec<PathBuf>,
}

/// A scene that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// File.
        file: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The scene file is not a regular file or cannot be read.
    #[error("{source}")]
    File {
        /// File.
        file: String,
        /// Why.
        source: FileError,
    },
    /// Not JSON.
    #[error("{file}:{line}:{column}: invalid JSON: {message}")]
    Json {
        /// File.
        file: String,
        /// Line (1-based).
        line: usize,
        /// Column (1-based).
        column: usize,
        /// What the parser said.
        message: String,
    },
    /// JSON that breaks the scene format.
    #[error("{file}: {at}: {message}")]
    Invalid {
        /// File.
        file: String,
        /// JSON path (`objects[2].shape.difference[1].sphere.radius`).
        at: String,
        /// What is wrong.
        message: String,
    },
}

struct Ctx<'a> {
    file: String,
    dir: &'a Path,
    files: &'a Files,
    world: World,
    names: std::collections::HashSet<String>,
    warnings: Vec<String>,
    meshes: HashMap<(PathBuf, bool), Arc<MeshData>>,
}

type R<T> = Result<T, SceneError>;

/// A place for an error: a spelled-out path (`&str`, near the leaves) or an
/// implicit one ([`At`], while descending the shape tree).
trait Loc {
    fn render(&self) -> String;
}
impl Loc for str {
    fn render(&self) -> String {
        self.to_string()
    }
}
impl Loc for String {
    fn render(&self) -> String {
        self.clone()
    }
}
/// `parent.key`, spelled out only for an error (a leaf's fields are read on
/// every leaf; their paths are wanted on almost none).
struct Sub<'a>(&'a str, &'a str);
impl Loc for Sub<'_> {
    fn render(&self) -> String {
        join(self.0, self.1)
    }
}
impl Loc for At<'_> {
    fn render(&self) -> String {
        At::render(self)
    }
}

impl Ctx<'_> {
    fn err<T>(&self, at: &(impl Loc + ?Sized), message: impl Into<String>) -> R<T> {
        Err(SceneError::Invalid { file: self.file.clone(), at: at.render(), message: message.into() })
    }
    fn obj<'v>(&self, v: &'v Value, at: &(impl Loc + ?Sized)) -> R<&'v Map> {
        match v.as_object() {
            Some(m) => Ok(m),
            None => self.err(at, format!("expected an object, got {}", kind_of(v))),
        }
    }
    fn keys(&self, m: &Map, at: &(impl Loc + ?Sized), allowed: &[&str], required: &[&str]) -> R<()> {
        for k in m.keys() {
            if !allowed.contains(&k) {
                return self.err(&join(&at.render(), k), format!("unknown key `{k}` (expected one of: {})", allowed.join(", ")));
            }
        }
        for r in required {
            if !m.contains_key(r) {
                return self.err(at, format!("missing field `{r}`"));
            }
        }
        Ok(())
    }
    fn num(&self, v: &Value, at: &(impl Loc + ?Sized)) -> R<f64> {
        match v.as_f64() {
            Some(x) if finite_f32(v).is_some() => Ok(x),
            Some(x) => self.err(at, format!("number {x} is not finite in f32")),
            None => self.err(at, format!("expected a number, got {}", kind_of(v))),
        }
    }
    fn vec3(&self, v: &Value, at: &(impl Loc + ?Sized)) -> R<DVec3> {
        // The element's place is spelled out only for an error.
        let num = |k: usize| self.num(&v[k], &format!("{}[{k}]", at.render()));
        match v.as_array() {
            Some([x, y, z]) => match (finite_f32(x), finite_f32(y), finite_f32(z)) {
                (Some(x), Some(y), Some(z)) => Ok(DVec3::new(x, y, z)),
                _ => Ok(DVec3::new(num(0)?, num(1)?, num(2)?)),
            },
            Some(a) => self.err(at, format!("expected an array of 3 numbers, got {} elements", a.len())),
            None => self.err(at, format!("expected an array of 3 numbers, got {}", kind_of(v))),
        }
    }
    fn color(&self, v: &Value, at: &(impl Loc + ?Sized)) -> R<Vec3> {
        let c = self.vec3(v, at)?;
        if c.min_element() < 0.0 {
            return self.err(at, "colour components must be >= 0");
        }
        Ok(c.as_vec3())
    }
    fn name(&mut self, v: &Value, at: &(impl Loc + ?Sized)) -> R<String> {
        let Some(s) = v.as_str() else { return self.err(at, format!("expected a string, got {}", kind_of(v))) };
        if s.is_empty() {
            return self.err(at, "name is empty");
        }
        if !self.names.insert(s.to_string()) {
            return self.err(at, format!("name `{s}` is used twice"));
        }
        Ok(s.to_string())
    }
}

/// The number, if it is one and finite in f32.
/// The supported vertical field of view, in degrees. Narrower views have
/// pixel directions closer than f32 resolves (at 1080 rows, 0.01 degrees
/// is 1.6e-7 rad a row, under 3 ulps of a unit direction); at 180 the
/// tangent of the half angle is infinite (179.9: 1146).
pub const FOV_RANGE: (f64, f64) = (0.01, 179.9);

fn finite_f32(v: &Value) -> Option<f64> {
    v.as_f64().filter(|x| x.is_finite() && x.abs() <= f32::MAX as f64)
}

fn join(at: &str, k: &str) -> String {
    if at.is_empty() {
        k.to_string()
    } else {
        format!("{at}.{k}")
    }
}

fn kind_of(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

const LEAF_KINDS: &[&str] = &["sphere", "box", "cylinder", "cone", "torus", "plane", "swept_sphere", "generalized_cylinder", "mesh"];
const NODE_KINDS: &[&str] = &["union", "intersection", "difference", "transformed"];

/// Loads a scene file (mesh paths are relative to it); the files it names must
/// lie in its folder (see [`load_scene_with`] to allow others). Runs on a thread
/// with a large stack so that deeply nested scenes (100 000 levels) parse.
pub fn load_scene(path: &Path) -> Result<SceneFile, SceneError> {
    load_scene_with(path, &LoadOptions::default())
}

/// [`load_scene`] with options: the folders, besides the scene's own, that the
/// files it names may lie in.
pub fn load_scene_with(path: &Path, opts: &LoadOptions) -> Result<SceneFile, SceneError> {
    load_scene_recorded(path, opts).0
}

/// [`load_scene_with`], plus every file the load opened (canonical), whether it
/// succeeded or not: the record that shows what a scene made the loader read.
pub fn load_scene_recorded(path: &Path, opts: &LoadOptions) -> (Result<SceneFile, SceneError>, Vec<PathBuf>) {
    let file = path.display().to_string();
    let text = match read_user_text(path) {
        Ok(t) => t,
        Err(e) => return (Err(SceneError::File { file, source: e }), Vec::new()),
    };
    let (dir, files) = scene_files(path, opts);
    let mut opened: Vec<PathBuf> = std::fs::canonicalize(path).into_iter().collect();
    let r = parse_scene_in(&text, path, &dir, &files).map(|mut sf| {
        sf.files_read.splice(0..0, opened.iter().cloned());
        sf
    });
    opened.extend(files.opened());
    (r, opened)
}

/// Parses scene text; `path` names the file in errors and anchors relative mesh
/// paths, which must lie in its folder.
pub fn parse_scene(text: &str, path: &Path) -> Result<SceneFile, SceneError> {
    parse_scene_with(text, path, &LoadOptions::default())
}

/// [`parse_scene`] with options (see [`load_scene_with`]).
pub fn parse_scene_with(text: &str, path: &Path, opts: &LoadOptions) -> Result<SceneFile, SceneError> {
    let (dir, files) = scene_files(path, opts);
    parse_scene_in(text, path, &dir, &files)
}

/// The scene's real folder and the files it may read. Mesh paths are relative
/// to the real file that names them, and a link to a scene must not widen what
/// that scene may read.
fn scene_files(path: &Path, opts: &LoadOptions) -> (PathBuf, Files) {
    let dir = match std::fs::canonicalize(path) {
        Ok(real) => real.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("/")),
        Err(_) => path.parent().map(Path::to_path_buf).unwrap_or_default(),
    };
    let files = Files::new(&dir, opts);
    (dir, files)
}

fn parse_scene_in(text: &str, path: &Path, dir: &Path, files: &Files) -> Result<SceneFile, SceneError> {
    // Deep nesting recurses: parse on a thread with a large stack (address space
    // only; pages are touched as used). If the system refuses that much, try less.
    let crashed = || SceneError::Invalid {
        file: path.display().to_string(),
        at: "(unknown)".into(),
        message: "the parser crashed (a bug: please report this scene)".into(),
    };
    let run = |text: &str, dir: &Path| {
        // The last line of defence only: every input is meant to end in a typed
        // error; a panic that escapes anyway becomes a located one, not a crash.
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse_scene_inner(text, path, dir, files)))
            .unwrap_or_else(|_| Err(crashed()))
    };
    for stack in [1usize << 30, 1 << 26] {
        let spawned = std::thread::scope(|sc| {
            std::thread::Builder::new()
                .name("scene-parse".into())
                .stack_size(stack)
                .spawn_scoped(sc, || run(text, dir))
                .map(|h| h.join().unwrap_or_else(|_| Err(crashed())))
        });
        if let Ok(r) = spawned {
            return r;
        }
    }
    run(text, dir)
}

fn parse_scene_inner(text: &str, path: &Path, dir: &Path, files: &Files) -> Result<SceneFile, SceneError> {
    let file = path.display().to_string();
    let mut de = serde_json::Deserializer::from_str(text);
    de.disable_recursion_limit();
    let root = Value::deserialize(&mut de).and_then(|v| de.end().map(|_| v)).map_err(|e| SceneError::Json {
        file: file.clone(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    let mut cx = Ctx { file, dir, files, world: World::new(), names: Default::default(), warnings: Vec::new(), meshes: HashMap::new() };
    let res = parse_root(&mut cx, &root, path);
    // Deep trees drop recursively: do it here, on the big stack.
    drop(root);
    res.map(|mut sf| {
        sf.files_read = files.opened();
        sf
    })
}

fn parse_root(cx: &mut Ctx, root: &Value, path: &Path) -> R<SceneFile> {
    // Borrowed, not cloned: a clone doubled the memory of a large scene.
    let m = cx.obj(root, "")?;
    cx.keys(m, "", &["name", "camera", "image", "background", "lights", "objects"], &["camera", "objects"])?;
    let name = match m.get("name") {
        Some(Value::String(s)) => Some(s.to_string()),
        Some(v) => return cx.err("name", format!("expected a string, got {}", kind_of(v))),
        None => None,
    };
    // camera
    let cm = cx.obj(&m["camera"], "camera")?;
    cx.keys(cm, "camera", &["eye", "target", "up", "fov_y_deg"], &["eye", "target", "fov_y_deg"])?;
    let eye = cx.vec3(&cm["eye"], "camera.eye")?;
    let target = cx.vec3(&cm["target"], "camera.target")?;
    let up = match cm.get("up") {
        Some(v) => cx.vec3(v, "camera.up")?,
        None => DVec3::Y,
    };
    let fov = cx.num(&cm["fov_y_deg"], "camera.fov_y_deg")?;
    let (fov_lo, fov_hi) = FOV_RANGE;
    if !(fov_lo..=fov_hi).contains(&fov) {
        return cx.err("camera.fov_y_deg", format!("must be between {fov_lo} and {fov_hi} degrees (the supported range), got {fov}"));
    }
    for (v, at) in [(eye, "camera.eye"), (target, "camera.target")] {
        let far = v.abs().max_element();
        if far > MAX_COORD * (1.0 + 1e-6) {
            return cx.err(at, format!("a coordinate of {far:.3e} is outside the supported -{MAX_COORD:e} to {MAX_COORD:e}"));
        }
    }
    // The camera is f32: compare what it will hold (eye and target 1 apart
    // at 1e20 are one point in f32, whose spacing there is 8.8e12).
    let view = target.as_vec3().as_dvec3() - eye.as_vec3().as_dvec3();
    if view.length() == 0.0 {
        let how = if (target - eye).length() == 0.0 { "" } else { " once rounded to f32 (the scene's coordinates are f32)" };
        return cx.err("camera.target", format!("target equals eye{how}"));
    }
    let up32 = up.as_vec3().as_dvec3();
    if up32.length() == 0.0 {
        return cx.err("camera.up", "is the zero vector (or below f32's smallest number)");
    }
    // The renderer takes any up whose sine with the view is at least 1e-6
    // (in f32); 1e-5 leaves room for its rounding.
    if view.normalize().cross(up32.normalize()).length() < 1e-5 {
        return cx.err("camera.up", "is parallel to the viewing direction (supported: at least 1e-5 rad away from it)");
    }
    let camera = Camera { eye: eye.as_vec3(), target: target.as_vec3(), up: up.as_vec3(), fov_y_deg: fov as f32 };
    // image
    let (mut width, mut height) = (800u32, 600u32);
    if let Some(iv) = m.get("image") {
        let im = cx.obj(iv, "image")?;
        cx.keys(im, "image", &["width", "height"], &[])?;
        for (k, slot) in [("width", &mut width), ("height", &mut height)] {
            if let Some(v) = im.get(k) {
                let at = format!("image.{k}");
                match v.as_u64() {
                    Some(x) if (1..=65536).contains(&x) => *slot = x as u32,
                    _ => return cx.err(&at, format!("expected an integer from 1 to 65536, got {v}")),
                }
            }
        }
    }
    let background = match m.get("background") {
        Some(v) => cx.color(v, "background")?,
        None => Vec3::ZERO,
    };
    let lights = match m.get("lights") {
        None => {
            // Over the camera's shoulder: from behind-left-above the eye toward the target.
            let fwd = (target - eye).normalize();
            let right = fwd.cross(up).normalize();
            let dir = fwd - up.normalize() * 0.5 + right * 0.3;
            vec![Light { direction: dir.normalize().as_vec3(), color: Vec3::ONE }]
        }
        Some(Value::Array(a)) => {
            let mut out = Vec::new();
            for (i, l) in a.iter().enumerate() {
                let at = format!("lights[{i}]");
                let lm = cx.obj(l, &at)?;
                cx.keys(lm, &at, &["direction", "color"], &["direction"])?;
                let d = cx.vec3(&lm["direction"], &format!("{at}.direction"))?;
                if d.length() == 0.0 {
                    return cx.err(&format!("{at}.direction"), "is the zero vector");
                }
                let c = match lm.get("color") {
                    Some(v) => cx.color(v, &format!("{at}.color"))?,
                    None => Vec3::ONE,
                };
                out.push(Light { direction: d.as_vec3(), color: c });
            }
            out
        }
        Some(v) => return cx.err("lights", format!("expected an array, got {}", kind_of(v))),
    };
    // objects
    let Some(objs) = m["objects"].as_array() else {
        return cx.err("objects", format!("expected an array, got {}", kind_of(&m["objects"])));
    };
    let mut objects = Vec::new();
    for (i, o) in objs.iter().enumerate() {
        let at = format!("objects[{i}]");
        let om = cx.obj(o, &at)?;
        cx.keys(om, &at, &["name", "color", "shape"], &["shape"])?;
        let name = match om.get("name") {
            Some(v) => cx.name(v, &format!("{at}.name"))?,
            None => format!("object{i}"),
        };
        let color = match om.get("color") {
            Some(v) => Some(cx.color(v, &format!("{at}.color"))?),
            None => None,
        };
        let root_at = At::root();
        let objects_at = root_at.key("objects");
        let obj_at = objects_at.index(i);
        let e = parse_shape(cx, &om["shape"], &obj_at.key("shape"))?;
        // The object is its shape's root entity; give it the object's name and order.
        let leaf_name = cx.world.get::<&Name>(e).ok().map(|n| n.0.clone());
        let root = if leaf_name.is_some() && cx.world.get::<&CsgNode>(e).is_err() {
            // A bare leaf keeps its own name for `leaf`: wrap it in a one-child union.
            cx.world.spawn((CsgNode::union([e]),))
        } else {
            e
        };
        let _ = cx.world.insert(root, (Name::new(name), ObjectOrder(i as u32)));
        if let Some(c) = color {
            let _ = cx.world.insert_one(root, Material { color: c });
        }
        objects.push(root);
    }
    let world = std::mem::take(&mut cx.world);
    Ok(SceneFile {
        path: path.to_path_buf(),
        name,
        camera,
        width,
        height,
        background,
        lights,
        world,
        objects,
        warnings: std::mem::take(&mut cx.warnings),
        files_read: Vec::new(),
    })
}

fn parse_shape(cx: &mut Ctx, v: &Value, at: &At) -> R<Entity> {
    let m = cx.obj(v, at)?;
    let kinds: Vec<&str> = m.keys().filter(|&k| k != "name" && k != "color").collect();
    if kinds.is_empty() {
        return cx.err(at, format!("missing the shape kind (one of: {}, {})", LEAF_KINDS.join(", "), NODE_KINDS.join(", ")));
    }
    if kinds.len() > 1 {
        return cx.err(at, format!("more than one shape kind: {}", kinds.join(", ")));
    }
    let kind = kinds[0];
    let kat = at.key(kind);
    let name = match m.get("name") {
        Some(v) => Some(cx.name(v, &at.key("name"))?),
        None => None,
    };
    let color = match m.get("color") {
        Some(v) => Some(cx.color(v, &at.key("color"))?),
        None => None,
    };
    let body = &m[kind];
    let e = match kind {
        "union" | "intersection" | "difference" => {
            let Some(arr) = body.as_array() else {
                return cx.err(&kat, format!("expected an array of shapes, got {}", kind_of(body)));
            };
            if arr.is_empty() {
                return cx.err(&kat, "needs at least one shape");
            }
            let mut children = Vec::with_capacity(arr.len());
            for (i, c) in arr.iter().enumerate() {
                children.push(parse_shape(cx, c, &kat.index(i))?);
            }
            let op = match kind {
                "union" => Op::Union,
                "intersection" => Op::Intersection,
                _ => Op::Difference,
            };
            cx.world.spawn((CsgNode { op, children },))
        }
        "transformed" => {
            let tm = cx.obj(body, &kat)?;
            cx.keys(tm, &kat, &["shape", "translate", "rotate_deg", "scale", "matrix"], &["shape"])?;
            let t = if let Some(mv) = tm.get("matrix") {
                for k in ["translate", "rotate_deg", "scale"] {
                    if tm.contains_key(k) {
                        return cx.err(&kat.key(k), "cannot be combined with `matrix`");
                    }
                }
                let mat = kat.key("matrix").render();
                let Some(a) = mv.as_array() else { return cx.err(&mat, "expected an array of 16 numbers") };
                if a.len() != 16 {
                    return cx.err(&mat, format!("expected 16 numbers, got {}", a.len()));
                }
                let mut r = [0.0f64; 16];
                for (i, x) in a.iter().enumerate() {
                    r[i] = cx.num(x, &format!("{mat}[{i}]"))?;
                }
                if r[12] != 0.0 || r[13] != 0.0 || r[14] != 0.0 || r[15] != 1.0 {
                    return cx.err(&mat, "last row must be 0 0 0 1");
                }
                // Row-major in the file; glam is column-major.
                let m4 = DMat4::from_cols_array(&r).transpose();
                // Singular relative to its own size: the determinant against
                // the product of its columns' lengths (1 for a rotation times
                // a scale, whatever the scale; an absolute bound refused every
                // matrix of a solid 1e-6 across).
                let det = m4.determinant();
                let cols = m4.x_axis.truncate().length() * m4.y_axis.truncate().length() * m4.z_axis.truncate().length();
                if !(det.abs() > 1e-12 * cols) {
                    return cx.err(
                        &mat,
                        format!(
                            "matrix is singular (determinant {det:e}, {:e} of the product of its column lengths; at least 1e-12 is needed)",
                            det.abs() / cols
                        ),
                    );
                }
                Transform::from_mat4(m4)
            } else {
                let tr = match tm.get("translate") {
                    Some(v) => cx.vec3(v, &kat.key("translate"))?,
                    None => DVec3::ZERO,
                };
                let rot = match tm.get("rotate_deg") {
                    Some(v) => cx.vec3(v, &kat.key("rotate_deg"))?,
                    None => DVec3::ZERO,
                };
                let sc = match tm.get("scale") {
                    Some(v) if v.is_number() => DVec3::splat(cx.num(v, &kat.key("scale"))?),
                    Some(v) => cx.vec3(v, &kat.key("scale"))?,
                    None => DVec3::ONE,
                };
                if sc.x == 0.0 || sc.y == 0.0 || sc.z == 0.0 {
                    return cx.err(&kat.key("scale"), "a zero scale makes the transform singular");
                }
                Transform::from_trs_deg(tr, rot, sc)
            };
            let child = parse_shape(cx, &tm["shape"], &kat.key("shape"))?;
            // A transformed node is a one-child union carrying the transform.
            cx.world.spawn((CsgNode::union([child]), t))
        }
        // Leaves are named by their JSON path unless they have a `name` (set
        // below); the path is spelled out here, once per leaf, elided when long.
        "swept_sphere" => {
            let kat = kat.render();
            let desc = parse_sweep(cx, body, &kat)?;
            cx.world.spawn((desc, Name::new(kat)))
        }
        "generalized_cylinder" => {
            let kat = kat.render();
            let desc = parse_gcyl(cx, body, &kat)?;
            cx.world.spawn((desc, Name::new(kat)))
        }
        "mesh" => {
            let kat = kat.render();
            let m = parse_mesh(cx, body, &kat)?;
            cx.world.spawn((MeshSolid(m), Name::new(kat)))
        }
        _ if LEAF_KINDS.contains(&kind) => {
            let kat = kat.render();
            let shape = parse_leaf(cx, kind, body, &kat)?;
            if let Err(e) = shape.validate() {
                let at = join(&kat, e.field);
                return cx.err(&at, e.message);
            }
            let path = Name::new(kat);
            match shape {
                LeafShape::Sphere(s) => cx.world.spawn((s, path)),
                LeafShape::Cuboid(s) => cx.world.spawn((s, path)),
                LeafShape::Cylinder(s) => cx.world.spawn((s, path)),
                LeafShape::Cone(s) => cx.world.spawn((s, path)),
                LeafShape::Torus(s) => cx.world.spawn((s, path)),
                LeafShape::HalfSpace(s) => cx.world.spawn((s, path)),
            }
        }
        other => {
            return cx
                .err(&kat, format!("unknown shape kind `{other}` (expected one of: {}, {})", LEAF_KINDS.join(", "), NODE_KINDS.join(", ")))
        }
    };
    if let Some(n) = name {
        let _ = cx.world.insert_one(e, Name::new(n));
    }
    if let Some(c) = color {
        let _ = cx.world.insert_one(e, Material { color: c });
    }
    Ok(e)
}

fn parse_leaf(cx: &mut Ctx, kind: &str, body: &Value, at: &str) -> R<LeafShape> {
    let m = cx.obj(body, at)?;
    let f = |k: &'static str| Sub(at, k);
    Ok(match kind {
        "sphere" => {
            cx.keys(m, at, &["center", "radius"], &["center", "radius"])?;
            LeafShape::Sphere(Sphere {
                center: cx.vec3(&m["center"], &f("center"))?.as_vec3(),
                radius: cx.num(&m["radius"], &f("radius"))? as f32,
            })
        }
        "box" => {
            cx.keys(m, at, &["min", "max"], &["min", "max"])?;
            LeafShape::Cuboid(Cuboid { min: cx.vec3(&m["min"], &f("min"))?.as_vec3(), max: cx.vec3(&m["max"], &f("max"))?.as_vec3() })
        }
        "cylinder" => {
            cx.keys(m, at, &["a", "b", "radius"], &["a", "b", "radius"])?;
            LeafShape::Cylinder(Cylinder {
                a: cx.vec3(&m["a"], &f("a"))?.as_vec3(),
                b: cx.vec3(&m["b"], &f("b"))?.as_vec3(),
                radius: cx.num(&m["radius"], &f("radius"))? as f32,
            })
        }
        "cone" => {
            cx.keys(m, at, &["a", "b", "radius_a", "radius_b"], &["a", "b", "radius_a", "radius_b"])?;
            LeafShape::Cone(Cone {
                a: cx.vec3(&m["a"], &f("a"))?.as_vec3(),
                b: cx.vec3(&m["b"], &f("b"))?.as_vec3(),
                radius_a: cx.num(&m["radius_a"], &f("radius_a"))? as f32,
                radius_b: cx.num(&m["radius_b"], &f("radius_b"))? as f32,
            })
        }
        "torus" => {
            cx.keys(m, at, &["center", "axis", "major", "minor"], &["center", "axis", "major", "minor"])?;
            LeafShape::Torus(Torus {
                center: cx.vec3(&m["center"], &f("center"))?.as_vec3(),
                axis: cx.vec3(&m["axis"], &f("axis"))?.as_vec3(),
                major: cx.num(&m["major"], &f("major"))? as f32,
                minor: cx.num(&m["minor"], &f("minor"))? as f32,
            })
        }
        "plane" => {
            cx.keys(m, at, &["normal", "offset"], &["normal", "offset"])?;
            LeafShape::HalfSpace(HalfSpace {
                normal: cx.vec3(&m["normal"], &f("normal"))?.as_vec3(),
                offset: cx.num(&m["offset"], &f("offset"))? as f32,
            })
        }
        _ => unreachable!("checked by the caller"),
    })
}

fn parse_points<const N: usize>(cx: &Ctx, v: &Value, at: &str) -> R<Vec<[f32; N]>> {
    let Some(a) = v.as_array() else { return cx.err(at, format!("expected an array of points, got {}", kind_of(v))) };
    let mut out = Vec::with_capacity(a.len());
    for (i, p) in a.iter().enumerate() {
        let pat = format!("{at}[{i}]");
        let Some(q) = p.as_array() else { return cx.err(&pat, format!("expected an array of {N} numbers, got {}", kind_of(p))) };
        if q.len() != N {
            return cx.err(&pat, format!("expected {N} numbers, got {}", q.len()));
        }
        let mut x = [0.0f32; N];
        for k in 0..N {
            x[k] = cx.num(&q[k], &format!("{pat}[{k}]"))? as f32;
        }
        out.push(x);
    }
    Ok(out)
}

fn parse_sweep(cx: &mut Ctx, body: &Value, at: &str) -> R<SweptSphere> {
    let m = cx.obj(body, at)?;
    cx.keys(m, at, &["bezier"], &["bezier"])?;
    let bezier = parse_points::<4>(cx, &m["bezier"], &join(at, "bezier"))?;
    let d = SweptSphere { bezier };
    if let Err(e) = d.validate() {
        return cx.err(&join(at, e.field), e.message);
    }
    // Build once here so that numeric problems are reported with their place.
    if let Err(e) = rothray_primitives::sweep::SweptSphereData::new(&d, rothray_primitives::sweep::DEFAULT_TOLERANCE) {
        return cx.err(&join(at, e.field), e.message);
    }
    Ok(d)
}

fn parse_gcyl(cx: &mut Ctx, body: &Value, at: &str) -> R<GeneralizedCylinder> {
    let m = cx.obj(body, at)?;
    cx.keys(m, at, &["path", "profile", "frame", "normal", "twist_deg"], &["path", "profile"])?;
    let path = parse_points::<3>(cx, &m["path"], &join(at, "path"))?;
    let pat = join(at, "profile");
    let pm = cx.obj(&m["profile"], &pat)?;
    cx.keys(pm, &pat, &["circle", "polygon"], &[])?;
    let profile = match (pm.get("circle"), pm.get("polygon")) {
        (Some(c), None) => Profile::Circle(cx.num(c, &join(&pat, "circle"))? as f32),
        (None, Some(p)) => Profile::Polygon(parse_points::<2>(cx, p, &join(&pat, "polygon"))?),
        _ => return cx.err(&pat, "expected exactly one of `circle` or `polygon`"),
    };
    let frame = match m.get("frame") {
        None => Frame::RotationMinimizing,
        Some(Value::String(f)) if &**f == "rotation_minimizing" => Frame::RotationMinimizing,
        Some(Value::String(f)) if &**f == "frenet" => Frame::Frenet,
        Some(v) => return cx.err(&join(at, "frame"), format!("expected \"frenet\" or \"rotation_minimizing\", got {v}")),
    };
    let normal = match m.get("normal") {
        Some(v) => Some(cx.vec3(v, &join(at, "normal"))?.as_vec3()),
        None => None,
    };
    let twist_deg = match m.get("twist_deg") {
        Some(v) => cx.num(v, &join(at, "twist_deg"))? as f32,
        None => 0.0,
    };
    let d = GeneralizedCylinder { path, profile, frame, normal, twist_deg };
    if let Err(e) = d.validate() {
        return cx.err(&join(at, e.field), e.message);
    }
    if let Err(e) = rothray_primitives::gcyl::GenCylData::new(&d, rothray_primitives::gcyl::DEFAULT_TOLERANCE) {
        return cx.err(&join(at, e.field), e.message);
    }
    Ok(d)
}

fn parse_mesh(cx: &mut Ctx, body: &Value, at: &str) -> R<Arc<MeshData>> {
    let m = cx.obj(body, at)?;
    cx.keys(m, at, &["path", "inside"], &["path"])?;
    let pat = join(at, "path");
    let Some(rel) = m["path"].as_str() else { return cx.err(&pat, "expected a string") };
    let winding = match m.get("inside") {
        None => false,
        Some(Value::String(s)) if &**s == "orientation" => false,
        Some(Value::String(s)) if &**s == "winding" => true,
        Some(v) => return cx.err(&join(at, "inside"), format!("expected \"orientation\" or \"winding\", got {v}")),
    };
    let full = cx.dir.join(rel);
    // Checked here, before anything is opened, so that the message is located.
    let real = match cx.files.resolve(&full) {
        Ok(r) => r,
        Err(e) => return cx.err(&pat, e.to_string()),
    };
    let key = (real, winding);
    if let Some(d) = cx.meshes.get(&key) {
        return Ok(d.clone());
    }
    let rule = if winding { InsideRule::Winding } else { InsideRule::Orientation };
    match crate::mesh::load_mesh_data_in(&full, rule, cx.files) {
        Ok((data, warnings)) => {
            for w in warnings {
                cx.warnings.push(format!("{}: {pat}: {w}", cx.file));
            }
            let d = Arc::new(data);
            cx.meshes.insert(key, d.clone());
            Ok(d)
        }
        Err(e) => cx.err(&pat, e.to_string()),
    }
}
