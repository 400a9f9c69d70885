#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
//! A ring torus's query prep ([`TorusPrep`]) for the eight lanes of a
//! packet in 8-lane f64 SIMD ([`D8`]): the line in the torus's frame, the
//! quartic and its marks (the roots of the depressed cubic, its derivative,
//! inside `[-h, h]`), as `TorusPrep::new` makes them lane by lane, bit for
//! bit: the same IEEE operations on the same values in the same order, with
//! selects where the scalar code branches. Then the entry of each lane's
//! first negative run, when it is a root, is polished for all lanes
//! together ([`refine8`], the Newton steps of `quartic::refine` with a lane
//! mask): the root a nearest query asks first. The lane's query finishes
//! from its prep on the scalar path (`torus_query_prepped`: which other
//! roots to polish depends on the lane's range).
//!
//! Three steps stay scalar per lane, through the very functions the scalar
//! path calls: the cube root of Cardano's formula (`quartic::cbrt`, an
//! integer division of the exponent bits) and `acos` / `sin_cos` of the
//! trigonometric form (libm).
//!
//! Why: lane after lane, the prep and the entry's Newton steps were chains
//! of dependent square roots and divisions, half of the time of
//! benches/scenes/tori (perf, one thread). In lanes, tori traces 17%
//! faster flat and 10% lit (1920x1080, 2 threads, medians of 9 in three
//! alternating rounds: 0.0716-0.0734 s -> 0.0588-0.0601 s flat,
//! 0.1082-0.1110 s -> 0.0985-0.0999 s lit). The prep alone in lanes gained
//! nothing measurable (its divisions were already overlapped lane with
//! lane); the entries' polish did it.

use glam::DVec3;

use crate::kernels::TorusPrep;
use crate::quartic::{self, Marks, RunEnd};
use crate::simd8::D8;

/// `a . b` in glam's order: `(x x' + y y') + z z'`.
#[inline(always)]
pub(crate) fn dot3<D: D8>(a: &[D; 3], b: &[D; 3]) -> D {
    a[0].mul(b[0]).add(a[1].mul(b[1])).add(a[2].mul(b[2]))
}

/// `|x|`.
#[inline(always)]
fn abs<D: D8>(x: D) -> D {
    D::splat(-0.0).andnot(x)
}

/// `quartic::q`: `((s^2 + c2) s + c1) s + c0`.
#[inline(always)]
fn q<D: D8>(c: &[D; 3], s: D) -> D {
    s.mul(s).add(c[2]).mul(s).add(c[1]).mul(s).add(c[0])
}

/// The depressed cubic `s^3 + p s + r` and its derivative, as
/// `quartic::depressed_cubic_roots` writes them.
#[inline(always)]
fn cubic<D: D8>(p: D, r: D, s: D) -> (D, D) {
    (s.mul(s).add(p).mul(s).add(r), D::splat(3.0).mul(s).mul(s).add(p))
}

/// Per lane `f(x[k])` for the lanes of `lanes`, `1.0` elsewhere.
#[inline(always)]
fn per_lane<D: D8>(x: D, lanes: u32, f: fn(f64) -> f64) -> D {
    let a = x.store();
    let mut y = [1.0; 8];
    for k in 0..8 {
        if lanes & (1 << k) != 0 {
            y[k] = f(a[k]);
        }
    }
    D::load(&y)
}

/// Per lane of `lanes`, the sine and cosine of `acos(c) / 3` (libm, as the
/// scalar path); `1.0` elsewhere.
#[inline(always)]
fn sin_cos_third_acos<D: D8>(c: D, lanes: u32) -> (D, D) {
    let a = c.store();
    let (mut sn, mut cs) = ([1.0; 8], [1.0; 8]);
    for k in 0..8 {
        if lanes & (1 << k) != 0 {
            (sn[k], cs[k]) = (a[k].acos() / 3.0).sin_cos();
        }
    }
    (D::load(&sn), D::load(&cs))
}

/// `depressed_cubic_roots`' polish of root `s` of `s^3 + p s + r` (the
/// extrema at `-m` and `m`): one Newton step, kept where it moves the root
/// less than half its distance to the nearest extremum.
#[inline(always)]
fn polish<D: D8>((p, r, m): (D, D, D), s: D) -> D {
    let (g, gd) = cubic(p, r, s);
    let n = s.sub(g.div(gd));
    D::select(abs(n.sub(s)).le(D::splat(0.5).mul(abs(abs(s).sub(m)))), n, s)
}

