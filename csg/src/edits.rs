//! The edits of a program since it was built: which rows a live bake rewrote
//! or appended. Copies of the program (the per-thread tile programs,
//! [`crate::TileProgram`]) follow it by copying those rows only
//! ([`crate::follow`]), so a sync that re-bakes k objects costs each copy
//! work in proportion to those k objects' rows, not a copy of the program.

use std::collections::VecDeque;

/// Rows of a program that one edit wrote: half-open ranges of node ids, of
/// positions in `children`, and of wide nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Edit {
    /// Node ids.
    pub nodes: [u32; 2],
    /// Positions in `children`.
    pub children: [u32; 2],
    /// Wide nodes (`wides`).
    pub wides: [u32; 2],
}

impl Edit {
    fn rows(&self) -> usize {
        let len = |r: [u32; 2]| (r[1] - r[0]) as usize;
        len(self.nodes) + len(self.children) + len(self.wides)
    }
}

/// The latest edits of a program, oldest first. Only as many are kept as
/// cover fewer rows than the program has: a copy further behind than that
/// copies the whole program, which costs no more than replaying them.
#[derive(Clone, Debug, Default)]
pub struct EditLog {
    /// Edits recorded since the program was built (its version).
    version: u64,
    /// The latest edits; the last is edit number `version`.
    kept: VecDeque<Edit>,
    /// Rows the kept edits cover.
    rows: usize,
}

impl EditLog {
    /// Edits recorded since the program was built: a copy made (or brought
    /// up to date) at version v lacks exactly the edits after v.
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Records edit `e` of a program of `size` rows (nodes, children and wide
    /// nodes); forgets the oldest edits beyond that size.
    pub fn record(&mut self, e: Edit, size: usize) {
        self.version += 1;
        self.rows += e.rows();
        self.kept.push_back(e);
        while self.rows > size {
            let Some(old) = self.kept.pop_front() else { break };
            self.rows -= old.rows();
        }
    }

    /// The edits after version `v`, oldest first, or `None` when some of them
    /// are forgotten.
    pub fn since(&self, v: u64) -> Option<impl Iterator<Item = &Edit>> {
        let behind = self.version.checked_sub(v)?;
        (behind <= self.kept.len() as u64).then(|| self.kept.iter().skip(self.kept.len() - behind as usize))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edit(n: u32) -> Edit {
        Edit { nodes: [n, n + 1], ..Edit::default() }
    }

    /// A copy at any kept version gets exactly the edits after it; one
    /// further behind (or ahead) gets none and copies everything.
    #[test]
    fn since_lists_the_edits_after_a_version_while_kept() {
        let mut log = EditLog::default();
        for n in 0..10 {
            log.record(edit(n), 4);
        }
        assert_eq!(log.version(), 10);
        let after = |v| log.since(v).map(|it| it.map(|e| e.nodes[0]).collect::<Vec<_>>());
        assert_eq!(after(10), Some(vec![]));
        assert_eq!(after(8), Some(vec![8, 9]));
        assert_eq!(after(6), Some(vec![6, 7, 8, 9]));
        assert_eq!(after(5), None, "edit 6 (rows of node 5) is forgotten");
        assert_eq!(after(11), None, "a version from another history");
    }
}
