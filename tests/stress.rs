//! Numerical stress: every analytic leaf kind and CSG of them, far from the
//! origin and at small and huge scales, against the f64 model of
//! `oracle.rs` fed the same f32-rounded scene and rays. Errors are relative to
//! the view distance (the camera's distance to the solid, 4 sizes here); a
//! "topology error" is a ray whose span count differs from the model's once
//! chords and gaps shorter than 1e-4 of the view are set aside.
//!
//! The table (the README's) is printed by
//! `cargo test --release --test integration stress_table -- --nocapture`.

use glam::DVec3;
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::primitives::Span;

use crate::oracle::*;

pub(crate) fn r32(x: f64) -> f64 {
    x as f32 as f64
}

pub fn rv(v: DVec3) -> DVec3 {
    v.as_vec3().as_dvec3()
}

/// The solids of one stress case, centred at `c` with size `s`, every number
/// rounded to f32 as the scene file will be read.
pub fn solids(c: DVec3, s: f64) -> Vec<(&'static str, Shape)> {
    let c = rv(c);
    let p = |x: f64, y: f64, z: f64| rv(c + DVec3::new(x, y, z) * s);
    let sphere = Shape::Sphere { c, r: r32(0.8 * s) };
    let bx = Shape::Box { min: p(-0.7, -0.5, -0.6), max: p(0.6, 0.55, 0.5) };
    let cyl = Shape::Cylinder { a: p(-0.6, -0.3, 0.2), b: p(0.5, 0.4, -0.3), r: r32(0.35 * s) };
    let cone = Shape::Cone { a: p(-0.2, -0.7, 0.1), b: p(0.3, 0.6, -0.2), ra: r32(0.55 * s), rb: 0.0 };
    let axis = rv(DVec3::new(0.3, 1.0, 0.2));
    let torus = |major: f64, minor: f64| Shape::Torus { c, axis, major: r32(major * s), minor: r32(minor * s) };
    // |p - c|_1 <= 0.8 s as 8 half-spaces: the plane offsets are large numbers far out.
    let octa = Shape::Inter(
        (0..8)
            .map(|k| {
                let n = rv(DVec3::new([1.0, -1.0][k & 1], [1.0, -1.0][(k >> 1) & 1], [1.0, -1.0][k >> 2]));
                Shape::Plane { n, d: r32(n.dot(c) + 0.8 * s) }
            })
            .collect(),
    );
    let csg = Shape::Diff(vec![
        Shape::Inter(vec![bx.clone(), sphere.clone()]),
        Shape::Cylinder { a: p(-1.0, 0.0, 0.0), b: p(1.0, 0.1, 0.0), r: r32(0.25 * s) },
        Shape::Torus { c: p(0.0, 0.3, 0.0), axis, major: r32(0.6 * s), minor: r32(0.12 * s) },
    ]);
    vec![
        ("sphere", sphere),
        ("box", bx),
        ("cylinder", cyl),
        ("cone (apex)", cone),
        ("torus", torus(0.6, 0.2)),
        ("thin torus", torus(0.7, 0.01)),
        ("spindle torus", torus(0.3, 0.5)),
        ("octahedron (8 planes)", octa),
        ("(box & sphere) - cyl - torus", csg),
    ]
}

/// Crossings of the model along `o + t d` on `[t0, t1]`: n uniform samples
/// plus the `extra` points (the engine's span midpoints, so that a chord
/// between two samples is still seen), bisected to f64 precision.
pub(crate) fn model_crossings(f: &dyn Fn(DVec3) -> bool, o: DVec3, d: DVec3, (t0, t1): (f64, f64), n: usize, extra: &[f64]) -> Vec<f64> {
    let mut ts: Vec<f64> = (0..=n).map(|k| t0 + (t1 - t0) * k as f64 / n as f64).collect();
    ts.extend(extra.iter().filter(|t| **t > t0 && **t < t1));
    ts.sort_by(f64::total_cmp);
    let mut out = vec![];
    let mut prev = (t0, f(o + d * t0));
    if prev.1 {
        out.push(t0);
    }
    for &t in &ts[1..] {
        let cur = (t, f(o + d * t));
        if cur.1 != prev.1 {
            let (mut a, mut b) = (prev.0, cur.0);
            for _ in 0..64 {
                let m = 0.5 * (a + b);
                if f(o + d * m) == prev.1 {
                    a = m
                } else {
                    b = m
                }
            }
            out.push(0.5 * (a + b));
        }
        prev = cur;
    }
    if prev.1 {
        out.push(t1);
    }
    out
}

