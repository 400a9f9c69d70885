//! The region a bundle of rays sweeps, with conservative tests against boxes
//! and half-spaces: a pyramid from one apex (a tile of camera rays), or a box
//! of origins swept along one direction (the shadow rays of a tile's hits
//! towards a directional light). Tiles use it to find the objects, leaves and
//! wide-node children their rays can meet (see the engine's `tile` module).

use glam::Vec3;

use crate::{aabb::Aabb, polytope::Plane};

/// A region of rays: see [`Frustum::pyramid`] and [`Frustum::sweep`].
#[derive(Clone, Copy, Debug)]
pub struct Frustum(Region);

#[derive(Clone, Copy, Debug)]
enum Region {
    /// Every ray `apex + t d`, `t >= 0`, with `d` in the cone spanned by four
    /// edge directions (given in order around the cone).
    Pyramid {
        apex: Vec3,
        edges: [Vec3; 4],
        /// Inward normals of the side planes through the apex, then of the
        /// plane through the apex facing the cone (without it a box behind
        /// the apex passes each side plane with its own corner); zero when not
        /// usable.
        planes: [Vec3; 5],
    },
    /// Every ray `p + t dir`, `t >= 0`, from a point `p` of the box `[lo, hi]`.
    Sweep { lo: Vec3, hi: Vec3, dir: Vec3, grow: SweepGrowth },
}

/// What a sweep's box tests share, made once with the sweep (per test, its
/// three divisions and the slack were most of a light's region query for
/// a tile, the boxes of its objects' tree: 4% of benches/scenes/capsules lit).
#[derive(Clone, Copy, Debug)]
struct SweepGrowth {
    /// The origins' box centre and half extent.
    c: Vec3,
    h: Vec3,
    /// How much more each box grows (relative slack on the ray's rounding).
    slack: Vec3,
    /// `1 / dir`.
    inv: Vec3,
}

