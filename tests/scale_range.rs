//! The range limits of issue 15 against the f64 model (`oracle.rs`, through
//! `stress.rs`'s measure: both sides read the same f32-rounded scene and
//! rays): direction lengths over the whole f32 range, solids from 1e-20 to
//! 1e20 across, ray origins 1e20 away. Every kind of `stress::solids` and
//! their CSG; errors relative to the view distance, as in the stress table.
//!
//! `cargo test --release --test integration scale_range -- --nocapture`
//! prints every row.

use glam::DVec3;

use crate::stress::{measure, rv, solids, Case};

/// Measures every solid of `case` and returns the rows that miss the stress
/// target (span ends within 1e-5 of the view on chords of 2e-3 of it, 2e-4
/// on every chord; no wrong span count once chords under 4 `case.chord` are
/// set aside).
fn misses(label: &str, case: &Case, seed: u64) -> Vec<String> {
    let mut bad = vec![];
    for (ki, (name, shape)) in solids(case.c, case.s).into_iter().enumerate() {
        let st = measure(&shape, case, seed + ki as u64);
        let row =
            format!("| {name} | {label} | {:.1e} | {:.1e} | {} / {} of {} |", st.max_err, st.max_err_long, st.topo, st.topo4, st.rays);
        println!("{row}");
        if st.max_err_long > 1e-5 || st.max_err > 2e-4 || st.topo4 > 0 {
            bad.push(row);
        }
    }
    bad
}

fn run(cases: &[(String, Case)], seed: u64) {
    println!("seed {seed:#x}");
    println!("| solid | case | max end error / view | same, chords >= 2e-3 view | wrong span count |");
    println!("|---|---|---|---|---|");
    let mut bad = vec![];
    for (ci, (label, case)) in cases.iter().enumerate() {
        bad.extend(misses(label, case, seed + 100 * ci as u64));
    }
    for b in &bad {
        println!("MISSES: {b}");
    }
    assert!(bad.is_empty(), "{} rows miss", bad.len());
}

/// Direction lengths from subnormal (1e-43) to 1e38 (a unit direction gave
/// nothing below 1e-24 and from 1e20 on: |d|^2 left f32). A unit solid for
/// lengths from 1e-37 (t stays below f32's largest), a solid 1e-6 across for
/// subnormal ones.
#[test]
fn scale_range_directions() {
    let mut cases = vec![];
    for (lo, hi) in [(-37.0, -30.0), (-30.0, -20.0), (-20.0, -5.0), (5.0, 20.0), (20.0, 30.0), (30.0, 38.0)] {
        cases.push((format!("|d| 1e{lo}..1e{hi}"), Case { dir_exp: (lo, hi), ..Case::near(DVec3::ZERO, 1.0) }));
    }
    cases.push(("size 1e-6, |d| 1e-43..1e-38".into(), Case { dir_exp: (-43.0, -38.0), ..Case::near(DVec3::ZERO, 1e-6) }));
    run(&cases, 0x5ca1_e001);
}

/// Solids from 1e-20 to 1e20 across (a sphere of radius 1e23 or `scale` 1e30
/// gave no spans: the leaf's local direction squared to 0), at the origin and
/// 1e5 sizes from it.
#[test]
fn scale_range_sizes() {
    let dir = DVec3::new(0.6, -0.48, 0.64);
    let mut cases = vec![];
    for s in [1e-20, 1e-15, 1e-10, 1e10, 1e15, 1e20] {
        cases.push((format!("size {s:e}"), Case::near(DVec3::ZERO, s)));
    }
    for s in [1e-15, 1e15] {
        cases.push((format!("size {s:e} at {:e}", 1e5 * s), Case::near(rv(dir * (1e5 * s)), s)));
    }
    run(&cases, 0x5ca1_e101);
}

/// Ray origins 1e20 from solids 1e15 across, and 1e5 from unit solids, with
/// direction lengths from 1e-18 to 1e20 (t past f32 below; an origin at 1e20 gave a unit sphere
/// the span [1e20, inf]). Span counts are compared on chords of 1e-5 of the
/// view distance (the fusing tolerance grows by 2e-6 of it).
#[test]
fn scale_range_far_origins() {
    let far = |s: f64, view: f64, dir_exp: (f64, f64)| Case { c: DVec3::ZERO, s, view, dir_exp, chord: 2.5e-6 * view };
    let cases = vec![
        ("size 1e15 from 1e20".to_string(), far(1e15, 1e20, (-1.0, 1.0))),
        ("size 1e15 from 1e20, |d| 1e-18..1e20".to_string(), far(1e15, 1e20, (-18.0, 20.0))),
        ("size 1 from 1e5".to_string(), far(1.0, 1e5, (-1.0, 1.0))),
        ("size 1e-10 from 1e-5".to_string(), far(1e-10, 1e-5, (-1.0, 1.0))),
    ];
    run(&cases, 0x5ca1_e201);
}

