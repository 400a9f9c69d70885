//! Real roots of polynomials on an interval, in f64.
//!
//! Roots are isolated by the roots of the derivative (recursively): between two
//! consecutive critical points a polynomial is monotonic, so it has at most one root
//! there, found by safeguarded Newton (Newton steps that leave the bracket fall back
//! to bisection). This never misses a simple root, finds both roots of a
//! near-tangent (grazing) pair as long as the minimum between them is negative in
//! f64, and converges to full f64 precision. Degrees up to [`MAX_DEGREE`].

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
    let refine = |mut a: f64, mut b: f64, fa: f64| -> f64 {
        let neg_at_a = fa < 0.0;
        let mut x = 0.5 * (a + b);
        for _ in 0..100 {
            let (f, df) = eval_d(c, x);
            if f == 0.0 {
                return x;
            }
            if (f < 0.0) == neg_at_a { a = x } else { b = x }
            let mut nx = x - f / df;
            if !(nx > a && nx < b) {
                nx = 0.5 * (a + b);
            }
            let tol = eps.max(1e-15 * (1.0 + x.abs()));
            if (nx - x).abs() <= tol || b - a <= tol {
                return nx;
            }
            x = nx;
        }
        x
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
}
