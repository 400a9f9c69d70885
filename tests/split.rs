//! Work split across machines: `render --tile I/N` parts merged by `merge`
//! are byte-identical to one `render` (every AOV, spp 1 and more, any order of
//! parts); a missing, repeated or foreign part is refused (exit 2, naming the
//! file) and leaves an existing output alone; `trace --range` slices
//! concatenate to the whole file's output.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::bad_input::{rothray, tmpdir};

fn scene(name: &str) -> PathBuf {
    PathBuf::from(format!("{}/scenes/{name}", env!("CARGO_MANIFEST_DIR")))
}

fn ok(out: &Output, what: &str) {
    assert!(out.status.success(), "{what}: {}", String::from_utf8_lossy(&out.stderr));
}

/// Renders part `i` of `n` into `dir/name-i.part`.
fn part(dir: &Path, name: &str, sc: &Path, flags: &[&str], i: u32, n: u32) -> PathBuf {
    let p = dir.join(format!("{name}-{i}.part"));
    let tile = format!("{i}/{n}");
    let out = rothray().arg("render").arg(sc).arg("-o").arg(&p).args(["--tile", &tile]).args(flags).output().unwrap();
    ok(&out, &format!("{} {flags:?} --tile {tile}", sc.display()));
    p
}

fn single(dir: &Path, name: &str, sc: &Path, flags: &[&str]) -> Vec<u8> {
    let p = dir.join(format!("{name}-single.png"));
    let out = rothray().arg("render").arg(sc).arg("-o").arg(&p).args(flags).output().unwrap();
    ok(&out, &format!("{} {flags:?}", sc.display()));
    std::fs::read(p).unwrap()
}

fn merge(parts: &[PathBuf], out: &Path) -> Output {
    rothray().arg("merge").args(parts).arg("-o").arg(out).output().unwrap()
}

/// Splits `sc` into n parts for each n, merges them in a shuffled order and
/// compares with the single render.
fn check_exact(dir: &Path, tag: &str, sc: &Path, flags: &[&str], ns: &[u32]) {
    let want = single(dir, tag, sc, flags);
    for &n in ns {
        let mut parts: Vec<PathBuf> = (0..n).map(|i| part(dir, &format!("{tag}-n{n}"), sc, flags, i, n)).collect();
        // Any order: reversed, then the middle one first.
        parts.reverse();
        let mid = parts.len() / 2;
        parts.rotate_left(mid);
        let out = dir.join(format!("{tag}-n{n}.png"));
        let m = merge(&parts, &out);
        ok(&m, &format!("merge {tag} n {n}"));
        let got = std::fs::read(&out).unwrap();
        assert!(got == want, "{tag}: merge of {n} parts differs from the single render ({} {flags:?})", sc.display());
    }
}

/// A scene without lights: the renderer's flat-shading shortcut, which parts do not take.
fn flat_scene(dir: &Path) -> PathBuf {
    let p = dir.join("flat.json");
    std::fs::write(
        &p,
        r#"{"camera":{"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":40},"background":[0.2,0.3,0.4],"lights":[],
            "objects":[{"color":[1,0.5,0.2],"shape":{"difference":[{"box":{"min":[-1,-1,-1],"max":[1,1,1]}},{"sphere":{"center":[0,0,0],"radius":1.25}}]}},
                       {"color":[0.1,0.9,0.3],"shape":{"torus":{"center":[0.5,0.3,0],"axis":[1,1,0],"major":0.6,"minor":0.2}}}]}"#,
    )
    .unwrap();
    p
}

#[test]
fn merge_is_the_single_render_for_every_aov_and_spp() {
    let dir = tmpdir("split-exact");
    let flat = flat_scene(&dir);
    for (tag, sc) in [("sampler", scene("sampler.json")), ("flat", flat)] {
        for aov in ["shaded", "depth", "normal", "id"] {
            for spp in ["1", "3"] {
                // 30 rows: 4 rows of 8-pixel tiles, the last one 6 high; with
                // N = 3 part 0 holds two, with N = 7 parts 4 to 6 hold none.
                let flags = ["--width", "41", "--height", "30", "--spp", spp, "--aov", aov];
                check_exact(&dir, &format!("{tag}-{aov}-{spp}"), &sc, &flags, &[1, 3, 7]);
            }
        }
    }
    // More parts than chunks: the empty parts merge too.
    check_exact(&dir, "tiny", &scene("sampler.json"), &["--width", "9", "--height", "5"], &[4]);
    // The other split.
    check_exact(&dir, "bands", &scene("sampler.json"), &["--width", "40", "--height", "37", "--spp", "2", "--split", "bands"], &[3]);
}

#[test]
fn merge_is_the_single_render_on_every_scene() {
    let dir = tmpdir("split-scenes");
    let mut names: Vec<String> = std::fs::read_dir(scene(""))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".json"))
        .collect();
    names.sort();
    assert!(names.len() >= 5, "{names:?}");
    for name in &names {
        for aov in ["shaded", "depth", "normal", "id"] {
            for spp in ["1", "4"] {
                let flags = ["--width", "48", "--height", "27", "--spp", spp, "--aov", aov];
                check_exact(&dir, &format!("{name}-{aov}-{spp}"), &scene(name), &flags, &[3]);
            }
        }
    }
}

