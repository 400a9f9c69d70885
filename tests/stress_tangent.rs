//! Rays tangent to quadric surfaces other than balls: ellipsoids (a sphere
//! under a non-uniform scale, and under a matrix with shear), cylinders
//! (side, caps) and cones (side, apex, caps), at offsets 0 to 1e5 from the
//! origin and at sizes 1e-6 to 1e6, against the f64 model of `oracle.rs` fed
//! the same f32-rounded scene and rays (as `stress::tangent_chords` does for
//! balls).
//!
//! `cargo test --release --test integration stress_tangent -- --nocapture`
//! prints the table.

use glam::{DAffine3, DMat3, DVec3};
use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray::primitives::Span;

use crate::oracle::*;
use crate::stress::{model_crossings, r32, robust, rv, tangent_places, wrong_count};

/// A point of a surface and a direction tangent to it there.
pub(crate) type Aim = (DVec3, DVec3);

/// One family of tangent rays: the solid, its size (the view is 4 of them),
/// and where the rays touch it.
pub(crate) struct Family {
    pub(crate) name: &'static str,
    pub(crate) shape: Shape,
    /// An f32 point near the solid: the model works relative to it (see `Shape::moved`).
    pub(crate) near: DVec3,
    pub(crate) size: f64,
    pub(crate) aim: Box<dyn Fn(&mut SmallRng) -> Aim>,
    /// Does the f32 ray (origin, direction) lie exactly in the plane of a
    /// flat face? Its contact with the solid is then only that face, which
    /// the model may count as a chord or as nothing by its own rounding.
    pub(crate) in_plane: Option<Box<dyn Fn(DVec3, DVec3) -> bool>>,
}

pub(crate) fn unit(rng: &mut SmallRng) -> DVec3 {
    loop {
        let v = rp(rng, 1.0);
        if v.length() > 0.2 && v.length() < 1.0 {
            return v.normalize();
        }
    }
}

/// A unit vector orthogonal to unit `n`, uniform around it.
pub(crate) fn across(rng: &mut SmallRng, n: DVec3) -> DVec3 {
    loop {
        let v = unit(rng);
        let w = v - n * v.dot(n);
        if w.length() > 0.1 {
            return w.normalize();
        }
    }
}

/// An orthonormal pair across unit `w` (the model's own, not the engine's).
fn pair(w: DVec3) -> (DVec3, DVec3) {
    let h = if w.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
    let u = w.cross(h).normalize();
    (u, w.cross(u))
}

/// A sphere under `m` (an ellipsoid), described by `wrap` (the scene's
/// transformed nodes around the sphere): rays along a tangent plane of a
/// random surface point (normal `m^-T n`).
fn ellipsoid(name: &'static str, m: DAffine3, wrap: &dyn Fn(Shape) -> Shape, s: f64) -> Family {
    let (lc, lr) = (rv(DVec3::new(0.1, -0.2, 0.15)), r32(0.45));
    let shape = wrap(Shape::Sphere { c: lc, r: lr });
    let nt = m.matrix3.inverse().transpose();
    let aim = move |rng: &mut SmallRng| {
        let n = unit(rng);
        let p = m.transform_point3(lc + n * lr);
        (p, across(rng, (nt * n).normalize()))
    };
    Family { name, shape, near: rv(m.translation), size: 2.0 * s, aim: Box::new(aim), in_plane: None }
}

/// A cone (or cylinder: `ra == rb`) from `a` to `b`.
#[derive(Clone, Copy)]
struct Axial {
    a: DVec3,
    b: DVec3,
    ra: f64,
    rb: f64,
}

impl Axial {
    fn shape(&self) -> Shape {
        let Axial { a, b, ra, rb } = *self;
        if ra == rb {
            Shape::Cylinder { a, b, r: ra }
        } else {
            Shape::Cone { a, b, ra, rb }
        }
    }

    /// A side point at a random height and angle, and a random direction in
    /// the tangent plane there (spanned by the generator and the circle).
    fn side(&self, rng: &mut SmallRng) -> Aim {
        let ax = self.b - self.a;
        let (u, v) = pair(ax.normalize());
        let (h, phi) = (rng.gen_range(0.02..0.98), rng.gen_range(0.0..std::f64::consts::TAU));
        let radial = u * phi.cos() + v * phi.sin();
        let p = self.a + ax * h + radial * (self.ra + (self.rb - self.ra) * h);
        let generator = (ax + radial * (self.rb - self.ra)).normalize();
        let circle = ax.normalize().cross(radial);
        let w = rng.gen_range(0.0..std::f64::consts::TAU);
        (p, generator * w.cos() + circle * w.sin())
    }

    /// A point of a cap's disk (`a`'s, or either when `both`), and a
    /// direction in its plane.
    fn cap(&self, rng: &mut SmallRng, both: bool) -> Aim {
        let far = both && rng.gen_bool(0.5);
        let ax = self.b - self.a;
        let (u, v) = pair(ax.normalize());
        let (q, r) = if far { (self.b, self.rb) } else { (self.a, self.ra) };
        let (rho, phi) = (r * rng.gen_range(0.0f64..1.0).sqrt(), rng.gen_range(0.0..std::f64::consts::TAU));
        (q + (u * phi.cos() + v * phi.sin()) * rho, across(rng, ax.normalize()))
    }

