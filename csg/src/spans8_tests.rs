//! [`merge8`] against [`combine`] lane by lane, on random lists built to
//! hit every rule: boundaries shared or within eps of each other, short
//! spans and gaps, infinite ends, clipped ends (no surface), flipped
//! surfaces, leaves in either order.

use super::*;
use crate::spans::combine;
use rand::{rngs::SmallRng, Rng, SeedableRng};

/// A sorted list of at most `max` spans whose parameters come from a small
/// pool (so lists share boundaries) nudged by multiples of eps.
fn random_list(rng: &mut SmallRng, max: usize, pool: &[f32], eps: f32) -> Vec<Span> {
    let n = rng.gen_range(0..=max);
    let mut ts: Vec<f32> = (0..2 * n)
        .map(|_| {
            let base = pool[rng.gen_range(0..pool.len())];
            let nudge = [0.0, 0.5, 1.0, 1.0001, 2.0, -0.5, -1.0][rng.gen_range(0..7)];
            if rng.gen_bool(0.3) {
                rng.gen_range(0.0..10.0f32) // a boundary of its own
            } else if rng.gen_bool(0.7) {
                base
            } else {
                base + nudge * eps
            }
        })
        .collect();
    ts.sort_by(f32::total_cmp);
    if n > 0 && rng.gen_bool(0.15) {
        ts[2 * n - 1] = f32::INFINITY;
    }
    let surf = |rng: &mut SmallRng| {
        if rng.gen_bool(0.15) {
            Surf::NONE
        } else {
            let leaf = rng.gen_range(0..6u32) | if rng.gen_bool(0.2) { Surf::FLIP } else { 0 };
            Surf::new(leaf, rng.gen_range(0..4))
        }
    };
    let mut out: Vec<Span> = Vec::new();
    for j in 0..n {
        let (t0, t1) = (ts[2 * j], ts[2 * j + 1]);
        if t1 <= t0 || out.last().is_some_and(|l| l.t1 > t0) {
            continue; // keep the list sorted, disjoint, spans non-empty
        }
        out.push(Span { t0, t1, s0: surf(rng), s1: surf(rng) });
    }
    out
}

fn check<const C: usize>(seed: u64, rounds: usize) -> (usize, usize) {
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut lanes_checked, mut overflows) = (0, 0);
    for round in 0..rounds {
        let eps: [f32; 8] = std::array::from_fn(|_| [0.0, 1e-4, 1e-3, 0.05][rng.gen_range(0..4)]);
        let pool: Vec<f32> = (0..rng.gen_range(2..2 * C + 4)).map(|_| rng.gen_range(0.0..10.0f32)).collect();
        let mut a = Spans8::<C>::default();
        let mut b = Spans8::<C>::default();
        let mut la = Vec::new();
        let mut lb = Vec::new();
        for k in 0..8 {
            let x = random_list(&mut rng, C, &pool, eps[k]);
            let y = random_list(&mut rng, C, &pool, eps[k]);
            assert!(a.set_lane(k, &x) && b.set_lane(k, &y));
            la.push(x);
            lb.push(y);
        }
        let lanes: u32 = if rng.gen_bool(0.8) { 0xff } else { rng.gen_range(1..256) };
        for op in [Op::Union, Op::Intersection, Op::Difference] {
            let mut got = Spans8::<C>::default();
            let mut got_sse = Spans8::<C>::default();
            let over = merge8(op, &a, &b, &eps, lanes, &mut got);
            let over_sse = merge8_by_lane(op, &a, &b, &eps, lanes, &mut got_sse);
            assert_eq!(over, over_sse, "seed {seed} round {round} {op:?}: overflows differ between AVX2 and the lane-by-lane path");
            for k in (0..8).filter(|k| over & (1 << k) == 0) {
                let (x, y) = (got.lane(k), got_sse.lane(k));
                assert_eq!(x.as_slice(), y.as_slice(), "seed {seed} round {round} {op:?} lane {k}: AVX2 and the lane-by-lane path differ");
            }
            for k in 0..8 {
                if lanes & (1 << k) == 0 {
                    assert_eq!(got.len[k], 0);
                    continue;
                }
                let mut want = SpanList::new();
                combine(op, &la[k], &lb[k], eps[k], &mut want);
                let fits = want.len() <= C;
                assert_eq!(over & (1 << k) == 0, fits, "seed {seed} round {round} {op:?} lane {k}: overflow flag, want {want:?}");
                if fits {
                    let g = got.lane(k);
                    let bits = |l: &[Span]| l.iter().map(|s| (s.t0.to_bits(), s.t1.to_bits(), s.s0, s.s1)).collect::<Vec<_>>();
                    assert_eq!(
                        bits(g.as_slice()),
                        bits(want.as_slice()),
                        "seed {seed} round {round} {op:?} lane {k} eps {}:\n a {:?}\n b {:?}",
                        eps[k],
                        la[k],
                        lb[k]
                    );
                    lanes_checked += 1;
                } else {
                    overflows += 1;
                }
            }
        }
    }
    (lanes_checked, overflows)
}

#[test]
fn merge8_is_combine_lane_by_lane() {
    for (i, seed) in [0x5eed_0001u64, 0x5eed_0002, 0x5eed_0003].into_iter().enumerate() {
        println!("seed {seed:#x}");
        let (n, o) = match i {
            0 => check::<2>(seed, 4000),
            1 => check::<4>(seed, 3000),
            _ => check::<8>(seed, 1500),
        };
        println!("  capacity {}: {n} lanes equal to combine, {o} overflowed", [2, 4, 8][i]);
        assert!(n > 10_000 && o > 0, "the lists should exercise both cases");
    }
}
