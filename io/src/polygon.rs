//! Triangulating an OBJ polygon face in time linear in its size (ear clipping
//! only for small non-convex faces).
//!
//! tobj's own triangulation is a fan from the first vertex. That is linear to
//! build, but a fan of a big face is a spray of slivers that all meet at one
//! vertex and whose boxes all overlap, so every box query on the mesh (the BVH,
//! `check`'s self-intersection count) became quadratic: a 30 000-index face
//! took over two minutes in `rothray check`. A convex face is split instead by
//! halving (triangle `(i, mid, j)`, then each half), whose triangles nest like
//! a balanced tree; a small non-convex face is ear-clipped; a big non-convex
//! face is halved too, with a warning that the result may leave the face.

use glam::{DVec2, DVec3, Vec3};

/// Largest non-convex face that is ear-clipped; ear clipping is quadratic (or
/// worse) in the face size, so bigger ones are halved, with a warning.
pub const MAX_EAR_CLIP: usize = 512;

/// How a face was triangulated.
#[derive(Debug, PartialEq, Eq)]
pub enum Method {
    /// Convex: halving.
    Convex,
    /// Non-convex, small: ear clipping.
    EarClipped,
    /// Non-convex and larger than [`MAX_EAR_CLIP`], or no ear found: halving,
    /// which may put triangles outside the face.
    Forced,
}

/// Triangles (index triples into `idx`'s vertices) of the face `idx` over
/// `pos`, appended to `out` in the face's orientation.
pub fn triangulate(pos: &[Vec3], idx: &[u32], out: &mut Vec<[u32; 3]>) -> Method {
    let n = idx.len();
    if n < 3 {
        return Method::Convex;
    }
    if n == 3 {
        out.push([idx[0], idx[1], idx[2]]);
        return Method::Convex;
    }
    let p2 = project(pos, idx);
    if is_convex(&p2) {
        if n == 4 {
            // The diagonal tobj and most tools take, so that quads keep their shape.
            out.push([idx[0], idx[1], idx[2]]);
            out.push([idx[0], idx[2], idx[3]]);
        } else {
            halve(idx, out);
        }
        return Method::Convex;
    }
    if n <= MAX_EAR_CLIP && ear_clip(&p2, idx, out) {
        return Method::EarClipped;
    }
    halve(idx, out);
    Method::Forced
}

