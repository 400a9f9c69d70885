//! An independent f64 model of the scene format: point classification of every
//! leaf kind and of CSG trees, written from the format's definitions (not from
//! the engine's code), plus random scene generators and a span checker.

use glam::{DAffine3, DVec3};
use rand::{rngs::SmallRng, Rng};
use rothray::engine::{Ray, RenderScene};
use rothray::primitives::Span;
use std::fmt::Write;

#[derive(Clone, Debug)]
pub enum Shape {
    Sphere {
        c: DVec3,
        r: f64,
    },
    Box {
        min: DVec3,
        max: DVec3,
    },
    Cylinder {
        a: DVec3,
        b: DVec3,
        r: f64,
    },
    Cone {
        a: DVec3,
        b: DVec3,
        ra: f64,
        rb: f64,
    },
    Torus {
        c: DVec3,
        axis: DVec3,
        major: f64,
        minor: f64,
    },
    Plane {
        n: DVec3,
        d: f64,
    },
    /// A triangle mesh (OBJ file at `path`) of the octahedron `|p - c|_1 <= r`,
    /// its faces subdivided: flat, so the model classifies it exactly.
    Octa {
        c: DVec3,
        r: f64,
        path: String,
        /// Imported with `"inside": "winding"` (the generalized winding
        /// number) instead of the default orientation rule: the same solid.
        winding: bool,
    },
    Union(Vec<Shape>),
    Inter(Vec<Shape>),
    Diff(Vec<Shape>),
    Xf {
        m: DAffine3,
        json: String,
        s: Box<Shape>,
    },
}

fn v(x: DVec3) -> String {
    format!("[{:?},{:?},{:?}]", x.x, x.y, x.z)
}

impl Shape {
    /// Point classification (boundary = inside, to within rounding).
    pub fn inside(&self, p: DVec3) -> bool {
        match self {
            Shape::Sphere { c, r } => (p - *c).length_squared() <= r * r,
            Shape::Box { min, max } => p.cmpge(*min).all() && p.cmple(*max).all(),
            Shape::Cylinder { a, b, r } => {
                let ax = *b - *a;
                let h = (p - *a).dot(ax) / ax.length_squared();
                let radial = (p - *a) - ax * h;
                (0.0..=1.0).contains(&h) && radial.length_squared() <= r * r
            }
            Shape::Cone { a, b, ra, rb } => {
                let ax = *b - *a;
                let h = (p - *a).dot(ax) / ax.length_squared();
                let radial = (p - *a) - ax * h;
                let r = ra + (rb - ra) * h;
                (0.0..=1.0).contains(&h) && radial.length() <= r
            }
            Shape::Torus { c, axis, major, minor } => {
                let w = axis.normalize();
                let q = p - *c;
                let z = q.dot(w);
                let rad = (q - w * z).length();
                (rad - major).powi(2) + z * z <= minor * minor
            }
            Shape::Plane { n, d } => n.dot(p) <= *d,
            Shape::Octa { c, r, .. } => (p - *c).abs().element_sum() <= *r,
            Shape::Union(c) => c.iter().any(|s| s.inside(p)),
            Shape::Inter(c) => c.iter().all(|s| s.inside(p)),
            Shape::Diff(c) => c[0].inside(p) && !c[1..].iter().any(|s| s.inside(p)),
            Shape::Xf { m, s, .. } => s.inside(m.inverse().transform_point3(p)),
        }
    }

