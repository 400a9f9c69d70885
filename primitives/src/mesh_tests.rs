use super::*;

#[test]
fn mesh_det_sign_means_facing() {
    let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let r = WoopRay::new(Vec3::new(0.2, 0.2, 1.0), Vec3::NEG_Z);
    assert_eq!(intersect(&r, &tri, 0.0, 10.0), Some((1.0, true)));
    let r = WoopRay::new(Vec3::new(0.2, 0.2, -1.0), Vec3::Z * 2.0);
    assert_eq!(intersect(&r, &tri, 0.0, 10.0), Some((0.5, false)));
}

use crate::kernels;
use rand::{rngs::SmallRng, Rng, SeedableRng};

/// Octahedron subdivided `level` times, projected on the unit sphere (exact poles
/// at the axes, so axis rays hit vertices exactly). Outward, closed.
pub(crate) fn octasphere(level: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut pos = vec![Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
    let mut tris: Vec<[u32; 3]> = vec![];
    for (x, y, z) in [(0u32, 2u32, 4u32), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)] {
        tris.push([x, y, z]);
    }
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = vec![];
        for t in &tris {
            let mut m = [0u32; 3];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                let k = (a.min(b), a.max(b));
                m[e] = *mid.entry(k).or_insert_with(|| {
                    pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                    pos.len() as u32 - 1
                });
            }
            next.push([t[0], m[0], m[2]]);
            next.push([m[0], t[1], m[1]]);
            next.push([m[2], m[1], t[2]]);
            next.push([m[0], m[1], m[2]]);
        }
        tris = next;
    }
    (pos, tris)
}

/// Cube `[-1, 1]^3`, two triangles per face, outward.
pub(crate) fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut pos = vec![];
    for i in 0..8 {
        pos.push(Vec3::new(if i & 1 != 0 { 1.0 } else { -1.0 }, if i & 2 != 0 { 1.0 } else { -1.0 }, if i & 4 != 0 { 1.0 } else { -1.0 }));
    }
    // quads counter-clockwise seen from outside
    let quads = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    let mut tris = vec![];
    for q in quads {
        tris.push([q[0], q[1], q[2]]);
        tris.push([q[0], q[2], q[3]]);
    }
    (pos, tris)
}

/// Convex oracle: signed distance to the polyhedron's face planes (max over faces).
fn plane_distance(pos: &[Vec3], tris: &[[u32; 3]], p: Vec3) -> f32 {
    tris.iter()
        .map(|t| {
            let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
            let n = (b - a).cross(c - a).normalize();
            n.dot(p - a)
        })
        .fold(f32::NEG_INFINITY, f32::max)
}

/// Checks one ray against the invariants; returns the number of midpoints checked.
fn check_ray(m: &MeshData, o: Vec3, d: Vec3, convex: Option<(&[Vec3], &[[u32; 3]])>) -> usize {
    check_ray_closed(m, o, d, convex, true)
}

/// With `closed`: the crossings of the whole line are even in number and alternate
/// in, out (near-equal t, where a ray grazes an edge or vertex and the two triangles
/// round t differently, count as ties). Always: span midpoints are inside and gap
/// midpoints outside according to contains() (and the convex plane oracle).
fn check_ray_closed(m: &MeshData, o: Vec3, d: Vec3, convex: Option<(&[Vec3], &[[u32; 3]])>, closed: bool) -> usize {
    let xs = m.crossings(o, d, -1e30, 1e30);
    if closed {
        assert!(xs.len().is_multiple_of(2), "odd crossing count {} for o {o:?} d {d:?}: {xs:?}", xs.len());
        let mut k = 0;
        let mut depth = 0;
        while k < xs.len() {
            let mut j = k;
            let mut sum = 0;
            while j < xs.len() && (xs[j].0 - xs[k].0).abs() <= 1e-5 * xs[k].0.abs().max(1.0) {
                sum += xs[j].2;
                j += 1;
            }
            depth += sum;
            assert!(depth == 0 || depth == 1, "crossings do not alternate for o {o:?} d {d:?}: {xs:?}");
            k = j;
        }
        assert_eq!(depth, 0);
    }
    // closest_hit (ordered, pruned traversal) == first crossing of the all-hits traversal
    let first = xs.iter().find(|x| x.0 >= 0.0 && x.0 <= 10.0).map(|x| x.0);
    assert_eq!(m.closest_hit(o, d, 0.0, 10.0).map(|h| h.0), first, "closest_hit, o {o:?} d {d:?}");
    if convex.is_some() {
        assert!(xs.len() <= 2, "convex mesh crossed {} times: o {o:?} d {d:?}: {xs:?}", xs.len());
    }
    let mut spans: Vec<crate::Span> = vec![];
    let (tmin, tmax) = (0.0, 10.0);
    m.spans(&Ray::segment(o, d, tmin, tmax), 7, &mut spans);
    let mut checked = 0;
    let mut prev = tmin;
    // Each piece is probed at its middle. The probe is an f32 point, off the
    // line by its rounding (about 1e-7 here), while the spans are decided on
    // the line itself: a piece thinner than that is not probed.
    let mut probe = |(a, b): (f32, f32), want: bool| {
        if (b - a) * d.length() < 1e-5 {
            return;
        }
        let t = 0.5 * (a + b);
        let p = o + d * t;
        let got = m.contains(p);
        if let Some((pos, tris)) = convex {
            let sd = plane_distance(pos, tris, p);
            if sd.abs() < 1e-4 {
                return;
            }
            assert_eq!(sd < 0.0, want, "oracle disagrees at t {t} for o {o:?} d {d:?} spans {spans:?}");
        }
        assert_eq!(got, want, "contains({p:?}) = {got} at t {t}, spans {spans:?}, o {o:?} d {d:?}");
        checked += 1;
    };
    for s in &spans {
        assert!(s.t0 >= prev && s.t1 > s.t0, "spans not sorted/disjoint: {spans:?}");
        if s.t0 > prev {
            probe((prev, s.t0), false);
        }
        probe((s.t0, s.t1), true);
        prev = s.t1;
    }
    if prev < tmax {
        probe((prev, tmax), false);
    }
    checked
}

fn random_dir(rng: &mut SmallRng) -> Vec3 {
    loop {
        let d = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
        if d.length_squared() > 1e-3 && d.length_squared() <= 1.0 {
            return d * rng.gen_range(0.25f32..4.0);
        }
    }
}