/// The face in 2-D, seen from the side its Newell normal points to, so that it
/// runs counter-clockwise.
fn project(pos: &[Vec3], idx: &[u32]) -> Vec<DVec2> {
    let p: Vec<DVec3> = idx.iter().map(|&k| pos.get(k as usize).copied().unwrap_or(Vec3::ZERO).as_dvec3()).collect();
    let mut nrm = DVec3::ZERO;
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        nrm += DVec3::new((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
    }
    let ax = nrm.abs();
    // Drop the dominant axis; keep the remaining two in right-handed order.
    let (u, v, s) = if ax.z >= ax.x && ax.z >= ax.y {
        (0, 1, nrm.z)
    } else if ax.x >= ax.y {
        (1, 2, nrm.x)
    } else {
        (2, 0, nrm.y)
    };
    let flip = if s < 0.0 { -1.0 } else { 1.0 };
    p.iter().map(|q| DVec2::new(q[u], q[v] * flip)).collect()
}

fn cross(o: DVec2, a: DVec2, b: DVec2) -> f64 {
    (a - o).perp_dot(b - o)
}

/// Every turn is to the left, or a dent no deeper than the rounding of the
/// coordinates (a 1 000 000-gon stored in f32 has thousands of those), and the
/// turns add up to one full turn: convex and simple, up to rounding.
fn is_convex(p: &[DVec2]) -> bool {
    let n = p.len();
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for q in p {
        lo = lo.min(*q);
        hi = hi.max(*q);
    }
    let size = (hi - lo).length();
    let mag = lo.abs().max(hi.abs()).max_element();
    let dent_tol = 1e-6 * size + 4.0 * f32::EPSILON as f64 * mag;
    let mut total = 0.0;
    for i in 0..n {
        let (a, b, c) = (p[(i + n - 1) % n], p[i], p[(i + 1) % n]);
        let (e0, e1) = (b - a, c - b);
        let turn = e0.perp_dot(e1).atan2(e0.dot(e1));
        if turn < 0.0 {
            let base = (c - a).length();
            let depth = if base > 0.0 { cross(a, b, c).abs() / base } else { (b - a).length() };
            if depth > dent_tol {
                return false;
            }
        }
        total += turn;
    }
    (total - std::f64::consts::TAU).abs() < 1e-6
}

/// Triangle `(i, mid, j)` over the chain `i..=j`, then each half: every
/// triangle uses only diagonals, so for a convex face this is a triangulation.
fn halve(idx: &[u32], out: &mut Vec<[u32; 3]>) {
    // An explicit stack: a recursion would be as deep as log2(n), which is fine,
    // but the loop is as short.
    let mut stack = vec![(0usize, idx.len() - 1)];
    while let Some((i, j)) = stack.pop() {
        if j < i + 2 {
            continue;
        }
        let m = (i + j) / 2;
        out.push([idx[i], idx[m], idx[j]]);
        stack.push((i, m));
        stack.push((m, j));
    }
}

/// Ear clipping of a counter-clockwise simple polygon; false if it finds no ear
/// (the face is not simple), leaving `out` as it was.
fn ear_clip(p: &[DVec2], idx: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
    let start = out.len();
    let mut ring: Vec<usize> = (0..p.len()).collect();
    let mut guard = 0usize;
    let mut k = 0usize;
    while ring.len() > 3 {
        let n = ring.len();
        let (ia, ib, ic) = (ring[(k + n - 1) % n], ring[k % n], ring[(k + 1) % n]);
        let (a, b, c) = (p[ia], p[ib], p[ic]);
        let is_ear = cross(a, b, c) > 0.0
            && ring.iter().all(|&q| {
                q == ia || q == ib || q == ic || {
                    let x = p[q];
                    !(cross(a, b, x) >= 0.0 && cross(b, c, x) >= 0.0 && cross(c, a, x) >= 0.0)
                }
            });
        if is_ear {
            out.push([idx[ia], idx[ib], idx[ic]]);
            ring.remove(k % n);
            guard = 0;
        } else {
            k += 1;
            guard += 1;
            if guard > n {
                out.truncate(start);
                return false;
            }
        }
    }
    out.push([idx[ring[0]], idx[ring[1]], idx[ring[2]]]);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let a = std::f32::consts::TAU * i as f32 / n as f32;
                Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect()
    }

    fn area(pos: &[Vec3], t: &[[u32; 3]]) -> f64 {
        t.iter()
            .map(|t| {
                let [a, b, c] = t.map(|k| pos[k as usize].as_dvec3());
                (b - a).cross(c - a).z * 0.5
            })
            .sum()
    }

    #[test]
    fn a_convex_face_is_halved_into_n_minus_2_triangles_of_its_area() {
        let pos = circle(1000);
        let idx: Vec<u32> = (0..1000).collect();
        let mut t = Vec::new();
        assert_eq!(triangulate(&pos, &idx, &mut t), Method::Convex);
        assert_eq!(t.len(), 998);
        let want = 0.5 * 1000.0 * (std::f64::consts::TAU / 1000.0).sin();
        assert!((area(&pos, &t) - want).abs() < 1e-4, "{} vs {want}", area(&pos, &t));
        // No triangle is a sliver from vertex 0, as a fan's would be.
        assert!(t.iter().filter(|t| t.contains(&0)).count() < 20);
    }

    /// A 1 000 000-gon in f32 has dents at the rounding level: still convex.
    #[test]
    fn a_huge_face_in_f32_is_convex_up_to_rounding() {
        let n = 1_000_000;
        let pos = circle(n);
        let idx: Vec<u32> = (0..n as u32).collect();
        let mut t = Vec::new();
        assert_eq!(triangulate(&pos, &idx, &mut t), Method::Convex);
        assert_eq!(t.len(), n - 2);
        // A real dent is not rounding.
        let mut pos = circle(500);
        pos[10] *= 0.9;
        let idx: Vec<u32> = (0..500).collect();
        assert_eq!(triangulate(&pos, &idx, &mut Vec::new()), Method::EarClipped);
    }

    #[test]
    fn a_non_convex_face_is_ear_clipped_inside_itself() {
        // An L shape, counter-clockwise.
        let pos: Vec<Vec3> =
            [[0., 0.], [2., 0.], [2., 1.], [1., 1.], [1., 2.], [0., 2.]].iter().map(|p| Vec3::new(p[0], p[1], 0.0)).collect();
        let mut t = Vec::new();
        assert_eq!(triangulate(&pos, &[0, 1, 2, 3, 4, 5], &mut t), Method::EarClipped);
        assert_eq!(t.len(), 4);
        assert!((area(&pos, &t) - 3.0).abs() < 1e-9);
        assert!(t.iter().all(|t| area(&pos, &[*t]) > 0.0), "every triangle keeps the face's orientation");
    }
}