    /// A point within 1e-6..1e-2 sizes of the apex `b` (`rb == 0`), any direction.
    fn apex(&self, rng: &mut SmallRng, s: f64) -> Aim {
        let off = unit(rng) * s * 10f64.powf(rng.gen_range(-6.0..-2.0));
        (self.b + off, unit(rng))
    }
}

/// The families at centre `c`, size `s`: every number of the scene rounded
/// to f32 as the file will be read (transforms are read in f64).
fn families(c: DVec3, s: f64) -> Vec<Family> {
    let c = rv(c);
    let p = |x: f64, y: f64, z: f64| rv(c + DVec3::new(x, y, z) * s);
    let (rot, sc) = (DVec3::new(30.0, -50.0, 70.0), DVec3::new(1.7, 0.6, 1.1) * s);
    let m = DAffine3::from_translation(c)
        * DAffine3::from_rotation_z(rot.z.to_radians())
        * DAffine3::from_rotation_y(rot.y.to_radians())
        * DAffine3::from_rotation_x(rot.x.to_radians())
        * DAffine3::from_scale(sc);
    let json = format!(
        "\"translate\":[{:?},{:?},{:?}],\"rotate_deg\":[30.0,-50.0,70.0],\"scale\":[{:?},{:?},{:?}]",
        c.x, c.y, c.z, sc.x, sc.y, sc.z
    );
    let scaled = move |x: Shape| Shape::Xf { m, json: json.clone(), s: Box::new(x) };
    // A matrix with shear (row-major in the file), inside a translation and
    // a uniform scale (a matrix of size 1e-6 is refused as singular).
    let a = DMat3::from_cols(DVec3::new(1.3, 0.4, -0.2), DVec3::new(0.7, 0.9, 0.3), DVec3::new(-0.1, 0.5, 1.6));
    let rows: Vec<String> = (0..3).map(|i| format!("{:?},{:?},{:?},0", a.row(i).x, a.row(i).y, a.row(i).z)).collect();
    let (inner, outer) = (DAffine3::from_mat3(a), DAffine3::from_translation(c) * DAffine3::from_scale(DVec3::splat(s)));
    let sheared = move |x: Shape| {
        let x = Shape::Xf { m: inner, json: format!("\"matrix\":[{},0,0,0,1]", rows.join(",")), s: Box::new(x) };
        Shape::Xf { m: outer, json: format!("\"translate\":[{:?},{:?},{:?}],\"scale\":{s:?}", c.x, c.y, c.z), s: Box::new(x) }
    };
    let cyl = Axial { a: p(-0.6, -0.3, 0.2), b: p(0.5, 0.4, -0.3), ra: r32(0.35 * s), rb: r32(0.35 * s) };
    let cone = Axial { a: p(-0.2, -0.7, 0.1), b: p(0.3, 0.6, -0.2), ra: r32(0.55 * s), rb: 0.0 };
    let frustum = Axial { a: p(0.4, -0.5, -0.3), b: p(-0.3, 0.5, 0.4), ra: r32(0.5 * s), rb: r32(0.2 * s) };
    let fam = |name, x: Axial, aim: Box<dyn Fn(&mut SmallRng) -> Aim>| Family {
        name,
        shape: x.shape(),
        near: x.a,
        size: 1.5 * s,
        aim,
        in_plane: None,
    };
    vec![
        ellipsoid("ellipsoid (scale 1.7, 0.6, 1.1)", m, &scaled, s),
        ellipsoid("ellipsoid (sheared matrix)", outer * inner, &sheared, s),
        fam("cylinder side", cyl, Box::new(move |r| cyl.side(r))),
        fam("cylinder caps", cyl, Box::new(move |r| cyl.cap(r, true))),
        fam("cone side", cone, Box::new(move |r| cone.side(r))),
        fam("cone apex", cone, Box::new(move |r| cone.apex(r, s))),
        fam("cone cap", cone, Box::new(move |r| cone.cap(r, false))),
        fam("frustum side", frustum, Box::new(move |r| frustum.side(r))),
        fam("frustum caps", frustum, Box::new(move |r| frustum.cap(r, true))),
    ]
}

/// One family's figures at one place.
#[derive(Default)]
pub(crate) struct Tally {
    /// Rays with a wrong span count, chords and gaps under 1e-6 / 1e-4 of the view set aside.
    pub(crate) wrong6: usize,
    pub(crate) wrong4: usize,
    /// Largest span end error / view (rays with the model's count, chords >= 1e-6 of the view).
    pub(crate) err: f64,
    /// Model chords of 1e-6..1e-5, 1e-5..1e-4, 1e-4.. of the view.
    pub(crate) bands: [usize; 3],
    /// Rays set aside: they lie in a cap's plane to within the model's own
    /// f64 rounding, which then reports many spans of a convex solid (a cap
    /// plane with a small integer normal through f32 points holds ~1 in 300
    /// f32 rays exactly; the engine reports the boundary-inclusive chord),
    /// or exactly in a face's plane (`Family::in_plane`).
    pub(crate) in_plane: usize,
}

