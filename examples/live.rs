//! A live scene: N objects (each a box minus a sphere) in the tool's own
//! `hecs::World`, some moving every frame; each frame syncs the baked scene
//! and picks once; with `--moving`, each frame also renders a small preview
//! (as a tool's viewport would). Prints medians of the sync, pick and
//! preview times (CPU time of the process, all threads; `ROTHRAY_WALL=1` for
//! wall time).
//!
//! ```text
//! cargo run --release --example live                       # 10 000 objects, 100 moving, 100 frames
//! cargo run --release --example live -- --objects 100000 --moving 1
//! cargo run --release --example live -- --frames 1000      # and the trace speed after them
//! cargo run --release --example live -- --meshes 4         # and 4 instances of one cube mesh
//! cargo run --release --example live -- --union 1000000    # memory: one union of N spheres
//! cargo run --release --example live -- --union 1000000 --static 1   # the same by bake_scene
//! ```

use glam::Vec3;
use hecs::{Entity, World};
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::engine::*;

#[path = "live_world/mod.rs"]
mod live_world;
use live_world::{churn_one, extent, move_some, pick_ray, spawn_objects};

struct Args {
    objects: usize,
    moving: usize,
    frames: usize,
    union: usize,
    /// Instances of one mesh asset among the objects.
    meshes: usize,
    /// `--static 1`: the union baked by `bake_scene` (no sync state).
    fixed: bool,
}

fn parse_args() -> Args {
    let mut a = Args { objects: 10_000, moving: 100, frames: 100, union: 0, meshes: 0, fixed: false };
    let argv: Vec<String> = std::env::args().skip(1).collect();
    for pair in argv.chunks(2) {
        let v = pair.get(1).and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{}: a number please", pair[0]));
        match pair[0].as_str() {
            "--objects" => a.objects = v,
            "--moving" => a.moving = v,
            "--frames" => a.frames = v,
            "--union" => a.union = v,
            "--static" => a.fixed = v != 0,
            "--meshes" => a.meshes = v,
            o => panic!("unknown option {o}"),
        }
    }
    a
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A point in time: the process's CPU time (all threads), or wall time with
/// `ROTHRAY_WALL=1`. CPU time, because the figures are taken on machines
/// shared with other jobs, where wall time varied by 2x from run to run.
#[derive(Clone, Copy)]
struct Instant(f64);

impl Instant {
    fn now() -> Instant {
        if std::env::var_os("ROTHRAY_WALL").is_some() {
            static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
            return Instant(START.get_or_init(std::time::Instant::now).elapsed().as_secs_f64() * 1e3);
        }
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid out-pointer for the call.
        unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
        Instant(ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6)
    }
}

/// Milliseconds since `t`.
fn ms(t: Instant) -> f64 {
    Instant::now().0 - t.0
}

/// `VmHWM` (peak) and `VmRSS` of this process in bytes (Linux).
fn rss() -> (u64, u64) {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        s.lines().find(|l| l.starts_with(name)).and_then(|l| l.split_whitespace().nth(1)).and_then(|k| k.parse::<u64>().ok()).unwrap_or(0)
            * 1024
    };
    (field("VmHWM:"), field("VmRSS:"))
}

