//! One tile of a picture: its camera rays in packets of eight through the
//! tile's programs, then, per light, the shadow rays of its hits as one bundle
//! through programs specialised to their own region (the box of their origins
//! swept towards the light), then the pixels.

use glam::{Vec3, Vec4};

use crate::light_order::{order_along_light, LightOrder};
use crate::packet::PacketScratch;
use crate::render::{hash2, shade, Aov, CameraRays, RenderSettings};
use crate::scene::{Hit, Ray, RenderScene};
use crate::tile::TileScratch;
use rothray_primitives::{frustum::Frustum, Aabb};

/// What every tile of a frame shares.
pub(crate) struct Frame<'a> {
    pub scene: &'a RenderScene,
    pub s: &'a RenderSettings,
    pub rays: CameraRays,
    pub spp: u32,
    /// Image width (pixels).
    pub w: usize,
    /// Flat pictures: the pixel of each leaf (see `render_impl`).
    pub flat: Option<Vec<[u8; 3]>>,
    /// Do the hits need normals?
    pub normals: bool,
    pub bg8: [u8; 3],
}

/// The rows of the picture one job writes (`rows` rows from image row `y0`).
pub(crate) struct Rows<'a> {
    pub y0: usize,
    pub rows: usize,
    pub out: &'a mut [u8],
    pub depth: Option<&'a mut [f32]>,
    pub lin: Option<&'a mut [Vec3]>,
}

/// Per-thread memory of the renderer, reused from tile to tile.
#[derive(Default)]
pub(crate) struct Worker {
    pub ps: PacketScratch,
    pub ts: TileScratch,
    /// The tile level of the shadow bundles.
    pub shadow_ts: TileScratch,
    pub shadows: u64,
    /// Per pixel of the tile (in packet order): its place, ray, hit, sums.
    px: Vec<(usize, usize)>,
    rays: Vec<Ray>,
    hits: Vec<Option<Hit>>,
    acc: Vec<Vec3>,
    dmin: Vec<f32>,
    /// Lit shading: base colour, light sum, shadow origin and facing normal per pixel.
    base: Vec<Vec3>,
    light: Vec<Vec3>,
    origin: Vec<Vec3>,
    facing: Vec<Vec3>,
    /// The pixels (in packet order) that cast a shadow ray to the light at hand.
    lit: Vec<usize>,
    /// Room for ordering `lit` ([`order_along_light`]).
    order: LightOrder,
    /// The objects a group of tiles may meet (see `render.rs`).
    pub group: crate::tile::GroupObjects,
}

impl Worker {
    /// Lays out the pixels of the tile `[x0, x1)` x rows `[0, rows)` in blocks
    /// of 4x2 (a packet each) into `blocks` (`(start, len)`), and, when the
    /// tile is shaded afterwards (`keep`), clears the per-pixel sums.
    fn layout(&mut self, x0: usize, x1: usize, rows: usize, blocks: &mut Vec<(usize, usize)>, keep: bool) {
        self.px.clear();
        blocks.clear();
        for r0 in (0..rows).step_by(2) {
            for bx in (x0..x1).step_by(4) {
                let (bw, bh) = ((x1 - bx).min(4), (rows - r0).min(2));
                blocks.push((self.px.len(), bw * bh));
                // Row by row (pixel `k` of the block is `(k / bw, k % bw)`:
                // two integer divisions a pixel, some 18 instructions).
                for r in r0..r0 + bh {
                    self.px.extend((bx..bx + bw).map(|x| (r, x)));
                }
            }
        }
        if !keep {
            return; // a flat picture writes its pixels as its packets finish
        }
        let n = self.px.len();
        self.acc.clear();
        self.acc.resize(n, Vec3::ZERO);
        self.dmin.clear();
        self.dmin.resize(n, f32::INFINITY);
        self.rays.resize(n, Ray::new(Vec3::ZERO, Vec3::Z));
        self.hits.resize(n, None);
    }
}

