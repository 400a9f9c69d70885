use super::*;
use crate::table::{push_clipped, Cone, Cuboid, Cylinder, HalfSpace, LeafKind, LeafShape, Sphere};
use crate::{Ray, Span, Surf};
use glam::DAffine3;
use rand::{rngs::SmallRng, Rng, SeedableRng};

fn v(rng: &mut SmallRng, r: f32) -> Vec3 {
    Vec3::new(rng.gen_range(-r..r), rng.gen_range(-r..r), rng.gen_range(-r..r))
}

/// The SSE2 and two-register AVX builds of the kernels give exactly what
/// `ranges8` gave (the widest build the CPU has: AVX-512F on most x86_64
/// servers), for leaf `i` and the lanes `lanes` of `rays`.
fn builds_agree(t: &LeafTable, i: u32, (rays, lanes): (&Rays8Soa, u32), r: &Ranges8, what: &str) {
    #[cfg(target_arch = "x86_64")]
    {
        let mut builds = vec![("SSE2", Ranges8::default())];
        t.ranges8_sse(i, rays, lanes, &mut builds[0].1);
        let mut avx = Ranges8::default();
        if t.ranges8_avx2(i, rays, lanes, &mut avx) {
            builds.push(("AVX", avx));
        }
        for (name, s) in &builds {
            assert_eq!((r.done, r.hit), (s.done, s.hit), "leaf {i} {what}: {name} masks differ");
            for k in 0..8 {
                if r.hit & (1 << k) != 0 {
                    let a = (r.t0[k].to_bits(), r.s0[k], r.t1[k].to_bits(), r.s1[k]);
                    assert_eq!(a, (s.t0[k].to_bits(), s.s0[k], s.t1[k].to_bits(), s.s1[k]), "leaf {i} lane {k} {what}: {name} differs");
                }
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (t, i, rays, lanes, r, what);
}

/// A leaf table of every kind with a packet kernel, under random affine
/// maps with shear (and some axis-aligned ones, whose rays meet faces
/// edge-on), far from and near the origin.
fn table(rng: &mut SmallRng) -> LeafTable {
    let mut t = LeafTable::default();
    for j in 0..72 {
        let c = v(rng, 3.0) + if j % 5 == 0 { Vec3::splat(1e4) } else { Vec3::ZERO };
        let shape = match j % 6 {
            // Cones with the apex at either end, and frusta.
            4 | 5 => {
                let r = rng.gen_range(0.1..1.0);
                let (ra, rb) = match rng.gen_range(0..3) {
                    0 => (r, 0.0),
                    1 => (0.0, r),
                    _ => (r, rng.gen_range(0.05..1.0)),
                };
                LeafShape::Cone(Cone { a: c, b: c + v(rng, 2.0) + Vec3::Y * 0.1, radius_a: ra, radius_b: rb })
            }
            0 => LeafShape::Sphere(Sphere { center: c, radius: rng.gen_range(0.1..2.0) }),
            1 => {
                let h = Vec3::new(rng.gen_range(0.1..2.0), rng.gen_range(0.1..2.0), rng.gen_range(0.1..2.0));
                LeafShape::Cuboid(Cuboid { min: c - h, max: c + h })
            }
            2 => LeafShape::Cylinder(Cylinder { a: c, b: c + v(rng, 2.0) + Vec3::X * 0.1, radius: rng.gen_range(0.1..1.0) }),
            _ => LeafShape::HalfSpace(HalfSpace { normal: v(rng, 1.0) + Vec3::Y * 0.05, offset: rng.gen_range(-2.0..2.0) }),
        };
        let m = if rng.gen_range(0..3) == 0 {
            DAffine3::IDENTITY
        } else {
            let a = glam::DMat3::from_cols_array(&std::array::from_fn(|_| rng.gen_range(-1.0..1.0))) + glam::DMat3::IDENTITY * 1.5;
            DAffine3::from_mat3_translation(a, v(rng, 2.0).as_dvec3())
        };
        t.push(&shape, &m).expect("valid leaf");
    }
    t
}

/// Every lane that the packet kernel marks done gets exactly the spans
/// `spans_in` gives its ray (same t bits, same surfaces, after the same
/// clipping); the AVX and SSE2 builds agree lane for lane; every lane asked
/// is done (every packet kernel is f64: no direction needs rescaling).
#[test]
fn packet_kernels_match_the_scalar_kernels_bit_for_bit() {
    let seed = 8u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let t = table(&mut rng);
    let (mut lanes_done, mut lanes_hit) = (0u64, 0u64);
    for round in 0..6000 {
        let i = rng.gen_range(0..t.len() as u32);
        assert!(t.has_kernel8(i));
        let shared = round % 2 == 0;
        let o0 = v(&mut rng, 8.0);
        let base = v(&mut rng, 1.0);
        let o: [Vec3; 8] = std::array::from_fn(|_| if shared { o0 } else { v(&mut rng, 8.0) });
        let d: [Vec3; 8] = std::array::from_fn(|k| match (round % 7, k) {
            // Axis-parallel directions and zero components (flat slabs).
            (0, 0) => Vec3::X,
            (0, 1) => Vec3::new(0.0, -1.0, 0.0),
            (0, 2) => Vec3::new(0.3, 0.0, -0.7),
            // A direction too small for the kernels' range: rescaled by the scalar path.
            (1, 3) => Vec3::splat(1e-12),
            _ => base + v(&mut rng, 0.1),
        });
        let lanes = rng.gen_range(1..256u32);
        let rays = Rays8Soa::new(&o, &d);
        let mut r = Ranges8::default();
        t.ranges8(i, &rays, lanes, &mut r);
        builds_agree(&t, i, (&rays, lanes), &r, &format!("round {round}"));
        assert_eq!(r.done & !lanes, 0);
        for k in 0..8 {
            if lanes & (1 << k) == 0 {
                continue;
            }
            let tmin = if k % 3 == 0 { rng.gen_range(0.0..5.0) } else { 0.0 };
            let tmax = if k % 4 == 1 { rng.gen_range(tmin..20.0) } else { f32::INFINITY };
            let ray = Ray::segment(o[k], d[k], tmin, tmax);
            let mut want: Vec<Span> = Vec::new();
            t.spans_in(i, &ray, (tmin, tmax), &mut want);
            assert!(r.done & (1 << k) != 0, "leaf {i} lane {k} left undone");
            lanes_done += 1;
            let mut got: Vec<Span> = Vec::new();
            if r.hit & (1 << k) != 0 {
                lanes_hit += 1;
                let sp = Span { t0: r.t0[k], s0: Surf::new(i, r.s0[k]), t1: r.t1[k], s1: Surf::new(i, r.s1[k]) };
                push_clipped(&mut got, sp, tmin, tmax);
            }
            let bits = |s: &Vec<Span>| s.iter().map(|x| (x.t0.to_bits(), x.s0, x.t1.to_bits(), x.s1)).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "leaf {i} ({:?}) lane {k} round {round}", t.kind[i as usize]);
        }
    }
    let kinds: Vec<LeafKind> = (0..t.len()).map(|i| t.kind[i]).collect();
    let count = |k: LeafKind| kinds.iter().filter(|&&x| x == k).count();
    println!(
        "{lanes_done} lanes compared, {lanes_hit} meeting their leaf; balls {}, ellipsoids {}, cones {}",
        count(LeafKind::Sphere),
        count(LeafKind::Ellipsoid),
        count(LeafKind::Cone)
    );
    assert!(count(LeafKind::Sphere) > 0 && count(LeafKind::Ellipsoid) > 0 && count(LeafKind::Cone) > 0);
    assert!(lanes_hit > 3000 && lanes_done > 10000);
}

/// The same comparison on adversarial rays: coordinates and direction
/// components drawn from signed zeros, the canonical faces (0, ±1, ±0.5),
/// tiny and huge values, so that lanes start on faces, run inside them,
/// divide by zero and overflow; leaves with and without a map.
#[test]
fn packet_kernels_match_the_scalar_kernels_on_edge_cases() {
    let seed = 0x0ed6e5u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut t = LeafTable::default();
    let id = DAffine3::IDENTITY;
    t.push(&LeafShape::Sphere(Sphere { center: Vec3::ZERO, radius: 1.0 }), &id).unwrap();
    t.push(&LeafShape::Cuboid(Cuboid { min: Vec3::splat(-0.5), max: Vec3::splat(0.5) }), &id).unwrap();
    t.push(&LeafShape::Cylinder(Cylinder { a: Vec3::ZERO, b: Vec3::Z, radius: 1.0 }), &id).unwrap();
    t.push(&LeafShape::HalfSpace(HalfSpace { normal: Vec3::Y, offset: 0.5 }), &id).unwrap();
    t.push(&LeafShape::Sphere(Sphere { center: Vec3::new(1e3, 0.0, 0.0), radius: 1e-3 }), &id).unwrap();
    t.push(&LeafShape::Cone(Cone { a: Vec3::ZERO, b: Vec3::Z, radius_a: 1.0, radius_b: 0.0 }), &id).unwrap();
    t.push(&LeafShape::Cone(Cone { a: Vec3::ZERO, b: Vec3::Y, radius_a: 0.0, radius_b: 0.5 }), &id).unwrap();
    t.push(&LeafShape::Cone(Cone { a: Vec3::ZERO, b: Vec3::X, radius_a: 1.0, radius_b: 0.5 }), &id).unwrap();
    let vals = [0.0f32, -0.0, 1.0, -1.0, 0.5, -0.5, 1e-30, -1e-30, 1e30, -1e30, 2.0, 1e3, 1e-3, f32::MIN_POSITIVE];
    let pick = |rng: &mut SmallRng| vals[rng.gen_range(0..vals.len())];
    let (mut compared, mut hits) = (0u64, 0u64);
    for round in 0..20000 {
        let i = rng.gen_range(0..t.len() as u32);
        let o: [Vec3; 8] = std::array::from_fn(|_| Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng)));
        let d: [Vec3; 8] = std::array::from_fn(|_| loop {
            let v = Vec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
            if v != Vec3::ZERO {
                break v;
            }
        });
        let rays = Rays8Soa::new(&o, &d);
        let mut r = Ranges8::default();
        t.ranges8(i, &rays, 0xff, &mut r);
        builds_agree(&t, i, (&rays, 0xff), &r, &format!("round {round}"));
        for k in 0..8 {
            let ray = Ray::new(o[k], d[k]);
            // Every packet kernel is f64: every lane is done.
            assert!(r.done & (1 << k) != 0, "leaf {i} lane {k} round {round}: done");
            compared += 1;
            let mut want: Vec<Span> = Vec::new();
            t.spans_in(i, &ray, (f32::NEG_INFINITY, f32::INFINITY), &mut want);
            let mut got: Vec<Span> = Vec::new();
            if r.hit & (1 << k) != 0 {
                hits += 1;
                let sp = Span { t0: r.t0[k], s0: Surf::new(i, r.s0[k]), t1: r.t1[k], s1: Surf::new(i, r.s1[k]) };
                push_clipped(&mut got, sp, f32::NEG_INFINITY, f32::INFINITY);
            }
            let bits = |s: &Vec<Span>| s.iter().map(|x| (x.t0.to_bits(), x.s0, x.t1.to_bits(), x.s1)).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "leaf {i} ({:?}) lane {k} round {round}: o {:?} d {:?}", t.kind[i as usize], o[k], d[k]);
        }
    }
    println!("{compared} lanes compared, {hits} meeting their leaf");
    assert!(compared > 50_000 && hits > 10_000);
}

