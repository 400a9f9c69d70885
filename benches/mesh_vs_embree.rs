//! Closest-hit throughput of `MeshData` beside Embree 3 on the same rays.
//!
//! Builds the bunny (`scenes/bunny.obj`, 3674 triangles, loaded by
//! `rothray::io::load_mesh`) subdivided by edge midpoints (`RB_SUBDIV` times,
//! default 4: 940 544 triangles, still closed),
//! writes it and two ray sets (camera rays of a 1920x1080 view in 4x2 packets,
//! and random incoherent rays through the bounding box) to `RB_DIR`, runs the
//! Embree program (`RB_EMBREE`, built by `benches/embree/run.sh`) on them if it
//! exists, then traces the same rays with `MeshData::closest_hit` (and the
//! 8-ray packet path) on rayon pools of 1 and `RB_THREADS` threads, and checks
//! that both agree on hit / miss and `t`.
//!
//! `cargo bench --bench mesh_vs_embree` (or `benches/embree/run.sh`).
//! Environment: RB_THREADS (2), RB_REPEATS (7), RB_SUBDIV (4), RB_DIR
//! (target/embree-bench), RB_EMBREE (RB_DIR/embree_bench), RB_RANDOM (1000000),
//! RB_METHODS (comma-separated name prefixes of the rothray methods to run; all).
//! `sse2_closest_hit8` is the packet walk with the SSE2 node test that CPUs
//! without AVX run (`closest_hit8` picks AVX at run time where the CPU has it).
//! `binary (old)` is the scalar binary-BVH walk `closest_hit` used before the 4-wide tree.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::Vec3;
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rayon::prelude::*;
use rothray::primitives::mesh::{InsideRule, MeshData};

const CHUNK: usize = 1024;

#[derive(Clone, Copy)]
struct Ray {
    o: Vec3,
    d: Vec3,
    tmin: f32,
    tmax: f32,
}

