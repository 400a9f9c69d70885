//! Hostile input (issue 14): files outside the scene's folder, FIFOs, a glTF
//! index that made gltf-json panic, deep nesting, huge polygon faces, unbounded
//! counts. Every case is generated here; each asserts the exit status, a
//! located message, no panic, bounds on CPU time and peak memory with ten
//! times headroom (see `measure`), and, where files are involved, that nothing
//! outside the allowed folders was opened: through the io API's own record
//! always, and through strace where it is installed. The assimp corpus runs
//! through `rothray check` here too.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use crate::bad_input::{rothray, tmpdir};
use crate::measure::{run_measured, run_within_limits, Limits};

// Bounds: ten times what each case measured (CPU time by GNU time, whose
// resolution is 10 ms; peak RSS), on the shared 2-core build machine.

/// A tiny input (a tetrahedron, a refused path, a bad flag): process start, a
/// parse, an error or a 16x12 picture. Measured at most 0.01 s of CPU, 5 MB.
const TINY: Limits = Limits::new(100, 50);
/// 20 000-deep nesting, traced: measured 0.13 s, 38 MB (the old loader aborted
/// under 4 GB).
const DEEP: Limits = Limits::new(1_300, 380);
/// A prism with two 30 000-index caps, checked: measured 0.26 s, 50 MB.
const FACE_30K: Limits = Limits::new(2_600, 500);
/// A 1 000 001-index comb face, checked: measured 1.6 to 2.7 s (the machine's
/// load moves it), 161 MB.
const COMB_1M: Limits = Limits::new(27_000, 1_610);
/// Any one file of the assimp corpus, checked: the costliest
/// (2CylinderEngine.glb) measured 0.25 s, 47 MB.
const CORPUS: Limits = Limits::new(2_500, 470);

/// Runs a command under bounds (see `measure`); its own debug text names it.
trait Bounded {
    fn bounded(&mut self, limits: Limits) -> Output;
}

impl Bounded for Command {
    fn bounded(&mut self, limits: Limits) -> Output {
        let what = format!("{self:?}");
        run_within_limits(std::mem::replace(self, Command::new("true")), limits, &what)
    }
}

const CAM: &str = r#""camera":{"eye":[2,1.5,4],"target":[0.3,0.3,0.3],"up":[0,1,0],"fov_y_deg":40}"#;

/// A tetrahedron with outward faces.
const TET_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

fn mesh_scene(mesh_path: &str) -> String {
    let p = serde_json::to_string(mesh_path).unwrap();
    format!(r#"{{{CAM},"image":{{"width":16,"height":12}},"objects":[{{"name":"m","shape":{{"mesh":{{"path":{p}}}}}}}]}}"#)
}

/// A folder `scene/` holding the scene, and a sibling `outside/` holding a mesh
/// and a glTF buffer that the scene must not read unless allowed.
struct Layout {
    scene_dir: PathBuf,
    outside: PathBuf,
}

fn layout(name: &str) -> Layout {
    let root = tmpdir(&format!("hostile-{name}"));
    let scene_dir = root.join("scene");
    let outside = root.join("outside");
    std::fs::create_dir_all(&scene_dir).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(outside.join("tet.obj"), TET_OBJ).unwrap();
    std::fs::write(outside.join("tet.bin"), tet_bin()).unwrap();
    std::fs::write(scene_dir.join("tet.obj"), TET_OBJ).unwrap();
    Layout { scene_dir: scene_dir.canonicalize().unwrap(), outside: outside.canonicalize().unwrap() }
}

/// Positions (4 x VEC3 f32) then indices (12 x u16) of the tetrahedron.
fn tet_bin() -> Vec<u8> {
    let mut b = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]] {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    for i in [0u16, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

fn tet_gltf(uri: &str, position_accessor: u32) -> String {
    let uri = serde_json::to_string(uri).unwrap();
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"buffers":[{{"uri":{uri},"byteLength":72}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":24}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}},
{{"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":{position_accessor}}},"indices":1}}]}}]}}"#
    )
}

