//! Random CSG trees (all ops, all leaves, random affine maps on any node)
//! against point classification of the f64 model at span midpoints, gaps and ends.

use glam::DVec3;
use rand::{rngs::SmallRng, SeedableRng};

use crate::oracle::*;
use rothray::csg::DeepFirst;
use rothray::engine::RenderScene;

/// One random ray through object 0 of `scene` (built from `tree`): its spans
/// against the model, and the nearest hit against the first real surface of
/// those spans. Returns whether the ray hit.
fn check_random_ray(scene: &RenderScene, tree: &Shape, rng: &mut SmallRng, ctx: &str, st: &mut Check) -> bool {
    let f = |p: DVec3| tree.inside(p);
    let (o, d) = random_ray(rng);
    let ray = to_ray(o, d);
    let spans = scene.spans(&ray, 0);
    check_spans(&f, &to_ray(o, d), &spans, 1e-4, &format!("{ctx} tree {}", tree.json()), st);
    // The nearest hit is the first real surface of the Roth diagram.
    let hit = scene.intersect(&ray);
    let expect = first_surface_t(&spans);
    assert_eq!(hit.map(|h| h.t), expect, "{ctx}: nearest hit vs spans {spans:?} tree {}", tree.json());
    hit.is_some()
}

#[test]
fn random_csg_spans_match_point_classification() {
    let seed = 0xc5_9001u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut st = Check::default();
    for case in 0..250 {
        let tree = random_tree(&mut rng, 3);
        let scene = bake(std::slice::from_ref(&tree));
        let f = |p: DVec3| tree.inside(p);
        for r in 0..30 {
            check_random_ray(&scene, &tree, &mut rng, &format!("case {case} ray {r}"), &mut st);
            // Point queries agree with the model away from surfaces.
            let p = rp(&mut rng, 1.2);
            let near = |p: DVec3| {
                (0..6).any(|k| {
                    let mut e = DVec3::ZERO;
                    e[k / 2] = if k % 2 == 0 { 1e-4 } else { -1e-4 };
                    f(p + e) != f(p)
                })
            };
            if !near(p) {
                assert_eq!(scene.contains(p.as_vec3(), 0), f(p), "case {case}: contains({p:?})");
            }
        }
    }
    println!("{st:?} max span-end error {:.3e}", st.max_err);
    assert!(st.spans > 1500);
}

#[test]
fn random_csg_with_meshes_nearest_hit_is_first_surface() {
    // Meshes answer nearest-hit queries from a pruned walk that stops just past
    // their first entry; the evaluator redoes the query in full when that was not
    // enough. Both must agree with the full Roth diagram and with the model.
    let seed = 0xc5_9002u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut st = Check::default();
    let (mut hits, mut mesh_trees) = (0, 0);
    for case in 0..200 {
        let tree = random_tree_with(&mut rng, 3, true);
        mesh_trees += tree.json().contains("mesh") as usize;
        let scene = bake(std::slice::from_ref(&tree));
        remove_mesh_files(std::slice::from_ref(&tree));
        for r in 0..30 {
            hits += check_random_ray(&scene, &tree, &mut rng, &format!("case {case} ray {r}"), &mut st) as usize;
        }
    }
    println!("{st:?} max span-end error {:.3e}; {hits} hits; {mesh_trees} trees with meshes", st.max_err);
    assert!(mesh_trees > 80 && hits > 1500);
}

#[test]
fn wide_nodes_match_narrow_evaluation() {
    // A difference with 200 subtrahends and a union of 150 leaves (both get BVHs)
    // against the model; rays through the dense part.
    let seed = 0x1de_0002u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut holes = vec![Shape::Box { min: DVec3::splat(-1.0), max: DVec3::splat(1.0) }];
    for _ in 0..200 {
        holes.push(Shape::Sphere { c: rp(&mut rng, 1.0), r: 0.12 });
    }
    let cheese = Shape::Diff(holes);
    let mut parts = Vec::new();
    for _ in 0..150 {
        let l = random_leaf(&mut rng, false);
        parts.push(match l {
            Shape::Sphere { c, r } => Shape::Sphere { c: c * 2.0, r: r * 0.3 },
            other => random_xf(&mut rng, other),
        });
    }
    let blob = Shape::Union(parts);
    let scene = bake(&[cheese.clone(), blob.clone()]);
    let mut st = Check::default();
    for (oi, s) in [cheese, blob].iter().enumerate() {
        let f = |p: DVec3| s.inside(p);
        for r in 0..1500 {
            let (o, d) = random_ray(&mut rng);
            let spans = scene.spans(&to_ray(o, d), oi as u32);
            check_spans(&f, &to_ray(o, d), &spans, 1e-4, &format!("object {oi} ray {r}"), &mut st);
        }
    }
    println!("{st:?} span lists spilled so far: {}", rothray::csg::spill_count());
}

#[test]
fn long_span_lists_spill_and_stay_correct() {
    // 40 disjoint balls on a line: 40 spans on one ray, beyond the inline capacity.
    let balls: Vec<Shape> = (0..40).map(|i| Shape::Sphere { c: DVec3::new(i as f64 * 0.1 - 2.0, 0.0, 0.0), r: 0.04 }).collect();
    let u = Shape::Union(balls);
    let scene = bake(std::slice::from_ref(&u));
    let before = rothray::csg::spill_count();
    let o = DVec3::new(-3.0, 0.0, 0.0);
    let d = DVec3::X;
    let spans = scene.spans(&to_ray(o, d), 0);
    assert_eq!(spans.len(), 40);
    assert!(rothray::csg::spill_count() > before, "a 40-span list must spill (inline capacity {})", rothray::csg::spans::INLINE_SPANS);
    let mut st = Check::default();
    check_spans(&|p| u.inside(p), &to_ray(o, d), &spans, 1e-5, "line of balls", &mut st);
}

