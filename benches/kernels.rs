//! Kernel benchmarks (issue 12, item 4), criterion: ns per ray of the scalar
//! paths that exist today. `cargo bench --bench kernels [FILTER]`.
//!
//! Each benchmark traces a fixed, seeded set of rays (the seed is printed) per
//! iteration and declares it as its throughput, so criterion's time divided
//! by the set's size (printed with each group) is the time per ray, and its
//! `thrpt` line is rays per second.
//!
//! * `leaf/KIND`: [`LeafTable::spans`] of one leaf of every kind (sphere, box,
//!   cylinder, cone, torus, half-space, swept sphere, generalized cylinder,
//!   mesh), baked from a JSON scene through `rothray::io`, on 1024 rays aimed
//!   at the leaf's bounds from all sides (hits and misses; the hit fraction
//!   is printed).
//! * `leaf/KIND x8 packet` (and `... sse2`): the same rays eight at a time
//!   through the packet kernel ([`LeafTable::ranges8`], AVX when the CPU has
//!   it; SSE2 forced) for the kinds that have one (sphere, box, cylinder,
//!   cone, half-space); per ray as well.
//! * `leaf/KIND x8 beside`: packets of eight of those rays that all miss
//!   the leaf (the common solve in a forest, where the lanes meeting a
//!   child's box pass beside it), through [`LeafTable::ranges8`]; per ray.
//!   `... pretest` (and `x8 packet pretest`): through
//!   [`LeafTable::ranges8_beside`], whose miss pretests answer such packets
//!   without solving (and cost the others their time).
//! * `combine/OP/N`: [`combine`] of two lists of N spans each (1, 2, 4, 8),
//!   for union, intersection and difference; per call, not per ray.
//! * `wide_union/...`: a ground box and a union of 3000 small spheres (like
//!   `benches/scenes/forest.json`), camera rays of every 8th tile across and
//!   down the 1920x1080 view (the renderer's 16x8 tiles, 4x2 packets): one
//!   `RenderScene::intersect` per ray against `intersect_packet_with` with
//!   the tile's view (the union walked once per packet), with the tiles
//!   prepared outside the timing, and with `prepare_tile` timed too. The
//!   setup checks that both give every ray the same `t`.
//! * `mesh8/...`: `MeshData::closest_hit` eight times against one
//!   `closest_hit8` (the 4-wide BVH walked once per packet) on camera rays of
//!   the bunny's view, tiles picked the same way.
//!
//! * `combine/OP x8 merge (C)/N` (and `... by lane`: without AVX2): the same pairs through
//!   the 8-lane merge ([`merge8`], lists of capacity C), eight pairs per
//!   call; per pair, like `combine/OP/N`.
//!
//! Not here: the torus's packet prep (`LeafTable::torus_prep8`); sweeps and
//! generalized cylinders have no packet kernel.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::Vec3;
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::csg::spans8::{merge8, merge8_by_lane, Spans8};
use rothray::csg::{combine, Op, SpanList};
use rothray::engine::{tile_size, Camera, CameraRays, PacketScratch, Ray, RenderScene, TileScratch};
use rothray::primitives::frustum::Frustum;
use rothray::primitives::kernels8::{Ranges8, Rays8Soa};
use rothray::primitives::mesh::{InsideRule, MeshData};
use rothray::primitives::{Aabb, LeafKind, Span, Surf};