/// `kernels::through_hole` on eight lanes: the same operations in the same
/// order, its picks as selects (bit k of the mask: lane k's line passes
/// through the hole).
#[inline(always)]
fn through_hole8<D: D8>((oc, dn): (&[D; 3], &[D; 3]), (rho, h): (f64, D)) -> u32 {
    if !(rho < 1.0) {
        return 0;
    }
    let slab = rho * (1.0 + 1e-9);
    let (sa, sb) = (D::splat(-slab).sub(oc[2]).div(dn[2]), D::splat(slab).sub(oc[2]).div(dn[2]));
    let lt = sb.gt(sa);
    let (s0, s1) = (D::select(lt, sa, sb), D::select(lt, sb, sa));
    let flat = dn[2].eq(D::splat(0.0));
    let nh = h.neg();
    let lo = D::select(flat, nh, D::select(s0.gt(nh), s0, nh));
    let hi = D::select(flat, h, D::select(h.gt(s1), s1, h));
    // (No closure: one compiled apart from the AVX function made each of
    // its operations a call.)
    let (xl, yl) = (oc[0].add(lo.mul(dn[0])), oc[1].add(lo.mul(dn[1])));
    let (xh, yh) = (oc[0].add(hi.mul(dn[0])), oc[1].add(hi.mul(dn[1])));
    let inner = D::splat((1.0 - rho) * (1.0 - rho) * (1.0 - 1e-6));
    inner.gt(xl.mul(xl).add(yl.mul(yl))).and(inner.gt(xh.mul(xh).add(yh.mul(yh)))).bitmask()
}

