//! Tests of [`super`]: against roots known by construction, against the generic
//! [`crate::poly::roots_in_tol`], and (through the torus kernel) against
//! [`crate::kernels::torus_reference`]'s dense sampling plus bisection.

use glam::{DVec3, Vec3};
use rand::{rngs::SmallRng, Rng, SeedableRng};

use super::*;
use crate::{kernels, poly};

/// Coefficients `[c0, c1, c2]` of `(s^2 + al s + be)(s^2 - al s + ga)`, which is
/// a depressed quartic.
fn from_factors(al: f64, be: f64, ga: f64) -> [f64; 3] {
    [be * ga, al * (ga - be), be + ga - al * al]
}

#[test]
fn cube_root_is_close_to_libm() {
    let seed = 0xCB27u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut worst = 0.0f64;
    for _ in 0..100000 {
        let x = rng.gen_range(-1.0..1.0) * 10f64.powf(rng.gen_range(-300.0..300.0));
        let e = ((cbrt(x) - x.cbrt()) / x.cbrt()).abs();
        worst = worst.max(e);
    }
    for x in [0.0, -0.0, 1e-310, -1e-320, 1.0, -8.0, f64::MAX, f64::MIN_POSITIVE] {
        let e = ((cbrt(x) - x.cbrt()) / x.cbrt().abs().max(1e-300)).abs();
        worst = worst.max(e);
    }
    println!("worst relative error {worst:.3e}");
    assert!(worst <= 1e-12);
}

#[test]
fn cubic_roots_match_known_roots() {
    let seed = 0xC0B1Cu64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut worst = 0.0f64;
    for case in 0..20000 {
        let scale = 10f64.powf(rng.gen_range(-3.0..2.0));
        let mut out = [0.0; 3];
        if case % 2 == 0 {
            // Three real roots summing to 0, some nearly double.
            let r0 = rng.gen_range(-1.0..1.0) * scale;
            let gap = if case % 4 == 0 { 10f64.powf(rng.gen_range(-9.0..0.0)) } else { rng.gen_range(0.0..2.0) };
            let r1 = r0 + gap * scale;
            let r2 = -(r0 + r1);
            let mut want = [r0, r1, r2];
            want.sort_by(f64::total_cmp);
            let (p, r) = (r0 * r1 + r0 * r2 + r1 * r2, -r0 * r1 * r2);
            let n = depressed_cubic_roots(p, r, &mut out);
            let sep = (want[1] - want[0]).min(want[2] - want[1]);
            if n == 3 {
                for k in 0..3 {
                    let e = (out[k] - want[k]).abs();
                    // A root of a near-double pair is ill-conditioned: the
                    // rounding of the coefficients over the slope there.
                    let w = want[k];
                    let slack = 1e-14 * (w.abs().powi(3) + p.abs() * w.abs() + r.abs()) / (3.0 * w * w + p).abs();
                    assert!(e <= 1e-12 * scale + slack, "case {case}: {out:?} vs {want:?}");
                    if slack < 1e-12 * scale {
                        worst = worst.max(e / scale);
                    }
                }
            } else {
                // Rounding may merge a pair closer than ~sqrt(f64 eps).
                assert!(n == 1 && sep <= 1e-7 * scale, "case {case}: {n} roots {out:?} vs {want:?}");
            }
        } else {
            // (s - r0)(s^2 + r0 s + k), k > r0^2 / 4: one real root.
            let r0 = rng.gen_range(-1.0..1.0) * scale;
            let k = r0 * r0 / 4.0 + 10f64.powf(rng.gen_range(-6.0..0.5)) * scale * scale;
            let n = depressed_cubic_roots(k - r0 * r0, -r0 * k, &mut out);
            assert_eq!(n, 1, "case {case}");
            let e = (out[0] - r0).abs() / scale;
            assert!(e <= 1e-12, "case {case}: {} vs {r0}", out[0]);
            worst = worst.max(e);
        }
    }
    println!("worst error / scale {worst:.3e}");
}