    /// The same solid moved by `-by`, for the model only (its `json` is
    /// not moved). With `by` an f32 point near the solid, every f32 number
    /// of the scene and of a ray moves exactly, and the model's points lose
    /// 1e-16 of the solid's size instead of 1e-16 of its distance from the
    /// origin (a ray at 3e-8 rad to a cap 1e3 out: 3e-6 of the size).
    pub fn moved(&self, by: DVec3) -> Shape {
        let all = |c: &[Shape]| c.iter().map(|s| s.moved(by)).collect();
        match self {
            Shape::Sphere { c, r } => Shape::Sphere { c: *c - by, r: *r },
            Shape::Box { min, max } => Shape::Box { min: *min - by, max: *max - by },
            Shape::Cylinder { a, b, r } => Shape::Cylinder { a: *a - by, b: *b - by, r: *r },
            Shape::Cone { a, b, ra, rb } => Shape::Cone { a: *a - by, b: *b - by, ra: *ra, rb: *rb },
            Shape::Torus { c, axis, major, minor } => Shape::Torus { c: *c - by, axis: *axis, major: *major, minor: *minor },
            Shape::Plane { n, d } => Shape::Plane { n: *n, d: d - n.dot(by) },
            Shape::Octa { c, r, path, winding } => Shape::Octa { c: *c - by, r: *r, path: path.clone(), winding: *winding },
            Shape::Union(c) => Shape::Union(all(c)),
            Shape::Inter(c) => Shape::Inter(all(c)),
            Shape::Diff(c) => Shape::Diff(all(c)),
            Shape::Xf { m, json, s } => {
                Shape::Xf { m: DAffine3::from_mat3_translation(m.matrix3, m.translation - by), json: json.clone(), s: s.clone() }
            }
        }
    }

    pub fn json(&self) -> String {
        match self {
            Shape::Sphere { c, r } => format!("{{\"sphere\":{{\"center\":{},\"radius\":{r:?}}}}}", v(*c)),
            Shape::Box { min, max } => format!("{{\"box\":{{\"min\":{},\"max\":{}}}}}", v(*min), v(*max)),
            Shape::Cylinder { a, b, r } => {
                format!("{{\"cylinder\":{{\"a\":{},\"b\":{},\"radius\":{r:?}}}}}", v(*a), v(*b))
            }
            Shape::Cone { a, b, ra, rb } => {
                format!("{{\"cone\":{{\"a\":{},\"b\":{},\"radius_a\":{ra:?},\"radius_b\":{rb:?}}}}}", v(*a), v(*b))
            }
            Shape::Torus { c, axis, major, minor } => {
                format!("{{\"torus\":{{\"center\":{},\"axis\":{},\"major\":{major:?},\"minor\":{minor:?}}}}}", v(*c), v(*axis))
            }
            Shape::Plane { n, d } => format!("{{\"plane\":{{\"normal\":{},\"offset\":{d:?}}}}}", v(*n)),
            Shape::Octa { path, winding: false, .. } => format!("{{\"mesh\":{{\"path\":{path:?}}}}}"),
            Shape::Octa { path, winding: true, .. } => format!("{{\"mesh\":{{\"path\":{path:?},\"inside\":\"winding\"}}}}"),
            Shape::Union(c) | Shape::Inter(c) | Shape::Diff(c) => {
                let k = match self {
                    Shape::Union(_) => "union",
                    Shape::Inter(_) => "intersection",
                    _ => "difference",
                };
                let mut s = format!("{{\"{k}\":[");
                for (i, x) in c.iter().enumerate() {
                    if i > 0 {
                        s.push(',');
                    }
                    s.push_str(&x.json());
                }
                s.push_str("]}");
                s
            }
            Shape::Xf { json, s, .. } => format!("{{\"transformed\":{{{json},\"shape\":{}}}}}", s.json()),
        }
    }
}

/// Random point in a cube of half size `h`.
pub fn rp(rng: &mut SmallRng, h: f64) -> DVec3 {
    DVec3::new(rng.gen_range(-h..h), rng.gen_range(-h..h), rng.gen_range(-h..h))
}