/// Drops chords and gaps shorter than `min` (in t) from a crossing list.
pub(crate) fn robust(mut x: Vec<f64>, min: f64) -> Vec<f64> {
    loop {
        let short = (0..x.len().saturating_sub(1)).find(|&i| x[i + 1] - x[i] < min);
        match short {
            Some(i) => {
                x.drain(i..i + 2);
            }
            None => return x,
        }
    }
}

/// One stress case's figures.
#[derive(Default)]
pub struct Stats {
    pub rays: usize,
    /// Largest span end error / view over all rays with the model's span count.
    pub max_err: f64,
    /// The same over span ends of chords at least 2e-3 of the view long. A
    /// chord's end moves as 1 / its length under an error in the line's
    /// distance from the solid: a leaf traced through an f32 map (1/r in
    /// f32, 6e-8 relative) moves the ends of a chord of length L by about
    /// 6e-8 r^2 / (L / 2). Balls are traced in f64 from their f32 numbers
    /// (the sphere's short chords' ends were off by up to 8e-5 of the view).
    pub max_err_long: f64,
    /// Rays with a wrong span count, chords < 1e-4 of the view set aside.
    pub topo: usize,
    /// The same, chords < 4e-4 of the view set aside.
    pub topo4: usize,
}

/// Is the span count wrong, chords and gaps shorter than `min` set aside?
/// (A chord of `min` or more in one list that is not even half that long in
/// the other; one just over the line on one side and just under it on the
/// other is not.)
pub(crate) fn wrong_count(got: &[f64], want: &[f64], min: f64) -> bool {
    let (g, w) = (robust(got.to_vec(), min), robust(want.to_vec(), min));
    g.len() != w.len() && (g.len() > robust(want.to_vec(), 0.5 * min).len() || w.len() > robust(got.to_vec(), 0.5 * min).len())
}

/// Where one stress case looks from: its solids' centre `c` and size `s`, the
/// rays' origins `view` back from their targets, their directions' lengths
/// 10^x for x uniform in `dir_exp`; chords and gaps shorter than `chord` (a
/// length) are set aside when span counts are compared.
#[derive(Clone, Copy)]
pub struct Case {
    pub c: DVec3,
    pub s: f64,
    pub view: f64,
    pub dir_exp: (f64, f64),
    pub chord: f64,
}

impl Case {
    /// The stress table's case: viewed from 4 sizes, direction lengths 0.1 to 10.
    pub fn near(c: DVec3, s: f64) -> Case {
        Case { c, s, view: 4.0 * s, dir_exp: (-1.0, 1.0), chord: 1e-4 * (4.0 * s) }
    }
}

pub fn measure(shape: &Shape, case: &Case, seed: u64) -> Stats {
    let Case { c, s, view, dir_exp, chord } = *case;
    let scene = bake(std::slice::from_ref(shape));
    let mut rng = SmallRng::seed_from_u64(seed);
    let f = |p: DVec3| shape.inside(p);
    let mut st = Stats::default();
    for k in 0..160 {
        let dir = loop {
            let v = rp(&mut rng, 1.0);
            if v.length() > 0.2 && v.length() < 1.0 {
                break v.normalize();
            }
        };
        // A target inside the solid's region; every 4th ray grazes: its target
        // sits on the sphere of radius 0.8 s (the sphere's surface, the
        // octahedron's and box's corners' reach) and it runs tangent there.
        let (tgt, dir) = if k % 4 == 3 {
            let n = rp(&mut rng, 1.0).normalize();
            let t = n.cross(dir).normalize();
            (c + n * (0.8 * s), t)
        } else {
            (c + rp(&mut rng, 0.8 * s), dir)
        };
        let scale = 10f64.powf(rng.gen_range(dir_exp.0..dir_exp.1));
        let (o32, d32) = ((tgt - dir * view).as_vec3(), (dir * scale).as_vec3());
        let (o, d) = (o32.as_dvec3(), d32.as_dvec3());
        let ray = rothray::engine::Ray::new(o32, d32);
        let spans: Vec<Span> = scene.spans(&ray, 0);
        let got: Vec<f64> = spans.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
        // The model on the ray's stretch within 1.5 sizes of the centre.
        let dl = d.length();
        let tc = (c - o).dot(d) / (dl * dl);
        let half = 1.5 * s / dl;
        let mids: Vec<f64> = spans.iter().map(|s| 0.5 * (s.t0 as f64 + s.t1 as f64)).collect();
        let want = model_crossings(&f, o, d, ((tc - half).max(0.0), tc + half), 4000, &mids);
        let min = chord / dl;
        st.rays += 1;
        if wrong_count(&got, &want, min) {
            st.topo += 1;
            if st.topo <= 2 {
                println!("  topology: o {o32:?} d {d32:?}\n    engine {got:?}\n    model  {want:?}");
            }
        }
        st.topo4 += wrong_count(&got, &want, 4.0 * min) as usize;
        let (g, w) = (robust(got.clone(), min), robust(want.clone(), min));
        if g.len() != w.len() {
            continue;
        }
        for (i, (a, b)) in g.iter().zip(&w).enumerate() {
            let e = (a - b).abs() * dl / view;
            st.max_err = st.max_err.max(e);
            let chord = if i % 2 == 0 { w[i + 1] - w[i] } else { w[i] - w[i - 1] };
            if chord * dl >= 2e-3 * view {
                st.max_err_long = st.max_err_long.max(e);
            }
        }
    }
    st
}

