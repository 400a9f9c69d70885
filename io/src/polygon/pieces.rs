//! The pieces a set of non-crossing diagonals cuts a simple face into, each as
//! a counter-clockwise vertex ring, in time linear in the face plus a sort of
//! the diagonals around each vertex.
//!
//! Around each vertex `v` the neighbours are kept in counter-clockwise order
//! from the next vertex of the face to the previous one (every diagonal lies in
//! between, inside the face). Walking a piece with its inside on the left,
//! arriving at `v` from `u`, the walk leaves along the neighbour just before
//! `u` in that order: the sharpest left turn that stays in the piece.

use glam::DVec2;

use super::geom::orient;
use super::NotSimple;

/// Calls `piece` with each piece of the ring `p` cut by `diagonals`.
pub fn for_each_piece(
    p: &[DVec2],
    diagonals: &[[u32; 2]],
    mut piece: impl FnMut(&[u32]) -> Result<(), NotSimple>,
) -> Result<(), NotSimple> {
    let n = p.len();
    // Vertex v's neighbours are ring[off[v]..off[v + 1]]: next, the diagonals'
    // far ends counter-clockwise, previous.
    let mut off = vec![0u32; n + 1];
    for d in diagonals {
        for &v in d {
            off[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        off[v + 1] += off[v] + 2;
    }
    let total = off[n] as usize;
    let mut ring = vec![0u32; total];
    // Diagonal half-edges, each (far end, index of its twin), per vertex.
    let mut fill: Vec<u32> = (0..n).map(|v| off[v] + 1).collect();
    let mut twin = vec![u32::MAX; total];
    for d in diagonals {
        let [a, b] = [d[0] as usize, d[1] as usize];
        let (sa, sb) = (fill[a], fill[b]);
        fill[a] += 1;
        fill[b] += 1;
        ring[sa as usize] = b as u32;
        ring[sb as usize] = a as u32;
        twin[sa as usize] = sb;
        twin[sb as usize] = sa;
    }
    for v in 0..n {
        let (s, e) = (off[v] as usize, off[v + 1] as usize);
        ring[s] = ((v + 1) % n) as u32;
        ring[e - 1] = ((v + n - 1) % n) as u32;
        if e - s > 3 {
            sort_around(p, v, &mut ring, &mut twin, s, e);
        }
    }
    // `twin` for the face's own edges: v -> next arrives at next's last slot.
    for v in 0..n {
        let (s, e) = (off[v] as usize, off[v + 1] as usize);
        let nx = (v + 1) % n;
        twin[s] = off[nx + 1] - 1;
        twin[e - 1] = off[(v + n - 1) % n];
    }
    // Walk every outgoing half-edge once (the last slot of each vertex, v ->
    // previous, runs outside the face).
    let mut seen = vec![false; total];
    let mut buf: Vec<u32> = Vec::new();
    for v in 0..n {
        for start in off[v] as usize..off[v + 1] as usize - 1 {
            if seen[start] {
                continue;
            }
            buf.clear();
            let mut slot = start;
            let mut at = v as u32;
            loop {
                if seen[slot] || buf.len() >= total {
                    return Err(NotSimple);
                }
                seen[slot] = true;
                buf.push(at);
                at = ring[slot];
                // The slot of `u` in `at`'s ring, then the one before it.
                slot = twin[slot] as usize;
                if slot == off[at as usize] as usize {
                    return Err(NotSimple);
                }
                slot -= 1;
                if slot == start {
                    break;
                }
            }
            piece(&buf)?;
        }
    }
    Ok(())
}

/// Sorts the diagonal slots `s + 1 .. e - 1` of vertex `v` counter-clockwise
/// from the direction to the next vertex, carrying their twins' links along.
fn sort_around(p: &[DVec2], v: usize, ring: &mut [u32], twin: &mut [u32], s: usize, e: usize) {
    let (o, nx) = (p[v], p[ring[s] as usize]);
    // Half-turns from the direction to the next vertex: 0 for [0, pi), 1 for
    // [pi, 2 pi); then by the exact sign of the turn between the two.
    let half = |w: u32| -> u8 {
        let q = p[w as usize];
        let c = orient(o, nx, q);
        u8::from(!(c > 0.0 || (c == 0.0 && (nx - o).dot(q - o) > 0.0)))
    };
    let mut items: Vec<(u32, u32)> = (s + 1..e - 1).map(|k| (ring[k], twin[k])).collect();
    items.sort_by(|&(a, _), &(b, _)| {
        half(a).cmp(&half(b)).then_with(|| {
            let c = orient(o, p[a as usize], p[b as usize]);
            if c > 0.0 {
                std::cmp::Ordering::Less
            } else if c < 0.0 {
                std::cmp::Ordering::Greater
            } else {
                std::cmp::Ordering::Equal
            }
        })
    });
    for (k, (w, t)) in items.into_iter().enumerate() {
        ring[s + 1 + k] = w;
        twin[s + 1 + k] = t;
        twin[t as usize] = (s + 1 + k) as u32;
    }
}
