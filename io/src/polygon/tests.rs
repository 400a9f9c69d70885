//! The triangulation against an independent oracle: n - 2 triangles, none
//! turned over, whose areas add up to the face's shoelace area, whose centroids
//! are inside the face (crossing-number test), and which share every diagonal
//! with exactly one other triangle in the opposite direction while using every
//! face edge once (a closed fan of the face, not a spray of overlaps).
//! Randomized faces are seeded; each test prints its seed.

use std::collections::HashMap;

use glam::{DVec2, Vec3};

use super::*;

/// splitmix64: enough randomness for shapes, no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn f(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn to3(p: &[DVec2]) -> Vec<Vec3> {
    p.iter().map(|q| Vec3::new(q.x as f32, q.y as f32, 0.0)).collect()
}

/// A star-shaped face: `n` vertices at increasing angles, random radii.
fn star(rng: &mut Rng, n: usize) -> Vec<DVec2> {
    (0..n)
        .map(|i| {
            let a = std::f64::consts::TAU * (i as f64 + 0.8 * rng.f()) / n as f64;
            let r = 0.2 + 0.8 * rng.f();
            DVec2::new(a.cos(), a.sin()) * r
        })
        .collect()
}

/// A comb of `teeth` teeth of random heights on a bar, on integer-ish
/// coordinates (many vertices level with each other and in line), turned by
/// `angle`: every tooth's tip is a start vertex and every gap a merge vertex.
fn comb(rng: &mut Rng, teeth: usize, angle: f64) -> Vec<DVec2> {
    let mut p = vec![DVec2::new(teeth as f64, 0.0)];
    for t in (0..teeth).rev() {
        let h = 1.0 + rng.range(8) as f64;
        let x = t as f64;
        p.push(DVec2::new(x + 1.0, h));
        p.push(DVec2::new(x + 0.5, h));
        if t > 0 {
            p.push(DVec2::new(x + 0.5, 0.5));
        } else {
            p.push(DVec2::new(x, h));
        }
    }
    p.push(DVec2::new(0.0, 0.0));
    p.dedup();
    let (s, c) = angle.sin_cos();
    p.iter().map(|q| DVec2::new(c * q.x - s * q.y, s * q.x + c * q.y)).collect()
}

/// A thick spiral arm of `n` vertices (`n / 2` out along the outer wall, back
/// along the inner one), `turns` turns: most vertices are regular, and the sweep
/// line crosses many edges at once.
fn spiral(rng: &mut Rng, n: usize, turns: f64) -> Vec<DVec2> {
    let k = n / 2;
    let width = 0.4 + 0.4 * rng.f();
    let at = |t: f64, r: f64| {
        let a = std::f64::consts::TAU * turns * t;
        DVec2::new(a.cos(), a.sin()) * r
    };
    let mut p: Vec<DVec2> = (0..k).map(|i| i as f64 / (k - 1) as f64).map(|t| at(t, 1.0 + turns * t + width)).collect();
    p.extend((0..k).rev().map(|i| i as f64 / (k - 1) as f64).map(|t| at(t, 1.0 + turns * t)));
    p
}

fn shoelace(p: &[DVec2]) -> f64 {
    (0..p.len()).map(|i| p[i].perp_dot(p[(i + 1) % p.len()])).sum::<f64>() * 0.5
}

/// Crossing-number point-in-polygon test (independent of every predicate the
/// triangulation uses).
fn inside(p: &[DVec2], q: DVec2) -> bool {
    let mut c = false;
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        if (a.y > q.y) != (b.y > q.y) && q.x < a.x + (q.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            c = !c;
        }
    }
    c
}

