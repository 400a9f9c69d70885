//! Model test of the live bake (hecs style): random edit sequences on a
//! World, a [`sync_scene`] after each, and every answer compared with a fresh
//! full bake of the same World. Leaves are compared by entity (a live scene's
//! leaf rows differ from a fresh bake's).

use glam::{DAffine3, DVec3, Vec3};
use hecs::{Entity, World};
use rand::{rngs::SmallRng, Rng, SeedableRng};
use std::sync::Arc;

use crate::live::LiveCounts;
use crate::*;
use rothray_csg::FollowCounts;

fn seed_from_env(default: u64) -> u64 {
    let seed = std::env::var("ROTHRAY_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(default);
    println!("seed {seed} (ROTHRAY_SEED overrides)");
    seed
}

fn v3(rng: &mut SmallRng, r: f32) -> Vec3 {
    if r == 0.0 {
        return Vec3::ZERO;
    }
    Vec3::new(rng.gen_range(-r..r), rng.gen_range(-r..r), rng.gen_range(-r..r))
}

fn cube_mesh() -> Arc<MeshData> {
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
    Arc::new(MeshData::new(p, t, InsideRule::Winding).expect("cube mesh"))
}

/// A random analytic leaf.
fn spawn_leaf(world: &mut World, rng: &mut SmallRng, spread: f32) -> Entity {
    let t = Transform::from_translation(v3(rng, spread));
    let e = world.spawn((t,));
    insert_shape(world, rng, e);
    if rng.gen_bool(0.3) {
        world.insert_one(e, Material { color: v3(rng, 1.0).abs() }).unwrap();
    }
    e
}

/// A random leaf of a kind with a packet kernel (sphere, box, cylinder).
fn spawn_kernel_leaf(world: &mut World, rng: &mut SmallRng, spread: f32) -> Entity {
    let t = Transform::from_translation(v3(rng, spread));
    let r = rng.gen_range(0.2..0.6);
    match rng.gen_range(0..3) {
        0 => world.spawn((t, Sphere { center: v3(rng, 0.1), radius: r })),
        1 => world.spawn((t, Cuboid { min: Vec3::splat(-r), max: Vec3::splat(r) + v3(rng, 0.1).abs() })),
        _ => world.spawn((t, Cylinder { a: Vec3::new(0.0, -r, 0.0), b: Vec3::new(0.05, r, 0.0), radius: r * 0.6 })),
    }
}

fn insert_shape(world: &mut World, rng: &mut SmallRng, e: Entity) {
    let r = rng.gen_range(0.3..1.2);
    match rng.gen_range(0..5) {
        0 => world.insert_one(e, Sphere { center: v3(rng, 0.3), radius: r }),
        4 => {
            // A swept sphere: its data sits in the leaf table's own list.
            let p = |t: f32| [t - 0.5, 0.3 * t, 0.0, 0.2 + 0.1 * t];
            world.insert_one(e, SweptSphere { bezier: vec![p(0.0), p(0.3), p(0.7), p(1.0)] })
        }
        1 => world.insert_one(e, Cuboid { min: Vec3::splat(-r), max: Vec3::splat(r) + v3(rng, 0.2).abs() }),
        2 => world.insert_one(e, Cylinder { a: Vec3::new(0.0, -r, 0.0), b: Vec3::new(0.1, r, 0.0), radius: r * 0.5 }),
        _ => world.insert_one(e, Torus { center: Vec3::ZERO, axis: Vec3::Y, major: r, minor: r * 0.3 }),
    }
    .unwrap();
}

fn remove_shape(world: &mut World, e: Entity) {
    let _ = world.remove_one::<Sphere>(e);
    let _ = world.remove_one::<Cuboid>(e);
    let _ = world.remove_one::<Cylinder>(e);
    let _ = world.remove_one::<Torus>(e);
    let _ = world.remove_one::<MeshSolid>(e);
    let _ = world.remove_one::<SweptSphere>(e);
}

fn random_op(rng: &mut SmallRng) -> Op {
    [Op::Union, Op::Intersection, Op::Difference][rng.gen_range(0..3)]
}

/// A small tree of two levels (a leaf with an operation on two more), the
/// child of a forest's wide union: its packet walk takes it by the shape
/// stored in the union's `Wide`, whose leaves a live sync moves.
fn spawn_small_tree(world: &mut World, rng: &mut SmallRng) -> Entity {
    let at = Transform::from_translation(v3(rng, 3.0));
    let inner: Vec<Entity> = (0..2).map(|_| spawn_kernel_leaf(world, rng, 0.3)).collect();
    let inner = world.spawn((CsgNode { op: random_op(rng), children: inner },));
    let first = spawn_kernel_leaf(world, rng, 0.2);
    let kids = if rng.gen_bool(0.5) { vec![first, inner] } else { vec![inner, first] };
    world.spawn((CsgNode { op: random_op(rng), children: kids }, at))
}

/// A random object: a leaf, a node over leaves, nodes nested two deep, or
/// a wide union of small trees.
fn spawn_object(world: &mut World, rng: &mut SmallRng, mesh: &Arc<MeshData>) -> Entity {
    let at = v3(rng, 6.0);
    let root = match rng.gen_range(0..6) {
        0 => spawn_leaf(world, rng, 0.0),
        5 => {
            // (At least PACKET_UNION_MIN children: packets walk it.)
            let kids: Vec<Entity> = (0..rng.gen_range(32..40)).map(|_| spawn_small_tree(world, rng)).collect();
            world.spawn((CsgNode::union(kids),))
        }
        1 if rng.gen_bool(0.3) => {
            let m = world.spawn((Transform(DAffine3::from_scale(DVec3::splat(1.5))), MeshSolid(mesh.clone())));
            let s = spawn_leaf(world, rng, 0.6);
            world.spawn((CsgNode::difference([m, s]),))
        }
        _ => {
            let n = rng.gen_range(2..5);
            let mut kids: Vec<Entity> = (0..n).map(|_| spawn_leaf(world, rng, 0.8)).collect();
            if rng.gen_bool(0.4) {
                let inner: Vec<Entity> = (0..2).map(|_| spawn_leaf(world, rng, 0.5)).collect();
                kids.push(world.spawn((CsgNode { op: random_op(rng), children: inner }, Transform::from_translation(v3(rng, 0.5)))));
            }
            world.spawn((CsgNode { op: random_op(rng), children: kids },))
        }
    };
    world.insert_one(root, Transform::from_translation(at)).unwrap();
    if rng.gen_bool(0.3) {
        world.insert_one(root, Name::new(format!("obj{}", rng.gen::<u16>()))).unwrap();
    }
    if rng.gen_bool(0.2) {
        world.insert_one(root, ObjectOrder(rng.gen_range(0..5))).unwrap();
    }
    root
}

fn despawn_tree(world: &mut World, e: Entity, touched: &mut Vec<Entity>) {
    let kids = world.get::<&CsgNode>(e).map(|n| n.children.clone()).unwrap_or_default();
    for c in kids {
        despawn_tree(world, c, touched);
    }
    touched.push(e);
    let _ = world.despawn(e);
}

fn pick<T: hecs::Component>(world: &World, rng: &mut SmallRng) -> Option<Entity> {
    let all: Vec<Entity> = world.query::<&T>().iter().map(|(e, _)| e).collect();
    (!all.is_empty()).then(|| all[rng.gen_range(0..all.len())])
}

fn is_leaf(world: &World, e: Entity) -> bool {
    world.get::<&CsgNode>(e).is_err()
}

/// One random edit, listing the entities it touched; returns its name.
fn edit(world: &mut World, rng: &mut SmallRng, mesh: &Arc<MeshData>, touched: &mut Vec<Entity>) -> &'static str {
    match rng.gen_range(0..16) {
        0 | 1 => {
            let before: std::collections::HashSet<Entity> = world.iter().map(|e| e.entity()).collect();
            spawn_object(world, rng, mesh);
            touched.extend(world.iter().map(|e| e.entity()).filter(|e| !before.contains(e)));
            "spawn"
        }
        2 => {
            let roots = find_objects(world);
            if !roots.is_empty() {
                despawn_tree(world, roots[rng.gen_range(0..roots.len())], touched);
            }
            "despawn"
        }
        3 | 4 => {
            if let Some(e) = pick::<Transform>(world, rng) {
                let t = Transform::from_translation(v3(rng, 6.0));
                world.insert_one(e, t).unwrap();
                touched.push(e);
            }
            "move"
        }
        5 => {
            if let Some(e) = pick::<Transform>(world, rng).filter(|&e| is_leaf(world, e)) {
                remove_shape(world, e);
                insert_shape(world, rng, e);
                touched.push(e);
            }
            "reshape"
        }
        6 => {
            if let Some(e) = pick::<Sphere>(world, rng) {
                world.get::<&mut Sphere>(e).unwrap().radius = rng.gen_range(0.2..1.5);
                touched.push(e);
            }
            "radius"
        }
        7 => {
            // A leaf child moves to another node (leaves only: no cycles), or
            // is shared with it.
            let (Some(a), Some(b)) = (pick::<CsgNode>(world, rng), pick::<CsgNode>(world, rng)) else { return "reparent" };
            let kids = world.get::<&CsgNode>(a).unwrap().children.clone();
            let leaves: Vec<usize> = (0..kids.len()).filter(|&i| is_leaf(world, kids[i])).collect();
            if a != b && kids.len() > 1 && !leaves.is_empty() {
                let at = leaves[rng.gen_range(0..leaves.len())];
                // Now and then the leaf stays where it was too: two trees share it.
                let share = rng.gen_bool(0.3);
                let c = if share { kids[at] } else { world.get::<&mut CsgNode>(a).unwrap().children.remove(at) };
                world.get::<&mut CsgNode>(b).unwrap().children.push(c);
                touched.extend([a, b]);
            }
            "reparent"
        }
        8 => {
            if let Some(e) = pick::<CsgNode>(world, rng) {
                world.get::<&mut CsgNode>(e).unwrap().op = random_op(rng);
                touched.push(e);
            }
            "op"
        }
        9 => {
            if let Some(e) = pick::<Hidden>(world, rng).filter(|_| rng.gen_bool(0.5)) {
                world.remove_one::<Hidden>(e).unwrap();
                touched.push(e);
            } else {
                let roots = find_objects(world);
                if !roots.is_empty() {
                    let r = roots[rng.gen_range(0..roots.len())];
                    world.insert_one(r, Hidden).unwrap();
                    touched.push(r);
                }
            }
            "hide"
        }
        10 => {
            if let Some(e) = pick::<Transform>(world, rng) {
                world.insert_one(e, Material { color: v3(rng, 1.0).abs() }).unwrap();
                touched.push(e);
            }
            "material"
        }
        11 | 15 => {
            if let Some(e) = pick::<MeshSolid>(world, rng) {
                world.remove_one::<MeshSolid>(e).unwrap();
                world.insert_one(e, Sphere { center: Vec3::ZERO, radius: 0.7 }).unwrap();
                touched.push(e);
            }
            "remove mesh"
        }
        12 => {
            if let Some(e) = pick::<Transform>(world, rng).filter(|&e| is_leaf(world, e) && rng.gen_bool(0.3)) {
                remove_shape(world, e);
                world.insert_one(e, MeshSolid(mesh.clone())).unwrap();
                touched.push(e);
            }
            "add mesh"
        }
        _ => {
            if let Some(e) = pick::<Transform>(world, rng) {
                if rng.gen_bool(0.5) {
                    world.insert_one(e, Name::new(format!("n{}", rng.gen::<u8>()))).unwrap();
                } else {
                    world.insert_one(e, ObjectOrder(rng.gen_range(0..5))).unwrap();
                }
                touched.push(e);
            }
            "rename"
        }
    }
}