fn leak_test(name: &str, pos: Vec<Vec3>, tris: Vec<[u32; 3]>, seed: u64) {
    println!("{name}: seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).unwrap();
    assert_eq!(m.rule(), InsideRule::Orientation, "{:?}", m.warnings());
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    let convex = Some((&pos[..], &tris[..]));
    let mut checked = 0;
    let n = 100_000;
    for _ in 0..n {
        let o = Vec3::new(rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0));
        checked += check_ray(&m, o, random_dir(&mut rng), convex);
    }
    // Rays aimed at vertices and edge midpoints, from outside and from inside.
    let mut aimed = 0;
    let mut entered = 0;
    for t in &tris {
        for e in 0..3 {
            let a = pos[t[e] as usize];
            let b = pos[t[(e + 1) % 3] as usize];
            for target in [a, (a + b) * 0.5] {
                for _ in 0..4 {
                    let o = Vec3::new(rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0), rng.gen_range(-3.0..3.0));
                    let d = target - o;
                    checked += check_ray(&m, o, d, convex);
                    aimed += 1;
                    // A line from outside through a surface point into the interior enters there.
                    let outside = plane_distance(&pos, &tris, o) > 1e-3;
                    if outside && plane_distance(&pos, &tris, o + d * 1.001) < -1e-5 {
                        let xs = m.crossings(o, d, -1e30, 1e30);
                        assert_eq!(xs.len(), 2, "aimed ray leaked: o {o:?} target {target:?}");
                        assert!((xs[0].0 - 1.0).abs() < 1e-4, "entered at t {} not 1", xs[0].0);
                        entered += 1;
                    }
                }
            }
        }
    }
    println!("{name}: {n} random + {aimed} aimed rays ({entered} entering at the aimed point), {checked} midpoints agree with contains() and the plane oracle");
}

#[test]
fn mesh_leak_cube() {
    let (pos, tris) = cube();
    leak_test("cube", pos, tris, 1);
}

#[test]
fn mesh_leak_octasphere() {
    let (pos, tris) = octasphere(4);
    leak_test("octasphere(4)", pos, tris, 2);
}

/// Axis-aligned and diagonal rays through exactly representable vertices, edge
/// points and face diagonals of the cube (exact ties in the watertight test).
#[test]
fn mesh_exact_edge_and_vertex_rays_cube() {
    let (pos, tris) = cube();
    let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).unwrap();
    let mut n = 0;
    let mut hits = 0;
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            for i in -6..=6 {
                for j in -6..=6 {
                    let (u, v) = (i as f32 / 4.0, j as f32 / 4.0);
                    let mut o = Vec3::ZERO;
                    o[(axis + 1) % 3] = u;
                    o[(axis + 2) % 3] = v;
                    o[axis] = -3.0 * sign;
                    let mut d = Vec3::ZERO;
                    d[axis] = sign;
                    check_ray(&m, o, d, Some((&pos, &tris)));
                    let xs = m.crossings(o, d, -1e30, 1e30);
                    if u.abs() < 1.0 && v.abs() < 1.0 {
                        assert_eq!(xs.len(), 2, "missed the cube interior: o {o:?} d {d:?}");
                        assert_eq!((xs[0].0, xs[1].0), (2.0, 4.0));
                        hits += 1;
                    } else if u.abs() > 1.0 || v.abs() > 1.0 {
                        assert!(xs.is_empty());
                    }
                    n += 1;
                }
            }
        }
    }
    // Diagonals through opposite corners, in all 8 directions.
    for c in 0..8 {
        let d = Vec3::new(if c & 1 != 0 { 1.0 } else { -1.0 }, if c & 2 != 0 { 1.0 } else { -1.0 }, if c & 4 != 0 { 1.0 } else { -1.0 });
        let o = -2.0 * d;
        check_ray(&m, o, d, Some((&pos, &tris)));
        let xs = m.crossings(o, d, -1e30, 1e30);
        assert_eq!(xs.len(), 2, "diagonal through corners: {xs:?}");
        assert_eq!((xs[0].0, xs[1].0), (1.0, 3.0));
        n += 1;
    }
    println!("{n} exact-tie rays, {hits} through the interior");
}

/// Axis rays through the exact poles of the octasphere (4 triangles meet there).
#[test]
fn mesh_exact_pole_rays_octasphere() {
    let (pos, tris) = octasphere(3);
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let mut d = Vec3::ZERO;
            d[axis] = sign * 0.5;
            let o = -d * 10.0;
            let xs = m.crossings(o, d, -1e30, 1e30);
            assert_eq!(xs.len(), 2, "{xs:?}");
            assert_eq!((xs[0].0, xs[1].0), (8.0, 12.0));
            let mut s: Vec<crate::Span> = vec![];
            m.spans(&Ray::segment(o, d, 0.0, f32::INFINITY), 3, &mut s);
            assert_eq!(s.len(), 1);
            assert_eq!((s[0].t0, s[0].t1), (8.0, 12.0));
            // Outward normals at both ends.
            let n0 = m.normal(s[0].s0.sub, o + d * s[0].t0);
            let n1 = m.normal(s[0].s1.sub, o + d * s[0].t1);
            assert!(n0.dot(d) < 0.0 && n1.dot(d) > 0.0);
        }
    }
}

#[test]
fn mesh_contains_matches_brute_force_winding_number() {
    let seed = 11;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    for (name, (pos, tris)) in [("cube", cube()), ("octasphere(3)", octasphere(3))] {
        let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
        let mut inside = 0;
        let n = 20_000;
        for _ in 0..n {
            let p = Vec3::new(rng.gen_range(-1.5..1.5), rng.gen_range(-1.5..1.5), rng.gen_range(-1.5..1.5));
            let w = m.winding_number_exact(p);
            if (w - 0.5).abs() < 0.45 {
                continue; // on the surface
            }
            assert_eq!(m.contains(p), w > 0.5, "{name}: contains({p:?}) vs winding number {w}");
            let wf = m.winding_number(p) as f64;
            assert!((wf - w).abs() < 0.05, "{name}: fast winding number {wf} vs exact {w} at {p:?}");
            inside += (w > 0.5) as usize;
        }
        println!("{name}: {n} points, {inside} inside, contains() == (exact winding number > 0.5) for all");
    }
}

