//! The tile level of the trace path: for the region of rays of one tile (a
//! [`Frustum`]), the objects they can meet and each object's program
//! specialised to the tile ([`TileProgram`]). The rays of the tile evaluate
//! those programs ([`TileView`]); objects the tile misses, bounded or not, cost
//! its rays nothing.

use rothray_csg::{Program, TileCounts, TileProgram};
use rothray_primitives::frustum::{slot_rows, Frustum};

use crate::box_list::BoxList;
use crate::scene::RenderScene;

/// Marks an object the tile's rays cannot meet.
const NONE: u32 = u32::MAX;

/// A tile that meets at most this many bounded objects lists them: its rays
/// test those objects' boxes instead of walking the tree of all the scene's
/// objects (see `RenderScene::visit_candidates`), and its packets pick their
/// hits among them together (`packet_first.rs`). (With 128, a light's sweep
/// over a forest of 10 000 objects often met more, and those shadow packets'
/// lanes each walked the objects' tree: benches/scenes/forest_objects lit at
/// 1920x1080 0.1558 s -> 0.1521 s with 256, 0.1520 s with 512, medians of 9
/// in three rounds; callgrind 480x270 lit -27.5% with 256; capsules lit
/// unchanged.)
pub const OBJECT_LIST: usize = 256;

/// The bounded objects a group of tiles may meet
/// ([`RenderScene::objects_touched`]), in the objects' tree's order, with
/// their boxes four to a row as [`Frustum::touches_slots`] tests them.
/// Why: each tile of the group tested each of them against its region one
/// by one, some 200 boxes to keep 50 in a forest of 40 000 objects (a
/// tenth of its time flat, perf).
#[derive(Default)]
pub(crate) struct GroupObjects {
    ids: Vec<u32>,
    /// Per four objects, their boxes' `[min x, max x, min y, max y, min z,
    /// max z]` (empty past the last: min above max).
    rows: Vec<[[f32; 4]; 6]>,
}

impl GroupObjects {
    fn clear(&mut self) {
        self.ids.clear();
        self.rows.clear();
    }

    /// Makes the rows of the ids' boxes (`bounds`).
    fn make_rows(&mut self, bounds: impl Fn(u32) -> rothray_primitives::Aabb) {
        self.rows.clear();
        self.rows.extend(self.ids.chunks(4).map(|four| slot_rows(four.iter().map(|&oi| bounds(oi)))));
    }

    /// The objects whose boxes `region` may touch ([`Frustum::touches_box`],
    /// four at a time: the same answers), in order.
    fn touched_by(&self, region: &Frustum, mut f: impl FnMut(u32)) {
        for (q, r) in self.rows.iter().enumerate() {
            let mut m = region.touches_slots(r);
            while m != 0 {
                let j = m.trailing_zeros() as usize;
                m &= m - 1;
                f(self.ids[4 * q + j]);
            }
        }
    }
}

/// Per-thread memory of the tile level, reused from tile to tile.
#[derive(Default)]
pub struct TileScratch {
    tp: TileProgram,
    /// Per object, its root in `tp.prog` for the current tile, or [`NONE`].
    root_of: Vec<u32>,
    /// The objects given a root in the current tile.
    live: Vec<u32>,
    /// The boxes of the bounded ones among them, by index, as the rays test
    /// them, when there are at most [`OBJECT_LIST`] (`listed`).
    boxes: BoxList,
    listed: bool,
    /// Is some kept object's tile program a wide union of leaves (which a
    /// packet of the tile's rays walks together,
    /// `PacketMemo::walk_unions_for`)?
    unions: bool,
    /// Is every kept object's root a leaf other than a mesh, or a small
    /// node of kernel leaves (`packet_first::simple_root`: its packets pick
    /// their nearest hits among the objects together, `packet_first.rs`)?
    simple: bool,
    /// Counts since the last [`TileScratch::take_counts`].
    counts: TileStats,
}