/// The issue's three reproducers through `rothray trace` (the f64 answers in
/// the comments): a sphere of radius 1e23 and one under `scale` 1e30, seen
/// from their centres; a unit sphere 5 away along directions of length 1e-24,
/// 1e-37 and 1e20 (subnormal ones: `scale_range_directions`); and seen from 1e20.
#[test]
fn scale_range_reproducers() {
    use crate::bad_input::{rothray, tmpdir};
    let dir = tmpdir("scale-range");
    let cam = r#""camera":{"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":40}"#;
    let objects = r#"[{"name":"big","shape":{"sphere":{"center":[0,0,0],"radius":1e23}}},
        {"name":"scaled","shape":{"transformed":{"shape":{"sphere":{"center":[0,0,0],"radius":1}},"scale":1e30}}},
        {"name":"unit","shape":{"sphere":{"center":[0,0,0],"radius":1}}}]"#;
    std::fs::write(dir.join("s.json"), format!("{{{cam},\"objects\":{objects}}}")).unwrap();
    let rays = "0,0,0,0,0,1\n-5,0,0,1e-24,0,0\n-5,0,0,1e-37,0,0\n-5,0,0,1e20,0,0\n1e20,0,0,-1,0,0\n";
    std::fs::write(dir.join("r.csv"), rays).unwrap();
    let out = rothray().arg("trace").arg(dir.join("s.json")).arg("--rays").arg(dir.join("r.csv")).arg("--all").output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    println!("{text}");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let spans: Vec<(usize, String, f64, f64)> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].parse().unwrap(), f[1].to_string(), f[2].parse().unwrap(), f[3].parse().unwrap())
        })
        .collect();
    let find = |ray: usize, obj: &str| spans.iter().filter(|s| s.0 == ray && s.1 == obj).map(|s| (s.2, s.3)).collect::<Vec<_>>();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs();
    // From the centres: [0, radius].
    let r32 = 1e23f32 as f64;
    assert!(matches!(find(0, "big")[..], [(t0, t1)] if t0 == 0.0 && close(t1, r32)), "{:?}", find(0, "big"));
    let s32 = 1e30f32 as f64;
    assert!(matches!(find(0, "scaled")[..], [(t0, t1)] if t0 == 0.0 && close(t1, s32)), "{:?}", find(0, "scaled"));
    // The unit sphere from -5 along x: t = 4 / |d| to 6 / |d| (d as read in f32).
    for (ray, d) in [(1, 1e-24f32), (2, 1e-37f32), (3, 1e20f32)] {
        let (d, want) = (d as f64, find(ray, "unit"));
        assert!(matches!(want[..], [(t0, t1)] if close(t0, 4.0 / d) && close(t1, 6.0 / d)), "ray {ray}: {want:?}");
    }
    // From 1e20: the chord, 2 long at t = 1e20, is below f32's resolution.
    assert!(find(4, "unit").is_empty(), "{:?}", find(4, "unit"));
}

/// Leaves outside the supported range are located errors that state it.
#[test]
fn scale_range_rejected_with_the_range() {
    use crate::bad_input::{expect_error, scene_with};
    let too_big = r#"{"transformed":{"shape":{"sphere":{"center":[0,0,0],"radius":1e30}},"scale":1e30}}"#;
    expect_error(&scene_with(too_big), &["objects[0].shape.union[1].transformed.shape.sphere", "leaf out of range", "1e-30 to 1e30"]);
    let too_far = r#"{"box":{"min":[2e30,0,0],"max":[3e30,1,1]}}"#;
    expect_error(&scene_with(too_far), &["objects[0].shape.union[1].box", "reaches a coordinate of 3.000e30", "-1e30 to 1e30"]);
    let plane = r#"{"plane":{"normal":[0,1,0],"offset":1e31}}"#;
    expect_error(&scene_with(plane), &["objects[0].shape.union[1].plane", "-1e30 to 1e30"]);
    let tiny = r#"{"transformed":{"shape":{"sphere":{"center":[0,0,0],"radius":1e-30}},"scale":1e-30}}"#;
    expect_error(&scene_with(tiny), &["objects[0].shape.union[1].transformed.shape.sphere", "1e-30 to 1e30"]);
}

