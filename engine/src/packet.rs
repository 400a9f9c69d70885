//! The packet path of nearest-hit queries: eight camera rays from one origin
//! trace the scene's nearest-mode meshes once for all lanes
//! ([`LeafTable::mesh_nearest8`]), then each lane is settled from those walks
//! where they decide it (a miss of every containing mesh, or the packet
//! [`Shortcut`] for scenes with few leaves), else its CSG is evaluated with
//! the walks' results as memos. Baked by [`bake_packet_paths`].

use glam::Vec3;
use rothray_csg::{MemoLanes, NodeKind, PacketMemo, Program, RayCtx, Scratch};
use rothray_primitives::{
    box_wide::BoxTest8,
    mask8::fill_lanes,
    mesh::{NearestRays8, NO_THROUGH},
    Aabb, LeafTable, Span, Surf,
};

use crate::packet_first::PacketRays;
use crate::scene::{Hit, Ray, RenderScene};
use crate::tile::TileView;

/// At most this many leaves besides the packet meshes for the packet shortcut.
const SHORTCUT_LEAVES: usize = 8;

/// Per packet ray, the CSG evaluation reduced to what is already known: when
/// every leaf other than the packet meshes has its box beyond the nearest
/// packet-mesh entry `t` or (a cheap analytic leaf) no span before it, and every
/// other packet mesh is known empty there too,
/// every leaf but that mesh is empty on `[tmin, t + margin]`. Roth's operations
/// act pointwise (fusing and short-span rules reach only a few eps), so each
/// object's diagram there is its tree with those leaves empty: the mesh's own
/// object, when its tree then reduces to the mesh alone ([`reduce_to_leaf`]),
/// begins with the mesh's entry at `t`, and the other objects are empty. That
/// entry is the nearest hit, without evaluating anything.
pub(crate) struct Shortcut {
    /// World boxes of the leaves that are not packet meshes.
    others: Vec<Aabb>,
    /// Their leaf indices, `u32::MAX` for those whose own query is costly (a
    /// ray meeting such a box before the entry goes the full way): the others
    /// are asked for their spans up to the entry.
    exact: Vec<u32>,
    /// Per packet mesh (as in `packet_meshes`): the object whose tree is that
    /// mesh alone when every other leaf is empty, or `u32::MAX`.
    owner: Vec<u32>,
    /// The cheap analytic leaves under an odd number of subtrahend positions
    /// (subtracted), with their boxes: one that covers a mesh's first entry
    /// would cut it away, so the packet walk goes on through it
    /// ([`NearestRays8::through`]) and the evaluation needs no redo.
    cutters: Vec<(u32, Aabb)>,
    /// Per other leaf, its position in `cutters`, or `u32::MAX`.
    cutter_of: Vec<u32>,
}

/// Per leaf, whether it lies under an odd number of subtrahend positions of
/// its tree (marks `out[leaf]`).
fn mark_subtracted(program: &Program, n: u32, odd: bool, out: &mut [bool]) {
    let nu = n as usize;
    let first = program.first[nu] as usize;
    match program.kind[nu] {
        NodeKind::Leaf => out[first] = odd,
        kind => {
            for (i, &c) in program.children[first..first + program.count[nu] as usize].iter().enumerate() {
                mark_subtracted(program, c, odd ^ (kind == NodeKind::Difference && i > 0), out);
            }
        }
    }
}

/// A span sink that keeps only the first span.
struct First(Option<Span>);

impl rothray_primitives::SpanSink for First {
    #[inline]
    fn push_span(&mut self, s: Span) {
        if self.0.is_none() {
            self.0 = Some(s);
        }
    }
}

/// What node `n` becomes when every leaf but `keep` is empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reduced {
    Empty,
    Keep,
    /// Anything else (`keep` combined with itself).
    Other,
}