/// Cones on rays nearly parallel to a generator (the quadratic's leading
/// coefficient near 0: the linear case and its threshold), through the apex
/// region and along the axis: bit for bit against `spans_in`.
#[test]
fn packet_cones_match_the_scalar_cone_along_generators() {
    let seed = 0xc0e5u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut t = LeafTable::default();
    let id = DAffine3::IDENTITY;
    // Radius 1 - z/2 over 0 <= z <= 1 (generators run along (-cos f / 2, -sin f / 2, 1)), and an apex cone.
    t.push(&LeafShape::Cone(Cone { a: Vec3::ZERO, b: Vec3::Z, radius_a: 1.0, radius_b: 0.5 }), &id).unwrap();
    t.push(&LeafShape::Cone(Cone { a: Vec3::ZERO, b: Vec3::Z, radius_a: 0.5, radius_b: 0.0 }), &id).unwrap();
    let (mut compared, mut hits, mut linear) = (0u64, 0u64, 0u64);
    for round in 0..20000 {
        let i = rng.gen_range(0..2u32);
        let slope = 0.5f32;
        let o: [Vec3; 8] = std::array::from_fn(|_| v(&mut rng, 1.5));
        let d: [Vec3; 8] = std::array::from_fn(|k| {
            let f = rng.gen_range(0.0..std::f32::consts::TAU);
            let g = Vec3::new(-slope * f.cos(), -slope * f.sin(), 1.0) * if k % 2 == 0 { 1.0 } else { -1.0 };
            match round % 3 {
                0 => g,
                1 => g + v(&mut rng, 1.0) * 10f32.powi(-rng.gen_range(3..9)),
                _ => Vec3::new(0.0, 0.0, if k % 2 == 0 { 1.0 } else { -1.0 }) + v(&mut rng, 1e-3),
            }
        });
        let rays = Rays8Soa::new(&o, &d);
        let mut r = Ranges8::default();
        t.ranges8(i, &rays, 0xff, &mut r);
        builds_agree(&t, i, (&rays, 0xff), &r, &format!("round {round}"));
        for k in 0..8 {
            let ray = Ray::new(o[k], d[k]);
            assert!(r.done & (1 << k) != 0);
            let (dx, dy) = (d[k].x as f64, d[k].y as f64);
            let wd = -slope as f64 * d[k].z as f64;
            linear += ((dx * dx + dy * dy - wd * wd).abs() <= 1e-9) as u64;
            compared += 1;
            let mut want: Vec<Span> = Vec::new();
            t.spans_in(i, &ray, (f32::NEG_INFINITY, f32::INFINITY), &mut want);
            let mut got: Vec<Span> = Vec::new();
            if r.hit & (1 << k) != 0 {
                hits += 1;
                let sp = Span { t0: r.t0[k], s0: Surf::new(i, r.s0[k]), t1: r.t1[k], s1: Surf::new(i, r.s1[k]) };
                push_clipped(&mut got, sp, f32::NEG_INFINITY, f32::INFINITY);
            }
            let bits = |s: &Vec<Span>| s.iter().map(|x| (x.t0.to_bits(), x.s0, x.t1.to_bits(), x.s1)).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "cone {i} lane {k} round {round}: o {:?} d {:?}", o[k], d[k]);
        }
    }
    println!("{compared} lanes compared, {hits} meeting their cone, {linear} nearly parallel to a generator");
    assert!(hits > 20_000 && linear > 1000);
}

