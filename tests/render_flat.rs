//! The renderer's flat pictures (no lights, one sample: each hit's pixel comes
//! from a per-leaf table, a packet without hits is written as background at
//! once) against the single-ray query pixel by pixel.

use glam::Vec3;
use rothray::engine::{encode_srgb, render, Aov, RenderScene, RenderSettings};

#[test]
fn flat_pictures_match_single_ray_hits() {
    for (name, w, h) in [("bunny", 320u32, 180u32), ("sampler", 203, 117), ("logo", 160, 90)] {
        let path = format!("{}/scenes/{name}.json", env!("CARGO_MANIFEST_DIR"));
        let sf = rothray::io::load_scene(std::path::Path::new(&path)).expect("scene");
        let scene = RenderScene::from_world(&sf.world).expect("bake");
        let bg = Vec3::new(0.2, 0.3, 0.4);
        let s = RenderSettings {
            width: w,
            height: h,
            spp: 1,
            aov: Aov::Shaded,
            background: bg,
            lights: vec![],
            ambient: 0.7,
            part: rothray_engine::Part::WHOLE,
        };
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
        let s = RenderSettings {
            width: w,
            height: h,
            spp: 1,
            aov: Aov::Shaded,
            background: sf.background,
            lights: sf.lights.clone(),
            ambient: 0.1,
            part: rothray_engine::Part::WHOLE,
        };
        let (packets, st) = render(&scene, &sf.camera, &s, &|_, _| {});
        scene.set_ray_by_ray(true);
        let (alone, _) = render(&scene, &sf.camera, &s, &|_, _| {});
        let differ = packets.chunks(3).zip(alone.chunks(3)).filter(|(a, b)| a != b).count();
        println!("{path}: {} camera and {} shadow rays, {differ} pixels differ", st.primary_rays, st.shadow_rays);
        assert!(st.shadow_rays > 0, "{path}: no shadow rays: the lit path is not exercised");
        assert_eq!(differ, 0, "{path}: packets and ray by ray differ");
    }
}
