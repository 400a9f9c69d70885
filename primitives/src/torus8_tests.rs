use crate::kernels::TorusPrep;
use crate::kernels8::Rays8Soa;
use crate::quartic::{negative_runs, RunEnd};
use crate::table::{LeafShape, LeafTable, Torus};
use glam::{DAffine3, Vec3};
use rand::{rngs::SmallRng, Rng, SeedableRng};

fn v(rng: &mut SmallRng, r: f32) -> Vec3 {
    Vec3::new(rng.gen_range(-r..r), rng.gen_range(-r..r), rng.gen_range(-r..r))
}

/// Every field of a prep, bit for bit (`Debug` prints each f64 so that it
/// reads back exactly, `-0.0` and NaN included).
fn bits(p: &Option<TorusPrep>) -> String {
    format!("{p:?}")
}

/// The scalar path's polish of the first negative run's entry, when it is a
/// root (`torus_query_prepped`'s first polish).
fn first_entry(p: &TorusPrep, eps: f64) -> Option<f64> {
    let mut runs = [(RunEnd::Exact(0.0), RunEnd::Exact(0.0)); 3];
    let n = negative_runs(p.quartic().1, &mut runs);
    match runs[0].0 {
        // (Not where its piece lies wholly before the line's t = 0.)
        RunEnd::Root(_) if n > 0 && runs[0].0.hi() >= p.line_start() => Some(runs[0].0.polish(p.quartic().0, eps)),
        _ => None,
    }
}

/// The packet's preps ([`LeafTable::torus_prep8`], the widest build the
/// CPU has, and the AVX and SSE2 builds) are what `TorusPrep::new` makes
/// from each lane's f64 local line, bit for bit, on random ring tori
/// (thin and fat, far from the origin, under shear) and rays aimed at
/// them, grazing them, through their holes, along their axes and missing;
/// both branches of the cubic (one real root, three) and lanes left out.
#[test]
fn packet_torus_preps_match_the_scalar_prep_bit_for_bit() {
    let seed = 31u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut lanes_done, mut some, mut three, mut entries) = (0usize, 0usize, 0usize, 0usize);
    for round in 0..400 {
        // The bake's polish tolerance, and full f64 polishing.
        let torus_tol = if round % 2 == 0 { crate::kernels::TORUS_TOLERANCE as f64 } else { 0.0 };
        let mut t = LeafTable { torus_tol, ..Default::default() };
        let c = v(&mut rng, 3.0) + if round % 7 == 0 { Vec3::splat(1e4) } else { Vec3::ZERO };
        let axis = if round % 5 == 0 { Vec3::Z } else { v(&mut rng, 1.0) + Vec3::Y * 0.05 };
        let major = rng.gen_range(0.2..2.0);
        let minor = major * rng.gen_range(0.02..0.95);
        let m = if round % 3 == 0 {
            DAffine3::IDENTITY
        } else {
            let a = glam::DMat3::from_cols_array(&std::array::from_fn(|_| rng.gen_range(-0.3..0.3))) + glam::DMat3::IDENTITY;
            DAffine3::from_mat3_translation(a, v(&mut rng, 1.0).as_dvec3())
        };
        t.push(&LeafShape::Torus(Torus { center: c, axis, major, minor }), &m).expect("valid torus");
        assert!(t.has_torus_prep(0));
        let world_c = m.transform_point3(c.as_dvec3()).as_vec3();
        for _ in 0..20 {
            // Eyes far off, and near the tube (inside it, in the hole, just
            // off it: lines with runs behind their origins, as shadow rays).
            let reach = if rng.gen_range(0..3) == 0 { 1.3 * major } else { 6.0 * major };
            let eye = world_c + v(&mut rng, reach);
            let aim = match rng.gen_range(0..4) {
                0 => world_c,
                1 => world_c + v(&mut rng, 1.2 * major),
                2 => world_c + v(&mut rng, 0.1 * major),
                _ => world_c + v(&mut rng, 4.0 * major),
            };
            let o: [Vec3; 8] = std::array::from_fn(|k| eye + v(&mut rng, 0.05 * major) * (k as f32));
            let d: [Vec3; 8] = std::array::from_fn(|k| (aim - o[k] + v(&mut rng, 0.2 * major)) * rng.gen_range(0.5..3.0));
            let lanes = if rng.gen_range(0..4) == 0 { rng.gen_range(0..256u32) } else { 0xff };
            let rays = Rays8Soa::new(&o, &d);
            let mut got = [None; 8];
            t.torus_prep8(0, &rays, lanes, &mut got);
            let mut builds = vec![("dispatch", got)];
            #[cfg(target_arch = "x86_64")]
            {
                let mut sse = [None; 8];
                t.torus_prep8_sse(0, &rays, lanes, &mut sse);
                builds.push(("SSE2", sse));
                let mut avx = [None; 8];
                if t.torus_prep8_avx2(0, &rays, lanes, &mut avx) {
                    builds.push(("AVX", avx));
                }
            }
            for k in 0..8 {
                let want = if lanes & (1 << k) != 0 {
                    let (lo, ld) = t.line64_of(0, o[k], d[k]);
                    TorusPrep::new(lo, ld, t.p0[0].x as f64)
                } else {
                    None
                };
                let entry = want.and_then(|p| first_entry(&p, t.torus_tol * t.p0[0].x as f64));
                for (name, b) in &builds {
                    assert_eq!(bits(&b[k].map(|p| p.with_entry(None))), bits(&want), "seed {seed} round {round} lane {k}: {name} differs");
                    let got = b[k].and_then(|p| p.entry()).map(f64::to_bits);
                    assert_eq!(got, entry.map(f64::to_bits), "seed {seed} round {round} lane {k}: {name}'s entry differs");
                }
                entries += entry.is_some() as usize;
                lanes_done += 1;
                if let Some(p) = want {
                    some += 1;
                    three += (format!("{p:?}").matches("n: 5").count() > 0) as usize;
                }
            }
        }
    }
    println!("{lanes_done} lanes, {some} preps, {three} with three critical points inside, {entries} entries polished");
    assert!(
        some > 10_000 && three > 500 && entries > 5_000,
        "too few preps ({some}), three-root lanes ({three}) or entries ({entries}) exercised"
    );
}