/// Checks the oracle on `p` (counter-clockwise, simple); returns the method.
fn check(p: &[DVec2], what: &str, rng: &mut Rng) -> Method {
    // The coordinates the loader would see (f32), read back.
    let pos = to3(p);
    let p: Vec<DVec2> = pos.iter().map(|v| DVec2::new(v.x as f64, v.y as f64)).collect();
    let n = p.len();
    let idx: Vec<u32> = (0..n as u32).collect();
    let mut t = Vec::new();
    let method = triangulate(&pos, &idx, &mut t);
    assert_ne!(method, Method::Forced, "{what}: a simple face was not triangulated");
    assert_eq!(t.len(), n - 2, "{what}: {n} vertices");
    let area2 = |t: &[u32; 3]| geom::orient(p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
    assert!(t.iter().all(|t| area2(t) >= 0.0), "{what}: a triangle is turned over");
    let want = shoelace(&p);
    let got: f64 = t.iter().map(|t| area2(t) * 0.5).sum();
    assert!((got - want).abs() <= 1e-9 * want.abs(), "{what}: area {got} vs {want}");
    // Centroids of the triangles with area (a sample on big faces: the test
    // is O(n) each).
    let sample = if n > 600 { 300 } else { t.len() };
    for _ in 0..sample {
        let tri = t[rng.range(t.len())];
        if area2(&tri) > 1e-9 * want.abs() / n as f64 {
            let c = (p[tri[0] as usize] + p[tri[1] as usize] + p[tri[2] as usize]) / 3.0;
            assert!(inside(&p, c), "{what}: triangle {tri:?} has its centroid outside");
        }
    }
    // Every face edge used once, forwards; every other edge once each way.
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    for tri in &t {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
        }
    }
    for (&(a, b), &c) in &edges {
        let boundary = b == a + 1 || (a == 0 && b == n as u32 - 1);
        let want = if !boundary {
            0
        } else if b == a + 1 {
            1
        } else {
            -1
        };
        assert_eq!(c, want, "{what}: edge {a}-{b}");
    }
    assert_eq!(edges.len(), n + (n - 3), "{what}: n edges and n - 3 diagonals");
    method
}

#[test]
fn random_simple_faces_are_triangulated_inside_themselves() {
    let seed = 0x5eed_0014;
    println!("seed {seed:#x}");
    let mut rng = Rng(seed);
    let mut swept = 0;
    for case in 0..300 {
        let n = 3 + rng.range(if case % 10 == 0 { 5000 } else { 200 });
        let (p, what) = match case % 3 {
            0 => (star(&mut rng, n), "star"),
            1 => {
                let angle = if rng.range(2) == 0 { 0.0 } else { rng.f() * std::f64::consts::TAU };
                (comb(&mut rng, n.div_ceil(3).max(2), angle), "comb")
            }
            _ => {
                // At least 24 vertices a turn per wall, so that chords of one
                // turn stay clear of the next.
                let n = n.max(8);
                let turns = (0.5 + 4.0 * rng.f()).min(n as f64 / 48.0);
                (spiral(&mut rng, n, turns), "spiral")
            }
        };
        let what = format!("case {case} ({what}, {} vertices, seed {seed:#x})", p.len());
        if check(&p, &what, &mut rng) == Method::Swept {
            swept += 1;
        }
    }
    assert!(swept > 250, "{swept} faces went through the sweep");
}

#[test]
fn a_convex_face_is_halved_into_n_minus_2_triangles_of_its_area() {
    let p: Vec<DVec2> = (0..1000).map(|i| std::f64::consts::TAU * i as f64 / 1000.0).map(|a| DVec2::new(a.cos(), a.sin())).collect();
    let mut rng = Rng(1);
    assert_eq!(check(&p, "circle", &mut rng), Method::Convex);
    let mut t = Vec::new();
    triangulate(&to3(&p), &(0..1000).collect::<Vec<_>>(), &mut t);
    // No triangle is a sliver from vertex 0, as a fan's would be.
    assert!(t.iter().filter(|t| t.contains(&0)).count() < 20);
}

/// A 1 000 000-gon in f32 has dents at the rounding level: still convex.
#[test]
fn a_huge_face_in_f32_is_convex_up_to_rounding() {
    let n = 1_000_000;
    let pos: Vec<Vec3> = (0..n).map(|i| std::f32::consts::TAU * i as f32 / n as f32).map(|a| Vec3::new(a.cos(), a.sin(), 0.0)).collect();
    let idx: Vec<u32> = (0..n as u32).collect();
    let mut t = Vec::new();
    assert_eq!(triangulate(&pos, &idx, &mut t), Method::Convex);
    assert_eq!(t.len(), n - 2);
    // A real dent is not rounding.
    let mut pos: Vec<Vec3> = pos.iter().step_by(2000).copied().collect();
    pos[10] *= 0.9;
    let idx: Vec<u32> = (0..pos.len() as u32).collect();
    assert_eq!(triangulate(&pos, &idx, &mut Vec::new()), Method::Swept);
}