#[test]
fn random_csg_with_meshes_packets_match_single_rays() {
    // The renderer's packet path (eight camera-like rays from one origin, meshes
    // walked once per packet and served to each ray's evaluation) must give every
    // ray exactly what the single-ray query gives, and that agrees with the full
    // Roth diagram (checked against the model by the tests above). Scenes hold one
    // or two random trees, with meshes in 7 of 10.
    let seed = 0xc5_9003u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut rays, mut hits, mut packed_scenes) = (0, 0, 0);
    // Rays that miss in scenes whose every object lies inside a packet mesh: the
    // packet path skips their evaluation when they miss those meshes.
    let (mut covered_scenes, mut covered_misses) = (0, 0);
    // Rays the packet shortcut answered without evaluating (scenes with few leaves).
    let (mut shortcuts, mut throughs) = (0, 0);
    for case in 0..150 {
        let mut trees = vec![random_tree_with(&mut rng, 3, true)];
        if case % 3 == 0 {
            trees.push(random_tree_with(&mut rng, 2, true));
        }
        packed_scenes += trees.iter().any(|t| t.json().contains("mesh")) as usize;
        let scene = bake(&trees);
        remove_mesh_files(&trees);
        covered_scenes += scene.packet_covered() as usize;
        let mut ps = rothray::engine::PacketScratch::default();
        for p in 0..20 {
            let (o, d) = random_ray(&mut rng);
            // Spread like a 4x2 block of pixels, wide or narrow.
            let packet = packet_around(o, d, if p % 4 == 0 { 0.05 } else { 0.003 });
            let mut out = [None; 8];
            scene.intersect_packet(&packet, &mut ps, &mut out);
            for k in 0..8 {
                let one = scene.intersect(&packet[k]);
                assert_eq!(
                    hit_key(out[k]),
                    hit_key(one),
                    "case {case} packet {p} ray {k}: {:?} trees {:?}",
                    packet[k],
                    trees.iter().map(|t| t.json()).collect::<Vec<_>>()
                );
                rays += 1;
                hits += one.is_some() as usize;
                covered_misses += (scene.packet_covered() && one.is_none()) as usize;
                // And the first surface of each object's full diagram.
                let want = nearest_in_diagrams(&scene, &packet[k], trees.len());
                assert_eq!(one.map(|h| h.t), want, "case {case} packet {p} ray {k}: nearest vs spans");
            }
        }
        shortcuts += ps.shortcuts;
        throughs += ps.throughs;
    }
    println!("{rays} rays in packets, {hits} hits, {packed_scenes} scenes with meshes");
    println!("{covered_scenes} scenes inside packet meshes, {covered_misses} missing rays there");
    println!("{shortcuts} rays answered by the packet shortcut, {throughs} given an interval to walk on through a subtracted leaf");
    assert!(hits > 1000 && packed_scenes > 70 && covered_misses > 500 && shortcuts > 500 && throughs > 50);
}

#[test]
fn bitten_mesh_packets_match_single_rays() {
    // scenes/bunny in small: a mesh with a ball cut out of its front, a ball
    // beside it and one behind. Every camera packet of a 160x120 picture (the
    // renderer's 4x2 blocks, from eyes all around) must give each ray exactly
    // what the single-ray query gives; most mesh hits go through the packet shortcut
    // (the balls' boxes lie beyond the mesh entry, or are missed), and rays into
    // the bite walk the mesh on through the cut-out ball.
    let seed = 0xc5_9004u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mesh = octa_mesh(DVec3::ZERO, 1.0, 3);
    let bitten = Shape::Diff(vec![mesh.clone(), Shape::Sphere { c: DVec3::new(0.3, 0.2, 0.6), r: 0.35 }]);
    let others = [Shape::Sphere { c: DVec3::new(1.4, 0.0, 0.0), r: 0.3 }, Shape::Sphere { c: DVec3::new(0.0, 0.0, -1.6), r: 0.4 }];
    let scene = bake(&[bitten.clone(), others[0].clone(), others[1].clone()]);
    remove_mesh_files(std::slice::from_ref(&mesh));
    let mut ps = rothray::engine::PacketScratch::default();
    let (w, h) = (160u32, 120u32);
    let (mut rays, mut hits) = (0, 0);
    for view in 0..6 {
        let eye = (rp(&mut rng, 1.0).normalize() * rand::Rng::gen_range(&mut rng, 2.5..5.0)).as_vec3();
        let cam = rothray::engine::Camera { eye, target: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_y_deg: 50.0 };
        let cr = cam.rays(w, h);
        for y in (0..h).step_by(2) {
            for x in (0..w).step_by(4) {
                let fx: [f32; 8] = std::array::from_fn(|k| (x + k as u32 % 4) as f32 + 0.5);
                let fy: [f32; 8] = std::array::from_fn(|k| (y + k as u32 / 4) as f32 + 0.5);
                let packet = cr.ray8(&fx, &fy);
                let mut out = [None; 8];
                scene.intersect_packet(&packet, &mut ps, &mut out);
                // The renderer's variant without normals (pictures without lights).
                let mut bare = [None; 8];
                scene.intersect_packet_with(&packet, &mut ps, &mut bare, false, None);
                for k in 0..8 {
                    let one = scene.intersect(&packet[k]);
                    let key = |h: Option<rothray::engine::Hit>| {
                        h.map(|h| (h.t.to_bits(), h.object, h.leaf, h.sub, h.normal.to_array().map(f32::to_bits)))
                    };
                    assert_eq!(key(out[k]), key(one), "view {view} eye {eye} pixel ({}, {})", fx[k], fy[k]);
                    let no_normal = one.map(|h| rothray::engine::Hit { normal: glam::Vec3::ZERO, ..h });
                    assert_eq!(key(bare[k]), key(no_normal), "view {view} eye {eye} pixel ({}, {}) without normals", fx[k], fy[k]);
                    rays += 1;
                    hits += one.is_some() as usize;
                }
            }
        }
    }
    // A packet with unusable rays (NaN or zero direction, tmin > tmax) goes ray
    // by ray: those get no hit, the others what the single-ray query gives.
    let cam = rothray::engine::Camera { eye: glam::Vec3::new(0.0, 0.5, 4.0), target: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_y_deg: 30.0 };
    let cr = cam.rays(64, 64);
    let mut packet = cr.ray8(&std::array::from_fn(|k| 30.0 + (k % 4) as f32), &std::array::from_fn(|k| 30.0 + (k / 4) as f32));
    packet[1].dir.y = f32::NAN;
    packet[4].dir = glam::Vec3::ZERO;
    packet[6].tmin = 5.0;
    packet[6].tmax = 1.0;
    let mut out = [None; 8];
    scene.intersect_packet(&packet, &mut ps, &mut out);
    for k in 0..8 {
        let one = if [1, 4, 6].contains(&k) { None } else { scene.intersect(&packet[k]) };
        assert_eq!(out[k].map(|h| (h.t.to_bits(), h.leaf)), one.map(|h| (h.t.to_bits(), h.leaf)), "unusable-ray packet, lane {k}");
    }
    assert!(out[0].is_some(), "the packet is aimed at the mesh");
    println!(
        "{rays} rays, {hits} hits, {} by the packet shortcut, {} given an interval to walk on through the bite (two queries per ray)",
        ps.shortcuts, ps.throughs
    );
    assert!(hits > 10_000 && ps.shortcuts > 10_000 && ps.throughs > 500);
}

