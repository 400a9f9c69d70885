//! The baked render scene (plain tables, no `Entity` in the hot path) and the
//! queries it answers on one ray: nearest hit, any hit, Roth spans, point
//! classification. The bake is in [`crate::bake`], the packet path in
//! `packet.rs`, the tile level in [`crate::tile`].

use std::cell::RefCell;

use glam::Vec3;
use hecs::Entity;
use rothray_csg::{first_surface, DeepFirst, Mode, Program, RayCtx, Scratch};
use rothray_primitives::{
    bvh::FlatBvh,
    ray::{scale_t, ScaledSink},
    Aabb, LeafTable, Span, SpanSink, Surf,
};

use crate::box_list::{entry, BoxList};
use crate::knobs::Knobs;
use crate::tile::TileView;

pub use rothray_primitives::Ray;

/// The nearest surface a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// Outward unit normal of the solid there.
    pub normal: Vec3,
    /// Index of the object (see [`RenderScene::objects`]).
    pub object: u32,
    /// Index of the leaf whose surface it is (see [`RenderScene::leaf_info`]).
    pub leaf: u32,
    /// Kind-specific sub-surface id.
    pub sub: u32,
}

/// What the scene knows about one top-level object.
#[derive(Clone, Debug)]
pub struct ObjectInfo {
    /// Its entity.
    pub entity: Entity,
    /// Its name (`Name`, else `object<i>`).
    pub name: String,
    /// Root node in the program.
    pub root: u32,
    /// Bounds.
    pub bounds: Aabb,
}

/// What the scene knows about one leaf.
#[derive(Clone, Debug)]
pub struct LeafInfo {
    /// Its entity.
    pub entity: Entity,
    /// Its `Name` (empty without one; [`RenderScene::leaf_name`] then
    /// gives `leaf<i>`).
    pub name: String,
    /// Its colour (own `Material`, else the nearest ancestor's, else grey).
    pub color: Vec3,
    /// Object it belongs to.
    pub object: u32,
}

/// The baked scene: SoA leaf table, CSG program, BVH over objects.
#[derive(Default)]
pub struct RenderScene {
    /// Every leaf, SoA.
    pub leaves: LeafTable,
    /// Every CSG tree.
    pub program: Program,
    /// Top-level objects in order.
    pub objects: Vec<ObjectInfo>,
    /// Per leaf: entity, name, colour, object.
    pub leaf_info: Vec<LeafInfo>,
    /// A binary tree over the bounded objects' boxes: for region queries (tiles) and
    /// for the objects along single rays (`RenderScene::visit_candidates`).
    pub(crate) objects_cull: FlatBvh,
    pub(crate) unbounded: Vec<u32>,
    /// Bounds of the finite objects.
    pub bounds: Aabb,
    /// Length tolerance of the scene (fusing coincident crossings).
    pub eps: f32,
    /// Centre of `bounds` (origin when empty): the tolerance grows with a ray's
    /// distance from it.
    pub(crate) center: Vec3,
    /// How many times [`crate::sync_scene`] rebuilt the tables.
    pub bake_count: u64,
    /// Accuracy knob of the swept-sphere and generalized-cylinder solvers, relative
    /// to each shape's size (default 1e-6; see `rothray bench --tolerances`).
    pub tolerance: f32,
    /// Per-approximation accuracy settings, read by the bake (`None`: defaults).
    pub knobs: Knobs,
    /// The fusing tolerance's growth per unit of a ray origin's distance from
    /// `center` (set by the bake, see [`RenderScene::ray_ctx`]).
    pub(crate) eps_far: f32,
    /// What [`crate::sync_scene`] keeps between syncs (`None` until it bakes).
    pub(crate) live: Option<Box<crate::live::LiveState>>,
    /// Mesh leaves that nearest-hit queries ask in nearest mode, traced ahead for
    /// whole packets by [`RenderScene::intersect_packet`] (empty when there are
    /// more than [`PACKET_MESHES`]).
    pub(crate) packet_meshes: Vec<u32>,
    /// Per object, a packet mesh that contains its whole solid (see
    /// [`containing_leaves`]), when every object has one: a ray whose packet
    /// found all of them empty on its range hits nothing and skips its own
    /// evaluation.
    pub(crate) packet_cover: Option<Vec<u32>>,
    /// Per object, how its unsure nearest queries are tried again.
    pub(crate) retry: Vec<Retry>,
    /// The packet shortcut (see [`Shortcut`]), for scenes with few leaves.
    pub(crate) shortcut: Option<crate::packet::Shortcut>,
    /// Packet queries go ray by ray (see [`RenderScene::set_ray_by_ray`]).
    pub(crate) ray_by_ray: bool,
    /// The renderer's workers between renders (see [`crate::workers`]).
    pub(crate) workers: crate::workers::WorkerPool,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// How an object's nearest queries go on when the first try is not sure
/// (made at bake: `bake::retry_of`).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Retry {
    /// The length past the unsure result that the full redo tries first (a
    /// tenth of the object's size when it holds a mesh; 0: none).
    pub window: f32,
    /// The root is a difference that the masked try helps
    /// (`Program::masks_help`): its queries take that try at once, not
    /// after a nearest-mode try that its cut entries would mostly leave
    /// unsure.
    pub masked_first: bool,
    /// The root's tree is narrow and of at most `DEEP_LEAVES` leaves: an
    /// unsure query tries the sweep of its crossings first
    /// (`Program::deep_first`).
    pub deep: bool,
}