#[test]
fn quartic_roots_match_products_of_known_factors() {
    let seed = 0x4_0A27u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut worst = 0.0f64;
    let (mut lost_pairs, mut generic_lost, mut widest_lost) = (0, 0, 0.0f64);
    for case in 0..20000 {
        let scale = 10f64.powf(rng.gen_range(-2.0..1.0));
        let r0 = rng.gen_range(-1.0..1.0) * scale;
        let gap = if case % 3 == 0 { 10f64.powf(rng.gen_range(-10.0..-1.0)) } else { rng.gen_range(0.0..1.5) } * scale;
        let r1 = r0 + gap;
        let al = -(r0 + r1);
        let be = r0 * r1;
        // The other factor: two real roots (summing to al) or a complex pair.
        let (ga, mut want) = if case % 2 == 0 {
            let d = rng.gen_range(0.0..1.5) * scale;
            let (r2, r3) = (0.5 * al - d, 0.5 * al + d);
            (r2 * r3, vec![r0, r1, r2, r3])
        } else {
            (al * al / 4.0 + 10f64.powf(rng.gen_range(-4.0..0.0)) * scale * scale, vec![r0, r1])
        };
        want.sort_by(f64::total_cmp);
        let c = from_factors(al, be, ga);
        let h = 2.0 * scale;
        let want: Vec<f64> = want.into_iter().filter(|r| r.abs() <= h).collect();
        let mut out = [0.0; 4];
        let n = depressed_quartic_roots(&c, h, 0.0, &mut out);
        // Every found root is a known one; known roots are found except both
        // of a pair closer than rounding can separate (the minimum between
        // them is not negative in f64: a tangent ray).
        let mut j = 0;
        for (i, &w) in want.iter().enumerate() {
            let close_pair = |k: usize| k < want.len() && (want[k] - want[i]).abs() <= 1e-6 * scale;
            match out[..n].get(j) {
                Some(&r) if (r - w).abs() <= 1e-6 * scale => {
                    // The rounding of the coefficients over the slope at the root
                    // (large for a near-double pair).
                    let m = w.powi(4) + c[2].abs() * w * w + c[1].abs() * w.abs() + c[0].abs();
                    let slope = ((4.0 * w * w + 2.0 * c[2]) * w + c[1]).abs();
                    let slack = 1e-14 * m / slope;
                    assert!((r - w).abs() <= 1e-12 * scale + slack, "case {case}: root {r} vs {w} ({want:?})");
                    if slack < 1e-12 * scale {
                        worst = worst.max((r - w).abs() / scale);
                    }
                    j += 1;
                }
                _ => {
                    assert!(close_pair(i + 1) || (i > 0 && close_pair(i - 1)), "case {case}: lost {w} ({want:?}, got {:?})", &out[..n]);
                    lost_pairs += 1;
                    let near =
                        [i.wrapping_sub(1), i + 1].iter().filter_map(|&k| want.get(k)).map(|x| (x - w).abs()).fold(f64::INFINITY, f64::min);
                    widest_lost = widest_lost.max(near / scale);
                }
            }
        }
        assert_eq!(j, n, "case {case}: extra roots {:?} vs {want:?}", &out[..n]);
        generic_lost += want.len() - solve(&c, h, 0.0, true).len();
    }
    println!("worst error / scale {worst:.3e}, roots of near-double pairs not separated {lost_pairs} (generic isolation: {generic_lost}), widest such pair / scale {widest_lost:.3e}");
    // Below ~1e-8 of the scale the minimum between the pair, ~ -(gap / 2)^2
    // scale^2, is under the rounding of q: found or not by luck.
    assert!(widest_lost <= 1e-7);
}

