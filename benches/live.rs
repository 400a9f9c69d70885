//! Live syncs (issue 13), criterion: N objects (a box minus a sphere each) in
//! a World; move some (or despawn one and spawn one), sync, pick once. `cargo bench --bench live`. Wall
//! time; `examples/live.rs` prints the same cases in CPU time.

use criterion::{criterion_group, criterion_main, Criterion};
use hecs::World;
use rand::{rngs::SmallRng, SeedableRng};
use rothray::engine::*;

#[path = "../examples/live_world/mod.rs"]
mod live_world;
use live_world::{churn_one, move_some, pick_ray, spawn_objects};

fn live(c: &mut Criterion) {
    let mut rng = SmallRng::seed_from_u64(13);
    for (n, moving) in [(10_000, 1), (10_000, 100), (100_000, 1), (100_000, 0)] {
        let mut world = World::new();
        let mut roots = spawn_objects(&mut world, n, &mut rng);
        let mut scene = RenderScene::default();
        sync_scene(&mut world, &mut scene).unwrap();
        c.bench_function(&format!("move {moving} of {n}, sync_scene, pick"), |b| {
            b.iter(|| {
                move_some(&mut world, &roots, moving, &mut rng);
                sync_scene(&mut world, &mut scene).unwrap();
                scene.intersect(&pick_ray(&scene, &mut rng))
            })
        });
        c.bench_function(&format!("move {moving} of {n}, sync_scene_touched, pick"), |b| {
            b.iter(|| {
                let moved = move_some(&mut world, &roots, moving, &mut rng);
                sync_scene_touched(&mut world, &mut scene, &moved).unwrap();
                scene.intersect(&pick_ray(&scene, &mut rng))
            })
        });
        if moving == 1 {
            c.bench_function(&format!("despawn 1 and spawn 1 of {n}, sync_scene_touched, pick"), |b| {
                b.iter(|| {
                    let touched = churn_one(&mut world, &mut roots, n, &mut rng);
                    sync_scene_touched(&mut world, &mut scene, &touched).unwrap();
                    scene.intersect(&pick_ray(&scene, &mut rng))
                })
            });
        }
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
