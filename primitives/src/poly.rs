//! Real roots of polynomials on an interval, in f64. Degrees up to [`MAX_DEGREE`].
//!
//! Two isolators, both polishing by safeguarded Newton (Newton steps that leave
//! the bracket fall back to bisection):
//!
//! * [`roots_in`] / [`roots_in_tol`]: isolation by the roots of the derivative
//!   (recursively): between two consecutive critical points a polynomial is
//!   monotonic, so it has at most one root there. This never misses a simple
//!   root, finds both roots of a near-tangent (grazing) pair as long as the
//!   minimum between them is negative in f64, and reports exactly the roots.
//!   Costly at high degree (a whole chain of derivatives, each polished).
//! * [`bern_roots`] / [`roots_bern`]: Bernstein subdivision (Descartes' rule of
//!   signs on an interval, de Casteljau halving). Several times cheaper at
//!   degree 6-10, never misses a simple root farther than the tolerance from the
//!   others, but returns *candidates*: an interval still ambiguous at the
//!   tolerance (a cluster, a tangency) reports its midpoint. For callers that
//!   only evaluate something at the points, or split at them.

/// Largest supported degree.
pub const MAX_DEGREE: usize = 12;

/// Evaluates `c[0] + c[1] x + ... + c[n] x^n` (Horner).
#[inline]
pub fn eval(c: &[f64], x: f64) -> f64 {
    let mut acc = 0.0;
    for &k in c.iter().rev() {
        acc = acc * x + k;
    }
    acc
}

/// Value and derivative at `x`.
#[inline]
pub fn eval_d(c: &[f64], x: f64) -> (f64, f64) {
    let mut p = 0.0;
    let mut dp = 0.0;
    for &k in c.iter().rev() {
        dp = dp * x + p;
        p = p * x + k;
    }
    (p, dp)
}

/// Pushes the real roots of `c` (lowest degree first, `c.len() - 1` the degree) in
/// `[lo, hi]` into `out` in increasing order; returns how many. Double roots where the
/// polynomial touches zero without crossing are reported once if the touching value
/// is exactly zero, and otherwise not at all (a tangent ray). Converges to full f64
/// precision.
pub fn roots_in(c: &[f64], lo: f64, hi: f64, out: &mut [f64; MAX_DEGREE]) -> usize {
    roots_in_tol(c, lo, hi, 0.0, out)
}

/// [`roots_in`] with a convergence threshold `eps` on x (the same
/// derivative isolation, so it never misses a simple root).
pub fn roots_in_tol(c: &[f64], lo: f64, hi: f64, eps: f64, out: &mut [f64; MAX_DEGREE]) -> usize {
    let mut n = c.len();
    while n > 0 && c[n - 1] == 0.0 {
        n -= 1;
    }
    let c = &c[..n];
    if n <= 1 || !(lo <= hi) {
        return 0;
    }
    if n == 2 {
        let r = -c[0] / c[1];
        if r >= lo && r <= hi {
            out[0] = r;
            return 1;
        }
        return 0;
    }
    if n == 3 {
        // Closed form (stable), instead of bracketing through the derivative: every
        // isolation chain ends at a quadratic (-9% instructions on scenes/sweep).
        let (a, b, cc) = (c[2], c[1], c[0]);
        let disc = b * b - 4.0 * a * cc;
        if disc < 0.0 {
            return 0;
        }
        let q = -0.5 * (b + disc.sqrt().copysign(b));
        let (mut r0, mut r1) = (q / a, if q != 0.0 { cc / q } else { q / a });
        if r0 > r1 {
            std::mem::swap(&mut r0, &mut r1);
        }
        let mut count = 0;
        for r in [r0, r1] {
            if r >= lo && r <= hi && (count == 0 || out[count - 1] != r) {
                out[count] = r;
                count += 1;
            }
        }
        return count;
    }
    let refine = |a: f64, b: f64, fa: f64| -> f64 {
        let mut br = Bracket { a, b, neg_at_a: fa < 0.0, x: 0.5 * (a + b) };
        for _ in 0..100 {
            let (f, df) = eval_d(c, br.x);
            if let Some(r) = br.step(f, df, eps) {
                return r;
            }
        }
        br.x
    };
    let mut d = [0.0f64; MAX_DEGREE + 1];
    for i in 1..n {
        d[i - 1] = c[i] * i as f64;
    }
    let mut crit = [0.0f64; MAX_DEGREE];
    // The derivative's roots only bracket monotonic pieces; near them the
    // polynomial is flat, so a bracket off by d moves its value by O(d^2):
    // 1e-9 of the interval is plenty (the roots themselves stay at `eps`).
    let nc = roots_in_tol(&d[..n - 1], lo, hi, eps.max(1e-9 * (hi - lo)), &mut crit);
    let mut count = 0;
    let mut a = lo;
    let mut fa = eval(c, a);
    if fa == 0.0 {
        out[count] = a;
        count += 1;
    }
    for i in 0..=nc {
        let b = if i < nc { crit[i] } else { hi };
        if b <= a && i < nc {
            continue;
        }
        let fb = eval(c, b);
        if fb == 0.0 {
            if count == 0 || out[count - 1] != b {
                out[count] = b;
                count += 1;
            }
        } else if fa != 0.0 && (fa < 0.0) != (fb < 0.0) {
            let r = refine(a, b, fa);
            if count == 0 || out[count - 1] != r {
                out[count] = r;
                count += 1;
            }
        }
        a = b;
        fa = fb;
        if count >= MAX_DEGREE {
            break;
        }
    }
    count
}