/// The octasphere against the analytic unit sphere: every mesh crossing lies between
/// the inscribed and circumscribed spheres, and hit/miss agree outside that shell.
#[test]
fn mesh_octasphere_vs_analytic_sphere() {
    let seed = 5;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let level = 6;
    let (pos, tris) = octasphere(level);
    // Tessellation error: how far inside the unit sphere the flattest triangle plane lies.
    let h = tris
        .iter()
        .map(|t| {
            let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
            1.0 - (b - a).cross(c - a).normalize().dot(a)
        })
        .fold(0.0f32, f32::max);
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let (mut max_r_err, mut max_t_err, mut n_hit, mut n_cmp) = (0.0f32, 0.0f32, 0, 0);
    let n = 50_000;
    for _ in 0..n {
        let o = random_dir(&mut rng).normalize() * rng.gen_range(1.2..4.0);
        let target = Vec3::new(rng.gen_range(-1.1..1.1), rng.gen_range(-1.1..1.1), rng.gen_range(-1.1..1.1));
        let d = (target - o) * rng.gen_range(0.5..2.0);
        let mut s: Vec<crate::Span> = vec![];
        m.spans(&Ray::segment(o, d, f32::NEG_INFINITY, f32::INFINITY), 0, &mut s);
        let a = kernels::sphere(o, d);
        // closest approach of the line to the centre
        let f = (o - d * (o.dot(d) / d.length_squared())).length();
        if f < 1.0 - h - 1e-5 {
            assert_eq!(s.len(), 1, "missed the inscribed sphere: o {o:?} d {d:?}");
        } else if f > 1.0 + 1e-5 {
            assert!(s.is_empty());
        }
        if let (Some(sp), Some((t0, _, t1, _))) = (s.first(), a) {
            n_hit += 1;
            for (tm, ta) in [(sp.t0, t0), (sp.t1, t1)] {
                let r = (o + d * tm).length();
                assert!(r <= 1.0 + 1e-5 && r >= 1.0 - h - 1e-5, "crossing at radius {r}, shell [{}, 1]", 1.0 - h);
                max_r_err = max_r_err.max((1.0 - r).abs());
                // compare t where the ray is not grazing (cos incidence > 0.5)
                let p = o + d * ta;
                if p.normalize().dot(d.normalize()).abs() > 0.5 {
                    max_t_err = max_t_err.max((tm - ta).abs() * d.length());
                    n_cmp += 1;
                }
            }
        }
    }
    println!(
        "octasphere({level}), {} triangles, sagitta {h:.3e}: {n} rays, {n_hit} hits, max radial error {max_r_err:.3e}, max distance error along non-grazing rays {max_t_err:.3e} ({n_cmp} crossings)",
        m.triangle_count()
    );
    assert!(max_t_err <= 2.0 * h + 1e-5);
}

/// Open and inconsistently oriented meshes fall back to the winding number, with a
/// warning, and their spans still agree with contains().
#[test]
fn mesh_open_and_inconsistent_fall_back_to_winding() {
    let seed = 3;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    // hemisphere (z >= 0 half of the octasphere): open
    let (pos, tris) = octasphere(3);
    let half: Vec<[u32; 3]> = tris.iter().copied().filter(|t| t.iter().all(|&k| pos[k as usize].z >= -1e-6)).collect();
    let m = MeshData::new(pos.clone(), half, InsideRule::Orientation).unwrap();
    assert_eq!(m.rule(), InsideRule::Winding);
    assert!(m.warnings()[0].contains("not closed"), "{:?}", m.warnings());
    let r = m.report();
    assert!(r.boundary_edges > 0 && !r.closed && !r.usable_as_solid);
    // cube with one triangle flipped: closed but inconsistent
    let (cpos, mut ctris) = cube();
    ctris[3].swap(1, 2);
    let c = MeshData::new(cpos.clone(), ctris, InsideRule::Orientation).unwrap();
    assert_eq!(c.rule(), InsideRule::Winding);
    assert!(!c.report().consistently_oriented);
    // A good cube under the winding rule.
    let (gpos, gtris) = cube();
    let g = MeshData::new(gpos, gtris, InsideRule::Winding).unwrap();
    let mut max_err = 0.0f64;
    let mut checked = 0;
    for mesh in [&m, &c, &g] {
        for _ in 0..5000 {
            let o = Vec3::new(rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0));
            checked += check_ray_closed(mesh, o, random_dir(&mut rng), None, false);
            let p = Vec3::new(rng.gen_range(-1.2..1.2), rng.gen_range(-1.2..1.2), rng.gen_range(-1.2..1.2));
            max_err = max_err.max((mesh.winding_number(p) as f64 - mesh.winding_number_exact(p)).abs());
        }
    }
    println!("winding rule: {checked} midpoints agree with contains(); max |fast - exact winding number| {max_err:.3e}");
}

#[test]
fn mesh_inside_out_is_flipped() {
    let (pos, mut tris) = cube();
    for t in &mut tris {
        t.swap(1, 2);
    }
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    assert_eq!(m.rule(), InsideRule::Orientation);
    assert!(m.warnings()[0].contains("inside out"));
    assert!(m.contains(Vec3::ZERO) && !m.contains(Vec3::splat(1.5)));
    let mut s: Vec<crate::Span> = vec![];
    m.spans(&Ray::segment(Vec3::new(-3.0, 0.1, 0.2), Vec3::X, 0.0, 100.0), 0, &mut s);
    assert_eq!(s.len(), 1);
    assert_eq!(m.normal(s[0].s0.sub, Vec3::new(-1.0, 0.1, 0.2)), Vec3::NEG_X);
    assert_eq!(m.normal(s[0].s1.sub, Vec3::new(1.0, 0.1, 0.2)), Vec3::X);
}

#[test]
fn mesh_starts_inside_and_clips() {
    let (pos, tris) = cube();
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let mut s: Vec<crate::Span> = vec![];
    m.spans(&Ray::segment(Vec3::new(-3.0, 0.1, 0.2), Vec3::X, 2.5, 3.5), 0, &mut s);
    assert_eq!(s.len(), 1);
    assert_eq!((s[0].t0, s[0].t1, s[0].s0, s[0].s1), (2.5, 3.5, Surf::NONE, Surf::NONE));
    s.clear();
    m.spans(&Ray::segment(Vec3::new(-3.0, 0.1, 0.2), Vec3::X, 2.5, 100.0), 0, &mut s);
    assert_eq!((s[0].t0, s[0].t1, s[0].s0), (2.5, 4.0, Surf::NONE));
    assert!(s[0].s1.is_real());
    s.clear();
    m.spans(&Ray::segment(Vec3::new(-3.0, 0.1, 0.2), Vec3::X, 0.0, 1.0), 0, &mut s);
    assert!(s.is_empty());
    assert_eq!(m.closest_hit(Vec3::new(-3.0, 0.1, 0.2), Vec3::X, 0.0, 100.0).map(|h| h.0), Some(2.0));
}