fn refused(out: &Output, file: &Path, words: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "want exit 2: {err}");
    assert!(err.contains(&*file.display().to_string()), "the message does not name {}: {err}", file.display());
    for w in words {
        assert!(err.contains(w), "the message lacks `{w}`: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_parts_are_refused_and_the_output_kept() {
    let dir = tmpdir("split-refuse");
    let sc = scene("sampler.json");
    let flags = ["--width", "32", "--height", "20", "--spp", "2"];
    let p: Vec<PathBuf> = (0..3).map(|i| part(&dir, "a", &sc, &flags, i, 3)).collect();
    let out = dir.join("out.png");
    std::fs::write(&out, b"keep me").unwrap();
    let kept = |what: &str| {
        assert_eq!(std::fs::read(&out).unwrap(), b"keep me", "{what}: the existing output was touched");
        let stray: Vec<_> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).filter(|n| n.to_string_lossy().contains(".tmp")).collect();
        assert!(stray.is_empty(), "{what}: temporary files left: {stray:?}");
    };

    // Missing.
    let m = merge(&[p[2].clone(), p[0].clone()], &out);
    refused(&m, &p[2], &["missing part 1 of 3"]);
    kept("missing");

    // Repeated (the same part under another name).
    let copy = dir.join("copy-of-a-1.part");
    std::fs::copy(&p[1], &copy).unwrap();
    let m = merge(&[p[0].clone(), p[1].clone(), copy.clone(), p[2].clone()], &out);
    refused(&m, &copy, &["repeated part 1/3", &p[1].display().to_string()]);
    kept("repeated");

    // Foreign: another scene, same settings.
    let other = part(&dir, "other", &scene("logo.json"), &flags, 1, 3);
    let m = merge(&[p[0].clone(), other.clone(), p[2].clone()], &out);
    refused(&m, &other, &["another scene"]);
    kept("foreign scene");

    // Foreign: the same scene with other settings (spp, aov, size).
    for (tag, f) in [
        ("spp", vec!["--width", "32", "--height", "20", "--spp", "3"]),
        ("aov", vec!["--width", "32", "--height", "20", "--spp", "2", "--aov", "depth"]),
        ("size", vec!["--width", "33", "--height", "20", "--spp", "2"]),
    ] {
        let q = part(&dir, tag, &sc, &f, 2, 3);
        let m = merge(&[p[0].clone(), p[1].clone(), q.clone()], &out);
        refused(&m, &q, &["other settings"]);
        kept(tag);
    }

    // Another tile size (the tiles' programs, so possibly the pixels, differ).
    let q = dir.join("tile32.part");
    let out32 = rothray()
        .env("ROTHRAY_TILE", "32x16")
        .arg("render")
        .arg(&sc)
        .arg("-o")
        .arg(&q)
        .args(["--tile", "2/3"])
        .args(flags)
        .output()
        .unwrap();
    ok(&out32, "ROTHRAY_TILE=32x16");
    let m = merge(&[p[0].clone(), p[1].clone(), q.clone()], &out);
    refused(&m, &q, &["tile size", "32x16"]);
    kept("tile size");

    // Another N.
    let q = part(&dir, "n4", &sc, &flags, 2, 4);
    let m = merge(&[p[0].clone(), p[1].clone(), q.clone()], &out);
    refused(&m, &q, &["2/4"]);
    kept("n");

    // Not a part file; a truncated one.
    let png = dir.join("not-a-part.png");
    std::fs::write(&png, b"\x89PNG\r\n\x1a\n0000000000000000").unwrap();
    let m = merge(&[p[0].clone(), png.clone(), p[2].clone()], &out);
    refused(&m, &png, &["not a rothray part file"]);
    kept("not a part");
    let bytes = std::fs::read(&p[1]).unwrap();
    let cut = dir.join("cut.part");
    std::fs::write(&cut, &bytes[..bytes.len() - 5]).unwrap();
    let m = merge(&[p[0].clone(), cut.clone(), p[2].clone()], &out);
    refused(&m, &cut, &["truncated"]);
    kept("truncated");
    // A flipped pixel bit.
    let mut bad = bytes.clone();
    let k = bad.len() - 7;
    bad[k] ^= 1;
    let flip = dir.join("flip.part");
    std::fs::write(&flip, &bad).unwrap();
    let m = merge(&[p[0].clone(), flip.clone(), p[2].clone()], &out);
    refused(&m, &flip, &["damaged"]);
    kept("damaged");

    // And the good set replaces it.
    ok(&merge(&p, &out), "merge");
    assert_eq!(std::fs::read(&out).unwrap(), single(&dir, "a", &sc, &flags));
}