fn reduce_to_leaf(program: &Program, n: u32, keep: u32) -> Reduced {
    let nu = n as usize;
    let first = program.first[nu] as usize;
    if program.kind[nu] == NodeKind::Leaf {
        return if first as u32 == keep { Reduced::Keep } else { Reduced::Empty };
    }
    let ch = &program.children[first..first + program.count[nu] as usize];
    let red = |c: &u32| reduce_to_leaf(program, *c, keep);
    let one = |mut it: std::vec::IntoIter<Reduced>| match (it.next(), it.next()) {
        (None, _) => Reduced::Empty,
        (Some(r), None) => r,
        _ => Reduced::Other,
    };
    match program.kind[nu] {
        NodeKind::Leaf => unreachable!(),
        NodeKind::Union => one(ch.iter().map(red).filter(|&r| r != Reduced::Empty).collect::<Vec<_>>().into_iter()),
        NodeKind::Intersection => {
            let rs: Vec<Reduced> = ch.iter().map(red).collect();
            if rs.is_empty() || rs.contains(&Reduced::Empty) {
                Reduced::Empty
            } else {
                one(rs.into_iter())
            }
        }
        NodeKind::Difference => match ch.first().map(red) {
            None | Some(Reduced::Empty) => Reduced::Empty,
            Some(r) => {
                if ch[1..].iter().map(red).all(|s| s == Reduced::Empty) {
                    r
                } else {
                    Reduced::Other
                }
            }
        },
    }
}

/// What the packet knows of one lane before its own evaluation (for
/// [`RenderScene::shortcut_hit`]).
struct LaneKnown<'a, 'm> {
    /// The packet meshes' records (as in `packet_meshes`).
    lanes: &'a [Option<MemoLanes<'m>>; PACKET_MESHES],
    /// Per cutter (see [`Shortcut::cutters`]) and lane, its first span.
    cut_spans: &'a [Option<Span>],
    /// Per cutter, the lanes whose `cut_spans` entry was made.
    cut_done: &'a [u8],
    /// The lane.
    k: usize,
}

/// At most this many mesh leaves are traced ahead per packet; scenes with more
/// go ray by ray.
pub const PACKET_MESHES: usize = 4;

/// Per-thread memory of [`RenderScene::intersect_packet`].
#[derive(Default)]
pub struct PacketScratch {
    /// The single-ray scratch (also for shading).
    pub scratch: Scratch,
    memo: PacketMemo,
    /// Rays answered by the packet shortcut so far (for tests).
    pub shortcuts: u64,
    /// Packet rays given an interval to walk on through (they meet a
    /// subtracted cheap leaf; the walk holds on only where the first mesh
    /// crossing lies inside it) so far (for tests).
    pub throughs: u64,
    /// Per cutter (see `Shortcut::cutters`) and lane, its first span on the
    /// ray's range, where `cut_done` has the lane's bit.
    cut_spans: Vec<Option<Span>>,
    cut_done: Vec<u8>,
    /// Per lane, the tile's listed objects along its ray
    /// ([`packet_candidates`]).
    listed: [Vec<(f32, u32)>; 8],
    /// The objects the packet meets, for `packet_first.rs`.
    pub(crate) met: crate::packet_first::MetList,
}

/// Fewer lanes than this list the tile's objects each on its own (four
/// boxes a test, `BoxList::entries`) rather than with one test of all eight
/// lanes per box ([`packet_candidates`]): the lanes a packet's objects
/// left unsettled are mostly one or two, and for them the packet's tests
/// of every box were 4.6% of a forest of 40 000 objects flat (perf).
const PACKET_LIST_LANES: u32 = 3;

/// The objects of `tile`'s list along each of the eight `rays` (lanes
/// `lanes`), made for the packet at once ([`BoxList::packet_entries`]) into
/// `out`, when the tile lists its objects (two or more: one is taken
/// without a box test) and the rays form a packet; else `false`.
fn packet_candidates(tile: Option<&TileView>, rays: &[Ray], lanes: u32, out: &mut [Vec<(f32, u32)>; 8]) -> bool {
    if lanes.count_ones() < PACKET_LIST_LANES {
        return false;
    }
    let Some(list) = tile.and_then(|t| t.bounded).filter(|l| l.len() > 1) else { return false };
    if rays.len() != 8 {
        return false;
    }
    let Some(test) = BoxTest8::new(&std::array::from_fn(|k| rays[k].origin), &std::array::from_fn(|k| rays[k].dir)) else { return false };
    let (tmin, tmax): ([f32; 8], [f32; 8]) = (std::array::from_fn(|k| rays[k].tmin), std::array::from_fn(|k| rays[k].tmax));
    list.packet_entries(&test, (&tmin, &tmax), lanes, out);
    true
}