#[test]
fn mesh_bad_input() {
    let (pos, tris) = cube();
    assert_eq!(MeshData::new(vec![], vec![], InsideRule::Orientation).unwrap_err(), MeshError::Empty);
    let e = MeshData::new(pos.clone(), vec![[0, 1, 8]], InsideRule::Orientation).unwrap_err();
    assert!(matches!(e, MeshError::IndexOutOfRange { triangle: 0, index: 8, vertices: 8 }), "{e}");
    let mut bad = pos.clone();
    bad[3].y = f32::NAN;
    assert_eq!(MeshData::new(bad, tris.clone(), InsideRule::Orientation).unwrap_err(), MeshError::NonFinite { vertex: 3 });
    // one face only: flat
    let e = MeshData::new(pos.clone(), tris[..2].to_vec(), InsideRule::Orientation).unwrap_err();
    assert!(matches!(e, MeshError::NoVolume(_)), "{e}");
    // all degenerate
    assert_eq!(MeshData::new(pos.clone(), vec![[1, 1, 2]], InsideRule::Winding).unwrap_err(), MeshError::Empty);
    // a closed surface of zero volume: two faces back to back
    let flat = vec![[0, 1, 2], [0, 2, 1], [4, 5, 6], [4, 6, 5]];
    let e = MeshData::new(pos.clone(), flat, InsideRule::Orientation).unwrap_err();
    assert!(matches!(e, MeshError::NoVolume(_)), "{e}");
    // split vertices (as in files with UV seams) are welded: still closed
    let mut spos = vec![];
    let mut stris = vec![];
    for t in &tris {
        let b = spos.len() as u32;
        for &k in t {
            spos.push(pos[k as usize]);
        }
        stris.push([b, b + 1, b + 2]);
    }
    let m = MeshData::new(spos, stris, InsideRule::Orientation).unwrap();
    let r = m.report();
    assert_eq!((r.vertices, r.triangles, r.boundary_edges, r.closed), (8, 12, 0, true));
    assert!((r.volume - 8.0).abs() < 1e-9 && (r.area - 24.0).abs() < 1e-9);
}

#[test]
fn mesh_report_counts_self_intersections() {
    // Two overlapping cubes in one mesh: closed and oriented, but crossing.
    let (pos, tris) = cube();
    let mut p2 = pos.clone();
    let mut t2 = tris.clone();
    p2.extend(pos.iter().map(|p| *p * 0.999 + Vec3::new(1.0, 0.5, 0.25)));
    t2.extend(tris.iter().map(|t| t.map(|k| k + 8)));
    let r = MeshData::new(p2, t2, InsideRule::Orientation).unwrap().report();
    println!("two overlapping cubes: {r:?}");
    assert!(r.closed && r.self_intersections.unwrap() > 0);
    let r = MeshData::new(pos, tris, InsideRule::Orientation).unwrap().report();
    assert_eq!(r.self_intersections, Some(0));
    let (pos, tris) = octasphere(4);
    assert_eq!(MeshData::new(pos, tris, InsideRule::Orientation).unwrap().report().self_intersections, Some(0));
    // a tilted flat mesh encloses nothing
    let flat = vec![Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 1.0), Vec3::new(1.0, 2.0, 1.0)];
    let e = MeshData::new(flat, vec![[0, 1, 2], [1, 3, 2]], InsideRule::Winding).unwrap_err();
    assert!(matches!(e, MeshError::NoVolume(_)), "{e}");
}

/// Throughput of closest_hit and spans on a large sphere (run with --ignored in release).
#[test]
#[ignore]
fn mesh_perf() {
    let seed = 9;
    println!("seed {seed}");
    for level in [6, 8, 9] {
        let (pos, tris) = octasphere(level);
        let t = std::time::Instant::now();
        let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
        let build = t.elapsed().as_secs_f64();
        let mut rng = SmallRng::seed_from_u64(seed);
        let rays: Vec<(Vec3, Vec3)> = (0..200_000)
            .map(|_| {
                let o = random_dir(&mut rng).normalize() * 3.0;
                let target = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                (o, target - o)
            })
            .collect();
        let t = std::time::Instant::now();
        let mut hits = 0;
        for &(o, d) in &rays {
            hits += m.closest_hit(o, d, 0.0, f32::INFINITY).is_some() as usize;
        }
        let ch = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let mut spans: Vec<crate::Span> = Vec::with_capacity(8);
        let mut ns = 0;
        for &(o, d) in &rays {
            spans.clear();
            m.spans(&Ray::segment(o, d, 0.0, f32::INFINITY), 0, &mut spans);
            ns += spans.len();
        }
        let sp = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let mut inside = 0;
        for &(o, d) in rays.iter().take(20_000) {
            inside += m.contains(o + d * 0.5) as usize;
        }
        let ct = t.elapsed().as_secs_f64();
        let wt = std::time::Instant::now();
        let mut w = 0.0;
        for &(o, d) in rays.iter().take(20_000) {
            w += m.winding_number(o + d * 0.5);
        }
        let wt = wt.elapsed().as_secs_f64();
        // Coherent rays: a 512 x 512 pinhole camera at distance 3 looking at the sphere.
        let cam: Vec<(Vec3, Vec3)> = (0..512 * 512)
            .map(|i| {
                let (x, y) = ((i % 512) as f32 / 256.0 - 1.0, (i / 512) as f32 / 256.0 - 1.0);
                (Vec3::new(0.0, 0.0, 3.0), Vec3::new(x * 0.45, y * 0.45, -1.0))
            })
            .collect();
        let t = std::time::Instant::now();
        let mut chits = 0;
        for &(o, d) in &cam {
            chits += m.closest_hit(o, d, 0.0, f32::INFINITY).is_some() as usize;
        }
        let cch = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        for &(o, d) in &cam {
            spans.clear();
            m.spans(&Ray::segment(o, d, 0.0, f32::INFINITY), 0, &mut spans);
        }
        let csp = t.elapsed().as_secs_f64();
        println!(
            "octasphere({level}) camera 512x512: closest_hit {:.2} Mrays/s ({chits} hits), spans {:.2} Mrays/s",
            cam.len() as f64 / cch / 1e6,
            cam.len() as f64 / csp / 1e6
        );
        let n = rays.len() as f64;
        println!(
            "octasphere({level}) {} tris: build {build:.3} s; random incoherent rays: closest_hit {:.2} Mrays/s ({hits} hits); spans {:.2} Mrays/s ({ns} spans); contains {:.2} M/s ({inside}); winding_number {:.3} M/s (sum {w:.0})",
            m.triangle_count(),
            n / ch / 1e6,
            n / sp / 1e6,
            20_000.0 / ct / 1e6,
            20_000.0 / wt / 1e6
        );
    }
}