/// A span with its surfaces named by entity.
fn span_key(s: &RenderScene, sp: &primitives::Span) -> String {
    let surf = |x: primitives::Surf| {
        if x.is_real() {
            format!("{:?}/{}/{}", s.leaf_info[x.leaf_index() as usize].entity, x.sub, x.flipped())
        } else {
            "-".into()
        }
    };
    format!("[{:08x} {} {:08x} {}]", sp.t0.to_bits(), surf(sp.s0), sp.t1.to_bits(), surf(sp.s1))
}

fn hit_key(s: &RenderScene, h: Option<Hit>) -> String {
    match h {
        None => "miss".into(),
        Some(h) => {
            let l = &s.leaf_info[h.leaf as usize];
            format!(
                "t {:08x} n {:?} obj {:?} leaf {:?} sub {} color {:?}",
                h.t.to_bits(),
                h.normal.to_array().map(f32::to_bits),
                s.objects[h.object as usize].entity,
                l.entity,
                h.sub,
                l.color.to_array().map(f32::to_bits)
            )
        }
    }
}

/// The renderer (tiles culled by the object cull tree, packets) draws the
/// same normal picture of both scenes.
fn compare_pictures(live: &RenderScene, fresh: &RenderScene, what: &str) {
    let cam = Camera { eye: Vec3::new(9.0, 12.0, 30.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 50.0 };
    let s = RenderSettings {
        width: 64,
        height: 48,
        spp: 1,
        aov: Aov::Normal,
        background: Vec3::ZERO,
        lights: Vec::new(),
        ambient: 0.2,
        part: Part::WHOLE,
    };
    let (a, _) = render(live, &cam, &s, &|_, _| {});
    let (b, _) = render(fresh, &cam, &s, &|_, _| {});
    assert!(a == b, "{what}: the normal pictures differ");
}

/// Tile states that live as long as a live scene, as a tool's render
/// threads keep them: each copies the scene's program once and then follows
/// its syncs edit by edit (`rothray_csg::EditLog`).
struct LongLivedTiles {
    /// Prepared after every sync.
    each: TileScratch,
    /// Prepared after every few syncs (several versions behind).
    some: TileScratch,
    packets: PacketScratch,
}

impl LongLivedTiles {
    fn new() -> Self {
        LongLivedTiles { each: TileScratch::default(), some: TileScratch::default(), packets: PacketScratch::default() }
    }
}

/// Every tile of a small picture of `live` through the long-lived tile
/// states answers as the fresh bake does ray by ray (nearest hits with
/// normals, any-hit): a row a sync rewrote and a copy missed would show.
fn compare_tiles(live: &RenderScene, tiles: &mut LongLivedTiles, fresh: &RenderScene, rng: &mut SmallRng, what: &str) {
    let cam = Camera { eye: v3(rng, 4.0) + Vec3::new(0.0, 6.0, 26.0), target: v3(rng, 3.0), up: Vec3::Y, fov_y_deg: 55.0 };
    let (w, h) = (48, 32);
    let rays = cam.rays(w, h);
    let (tw, th) = tile_size();
    let states = if rng.gen_bool(0.3) { vec![&mut tiles.each, &mut tiles.some] } else { vec![&mut tiles.each] };
    for ts in states {
        for y0 in (0..h as usize).step_by(th) {
            for x0 in (0..w as usize).step_by(tw) {
                let (x1, y1) = ((x0 + tw).min(w as usize), (y0 + th).min(h as usize));
                let any = live.prepare_tile(&rays.tile_region(x0, x1, y0, y1), ts);
                let px: Vec<(usize, usize)> = (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y))).collect();
                for chunk in px.chunks(8) {
                    let r: Vec<Ray> = chunk.iter().map(|&(x, y)| rays.ray(x as f32 + 0.5, y as f32 + 0.5)).collect();
                    let mut got = vec![None; r.len()];
                    if any {
                        live.intersect_packet_with(&r, &mut tiles.packets, &mut got, true, Some(&ts.view()));
                    }
                    for (k, ray) in r.iter().enumerate() {
                        assert_eq!(hit_key(live, got[k]), hit_key(fresh, fresh.intersect(ray)), "{what}: tile ({x0}, {y0}) ray {ray:?}");
                        let occluded = any && live.occluded_in(ray, &mut tiles.packets.scratch, Some(&ts.view()));
                        assert_eq!(occluded, fresh.occluded(ray), "{what}: tile ({x0}, {y0}) any-hit {ray:?}");
                    }
                }
            }
        }
    }
}

