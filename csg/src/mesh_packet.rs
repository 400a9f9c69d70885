//! Mesh leaves walked once for a packet of eight rays from one origin (a
//! tile's camera rays), when the first lane asks for one: each lane's
//! nearest-mode query ([`LeafTable::mesh_nearest8`], exactly what
//! `LeafTable::spans_for` gives it on its whole range) is recorded, and
//! every lane that asks is served from the record ([`serve_record`]), as
//! the meshes the packet path walks ahead are.
//!
//! A packet of eight rays with one direction and their own origins (a
//! tile's shadow rays toward a directional light) walks a mesh once
//! instead ([`LeafTable::mesh_parallel8`]): the lanes whose own query walks
//! the mesh to its box exit get their whole spans, exact everywhere, and
//! those starting outside the mesh's bounds their nearest queries' spans,
//! as the walked-ahead meshes' shadow packets get them.
//!
//! Why: only scenes of at most `PACKET_MESHES` (4) mesh leaves in all had
//! their meshes walked in packets (walked ahead, for every packet); with
//! more, every ray walked every mesh alone (60 knobs in a union: 52% of the
//! time in one ray's mesh walks, 3.2x POV-Ray's speed flat).

use rothray_primitives::{
    glam::Vec3,
    mesh::{NearestRays8, NO_THROUGH},
    LeafTable, SpanSink,
};

use super::{serve_record, MemoLeaf, PacketMemo};

/// The packet's rays and the meshes walked for them so far.
#[derive(Debug, Default)]
pub(crate) struct MeshWalks {
    /// The lanes taking part (0: no packet, nothing is walked).
    lanes: u32,
    /// Rays with one direction `d[0]` and the origins `os` (shadow rays),
    /// not rays from one origin `o`.
    parallel: bool,
    o: Vec3,
    os: [Vec3; 8],
    d: [Vec3; 8],
    tmin: [f32; 8],
    tmax: [f32; 8],
    /// Each lane's nearest-mode slack ([`RayCtx::nearest_slack_of`](super::RayCtx::nearest_slack_of)).
    slack: [f32; 8],
    /// Records by mesh leaf, `len` in use.
    recs: Vec<MemoLeaf>,
    len: usize,
}

impl MeshWalks {
    pub(crate) fn clear(&mut self) {
        self.lanes = 0;
        self.len = 0;
    }

    /// Walks mesh leaf `i` for the lanes into a new record; returns its place.
    #[inline(never)]
    fn walk(&mut self, leaves: &LeafTable, i: u32) -> usize {
        let MeshWalks { lanes, parallel, o, os, d, tmin, tmax, slack, recs, len } = self;
        if recs.len() == *len {
            recs.push(MemoLeaf::default());
        }
        let e = &mut recs[*len];
        for v in e.spans.iter_mut() {
            v.clear();
        }
        let (done, valid) = if *parallel {
            let (done, valid) = leaves.mesh_parallel8(i, (os, d[0]), (tmin, tmax, Some(slack)), *lanes, &mut e.spans);
            crate::counts::parallel_mesh_lanes(done.count_ones(), 8 - done.count_ones());
            (done, valid)
        } else {
            let q = NearestRays8 { o: *o, d, tmin, tmax, slack, through: &NO_THROUGH, exact: None };
            leaves.mesh_nearest8(i, &q, *lanes, &mut e.spans)
        };
        (e.leaf, e.done, e.tmin, e.tmax, e.valid) = (i, done, *tmin, *tmax, valid);
        *len += 1;
        *len - 1
    }
}

impl PacketMemo {
    /// Lets the lanes of a packet of eight rays from origin `o` with
    /// directions `d` on `[tmin[k], tmax[k]]` (each finite and plain, as the
    /// packet path checks) and nearest-mode slacks `slack` have their mesh
    /// leaves walked together: the first lane to ask for one walks it for
    /// all of them.
    pub fn walk_meshes_for(&mut self, (o, d): (Vec3, &[Vec3; 8]), (tmin, tmax): (&[f32; 8], &[f32; 8]), slack: &[f32; 8]) {
        let w = self.meshes.get_mut();
        (w.lanes, w.parallel, w.o, w.d, w.tmin, w.tmax, w.slack, w.len) = (0xff, false, o, *d, *tmin, *tmax, *slack, 0);
    }