/// A random leaf of size about 1 near the origin (planes only if `planes`).
pub fn random_leaf(rng: &mut SmallRng, planes: bool) -> Shape {
    let kinds = if planes { 6 } else { 5 };
    match rng.gen_range(0..kinds) {
        0 => Shape::Sphere { c: rp(rng, 0.5), r: rng.gen_range(0.2..1.0) },
        1 => {
            let a = rp(rng, 0.8);
            let b = a + DVec3::new(rng.gen_range(0.1..1.2), rng.gen_range(0.1..1.2), rng.gen_range(0.1..1.2));
            Shape::Box { min: a, max: b }
        }
        2 => Shape::Cylinder { a: rp(rng, 0.8), b: rp(rng, 0.8) + DVec3::splat(0.05), r: rng.gen_range(0.1..0.6) },
        3 => {
            let (mut ra, mut rb) = (rng.gen_range(0.0..0.7), rng.gen_range(0.0..0.7));
            if rng.gen_bool(0.3) {
                ra = 0.0;
            } else if rng.gen_bool(0.3) {
                rb = 0.0;
            }
            if ra + rb < 0.05 {
                rb = 0.3;
            }
            Shape::Cone { a: rp(rng, 0.8), b: rp(rng, 0.8) + DVec3::splat(0.05), ra, rb }
        }
        4 => {
            let major = rng.gen_range(0.3..0.9);
            let minor = if rng.gen_bool(0.2) { rng.gen_range(0.01..0.05) } else { rng.gen_range(0.05..0.5) };
            Shape::Torus { c: rp(rng, 0.4), axis: rp(rng, 1.0) + DVec3::new(0.0, 0.01, 0.0), major, minor }
        }
        _ => Shape::Plane { n: rp(rng, 1.0) + DVec3::new(0.0, 0.01, 0.0), d: rng.gen_range(-0.5..0.5) },
    }
}

/// Wraps a shape in a random transform (rotation, non-uniform scale, translation, or a matrix with shear).
pub fn random_xf(rng: &mut SmallRng, s: Shape) -> Shape {
    if rng.gen_bool(0.3) {
        // A general matrix with shear.
        let mut m = glam::DMat3::from_cols(rp(rng, 1.0), rp(rng, 1.0), rp(rng, 1.0));
        m += glam::DMat3::IDENTITY * 1.2;
        if m.determinant().abs() < 0.2 {
            m = glam::DMat3::IDENTITY;
        }
        let t = rp(rng, 0.3);
        let a = DAffine3::from_mat3_translation(m, t);
        let r = |i: usize| m.row(i);
        let json = format!(
            "\"matrix\":[{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},0,0,0,1]",
            r(0).x,
            r(0).y,
            r(0).z,
            t.x,
            r(1).x,
            r(1).y,
            r(1).z,
            t.y,
            r(2).x,
            r(2).y,
            r(2).z,
            t.z
        );
        return Shape::Xf { m: a, json, s: Box::new(s) };
    }
    let t = rp(rng, 0.3);
    let rot = DVec3::new(rng.gen_range(-180.0..180.0), rng.gen_range(-180.0..180.0), rng.gen_range(-180.0..180.0));
    let sc = DVec3::new(rng.gen_range(0.4..1.6), rng.gen_range(0.4..1.6), rng.gen_range(0.4..1.6));
    let m = DAffine3::from_translation(t)
        * DAffine3::from_rotation_z(rot.z.to_radians())
        * DAffine3::from_rotation_y(rot.y.to_radians())
        * DAffine3::from_rotation_x(rot.x.to_radians())
        * DAffine3::from_scale(sc);
    let json = format!("\"translate\":{},\"rotate_deg\":{},\"scale\":{}", v(t), v(rot), v(sc));
    Shape::Xf { m, json, s: Box::new(s) }
}

