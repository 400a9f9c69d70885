//! The live scene of `examples/live.rs` and `benches/live.rs`: N objects,
//! each a box minus a sphere, moved and picked at random.

use glam::{DAffine3, DVec3, Vec3};
use hecs::{Entity, World};
use rand::{rngs::SmallRng, Rng};
use rothray::engine::*;

/// Side of the cube the objects fill (about 3 units apart).
pub fn extent(n: usize) -> f32 {
    3.0 * (n as f32).cbrt()
}

pub fn spawn_objects(world: &mut World, n: usize, rng: &mut SmallRng) -> Vec<Entity> {
    spawn_objects_in(world, n, extent(n), rng)
}

/// `n` objects scattered over a cube of side `side`.
pub fn spawn_objects_in(world: &mut World, n: usize, side: f32, rng: &mut SmallRng) -> Vec<Entity> {
    (0..n)
        .map(|_| {
            let p = Vec3::new(rng.gen_range(0.0..side), rng.gen_range(0.0..side), rng.gen_range(0.0..side));
            let b = world.spawn((Cuboid { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) },));
            let s = world.spawn((Transform::from_translation(Vec3::new(0.0, 0.0, 0.8)), Sphere { center: Vec3::ZERO, radius: 1.2 }));
            world.spawn((CsgNode::difference([b, s]), Transform::from_translation(p)))
        })
        .collect()
}

/// Despawns a random object of `roots` (its node and both operands) and
/// spawns a new one in the cube of `n` objects; returns every entity
/// spawned or despawned (what a tool would list to `sync_scene_touched`).
pub fn churn_one(world: &mut World, roots: &mut [Entity], n: usize, rng: &mut SmallRng) -> Vec<Entity> {
    let i = rng.gen_range(0..roots.len());
    let old = roots[i];
    let mut touched: Vec<Entity> = world.get::<&CsgNode>(old).unwrap().children.to_vec();
    touched.push(old);
    for &e in &touched {
        world.despawn(e).unwrap();
    }
    let new = spawn_objects_in(world, 1, extent(n), rng)[0];
    touched.extend(world.get::<&CsgNode>(new).unwrap().children.iter().copied());
    touched.push(new);
    roots[i] = new;
    touched
}

/// Moves `k` random objects by up to half a unit; returns them.
pub fn move_some(world: &mut World, roots: &[Entity], k: usize, rng: &mut SmallRng) -> Vec<Entity> {
    let moved: Vec<Entity> = (0..k).map(|_| roots[rng.gen_range(0..roots.len())]).collect();
    for &r in &moved {
        let mut t = world.get::<&mut Transform>(r).unwrap();
        let d = DVec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5));
        t.0 = DAffine3::from_translation(d) * t.0;
    }
    moved
}

/// A pick: the ray from a corner of the scene through a random object.
pub fn pick_ray(scene: &RenderScene, rng: &mut SmallRng) -> Ray {
    let o = scene.bounds.max + Vec3::splat(5.0);
    let target = scene.objects[rng.gen_range(0..scene.objects.len())].bounds.center();
    Ray::new(o, target - o)
}