/// Random torus rays (seeded), a third of them tangent to the tube and a third
/// grazing the bounding sphere: `(origin, direction, rho)` in the kernel's frame.
fn torus_rays(seed: u64, n: usize) -> Vec<(Vec3, Vec3, f32)> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut v = Vec::with_capacity(n);
    for i in 0..n {
        let rho = [0.002f64, 0.01, 0.05, 0.3, 0.7, 1.0, 1.4][i % 7];
        let unit =
            |rng: &mut SmallRng| DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)).normalize();
        let (o, d) = match i % 3 {
            0 => (unit(&mut rng) * rng.gen_range(2.0..6.0), unit(&mut rng)),
            1 => {
                // Tangent to the tube at a random point (as tests/leaf_oracle.rs).
                let phi = rng.gen_range(0.0..std::f64::consts::TAU);
                let th = rng.gen_range(0.0..std::f64::consts::TAU);
                let radial = DVec3::new(phi.cos(), phi.sin(), 0.0);
                let nrm = radial * th.cos() + DVec3::Z * th.sin();
                let p = radial + nrm * rho * (1.0 + rng.gen_range(-1e-3..1e-3));
                let t = nrm.any_orthonormal_vector();
                let a = rng.gen_range(0.0..std::f64::consts::TAU);
                let d = (t * a.cos() + nrm.cross(t) * a.sin()).normalize();
                (p - d * rng.gen_range(2.0..4.0), d)
            }
            _ => {
                // Aimed at a random point near the torus.
                let target = unit(&mut rng) * rng.gen_range(0.0..1.0 + rho);
                let o = unit(&mut rng) * rng.gen_range(2.5..5.0);
                (o, (target - o).normalize())
            }
        };
        // Not unit length: the kernel takes the caller's t.
        let k = rng.gen_range(0.5..2.0);
        v.push((o.as_vec3(), (d * k).as_vec3(), rho as f32));
    }
    v
}

/// The torus quartic exactly as [`kernels::torus_tol`] builds it, from the
/// f32 ray: `(coefficients, h, outer radius)`.
fn torus_quartic(o: Vec3, d: Vec3, rho: f32) -> Option<([f64; 3], f64, f64)> {
    let (o, d, rho) = (o.as_dvec3(), d.as_dvec3(), rho as f64);
    let dn = d / d.length();
    let oc = o - dn * o.dot(dn);
    let rb = 1.0 + rho;
    let h2 = rb * rb - oc.length_squared();
    if h2 <= 0.0 {
        return None;
    }
    let h = h2.sqrt() * (1.0 + 1e-9) + 1e-12;
    let e = oc.length_squared() + 1.0 - rho * rho;
    let (a2, a1, a0) = (dn.x * dn.x + dn.y * dn.y, oc.x * dn.x + oc.y * dn.y, oc.x * oc.x + oc.y * oc.y);
    Some(([e * e - 4.0 * a0, -8.0 * a1, 2.0 * e - 4.0 * a2], h, rb))
}

/// Roots by [`depressed_quartic_roots`] or the generic [`poly::roots_in_tol`].
fn solve(c: &[f64; 3], h: f64, eps: f64, generic: bool) -> Vec<f64> {
    if generic {
        let mut b = [0.0; poly::MAX_DEGREE];
        let n = poly::roots_in_tol(&[c[0], c[1], c[2], 0.0, 1.0], -h, h, eps, &mut b);
        b[..n].to_vec()
    } else {
        let mut a = [0.0; 4];
        let n = depressed_quartic_roots(c, h, eps, &mut a);
        a[..n].to_vec()
    }
}

#[test]
fn torus_roots_match_the_generic_isolation() {
    let seed = 0x7_0A05u64;
    println!("seed {seed:#x}");
    // Worst |root - generic full-precision root| / outer radius: new at
    // full precision, new and generic at the default tolerance.
    let (mut full, mut new_tol, mut old_tol) = (0.0f64, 0.0f64, 0.0f64);
    let mut differ = 0;
    for (i, (o, d, rho)) in torus_rays(seed, 30000).into_iter().enumerate() {
        let Some((c, h, rb)) = torus_quartic(o, d, rho) else { continue };
        let want = solve(&c, h, 0.0, true);
        let eps = kernels::TORUS_TOLERANCE as f64 * rb;
        for (got, worst, allowed) in [
            (solve(&c, h, 0.0, false), &mut full, 1e-9),
            (solve(&c, h, eps, false), &mut new_tol, 1e-6),
            (solve(&c, h, eps, true), &mut old_tol, 1e-6),
        ] {
            if got.len() != want.len() {
                // Only a pair at a tangency, closer than f64 can resolve.
                let more = if got.len() > want.len() { &got } else { &want };
                let gap = more.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
                assert!(got.len().abs_diff(want.len()) == 2 && gap <= 1e-6 * rb, "ray {i}: {got:?} vs {want:?}");
                differ += 1;
                continue;
            }
            for (g, w) in got.iter().zip(&want) {
                let e = (g - w).abs() / rb;
                assert!(e <= allowed, "ray {i} (allowed {allowed:e}): {got:?} vs {want:?}");
                *worst = worst.max(e);
            }
        }
    }
    println!("worst |root - generic root at tolerance 0| / outer radius: new at 0 {full:.3e}, new at 1e-6 {new_tol:.3e}, generic at 1e-6 {old_tol:.3e}; tangent pairs found by one only {differ}");
}

