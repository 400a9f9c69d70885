//! A copy of a program that follows it: the per-thread base of a tile program
//! ([`crate::TileProgram`]), whose own nodes go after the copied rows. When
//! the program was edited in place (a live sync re-baked some objects, see
//! [`crate::EditLog`]), the copy takes the rows of those edits only; a copy of
//! another program, or too far behind, copies it whole (reusing its memory).

use crate::edits::Edit;
use crate::program::Program;

/// Where a copy stands: the program version it holds and that program's
/// row counts (rows past them are a tile's own).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Follower {
    version: u64,
    nodes: usize,
    children: usize,
}

/// What following a program cost (for tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FollowCounts {
    /// Whole copies.
    pub copies: u64,
    /// Edits replayed.
    pub edits: u64,
}

impl Follower {
    /// Makes `copy` hold exactly the rows of `base` (and none of its own).
    pub(crate) fn follow(&mut self, copy: &mut Program, base: &Program, counts: &mut FollowCounts) {
        // (The tile's own rows are written next: new contents.)
        copy.serial = crate::program::fresh_serial();
        let same = copy.id == base.id && base.id != 0;
        if same && self.version == base.edits.version() {
            self.truncate(copy);
            return;
        }
        match base.edits.since(self.version).filter(|_| same) {
            Some(edits) => {
                self.truncate(copy);
                for e in edits {
                    counts.edits += 1;
                    copy_rows(copy, base, e);
                }
                append_rows(copy, base);
            }
            None => {
                counts.copies += 1;
                copy_all(copy, base);
            }
        }
        *self = Follower { version: base.edits.version(), nodes: base.kind.len(), children: base.children.len() };
    }

    /// Drops the rows past the copied program's.
    fn truncate(&self, p: &mut Program) {
        let n = self.nodes;
        p.kind.truncate(n);
        p.first.truncate(n);
        p.count.truncate(n);
        p.wide.truncate(n);
        p.bounds.truncate(n);
        p.leafy.truncate(n);
        p.small.truncate(n);
        p.children.truncate(self.children);
        p.local_len = 0;
        p.lists_len = 0;
        p.narrowed_unions.clear();
    }
}

/// `dst[r]` from `src[r]`, within `dst`'s length (rows past it are appended
/// by [`append_rows`]).
fn put<T: Clone>(dst: &mut [T], src: &[T], r: [u32; 2]) {
    let (a, b) = (r[0] as usize, (r[1] as usize).min(dst.len()));
    if a < b {
        dst[a..b].clone_from_slice(&src[a..b]);
    }
}

/// Copies the rows of edit `e` from `base`.
fn copy_rows(copy: &mut Program, base: &Program, e: &Edit) {
    put(&mut copy.kind, &base.kind, e.nodes);
    put(&mut copy.first, &base.first, e.nodes);
    put(&mut copy.count, &base.count, e.nodes);
    put(&mut copy.wide, &base.wide, e.nodes);
    put(&mut copy.bounds, &base.bounds, e.nodes);
    put(&mut copy.leafy, &base.leafy, e.nodes);
    put(&mut copy.small, &base.small, e.nodes);
    put(&mut copy.children, &base.children, e.children);
    put(&mut copy.wides, &base.wides, e.wides);
}

/// Appends the rows `base` has past `copy`'s (the program grows at its end).
fn append_rows(copy: &mut Program, base: &Program) {
    fn tail<T: Clone>(dst: &mut Vec<T>, src: &[T]) {
        debug_assert!(dst.len() <= src.len(), "a program edited in place does not shrink");
        let n = dst.len().min(src.len());
        dst.extend_from_slice(&src[n..]);
    }
    tail(&mut copy.kind, &base.kind);
    tail(&mut copy.first, &base.first);
    tail(&mut copy.count, &base.count);
    tail(&mut copy.wide, &base.wide);
    tail(&mut copy.bounds, &base.bounds);
    tail(&mut copy.leafy, &base.leafy);
    tail(&mut copy.small, &base.small);
    tail(&mut copy.children, &base.children);
    tail(&mut copy.wides, &base.wides);
}

/// Copies every row of `base` (into `copy`'s memory); not its edit log: a
/// copy is not followed.
fn copy_all(copy: &mut Program, base: &Program) {
    // Named field by field, so that a new field is not forgotten here.
    let Program {
        kind,
        first,
        count,
        wide,
        bounds,
        leafy,
        small,
        children,
        wides,
        local_wides: _,
        local_len: _,
        lists: _,
        lists_len: _,
        ray_plane: _,
        id,
        edits: _,
        serial: _,
        narrowed_unions: _,
    } = base;
    copy.kind.clone_from(kind);
    copy.first.clone_from(first);
    copy.count.clone_from(count);
    copy.wide.clone_from(wide);
    copy.bounds.clone_from(bounds);
    copy.leafy.clone_from(leafy);
    copy.small.clone_from(small);
    copy.children.clone_from(children);
    copy.wides.clone_from(wides);
    copy.local_len = 0;
    copy.lists_len = 0;
    copy.narrowed_unions.clear();
    copy.id = *id;
}