/// Renders the tile of columns `[x0, x1)` of `rows` into its pixels.
/// `among`: the objects a group of tiles holding this one may meet
/// ([`RenderScene::objects_touched`]), when the job found them.
pub(crate) fn render_tile(
    f: &Frame,
    wk: &mut Worker,
    rows: &mut Rows,
    (x0, x1): (usize, usize),
    among: Option<&crate::tile::GroupObjects>,
    blocks: &mut Vec<(usize, usize)>,
) {
    let (w, scene, s) = (f.w, f.scene, f.s);
    let (y0, nrows) = (rows.y0, rows.rows);
    if !scene.prepare_tile_among(&f.rays.tile_region(x0, x1, y0, y0 + nrows), among, &mut wk.ts) {
        fill_background(f, rows, x0, x1);
        return;
    }
    wk.layout(x0, x1, nrows, blocks, f.flat.is_none());
    let lit = s.aov == Aov::Shaded && !s.lights.is_empty();
    for si in 0..f.spp {
        let any = camera_rays(f, wk, rows, si, blocks);
        if f.flat.is_some() {
            return; // the pixels are written
        }
        if f.spp == 1 && !any {
            // Background only: the pixels are `bg8`, the depths stay infinite.
            fill_background(f, rows, x0, x1);
            return;
        }
        if lit {
            shade_lit(f, wk);
        } else {
            for k in 0..wk.px.len() {
                let smp = shade(scene, s, wk.hits[k]);
                wk.acc[k] += smp.rgb;
                wk.dmin[k] = wk.dmin[k].min(smp.depth);
            }
        }
    }
    let encode = crate::render::pixel_encoder(s.aov);
    for (k, &(r, x)) in wk.px.iter().enumerate() {
        let i = r * w + x;
        // (x / 1 is x: one sample skips the division.)
        let c = if f.spp == 1 { wk.acc[k] } else { wk.acc[k] / f.spp as f32 };
        rows.out[3 * i..3 * i + 3].copy_from_slice(&encode(c));
        if let Some(d) = rows.depth.as_deref_mut() {
            d[i] = wk.dmin[k];
        }
        if let Some(l) = rows.lin.as_deref_mut() {
            l[i] = c;
        }
    }
}

fn fill_background(f: &Frame, rows: &mut Rows, x0: usize, x1: usize) {
    if f.bg8 != [0; 3] {
        for r in 0..rows.rows {
            for px in rows.out[3 * (r * f.w + x0)..3 * (r * f.w + x1)].chunks_exact_mut(3) {
                px.copy_from_slice(&f.bg8);
            }
        }
    }
}

/// Pixel coordinates below this are whole f32 numbers, their sums with 1,
/// 2, 3 too (see `camera_rays`).
const PIXELS_EXACT: usize = 1 << 22;

/// Sample `si` of every pixel of the tile: camera rays in packets, hits (kept
/// for shading; a flat picture writes its pixels at once: copying the rays and
/// hits was 4% of a frame of scenes/bunny). Returns whether any ray hit.
fn camera_rays(f: &Frame, wk: &mut Worker, rows: &mut Rows, si: u32, blocks: &[(usize, usize)]) -> bool {
    let view = wk.ts.view();
    let y0 = rows.y0;
    let mut any = false;
    for &(start, np) in blocks {
        // Made by `ray8`, four at a time (filling a template array one by one
        // and reading it back stalled on store forwarding). Lanes past `np`
        // repeat the last pixel.
        let rs = if f.spp == 1 && np == 8 && y0 + wk.px[start].0 < PIXELS_EXACT && wk.px[start].1 < PIXELS_EXACT {
            // A whole block of 4x2 pixel centres, made in registers: the
            // scalar stores of the points' arrays, read back four at a time
            // by `ray8`, stalled on store forwarding (a fifth of its cycles
            // on benches/scenes/forest_deep flat, perf). The same numbers:
            // `(x + i) as f32` is `x as f32 + i` below 2^24.
            let (r, x) = wk.px[start];
            let xs = Vec4::splat(x as f32) + Vec4::new(0.0, 1.0, 2.0, 3.0) + Vec4::splat(0.5);
            let y = (y0 + r) as f32;
            f.rays.ray8_v([xs; 2], [Vec4::splat(y + 0.5), Vec4::splat((y + 1.0) + 0.5)])
        } else {
            let mut fx = [0.0f32; 8];
            let mut fy = [0.0f32; 8];
            for k in 0..8 {
                let (r, x) = wk.px[start + k.min(np - 1)];
                let y = y0 + r;
                let (jx, jy) = if f.spp == 1 {
                    (0.5, 0.5)
                } else {
                    let rr = hash2((y * f.w + x) as u32, si);
                    ((rr & 0xffff) as f32 / 65536.0, (rr >> 16) as f32 / 65536.0)
                };
                (fx[k], fy[k]) = (x as f32 + jx, y as f32 + jy);
            }
            f.rays.ray8(&fx, &fy)
        };
        let mut hits = [None; 8];
        f.scene.intersect_packet_with(&rs[..np], &mut wk.ps, &mut hits, f.normals, Some(&view));
        let hit = hits[..np].iter().any(Option::is_some);
        any |= hit;
        if let Some(flat) = &f.flat {
            for k in 0..np {
                let (r, x) = wk.px[start + k];
                let i = r * f.w + x;
                let c = hits[k].map_or(f.bg8, |h| flat[h.leaf as usize]);
                if hit || f.bg8 != [0; 3] {
                    rows.out[3 * i..3 * i + 3].copy_from_slice(&c);
                }
            }
            continue;
        }
        wk.rays[start..start + np].copy_from_slice(&rs[..np]);
        wk.hits[start..start + np].copy_from_slice(&hits[..np]);
    }
    any
}

