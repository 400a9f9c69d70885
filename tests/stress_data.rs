//! Numerical stress of the leaves with data: swept spheres, generalized
//! cylinders and meshes, far from the origin (1e3 to 1e5, size 1) and at
//! sizes 1e-5 to 1e4, against f64 models written here from the format's
//! definitions and fed the same f32-rounded numbers the engine reads:
//! - swept sphere: a point is inside when some ball of the chain holds it
//!   (the distance to the ball centres minimised over u: 64 samples a
//!   segment, each local minimum refined by golden section);
//! - generalized cylinder with a circle profile (any path: no frame needed):
//!   a root s of `(p - C(s)) . C'(s)` within the radius of `C(s)`;
//! - generalized cylinder with a polygon profile and twist on a planar path
//!   whose start normal is the plane's: the rotation-minimizing frame is then
//!   that normal at every s (turned by the twist), so the model knows it in
//!   closed form;
//! - mesh: an octahedron of flat faces, its vertices exact in f32 (centre on a
//!   1/8 grid, radius a power of two), classified as `|p - c|_1 <= r`.
//!
//! Errors are relative to the view distance (4 sizes), as in `stress.rs`. The
//! table: `cargo test --release --test integration stress_data -- --nocapture`.

use glam::DVec3;
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::primitives::Span;

use crate::oracle::{octa_mesh, octa_mesh_winding, remove_mesh_files, rp, Shape};
use crate::stress::{model_crossings, r32, robust, rv, wrong_count, Stats};

/// A solid with data and its f64 model.
enum Model {
    /// Swept sphere: control points `[x, y, z, r]`.
    Sweep(Vec<[f64; 4]>),
    /// Generalized cylinder with a circle profile of radius `r`.
    Tube { path: Vec<DVec3>, r: f64 },
    /// Generalized cylinder with a polygon profile, `twist` (radians) over the
    /// path, on a path in the plane normal to `n` (its start normal).
    Prism { path: Vec<DVec3>, n: DVec3, poly: Vec<[f64; 2]>, twist: f64 },
    /// Mesh octahedron (its JSON and model in `oracle::Shape::Octa`).
    Octa(Shape),
}

fn bez3(p: &[DVec3], u: f64) -> (DVec3, DVec3) {
    let v = 1.0 - u;
    let c = p[0] * (v * v * v) + p[1] * (3.0 * v * v * u) + p[2] * (3.0 * v * u * u) + p[3] * (u * u * u);
    let d = (p[1] - p[0]) * (3.0 * v * v) + (p[2] - p[1]) * (6.0 * v * u) + (p[3] - p[2]) * (3.0 * u * u);
    (c, d)
}

fn v3(p: DVec3) -> String {
    format!("[{:?},{:?},{:?}]", p.x, p.y, p.z)
}

/// The roots in [0, 1] of `(p - C(u)) . C'(u)` on one cubic segment (64
/// samples, bisected), with `C(u)` and `C'(u)` there.
fn foot_points(seg: &[DVec3], p: DVec3, out: &mut Vec<(f64, DVec3, DVec3)>) {
    let h = |u: f64| {
        let (c, d) = bez3(seg, u);
        (p - c).dot(d)
    };
    const N: usize = 64;
    let mut prev = (0.0, h(0.0));
    for k in 1..=N {
        let u = k as f64 / N as f64;
        let cur = (u, h(u));
        if (prev.1 <= 0.0) != (cur.1 <= 0.0) || prev.1 == 0.0 {
            let (mut a, mut b) = (prev.0, cur.0);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if (h(m) <= 0.0) == (prev.1 <= 0.0) {
                    a = m
                } else {
                    b = m
                }
            }
            let u = 0.5 * (a + b);
            let (c, d) = bez3(seg, u);
            out.push((u, c, d));
        }
        prev = cur;
    }
}

fn in_polygon(poly: &[[f64; 2]], x: f64, y: f64) -> bool {
    let mut inside = false;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a[1] > y) != (b[1] > y) && x < a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            inside = !inside;
        }
    }
    inside
}