fn live(a: &Args) {
    let mut rng = SmallRng::seed_from_u64(13);
    let mut world = World::new();
    let mut roots = spawn_objects(&mut world, a.objects, &mut rng);
    roots.extend(spawn_meshes(&mut world, a.meshes, extent(a.objects), &mut rng));
    let mut scene = RenderScene::default();
    let t = Instant::now();
    sync_scene(&mut world, &mut scene).unwrap();
    println!("{} objects, first sync {:.1} ms", a.objects, ms(t));
    let t = Instant::now();
    let fresh = RenderScene::from_world(&world).unwrap();
    println!("full bake (bake_scene): {:.1} ms", ms(t));
    drop(fresh);

    // Each case twice: `sync_scene` (compares every entity with the last
    // sync's copy) and `sync_scene_touched` (only the entities listed).
    for listed in [false, true] {
        let how = if listed { "sync_scene_touched" } else { "sync_scene" };
        let sync = |world: &mut World, scene: &mut RenderScene, touched: &[Entity]| {
            if listed {
                sync_scene_touched(world, scene, touched).unwrap()
            } else {
                sync_scene(world, scene).unwrap()
            }
        };
        let (mut idle, mut one) = (Vec::new(), Vec::new());
        for _ in 0..a.frames.max(1) {
            let t = Instant::now();
            assert!(!sync(&mut world, &mut scene, &[]));
            idle.push(ms(t));
            let moved = move_some(&mut world, &roots, 1, &mut rng);
            let t = Instant::now();
            sync(&mut world, &mut scene, &moved);
            let hit = scene.intersect(&pick_ray(&scene, &mut rng));
            one.push(ms(t));
            std::hint::black_box(hit);
        }
        println!("{how}: nothing changed: median {:.3} ms", median(&mut idle));
        println!("{how}: move 1, sync, pick: median {:.3} ms", median(&mut one));
        // Objects come and go: despawn one, spawn one, sync, pick.
        let mut churn = Vec::new();
        for _ in 0..a.frames.max(1) {
            let touched = churn_one(&mut world, &mut roots[..a.objects], a.objects, &mut rng);
            let t = Instant::now();
            sync(&mut world, &mut scene, &touched);
            let hit = scene.intersect(&pick_ray(&scene, &mut rng));
            churn.push(ms(t));
            std::hint::black_box(hit);
        }
        println!("{how}: despawn 1 and spawn 1, sync, pick: median {:.3} ms", median(&mut churn));

        let (mut synced, mut pick, mut shown, mut tiled) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut hits = 0;
        // A tile state as long-lived as a tool's render thread keeps it.
        let mut ts = TileScratch::default();
        scene.prepare_tile(&nothing_seen(&scene), &mut ts);
        for _ in 0..a.frames {
            let moved = move_some(&mut world, &roots, a.moving, &mut rng);
            let t = Instant::now();
            sync(&mut world, &mut scene, &moved);
            synced.push(ms(t));
            let ray = pick_ray(&scene, &mut rng);
            let t = Instant::now();
            let hit = scene.intersect(&ray);
            pick.push(ms(t));
            hits += hit.is_some() as usize;
            let t = Instant::now();
            std::hint::black_box(scene.prepare_tile(&nothing_seen(&scene), &mut ts));
            tiled.push(ms(t));
            let t = Instant::now();
            std::hint::black_box(preview(&scene));
            shown.push(ms(t));
        }
        if a.frames > 0 {
            let (s, p, v) = (median(&mut synced), median(&mut pick), median(&mut shown));
            println!("{how}: move {}, sync: median {s:.3} ms; pick: median {p:.4} ms ({hits} of {} picks hit)", a.moving, a.frames);
            let f = median(&mut tiled);
            println!(
                "{how}: move {}, first tile after the sync: median {f:.4} ms; preview {PREVIEW_W}x{PREVIEW_H}: median {v:.3} ms",
                a.moving
            );
        }
    }
    // After all those frames of refits: the live trees against fresh ones.
    trace_speed(&world, &scene, &mut rng);

    move_some(&mut world, &roots, a.objects, &mut rng);
    let t = Instant::now();
    sync_scene(&mut world, &mut scene).unwrap();
    println!("move all {}, sync: {:.1} ms", a.objects, ms(t));
    let (peak, now) = rss();
    println!("peak RSS {:.1} MB, RSS {:.1} MB", peak as f64 / 1e6, now as f64 / 1e6);
}

/// The preview's size in pixels: a tool's small viewport.
const PREVIEW_W: u32 = 128;
const PREVIEW_H: u32 = 72;

/// A tool's preview after a sync: a small flat picture from a point inside
/// the scene looking at its centre (its rays meet a few objects each, so the
/// frame's fixed costs show, the tile level's among them).
fn preview(scene: &RenderScene) -> Vec<u8> {
    let c = scene.bounds.center();
    let cam = Camera { eye: c + (scene.bounds.max - scene.bounds.min) * 0.2, target: c, up: Vec3::Y, fov_y_deg: 40.0 };
    let s = RenderSettings {
        width: PREVIEW_W,
        height: PREVIEW_H,
        spp: 1,
        aov: Aov::Shaded,
        background: Vec3::ZERO,
        lights: Vec::new(),
        ambient: 1.0,
        part: Part::WHOLE,
    };
    render(scene, &cam, &s, &|_, _| {}).0
}

