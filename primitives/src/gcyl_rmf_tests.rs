//! The generalized cylinder's frame and spans against an independent oracle:
//! the rotation-minimizing frame ODE `X' = -(X . T') T` integrated by RK4 in
//! f64 over the control points (Bernstein form, not the kernel's monomials),
//! thousands of steps per segment, and a point-sampling ray oracle that
//! classifies points by their foot points on the path (found by sampling and
//! bisection). Nothing here uses the kernel's frame samples or its rational
//! ray-plane parametrisation.

use super::*;
use crate::Span;
use rand::{rngs::SmallRng, Rng, SeedableRng};

/// RK4 steps per segment of the oracle frame (the kernel uses 64 samples).
const ORACLE_STEPS: usize = 4096;

/// The oracle: a Bezier chain with its rotation-minimizing frame tabulated.
struct Oracle {
    ctrl: Vec<[DVec3; 4]>,
    poly: Vec<DVec2>,
    twist: f64,
    /// `x[i][k]`: the frame's x axis (untwisted) at `u = k / ORACLE_STEPS` of segment i.
    x: Vec<Vec<DVec3>>,
}

fn bez(p: &[DVec3; 4], u: f64) -> DVec3 {
    let v = 1.0 - u;
    p[0] * (v * v * v) + p[1] * (3.0 * v * v * u) + p[2] * (3.0 * v * u * u) + p[3] * (u * u * u)
}

fn bez_d1(p: &[DVec3; 4], u: f64) -> DVec3 {
    let v = 1.0 - u;
    ((p[1] - p[0]) * (v * v) + (p[2] - p[1]) * (2.0 * v * u) + (p[3] - p[2]) * (u * u)) * 3.0
}

fn bez_d2(p: &[DVec3; 4], u: f64) -> DVec3 {
    ((p[2] - p[1] * 2.0 + p[0]) * (1.0 - u) + (p[3] - p[2] * 2.0 + p[1]) * u) * 6.0
}

/// dX/du of the rotation-minimizing frame: `-(X . dT/du) T`.
fn rmf_rate(p: &[DVec3; 4], u: f64, x: DVec3) -> DVec3 {
    let (d1, d2) = (bez_d1(p, u), bez_d2(p, u));
    let l = d1.length();
    let t = d1 / l;
    let tp = (d2 - t * t.dot(d2)) / l;
    -t * x.dot(tp)
}

fn rk4(p: &[DVec3; 4], u: f64, h: f64, x: DVec3) -> DVec3 {
    let k1 = rmf_rate(p, u, x);
    let k2 = rmf_rate(p, u + 0.5 * h, x + k1 * (0.5 * h));
    let k3 = rmf_rate(p, u + 0.5 * h, x + k2 * (0.5 * h));
    let k4 = rmf_rate(p, u + h, x + k3 * h);
    let x = x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
    let t = bez_d1(p, u + h).normalize();
    (x - t * x.dot(t)).normalize()
}

impl Oracle {
    fn new(desc: &GeneralizedCylinder) -> Oracle {
        let pts: Vec<DVec3> = desc.path.iter().map(|p| Vec3::from(*p).as_dvec3()).collect();
        let ctrl: Vec<[DVec3; 4]> = pts.windows(4).step_by(3).map(|w| [w[0], w[1], w[2], w[3]]).collect();
        let Profile::Polygon(pv) = &desc.profile else { panic!("the oracle takes polygon profiles") };
        let poly = pv.iter().map(|q| DVec2::new(q[0] as f64, q[1] as f64)).collect();
        // The documented start: `normal`, else +y, or +x when +y is within 8 degrees of T(0).
        let t0 = bez_d1(&ctrl[0], 0.0).normalize();
        let nv = match desc.normal {
            Some(v) => v.as_dvec3().normalize(),
            None if DVec3::Y.dot(t0).abs() > 8f64.to_radians().cos() => DVec3::X,
            None => DVec3::Y,
        };
        let mut x = (nv - t0 * nv.dot(t0)).normalize();
        let h = 1.0 / ORACLE_STEPS as f64;
        let mut tab = Vec::new();
        for p in &ctrl {
            // At a tangent-continuous joint the ODE just carries X on.
            let t = bez_d1(p, 0.0).normalize();
            x = (x - t * x.dot(t)).normalize();
            let mut col = vec![x];
            for k in 0..ORACLE_STEPS {
                x = rk4(p, k as f64 * h, h, x);
                col.push(x);
            }
            tab.push(col);
        }
        Oracle { ctrl, poly, twist: (desc.twist_deg as f64).to_radians(), x: tab }
    }

