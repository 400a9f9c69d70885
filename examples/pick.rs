//! Picking: a World with a few CSG solids, a grid of rays from a cursor,
//! the entities hit.
//!
//! ```text
//! cargo run --release --example pick
//! ```

use glam::Vec3;
use hecs::World;
use rothray::engine::*;

fn main() {
    let mut world = World::new();
    // A box with a spherical bite, a capsule-like union, and a lens (the
    // intersection of two spheres).
    let b = world.spawn((Name::new("box"), Cuboid { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) }));
    let s =
        world.spawn((Name::new("bite"), Transform::from_translation(Vec3::new(0.8, 0.8, 0.8)), Sphere { center: Vec3::ZERO, radius: 0.9 }));
    world.spawn((Name::new("bitten box"), CsgNode::difference([b, s]), Transform::from_translation(Vec3::new(-2.5, 0.0, 0.0))));
    let c = world.spawn((Name::new("rod"), Cylinder { a: Vec3::new(0.0, -1.0, 0.0), b: Vec3::new(0.0, 1.0, 0.0), radius: 0.5 }));
    let top = world.spawn((Name::new("top"), Sphere { center: Vec3::new(0.0, 1.0, 0.0), radius: 0.5 }));
    let bottom = world.spawn((Name::new("bottom"), Sphere { center: Vec3::new(0.0, -1.0, 0.0), radius: 0.5 }));
    world.spawn((Name::new("capsule"), CsgNode::union([c, top, bottom])));
    let l = world.spawn((Sphere { center: Vec3::new(-0.6, 0.0, 0.0), radius: 1.0 },));
    let r = world.spawn((Sphere { center: Vec3::new(0.6, 0.0, 0.0), radius: 1.0 },));
    world.spawn((Name::new("lens"), CsgNode::intersection([l, r]), Transform::from_translation(Vec3::new(2.5, 0.0, 0.0))));

    let mut scene = RenderScene::default();
    sync_scene(&mut world, &mut scene).unwrap();

    // The cursor: a camera at z = 8 looking down -z; a 9 x 5 grid of rays
    // around the cursor's ray, 0.8 units apart at the solids' depth.
    let eye = Vec3::new(0.0, 0.0, 8.0);
    for row in -2..=2 {
        let mut line = String::new();
        for col in -4..=4 {
            let target = Vec3::new(col as f32 * 0.8, row as f32 * -0.8, 0.0);
            let hit = scene.intersect(&Ray::new(eye, target - eye));
            let label = match hit {
                Some(h) => {
                    let object = &scene.objects[h.object as usize].name;
                    let leaf = scene.leaf_name(h.leaf);
                    format!("{object}/{leaf}")
                }
                None => "-".into(),
            };
            line.push_str(&format!("{label:>18}"));
        }
        println!("{line}");
    }
    // The entity behind the centre ray, and the object it belongs to.
    let h = scene.intersect(&Ray::new(eye, -eye)).expect("the capsule is in the middle");
    let leaf = scene.leaf_info[h.leaf as usize].entity;
    let object = scene.objects[h.object as usize].entity;
    println!("centre: t {:.3}, leaf entity {leaf:?} of object entity {object:?}, normal {:.3}", h.t, h.normal);
}
