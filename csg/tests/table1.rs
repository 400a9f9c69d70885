//! Table 1 and the regularisation rules, pinned case by case, plus a randomized
//! comparison of `combine` with point sampling of the boolean function.

use rand::{rngs::SmallRng, Rng, SeedableRng};
use rothray_csg::{combine, Op, SpanList};
use rothray_primitives::{Span, Surf};

fn sp(t0: f32, t1: f32, leaf: u32) -> Span {
    Span { t0, t1, s0: Surf::new(leaf, 0), s1: Surf::new(leaf, 1) }
}
fn run(op: Op, a: &[Span], b: &[Span], eps: f32) -> Vec<(f32, f32, u32, u32)> {
    let mut out = SpanList::new();
    combine(op, a, b, eps, &mut out);
    out.as_slice().iter().map(|s| (s.t0, s.t1, s.s0.leaf, s.s1.leaf)).collect()
}
const F: u32 = Surf::FLIP;

#[test]
fn table1_overlapping() {
    let a = [sp(0.0, 2.0, 1)];
    let b = [sp(1.0, 3.0, 2)];
    assert_eq!(run(Op::Union, &a, &b, 1e-6), vec![(0.0, 3.0, 1, 2)]);
    assert_eq!(run(Op::Intersection, &a, &b, 1e-6), vec![(1.0, 2.0, 2, 1)]);
    // b's entry becomes the difference's exit, with its normal flipped.
    assert_eq!(run(Op::Difference, &a, &b, 1e-6), vec![(0.0, 1.0, 1, 2 | F)]);
    assert_eq!(run(Op::Difference, &b, &a, 1e-6), vec![(2.0, 3.0, 1 | F, 2)]);
}

#[test]
fn table1_disjoint_and_nested() {
    let a = [sp(0.0, 1.0, 1)];
    let b = [sp(2.0, 3.0, 2)];
    assert_eq!(run(Op::Union, &a, &b, 1e-6), vec![(0.0, 1.0, 1, 1), (2.0, 3.0, 2, 2)]);
    assert!(run(Op::Intersection, &a, &b, 1e-6).is_empty());
    assert_eq!(run(Op::Difference, &a, &b, 1e-6), vec![(0.0, 1.0, 1, 1)]);
    let outer = [sp(0.0, 10.0, 1)];
    let inner = [sp(4.0, 6.0, 2)];
    assert_eq!(run(Op::Difference, &outer, &inner, 1e-6), vec![(0.0, 4.0, 1, 2 | F), (6.0, 10.0, 2 | F, 1)]);
    assert!(run(Op::Difference, &inner, &outer, 1e-6).is_empty());
    assert_eq!(run(Op::Intersection, &outer, &inner, 1e-6), vec![(4.0, 6.0, 2, 2)]);
}

#[test]
fn coincident_faces_fuse_to_the_first_operand() {
    // Two boxes sharing a face: the union has no inner face.
    let a = [sp(0.0, 1.0, 1)];
    let b = [sp(1.0 + 1e-7, 2.0, 2)];
    assert_eq!(run(Op::Union, &a, &b, 1e-5), vec![(0.0, 2.0, 1, 2)]);
    // A sphere intersected with itself (rounding apart): the first operand's surfaces, always.
    let b2 = [sp(3e-7, 1.0 - 2e-7, 2)];
    assert_eq!(run(Op::Intersection, &a, &b2, 1e-5), vec![(0.0, 1.0, 1, 1)]);
    let b3 = [sp(-3e-7, 1.0 + 2e-7, 2)];
    assert_eq!(run(Op::Intersection, &a, &b3, 1e-5), vec![(0.0, 1.0, 1, 1)]);
    // A notch cut with a shared face leaves no sliver.
    let big = [sp(0.0, 4.0, 1)];
    let cut = [sp(4e-7, 2.0, 2)];
    assert_eq!(run(Op::Difference, &big, &cut, 1e-5), vec![(2.0, 4.0, 2 | F, 1)]);
    // Identical operands: difference empty.
    assert!(run(Op::Difference, &a, &a, 1e-5).is_empty());
}

#[test]
fn short_spans_dropped_touching_spans_merged() {
    let a = [sp(0.0, 1.0, 1), sp(1.0 + 5e-6, 2.0, 1)];
    let b = [sp(5.0, 6.0, 2)];
    assert_eq!(run(Op::Union, &a, &b, 1e-5), vec![(0.0, 2.0, 1, 1), (5.0, 6.0, 2, 2)]);
    let a = [sp(0.0, 1.0, 1)];
    let b = [sp(0.5, 1.0 - 5e-6, 2)];
    // a - b leaves [0, 0.5] and a sliver [1-5e-6, 1]: dropped.
    assert_eq!(run(Op::Difference, &a, &b, 1e-5), vec![(0.0, 0.5, 1, 2 | F)]);
}

#[test]
fn clipped_ends_are_not_surfaces() {
    let a = [Span { t0: 0.0, t1: 1.0, s0: Surf::NONE, s1: Surf::new(1, 0) }];
    let b = [sp(0.5, 2.0, 2)];
    let r = run(Op::Union, &a, &b, 1e-6);
    assert_eq!(r, vec![(0.0, 2.0, u32::MAX, 2)]);
}

fn inside(l: &[Span], t: f32) -> bool {
    l.iter().any(|s| s.t0 <= t && t <= s.t1)
}

#[test]
fn random_lists_match_pointwise_boolean() {
    let seed = 0x5eed_1234u64;
    println!("seed {seed:#x}");
    let mut rng = SmallRng::seed_from_u64(seed);
    let gen = |rng: &mut SmallRng, leaf: u32| {
        let n = rng.gen_range(0..6);
        let mut ts: Vec<f32> = (0..2 * n).map(|_| (rng.gen_range(0..1000) as f32) * 0.01).collect();
        ts.sort_by(f32::total_cmp);
        ts.dedup();
        if ts.len() % 2 == 1 {
            ts.pop();
        }
        ts.chunks(2).filter(|c| c[1] > c[0]).map(|c| sp(c[0], c[1], leaf)).collect::<Vec<_>>()
    };
    for case in 0..5000 {
        let a = gen(&mut rng, 1);
        let b = gen(&mut rng, 2);
        for op in [Op::Union, Op::Intersection, Op::Difference] {
            let mut out = SpanList::new();
            combine(op, &a, &b, 1e-6, &mut out);
            let o = out.as_slice();
            for w in o.windows(2) {
                assert!(w[0].t1 < w[1].t0, "case {case}: not sorted/disjoint {o:?}");
            }
            // Sample at points away from every boundary.
            for k in 0..400 {
                let t = k as f32 * 0.025 + 0.0037;
                assert_eq!(inside(o, t), op.apply(inside(&a, t), inside(&b, t)), "case {case} op {op:?} t {t} a {a:?} b {b:?} -> {o:?}");
            }
        }
    }
}