/// Every kind at offsets 0..1e6 (size 1) and at sizes 1e-6..1e6 (offset 0).
fn table() -> Vec<(String, String, Stats)> {
    let seed = 0x57e5_5001u64;
    println!("seed {seed:#x}");
    let dir = DVec3::new(0.6, -0.48, 0.64);
    let mut cases: Vec<(String, DVec3, f64)> = [0.0, 1e3, 1e4, 1e5, 1e6].iter().map(|&o| (format!("offset {o:e}"), dir * o, 1.0)).collect();
    cases.extend([1e-6, 1e-3, 1e3, 1e6].iter().map(|&s| (format!("scale {s:e}"), DVec3::ZERO, s)));
    let mut rows = vec![];
    println!("| solid | where | max end error / view | same, chords >= 2e-3 view | wrong span count (chords >= 1e-4 / 4e-4 of the view) |");
    println!("|---|---|---|---|---|");
    for (ci, (label, c, s)) in cases.iter().enumerate() {
        for (ki, (name, shape)) in solids(*c, *s).into_iter().enumerate() {
            let st = measure(&shape, &Case::near(rv(*c), *s), seed + (ci * 100 + ki) as u64);
            println!("| {name} | {label} | {:.1e} | {:.1e} | {} / {} of {} |", st.max_err, st.max_err_long, st.topo, st.topo4, st.rays);
            rows.push((name.to_string(), label.clone(), st));
        }
    }
    rows
}

/// The target, up to offset 1e5 and at every scale: span ends within 1e-5 of
/// the view distance, short chords' ends included, and no wrong span count
/// once chords and gaps shorter than 1e-4 of the view are set aside (the
/// issue's target). Tangent rays of the sphere had 6 to 9 wrong counts of
/// 160 from chords of 1e-4 to 3e-4 of the view and short chords' ends off
/// by up to 8e-5 of it while the ball was traced through its f32 map.
#[test]
fn stress_table() {
    let rows = table();
    let bad: Vec<_> = rows.iter().filter(|r| !r.1.starts_with("offset 1e6")).filter(|r| r.2.max_err > 1e-5 || r.2.topo > 0).collect();
    for r in &bad {
        println!("MISSES: {} at {}: {:.2e} / {:.2e}, {} wrong counts", r.0, r.1, r.2.max_err, r.2.max_err_long, r.2.topo);
    }
    assert!(bad.is_empty(), "{} cases miss", bad.len());
}

/// The balls of the tangent test at centre `c`, size `s`: a sphere, and one
/// under a rotation and uniform scale (both traced as balls in f64), each
/// with its world centre and radius as the engine reads them (f32-rounded
/// description, f64 transforms).
fn tangent_balls(c: DVec3, s: f64) -> Vec<(&'static str, Shape, DVec3, f64)> {
    let c = rv(c);
    let plain = Shape::Sphere { c, r: r32(0.8 * s) };
    let (rot, sc) = (DVec3::new(30.0, -50.0, 70.0), 1.7 * s);
    let m = glam::DAffine3::from_translation(c)
        * glam::DAffine3::from_rotation_z(rot.z.to_radians())
        * glam::DAffine3::from_rotation_y(rot.y.to_radians())
        * glam::DAffine3::from_rotation_x(rot.x.to_radians())
        * glam::DAffine3::from_scale(DVec3::splat(sc));
    let (lc, lr) = (rv(DVec3::new(0.1, -0.2, 0.15)), r32(0.45));
    let json = format!("\"translate\":[{:?},{:?},{:?}],\"rotate_deg\":[30.0,-50.0,70.0],\"scale\":{sc:?}", c.x, c.y, c.z);
    let xf = Shape::Xf { m, json, s: Box::new(Shape::Sphere { c: lc, r: lr }) };
    vec![("sphere", plain, c, r32(0.8 * s)), ("rotated, scaled sphere", xf, m.transform_point3(lc), lr * sc)]
}