    /// (point, tangent, x axis, y axis) at `u` of segment `i`, twist included.
    fn frame(&self, i: usize, u: f64) -> (DVec3, DVec3, DVec3, DVec3) {
        let p = &self.ctrl[i];
        let k = ((u * ORACLE_STEPS as f64) as usize).min(ORACLE_STEPS - 1);
        let u0 = k as f64 / ORACLE_STEPS as f64;
        let x = if u > u0 { rk4(p, u0, u - u0, self.x[i][k]) } else { self.x[i][k] };
        let t = bez_d1(p, u).normalize();
        let ang = self.twist * (i as f64 + u) / self.ctrl.len() as f64;
        let x = x * ang.cos() + t.cross(x) * ang.sin();
        (bez(p, u), t, x, t.cross(x))
    }

    fn in_polygon(&self, q: DVec2) -> bool {
        let v = &self.poly;
        let mut inside = false;
        for i in 0..v.len() {
            let (a, b) = (v[i], v[(i + 1) % v.len()]);
            if (a.y > q.y) != (b.y > q.y) && q.x < a.x + (q.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                inside = !inside;
            }
        }
        inside
    }

    /// Is `q` on some profile copy? Foot points `(q - C(u)) . C'(u) = 0` by
    /// sampling 96 intervals per segment and bisecting sign changes.
    fn contains(&self, q: DVec3) -> bool {
        let rp2 = self.poly.iter().map(|p| p.length_squared()).fold(0.0, f64::max);
        for (i, p) in self.ctrl.iter().enumerate() {
            let f = |u: f64| (q - bez(p, u)).dot(bez_d1(p, u));
            let n = 96;
            let mut prev = (0.0, f(0.0));
            for k in 1..=n {
                let u = k as f64 / n as f64;
                let cur = (u, f(u));
                if prev.1 == 0.0 || (prev.1 < 0.0) != (cur.1 < 0.0) {
                    let (mut a, mut b) = (prev.0, cur.0);
                    for _ in 0..60 {
                        let m = 0.5 * (a + b);
                        if (f(m) < 0.0) == (prev.1 < 0.0) {
                            a = m
                        } else {
                            b = m
                        }
                    }
                    let u = if prev.1 == 0.0 { prev.0 } else { 0.5 * (a + b) };
                    let (c, _, x, y) = self.frame(i, u);
                    let d = q - c;
                    if d.length_squared() <= rp2 * 1.0001 && self.in_polygon(DVec2::new(d.dot(x), d.dot(y))) {
                        return true;
                    }
                }
                prev = cur;
            }
        }
        false
    }

    /// Boundary crossings of `o + t d` within `[t0, t1]` (n samples, bisection).
    fn crossings(&self, o: DVec3, d: DVec3, t0: f64, t1: f64, n: usize) -> Vec<f64> {
        let mut out = vec![];
        let mut prev = (t0, self.contains(o + d * t0));
        for k in 1..=n {
            let t = t0 + (t1 - t0) * k as f64 / n as f64;
            let cur = (t, self.contains(o + d * t));
            if cur.1 != prev.1 {
                let (mut a, mut b) = (prev.0, cur.0);
                for _ in 0..50 {
                    let m = 0.5 * (a + b);
                    if self.contains(o + d * m) == prev.1 {
                        a = m
                    } else {
                        b = m
                    }
                }
                out.push(0.5 * (a + b));
            }
            prev = cur;
        }
        out
    }
}