#[test]
fn bad_tiles_are_located_errors() {
    let dir = tmpdir("split-tile");
    let sc = scene("sampler.json");
    let o = dir.join("x.part");
    for (t, want) in [
        ("3/3", "not below N = 3"),
        ("0/0", "N is 0"),
        ("1", "expected I/N"),
        ("a/2", "not a whole number"),
        ("-1/2", "not a whole number"),
    ] {
        let out = rothray().arg("render").arg(&sc).arg("-o").arg(&o).arg(format!("--tile={t}")).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--tile {t}: {err}");
        assert!(err.contains("--tile") && err.contains(want), "--tile {t}: {err}");
        assert!(!o.exists(), "--tile {t} wrote a part");
    }
}

#[test]
fn trace_ranges_concatenate_to_the_whole_file() {
    let dir = tmpdir("split-trace");
    let sc = scene("sampler.json");
    // 40 rays over the picture, one unusable (it keeps its number), a header and a blank line.
    let mut text = String::from("ox,oy,oz,dx,dy,dz\n");
    for i in 0..40 {
        if i == 11 {
            text.push_str("1,2,3\n\n");
            continue;
        }
        let (x, y) = ((i % 8) as f32 * 0.5 - 1.75, (i / 8) as f32 * 0.5 - 1.0);
        text.push_str(&format!("{x},{y},5,0,0,-1\n"));
    }
    let rays = dir.join("r.csv");
    std::fs::write(&rays, text).unwrap();
    for all in [false, true] {
        let trace = |range: Option<&str>| {
            let mut c = rothray();
            c.arg("trace").arg(&sc).arg("--rays").arg(&rays);
            if all {
                c.arg("--all");
            }
            if let Some(r) = range {
                c.args(["--range", r]);
            }
            let out = c.output().unwrap();
            ok(&out, &format!("trace --range {range:?}"));
            String::from_utf8(out.stdout).unwrap()
        };
        let whole = trace(None);
        let (head, body) = whole.split_once('\n').unwrap();
        assert!(body.lines().count() >= 10, "{whole}");
        let mut cat = String::new();
        for r in ["0..7", "7..7", "7..12", "12..39", "39.."] {
            let part = trace(Some(r));
            let (h, b) = part.split_once('\n').unwrap();
            assert_eq!(h, head);
            cat.push_str(b);
        }
        assert_eq!(cat, body, "--all {all}");
        // The numbers are those of the whole file.
        let part = trace(Some("20..21"));
        assert!(part.lines().skip(1).all(|l| l.starts_with("20,")), "{part}");
    }
    for (r, want) in [
        ("0..41", "B can be at most 40"),
        ("41..", "B can be at most 40"),
        ("5..3", "above"),
        ("x..3", "not a whole number"),
        ("7", "expected A..B"),
    ] {
        let out = rothray().arg("trace").arg(&sc).arg("--rays").arg(&rays).args(["--range", r]).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--range {r}: {err}");
        assert!(err.contains(want) && err.contains("--range"), "--range {r}: {err}");
    }
}

/// The command lines of `deploy/k8s-indexed-job.yaml`, run as its pods would
/// run them (one per `JOB_COMPLETION_INDEX`, then the merge), with /data in a
/// temporary folder: the merged PNG is the single render.
#[test]
fn kubernetes_indexed_job_command_lines() {
    let manifest = std::fs::read_to_string(format!("{}/deploy/k8s-indexed-job.yaml", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let line_with = |s: &str| -> String {
        let l = manifest.lines().find(|l| l.contains(s) && !l.trim_start().starts_with('#')).unwrap_or_else(|| panic!("no `{s}` line"));
        l.trim_start().strip_prefix("- ").unwrap().to_string()
    };
    let (render, merge_cmd) = (line_with("rothray render"), line_with("rothray merge"));
    let completions: u32 = manifest.lines().find_map(|l| l.trim().strip_prefix("completions:")).unwrap().trim().parse().unwrap();
    assert!(render.contains(&format!("--tile $JOB_COMPLETION_INDEX/{completions}")), "{render}");
    assert!(merge_cmd.contains(&format!("-lt {completions}")), "{merge_cmd}");
    let dir = tmpdir("split-k8s");
    let data = dir.join("data");
    let _ = std::fs::remove_dir_all(&data);
    std::fs::create_dir_all(&data).unwrap();
    std::fs::copy(scene("sampler.json"), data.join("scene.json")).unwrap();
    let bin = env!("CARGO_BIN_EXE_rothray");
    let local = |cmd: &str| cmd.replace("/data", &data.display().to_string()).replace("rothray ", &format!("{bin} "));
    // Pods in any order.
    for i in (0..completions).rev() {
        let out =
            std::process::Command::new("sh").arg("-c").arg(local(&render)).env("JOB_COMPLETION_INDEX", i.to_string()).output().unwrap();
        ok(&out, &format!("pod {i}: {}", local(&render)));
    }
    let out = std::process::Command::new("sh").arg("-c").arg(local(&merge_cmd)).output().unwrap();
    ok(&out, &local(&merge_cmd));
    let want = single(&dir, "k8s", &data.join("scene.json"), &[]);
    assert!(std::fs::read(data.join("out.png")).unwrap() == want, "the Kubernetes merge differs from the single render");
}