/// Every answer of `live` equals that of `fresh` on random rays and points.
fn compare(live: &RenderScene, fresh: &RenderScene, rng: &mut SmallRng, what: &str) {
    let objs = |s: &RenderScene| -> Vec<String> {
        s.objects.iter().map(|o| format!("{:?} {} {:?} {:?}", o.entity, o.name, o.bounds.min.to_array(), o.bounds.max.to_array())).collect()
    };
    assert_eq!(objs(live), objs(fresh), "{what}: objects");
    assert_eq!(live.eps.to_bits(), fresh.eps.to_bits(), "{what}: eps");
    for k in 0..150 {
        let o = v3(rng, 14.0);
        let target = if fresh.objects.is_empty() || k % 3 == 0 {
            v3(rng, 8.0)
        } else {
            fresh.objects[rng.gen_range(0..fresh.objects.len())].bounds.center()
        };
        let ray = Ray::new(o, target - o + v3(rng, 0.3));
        let (a, b) = (live.intersect(&ray), fresh.intersect(&ray));
        assert_eq!(hit_key(live, a), hit_key(fresh, b), "{what}: intersect {ray:?}");
        assert_eq!(live.occluded(&ray), fresh.occluded(&ray), "{what}: occluded {ray:?}");
        if !fresh.objects.is_empty() {
            let oi = rng.gen_range(0..fresh.objects.len() as u32);
            let sa: Vec<String> = live.spans(&ray, oi).iter().map(|x| span_key(live, x)).collect();
            let sb: Vec<String> = fresh.spans(&ray, oi).iter().map(|x| span_key(fresh, x)).collect();
            assert_eq!(sa, sb, "{what}: spans of object {oi} on {ray:?}");
            let p = v3(rng, 8.0);
            assert_eq!(live.classify(p), fresh.classify(p), "{what}: classify {p}");
        }
    }
}