/// The mesh leaves of `roots` that a nearest-hit evaluation queries in nearest
/// mode: those with no intersection's first operand on their path (that operand
/// is evaluated in full, see `Program::child_mode`).
pub(crate) fn nearest_mode_meshes(program: &Program, leaves: &LeafTable, roots: impl Iterator<Item = u32>) -> Vec<u32> {
    let mut found = Vec::new();
    let mut stack: Vec<u32> = roots.collect();
    while let Some(n) = stack.pop() {
        let nu = n as usize;
        let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
        match program.kind[nu] {
            NodeKind::Leaf => {
                if leaves.is_mesh(first as u32) && !found.contains(&(first as u32)) {
                    found.push(first as u32);
                }
            }
            NodeKind::Intersection => stack.extend_from_slice(&program.children[first + 1..first + count]),
            _ => stack.extend_from_slice(&program.children[first..first + count]),
        }
    }
    found
}

/// Leaves whose solid contains the whole solid of node `n`: the node itself
/// when a leaf, the leaves of any operand of an intersection, those of a
/// difference's first operand; none through a union. Boolean operations on
/// Roth spans never produce a span where such a leaf has none, so a ray that
/// misses one of them misses the node.
fn containing_leaves(program: &Program, n: u32, out: &mut Vec<u32>) {
    let nu = n as usize;
    let (first, count) = (program.first[nu] as usize, program.count[nu] as usize);
    match program.kind[nu] {
        NodeKind::Leaf => out.push(first as u32),
        NodeKind::Intersection => {
            for &c in &program.children[first..first + count] {
                containing_leaves(program, c, out);
            }
        }
        NodeKind::Difference if count > 0 => containing_leaves(program, program.children[first], out),
        _ => {}
    }
}

/// Do the rays of `tile` (of the whole scene without one) share work in a
/// packet: does it keep a leaf with a packet kernel, a wide union, or a
/// mesh?
fn shares_work(tile: Option<&TileView>) -> bool {
    tile.is_none_or(|t| t.kernels8 || t.unions || t.meshes)
}

/// Are all eight `rays` plain ([`Ray::is_plain`])? Each lane's answer
/// combined with `&`, with no early exit.
#[inline(always)]
fn all_plain(rays: &[Ray; 8]) -> bool {
    rays.iter().fold(true, |ok, r| ok & r.is_plain())
}

/// Does `tile` (the whole scene without one) keep a leaf with a packet kernel?
fn solves_leaves(tile: Option<&TileView>) -> bool {
    tile.is_none_or(|t| t.kernels8)
}

