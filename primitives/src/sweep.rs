//! Swept spheres (Van Wijk 1984): the union of the balls of centre `c(u)` and
//! radius `r(u)` along a chain of cubic Bezier segments in `(x, y, z, r)`.
//!
//! # Method (per segment, in f64)
//! With the ray `q(s) = o' + s n` (`n` the unit direction, `o'` the ray's closest
//! approach to the segment's box centre, so every coefficient is well scaled),
//! ball(u) holds `q(s)` iff `s^2 - 2 s a(u) + |w(u)|^2 - r(u)^2 <= 0` with
//! `w = c - o'` and `a = n . w` (a cubic). Its discriminant
//! `D(u) = r(u)^2 - |w(u) x n|^2` is a degree-6 polynomial; where `D >= 0` the ray
//! is inside ball(u) for `s in [s-(u), s+(u)] = a(u) -+ sqrt(D(u))`.
//! Over each connected u-range where `D >= 0` the union of these intervals is
//! one interval `[min s-, max s+]` (a continuous family of intervals), so a
//! segment gives one span per such range. The ranges come from the roots of `D`
//! in `[0, 1]`; the extrema of `s-` and `s+` lie at the range ends or at the
//! roots of `E = 4 a'^2 D - D'^2 = 4 D s-' s+'` (degree 10), which are found in
//! that range only. At a root of `D` inside `(0, 1)` the slope of `s-` and `s+` is
//! infinite, so those ends are never the extrema: the only values that matter
//! are `s-+` at stationary points (where an error `e` in `u` moves `s` by
//! `O(e^2)`) and at `u = 0, 1` (the round end balls, exact). That is why this is
//! exact to f32 precision in `t` and has none of the dark spots of the degree-10
//! elimination POV-Ray uses.
//!
//! Roots are isolated by Bernstein subdivision ([`crate::poly::bern_roots`]:
//! sign variations of the Bernstein coefficients on an interval, de Casteljau
//! halving, safeguarded Newton once an interval holds a single sign change).
//! `D`'s Bernstein coefficients on `[0, 1]` come first: all negative, the ray
//! misses this piece of tube (most rays that enter its box but miss) and no
//! root is looked for; near misses end in the isolation, which stops
//! subdividing where no sign change is left. `E`'s coefficients are built once
//! per segment and restricted to each range by de Casteljau. The isolator
//! returns candidates: every simple root farther than the tolerance from the
//! others, and possibly extra points (an interval still ambiguous at the
//! tolerance reports its midpoint). Extra points are harmless here: `D`'s roots
//! only split `[0, 1]` into pieces classified by `D`'s sign at their
//! midpoints, and `s-+` at any `u` of a range are points inside the sweep.
//!
//! Segments overlap at their joints; their spans are merged (sorted, disjoint).
//! A BVH over the segments' tight boxes is used for chains of more than
//! [`BVH_MIN_SEGMENTS`] segments.
//!
//! # Tolerance
//! `tolerance` is the convergence threshold of the root polishing in the
//! segment parameter `u` (dimensionless: a fraction of a segment; clamped to
//! `[1e-14, 1e-2]`). Since span ends sit at stationary points, the error in `t`
//! relative to the sweep's size is of the order of `tolerance^2` times the
//! segment's (dimensionless) curvature. Measured on the benchmark scene's camera
//! rays (960x540, 8% of them hit; test `sweep_bench`,
//! `cargo test -p rothray-primitives --release sweep_bench -- --ignored --nocapture`,
//! best of 3 per tolerance, quietest of 3 rounds, one thread on a shared 2-core
//! machine): 1e-6 (default) and tighter give span ends identical in f32 to
//! 1e-12, 62 ns/ray on average at 1e-6 and 65 at 1e-9 (the derivative-chain
//! isolation of `roots_in_tol`, measured alongside: 144 and 161); 1e-4 moves
//! ends by <= 5e-7 in t, 61 ns/ray; 1e-3 by <= 1e-5, 59 ns/ray; 1e-2 by <=
//! 4e-3, 67 ns/ray (no span lost on these rays, but coarse is not faster). The
//! knob is cheap to leave at the default: most of the time goes into isolating
//! roots, not polishing them.
//!
//! # Sub-surface ids and normals
//! A crossing's `sub` is the index of the segment it lies on. [`SweptSphereData::normal`]
//! finds the `u*` that minimises `|p - c(u)|^2 - r(u)^2` over that segment
//! (endpoints and roots of the derivative, degree 5, by [`crate::poly::roots_bern`]
//! at 1e-14: extra candidates only add evaluations) and returns
//! `(p - c(u*)) / |p - c(u*)|`, the gradient of the union's distance function.

use glam::{DVec3, Vec3};
use smallvec::SmallVec;

use crate::poly::{bern_restrict, bern_roots, cubic_range, roots_bern, to_bernstein};

/// An unmerged span `(t0, sub0, t1, sub1)`.
type RawSpan = (f32, u32, f32, u32);
use crate::{aabb::Aabb, bvh::FlatBvh, table::push_clipped, Ray, ShapeError, Span, SpanSink, Surf};

/// Chains with more segments than this get a BVH over their segments.
pub const BVH_MIN_SEGMENTS: usize = 4;

/// Default [`SweptSphereData::new`] tolerance.
pub const DEFAULT_TOLERANCE: f32 = 1e-6;