#[test]
fn an_l_shaped_face_is_swept() {
    let p: Vec<DVec2> = [[0., 0.], [2., 0.], [2., 1.], [1., 1.], [1., 2.], [0., 2.]].iter().map(|p| DVec2::new(p[0], p[1])).collect();
    assert_eq!(check(&p, "L", &mut Rng(2)), Method::Swept);
}

/// Faces that cross or touch themselves in their plane are halved and
/// reported, without a panic, and still give n - 2 triangles over their
/// vertices (the mesh stays closed).
#[test]
fn faces_that_are_not_simple_are_forced_not_panicking() {
    let seed = 0x5eed_0015;
    println!("seed {seed:#x}");
    let mut rng = Rng(seed);
    let mut faces: Vec<Vec<DVec2>> = vec![
        // A bow tie.
        vec![DVec2::new(0., 0.), DVec2::new(1., 1.), DVec2::new(1., 0.), DVec2::new(0., 1.)],
        // A vertex touching an edge, and a pinch (two vertices at one point).
        vec![DVec2::new(0., 0.), DVec2::new(2., 0.), DVec2::new(1., 0.), DVec2::new(2., 2.), DVec2::new(0., 2.)],
        vec![DVec2::new(0., 0.), DVec2::new(2., 0.), DVec2::new(1., 1.), DVec2::new(2., 2.), DVec2::new(0., 2.), DVec2::new(1., 1.)],
        // An edge folding back along itself (a spike).
        vec![DVec2::new(0., 0.), DVec2::new(2., 0.), DVec2::new(2., 2.), DVec2::new(1., 1.), DVec2::new(1.5, 1.5), DVec2::new(0., 2.)],
        // Everything in one line.
        vec![DVec2::new(0., 0.), DVec2::new(1., 0.), DVec2::new(2., 0.), DVec2::new(3., 0.)],
    ];
    // Random vertex soups: almost surely self-crossing.
    for _ in 0..200 {
        let n = 4 + rng.range(300);
        faces.push((0..n).map(|_| DVec2::new(rng.f(), rng.f())).collect());
    }
    // A star whose vertices are shuffled a little.
    let mut s = star(&mut rng, 2000);
    s.swap(100, 900);
    faces.push(s);
    for (k, p) in faces.iter().enumerate() {
        let pos = to3(p);
        let idx: Vec<u32> = (0..p.len() as u32).collect();
        let mut t = Vec::new();
        let m = triangulate(&pos, &idx, &mut t);
        assert_eq!(t.len(), p.len() - 2, "face {k} (seed {seed:#x})");
        if k < 5 || k == faces.len() - 1 {
            assert_eq!(m, Method::Forced, "face {k}");
        }
    }
}

/// Repeated points (an index given twice in a row, or vertices that project to
/// one point) get zero-area triangles, so the face's edges are all used and
/// the mesh stays closed.
#[test]
fn repeated_points_keep_every_edge() {
    let p: Vec<DVec2> = [[0., 0.], [2., 0.], [2., 0.], [2., 1.], [1., 1.], [1., 2.], [0., 2.], [0., 2.], [0., 2.], [0., 0.]]
        .iter()
        .map(|p| DVec2::new(p[0], p[1]))
        .collect();
    assert_eq!(check(&p, "repeats", &mut Rng(3)), Method::Swept);
}