/// [`TorusPrep::new`] for the local lines `o + t d` of the lanes `lanes`
/// (`None` for the others and where a line misses the torus's bounding
/// sphere or slab), torus minor radius `rho < 1`.
#[inline(always)]
pub(crate) fn torus_prep8_in<D: D8>(o: &[D; 3], d: &[D; 3], (rho, tol): (f64, f64), lanes: u32, out: &mut [Option<TorusPrep>; 8]) {
    let zero = D::splat(0.0);
    // TorusLine::new.
    let dl = dot3(d, d).sqrt();
    let dn = [d[0].div(dl), d[1].div(dl), d[2].div(dl)];
    let tc = dot3(o, &dn).neg();
    let oc = [o[0].add(dn[0].mul(tc)), o[1].add(dn[1].mul(tc)), o[2].add(dn[2].mul(tc))];
    let rb = 1.0 + rho;
    let oc2 = dot3(&oc, &oc);
    let h2 = D::splat(rb * rb).sub(oc2);
    let h = h2.sqrt().mul(D::splat(1.0 + 1e-9)).add(D::splat(1e-12));
    let zr = abs(dn[2]).mul(h);
    let (above, below) = (D::splat(rho * (1.0 + 1e-9)), D::splat(-rho * (1.0 + 1e-9)));
    let miss = h2.le(zero).bitmask() | oc[2].sub(zr).gt(above).bitmask() | below.gt(oc[2].add(zr)).bitmask();
    let live = lanes & dl.gt(zero).bitmask() & !miss & !through_hole8((&oc, &dn), (rho, h));
    if live == 0 {
        *out = [None; 8];
        return;
    }
    // TorusLine::quartic.
    let e = oc2.add(D::splat(1.0)).sub(D::splat(rho * rho));
    let a2 = dn[0].mul(dn[0]).add(dn[1].mul(dn[1]));
    let a1 = oc[0].mul(dn[0]).add(oc[1].mul(dn[1]));
    let a0 = oc[0].mul(oc[0]).add(oc[1].mul(oc[1]));
    let c = [e.mul(e).sub(D::splat(4.0).mul(a0)), D::splat(-8.0).mul(a1), D::splat(2.0).mul(e).sub(D::splat(4.0).mul(a2))];
    // Marks::new: the critical points, depressed_cubic_roots(c2 / 2, c1 / 4).
    let (p, r) = (D::splat(0.5).mul(c[2]), D::splat(0.25).mul(c[1]));
    let p3 = p.div(D::splat(3.0));
    let r2 = D::splat(0.5).mul(r);
    let disc = r2.mul(r2).add(p3.mul(p3).mul(p3));
    let one = disc.gt(zero);
    let one_bits = one.bitmask() & live;
    // Each branch only where a live lane takes it (packets are mostly of
    // one kind; the other branch's divisions and square roots were read by
    // no lane). A lane reads only its own branch's values below.
    // One real root (Cardano), then a Newton step where the slope is not 0.
    let root = if one_bits != 0 {
        let u = per_lane(r2.add(disc.sqrt().copysign(r2)).neg(), one_bits, quartic::cbrt);
        let s = u.sub(p3.div(u));
        let (gs, ds) = cubic(p, r, s);
        D::select(ds.eq(zero), s, s.sub(gs.div(ds)))
    } else {
        zero
    };
    // Three real roots: the trigonometric form, each polished by a Newton
    // step that moves it less than half its distance to the nearest extremum.
    let three_bits = live & !one_bits;
    let (lo, mid, hi) = if three_bits != 0 {
        let m = p3.neg().sqrt();
        let ratio = r2.neg().div(m.mul(m).mul(m));
        let (neg1, pos1) = (D::splat(-1.0), D::splat(1.0));
        let clamped = D::select(neg1.gt(ratio), neg1, ratio);
        let clamped = D::select(clamped.gt(pos1), pos1, clamped);
        let c3 = D::select(m.gt(zero), clamped, zero);
        let (sn, cs) = sin_cos_third_acos(c3, three_bits);
        const SQRT3: f64 = 1.732_050_807_568_877_2;
        let hi = polish((p, r, m), D::splat(2.0).mul(m).mul(cs));
        let lo = polish((p, r, m), m.neg().mul(cs.add(D::splat(SQRT3).mul(sn))));
        let mid = polish((p, r, m), m.mul(D::splat(SQRT3).mul(sn).sub(cs)));
        (lo, mid, hi)
    } else {
        (zero, zero, zero)
    };
    // The marks strictly inside (-h, h), increasing, each past the last kept.
    let b0 = D::select(one, root, lo);
    let nh = h.neg();
    let in0 = b0.gt(nh).and(h.gt(b0));
    let last = D::select(in0, b0, nh);
    let in1 = one.andnot(mid.gt(last).and(h.gt(mid)));
    let last = D::select(in1, mid, last);
    let in2 = one.andnot(hi.gt(last).and(h.gt(hi)));
    let (crit, kept) = ([b0.store(), mid.store(), hi.store()], [in0.bitmask(), in1.bitmask(), in2.bitmask()]);
    let qc = [q(&c, b0).store(), q(&c, mid).store(), q(&c, hi).store()];
    let (q_lo, q_hi) = (q(&c, nh).store(), q(&c, h).store());
    let (dl, tc, h) = (dl.store(), tc.store(), h.store());
    let (dn, oc, c) = (dn.map(D::store), oc.map(D::store), c.map(D::store));
    for (k, o) in out.iter_mut().enumerate() {
        if live & (1 << k) == 0 {
            *o = None;
            continue;
        }
        // The marks: -h, the critical points kept, h; each slot picked by
        // selects at fixed places (stored at the count's place and read back
        // whole, the arrays stalled on store forwarding: 20% of this
        // function's cycles, perf on tori).
        let (mut x, mut f, mut n) = ([-h[k]; 5], [q_lo[k]; 5], 1);
        let items =
            [(crit[0][k], qc[0][k], kept[0]), (crit[1][k], qc[1][k], kept[1]), (crit[2][k], qc[2][k], kept[2]), (h[k], q_hi[k], u32::MAX)];
        for (xv, fv, keep) in items {
            let keep = keep & (1 << k) != 0;
            for s in 1..5 {
                let here = keep & (s == n);
                x[s] = if here { xv } else { x[s] };
                f[s] = if here { fv } else { f[s] };
            }
            n += keep as usize;
        }
        let marks = Marks::from_parts(x, f, n);
        let lane3 = |v: &[[f64; 8]; 3]| DVec3::new(v[0][k], v[1][k], v[2][k]);
        *o = Some(TorusPrep::from_parts((dl[k], lane3(&dn), tc[k], lane3(&oc), h[k]), [c[0][k], c[1][k], c[2][k]], marks));
    }
    polish_entries::<D>(&c, tol * rho, out);
}

/// Each lane's first negative run's entry, when it is a root, polished to
/// `eps` for all those lanes together: the root a nearest query polishes
/// first, and alone (lane by lane its Newton steps were a chain of
/// dependent divisions, a fifth of tori's time); the same bits as
/// `RunEnd::polish` ([`refine8`]). An entry whose piece lies wholly before
/// the line's `t = 0` is left out: a range starting there or later does
/// not polish it (a shadow ray leaving the run it starts on). (Taking
/// instead the first run that may reach `t = 0` made tori trace 3-4%
/// slower flat and no faster lit, whether every lane's runs were listed or
/// walked only that far.)
#[inline(always)]
fn polish_entries<D: D8>(c: &[[f64; 8]; 3], eps: f64, out: &mut [Option<TorusPrep>; 8]) {
    let (mut a, mut b) = (Ends::default(), Ends::default());
    let mut lanes = 0u32;
    for (k, p) in out.iter().enumerate() {
        let Some(p) = p else { continue };
        if let Some(RunEnd::Root(piece)) = p.quartic().1.first_run_start() {
            let (pa, pb) = piece.ends();
            if pb.0 < p.line_start() {
                continue;
            }
            a.set(k, pa);
            b.set(k, pb);
            lanes |= 1 << k;
        }
    }
    if lanes == 0 {
        return;
    }
    let c = [D::load(&c[0]), D::load(&c[1]), D::load(&c[2])];
    let x = refine8(&c, (a.load::<D>(), b.load::<D>()), seed8(&c, &a, &b), eps).store();
    for (k, p) in out.iter_mut().enumerate() {
        if let Some(p) = p.as_mut().filter(|_| lanes & (1 << k) != 0) {
            p.set_entry(x[k]);
        }
    }
}