/// Shadow packets as the renderer makes them: the hits of camera packets
/// moved off their surface (or left on it, or pushed a little inside),
/// eight at a time with one direction toward a light. Their packet walks
/// of the meshes (one walk of each mesh's tree for the eight rays,
/// `MeshData::spans_parallel8`) must leave every ray's any-hit exactly what
/// the single-ray query gives, in the bitten mesh of the test above and in
/// random trees with meshes.
#[test]
fn shadow_packets_off_meshes_match_single_rays() {
    use rand::Rng;
    let seed = 0xc5_9005u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mesh = octa_mesh(DVec3::ZERO, 1.0, 3);
    let bitten = Shape::Diff(vec![mesh.clone(), Shape::Sphere { c: DVec3::new(0.3, 0.2, 0.6), r: 0.35 }]);
    let others = [Shape::Sphere { c: DVec3::new(1.4, 0.0, 0.0), r: 0.3 }, Shape::Sphere { c: DVec3::new(0.0, 0.0, -1.6), r: 0.4 }];
    let _ = rothray::csg::take_eval_counts();
    let (mut rays, mut blocked) = (0usize, 0usize);
    for case in 0..40 {
        let trees = if case == 0 {
            vec![bitten.clone(), others[0].clone(), others[1].clone()]
        } else {
            let mut t = vec![random_tree_with(&mut rng, 3, true)];
            if case % 3 == 0 {
                t.push(random_tree_with(&mut rng, 2, true));
            }
            t
        };
        let scene = bake(&trees);
        remove_mesh_files(&trees);
        let mut ps = rothray::engine::PacketScratch::default();
        for view in 0..if case == 0 { 12 } else { 3 } {
            let eye = (rp(&mut rng, 1.0).normalize() * rng.gen_range(2.5..5.0)).as_vec3();
            let cam = rothray::engine::Camera { eye, target: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_y_deg: 50.0 };
            let cr = cam.rays(64, 48);
            let light = -(rp(&mut rng, 1.0) + DVec3::new(0.0, -1.5, 0.0)).normalize().as_vec3();
            let mut origins = Vec::new();
            for y in 0..48u32 {
                for x in 0..64u32 {
                    let ray = cr.ray8(&[x as f32 + 0.5; 8], &[y as f32 + 0.5; 8])[0];
                    let Some(h) = scene.intersect(&ray) else { continue };
                    let nf = if h.normal.dot(ray.dir) > 0.0 { -h.normal } else { h.normal };
                    if nf.dot(light) <= 0.0 && origins.len() % 5 != 0 {
                        continue; // mostly the surfaces a light reaches
                    }
                    let p = ray.origin + ray.dir * h.t;
                    let off = match origins.len() % 7 {
                        0 => 0.0,
                        1 => -1e-5,
                        _ => 1e-4 * (1.0 + p.abs().max_element()),
                    };
                    origins.push(p + nf * off);
                }
            }
            for chunk in origins.chunks_exact(8) {
                let packet: Vec<rothray::engine::Ray> = chunk.iter().map(|&o| rothray::engine::Ray::new(o, light)).collect();
                let mut out = [false; 8];
                scene.occluded_packet(&packet, &mut ps, &mut out, None);
                for k in 0..8 {
                    assert_eq!(out[k], scene.occluded(&packet[k]), "seed {seed:#x} case {case} view {view} ray {k}: {:?}", packet[k]);
                    rays += 1;
                    blocked += out[k] as usize;
                }
            }
        }
    }
    let c = rothray::csg::take_eval_counts();
    println!(
        "{rays} shadow rays, {blocked} blocked; mesh lanes from the packets' walks {}, left to their own queries {}",
        c.parallel_mesh_lanes, c.parallel_mesh_left
    );
    assert!(
        rays > 20_000 && blocked > rays / 10 && c.parallel_mesh_lanes > rays as u64 / 4,
        "too few rays, blocked rays or packet-walked lanes to test"
    );
}

#[test]
fn packet_shortcut_keeps_the_short_span_rule() {
    // Regression (found in review): a grazing ray crosses the mesh over less
    // than eps. The full evaluation drops that span in the union (its other
    // operand, a ball far behind, has spans in the range evaluated) and hits
    // the ball; the packet shortcut must not take the mesh's entry instead.
    let mesh = octa_mesh(DVec3::ZERO, 1.0, 1);
    let sphere = Shape::Sphere { c: DVec3::new(1.0, 0.0, -0.5), r: 0.25 };
    let scene = bake(&[Shape::Union(vec![sphere, mesh.clone()])]);
    remove_mesh_files(std::slice::from_ref(&mesh));
    let d = glam::Vec3::new(1e-4, 1e-4, -1.0);
    let o = glam::Vec3::new(1.0 - 1e-5, 0.0, 0.0) - d * 5.0;
    let packet: Vec<rothray::engine::Ray> =
        (0..8).map(|k| rothray::engine::Ray::new(o, d + glam::Vec3::new(k as f32 * 1e-6, (k / 4) as f32 * 1e-6, 0.0))).collect();
    let mut ps = rothray::engine::PacketScratch::default();
    let mut out = [None; 8];
    scene.intersect_packet(&packet, &mut ps, &mut out);
    let mut grazing = 0;
    for k in 0..8 {
        let one = scene.intersect(&packet[k]);
        assert_eq!(hit_key(out[k]), hit_key(one), "lane {k}: packet {:?} single {:?}", out[k], one);
        grazing += one.is_some_and(|h| h.leaf == 0) as usize;
    }
    assert!(grazing > 0, "the packet should hold grazing rays that end on the ball");
}