/// The kernels' miss pretests (`side_slab_miss`, `ball_miss`) never call a
/// line a miss that the solve meets. Lines grazing each ball, ellipsoid,
/// cylinder and cone (found by bisection between a line through the
/// leaf and one far beside it, on the scalar `spans_in`: silhouettes,
/// rims, apexes) are nudged by 1e-2 to 1e-7 of the leaf's size either
/// way; each goes as a packet of eight copies through `ranges8_beside`, so
/// that the kernel answers without solving exactly where the pretest calls
/// it a miss, and is compared with `spans_in` and with the builds that
/// solve every packet (`ranges8_sse`, `ranges8_avx2`) bit for bit. And the pretests are not idle:
/// they call most lines that pass 1e-2 beside a leaf misses.
// (x86_64 only: elsewhere there are no packet kernels, every lane goes the
// scalar way.)
#[cfg(target_arch = "x86_64")]
#[test]
fn miss_pretests_never_drop_a_hit() {
    let seed = 0x9ba2e5u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut compared, mut hits, mut wrong, mut near_misses, mut called) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let bits = |s: &Vec<Span>| s.iter().map(|x| (x.t0.to_bits(), x.s0, x.t1.to_bits(), x.s1)).collect::<Vec<_>>();
    for round in 0..400 {
        // One leaf, under a similarity or a shear, near or far from the origin.
        let far = if round % 4 == 0 { Vec3::splat(3e3) } else { Vec3::ZERO };
        let c = v(&mut rng, 3.0) + far;
        let axis = v(&mut rng, 1.0) + Vec3::Y * 0.2;
        let r = rng.gen_range(0.05..1.0);
        let (shape, mid) = match round % 4 {
            0 | 1 => (LeafShape::Sphere(Sphere { center: c, radius: r }), c),
            2 => (LeafShape::Cylinder(Cylinder { a: c, b: c + axis, radius: r }), c + 0.5 * axis),
            _ => {
                let (ra, rb) = [(r, 0.0), (0.0, r), (r, 0.3 * r)][rng.gen_range(0..3)];
                (LeafShape::Cone(Cone { a: c, b: c + axis, radius_a: ra, radius_b: rb }), c + if ra > rb { 0.25 } else { 0.75 } * axis)
            }
        };
        let m = if round % 3 == 0 {
            DAffine3::IDENTITY
        } else {
            let a = glam::DMat3::from_cols_array(&std::array::from_fn(|_| rng.gen_range(-0.5..0.5))) + glam::DMat3::IDENTITY;
            // About `mid`, so that it stays inside and near the origin's offset.
            DAffine3::from_translation(mid.as_dvec3()) * DAffine3::from_mat3(a) * DAffine3::from_translation(-mid.as_dvec3())
        };
        let mut t = LeafTable::default();
        t.push(&shape, &m).expect("valid leaf");
        let size = 2.0 * r + axis.length();
        let meets = |o: Vec3, d: Vec3| {
            let mut s: Vec<Span> = Vec::new();
            t.spans_in(0, &Ray::new(o, d), (f32::NEG_INFINITY, f32::INFINITY), &mut s);
            !s.is_empty()
        };
        for _ in 0..10 {
            let d = v(&mut rng, 1.0).normalize_or(Vec3::X);
            let u = d.any_orthonormal_vector().lerp(d.cross(Vec3::Y).normalize_or(Vec3::Z), rng.gen_range(0.0..1.0)).normalize();
            let o = mid - 4.0 * size * d;
            let (mut lo, mut hi) = (0.0f32, 4.0 * size);
            if !meets(o, d) || meets(o + hi * u, d) {
                continue;
            }
            for _ in 0..60 {
                let s = 0.5 * (lo + hi);
                if meets(o + s * u, d) {
                    lo = s;
                } else {
                    hi = s;
                }
            }
            for e in 2..=7 {
                for sign in [1.0f32, -1.0] {
                    let s = if sign > 0.0 { hi } else { lo } + sign * size * 10f32.powi(-e);
                    let oe = o + s * u;
                    let rays = Rays8Soa::new(&[oe; 8], &[d; 8]);
                    let mut got8 = Ranges8::default();
                    t.ranges8_beside(0, &rays, 0xff, &mut got8);
                    builds_agree(&t, 0, (&rays, 0xff), &got8, &format!("round {round} offset {sign}e-{e}"));
                    let mut want: Vec<Span> = Vec::new();
                    t.spans_in(0, &Ray::new(oe, d), (f32::NEG_INFINITY, f32::INFINITY), &mut want);
                    let mut got: Vec<Span> = Vec::new();
                    if got8.hit & 1 != 0 {
                        let sp = Span { t0: got8.t0[0], s0: Surf::new(0, got8.s0[0]), t1: got8.t1[0], s1: Surf::new(0, got8.s1[0]) };
                        push_clipped(&mut got, sp, f32::NEG_INFINITY, f32::INFINITY);
                    }
                    assert_eq!(bits(&got), bits(&want), "{:?} round {round}: o {oe:?} d {d:?}", t.kind[0]);
                    let sure = t.sure_misses8(0, &rays) & 1 != 0;
                    wrong += (sure && !want.is_empty()) as u64;
                    hits += !want.is_empty() as u64;
                    compared += 1;
                    if e == 2 && sign > 0.0 && want.is_empty() {
                        near_misses += 1;
                        called += sure as u64;
                    }
                }
            }
        }
    }
    println!("{compared} grazing lines compared, {hits} meeting their leaf; {called} of {near_misses} passing 1e-2 beside called misses");
    assert_eq!(wrong, 0, "lines called misses that meet their leaf");
    assert!(compared > 20_000 && hits > 8_000);
    assert!(called * 10 > near_misses * 6 && near_misses > 1000);
}

