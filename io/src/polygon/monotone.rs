//! Triangles of one y-monotone piece in linear time (de Berg et al., ch. 3.3):
//! the piece's two chains, merged top to bottom, feed a stack of vertices that
//! still need a diagonal; a vertex on the other chain sees the whole stack, a
//! vertex on the same chain cuts off the convex ones.
//!
//! Triangles are written counter-clockwise by construction from the chains,
//! not by the sign of their area, so that a triangle of zero area (vertices in
//! line along one side) still has the orientation that keeps the mesh closed.

use glam::DVec2;

use super::geom::{orient, sweep_cmp};
use super::NotSimple;

/// Which chain a vertex is on: going down the left one follows the ring.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Chain {
    Left,
    Right,
}

/// Appends the triangles of the counter-clockwise monotone ring `f` (vertex
/// indices into `p`) to `out`; `merged` is scratch space.
pub(super) fn fill_monotone(p: &[DVec2], f: &[u32], merged: &mut Vec<(u32, Chain)>, out: &mut Vec<[u32; 3]>) -> Result<(), NotSimple> {
    let m = f.len();
    if m < 3 {
        return Err(NotSimple);
    }
    if m == 3 {
        out.push([f[0], f[1], f[2]]);
        return Ok(());
    }
    let first = |a: usize, b: usize| sweep_cmp(p, f[a], f[b]).is_lt();
    let top = (0..m).fold(0, |t, k| if first(k, t) { k } else { t });
    let bot = (0..m).fold(0, |t, k| if first(t, k) { k } else { t });
    // Left chain: top, top + 1, .. (down); right chain: top - 1, top - 2, ..
    // (also down); both end before `bot`, which comes last.
    merged.clear();
    merged.push((f[top], Chain::Left));
    let (mut l, mut r) = ((top + 1) % m, (top + m - 1) % m);
    // The last vertex taken from each chain: each chain must go down, or the
    // piece is not monotone.
    let (mut last_l, mut last_r) = (top, top);
    while l != bot || r != bot {
        let take_left = r == bot || (l != bot && first(l, r));
        if take_left {
            if !first(last_l, l) {
                return Err(NotSimple);
            }
            merged.push((f[l], Chain::Left));
            last_l = l;
            l = (l + 1) % m;
        } else {
            if !first(last_r, r) {
                return Err(NotSimple);
            }
            merged.push((f[r], Chain::Right));
            last_r = r;
            r = (r + m - 1) % m;
        }
        if merged.len() >= m {
            return Err(NotSimple);
        }
    }
    merged.push((f[bot], Chain::Left));
    stack_triangles(p, merged, out);
    Ok(())
}

/// The stack sweep over the merged chains (top first, bottom last).
fn stack_triangles(p: &[DVec2], u: &[(u32, Chain)], out: &mut Vec<[u32; 3]>) {
    let at = |k: u32| p[k as usize];
    // A triangle of `v` with two stack vertices `hi` (met first) and `lo`,
    // the stack's chain not being `v`'s.
    let across = |v: u32, c: Chain, hi: u32, lo: u32| match c {
        Chain::Left => [v, lo, hi],
        Chain::Right => [v, hi, lo],
    };
    let m = u.len();
    let mut stack: Vec<(u32, Chain)> = vec![u[0], u[1]];
    for &(v, c) in &u[2..m - 1] {
        let top = stack[stack.len() - 1];
        if c != top.1 {
            for w in stack.windows(2) {
                out.push(across(v, c, w[0].0, w[1].0));
            }
            stack.clear();
            stack.push(top);
        } else {
            let mut last = top;
            stack.pop();
            while let Some(&s) = stack.last() {
                let t = match c {
                    Chain::Left => [s.0, last.0, v],
                    Chain::Right => [v, last.0, s.0],
                };
                if orient(at(t[0]), at(t[1]), at(t[2])) <= 0.0 {
                    break;
                }
                out.push(t);
                last = s;
                stack.pop();
            }
            stack.push(last);
        }
        stack.push((v, c));
    }
    // The bottom closes both chains: it sees the whole stack, as a vertex on
    // the chain the stack is not on.
    let (v, top_chain) = (u[m - 1].0, stack[stack.len() - 1].1);
    let c = if top_chain == Chain::Left { Chain::Right } else { Chain::Left };
    for w in stack.windows(2) {
        out.push(across(v, c, w[0].0, w[1].0));
    }
}