/// The files `args` opens, by strace, or None where strace is not installed
/// (or not permitted).
fn strace_opened(args: &[&std::ffi::OsStr]) -> Option<Vec<String>> {
    let log = std::env::temp_dir().join(format!("rothray-strace-{}-{}", std::process::id(), rand_suffix()));
    let mut cmd = Command::new("strace");
    cmd.args(["-f", "-qq", "-e", "trace=open,openat,openat2,creat", "-o"]).arg(&log).arg(env!("CARGO_BIN_EXE_rothray")).args(args);
    // strace's own cost is not the case's: only the hang guard applies.
    let (out, _) = run_measured(cmd, Duration::from_secs(120));
    let text = std::fs::read_to_string(&log).ok()?;
    let _ = std::fs::remove_file(&log);
    if text.is_empty() && !out.status.success() {
        return None;
    }
    Some(text.lines().filter_map(|l| l.split('"').nth(1).map(str::to_string)).collect())
}

fn rand_suffix() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

fn have_strace() -> bool {
    Command::new("strace").arg("-V").output().map(|o| o.status.success()).unwrap_or(false)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A refused scene: exit 2, located by file and JSON path, says why and how to
/// allow it, never a panic; the io API's record and strace show that nothing
/// under `outside` was opened.
fn assert_refused(l: &Layout, scene: &Path, why: &str) {
    let png = l.scene_dir.join("out.png");
    let mut cmd = rothray();
    cmd.arg("render").arg(scene).arg("-o").arg(&png);
    let out = cmd.bounded(TINY);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{}: {err}", scene.display());
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(&*scene.display().to_string()), "names the scene: {err}");
    assert!(err.contains("objects[0].shape.mesh.path"), "located: {err}");
    assert!(err.contains(why), "says why ({why}): {err}");
    // Never a byte of a file that was not parsed as a mesh.
    assert!(!err.contains("root:"), "quotes /etc/passwd: {err}");
    let (r, opened) = rothray_io::load_scene_recorded(scene, &Default::default());
    assert!(r.is_err());
    assert!(!opened.is_empty(), "the record holds at least the scene");
    assert!(opened.iter().all(|p| p.starts_with(&l.scene_dir)), "opened outside: {opened:?}");
    if let Some(files) = strace_opened(&["render".as_ref(), scene.as_os_str(), "-o".as_ref(), png.as_os_str()]) {
        assert!(files.iter().any(|f| f.ends_with(".json")), "strace saw the scene opened: {files:?}");
        let bad: Vec<_> =
            files.iter().filter(|f| f.contains("/outside/") || f.starts_with("/etc/passwd") || f.starts_with("/dev/zero")).collect();
        assert!(bad.is_empty(), "opened outside the scene's folder: {bad:?}");
    }
}

