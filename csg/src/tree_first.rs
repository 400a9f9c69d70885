//! The first surface of a small tree of any depth on each lane of a
//! packet, from its leaves' 8-lane solves: an object's root whose nodes
//! are all narrow and whose leaves are at most [`TREE_LEAVES`] kernel
//! leaves ([`Program::small`]), such as a box cut by a sphere minus a union
//! of cylinders.
//!
//! The argument of [`small_first`](super::small_first::small_first)
//! carries over to any depth: where every leaf boundary from `lo - 2 eps`
//! on lies more than `2 eps` from the next one and from `lo`, no `combine`
//! of the tree's evaluation (`small_node`, its full diagram) fuses, merges
//! or drops anything, so its result is the exact set operation's. Its
//! boundaries are the leaves' own, a leaf's surface flipped once for each
//! difference it is subtracted by. So a lane sweeps all the leaves'
//! boundaries in order and reads, at each, whether the set of leaves it is
//! inside is inside the tree: one bit of the tree's truth table, made once
//! per packet from the leaves' bit patterns by the tree's own operations
//! (OR, AND, AND NOT on 256 bits).
//!
//! Why: such an object was evaluated lane by lane with span lists and
//! `combine` at every node (benches/scenes/logo: `eval_node` and
//! `small_node` over 60% of its instructions flat, callgrind 480x270);
//! here a lane costs a sort of its boundaries and a sweep.

use rothray_primitives::{kernels8::Ranges8, Surf};

use super::small_first::{lane_events, sweep, SmallFirst, SmallOps};
use super::{NodeKind, Program};

/// The most leaves of a tree answered here (its truth table has
/// `2^TREE_LEAVES` bits).
pub const TREE_LEAVES: usize = 8;

/// Bit `m` of `LEAF[j]` (bit `m % 64` of word `m / 64`) is bit `j` of `m`:
/// the sets of leaves inside leaf `j`.
const LEAF: [[u64; 4]; TREE_LEAVES] = [
    [0xaaaa_aaaa_aaaa_aaaa; 4],
    [0xcccc_cccc_cccc_cccc; 4],
    [0xf0f0_f0f0_f0f0_f0f0; 4],
    [0xff00_ff00_ff00_ff00; 4],
    [0xffff_0000_ffff_0000; 4],
    [0xffff_ffff_0000_0000; 4],
    [0, u64::MAX, 0, u64::MAX],
    [0, 0, u64::MAX, u64::MAX],
];

/// A small tree's leaves (in the order of a depth-first walk), their
/// solves, and its truth table.
pub(crate) struct TreeOps {
    /// The leaves and their solves (`kind` unused).
    pub(crate) ops: SmallOps<TREE_LEAVES>,
    /// Bit `j`: leaf `j`'s surfaces are flipped in the tree's result.
    flip: u32,
    /// Bit `m`: is a point inside exactly the leaves of `m` inside the tree?
    table: [u64; 4],
}

impl TreeOps {
    /// The leaves of small tree `n` of `prog` solved by `solve`, and its
    /// truth table; `None` when a solve is not to be had or the tree has
    /// more than [`TREE_LEAVES`] leaves.
    #[inline(always)]
    pub(crate) fn gather(prog: &Program, n: usize, mut solve: impl FnMut(u32) -> Option<Ranges8>) -> Option<TreeOps> {
        let ops = SmallOps { kind: prog.kind[n], count: 0, leaf: [0; TREE_LEAVES], r: [Ranges8::default(); TREE_LEAVES], done: u32::MAX };
        let mut t = TreeOps { ops, flip: 0, table: [0; 4] };
        t.table = t.pattern(prog, n, false, &mut solve)?;
        Some(t)
    }

    /// The truth table of node `c` over the leaves met so far and its own
    /// (added to `ops`); `flip`: is `c` subtracted an odd number of times?
    fn pattern(&mut self, prog: &Program, c: usize, flip: bool, solve: &mut impl FnMut(u32) -> Option<Ranges8>) -> Option<[u64; 4]> {
        let kind = prog.kind[c];
        if kind == NodeKind::Leaf {
            let j = self.ops.count;
            if j == TREE_LEAVES {
                return None;
            }
            let leaf = prog.first[c];
            let r = solve(leaf)?;
            self.ops.leaf[j] = leaf;
            self.ops.r[j] = r;
            self.ops.done &= r.done;
            self.flip |= (flip as u32) << j;
            self.ops.count += 1;
            return Some(LEAF[j]);
        }
        let first = prog.first[c] as usize;
        let mut acc = [0u64; 4];
        for i in 0..prog.count[c] as usize {
            let sub = kind == NodeKind::Difference && i > 0;
            let p = self.pattern(prog, prog.children[first + i] as usize, flip ^ sub, solve)?;
            for w in 0..4 {
                acc[w] = match kind {
                    _ if i == 0 => p[w],
                    NodeKind::Union => acc[w] | p[w],
                    NodeKind::Intersection => acc[w] & p[w],
                    _ => acc[w] & !p[w],
                };
            }
        }
        Some(acc)
    }

    /// Is a point inside exactly the leaves `m` inside the tree?
    #[inline(always)]
    fn member(&self, m: u32) -> bool {
        self.table[(m >> 6) as usize & 3] >> (m & 63) & 1 != 0
    }

    /// Is the tree empty on the whole line of lane `k`: is no set of the
    /// leaves its line meets (whether or not they overlap) inside it?
    #[inline(always)]
    fn empty_on_line(&self, k: usize) -> bool {
        let mut t = self.table;
        for j in 0..self.ops.count {
            if self.ops.r[j].hit & (1 << k) == 0 {
                for w in 0..4 {
                    t[w] &= !LEAF[j][w];
                }
            }
        }
        t == [0; 4]
    }
}

/// Lane `k`'s first span of the tree `t` on the range starting at `lo`,
/// as [`small_first`](super::small_first::small_first) gives it for a
/// node of leaves (see the module's notes).
#[inline(always)]
pub(crate) fn tree_first(t: &TreeOps, k: usize, (lo, eps): (f32, f32)) -> SmallFirst {
    if t.empty_on_line(k) {
        return SmallFirst::Empty;
    }
    let ops = &t.ops;
    let mut ev = [(0.0f32, 0usize, false); 2 * TREE_LEAVES];
    let (n, inside) = lane_events(ops, k, lo - 2.0 * eps, &mut ev);
    let surf = |(_, j, exit): (f32, usize, bool)| {
        let r = &ops.r[j];
        let s = Surf::new(ops.leaf[j], if exit { r.s1[k] } else { r.s0[k] });
        if t.flip & (1 << j) != 0 {
            s.flip()
        } else {
            s
        }
    };
    sweep(&mut ev[..n], inside, (lo, eps), |m| t.member(m), surf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `LEAF[j]`'s bit `m` is bit `j` of `m`, for every `m` and `j`.
    #[test]
    fn leaf_patterns_hold_their_bit() {
        for (j, p) in LEAF.iter().enumerate() {
            for m in 0..256u32 {
                assert_eq!(p[(m / 64) as usize] >> (m % 64) & 1, (m >> j) as u64 & 1, "leaf {j} set {m:#b}");
            }
        }
    }
}