/// What the tile level did (summed over tiles).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TileStats {
    /// Tiles prepared.
    pub tiles: u64,
    /// Tiles that meet no object (their rays are not traced).
    pub tiles_culled: u64,
    /// Objects kept, summed over tiles.
    pub objects_kept: u64,
    /// Shadow bundles that met too many objects to list them and went as
    /// two halves (`render_tile::shadow_bundle`).
    pub bundles_split: u64,
    /// What the specialisation did.
    pub spec: TileCounts,
}

impl TileStats {
    /// Adds `o` to these counts.
    pub fn add(&mut self, o: &TileStats) {
        self.tiles += o.tiles;
        self.tiles_culled += o.tiles_culled;
        self.objects_kept += o.objects_kept;
        self.bundles_split += o.bundles_split;
        self.spec.leaves_pruned += o.spec.leaves_pruned;
        self.spec.leaves_kept += o.spec.leaves_kept;
        self.spec.wide_queries += o.spec.wide_queries;
        self.spec.nodes_written += o.spec.nodes_written;
        self.spec.lists += o.spec.lists;
        self.spec.listed += o.spec.listed;
    }
}

/// What the rays of one tile evaluate: the tile's program and, per object,
/// its root there ([`TileView::root`]).
#[derive(Clone, Copy)]
pub struct TileView<'a> {
    /// The baked program followed by the tile's specialised nodes.
    pub prog: &'a Program,
    root_of: &'a [u32],
    /// The bounded objects the tile meets, when it lists them.
    pub(crate) bounded: Option<&'a BoxList>,
    /// Has the tile objects that packets walk together (see `TileScratch`)?
    pub(crate) unions: bool,
    /// Has the tile leaves with packet kernels (`LeafTable::ranges8`)?
    pub(crate) kernels8: bool,
    /// May it have mesh leaves (`TileProgram::meshes`)?
    pub(crate) meshes: bool,
    /// Are all its objects' roots answered by `PacketMemo::first_surfaces8`
    /// (see `TileScratch`)?
    pub(crate) simple: bool,
}

impl TileView<'_> {
    /// Object `oi`'s root in [`TileView::prog`], or `None` when the tile's rays
    /// cannot meet it.
    #[inline(always)]
    pub fn root(&self, oi: u32) -> Option<u32> {
        let r = self.root_of[oi as usize];
        (r != NONE).then_some(r)
    }

    /// Do the tile's rays test a list of its objects' boxes (at most
    /// [`OBJECT_LIST`] bounded objects), rather than walk the objects' tree?
    pub fn lists_objects(&self) -> bool {
        self.bounded.is_some()
    }
}

impl TileScratch {
    /// The view of the tile last prepared.
    pub fn view(&self) -> TileView<'_> {
        TileView {
            prog: &self.tp.prog,
            root_of: &self.root_of,
            bounded: self.listed.then_some(&self.boxes),
            unions: self.unions,
            kernels8: self.tp.kernels8(),
            meshes: self.tp.meshes(),
            simple: self.simple,
        }
    }

    /// What keeping the tile program's copy of the scene's program up to
    /// date cost so far (whole copies, edits replayed).
    pub fn follow_counts(&self) -> rothray_csg::FollowCounts {
        self.tp.follow_counts()
    }

    /// How many objects the current tile keeps.
    pub(crate) fn objects(&self) -> usize {
        self.live.len()
    }

    /// Counts a shadow bundle split in two (see [`TileStats::bundles_split`]).
    pub(crate) fn count_split(&mut self) {
        self.counts.bundles_split += 1;
    }

    /// The counts so far, reset.
    pub fn take_counts(&mut self) -> TileStats {
        let mut c = std::mem::take(&mut self.counts);
        c.spec = self.tp.take_counts();
        c
    }
}

impl RenderScene {
    /// Prepares the tile whose rays all lie in `region`: finds the objects they
    /// can meet and specialises their programs. Returns whether any object is
    /// left (when none, no ray of the tile hits anything).
    pub fn prepare_tile(&self, region: &Frustum, ts: &mut TileScratch) -> bool {
        self.prepare_tile_among(region, None, ts)
    }