#[test]
fn meshes_outside_the_scene_folder_are_refused() {
    let l = layout("outside");
    // `..`, an absolute path, and system files.
    let outside_abs = l.outside.join("tet.obj").display().to_string();
    for (name, mesh) in [("dotdot", "../outside/tet.obj"), ("abs", outside_abs.as_str()), ("passwd", "/etc/passwd"), ("zero", "/dev/zero")]
    {
        let f = l.scene_dir.join(format!("{name}.json"));
        std::fs::write(&f, mesh_scene(mesh)).unwrap();
        assert_refused(&l, &f, "outside the allowed folders");
    }
    // A symbolic link in the folder that points outside.
    #[cfg(unix)]
    {
        let link = l.scene_dir.join("link.obj");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(l.outside.join("tet.obj"), &link).unwrap();
        let f = l.scene_dir.join("link.json");
        std::fs::write(&f, mesh_scene("link.obj")).unwrap();
        assert_refused(&l, &f, "outside the allowed folders");
        let err = stderr(&rothray().arg("render").arg(&f).arg("-o").arg(l.scene_dir.join("x.png")).bounded(TINY));
        assert!(err.contains("--allow-path"), "says how to allow it: {err}");
    }
    // The control: the same mesh inside the folder renders.
    let f = l.scene_dir.join("inside.json");
    std::fs::write(&f, mesh_scene("tet.obj")).unwrap();
    let out = rothray().arg("render").arg(&f).arg("-o").arg(l.scene_dir.join("ok.png")).bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn allow_path_admits_an_outside_folder_and_only_it() {
    let l = layout("allow");
    let f = l.scene_dir.join("s.json");
    std::fs::write(&f, mesh_scene("../outside/tet.obj")).unwrap();
    let png = l.scene_dir.join("allowed.png");
    let out = rothray().arg("render").arg(&f).arg("-o").arg(&png).arg("--allow-path").arg(&l.outside).bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(png.exists());
    // The API records the scene and the allowed mesh, and nothing else.
    let opts = rothray_io::LoadOptions { allow_paths: vec![l.outside.clone()] };
    let (r, opened) = rothray_io::load_scene_recorded(&f, &opts);
    assert!(r.is_ok());
    assert_eq!(opened, vec![f.canonicalize().unwrap(), l.outside.join("tet.obj")]);
    // Allowing some other folder does not admit it; trace and bench take the flag too.
    let other = l.scene_dir.join("sub");
    std::fs::create_dir_all(&other).unwrap();
    let rays = l.scene_dir.join("r.csv");
    std::fs::write(&rays, "2,1.5,4,-1.7,-1.2,-3.7\n").unwrap();
    let out = rothray().arg("trace").arg(&f).arg("--rays").arg(&rays).arg("--allow-path").arg(&other).bounded(TINY);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let out = rothray()
        .arg("trace")
        .arg(&f)
        .arg("--rays")
        .arg(&rays)
        .arg("--allow-path")
        .arg(&other)
        .arg("--allow-path")
        .arg(&l.outside)
        .bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).lines().nth(1).unwrap().starts_with("0,1,"), "the ray hits the allowed mesh");
    let out = rothray()
        .arg("bench")
        .arg(&f)
        .args(["--repeats", "1", "--width", "8", "--height", "8", "--allow-path"])
        .arg(&l.outside)
        .bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn gltf_buffers_outside_the_folder_are_refused_even_percent_escaped() {
    let l = layout("gltf");
    std::fs::write(l.scene_dir.join("tet.bin"), tet_bin()).unwrap();
    // The control: a buffer next to the glTF loads.
    std::fs::write(l.scene_dir.join("ok.gltf"), tet_gltf("tet.bin", 0)).unwrap();
    let f = l.scene_dir.join("ok.json");
    std::fs::write(&f, mesh_scene("ok.gltf")).unwrap();
    let out = rothray().arg("render").arg(&f).arg("-o").arg(l.scene_dir.join("ok.png")).bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
    let outside_bin = l.outside.join("tet.bin").display().to_string();
    for (name, uri) in [
        ("dotdot", "../outside/tet.bin".to_string()),
        ("escaped", "..%2Foutside%2Ftet.bin".to_string()),
        ("escaped2", "%2E%2E/outside/tet.bin".to_string()),
        ("abs", outside_bin.clone()),
        ("passwd", "../../../../../../../../etc/passwd".to_string()),
    ] {
        let g = format!("{name}.gltf");
        std::fs::write(l.scene_dir.join(&g), tet_gltf(&uri, 0)).unwrap();
        let f = l.scene_dir.join(format!("{name}.json"));
        std::fs::write(&f, mesh_scene(&g)).unwrap();
        assert_refused(&l, &f, "outside the allowed folders");
        // `check` confines a mesh's buffers to the mesh's folder too.
        let out = rothray().arg("check").arg(l.scene_dir.join(&g)).bounded(TINY);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("buffer 0") && err.contains("--allow-path"), "{err}");
    }
    // Allowed, the escaped one loads.
    let out = rothray().arg("check").arg(l.scene_dir.join("escaped.gltf")).arg("--allow-path").arg(&l.outside).bounded(TINY);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[cfg(unix)]
fn mkfifo(p: &Path) {
    let _ = std::fs::remove_file(p);
    let st = Command::new("mkfifo").arg(p).status().expect("mkfifo");
    assert!(st.success());
}