/// Readies `memo` for a packet of eight plain rays (`ctx`, no memo yet) of
/// `tile`: its wide unions walked, its analytic leaves solved and (rays
/// from one origin) its meshes walked for all lanes when the first lane
/// asks.
fn ready_memo(memo: &mut PacketMemo, (rays, eps): (&[Ray; 8], &[f32; 8]), tile: Option<&TileView>) {
    memo.clear();
    if tile.is_some_and(|t| t.unions) {
        memo.walk_unions_for((rays, eps), 0xff);
    }
    if solves_leaves(tile) {
        memo.solve_leaves_for(|k| (rays[k].origin, rays[k].dir), 0xff);
    }
    let o = rays[0].origin;
    if tile.is_some_and(|t| t.meshes) && rays.iter().all(|r| r.origin == o) {
        let (mut d, mut tmin, mut tmax, mut slack) = ([Vec3::ZERO; 8], [0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        fill_lanes(&mut d, |k| rays[k].dir);
        fill_lanes(&mut tmin, |k| rays[k].tmin);
        fill_lanes(&mut tmax, |k| rays[k].tmax);
        fill_lanes(&mut slack, |k| RayCtx::nearest_slack_of(eps[k]));
        memo.walk_meshes_for((o, &d), (&tmin, &tmax), &slack);
    }
}

/// Bake step of the packet path: the nearest-mode meshes traced ahead per
/// packet, the objects they cover, and the [`Shortcut`] for scenes with few
/// leaves. Runs after the program and objects are baked.
pub(crate) fn bake_packet_paths(scene: &mut RenderScene) {
    let pm = nearest_mode_meshes(&scene.program, &scene.leaves, scene.objects.iter().map(|o| o.root));
    set_packet_paths(scene, pm);
}

/// The packet path's tables for the nearest-mode meshes `pm` (as
/// [`nearest_mode_meshes`] lists them over every object): none past
/// [`PACKET_MESHES`]. Walks trees only in scenes with at most as many
/// objects as packet meshes, or with few leaves (the shortcut): a live
/// sync of a large scene pays nothing here.
pub(crate) fn set_packet_paths(scene: &mut RenderScene, mut pm: Vec<u32>) {
    if pm.len() > PACKET_MESHES {
        pm.clear();
    }
    scene.packet_cover = packet_cover(scene, &pm);
    scene.shortcut = if pm.is_empty() || scene.leaves.len() > pm.len() + SHORTCUT_LEAVES {
        None
    } else {
        let rest: Vec<u32> = (0..scene.leaves.len() as u32).filter(|l| !pm.contains(l)).collect();
        let others: Vec<Aabb> = scene.leaf_bounds(&rest);
        let exact: Vec<u32> = rest
            .iter()
            .map(|&l| {
                use rothray_primitives::table::LeafKind::*;
                let cheap = matches!(scene.leaves.kind[l as usize], Sphere | Ellipsoid | Cuboid | Cylinder | Cone | HalfSpace);
                if cheap {
                    l
                } else {
                    u32::MAX
                }
            })
            .collect();
        let owner: Vec<u32> = pm
            .iter()
            .map(|&m| {
                let oi = scene.leaf_info[m as usize].object;
                let keep = reduce_to_leaf(&scene.program, scene.objects[oi as usize].root, m) == Reduced::Keep;
                if keep {
                    oi
                } else {
                    u32::MAX
                }
            })
            .collect();
        let mut sub = vec![false; scene.leaves.len()];
        for o in &scene.objects {
            mark_subtracted(&scene.program, o.root, false, &mut sub);
        }
        let subtracted: Vec<bool> = rest.iter().map(|&l| sub[l as usize]).collect();
        let cutters: Vec<(u32, Aabb)> =
            exact.iter().zip(&subtracted).zip(&others).filter(|((&l, &s), _)| s && l != u32::MAX).map(|((&l, _), b)| (l, *b)).collect();
        let cutter_of: Vec<u32> = rest.iter().map(|l| cutters.iter().position(|c| c.0 == *l).map_or(u32::MAX, |p| p as u32)).collect();
        owner.iter().any(|&o| o != u32::MAX).then_some(Shortcut { others, exact, owner, cutters, cutter_of })
    };
    scene.packet_meshes = pm;
}

/// [`packet_cover`] by a walk of every object's tree (also the tests' oracle).
pub(crate) fn packet_cover_by_walk(scene: &RenderScene, pm: &[u32]) -> Option<Vec<u32>> {
    scene
        .objects
        .iter()
        .map(|o| {
            let mut c = Vec::new();
            containing_leaves(&scene.program, o.root, &mut c);
            c.into_iter().find(|l| pm.contains(l))
        })
        .collect()
}

/// Per object, a leaf of `pm` containing its solid, when every object has
/// one. A leaf lies in one object's tree, so with more objects than leaves
/// in `pm` some object has none: no walk is needed to know.
fn packet_cover(scene: &RenderScene, pm: &[u32]) -> Option<Vec<u32>> {
    if scene.objects.len() > pm.len() {
        return None;
    }
    packet_cover_by_walk(scene, pm)
}

impl RenderScene {
    /// Nearest hits of up to eight rays (`out[k]` for `rays[k]`), the same as
    /// [`RenderScene::intersect_with`] ray by ray. Eight valid rays from one origin
    /// (camera rays through neighbouring pixels) go as a packet: the scene's
    /// nearest-mode meshes are traced once for all eight
    /// ([`LeafTable::mesh_nearest8`], going on through subtracted analytic
    /// leaves where a ray's first crossing lies inside one); then each ray is
    /// settled from those results where they decide it (a miss of every
    /// containing mesh, or the packet shortcut of the README), else its CSG is
    /// evaluated with them.
    pub fn intersect_packet(&self, rays: &[Ray], ps: &mut PacketScratch, out: &mut [Option<Hit>]) {
        self.intersect_packet_with(rays, ps, out, true, None);
    }

    /// [`RenderScene::intersect_packet`]; without `normals` every hit's `normal`
    /// is left zero (a picture without lights does not read it: the normal of
    /// a mesh triangle was ~6% of a frame of scenes/bunny). With `tile`, the
    /// rays (all inside the region it was prepared for) evaluate the tile's
    /// programs, with the same answers.
    #[doc(hidden)]
    pub fn intersect_packet_with(
        &self,
        rays: &[Ray],
        ps: &mut PacketScratch,
        out: &mut [Option<Hit>],
        normals: bool,
        tile: Option<&TileView>,
    ) {
        let n = rays.len().min(out.len());
        if n == 0 {
            return;
        }
        if self.ray_by_ray {
            for k in 0..n {
                out[k] = self.intersect_ray(&rays[k], &mut ps.scratch, normals, tile);
            }
            return;
        }
        let o = rays[0].origin;
        // `is_valid` for each ray, with the shared origin checked once.
        let meshes = n == 8
            && !self.packet_meshes.is_empty()
            && o.is_finite()
            && rays.iter().all(|r| r.origin == o && r.dir.is_finite() && r.dir != Vec3::ZERO && r.tmin <= r.tmax)
            && rays.iter().all(|r| Ray::dir_rescale(r.dir).is_none());
        let unions = tile.is_some_and(|t| t.unions);
        if !meshes {
            // (A tile without packet kernels or wide unions has nothing to share.)
            if n == 8 && shares_work(tile) && all_plain(rays[..8].try_into().expect("eight rays")) {
                self.lane_packet(rays, ps, out, normals, tile);
                return;
            }
            for k in 0..n {
                out[k] = self.intersect_ray(&rays[k], &mut ps.scratch, normals, tile);
            }
            return;
        }
        // What `ray_ctx` gives each ray (the same bits), its origin's share once.
        let ew = self.eps_at(o);
        let d: [Vec3; 8] = std::array::from_fn(|k| rays[k].dir);
        let eps: [f32; 8] = std::array::from_fn(|k| ew / d[k].length());
        let tmin: [f32; 8] = std::array::from_fn(|k| rays[k].tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| rays[k].tmax);
        let slack: [f32; 8] = std::array::from_fn(|k| RayCtx::nearest_slack_of(eps[k]));
        // A ray through a subtracted analytic leaf keeps walking the meshes to
        // where that leaf ends when their first crossing lies inside it (the
        // nearest-mode answer would be cut away there: with the crossings up to
        // the leaf's end, the evaluation needs no redo).
        let mut through = NO_THROUGH;
        let inv_d: [Vec3; 8] = std::array::from_fn(|k| rays[k].inv_dir);
        if let Some(sc) = self.shortcut.as_ref().filter(|sc| !sc.cutters.is_empty()) {
            ps.cut_spans.resize(8 * sc.cutters.len(), None);
            ps.cut_done.resize(sc.cutters.len(), 0);
            for (ci, &(l, ref b)) in sc.cutters.iter().enumerate() {
                // Only a guess (a ray without it is redone, exactly): a box
                // that the packet's corner rays both miss is taken as missed.
                ps.cut_done[ci] = 0;
                if b.ray_range(o, inv_d[0], tmin[0], tmax[0]).is_none() && b.ray_range(o, inv_d[7], tmin[7], tmax[7]).is_none() {
                    continue;
                }
                ps.cut_done[ci] = 0xff;
                for k in 0..8 {
                    ps.cut_spans[8 * ci + k] = None;
                    if b.ray_range(o, inv_d[k], tmin[k], tmax[k]).is_none() {
                        continue;
                    }
                    let mut first = First(None);
                    self.leaves.spans(l, &rays[k], &mut first);
                    ps.cut_spans[8 * ci + k] = first.0;
                    if let Some(f) = first.0 {
                        if f.t0 < through[k][0] {
                            ps.throughs += (through[k][0] == f32::INFINITY) as u64;
                            through[k] = [f.t0, f.t1 + 64.0 * eps[k]];
                        }
                    }
                }
            }
        }
        ps.memo.clear();
        let q = NearestRays8 { o, d: &d, tmin: &tmin, tmax: &tmax, slack: &slack, through: &through, exact: None };
        for &i in &self.packet_meshes {
            ps.memo.add(i, &tmin, &tmax, |sp| self.leaves.mesh_nearest8(i, &q, 0xff, sp));
        }
        // Rays for which every object lies inside a mesh they miss: no hit. A
        // packet of such rays only (background) is done.
        let mut left = 0xffu32;
        if let Some(cover) = &self.packet_cover {
            let mut missed = 0xffu32;
            for &l in cover {
                missed &= ps.memo.empty8(l, &tmin, &tmax);
            }
            for (k, o) in out.iter_mut().enumerate().take(8) {
                if missed & (1 << k) != 0 {
                    *o = None;
                }
            }
            left &= !missed;
            if left == 0 {
                return;
            }
        }
        // The tile's wide unions, walked for the packet's rays on demand.
        if unions {
            ps.memo.walk_unions_for((rays[..8].try_into().expect("eight rays"), &eps), left);
        }
        // Its analytic leaves, solved for all lanes when the first asks.
        if solves_leaves(tile) {
            ps.memo.solve_leaves_for(|k| (o, d[k]), left);
        }
        // All eight contexts are written before the first is read: reading one
        // just built (its fields written piecewise, read with wider loads) stalls
        // on store forwarding.
        let memo = &ps.memo;
        // The packet meshes' records, looked up once for the eight rays.
        let mut lanes: [Option<MemoLanes>; PACKET_MESHES] = [None; PACKET_MESHES];
        for (j, &m) in self.packet_meshes.iter().enumerate() {
            lanes[j] = memo.lanes(m);
        }
        let ctx: [RayCtx; 8] = std::array::from_fn(|k| RayCtx { ray: rays[k], eps: eps[k], memo: Some((memo, k)) });
        let listed = packet_candidates(tile, rays, left, &mut ps.listed);
        let mut found = [None; 8];
        for k in 0..8 {
            if left & (1 << k) == 0 {
                continue;
            }
            if let Some(sc) = &self.shortcut {
                let known = LaneKnown { lanes: &lanes, cut_spans: &ps.cut_spans, cut_done: &ps.cut_done, k };
                if let Some(h) = self.shortcut_hit(sc, &ctx[k], &known, normals) {
                    out[k] = h;
                    ps.shortcuts += 1;
                    continue;
                }
            }
            found[k] = self.nearest_ctx(&ctx[k], &mut ps.scratch, tile, listed.then_some(&mut ps.listed[k]));
            out[k] = None;
        }
        self.make_hits(rays, &found, normals, out);
    }

    /// The hits of the lanes that found one (`found[k]`: object, `t` and
    /// surface), made together once every lane is settled: the normals'
    /// chains of square roots and divisions, one per lane, then overlap
    /// (made lane by lane between the lanes' evaluations, they were 9% of
    /// the cycles of scenes/forest lit at 1920x1080, perf, against 3% of
    /// its instructions).
    #[inline]
    fn make_hits(&self, rays: &[Ray], found: &[Option<(u32, f32, Surf)>; 8], normals: bool, out: &mut [Option<Hit>]) {
        for k in 0..8 {
            if let Some((oi, t, s)) = found[k] {
                out[k] = Some(self.hit_at(&rays[k], oi, t, s, normals));
            }
        }
    }

    /// [`RenderScene::intersect_packet_with`] for eight valid rays in range
    /// and no packet meshes: each ray is evaluated with a memo that solves
    /// an analytic leaf (and walks a tile's wide union of leaves) for all
    /// eight rays when the first of them asks for it.
    fn lane_packet(&self, rays: &[Ray], ps: &mut PacketScratch, out: &mut [Option<Hit>], normals: bool, tile: Option<&TileView>) {
        let rays: &[Ray; 8] = rays[..8].try_into().expect("eight rays");
        let eps = self.eps8(rays);
        ready_memo(&mut ps.memo, (rays, &eps), tile);
        let mut found = [None; 8];
        // Lanes settled by the objects' packet answers (`packet_first.rs`).
        let settled =
            self.packet_nearest(&PacketRays { rays, eps: &eps, memo: &ps.memo }, tile, (&mut ps.met, &mut ps.scratch), &mut found);
        if settled == 0xff {
            for o in out.iter_mut().take(8) {
                *o = None;
            }
            self.make_hits(rays, &found, normals, out);
            return;
        }
        let listed = packet_candidates(tile, rays, 0xff & !settled, &mut ps.listed);
        let memo = &ps.memo;
        for k in 0..8 {
            out[k] = None;
            if settled & (1 << k) != 0 {
                continue;
            }
            let ctx = RayCtx { ray: rays[k], eps: eps[k], memo: Some((memo, k)) };
            found[k] = self.nearest_ctx(&ctx, &mut ps.scratch, tile, listed.then_some(&mut ps.listed[k]));
        }
        self.make_hits(rays, &found, normals, out);
    }

    /// Any-hit for up to eight rays inside the region `tile` was prepared
    /// for (`out[k]` for `rays[k]`), the same as [`RenderScene::occluded_in`]
    /// ray by ray: eight rays in range (a tile's shadow rays towards one
    /// light) walk the tile's wide unions of leaves and solve its analytic
    /// leaves together (when the first of them asks for one).
    pub fn occluded_packet(&self, rays: &[Ray], ps: &mut PacketScratch, out: &mut [bool], tile: Option<&TileView>) {
        let n = rays.len().min(out.len());
        // Rays with one direction (toward a directional light) walk the
        // packet meshes together.
        // (Bits, not values: -0 and +0 components would set up other walks.)
        let dir_bits = |r: &Ray| r.dir.to_array().map(f32::to_bits);
        let one_dir = || rays.iter().all(|r| dir_bits(r) == dir_bits(&rays[0]));
        let parallel = n == 8 && !self.packet_meshes.is_empty() && one_dir();
        if n == 8 && !self.ray_by_ray && (shares_work(tile) || parallel) && all_plain(rays[..8].try_into().expect("eight rays")) {
            let rays: &[Ray; 8] = rays[..8].try_into().expect("eight rays");
            let eps = self.eps8(rays);
            ready_memo(&mut ps.memo, (rays, &eps), tile);
            if parallel {
                self.walk_meshes_parallel(rays, &mut ps.memo);
            } else if tile.is_some_and(|t| t.meshes) && one_dir() {
                // More meshes than are walked ahead: each walked when a
                // lane first asks (`PacketMemo::walk_meshes_parallel_for`).
                let (mut o, mut tmin, mut tmax, mut slack) = ([Vec3::ZERO; 8], [0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
                fill_lanes(&mut o, |k| rays[k].origin);
                fill_lanes(&mut tmin, |k| rays[k].tmin);
                fill_lanes(&mut tmax, |k| rays[k].tmax);
                fill_lanes(&mut slack, |k| RayCtx::nearest_slack_of(eps[k]));
                ps.memo.walk_meshes_parallel_for((&o, rays[0].dir), (&tmin, &tmax), &slack);
            }
            let settled = self.packet_any(&PacketRays { rays, eps: &eps, memo: &ps.memo }, tile, (&mut ps.met, &mut ps.scratch), out);
            if settled == 0xff {
                return;
            }
            let listed = packet_candidates(tile, rays, 0xff & !settled, &mut ps.listed);
            let memo = &ps.memo;
            for k in 0..8 {
                if settled & (1 << k) != 0 {
                    continue;
                }
                let lane = RayCtx { ray: rays[k], eps: eps[k], memo: Some((memo, k)) };
                out[k] = self.occluded_listed(&lane, &mut ps.scratch, tile, listed.then_some(&mut ps.listed[k]));
            }
        } else {
            for k in 0..n {
                out[k] = self.occluded_in(&rays[k], &mut ps.scratch, tile);
            }
        }
    }

    /// The spans of the packet meshes for eight rays with one direction,
    /// recorded in `memo` for the lanes whose own query walks a mesh to its
    /// box exit (a shadow ray starts inside the mesh's bounds, so its
    /// nearest query cannot prune): one walk of each mesh's tree for the
    /// packet ([`LeafTable::mesh_parallel8`]), each lane's spans exactly its
    /// own walk's.
    fn walk_meshes_parallel(&self, rays: &[Ray], memo: &mut PacketMemo) {
        let o: [Vec3; 8] = std::array::from_fn(|k| rays[k].origin);
        let tmin: [f32; 8] = std::array::from_fn(|k| rays[k].tmin);
        let tmax: [f32; 8] = std::array::from_fn(|k| rays[k].tmax);
        for &i in &self.packet_meshes {
            memo.add(i, &tmin, &tmax, |sp| {
                // (Not the lanes starting outside the mesh's bounds: walked
                // ahead for every packet, whether or not they ask, those
                // cost benches/scenes/mesh_cut 7% of its lit time.)
                let (done, valid) = self.leaves.mesh_parallel8(i, (&o, rays[0].dir), (&tmin, &tmax, None), 0xff, sp);
                rothray_csg::counts::parallel_mesh_lanes(done.count_ones(), 8 - done.count_ones());
                (done, valid)
            });
        }
    }

    /// Does every object lie inside a packet mesh (so that packet rays missing
    /// those meshes skip their evaluation)? For tests.
    #[doc(hidden)]
    pub fn packet_covered(&self) -> bool {
        !self.packet_meshes.is_empty() && self.packet_cover.is_some()
    }

    /// The nearest hit of packet lane `known.k` by the [`Shortcut`], when it
    /// applies (`Some(None)`: no hit at all, every leaf is empty on the ray's
    /// range).
    #[inline]
    fn shortcut_hit(&self, sc: &Shortcut, ctx: &RayCtx, known: &LaneKnown, normals: bool) -> Option<Option<Hit>> {
        let LaneKnown { lanes, cut_spans, cut_done, k } = *known;
        let ray = &ctx.ray;
        // The nearest packet-mesh entry, and up to where each mesh is known empty.
        let mut best: Option<(f32, Surf, usize)> = None;
        let mut clear = [f32::INFINITY; PACKET_MESHES];
        for (j, l) in lanes[..self.packet_meshes.len()].iter().enumerate() {
            let (spans, valid) = l.and_then(|l| l.get(k))?;
            match spans.first() {
                // Inside at `tmin`: the shortcut does not reason about that.
                Some(s) if !s.s0.is_real() => return None,
                // A first span no longer than eps is dropped by `combine` when
                // the evaluation meets any other operand, however far: the full
                // evaluation decides it.
                Some(s) if s.t1 - s.t0 <= 2.0 * ctx.eps => return None,
                Some(s) => {
                    clear[j] = s.t0;
                    if best.is_none_or(|b| s.t0 < b.0) {
                        best = Some((s.t0, s.s0, j));
                    }
                }
                None if valid < ray.tmax => clear[j] = valid,
                None => {}
            }
        }
        // Everything else must be empty on [tmin, reach]: 16 eps past the entry
        // (as for the redo window: what lies further cannot fuse with it or cut
        // it short), or the whole range when there is no entry.
        let (reach, j_best) = match best {
            Some((t, _, j)) => (t + 16.0 * ctx.eps, j),
            None => (ray.tmax, usize::MAX),
        };
        for (j, &c) in clear[..self.packet_meshes.len()].iter().enumerate() {
            if j != j_best && c <= reach {
                return None;
            }
        }
        for (i, (b, &l)) in sc.others.iter().zip(&sc.exact).enumerate() {
            let ci = sc.cutter_of[i] as usize;
            if ci != u32::MAX as usize && cut_done[ci] & (1 << k) != 0 {
                // Its first span is known: any before `reach`?
                if cut_spans[8 * ci + k].is_some_and(|f| f.t0 < reach) {
                    return None;
                }
                continue;
            }
            if let Some((t0, _)) = b.ray_range(ray.origin, ray.inv_dir, ray.tmin, ray.tmax) {
                if t0 <= reach {
                    // The box reaches the entry: does the leaf itself?
                    let mut first = First(None);
                    if l != u32::MAX {
                        self.leaves.spans(l, &ray.with_range(ray.tmin, reach), &mut first);
                    }
                    if l == u32::MAX || first.0.is_some() {
                        return None;
                    }
                }
            }
        }
        let Some((t, s, j)) = best else { return Some(None) };
        let oi = sc.owner[j];
        if oi == u32::MAX {
            return None;
        }
        Some(Some(self.hit_at(ray, oi, t, s, normals)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `eps8` gives every lane the tolerance of the context `ray_ctx` gives its ray, bit
    /// for bit: rays from near and far (where the tolerance grows with the
    /// distance), of unit and other lengths, one origin or eight.
    #[test]
    fn eps8_is_ray_ctx_per_lane() {
        use crate::components::Sphere;
        use rand::{rngs::SmallRng, Rng, SeedableRng};
        let seed = 0x7c8u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut world = hecs::World::new();
        world.spawn((crate::Transform::from_translation(Vec3::new(3.0, -2.0, 1.0)), Sphere { center: Vec3::ZERO, radius: 1.5 }));
        let scene = RenderScene::from_world(&world).unwrap();
        for case in 0..5000 {
            let far = [1.0f32, 1e3, 1e6, 3e8][case % 4];
            let shared = Vec3::new(rng.gen_range(-far..far), rng.gen_range(-far..far), rng.gen_range(-far..far));
            let rays: [Ray; 8] = std::array::from_fn(|_| {
                let o = if case % 2 == 0 {
                    shared
                } else {
                    Vec3::new(rng.gen_range(-far..far), rng.gen_range(-far..far), rng.gen_range(-far..far))
                };
                let len = [1.0f32, 1e-6, 7.5, 1e6][rng.gen_range(0..4)];
                let d = Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)) * len;
                Ray::new(o, d)
            });
            let eps = scene.eps8(&rays);
            for k in 0..8 {
                let c1 = scene.ray_ctx(&rays[k]);
                assert_eq!(eps[k].to_bits(), c1.eps.to_bits(), "case {case} lane {k}: {:?}", rays[k]);
                assert_eq!(rays[k], c1.ray, "case {case} lane {k}");
            }
        }
    }
}