/// Seed of every random set (printed, so a run can be reproduced).
const SEED: u64 = 0x6b65_726e_656c;
/// Rays per leaf set.
const LEAF_RAYS: usize = 1024;
/// Span-list pairs per combine set.
const PAIRS: usize = 256;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// One object per leaf kind, each alone (they overlap; only their leaves are
/// queried). The mesh is the bunny of `scenes/`, scaled to about a unit.
const LEAVES_JSON: &str = r#"{
 "camera": {"eye": [0, 0, 6], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40},
 "objects": [
  {"name": "sphere", "shape": {"sphere": {"center": [0, 0, 0], "radius": 1}}},
  {"name": "box", "shape": {"box": {"min": [-1, -0.7, -0.5], "max": [1, 0.7, 0.5]}}},
  {"name": "cylinder", "shape": {"cylinder": {"a": [0, -1, 0], "b": [0, 1, 0.3], "radius": 0.6}}},
  {"name": "cone", "shape": {"cone": {"a": [0, -1, 0], "b": [0.2, 1, 0], "radius_a": 0.8, "radius_b": 0.2}}},
  {"name": "torus", "shape": {"torus": {"center": [0, 0, 0], "axis": [0.2, 1, 0.1], "major": 1, "minor": 0.3}}},
  {"name": "half-space", "shape": {"plane": {"normal": [0.1, 1, 0.2], "offset": 0.1}}},
  {"name": "swept sphere", "shape": {"swept_sphere": {"bezier": [
    [-1.5, 0, 0, 0.3], [-1.17, 0.33, 0.08, 0.35], [-0.83, 1.17, 0.58, 0.48], [-0.5, 1, 0.5, 0.5],
    [-0.17, 0.83, 0.42, 0.52], [0.17, -0.83, -0.42, 0.45], [0.5, -1, -0.5, 0.4],
    [0.83, -1.17, -0.58, 0.35], [1.17, -0.33, -0.08, 0.22], [1.5, 0, 0, 0.2]]}}},
  {"name": "generalized cylinder", "shape": {"generalized_cylinder": {
    "path": [[1, -1.2, 0], [1, -0.8, 1.6], [-1, 0, 1.6], [-1, 0.4, 0]],
    "profile": {"polygon": [[0.3, -0.3], [0.3, 0.3], [-0.3, 0.3], [-0.3, -0.3]]}, "twist_deg": 90}}},
  {"name": "mesh", "shape": {"transformed": {"translate": [0, -0.7, 0], "scale": 0.15, "shape": {"mesh": {"path": "bunny.obj"}}}}}
 ]
}"#;

/// Bakes `text` as if it were a file of `scenes/` (so `bunny.obj` resolves there).
fn bake_json(text: &str) -> RenderScene {
    let sf = rothray::io::parse_scene(text, &root().join("scenes/kernels-bench.json")).expect("bench scene parses");
    RenderScene::from_world(&sf.world).expect("bench scene bakes")
}

/// `n` unit-direction rays from a sphere around `b` (three times its radius)
/// toward random points of `b` grown by 30%: rays that graze the bounds miss
/// most solids, so the set mixes hits and misses.
fn rays_at(rng: &mut SmallRng, b: &Aabb, n: usize) -> Vec<Ray> {
    let (c, h) = ((b.min + b.max) * 0.5, (b.max - b.min) * 0.5);
    let r = 3.0 * h.length();
    (0..n)
        .map(|_| {
            let u = loop {
                let v = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                if (0.01..=1.0).contains(&v.length_squared()) {
                    break v.normalize();
                }
            };
            let o = c + u * r;
            let t = c + h * 1.3 * Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
            Ray::new(o, (t - o).normalize())
        })
        .collect()
}

/// 20 samples in `secs` seconds: the whole run takes about two minutes.
fn group_config(g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>, secs: u64) {
    g.sample_size(20).measurement_time(Duration::from_secs(secs)).warm_up_time(Duration::from_millis(500));
}

/// The bench's name of a leaf kind (the scene format's, for the analytic kinds).
fn kind_name(k: LeafKind) -> &'static str {
    match k {
        LeafKind::Sphere => "sphere",
        LeafKind::Ellipsoid => "ellipsoid",
        LeafKind::Cuboid => "box",
        LeafKind::Cylinder => "cylinder",
        LeafKind::Cone => "cone",
        LeafKind::Torus => "torus",
        LeafKind::HalfSpace => "half-space",
        LeafKind::SweptSphere => "swept sphere",
        LeafKind::GenCylinder => "generalized cylinder",
        LeafKind::Mesh => "mesh",
    }
}

