use super::*;
use crate::comb_face::comb_obj;
use std::path::PathBuf;

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rothray-mesh-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &Path, name: &str, data: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, data).unwrap();
    p
}

/// Cube [-1,1]^3 as OBJ: two objects, quads, normals and texture coordinates on
/// some faces (so tobj splits vertices), negative (relative) indices on others.
const CUBE_OBJ: &str = "# cube
mtllib missing.mtl
v -1 -1 -1
v 1 -1 -1
v -1 1 -1
v 1 1 -1
v -1 -1 1
v 1 -1 1
v -1 1 1
v 1 1 1
vt 0 0
vt 1 0
vn 0 0 -1
o first
g a
f 1/1/1 3/2/1 4/1/1 2/2/1
f 1 2 6 5
o second
f -8 -4 -2 -6
f 3 7 8 4
f -4 -3 -1 -2
f 2 4 8 6
";

#[test]
fn mesh_obj_cube() {
    let d = scratch("obj");
    let p = write(&d, "cube.obj", CUBE_OBJ);
    let (pos, tris, warnings) = load_mesh(&p).unwrap();
    assert_eq!(tris.len(), 12);
    assert!(warnings.is_empty(), "{warnings:?}");
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let r = m.report();
    println!("{r:?}");
    assert_eq!((r.vertices, r.boundary_edges, r.closed, r.consistently_oriented), (8, 0, true, true));
    assert!((r.volume - 8.0).abs() < 1e-9);
    assert!(m.contains(Vec3::ZERO));
}