/// The sizes a leaf's map does not carry, and the camera: located errors
/// that state the supported range.
#[test]
fn scale_range_rejects_own_sizes_and_camera() {
    use crate::bad_input::{expect_error, scene_with};
    let at = "objects[0].shape.union[1]";
    let thin_box = r#"{"box":{"min":[0,0,0],"max":[1e-31,1,1]}}"#;
    expect_error(
        &scene_with(thin_box),
        &[&format!("{at}.box"), "half extent along its local axis 0 is 5.000e-32", "1e-30 to 1e30", "flat box"],
    );
    // Thin in the world only through its transform.
    let scaled_box = r#"{"transformed":{"shape":{"box":{"min":[0,0,0],"max":[1,1,1e-10]}},"scale":[1,1,1e-21]}}"#;
    expect_error(&scene_with(scaled_box), &[&format!("{at}.transformed.shape.box"), "local axis 2 is 5.000e-32"]);
    // A flat box is empty, and accepted.
    let flat = dir_scene("flat", &scene_with(r#"{"box":{"min":[0,0,0],"max":[0,1,1]}}"#));
    let out = crate::bad_input::rothray().arg("render").arg(&flat).arg("-o").arg(flat.with_extension("png")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let thin_torus = r#"{"torus":{"center":[0,0,0],"axis":[0,1,0],"major":1,"minor":1e-5}}"#;
    expect_error(&scene_with(thin_torus), &[&format!("{at}.torus"), "minor-to-major radius ratio is 1.000e-5", "1e-4 to 1e20"]);
    let fat_torus = r#"{"torus":{"center":[0,0,0],"axis":[0,1,0],"major":1e-22,"minor":1}}"#;
    expect_error(&scene_with(fat_torus), &[&format!("{at}.torus"), "ratio is 1.000e22", "1e-4 to 1e20"]);
    let tiny_tube = r#"{"transformed":{"shape":{"torus":{"center":[0,0,0],"axis":[0,1,0],"major":1,"minor":1e-3}},"scale":1e-28}}"#;
    expect_error(&scene_with(tiny_tube), &[&format!("{at}.transformed.shape.torus"), "minor radius is 1.000e-31", "1e-30 to 1e30"]);
    // The camera.
    let cam = |c: &str| format!(r#"{{"camera":{{{c}}},"image":{{"width":8,"height":8}},"objects":[]}}"#);
    let ok = r#""target":[0,0,0],"up":[0,1,0],"fov_y_deg":40"#;
    expect_error(&cam(&format!(r#""eye":[0,0,2e30],{ok}"#)), &["camera.eye", "2.000e30", "-1e30 to 1e30"]);
    expect_error(&cam(r#""eye":[0,0,5],"target":[-3e30,0,0],"fov_y_deg":40"#), &["camera.target", "-1e30 to 1e30"]);
    expect_error(
        &cam(r#""eye":[1e20,0,0],"target":[1.0000000000001e20,0,0],"fov_y_deg":40"#),
        &["camera.target", "target equals eye once rounded to f32"],
    );
    expect_error(
        &cam(r#""eye":[0,0,5],"target":[0,0,0],"fov_y_deg":0.001"#),
        &["camera.fov_y_deg", "between 0.01 and 179.9 degrees", "got 0.001"],
    );
    expect_error(&cam(r#""eye":[0,0,5],"target":[0,0,0],"fov_y_deg":179.95"#), &["camera.fov_y_deg", "179.9"]);
    expect_error(&cam(r#""eye":[0,0,5],"target":[0,0,0],"up":[0,0,1e-50],"fov_y_deg":40"#), &["camera.up", "zero vector"]);
    expect_error(&cam(r#""eye":[0,0,5],"target":[0,0,0],"up":[1e-6,0,1],"fov_y_deg":40"#), &["camera.up", "parallel", "1e-5 rad"]);
}

fn dir_scene(name: &str, json: &str) -> std::path::PathBuf {
    let f = crate::bad_input::tmpdir("range").join(format!("{name}.json"));
    std::fs::write(&f, json).unwrap();
    f
}

/// Cameras at the ends of the range aim where they are told: a view 1e20
/// long (its square overflows f32; the view fell back to -z) and an up
/// vector 1e-20 long (taken as parallel to every view).
#[test]
fn scale_range_cameras() {
    use rothray::engine::Camera;
    let dir = |c: Camera| c.rays(9, 9).ray(4.5, 4.5).dir.as_dvec3();
    let far = Camera { eye: glam::Vec3::new(1e20, 2e19, 0.0), target: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_y_deg: 40.0 };
    let want = DVec3::new(-1e20, -2e19, 0.0).normalize();
    assert!((dir(far) - want).length() < 1e-6, "{:?}", dir(far));
    let near = Camera { eye: glam::Vec3::new(1e-20, 0.0, 0.0), target: glam::Vec3::ZERO, ..far };
    assert!((dir(near) - DVec3::NEG_X).length() < 1e-6, "{:?}", dir(near));
    // The ray a row above the centre leans toward +y with any up length.
    let up_of = |up: glam::Vec3| {
        let c = Camera { eye: glam::Vec3::new(0.0, 0.0, 5.0), target: glam::Vec3::ZERO, up, fov_y_deg: 40.0 };
        c.rays(9, 9).ray(4.5, 3.5).dir
    };
    for l in [1e-20f32, 1e-10, 1e10, 1e20] {
        assert_eq!(up_of(glam::Vec3::Y * l), up_of(glam::Vec3::Y), "up of length {l}");
    }
}