fn leaf_kernels(c: &mut Criterion) {
    let scene = bake_json(LEAVES_JSON);
    let leaves = &scene.leaves;
    let mut rng = SmallRng::seed_from_u64(SEED);
    println!("leaf kernels: seed {SEED:#x}, {LEAF_RAYS} rays per leaf; ns per ray = time / {LEAF_RAYS}");
    let mut g = c.benchmark_group("leaf");
    group_config(&mut g, 2);
    g.throughput(Throughput::Elements(LEAF_RAYS as u64));
    let mut out: Vec<Span> = Vec::with_capacity(16);
    for i in 0..leaves.len() as u32 {
        let kind = leaves.kind[i as usize];
        // A half-space is unbounded: aim at the unit box around its anchor.
        // (A baked scene keeps leaf bounds in its program: `leaf_bounds`.)
        let b = if kind == LeafKind::HalfSpace { Aabb::new(Vec3::splat(-1.0), Vec3::ONE) } else { scene.leaf_bounds(&[i])[0] };
        let rays = rays_at(&mut rng, &b, LEAF_RAYS);
        let hits = rays
            .iter()
            .filter(|r| {
                out.clear();
                leaves.spans(i, r, &mut out);
                !out.is_empty()
            })
            .count();
        let name = kind_name(kind);
        println!("leaf/{name}: {hits} of {LEAF_RAYS} rays hit");
        g.bench_function(name, |bch| {
            bch.iter(|| {
                let mut n = 0usize;
                for r in &rays {
                    out.clear();
                    leaves.spans(i, black_box(r), &mut out);
                    n += out.len();
                }
                n
            })
        });
        if !leaves.has_kernel8(i) {
            continue;
        }
        // The same rays eight at a time through the packet kernel (its
        // unclipped ranges; the scalar figure above includes the clipping).
        let packets: Vec<Rays8Soa> = rays
            .chunks_exact(8)
            .map(|c| Rays8Soa::new(&std::array::from_fn(|k| c[k].origin), &std::array::from_fn(|k| c[k].dir)))
            .collect();
        let mut r8 = Ranges8::default();
        let mut packet_bench = |label: &str, solve: &dyn Fn(&Rays8Soa, &mut Ranges8)| {
            g.bench_function(format!("{name} {label}"), |bch| {
                bch.iter(|| {
                    let mut n = 0u32;
                    for p in &packets {
                        solve(black_box(p), &mut r8);
                        n += r8.hit.count_ones();
                    }
                    n
                })
            });
        };
        packet_bench("x8 packet", &|p, r| leaves.ranges8(i, p, 0xff, r));
        packet_bench("x8 packet pretest", &|p, r| leaves.ranges8_beside(i, p, 0xff, r));
        packet_bench("x8 packet sse2", &|p, r| leaves.ranges8_sse(i, p, 0xff, r));
        // Packets of the rays that miss the leaf, as most of a forest's
        // solves are (every lane meeting the child's box passes beside it):
        // what the kernels' miss pretests answer without solving.
        let beside: Vec<&Ray> = rays
            .iter()
            .filter(|r| {
                out.clear();
                leaves.spans(i, r, &mut out);
                out.is_empty()
            })
            .collect();
        let missing: Vec<Rays8Soa> = beside
            .chunks_exact(8)
            .map(|c| Rays8Soa::new(&std::array::from_fn(|k| c[k].origin), &std::array::from_fn(|k| c[k].dir)))
            .collect();
        println!("leaf/{name} x8 beside: {} packets of 8 rays that miss; ns per ray = time / {}", missing.len(), 8 * missing.len());
        g.throughput(Throughput::Elements(8 * missing.len() as u64));
        for (label, pretest) in [("x8 beside", false), ("x8 beside pretest", true)] {
            g.bench_function(format!("{name} {label}"), |bch| {
                bch.iter(|| {
                    let mut n = 0u32;
                    for p in &missing {
                        if pretest {
                            leaves.ranges8_beside(i, black_box(p), 0xff, &mut r8);
                        } else {
                            leaves.ranges8(i, black_box(p), 0xff, &mut r8);
                        }
                        n += r8.hit.count_ones();
                    }
                    n
                })
            });
        }
        g.throughput(Throughput::Elements(LEAF_RAYS as u64));
    }
    g.finish();
}