impl Model {
    fn inside(&self, p: DVec3) -> bool {
        match self {
            Model::Sweep(pts) => {
                // The chain lies in its control points' hull, each radius under the largest.
                let rmax = pts.iter().fold(0.0f64, |a, q| a.max(q[3]));
                let lo = pts.iter().fold(DVec3::INFINITY, |a, q| a.min(DVec3::new(q[0], q[1], q[2])));
                let hi = pts.iter().fold(DVec3::NEG_INFINITY, |a, q| a.max(DVec3::new(q[0], q[1], q[2])));
                if p.cmplt(lo - rmax).any() || p.cmpgt(hi + rmax).any() {
                    return false;
                }
                pts.windows(4).step_by(3).any(|seg| {
                    let xyz: Vec<DVec3> = seg.iter().map(|q| DVec3::new(q[0], q[1], q[2])).collect();
                    let g = |u: f64| {
                        let v = 1.0 - u;
                        let w = [v * v * v, 3.0 * v * v * u, 3.0 * v * u * u, u * u * u];
                        let r: f64 = (0..4).map(|i| w[i] * seg[i][3]).sum();
                        bez3(&xyz, u).0.distance(p) - r
                    };
                    const N: usize = 64;
                    let gs: Vec<f64> = (0..=N).map(|k| g(k as f64 / N as f64)).collect();
                    (0..=N).any(|k| {
                        if gs[k] <= 0.0 {
                            return true;
                        }
                        let local_min = (k == 0 || gs[k] <= gs[k - 1]) && (k == N || gs[k] <= gs[k + 1]);
                        if !local_min {
                            return false;
                        }
                        // Golden section on the neighbouring samples.
                        let (mut a, mut b) = ((k.max(1) - 1) as f64 / N as f64, (k + 1).min(N) as f64 / N as f64);
                        let phi = 0.5 * (5f64.sqrt() - 1.0);
                        for _ in 0..60 {
                            let (x1, x2) = (b - phi * (b - a), a + phi * (b - a));
                            if g(x1) <= 0.0 || g(x2) <= 0.0 {
                                return true;
                            }
                            if g(x1) < g(x2) {
                                b = x2
                            } else {
                                a = x1
                            }
                        }
                        g(0.5 * (a + b)) <= 0.0
                    })
                })
            }
            Model::Tube { path, r } => {
                let mut feet = vec![];
                for seg in path.windows(4).step_by(3) {
                    foot_points(seg, p, &mut feet);
                }
                feet.iter().any(|(_, c, _)| c.distance_squared(p) <= r * r)
            }
            Model::Prism { path, n, poly, twist } => {
                let segs = path.len() / 3;
                let mut feet = vec![];
                for (i, seg) in path.windows(4).step_by(3).enumerate() {
                    let start = feet.len();
                    foot_points(seg, p, &mut feet);
                    for f in &mut feet[start..] {
                        f.0 = (i as f64 + f.0) / segs as f64;
                    }
                }
                feet.iter().any(|&(s, c, d)| {
                    let t = d.normalize();
                    let (x0, y0) = (*n, t.cross(*n));
                    let (sn, cs) = (twist * s).sin_cos();
                    let x = x0 * cs + y0 * sn;
                    let y = t.cross(x);
                    in_polygon(poly, (p - c).dot(x), (p - c).dot(y))
                })
            }
            Model::Octa(s) => s.inside(p),
        }
    }

    fn json(&self) -> String {
        match self {
            Model::Sweep(pts) => {
                let pts: Vec<String> = pts.iter().map(|q| format!("[{:?},{:?},{:?},{:?}]", q[0], q[1], q[2], q[3])).collect();
                format!("{{\"swept_sphere\":{{\"bezier\":[{}]}}}}", pts.join(","))
            }
            Model::Tube { path, r } => {
                let pts: Vec<String> = path.iter().map(|p| v3(*p)).collect();
                format!("{{\"generalized_cylinder\":{{\"path\":[{}],\"profile\":{{\"circle\":{r:?}}}}}}}", pts.join(","))
            }
            Model::Prism { path, n, poly, twist } => {
                let pts: Vec<String> = path.iter().map(|p| v3(*p)).collect();
                let pg: Vec<String> = poly.iter().map(|q| format!("[{:?},{:?}]", q[0], q[1])).collect();
                format!(
                    "{{\"generalized_cylinder\":{{\"path\":[{}],\"profile\":{{\"polygon\":[{}]}},\"normal\":{},\"twist_deg\":{:?}}}}}",
                    pts.join(","),
                    pg.join(","),
                    v3(*n),
                    twist.to_degrees() as f32
                )
            }
            Model::Octa(s) => s.json(),
        }
    }
}

