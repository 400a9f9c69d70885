//! [`small_first8`] (both builds) against `small_first` lane by lane and
//! the first-entry walk's reading of its answer, on random solves built to
//! hit every case: boundaries before, at and just past the range's start,
//! within a few eps of each other or equal, infinite ends (half-spaces),
//! NaN ends, short spans, lanes that miss, both node kinds.

use super::super::lane_ends::end;
use super::super::small_first::{small_first, SmallFirst};
use super::*;
use rand::{rngs::SmallRng, Rng, SeedableRng};

/// A span put: its ends and surfaces.
type Put = (f32, f32, Surf, Surf);

/// What the walk makes of lane `k`'s `small_first` (as `take_small_lane`
/// reads it): killed, the span put and the bound.
fn by_lane(ops: &SmallOps<2>, k: usize, (lo, hi, eps): (f32, f32, f32)) -> (bool, Option<Put>, f32) {
    let first = match small_first::<2, 4>(ops, k, (lo, eps)) {
        SmallFirst::Span { t: (t0, t1), .. } if !(t1 - t0 > 8.0 * eps) => SmallFirst::From(t0),
        f => f,
    };
    match first {
        SmallFirst::Empty => (false, None, f32::INFINITY),
        SmallFirst::Inside => (true, None, f32::INFINITY),
        SmallFirst::From(t) if t < lo => (true, None, f32::INFINITY),
        SmallFirst::From(t) => (false, None, t),
        SmallFirst::Span { t: (t0, _), .. } if t0 >= hi => (false, None, f32::INFINITY),
        SmallFirst::Span { t: (t0, t1), s: (s0, s1), next } => {
            let real1 = t1 <= hi && t1.is_finite();
            let c1 = if real1 { t1 } else { t1.min(hi) };
            (false, Some((t0, c1, s0, if real1 { s1 } else { Surf::NONE })), next)
        }
    }
}

#[test]
fn small_first8_matches_small_first_lane_by_lane() {
    let (mut spans, mut bounds, mut kills, mut odd) = (0u64, 0u64, 0u64, 0u64);
    for seed in 0..4000u64 {
        let mut rng = SmallRng::seed_from_u64(0xf185 + seed);
        let kind = if rng.gen_bool(0.5) { NodeKind::Intersection } else { NodeKind::Difference };
        let mut ops = SmallOps::<2> {
            kind,
            count: 2,
            leaf: [rng.gen_range(0..1000), rng.gen_range(0..1000)],
            r: [Ranges8::default(); 2],
            done: u32::MAX,
        };
        let eps: [f32; 8] = std::array::from_fn(|_| [1e-3, 1e-6, 0.0][rng.gen_range(0..3)]);
        let lo: [f32; 8] = std::array::from_fn(|_| [0.0, -0.0, 1e-4, rng.gen_range(-2.0..2.0)][rng.gen_range(0..4)]);
        let hi: [f32; 8] = std::array::from_fn(|k| if rng.gen_bool(0.3) { f32::INFINITY } else { lo[k] + rng.gen_range(0.0..3.0) });
        for r in ops.r.iter_mut() {
            r.hit = rng.gen::<u32>() & 0xff | if rng.gen_bool(0.7) { 0xff } else { 0 };
            for k in 0..8 {
                let pool = [lo[k] + 0.5, lo[k] + 1.0, lo[k] + 1.0 + 3.0 * eps[k]];
                let (a, b) = (end(&mut rng, lo[k], eps[k], &pool), end(&mut rng, lo[k], eps[k], &pool));
                (r.t0[k], r.t1[k]) = if a.total_cmp(&b).is_gt() && rng.gen_bool(0.95) { (b, a) } else { (a, b) };
                (r.s0[k], r.s1[k]) = (rng.gen_range(0..6), rng.gen_range(0..6));
            }
        }
        let lanes = rng.gen::<u32>() & 0xff;
        let ranges = Ranges { lo: &lo, hi: &hi, eps: &eps };
        let two = Two::of(&ops);
        let mut builds = vec![("base", small_first8_base(&two, lanes, &ranges))];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            builds.push(("avx2", unsafe { small_first8_avx2(&two, lanes, &ranges) }));
        }
        for (name, f) in builds {
            for k in 0..8 {
                let at =
                    format!("seed {:#x} lane {k} build {name}: {:?}", 0xf185 + seed, ops.r.map(|r| (r.hit >> k & 1, r.t0[k], r.t1[k])));
                if lanes & (1 << k) == 0 {
                    assert_eq!((f.kill | f.span | f.odd) & (1 << k), 0, "{at}");
                    assert_eq!(f.next[k], f32::INFINITY, "{at}");
                    continue;
                }
                if f.odd & (1 << k) != 0 {
                    assert!(ops.r.iter().any(|r| r.hit & (1 << k) != 0 && (r.t0[k].is_nan() || r.t1[k].is_nan())), "{at}");
                    assert_eq!((f.kill | f.span) & (1 << k), 0, "{at}");
                    odd += 1;
                    continue;
                }
                let (kill, span, next) = by_lane(&ops, k, (lo[k], hi[k], eps[k]));
                assert_eq!(f.kill & (1 << k) != 0, kill, "{at}");
                // (An unsure lane's bound is its smallest event less eps: with
                // events -0 and +0 the sorts may pick either zero. The walk
                // only compares the bound.)
                let zero = f.next[k] == 0.0 && next == 0.0;
                assert!(zero || f.next[k].to_bits() == next.to_bits(), "{at} next: {} against {next}", f.next[k]);
                let got = (f.span & (1 << k) != 0).then(|| (f.t0[k], f.t1[k], f.s0[k], f.s1[k]));
                assert_eq!(
                    got.map(|(a, b, s, t)| (a.to_bits(), b.to_bits(), s, t)),
                    span.map(|(a, b, s, t)| (a.to_bits(), b.to_bits(), s, t)),
                    "{at} span"
                );
                spans += span.is_some() as u64;
                bounds += (span.is_none() && next.is_finite()) as u64;
                kills += kill as u64;
            }
        }
    }
    println!("lanes with spans {spans}, with bounds only {bounds}, killed {kills}, left to small_first {odd}");
    assert!(spans > 1000 && bounds > 1000 && kills > 1000 && odd > 100, "too few of each case to test");
}