#[test]
fn mesh_obj_errors_name_the_line() {
    let d = scratch("objbad");
    let cases: &[(&str, &str, &str)] = &[
        ("num.obj", "v 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n", "line 2"),
        ("idx.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 1 2 9\n", "line 6"),
        ("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4"),
        ("neg.obj", "v 0 0 0\nf -1 -2 -3\nv 1 0 0\nv 0 1 0\n", "line 2"),
        ("face.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "line 4"),
        ("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n", "line 3"),
        ("inf.obj", "v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n", "line 3"),
        ("utf.obj", "v 0 0 0\nv 1 0 0\n\u{0}\u{1}\nv 0 1 0\n", ""),
        ("empty.obj", "# nothing\nv 0 0 0\n", "no triangles"),
    ];
    for (name, text, want) in cases {
        let p = write(&d, name, text);
        let e = load_mesh(&p).unwrap_err().to_string();
        println!("{name}: {e}");
        assert!(e.contains(name), "{e}");
        assert!(e.contains(want), "{name}: {e}");
    }
    let p = write(&d, "bad.obj", b"v 0 0 0\n\xff\xfe\n");
    let e = load_mesh(&p).unwrap_err().to_string();
    assert!(e.contains("line 2") && e.contains("UTF-8"), "{e}");
    // points and lines are skipped with a warning
    let p = write(&d, "pl.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\np 1\nl 1 2\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
    let (_, tris, w) = load_mesh(&p).unwrap();
    assert_eq!(tris.len(), 4);
    assert!(w[0].contains("skipped 1 point and 1 line"), "{w:?}");
    let e = load_mesh(&d.join("nope.obj")).unwrap_err().to_string();
    assert!(e.contains("nope.obj") && e.contains("cannot read"), "{e}");
    let e = load_mesh(&write(&d, "x.stl", "solid")).unwrap_err().to_string();
    assert!(e.contains("unknown mesh format"), "{e}");
}

/// Binary buffer of the cube: 8 positions (f32) then 36 u16 indices.
fn cube_bin() -> (Vec<u8>, usize, usize) {
    let mut b = vec![];
    for i in 0..8 {
        for a in 0..3 {
            let v: f32 = if i & (1 << a) != 0 { 1.0 } else { -1.0 };
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    let quads = [[0u16, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    let pos_len = b.len();
    for q in quads {
        for k in [q[0], q[1], q[2], q[0], q[2], q[3]] {
            b.extend_from_slice(&k.to_le_bytes());
        }
    }
    let idx_len = b.len() - pos_len;
    (b, pos_len, idx_len)
}

/// glTF JSON for the cube; `uri` None = GLB BIN chunk. Node 0 places the mesh
/// with `scale`; node 1 (its child) mirrors a second copy at x + 10.
fn cube_json(uri: Option<&str>, byte_len: usize, pos_len: usize, idx_len: usize, extra: &str) -> String {
    let buffer = match uri {
        Some(u) => format!(r#"{{"byteLength": {byte_len}, "uri": "{u}"}}"#),
        None => format!(r#"{{"byteLength": {byte_len}}}"#),
    };
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
 "nodes": [{{"mesh": 0, "scale": [2, 2, 2], "children": [1]}}, {{"mesh": 0, "translation": [10, 0, 0], "scale": [-1, 1, 1]}}],
 "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
 "buffers": [{buffer}],
 "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": {pos_len}}}, {{"buffer": 0, "byteOffset": {pos_len}, "byteLength": {idx_len}}}],
 "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3", "min": [-1,-1,-1], "max": [1,1,1]}},
               {{"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}}]{extra}}}"#
    )
}

fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = vec![];
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// Both cube instances: the scaled one (volume 64) and the mirrored child, which
/// inherits the scale (volume 64) and must stay outward (a mirror flips the winding).
fn check_two_cubes(p: &Path) {
    let (pos, tris, w) = load_mesh(p).unwrap();
    assert!(w.is_empty(), "{w:?}");
    assert_eq!(tris.len(), 24);
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let r = m.report();
    assert!(r.closed && r.consistently_oriented && r.warnings.is_empty(), "{r:?}");
    assert!((r.volume - 128.0).abs() < 1e-6, "{r:?}");
    // child at parent * (translate 10, mirror x): centre at x = 20, half size 2
    assert!(m.contains(Vec3::new(20.0, 0.0, 0.0)) && m.contains(Vec3::new(0.0, 1.9, 0.0)));
    assert!(!m.contains(Vec3::new(10.0, 0.0, 0.0)));
    assert_eq!(r.bounds.max, Vec3::new(22.0, 2.0, 2.0));
}

#[test]
fn mesh_gltf_embedded_external_and_glb() {
    let d = scratch("gltf");
    let (bin, pl, il) = cube_bin();
    let uri = format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    check_two_cubes(&write(&d, "embedded.gltf", cube_json(Some(&uri), bin.len(), pl, il, "")));
    write(&d, "cube data.bin", &bin);
    check_two_cubes(&write(&d, "external.gltf", cube_json(Some("cube%20data.bin"), bin.len(), pl, il, "")));
    check_two_cubes(&write(&d, "binary.glb", glb(&cube_json(None, bin.len(), pl, il, ""), &bin)));
}

#[test]
fn mesh_gltf_strip_fan_and_skipped_modes() {
    let d = scratch("modes");
    // A square pyramid: base as a strip (2 triangles), sides as a fan around the apex.
    let pts: [[f32; 3]; 6] = [[-1., -1., 0.], [-1., 1., 0.], [1., -1., 0.], [1., 1., 0.], [0., 0., 1.], [0., 0., 0.]];
    let mut b = vec![];
    for p in pts {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    // strip 0,1,2,3 (base, facing -z); fan apex 4, then around 0,2,3,1,0 (sides outward)
    let strip = [0u8, 1, 2, 3];
    let fan = [4u8, 0, 2, 3, 1, 0];
    let pos_len = b.len();
    b.extend_from_slice(&strip);
    b.extend_from_slice(&fan);
    let uri = format!("data:application/gltf-buffer;base64,{}", base64::engine::general_purpose::STANDARD.encode(&b));
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}},
 "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "mode": 5}},
                             {{"attributes": {{"POSITION": 0}}, "indices": 2, "mode": 6}},
                             {{"attributes": {{"POSITION": 0}}, "mode": 1}}]}}],
 "nodes": [{{"mesh": 0}}],
 "buffers": [{{"byteLength": {}, "uri": "{uri}"}}],
 "bufferViews": [{{"buffer": 0, "byteLength": {pos_len}}}, {{"buffer": 0, "byteOffset": {pos_len}, "byteLength": 10}}],
 "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 6, "type": "VEC3", "min": [-1,-1,0], "max": [1,1,1]}},
               {{"bufferView": 1, "componentType": 5121, "count": 4, "type": "SCALAR"}},
               {{"bufferView": 1, "byteOffset": 4, "componentType": 5121, "count": 6, "type": "SCALAR"}}]}}"#,
        b.len()
    );
    let (pos, tris, w) = load_mesh(&write(&d, "pyramid.gltf", json)).unwrap();
    assert_eq!(tris.len(), 2 + 4);
    assert!(w.len() == 1 && w[0].contains("Lines"), "{w:?}");
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let r = m.report();
    assert!(r.closed && r.consistently_oriented, "{r:?}");
    assert!((r.volume - 4.0 / 3.0).abs() < 1e-6, "{r:?}");
}

