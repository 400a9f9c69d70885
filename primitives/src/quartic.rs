//! Real roots of a depressed quartic `s^4 + c2 s^2 + c1 s + c0` on `[-h, h]`,
//! in f64: the torus kernel's polynomial once the origin sits at the ray's
//! closest approach to the centre (no cubic term).
//!
//! The same isolation as [`crate::poly::roots_in_tol`] (between consecutive
//! critical points the quartic is monotone, so it has at most one root there),
//! but the critical points, the roots of the depressed cubic
//! `4 s^3 + 2 c2 s + c1`, come in closed form (trigonometric for three real
//! roots, Cardano for one) polished by one Newton step, instead of a
//! recursive isolation of the cubic plus a Newton loop per critical point; and
//! each quartic root's Newton starts from a quadratic model at the bracket's
//! extremum, not the bracket's midpoint.

use crate::poly::Bracket;

/// `q(s)` by Horner, in the same order as [`crate::poly::eval`] on
/// `[c0, c1, c2, 0, 1]` (the same rounding as the generic path).
#[inline(always)]
fn q(c: &[f64; 3], s: f64) -> f64 {
    ((s * s + c[2]) * s + c[1]) * s + c[0]
}

/// `q(s)` and `q'(s)`.
#[inline(always)]
fn q_d(c: &[f64; 3], s: f64) -> (f64, f64) {
    let s2 = s * s;
    (((s2 + c[2]) * s + c[1]) * s + c[0], (4.0 * s2 + 2.0 * c[2]) * s + c[1])
}

/// Cube root to about 1e-14 (relative; 6e-15 worst over 1e5 random inputs in
/// quartic_tests.rs): an exponent-thirding guess (within 4%, the fdlibm
/// constant) and two Halley steps (each cubes the error). The caller's Newton
/// step on the cubic takes the root the rest of the way. About 27
/// instructions a call on benches/scenes/tori.json (callgrind), against 125
/// for `f64::cbrt` (compiler-builtins' software libm).
#[inline]
fn cbrt(x: f64) -> f64 {
    let ax = x.abs();
    if !(f64::MIN_POSITIVE..f64::INFINITY).contains(&ax) {
        // Zero, subnormal, infinite, NaN: the guess below assumes a normal number.
        return x.cbrt();
    }
    let mut y = f64::from_bits(ax.to_bits() / 3 + (715_094_163u64 << 32));
    for _ in 0..2 {
        let y3 = y * y * y;
        y *= (y3 + 2.0 * ax) / (2.0 * y3 + ax);
    }
    y.copysign(x)
}

/// The real roots of `s^3 + p s + r`, increasing; returns how many (1 or 3;
/// a double root counts twice).
pub fn depressed_cubic_roots(p: f64, r: f64, out: &mut [f64; 3]) -> usize {
    let p3 = p / 3.0;
    let r2 = 0.5 * r;
    let disc = r2 * r2 + p3 * p3 * p3;
    let g = |s: f64| (s * s + p) * s + r;
    let gd = |s: f64| 3.0 * s * s + p;
    if disc > 0.0 {
        // One real root (Cardano). `u` takes the sign that adds magnitudes, so
        // it never cancels; `u - p3 / u` may cancel when |p| dominates (root
        // ~ -r / p), which the Newton step repairs (g' >= |p| there).
        let u = cbrt(-(r2 + disc.sqrt().copysign(r2)));
        let s = u - p3 / u;
        let d = gd(s);
        out[0] = if d != 0.0 { s - g(s) / d } else { s };
        return 1;
    }
    // Three real roots: s = 2 m cos(theta + 2 pi k / 3), cos(3 theta) = -r2 / m^3,
    // separated by the cubic's extrema at -m and m.
    let m = (-p3).sqrt();
    let c3 = if m > 0.0 { (-r2 / (m * m * m)).clamp(-1.0, 1.0) } else { 0.0 };
    let (sn, cs) = (c3.acos() / 3.0).sin_cos();
    const SQRT3: f64 = 1.732_050_807_568_877_2;
    let hi = 2.0 * m * cs;
    let lo = -m * (cs + SQRT3 * sn);
    let mid = m * (SQRT3 * sn - cs);
    // One Newton step each, taken only when it moves the root less than half
    // its distance to the nearest extremum of the cubic: near a double root
    // g' -> 0 and the step can jump (seen: 19.24 -> 17.24 with the root at
    // 19.24 and m = 19.24), and there the closed form is as good as it gets.
    let polish = |s: f64| {
        let n = s - g(s) / gd(s);
        if (n - s).abs() <= 0.5 * (s.abs() - m).abs() {
            n
        } else {
            s
        }
    };
    out[0] = polish(lo);
    out[1] = polish(mid);
    out[2] = polish(hi);
    3
}

/// [`Bracket::step`] to the end (at most 100 steps).
fn refine(c: &[f64; 3], mut br: Bracket, eps: f64) -> f64 {
    for _ in 0..100 {
        let (f, df) = q_d(c, br.x);
        if let Some(r) = br.step(f, df, eps) {
            return r;
        }
    }
    br.x
}