/// Is `f`, the first surface of `spans`, a sure nearest answer when
/// `spans` are exact only up to `valid` (before the range's end)? Not
/// when there is none. Nor an exit (the ray starts inside) close to
/// `valid` (see `Program::eval`; found by a packet-against-single-ray
/// fuzz: a union's exit at its first operand's end while the second went
/// on). Nor an entry whose span was cut at `valid` after at most 2 eps:
/// a confirmed entry keeps 4 eps, so this span comes from operands asked
/// on a range cut there, and such cuts leave spans shorter than eps that
/// regularisation drops in one operand and not in another (a cone minus
/// a near twin of itself, asked on 1e-5 of the ray, kept its entry where
/// the full diagram has nothing:
/// `csg_oracle::near_twins_nearest_hits_are_first_surfaces`).
#[inline(always)]
fn sure(f: Option<(f32, Surf)>, spans: &[Span], valid: f32, eps: f32) -> bool {
    let Some((t, _)) = f else { return false };
    match spans.first() {
        Some(s) if s.s0.is_real() => s.s1.is_real() || s.t1 < valid || s.t1 - s.t0 > 2.0 * eps,
        _ => t < valid - 16.0 * eps,
    }
}

/// The first surface of a nearest query's result `spans` on a range ending
/// at `tmax`, exact up to `valid`, when it is sure ([`sure`], or exact on the
/// whole range); `None` when the query must be tried again.
#[inline(always)]
pub(crate) fn sure_first(spans: &[Span], (valid, tmax): (f32, f32), eps: f32) -> Option<Option<(f32, Surf)>> {
    let f = first_surface(spans);
    (!(valid < tmax) || sure(f, spans, valid, eps)).then_some(f)
}

/// Calls `f` with the objects of `cands` (box entry, object) in the order
/// of entry, then object, while entries stay within the limit (`limit`,
/// then what `f` returns): the order a sort gives, each next one picked
/// by a scan of the rest when there are many. A ray mostly stops after a
/// few (its first hit lowers the limit below the others' entries), and the
/// insertion sort of every candidate made `nearest_ctx` a quarter of the
/// cycles of benches/scenes/forest_objects (perf, one thread; a fifth with
/// the scans; callgrind 480x270 flat: -2.0% instructions there, +0.5% on
/// capsules and +0.8% on logo, whose lists are short).
#[inline(always)]
fn visit_in_order(cands: &mut [(f32, u32)], mut limit: f32, scratch: &mut Scratch, f: &mut impl FnMut(u32, &mut Scratch) -> f32) {
    // Entry as `total_cmp` orders it, then object: one integer compare.
    let key = |c: &(f32, u32)| rothray_csg::program::cand_key(c.1, c.0);
    // Few: sorted whole, in fewer steps than the scans take.
    let sorted = cands.len() <= 8;
    if sorted && cands.len() > 1 {
        cands.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }
    for i in 0..cands.len() {
        if !sorted {
            let (mut m, mut km) = (i, key(&cands[i]));
            for (j, c) in cands.iter().enumerate().skip(i + 1) {
                let kc = key(c);
                if kc < km {
                    (m, km) = (j, kc);
                }
            }
            cands.swap(i, m);
        }
        let (t0, oi) = cands[i];
        if t0 > limit {
            break;
        }
        limit = f(oi, scratch);
    }
}