#[cfg(unix)]
#[test]
fn fifos_are_refused_not_waited_on() {
    let l = layout("fifo");
    let fifo = l.scene_dir.join("pipe.obj");
    mkfifo(&fifo);
    let f = l.scene_dir.join("s.json");
    std::fs::write(&f, mesh_scene("pipe.obj")).unwrap();
    let mut cmd = rothray();
    cmd.arg("render").arg(&f).arg("-o").arg(l.scene_dir.join("x.png"));
    let out = cmd.bounded(TINY);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("objects[0].shape.mesh.path") && err.contains("FIFO") && err.contains("not a regular file"), "{err}");
    // As --rays, as the scene, as `check`'s mesh.
    let rays = l.scene_dir.join("rays.csv");
    mkfifo(&rays);
    std::fs::write(&f, mesh_scene("tet.obj")).unwrap();
    let mut cmd = rothray();
    cmd.arg("trace").arg(&f).arg("--rays").arg(&rays);
    let out = cmd.bounded(TINY);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("rays.csv") && err.contains("FIFO"), "{err}");
    let scene_fifo = l.scene_dir.join("fifo.json");
    mkfifo(&scene_fifo);
    let mut cmd = rothray();
    cmd.arg("render").arg(&scene_fifo).arg("-o").arg(l.scene_dir.join("x.png"));
    let out = cmd.bounded(TINY);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let mut cmd = rothray();
    cmd.arg("check").arg(&fifo);
    let out = cmd.bounded(TINY);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("FIFO"));
}