#[test]
#[ignore]
fn mesh_bvh_stats() {
    let (pos, tris) = octasphere(6);
    let m = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let nodes = &m.bvh.nodes;
    let leaves = nodes.iter().filter(|n| n.count > 0).count();
    let prims: u32 = nodes.iter().filter(|n| n.count > 0).map(|n| n.count).sum();
    // depth
    let mut maxd = 0;
    let mut st = vec![(0u32, 0)];
    let mut sa = 0.0f64;
    while let Some((i, d)) = st.pop() {
        maxd = maxd.max(d);
        let n = &nodes[i as usize];
        let e = n.max - n.min;
        sa += (e.x * e.y + e.y * e.z + e.z * e.x) as f64;
        if n.count == 0 {
            st.push((n.first, d + 1));
            st.push((n.first + 1, d + 1));
        }
    }
    println!("{} nodes, {leaves} leaves, {prims} prims, max depth {maxd}, sum half-area {sa:.1}", nodes.len());
    println!("root {:?} child0 {:?} child1 {:?}", nodes[0], nodes[nodes[0].first as usize], nodes[nodes[0].first as usize + 1]);
}

/// The 4-wide walk, the 8-ray packet walk and the old binary walk find the same
/// nearest crossing (coherent bundles, mixed-octant bundles, axis-aligned rays
/// with zero direction components, rays aimed at vertices, clipped ranges), on
/// both node tests of the packet walk (SSE2 and, where the CPU has it, AVX).
#[test]
fn mesh_closest_hit8_matches_single_rays() {
    #[cfg(target_arch = "x86_64")]
    println!("AVX: {}", std::arch::is_x86_feature_detected!("avx"));
    let seed = 21u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    for (name, (pos, tris)) in [("cube", cube()), ("octasphere(5)", octasphere(5))] {
        let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).unwrap();
        let mut bundles = 0;
        for i in 0..3000 {
            let o = random_dir(&mut rng).normalize() * rng.gen_range(1.5..3.0);
            let spread = if i % 3 == 0 { 2.0 } else { 0.05 };
            let base = if i % 5 == 0 {
                pos[rng.gen_range(0..pos.len())] - o
            } else {
                -o + Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5))
            };
            let mut d: [Vec3; 8] = std::array::from_fn(|k| {
                if k == 0 {
                    base
                } else {
                    base + Vec3::new(rng.gen_range(-spread..spread), rng.gen_range(-spread..spread), rng.gen_range(-spread..spread))
                }
            });
            if i % 7 == 0 {
                // Axis-aligned bundle (zero components).
                d = std::array::from_fn(|k| Vec3::new(0.0, 0.0, -1.0 - k as f32 * 0.1));
            }
            let os: [Vec3; 8] = std::array::from_fn(|k| if i % 7 == 0 { Vec3::new(0.1 * k as f32 - 0.35, 0.2, 3.0) } else { o });
            let tmin: [f32; 8] = std::array::from_fn(|k| if k == 3 { 0.5 } else { 0.0 });
            let tmax: [f32; 8] = std::array::from_fn(|k| {
                if k == 5 {
                    0.9
                } else if k == 6 {
                    -1.0
                } else {
                    10.0
                }
            });
            let h8 = m.closest_hit8(&os, &d, &tmin, &tmax);
            // The SSE2 node test (machines without AVX) and the AVX one agree exactly.
            assert_eq!(m.closest_hit8_sse(&os, &d, &tmin, &tmax), h8, "{name}: bundle {i}: SSE2 and dispatched packet walks differ");
            for k in 0..8 {
                let h1 = m.closest_hit(os[k], d[k], tmin[k], tmax[k]);
                assert_eq!(h8[k].map(|h| h.0), h1.map(|h| h.0), "{name}: bundle {i} ray {k}: o {:?} d {:?}", os[k], d[k]);
                let old = m.closest_hit_pairs(os[k], d[k], tmin[k], tmax[k]);
                assert_eq!(old.map(|h| h.0), h1.map(|h| h.0), "{name}: old walk, bundle {i} ray {k}: o {:?} d {:?}", os[k], d[k]);
            }
            bundles += 1;
        }
        println!("{name}: {bundles} bundles agree");
    }
}

