//! The tile level of the trace path: for the region of rays of one tile (a
//! [`Frustum`]), the objects they can meet and each object's program
//! specialised to the tile ([`TileProgram`]). The rays of the tile evaluate
//! those programs ([`TileView`]); objects the tile misses, bounded or not, cost
//! its rays nothing.

use rothray_csg::{Program, TileCounts, TileProgram};
use rothray_primitives::frustum::Frustum;

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
    /// What the specialisation did.
    pub spec: TileCounts,
}

impl TileStats {
    /// Adds `o` to these counts.
    pub fn add(&mut self, o: &TileStats) {
        self.tiles += o.tiles;
        self.tiles_culled += o.tiles_culled;
        self.objects_kept += o.objects_kept;
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
            simple: self.simple,
        }
    }

    /// What keeping the tile program's copy of the scene's program up to
    /// date cost so far (whole copies, edits replayed).
    pub fn follow_counts(&self) -> rothray_csg::FollowCounts {
        self.tp.follow_counts()
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
        self.objects_cull().cull(|b| region.touches_box(b), &mut keep);
        // The unbounded objects kept come first.
        let unbounded = ts.live.iter().take_while(|&&oi| !self.objects[oi as usize].bounds.is_finite()).count();
        ts.listed = ts.live.len() - unbounded <= OBJECT_LIST;
        ts.boxes.clear();
        if ts.listed {
            // By index (`live` is only a list of what to reset).
            ts.live[unbounded..].sort_unstable();
            for &oi in &ts.live[unbounded..] {
                ts.boxes.push(&self.objects[oi as usize].bounds, oi);
            }
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