/// Largest Bernstein coefficient of `a` on [0, 1]: an upper bound of the
/// polynomial there (convex hull property).
pub fn bernstein_max(a: &[f64]) -> f64 {
    bernstein_coeffs(a).fold(f64::NEG_INFINITY, f64::max)
}

/// Smallest Bernstein coefficient of `a` on [0, 1]: a lower bound there.
pub fn bernstein_min(a: &[f64]) -> f64 {
    bernstein_coeffs(a).fold(f64::INFINITY, f64::min)
}

/// Binomial coefficients C(n, k) for n, k <= MAX_DEGREE (Pascal's triangle).
const BINOM: [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] = {
    let mut t = [[0.0f64; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        t[n][0] = 1.0;
        let mut k = 1;
        while k <= n {
            t[n][k] = t[n - 1][k - 1] + if k < n { t[n - 1][k] } else { 0.0 };
            k += 1;
        }
        n += 1;
    }
    t
};

/// Bernstein coefficients on [0, 1] of a polynomial in monomial form:
/// `b_k = sum_{i <= k} C(k, i) / C(n, i) a_i`.
fn bernstein_coeffs(a: &[f64]) -> impl Iterator<Item = f64> + '_ {
    let n = a.len() - 1;
    (0..=n).map(move |k| (0..=k).map(|i| BINOM[k][i] / BINOM[n][i] * a[i]).sum())
}

/// Is the polynomial negative on all of [0, 1]? Bernstein coefficients all
/// negative prove it; when they do not, the control polygon is split in half (de
/// Casteljau) up to `depth` times, which tightens the bound. Conservative: a
/// `false` may still have no positive value.
pub fn negative_on_unit(a: &[f64], depth: u32) -> bool {
    let n = a.len();
    if n == 0 || n > MAX_DEGREE + 1 {
        return false;
    }
    let mut b = [0.0f64; MAX_DEGREE + 1];
    for (k, x) in bernstein_coeffs(a).enumerate() {
        b[k] = x;
    }
    bern_negative(&b[..n], depth)
}

fn bern_negative(b: &[f64], depth: u32) -> bool {
    let n = b.len();
    if b[0] >= 0.0 || b[n - 1] >= 0.0 {
        return false; // a value at an end is not negative
    }
    if b.iter().all(|&x| x < 0.0) {
        return true;
    }
    if depth == 0 {
        return false;
    }
    // de Casteljau at 1/2: left and right control polygons.
    let mut w = [0.0f64; MAX_DEGREE + 1];
    w[..n].copy_from_slice(b);
    let mut left = [0.0f64; MAX_DEGREE + 1];
    let mut right = [0.0f64; MAX_DEGREE + 1];
    for r in 0..n {
        left[r] = w[0];
        right[n - 1 - r] = w[n - 1 - r];
        for i in 0..n - 1 - r {
            w[i] = 0.5 * (w[i] + w[i + 1]);
        }
    }
    bern_negative(&left[..n], depth - 1) && bern_negative(&right[..n], depth - 1)
}