#[test]
fn packets_and_single_rays_match_the_full_diagram_fuzz() {
    // 40 seeds x 60 random scenes x 20 packets (wide and narrow, a fifth of
    // them starting inside the unit region): every packet lane equals the
    // single-ray hit, and that equals the first surface of the full Roth
    // diagrams. Found in review: single rays starting inside a union whose
    // first operand ended where the evaluation stopped being exact took that
    // end (fused with the second operand's cut-off span) as their exit.
    use rand::Rng;
    let (mut rays, mut inside) = (0, 0);
    for seed in 0..40u64 {
        let mut rng = SmallRng::seed_from_u64(0xabc0 + seed);
        for case in 0..60 {
            let mut trees = vec![random_tree_with(&mut rng, 3, true)];
            if case % 3 == 0 {
                trees.push(random_tree_with(&mut rng, 2, true));
            }
            let scene = bake(&trees);
            remove_mesh_files(&trees);
            let mut ps = rothray::engine::PacketScratch::default();
            for p in 0..20 {
                let (o, d) = random_ray(&mut rng);
                let packet = packet_around(o, d, if p % 4 == 0 { 0.05 } else { 0.003 * rng.gen_range(0.01..1.0) });
                let mut out = [None; 8];
                scene.intersect_packet(&packet, &mut ps, &mut out);
                for k in 0..8 {
                    let one = scene.intersect(&packet[k]);
                    let ctx = || {
                        format!(
                            "seed {:#x} case {case} packet {p} ray {k}: {:?} trees {:?}",
                            0xabc0 + seed,
                            packet[k],
                            trees.iter().map(|t| t.json()).collect::<Vec<_>>()
                        )
                    };
                    assert_eq!(hit_key(out[k]), hit_key(one), "packet vs single ray, {}", ctx());
                    inside +=
                        (0..trees.len() as u32).any(|oi| scene.spans(&packet[k], oi).first().is_some_and(|s| !s.s0.is_real())) as usize;
                    let want = nearest_in_diagrams(&scene, &packet[k], trees.len());
                    assert_eq!(one.map(|h| h.t), want, "single ray vs full diagram, {}", ctx());
                    rays += 1;
                }
            }
        }
    }
    println!("{rays} rays, {inside} starting inside an object");
    assert!(rays == 384_000 && inside > 10_000);
}

/// Nearest hit against the first surface of the full diagrams, one ray: the
/// same t, and unless two objects' first surfaces tie, the same object,
/// leaf and surface.
fn nearest_is_first_surface(scene: &RenderScene, ray: &rothray::engine::Ray, ctx: &dyn Fn() -> String) {
    nearest_is_first_surface_of(scene, scene, ray, ctx);
}

/// [`nearest_is_first_surface`] with the diagrams of `oracle` (the same
/// objects, baked another way).
fn nearest_is_first_surface_of(scene: &RenderScene, oracle: &RenderScene, ray: &rothray::engine::Ray, ctx: &dyn Fn() -> String) {
    let one = scene.intersect(ray);
    let firsts: Vec<(f32, u32, u32, u32)> = (0..oracle.objects.len() as u32)
        .filter_map(|oi| rothray::csg::first_surface(&oracle.spans(ray, oi)).map(|(t, s)| (t, oi, s.leaf_index(), s.sub)))
        .collect();
    let want = firsts.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0));
    assert_eq!(one.map(|h| h.t), want.map(|w| w.0), "nearest vs full diagram, {}", ctx());
    if let (Some(h), Some(w)) = (one, want) {
        if firsts.iter().filter(|f| f.0 == w.0).count() == 1 {
            assert_eq!((h.object, h.leaf, h.sub), (w.1, w.2, w.3), "nearest vs full diagram: surface, {}", ctx());
        }
    }
}

#[test]
fn short_first_operand_span() {
    // Regression (found by `nearest_hits_are_first_surfaces_of_random_scenes`):
    // a ray grazes a sheared box's edge over 1.1e-5, less than eps. The box is
    // the union's first operand, the torus its second. Its nearest-hit
    // query took the box's entry as the union's first, then asked the torus
    // only up to just past it (empty there): the short span stayed. The full
    // diagram merged it with the torus's span further on and dropped it
    // (short spans go), so its first surface was the torus 0.47 further. A
    // nearest-mode union now confirms no first span shorter than eps.
    let scene = bake_shape_json(
        r#"{"transformed":{"translate":[0.1180156967896604,0.2641243240929097,0.23369156044707534],"rotate_deg":[-11.477654658303067,84.72017068233015,-106.53501602178694],"scale":[0.49690345276979453,0.5297953485632014,0.9083143999046742],"shape":{"union":[{"transformed":{"translate":[-0.04499939663409236,-0.17080785570543,-0.22178182962687287],"rotate_deg":[-68.2490279080483,-28.195717869723552,72.58223901132749],"scale":[1.4959293813028807,0.9448904957534981,0.6106761459385521],"shape":{"transformed":{"matrix":[0.4112692961444526,-0.8196984205391287,0.23391842968947296,0.0038794358106269966,0.24469361185533112,2.0837160915378083,0.41525940620507695,0.2911698061917887,-0.6766377228539686,-0.6535287458300627,1.4040057861236666,0.14949276527912103,0,0,0,1],"shape":{"box":{"min":[-0.5632247329576284,-0.40735964683482817,0.6080867197210071],"max":[-0.2786194646083844,0.7915957473730122,1.5685395408959657]}}}}}},{"torus":{"center":[0.3297684758253786,0.393470751706395,0.16593692639449598],"axis":[-0.9512291028515172,-0.9013570490872185,0.1597020480497009],"major":0.8802645485466964,"minor":0.3498344250717844}}]}}}"#,
    );
    let ray =
        rothray::engine::Ray::new(glam::Vec3::new(-0.36582097, -1.4847515, 5.9353414), glam::Vec3::new(0.17979792, 0.3308626, -0.9913008));
    nearest_is_first_surface(&scene, &ray, &|| "the reproducer".into());
    let packet = [ray; 8];
    let mut ps = rothray::engine::PacketScratch::default();
    let mut out = [None; 8];
    scene.intersect_packet(&packet, &mut ps, &mut out);
    assert_eq!(hit_key(out[0]), hit_key(scene.intersect(&ray)), "packet vs single ray");
}

#[test]
fn grazing_operands_give_the_full_diagrams_first_surface() {
    // A ray crossing a box's edge over a chord from 1e-8 to 1e-3 long (eps
    // is about 1e-5 here), the box first or second in a union with a ball
    // behind it, and as the positive operand of a difference whose hole
    // lies further on. Nearest hit equals the full diagram's first surface
    // in every case; some chords are short enough to be dropped.
    let boxed = Shape::Box { min: DVec3::splat(-1.0), max: DVec3::splat(1.0) };
    // On the ray 2 past the box (its chord near s = 3, these near s = 5).
    let ball = Shape::Sphere { c: DVec3::new(3.0, 0.1, -1.0), r: 0.5 };
    let hole = Shape::Sphere { c: DVec3::new(3.0, 0.1, -1.0), r: 0.2 };
    let trees = [
        Shape::Union(vec![boxed.clone(), ball.clone()]),
        Shape::Union(vec![ball.clone(), boxed.clone()]),
        Shape::Diff(vec![Shape::Union(vec![boxed.clone(), ball.clone()]), hole.clone()]),
        Shape::Diff(vec![boxed.clone(), ball.clone()]),
    ];
    let (mut dropped, mut kept) = (0, 0);
    for (i, tree) in trees.iter().enumerate() {
        let scene = bake(std::slice::from_ref(tree));
        for j in 0..=50 {
            // The line x + z = 2 - depth in the plane y = 0.1, towards +x -z:
            // inside the box for s in [3 - depth, 3].
            let depth = 10f64.powf(-8.0 + 5.0 * j as f64 / 50.0);
            let d = DVec3::new(1.0, 0.0, -1.0);
            let o = DVec3::new(-2.0, 0.1, 4.0 - depth);
            let ray = to_ray(o, d);
            nearest_is_first_surface(&scene, &ray, &|| format!("tree {i} depth {depth:e}"));
            let spans = scene.spans(&ray, 0);
            let on_box = spans.first().is_some_and(|s| s.t1 - s.t0 < 0.1);
            if i == 0 {
                (dropped, kept) = (dropped + !on_box as u32, kept + on_box as u32);
            }
        }
    }
    println!("union with the box first: {dropped} chords dropped, {kept} kept");
    assert!(dropped > 5 && kept > 5);
}