/// The packet tables that a live scene keeps object by object are what a
/// walk of every object's tree makes of it.
fn check_packet_paths(scene: &RenderScene, what: &str) {
    let mut pm = crate::packet::nearest_mode_meshes(&scene.program, &scene.leaves, scene.objects.iter().map(|o| o.root));
    if pm.len() > PACKET_MESHES {
        pm.clear();
    }
    assert_eq!(scene.packet_meshes, pm, "{what}: packet meshes");
    assert_eq!(scene.packet_cover, crate::packet::packet_cover_by_walk(scene, &pm), "{what}: packet cover");
}

fn add_follow(total: &mut FollowCounts, tiles: &LongLivedTiles) {
    for ts in [&tiles.each, &tiles.some] {
        total.copies += ts.follow_counts().copies;
        total.edits += ts.follow_counts().edits;
    }
}

fn add_counts(total: &mut LiveCounts, c: LiveCounts) {
    total.full += c.full;
    total.partial += c.partial;
    total.in_place += c.in_place;
    total.appended += c.appended;
    total.births += c.births;
    total.rebuilds += c.rebuilds;
}

/// Objects come and go as in a game (spawned with random trees, names and
/// orders, despawned whole, a few moved in the same frames), a sync after
/// each frame: structural syncs of births and deaths only take the path
/// that edits the object tree in place (`live_births.rs`), and the scene
/// answers as a fresh bake does (hits, spans, classification, tiles that
/// live as long as the scene, pictures).
#[test]
fn births_and_deaths_sync_like_a_fresh_bake() {
    let seed = seed_from_env(1717);
    let mut rng = SmallRng::seed_from_u64(seed);
    let mesh = cube_mesh();
    let mut total = LiveCounts::default();
    for world_no in 0..4 {
        let mut world = World::new();
        let mut roots: Vec<Entity> = (0..[0, 3, 40, 200][world_no]).map(|_| spawn_object(&mut world, &mut rng, &mesh)).collect();
        let mut scene = RenderScene::default();
        let mut tiles = LongLivedTiles::new();
        sync_scene(&mut world, &mut scene).unwrap();
        let listed = world_no % 2 == 1;
        for step in 0..80 {
            let mut touched = Vec::new();
            let mut what = Vec::new();
            for _ in 0..rng.gen_range(1..4) {
                match rng.gen_range(0..5) {
                    0 | 1 => {
                        let before: std::collections::HashSet<Entity> = world.iter().map(|e| e.entity()).collect();
                        roots.push(spawn_object(&mut world, &mut rng, &mesh));
                        touched.extend(world.iter().map(|e| e.entity()).filter(|e| !before.contains(e)));
                        what.push("spawn");
                    }
                    2 | 3 if !roots.is_empty() => {
                        let r = roots.swap_remove(rng.gen_range(0..roots.len()));
                        despawn_tree(&mut world, r, &mut touched);
                        what.push("despawn");
                    }
                    _ if !roots.is_empty() => {
                        let r = roots[rng.gen_range(0..roots.len())];
                        world.insert_one(r, Transform::from_translation(v3(&mut rng, 6.0))).unwrap();
                        touched.push(r);
                        what.push("move");
                    }
                    _ => {}
                }
            }
            let what = format!("seed {seed} world {world_no} step {step} {what:?}");
            if listed {
                sync_scene_touched(&mut world, &mut scene, &touched).unwrap();
            } else {
                sync_scene(&mut world, &mut scene).unwrap();
            }
            let fresh = RenderScene::from_world(&world).unwrap();
            compare(&scene, &fresh, &mut rng, &what);
            check_packet_paths(&scene, &what);
            compare_tiles(&scene, &mut tiles, &fresh, &mut rng, &what);
            if step % 8 == 0 {
                compare_pictures(&scene, &fresh, &what);
            }
        }
        let c = scene.live.as_ref().unwrap().counts;
        println!("world {world_no}: {c:?}");
        add_counts(&mut total, c);
    }
    println!("{total:?}");
    // (Full bakes: a world of a few objects changing half of them, and sweeps of dead rows.)
    assert!(total.full * 10 < total.births, "births and deaths rarely bake everything: {total:?}");
    assert!(total.births > 200, "the births path ran: {total:?}");
}

