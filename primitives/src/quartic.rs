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
pub(crate) fn q(c: &[f64; 3], s: f64) -> f64 {
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
pub(crate) fn cbrt(x: f64) -> f64 {
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

/// One Newton step in the bracket from `br.x` ([`Bracket::step`]): the
/// root when done. (A stop on the step's predicted quadratic convergence,
/// with q'' at the iterate, was tried: near an inflection point q'' ~ 0
/// accepted a step of 0.35 that left the root 586 times the tolerance off.)
#[inline(always)]
fn step(c: &[f64; 3], br: &mut Bracket, eps: f64) -> Option<f64> {
    let (f, df) = q_d(c, br.x);
    br.step(f, df, eps)
}

/// [`step`] to the end (at most 100 steps).
fn refine(c: &[f64; 3], br: Bracket, eps: f64) -> f64 {
    refine_n(c, br, eps, 100)
}

/// [`step`] to the end, at most `n` steps.
fn refine_n(c: &[f64; 3], mut br: Bracket, eps: f64, n: usize) -> f64 {
    for _ in 0..n {
        if let Some(r) = step(c, &mut br, eps) {
            return r;
        }
    }
    br.x
}

/// Two [`refine`]s at once, their steps interleaved while both run: each step
/// is a chain of dependent multiplies and a division, so two independent
/// chains cost about as much as one (the common ray meets the tube twice, a
/// root on each side of the one minimum). Each root is exactly what `refine`
/// gives (the one left running keeps what is left of its 100 steps: the
/// packet's polish of a first entry, `torus8.rs`, is a lone `refine`).
fn refine_pair(c: &[f64; 3], mut b0: Bracket, mut b1: Bracket, eps: f64) -> (f64, f64) {
    for i in 0..100 {
        match (step(c, &mut b0, eps), step(c, &mut b1, eps)) {
            (Some(r0), Some(r1)) => return (r0, r1),
            (Some(r0), None) => return (r0, refine_n(c, b1, eps, 99 - i)),
            (None, Some(r1)) => return (refine_n(c, b0, eps, 99 - i), r1),
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

/// The quartic's breakpoints on `[-h, h]`, increasing: the ends and the
/// critical points strictly inside, with the values there. Between two
/// consecutive ones the quartic is monotone.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Marks {
    x: [f64; 5],
    f: [f64; 5],
    n: usize,
}

impl Marks {
    #[inline]
    pub(crate) fn new(c: &[f64; 3], h: f64) -> Marks {
        let mut crit = [0.0f64; 3];
        let nc = depressed_cubic_roots(0.5 * c[2], 0.25 * c[1], &mut crit);
        let mut m = Marks { x: [-h; 5], f: [q(c, -h); 5], n: 1 };
        for &b in &crit[..nc] {
            if b > m.x[m.n - 1] && b < h {
                (m.x[m.n], m.f[m.n]) = (b, q(c, b));
                m.n += 1;
            }
        }
        (m.x[m.n], m.f[m.n]) = (h, q(c, h));
        m.n += 1;
        m
    }

    /// Marks made elsewhere in the same way (`torus8.rs`: eight lanes at once).
    #[inline(always)]
    pub(crate) fn from_parts(x: [f64; 5], f: [f64; 5], n: usize) -> Marks {
        Marks { x, f, n }
    }

    /// Where the first run of [`negative_runs`] starts (`None`: no run),
    /// found as that walk finds it, without listing the runs. (The sign
    /// rules are written twice: one helper giving both walks each piece's
    /// sign changes cost tori 2.8% instructions, callgrind 480x270, in the
    /// hot `negative_runs`; `packet_torus_preps_match_the_scalar_prep_bit_for_bit`
    /// checks the two agree.)
    #[inline(always)]
    pub(crate) fn first_run_start(&self) -> Option<RunEnd> {
        for j in 0..self.n - 1 {
            let (fa, fb) = (self.f[j], self.f[j + 1]);
            if fa != 0.0 && fb != 0.0 && (fa < 0.0) != (fb < 0.0) {
                return Some(if fa < 0.0 { RunEnd::Exact(self.x[j]) } else { RunEnd::Root(self.piece(j)) });
            }
            if if fa != 0.0 { fa < 0.0 } else { fb < 0.0 } {
                return Some(RunEnd::Exact(self.x[j]));
            }
        }
        None
    }

    /// The piece from mark `j` to mark `j + 1` as a bracket end pair for
    /// [`seed`]: `(x, q(x), is a critical point)` each.
    #[inline(always)]
    fn piece(&self, j: usize) -> Piece {
        let last = self.n - 1;
        Piece { a: (self.x[j], self.f[j], j > 0), b: (self.x[j + 1], self.f[j + 1], j + 1 < last) }
    }
}

/// A monotone piece whose ends' values have opposite signs: one root inside.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Piece {
    a: (f64, f64, bool),
    b: (f64, f64, bool),
}

impl Piece {
    /// The piece's ends, `(x, q(x), is a critical point)` each.
    #[inline(always)]
    pub(crate) fn ends(self) -> ((f64, f64, bool), (f64, f64, bool)) {
        (self.a, self.b)
    }

    /// The piece's root, polished to `eps` from the seed of [`seed`].
    fn bracket(self, c: &[f64; 3]) -> Bracket {
        Bracket { a: self.a.0, b: self.b.0, neg_at_a: self.a.1 < 0.0, x: seed(c, self.a, self.b) }
    }
}

/// Pushes the real roots of `s^4 + c[2] s^2 + c[1] s + c[0]` in `[-h, h]` into
/// `out`, increasing; returns how many. As [`crate::poly::roots_in_tol`] with
/// `eps`: a touching double root is reported once if its value is exactly 0,
/// else not at all.
pub fn depressed_quartic_roots(c: &[f64; 3], h: f64, eps: f64, out: &mut [f64; 4]) -> usize {
    if !(h > 0.0) {
        return 0;
    }
    let m = Marks::new(c, h);
    // First every bracket (cheap), then the polishing, two at a time.
    let mut found = [RunEnd::Exact(0.0); 4];
    let mut nf = 0;
    if m.f[0] == 0.0 {
        found[0] = RunEnd::Exact(-h);
        nf = 1;
    }
    for j in 0..m.n - 1 {
        let (fa, fb) = (m.f[j], m.f[j + 1]);
        if fb == 0.0 {
            found[nf] = RunEnd::Exact(m.x[j + 1]);
            nf += 1;
        } else if fa != 0.0 && (fa < 0.0) != (fb < 0.0) {
            found[nf] = RunEnd::Root(m.piece(j));
            nf += 1;
        }
        if nf >= 4 {
            break;
        }
    }
    let mut roots = [0.0f64; 4];
    let mut pending: Option<usize> = None;
    for k in 0..nf {
        match found[k] {
            RunEnd::Exact(x) => roots[k] = x,
            RunEnd::Root(_) => match pending.take() {
                None => pending = Some(k),
                Some(j) => (roots[j], roots[k]) = RunEnd::polish_pair(c, found[j], found[k], eps),
            },
        }
    }
    if let Some(j) = pending {
        roots[j] = found[j].polish(c, eps);
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

/// An end of a run where the quartic is negative: a point where it is 0, or
/// a root not polished yet, in its piece.
#[derive(Clone, Copy, Debug)]
pub(crate) enum RunEnd {
    /// Exactly here (a mark where q is 0, or an end of `[-h, h]`).
    Exact(f64),
    /// The one root of this monotone piece.
    Root(Piece),
}

impl RunEnd {
    /// The smallest place the end can be.
    #[inline(always)]
    pub(crate) fn lo(self) -> f64 {
        match self {
            RunEnd::Exact(x) => x,
            RunEnd::Root(p) => p.a.0,
        }
    }

    /// The largest place the end can be.
    #[inline(always)]
    pub(crate) fn hi(self) -> f64 {
        match self {
            RunEnd::Exact(x) => x,
            RunEnd::Root(p) => p.b.0,
        }
    }

    /// The end, polished to `eps` where it is a root.
    pub(crate) fn polish(self, c: &[f64; 3], eps: f64) -> f64 {
        match self {
            RunEnd::Exact(x) => x,
            RunEnd::Root(p) => refine(c, p.bracket(c), eps),
        }
    }

    /// Two ends polished at once ([`refine_pair`]): each as [`RunEnd::polish`] gives it.
    pub(crate) fn polish_pair(c: &[f64; 3], e0: RunEnd, e1: RunEnd, eps: f64) -> (f64, f64) {
        match (e0, e1) {
            (RunEnd::Root(p0), RunEnd::Root(p1)) => refine_pair(c, p0.bracket(c), p1.bracket(c), eps),
            _ => (e0.polish(c, eps), e1.polish(c, eps)),
        }
    }
}

/// The runs where `s^4 + c[2] s^2 + c[1] s + c[0] < 0` on `[-h, h]` (`h > 0`),
/// from the quartic's marks there ([`Marks::new`]), as
/// (start, end) pairs, increasing, none polished yet (the caller polishes
/// only the ends it needs); returns how many (at most 3: a quartic has at
/// most two such runs, rounding at the ends may add one).
///
/// Each monotone piece between marks is negative before or after its root
/// as its ends' values say; a mark where q is 0 separates the runs only when
/// the sign differs on its two sides (a touching double root joins nothing).
pub(crate) fn negative_runs(m: &Marks, out: &mut [(RunEnd, RunEnd); 3]) -> usize {
    let h = m.x[m.n - 1];
    let mut runs = Runs { out, n: 0, inside: false, open: RunEnd::Exact(-h) };
    for j in 0..m.n - 1 {
        let (fa, fb) = (m.f[j], m.f[j + 1]);
        if fa != 0.0 && fb != 0.0 && (fa < 0.0) != (fb < 0.0) {
            runs.set(fa < 0.0, RunEnd::Exact(m.x[j]));
            runs.set(fb < 0.0, RunEnd::Root(m.piece(j)));
        } else {
            runs.set(if fa != 0.0 { fa < 0.0 } else { fb < 0.0 }, RunEnd::Exact(m.x[j]));
        }
    }
    runs.set(false, RunEnd::Exact(h));
    runs.n
}

/// The runs being listed by [`negative_runs`].
struct Runs<'a> {
    out: &'a mut [(RunEnd, RunEnd); 3],
    n: usize,
    inside: bool,
    open: RunEnd,
}

impl Runs<'_> {
    /// The sign is negative (`inside`) from `at` on.
    #[inline(always)]
    fn set(&mut self, inside: bool, at: RunEnd) {
        if inside == self.inside {
            return;
        }
        if inside {
            self.open = at;
        } else if self.n < self.out.len() {
            self.out[self.n] = (self.open, at);
            self.n += 1;
        }
        self.inside = inside;
    }
}

#[cfg(test)]
#[path = "quartic_tests.rs"]
mod tests;
