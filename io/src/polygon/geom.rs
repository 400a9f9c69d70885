//! The predicates both sweeps share: the sweep order of points, the side of a
//! point against an edge, and the order of edges on the sweep line.
//!
//! The face's 2-D coordinates are f32 values (an OBJ vertex's, one axis
//! dropped, one maybe negated), and `orient` works in f64; products of f32
//! differences cannot overflow or underflow it. Where the coordinates are
//! integers below 2^24 times one power of two (grids, the comb tests), the
//! differences are exact and each product of two fits in 53 bits, so the sign
//! is exact and the sweeps' decisions are consistent, which is what keeps the
//! status tree ordered. Other faces get f64's ~1e-16 relative accuracy: only a
//! nearly collinear triple can be judged the wrong way (an adaptive exact
//! predicate, as Shewchuk's, would close this). Then the checks after the
//! sweep (n - 2 triangles, none turned over) send the face to halving with a
//! warning, and a misordered `BTreeMap` gives wrong answers, not undefined
//! behaviour.

use std::cmp::Ordering;

use glam::DVec2;

/// Twice the signed area of `(a, b, c)`: positive when `c` is left of `a -> b`.
pub fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
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