/// `n` sorted, disjoint spans in (0, 10) with surfaces of leaf `leaf`.
fn span_list(rng: &mut SmallRng, n: usize, leaf: u32) -> Vec<Span> {
    let mut ts: Vec<f32> = (0..2 * n).map(|_| rng.gen_range(0.0..10.0)).collect();
    ts.sort_by(f32::total_cmp);
    (0..n)
        .map(|k| Span { t0: ts[2 * k], t1: ts[2 * k + 1], s0: Surf::new(leaf, 2 * k as u32), s1: Surf::new(leaf, 2 * k as u32 + 1) })
        .collect()
}

fn combine_lists(c: &mut Criterion) {
    let mut rng = SmallRng::seed_from_u64(SEED ^ 1);
    println!("combine: seed {:#x}, {PAIRS} pairs of random lists per set; ns per call = time / {PAIRS}", SEED ^ 1);
    let mut g = c.benchmark_group("combine");
    group_config(&mut g, 2);
    g.throughput(Throughput::Elements(PAIRS as u64));
    let mut out = SpanList::new();
    for n in [1usize, 2, 4, 8] {
        let pairs: Vec<(Vec<Span>, Vec<Span>)> = (0..PAIRS).map(|_| (span_list(&mut rng, n, 0), span_list(&mut rng, n, 1))).collect();
        for (op, name) in [(Op::Union, "union"), (Op::Intersection, "intersection"), (Op::Difference, "difference")] {
            g.bench_with_input(BenchmarkId::new(name, n), &pairs, |bch, pairs| {
                bch.iter(|| {
                    let mut k = 0usize;
                    for (a, b) in pairs {
                        combine(op, black_box(a), black_box(b), 1e-4, &mut out);
                        k += out.len();
                    }
                    k
                })
            });
            // The same pairs, eight lanes per call; capacities that hold
            // every result (a union of n and n spans has up to 2n).
            match n {
                1 => merge8_bench::<2>(&mut g, (op, name), n, &pairs),
                2 => merge8_bench::<4>(&mut g, (op, name), n, &pairs),
                4 => merge8_bench::<8>(&mut g, (op, name), n, &pairs),
                _ => merge8_bench::<16>(&mut g, (op, name), n, &pairs),
            }
        }
    }
    g.finish();
}

/// `combine/OP x8 merge (C)/N` (and `... by lane`, the path without AVX2): [`merge8`] on the pairs of
/// `combine/OP/N`, eight pairs per call, lists of capacity `C`; the same
/// throughput (pairs), so the times compare directly.
fn merge8_bench<const C: usize>(
    g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    (op, name): (Op, &str),
    n: usize,
    pairs: &[(Vec<Span>, Vec<Span>)],
) {
    let packets: Vec<(Spans8<C>, Spans8<C>)> = pairs
        .chunks(8)
        .map(|ch| {
            let (mut a, mut b) = (Spans8::<C>::default(), Spans8::<C>::default());
            for (k, (x, y)) in ch.iter().enumerate() {
                assert!(a.set_lane(k, x) && b.set_lane(k, y));
            }
            (a, b)
        })
        .collect();
    let eps = [1e-4f32; 8];
    let mut out = Spans8::<C>::default();
    type Merge<const C: usize> = fn(Op, &Spans8<C>, &Spans8<C>, &[f32; 8], u32, &mut Spans8<C>) -> u32;
    for (suffix, f) in [("", merge8::<C> as Merge<C>), (" by lane", merge8_by_lane::<C> as Merge<C>)] {
        g.bench_with_input(BenchmarkId::new(format!("{name} x8 merge ({C}){suffix}"), n), &packets, |bch, packets| {
            bch.iter(|| {
                let mut k = 0u32;
                for (a, b) in packets {
                    k += f(op, black_box(a), black_box(b), &eps, 0xff, &mut out);
                    k += out.len[0];
                }
                k
            })
        });
    }
}

