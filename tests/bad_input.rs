//! Every error of the contract's list: a located message (file and JSON path)
//! and exit status 2, never a panic. Plus the odd-but-valid inputs that must
//! work: an empty scene, 10 000 nested nodes, a difference of one child.

use std::process::Command;

pub fn rothray() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rothray"))
}

pub fn tmpdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("rothray-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

const CAM: &str = r#""camera":{"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":40}"#;

pub fn scene_with(shape: &str) -> String {
    format!(
        r#"{{{CAM},"image":{{"width":32,"height":24}},"objects":[{{"name":"a","shape":{{"union":[{{"sphere":{{"center":[0,0,0],"radius":1}}}},{shape}]}}}}]}}"#
    )
}

pub fn expect_error(json: &str, must_contain: &[&str]) {
    let dir = tmpdir("bad");
    // A mesh that encloses no volume (one flat triangle), next to the scene.
    std::fs::write(dir.join("flat.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let f = dir.join(format!("s{}.json", json.len() ^ (json.as_bytes().iter().map(|&b| b as usize).sum::<usize>() << 8)));
    std::fs::write(&f, json).unwrap();
    let out = rothray().args(["render"]).arg(&f).args(["-o"]).arg(dir.join("x.png")).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "want exit 2 for {json}\nstderr: {err}");
    assert!(!err.contains("panicked"), "panic for {json}: {err}");
    assert!(err.contains(&*f.display().to_string()), "error does not name the file: {err}");
    for m in must_contain {
        assert!(err.contains(m), "error for {json} lacks `{m}`: {err}");
    }
}

#[test]
fn contract_errors_are_located_with_exit_2() {
    let cases: &[(&str, &[&str])] = &[
        (r#"{"sphere":{"center":[0,0,0],"radius":-1}}"#, &["objects[0].shape.union[1].sphere.radius"]),
        (r#"{"sphere":{"center":[0,0,0],"radius":0}}"#, &["objects[0].shape.union[1].sphere.radius"]),
        (r#"{"sphere":{"center":[0,0,0],"radius":1,"extra":2}}"#, &["objects[0].shape.union[1].sphere.extra", "unknown key"]),
        (r#"{"sphere":{"center":[0,0,0]}}"#, &["objects[0].shape.union[1].sphere", "missing field `radius`"]),
        (r#"{"spheer":{"center":[0,0,0],"radius":1}}"#, &["objects[0].shape.union[1].spheer", "unknown shape kind"]),
        (r#"{"box":{"min":[0,0,0],"max":[1,-1,1]}}"#, &["objects[0].shape.union[1].box.min", "above"]),
        (r#"{"torus":{"center":[0,0,0],"axis":[0,0,0],"major":1,"minor":0.2}}"#, &["objects[0].shape.union[1].torus.axis"]),
        (r#"{"plane":{"normal":[0,0,0],"offset":1}}"#, &["objects[0].shape.union[1].plane.normal"]),
        (r#"{"cylinder":{"a":[0,0,0],"b":[0,0,0],"radius":1}}"#, &["objects[0].shape.union[1].cylinder.b"]),
        (r#"{"cone":{"a":[0,0,0],"b":[0,1,0],"radius_a":-1,"radius_b":0}}"#, &["objects[0].shape.union[1].cone.radius_a"]),
        (r#"{"sphere":{"center":[0,1e39,0],"radius":1}}"#, &["objects[0].shape.union[1].sphere.center[1]", "not finite"]),
        (r#"{"sphere":{"center":[0,"x",0],"radius":1}}"#, &["objects[0].shape.union[1].sphere.center[1]"]),
        (
            r#"{"transformed":{"matrix":[1,0,0,0, 0,1,0,0, 0,0,0,0, 0,0,0,1],"shape":{"sphere":{"center":[0,0,0],"radius":1}}}}"#,
            &["objects[0].shape.union[1].transformed.matrix", "singular"],
        ),
        (
            r#"{"transformed":{"scale":[1,0,1],"shape":{"sphere":{"center":[0,0,0],"radius":1}}}}"#,
            &["objects[0].shape.union[1].transformed.scale"],
        ),
        (r#"{"union":[]}"#, &["objects[0].shape.union[1].union"]),
        (r#"{"sphere":{"center":[0,0,0],"radius":1},"name":"a"}"#, &["objects[0].shape.union[1].name", "twice"]),
        (
            r#"{"swept_sphere":{"bezier":[[0,0,0,1],[1,0,0,1],[2,0,0,1],[3,0,0,1],[4,0,0,1]]}}"#,
            &["objects[0].shape.union[1].swept_sphere.bezier", "3n+1"],
        ),
        (
            r#"{"swept_sphere":{"bezier":[[0,0,0,-1],[1,0,0,1],[2,0,0,1],[3,0,0,1]]}}"#,
            &["objects[0].shape.union[1].swept_sphere.bezier", "negative"],
        ),
        (
            r#"{"generalized_cylinder":{"path":[[0,0,0],[1,0,0],[2,1,0],[3,0,0]],"profile":{"polygon":[[0,0],[1,1],[1,0],[0,1]]}}}"#,
            &["objects[0].shape.union[1].generalized_cylinder.profile", "self-intersecting"],
        ),
        (
            r#"{"generalized_cylinder":{"path":[[0,0,0],[1,0,0],[2,1,0]],"profile":{"circle":0.2}}}"#,
            &["objects[0].shape.union[1].generalized_cylinder.path"],
        ),
        (
            r#"{"generalized_cylinder":{"path":[[0,0,0],[1,0,0],[2,1,0],[3,0,0]],"profile":{"circle":0.2},"frame":"bogus"}}"#,
            &["objects[0].shape.union[1].generalized_cylinder.frame"],
        ),
        (r#"{"mesh":{"path":"no-such-mesh.obj"}}"#, &["objects[0].shape.union[1].mesh.path", "no-such-mesh.obj"]),
        (r#"{"mesh":{"path":"flat.obj"}}"#, &["objects[0].shape.union[1].mesh.path", "no volume"]),
        (r#"{"mesh":{"path":"flat.obj","inside":"sometimes"}}"#, &["objects[0].shape.union[1].mesh.inside"]),
    ];
    for (shape, want) in cases {
        expect_error(&scene_with(shape), want);
    }
    // Not JSON at all: line and column.
    expect_error("{\"camera\": [1,2,", &["invalid JSON", ":1:"]);
    expect_error(
        &format!("{{{CAM},\"objects\":[{{\"shape\":{{\"sphere\":{{\"center\":[0,0,0],\"radius\":1}}}}}}],\"bogus\":1}}"),
        &["bogus", "unknown key"],
    );
    expect_error(r#"{"objects":[]}"#, &["missing field `camera`"]);
    expect_error(&format!("{{{},\"objects\":[]}}", CAM.replace("40", "0")), &["camera.fov_y_deg"]);
    // Unreadable file.
    let out = rothray().args(["render", "/nonexistent/scene.json", "-o", "/tmp/x.png"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/scene.json"));
}

#[test]
fn odd_but_valid_scenes_render() {
    let dir = tmpdir("odd");
    // Empty scene: a background-only image.
    let f = dir.join("empty.json");
    std::fs::write(&f, format!(r#"{{{CAM},"image":{{"width":16,"height":8}},"background":[0.2,0.4,0.6],"objects":[]}}"#)).unwrap();
    let png = dir.join("empty.png");
    let out = rothray().arg("render").arg(&f).arg("-o").arg(&png).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(png.exists());
    // A difference of one child is that child.
    let f = dir.join("diff1.json");
    std::fs::write(&f, scene_with(r#"{"difference":[{"box":{"min":[-2,-2,-2],"max":[-1.5,-1.5,-1.5]}}]}"#)).unwrap();
    let out = rothray().arg("render").arg(&f).arg("-o").arg(dir.join("d.png")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // 10 000 nested nodes, alternating kinds so nothing flattens away.
    let mut s = String::from(r#"{"sphere":{"center":[0,0,0],"radius":1}}"#);
    for i in 0..10_000 {
        s = match i % 3 {
            0 => format!(r#"{{"union":[{s}]}}"#),
            1 => format!(r#"{{"intersection":[{s},{{"sphere":{{"center":[0,0,0],"radius":{}}}}}]}}"#, 2.0 + i as f64 * 1e-4),
            _ => format!(r#"{{"transformed":{{"translate":[0,0,0],"shape":{s}}}}}"#),
        };
    }
    let f = dir.join("deep.json");
    std::fs::write(&f, format!(r#"{{{CAM},"image":{{"width":24,"height":16}},"objects":[{{"shape":{s}}}]}}"#)).unwrap();
    let rays = dir.join("deep.csv");
    std::fs::write(&rays, "0,0,5,0,0,-1\n").unwrap();
    let out = rothray().arg("trace").arg(&f).arg("--rays").arg(&rays).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().nth(1).unwrap().starts_with("0,1,4.0,"), "{text}");
}

#[test]
fn bad_rays_are_reported_and_skipped() {
    let dir = tmpdir("rays");
    let f = dir.join("s.json");
    std::fs::write(&f, scene_with(r#"{"box":{"min":[2,2,2],"max":[3,3,3]}}"#)).unwrap();
    let rays = dir.join("r.csv");
    std::fs::write(&rays, "ox,oy,oz,dx,dy,dz\n0,0,5,0,0,-1\n0,0,5,0,0,0\n0,0,5,NaN,0,-1\n0,0,5,0,0,inf\n1,2\n0,0,5,0,0,-2\n").unwrap();
    let out = rothray().arg("trace").arg(&f).arg("--rays").arg(&rays).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "ray,hit,t,nx,ny,nz,object,leaf");
    assert!(lines[1].starts_with("0,1,4.0,0.0,0.0,1.0,a,"), "{text}");
    assert!(lines[2].starts_with("5,1,2.0,"), "t in units of the direction: {text}");
    assert_eq!(lines.len(), 3, "{text}");
    for k in 1..=4 {
        assert!(err.contains(&format!("ray {k}:")), "no error line for ray {k}: {err}");
    }
    assert!(err.contains("r.csv:3"), "error lines name the file and line: {err}");
}

/// A `matrix` is singular relative to its own size: a sheared matrix of a
/// solid 1e-6 across (determinant 1e-18) loads, one whose third column is
/// the first plus 1e-13 of another (determinant 1e-13 of its columns'
/// lengths) is refused, at any scale.
#[test]
fn matrix_singularity_is_relative_to_its_size() {
    let small =
        r#"{"transformed":{"matrix":[1e-6,5e-7,0,0, 0,1e-6,0,0, 0,0,1e-6,0, 0,0,0,1],"shape":{"sphere":{"center":[0,0,0],"radius":1}}}}"#;
    let dir = tmpdir("tiny-matrix");
    let f = dir.join("s.json");
    std::fs::write(&f, scene_with(small)).unwrap();
    let out = rothray().args(["render"]).arg(&f).args(["-o"]).arg(dir.join("x.png")).output().unwrap();
    assert!(out.status.success(), "a matrix 1e-6 across is not singular: {}", String::from_utf8_lossy(&out.stderr));
    for (s, tiny) in [("1", "1e-13"), ("1e6", "1e-7")] {
        let flat = format!(
            r#"{{"transformed":{{"matrix":[{s},0,{s},0, 0,{s},0,0, 0,0,{tiny},0, 0,0,0,1],"shape":{{"sphere":{{"center":[0,0,0],"radius":1}}}}}}}}"#
        );
        expect_error(&scene_with(&flat), &["objects[0].shape.union[1].transformed.matrix", "singular", "1e-12"]);
    }
}
