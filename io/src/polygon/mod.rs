//! Triangulating an OBJ polygon face in O(n log n) of its size.
//!
//! tobj's own triangulation is a fan from the first vertex. That is linear to
//! build, but a fan of a big face is a spray of slivers that all meet at one
//! vertex and whose boxes all overlap, so every box query on the mesh (the BVH,
//! `check`'s self-intersection count) became quadratic: a 30 000-index face
//! took over two minutes in `rothray check`. So:
//!
//! * a convex face is split by halving (triangle `(i, mid, j)`, then each
//!   half), whose triangles nest like a balanced tree;
//! * any other face is projected onto the plane its Newell normal picks,
//!   checked to be simple there ([`simple`], a Shamos-Hoey sweep), cut into
//!   y-monotone pieces by a sweep ([`split`], de Berg et al. ch. 3), whose
//!   pieces ([`pieces`]) are triangulated in linear time ([`monotone`]);
//! * a face that crosses or touches itself in that plane has no inside to
//!   triangulate: it is halved (bounded, closed, but triangles may leave the
//!   face), and the loader warns with its line.
//!
//! Measured (release, on a 2-core machine shared with three builds): a
//! 1 000 001-vertex comb face (333 333 merge vertices) triangulates in 0.85 to
//! 1.2 s; `rothray check` of it, parsing included, takes 1.6 to 2.7 s of CPU and
//! 161 MB. The ear clipping this replaced was quadratic (a 30 000-vertex face
//! took 21 s), so faces over 512 vertices were halved across their notches.
//!
//! Not every face has a triangulation without slivers: the comb's bar, with
//! 333 333 vertices in line along its top and two corners below, can only be
//! fanned from those two corners, and every ray that meets the bar then walks
//! all of those boxes (a 320x240 render of the comb prism ran past 12 minutes,
//! where the 1 000 000-index spiral prism renders in 10.9 s). Steiner points
//! inside the face would fix that; the loader adds none.

mod geom;
mod monotone;
mod pieces;
mod simple;
mod split;
#[cfg(test)]
mod tests;

use glam::{DVec2, DVec3, Vec3};

/// How a face was triangulated.
#[derive(Debug, PartialEq, Eq)]
pub enum Method {
    /// Convex (or fewer than four vertices): halving.
    Convex,
    /// Simple but not convex: the monotone sweep.
    Swept,
    /// Not simple in its plane (it crosses or touches itself, or folds onto
    /// itself): halving, which may put triangles outside the face.
    Forced,
}

/// A face that the sweep cannot triangulate: it crosses or touches itself in
/// its plane (or, on a face that passed the simplicity test, an inconsistency
/// that should not happen and is treated the same way).
#[derive(Debug)]
struct NotSimple;

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
    let mut local = Vec::with_capacity(n - 2);
    match sweep(&p2, &mut local) {
        Ok(()) => {
            out.extend(local.iter().map(|t| t.map(|k| idx[k as usize])));
            Method::Swept
        }
        Err(NotSimple) => {
            halve(idx, out);
            Method::Forced
        }
    }
}

/// Triangles (as positions in the ring) of the counter-clockwise ring `p`, or
/// `NotSimple`. Vertices at the same point as the one before them (an index
/// repeated, or two vertices that project to one point) are set aside and get
/// a triangle of zero area each, which keeps the mesh closed around them.
fn sweep(p: &[DVec2], out: &mut Vec<[u32; 3]>) -> Result<(), NotSimple> {
    let n = p.len();
    // Start at a vertex that differs from its predecessor, so that a run of
    // repeats never wraps around the start.
    let s = (0..n).find(|&i| p[i] != p[(i + n - 1) % n]).ok_or(NotSimple)?;
    let mut keep: Vec<u32> = Vec::with_capacity(n);
    let mut repeats: Vec<[u32; 3]> = Vec::new();
    for k in 0..n {
        let i = (s + k) % n;
        match keep.last() {
            Some(&u) if p[u as usize] == p[i] => repeats.push([u, i as u32, ((i + 1) % n) as u32]),
            _ => keep.push(i as u32),
        }
    }
    let q: Vec<DVec2> = keep.iter().map(|&i| p[i as usize]).collect();
    let m = q.len();
    if m < 3 {
        return Err(NotSimple);
    }
    let mut order: Vec<u32> = (0..m as u32).collect();
    order.sort_unstable_by(|&a, &b| geom::sweep_cmp(&q, a, b));
    if !simple::is_simple(&q, &order) {
        return Err(NotSimple);
    }
    let diagonals = split::monotone_diagonals(&q, &order)?;
    drop(order);
    let start = out.len();
    let mut merged = Vec::new();
    pieces::for_each_piece(&q, &diagonals, |f| monotone::fill_monotone(&q, f, &mut merged, out))?;
    // A simple ring of m vertices has m - 2 triangles, none of them turned over.
    let tris = &mut out[start..];
    if tris.len() != m - 2 || tris.iter().any(|t| geom::orient(q[t[0] as usize], q[t[1] as usize], q[t[2] as usize]) < 0.0) {
        out.truncate(start);
        return Err(NotSimple);
    }
    for t in tris.iter_mut() {
        *t = t.map(|k| keep[k as usize]);
    }
    out.extend(repeats);
    Ok(())
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
            let depth = if base > 0.0 { geom::orient(a, b, c).abs() / base } else { (b - a).length() };
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