/// `1 / C(n, k)` for n, k <= MAX_DEGREE.
const INV_BINOM: [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] = {
    let mut t = [[0.0f64; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        let mut k = 0;
        while k <= n {
            t[n][k] = 1.0 / BINOM[n][k];
            k += 1;
        }
        n += 1;
    }
    t
};

/// Bernstein coefficients on [0, 1] of the monomial polynomial `a` (lowest degree
/// first, degree `N - 1 <= MAX_DEGREE`): `b_k = sum_{i <= k} C(k, i) a_i / C(n, i)`,
/// computed as `n` passes of pairwise sums (a binomial transform).
#[inline]
pub fn to_bernstein<const N: usize>(a: &[f64; N]) -> [f64; N] {
    const { assert!(N >= 1 && N <= MAX_DEGREE + 1) };
    let n = N - 1;
    let mut b = [0.0; N];
    for i in 0..N {
        b[i] = a[i] * INV_BINOM[n][i];
    }
    // Exclusive ranges only: inclusive ones stay as loops with extra checks.
    for r in 1..N {
        for k in (r..N).rev() {
            b[k] += b[k - 1];
        }
    }
    b
}

/// Bernstein coefficients on `[t0, t1]` (`0 <= t0 <= t1 <= 1`) from those on
/// [0, 1], in place: de Casteljau at `t1` keeping the left part, then at
/// `t0 / t1` keeping the right part. Only convex combinations: stable, and the
/// end coefficients are the polynomial's values at `t0` and `t1` up to rounding.
#[inline]
pub fn bern_restrict<const N: usize>(b: &mut [f64; N], t0: f64, t1: f64) {
    if t1 < 1.0 {
        // After pass r, b[r - 1] is the left polygon's coefficient r - 1.
        let (s, t) = (1.0 - t1, t1);
        for r in 1..N {
            for i in (r..N).rev() {
                b[i] = s * b[i - 1] + t * b[i];
            }
        }
    }
    if t0 > 0.0 && t1 > 0.0 {
        let t = t0 / t1;
        let s = 1.0 - t;
        // After pass r, b[N - r] is the right polygon's coefficient N - r.
        for r in 1..N {
            for i in 0..N - r {
                b[i] = s * b[i] + t * b[i + 1];
            }
        }
    }
}

/// Safeguarded Newton on a polynomial in a bracket `[a, b]` holding one sign
/// change (`neg_at_a`: the sign just right of `a`), at `x`: Newton steps that
/// leave the bracket become bisections, and it is done when a step or the
/// bracket is below `max(eps, 1e-15 (1 + |x|))`. The step of
/// [`roots_in_tol`], of [`Newton`] (which may stop earlier) and of the
/// torus's quartic (`quartic.rs`).
#[derive(Clone, Copy)]
pub(crate) struct Bracket {
    pub(crate) a: f64,
    pub(crate) b: f64,
    pub(crate) neg_at_a: bool,
    pub(crate) x: f64,
}

/// What a [`Bracket`] step gives: the root, or the next iterate.
pub(crate) enum Proposal {
    Root(f64),
    Next(Next),
}

/// The next iterate `nx`, whether it is a Newton step (not a bisection),
/// its length `s` and the tolerance `tol` it was measured against.
pub(crate) struct Next {
    nx: f64,
    newton: bool,
    s: f64,
    tol: f64,
}

impl Bracket {
    /// One step from the value `f` and derivative `df` at `x`: the bracket
    /// narrows to the side holding the sign change, then the next iterate.
    #[inline(always)]
    pub(crate) fn propose(&mut self, f: f64, df: f64, eps: f64) -> Proposal {
        let x = self.x;
        if f == 0.0 {
            return Proposal::Root(x);
        }
        if (f < 0.0) == self.neg_at_a {
            self.a = x
        } else {
            self.b = x
        }
        let (a, b) = (self.a, self.b);
        let mut nx = x - f / df;
        let newton = nx > a && nx < b;
        if !newton {
            nx = 0.5 * (a + b);
        }
        let tol = eps.max(1e-15 * (1.0 + x.abs()));
        let s = (nx - x).abs();
        if s <= tol || b - a <= tol {
            return Proposal::Root(nx);
        }
        Proposal::Next(Next { nx, newton, s, tol })
    }

    /// [`Bracket::propose`], moving to the next iterate: the root when done.
    #[inline(always)]
    pub(crate) fn step(&mut self, f: f64, df: f64, eps: f64) -> Option<f64> {
        match self.propose(f, df, eps) {
            Proposal::Root(r) => Some(r),
            Proposal::Next(n) => {
                self.x = n.nx;
                None
            }
        }
    }
}

/// Safeguarded Newton in the bracket `(a, b)` holding one sign change
/// (`neg_at_a`: the sign just right of `a`), from `x`; Newton steps that leave the
/// bracket become bisections. Stops when a step or the bracket is below
/// `tol = max(eps, 1e-15 (1 + |x|))`, or when two Newton steps in a row show
/// quadratic convergence that puts the next iterate within `tol / 10` of the
/// root (error after a step `s_k` about `K s_k^2`, `K ~ s_k / s_{k-1}^2`): that
/// saves the evaluation that would only confirm it.
#[derive(Clone, Copy)]
struct Newton {
    br: Bracket,
    /// Last Newton step length (infinite after a bisection).
    prev: f64,
}

impl Newton {
    fn new(a: f64, b: f64, neg_at_a: bool, x: f64) -> Self {
        Newton { br: Bracket { a, b, neg_at_a, x }, prev: f64::INFINITY }
    }

    /// One step from the value and derivative at `self.br.x`: the root when done.
    #[inline(always)]
    fn step(&mut self, f: f64, df: f64, eps: f64) -> Option<f64> {
        let Next { nx, newton, s, tol } = match self.br.propose(f, df, eps) {
            Proposal::Root(r) => return Some(r),
            Proposal::Next(n) => n,
        };
        let prev = self.prev;
        if newton && prev.is_finite() && s < 0.5 * prev && s * s * s <= 0.1 * tol * prev * prev {
            return Some(nx);
        }
        self.prev = if newton { s } else { f64::INFINITY };
        self.br.x = nx;
        None
    }
}

/// [`Newton`] on `c` to the end (at most 100 steps).
#[inline]
fn refine_bracket<const N: usize>(c: &[f64; N], mut nt: Newton, eps: f64) -> f64 {
    for _ in 0..100 {
        let (f, df) = eval_d(c, nt.br.x);
        if let Some(r) = nt.step(f, df, eps) {
            return r;
        }
    }
    nt.br.x
}

/// Two [`refine_bracket`]s at once, their evaluations interleaved (Horner is
/// latency bound: two independent chains cost about as much as one). Each
/// root is exactly what `refine_bracket` gives.
#[inline]
fn refine_pair<const N: usize>(c: &[f64; N], mut n0: Newton, mut n1: Newton, eps: f64) -> (f64, f64) {
    let (mut r0, mut r1) = (None, None);
    for _ in 0..100 {
        let (x0, x1) = (n0.br.x, n1.br.x);
        let (mut p0, mut d0, mut p1, mut d1) = (0.0, 0.0, 0.0, 0.0);
        for &k in c.iter().rev() {
            d0 = d0 * x0 + p0;
            p0 = p0 * x0 + k;
            d1 = d1 * x1 + p1;
            p1 = p1 * x1 + k;
        }
        if r0.is_none() {
            r0 = n0.step(p0, d0, eps);
        }
        if r1.is_none() {
            r1 = n1.step(p1, d1, eps);
        }
        if r0.is_some() && r1.is_some() {
            break;
        }
    }
    (r0.unwrap_or(n0.br.x), r1.unwrap_or(n1.br.x))
}

/// Deepest subdivision of [`bern_roots`] (2^-52 of the interval is f64's
/// resolution on [0, 1]).
const BERN_MAX_DEPTH: u32 = 52;

/// Subdivision budget of [`bern_roots`] (intervals visited): beyond it (only
/// for polynomials that are zero up to rounding over a range, whose sign
/// pattern is noise) it falls back to [`roots_in_tol`].
const BERN_BUDGET: u32 = 2000;

struct BernIso<'a, const N: usize> {
    c: &'a [f64; N],
    eps: f64,
    out: &'a mut [f64; MAX_DEGREE],
    count: usize,
    /// A bracket waiting for a second one, to be polished together.
    pending: Option<Newton>,
    visits: u32,
    failed: bool,
}