#[test]
fn nearest_hits_are_first_surfaces_of_random_scenes() {
    // The scenes of `tests/tiles.rs` (deep trees, wide unions and
    // differences with coincident children, half-spaces, meshes), 400 000
    // rays: each ray's nearest hit is the first surface of the objects'
    // full diagrams (seed 0xac5f held `short_first_operand_span`).
    let mut rays = 0;
    for seed in 0..200u64 {
        let seed = 0xabc0 + seed;
        let mut rng = SmallRng::seed_from_u64(seed);
        let (trees, scene) = crate::tiles::random_scene(&mut rng, seed as u32, DVec3::ZERO);
        for r in 0..2000 {
            let o = rp(&mut rng, 3.0) + DVec3::new(0.0, 0.0, 4.0);
            let d = rp(&mut rng, 1.0) - o * 0.2;
            let ray = to_ray(o, d);
            nearest_is_first_surface(&scene, &ray, &|| {
                format!("seed {seed:#x} ray {r}: {ray:?} trees {:?}", trees.iter().map(|t| t.json()).collect::<Vec<_>>())
            });
            rays += 1;
        }
    }
    assert_eq!(rays, 400_000);
}

/// An OBJ mesh of two cubes, [-1,1]^3 and [3,5]x[-1,1]x[-3,-1], written to
/// the temporary folder as `name`; returns its path.
fn two_cubes_obj(name: &str) -> std::path::PathBuf {
    use std::fmt::Write;
    let mut obj = String::new();
    let mut nv = 0;
    for (lo, hi) in [(DVec3::splat(-1.0), DVec3::splat(1.0)), (DVec3::new(3.0, -1.0, -3.0), DVec3::new(5.0, 1.0, -1.0))] {
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        // Quads counter-clockwise seen from outside, split in two.
        for q in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
            writeln!(obj, "f {} {} {}", nv + q[0] + 1, nv + q[1] + 1, nv + q[2] + 1).unwrap();
            writeln!(obj, "f {} {} {}", nv + q[0] + 1, nv + q[2] + 1, nv + q[3] + 1).unwrap();
        }
        nv += 8;
    }
    let path = std::env::temp_dir().join(format!("rothray-oracle-{}-{name}.obj", std::process::id()));
    std::fs::write(&path, obj).expect("write the two-cube mesh");
    path
}

/// Nearest hit against the first surface of the full diagram for object
/// shapes given as JSON, on the rays `ray(j)`; returns the mismatches.
fn nearest_vs_diagram_on(shapes: &[String], rays: &dyn Fn(usize) -> rothray::engine::Ray, n: usize) -> Vec<String> {
    let mut bad = Vec::new();
    for (i, sh) in shapes.iter().enumerate() {
        let scene = bake_shape_json(sh);
        for j in 0..n {
            let ray = rays(j);
            let (one, want) = (scene.intersect(&ray).map(|h| h.t), nearest_in_diagrams(&scene, &ray, 1));
            if one != want {
                bad.push(format!("shape {i} ray {j}: nearest {one:?}, diagram {want:?} ({:?})", scene.spans(&ray, 0)));
            }
        }
    }
    bad
}

#[test]
fn grazed_mesh_operands() {
    // Regression: a mesh of two cubes, the ray grazing the first's edge over
    // a chord of 1e-8 to 1e-3, then crossing the second. A nearest-mode mesh
    // query stops just past its first entry: that of the short span. In a
    // union with a ball inside the second cube, or minus that ball, the ball
    // was then asked only up to there (empty), and the short span stayed;
    // the full diagram merges it with the ball and drops it (27 of 51 rays
    // each, before a leaf query that stops at a short first span was asked
    // again in full). Also the mesh alone, cut by a half-space, and
    // subtracted from a box.
    let path = two_cubes_obj("two-cubes");
    let mesh = format!("{{\"mesh\":{{\"path\":{:?}}}}}", path.to_string_lossy());
    let ball = r#"{"sphere":{"center":[4,0.1,-2],"radius":0.3}}"#;
    let boxj = r#"{"box":{"min":[-1,-1,-1],"max":[1,1,1]}}"#;
    let shapes = [
        mesh.clone(),
        format!("{{\"difference\":[{mesh},{ball}]}}"),
        format!("{{\"difference\":[{mesh},{ball},{boxj}]}}"),
        format!("{{\"union\":[{mesh},{ball}]}}"),
        format!("{{\"union\":[{ball},{mesh}]}}"),
        format!("{{\"intersection\":[{mesh},{{\"plane\":{{\"normal\":[0,1,0],\"offset\":0.5}}}}]}}"),
        format!("{{\"difference\":[{boxj},{mesh}]}}"),
    ];
    // The line x + z = 2 - depth in the plane y = 0.1, towards +x -z.
    let depth = |j: usize| 10f64.powf(-8.0 + 5.0 * j as f64 / 50.0);
    let ray = |j: usize| to_ray(DVec3::new(-2.0, 0.1, 4.0 - depth(j)), DVec3::new(1.0, 0.0, -1.0));
    let bad = nearest_vs_diagram_on(&shapes, &ray, 51);
    let _ = std::fs::remove_file(&path);
    assert!(bad.is_empty(), "{} mismatches:\n{}", bad.len(), bad.join("\n"));
}