/// Random edits (spawn, despawn, move, reshape, radius, re-parent, op, hide,
/// material, add and remove a mesh, rename, order), a sync after each batch,
/// each synced scene compared with a fresh full bake.
#[test]
fn live_sync_matches_a_fresh_bake_after_random_edits() {
    let seed = seed_from_env(13);
    let mut rng = SmallRng::seed_from_u64(seed);
    let mesh = cube_mesh();
    let (mut total, mut last) = (LiveCounts::default(), LiveCounts::default());
    let mut follow = FollowCounts::default();
    for world_no in 0..6 {
        let mut world = World::new();
        for _ in 0..rng.gen_range(0..12) {
            spawn_object(&mut world, &mut rng, &mesh);
        }
        let mut scene = RenderScene::default();
        let mut tiles = LongLivedTiles::new();
        let mut log = Vec::new();
        // Odd worlds sync with the list of touched entities (now and then
        // with a full scan in between).
        let listed = world_no % 2 == 1;
        for step in 0..150 {
            let mut touched = Vec::new();
            for _ in 0..rng.gen_range(1..4) {
                log.push(edit(&mut world, &mut rng, &mesh, &mut touched));
            }
            let what = format!("seed {seed} world {world_no} step {step} after {:?}", &log[log.len().saturating_sub(3)..]);
            let got = if listed && rng.gen_bool(0.9) {
                sync_scene_touched(&mut world, &mut scene, &touched)
            } else {
                sync_scene(&mut world, &mut scene)
            };
            match RenderScene::from_world(&world) {
                Ok(fresh) => {
                    assert!(got.is_ok(), "{what}: live sync failed ({got:?}) where a fresh bake works");
                    compare(&scene, &fresh, &mut rng, &what);
                    check_packet_paths(&scene, &what);
                    compare_tiles(&scene, &mut tiles, &fresh, &mut rng, &what);
                    // (The renderer's workers live as long as the scene.)
                    compare_pictures(&scene, &fresh, &what);
                }
                Err(e) => assert_eq!(got.err(), Some(e), "{what}: errors"),
            }
            // A failed sync drops the live state, and its counts with it.
            match scene.live.as_ref() {
                Some(l) => last = l.counts,
                None => add_counts(&mut total, std::mem::take(&mut last)),
            }
        }
        add_counts(&mut total, std::mem::take(&mut last));
        add_follow(&mut follow, &tiles);
    }
    println!("{total:?}; tile copies: {follow:?}");
    assert!(total.full > 0 && total.partial > 50 && total.in_place > 0 && total.appended > 0, "every path ran: {total:?}");
    assert!(total.births > 0, "births and deaths ran in worlds without hidden objects: {total:?}");
    assert!(follow.edits > 0 && follow.copies > 0, "the tile copies followed edits and copied whole programs: {follow:?}");
}