/// A swept sphere as described in a scene: `3n + 1` points `[x, y, z, r]`,
/// segment `i` using points `3i..=3i+3`.
#[derive(Clone, Debug, PartialEq)]
pub struct SweptSphere {
    /// Control points `(x, y, z, r)` of the cubic Bezier chain.
    pub bezier: Vec<[f32; 4]>,
}

fn err(message: impl Into<String>) -> ShapeError {
    ShapeError { field: "bezier", message: message.into() }
}

impl SweptSphere {
    /// Checks the numbers: length `3n + 1` (n >= 1), finite numbers, radii `>= 0`,
    /// not all zero.
    pub fn validate(&self) -> Result<(), ShapeError> {
        let n = self.bezier.len();
        if n < 4 || !(n - 1).is_multiple_of(3) {
            return Err(err(format!("length {n} is not 3n+1 (n >= 1)")));
        }
        for (i, p) in self.bezier.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(err(format!("point {i} {p:?} has a NaN or infinite number")));
            }
            if p[3] < 0.0 {
                return Err(err(format!("point {i} has a negative radius {}", p[3])));
            }
        }
        if self.bezier.iter().all(|p| p[3] == 0.0) {
            return Err(err("all radii are zero (the sweep has no volume)"));
        }
        Ok(())
    }
}

/// One segment in monomial form `sum_k coef[k] u^k`.
#[derive(Clone, Debug)]
struct Seg {
    c: [[f64; 4]; 3],
    r: [f64; 4],
    /// `r(u)^2` (degree 6).
    r2: [f64; 7],
    center: DVec3,
}

impl Seg {
    fn center_at(&self, u: f64) -> DVec3 {
        DVec3::new(eval(&self.c[0], u), eval(&self.c[1], u), eval(&self.c[2], u))
    }
    /// `|p - c(u)|^2 - r(u)^2` as a degree-6 polynomial in u.
    fn dist2_poly(&self, p: DVec3) -> [f64; 7] {
        let mut g = [0.0; 7];
        for ax in 0..3 {
            let mut w = self.c[ax];
            w[0] -= p[ax];
            for i in 0..4 {
                for j in 0..4 {
                    g[i + j] += w[i] * w[j];
                }
            }
        }
        for i in 0..4 {
            for j in 0..4 {
                g[i + j] -= self.r[i] * self.r[j];
            }
        }
        g
    }
    /// The u in [0, 1] minimising `|p - c(u)|^2 - r(u)^2`, and that minimum.
    fn closest(&self, p: DVec3) -> (f64, f64) {
        let g = self.dist2_poly(p);
        let dg = deriv(&g);
        let mut best = (0.0, eval(&g, 0.0));
        let g1 = eval(&g, 1.0);
        if g1 < best.1 {
            best = (1.0, g1);
        }
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        let dg: &[f64; 6] = dg[..6].try_into().unwrap();
        let n = roots_bern(dg, 0.0, 1.0, 1e-14, &mut roots);
        for &u in &roots[..n] {
            let v = eval(&g, u);
            if v < best.1 {
                best = (u, v);
            }
        }
        best
    }
}

/// A baked swept sphere: per-segment polynomials, tight boxes, a BVH for long
/// chains. Immutable, `Send + Sync`.
#[derive(Clone, Debug)]
pub struct SweptSphereData {
    segs: Vec<Seg>,
    /// Segments with some positive radius (the others hold no volume).
    live: Vec<u32>,
    /// Tight box per segment (indexed like `segs`).
    boxes: Vec<Aabb>,
    bounds: Aabb,
    /// BVH over `live` (primitive `k` is segment `live[k]`).
    bvh: Option<FlatBvh>,
    tol: f64,
}

#[inline]
fn eval(c: &[f64], x: f64) -> f64 {
    crate::poly::eval(c, x)
}

fn deriv<const N: usize>(c: &[f64; N]) -> [f64; N] {
    let mut d = [0.0; N];
    for i in 1..N {
        d[i - 1] = c[i] * i as f64;
    }
    d
}

/// `p^2` (`M = 2N - 1` coefficients), each unordered pair of products once.
fn square<const N: usize, const M: usize>(p: &[f64; N]) -> [f64; M] {
    debug_assert_eq!(M, 2 * N - 1);
    let mut q = [0.0; M];
    for j in 0..N {
        q[2 * j] += p[j] * p[j];
        for k in j + 1..N {
            q[j + k] += 2.0 * p[j] * p[k];
        }
    }
    q
}

fn bezier_to_monomial(p: [f64; 4]) -> [f64; 4] {
    [p[0], 3.0 * (p[1] - p[0]), 3.0 * (p[0] - 2.0 * p[1] + p[2]), -p[0] + 3.0 * (p[1] - p[2]) + p[3]]
}

/// f64 -> f32 rounded down / up (so f32 boxes still enclose the f64 ones).
pub(crate) fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if f as f64 > x {
        f.next_down()
    } else {
        f
    }
}
pub(crate) fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x {
        f.next_up()
    } else {
        f
    }
}

/// Sorts `iv` and pushes the union as sorted disjoint spans (clipped).
pub(crate) fn push_union<S: SpanSink + ?Sized>(iv: &mut [RawSpan], tmin: f32, tmax: f32, leaf: u32, out: &mut S) {
    push_union_slack(iv, 0.0, tmin, tmax, leaf, out)
}