/// Where the tangent and grazing tests put their solids: `(label, centre,
/// size)` at offsets 0 to 1e5 along one direction, and at sizes 1e-6 to 1e6
/// at the origin.
pub fn tangent_places() -> Vec<(String, DVec3, f64)> {
    let dir0 = DVec3::new(0.6, -0.48, 0.64);
    let mut cases: Vec<(String, DVec3, f64)> = [0.0, 1e3, 1e4, 1e5].iter().map(|&o| (format!("offset {o:e}"), dir0 * o, 1.0)).collect();
    cases.extend([1e-6, 1e-3, 1e3, 1e6].iter().map(|&s| (format!("scale {s:e}"), DVec3::ZERO, s)));
    cases
}

/// Rays tangent to balls, far from the origin and at every scale: the f32
/// ray from 4 sizes away, aimed at a point of the surface along a tangent
/// (the f32 rounding of the ray leaves a chord of 0 to ~3e-4 of the view,
/// or a near miss). Target: the span count of the f32 inputs for every
/// chord of at least 1e-6 of the view, ends within 1e-6 of the view. With
/// the ball traced through its f32 map (1/r rounded) and f32 closest
/// approach, counts were wrong for chords up to ~3e-4 of the view
/// (stress_table: 6 to 9 rays of 160 for the sphere at 1e-4).
#[test]
fn tangent_chords() {
    let seed = 0x7a49_e175u64;
    println!("seed {seed:#x}");
    let cases = tangent_places();
    let mut bad = vec![];
    println!("| ball | where | wrong counts (chords >= 1e-6 view) | max end error / view | chords 1e-6..1e-5 / 1e-5..1e-4 / 1e-4.. of the view |");
    for (ci, (label, c, s)) in cases.iter().enumerate() {
        for (ki, (name, shape, cw, rw)) in tangent_balls(*c, *s).into_iter().enumerate() {
            let scene = bake(std::slice::from_ref(&shape));
            let f = |p: DVec3| shape.inside(p);
            let mut rng = SmallRng::seed_from_u64(seed + (ci * 10 + ki) as u64);
            let view = 4.0 * s;
            let (mut wrong, mut err, mut bands) = (0, 0f64, [0usize; 3]);
            for _ in 0..400 {
                let n = rp(&mut rng, 1.0).normalize();
                let t = n.cross(rp(&mut rng, 1.0)).normalize();
                let o32 = (cw + n * rw - t * view).as_vec3();
                let d = ((cw + n * rw) - o32.as_dvec3()).normalize() * 10f64.powf(rng.gen_range(-1.0..1.0));
                let d32 = d.as_vec3();
                let (o, d) = (o32.as_dvec3(), d32.as_dvec3());
                let spans: Vec<Span> = scene.spans(&rothray::engine::Ray::new(o32, d32), 0);
                let got: Vec<f64> = spans.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
                // The model, sampled at the line's closest approach to the
                // centre too: a chord too short for the grid is still seen.
                let dl = d.length();
                let tc = (cw - o).dot(d) / (dl * dl);
                let half = 2.0 * rw / dl;
                let mut extra: Vec<f64> = spans.iter().map(|s| 0.5 * (s.t0 as f64 + s.t1 as f64)).collect();
                extra.push(tc);
                let want = model_crossings(&f, o, d, (tc - half, tc + half), 400, &extra);
                if let [a, b] = want[..] {
                    let l = (b - a) * dl / view;
                    if l >= 1e-6 {
                        bands[(l.log10() + 6.0).floor().clamp(0.0, 2.0) as usize] += 1;
                    }
                }
                let min = 1e-6 * view / dl;
                if wrong_count(&got, &want, min) {
                    wrong += 1;
                    if wrong <= 2 {
                        println!("  wrong count: o {o32:?} d {d32:?}\n    engine {got:?}\n    model  {want:?}");
                    }
                    continue;
                }
                let (g, w) = (robust(got, min), robust(want, min));
                if g.len() == w.len() {
                    for (a, b) in g.iter().zip(&w) {
                        err = err.max((a - b).abs() * dl / view);
                    }
                }
            }
            println!("| {name} | {label} | {wrong} of 400 | {err:.1e} | {} / {} / {} |", bands[0], bands[1], bands[2]);
            if wrong > 0 || err > 1e-6 {
                bad.push(format!("{name} at {label}"));
            }
        }
    }
    assert!(bad.is_empty(), "tangent rays miss the target: {bad:?}");
}