#[test]
fn near_flush_cutter() {
    // Regression: a cube minus a union whose box's top face lies 1e-6 below
    // the cube's (and a far ball). The full diagram fuses the two entries
    // (within eps) and the cube's span then ends where the cutter's starts:
    // nothing. The nearest query asked the cutter (`Mode::Before`) only up
    // to its first entry, so the difference kept the cube's entry (51 of 51
    // rays). A subtrahend entering within 2 eps of the positive operand's
    // entry is now asked up to 4 eps past it, as a positive operand is. (The
    // same cutter as a single leaf was asked in full and agreed. Making the
    // difference's result exact only up to 4 eps before a subtrahend's stop
    // fixed these rays but broke a nested difference of meshes in
    // `packets_and_single_rays_match_the_full_diagram_fuzz`.)
    let shapes = [
        r#"{"difference":[{"box":{"min":[-1,-1,-1],"max":[1,1,1]}},{"union":[{"box":{"min":[-1.5,-1.5,-1.5],"max":[1.5,1.5,0.999999]}},{"sphere":{"center":[5,5,5],"radius":0.1}}]}]}"#.to_string(),
    ];
    let ray = |j: usize| to_ray(DVec3::new(0.1 + 1e-4 * j as f64, 0.2, 5.0), DVec3::new(0.01, 0.0, -1.0));
    let bad = nearest_vs_diagram_on(&shapes, &ray, 51);
    assert!(bad.is_empty(), "{} mismatches:\n{}", bad.len(), bad.join("\n"));
}

/// `s` with a near twin at every CSG node (probability `p`): a copy of a
/// random child moved by 1e-7 to 1e-3 (eps is about 1e-5 here), inserted
/// at a random place, so that unions, intersections and differences meet
/// near-coincident faces (a cutter nearly flush with a face).
fn with_near_twins(rng: &mut SmallRng, s: Shape, p: f64) -> Shape {
    use rand::Rng;
    let kids_of = |kids: Vec<Shape>, rng: &mut SmallRng| {
        let mut kids: Vec<Shape> = kids.into_iter().map(|k| with_near_twins(rng, k, p)).collect();
        if rng.gen_bool(p) {
            let k = rng.gen_range(0..kids.len());
            let off = rp(rng, 1.0).normalize_or_zero() * 10f64.powf(rng.gen_range(-7.0..-3.0));
            let json = format!("\"translate\":[{:?},{:?},{:?}]", off.x, off.y, off.z);
            let twin = Shape::Xf { m: glam::DAffine3::from_translation(off), json, s: Box::new(kids[k].clone()) };
            let at = rng.gen_range(0..=kids.len());
            kids.insert(at, twin);
        }
        kids
    };
    match s {
        Shape::Union(k) => Shape::Union(kids_of(k, rng)),
        Shape::Inter(k) => Shape::Inter(kids_of(k, rng)),
        Shape::Diff(k) => Shape::Diff(kids_of(k, rng)),
        Shape::Xf { m, json, s } => Shape::Xf { m, json, s: Box::new(with_near_twins(rng, *s, p)) },
        other => other,
    }
}

#[test]
fn near_twins_nearest_hits_are_first_surfaces() {
    // Random trees (meshes in every third) with a near twin of a child at
    // half of their CSG nodes, 600 rays each: each ray's nearest hit is the
    // first surface of the full diagram.
    let seed = 0xc5_9010u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut rays = 0;
    for case in 0..250 {
        let tree = random_tree_with(&mut rng, 3, case % 3 == 0);
        let tree = with_near_twins(&mut rng, tree, 0.5);
        let scene = bake(std::slice::from_ref(&tree));
        remove_mesh_files(std::slice::from_ref(&tree));
        for r in 0..600 {
            let (o, d) = random_ray(&mut rng);
            let ray = to_ray(o, d);
            nearest_is_first_surface(&scene, &ray, &|| format!("case {case} ray {r}: {ray:?} tree {}", tree.json()));
            rays += 1;
        }
    }
    assert_eq!(rays, 150_000);
}

#[test]
fn near_twin_slivers_from_inside() {
    // Regression: one of the rays that differed in a larger near-twin run
    // (1 500 trees, seed 0x77, case 1433), minimised: A = (S - T') moved by
    // 3e-5, minus B = (S - T'' - T), where S is a sphere and T', T'' are a
    // torus T moved by 2e-5. The ray starts inside S; eps is 1.3e-5 in t.
    // Full diagrams: A = [0, 0.0298685) u [0.2932449, ..), B = [0, 0.0298587)
    // u [0.2932345, ..) (T = [0.0298478, 0.2932242) enters within eps of B's
    // end and is fused into it), so A - B is a sliver under eps at each
    // end: nothing. The nearest query asked B only up to A's first span's
    // end, 0.0298685: S, T'' and T clipped there all ended at that range
    // end, within eps of B's end, and the fusing then kept T's entry:
    // B = [0, 0.0298478), and A - B = [0.0298478, 0.0298685), a hit at T.
    // A difference's later operands are now asked 4 eps past the result's
    // end in the nearest modes (`operands_end`). (In that run the fix
    // leaves the 5 rays of case 821 that differed before it, and no other.)
    let shape = r#"{"difference":[{"transformed":{"translate":[1.4786156310588637e-05,-2.748444627796021e-06,-2.4295940701135698e-05],"shape":{"difference":[{"sphere":{"center":[-0.13262931649337095,0.30432019708824365,0.18940563698396296],"radius":0.9886724441341528}},{"transformed":{"translate":[1.0552175103705918e-05,-1.0670604095630437e-05,-1.7949908196547406e-05],"shape":{"transformed":{"translate":[0.0925900248395396,-0.15690054906013207,0.012337675856428088],"rotate_deg":[139.35390960527167,19.959414251206596,166.5909797406921],"scale":[1.0277918084510544,0.5117260691586586,0.545987601712118],"shape":{"torus":{"center":[0.3943646762278983,0.17839996412504533,0.03850505129189036],"axis":[0.5497843849401289,-0.9172632860831691,-0.14681148282574163],"major":0.5097308543197512,"minor":0.42891638486794287}}}}}}]}}},{"difference":[{"sphere":{"center":[-0.13262931649337095,0.30432019708824365,0.18940563698396296],"radius":0.9886724441341528}},{"transformed":{"translate":[1.0552175103705918e-05,-1.0670604095630437e-05,-1.7949908196547406e-05],"shape":{"transformed":{"translate":[0.0925900248395396,-0.15690054906013207,0.012337675856428088],"rotate_deg":[139.35390960527167,19.959414251206596,166.5909797406921],"scale":[1.0277918084510544,0.5117260691586586,0.545987601712118],"shape":{"torus":{"center":[0.3943646762278983,0.17839996412504533,0.03850505129189036],"axis":[0.5497843849401289,-0.9172632860831691,-0.14681148282574163],"major":0.5097308543197512,"minor":0.42891638486794287}}}}}},{"transformed":{"translate":[0.0925900248395396,-0.15690054906013207,0.012337675856428088],"rotate_deg":[139.35390960527167,19.959414251206596,166.5909797406921],"scale":[1.0277918084510544,0.5117260691586586,0.545987601712118],"shape":{"torus":{"center":[0.3943646762278983,0.17839996412504533,0.03850505129189036],"axis":[0.5497843849401289,-0.9172632860831691,-0.14681148282574163],"major":0.5097308543197512,"minor":0.42891638486794287}}}}]}]}"#;
    let scene = bake_shape_json(shape);
    let ray = rothray::engine::Ray::new(
        glam::Vec3::new(0.006999917, -0.093656145, 0.41363698),
        glam::Vec3::new(1.2009127, -0.7221188, -1.9700159),
    );
    nearest_is_first_surface(&scene, &ray, &|| "the reproducer".into());
}