/// [`push_union`], also merging spans separated by gaps of at most `slack`.
pub(crate) fn push_union_slack<S: SpanSink + ?Sized>(iv: &mut [RawSpan], slack: f32, tmin: f32, tmax: f32, leaf: u32, out: &mut S) {
    if iv.is_empty() {
        return;
    }
    iv.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut cur = iv[0];
    for &x in &iv[1..] {
        if x.0 <= cur.2 + slack {
            if x.2 > cur.2 {
                cur.2 = x.2;
                cur.3 = x.3;
            }
        } else {
            push_clipped(out, Span { t0: cur.0, s0: Surf::new(leaf, cur.1), t1: cur.2, s1: Surf::new(leaf, cur.3) }, tmin, tmax);
            cur = x;
        }
    }
    push_clipped(out, Span { t0: cur.0, s0: Surf::new(leaf, cur.1), t1: cur.2, s1: Surf::new(leaf, cur.3) }, tmin, tmax);
}

impl SweptSphereData {
    /// Bakes `desc` (validated here). `tolerance`: see the module doc
    /// ([`DEFAULT_TOLERANCE`] is a good default).
    pub fn new(desc: &SweptSphere, tolerance: f32) -> Result<Self, ShapeError> {
        desc.validate()?;
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(ShapeError { field: "tolerance", message: format!("must be positive, got {tolerance}") });
        }
        let n = (desc.bezier.len() - 1) / 3;
        let mut segs = Vec::with_capacity(n);
        let mut boxes = Vec::with_capacity(n);
        let mut live = Vec::new();
        let mut bounds = Aabb::EMPTY;
        for i in 0..n {
            let p = &desc.bezier[3 * i..3 * i + 4];
            let comp = |k: usize| bezier_to_monomial([p[0][k] as f64, p[1][k] as f64, p[2][k] as f64, p[3][k] as f64]);
            let c = [comp(0), comp(1), comp(2)];
            let r = comp(3);
            // Exact box: extremes of c_k(u) -+ r(u) per axis.
            let mut lo = [0.0f32; 3];
            let mut hi = [0.0f32; 3];
            for k in 0..3 {
                let mut plus = c[k];
                let mut minus = c[k];
                for j in 0..4 {
                    plus[j] += r[j];
                    minus[j] -= r[j];
                }
                lo[k] = f32_down(cubic_range(&minus).0);
                hi[k] = f32_up(cubic_range(&plus).1);
            }
            let b = Aabb::new(Vec3::from(lo), Vec3::from(hi));
            if p.iter().any(|q| q[3] > 0.0) {
                live.push(i as u32);
                bounds = bounds.union(&b);
            }
            segs.push(Seg { c, r, r2: square(&r), center: b.center().as_dvec3() });
            boxes.push(b);
        }
        let bvh = if live.len() > BVH_MIN_SEGMENTS {
            let lb: Vec<Aabb> = live.iter().map(|&i| boxes[i as usize]).collect();
            Some(FlatBvh::build(&lb, 1))
        } else {
            None
        };
        Ok(SweptSphereData { segs, live, boxes, bounds, bvh, tol: (tolerance as f64).clamp(1e-14, 1e-2) })
    }

    /// Tight local box (exact extremes of `c(u) -+ r(u)`, rounded outward).
    pub fn local_bounds(&self) -> Aabb {
        self.bounds
    }

    /// Number of Bezier segments.
    pub fn segment_count(&self) -> usize {
        self.segs.len()
    }

    /// Pushes the spans of the (local) ray inside the sweep, clipped to its
    /// range, sorted and disjoint; real crossings carry `Surf::new(leaf, segment)`.
    pub fn spans<S: SpanSink + ?Sized>(&self, ray: &Ray, leaf: u32, out: &mut S) {
        let Ray { origin: o, dir: d, inv_dir: inv, tmin, tmax } = *ray;
        if self.bounds.ray_range(o, inv, tmin, tmax).is_none() {
            return;
        }
        let od = o.as_dvec3();
        let dd = d.as_dvec3();
        let dl = dd.length();
        if !(dl > 0.0 && dl.is_finite()) {
            return;
        }
        let dn = dd / dl;
        let mut iv: SmallVec<[RawSpan; 16]> = SmallVec::new();
        match &self.bvh {
            Some(b) => b.traverse(o, inv, tmin, tmax, |k, _| {
                let i = self.live[k as usize];
                self.seg_spans(i, od, dn, dl, &mut iv);
                tmax
            }),
            None => {
                for &i in &self.live {
                    if self.boxes[i as usize].ray_range(o, inv, tmin, tmax).is_some() {
                        self.seg_spans(i, od, dn, dl, &mut iv);
                    }
                }
            }
        }
        push_union(&mut iv, tmin, tmax, leaf, out);
    }

    /// Spans of segment `i` (unclipped) appended to `out`.
    fn seg_spans(&self, i: u32, od: DVec3, dn: DVec3, dl: f64, out: &mut SmallVec<[RawSpan; 16]>) {
        let seg = &self.segs[i as usize];
        let tc = (seg.center - od).dot(dn);
        let op = od + dn * tc;
        let mut w = seg.c;
        for ax in 0..3 {
            w[ax][0] -= op[ax];
        }
        let mut a = [0.0; 4];
        let mut cx = [0.0; 4];
        let mut cy = [0.0; 4];
        let mut cz = [0.0; 4];
        for k in 0..4 {
            let v = DVec3::new(w[0][k], w[1][k], w[2][k]);
            a[k] = v.dot(dn);
            let c = v.cross(dn);
            cx[k] = c.x;
            cy[k] = c.y;
            cz[k] = c.z;
        }
        // D = r^2 - |w x n|^2 (the products once per unordered pair).
        let mut dp = seg.r2;
        for j in 0..4 {
            dp[2 * j] -= cx[j] * cx[j] + cy[j] * cy[j] + cz[j] * cz[j];
            for k in j + 1..4 {
                dp[j + k] -= 2.0 * (cx[j] * cx[k] + cy[j] * cy[k] + cz[j] * cz[k]);
            }
        }
        // D's Bernstein coefficients all negative: the ray misses this piece of
        // tube (most rays that enter the box but miss). Near misses with a sign
        // change in the control polygon are settled by the isolation below,
        // whose subdivision stops as soon as no sign change is left.
        let bd = to_bernstein(&dp);
        if bd.iter().all(|&x| x < 0.0) {
            return;
        }
        let mut roots = [0.0; crate::poly::MAX_DEGREE];
        let nr = bern_roots(&bd, &dp, 0.0, 1.0, self.tol, &mut roots);
        // Breakpoints 0, roots, 1; pieces with D > 0 inside, merged into ranges.
        let mut pts: SmallVec<[f64; 14]> = SmallVec::new();
        pts.push(0.0);
        for &x in &roots[..nr] {
            if x > *pts.last().unwrap() && x < 1.0 {
                pts.push(x);
            }
        }
        pts.push(1.0);
        let mut ranges: SmallVec<[(f64, f64); 4]> = SmallVec::new();
        for k in 0..pts.len() - 1 {
            let (u0, u1) = (pts[k], pts[k + 1]);
            if eval(&dp, 0.5 * (u0 + u1)) > 0.0 {
                match ranges.last_mut() {
                    Some(l) if l.1 == u0 => l.1 = u1,
                    _ => ranges.push((u0, u1)),
                }
            }
        }
        if ranges.is_empty() {
            return;
        }
        // E = 4 a'^2 D - D'^2 (degree 10): stationary points of s- and s+.
        let da2: [f64; 5] = square(&[2.0 * a[1], 4.0 * a[2], 6.0 * a[3]]);
        let dd = deriv(&dp);
        let dd2: [f64; 11] = square(&[dd[0], dd[1], dd[2], dd[3], dd[4], dd[5]]);
        let mut e = [0.0f64; 11];
        for j in 0..5 {
            for k in 0..7 {
                e[j + k] += da2[j] * dp[k];
            }
        }
        for k in 0..11 {
            e[k] -= dd2[k];
        }
        let be = to_bernstein(&e);
        let s_pm = |u: f64| {
            let h = eval(&dp, u).max(0.0).sqrt();
            let m = eval(&a, u);
            (m - h, m + h)
        };
        for &(u0, u1) in &ranges {
            let (mut lo, mut hi) = s_pm(u0);
            let (l1, h1) = s_pm(u1);
            lo = lo.min(l1);
            hi = hi.max(h1);
            let mut br = be;
            bern_restrict(&mut br, u0, u1);
            let ne = bern_roots(&br, &e, u0, u1, self.tol, &mut roots);
            for &u in &roots[..ne] {
                let (l, h) = s_pm(u);
                lo = lo.min(l);
                hi = hi.max(h);
            }
            out.push((((tc + lo) / dl) as f32, i, ((tc + hi) / dl) as f32, i));
        }
    }

    /// Is the local point inside (boundary included)? Exact: the minimum over u of
    /// the degree-6 polynomial `|p - c(u)|^2 - r(u)^2` per segment.
    pub fn contains(&self, p: Vec3) -> bool {
        if !self.bounds.contains(p) {
            return false;
        }
        let pd = p.as_dvec3();
        let test = |i: u32| self.boxes[i as usize].contains(p) && self.segs[i as usize].closest(pd).1 <= 0.0;
        match &self.bvh {
            Some(b) => {
                let mut hit = false;
                b.point_query(p, |k| {
                    if !hit {
                        hit = test(self.live[k as usize]);
                    }
                });
                hit
            }
            None => self.live.iter().any(|&i| test(i)),
        }
    }

    /// Outward unit normal at the surface point `p` of segment `sub`.
    pub fn normal(&self, sub: u32, p: Vec3) -> Vec3 {
        let Some(seg) = self.segs.get(sub as usize) else { return Vec3::Y };
        let pd = p.as_dvec3();
        let (u, _) = seg.closest(pd);
        let v = pd - seg.center_at(u);
        if v.length_squared() > 0.0 {
            return v.normalize().as_vec3();
        }
        // p on the centre line (a zero radius): the tangent direction is the best guess.
        let t = DVec3::new(seg.c[0][1], seg.c[1][1], seg.c[2][1]);
        (t.try_normalize().unwrap_or(DVec3::Y)).as_vec3()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::Span;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// The benchmark scene's sweep (/work/shared/scenes/sweep.json).
    pub(crate) fn bench_shape() -> SweptSphere {
        let b: [[f64; 4]; 10] = [
            [-1.5, 0.0, 0.0, 0.3],
            [-1.1666666666666667, 0.3333333333333333, 0.08333333333333333, 0.35],
            [-0.8333333333333333, 1.1666666666666667, 0.5833333333333334, 0.48333333333333334],
            [-0.5, 1.0, 0.5, 0.5],
            [-0.16666666666666669, 0.8333333333333334, 0.4166666666666667, 0.5166666666666667],
            [0.16666666666666669, -0.8333333333333334, -0.4166666666666667, 0.45],
            [0.5, -1.0, -0.5, 0.4],
            [0.8333333333333333, -1.1666666666666667, -0.5833333333333334, 0.35000000000000003],
            [1.1666666666666667, -0.3333333333333333, -0.08333333333333333, 0.21666666666666667],
            [1.5, 0.0, 0.0, 0.2],
        ];
        SweptSphere { bezier: b.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, p[3] as f32]).collect() }
    }

    fn shapes() -> Vec<(&'static str, SweptSphere)> {
        let s = |v: &[[f32; 4]]| SweptSphere { bezier: v.to_vec() };
        let mut long = vec![[0.0f32, 0.0, 0.0, 0.2]];
        for i in 0..8 {
            let x = i as f32;
            long.push([x + 0.33, 0.6 * (i % 2) as f32, 0.2, 0.15]);
            long.push([x + 0.66, -0.6 * (i % 2) as f32, -0.2, 0.25]);
            long.push([x + 1.0, 0.0, 0.0, 0.1 + 0.05 * (i % 3) as f32]);
        }
        vec![
            ("bench", bench_shape()),
            // A segment that curls back over itself, then a second one.
            (
                "curl",
                s(&[
                    [0.0, 0.0, 0.0, 0.2],
                    [3.0, 3.0, 0.0, 0.45],
                    [-3.0, 3.0, 0.4, 0.3],
                    [0.2, 0.1, 0.8, 0.25],
                    [1.0, -0.5, 1.0, 0.2],
                    [1.5, 0.5, 0.0, 0.1],
                    [2.0, 0.0, -0.5, 0.3],
                ]),
            ),
            // A thin neck (r = 1e-3) at the joint, a zero radius at the start.
            (
                "neck",
                s(&[
                    [-1.0, 0.0, 0.0, 0.0],
                    [-0.7, 0.3, 0.0, 0.4],
                    [-0.3, 0.1, 0.1, 0.01],
                    [0.0, 0.0, 0.0, 0.001],
                    [0.3, -0.1, -0.1, 0.005],
                    [0.7, 0.2, 0.0, 0.4],
                    [1.0, 0.0, 0.2, 0.3],
                ]),
            ),
            ("long", s(&long)),
        ]
    }

    /// Control points of segment `i` in f64.
    fn ctrl(sh: &SweptSphere, i: usize) -> [[f64; 4]; 4] {
        let mut c = [[0.0; 4]; 4];
        for k in 0..4 {
            for j in 0..4 {
                c[k][j] = sh.bezier[3 * i + k][j] as f64;
            }
        }
        c
    }

    /// Bernstein evaluation (independent of the monomial form used by the code).
    fn bez(c: &[[f64; 4]; 4], u: f64) -> (DVec3, f64) {
        let v = 1.0 - u;
        let w = [v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u];
        let mut p = [0.0; 4];
        for k in 0..4 {
            for j in 0..4 {
                p[j] += w[k] * c[k][j];
            }
        }
        (DVec3::new(p[0], p[1], p[2]), p[3])
    }

    /// Slow f64 reference: `min_u |p - c(u)| - r(u)` by dense sampling plus golden
    /// refinement of every sampled local minimum. It is a distance bound (|F| <= the
    /// distance to the surface), which the reference ray marcher relies on.
    struct Reference {
        segs: Vec<[[f64; 4]; 4]>,
    }
    impl Reference {
        fn new(sh: &SweptSphere) -> Self {
            Reference { segs: (0..(sh.bezier.len() - 1) / 3).map(|i| ctrl(sh, i)).collect() }
        }
        fn f(&self, p: DVec3) -> f64 {
            const N: usize = 32;
            let mut best = f64::INFINITY;
            for c in &self.segs {
                let h = |u: f64| {
                    let (q, r) = bez(c, u);
                    (p - q).length() - r
                };
                let v: Vec<f64> = (0..=N).map(|k| h(k as f64 / N as f64)).collect();
                for k in 0..=N {
                    let l = if k > 0 { v[k - 1] } else { f64::INFINITY };
                    let r = if k < N { v[k + 1] } else { f64::INFINITY };
                    if v[k] <= l && v[k] <= r {
                        // golden section on [k-1, k+1] / N
                        let (mut a, mut b) = ((k as f64 - 1.0).max(0.0) / N as f64, (k as f64 + 1.0).min(N as f64) / N as f64);
                        let g = 0.5 * (5f64.sqrt() - 1.0);
                        let mut x1 = b - g * (b - a);
                        let mut x2 = a + g * (b - a);
                        let (mut f1, mut f2) = (h(x1), h(x2));
                        for _ in 0..60 {
                            if f1 < f2 {
                                b = x2;
                                x2 = x1;
                                f2 = f1;
                                x1 = b - g * (b - a);
                                f1 = h(x1);
                            } else {
                                a = x1;
                                x1 = x2;
                                f1 = f2;
                                x2 = a + g * (b - a);
                                f2 = h(x2);
                            }
                        }
                        best = best.min(f1).min(f2).min(v[k]);
                    }
                }
            }
            best
        }
        /// Crossings of `o + t d` on `[t0, t1]` (both ends outside): sphere tracing
        /// with a minimum step `hmin` (world units), then bisection.
        fn crossings(&self, o: DVec3, d: DVec3, t0: f64, t1: f64, hmin: f64) -> Vec<f64> {
            let dl = d.length();
            let mut out = vec![];
            let mut t = t0;
            let mut f = self.f(o + d * t);
            while t < t1 {
                let tn = (t + f.abs().max(hmin) / dl).min(t1);
                let fnx = self.f(o + d * tn);
                if (f <= 0.0) != (fnx <= 0.0) {
                    let (mut a, mut b) = (t, tn);
                    for _ in 0..64 {
                        let m = 0.5 * (a + b);
                        if (self.f(o + d * m) <= 0.0) == (f <= 0.0) {
                            a = m
                        } else {
                            b = m
                        }
                    }
                    out.push(0.5 * (a + b));
                }
                t = tn;
                f = fnx;
            }
            out
        }
    }

    /// Length of the symmetric difference of two span lists given as sorted
    /// boundary lists (in, out, in, out...).
    fn sym_diff(a: &[f64], b: &[f64]) -> f64 {
        let inside = |l: &[f64], t: f64| l.chunks(2).any(|c| c.len() == 2 && t >= c[0] && t <= c[1]);
        let mut pts: Vec<f64> = a.iter().chain(b.iter()).copied().collect();
        pts.sort_by(|x, y| x.total_cmp(y));
        let mut s = 0.0;
        for w in pts.windows(2) {
            let m = 0.5 * (w[0] + w[1]);
            if inside(a, m) != inside(b, m) {
                s += w[1] - w[0];
            }
        }
        s
    }

    #[derive(Default, Debug)]
    pub(crate) struct Stats {
        pub rays: usize,
        pub hits: usize,
        pub same_count: usize,
        pub max_end_err: f64,
        pub count_mismatch: usize,
        pub max_symdiff: f64,
    }

    fn compare(data: &SweptSphereData, rf: &Reference, o: Vec3, d: Vec3, size: f64, st: &mut Stats) {
        let b = data.local_bounds();
        let Some((ta, tb)) = b.ray_range(o, d.recip(), -1e30, 1e30) else {
            st.rays += 1;
            return;
        };
        let dl = d.as_dvec3().length();
        let pad = 0.01 * size / dl;
        let (t0, t1) = (ta as f64 - pad, tb as f64 + pad);
        let mut got: Vec<Span> = vec![];
        data.spans(&Ray::segment(o, d, t0 as f32, t1 as f32), 0, &mut got);
        for w in got.windows(2) {
            assert!(w[0].t1 < w[1].t0, "spans not sorted/disjoint: {got:?}");
        }
        let g: Vec<f64> = got.iter().flat_map(|s| [s.t0 as f64, s.t1 as f64]).collect();
        let r = rf.crossings(o.as_dvec3(), d.as_dvec3(), t0, t1, 2e-5 * size);
        st.rays += 1;
        if !r.is_empty() || !g.is_empty() {
            st.hits += 1;
        }
        if g.len() == r.len() {
            st.same_count += 1;
            for (x, y) in g.iter().zip(&r) {
                st.max_end_err = st.max_end_err.max((x - y).abs() * dl / size);
            }
        } else {
            st.count_mismatch += 1;
            println!("count mismatch: o={o:?} d={d:?} spans {g:?} reference {r:?}");
        }
        let sd = sym_diff(&g, &r) * dl / size;
        if sd > st.max_symdiff {
            st.max_symdiff = sd;
        }
        assert!(sd < 2e-3, "ray o={o:?} d={d:?}: spans {g:?} reference {r:?} (symdiff {sd})");
    }

    fn rand_unit(rng: &mut SmallRng) -> DVec3 {
        loop {
            let v = DVec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
            let l = v.length_squared();
            if l > 1e-4 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }

    #[test]
    fn spans_match_f64_reference() {
        let seed = 0x5eed_0001u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for (name, sh) in shapes() {
            let data = SweptSphereData::new(&sh, DEFAULT_TOLERANCE).unwrap();
            let rf = Reference::new(&sh);
            let b = data.local_bounds();
            let size = b.diagonal_length() as f64;
            let c = b.center().as_dvec3();
            let nseg = data.segment_count();
            let mut kinds = [Stats::default(), Stats::default(), Stats::default(), Stats::default()];
            let n = if name == "long" { 120 } else { 250 };
            for k in 0..n * 4 {
                let kind = k % 4;
                let scale = rng.gen_range(0.2..5.0);
                let (o, d) = match kind {
                    // random rays through the box
                    0 => {
                        let o = c + rand_unit(&mut rng) * size;
                        let tgt = b.min.as_dvec3() + (b.max - b.min).as_dvec3() * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                        (o, (tgt - o).normalize())
                    }
                    // tangent to a ball of the sweep
                    1 => {
                        let i = rng.gen_range(0..nseg);
                        let (q, r) = bez(&ctrl(&sh, i), rng.gen());
                        let v = rand_unit(&mut rng);
                        let nrm = v.any_orthonormal_vector();
                        let nrm = (nrm * rng.gen_range(-1.0..1.0) + v.cross(nrm) * rng.gen_range(-1.0..1.0)).normalize();
                        let p = q + nrm * r;
                        (p - v * size, v)
                    }
                    // along the path
                    2 => {
                        let i = rng.gen_range(0..nseg);
                        let u: f64 = rng.gen();
                        let cc = ctrl(&sh, i);
                        let (q, _) = bez(&cc, u);
                        let (q2, _) = bez(&cc, (u + 1e-4).min(1.0));
                        let (q1, _) = bez(&cc, (u - 1e-4).max(0.0));
                        let v = (q2 - q1).normalize() + rand_unit(&mut rng) * 0.05;
                        let v = v.normalize();
                        (q - v * size, v)
                    }
                    // through a random centre point (necks when the radius is tiny)
                    _ => {
                        let i = rng.gen_range(0..nseg);
                        let u = if name == "neck" { rng.gen_range(0.9..1.0) } else { rng.gen() };
                        let (q, _) = bez(&ctrl(&sh, i), u);
                        let v = rand_unit(&mut rng);
                        (q - v * size, v)
                    }
                };
                compare(&data, &rf, o.as_vec3(), (d * scale).as_vec3(), size, &mut kinds[kind]);
            }
            for (k, s) in ["random", "grazing", "along path", "through centre"].iter().zip(&kinds) {
                println!("{name:6} {k:14} {s:?}");
                assert!(s.max_end_err < 2e-5, "{name} {k}: {s:?}");
            }
        }
    }

    /// Capsule from a to b of radius r in f64: union of two balls and a cylinder.
    fn capsule(a: DVec3, b: DVec3, r: f64, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
        let ball = |c: DVec3| {
            let oc = o - c;
            let (qa, qb, qc) = (d.dot(d), oc.dot(d), oc.dot(oc) - r * r);
            let disc = qb * qb - qa * qc;
            (disc >= 0.0).then(|| ((-qb - disc.sqrt()) / qa, (-qb + disc.sqrt()) / qa))
        };
        let ax = (b - a).normalize();
        let len = (b - a).length();
        let (op, dp) = (o - a - ax * (o - a).dot(ax), d - ax * d.dot(ax));
        let cyl = {
            let (qa, qb, qc) = (dp.dot(dp), op.dot(dp), op.dot(op) - r * r);
            let disc = qb * qb - qa * qc;
            if disc >= 0.0 && qa > 0.0 {
                let (c0, c1) = ((-qb - disc.sqrt()) / qa, (-qb + disc.sqrt()) / qa);
                let (z0, dz) = ((o - a).dot(ax), d.dot(ax));
                let (s0, s1) = ((0.0 - z0) / dz, (len - z0) / dz);
                let (s0, s1) = (s0.min(s1), s0.max(s1));
                let (l, h) = (c0.max(s0), c1.min(s1));
                (l <= h).then_some((l, h))
            } else {
                None
            }
        };
        [ball(a), ball(b), cyl].into_iter().flatten().reduce(|x, y| (x.0.min(y.0), x.1.max(y.1)))
    }

    #[test]
    fn straight_constant_radius_is_a_capsule() {
        let seed = 0x5eed_0002u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut max_err = 0.0f64;
        let mut hits = 0;
        for _ in 0..20 {
            let a = rand_unit(&mut rng) * rng.gen_range(0.0..2.0);
            let b = a + rand_unit(&mut rng) * rng.gen_range(0.1..3.0);
            let r = rng.gen_range(0.01..1.0);
            let af = a.as_vec3();
            let bf = b.as_vec3();
            let pts = [af, af + (bf - af) / 3.0, af + (bf - af) * (2.0 / 3.0), bf];
            let sh = SweptSphere { bezier: pts.iter().map(|p| [p.x, p.y, p.z, r as f32]).collect() };
            let data = SweptSphereData::new(&sh, DEFAULT_TOLERANCE).unwrap();
            let size = data.local_bounds().diagonal_length() as f64;
            // exact f64 description of the f32 points
            let (a, b, r) = (af.as_dvec3(), bf.as_dvec3(), r as f32 as f64);
            for _ in 0..200 {
                let c = (a + b) * 0.5 + rand_unit(&mut rng) * rng.gen_range(0.0..size * 0.4);
                let v = rand_unit(&mut rng) * rng.gen_range(0.3..3.0);
                let o = (c - v * 3.0).as_vec3();
                let d = v.as_vec3();
                let mut got: Vec<Span> = vec![];
                data.spans(&Ray::segment(o, d, -1e9, 1e9), 0, &mut got);
                let want = capsule(a, b, r, o.as_dvec3(), d.as_dvec3());
                match want {
                    Some((t0, t1)) if (t1 - t0) * v.length() > 1e-5 * size => {
                        hits += 1;
                        assert_eq!(got.len(), 1, "{got:?} vs {want:?}");
                        let e = (got[0].t0 as f64 - t0).abs().max((got[0].t1 as f64 - t1).abs()) * v.length() / size;
                        max_err = max_err.max(e);
                    }
                    Some(_) => {}
                    None => assert!(got.is_empty(), "{got:?}"),
                }
            }
        }
        println!("capsule: {hits} hits, max span end error {max_err:e} (relative to size)");
        assert!(max_err < 2e-6);
    }

    #[test]
    fn contains_agrees_with_spans() {
        let seed = 0x5eed_0003u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut checked = 0;
        for (name, sh) in shapes() {
            let data = SweptSphereData::new(&sh, DEFAULT_TOLERANCE).unwrap();
            let b = data.local_bounds();
            let size = b.diagonal_length() as f64;
            let c = b.center().as_dvec3();
            for _ in 0..2000 {
                let o = c + rand_unit(&mut rng) * size;
                let tgt = b.min.as_dvec3() + (b.max - b.min).as_dvec3() * DVec3::new(rng.gen(), rng.gen(), rng.gen());
                let (o, d) = (o.as_vec3(), (tgt - o).as_vec3());
                let mut got: Vec<Span> = vec![];
                data.spans(&Ray::segment(o, d, 0.0, 10.0), 0, &mut got);
                for (k, s) in got.iter().enumerate() {
                    if (s.t1 - s.t0) * d.length() < 1e-4 * size as f32 {
                        continue;
                    }
                    let m = 0.5 * (s.t0 + s.t1);
                    assert!(data.contains(o + d * m), "{name}: span midpoint outside {s:?}");
                    checked += 1;
                    if let Some(n) = got.get(k + 1) {
                        if (n.t0 - s.t1) * d.length() > 1e-4 * size as f32 {
                            let m = 0.5 * (s.t1 + n.t0);
                            assert!(!data.contains(o + d * m), "{name}: gap midpoint inside");
                        }
                    }
                    // normal at the entry: unit, and pointing against the ray
                    if s.s0.is_real() {
                        let nrm = data.normal(s.s0.sub, o + d * s.t0);
                        assert!((nrm.length() - 1.0).abs() < 1e-4);
                        assert!(nrm.dot(d) <= 1e-3 * d.length(), "{name}: entry normal {nrm:?} d {d:?}");
                    }
                }
            }
        }
        println!("checked {checked} span midpoints");
    }

    #[test]
    fn validate_rejects_bad_input() {
        let ok = bench_shape();
        assert!(ok.validate().is_ok());
        let e = SweptSphere { bezier: ok.bezier[..5].to_vec() }.validate().unwrap_err();
        assert_eq!(e.field, "bezier");
        assert!(e.message.contains("length 5 is not 3n+1"), "{}", e.message);
        let mut nan = ok.clone();
        nan.bezier[2][1] = f32::NAN;
        assert!(nan.validate().is_err());
        let mut neg = ok.clone();
        neg.bezier[4][3] = -0.1;
        assert!(neg.validate().unwrap_err().message.contains("negative radius"));
        let mut zero = ok.clone();
        zero.bezier.iter_mut().for_each(|p| p[3] = 0.0);
        assert!(zero.validate().unwrap_err().message.contains("zero"));
        assert!(SweptSphereData::new(&ok, 0.0).is_err());
    }

    #[test]
    fn bounds_are_tight_and_enclosing() {
        let seed = 0x5eed_0004u64;
        println!("seed {seed}");
        for (name, sh) in shapes() {
            let data = SweptSphereData::new(&sh, DEFAULT_TOLERANCE).unwrap();
            let b = data.local_bounds();
            let mut lo = DVec3::splat(f64::INFINITY);
            let mut hi = DVec3::splat(f64::NEG_INFINITY);
            for i in 0..data.segment_count() {
                let c = ctrl(&sh, i);
                for k in 0..=2000 {
                    let (q, r) = bez(&c, k as f64 / 2000.0);
                    if c.iter().all(|p| p[3] == 0.0) {
                        continue;
                    }
                    lo = lo.min(q - DVec3::splat(r));
                    hi = hi.max(q + DVec3::splat(r));
                }
            }
            let slack = (lo - b.min.as_dvec3()).max_element().max((b.max.as_dvec3() - hi).max_element());
            println!("{name}: bounds slack {slack:e}");
            assert!(b.min.as_dvec3().cmple(lo).all() && b.max.as_dvec3().cmpge(hi).all());
            assert!(slack < 1e-5);
        }
    }

    /// Camera rays of /work/shared/scenes/sweep.json (eye (0,0,6), fov_y 50 deg):
    /// time per ray and span-end drift against tolerance 1e-12, per tolerance.
    /// `cargo test -p rothray-primitives --release sweep_bench -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn sweep_bench() {
        let sh = bench_shape();
        let (w, h) = (960usize, 540usize);
        let fov = 50f32.to_radians();
        let eye = Vec3::new(0.0, 0.0, 6.0);
        let half_h = (fov * 0.5).tan();
        let rays: Vec<Vec3> = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
                let sx = (2.0 * x / w as f32 - 1.0) * half_h * w as f32 / h as f32;
                let sy = (1.0 - 2.0 * y / h as f32) * half_h;
                Vec3::new(sx, sy, -1.0)
            })
            .collect();
        let run = |tol: f32| {
            let data = SweptSphereData::new(&sh, tol).unwrap();
            let mut out: Vec<Vec<Span>> = Vec::with_capacity(rays.len());
            let t = std::time::Instant::now();
            for d in &rays {
                let mut v = vec![];
                data.spans(&Ray::segment(eye, *d, 0.0, f32::INFINITY), 0, &mut v);
                out.push(v);
            }
            (t.elapsed().as_secs_f64() * 1e9 / rays.len() as f64, out)
        };
        let (_, exact) = run(1e-12);
        for tol in [1e-2f32, 1e-3, 1e-4, 1e-6, 1e-9] {
            // Best of 3: the machine is shared, other load only adds time.
            let (ns, got) = (0..3).map(|_| run(tol)).min_by(|x, y| x.0.total_cmp(&y.0)).unwrap();
            let mut err = 0.0f32;
            let mut hits = 0;
            for (a, b) in got.iter().zip(&exact) {
                hits += (!b.is_empty()) as usize;
                if a.len() != b.len() {
                    err = f32::INFINITY;
                    continue;
                }
                for (x, y) in a.iter().zip(b) {
                    err = err.max((x.t0 - y.t0).abs()).max((x.t1 - y.t1).abs());
                }
            }
            println!("tolerance {tol:e}: {ns:.0} ns/ray (best of 3) over {} rays ({hits} hit), max |dt| vs 1e-12: {err:e}", rays.len());
        }
    }
}