#[test]
fn mesh_gltf_errors() {
    let d = scratch("gltfbad");
    let (bin, pl, il) = cube_bin();
    let enc = |b: &[u8]| format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(b));
    let uri = enc(&bin);
    let ok = cube_json(Some(&uri), bin.len(), pl, il, "");
    let mut cases: Vec<(&str, String, &str)> = vec![];
    // accessor count far beyond the view: must fail before allocating
    cases.push(("count.gltf", ok.replace(r#""count": 8"#, r#""count": 4000000000"#), "do not fit in bufferView"));
    cases.push(("type.gltf", ok.replace(r#""componentType": 5126"#, r#""componentType": 5123"#), "POSITION must be VEC3 of FLOAT"));
    cases.push((
        "itype.gltf",
        ok.replace(r#""componentType": 5123, "count": 36"#, r#""componentType": 5126, "count": 18"#),
        "indices must be SCALAR",
    ));
    cases.push(("missing.gltf", cube_json(Some("gone.bin"), bin.len(), pl, il, ""), "missing buffer data"));
    cases.push(("short.gltf", cube_json(Some(&enc(&bin[..40])), bin.len(), pl, il, ""), "declared"));
    cases.push(("b64.gltf", cube_json(Some("data:application/octet-stream;base64,@@@@"), bin.len(), pl, il, ""), "base64"));
    cases.push(("http.gltf", cube_json(Some("http://example.invalid/x.bin"), bin.len(), pl, il, ""), "unsupported"));
    cases.push((
        "draco.gltf",
        cube_json(
            Some(&uri),
            bin.len(),
            pl,
            il,
            r#", "extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"]"#,
        ),
        "KHR_draco_mesh_compression",
    ));
    cases.push(("json.gltf", ok[..ok.len() / 2].to_string(), "JSON"));
    cases.push(("view.gltf", ok.replace(&format!(r#""byteLength": {pl}}}"#), &format!(r#""byteLength": {}}}"#, pl + 4000)), "bufferView"));
    cases.push(("ref.gltf", ok.replace(r#""indices": 1"#, r#""indices": 7"#), "JSON"));
    cases.push(("cycle.gltf", ok.replace(r#""translation": [10, 0, 0]"#, r#""children": [0], "translation": [10, 0, 0]"#), "node"));
    // index out of range, NaN position
    let mut b2 = bin.clone();
    b2[pl..pl + 2].copy_from_slice(&9u16.to_le_bytes());
    cases.push(("index.gltf", cube_json(Some(&enc(&b2)), bin.len(), pl, il, ""), "vertex index 9 out of range"));
    let mut b3 = bin.clone();
    b3[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    cases.push(("nan.gltf", cube_json(Some(&enc(&b3)), bin.len(), pl, il, ""), "NaN"));
    for (name, text, want) in &cases {
        let p = write(&d, name, text);
        let e = load_mesh(&p).unwrap_err().to_string();
        println!("{name}: {e}");
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    // GLB without a BIN chunk, truncated GLB
    let g = glb(&cube_json(None, bin.len(), pl, il, ""), &bin);
    let mut nobin = g[..12 + 8].to_vec();
    let jl = u32::from_le_bytes(g[12..16].try_into().unwrap()) as usize;
    nobin.extend_from_slice(&g[20..20 + jl]);
    let total = nobin.len() as u32;
    nobin[8..12].copy_from_slice(&total.to_le_bytes());
    for (name, data, want) in [("nobin.glb", nobin, "BIN"), ("trunc.glb", g[..g.len() - 9].to_vec(), "GLB")] {
        let e = load_mesh(&write(&d, name, data)).unwrap_err().to_string();
        println!("{name}: {e}");
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
}

fn bunny_path() -> PathBuf {
    let shared = PathBuf::from("/work/shared/scenes/bunny.obj");
    if shared.exists() {
        shared
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/bunny.obj")
    }
}

#[test]
fn mesh_bunny_report() {
    let p = bunny_path();
    let (pos, tris, w) = load_mesh(&p).unwrap();
    println!("{}: {} positions, {} triangles, loader warnings {w:?}", p.display(), pos.len(), tris.len());
    assert_eq!((pos.len(), tris.len()), (1839, 3674));
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let r = m.report();
    println!("{r:#?}");
    assert_eq!(r.triangles, 3674);
    // Pinned: the shared bunny is a closed, consistently oriented 2-manifold.
    assert!(r.closed && r.consistently_oriented && r.usable_as_solid && r.warnings.is_empty());
    assert_eq!((r.boundary_edges, r.non_manifold_edges, r.self_intersections), (0, 0, Some(0)));
    assert!((r.volume - 194.288).abs() < 0.01, "{}", r.volume);
    assert!(m.contains(r.bounds.center()) || !m.contains(r.bounds.max + Vec3::ONE));
}

/// Every OBJ / glTF / GLB of Debian's assimp-testmodels goes through load_mesh and
/// MeshData::new without a panic (errors are fine).
#[test]
fn mesh_assimp_testmodels_do_not_panic() {
    let Some((root, files)) = crate::assimp_corpus::assimp_mesh_files() else {
        println!("SKIPPED: assimp-testmodels not installed (apt-get install assimp-testmodels)");
        return;
    };
    let (mut loaded, mut solid, mut failed, mut panicked) = (0, 0, 0, vec![]);
    for f in &files {
        let r = std::panic::catch_unwind(|| match load_mesh(f) {
            Ok((pos, tris, _)) => match MeshData::new(pos, tris, InsideRule::Orientation) {
                Ok(m) => (1, m.report().usable_as_solid as usize, String::new()),
                Err(e) => (1, 0, e.to_string()),
            },
            Err(e) => (0, 0, e.to_string()),
        });
        match r {
            Ok((l, s, e)) => {
                loaded += l;
                solid += s;
                if !e.is_empty() {
                    failed += 1;
                    println!("error (fine): {e}");
                }
            }
            Err(_) => panicked.push(f.clone()),
        }
    }
    println!(
        "{} files under {}: {loaded} loaded, {solid} closed solids, {failed} errors, {} panics",
        files.len(),
        root.display(),
        panicked.len()
    );
    assert!(panicked.is_empty(), "panicked on {panicked:?}");
}

/// A 1 000 001-index comb face through the OBJ loader: n - 2 triangles, none
/// turned over, of the face's shoelace area, and no warning (the sweep took it;
/// the old loader halved it across the gaps, with a warning). A smaller comb
/// prism is a closed solid of the right volume.
#[test]
fn mesh_obj_million_index_comb_face() {
    let seed = 0x5eed_0017;
    println!("seed {seed:#x}");
    let d = scratch("comb");
    let (v, face, area) = comb_obj(333_333, seed);
    let f: String = face.iter().map(|k| format!(" {k}")).collect();
    let p = write(&d, "comb.obj", format!("{v}f{f}\n"));
    let (pos, tris, warnings) = load_mesh(&p).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(tris.len(), face.len() - 2);
    let area2 = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|k| pos[k as usize].as_dvec3());
        (b - a).cross(c - a).z
    };
    assert!(tris.iter().all(|t| area2(t) >= 0.0), "a triangle is turned over");
    assert_eq!(tris.iter().map(area2).sum::<f64>() * 0.5, area, "integer coordinates: exact");

    let (v, face, area) = comb_obj(3_000, seed);
    let n = face.len();
    let mut s = v.clone();
    s.extend(v.lines().map(|l| format!("{}1\n", l.strip_suffix('0').unwrap())));
    s.push('f');
    s.extend(face.iter().rev().map(|k| format!(" {k}")));
    s.push_str("\nf");
    s.extend(face.iter().map(|k| format!(" {}", k + n)));
    s.push('\n');
    for i in 1..=n {
        let j = i % n + 1;
        s.push_str(&format!("f {i} {j} {} {}\n", j + n, i + n));
    }
    let p = write(&d, "prism.obj", s);
    let (pos, tris, warnings) = load_mesh(&p).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let r = MeshData::new(pos, tris, InsideRule::Orientation).unwrap().report();
    assert!(r.closed && r.consistently_oriented && r.usable_as_solid, "{r:?}");
    assert_eq!(r.self_intersections, Some(0));
    assert!((r.volume - area).abs() < 1e-9 * area, "volume {} vs {area}", r.volume);
}

/// A face that crosses itself (a bow tie) and one that touches itself (a
/// pinch) are halved, warned with their lines; a face of 1 or 2 vertices is
/// skipped, warned with its line.
#[test]
fn mesh_obj_faces_that_are_not_simple_or_too_short_are_warned_with_their_line() {
    let d = scratch("notsimple");
    let text = "v 0 0 0\nv 1 1 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 2 2 0\nv 0.5 0.5 0\n\
f 1 2 3 4\nf 1 3 5 6 7 2 4\nf 1 3\nf 1 2 3\n";
    let p = write(&d, "bad.obj", text);
    let (_, tris, warnings) = load_mesh(&p).unwrap();
    assert_eq!(tris.len(), 2 + 5 + 1, "every face of 3 or more vertices gives n - 2 triangles");
    let w = warnings.join("\n");
    assert!(w.contains("line 8 (4 vertices), line 9 (7 vertices)"), "{w}");
    assert!(w.contains("not simple"), "{w}");
    assert!(w.contains("line 10") && w.contains("fewer than 3 vertices"), "{w}");
}