/// Two [`refine`]s at once, their steps interleaved while both run: each step
/// is a chain of dependent multiplies and a division, so two independent
/// chains cost about as much as one (the common ray meets the tube twice, a
/// root on each side of the one minimum). Each root is exactly what `refine`
/// gives.
fn refine_pair(c: &[f64; 3], mut b0: Bracket, mut b1: Bracket, eps: f64) -> (f64, f64) {
    for _ in 0..100 {
        let ((f0, d0), (f1, d1)) = (q_d(c, b0.x), q_d(c, b1.x));
        match (b0.step(f0, d0, eps), b1.step(f1, d1, eps)) {
            (Some(r0), Some(r1)) => return (r0, r1),
            (Some(r0), None) => return (r0, refine(c, b1, eps)),
            (None, Some(r1)) => return (refine(c, b0, eps), r1),
            (None, None) => {}
        }
    }
    (b0.x, b1.x)
}

/// The first Newton iterate in the monotone bracket `[a, b]`, whose ends are
/// `(x, q(x), is a critical point)` with values of opposite signs.
///
/// At a critical point `e` the quartic is locally `q(e) + q''(e) t^2 / 2`, so
/// the root is near `e + sqrt(-2 q(e) / q''(e))`: on random torus rays
/// (quartic_tests.rs, 57k roots at tolerance 1e-6) that needs 3.5 Newton
/// steps per root against 6.2 from the midpoint, 6.5 from the secant and 5.0
/// from a Newton step off the bracket's outer end. Between two critical points
/// the one with the smaller |q| is nearer the root.
#[inline(always)]
fn seed(c: &[f64; 3], (a, fa, flat_a): (f64, f64, bool), (b, fb, flat_b): (f64, f64, bool)) -> f64 {
    let (e, fe, dir) = match (flat_a, flat_b) {
        (true, true) if fa.abs() < fb.abs() => (a, fa, 1.0),
        (_, true) => (b, fb, -1.0),
        (true, false) => (a, fa, 1.0),
        // No critical point inside [-h, h]: a monotone quartic there.
        _ => return 0.5 * (a + b),
    };
    let x = e + dir * (-2.0 * fe / (12.0 * e * e + 2.0 * c[2])).sqrt();
    // Outside (or NaN, for a flat q'' = 0) the model is no guide.
    if x > a && x < b {
        x
    } else {
        0.5 * (a + b)
    }
}

/// A root as found while walking the monotone pieces: exact (q is 0 at an
/// end or a critical point) or still to be polished in its bracket.
#[derive(Clone, Copy)]
enum Found {
    Exact(f64),
    Polish(Bracket),
}

/// Pushes the real roots of `s^4 + c[2] s^2 + c[1] s + c[0]` in `[-h, h]` into
/// `out`, increasing; returns how many. As [`crate::poly::roots_in_tol`] with
/// `eps`: a touching double root is reported once if its value is exactly 0,
/// else not at all.
pub fn depressed_quartic_roots(c: &[f64; 3], h: f64, eps: f64, out: &mut [f64; 4]) -> usize {
    if !(h > 0.0) {
        return 0;
    }
    let mut crit = [0.0f64; 3];
    let nc = depressed_cubic_roots(0.5 * c[2], 0.25 * c[1], &mut crit);
    // First every bracket (cheap), then the polishing, two at a time.
    let mut found = [Found::Exact(0.0); 4];
    let mut nf = 0;
    let mut a = -h;
    let mut fa = q(c, a);
    if fa == 0.0 {
        found[0] = Found::Exact(a);
        nf = 1;
    }
    for i in 0..=nc {
        let b = if i < nc { crit[i] } else { h };
        if i < nc && (b <= a || b >= h) {
            continue;
        }
        let fb = q(c, b);
        if fb == 0.0 {
            found[nf] = Found::Exact(b);
            nf += 1;
        } else if fa != 0.0 && (fa < 0.0) != (fb < 0.0) {
            let x = seed(c, (a, fa, i > 0), (b, fb, i < nc));
            found[nf] = Found::Polish(Bracket { a, b, neg_at_a: fa < 0.0, x });
            nf += 1;
        }
        a = b;
        fa = fb;
        if nf >= 4 {
            break;
        }
    }
    let mut roots = [0.0f64; 4];
    let mut pending: Option<usize> = None;
    for k in 0..nf {
        match found[k] {
            Found::Exact(x) => roots[k] = x,
            Found::Polish(br) => match pending.take() {
                None => pending = Some(k),
                Some(j) => {
                    let Found::Polish(first) = found[j] else { unreachable!() };
                    (roots[j], roots[k]) = refine_pair(c, first, br, eps);
                }
            },
        }
    }
    if let Some(j) = pending {
        let Found::Polish(br) = found[j] else { unreachable!() };
        roots[j] = refine(c, br, eps);
    }
    let mut count = 0;
    for &r in &roots[..nf] {
        if count == 0 || out[count - 1] != r {
            out[count] = r;
            count += 1;
        }
    }
    count
}

#[cfg(test)]
#[path = "quartic_tests.rs"]
mod tests;