#[test]
fn a_gltf_accessor_that_does_not_exist_is_an_error_not_a_panic() {
    let l = layout("pos99");
    std::fs::write(l.scene_dir.join("tet.bin"), tet_bin()).unwrap();
    let g = l.scene_dir.join("p99.gltf");
    std::fs::write(&g, tet_gltf("tet.bin", 99)).unwrap();
    let out = rothray().arg("check").arg(&g).bounded(TINY);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(!err.contains("panicked") && !err.contains("crashed"), "{err}");
    assert!(err.contains("p99.gltf") && err.contains("attributes.POSITION") && err.contains("accessor 99"), "{err}");
    let f = l.scene_dir.join("s.json");
    std::fs::write(&f, mesh_scene("p99.gltf")).unwrap();
    let out = rothray().arg("render").arg(&f).arg("-o").arg(l.scene_dir.join("x.png")).bounded(TINY);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(!err.contains("panicked") && !err.contains("crashed"), "{err}");
    assert!(err.contains("objects[0].shape.mesh.path") && err.contains("accessor 99"), "{err}");
    // Indices and morph targets are checked the same way.
    let text = tet_gltf("tet.bin", 0).replace(r#""indices":1"#, r#""indices":1,"targets":[{"POSITION":42}]"#);
    std::fs::write(&g, text).unwrap();
    let err = stderr(&rothray().arg("check").arg(&g).bounded(TINY));
    assert!(err.contains("targets[0].POSITION") && err.contains("accessor 42") && !err.contains("panicked"), "{err}");
}

#[test]
fn deep_nesting_costs_memory_linear_in_depth_and_short_leaf_names() {
    let dir = tmpdir("deep20k");
    // 20 000 levels, alternating kinds, with a sibling leaf at every third
    // level: 6 667 leaves whose full paths average 200 KB. The old loader kept
    // every path and aborted under 4 GB; linear costs need well under 1 GB.
    let depth = 20_000;
    let mut open = String::new();
    let mut closers: Vec<String> = Vec::new();
    for i in 0..depth {
        match i % 3 {
            0 => {
                open.push_str(r#"{"union":["#);
                closers.push("]}".into());
            }
            1 => {
                open.push_str(r#"{"intersection":["#);
                closers.push(format!(r#",{{"sphere":{{"center":[0,0,0],"radius":{}}}}}]}}"#, 2.0 + i as f64 * 1e-4));
            }
            _ => {
                open.push_str(r#"{"transformed":{"translate":[0,0,0],"shape":"#);
                closers.push("}}".into());
            }
        }
    }
    let close: String = closers.iter().rev().map(String::as_str).collect();
    let body = format!(r#"{open}{{"sphere":{{"center":[0,0,0],"radius":1}}}}{close}"#);
    let f = dir.join("deep.json");
    std::fs::write(&f, format!(r#"{{"camera":{{"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":40}},"image":{{"width":8,"height":8}},"objects":[{{"shape":{body}}}]}}"#)).unwrap();
    let rays = dir.join("r.csv");
    std::fs::write(&rays, "0,0,5,0,0,-1\n").unwrap();
    // The old loader aborted under 4 GB here.
    let out = rothray().arg("trace").arg(&f).arg("--rays").arg(&rays).bounded(DEEP);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let hit = text.lines().nth(1).unwrap();
    assert!(hit.starts_with("0,1,4.0,"), "{hit}");
    // The deepest leaf's default name keeps both ends and says how many levels
    // it leaves out, instead of 400 KB of path.
    let leaf = hit.rsplit(',').next().unwrap();
    assert!(leaf.len() < 400, "leaf name of {} chars", leaf.len());
    assert!(leaf.starts_with("objects[0].shape.union[0]") && leaf.ends_with(".sphere") && leaf.contains(" levels>"), "{leaf}");
}

/// A prism whose two caps are faces of `n` indices each.
fn prism_obj(n: usize) -> String {
    let mut s = String::new();
    for z in [0, 1] {
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            s.push_str(&format!("v {:.9} {:.9} {z}\n", a.cos(), a.sin()));
        }
    }
    s.push('f');
    for i in (1..=n).rev() {
        s.push_str(&format!(" {i}"));
    }
    s.push_str("\nf");
    for i in 1..=n {
        s.push_str(&format!(" {}", n + i));
    }
    s.push('\n');
    for i in 0..n {
        let j = (i + 1) % n;
        s.push_str(&format!("f {} {} {} {}\n", i + 1, j + 1, n + j + 1, n + i + 1));
    }
    s
}

#[test]
fn a_30000_index_face_is_triangulated_into_a_closed_solid() {
    let dir = tmpdir("bigface");
    let n = 30_000;
    let p = dir.join("prism.obj");
    std::fs::write(&p, prism_obj(n)).unwrap();
    // The old fan made `check` quadratic (over two minutes).
    let out = rothray().arg("check").arg(&p).arg("--json").bounded(FACE_30K);
    assert!(out.status.success(), "{}", stderr(&out));
    let j: serde_json::Value = serde_json::from_str(String::from_utf8_lossy(&out.stdout).trim()).unwrap();
    assert_eq!(j["triangles"], 2 * (n - 2) + 2 * n, "{j}");
    assert_eq!(j["closed"], true, "{j}");
    assert_eq!(j["consistently_oriented"], true, "{j}");
    assert_eq!(j["self_intersections"], 0, "{j}");
    let vol = j["volume"].as_f64().unwrap();
    assert!((vol - std::f64::consts::PI).abs() < 1e-3, "volume {vol}");
}

/// The comb face of [`crate::comb_face::comb_obj`] as an OBJ file's text.
fn comb_face_obj(teeth: usize, seed: u64) -> String {
    let (v, face, _) = crate::comb_face::comb_obj(teeth, seed);
    let f: String = face.iter().map(|k| format!(" {k}")).collect();
    format!("{v}f{f}\n")
}

/// The issue's 1 000 000-index face, as a comb (333 333 merge vertices, no
/// fan or halving valid): triangulated by the sweep without a warning, then
/// refused as a solid (one face encloses nothing), within bounds; the old
/// ear clipping was quadratic and ran past a minute.
#[test]
fn a_million_index_comb_face_is_triangulated_within_bounds() {
    let seed = 0x5eed_0018;
    println!("seed {seed:#x}");
    let dir = tmpdir("comb1m");
    let p = dir.join("comb.obj");
    std::fs::write(&p, comb_face_obj(333_333, seed)).unwrap();
    let out = rothray().arg("check").arg(&p).bounded(COMB_1M);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("comb.obj") && err.contains("encloses no volume"), "{err}");
    assert!(!err.contains("warning") && !err.contains("panicked"), "{err}");
}

/// Every OBJ / glTF / GLB of the assimp corpus through `rothray check`: exit 0,
/// or 2 with a message naming the file; no panic; nothing opened outside the
/// file's folder (the io API's record); each within bounds.
#[test]
fn the_assimp_corpus_is_checked_within_bounds() {
    let Some((root, files)) = crate::assimp_corpus::assimp_mesh_files() else {
        println!("SKIPPED: assimp-testmodels not installed (apt-get install assimp-testmodels)");
        return;
    };
    let (mut ok, mut refused) = (0, 0);
    for f in &files {
        let out = rothray().arg("check").arg(f).bounded(CORPUS);
        let err = stderr(&out);
        assert!(!err.contains("panicked") && !err.contains("crashed"), "{}: {err}", f.display());
        match out.status.code() {
            Some(0) => ok += 1,
            Some(2) => {
                assert!(err.contains(&*f.display().to_string()), "not located: {err}");
                refused += 1;
            }
            c => panic!("{}: exit {c:?}: {err}", f.display()),
        }
        let folder = f.parent().unwrap().canonicalize().unwrap();
        if let Ok((real, files)) = rothray_io::user_mesh(f, &Default::default()) {
            let _ = rothray_io::load_mesh_in(&real, &files);
            let opened = files.opened();
            assert!(opened.iter().all(|p| p.starts_with(&folder)), "{}: opened {opened:?}", f.display());
        }
    }
    println!("{} files under {}: {ok} checked, {refused} refused with a located error", files.len(), root.display());
    assert!(ok + refused == files.len() && ok > 10);
}

#[test]
fn obj_faces_with_fewer_than_three_vertices_are_warned_with_their_line() {
    let dir = tmpdir("shortface");
    let p = dir.join("short.obj");
    std::fs::write(&p, format!("{TET_OBJ}f 1 2\nf 3\n")).unwrap();
    let out = rothray().arg("check").arg(&p).bounded(TINY);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning") && err.contains("line 9, 10") && err.contains("fewer than 3 vertices"), "{err}");
}

#[test]
fn command_line_counts_are_bounded() {
    let dir = tmpdir("bounds");
    let f = dir.join("s.json");
    std::fs::write(&f, format!(r#"{{{CAM},"objects":[]}}"#)).unwrap();
    let png = dir.join("x.png");
    let cases: &[(&[&str], &str)] = &[
        (&["bench", "S", "--repeats", "1000000000"], "--repeats"),
        (&["bench", "S", "--repeats", "0"], "--repeats"),
        (&["render", "S", "-o", "P", "--spp", "100000"], "--spp"),
        (&["render", "S", "-o", "P", "--width", "100000"], "--width"),
        (&["render", "S", "-o", "P", "--width", "65536", "--height", "65536"], "2^28"),
        (&["render", "S", "-o", "P", "--width", "8192", "--height", "8192", "--spp", "1024"], "2^32"),
    ];
    for (args, want) in cases {
        let mut cmd = rothray();
        for a in *args {
            match *a {
                "S" => cmd.arg(&f),
                "P" => cmd.arg(&png),
                a => cmd.arg(a),
            };
        }
        let out = cmd.bounded(TINY);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

#[test]
fn a_file_that_is_not_a_mesh_is_not_opened() {
    let l = layout("notmesh");
    std::fs::write(l.scene_dir.join("secret.txt"), "root:x:0:0\n").unwrap();
    let f = l.scene_dir.join("s.json");
    std::fs::write(&f, mesh_scene("secret.txt")).unwrap();
    let (r, opened) = rothray_io::load_scene_recorded(&f, &Default::default());
    let e = r.err().unwrap().to_string();
    assert!(e.contains("unknown mesh format") && !e.contains("root:"), "{e}");
    assert_eq!(opened, vec![f.canonicalize().unwrap()], "only the scene was opened");
    if have_strace() {
        let files = strace_opened(&["check".as_ref(), l.scene_dir.join("secret.txt").as_os_str()]).unwrap();
        assert!(!files.iter().any(|f| f.ends_with("secret.txt")), "{files:?}");
    }
}