/// Up to four boxes as the rows [`Frustum::touches_slots`] tests (min x,
/// max x, min y, max y, min z, max z); the slots past the boxes given are
/// empty (min above max).
pub fn slot_rows(boxes: impl IntoIterator<Item = Aabb>) -> [[f32; 4]; 6] {
    let (lo, hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    let mut r = [lo, hi, lo, hi, lo, hi];
    for (j, b) in boxes.into_iter().enumerate().take(4) {
        for a in 0..3 {
            r[2 * a][j] = b.min[a];
            r[2 * a + 1][j] = b.max[a];
        }
    }
    r
}

impl Frustum {
    /// The pyramid from `apex` spanned by `edges` (in order around it, either
    /// way round).
    pub fn pyramid(apex: Vec3, edges: [Vec3; 4]) -> Frustum {
        let mid = edges.iter().fold(Vec3::ZERO, |a, e| a + e.normalize_or_zero());
        let mut planes = [Vec3::ZERO; 5];
        for i in 0..4 {
            let n = edges[i].cross(edges[(i + 1) % 4]).normalize_or_zero();
            planes[i] = if n.dot(mid) < 0.0 { -n } else { n };
        }
        // The front plane only when every edge lies in front of it.
        let f = mid.normalize_or_zero();
        if edges.iter().all(|e| e.dot(f) > 0.0) {
            planes[4] = f;
        }
        Frustum(Region::Pyramid { apex, edges, planes })
    }

    /// The rays from every point of the box `origins` along `dir` (the shadow
    /// rays of a bundle of hits towards a directional light).
    pub fn sweep(origins: &Aabb, dir: Vec3) -> Frustum {
        let (lo, hi) = (origins.min, origins.max);
        let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
        let slack = 1e-6 * (1.0 + c.abs().max_element() + h.max_element()) + h * 1e-6;
        Frustum(Region::Sweep { lo, hi, dir, grow: SweepGrowth { c, h, slack, inv: dir.recip() } })
    }

    /// The box holding every ray's origin: the pyramid's apex, or the
    /// sweep's box of origins.
    pub fn origins(&self) -> Aabb {
        match &self.0 {
            Region::Pyramid { apex, .. } => Aabb::new(*apex, *apex),
            Region::Sweep { lo, hi, .. } => Aabb::new(*lo, *hi),
        }
    }

    /// The plane in which each ray of the region is one point (see
    /// [`crate::ray_plane`]).
    pub fn ray_plane(&self) -> Option<crate::ray_plane::RayPlane> {
        use crate::ray_plane::RayPlane;
        match &self.0 {
            Region::Pyramid { apex, edges, .. } => {
                let mid = edges.iter().fold(Vec3::ZERO, |a, e| a + e.normalize_or_zero());
                // Every ray of the region must lie in front of the plane's eye.
                edges.iter().all(|e| e.dot(mid) > 0.0).then(|| RayPlane::perspective(*apex, mid)).flatten()
            }
            Region::Sweep { lo, hi, dir, .. } => RayPlane::orthographic(*dir, (*lo + *hi) * 0.5, (*hi - *lo).length() * 0.5),
        }
    }

    /// Can a ray of the region touch the box? Conservative, with a small
    /// relative slack; infinite sides are fine.
    #[inline]
    pub fn touches_box(&self, b: &Aabb) -> bool {
        if b.is_empty() {
            return false;
        }
        match &self.0 {
            Region::Pyramid { apex, planes, .. } => {
                for &n in planes {
                    // The box corner farthest along n.
                    let p = Vec3::select(n.cmpge(Vec3::ZERO), b.max, b.min) - *apex;
                    // 0 * inf is NaN on an infinite side: the comparison is
                    // false and the plane does not cull, as it must not.
                    let v = n.dot(p);
                    if v < -1e-6 * (1.0 + p.abs().max_element()) {
                        return false;
                    }
                }
                true
            }
            Region::Sweep { grow, .. } => {
                // The box grown by the origins' half extent, against the ray
                // from their centre (Minkowski sum), grown a little more.
                let SweepGrowth { c, h, slack, inv } = *grow;
                let g = Aabb::new(b.min - h - slack, b.max + h + slack);
                g.ray_range(c, inv, 0.0, f32::INFINITY).is_some()
            }
        }
    }

    /// [`Frustum::touches_box`] for the four slot boxes of a 4-wide node
    /// (`rows` SoA as [`crate::mesh`]'s nodes keep them; empty slots have
    /// min > max): bit `s` set when slot `s` may be touched. A pyramid tests
    /// the four at once (the same operations per slot); a region query of
    /// a tile tests hundreds of boxes.
    #[inline]
    pub fn touches_slots(&self, rows: &[[f32; 4]; 6]) -> u32 {
        use glam::Vec4;
        let lo = [Vec4::from_array(rows[0]), Vec4::from_array(rows[2]), Vec4::from_array(rows[4])];
        let hi = [Vec4::from_array(rows[1]), Vec4::from_array(rows[3]), Vec4::from_array(rows[5])];
        let full = (lo[0].cmple(hi[0]) & lo[1].cmple(hi[1]) & lo[2].cmple(hi[2])).bitmask();
        match &self.0 {
            Region::Pyramid { apex, planes, .. } => {
                let mut keep = full;
                for &n in planes {
                    if n == Vec3::ZERO {
                        continue; // (0 . p is 0, never below the slack)
                    }
                    let pick = |a: usize| if n[a] >= 0.0 { hi[a] } else { lo[a] } - Vec4::splat(apex[a]);
                    let (px, py, pz) = (pick(0), pick(1), pick(2));
                    let v = px * n.x + py * n.y + pz * n.z;
                    let m = px.abs().max(py.abs()).max(pz.abs());
                    // As `touches_box`: a NaN (0 * inf) compares false and
                    // does not cull.
                    keep &= !v.cmplt((m + Vec4::ONE) * -1e-6).bitmask();
                }
                keep
            }
            Region::Sweep { grow, .. } => {
                // As `touches_box`: the boxes grown by the origins' half
                // extent and the slack, against the ray from their centre
                // (`Aabb::ray_range`'s operations per slot).
                let SweepGrowth { c, h, slack, inv } = *grow;
                let (mut t0, mut t1) = (Vec4::ZERO, Vec4::INFINITY);
                for a in 0..3 {
                    let g0 = lo[a] - Vec4::splat(h[a]) - Vec4::splat(slack[a]);
                    let g1 = hi[a] + Vec4::splat(h[a]) + Vec4::splat(slack[a]);
                    let e1 = (g0 - Vec4::splat(c[a])) * inv[a];
                    let e2 = (g1 - Vec4::splat(c[a])) * inv[a];
                    let nan = e1.cmpne(e1) | e2.cmpne(e2);
                    t0 = Vec4::select(nan, Vec4::NEG_INFINITY, e1.min(e2)).max(t0);
                    t1 = Vec4::select(nan, Vec4::INFINITY, e1.max(e2)).min(t1);
                }
                full & t0.cmple(t1).bitmask()
            }
        }
    }

    /// Can a ray of the region reach the half-space `dot(n, p) <= d`? Exact up
    /// to a small slack: yes when a ray starts inside, or heads towards the
    /// plane (then it goes arbitrarily deep into it).
    #[inline]
    pub fn touches_plane(&self, p: &Plane) -> bool {
        let n = p.n.as_vec3();
        let near = |q: Vec3| (n.dot(q) as f64) <= p.d + 1e-6 * (1.0 + p.d.abs() + q.abs().max_element() as f64);
        match &self.0 {
            Region::Pyramid { apex, edges, .. } => near(*apex) || edges.iter().any(|e| n.dot(*e) < 0.0),
            // The box corner lowest along n.
            Region::Sweep { lo, hi, dir, .. } => near(Vec3::select(n.cmpge(Vec3::ZERO), *lo, *hi)) || n.dot(*dir) < 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// No point on a ray of the pyramid lies in a box (or half-space) that the
    /// pyramid is said to miss: 200 000 random points against random boxes.
    #[test]
    fn culled_regions_hold_no_point_of_the_pyramid() {
        let seed = 11u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let v = |r: &mut SmallRng, s: f32| Vec3::new(r.gen_range(-s..s), r.gen_range(-s..s), r.gen_range(-s..s));
        let mut culled = 0;
        for _ in 0..2000 {
            let apex = v(&mut rng, 3.0);
            let c = v(&mut rng, 1.0).normalize_or(Vec3::Z);
            let (u, w) = c.any_orthonormal_pair();
            let (a, b) = (rng.gen_range(0.01..0.5), rng.gen_range(0.01..0.5));
            let edges = [c + u * a + w * b, c - u * a + w * b, c - u * a - w * b, c + u * a - w * b];
            let f = Frustum::pyramid(apex, edges);
            let ctr = v(&mut rng, 5.0);
            let h = Vec3::new(rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0));
            let bx = Aabb::new(ctr - h, ctr + h);
            let pl = Plane::new(v(&mut rng, 1.0).as_dvec3(), rng.gen_range(-3.0..3.0)).unwrap();
            let (tb, tp) = (f.touches_box(&bx), f.touches_plane(&pl));
            culled += (!tb) as u32 + (!tp) as u32;
            for _ in 0..100 {
                let (s, t) = (rng.gen_range(0.0..1.0f32), rng.gen_range(0.0..1.0f32));
                let d = (edges[0] * (1.0 - s) + edges[1] * s) * (1.0 - t) + (edges[3] * (1.0 - s) + edges[2] * s) * t;
                let p = apex + d * rng.gen_range(0.0..20.0);
                assert!(tb || !bx.contains(p), "box {bx:?} culled but holds {p}");
                assert!(tp || pl.n.dot(p.as_dvec3()) > pl.d, "plane {pl:?} culled but holds {p}");
            }
        }
        println!("{culled} of 4000 regions culled");
        assert!(culled > 1000, "the tests cull too little to mean anything: {culled}");
    }

    /// The same for sweeps: no point `p + t dir` (p in the origin box) lies in
    /// a box or half-space that the sweep is said to miss.
    #[test]
    fn culled_regions_hold_no_point_of_the_sweep() {
        let seed = 12u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let v = |r: &mut SmallRng, s: f32| Vec3::new(r.gen_range(-s..s), r.gen_range(-s..s), r.gen_range(-s..s));
        let mut culled = 0;
        for _ in 0..2000 {
            let c = v(&mut rng, 3.0);
            let h = Vec3::new(rng.gen_range(0.0..0.5), rng.gen_range(0.0..0.5), rng.gen_range(0.0..0.5));
            let org = Aabb::new(c - h, c + h);
            let dir = v(&mut rng, 1.0).normalize_or(Vec3::Y);
            let f = Frustum::sweep(&org, dir);
            let ctr = v(&mut rng, 5.0);
            let hb = Vec3::new(rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0), rng.gen_range(0.01..1.0));
            let bx = Aabb::new(ctr - hb, ctr + hb);
            let pl = Plane::new(v(&mut rng, 1.0).as_dvec3(), rng.gen_range(-3.0..3.0)).unwrap();
            let (tb, tp) = (f.touches_box(&bx), f.touches_plane(&pl));
            culled += (!tb) as u32 + (!tp) as u32;
            for _ in 0..100 {
                let o = c + (v(&mut rng, 1.0)) * h;
                let p = o + dir * rng.gen_range(0.0..20.0);
                assert!(tb || !bx.contains(p), "box {bx:?} culled but holds {p}");
                assert!(tp || pl.n.dot(p.as_dvec3()) > pl.d, "plane {pl:?} culled but holds {p}");
            }
        }
        println!("{culled} of 4000 regions culled");
        assert!(culled > 1000, "the tests cull too little to mean anything: {culled}");
    }

    /// `touches_slots` is `touches_box` slot by slot, for pyramids and
    /// sweeps (axis-aligned directions and origin boxes of no extent
    /// included), with empty slots never touched.
    #[test]
    fn slots_are_tested_as_boxes() {
        let seed = 13u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let v = |r: &mut SmallRng, s: f32| Vec3::new(r.gen_range(-s..s), r.gen_range(-s..s), r.gen_range(-s..s));
        let mut touched = 0;
        for i in 0..20_000 {
            let f = if i % 2 == 0 {
                let c = v(&mut rng, 1.0).normalize_or(Vec3::Z);
                let (u, w) = c.any_orthonormal_pair();
                let (a, b) = (rng.gen_range(0.01..0.5), rng.gen_range(0.01..0.5));
                Frustum::pyramid(v(&mut rng, 3.0), [c + u * a + w * b, c - u * a + w * b, c - u * a - w * b, c + u * a - w * b])
            } else {
                let c = v(&mut rng, 3.0);
                let h = if i % 6 == 1 {
                    Vec3::ZERO
                } else {
                    Vec3::new(rng.gen_range(0.0..0.5), rng.gen_range(0.0..0.5), rng.gen_range(0.0..0.5))
                };
                let mut dir = v(&mut rng, 1.0).normalize_or(Vec3::Y);
                if i % 10 == 3 {
                    dir = Vec3::X;
                }
                Frustum::sweep(&Aabb::new(c - h, c + h), dir)
            };
            let mut rows = [
                [f32::INFINITY; 4],
                [f32::NEG_INFINITY; 4],
                [f32::INFINITY; 4],
                [f32::NEG_INFINITY; 4],
                [f32::INFINITY; 4],
                [f32::NEG_INFINITY; 4],
            ];
            let mut boxes = [None; 4];
            for (s, slot) in boxes.iter_mut().enumerate() {
                if rng.gen_bool(0.8) {
                    let ctr = v(&mut rng, 5.0);
                    let hb = Vec3::new(rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0), rng.gen_range(0.0..1.0));
                    let b = Aabb::new(ctr - hb, ctr + hb);
                    for a in 0..3 {
                        rows[2 * a][s] = b.min[a];
                        rows[2 * a + 1][s] = b.max[a];
                    }
                    *slot = Some(b);
                }
            }
            let m = f.touches_slots(&rows);
            for (s, b) in boxes.iter().enumerate() {
                let want = b.is_some_and(|b| f.touches_box(&b));
                assert_eq!(m & (1 << s) != 0, want, "case {i} slot {s}: {f:?} {b:?}");
                touched += want as u32;
            }
        }
        println!("{touched} of about 64 000 slots touched");
        assert!(touched > 1_000 && touched < 60_000, "too one-sided to mean anything: {touched}");
    }
}