/// The shaded picture with lights: what `shade` computes per hit, with the
/// shadow rays of each light traced as one bundle through programs
/// specialised to their region (same operations in the same order, so the
/// same pixels).
fn shade_lit(f: &Frame, wk: &mut Worker) {
    let (scene, s) = (f.scene, f.s);
    let n = wk.px.len();
    // Written in place, one pass per step (pushed one by one onto cleared
    // arrays, their length checks and moves were about 100 instructions a
    // pixel of benches/scenes/capsules lit, callgrind).
    for v in [&mut wk.base, &mut wk.light, &mut wk.origin, &mut wk.facing] {
        v.resize(n, Vec3::ZERO);
    }
    let ambient = Vec3::splat(s.ambient);
    let per_px = wk.rays[..n].iter().zip(&wk.hits[..n]).zip(wk.base[..n].iter_mut().zip(&mut wk.light[..n]));
    for (((ray, hit), (base, light)), (origin, facing)) in per_px.zip(wk.origin[..n].iter_mut().zip(&mut wk.facing[..n])) {
        (*base, *origin, *facing) = match hit {
            None => (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO),
            Some(h) => {
                // Face the viewer (a ray that starts inside a solid sees its inner side).
                let nf = if h.normal.dot(ray.dir) > 0.0 { -h.normal } else { h.normal };
                let p = ray.origin + ray.dir * h.t;
                let off = (scene.eps * 20.0).max(1e-4 * (1.0 + p.abs().max_element()));
                (scene.leaf_info[h.leaf as usize].color, p + nf * off, nf)
            }
        };
        *light = ambient;
    }
    for l in &s.lights {
        let to_l = -l.direction.normalize_or_zero();
        // The shadow rays of this light: hits whose surface faces it, and
        // the box of their origins.
        wk.lit.clear();
        for (k, (hit, facing)) in wk.hits[..n].iter().zip(&wk.facing[..n]).enumerate() {
            if hit.is_some() && facing.dot(to_l) > 0.0 {
                wk.lit.push(k);
            }
        }
        if wk.lit.is_empty() {
            continue;
        }
        wk.shadows += wk.lit.len() as u64;
        let mut lit = std::mem::take(&mut wk.lit);
        shadow_bundle(scene, wk, &mut lit, (l.color, to_l));
        wk.lit = lit;
    }
    let per_px = wk.hits[..n].iter().zip(wk.base[..n].iter().zip(&wk.light[..n]));
    for ((hit, (base, light)), (acc, dmin)) in per_px.zip(wk.acc[..n].iter_mut().zip(&mut wk.dmin[..n])) {
        let (rgb, depth) = match hit {
            None => (s.background, f32::INFINITY),
            Some(h) => (*base * *light, h.t),
        };
        *acc += rgb;
        *dmin = dmin.min(depth);
    }
}