/// The shape of the hostile test's face: a comb of 333 333 teeth, 1 000 000
/// vertices, through the sweep (the oracle samples centroids).
#[test]
fn a_million_vertex_comb_is_swept() {
    let seed = 0x5eed_0016;
    println!("seed {seed:#x}");
    let mut rng = Rng(seed);
    let p = comb(&mut rng, 333_333, 0.3);
    assert!(p.len() >= 1_000_000);
    // Printed, not asserted: the figure the module's doc quotes.
    let (pos, idx) = (to3(&p), (0..p.len() as u32).collect::<Vec<_>>());
    let t0 = std::time::Instant::now();
    triangulate(&pos, &idx, &mut Vec::new());
    println!("{} vertices triangulated in {:.2} s", p.len(), t0.elapsed().as_secs_f64());
    assert_eq!(check(&p, "million comb", &mut rng), Method::Swept);
}

/// Coordinates near f32's largest and smallest (the products of their
/// differences stay within f64's range, so `orient` keeps its exact sign): the
/// same comb scaled by powers of two gives the same triangles.
#[test]
fn extreme_coordinates_give_the_same_triangles() {
    let mut rng = Rng(0x5eed_0019);
    let p = comb(&mut rng, 50, 0.0);
    let idx: Vec<u32> = (0..p.len() as u32).collect();
    let mut want = Vec::new();
    assert_eq!(triangulate(&to3(&p), &idx, &mut want), Method::Swept);
    for s in [2f64.powi(120), 2f64.powi(-120)] {
        let q: Vec<DVec2> = p.iter().map(|v| *v * s).collect();
        let mut t = Vec::new();
        assert_eq!(triangulate(&to3(&q), &idx, &mut t), Method::Swept, "scale {s}");
        assert_eq!(t, want, "scale {s}");
    }
}

/// Random rings on a 5x5 grid (many repeated points, vertices in line, edges
/// along each other, crossings): never a panic, always n - 2 triangles, and
/// whenever the sweep accepts a ring (it found it simple, up to repeats), the
/// oracle holds.
#[test]
fn degenerate_grid_rings_never_panic_and_swept_ones_are_right() {
    let seed = 0x5eed_001a;
    println!("seed {seed:#x}");
    let mut rng = Rng(seed);
    let mut swept = 0;
    for case in 0..20_000 {
        let n = 3 + rng.range(9);
        let p: Vec<DVec2> = (0..n).map(|_| DVec2::new(rng.range(5) as f64, rng.range(5) as f64)).collect();
        let pos = to3(&p);
        let idx: Vec<u32> = (0..n as u32).collect();
        let mut t = Vec::new();
        let m = triangulate(&pos, &idx, &mut t);
        assert_eq!(t.len(), n - 2, "case {case} (seed {seed:#x}): {p:?}");
        if m == Method::Swept {
            swept += 1;
            // In the face's own orientation (a clockwise ring gives clockwise
            // triangles).
            let sign = shoelace(&p).signum();
            let area2 = |t: &[u32; 3]| sign * geom::orient(p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
            assert!(t.iter().all(|t| area2(t) >= 0.0), "case {case}: {p:?} -> {t:?}");
            let got: f64 = t.iter().map(area2).sum::<f64>() * 0.5;
            assert_eq!(got, shoelace(&p).abs(), "case {case}: {p:?} -> {t:?}");
        }
    }
    println!("{swept} of 20 000 random rings swept");
    assert!(swept > 1000);
    // The simplicity test against all pairs of edges, on rings of distinct
    // grid points: a simple non-convex ring is swept (and passes the full
    // oracle, counter-clockwise), any other is forced.
    let (mut simple, mut forced) = (0, 0);
    for case in 0..40_000 {
        let mut p: Vec<DVec2> = (0..4 + rng.range(8)).map(|_| DVec2::new(rng.range(6) as f64, rng.range(6) as f64)).collect();
        if (0..p.len()).any(|i| (0..i).any(|j| p[i] == p[j])) {
            continue;
        }
        if shoelace(&p) < 0.0 {
            p.reverse();
        }
        let idx: Vec<u32> = (0..p.len() as u32).collect();
        let m = triangulate(&to3(&p), &idx, &mut Vec::new());
        let what = format!("grid ring {case} (seed {seed:#x}): {p:?}");
        match (m, brute_simple(&p)) {
            (Method::Convex, _) => {}
            (_, true) => {
                assert_eq!(check(&p, &what, &mut rng), Method::Swept, "{what}");
                simple += 1;
            }
            (m, false) => {
                assert_eq!(m, Method::Forced, "{what}");
                forced += 1;
            }
        }
    }
    println!("{simple} simple grid rings swept, {forced} others forced");
    assert!(simple > 1500 && forced > 1500);
}

/// All pairs of edges: consecutive ones may only share their vertex (not
/// fold back along each other), others may not touch.
fn brute_simple(p: &[DVec2]) -> bool {
    let n = p.len();
    let on = |a: DVec2, b: DVec2, q: DVec2| geom::orient(a, b, q) == 0.0 && q.cmpge(a.min(b)).all() && q.cmple(a.max(b)).all();
    for i in 0..n {
        for j in i + 1..n {
            let (a, b, c, d) = (p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]);
            if j == i + 1 || (i == 0 && j == n - 1) {
                // Shared vertex s, far ends x and y.
                let (s, x, y) = if j == i + 1 { (b, a, d) } else { (a, b, c) };
                if on(s, x, y) || on(s, y, x) {
                    return false;
                }
                continue;
            }
            let (o1, o2, o3, o4) = (geom::orient(a, b, c), geom::orient(a, b, d), geom::orient(c, d, a), geom::orient(c, d, b));
            if (o1 * o2 < 0.0 && o3 * o4 < 0.0) || on(a, b, c) || on(a, b, d) || on(c, d, a) || on(c, d, b) {
                return false;
            }
        }
    }
    true
}