/// 400 rays of `fam`, each from 4 sizes away along its tangent, aimed at its
/// surface point (the f32 rounding of the ray leaves a short chord or a near miss).
pub(crate) fn tally(fam: &Family, s: f64, seed: u64) -> Tally {
    let scene = bake(std::slice::from_ref(&fam.shape));
    let model = fam.shape.moved(fam.near);
    let f = |p: DVec3| model.inside(p);
    let mut rng = SmallRng::seed_from_u64(seed);
    let view = 4.0 * s;
    let mut t = Tally::default();
    for _ in 0..400 {
        let (p, dir) = (fam.aim)(&mut rng);
        let o32 = (p - dir * view).as_vec3();
        let d32 = ((p - o32.as_dvec3()).normalize() * 10f64.powf(rng.gen_range(-1.0..1.0))).as_vec3();
        let (o, d) = (o32.as_dvec3(), d32.as_dvec3());
        let spans: Vec<Span> = scene.spans(&rothray::engine::Ray::new(o32, d32), 0);
        // The model near the aim point, sampled there too: a chord too short
        // for the grid is still seen.
        let dl = d.length();
        let tp = (p - o).dot(d) / (dl * dl);
        let half = 2.0 * fam.size / dl;
        // The engine's spans cut to the model's window (an unbounded
        // half-space's span ends at the window's ends on both sides).
        let (w0, w1) = ((tp - half).max(0.0), tp + half);
        let got: Vec<f64> = spans
            .iter()
            .map(|s| (s.t0 as f64).max(w0)..(s.t1 as f64).min(w1))
            .filter(|r| r.end > r.start)
            .flat_map(|r| [r.start, r.end])
            .collect();
        let mut extra: Vec<f64> = spans.iter().map(|s| 0.5 * (s.t0 as f64 + s.t1 as f64)).collect();
        extra.push(tp);
        let want = model_crossings(&f, o - fam.near, d, (w0, w1), 1000, &extra);
        if want.len() > 2 || fam.in_plane.as_ref().is_some_and(|f| f(o, d)) {
            t.in_plane += 1;
            continue;
        }
        for w in want.chunks(2) {
            let l = (w[1] - w[0]) * dl / view;
            if l >= 1e-6 {
                t.bands[(l.log10() + 6.0).floor().clamp(0.0, 2.0) as usize] += 1;
            }
        }
        let min = 1e-6 * view / dl;
        t.wrong4 += wrong_count(&got, &want, 100.0 * min) as usize;
        if wrong_count(&got, &want, min) {
            t.wrong6 += 1;
            if t.wrong6 <= 2 {
                println!("  wrong count ({}): o {o32:?} d {d32:?}\n    engine {got:?}\n    model  {want:?}", fam.name);
            }
            continue;
        }
        let (g, w) = (robust(got, min), robust(want, min));
        if g.len() == w.len() {
            for (a, b) in g.iter().zip(&w) {
                let e = (a - b).abs() * dl / view;
                if e > 1e-6 && e > t.err {
                    println!("  end off by {e:.1e} of the view ({}): o {o32:?} d {d32:?}\n    engine {g:?}\n    model  {w:?}", fam.name);
                }
                t.err = t.err.max(e);
            }
        }
    }
    t
}

/// Tangent rays of ellipsoids, cylinders and cones at offsets 0 to 1e5 and
/// sizes 1e-6 to 1e6. Target: the span count of the f32 inputs for every
/// chord of at least 1e-6 of the view, ends within 1e-6 of the view (as
/// balls). Through the leaf's f32 world-to-local map (6e-8 relative) a
/// chord of length L moved by about 6e-8 r^2 / (L/2): 7e-5 of the view for
/// a chord of 1e-4 of a 4-radii view.
#[test]
fn tangent_quadrics() {
    let seed = 0x7a49_e176u64;
    println!("seed {seed:#x}");
    let cases = tangent_places();
    let mut bad = vec![];
    println!("| surface | where | wrong counts, chords >= 1e-6 / 1e-4 of the view | max end error / view | chords 1e-6..1e-5 / 1e-5..1e-4 / 1e-4.. of the view | in a cap's plane (set aside) |");
    println!("|---|---|---|---|---|---|");
    for (ci, (label, c, s)) in cases.iter().enumerate() {
        for (ki, fam) in families(*c, *s).iter().enumerate() {
            let t = tally(fam, *s, seed + (ci * 100 + ki) as u64);
            let [b0, b1, b2] = t.bands;
            println!(
                "| {} | {label} | {} / {} of 400 | {:.1e} | {b0} / {b1} / {b2} | {} |",
                fam.name, t.wrong6, t.wrong4, t.err, t.in_plane
            );
            if t.wrong6 > 0 || t.err > 1e-6 {
                bad.push(format!("{} at {label}", fam.name));
            }
        }
    }
    assert!(bad.is_empty(), "tangent rays miss the target: {bad:?}");
}
