//! The renderer's flat pictures (no lights, one sample: each hit's pixel comes
//! from a per-leaf table, a packet without hits is written as background at
//! once) against the single-ray query pixel by pixel.

use glam::Vec3;
use rothray::engine::{encode_srgb, render, Aov, RenderScene, RenderSettings};

/// Shaded pictures of one sample a pixel, `w` x `h`, of the whole image.
fn shaded((w, h): (u32, u32), background: Vec3, lights: Vec<rothray::engine::Light>, ambient: f32) -> RenderSettings {
    RenderSettings { width: w, height: h, spp: 1, aov: Aov::Shaded, background, lights, ambient, part: rothray_engine::Part::WHOLE }
}

#[test]
fn flat_pictures_match_single_ray_hits() {
    for (name, w, h) in [("bunny", 320u32, 180u32), ("sampler", 203, 117), ("logo", 160, 90)] {
        let path = format!("{}/scenes/{name}.json", env!("CARGO_MANIFEST_DIR"));
        let sf = rothray::io::load_scene(std::path::Path::new(&path)).expect("scene");
        let scene = RenderScene::from_world(&sf.world).expect("bake");
        let bg = Vec3::new(0.2, 0.3, 0.4);
        let s = shaded((w, h), bg, vec![], 0.7);
        let img = render(&scene, &sf.camera, &s, &|_, _| {}).0;
        let rays = sf.camera.rays(w, h);
        let mut hits = 0;
        for y in 0..h {
            for x in 0..w {
                let hit = scene.intersect(&rays.ray(x as f32 + 0.5, y as f32 + 0.5));
                hits += hit.is_some() as usize;
                let want = hit.map_or(encode_srgb(bg), |h| encode_srgb(scene.leaf_info[h.leaf as usize].color * 0.7));
                let i = ((y * w + x) * 3) as usize;
                assert_eq!(img[i..i + 3], want, "{name}: pixel ({x}, {y}), hit {hit:?}");
            }
        }
        println!("{name}: {hits} of {} pixels hit", w * h);
        assert!(hits > (w * h / 20) as usize, "{name}: too few hits to mean anything");
    }
}

/// Packets change no pixel: scenes of every kind the packets serve (wide
/// unions of leaves and of small trees one or two levels deep, meshes,
/// analytic leaves solved eight at a time, small trees as objects, tori
/// that go ray by ray), shaded with shadows, rendered with packets and ray by ray
/// ([`RenderScene::set_ray_by_ray`]) are byte-identical.
#[test]
fn packets_and_ray_by_ray_render_the_same_pictures() {
    let root = env!("CARGO_MANIFEST_DIR");
    for (path, w, h) in [
        ("benches/scenes/forest.json", 240u32, 135u32),
        ("benches/scenes/forest_cut.json", 240, 135),
        ("benches/scenes/forest_deep.json", 240, 135),
        ("benches/scenes/capsules.json", 240, 135),
        ("benches/scenes/mesh_cut.json", 240, 135),
        ("benches/scenes/tori.json", 240, 135),
        ("scenes/cheese.json", 240, 135),
        ("scenes/logo.json", 240, 135),
        ("scenes/bunny.json", 160, 90),
    ] {
        let sf = rothray::io::load_scene(std::path::Path::new(&format!("{root}/{path}"))).expect("scene");
        let mut scene = RenderScene::from_world(&sf.world).expect("bake");
        let s = shaded((w, h), sf.background, sf.lights.clone(), 0.1);
        let (packets, st) = render(&scene, &sf.camera, &s, &|_, _| {});
        scene.set_ray_by_ray(true);
        let (alone, _) = render(&scene, &sf.camera, &s, &|_, _| {});
        let differ = packets.chunks(3).zip(alone.chunks(3)).filter(|(a, b)| a != b).count();
        println!("{path}: {} camera and {} shadow rays, {differ} pixels differ", st.primary_rays, st.shadow_rays);
        assert!(st.shadow_rays > 0, "{path}: no shadow rays: the lit path is not exercised");
        assert_eq!(differ, 0, "{path}: packets and ray by ray differ");
    }
}