/// The solids of one case, centred near `c` with size `s`, every number
/// rounded to f32 as the scene file will be read.
fn solids(c: DVec3, s: f64) -> Vec<(&'static str, Model)> {
    let c = rv(c);
    // A non-planar chain of two segments, tangent-continuous in its design
    // (f32 rounding leaves a kink of ~1e-7 rad), and its planar shadow.
    let xyz =
        [[-0.7, -0.3, 0.1], [-0.4, 0.4, 0.3], [-0.1, 0.3, -0.2], [0.1, 0.0, -0.1], [0.3, -0.3, 0.0], [0.5, -0.2, 0.4], [0.7, 0.3, 0.2]];
    let radii = [0.15, 0.2, 0.1, 0.18, 0.26, 0.12, 0.2];
    let at = |q: [f64; 3], z: bool| rv(c + DVec3::new(q[0], q[1], if z { q[2] } else { 0.0 }) * s);
    let sweep = Model::Sweep(
        xyz.iter()
            .zip(radii)
            .map(|(q, r)| {
                let p = at(*q, true);
                [p.x, p.y, p.z, r32(r * s)]
            })
            .collect(),
    );
    let tube = Model::Tube { path: xyz.iter().map(|q| at(*q, true)).collect(), r: r32(0.15 * s) };
    let poly =
        [[0.12, -0.06], [0.12, 0.06], [-0.12, 0.06], [-0.12, -0.06], [0.0, -0.1]].iter().map(|q| [r32(q[0] * s), r32(q[1] * s)]).collect();
    let prism = Model::Prism { path: xyz.iter().map(|q| at(*q, false)).collect(), n: DVec3::Z, poly, twist: (40f32 as f64).to_radians() };
    // The octahedron: exact in f32 (see the module docs).
    let (oc, or) = if c == DVec3::ZERO { (c, 2f64.powi((0.8 * s).log2().floor() as i32)) } else { ((c * 8.0).round() / 8.0, 1.0) };
    let octa = Model::Octa(octa_mesh(oc, or, 2));
    let octa_w = Model::Octa(octa_mesh_winding(oc, or, 2));
    vec![
        ("swept sphere", sweep),
        ("gen. cylinder, circle", tube),
        ("gen. cylinder, polygon + twist", prism),
        ("mesh octahedron", octa),
        ("mesh octahedron, winding rule", octa_w),
    ]
}

