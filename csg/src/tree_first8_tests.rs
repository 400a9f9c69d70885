//! [`tree_first8`] (both builds) against `tree_first` lane by lane, on
//! random truth tables over one to eight leaves (unions, intersections,
//! differences and any other function of them) and random solves built to
//! hit every case: boundaries before, at and just past the range's start,
//! within a few eps of each other or equal, infinite ends, NaN ends, lanes
//! that miss.

use super::super::lane_ends::end;
use super::*;
use rand::{rngs::SmallRng, Rng, SeedableRng};

/// A random truth table over the leaves' patterns `p`: a random tree of
/// unions, intersections and differences, or (sometimes) random bits.
fn table(rng: &mut SmallRng, p: &[[u64; 4]]) -> [u64; 4] {
    if rng.gen_bool(0.1) {
        return std::array::from_fn(|_| rng.gen());
    }
    let mut acc = p[0];
    for q in &p[1..] {
        for w in 0..4 {
            acc[w] = match rng.gen_range(0..3) {
                0 => acc[w] | q[w],
                1 => acc[w] & q[w],
                _ => acc[w] & !q[w],
            };
        }
    }
    acc
}

/// `f` as the callers read it: a span starting at infinity is no span, a
/// span's end at infinity has no surface (see the module's notes).
fn read(f: SmallFirst) -> SmallFirst {
    match f {
        SmallFirst::Span { t: (t0, _), .. } if t0 == f32::INFINITY => SmallFirst::Empty,
        SmallFirst::Span { t: (t0, t1), s: (s0, _), next } if t1 == f32::INFINITY => {
            SmallFirst::Span { t: (t0, t1), s: (s0, Surf::NONE), next }
        }
        f => f,
    }
}

#[test]
fn tree_first8_matches_tree_first_lane_by_lane() {
    let (mut spans, mut froms, mut insides, mut empties, mut nans) = (0u64, 0u64, 0u64, 0u64, 0u64);
    for seed in 0..3000u64 {
        let seed = 0x7f8 + seed;
        let mut rng = SmallRng::seed_from_u64(seed);
        let count = rng.gen_range(1..=TREE_LEAVES);
        let leaf = std::array::from_fn(|_| rng.gen_range(0..1000));
        let flip = rng.gen::<u32>() & 0xff;
        let t = TreeShape::for_tests(count, leaf, flip, |p| table(&mut rng, p));
        let eps: [f32; 8] = std::array::from_fn(|_| [1e-3, 1e-6, 0.0][rng.gen_range(0..3)]);
        let lo: [f32; 8] = std::array::from_fn(|_| [0.0, -0.0, 1e-4, rng.gen_range(-2.0..2.0)][rng.gen_range(0..4)]);
        let nan_rate = if rng.gen_bool(0.2) { 1.0 } else { 0.0 };
        let mut solves = [Ranges8::default(); TREE_LEAVES];
        for r in solves.iter_mut().take(count) {
            r.done = 0xff;
            r.hit = rng.gen::<u32>() & 0xff | if rng.gen_bool(0.6) { 0xff } else { 0 };
            for k in 0..8 {
                let pool = [lo[k] + 0.5, lo[k] + 1.0, lo[k] + 1.0 + 3.0 * eps[k]];
                let mut e = || {
                    let x = end(&mut rng, lo[k], eps[k], &pool);
                    if x.is_nan() && nan_rate == 0.0 {
                        lo[k] + 2.0
                    } else {
                        x
                    }
                };
                let (a, b) = (e(), e());
                (r.t0[k], r.t1[k]) = if a.total_cmp(&b).is_gt() && rng.gen_bool(0.95) { (b, a) } else { (a, b) };
                (r.s0[k], r.s1[k]) = (rng.gen_range(0..6), rng.gen_range(0..6));
            }
        }
        let r: Vec<&Ranges8> = solves[..count].iter().collect();
        let lanes = rng.gen::<u32>() & 0xff | if rng.gen_bool(0.5) { 0xff } else { 0 };
        let ranges = LaneStarts { lo: &lo, eps: &eps };
        let untouched = SmallFirst::From(-7.0);
        let mut builds = Vec::new();
        let mut base = [untouched; 8];
        tree_first8_base(&t, &r, lanes, &ranges, &mut base);
        builds.push(("base", base));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut avx2 = [untouched; 8];
            // SAFETY: the CPU has AVX2.
            unsafe { tree_first8_avx2(&t, &r, lanes, &ranges, &mut avx2) };
            builds.push(("avx2", avx2));
        }
        for (name, got) in builds {
            for k in 0..8 {
                let at = format!(
                    "seed {seed:#x} lane {k} build {name}: {:?}",
                    r.iter().map(|r| (r.hit >> k & 1, r.t0[k], r.t1[k])).collect::<Vec<_>>()
                );
                if lanes & (1 << k) == 0 {
                    assert_eq!(got[k], untouched, "{at}");
                    continue;
                }
                let want = tree_first(&t, &r, k, (lo[k], eps[k]));
                match (read(got[k]), read(want)) {
                    // (An unsure lane's bound is its smallest boundary less
                    // eps: of -0 and +0 the sorts may pick either.)
                    (SmallFirst::From(x), SmallFirst::From(y)) => assert!(x == y || (x.is_nan() && y.is_nan()), "{at}: {x} against {y}"),
                    (SmallFirst::Span { t: (a0, a1), s: sa, next: na }, SmallFirst::Span { t: (b0, b1), s: sb, next: nb }) => {
                        assert_eq!((a0.to_bits(), a1.to_bits(), sa, na.to_bits()), (b0.to_bits(), b1.to_bits(), sb, nb.to_bits()), "{at}")
                    }
                    (x, y) => assert_eq!(x, y, "{at}"),
                }
                let lane_nan = r.iter().any(|r| r.hit & (1 << k) != 0 && (r.t0[k].is_nan() || r.t1[k].is_nan()));
                nans += lane_nan as u64;
                match want {
                    SmallFirst::Span { .. } => spans += 1,
                    SmallFirst::From(_) => froms += 1,
                    SmallFirst::Inside => insides += 1,
                    SmallFirst::Empty => empties += 1,
                }
            }
        }
    }
    println!("lanes: spans {spans}, bounds {froms}, inside {insides}, empty {empties}, with a NaN {nans}");
    assert!(spans > 2000 && froms > 2000 && insides > 1000 && empties > 1000 && nans > 200, "too few of each case to test");
}