/// The packet walk of the nearest query gives every ray what its own
/// `spans_nearest` gives (the same spans and cut, bit for bit), for coherent and
/// spread bundles, bundles aimed at vertices, per-ray clipped ranges and
/// slacks, and starts inside the bounds (left to the single-ray query); with
/// the AVX leaf test (eight rays against one triangle) and without.
#[test]
fn mesh_spans_nearest8_matches_single_rays() {
    let seed = 33u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    for (name, (pos, tris)) in [("cube", cube()), ("octasphere(5)", octasphere(5))] {
        let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).unwrap();
        let (mut packed, mut single) = (0, 0);
        let mut through_held = 0;
        // Rays of narrow bundles from outside the bounds (what camera packets are).
        let (mut narrow, mut narrow_packed) = (0, 0);
        for i in 0..3000 {
            let o = if i % 11 == 0 {
                // Inside the bounds: those rays go one by one.
                Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5))
            } else {
                random_dir(&mut rng).normalize() * rng.gen_range(1.5..3.0)
            };
            let spread = if i % 3 == 0 { 1.0 } else { 0.02 };
            let base = if i % 5 == 0 {
                pos[rng.gen_range(0..pos.len())] - o
            } else {
                -o + Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5))
            };
            let d: [Vec3; 8] = std::array::from_fn(|k| {
                if k == 0 || i % 5 == 0 && k == 4 {
                    base
                } else {
                    base + Vec3::new(rng.gen_range(-spread..spread), rng.gen_range(-spread..spread), rng.gen_range(-spread..spread))
                }
            });
            let tmin: [f32; 8] = std::array::from_fn(|k| if k == 3 { 0.5 } else { 0.0 });
            let tmax: [f32; 8] = std::array::from_fn(|k| {
                if k == 5 {
                    0.9
                } else if k == 6 {
                    -1.0
                } else {
                    10.0
                }
            });
            let slack: [f32; 8] = std::array::from_fn(|k| if k == 2 { 0.0 } else { 1e-4 * k as f32 });
            let active = if i % 13 == 0 { 0b1011_0110 } else { 0xff };
            let mut out: [Vec<Span>; 8] = Default::default();
            let q = NearestRays8 { o, d: &d, tmin: &tmin, tmax: &tmax, slack: &slack, through: &NO_THROUGH, exact: None };
            let (done, cut) = m.spans_nearest8(&q, active, 7, &mut out);
            assert_eq!(done & !active, 0, "{name}: bundle {i}: a ray outside the active set was traced");
            // The SSE2 walk (machines without AVX: every leaf ray by ray) agrees exactly.
            let mut out_sse: [Vec<Span>; 8] = Default::default();
            let sse = m.spans_nearest8_sse(&q, active, 7, &mut out_sse);
            assert_eq!((sse.0, sse.1.map(f32::to_bits)), (done, cut.map(f32::to_bits)), "{name}: bundle {i}: SSE2 walk");
            assert_eq!(out_sse, out, "{name}: bundle {i}: SSE2 walk spans");
            let is_narrow = i % 3 != 0 && i % 11 != 0 && active == 0xff;
            for k in 0..8 {
                if is_narrow && tmax[k] >= tmin[k] {
                    narrow += 1;
                    narrow_packed += (done >> k) & 1;
                }
                if done & (1 << k) == 0 {
                    assert!(out[k].is_empty());
                    single += 1;
                    continue;
                }
                packed += 1;
                let mut one: Vec<Span> = Vec::new();
                let v = m.spans_nearest(&Ray::segment(o, d[k], tmin[k], tmax[k]), slack[k], 7, &mut one);
                // The contract: exact on [tmin, v], i.e. the full query clipped there.
                let mut full: Vec<Span> = Vec::new();
                m.spans(&Ray::segment(o, d[k], tmin[k], v.min(tmax[k])), 7, &mut full);
                assert_eq!(full, one, "{name}: bundle {i} ray {k}: not the full spans on [tmin, {v}]");
                assert_eq!(v, cut[k], "{name}: bundle {i} ray {k}: cut; o {o:?} d {:?}", d[k]);
                let ts = |s: &[Span]| s.iter().map(|s| (s.t0, s.t1, s.s0, s.s1)).collect::<Vec<_>>();
                assert_eq!(ts(&out[k]), ts(&one), "{name}: bundle {i} ray {k}: spans; o {o:?} d {:?}", d[k]);
            }
            // The same bundle with `through` intervals (a subtrahend over the first
            // crossing keeps the walk going to its end): still exact on
            // [tmin, cut], and past the interval's end when the first crossing
            // lies in it; SSE2 and AVX agree.
            let through: [[f32; 2]; 8] = std::array::from_fn(|k| {
                let first = out[k].first().map_or(1.0, |s| s.t0);
                match k % 3 {
                    0 => [first - 0.05, first + rng.gen_range(0.0..0.8)],
                    1 => [first + 0.01, first + 0.3],
                    _ => [f32::INFINITY, f32::NEG_INFINITY],
                }
            });
            let qt = NearestRays8 { through: &through, ..q };
            let mut out_t: [Vec<Span>; 8] = Default::default();
            let nt = m.spans_nearest8(&qt, active, 7, &mut out_t);
            let mut out_ts: [Vec<Span>; 8] = Default::default();
            let nts = m.spans_nearest8_sse(&qt, active, 7, &mut out_ts);
            assert_eq!((nts.0, nts.1.map(f32::to_bits)), (nt.0, nt.1.map(f32::to_bits)), "{name}: bundle {i}: SSE2 walk with through");
            assert_eq!(out_ts, out_t, "{name}: bundle {i}: SSE2 walk spans with through");
            assert_eq!(nt.0, done, "{name}: bundle {i}: the same rays are done with through");
            for k in 0..8 {
                if done & (1 << k) == 0 {
                    continue;
                }
                let v = nt.1[k];
                let mut full: Vec<Span> = Vec::new();
                m.spans(&Ray::segment(o, d[k], tmin[k], v.min(tmax[k])), 7, &mut full);
                assert_eq!(full, out_t[k], "{name}: bundle {i} ray {k}: through {:?}: not the full spans on [tmin, {v}]", through[k]);
                let crossings = m.crossings(o, d[k], tmin[k], tmax[k]);
                if let Some(&(t1, ..)) = crossings.first() {
                    if t1 >= through[k][0] && t1 <= through[k][1] {
                        through_held += 1;
                        assert!(
                            v >= through[k][1].min(tmax[k]),
                            "{name}: bundle {i} ray {k}: cut {v} short of {:?} (first crossing {t1})",
                            through[k]
                        );
                    }
                }
            }
        }
        println!("{name}: {packed} rays traced in packets, {single} left to the single-ray query; narrow bundles: {narrow_packed} of {narrow} rays packed; {through_held} walks held on through a subtrahend");
        assert!(through_held > 1000, "{name}: too few walks held on");
        assert!(narrow_packed * 10 > narrow * 8, "{name}: narrow bundles should go as packets");
    }
}

/// The branch-free child ordering: the hit slots come first, by `t` (up to the
/// two key bits it gives up), each exactly once; checked against a sort, with
/// negative, zero, infinite and tied `t`s.
#[test]
fn mesh_order4_sorts_hit_children() {
    let seed = 44u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let pick = |rng: &mut SmallRng| match rng.gen_range(0..6) {
        0 => 0.0,
        1 => -0.0,
        2 => f32::INFINITY,
        3 => rng.gen_range(-5.0f32..0.0),
        4 => 1.0,
        _ => rng.gen_range(0.0f32..100.0),
    };
    for case in 0..20000 {
        let t: [f32; 4] = std::array::from_fn(|_| pick(&mut rng));
        let hit = rng.gen_range(1u32..16);
        let (order, n) = wide::order4(t, hit);
        assert_eq!(n, hit.count_ones() as usize, "case {case}");
        let mut seen = 0u32;
        for &s in &order {
            seen |= 1 << s;
        }
        assert_eq!(seen, 0xf, "case {case}: {order:?} is not a permutation");
        for i in 0..n {
            assert!(hit & (1 << order[i]) != 0, "case {case}: t {t:?} hit {hit:#b} order {order:?}");
        }
        for i in 1..n {
            let (a, b) = (t[order[i - 1] as usize], t[order[i] as usize]);
            // Keys drop the two low mantissa bits: a may exceed b by a few ulps only.
            assert!(
                a <= b || (a - b).abs() <= 4.0 * a.abs().max(b.abs()) * f32::EPSILON,
                "case {case}: t {t:?} hit {hit:#b} order {order:?}"
            );
        }
    }
}