/// A tile region that meets no object (from a corner of the scene, facing
/// away): preparing it costs what a tile state pays to follow the sync.
fn nothing_seen(scene: &RenderScene) -> rothray::primitives::frustum::Frustum {
    let (d, u, v) = (Vec3::ONE, Vec3::new(0.1, -0.1, 0.0), Vec3::new(0.1, 0.1, -0.2));
    let edges = [d + u + v, d - u + v, d - u - v, d + u - v];
    rothray::primitives::frustum::Frustum::pyramid(scene.bounds.max + Vec3::splat(1.0), edges)
}

/// Traces the same rays through the live scene (its objects' tree refit
/// frame after frame) and a fresh bake of the same world.
fn trace_speed(world: &World, scene: &RenderScene, rng: &mut SmallRng) {
    let fresh = RenderScene::from_world(world).unwrap();
    let rays: Vec<Ray> = (0..20_000).map(|_| pick_ray(&fresh, rng)).collect();
    let time = |s: &RenderScene| {
        let mut best = f64::INFINITY;
        let mut n = 0;
        for _ in 0..3 {
            let t = Instant::now();
            n = rays.iter().filter(|r| s.intersect(r).is_some()).count();
            best = best.min(ms(t));
        }
        (best, n)
    };
    let (tl, nl) = time(scene);
    let (tf, nf) = time(&fresh);
    assert_eq!(nl, nf, "the live scene and a fresh bake hit as often");
    println!("20 000 picks (best of 3): live scene {tl:.1} ms, fresh bake {tf:.1} ms ({:.2}x)", tl / tf);
}

/// `n` instances of one cube mesh (imported once, shared), scattered over
/// `side`.
fn spawn_meshes(world: &mut World, n: usize, side: f32, rng: &mut SmallRng) -> Vec<Entity> {
    let p: Vec<Vec3> = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32) - 0.5).collect();
    let t = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    let mesh = std::sync::Arc::new(MeshData::new(p, t, InsideRule::Winding).expect("a cube"));
    (0..n)
        .map(|_| {
            let at = Vec3::new(rng.gen_range(0.0..side), rng.gen_range(0.0..side), rng.gen_range(0.0..side));
            world.spawn((Transform::from_translation(at), MeshSolid(mesh.clone())))
        })
        .collect()
}

/// Memory: one union of `n` spheres, baked once (by `sync_scene`, or by
/// `bake_scene` when `fixed`).
fn union(n: usize, fixed: bool) {
    let mut rng = SmallRng::seed_from_u64(13);
    let mut world = World::new();
    let side = extent(n);
    let kids: Vec<Entity> = (0..n)
        .map(|_| {
            let c = Vec3::new(rng.gen_range(0.0..side), rng.gen_range(0.0..side), rng.gen_range(0.0..side));
            world.spawn((Sphere { center: c, radius: 1.0 },))
        })
        .collect();
    world.spawn((CsgNode::union(kids),));
    let (_, before) = rss();
    let mut scene = RenderScene::default();
    let t = Instant::now();
    if fixed {
        bake_scene(&world, &mut scene).unwrap();
    } else {
        sync_scene(&mut world, &mut scene).unwrap();
    }
    let bake = ms(t);
    let (peak, after) = rss();
    println!(
        "union of {n} spheres: {} {bake:.0} ms; RSS {:.0} MB before the sync, {:.0} MB after, peak {:.0} MB",
        if fixed { "bake_scene" } else { "sync_scene" },
        before as f64 / 1e6,
        after as f64 / 1e6,
        peak as f64 / 1e6
    );
    println!(
        "per leaf: {:.0} bytes kept by the scene{}, {:.0} bytes at the peak",
        (after - before) as f64 / n as f64,
        if fixed { "" } else { " and its sync state" },
        (peak - before) as f64 / n as f64
    );
}

fn main() {
    let a = parse_args();
    if a.union > 0 {
        union(a.union, a.fixed);
    } else {
        live(&a);
    }
}