/// Many objects moving a few at a time: the refit trees (and their rebuild
/// once degraded), in-place rows and dead rows, against fresh bakes.
#[test]
fn live_refits_many_objects_like_a_fresh_bake() {
    let seed = seed_from_env(1313);
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut world = World::new();
    let roots: Vec<Entity> = (0..1500)
        .map(|_| {
            let a = spawn_leaf(&mut world, &mut rng, 0.0);
            let b = spawn_leaf(&mut world, &mut rng, 0.7);
            world.spawn((CsgNode::difference([a, b]), Transform::from_translation(v3(&mut rng, 40.0))))
        })
        .collect();
    let mut scene = RenderScene::default();
    let mut tiles = LongLivedTiles::new();
    sync_scene(&mut world, &mut scene).unwrap();
    for round in 0..60 {
        for _ in 0..rng.gen_range(1..40) {
            let r = roots[rng.gen_range(0..roots.len())];
            let t = world.get::<&Transform>(r).unwrap().0.translation;
            world.insert_one(r, Transform(DAffine3::from_translation(t + v3(&mut rng, 3.0).as_dvec3()))).unwrap();
            if rng.gen_bool(0.1) {
                world.get::<&mut CsgNode>(r).unwrap().op = random_op(&mut rng);
            }
            if rng.gen_bool(0.02) {
                // More rows: the object's rows move to the end of the tables.
                let c = spawn_leaf(&mut world, &mut rng, 0.7);
                world.get::<&mut CsgNode>(r).unwrap().children.push(c);
            }
        }
        assert!(sync_scene(&mut world, &mut scene).unwrap());
        assert!(!sync_scene(&mut world, &mut scene).unwrap(), "nothing changed, nothing baked");
        let fresh = RenderScene::from_world(&world).unwrap();
        compare_tiles(&scene, &mut tiles, &fresh, &mut rng, &format!("seed {seed} round {round}"));
        if round % 10 == 9 {
            compare(&scene, &fresh, &mut rng, &format!("seed {seed} round {round}"));
            compare_pictures(&scene, &fresh, &format!("seed {seed} round {round}"));
        }
    }
    let c = scene.live.as_ref().unwrap().counts;
    let f = tiles.each.follow_counts();
    println!("{c:?}; tile copies: {f:?}");
    assert!(c.partial >= 60 && c.in_place > 0 && c.appended > 0 && c.rebuilds > 0, "every path ran: {c:?}");
    // A sync that re-bakes a few objects costs a tile state their rows, not
    // a copy of the program: it copies once per full bake.
    assert!(f.copies <= c.full && f.edits > 0, "the tile state followed the syncs edit by edit: {f:?}, {c:?}");
}

