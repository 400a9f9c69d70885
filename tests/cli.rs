//! The command line contract: `trace` (nearest and `--all`), `bench --json`,
//! `render` with every AOV and supersampling.

use crate::bad_input::{rothray, tmpdir};

fn sampler() -> String {
    format!("{}/scenes/sampler.json", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn trace_nearest_and_all() {
    let dir = tmpdir("trace");
    let rays = dir.join("r.csv");
    // Through the capsule (union of a cylinder and two spheres) and through the pierced cone.
    std::fs::write(&rays, "2,-1,5,0,0,-1\n0,0.5,5,0,0,-1,0,100\n0,0,5,0,0,-1\n10,10,10,1,0,0\n").unwrap();
    let out = rothray().arg("trace").arg(sampler()).arg("--rays").arg(&rays).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let l: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(l[0].join(","), "ray,hit,t,nx,ny,nz,object,leaf");
    // Ray 0 hits the capsule's tilted cylinder just before its end sphere (z = 0.4, t = 4.6).
    assert_eq!(l[1][1], "1");
    let t0: f32 = l[1][2].parse().unwrap();
    assert!(t0 > 4.5 && t0 < 4.6, "{text}");
    assert_eq!(l[1][6], "capsule");
    assert_eq!(l[1][7], "objects[2].shape.union[0].cylinder");
    // Ray 2 goes down the cone's axis... and into the pierced hole of the cylinder (x axis, r 0.3): hits the cone.
    assert_eq!(l[3][6], "pierced");
    assert_eq!(l[4][1], "0");
    assert_eq!(l[4][2..].join(","), ",,,,,");
    // Round trip of f32 printing.
    let t: f32 = l[1][2].parse().unwrap();
    assert_eq!(format!("{t:?}"), l[1][2]);

    let out =
        rothray().arg("trace").arg(sampler()).arg("--rays").arg(&rays).arg("--all").arg("-o").arg(dir.join("all.csv")).output().unwrap();
    assert!(out.status.success());
    let all = std::fs::read_to_string(dir.join("all.csv")).unwrap();
    let mut lines = all.lines();
    assert_eq!(lines.next(), Some("ray,object,t_in,t_out"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().any(|r| r[0] == "0" && r[1] == "capsule"));
    // Increasing t within each (ray, object).
    for w in rows.windows(2) {
        if w[0][0] == w[1][0] && w[0][1] == w[1][1] {
            assert!(w[0][3].parse::<f32>().unwrap() < w[1][2].parse::<f32>().unwrap());
        }
    }
    assert!(!rows.iter().any(|r| r[0] == "3"), "a ray inside nothing prints no line");
}

#[test]
fn bench_json_last_line() {
    let out =
        rothray().args(["bench"]).arg(sampler()).args(["--width", "64", "--height", "36", "--repeats", "3", "--json"]).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let last = text.lines().last().unwrap();
    let j: serde_json::Value = serde_json::from_str(last).unwrap();
    for k in ["scene", "rays", "bake_s", "trace_s_median", "mrays_per_s"] {
        assert!(j.get(k).is_some(), "missing {k} in {last}");
    }
    assert!(j["rays"].as_u64().unwrap() >= 64 * 36);
}

#[test]
fn render_every_aov() {
    let dir = tmpdir("aov");
    for aov in ["shaded", "depth", "normal", "id"] {
        let png = dir.join(format!("{aov}.png"));
        let out = rothray()
            .arg("render")
            .arg(sampler())
            .arg("-o")
            .arg(&png)
            .args(["--width", "80", "--height", "45", "--spp", "4", "--aov", aov])
            .output()
            .unwrap();
        assert!(out.status.success(), "{aov}: {}", String::from_utf8_lossy(&out.stderr));
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
    }
    let out = rothray().arg("render").arg(sampler()).args(["-o", "/tmp/x.png", "--aov", "bogus"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    // A frame too large to hold is refused up front, not in the allocator.
    let out = rothray().arg("render").arg(sampler()).args(["-o", "/tmp/x.png", "--width", "65536", "--height", "65536"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `bench --knob K --json` for every knob on its README scene: at least 4
/// rows, the finest setting no worse than the coarsest, and an SVG plot.
#[test]
fn bench_knob_json_rows() {
    let root = env!("CARGO_MANIFEST_DIR");
    let dir = tmpdir("knobs");
    let cases = [
        ("sweep", "scenes/sweep.json"),
        ("gcyl", "scenes/knob_gcyl.json"),
        ("frame", "scenes/knob_gcyl.json"),
        ("torus", "benches/scenes/tori.json"),
        ("winding", "scenes/knob_winding.json"),
        ("fuse", "scenes/coincident.json"),
    ];
    for (knob, scene) in cases {
        let plot = dir.join(format!("{knob}.svg"));
        let out = rothray()
            .arg("bench")
            .arg(format!("{root}/{scene}"))
            .args(["--knob", knob, "--width", "96", "--height", "54", "--repeats", "1", "--json", "--plot"])
            .arg(&plot)
            .output()
            .unwrap();
        assert!(out.status.success(), "{knob}: {}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        let j: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
        assert_eq!(j["knob"], knob);
        let rows = j["rows"].as_array().unwrap();
        assert!(rows.len() >= 4, "{knob}: {text}");
        let (first, last) = (&rows[0], &rows[rows.len() - 1]);
        for k in ["max_err", "rms_err", "hit_miss_differs"] {
            assert!(last[k].as_f64().unwrap() <= first[k].as_f64().unwrap(), "{knob}: {k} finest worse than coarsest: {text}");
        }
        assert_eq!(rows.iter().any(|r| r.get("speckles").is_some()), knob == "fuse", "{knob}");
        assert!(std::fs::read_to_string(&plot).unwrap().starts_with("<svg"), "{knob}: no plot");
    }
    let out = rothray().arg("bench").arg(format!("{root}/scenes/sweep.json")).args(["--knob", "nope"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("the knobs are sweep, gcyl, frame, torus, winding, fuse"));
    let out =
        rothray().arg("bench").arg(format!("{root}/scenes/sweep.json")).args(["--knob", "frame", "--tolerances", "1.5"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("a whole number from 2 to 65536"));
}
