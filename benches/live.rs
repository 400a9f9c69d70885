//! Live syncs (issue 13), criterion: N objects (a box minus a sphere each) in
//! a World; move some, sync, pick once. `cargo bench --bench live`. Wall
//! time; `examples/live.rs` prints the same cases in CPU time.

use criterion::{criterion_group, criterion_main, Criterion};
use glam::{DAffine3, DVec3, Vec3};
use hecs::{Entity, World};
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::engine::*;

fn spawn_objects(world: &mut World, n: usize, rng: &mut SmallRng) -> Vec<Entity> {
    let side = 3.0 * (n as f32).cbrt();
    (0..n)
        .map(|_| {
            let p = Vec3::new(rng.gen_range(0.0..side), rng.gen_range(0.0..side), rng.gen_range(0.0..side));
            let b = world.spawn((Cuboid { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) },));
            let s = world.spawn((Transform::from_translation(Vec3::new(0.0, 0.0, 0.8)), Sphere { center: Vec3::ZERO, radius: 1.2 }));
            world.spawn((CsgNode::difference([b, s]), Transform::from_translation(p)))
        })
        .collect()
}

fn move_some(world: &mut World, roots: &[Entity], k: usize, rng: &mut SmallRng) -> Vec<Entity> {
    let moved: Vec<Entity> = (0..k).map(|_| roots[rng.gen_range(0..roots.len())]).collect();
    for &r in &moved {
        let d = DVec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5));
        let mut t = world.get::<&mut Transform>(r).unwrap();
        t.0 = DAffine3::from_translation(d) * t.0;
    }
    moved
}

fn pick(scene: &RenderScene, rng: &mut SmallRng) -> Option<Hit> {
    let o = scene.bounds.max + Vec3::splat(5.0);
    let target = scene.objects[rng.gen_range(0..scene.objects.len())].bounds.center();
    scene.intersect(&Ray::new(o, target - o))
}

fn live(c: &mut Criterion) {
    let mut rng = SmallRng::seed_from_u64(13);
    for (n, moving) in [(10_000, 1), (10_000, 100), (100_000, 1), (100_000, 0)] {
        let mut world = World::new();
        let roots = spawn_objects(&mut world, n, &mut rng);
        let mut scene = RenderScene::default();
        sync_scene(&mut world, &mut scene).unwrap();
        c.bench_function(&format!("move {moving} of {n}, sync_scene, pick"), |b| {
            b.iter(|| {
                move_some(&mut world, &roots, moving, &mut rng);
                sync_scene(&mut world, &mut scene).unwrap();
                pick(&scene, &mut rng)
            })
        });
        c.bench_function(&format!("move {moving} of {n}, sync_scene_touched, pick"), |b| {
            b.iter(|| {
                let moved = move_some(&mut world, &roots, moving, &mut rng);
                sync_scene_touched(&mut world, &mut scene, &moved).unwrap();
                pick(&scene, &mut rng)
            })
        });
    }
    let mut world = World::new();
    spawn_objects(&mut world, 100_000, &mut rng);
    let mut group = c.benchmark_group("full");
    group.sample_size(10);
    group.bench_function("first sync of 100000", |b| {
        b.iter(|| {
            let mut scene = RenderScene::default();
            sync_scene(&mut world, &mut scene).unwrap();
            scene
        })
    });
    group.finish();
}

criterion_group!(benches, live);
criterion_main!(benches);