/// The reference for the self-intersection count: every pair, each edge
/// tested on its own (the straightforward form of the test, kept here as the
/// oracle for the pruned walk and the shared plane signs).
fn brute_self_intersections(tris: &[[Vec3; 3]]) -> usize {
    fn o3(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> f64 {
        (b - a).cross(c - a).dot(d - a)
    }
    fn seg(p: DVec3, q: DVec3, a: DVec3, b: DVec3, c: DVec3) -> bool {
        if !(o3(a, b, c, p) * o3(a, b, c, q) < 0.0) {
            return false;
        }
        let (u, v, w) = (o3(p, q, a, b), o3(p, q, b, c), o3(p, q, c, a));
        (u > 0.0 && v > 0.0 && w > 0.0) || (u < 0.0 && v < 0.0 && w < 0.0)
    }
    let mut n = 0;
    for i in 0..tris.len() {
        for j in i + 1..tris.len() {
            let (a, b) = (tris[i], tris[j]);
            if a.iter().any(|p| b.contains(p)) {
                continue;
            }
            let (a, b) = (a.map(|p| p.as_dvec3()), b.map(|p| p.as_dvec3()));
            if (0..3).any(|e| seg(a[e], a[(e + 1) % 3], b[0], b[1], b[2])) || (0..3).any(|e| seg(b[e], b[(e + 1) % 3], a[0], a[1], a[2])) {
                n += 1;
            }
        }
    }
    n
}

/// The BVH self-walk counts what the all-pairs reference counts, on seeded
/// random triangle soups: some on a small grid (many triangles flat in an axis
/// plane, touching, sharing corners: what the flat-node pruning acts on), some
/// in general position.
#[test]
fn self_intersection_count_matches_all_pairs() {
    let seed = 0x5e1f_0014;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut total = 0;
    for case in 0..200 {
        let grid = case % 2 == 0;
        let pool: Vec<Vec3> = (0..3 + rng.gen_range(0..60))
            .map(|_| {
                if grid {
                    Vec3::new(rng.gen_range(0..4) as f32, rng.gen_range(0..4) as f32, rng.gen_range(0..4) as f32)
                } else {
                    Vec3::new(rng.gen(), rng.gen(), rng.gen())
                }
            })
            .collect();
        let tris: Vec<[Vec3; 3]> = (0..1 + rng.gen_range(0..150))
            .map(|_| {
                let a = pool[rng.gen_range(0..pool.len())];
                let mut b = pool[rng.gen_range(0..pool.len())];
                let mut c = pool[rng.gen_range(0..pool.len())];
                if grid && rng.gen_bool(0.5) {
                    // Flat in an axis: copy one coordinate.
                    let k = rng.gen_range(0..3);
                    b[k] = a[k];
                    c[k] = a[k];
                }
                [a, b, c]
            })
            .collect();
        let boxes: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                let mut b = Aabb::EMPTY;
                t.iter().for_each(|&p| b.grow(p));
                b
            })
            .collect();
        let bvh = FlatBvh::build_binary(&boxes, MAX_LEAF);
        let slots: Vec<[Vec3; 3]> = bvh.prims.iter().map(|&p| tris[p as usize]).collect();
        let want = brute_self_intersections(&tris);
        assert_eq!(selfx::count(&bvh.nodes, &slots), want, "case {case} (seed {seed:#x}), {} triangles", tris.len());
        total += want;
    }
    assert!(total > 1000, "only {total} crossings: the cases test little");
}

/// The octahedron `|p - c|_1 <= r`, each face split into 16 triangles, its
/// corners exact in f32 (as `tests/oracle.rs::octa_mesh` writes it).
fn octahedron(c: Vec3, r: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let (mut pos, mut tris) = (vec![], vec![]);
    let n = 4usize;
    for sx in [-1.0f32, 1.0] {
        for sy in [-1.0f32, 1.0] {
            for sz in [-1.0f32, 1.0] {
                let (a, mut b, mut cc) = (Vec3::new(sx, 0.0, 0.0), Vec3::new(0.0, sy, 0.0), Vec3::new(0.0, 0.0, sz));
                if sx * sy * sz < 0.0 {
                    std::mem::swap(&mut b, &mut cc);
                }
                let mut idx = HashMap::new();
                for i in 0..=n {
                    for j in 0..=n - i {
                        idx.insert((i, j), pos.len() as u32);
                        pos.push(c + (a * (n - i - j) as f32 + b * i as f32 + cc * j as f32) * (r / n as f32));
                    }
                }
                for i in 0..n {
                    for j in 0..n - i {
                        tris.push([idx[&(i, j)], idx[&(i + 1, j)], idx[&(i, j + 1)]]);
                        if i + j + 1 < n {
                            tris.push([idx[&(i + 1, j)], idx[&(i + 1, j + 1)], idx[&(i, j + 1)]]);
                        }
                    }
                }
            }
        }
    }
    (pos, tris)
}