/// `orient`'s sign against exact integer arithmetic, on nearly collinear
/// triples of f32 values spread over 2^-10 .. 2^26 (as integers in units of
/// 2^-34 their products fit i128): the third point is the f32 rounding of a
/// point a sixteenth-multiple of the way from the first to the second, often
/// exactly on the line. (The plain f64 formula also gets all of these right,
/// as printed: the exact stage covers wider spreads than i128 can check.)
#[test]
fn orient_has_the_exact_sign() {
    let seed = 0x5eed_001b;
    println!("seed {seed:#x}");
    let mut rng = Rng(seed);
    let f = |rng: &mut Rng| -> f32 {
        let m = (rng.next() >> 40) as f32; // 24 bits
        let e = rng.range(13) as i32 - 10;
        let v = m * 2f32.powi(e);
        if rng.range(2) == 0 {
            -v
        } else {
            v
        }
    };
    // None where a coordinate is not a whole number of units (a point rounded
    // near zero).
    let exact = |p: [[f32; 2]; 3]| -> Option<i128> {
        let unit = 2f64.powi(34);
        if p.iter().flatten().any(|&x| (x as f64 * unit).fract() != 0.0) {
            return None;
        }
        let q = p.map(|v| v.map(|x| (x as f64 * unit) as i128));
        Some((q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0]))
    };
    let (mut zeros, mut naive_wrong) = (0, 0);
    for _ in 0..200_000 {
        let (a, b) = ([f(&mut rng), f(&mut rng)], [f(&mut rng), f(&mut rng)]);
        // Often exactly on the line (a short binary fraction of the way).
        let t = (1 + rng.range(15)) as f64 / 16.0;
        let c = [(a[0] as f64 + t * (b[0] as f64 - a[0] as f64)) as f32, (a[1] as f64 + t * (b[1] as f64 - a[1] as f64)) as f32];
        let Some(want) = exact([a, b, c]) else { continue };
        let want = want.signum() as f64;
        let d = |v: [f32; 2]| DVec2::new(v[0] as f64, v[1] as f64);
        let (pa, pb, pc) = (d(a), d(b), d(c));
        let got = geom::orient(pa, pb, pc);
        let got = if got == 0.0 { 0.0 } else { got.signum() };
        assert_eq!(got, want, "{a:?} {b:?} {c:?}");
        zeros += usize::from(want == 0.0);
        naive_wrong += usize::from({
            let n = (pb - pa).perp_dot(pc - pa);
            (if n == 0.0 { 0.0 } else { n.signum() }) != want
        });
    }
    println!("{zeros} exactly collinear, {naive_wrong} where the plain f64 formula had the wrong sign");
    assert!(zeros > 1000, "the cases test little");
}