/// `BesideOdds` turns the pretests on where most solves have every lane
/// missing and off where most have a lane meeting the leaf, and its
/// answers are `ranges8`'s whichever it picks: a cylinder's packets beside
/// it, then through it, then beside it again.
#[test]
fn beside_odds_follow_the_solves() {
    let seed = 0x0dd5u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut t = LeafTable::default();
    t.push(&LeafShape::Cylinder(Cylinder { a: Vec3::ZERO, b: Vec3::Y, radius: 0.5 }), &DAffine3::IDENTITY).unwrap();
    let mut odds = BesideOdds::default();
    assert!(!odds.pays(LeafKind::Cylinder), "off before any solve");
    let packet = |beside: bool, rng: &mut SmallRng| {
        // Lines along z at heights inside the slab, beside the side (|x| > 0.6) or through it.
        let o: [Vec3; 8] = std::array::from_fn(|_| {
            let x = if beside { rng.gen_range(0.6..2.0) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 } } else { rng.gen_range(-0.4..0.4) };
            Vec3::new(x, rng.gen_range(0.1..0.9), -5.0)
        });
        let d: [Vec3; 8] = std::array::from_fn(|_| Vec3::new(rng.gen_range(-0.01..0.01), 0.0, 1.0));
        Rays8Soa::new(&o, &d)
    };
    for (phase, beside, want) in [(0, true, true), (1, false, false), (2, true, true)] {
        for round in 0..200 {
            let rays = packet(beside, &mut rng);
            let (mut got, mut plain) = (Ranges8::default(), Ranges8::default());
            odds.solve(&t, 0, &rays, 0xff, &mut got);
            t.ranges8(0, &rays, 0xff, &mut plain);
            assert_eq!((got.done, got.hit), (plain.done, plain.hit), "phase {phase} round {round}");
            for k in 0..8 {
                if plain.hit & (1 << k) != 0 {
                    assert_eq!((got.t0[k].to_bits(), got.t1[k].to_bits()), (plain.t0[k].to_bits(), plain.t1[k].to_bits()));
                }
            }
            assert_eq!(plain.hit == 0, beside, "phase {phase} round {round}: the packet is not what it should be");
        }
        assert_eq!(odds.pays(LeafKind::Cylinder), want, "phase {phase}");
    }
}