/// Like `stress::measure`, for a solid with data: 160 rays from 4 sizes away
/// at targets within 0.8 sizes of `c` (every 4th, for the mesh, at a vertex
/// or an edge's midpoint), direction lengths 0.1 to 10.
fn measure(m: &Model, c: DVec3, s: f64, seed: u64) -> (Stats, usize) {
    let json = format!("{{\"camera\":{{\"eye\":[0,0,6],\"target\":[0,0,0],\"up\":[0,1,0],\"fov_y_deg\":40}},\"objects\":[{{\"name\":\"o\",\"shape\":{}}}]}}", m.json());
    let opts = rothray::io::LoadOptions { allow_paths: vec![std::env::temp_dir()] };
    let sf = rothray::io::parse_scene_with(&json, std::path::Path::new("test.json"), &opts).expect("scene parses");
    let scene = rothray::engine::RenderScene::from_world(&sf.world).expect("scene bakes");
    let view = 4.0 * s;
    let c = rv(c);
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut st = Stats::default();
    let mut hits = 0;
    for k in 0..160 {
        let dir = loop {
            let v = rp(&mut rng, 1.0);
            if v.length() > 0.2 && v.length() < 1.0 {
                break v.normalize();
            }
        };
        let tgt = match m {
            Model::Octa(Shape::Octa { c, r, .. }) if k % 4 == 3 => {
                let (i, j) = (rng.gen_range(0..3), rng.gen_range(0..3));
                let mut e = |i: usize| DVec3::AXES[i] * if rng.gen_bool(0.5) { *r } else { -*r };
                let (a, b) = (e(i), e(j));
                *c + if i == j { a } else { 0.5 * (a + b) }
            }
            _ => c + rp(&mut rng, 0.8 * s),
        };
        let scale = 10f64.powf(rng.gen_range(-1.0..1.0));
        let (o32, d32) = ((tgt - dir * view).as_vec3(), (dir * scale).as_vec3());
        let (o, d) = (o32.as_dvec3(), d32.as_dvec3());
        let spans: Vec<Span> = scene.spans(&rothray::engine::Ray::new(o32, d32), 0);
        let got: Vec<f64> = spans.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
        let dl = d.length();
        let tc = (c - o).dot(d) / (dl * dl);
        let half = 1.6 * s / dl;
        let mids: Vec<f64> = spans.iter().map(|s| 0.5 * (s.t0 as f64 + s.t1 as f64)).collect();
        let want = model_crossings(&|p| m.inside(p), o, d, ((tc - half).max(0.0), tc + half), 2000, &mids);
        let min = 1e-4 * view / dl;
        st.rays += 1;
        hits += !want.is_empty() as usize;
        if wrong_count(&got, &want, min) {
            st.topo += 1;
            if st.topo <= 2 {
                println!("  wrong count: o {o32:?} d {d32:?}\n    engine {got:?}\n    model  {want:?}");
            }
            continue;
        }
        let (g, w) = (robust(got, min), robust(want, min));
        if g.len() == w.len() {
            for (a, b) in g.iter().zip(&w) {
                let e = (a - b).abs() * dl / view;
                // A mesh end where the ray runs within 1e-2 rad of the face's
                // plane: counted apart (an f32 error across the face is
                // stretched along the ray by 1 / sin; mesh ends are refined
                // in f64 from their triangle's plane).
                let sin = match m {
                    Model::Octa(Shape::Octa { c, .. }) => {
                        let n = (o + d * b - *c).signum();
                        (n.dot(d) / (n.length() * dl)).abs()
                    }
                    _ => 1.0,
                };
                if sin < 1e-2 {
                    st.max_err_long = st.max_err_long.max(e);
                } else {
                    st.max_err = st.max_err.max(e);
                }
            }
        }
    }
    if let Model::Octa(s) = m {
        remove_mesh_files(std::slice::from_ref(s));
    }
    (st, hits)
}

/// The target of issue 15 for solids with data, at offsets 1e3 to 1e5 and
/// sizes 1e-5 to 1e4: span ends within 1e-5 of the view, no wrong span count
/// once chords and gaps under 1e-4 of the view are set aside; a mesh end
/// where the ray runs within 1e-2 rad of the face within 1e-6 of the view
/// (its t refined in f64 from the triangle's plane: with the f32 triangle
/// test's own t it was 1.6e-5 of the view at 8e-4 rad, size 1e2).
#[test]
fn stress_data() {
    let seed = 0x57e5_da7au64;
    println!("seed {seed:#x}");
    let dir = DVec3::new(0.6, -0.48, 0.64);
    let mut cases: Vec<(String, DVec3, f64)> = [0.0, 1e3, 1e4, 1e5].iter().map(|&o| (format!("offset {o:e}"), dir * o, 1.0)).collect();
    cases.extend([1e-5, 1e-2, 1e2, 1e4].iter().map(|&s| (format!("scale {s:e}"), DVec3::ZERO, s)));
    println!("| solid | where | max end error / view | mesh ends grazing a face (sin < 1e-2): max error / view | wrong span count |");
    println!("|---|---|---|---|---|");
    let mut bad = vec![];
    for (ci, (label, c, s)) in cases.iter().enumerate() {
        for (ki, (name, m)) in solids(*c, *s).into_iter().enumerate() {
            let (st, hits) = measure(&m, *c, *s, seed + (ci * 10 + ki) as u64);
            let graze = if st.max_err_long > 0.0 { format!("{:.1e}", st.max_err_long) } else { "-".into() };
            println!("| {name} | {label} | {:.1e} | {graze} | {} of {} ({hits} hit) |", st.max_err, st.topo, st.rays);
            if st.max_err > 1e-5 || st.max_err_long > 1e-6 || st.topo > 0 {
                bad.push(format!("{name} at {label}"));
            }
        }
    }
    assert!(bad.is_empty(), "{} cases miss: {bad:?}", bad.len());
}