/// Rays of `tests/stress_grazing.rs` that the f32 triangle test alone got
/// wrong, against their exact crossings (rational arithmetic on the same
/// f32 numbers). An octahedron 1e5 from the origin: rays within ~1e-7 rad
/// of a face's plane (the f32 test found a spurious exit and re-entry
/// there, a gap of 4% of the view, or crossed the wrong faces: ends 0.16 of
/// the view off); one 1e-6 across: a ray leaving through an edge between a
/// face it crosses and one it grazes at 1e-4 rad (the f32 test chose the
/// grazed one: the end 6.5e-5 of the view off).
#[test]
fn mesh_grazing_rays_cross_the_right_triangles() {
    let (pos, tris) = octahedron(Vec3::new(60000.0, -48000.0, 64000.0), 1.0);
    let far = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let (pos, tris) = octahedron(Vec3::ZERO, 2f32.powi(-21));
    let small = MeshData::new(pos, tris, InsideRule::Orientation).unwrap();
    let cases: [(&MeshData, [f32; 6], [f64; 2]); 3] = [
        (&far, [59997.473, -48002.96, 64000.566, 0.09717514, 0.08751823, -0.009656917], [26.008129305389755, 33.83223769825351]),
        (&far, [59996.613, -48000.33, 64002.715, 0.08185559, 0.0026659388, -0.084521525], [32.120146112751, 41.374314024202064]),
        (
            &small,
            [-2.6490754e-6, -2.880292e-6, -2.448061e-7, 2.0256984, 2.103552, -0.07844852],
            [1.3077253181547816e-6, 1.3692515536049696e-6],
        ),
    ];
    for (m, r, want) in cases {
        let (o, d) = (Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]));
        let got = m.crossings(o, d, 0.0, f32::INFINITY);
        assert_eq!(got.len(), 2, "o {o:?} d {d:?}: {got:?}");
        for (g, w) in got.iter().zip(want) {
            assert!((g.0 as f64 - w).abs() <= 1e-6 * w, "o {o:?} d {d:?}: {got:?}, want {want:?}");
        }
        let mut spans = Vec::new();
        m.spans(&Ray::new(o, d), 0, &mut spans);
        assert_eq!(spans.len(), 1, "o {o:?} d {d:?}: {spans:?}");
        assert!(
            (spans[0].t0 as f64 - want[0]).abs() <= 1e-6 * want[0] && (spans[0].t1 as f64 - want[1]).abs() <= 1e-6 * want[1],
            "{spans:?}"
        );
    }
}

/// Packets of eight rays with one direction from their own origins (shadow
/// rays leaving a mesh's surface toward a light) get from one walk of the
/// tree exactly the spans each ray's own full walk gives (`spans_on`), with
/// the boxes tested in AVX and lane by lane; lanes whose point at `tmin`
/// lies outside the bounds get what their nearest queries give
/// (`spans_nearest_on`, spans and valid end), or with no slacks given are
/// left to their own queries.
#[test]
fn mesh_spans_parallel8_match_single_rays() {
    let seed = 41u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut lanes_done, mut spans_seen, mut left) = (0usize, 0usize, 0usize);
    let (mut near_lanes, mut cut_spans) = (0usize, 0usize);
    for (name, (pos, tris)) in [("cube", cube()), ("octasphere(5)", octasphere(5)), ("octasphere(2)", octasphere(2))] {
        let m = MeshData::new(pos.clone(), tris.clone(), InsideRule::Orientation).unwrap();
        for i in 0..1500 {
            // A direction toward the light; origins on and near the surface
            // (on vertices: rays through edges and vertices), inside, and a
            // few far outside.
            let d = if i % 7 == 0 { Vec3::new(0.0, -1.0, 0.0) } else { random_dir(&mut rng) * rng.gen_range(0.5..2.0) };
            let base = pos[rng.gen_range(0..pos.len())];
            let o: [Vec3; 8] = std::array::from_fn(|k| match (i + k) % 9 {
                0 => pos[rng.gen_range(0..pos.len())],
                1 => Vec3::new(rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5)),
                2 => random_dir(&mut rng).normalize() * 3.0,
                _ => {
                    base * rng.gen_range(0.97..1.03)
                        + Vec3::new(rng.gen_range(-0.05..0.05), rng.gen_range(-0.05..0.05), rng.gen_range(-0.05..0.05))
                }
            });
            let tmin: [f32; 8] = std::array::from_fn(|k| if k == 3 { 0.01 } else { 0.0 });
            let tmax: [f32; 8] = std::array::from_fn(|k| match k {
                5 => 0.3,
                6 => -1.0,
                _ => f32::INFINITY,
            });
            let x: [Line64; 8] = std::array::from_fn(|k| Line64::of(o[k], d));
            let active = if i % 13 == 0 { 0b1011_0110 } else { 0xff };
            // Slacks of a few eps and of a fifth of the mesh (cuts past
            // several crossings), or none (lanes outside left alone).
            let slack: [f32; 8] = std::array::from_fn(|k| if k % 3 == 0 { 0.2 } else { 4.0 * 1e-6 * (k as f32 + 1.0) });
            let with_slack = i % 5 != 0;
            let q = ParallelRays8 { o: &o, d, tmin: &tmin, tmax: &tmax, x: &x, slack: with_slack.then_some(&slack) };
            let mut builds = vec![false];
            if cfg!(target_arch = "x86_64") && std::arch::is_x86_feature_detected!("avx") {
                builds.push(true);
            }
            for avx in builds {
                let mut out: [Vec<Span>; 8] = Default::default();
                let (done, valid) = m.spans_parallel8_in(&q, (active, avx), 7, &mut out);
                for k in 0..8 {
                    let ray = Ray::segment(o[k], d, tmin[k], tmax[k]);
                    let outside = m.outside_at(o[k], d, tmin[k]);
                    let taken = active & (1 << k) != 0 && tmax[k] >= tmin[k] && (!outside || with_slack);
                    assert_eq!(done & (1 << k) != 0, taken, "seed {seed} {name} ray {i} lane {k} (avx {avx}): done mask");
                    if !taken {
                        left += 1;
                        continue;
                    }
                    let mut want: Vec<Span> = Vec::new();
                    let want_valid = if outside {
                        near_lanes += 1;
                        m.spans_nearest_on(&ray, x[k], slack[k], 7, &mut want)
                    } else {
                        m.spans_on(&ray, x[k], 7, &mut want);
                        f32::INFINITY
                    };
                    let bits = |v: &[Span]| v.iter().map(|s| (s.t0.to_bits(), s.s0, s.t1.to_bits(), s.s1)).collect::<Vec<_>>();
                    assert_eq!(bits(&out[k]), bits(&want), "seed {seed} {name} ray {i} lane {k} (avx {avx}): spans differ");
                    assert_eq!(valid[k].to_bits(), want_valid.to_bits(), "seed {seed} {name} ray {i} lane {k} (avx {avx}): valid end");
                    lanes_done += 1;
                    spans_seen += want.len();
                    cut_spans += (outside && want.last().is_some_and(|s| !s.s1.is_real())) as usize;
                }
            }
        }
    }
    println!(
        "{lanes_done} lanes done ({near_lanes} starting outside the bounds, {cut_spans} of them cut at their slack), \
         {spans_seen} spans, {left} lanes left to their own queries"
    );
    assert!(lanes_done > 30_000 && spans_seen > 10_000 && left > 5_000, "too few lanes or spans exercised");
    assert!(near_lanes > 5_000 && cut_spans > 1_000, "too few lanes starting outside, or cut by their slack");
}
