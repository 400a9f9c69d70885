//! The predicates both sweeps share: the sweep order of points, the side of a
//! point against an edge, and the order of edges on the sweep line.
//!
//! The face's 2-D coordinates are f32 values (an OBJ vertex's, one axis
//! dropped, one maybe negated), so the product of two of them is exact in f64
//! and cannot overflow or underflow it. `orient` takes the plain f64 formula
//! when Shewchuk's error bound proves its sign, and otherwise sums the six
//! exact products of its expansion exactly: the sign is always exact. That is
//! what keeps the sweeps' decisions consistent, and so the status tree
//! ordered, on nearly collinear vertices.

use std::cmp::Ordering;

use glam::DVec2;

/// Twice the signed area of `(a, b, c)` (positive when `c` is left of
/// `a -> b`), with the exact sign for f32-valued coordinates; the magnitude is
/// f64's.
pub fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    let l = (b.x - a.x) * (c.y - a.y);
    let r = (b.y - a.y) * (c.x - a.x);
    let det = l - r;
    // Shewchuk's ccwerrboundA: beyond it the rounded sign is the true one.
    let bound = 3.330_669_073_875_471_6e-16 * (l.abs() + r.abs());
    if det > bound || -det > bound {
        return det;
    }
    exact_orient(a, b, c)
}

/// The sign of `orient` (as -1, 0 or 1) from its expansion
/// `bx cy - bx ay - ax cy - by cx + by ax + ay cx` (the `ax ay` terms cancel):
/// six products of f32 values, each exact in f64, summed without rounding
/// into a nonoverlapping expansion (Shewchuk's grow-expansion), whose largest
/// nonzero component has the sum's sign.
fn exact_orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    let terms = [b.x * c.y, -(b.x * a.y), -(a.x * c.y), -(b.y * c.x), b.y * a.x, a.y * c.x];
    let mut e = [0.0f64; 6];
    let mut len = 0;
    for t in terms {
        let mut q = t;
        let mut k = 0;
        for i in 0..len {
            let (s, h) = two_sum(q, e[i]);
            if h != 0.0 {
                e[k] = h;
                k += 1;
            }
            q = s;
        }
        e[k] = q;
        len = k + 1;
    }
    e[..len].iter().rev().find(|&&x| x != 0.0).map_or(0.0, |x| x.signum())
}

/// `a + b` as the rounded sum and its exact error (Knuth).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Does `a` come after `b` in the sweep (top to bottom; on a tie in y, left to
/// right)? The tie rule tilts the sweep line infinitesimally, so no two
/// distinct points are level and horizontal edges need no special case.
pub fn below(a: DVec2, b: DVec2) -> bool {
    a.y < b.y || (a.y == b.y && a.x > b.x)
}

/// The sweep order of vertices `i` and `j` of `p` (`Less`: `i` is met first);
/// equal points go by index, so the order is total.
pub fn sweep_cmp(p: &[DVec2], i: u32, j: u32) -> Ordering {
    let (a, b) = (p[i as usize], p[j as usize]);
    b.y.total_cmp(&a.y).then(a.x.total_cmp(&b.x)).then(i.cmp(&j))
}

/// An edge on the sweep line: its upper and lower end (in the sweep order) and
/// its index in the face (edge `i` runs from vertex `i` to vertex `i + 1`).
/// Ordered left to right where the two edges are both cut by the sweep line,
/// which is the only place the sweeps compare them.
#[derive(Clone, Copy, Debug)]
pub struct Seg {
    /// Upper end.
    pub top: DVec2,
    /// Lower end.
    pub bot: DVec2,
    /// Edge index; `u32::MAX` for a probe point.
    pub id: u32,
}

impl Seg {
    /// Edge `i` of `p` (from vertex `i` to vertex `i + 1`).
    pub fn edge(p: &[DVec2], i: usize) -> Seg {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        let (top, bot) = if below(b, a) { (a, b) } else { (b, a) };
        Seg { top, bot, id: i as u32 }
    }

    /// A point as a degenerate edge that sorts after every edge through it:
    /// `range(..probe).next_back()` is the edge directly left of the point.
    pub fn probe(q: DVec2) -> Seg {
        Seg { top: q, bot: q, id: u32::MAX }
    }
}

/// Where `s` is against the line of `t`, when `s`'s upper end is within `t`'s
/// span of the sweep: `Greater` is to the right. On the line, `s`'s lower end
/// decides (two edges leaving one vertex), then the index.
fn side(t: &Seg, s: &Seg) -> Ordering {
    let o = orient(t.top, t.bot, s.top);
    let o = if o == 0.0 { orient(t.top, t.bot, s.bot) } else { o };
    // Walking down `t`, its left hand points to +x: left of it is right.
    if o > 0.0 {
        Ordering::Greater
    } else if o < 0.0 {
        Ordering::Less
    } else {
        s.id.cmp(&t.id)
    }
}

impl Ord for Seg {
    fn cmp(&self, o: &Seg) -> Ordering {
        if self.id == o.id {
            return Ordering::Equal;
        }
        // Test the end that the sweep met later against the other edge's line:
        // it lies within that edge's span, so the side is the order.
        if below(o.top, self.top) {
            side(self, o).reverse()
        } else {
            side(o, self)
        }
    }
}

impl PartialOrd for Seg {
    fn partial_cmp(&self, o: &Seg) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl PartialEq for Seg {
    fn eq(&self, o: &Seg) -> bool {
        self.id == o.id
    }
}

impl Eq for Seg {}