fn rand_unit(rng: &mut SmallRng) -> DVec3 {
    loop {
        let v = DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
        let l = v.length_squared();
        if l > 1e-4 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// A tangent-continuous chain of `n` non-planar segments: each joint mirrors
/// its incoming control point, the others wander in 3D.
fn random_path(rng: &mut SmallRng, n: usize) -> Vec<[f32; 3]> {
    let mut p = vec![DVec3::ZERO];
    let mut dir = rand_unit(rng);
    for k in 0..n {
        let a = *p.last().unwrap();
        let c1 = if k == 0 { a + dir * rng.gen_range(0.4..0.8) } else { a * 2.0 - p[p.len() - 2] };
        dir = (dir + rand_unit(rng) * 1.2).normalize();
        let c3 = a + dir * rng.gen_range(1.2..2.0) + rand_unit(rng) * 0.4;
        let c2 = c3 - (dir + rand_unit(rng) * 0.8).normalize() * rng.gen_range(0.4..0.8);
        p.extend([c1, c2, c3]);
    }
    // Round to f32 once; the joints' mirrored control points are then taken from the rounded values.
    p.iter().map(|v| v.as_vec3().to_array()).collect()
}

fn random_polygon(rng: &mut SmallRng) -> Vec<[f32; 2]> {
    let s = rng.gen_range(0.08..0.2f32);
    match rng.gen_range(0..3) {
        0 => vec![[-s, -s], [s, -s], [s, s], [-s, s]],
        1 => vec![[0.0, s * 1.3], [-s, -0.7 * s], [1.1 * s, -0.6 * s]],
        // an L (not convex), off-centre
        _ => vec![[-s, -s], [1.4 * s, -s], [1.4 * s, -0.3 * s], [-0.2 * s, -0.3 * s], [-0.2 * s, 1.6 * s], [-s, 1.6 * s]],
    }
}

fn random_shape(rng: &mut SmallRng) -> GeneralizedCylinder {
    let n = rng.gen_range(2..=6);
    let twist = if rng.gen_bool(0.5) { rng.gen_range(-270.0..270.0f32) } else { 0.0 };
    GeneralizedCylinder {
        path: random_path(rng, n),
        profile: Profile::Polygon(random_polygon(rng)),
        frame: Frame::RotationMinimizing,
        normal: None,
        twist_deg: twist,
    }
}

/// The issue-15 reproducer: two non-planar segments, square profile.
fn issue15_shape() -> GeneralizedCylinder {
    GeneralizedCylinder {
        path: vec![
            [1.0, 0.0, 0.0],
            [1.0, 0.8, 1.6],
            [-1.0, 1.6, 1.6],
            [-1.0, 2.4, 0.0],
            [-1.0, 3.2, -1.6],
            [1.0, 4.0, -1.6],
            [1.0, 4.8, 0.0],
        ],
        profile: Profile::Polygon(vec![[0.3, -0.3], [0.3, 0.3], [-0.3, 0.3], [-0.3, -0.3]]),
        frame: Frame::RotationMinimizing,
        normal: None,
        twist_deg: 0.0,
    }
}

/// Largest angle (radians) between the kernel's and the oracle's x axes over
/// `k` evenly spaced points per segment.
fn worst_frame_angle(g: &GenCylData, o: &Oracle, k: usize) -> f64 {
    let mut worst = 0.0f64;
    for i in 0..g.segment_count() {
        for j in 0..=k {
            let u = j as f64 / k as f64;
            let f = g.frame_at(i, u);
            let (_, _, x, _) = o.frame(i, u);
            worst = worst.max(f.x.cross(x).length().atan2(f.x.dot(x)));
        }
    }
    worst
}

#[test]
fn issue15_reproducer_matches_oracle() {
    let desc = issue15_shape();
    let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
    let o = Oracle::new(&desc);
    let ang = worst_frame_angle(&g, &o, 200);
    println!("issue 15 path: worst frame angle {ang:e} rad");
    assert!(ang < 1e-6, "frame drifts by {ang} rad");
    // The issue's ray, as `trace` reads it (f64 text rounded to f32).
    let (of, df) = (
        DVec3::new(12.333760464816386, -0.9212136467628258, -10.956556751596601).as_vec3(),
        DVec3::new(-7.2826926607742575, 2.40286682089548, 5.812184696584759).as_vec3(),
    );
    let mut got: Vec<Span> = vec![];
    g.spans(&Ray::segment(of, df, 0.0, f32::INFINITY), 0, &mut got);
    let r = o.crossings(of.as_dvec3(), df.as_dvec3(), 1.6, 1.85, 400);
    println!("kernel {got:?}\noracle {r:?}");
    assert_eq!(r.len(), 2);
    assert!((r[0] - 1.7049).abs() < 1e-3 && (r[1] - 1.7532).abs() < 1e-3, "oracle {r:?}");
    assert_eq!(got.len(), 1);
    assert!((got[0].t0 as f64 - r[0]).abs() < 1e-5 && (got[0].t1 as f64 - r[1]).abs() < 1e-5);
}

#[test]
fn rmf_matches_ode_on_random_multi_segment_paths() {
    let seed = 0x9c71_0015u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut worst = 0.0f64;
    for case in 0..40 {
        let desc = random_shape(&mut rng);
        let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
        let o = Oracle::new(&desc);
        let ang = worst_frame_angle(&g, &o, 100);
        assert!(ang < 1e-6, "case {case}: {} segments, twist {}: frame off by {ang} rad", g.segment_count(), desc.twist_deg);
        worst = worst.max(ang);
    }
    println!("40 random paths of 2-6 segments: worst frame angle {worst:e} rad");
}

#[test]
fn spans_match_ode_oracle_on_random_multi_segment_paths() {
    let seed = 0x9c71_0016u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut rays, mut same, mut worst, mut short_mism) = (0, 0, 0.0f64, 0);
    for case in 0..16 {
        let desc = random_shape(&mut rng);
        let g = GenCylData::new(&desc, DEFAULT_TOLERANCE).unwrap();
        let o = Oracle::new(&desc);
        let b = g.local_bounds();
        let size = b.diagonal_length() as f64;
        for _ in 0..12 {
            // aimed at a random point of the tube, from outside the bounds
            let i = rng.gen_range(0..g.segment_count());
            let (c, _, x, y) = o.frame(i, rng.gen());
            let tgt = c + (x * rng.gen_range(-1.0..1.0) + y * rng.gen_range(-1.0..1.0)) * 0.1;
            let v = rand_unit(&mut rng) * rng.gen_range(0.3..3.0);
            let (of, df) = ((tgt - v * size).as_vec3(), v.as_vec3());
            let (od, dd) = (of.as_dvec3(), df.as_dvec3());
            let Some((ta, tb)) = b.ray_range(of, df.recip(), 0.0, f32::INFINITY) else { continue };
            let pad = 0.01 * size / dd.length();
            let mut got: Vec<Span> = vec![];
            g.spans(&Ray::segment(of, df, ta - pad as f32, tb + pad as f32), 0, &mut got);
            let gv: Vec<f64> = got.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
            let r = o.crossings(od, dd, ta as f64 - pad, tb as f64 + pad, 1200);
            rays += 1;
            if gv.len() == r.len() {
                same += 1;
                for (a, e) in gv.iter().zip(&r) {
                    let err = (a - e).abs() * dd.length() / size;
                    assert!(err < 1e-5, "case {case}: end error {err:e}, o={of:?} d={df:?} kernel {gv:?} oracle {r:?}");
                    worst = worst.max(err);
                }
            } else {
                // only chords (or gaps) shorter than 1e-4 of the size may differ
                let shortest = |l: &[f64]| l.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min) * dd.length() / size;
                let s = shortest(&gv).min(shortest(&r));
                assert!(s < 1e-4, "case {case}: span count differs, o={of:?} d={df:?} kernel {gv:?} oracle {r:?}");
                short_mism += 1;
            }
        }
    }
    println!(
        "{rays} rays: {same} with the oracle's span count (worst end error {worst:e} of the size), {short_mism} differ by a chord < 1e-4"
    );
    assert!(same * 10 >= rays * 9);
}