/// `through_hole` culls a line only where it misses the torus: on random
/// ring tori (major radius 1, minor `rho`) and lines aimed at their holes,
/// inner equators and tubes (axis-parallel, in the plane, and tilted), no
/// point of a culled chord inside the bounding sphere is inside the solid
/// (point classification at 4001 points of the chord), and the test is not
/// vacuous: many lines are culled, and many are not.
#[test]
fn lines_culled_through_the_hole_miss_the_torus() {
    use glam::DVec3;
    let seed = 77u64;
    println!("seed {seed}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut culled, mut kept, mut kept_hitting) = (0usize, 0usize, 0usize);
    for i in 0..20_000 {
        let rho: f64 = rng.gen_range(0.02..0.9);
        // A point in the hole, near the inner equator, or in the tube.
        let r = match i % 3 {
            0 => rng.gen_range(0.0..1.0 - rho),
            1 => (1.0 - rho) * (1.0 + rng.gen_range(-1e-3..1e-3)),
            _ => rng.gen_range(1.0 - rho..1.0 + rho),
        };
        let a: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
        let p = DVec3::new(r * a.cos(), r * a.sin(), rng.gen_range(-1.2..1.2) * rho);
        let d = match i % 5 {
            0 => DVec3::new(rng.gen_range(-1e-3..1e-3), rng.gen_range(-1e-3..1e-3), 1.0),
            1 => DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 0.0),
            _ => DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
        };
        let Some(dn) = d.try_normalize() else { continue };
        // The line as `TorusLine::new` has it: its point nearest the
        // centre, and the half chord of the bounding sphere.
        let oc = p - dn * p.dot(dn);
        let h2 = (1.0 + rho) * (1.0 + rho) - oc.length_squared();
        if h2 <= 0.0 {
            continue;
        }
        let h = h2.sqrt() * (1.0 + 1e-9) + 1e-12;
        let inside = |s: f64| {
            let q = oc + dn * s;
            let ring = (q.x * q.x + q.y * q.y).sqrt() - 1.0;
            ring * ring + q.z * q.z <= rho * rho
        };
        let hits = (0..=4000).any(|j| inside(-h + 2.0 * h * j as f64 / 4000.0)) || inside(-p.dot(dn));
        if crate::kernels::through_hole(oc, dn, (rho, h)) {
            culled += 1;
            assert!(!hits, "seed {seed} line {i}: culled, yet inside the torus (rho {rho}, oc {oc:?}, dn {dn:?})");
        } else {
            kept += 1;
            kept_hitting += hits as usize;
        }
    }
    println!("{culled} culled, {kept} kept ({kept_hitting} of them meet the torus)");
    assert!(culled > 2000 && kept_hitting > 2000, "seed {seed}: too few lines of a kind");
    // A spindle or horn torus (rho >= 1) has no hole: the points near its
    // axis are inside, and no line is culled (a cull there broke
    // tests/stress.rs `torus_ratios` at ratios 1e3 to 1e20).
    for i in 0..2000 {
        let rho = [1.0, 1.5, 10.0, 1e3][i % 4];
        let p = DVec3::new(rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1), rng.gen_range(-1.0..1.0) * rho);
        let Some(dn) = DVec3::new(rng.gen_range(-0.1..0.1), rng.gen_range(-0.1..0.1), 1.0).try_normalize() else { continue };
        let oc = p - dn * p.dot(dn);
        let h = ((1.0 + rho) * (1.0 + rho) - oc.length_squared()).sqrt();
        assert!(!crate::kernels::through_hole(oc, dn, (rho, h)), "seed {seed}: a line near the axis of a torus of rho {rho} culled");
    }
}
