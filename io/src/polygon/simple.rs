//! Is a face simple? A Shamos-Hoey sweep, O(n log n): edges enter the status
//! at their upper end and leave at their lower end, and only edges that are
//! neighbours on the sweep line are tested; the first crossing (in the sweep)
//! is always between two neighbours, so it is found before the status order
//! could be spoiled by it.
//!
//! The monotone split that follows is only correct for a simple face, and a
//! face that crosses itself has no inside to triangulate: this is what turns
//! such a face into a warning instead of triangles laid across it.

use std::collections::BTreeSet;
use std::ops::Bound::{Excluded, Unbounded};

use glam::DVec2;

use super::geom::{orient, Seg};

/// True when no two edges of the ring `p` meet except consecutive edges at
/// their shared vertex, and no two vertices coincide. `order` is the vertices
/// in sweep order.
pub fn is_simple(p: &[DVec2], order: &[u32]) -> bool {
    let n = p.len();
    // Two vertices at one point (a pinch) are not simple, and are next to each
    // other in the sweep order.
    if order.windows(2).any(|w| p[w[0] as usize] == p[w[1] as usize]) {
        return false;
    }
    let mut status: BTreeSet<Seg> = BTreeSet::new();
    for &v in order {
        let v = v as usize;
        let edges = [(v + n - 1) % n, v];
        // Edges ending here leave first, then edges starting here enter.
        for &e in &edges {
            let s = Seg::edge(p, e);
            if s.bot == p[v] && s.top != s.bot {
                let before = status.range(..s).next_back().copied();
                let after = status.range((Excluded(s), Unbounded)).next().copied();
                if !status.remove(&s) {
                    return false;
                }
                if let (Some(a), Some(b)) = (before, after) {
                    if meet(p, a.id as usize, b.id as usize) {
                        return false;
                    }
                }
            }
        }
        for &e in &edges {
            let s = Seg::edge(p, e);
            if s.top == p[v] {
                status.insert(s);
                let before = status.range(..s).next_back().copied();
                let after = status.range((Excluded(s), Unbounded)).next().copied();
                for o in [before, after].into_iter().flatten() {
                    if meet(p, s.id as usize, o.id as usize) {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// Do edges `i` and `j` of the ring meet where a simple polygon's may not?
/// Consecutive edges share a vertex and may only meet there (not fold back
/// along each other); any other two must not touch at all.
fn meet(p: &[DVec2], i: usize, j: usize) -> bool {
    let n = p.len();
    let (a, b) = (p[i], p[(i + 1) % n]);
    let (c, d) = (p[j], p[(j + 1) % n]);
    if (i + 1) % n == j || (j + 1) % n == i {
        // The shared vertex and the two far ends.
        let (s, x, y) = if (i + 1) % n == j { (b, a, d) } else { (a, b, c) };
        return orient(s, x, y) == 0.0 && (x - s).dot(y - s) > 0.0;
    }
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    let opposite = |x: f64, y: f64| (x > 0.0 && y < 0.0) || (x < 0.0 && y > 0.0);
    if opposite(o1, o2) && opposite(o3, o4) {
        return true;
    }
    let on = |x: DVec2, y: DVec2, q: DVec2| q.cmpge(x.min(y)).all() && q.cmple(x.max(y)).all();
    (o1 == 0.0 && on(a, b, c)) || (o2 == 0.0 && on(a, b, d)) || (o3 == 0.0 && on(c, d, a)) || (o4 == 0.0 && on(c, d, b))
}