impl<const N: usize> BernIso<'_, N> {
    fn push_value(&mut self, x: f64) {
        if self.count > 0 && self.out[self.count - 1] >= x {
            return;
        }
        if self.count == MAX_DEGREE {
            self.failed = true;
            return;
        }
        self.out[self.count] = x;
        self.count += 1;
    }

    /// Polishes the pending bracket, if any, and pushes its root.
    fn flush(&mut self) {
        if let Some(nt) = self.pending.take() {
            let r = refine_bracket(self.c, nt, self.eps);
            self.push_value(r);
        }
    }

    /// A candidate point (after the pending root, which lies to its left).
    fn push(&mut self, x: f64) {
        self.flush();
        self.push_value(x);
    }

    /// A bracket: kept until a second one comes, then both are polished at once.
    fn push_bracket(&mut self, nt: Newton) {
        match self.pending.take() {
            None => self.pending = Some(nt),
            Some(p) => {
                let (r0, r1) = refine_pair(self.c, p, nt, self.eps);
                self.push_value(r0);
                self.push_value(r1);
            }
        }
    }

    /// `b`: the Bernstein coefficients on `[a, z]`.
    fn isolate(&mut self, b: &[f64; N], a: f64, z: f64, depth: u32) {
        self.visits += 1;
        if self.failed || self.visits > BERN_BUDGET {
            self.failed = true;
            return;
        }
        // Sign patterns as bit masks: all coefficients of one sign (the common
        // case) means no root.
        // (Sign bits: a zero may be -0.0, so zeros are detected apart.)
        let full = (1u32 << N) - 1;
        let mut neg = 0u32;
        let mut amin = f64::INFINITY;
        for (k, &x) in b.iter().enumerate() {
            neg |= ((x.to_bits() >> 63) as u32) << k;
            amin = amin.min(x.abs());
        }
        let (neg, pos) = if amin > 0.0 {
            (neg, !neg & full)
        } else {
            let (mut n, mut p) = (0u32, 0u32);
            for (k, &x) in b.iter().enumerate() {
                n |= ((x < 0.0) as u32) << k;
                p |= ((x > 0.0) as u32) << k;
            }
            (n, p)
        };
        if neg == 0 || pos == 0 {
            return;
        }
        // Sign variations, zeros skipped (Descartes' rule in the Bernstein basis:
        // an upper bound of the roots in (a, z), of the same parity); `k0` is
        // where the last counted one ends, `first` the sign at `a`.
        let (v, k0, first) = if neg | pos == full {
            let ch = (neg ^ (neg >> 1)) & ((1u32 << (N - 1)) - 1);
            (ch.count_ones(), ch.trailing_zeros() as usize + 1, neg & 1 != 0)
        } else {
            let (mut v, mut k0, mut first, mut prev) = (0, 0, false, 0.0);
            for (k, &x) in b.iter().enumerate() {
                if x == 0.0 {
                    continue;
                }
                if prev == 0.0 {
                    first = x < 0.0;
                } else if (x < 0.0) != (prev < 0.0) {
                    v += 1;
                    k0 = k;
                }
                prev = x;
            }
            (v, k0, first)
        };
        let w = z - a;
        if v == 1 {
            // One root in (a, z). Start where the control polygon crosses zero
            // (b[k0] and the previous nonzero coefficient have opposite signs).
            let mut kp = k0 - 1;
            while b[kp] == 0.0 {
                kp -= 1;
            }
            let (p, q) = (b[kp], b[k0]);
            let f = (kp as f64 + (k0 - kp) as f64 * p / (p - q)) / (N - 1) as f64;
            let x0 = (a + w * f).clamp(a, z);
            self.push_bracket(Newton::new(a, z, first, x0));
            return;
        }
        let m = 0.5 * (a + z);
        if depth >= BERN_MAX_DEPTH || w <= self.eps || m <= a || m >= z {
            // Unresolved (a cluster or a multiple root within the tolerance):
            // the midpoint is reported as a candidate.
            self.push(m);
            return;
        }
        // de Casteljau at 1/2: `left` is built in place, `right` from its end.
        let mut left = *b;
        let mut right = [0.0f64; N];
        right[N - 1] = left[N - 1];
        for r in 1..N {
            for i in (r..N).rev() {
                left[i] = 0.5 * (left[i - 1] + left[i]);
            }
            right[N - 1 - r] = left[N - 1];
        }
        self.isolate(&left, a, m, depth + 1);
        if left[N - 1] == 0.0 {
            self.push(m);
        }
        self.isolate(&right, m, z, depth + 1);
    }
}

