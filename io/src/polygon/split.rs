//! The diagonals that cut a simple face into y-monotone pieces: the sweep of
//! de Berg et al., *Computational Geometry*, ch. 3, O(n log n).
//!
//! Going down the face, a vertex whose two neighbours are both below it and
//! whose inner angle is reflex (a "split" vertex) opens a notch, and one whose
//! neighbours are both above (a "merge" vertex) closes one; each gets a
//! diagonal to the last vertex seen between the same two edges (that edge's
//! "helper"). The status holds the edges with the face's inside to their right,
//! ordered along the sweep line, each with its helper.

use std::collections::BTreeMap;

use glam::DVec2;

use super::geom::{below, orient, Seg};
use super::NotSimple;

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Start,
    End,
    Split,
    Merge,
    /// On the face's left side going down (inside to the right).
    LeftRegular,
    /// On its right side.
    RightRegular,
}

/// How the sweep treats vertex `i` of the counter-clockwise ring `p`.
fn kind(p: &[DVec2], i: usize) -> Result<Kind, NotSimple> {
    let n = p.len();
    let (a, v, b) = (p[(i + n - 1) % n], p[i], p[(i + 1) % n]);
    let turn = orient(a, v, b);
    Ok(match (below(a, v), below(b, v)) {
        (true, true) if turn > 0.0 => Kind::Start,
        (true, true) if turn < 0.0 => Kind::Split,
        (false, false) if turn > 0.0 => Kind::End,
        (false, false) if turn < 0.0 => Kind::Merge,
        // Both neighbours on one side and in line: the edges fold onto each
        // other (the simplicity test rejects this first).
        (true, true) | (false, false) => return Err(NotSimple),
        (false, true) => Kind::LeftRegular,
        (true, false) => Kind::RightRegular,
    })
}

/// The diagonals (vertex pairs) that split the simple counter-clockwise ring
/// `p` into y-monotone pieces; `order` is its vertices in sweep order.
pub fn monotone_diagonals(p: &[DVec2], order: &[u32]) -> Result<Vec<[u32; 2]>, NotSimple> {
    let n = p.len();
    let kinds: Vec<Kind> = (0..n).map(|i| kind(p, i)).collect::<Result<_, _>>()?;
    let mut status: BTreeMap<Seg, u32> = BTreeMap::new();
    let mut diagonals = Vec::new();
    // Edge `i - 1` ends at `v`: leave the status, joining `v` to a merge helper.
    let close = |status: &mut BTreeMap<Seg, u32>, diagonals: &mut Vec<[u32; 2]>, v: usize| -> Result<(), NotSimple> {
        let e = (v + n - 1) % n;
        let helper = status.remove(&Seg::edge(p, e)).ok_or(NotSimple)?;
        if kinds[helper as usize] == Kind::Merge {
            diagonals.push([v as u32, helper]);
        }
        Ok(())
    };
    // The edge directly left of `v` takes `v` as its helper, joining a merge
    // helper to `v`; `force` joins any helper (a split vertex).
    let left = |status: &mut BTreeMap<Seg, u32>, diagonals: &mut Vec<[u32; 2]>, v: usize, force: bool| -> Result<(), NotSimple> {
        let (_, helper) = status.range_mut(..Seg::probe(p[v])).next_back().ok_or(NotSimple)?;
        if force || kinds[*helper as usize] == Kind::Merge {
            diagonals.push([v as u32, *helper]);
        }
        *helper = v as u32;
        Ok(())
    };
    for &v in order {
        let v = v as usize;
        match kinds[v] {
            Kind::Start => {
                status.insert(Seg::edge(p, v), v as u32);
            }
            Kind::End => close(&mut status, &mut diagonals, v)?,
            Kind::Split => {
                left(&mut status, &mut diagonals, v, true)?;
                status.insert(Seg::edge(p, v), v as u32);
            }
            Kind::Merge => {
                close(&mut status, &mut diagonals, v)?;
                left(&mut status, &mut diagonals, v, false)?;
            }
            Kind::LeftRegular => {
                close(&mut status, &mut diagonals, v)?;
                status.insert(Seg::edge(p, v), v as u32);
            }
            Kind::RightRegular => left(&mut status, &mut diagonals, v, false)?,
        }
    }
    Ok(diagonals)
}