/// The octahedron `|p - c|_1 <= r` as an OBJ file (each face split into
/// `4^levels` triangles), written to the temp directory.
pub fn octa_mesh(c: DVec3, r: f64, levels: u32) -> Shape {
    static COUNT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("rothray-oracle-{}-{k}.obj", std::process::id()));
    let mut obj = String::new();
    let mut nv = 0;
    let n = 1usize << levels;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0f64, 1.0] {
                // Face corners on the axes; counter-clockwise seen from outside.
                let (a, mut b, mut cc) = (DVec3::new(sx, 0.0, 0.0), DVec3::new(0.0, sy, 0.0), DVec3::new(0.0, 0.0, sz));
                if sx * sy * sz < 0.0 {
                    std::mem::swap(&mut b, &mut cc);
                }
                // Integer weights: a vertex on a shared edge is bit-identical on both faces.
                let p = |i: usize, j: usize| c + (a * (n - i - j) as f64 + b * i as f64 + cc * j as f64) * (r / n as f64);
                let mut idx = std::collections::HashMap::new();
                for i in 0..=n {
                    for j in 0..=n - i {
                        let q = p(i, j);
                        writeln!(obj, "v {:?} {:?} {:?}", q.x, q.y, q.z).unwrap();
                        nv += 1;
                        idx.insert((i, j), nv);
                    }
                }
                for i in 0..n {
                    for j in 0..n - i {
                        writeln!(obj, "f {} {} {}", idx[&(i, j)], idx[&(i + 1, j)], idx[&(i, j + 1)]).unwrap();
                        if i + j + 1 < n {
                            writeln!(obj, "f {} {} {}", idx[&(i + 1, j)], idx[&(i + 1, j + 1)], idx[&(i, j + 1)]).unwrap();
                        }
                    }
                }
            }
        }
    }
    std::fs::write(&path, obj).expect("write the octahedron mesh");
    Shape::Octa { c, r, path: path.to_string_lossy().into_owned(), winding: false }
}

/// [`octa_mesh`] imported under the winding rule (`"inside": "winding"`).
pub fn octa_mesh_winding(c: DVec3, r: f64, levels: u32) -> Shape {
    match octa_mesh(c, r, levels) {
        Shape::Octa { c, r, path, .. } => Shape::Octa { c, r, path, winding: true },
        _ => unreachable!("octa_mesh makes an octahedron"),
    }
}

/// Deletes the mesh files [`octa_mesh`] wrote in this process.
pub fn remove_mesh_files(shapes: &[Shape]) {
    // Only these shapes' own files: tests run in parallel threads of one process,
    // so removing every file of the process could pull one from under a test that
    // has not baked it yet.
    for s in shapes {
        let json = s.json();
        for part in json.split("\"path\":").skip(1) {
            if let Some(path) = part.strip_prefix('"').and_then(|r| r.split('"').next()) {
                let _ = std::fs::remove_file(path);
            }
        }
    }
}

/// A random CSG tree of the given depth.
pub fn random_tree(rng: &mut SmallRng, depth: u32) -> Shape {
    random_tree_with(rng, depth, false)
}

/// [`random_tree`], with octahedron meshes among the leaves when `meshes`.
pub fn random_tree_with(rng: &mut SmallRng, depth: u32, meshes: bool) -> Shape {
    if depth == 0 || rng.gen_bool(0.25) {
        let planes = rng.gen_bool(0.1);
        let l = if meshes && rng.gen_bool(0.4) {
            octa_mesh(rp(rng, 0.5), rng.gen_range(0.3..1.2), rng.gen_range(0..4))
        } else {
            random_leaf(rng, planes)
        };
        return if rng.gen_bool(0.5) { random_xf(rng, l) } else { l };
    }
    let n = rng.gen_range(1..4);
    let c: Vec<Shape> = (0..n).map(|_| random_tree_with(rng, depth - 1, meshes)).collect();
    let s = match rng.gen_range(0..3) {
        0 => Shape::Union(c),
        1 => Shape::Inter(c),
        _ => Shape::Diff(c),
    };
    if rng.gen_bool(0.3) {
        random_xf(rng, s)
    } else {
        s
    }
}

/// A scene JSON with the given objects.
pub fn scene_json(objects: &[Shape]) -> String {
    let mut s = String::from("{\"camera\":{\"eye\":[0,0,6],\"target\":[0,0,0],\"up\":[0,1,0],\"fov_y_deg\":40},\"objects\":[");
    for (i, o) in objects.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        write!(s, "{{\"name\":\"o{i}\",\"shape\":{}}}", o.json()).unwrap();
    }
    s.push_str("]}");
    s
}