/// A random tree of the leaves with packet kernels (no torus), half of them
/// transformed, `depth` levels at most.
fn kernel_tree(rng: &mut SmallRng, depth: u32) -> Shape {
    use rand::Rng;
    if depth == 0 || rng.gen_bool(0.2) {
        let l = loop {
            let planes = rng.gen_bool(0.15);
            let l = random_leaf(rng, planes);
            if !matches!(l, Shape::Torus { .. }) {
                break l;
            }
        };
        return if rng.gen_bool(0.5) { random_xf(rng, l) } else { l };
    }
    let c: Vec<Shape> = (0..rng.gen_range(2..4)).map(|_| kernel_tree(rng, depth - 1)).collect();
    match rng.gen_range(0..3) {
        0 => Shape::Union(c),
        1 => Shape::Inter(c),
        _ => Shape::Diff(c),
    }
}

#[test]
fn small_trees_match_the_frame_path() {
    // Small trees (narrow nodes over analytic leaves, `Program::small_eval`)
    // against the evaluator's frames (the scene baked again with the pass
    // off): the same full diagrams bit for bit, and each nearest hit, single
    // or in a packet, is the first surface of the frame path's diagrams.
    // Trees of kernel leaves only, and general trees (tori, meshes, deeper)
    // whose subtrees may be small.
    use rand::Rng;
    let seed = 0x5a11u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut rays, mut roots) = (0, 0);
    for case in 0..300 {
        let trees: Vec<Shape> = (0..rng.gen_range(1..3))
            .map(|_| if case % 3 == 2 { random_tree_with(&mut rng, 4, true) } else { kernel_tree(&mut rng, 4) })
            .collect();
        let scene = bake(&trees);
        let mut frames = bake(&trees);
        remove_mesh_files(&trees);
        frames.without_small_trees();
        roots += scene.small_tree_roots();
        assert_eq!(frames.small_tree_roots(), 0);
        let mut ps = rothray::engine::PacketScratch::default();
        for p in 0..25 {
            let (o, d) = random_ray(&mut rng);
            let packet = packet_around(o, d, if p % 4 == 0 { 0.05 } else { 0.003 });
            let mut out = [None; 8];
            scene.intersect_packet(&packet, &mut ps, &mut out);
            for (k, ray) in packet.iter().enumerate() {
                let ctx = || {
                    format!(
                        "seed {seed:#x} case {case} packet {p} ray {k}: {ray:?} trees {:?}",
                        trees.iter().map(|t| t.json()).collect::<Vec<_>>()
                    )
                };
                for oi in 0..trees.len() as u32 {
                    assert_eq!(scene.spans(ray, oi), frames.spans(ray, oi), "full diagram, object {oi}, {}", ctx());
                }
                assert_eq!(hit_key(out[k]), hit_key(scene.intersect(ray)), "packet vs single ray, {}", ctx());
                nearest_is_first_surface_of(&scene, &frames, ray, &ctx);
                rays += 1;
            }
        }
    }
    println!("{rays} rays, {roots} small-tree roots");
    assert!(rays == 60_000 && roots > 200, "{roots} small-tree roots");
}

/// A cut onion of `levels` shells around the origin: each shell the
/// difference of a leaf and a slightly smaller copy, in a union with the
/// deeper levels, the whole cut by one or two cutters (a rotated wedge, a
/// ball, a half-space, or a near twin of the shell's inner surface).
/// Rays that enter inside a cut take the nearest query's second try
/// (`csg/src/masked.rs`).
fn cut_onion(rng: &mut rand::rngs::SmallRng, levels: usize) -> Shape {
    use rand::Rng;
    let kind = rng.gen_range(0..3);
    let leaf = |r: f64| match kind {
        0 => Shape::Sphere { c: DVec3::ZERO, r },
        1 => Shape::Box { min: DVec3::splat(-r), max: DVec3::splat(r) },
        _ => Shape::Cylinder { a: DVec3::new(0.0, -r, 0.0), b: DVec3::new(0.0, r, 0.0), r },
    };
    let mut inner: Option<Shape> = None;
    for k in (0..levels).rev() {
        let r = 0.3 + 1.5 * (levels - k) as f64 / levels as f64;
        let th = rng.gen_range(0.01..0.08);
        let shell = Shape::Diff(vec![leaf(r), leaf(r - th)]);
        let node = match inner.take() {
            None => shell,
            Some(i) if rng.gen_bool(0.2) => Shape::Union(vec![i, shell]),
            Some(i) if rng.gen_bool(0.15) => Shape::Union(vec![shell, leaf(0.1 * r), i]),
            Some(i) => Shape::Union(vec![shell, i]),
        };
        let mut parts = vec![node];
        for _ in 0..rng.gen_range(1..3) {
            let cutter = match rng.gen_range(0..4) {
                0 => {
                    // A wedge: a box corner at the centre, its floor near y = 0.
                    let y0 = rng.gen_range(-0.1..0.1);
                    let wedge = Shape::Box { min: DVec3::new(0.0, y0, 0.0), max: DVec3::splat(3.0) };
                    let a = rng.gen_range(-180.0f64..180.0);
                    let m = glam::DAffine3::from_rotation_y(a.to_radians());
                    Shape::Xf { m, json: format!("\"rotate_deg\":[0,{a:?},0]"), s: Box::new(wedge) }
                }
                1 => Shape::Sphere { c: rp(rng, 1.0).normalize() * r, r: rng.gen_range(0.2..1.0) * r },
                2 => Shape::Plane { n: rp(rng, 1.0) + DVec3::new(0.0, 0.01, 0.0), d: rng.gen_range(-0.3..0.3) },
                // The shell's inner surface again, a hair larger or smaller.
                _ => leaf(r - th + rng.gen_range(-2e-6..2e-6)),
            };
            parts.push(cutter);
        }
        inner = Some(Shape::Diff(parts));
    }
    inner.expect("levels > 0")
}