#[test]
fn torus_spans_match_dense_sampling() {
    let seed = 0x7_0A06u64;
    println!("seed {seed:#x}");
    let samples = 20000;
    let (mut worst, mut short) = (0.0f64, 0);
    for (i, (o, d, rho)) in torus_rays(seed, 6000).into_iter().enumerate() {
        let mut spans = [(0.0f32, 0.0f32); 3];
        let n = kernels::torus_tol(o, d, (rho, kernels::TORUS_TOLERANCE as f64), &mut spans);
        let got: Vec<f64> = spans[..n].iter().flat_map(|s| [s.0 as f64, s.1 as f64]).collect();
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        let tc = -od.dot(dd) / dd.length_squared();
        let reach = (2.0 + 2.0 * rho as f64) / dd.length();
        let want = kernels::torus_reference(od, dd, rho as f64, tc - reach, tc + reach, samples);
        let step = 2.0 * reach / samples as f64;
        // f32 output of t ~ 5 plus the conditioning of a near-tangent crossing.
        let tol = 2e-6 * reach;
        let mut j = 0;
        for (k, &w) in want.iter().enumerate() {
            while j < got.len() && got[j] < w - tol {
                // A span the sampling stepped over: shorter than a step.
                assert!(j % 2 == 0 && got[j + 1] - got[j] <= 2.0 * step, "ray {i}: {got:?} vs {want:?}");
                short += 1;
                j += 2;
            }
            if j < got.len() && (got[j] - w).abs() <= tol {
                worst = worst.max((got[j] - w).abs() / reach);
                j += 1;
            } else {
                // Lost: only the two crossings of a tangent, closer than 1e-6.
                let near = |p: Option<&f64>| p.is_some_and(|&p| (p - w).abs() <= 1e-6 * reach);
                assert!(near(want.get(k + 1)) || (k > 0 && near(want.get(k - 1))), "ray {i}: lost {w} ({got:?} vs {want:?})");
            }
        }
        while j < got.len() {
            assert!(j % 2 == 0 && got[j + 1] - got[j] <= 2.0 * step, "ray {i}: {got:?} vs {want:?}");
            short += 1;
            j += 2;
        }
    }
    println!("worst |t - reference| / reach {worst:.3e}; spans shorter than a sample step {short}");
}

/// The spans of a query clipped to its range, as a caller keeps them
/// (`push_clipped`: ends past the range become the range's).
fn clipped(spans: &[(f32, f32)], (lo, hi): (f32, f32)) -> Vec<(f32, f32)> {
    spans.iter().map(|&(a, b)| (a.max(lo), b.min(hi))).filter(|s| s.1 > s.0).collect()
}