/// Lit pictures of a dense field of objects, whose shadow bundles meet too
/// many objects to list them and go as halves (`shadow_bundle`), against
/// each pixel shaded from its single-ray hit and single-ray shadow queries
/// (no tiles), with the renderer's formulas: byte-identical. Random fields
/// of 1 500 spheres and boxes over a ground box, low resolutions (big
/// tiles, big bundles).
#[test]
fn split_shadow_bundles_match_single_ray_shading() {
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    use rothray::engine::{Ray, RenderStats};
    let seed = 0x5b1d_u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let dir = std::env::temp_dir().join(format!("rothray_split_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut split = 0;
    for case in 0..3 {
        let mut objects = vec![serde_json::json!({"name": "ground", "color": [0.5, 0.6, 0.4],
            "shape": {"box": {"min": [-12, -0.5, -12], "max": [12, 0, 12]}}})];
        for i in 0..1500 {
            let (x, y, z) = (rng.gen_range(-10.0..10.0), rng.gen_range(0.1..2.5), rng.gen_range(-10.0..10.0));
            let r: f64 = rng.gen_range(0.05..0.25);
            let shape = if i % 3 == 0 {
                serde_json::json!({"box": {"min": [x - r, y - r, z - r], "max": [x + r, y + r, z + r]}})
            } else {
                serde_json::json!({"sphere": {"center": [x, y, z], "radius": r}})
            };
            objects.push(serde_json::json!({"name": format!("o{i}"), "color": [rng.gen_range(0.2..1.0), 0.5, 0.7], "shape": shape}));
        }
        let light = [rng.gen_range(-1.0..1.0), -1.5, rng.gen_range(-1.0..1.0)];
        let sc = serde_json::json!({"name": "field", "camera": {"eye": [0, 4, 14], "target": [0, 0.5, 0], "up": [0, 1, 0], "fov_y_deg": 55},
            "image": {"width": 64, "height": 36}, "background": [0.1, 0.1, 0.2],
            "lights": [{"direction": light, "color": [1, 1, 1]}], "objects": objects});
        let path = dir.join(format!("field{case}.json"));
        std::fs::write(&path, sc.to_string()).expect("write scene");
        let sf = rothray::io::load_scene(&path).expect("scene");
        let scene = RenderScene::from_world(&sf.world).expect("bake");
        let (w, h) = ([48u32, 64, 96][case], [27u32, 36, 54][case]);
        let s = shaded((w, h), sf.background, sf.lights.clone(), 0.15);
        let (img, st): (Vec<u8>, RenderStats) = render(&scene, &sf.camera, &s, &|_, _| {});
        split += st.tiles.bundles_split;
        let rays = sf.camera.rays(w, h);
        let (mut hits, mut shadowed) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let ray = rays.ray(x as f32 + 0.5, y as f32 + 0.5);
                let c = match scene.intersect(&ray) {
                    None => s.background,
                    Some(hit) => {
                        hits += 1;
                        // `render_tile::shade_lit`, pixel by pixel.
                        let nf = if hit.normal.dot(ray.dir) > 0.0 { -hit.normal } else { hit.normal };
                        let p = ray.origin + ray.dir * hit.t;
                        let off = (scene.eps * 20.0).max(1e-4 * (1.0 + p.abs().max_element()));
                        let mut light = Vec3::splat(s.ambient);
                        for l in &s.lights {
                            let to_l = -l.direction.normalize_or_zero();
                            if nf.dot(to_l) > 0.0 {
                                if scene.occluded(&Ray::new(p + nf * off, to_l)) {
                                    shadowed += 1;
                                } else {
                                    light += l.color * nf.dot(to_l);
                                }
                            }
                        }
                        Vec3::ZERO + scene.leaf_info[hit.leaf as usize].color * light
                    }
                };
                let i = ((y * w + x) * 3) as usize;
                assert_eq!(img[i..i + 3], encode_srgb(c), "case {case}: pixel ({x}, {y})");
            }
        }
        println!("case {case}: {hits} hits, {shadowed} in shadow, {} bundles split", st.tiles.bundles_split);
        assert!(hits > (w * h / 3) as usize && shadowed > 20, "case {case}: too few hits or shadows to mean anything");
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(split > 0, "no shadow bundle was split: the halves are not exercised");
}