/// Errors of a torus of major radius 1 and minor radius `ratio`, viewed from
/// 4 tube radii (`ratio` < 1) or 4 sizes, 300 rays aimed near its tube.
fn torus_ratio_stats(ratio: f64, seed: u64) -> Stats {
    let (major, minor) = (r32(1.0), r32(ratio));
    let axis = rv(DVec3::new(0.3, 1.0, 0.2));
    let shape = Shape::Torus { c: DVec3::ZERO, axis, major, minor };
    let scene = bake(std::slice::from_ref(&shape));
    let f = |p: DVec3| shape.inside(p);
    let w = axis.normalize();
    let (u, v) = (w.any_orthonormal_vector(), w.cross(w.any_orthonormal_vector()));
    let view = 4.0 * if ratio < 1.0 { minor } else { major + minor };
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut st = Stats::default();
    for _ in 0..300 {
        let a = rng.gen_range(0.0..std::f64::consts::TAU);
        let ring = (u * a.cos() + v * a.sin()) * major;
        let tgt = if ratio < 1.0 { ring + rp(&mut rng, 1.2 * minor) } else { rp(&mut rng, 1.1 * (major + minor)) };
        let dir = rp(&mut rng, 1.0).normalize();
        let (o32, d32) = ((tgt - dir * view).as_vec3(), (dir * 10f64.powf(rng.gen_range(-1.0..1.0))).as_vec3());
        let (o, d) = (o32.as_dvec3(), d32.as_dvec3());
        let spans: Vec<Span> = scene.spans(&rothray::engine::Ray::new(o32, d32), 0);
        let got: Vec<f64> = spans.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
        let dl = d.length();
        let tc = (tgt - o).dot(d) / (dl * dl);
        let half = 1.5 * view / dl;
        let mut extra: Vec<f64> = spans.iter().map(|s| 0.5 * (s.t0 as f64 + s.t1 as f64)).collect();
        extra.push(tc);
        let (lo, hi) = ((tc - half).max(0.0), tc + half);
        let want = model_crossings(&f, o, d, (lo, hi), 4000, &extra);
        // The engine's spans on the same stretch (the far side of the ring is not compared).
        let got: Vec<f64> = got.chunks(2).filter(|s| s[1] > lo && s[0] < hi).flat_map(|s| [s[0].max(lo), s[1].min(hi)]).collect();
        let min = 1e-4 * view / dl;
        st.rays += 1;
        if wrong_count(&got, &want, min) {
            st.topo += 1;
            continue;
        }
        let (g, w) = (robust(got, min), robust(want, min));
        if g.len() == w.len() {
            for (a, b) in g.iter().zip(&w) {
                st.max_err = st.max_err.max((a - b).abs() * dl / view);
            }
        }
    }
    st
}

/// Tori over the supported minor-to-major ratios (`TORUS_RATIO`, 1e-4 to
/// 1e20), viewed from 4 tube radii (thin) or 4 sizes (fat): no wrong span
/// count once chords under 1e-4 of the view are set aside, and every end
/// within 1e-5 of the view (the target). Thin tubes meet it since
/// rays are mapped to the torus's frame in f64: through the f32 map (6e-8
/// of the major radius) the ends were off by 2.6e-3 of the view at 1e-4,
/// and at 1e-5 with a wrong count.
#[test]
fn torus_ratios() {
    let seed = 0x70_0000u64;
    println!("seed {seed:#x}");
    let mut bad = vec![];
    for (k, ratio) in [1e-4, 3e-4, 1e-3, 1e-2, 0.3, 3.0, 1e3, 1e8, 1e14, 1e20].into_iter().enumerate() {
        let st = torus_ratio_stats(ratio, seed + k as u64);
        let of_major = st.max_err * 4.0 * ratio;
        let also = if ratio < 1.0 { format!(" ({of_major:.1e} of the major radius)") } else { String::new() };
        println!("ratio {ratio:e}: max end error {:.1e} of the view{also}, wrong counts {} of {}", st.max_err, st.topo, st.rays);
        let ok = st.topo == 0 && st.max_err <= 1e-5;
        if !ok {
            bad.push(ratio);
        }
    }
    assert!(bad.is_empty(), "ratios missing the target: {bad:?}");
}