    /// The bounded objects whose box and every ancestor box in the objects'
    /// tree `group` may touch, in the tree's order, into `out`: the
    /// candidates of [`RenderScene::prepare_tile_among`] for tiles inside
    /// `group`. Why: a tile's search of the objects' tree tested some 50
    /// boxes to keep one or two objects (benches/scenes/capsules: a tenth
    /// of its time flat, perf); tiles in a row share one search.
    pub(crate) fn objects_touched(&self, group: &Frustum, out: &mut GroupObjects) {
        out.clear();
        self.objects_cull().cull(|b| group.touches_box(b), |oi| out.ids.push(oi));
        out.make_rows(|oi| self.objects[oi as usize].bounds);
    }

    /// [`RenderScene::prepare_tile`], the bounded objects taken from
    /// `among` when given ([`RenderScene::objects_touched`] of a region
    /// holding `region`: every object whose box the tile's region touches
    /// is among them, in the tree's order) instead of the objects' tree.
    /// Each object's own box is tested against `region` as the tree's
    /// search leaves it to (`TileProgram::specialise`), so the objects kept
    /// are those the tile's own search keeps, in the same order, but any
    /// whose box the group's region does not touch: the box tests are
    /// conservative, and the tile's may pass a box just outside its
    /// pyramid that a plane of the group's cuts off; no ray of the tile
    /// meets such an object (the tile's rays are the group's).
    pub(crate) fn prepare_tile_among(&self, region: &Frustum, among: Option<&GroupObjects>, ts: &mut TileScratch) -> bool {
        ts.tp.begin(&self.program);
        // Only the last tile's objects have a root: resetting them leaves
        // `root_of` all NONE, whatever program or scene it was made for (a
        // sync that adds or removes objects costs it their number only).
        for &oi in &ts.live {
            ts.root_of[oi as usize] = NONE;
        }
        ts.live.clear();
        ts.root_of.resize(self.objects.len(), NONE);
        let TileScratch { tp, root_of, live, .. } = ts;
        let mut keep = |oi: u32| {
            let o = &self.objects[oi as usize];
            if let Some(r) = tp.specialise(&self.program, &self.leaves, o.root, region) {
                root_of[oi as usize] = r;
                live.push(oi);
            }
        };
        for &oi in self.unbounded_objects() {
            keep(oi);
        }
        match among {
            // (Those whose boxes the region misses would not be kept.)
            Some(objects) => objects.touched_by(region, &mut keep),
            None => self.objects_cull().cull(|b| region.touches_box(b), &mut keep),
        }
        // The unbounded objects kept come first.
        let unbounded = ts.live.iter().take_while(|&&oi| !self.objects[oi as usize].bounds.is_finite()).count();
        ts.listed = ts.live.len() - unbounded <= OBJECT_LIST;
        ts.boxes.clear();
        if ts.listed {
            // Nearest first from where the tile's rays start (`live` is
            // only a list of what to reset).
            ts.boxes.fill(region.origins(), ts.live[unbounded..].iter().map(|&oi| (self.objects[oi as usize].bounds, oi)));
        }
        ts.unions = ts.live.iter().any(|&oi| ts.tp.prog.walks_in_packets(ts.root_of[oi as usize]));
        ts.simple = ts.live.iter().all(|&oi| crate::packet_first::simple_root(&ts.tp.prog, &self.leaves, ts.root_of[oi as usize]));
        let TileScratch { live, counts, .. } = ts;
        counts.tiles += 1;
        counts.objects_kept += live.len() as u64;
        if live.is_empty() {
            counts.tiles_culled += 1;
        }
        !live.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::components::{Cuboid, Sphere, Transform};
    use crate::render::Camera;
    use glam::Vec3;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// A tile prepared among the objects a group of tiles holding it may
    /// meet keeps the objects its own search of the tree keeps, in the same
    /// order, but those no ray of the group can meet (the tests are
    /// conservative: the tile's may pass a box just outside its pyramid
    /// that the group's planes cut off), and its rays get the same hits:
    /// random scenes of 40 to 400 small and large objects, tiles and groups
    /// of random sizes seen from inside and outside the scene.
    #[test]
    fn tiles_among_a_groups_objects_keep_their_own() {
        let seed = 0x6a0u64;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut kept, mut dropped, mut hits) = (0, 0, 0);
        for case in 0..30 {
            let mut world = hecs::World::new();
            for _ in 0..rng.gen_range(40..400) {
                let at = Vec3::new(rng.gen_range(-6.0..6.0), rng.gen_range(-6.0..6.0), rng.gen_range(-6.0..6.0));
                let r = if rng.gen_bool(0.1) { rng.gen_range(1.0..3.0) } else { rng.gen_range(0.05..0.5) };
                if rng.gen_bool(0.5) {
                    world.spawn((Transform::from_translation(at), Sphere { center: Vec3::ZERO, radius: r }));
                } else {
                    world.spawn((Transform::from_translation(at), Cuboid { min: Vec3::splat(-r), max: Vec3::splat(r) }));
                }
            }
            let scene = RenderScene::from_world(&world).unwrap();
            let eye = if case % 3 == 0 { Vec3::ZERO } else { Vec3::new(rng.gen_range(-20.0..20.0), rng.gen_range(-5.0..5.0), 15.0) };
            let cam = Camera { eye, target: Vec3::new(0.3, -0.2, 0.1), up: Vec3::Y, fov_y_deg: rng.gen_range(20.0..90.0) };
            let (w, h) = (rng.gen_range(64..400u32), rng.gen_range(32..300u32));
            let rays = cam.rays(w, h);
            let (mut own, mut among) = (TileScratch::default(), TileScratch::default());
            let mut scratch = rothray_csg::Scratch::default();
            let mut group = GroupObjects::default();
            for _ in 0..40 {
                // A group, and a tile inside it.
                let (gx0, gy0) = (rng.gen_range(0..w as usize - 16), rng.gen_range(0..h as usize - 8));
                let (gx1, gy1) = (rng.gen_range(gx0 + 16..=w as usize), rng.gen_range(gy0 + 8..=h as usize));
                let (x0, y0) = (rng.gen_range(gx0..gx1 - 4), rng.gen_range(gy0..gy1 - 2));
                let (x1, y1) = (rng.gen_range(x0 + 4..=gx1), rng.gen_range(y0 + 2..=gy1));
                let g = rays.tile_region(gx0, gx1, gy0, gy1);
                scene.objects_touched(&g, &mut group);
                let region = rays.tile_region(x0, x1, y0, y1);
                let a = scene.prepare_tile(&region, &mut own);
                let b = scene.prepare_tile_among(&region, Some(&group), &mut among);
                let at = format!("case {case}: tile {x0}..{x1} x {y0}..{y1} of group {gx0}..{gx1} x {gy0}..{gy1}");
                // In the same order: each one further on in `own`; those
                // skipped there are out of the group's reach.
                let mut rest = own.live.iter().copied();
                for &oi in among.live.iter().chain([&u32::MAX]) {
                    for o in rest.by_ref() {
                        if o == oi {
                            break;
                        }
                        assert!(!g.touches_box(&scene.objects[o as usize].bounds), "{at}: object {o} dropped but the group touches it");
                        dropped += 1;
                    }
                }
                assert!(among.live.iter().all(|oi| own.live.contains(oi)), "{at}: an object kept only among the group's");
                assert!(a || !b, "{at}");
                kept += among.live.len();
                // The tile's rays hit the same.
                let (va, vb) = (own.view(), among.view());
                for _ in 0..20 {
                    let ray = rays.ray(rng.gen_range(x0 as f32..x1 as f32), rng.gen_range(y0 as f32..y1 as f32));
                    let ha = if a { scene.intersect_ray(&ray, &mut scratch, true, Some(&va)) } else { None };
                    let hb = if b { scene.intersect_ray(&ray, &mut scratch, true, Some(&vb)) } else { None };
                    assert_eq!(ha, hb, "{at}: {ray:?}");
                    hits += ha.is_some() as u32;
                }
            }
        }
        println!("{kept} objects kept, {dropped} dropped, {hits} hits");
        assert!(kept > 1000 && hits > 1000, "too few objects kept or hit to mean anything: {kept}, {hits}");
    }
}