/// Like `benches/scenes/forest.json` (whose union mixes 10 000 spheres and
/// cones): a ground box and one union of `n` small spheres on it.
fn forest_json(rng: &mut SmallRng, n: usize) -> String {
    let spheres: Vec<String> = (0..n)
        .map(|_| {
            let r: f32 = rng.gen_range(0.1..0.25);
            let (x, z): (f32, f32) = (rng.gen_range(-20.0..20.0), rng.gen_range(-25.0..3.0));
            format!(r#"{{"sphere": {{"center": [{x}, {r}, {z}], "radius": {r}}}}}"#)
        })
        .collect();
    format!(
        r#"{{"camera": {{"eye": [0, 7, 9], "target": [0, 0, -10], "up": [0, 1, 0], "fov_y_deg": 50}},
        "objects": [
          {{"name": "ground", "shape": {{"box": {{"min": [-25, -0.5, -25], "max": [25, 0, 5]}}}}}},
          {{"name": "trees", "shape": {{"union": [{}]}}}}]}}"#,
        spheres.join(",")
    )
}

/// A tile of the image: its region and its 4x2 packets of camera rays.
struct Tile {
    region: Frustum,
    packets: Vec<[Ray; 8]>,
}

/// Every `stride`-th tile (of the renderer's size) across and down a
/// `width` x `height` image: the whole view, hits and misses (background)
/// in their share, with full-size pixel footprints.
fn tiles(cam: &CameraRays, (width, height): (usize, usize), stride: usize) -> Vec<Tile> {
    let (tw, th) = tile_size();
    let mut out = vec![];
    for ty in (0..height - th + 1).step_by(th * stride) {
        for tx in (0..width - tw + 1).step_by(tw * stride) {
            let corner = |x: usize, y: usize| cam.ray(x as f32, y as f32).dir;
            let (x1, y1) = (tx + tw, ty + th);
            let region = Frustum::pyramid(cam.ray(0.0, 0.0).origin, [corner(tx, ty), corner(x1, ty), corner(x1, y1), corner(tx, y1)]);
            let mut packets = vec![];
            for py in (ty..y1).step_by(2) {
                for px in (tx..x1).step_by(4) {
                    let xs: [f32; 8] = std::array::from_fn(|k| (px + k % 4) as f32 + 0.5);
                    let ys: [f32; 8] = std::array::from_fn(|k| (py + k / 4) as f32 + 0.5);
                    packets.push(cam.ray8(&xs, &ys));
                }
            }
            out.push(Tile { region, packets });
        }
    }
    out
}

fn wide_union(c: &mut Criterion) {
    let seed = SEED ^ 2;
    let mut rng = SmallRng::seed_from_u64(seed);
    let scene = bake_json(&forest_json(&mut rng, 3000));
    let cam = Camera { eye: Vec3::new(0.0, 7.0, 9.0), target: Vec3::new(0.0, 0.0, -10.0), up: Vec3::Y, fov_y_deg: 50.0 };
    let cam = cam.rays(1920, 1080);
    let tiles = tiles(&cam, (1920, 1080), 8);
    let rays: Vec<Ray> = tiles.iter().flat_map(|t| t.packets.iter().flatten().copied()).collect();
    // Every tile prepared once, for the timing of the packets alone.
    let prepared: Vec<TileScratch> = tiles
        .iter()
        .map(|t| {
            let mut ts = TileScratch::default();
            scene.prepare_tile(&t.region, &mut ts);
            ts
        })
        .collect();
    let mut ps = PacketScratch::default();
    let mut hits = [None; 8];
    // The packets give each ray what the single-ray query gives (t compared;
    // the tests compare every field).
    let mut n_hit = 0;
    for (t, ts) in tiles.iter().zip(&prepared) {
        for p in &t.packets {
            scene.intersect_packet_with(p, &mut ps, &mut hits, false, Some(&ts.view()));
            for k in 0..8 {
                let one = scene.intersect(&p[k]);
                assert_eq!(hits[k].map(|h| h.t.to_bits()), one.map(|h| h.t.to_bits()), "packet and single ray differ");
                n_hit += usize::from(one.is_some_and(|h| h.object == 1));
            }
        }
    }
    println!(
        "wide_union: seed {seed:#x}, 3000 spheres, {} rays in {} tiles, {n_hit} hit the union; ns per ray = time / {}",
        rays.len(),
        tiles.len(),
        rays.len()
    );
    let mut g = c.benchmark_group("wide_union");
    // An iteration is all 255 tiles (~7 ms one ray at a time): 2 s fit fewer
    // than criterion's 20 samples.
    group_config(&mut g, 4);
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.bench_function("intersect per ray", |b| b.iter(|| rays.iter().filter(|r| scene.intersect(black_box(r)).is_some()).count()));
    g.bench_function("packets, tiles prepared", |b| {
        b.iter(|| {
            let mut n = 0usize;
            for (t, ts) in tiles.iter().zip(&prepared) {
                let view = ts.view();
                for p in &t.packets {
                    scene.intersect_packet_with(black_box(p), &mut ps, &mut hits, false, Some(&view));
                    n += hits.iter().filter(|h| h.is_some()).count();
                }
            }
            n
        })
    });
    let mut ts = TileScratch::default();
    g.bench_function("prepare_tile + packets", |b| {
        b.iter(|| {
            let mut n = 0usize;
            for t in &tiles {
                scene.prepare_tile(black_box(&t.region), &mut ts);
                let view = ts.view();
                for p in &t.packets {
                    scene.intersect_packet_with(p, &mut ps, &mut hits, false, Some(&view));
                    n += hits.iter().filter(|h| h.is_some()).count();
                }
            }
            n
        })
    });
    g.finish();
}