#[test]
fn second_tries_under_masks_give_the_full_diagrams_first_surface() {
    // Nearest hits on cut onions (the try under masks, which such objects
    // take at once: a union under a difference stops where its spans leave
    // the cutters above, not at its first entry) against the first surface
    // of the full diagram, bit for bit, and the surface; rays from all
    // around, aimed near the centre.
    let (mut sure, mut left, mut rays) = (0, 0, 0);
    for s in 0..160u64 {
        let seed = 0x0a5c_0000 + s;
        let mut rng = SmallRng::seed_from_u64(seed);
        let levels = 2 + (s as usize % 9);
        let tree = cut_onion(&mut rng, levels);
        let mut scene = bake(std::slice::from_ref(&tree));
        // (The sweep of the crossings would answer most rays first.)
        scene.without_deep_sweeps();
        let _ = rothray::csg::take_eval_counts();
        for r in 0..1500 {
            let o = rp(&mut rng, 1.0).normalize() * 5.0;
            let d = rp(&mut rng, 0.8) - o;
            let ray = to_ray(o, d);
            nearest_is_first_surface(&scene, &ray, &|| format!("seed {seed:#x} ray {r}: {ray:?} tree {}", tree.json()));
            rays += 1;
        }
        let c = rothray::csg::take_eval_counts();
        (sure, left) = (sure + c.masked_sure, left + c.masked_left);
    }
    println!("{rays} rays: {sure} tries under masks sure, {left} redone in full");
    assert!(sure > 30_000, "the onions' cuts should send many rays to the second try");
}

#[test]
fn deep_sweeps_give_the_full_diagrams_first_surface() {
    // The sweep of a tree's crossings (`csg/src/deep_first.rs`), asked on
    // every ray and object (not only where a nearest-mode try was unsure):
    // where it answers, its answer is the full diagram's first surface, bit
    // for bit, surface and orientation included. Random trees of every
    // leaf kind (meshes in every third), a near twin of a child at a
    // quarter of the nodes in every other (crossings within eps, where it
    // must not answer), and cut onions; rays from anywhere, inside too.
    let seed = 0xdee9_0000u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut scratch = rothray::csg::Scratch::default();
    let (mut answered, mut hits, mut declined) = (0, 0, 0);
    for case in 0..240 {
        let tree = match case % 4 {
            0 => cut_onion(&mut rng, 2 + case % 7),
            _ => random_tree_with(&mut rng, 5, case % 3 == 0),
        };
        let tree = if case % 2 == 1 { with_near_twins(&mut rng, tree, 0.25) } else { tree };
        let scene = bake(std::slice::from_ref(&tree));
        remove_mesh_files(std::slice::from_ref(&tree));
        let root = scene.objects[0].root;
        if !scene.program.deep_fits(root) {
            continue;
        }
        for r in 0..400 {
            let (o, d) = if case % 4 == 0 {
                let o = rp(&mut rng, 1.0).normalize() * 5.0;
                (o, rp(&mut rng, 0.8) - o)
            } else {
                random_ray(&mut rng)
            };
            let ray = to_ray(o, d);
            let ctx = scene.ray_ctx(&ray);
            let want = rothray::csg::first_surface(&scene.spans(&ray, 0));
            let got = match scene.program.deep_first(&scene.leaves, &ctx, root, (ray.tmin, ray.tmax), &mut scratch) {
                DeepFirst::Sure(f) => f,
                DeepFirst::Unknown => {
                    declined += 1;
                    continue;
                }
            };
            assert_eq!(
                got.map(|(t, s)| (t.to_bits(), s)),
                want.map(|(t, s)| (t.to_bits(), s)),
                "sweep vs full diagram, seed {seed:#x} case {case} ray {r}: {ray:?} tree {}",
                tree.json()
            );
            answered += 1;
            hits += got.is_some() as usize;
        }
    }
    println!("{answered} rays answered by the sweep ({hits} hits), {declined} declined");
    assert!(answered > 40_000 && hits > 10_000 && declined > 1_000, "{answered} answered, {hits} hits, {declined} declined");
}

#[test]
fn unions_of_bitten_meshes_give_the_full_diagrams_first_surface() {
    // A wide union of meshes each minus a ball over the tip that faces the
    // eye (knob_cut_union in small). A ray into a bite finds its mesh's
    // piece empty up to where the mesh's nearest query stopped (just past
    // its entry, which the ball removed); that piece is asked again in full
    // on the union's range, and the union goes on to the other pieces.
    // Nearest hits, single rays and packets, against the first surface of
    // the full diagram, bit for bit; the hits on a ball's wall (inside a
    // bite) are the case in point.
    let (mut rays, mut walls) = (0, 0);
    for s in 0..6u64 {
        let seed = 0x0b17_0000 + s;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let n = 8 + 2 * s as usize;
        let mut balls = Vec::new();
        let pieces: Vec<Shape> = (0..n)
            .map(|_| {
                let c = DVec3::new(
                    rand::Rng::gen_range(&mut rng, -1.5..1.5),
                    rand::Rng::gen_range(&mut rng, -1.0..1.0),
                    rand::Rng::gen_range(&mut rng, -1.5..0.5),
                );
                let r = rand::Rng::gen_range(&mut rng, 0.4..0.8);
                let ball = (c + DVec3::new(0.0, 0.0, r * 0.8), r * 0.5);
                balls.push(ball);
                Shape::Diff(vec![octa_mesh(c, r, 1 + s as u32 % 2), Shape::Sphere { c: ball.0, r: ball.1 }])
            })
            .collect();
        let tree = Shape::Union(pieces);
        let scene = bake(std::slice::from_ref(&tree));
        remove_mesh_files(std::slice::from_ref(&tree));
        let mut ps = rothray::engine::PacketScratch::default();
        for r in 0..400 {
            let o = DVec3::new(0.0, 0.0, 6.0) + rp(&mut rng, 0.5);
            let (c, _) = balls[r % n];
            let d = c + rp(&mut rng, 0.3) - o;
            let packet = packet_around(o, d, 0.004);
            let mut out = [None; 8];
            scene.intersect_packet(&packet, &mut ps, &mut out);
            for (k, ray) in packet.iter().enumerate() {
                let ctx = || format!("seed {seed:#x} ray {r} lane {k}: {ray:?}");
                nearest_is_first_surface(&scene, ray, &ctx);
                let one = scene.intersect(ray);
                assert_eq!(hit_key(out[k]), hit_key(one), "packet against single ray, {}", ctx());
                if let Some(h) = one {
                    let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * h.t as f64;
                    walls += balls.iter().any(|&(bc, br)| ((p - bc).length() - br).abs() < 1e-4) as usize;
                }
                rays += 1;
            }
        }
    }
    println!("{rays} rays, {walls} hits on a ball's wall");
    assert!(rays == 19_200 && walls > 2000);
}