/// A ring torus's spans come from the quartic's negative runs, with only the
/// roots a query needs polished (`torus_query`). Against the classification
/// of the points between all roots (`torus_by_midpoints`, the spindle
/// torus's path): the same spans on the whole line; and on random ranges
/// (shadow-like ones starting on the surface among them) the same spans once
/// clipped, the first-only query's spans equal to the full ones up to the
/// place it says they are exact (both clipped there), and past the span the range starts inside
/// of (if any) no more than the first span entered.
#[test]
fn ring_torus_queries_match_the_full_classification() {
    let seed = 0x7_0A07u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut cut_short, mut compared) = (0, 0);
    for (i, (o, d, rho)) in torus_rays(seed, 20000).into_iter().enumerate() {
        if rho >= 1.0 {
            continue;
        }
        let shape = (rho, kernels::TORUS_TOLERANCE as f64);
        let (od, dd) = (o.as_dvec3(), d.as_dvec3());
        let all = kernels::TorusAsk { range: (f32::NEG_INFINITY, f32::INFINITY), first_only: false };
        let mut full = [(0.0f32, 0.0f32); 3];
        let (n, v) = kernels::torus_query(od, dd, shape, all, &mut full);
        let mut mid = [(0.0f32, 0.0f32); 3];
        let m = kernels::torus_by_midpoints(od, dd, shape, &mut mid);
        assert_eq!((&full[..n], v), (&mid[..m], f32::INFINITY), "ray {i}: runs against midpoints");
        // Ranges: random, and starting at each span end (a shadow ray leaving the surface).
        let mut ranges: Vec<(f32, f32)> = (0..4)
            .map(|_| {
                let a = rng.gen_range(-3.0f32..3.0);
                (a, if rng.gen_bool(0.3) { f32::INFINITY } else { a + rng.gen_range(0.0f32..4.0) })
            })
            .collect();
        ranges.extend(full[..n].iter().flat_map(|s| [(s.0, f32::INFINITY), (s.1, f32::INFINITY)]));
        for range in ranges {
            let want = clipped(&full[..n], range);
            let mut got = [(0.0f32, 0.0f32); 3];
            let (k, v) = kernels::torus_query(od, dd, shape, kernels::TorusAsk { range, first_only: false }, &mut got);
            assert_eq!(v, f32::INFINITY);
            assert_eq!(clipped(&got[..k], range), want, "ray {i} range {range:?}");
            let (k, v) = kernels::torus_query(od, dd, shape, kernels::TorusAsk { range, first_only: true }, &mut got);
            // Past `v` the answer is not exact (a skipped exit reads as infinity).
            let first = clipped(&got[..k], (range.0, range.1.min(v)));
            let upto: Vec<(f32, f32)> = want.iter().filter(|s| s.0 < v).map(|&(a, b)| (a, b.min(v))).collect();
            assert_eq!(first, upto, "ray {i} range {range:?}: first-only query, exact up to {v}");
            let entered = got[..k].iter().filter(|s| s.0 >= range.0 && s.0 < range.1).count();
            assert!(entered <= 1 || v == f32::INFINITY, "ray {i}: more than the first span entered");
            cut_short += (v < f32::INFINITY) as usize;
            compared += 1;
        }
    }
    println!("{compared} ranges compared, {cut_short} first-only queries stopped before the end");
    assert!(cut_short > 100, "the first-only stop was hardly exercised");
}

/// A Newton iterate near an inflection point of the quartic (q'' ~ 0 there)
/// is not taken for the root: a stop on the step's predicted quadratic
/// convergence with q'' at the iterate accepted a step of 0.35 here and left
/// the root 586 times the tolerance off (-0.126293 against -0.067657; found
/// by a review's fuzz of 2M random quartics).
#[test]
fn roots_stay_within_the_tolerance_near_an_inflection_point() {
    let c = [0.06197942810790397, 0.8261534883995932, -1.333821148272488];
    let (mut tol, mut exact) = ([0.0; 4], [0.0; 4]);
    let n = depressed_quartic_roots(&c, 2.0, 1e-4, &mut tol);
    let m = depressed_quartic_roots(&c, 2.0, 0.0, &mut exact);
    assert_eq!(n, m);
    for (a, b) in tol[..n].iter().zip(&exact[..m]) {
        assert!((a - b).abs() <= 1e-4, "{:?} against {:?}", &tol[..n], &exact[..m]);
    }
}

/// The torus ray of that review (f64 local line, ring of minor radius 0.3):
/// with the unsound stop its exit came out at 3.626172 instead of 3.3937016.
#[test]
fn torus_exit_near_an_inflection_point_is_polished() {
    let o = DVec3::new(0.33681535407726504, 2.9122889750511383, 0.6635215184223685);
    let d = DVec3::new(-0.40923684094131735, -0.8675773176545557, -0.28255053690923565);
    let all = kernels::TorusAsk { range: (f32::NEG_INFINITY, f32::INFINITY), first_only: false };
    let mut got = [(0.0f32, 0.0f32); 3];
    let (n, _) = kernels::torus_query(o, d, (0.3, kernels::TORUS_TOLERANCE as f64), all, &mut got);
    let mut want = [(0.0f32, 0.0f32); 3];
    let m = kernels::torus_by_midpoints(o, d, (0.3, 0.0), &mut want);
    assert_eq!(n, m);
    for (g, w) in got[..n].iter().zip(&want[..m]) {
        assert!((g.0 - w.0).abs() <= 1e-5 && (g.1 - w.1).abs() <= 1e-5, "{:?} against {:?}", &got[..n], &want[..m]);
    }
}