/// The bunny through the io crate, and `scenes/bunny.json`'s view of it (in
/// the OBJ's units) as 4x2 packets of every 8th tile of a 1920x1080 image.
fn mesh_packets(c: &mut Criterion) {
    let (mesh, _) = rothray::io::load_mesh_data(&root().join("scenes/bunny.obj"), InsideRule::Orientation).expect("bunny loads");
    let cam = Camera { eye: Vec3::new(0.5, 1.2, 3.2) / 0.15, target: Vec3::new(0.0, 0.7, 0.0) / 0.15, up: Vec3::Y, fov_y_deg: 40.0 };
    let cam = cam.rays(1920, 1080);
    let packets: Vec<[Ray; 8]> = tiles(&cam, (1920, 1080), 8).into_iter().flat_map(|t| t.packets).collect();
    let soa: Vec<([Vec3; 8], [Vec3; 8])> = packets.iter().map(|p| (p.map(|r| r.origin), p.map(|r| r.dir))).collect();
    let (tmin, tmax) = ([0.0f32; 8], [f32::INFINITY; 8]);
    let hit_count =
        |m: &MeshData| soa.iter().map(|(o, d)| m.closest_hit8(o, d, &tmin, &tmax).iter().filter(|h| h.is_some()).count()).sum::<usize>();
    // The packet walk gives each ray the single-ray walk's answer (the
    // tests check this over many more rays; here it guards the setup).
    for (o, d) in &soa {
        let h8 = mesh.closest_hit8(o, d, &tmin, &tmax);
        for k in 0..8 {
            assert_eq!(h8[k], mesh.closest_hit(o[k], d[k], 0.0, f32::INFINITY), "closest_hit8 and closest_hit differ");
        }
    }
    let n = packets.len() * 8;
    println!("mesh8: bunny ({} triangles), {n} camera rays, {} hit; ns per ray = time / {n}", mesh.triangle_count(), hit_count(&mesh));
    let mut g = c.benchmark_group("mesh8");
    group_config(&mut g, 2);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("closest_hit x8", |b| {
        b.iter(|| {
            soa.iter()
                .flat_map(|(o, d)| (0..8).map(move |k| (o[k], d[k])))
                .filter(|&(o, d)| mesh.closest_hit(o, d, 0.0, f32::INFINITY).is_some())
                .count()
        })
    });
    g.bench_function("closest_hit8", |b| b.iter(|| hit_count(black_box(&mesh))));
    g.finish();
}

criterion_group!(benches, leaf_kernels, combine_lists, wide_union, mesh_packets);
criterion_main!(benches);