/// An object as one query evaluates it: its root in a program (the baked one
/// or a tile's), and its index.
#[derive(Clone, Copy)]
pub(crate) struct ObjRef<'a> {
    pub(crate) prog: &'a Program,
    pub(crate) root: u32,
    pub(crate) oi: u32,
}

impl RenderScene {
    /// With `on`, packet queries ([`RenderScene::intersect_packet`], the
    /// renderer's camera and shadow packets) trace each ray alone: no packet
    /// walks of wide unions or meshes, no leaf solved for eight rays at once.
    /// The answers are the same bit for bit (tests/render_flat.rs); this is
    /// for measuring what the packets gain (`rothray bench --ray-by-ray`).
    /// Off after a bake; a [`crate::sync_scene`] keeps it.
    pub fn set_ray_by_ray(&mut self, on: bool) {
        self.ray_by_ray = on;
    }

    /// Turns off the whole pass of small trees (`Program::small_eval`):
    /// every tree goes through the evaluator's frames, in the caller's
    /// mode. For tests (the frame path is their oracle) and measurements;
    /// a live sync bakes changed rows with the pass on again.
    #[doc(hidden)]
    pub fn without_small_trees(&mut self) {
        self.program.small.fill(0);
    }

    /// Turns off the sweep of a tree's crossings for unsure nearest queries
    /// (`Program::deep_first`): they take the masked try and the redo in
    /// full as before. For tests of those (the sweep answers most of their
    /// rays) and measurements; a live sync bakes changed objects with the
    /// sweep on again.
    #[doc(hidden)]
    pub fn without_deep_sweeps(&mut self) {
        for r in self.retry.iter_mut() {
            r.deep = false;
        }
    }

    /// How many nodes of the baked program are small trees' roots (for tests).
    #[doc(hidden)]
    pub fn small_tree_roots(&self) -> usize {
        (0..self.program.kind.len()).filter(|&n| self.program.small_root(n)).count()
    }

    /// The world bounds of the leaves `leaves` (rows of the leaf table),
    /// read from their program nodes: the bake keeps the leaves' bounds
    /// there only.
    pub fn leaf_bounds(&self, leaves: &[u32]) -> Vec<Aabb> {
        let p = &self.program;
        let mut node_of = vec![u32::MAX; self.leaves.len()];
        for n in (0..p.kind.len()).filter(|&n| p.kind[n] == rothray_csg::NodeKind::Leaf) {
            node_of[p.first[n] as usize] = n as u32;
        }
        leaves.iter().map(|&l| p.bounds[node_of[l as usize] as usize]).collect()
    }