/// Candidate roots in `[lo, hi]` of a polynomial given both ways: `b` its
/// Bernstein coefficients on `[lo, hi]` (degree `N - 1`) and `c` its monomial
/// coefficients (used to polish), in increasing order into `out`; returns how
/// many.
///
/// Isolation by subdivision (Descartes' rule of signs in the Bernstein basis):
/// no sign variation in an interval's coefficients, no root there; one, exactly
/// one root, polished by safeguarded Newton from the control polygon's zero to
/// `eps` in x (like [`roots_in_tol`]); more, the interval is halved by de
/// Casteljau. An interval that is still ambiguous at width `eps` (or after 52
/// halvings) reports its midpoint. So every simple root separated from the
/// others by more than `eps` is found to `eps`; a cluster or an even-multiplicity
/// root narrower than `eps` gives (at least) one candidate point near it, and
/// a polynomial that only touches zero in f64 may give a candidate where it
/// has no root: callers must accept extra candidate points (unlike
/// [`roots_in_tol`], which reports a tangency only where the value is exactly
/// zero). Exact zeros at `lo`, `hi` and at split points are reported. If the
/// coefficients' sign pattern is noise over a long range (a polynomial zero up
/// to rounding) the subdivision budget runs out and the answer is
/// [`roots_in_tol`]'s.
pub fn bern_roots<const N: usize>(b: &[f64; N], c: &[f64; N], lo: f64, hi: f64, eps: f64, out: &mut [f64; MAX_DEGREE]) -> usize {
    if N < 2 || !(lo <= hi) || b.iter().all(|&x| x == 0.0) {
        return 0;
    }
    // The end coefficients are the values at the ends: take them from `c`, so
    // that the signs at the ends agree with the polishing's evaluations (they
    // may differ in the last bits, which matters for a root at an end).
    let mut b = *b;
    b[0] = if lo == 0.0 { c[0] } else { eval(c, lo) };
    b[N - 1] = eval(c, hi);
    let mut st = BernIso { c, eps, out, count: 0, pending: None, visits: 0, failed: false };
    if b[0] == 0.0 {
        st.push(lo);
    }
    if hi > lo {
        st.isolate(&b, lo, hi, 0);
    }
    if b[N - 1] == 0.0 {
        st.push(hi);
    }
    st.flush();
    if st.failed {
        return roots_in_tol(c, lo, hi, eps, st.out);
    }
    st.count
}