    /// Lets the lanes of a packet of eight rays with one direction `d` from
    /// the origins `o` on `[tmin[k], tmax[k]]` (each finite and plain) and
    /// nearest-mode slacks `slack` have their mesh leaves walked together
    /// (see the module's notes).
    pub fn walk_meshes_parallel_for(&mut self, (o, d): (&[Vec3; 8], Vec3), (tmin, tmax): (&[f32; 8], &[f32; 8]), slack: &[f32; 8]) {
        let w = self.meshes.get_mut();
        (w.lanes, w.parallel, w.os, w.d[0], w.tmin, w.tmax, w.slack, w.len) = (0xff, true, *o, d, *tmin, *tmax, *slack, 0);
    }

    /// Lane `k`'s nearest-mode spans (slack `slack`) of mesh leaf `i` on
    /// `(lo, hi)`, appended to `out`, and where they stop being exact, from
    /// the packet's walk of the mesh (made now when no lane asked before);
    /// `None` when the packet does not answer (no walks set, another slack,
    /// a lane the walk left to its own query, or a range its record does
    /// not cover).
    #[inline]
    pub(crate) fn mesh_lane<S: SpanSink + ?Sized>(
        &self,
        leaves: &LeafTable,
        i: u32,
        (k, (lo, hi)): (usize, (f32, f32)),
        slack: f32,
        out: &mut S,
    ) -> Option<f32> {
        let mut w = self.meshes.borrow_mut();
        if w.lanes & (1 << k) == 0 || w.slack[k].to_bits() != slack.to_bits() {
            return None;
        }
        let at = w.record(leaves, i);
        w.serve_lane(at, (k, (lo, hi)), slack, out)
    }

    /// The packet's walk of mesh leaf `i` (made now when no lane asked
    /// before) and its place, for serving many lanes with one look-up
    /// ([`MeshWalks::serve_lane`]); `None` when the packet walks no meshes,
    /// or walked this one ahead (served by [`PacketMemo::nearest_lane`]).
    /// Why: a union's first-entry walk read each lane's answer through
    /// `nearest_lane`, a borrow and a search of the records per lane (60
    /// knob meshes in a union: 9% of the instructions flat, callgrind
    /// 480x270).
    #[inline]
    pub(crate) fn mesh_walk(&self, leaves: &LeafTable, i: u32) -> Option<(std::cell::Ref<'_, MeshWalks>, usize)> {
        if self.len > 0 && self.entry(i).is_some() {
            return None;
        }
        let at = {
            let mut w = self.meshes.borrow_mut();
            if w.lanes == 0 {
                return None;
            }
            w.record(leaves, i)
        };
        Some((self.meshes.borrow(), at))
    }
}

impl MeshWalks {
    /// The place of mesh leaf `i`'s record, walked now when no lane asked
    /// for it before.
    #[inline(always)]
    fn record(&mut self, leaves: &LeafTable, i: u32) -> usize {
        match self.recs[..self.len].iter().position(|e| e.leaf == i) {
            Some(at) => at,
            None => self.walk(leaves, i),
        }
    }

    /// Lane `k`'s answer on `(lo, hi)` from record `at`, as
    /// [`PacketMemo::mesh_lane`] gives it (`None`: the lane does not take
    /// part, another slack, or a range the record does not cover).
    #[inline(always)]
    pub(crate) fn serve_lane<S: SpanSink + ?Sized>(
        &self,
        at: usize,
        (k, (lo, hi)): (usize, (f32, f32)),
        slack: f32,
        out: &mut S,
    ) -> Option<f32> {
        if self.lanes & (1 << k) == 0 || self.slack[k].to_bits() != slack.to_bits() {
            return None;
        }
        let v = serve_record(&self.recs[at], k, (lo, hi), out);
        crate::counts::mesh_walk_lane(v.is_some());
        v
    }
}