    /// The per-ray context: the fusing tolerance grows with the distance from the
    /// scene, since f32 rounding of the crossings does.
    #[inline]
    pub fn ray_ctx(&self, ray: &Ray) -> RayCtx<'static> {
        RayCtx::new(*ray, self.eps_at(ray.origin))
    }

    /// The tolerances of a packet's eight rays: the `eps` of the context
    /// [`RenderScene::ray_ctx`] gives each, the same bits. (The contexts
    /// themselves are made only for the lanes evaluated alone: copying the
    /// eight rays into them was some 65 instructions a packet, callgrind.)
    /// Plain loops, not `std::array::from_fn` (through it the eight were a
    /// call each where the compiler chose not to inline it: +1.2% wall on
    /// benches/scenes/tori flat). The lengths and divisions go lane after
    /// lane through arrays, so that the compiler does them four or eight at
    /// a time (a vector square root or division rounds each lane as the
    /// scalar one does): -1% wall on capsules and tori flat, one thread.
    #[inline(always)]
    pub(crate) fn eps8(&self, rays: &[Ray; 8]) -> [f32; 8] {
        let (mut far, mut dir) = ([0.0f32; 8], [0.0f32; 8]);
        for k in 0..8 {
            far[k] = (rays[k].origin - self.center).length();
            dir[k] = rays[k].dir.length();
        }
        let mut eps = [0.0f32; 8];
        for k in 0..8 {
            // `eps_at`, then `RayCtx::new`.
            eps[k] = self.eps_at_distance(far[k]) / dir[k];
        }
        eps
    }

    /// The length tolerance of rays from `o` (see [`RenderScene::ray_ctx`]).
    #[inline]
    pub(crate) fn eps_at(&self, o: Vec3) -> f32 {
        self.eps_at_distance((o - self.center).length())
    }

    /// [`RenderScene::eps_at`] of a point `far` from the scene's centre.
    #[inline(always)]
    fn eps_at_distance(&self, far: f32) -> f32 {
        self.eps + self.eps_far * if far.is_finite() { far } else { 0.0 }
    }

    /// True when every object has finite bounds (no half-space reaches infinity).
    pub fn all_bounded(&self) -> bool {
        self.unbounded.is_empty()
    }

    /// The objects without finite bounds.
    pub(crate) fn unbounded_objects(&self) -> &[u32] {
        &self.unbounded
    }

    /// A binary tree over the bounded objects' boxes (ids: object indices).
    pub(crate) fn objects_cull(&self) -> &FlatBvh {
        &self.objects_cull
    }

    /// Object index of an entity (a top-level object).
    pub fn object_of(&self, e: Entity) -> Option<u32> {
        self.objects.iter().position(|o| o.entity == e).map(|i| i as u32)
    }

    /// Nearest hit (uses a thread-local scratch).
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        SCRATCH.with(|s| self.intersect_with(ray, &mut s.borrow_mut()))
    }

    /// Is anything hit along the ray (shadow rays)?
    pub fn occluded(&self, ray: &Ray) -> bool {
        SCRATCH.with(|s| self.occluded_with(ray, &mut s.borrow_mut()))
    }

    /// First surface of object `oi` on `range` of `ctx`'s ray: `(t, surface)`.
    #[inline]
    pub(crate) fn object_first(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32), scratch: &mut Scratch) -> Option<(f32, Surf)> {
        let ObjRef { prog, root, oi } = obj;
        let (tmin, tmax) = range;
        // (The kind first: eval_in reads it anyway, and most roots are no
        // difference, which spares them the load of their window.)
        if prog.kind[root as usize] == rothray_csg::NodeKind::Difference && self.retry[oi as usize].masked_first {
            return self.masked_first(obj, ctx, range, scratch);
        }
        let valid = prog.eval_in(&self.leaves, root, ctx, range, Mode::Nearest, scratch);
        let Some(f) = sure_first(scratch.out.as_slice(), (valid, tmax), ctx.eps) else {
            if let DeepFirst::Sure(f) = self.deep_try(obj, ctx, range, scratch) {
                return f;
            }
            if prog.masks_help(root) {
                // A second try that sees past the cut entries before the
                // redo in full.
                if let Some(f) = self.masked_try(obj, ctx, range, scratch) {
                    return f;
                }
            }
            // Nothing sure before `valid` (a union's entry covered by another
            // operand, a mesh's first span cut away by a difference): redo in
            // full. With meshes, first up to a tenth of the object's size past
            // `valid` (their walks then collect only the crossings up to there).
            // Measured on scenes/bunny (callgrind, 480x270): 206.4e6 -> 200.7e6
            // instructions; windows of 0.05-0.25 gave 213e6-204e6.
            let w = self.retry[oi as usize].window;
            let t1 = if w > 0.0 { valid + w / ctx.ray.dir.length() } else { tmax };
            return self.redo(obj, ctx, (tmin, t1, tmax), scratch);
        };
        f
    }

    /// [`RenderScene::object_first`] of an object that takes the masked
    /// try at once ([`Retry::masked_first`]), redone in full when unsure.
    /// (Out of line: the common path of `object_first` keeps its code.)
    #[inline(never)]
    fn masked_first(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32), scratch: &mut Scratch) -> Option<(f32, Surf)> {
        if let DeepFirst::Sure(f) = self.deep_try(obj, ctx, range, scratch) {
            return f;
        }
        self.masked_try(obj, ctx, range, scratch).unwrap_or_else(|| self.redo(obj, ctx, (range.0, range.1, range.1), scratch))
    }

    /// The first surface of object `obj` on `range` from the sweep of its
    /// tree's crossings (`csg/src/deep_first.rs`), for an object whose tree
    /// it takes.
    fn deep_try(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32), scratch: &mut Scratch) -> DeepFirst {
        if !self.retry[obj.oi as usize].deep {
            return DeepFirst::Unknown;
        }
        let f = obj.prog.deep_first(&self.leaves, ctx, obj.root, range, scratch);
        rothray_csg::counts::deep_try(matches!(f, DeepFirst::Sure(_)));
        f
    }

    /// The first surface of object `obj` on `range` from the masked try
    /// (`csg/src/masked.rs`), when that is sure (`None`: not sure).
    fn masked_try(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32), scratch: &mut Scratch) -> Option<Option<(f32, Surf)>> {
        let ObjRef { prog, root, .. } = obj;
        let valid = prog.eval_masked((&self.leaves, ctx), root, range, scratch);
        let f = first_surface(scratch.out.as_slice());
        let done = valid >= range.1 || sure(f, scratch.out.as_slice(), valid, ctx.eps);
        rothray_csg::counts::masked_try(done);
        done.then_some(f)
    }

    /// The first surface of node `root` on `range = (tmin, t1, tmax)` from its full
    /// diagram: first over `[tmin, t1]`, accepted when that first surface is
    /// clear of `t1` (16 eps: clipping at `t1` changes the result only within a
    /// few eps of it, where boundaries fuse and short spans are dropped), else
    /// over the whole range.
    fn redo(&self, obj: ObjRef, ctx: &RayCtx, range: (f32, f32, f32), scratch: &mut Scratch) -> Option<(f32, Surf)> {
        let ObjRef { prog, root, .. } = obj;
        let (tmin, t1, tmax) = range;
        rothray_csg::counts::full_redo();
        if t1 < tmax {
            prog.eval_in(&self.leaves, root, ctx, (tmin, t1), Mode::All, scratch);
            if let Some((t, s)) = first_surface(scratch.out.as_slice()) {
                if t < t1 - 16.0 * ctx.eps {
                    return Some((t, s));
                }
            }
        }
        prog.eval_in(&self.leaves, root, ctx, (tmin, tmax), Mode::All, scratch);
        first_surface(scratch.out.as_slice())
    }

    /// Object `oi` as the rays of `tile` see it (`None`: they cannot meet it),
    /// or as baked without a tile.
    #[inline(always)]
    fn obj_ref<'a>(&'a self, oi: u32, tile: Option<&TileView<'a>>) -> Option<ObjRef<'a>> {
        match tile {
            Some(t) => t.root(oi).map(|root| ObjRef { prog: t.prog, root, oi }),
            None => Some(ObjRef { prog: &self.program, root: self.objects[oi as usize].root, oi }),
        }
    }

    /// Nearest hit with caller-provided scratch (no thread-local access).
    pub fn intersect_with(&self, ray: &Ray, scratch: &mut Scratch) -> Option<Hit> {
        self.intersect_ray(ray, scratch, true, None)
    }

    /// The nearest hit of any valid ray: one whose direction is out of the
    /// range the queries take as given ([`Ray::dir_rescale`]: a direction of
    /// 1e-24 gave no hit, its |d|^2 being 0 in f32) is traced scaled by a
    /// power of two, its t scaled back (`None` when that t is past f32).
    pub(crate) fn intersect_ray(&self, ray: &Ray, scratch: &mut Scratch, normals: bool, tile: Option<&TileView>) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        if let Some(k) = Ray::dir_rescale(ray.dir) {
            let h = self.intersect_ctx(&self.ray_ctx(&ray.rescaled(k)), scratch, normals, tile)?;
            let t = scale_t(h.t, k);
            return t.is_finite().then_some(Hit { t, ..h });
        }
        self.intersect_ctx(&self.ray_ctx(ray), scratch, normals, tile)
    }

    /// The nearest hit of the ray of `ctx` (objects as `tile` sees them).
    pub(crate) fn intersect_ctx(&self, ctx: &RayCtx, scratch: &mut Scratch, normals: bool, tile: Option<&TileView>) -> Option<Hit> {
        let (oi, t, s) = self.nearest_ctx(ctx, scratch, tile, None)?;
        Some(self.hit_at(&ctx.ray, oi, t, s, normals))
    }

    /// [`RenderScene::intersect_ctx`] before the hit is made: the object,
    /// `t` and surface of the nearest hit (a packet makes its lanes' hits,
    /// normals and all, once every lane has its answer). `listed`: the
    /// objects of the tile's list along the ray, as
    /// [`RenderScene::listed_candidates`] gives them, when the packet made
    /// them (see [`BoxList::packet_entries`]).
    #[inline]
    pub(crate) fn nearest_ctx(
        &self,
        ctx: &RayCtx,
        scratch: &mut Scratch,
        tile: Option<&TileView>,
        listed: Option<&mut Vec<(f32, u32)>>,
    ) -> Option<(u32, f32, Surf)> {
        let ray = &ctx.ray;
        let mut best_t = ray.tmax;
        // The best hit's object (`u32::MAX`: none yet) and surface, kept as
        // separate words: a `Surf` stored in two halves and read back whole
        // stalled on store forwarding (15% of this function's cycles on
        // benches/scenes/tori, perf).
        let (mut best_oi, mut best_leaf, mut best_sub) = (u32::MAX, 0u32, 0u32);
        let mut take = |oi: u32, (t, s): (f32, Surf), best_t: &mut f32| {
            if t < *best_t || best_oi == u32::MAX {
                *best_t = t;
                (best_oi, best_leaf, best_sub) = (oi, s.leaf, s.sub);
            }
        };
        // Objects in the same order with or without a tile, so that ties go
        // the same way: the unbounded ones by index, then the bounded ones
        // by box entry, then index.
        for &oi in &self.unbounded {
            let Some(obj) = self.obj_ref(oi, tile) else { continue };
            if let Some(hit) = self.object_first(obj, ctx, (ray.tmin, best_t), scratch) {
                take(oi, hit, &mut best_t);
            }
        }
        // Sorted by entry: no later box reaches the best hit.
        self.visit_candidates((ray, listed), tile, best_t, scratch, |oi, scratch| {
            if let Some(obj) = self.obj_ref(oi, tile) {
                if let Some(hit) = self.object_first(obj, ctx, (ray.tmin, best_t), scratch) {
                    take(oi, hit, &mut best_t);
                }
            }
            best_t
        });
        (best_oi != u32::MAX).then_some((best_oi, best_t, Surf { leaf: best_leaf, sub: best_sub }))
    }

    /// The hit of object `oi` at `t` on surface `s` (its normal made when
    /// `normals`, else zero).
    #[inline]
    pub(crate) fn hit_at(&self, ray: &Ray, oi: u32, t: f32, s: Surf, normals: bool) -> Hit {
        let leaf = s.leaf_index();
        let mut n = Vec3::ZERO;
        if normals {
            n = self.leaves.normal(leaf, s.sub, ray, t);
            if s.flipped() {
                n = -n;
            }
        }
        Hit { t, normal: n, object: oi, leaf, sub: s.sub }
    }

    /// Any-hit with caller-provided scratch.
    pub fn occluded_with(&self, ray: &Ray, scratch: &mut Scratch) -> bool {
        self.occluded_in(ray, scratch, None)
    }

    /// [`RenderScene::occluded_with`]; with `tile`, the ray (inside the region
    /// the tile was prepared for) evaluates the tile's programs, with the same
    /// answer.
    pub fn occluded_in(&self, ray: &Ray, scratch: &mut Scratch, tile: Option<&TileView>) -> bool {
        if !ray.is_valid() {
            return false;
        }
        if let Some(k) = Ray::dir_rescale(ray.dir) {
            // As in `intersect_ray`: the same line with a direction in range.
            return self.occluded_in(&ray.rescaled(k), scratch, tile);
        }
        self.occluded_ctx(&self.ray_ctx(ray), scratch, tile)
    }

    /// [`RenderScene::occluded_in`] for a ray in range (no rescale), with
    /// its context (which may carry a packet's memo).
    pub(crate) fn occluded_ctx(&self, ctx: &RayCtx, scratch: &mut Scratch, tile: Option<&TileView>) -> bool {
        self.occluded_listed(ctx, scratch, tile, None)
    }

    /// [`RenderScene::occluded_ctx`]; `listed` as for
    /// [`RenderScene::nearest_ctx`].
    pub(crate) fn occluded_listed(
        &self,
        ctx: &RayCtx,
        scratch: &mut Scratch,
        tile: Option<&TileView>,
        listed: Option<&mut Vec<(f32, u32)>>,
    ) -> bool {
        let ray = &ctx.ray;
        for &oi in &self.unbounded {
            let Some(obj) = self.obj_ref(oi, tile) else { continue };
            if self.object_first(obj, ctx, (ray.tmin, ray.tmax), scratch).is_some() {
                return true;
            }
        }
        let mut own = std::mem::take(&mut scratch.cands);
        own.clear();
        let cands = match tile {
            Some(TileView { bounded: Some(list), .. }) => Self::tile_candidates(ray, list, listed, &mut own),
            _ => {
                self.objects_cull.traverse(ray.origin, ray.inv_dir, ray.tmin, ray.tmax, |oi, _| {
                    if tile.is_none_or(|t| t.root(oi).is_some()) {
                        if let Some(t0) = entry(&self.objects[oi as usize].bounds, ray) {
                            own.push((t0, oi));
                        }
                    }
                    ray.tmax
                });
                &mut own
            }
        };
        let hit = cands
            .iter()
            .any(|&(_, oi)| self.obj_ref(oi, tile).is_some_and(|obj| self.object_first(obj, ctx, (ray.tmin, ray.tmax), scratch).is_some()));
        scratch.cands = own;
        hit
    }

    /// Calls `f(object, scratch)` for the bounded objects whose boxes the
    /// ray's range meets (among those the tile keeps), in the order of
    /// their box entries then indices, while the entry is at most the
    /// limit (`limit` at first, then what `f` returns). A tile's list is
    /// listed and sorted; the objects' tree is walked nearest box first
    /// ([`FlatBvh::visit_nearest`]), so a ray that hits early leaves the
    /// rest of its range unlisted (a 128x72 preview from inside 100 000
    /// objects listed every box along each ray).
    fn visit_candidates(
        &self,
        (ray, listed): (&Ray, Option<&mut Vec<(f32, u32)>>),
        tile: Option<&TileView>,
        limit: f32,
        scratch: &mut Scratch,
        mut f: impl FnMut(u32, &mut Scratch) -> f32,
    ) {
        if let Some(TileView { bounded: Some(list), .. }) = tile {
            let mut own = std::mem::take(&mut scratch.cands);
            let cands = Self::tile_candidates(ray, list, listed, &mut own);
            visit_in_order(cands, limit, scratch, &mut f);
            scratch.cands = own;
            return;
        }
        let mut queue = std::mem::take(&mut scratch.queue);
        let entry = |oi: u32| {
            if tile.is_some_and(|t| t.root(oi).is_none()) {
                return None;
            }
            entry(&self.objects[oi as usize].bounds, ray)
        };
        self.objects_cull.visit_nearest((ray.origin, ray.inv_dir, ray.tmin, ray.tmax), limit, &mut queue, entry, |oi, _| f(oi, scratch));
        scratch.queue = queue;
    }

    /// The objects of the tile's list along the ray: `listed` when the
    /// packet made them, else listed now into `own`.
    #[inline(always)]
    fn tile_candidates<'c>(
        ray: &Ray,
        list: &BoxList,
        listed: Option<&'c mut Vec<(f32, u32)>>,
        own: &'c mut Vec<(f32, u32)>,
    ) -> &'c mut Vec<(f32, u32)> {
        match listed {
            Some(l) => l,
            None => {
                Self::listed_candidates(ray, list, own);
                own
            }
        }
    }

    /// The objects of the tile's list whose boxes the ray's range meets,
    /// each with its box entry, in `out`: the same set as the objects' tree
    /// gives (its boxes contain their children's and the slab test is
    /// monotone in the box, so the tree never hides a box that
    /// [`Aabb::ray_range`] would accept). (Measured with callgrind at
    /// 480x270 on benches/scenes: capsules (300 objects, 2.8 per tile) spent
    /// a third of its instructions walking the objects' tree per ray.)
    fn listed_candidates(ray: &Ray, list: &BoxList, out: &mut Vec<(f32, u32)>) {
        out.clear();
        if list.len() == 1 {
            // One object needs no order, and its evaluation tests its own
            // box first: a ray that misses it gets nothing from it either way.
            out.push((ray.tmin, list.first_id()));
        } else {
            list.entries(ray, out);
        }
    }

    /// The Roth diagram of object `oi` along the ray, clipped to `[tmin, tmax]`.
    pub fn spans(&self, ray: &Ray, oi: u32) -> Vec<Span> {
        SCRATCH.with(|s| {
            let s = &mut *s.borrow_mut();
            if !ray.is_valid() || oi as usize >= self.objects.len() {
                return Vec::new();
            }
            // As in `intersect_ray`: a direction out of range is traced scaled.
            let k = Ray::dir_rescale(ray.dir);
            let ctx = self.ray_ctx(&k.map_or(*ray, |k| ray.rescaled(k)));
            self.program.eval(&self.leaves, self.objects[oi as usize].root, &ctx, Mode::All, s);
            let Some(k) = k else { return s.out.as_slice().to_vec() };
            let mut out = Vec::new();
            for sp in s.out.as_slice() {
                ScaledSink { out: &mut out, k }.push_span(*sp);
            }
            out
        })
    }

    /// The Roth diagram of the solid an entity stands for (an object).
    pub fn spans_of(&self, ray: &Ray, e: Entity) -> Vec<Span> {
        self.object_of(e).map(|oi| self.spans(ray, oi)).unwrap_or_default()
    }

    /// Is the point inside object `oi` (boundary included)?
    pub fn contains(&self, p: Vec3, oi: u32) -> bool {
        if oi as usize >= self.objects.len() || !p.is_finite() {
            return false;
        }
        SCRATCH.with(|s| self.program.contains(&self.leaves, self.objects[oi as usize].root, p, &mut s.borrow_mut()))
    }

    /// Is the point inside the object entity `e`?
    pub fn contains_entity(&self, p: Vec3, e: Entity) -> bool {
        self.object_of(e).map(|oi| self.contains(p, oi)).unwrap_or(false)
    }

    /// The objects containing `p`.
    pub fn classify(&self, p: Vec3) -> Vec<u32> {
        (0..self.objects.len() as u32).filter(|&oi| self.contains(p, oi)).collect()
    }

    /// Nearest hits of a bundle of rays (in parallel for large bundles).
    pub fn intersect_bundle(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len());
        if rays.len() < 256 {
            SCRATCH.with(|s| {
                let s = &mut *s.borrow_mut();
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    *o = self.intersect_with(r, s);
                }
            });
            return;
        }
        rays.par_chunks(64).zip(out.par_chunks_mut(64)).for_each_init(Scratch::default, |s, (rs, os)| {
            for (r, o) in rs.iter().zip(os.iter_mut()) {
                *o = self.intersect_with(r, s);
            }
        });
    }

    /// Any-hit of a bundle of rays.
    pub fn occluded_bundle(&self, rays: &[Ray], out: &mut [bool]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len());
        rays.par_chunks(64).zip(out.par_chunks_mut(64)).for_each_init(Scratch::default, |s, (rs, os)| {
            for (r, o) in rs.iter().zip(os.iter_mut()) {
                *o = self.occluded_with(r, s);
            }
        });
    }
}