pub fn bake(objects: &[Shape]) -> RenderScene {
    bake_text(&scene_json(objects))
}

/// A scene of one object whose shape is the JSON `shape` (as the scene
/// format writes it), baked.
pub fn bake_shape_json(shape: &str) -> RenderScene {
    bake_text(&format!(
        "{{\"camera\":{{\"eye\":[0,0,6],\"target\":[0,0,0],\"up\":[0,1,0],\"fov_y_deg\":40}},\"objects\":[{{\"name\":\"o0\",\"shape\":{shape}}}]}}"
    ))
}

fn bake_text(text: &str) -> RenderScene {
    // The random meshes are written to the temporary folder, outside the
    // (nominal) scene's folder: allow it, as a user would with --allow-path.
    let opts = rothray::io::LoadOptions { allow_paths: vec![std::env::temp_dir()] };
    let sf = rothray::io::parse_scene_with(text, std::path::Path::new("test.json"), &opts).expect("scene parses");
    RenderScene::from_world(&sf.world).expect("scene bakes")
}

/// A random ray from outside a ball of radius 3 aimed into the unit region
/// (or, with probability 1/5, starting inside it).
pub fn random_ray(rng: &mut SmallRng) -> (DVec3, DVec3) {
    let target = rp(rng, 0.9);
    let o = if rng.gen_bool(0.2) { rp(rng, 1.0) } else { rp(rng, 1.0).normalize() * 3.5 };
    let mut d = target - o;
    if d.length() < 1e-3 {
        d = DVec3::X;
    }
    // Unnormalised on purpose: t is in units of d.
    (o, d * rng.gen_range(0.3..2.0))
}

/// Statistics of a span check.
#[derive(Default, Debug)]
pub struct Check {
    pub rays: usize,
    pub spans: usize,
    pub ends: usize,
    pub max_err: f64,
    pub missed: usize,
}

/// Checks the engine's spans of one ray against the f64 predicate:
/// sorted and disjoint; span midpoints inside; gaps (sampled) outside; every
/// real end within `tol` (in units of length) of an f64 crossing. The ray is
/// the f32 ray the engine traced, judged in f64.
pub fn check_spans(f: &dyn Fn(DVec3) -> bool, ray: &Ray, spans: &[Span], tol: f64, ctx: &str, st: &mut Check) {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (tmin, tmax) = (ray.tmin as f64, ray.tmax as f64);
    st.rays += 1;
    st.spans += spans.len();
    let dl = d.length();
    let tt = tol / dl; // tolerance in t
    for w in spans.windows(2) {
        assert!(w[0].t1 < w[1].t0, "{ctx}: spans not sorted/disjoint: {spans:?}");
    }
    for (k, s) in spans.iter().enumerate() {
        let (t0, t1) = (s.t0 as f64, s.t1 as f64);
        assert!(t0 >= tmin - 1e-9 && t1 <= tmax + 1e-9 && t0 < t1, "{ctx}: span out of range {s:?}");
        if t1 - t0 > 4.0 * tt {
            let m = if t1.is_finite() { 0.5 * (t0 + t1) } else { t0 + 1.0 };
            assert!(f(o + d * m), "{ctx}: span midpoint t={m} is outside the solid; spans {spans:?}");
        }
        // Room on each side of each end: half the span, half the neighbouring gap, capped at tt.
        let prev_end = if k > 0 { spans[k - 1].t1 as f64 } else { f64::NEG_INFINITY };
        let next_start = if k + 1 < spans.len() { spans[k + 1].t0 as f64 } else { f64::INFINITY };
        let half = 0.5 * (t1 - t0);
        for (t, real, inward, room_out) in
            [(t0, s.s0.is_real(), 1.0, 0.5 * (t0 - prev_end)), (t1, s.s1.is_real(), -1.0, 0.5 * (next_start - t1))]
        {
            if !real {
                continue;
            }
            st.ends += 1;
            let di = tt.min(half);
            let dout = tt.min(room_out);
            let pin = t + inward * di;
            let pout = t - inward * dout;
            let (fin, fout) = (f(o + d * pin), f(o + d * pout));
            if fin && !fout {
                // Bisect between them for the error figure.
                let (mut a, mut b) = (pout, pin);
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if f(o + d * m) {
                        b = m
                    } else {
                        a = m
                    }
                }
                st.max_err = st.max_err.max((0.5 * (a + b) - t).abs() * dl);
            } else if di >= 0.25 * tt && dout >= 0.25 * tt && !near_boundary(f, o + d * t, tol) {
                panic!(
                    "{ctx}: span end t={t} is not a boundary within {tol} (inside {fin} at {pin}, outside {} at {pout}); spans {spans:?}",
                    !fout
                );
            }
        }
    }
    // Gaps: sample densely; any inside sample away from span ends is a missed span.
    let lo = tmin.max(-1e3);
    let hi = tmax.min(lo + 20.0 / dl);
    let n = 400;
    for k in 0..n {
        let t = lo + (hi - lo) * (k as f64 + 0.5) / n as f64;
        if spans.iter().any(|s| t >= s.t0 as f64 - 4.0 * tt && t <= s.t1 as f64 + 4.0 * tt) {
            continue;
        }
        if f(o + d * t) {
            // Inside the solid but in no span: allowed only for slivers thinner than the tolerance.
            let thick = |dt: f64| f(o + d * (t + dt)) && f(o + d * (t - dt));
            if thick(4.0 * tt) {
                st.missed += 1;
                panic!("{ctx}: t={t} is inside the solid but in no span; spans {spans:?}");
            }
        }
    }
}