/// A mesh object: the shared asset under a random scale, turn and place,
/// alone or minus an analytic leaf.
fn spawn_mesh_object(world: &mut World, rng: &mut SmallRng, mesh: &Arc<MeshData>) -> Entity {
    let turn = glam::DQuat::from_rotation_y(rng.gen_range(0.0..6.0));
    let place = v3(rng, 7.0).as_dvec3();
    let m = world.spawn((MeshSolid(mesh.clone()),));
    let (root, local) = if rng.gen_bool(0.5) {
        let s = spawn_leaf(world, rng, 0.6);
        (world.spawn((CsgNode::difference([m, s]),)), DAffine3::from_scale(DVec3::splat(rng.gen_range(1.0..2.5))))
    } else {
        (m, DAffine3::IDENTITY)
    };
    world.insert_one(m, Transform(local)).unwrap();
    world.insert_one(root, Transform(DAffine3::from_rotation_translation(turn, place) * local)).unwrap();
    root
}

/// Scenes with meshes sync object by object: mesh objects (one asset,
/// shared by every instance) move, appear and vanish, analytic objects
/// move, and each sync re-bakes only those objects and answers as a fresh
/// bake does (hits, spans, classification, the renderer's packets; a
/// small world takes the packet shortcut).
#[test]
fn live_meshes_sync_by_object_like_a_fresh_bake() {
    let seed = seed_from_env(1331);
    let mut rng = SmallRng::seed_from_u64(seed);
    let mesh = cube_mesh();
    let mut total = LiveCounts::default();
    for (world_no, others) in [(0, 2), (1, 14)] {
        let mut world = World::new();
        let mut meshes: Vec<Entity> = (0..2).map(|_| spawn_mesh_object(&mut world, &mut rng, &mesh)).collect();
        let plain: Vec<Entity> = (0..others).map(|_| spawn_leaf(&mut world, &mut rng, 7.0)).collect();
        let mut scene = RenderScene::default();
        sync_scene(&mut world, &mut scene).unwrap();
        let mut shortcut = 0;
        for step in 0..60 {
            let what = match rng.gen_range(0..5) {
                0 | 1 => {
                    let r = meshes[rng.gen_range(0..meshes.len())];
                    let t = world.get::<&Transform>(r).unwrap().0;
                    world.insert_one(r, Transform(DAffine3::from_translation(v3(&mut rng, 2.0).as_dvec3()) * t)).unwrap();
                    "move mesh"
                }
                2 if meshes.len() < PACKET_MESHES => {
                    meshes.push(spawn_mesh_object(&mut world, &mut rng, &mesh));
                    "add mesh"
                }
                2 | 3 if meshes.len() > 1 => {
                    let r = meshes.swap_remove(rng.gen_range(0..meshes.len()));
                    despawn_tree(&mut world, r, &mut Vec::new());
                    "remove mesh"
                }
                _ => {
                    let r = plain[rng.gen_range(0..plain.len())];
                    world.insert_one(r, Transform::from_translation(v3(&mut rng, 7.0))).unwrap();
                    "move other"
                }
            };
            let what = format!("seed {seed} world {world_no} step {step} {what}");
            assert!(sync_scene(&mut world, &mut scene).unwrap(), "{what}: synced");
            assert!(!scene.leaves.meshes.is_empty(), "{what}: a scene with meshes");
            shortcut += scene.shortcut.is_some() as u32;
            let fresh = RenderScene::from_world(&world).unwrap();
            compare(&scene, &fresh, &mut rng, &what);
            check_packet_paths(&scene, &what);
            if step % 4 == 0 {
                compare_pictures(&scene, &fresh, &what);
            }
        }
        let c = scene.live.as_ref().unwrap().counts;
        println!("world {world_no}: {c:?}, shortcut in {shortcut} syncs");
        assert_eq!(c.full, 1, "world {world_no}: only the first sync bakes everything: {c:?}");
        assert!(world_no > 0 || shortcut > 0, "the small world takes the packet shortcut");
        add_counts(&mut total, c);
    }
    assert!(total.in_place > 0 && total.appended > 0 && total.births > 0, "every path ran: {total:?}");
}