fn env<T: std::str::FromStr>(k: &str, default: T) -> T {
    std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// One level of midpoint subdivision (each triangle -> 4, orientation kept; the
/// midpoint of a shared edge is one vertex, so a closed mesh stays closed).
fn subdivide(pos: &mut Vec<Vec3>, tris: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(tris.len() * 2);
    let mut m = |a: u32, b: u32, pos: &mut Vec<Vec3>| {
        let k = (a.min(b), a.max(b));
        *mid.entry(k).or_insert_with(|| {
            pos.push((pos[k.0 as usize] + pos[k.1 as usize]) * 0.5);
            pos.len() as u32 - 1
        })
    };
    let mut out = Vec::with_capacity(tris.len() * 4);
    for &[a, b, c] in tris {
        let ab = m(a, b, pos);
        let bc = m(b, c, pos);
        let ca = m(c, a, pos);
        out.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    out
}

fn write_mesh(path: &Path, pos: &[Vec3], tris: &[[u32; 3]]) {
    let mut b = Vec::with_capacity(8 + 12 * (pos.len() + tris.len()));
    b.extend_from_slice(&(pos.len() as u32).to_le_bytes());
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for p in pos {
        for c in p.to_array() {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in tris {
        for c in t {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(path, b).unwrap();
}

fn write_rays(path: &Path, rays: &[Ray]) {
    let mut b = Vec::with_capacity(4 + 32 * rays.len());
    b.extend_from_slice(&(rays.len() as u32).to_le_bytes());
    for r in rays {
        for c in [r.o.x, r.o.y, r.o.z, r.d.x, r.d.y, r.d.z, r.tmin, r.tmax] {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(path, b).unwrap();
}

/// Pinhole camera rays (`scenes/bunny.json`'s view, in the OBJ's units), in 8x8
/// tiles of 4x2 packets so 8 consecutive rays are a coherent packet.
fn camera_rays(w: usize, h: usize) -> Vec<Ray> {
    let eye = Vec3::new(0.5, 1.2, 3.2) / 0.15;
    let target = Vec3::new(0.0, 0.7, 0.0) / 0.15;
    let fwd = (target - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let th = (40f32.to_radians() * 0.5).tan();
    let tw = th * w as f32 / h as f32;
    let mut rays = Vec::with_capacity(w * h);
    for ty in (0..h).step_by(8) {
        for tx in (0..w).step_by(8) {
            for py in (ty..(ty + 8).min(h)).step_by(2) {
                for px in (tx..(tx + 8).min(w)).step_by(4) {
                    for y in py..(py + 2).min(h) {
                        for x in px..(px + 4).min(w) {
                            let sx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * tw;
                            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * th;
                            rays.push(Ray { o: eye, d: fwd + right * sx + up * sy, tmin: 0.0, tmax: f32::INFINITY });
                        }
                    }
                }
            }
        }
    }
    assert_eq!(rays.len(), w * h);
    rays
}

/// Incoherent rays: origins on a sphere around the mesh, aimed at random points
/// of its bounding box (unnormalised directions).
fn random_rays(n: usize, lo: Vec3, hi: Vec3, seed: u64) -> Vec<Ray> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let c = (lo + hi) * 0.5;
    let r = (hi - lo).length();
    (0..n)
        .map(|_| {
            let u = loop {
                let v = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                    break v.normalize();
                }
            };
            let o = c + u * r;
            let t = Vec3::new(rng.gen_range(lo.x..hi.x), rng.gen_range(lo.y..hi.y), rng.gen_range(lo.z..hi.z));
            Ray { o, d: t - o, tmin: 0.0, tmax: f32::INFINITY }
        })
        .collect()
}

type Tracer = fn(&MeshData, &[Ray], &mut [f32]);

fn trace1(m: &MeshData, rays: &[Ray], out: &mut [f32]) {
    for (r, t) in rays.iter().zip(out) {
        *t = m.closest_hit(r.o, r.d, r.tmin, r.tmax).map_or(f32::INFINITY, |h| h.0);
    }
}

fn trace_pairs(m: &MeshData, rays: &[Ray], out: &mut [f32]) {
    for (r, t) in rays.iter().zip(out) {
        *t = m.closest_hit_pairs(r.o, r.d, r.tmin, r.tmax).map_or(f32::INFINITY, |h| h.0);
    }
}

fn trace8(m: &MeshData, rays: &[Ray], out: &mut [f32]) {
    trace8_with(m, rays, out, MeshData::closest_hit8)
}

/// The packet walk with the baseline SSE2 node test (what a CPU without AVX runs).
fn trace8_sse(m: &MeshData, rays: &[Ray], out: &mut [f32]) {
    trace8_with(m, rays, out, MeshData::closest_hit8_sse)
}

type Hit8 = [Option<(f32, u32)>; 8];

#[inline(always)]
fn trace8_with(m: &MeshData, rays: &[Ray], out: &mut [f32], f: impl Fn(&MeshData, &[Vec3; 8], &[Vec3; 8], &[f32; 8], &[f32; 8]) -> Hit8) {
    for (rs, ts) in rays.chunks(8).zip(out.chunks_mut(8)) {
        if rs.len() < 8 {
            trace1(m, rs, ts);
            continue;
        }
        let o: [Vec3; 8] = std::array::from_fn(|k| rs[k].o);
        let d: [Vec3; 8] = std::array::from_fn(|k| rs[k].d);
        let tmin: [f32; 8] = std::array::from_fn(|k| rs[k].tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| rs[k].tmax);
        let h = f(m, &o, &d, &tmin, &tmax);
        for k in 0..8 {
            ts[k] = h[k].map_or(f32::INFINITY, |h| h.0);
        }
    }
}

/// Median and min seconds over `repeats` timed runs (after one warm-up), and the t's.
fn bench(pool: &rayon::ThreadPool, m: &MeshData, rays: &[Ray], f: Tracer, repeats: usize) -> (f64, f64, Vec<f32>) {
    let mut out = vec![0.0f32; rays.len()];
    let mut times = vec![];
    for r in 0..=repeats {
        let t0 = Instant::now();
        pool.install(|| {
            rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(rs, ts)| f(m, rs, ts));
        });
        if r > 0 {
            times.push(t0.elapsed().as_secs_f64());
        }
    }
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], times[0], out)
}

fn read_f32s(path: &Path) -> Vec<f32> {
    std::fs::read(path).unwrap().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}

/// (hit/miss disagreements, hits with |dt| > 1e-4 relative, max relative dt)
fn compare(a: &[f32], b: &[f32]) -> (usize, usize, f32) {
    let (mut hm, mut dt, mut maxrel) = (0, 0, 0.0f32);
    for (&x, &y) in a.iter().zip(b) {
        if x.is_finite() != y.is_finite() {
            hm += 1;
        } else if x.is_finite() {
            let rel = (x - y).abs() / x.abs().max(1e-3);
            maxrel = maxrel.max(rel);
            if rel > 1e-4 {
                dt += 1;
            }
        }
    }
    (hm, dt, maxrel)
}

fn main() {
    let threads: usize = env("RB_THREADS", 2);
    let repeats: usize = env("RB_REPEATS", 7);
    let levels: u32 = env("RB_SUBDIV", 4);
    let nrandom: usize = env("RB_RANDOM", 1_000_000);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir: PathBuf = std::env::var("RB_DIR").map(PathBuf::from).unwrap_or_else(|_| root.join("target/embree-bench"));
    let embree: PathBuf = std::env::var("RB_EMBREE").map(PathBuf::from).unwrap_or_else(|_| dir.join("embree_bench"));
    std::fs::create_dir_all(&dir).unwrap();

    // Through the io crate, as a scene's mesh is loaded (its warnings are
    // for damaged files; the bunny is closed and has none).
    let (mut pos, mut tris, _warnings) = rothray::io::load_mesh(&root.join("scenes/bunny.obj")).expect("scenes/bunny.obj loads");
    for _ in 0..levels {
        tris = subdivide(&mut pos, &tris);
    }
    let t0 = Instant::now();
    let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).expect("bunny mesh");
    let build = t0.elapsed().as_secs_f64();
    assert_eq!(m.rule(), InsideRule::Orientation, "subdivided bunny must stay closed: {:?}", m.warnings());
    let b = m.local_bounds();
    println!(
        "bunny subdivided {levels}x: {} triangles, {} vertices, MeshData::new {build:.3} s (closed: {})",
        m.triangle_count(),
        pos.len(),
        m.rule() == InsideRule::Orientation
    );
    println!("BVH: {}", m.bvh_stats());
    let mesh_path = dir.join("bunny.mesh");
    write_mesh(&mesh_path, &pos, &tris);

    let only_sets: String = env("RB_SETS", String::new());
    let sets = [("camera 1920x1080", "camera", camera_rays(1920, 1080)), ("random", "random", random_rays(nrandom, b.min, b.max, 1))];
    let mut counts = vec![1];
    if threads != 1 {
        counts.push(threads);
    }
    let mut report = String::new();
    for (label, tag, rays) in &sets {
        if !only_sets.is_empty() && !only_sets.split(',').any(|x| x == *tag) {
            continue;
        }
        let ray_path = dir.join(format!("{tag}.rays"));
        write_rays(&ray_path, rays);
        println!("\n== {label}: {} rays", rays.len());
        for &nt in &counts {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(nt).build().unwrap();
            let mut embree_t: Option<(f64, f64, Vec<f32>)> = None;
            if embree.exists() {
                let tpath = dir.join(format!("{tag}.embree_t"));
                let out = Command::new(&embree)
                    .arg(&mesh_path)
                    .arg(&ray_path)
                    .arg(nt.to_string())
                    .arg(repeats.to_string())
                    .arg(&tpath)
                    .output()
                    .expect("run embree_bench");
                let text = String::from_utf8_lossy(&out.stdout);
                print!("{text}");
                std::io::stdout().flush().unwrap();
                let mrays = |name: &str| {
                    text.lines()
                        .find(|l| l.contains(name))
                        .and_then(|l| l.split_whitespace().rev().nth(1).and_then(|s| s.parse::<f64>().ok()))
                        .unwrap_or(f64::NAN)
                };
                embree_t = Some((mrays("rtcIntersect1"), mrays("rtcIntersect8"), read_f32s(&tpath)));
            } else {
                println!("(no Embree program at {}; run benches/embree/run.sh)", embree.display());
            }
            let methods = [
                ("closest_hit", trace1 as Tracer),
                ("closest_hit8", trace8 as Tracer),
                ("sse2_closest_hit8", trace8_sse as Tracer),
                ("binary (old)", trace_pairs as Tracer),
            ];
            let only: String = env("RB_METHODS", String::new());
            for (name, f) in methods {
                if !only.is_empty() && !only.split(',').any(|x| name.starts_with(x)) {
                    continue;
                }
                let (med, min, ts) = bench(&pool, &m, rays, f, repeats);
                let mr = rays.len() as f64 / med / 1e6;
                let hits = ts.iter().filter(|t| t.is_finite()).count();
                let mut line = format!(
                    "rothray {name:<13} threads {nt} rays {} hits {hits} median {med:.4} s min {min:.4} s  {mr:.2} Mrays/s",
                    rays.len()
                );
                if let Some((e1, e8, et)) = &embree_t {
                    let (hm, dt, maxrel) = compare(&ts, et);
                    line += &format!(
                        "  | x{:.2} of rtcIntersect1, x{:.2} of rtcIntersect8 | vs Embree: {hm} hit/miss differ, {dt} t differ > 1e-4 rel (max rel {maxrel:.1e})",
                        mr / e1,
                        mr / e8
                    );
                }
                println!("{line}");
                report += &format!("{label}\t{line}\n");
            }
        }
    }
    std::fs::write(dir.join("summary.txt"), report).unwrap();
}