/// The shadow rays `lit` (pixels of the tile, at least one) towards a
/// light of colour `color` in direction `to_l` as one bundle, through
/// programs specialised to the box of their origins swept towards the
/// light: each
/// pixel whose ray is not blocked takes the light. A bundle whose region
/// meets too many objects to list them goes as two halves, each with its
/// own region (in the order across the light, so each half's region is
/// smaller), when it meets at most [`SPLIT_OBJECTS`]: unlisted, each ray
/// searched the objects' tree alone (capsules3000 at 480x270, where a
/// third of the shadow rays were in such bundles: 64% of the shadow rays'
/// instructions, callgrind).
fn shadow_bundle(scene: &RenderScene, wk: &mut Worker, lit: &mut [usize], (color, to_l): (Vec3, Vec3)) {
    let mut region = Aabb::EMPTY;
    for &k in lit.iter() {
        region.grow(wk.origin[k]);
    }
    if !scene.prepare_tile(&Frustum::sweep(&region, to_l), &mut wk.shadow_ts) {
        for &k in lit.iter() {
            wk.light[k] += color * wk.facing[k].dot(to_l);
        }
        return;
    }
    let unlisted = wk.shadow_ts.view().bounded.is_none();
    if unlisted && lit.len() > SPLIT_MIN && wk.shadow_ts.objects() <= SPLIT_OBJECTS {
        wk.shadow_ts.count_split();
        order_along_light(lit, &wk.origin, to_l, &mut wk.order);
        // (Whole packets in the first half.)
        let (a, b) = lit.split_at_mut((lit.len() / 2).div_ceil(8) * 8);
        for half in [a, b] {
            shadow_bundle(scene, wk, half, (color, to_l));
        }
        return;
    }
    let view = wk.shadow_ts.view();
    // (Only where a wide union is walked in packets, or many objects
    // are listed: there a packet's cost grows with the children or
    // objects any of its lanes meets. Elsewhere the order changed
    // nothing but its own cost: capsules +1.3% instructions lit.)
    if view.unions || view.bounded.is_some_and(|b| b.len() >= ORDER_OBJECTS) {
        order_along_light(lit, &wk.origin, to_l, &mut wk.order);
    }
    // In packets of eight (parallel rays from the tile's hits: the tile's
    // wide unions are walked once per packet). One ray made, the others
    // its copies from their own origins: the same rays without their
    // three divisions each (`Ray::new`: some 40 instructions a shadow
    // ray of benches/scenes/forest lit, callgrind).
    let proto = Ray::new(Vec3::ZERO, to_l);
    for chunk in lit.chunks(8) {
        let mut rays = [proto; 8];
        for (r, &k) in rays.iter_mut().zip(chunk) {
            r.origin = wk.origin[k];
        }
        let rays = &rays[..chunk.len()];
        let mut blocked = [false; 8];
        scene.occluded_packet(rays, &mut wk.ps, &mut blocked, Some(&view));
        for (&k, _) in chunk.iter().zip(blocked).filter(|(_, b)| !b) {
            wk.light[k] += color * wk.facing[k].dot(to_l);
        }
    }
}

/// A shadow bundle of more rays than this is split when its region meets
/// too many objects to list, but at most this many objects (then its
/// halves are likely to be listed; [`shadow_bundle`]). Where a bundle
/// meets more, its halves were unlisted too, and each prepared its
/// objects again for nothing: capsules3000 at 128x72 lit took 46% longer
/// splitting at any count, 2% less up to 512 (one thread, medians of 7;
/// 256x144 -12%, 480x270 -16%).
const SPLIT_MIN: usize = 16;
const SPLIT_OBJECTS: usize = 2 * crate::tile::OBJECT_LIST;

/// From this many objects listed, a shadow bundle's rays are ordered
/// ([`order_along_light`]): capsules3000 (`benches/scenes/gen.py --out DIR
/// capsules3000`, some 55 objects a shadow bundle) solved 13% fewer leaves
/// for its shadow packets and took 1.4% less time lit (one thread
/// 1920x1080, four alternating rounds), forest_objects4 1.8% less.
const ORDER_OBJECTS: usize = 32;