#[test]
fn a_hidden_root_despawned_without_its_children_leaves_them_as_objects() {
    // A CSG root is hidden (its tree belongs to no object), then despawned
    // alone: its children are nobody's children any more, so they become
    // objects of their own, as a fresh bake says.
    let seed = seed_from_env(4242);
    let mut rng = SmallRng::seed_from_u64(seed);
    for listed in [false, true] {
        let mut world = World::new();
        for _ in 0..3 {
            spawn_leaf(&mut world, &mut rng, 6.0);
        }
        let kids: Vec<Entity> = (0..2).map(|_| spawn_leaf(&mut world, &mut rng, 0.8)).collect();
        let root = world.spawn((CsgNode::union(kids), Transform::from_translation(v3(&mut rng, 2.0))));
        let mut scene = RenderScene::default();
        sync_scene(&mut world, &mut scene).unwrap();
        for what in ["hide the root", "despawn the hidden root alone"] {
            if what.starts_with("hide") {
                world.insert_one(root, Hidden).unwrap();
            } else {
                world.despawn(root).unwrap();
            }
            if listed {
                sync_scene_touched(&mut world, &mut scene, &[root]).unwrap();
            } else {
                sync_scene(&mut world, &mut scene).unwrap();
            }
            let fresh = RenderScene::from_world(&world).unwrap();
            let what = format!("seed {seed} listed {listed}: {what}");
            assert_eq!(scene.objects.len(), fresh.objects.len(), "{what}: objects");
            compare(&scene, &fresh, &mut rng, &what);
        }
    }
}