pub fn to_ray(o: DVec3, d: DVec3) -> Ray {
    Ray::new(o.as_vec3(), d.as_vec3())
}

/// Eight rays from `o` spread around `d` like a 4x2 block of pixels, `s` (of
/// |d|) apart: the renderer's packets.
pub fn packet_around(o: DVec3, d: DVec3, s: f64) -> Vec<Ray> {
    let (u, v) = (d.any_orthonormal_vector(), d.cross(d.any_orthonormal_vector()).normalize());
    let dl = d.length();
    (0..8).map(|k| to_ray(o, d + (u * (k % 4) as f64 + v * (k / 4) as f64) * s * dl)).collect()
}

/// A hit compared bit for bit: t, object, leaf, surface.
pub fn hit_key(h: Option<rothray::engine::Hit>) -> Option<(u32, u32, u32, u32)> {
    h.map(|h| (h.t.to_bits(), h.object, h.leaf, h.sub))
}

/// The nearest-hit answer a span list gives: its first real surface (the
/// entry, or the exit of a span that starts at the ray's start).
pub fn first_surface_t(spans: &[Span]) -> Option<f32> {
    spans.first().and_then(|s| {
        if s.s0.is_real() {
            Some(s.t0)
        } else if s.s1.is_real() {
            Some(s.t1)
        } else {
            None
        }
    })
}

/// The nearest of the first surfaces of objects `0..n`' full diagrams.
pub fn nearest_in_diagrams(scene: &RenderScene, ray: &Ray, n: usize) -> Option<f32> {
    (0..n as u32).filter_map(|oi| first_surface_t(&scene.spans(ray, oi))).fold(None, |a: Option<f32>, t| Some(a.map_or(t, |a| a.min(t))))
}

/// Is `p` within `r` of the solid's boundary (both inside and outside points in the ball)?
/// For grazing rays the crossing is ill-conditioned along the ray, but the point
/// must still lie on the surface.
pub fn near_boundary(f: &dyn Fn(DVec3) -> bool, p: DVec3, r: f64) -> bool {
    let c = f(p);
    let n = 64;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let a = i as f64 * 2.399963229728653;
        let q = (1.0 - z * z).sqrt();
        let dir = DVec3::new(q * a.cos(), q * a.sin(), z);
        for s in [0.25, 0.5, 1.0] {
            if f(p + dir * r * s) != c {
                return true;
            }
        }
    }
    false
}