/// [`bern_roots`] of the monomial polynomial `c` on `[lo, hi]`, `0 <= lo <= hi <= 1`
/// (Bernstein form on [0, 1], restricted to `[lo, hi]` by de Casteljau).
pub fn roots_bern<const N: usize>(c: &[f64; N], lo: f64, hi: f64, eps: f64, out: &mut [f64; MAX_DEGREE]) -> usize {
    if !(lo <= hi) {
        return 0;
    }
    debug_assert!(lo >= 0.0 && hi <= 1.0, "roots_bern: [{lo}, {hi}] not in [0, 1]");
    let mut b = to_bernstein(c);
    bern_restrict(&mut b, lo, hi);
    bern_roots(&b, c, lo, hi, eps, out)
}

/// Exact range of a cubic (monomial coefficients) over [0, 1].
pub fn cubic_range(c: &[f64; 4]) -> (f64, f64) {
    let mut lo = eval(c, 0.0).min(eval(c, 1.0));
    let mut hi = eval(c, 0.0).max(eval(c, 1.0));
    let d = [c[1], 2.0 * c[2], 3.0 * c[3]];
    let mut roots = [0.0; MAX_DEGREE];
    let n = roots_in(&d, 0.0, 1.0, &mut roots);
    for &u in &roots[..n] {
        let v = eval(c, u);
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from_roots(r: &[f64]) -> Vec<f64> {
        let mut c = vec![1.0];
        for &x in r {
            let mut n = vec![0.0; c.len() + 1];
            for (i, &k) in c.iter().enumerate() {
                n[i + 1] += k;
                n[i] -= k * x;
            }
            c = n;
        }
        c
    }

    #[test]
    fn finds_all_roots_of_products() {
        let cases: &[&[f64]] = &[
            &[-1.0, 2.0],
            &[0.1, 0.2, 0.3],
            &[-3.0, -1.0, 1.0, 3.0],
            &[0.5, 0.5000001, 2.0, 2.5],
            &[-0.9, -0.3, 0.2, 0.25, 0.7, 0.71, 1.3, 1.9],
        ];
        for r in cases {
            let c = from_roots(r);
            let mut out = [0.0; MAX_DEGREE];
            let n = roots_in(&c, -10.0, 10.0, &mut out);
            assert_eq!(n, r.len(), "roots {r:?} found {:?}", &out[..n]);
            for (a, b) in out[..n].iter().zip(r.iter()) {
                assert!((a - b).abs() < 1e-9, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn negative_on_unit_is_conservative_and_tightens() {
        // -(x - 0.5)^2 - 0.01: negative everywhere; its plain Bernstein bound is
        // not enough at degree 2 but halving proves it.
        let c = [-0.26, 1.0, -1.0];
        assert!(negative_on_unit(&c, 4));
        // Touches zero inside: never claimed negative.
        let c = from_roots(&[0.3, 0.3]).iter().map(|x| -x).collect::<Vec<_>>();
        assert!(!negative_on_unit(&c, 6));
        let c = from_roots(&[0.2, 0.7]);
        assert!(!negative_on_unit(&c, 6));
    }

    #[test]
    fn bernstein_bounds_enclose_the_polynomial() {
        // (x - 0.3)(x - 0.6)(x + 1): the coefficients bound every sampled value.
        let c = from_roots(&[0.3, 0.6, -1.0]);
        let (lo, hi) = (bernstein_min(&c), bernstein_max(&c));
        for k in 0..=100 {
            let v = eval(&c, k as f64 / 100.0);
            assert!(v >= lo - 1e-12 && v <= hi + 1e-12);
        }
        assert_eq!(BINOM[6][3], 20.0);
    }

    #[test]
    fn respects_interval() {
        let c = from_roots(&[-2.0, 0.5, 3.0]);
        let mut out = [0.0; MAX_DEGREE];
        let n = roots_in(&c, 0.0, 1.0, &mut out);
        assert_eq!(n, 1);
        assert!((out[0] - 0.5).abs() < 1e-12);
    }

    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// [`roots_bern`] for a coefficient slice of any supported length.
    fn bern_dyn(c: &[f64], lo: f64, hi: f64, eps: f64) -> Vec<f64> {
        let mut out = [0.0; MAX_DEGREE];
        macro_rules! by_len {
            ($($n:literal)*) => {
                match c.len() {
                    $($n => roots_bern::<$n>(c.try_into().unwrap(), lo, hi, eps, &mut out),)*
                    _ => panic!("length {}", c.len()),
                }
            };
        }
        let n = by_len!(1 2 3 4 5 6 7 8 9 10 11 12 13);
        out[..n].to_vec()
    }

    /// Bernstein form on [t0, t1] evaluated directly (sum of b_k B_k(s)).
    fn bern_eval(b: &[f64], s: f64) -> f64 {
        let n = b.len() - 1;
        b.iter().enumerate().map(|(k, &x)| x * BINOM[n][k] * s.powi(k as i32) * (1.0 - s).powi((n - k) as i32)).sum()
    }

    #[test]
    fn bernstein_conversion_and_restriction_match_monomial() {
        let seed = 0xbe_0001u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for _ in 0..500 {
            let a: [f64; 11] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
            let (mut t0, mut t1): (f64, f64) = (rng.gen(), rng.gen());
            if t0 > t1 {
                std::mem::swap(&mut t0, &mut t1);
            }
            match rng.gen_range(0..4) {
                0 => t0 = 0.0,
                1 => t1 = 1.0,
                _ => {}
            }
            let mut b = to_bernstein(&a);
            for k in 0..=20 {
                let s = k as f64 / 20.0;
                assert!((bern_eval(&b, s) - eval(&a, s)).abs() < 1e-13, "[0, 1] at {s}");
            }
            bern_restrict(&mut b, t0, t1);
            for k in 0..=20 {
                let s = k as f64 / 20.0;
                let want = eval(&a, t0 + (t1 - t0) * s);
                assert!((bern_eval(&b, s) - want).abs() < 1e-12, "[{t0}, {t1}] at {s}: {} vs {want}", bern_eval(&b, s));
            }
        }
    }

    /// Known roots (some close pairs, double roots, roots at and just outside 0
    /// and 1) times a random scale: every simple root that f64 resolves (its
    /// perturbation bound below half its distance to the others) and that the
    /// computed polynomial brackets is found within that bound plus 2 eps; every
    /// candidate is near a true root.
    #[test]
    fn bern_roots_finds_known_roots() {
        let seed = 0xbe_0002u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut checked, mut close_checked, mut skipped) = (0, 0, 0);
        for trial in 0..4000 {
            let deg = rng.gen_range(1..=MAX_DEGREE);
            let mut r: Vec<f64> = vec![];
            while r.len() < deg {
                let x: f64 = rng.gen();
                match rng.gen_range(0..10) {
                    0..=2 => r.push(x),
                    3 => r.push(rng.gen_range(-0.5..1.5)),
                    4 if r.len() + 2 <= deg => {
                        let s = 10f64.powf(rng.gen_range(-10.0..-6.0));
                        r.extend([x, x + s]);
                    }
                    5 if r.len() + 2 <= deg => r.extend([x, x]),
                    6 => r.push(if rng.gen() { 0.0 } else { 1.0 }),
                    7 => r.push(-(10f64.powf(rng.gen_range(-12.0..-6.0)))),
                    8 => r.push(1.0 + 10f64.powf(rng.gen_range(-12.0..-6.0))),
                    _ => r.push(rng.gen_range(0.0..0.01) + if rng.gen() { 0.0 } else { 0.99 }),
                }
            }
            let scale = 10f64.powf(rng.gen_range(-3.0..3.0)) * if rng.gen() { 1.0 } else { -1.0 };
            let c: Vec<f64> = from_roots(&r).iter().map(|x| x * scale).collect();
            let eps = [1e-4, 1e-6, 1e-9, 1e-14][rng.gen_range(0..4)];
            let got = bern_dyn(&c, 0.0, 1.0, eps);
            let ctx = || format!("trial {trial}: roots {r:?} scale {scale:e} eps {eps:e}: got {got:?}");
            assert!(got.windows(2).all(|w| w[0] < w[1]), "not increasing: {}", ctx());
            for (i, &x) in r.iter().enumerate() {
                if !(0.0..=1.0).contains(&x) {
                    continue;
                }
                let dp: f64 = scale * r.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, &y)| x - y).product::<f64>();
                let sep = r.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, &y)| (x - y).abs()).fold(f64::INFINITY, f64::min);
                // Perturbation of the root by the rounding of the coefficients.
                let noise: f64 = c.iter().enumerate().map(|(k, a)| a.abs() * x.abs().powi(k as i32)).sum();
                let bound = 64.0 * f64::EPSILON * noise / dp.abs() + 1e-15;
                if !(bound < 0.5 * sep) {
                    skipped += 1;
                    continue;
                }
                let (a, b) = ((x - bound).max(0.0), (x + bound).min(1.0));
                let (fa, fb) = (eval(&c, a), eval(&c, b));
                if a > 0.0 && b < 1.0 {
                    assert!(fa * fb < 0.0, "bound too small at {x}: {}", ctx());
                } else if fa * fb > 0.0 {
                    skipped += 1; // the computed polynomial's root left [0, 1]
                    continue;
                }
                let d = got.iter().map(|&y| (y - x).abs()).fold(f64::INFINITY, f64::min);
                assert!(d <= 2.0 * bound + 2.0 * eps, "root {x} missed (nearest {d:e}, bound {bound:e}): {}", ctx());
                checked += 1;
                if sep < 1e-5 {
                    close_checked += 1;
                }
            }
            // A candidate is near a true root, or a root of the computed polynomial
            // (clusters of a degree-12 polynomial move by much more than 1e-5).
            for &y in &got {
                let d = r.iter().map(|&x| (y - x).abs()).fold(f64::INFINITY, f64::min);
                let noise: f64 = c.iter().enumerate().map(|(k, a)| a.abs() * y.abs().powi(k as i32)).sum();
                assert!(
                    d <= 2.0 * eps + 1e-5 || eval(&c, y).abs() <= 64.0 * f64::EPSILON * noise,
                    "candidate {y} far from every root: {}",
                    ctx()
                );
            }
        }
        println!("{checked} roots checked ({close_checked} in pairs closer than 1e-5), {skipped} not resolvable in f64");
        assert!(checked > 10000 && close_checked > 300);
    }

    #[test]
    fn bern_roots_exact_zeros_and_degenerate_input() {
        // Dyadic roots, several at split points and the ends: each once.
        let c = from_roots(&[0.0, 0.25, 0.5, 0.75, 1.0]);
        let got = bern_dyn(&c, 0.0, 1.0, 1e-12);
        assert_eq!(got.len(), 5, "{got:?}");
        for (x, y) in got.iter().zip([0.0, 0.25, 0.5, 0.75, 1.0]) {
            assert!((x - y).abs() < 1e-12, "{got:?}");
        }
        // A sub-interval ending on roots, and one holding none.
        let got = bern_dyn(&c, 0.3, 0.8, 1e-12);
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(bern_dyn(&c, 0.55, 0.7, 1e-12).is_empty());
        // Zero and constant polynomials, an empty interval.
        assert!(bern_dyn(&[0.0; 7], 0.0, 1.0, 1e-9).is_empty());
        assert!(bern_dyn(&[2.0, 0.0, 0.0], 0.0, 1.0, 1e-9).is_empty());
        assert!(bern_dyn(&c, 0.7, 0.6, 1e-9).is_empty());
        // Roots of high multiplicity make the polynomial zero up to rounding on
        // a wide range (the sign pattern there is noise): a few candidates come
        // back, all near the roots (the subdivision stays far from its budget);
        // an even multiplicity may give none (no sign change in f64).
        for m in [4usize, 6, 8, 12] {
            for eps in [1e-6, 1e-9, 1e-14] {
                let got = bern_dyn(&from_roots(&vec![0.5; m]), 0.0, 1.0, eps);
                assert!(got.len() <= 4, "m {m}: {got:?}");
                assert!(got.iter().all(|x| (x - 0.5).abs() < 0.05), "m {m}: {got:?}");
                let r: Vec<f64> = [0.3, 0.7].iter().flat_map(|&x| vec![x; m / 2]).collect();
                let got = bern_dyn(&from_roots(&r), 0.0, 1.0, eps);
                assert!(got.len() <= 8, "m {m}: {got:?}");
                assert!(got.iter().all(|x| (x - 0.3).abs() < 0.05 || (x - 0.7).abs() < 0.05), "m {m}: {got:?}");
            }
        }
        // Exactly one root of a degree-1 polynomial.
        assert_eq!(bern_dyn(&[-0.3, 1.0], 0.0, 1.0, 1e-9).len(), 1);
    }

    /// Random dense polynomials (coefficients uniform in [-1, 1], degrees 1 to
    /// 12): every root roots_in_tol finds is found, and extra candidates are rare.
    #[test]
    fn bern_roots_agrees_with_roots_in_tol() {
        let seed = 0xbe_0003u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut total, mut extra) = (0, 0);
        for trial in 0..20000 {
            let n = rng.gen_range(2..=MAX_DEGREE + 1);
            let c: Vec<f64> = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let (mut lo, mut hi): (f64, f64) = (rng.gen(), rng.gen());
            if lo > hi {
                std::mem::swap(&mut lo, &mut hi);
            }
            if trial % 2 == 0 {
                (lo, hi) = (0.0, 1.0);
            }
            let eps = [1e-6, 1e-9, 1e-14][trial % 3];
            let mut out = [0.0; MAX_DEGREE];
            let k = roots_in_tol(&c, lo, hi, eps, &mut out);
            let got = bern_dyn(&c, lo, hi, eps);
            for &x in &out[..k] {
                let d = got.iter().map(|&y| (y - x).abs()).fold(f64::INFINITY, f64::min);
                assert!(d <= 1e-6, "trial {trial}: {c:?} on [{lo}, {hi}] eps {eps}: roots_in_tol {:?} bern {got:?}", &out[..k]);
            }
            total += k;
            extra += got.len().saturating_sub(k);
        }
        println!("{total} roots, {extra} extra candidates");
        assert!(extra * 1000 <= total, "{extra} extra candidates for {total} roots");
    }
}