/// One end of a monotone piece per lane: `(x, q(x), is a critical point)`.
#[derive(Default)]
struct Ends {
    x: [f64; 8],
    f: [f64; 8],
    flat: [f64; 8],
}

impl Ends {
    #[inline(always)]
    fn set(&mut self, k: usize, (x, f, flat): (f64, f64, bool)) {
        (self.x[k], self.f[k], self.flat[k]) = (x, f, if flat { f64::from_bits(u64::MAX) } else { 0.0 });
    }

    /// `(x, q(x), flat mask)` in lanes.
    #[inline(always)]
    fn load<D: D8>(&self) -> (D, D, D) {
        (D::load(&self.x), D::load(&self.f), D::load(&self.flat))
    }
}

/// `quartic::seed` in lanes: the first Newton iterate in the piece from `a`
/// to `b`, from the quadratic model at its critical end with the smaller
/// `|q|`, or the midpoint.
#[inline(always)]
fn seed8<D: D8>(c: &[D; 3], a: &Ends, b: &Ends) -> D {
    let ((xa, fa, flat_a), (xb, fb, flat_b)) = (a.load::<D>(), b.load::<D>());
    let mid = D::splat(0.5).mul(xa.add(xb));
    // (true, true) if |fa| < |fb| and (true, false): a; (_, true) otherwise: b.
    let at_a = flat_a.and(flat_b.andnot(D::splat(f64::from_bits(u64::MAX))).or(abs(fb).gt(abs(fa))));
    let none = flat_a.or(flat_b).andnot(D::splat(f64::from_bits(u64::MAX)));
    let (e, fe) = (D::select(at_a, xa, xb), D::select(at_a, fa, fb));
    let dir = D::select(at_a, D::splat(1.0), D::splat(-1.0));
    let x = e.add(dir.mul(D::splat(-2.0).mul(fe).div(D::splat(12.0).mul(e).mul(e).add(D::splat(2.0).mul(c[2]))).sqrt()));
    let inside = x.gt(xa).and(xb.gt(x));
    D::select(none.andnot(inside), x, mid)
}

/// `quartic::refine` in lanes: Newton steps in each lane's bracket
/// `[a, b]` (`Bracket::step`: a step leaving the bracket becomes a
/// bisection; done when a step or the bracket is below
/// `max(eps, 1e-15 (1 + |x|))`, or at a zero), from `x`, at most 100 steps.
#[inline(always)]
fn refine8<D: D8>(c: &[D; 3], ((mut a, fa, _), (mut b, _, _)): ((D, D, D), (D, D, D)), mut x: D, eps: f64) -> D {
    let zero = D::splat(0.0);
    let all = D::splat(f64::from_bits(u64::MAX));
    let neg_at_a = zero.gt(fa);
    let mut res = x;
    let mut active = all;
    for _ in 0..100 {
        let s2 = x.mul(x);
        let f = s2.add(c[2]).mul(x).add(c[1]).mul(x).add(c[0]);
        let df = D::splat(4.0).mul(s2).add(D::splat(2.0).mul(c[2])).mul(x).add(c[1]);
        let at_zero = f.eq(zero);
        let neg = zero.gt(f);
        // (f < 0) == neg_at_a: the root lies past x.
        let past = neg.and(neg_at_a).or(neg.or(neg_at_a).andnot(all));
        a = D::select(past, x, a);
        b = D::select(past, b, x);
        let nx = x.sub(f.div(df));
        let newton = nx.gt(a).and(b.gt(nx));
        let nx = D::select(newton, nx, D::splat(0.5).mul(a.add(b)));
        let t = D::splat(1e-15).mul(D::splat(1.0).add(abs(x)));
        let tol = D::select(t.gt(D::splat(eps)), t, D::splat(eps));
        let done = abs(nx.sub(x)).le(tol).or(b.sub(a).le(tol));
        res = D::select(active.and(at_zero), x, D::select(active.and(done), nx, res));
        active = at_zero.or(done).andnot(active);
        x = nx;
        if active.bitmask() == 0 {
            return res;
        }
    }
    D::select(active, x, res)
}

#[cfg(test)]
#[path = "torus8_tests.rs"]
mod tests;
