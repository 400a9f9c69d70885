//! Pinhole camera, Lambert shading with shadow rays, AOVs, parallel tiles.

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Vec3, Vec4};
use rayon::prelude::*;
use rothray_csg::{take_eval_counts, EvalCounts};

use crate::part::Part;
use crate::render_tile::{render_tile, Frame, Rows};
use crate::scene::{Hit, Ray, RenderScene};
use crate::tile::TileStats;
use rothray_primitives::frustum::Frustum;

/// Pinhole camera of the scene format.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye point.
    pub eye: Vec3,
    /// Point looked at (the image centre).
    pub target: Vec3,
    /// Up hint.
    pub up: Vec3,
    /// Full vertical field of view, degrees.
    pub fov_y_deg: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera { eye: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 }
    }
}

/// A camera prepared for one image size.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    eye: Vec3,
    fwd: Vec3,
    right: Vec3,
    up: Vec3,
    w: f32,
    h: f32,
}

/// `v` normalised in f32 while its squared length is in f32's normal range,
/// else `v64()` normalised in f64: the square of a view 1e20 long overflows
/// f32 (its direction fell back to -z), that of one 1e-20 long underflows.
/// `fallback` for a zero vector.
fn unit(v: Vec3, v64: impl Fn() -> glam::DVec3, fallback: Vec3) -> Vec3 {
    if (1e-30..=1e30).contains(&v.length_squared()) {
        return v.normalize();
    }
    v64().try_normalize().map_or(fallback, |u| u.as_vec3())
}

impl Camera {
    /// Prepares ray generation for a `width` x `height` image.
    pub fn rays(&self, width: u32, height: u32) -> CameraRays {
        let fwd = unit(self.target - self.eye, || self.target.as_dvec3() - self.eye.as_dvec3(), Vec3::NEG_Z);
        // A unit up: the parallel test below is then on a sine (an up 1e-10
        // long was taken as parallel to every view).
        let mut right = fwd.cross(unit(self.up, || self.up.as_dvec3(), Vec3::Y));
        if right.length_squared() < 1e-12 {
            right = fwd.any_orthonormal_vector();
        }
        let right = right.normalize();
        let up = right.cross(fwd);
        let th = (self.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = width as f32 / height as f32;
        CameraRays { eye: self.eye, fwd, right: right * th * aspect, up: up * th, w: width as f32, h: height as f32 }
    }
}

impl CameraRays {
    /// The ray through image point `(x, y)` in pixels (y down; pixel centres at +0.5).
    /// Its direction is unit length, so t is a distance.
    #[inline]
    pub fn ray(&self, x: f32, y: f32) -> Ray {
        let u = 2.0 * x / self.w - 1.0;
        let v = 1.0 - 2.0 * y / self.h;
        Ray::new(self.eye, (self.fwd + self.right * u + self.up * v).normalize())
    }

    /// [`ray`](Self::ray) for eight image points, four lanes at a time: per lane
    /// the same operations in the same order (so the same bits), with one
    /// vector square root and division per four rays instead of one each.
    pub fn ray8(&self, x: &[f32; 8], y: &[f32; 8]) -> [Ray; 8] {
        let half = |v: &[f32; 8], h: usize| Vec4::from_slice(&v[4 * h..4 * h + 4]);
        self.ray8_v([half(x, 0), half(x, 1)], [half(y, 0), half(y, 1)])
    }

    /// [`ray8`](Self::ray8) of the points given four to a vector.
    #[inline]
    pub fn ray8_v(&self, x: [Vec4; 2], y: [Vec4; 2]) -> [Ray; 8] {
        let mut d = [Vec3::ZERO; 8];
        for h in 0..2 {
            let (xs, ys) = (x[h], y[h]);
            let u = Vec4::splat(2.0) * xs / Vec4::splat(self.w) - Vec4::ONE;
            let v = Vec4::ONE - Vec4::splat(2.0) * ys / Vec4::splat(self.h);
            let comp = |a: usize| Vec4::splat(self.fwd[a]) + Vec4::splat(self.right[a]) * u + Vec4::splat(self.up[a]) * v;
            let (dx, dy, dz) = (comp(0), comp(1), comp(2));
            // `Vec3::normalize`: times 1 / sqrt(x*x + y*y + z*z).
            let r = Vec4::ONE / (dx * dx + dy * dy + dz * dz).sqrt();
            let (nx, ny, nz) = (dx * r, dy * r, dz * r);
            for l in 0..4 {
                d[4 * h + l] = Vec3::new(nx[l], ny[l], nz[l]);
            }
        }
        d.map(|d| Ray::new(self.eye, d))
    }
}

/// A directional light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// The way the light travels.
    pub direction: Vec3,
    /// Linear RGB.
    pub color: Vec3,
}

/// Which picture to make.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aov {
    /// Lambert shading with shadows.
    Shaded,
    /// Distance along the (unit) camera ray: white near, black far (8-bit grey, scaled to the image's range).
    Depth,
    /// World normal mapped as `0.5 + 0.5 n`.
    Normal,
    /// A flat colour per leaf ([`leaf_id_color`]).
    Id,
}

/// Render settings.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel (1: the pixel centre; more: jittered, averaged).
    pub spp: u32,
    /// Picture kind.
    pub aov: Aov,
    /// Background (linear RGB).
    pub background: Vec3,
    /// Lights.
    pub lights: Vec<Light>,
    /// Ambient term.
    pub ambient: f32,
    /// Which rows to render ([`Part::WHOLE`]: all of them); see [`render_raw`].
    pub part: Part,
}

/// The flat colour of leaf `i` in the `id` AOV (shared with `tools/scene2pov.py`):
/// `h = (i + 1) * 2654435761 mod 2^32`, colour = bytes 3, 2, 1 of h.
pub fn leaf_id_color(i: u32) -> [u8; 3] {
    let h = (i.wrapping_add(1)).wrapping_mul(2654435761);
    [(h >> 24) as u8, (h >> 16) as u8, (h >> 8) as u8]
}

fn srgb(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.0031308 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// The sRGB encoding of the shaded picture, through a 4096-entry table (`powf`
/// per channel was ~0.1 s of a 1920x1080 frame, more than tracing the logo
/// scene's rays).
fn srgb_table() -> &'static [u8; 4096] {
    static LUT: std::sync::OnceLock<[u8; 4096]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb(i as f32 / 4095.0)))
}

/// A linear colour as the 8-bit sRGB pixel of the shaded picture.
pub fn encode_srgb(c: Vec3) -> [u8; 3] {
    srgb_from(srgb_table(), c)
}

/// [`encode_srgb`] through the table `lut` (looked up once per tile, not
/// per pixel: the call, the table's `OnceLock` and the bounds checks were
/// 5% of the cycles of benches/scenes/ground lit, perf).
#[inline(always)]
fn srgb_from(lut: &[u8; 4096], c: Vec3) -> [u8; 3] {
    #[cfg(target_arch = "x86_64")]
    {
        // The three channels at once in SSE2, the same indices as below: a
        // NaN is clamped to 0 here (MAXPS returns its second operand) and
        // converts to index 0 there; the conversion needs no saturation.
        // (Channel by channel, the saturating conversions made the encoding
        // 14% of the shading loop's cycles on benches/scenes/ground lit, perf.)
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of x86_64.
        let i = unsafe {
            let v = _mm_min_ps(_mm_max_ps(_mm_setr_ps(c.x, c.y, c.z, 0.0), _mm_setzero_ps()), _mm_set1_ps(1.0));
            let i = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(v, _mm_set1_ps(4095.0)), _mm_set1_ps(0.5)));
            let mut o = [0i32; 4];
            _mm_storeu_si128(o.as_mut_ptr() as *mut __m128i, _mm_and_si128(i, _mm_set1_epi32(4095)));
            o
        };
        [lut[i[0] as usize & 4095], lut[i[1] as usize & 4095], lut[i[2] as usize & 4095]]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        // In 0..=4095 (a NaN converts to 0): the mask keeps it so and drops
        // the bounds check.
        let q = |x: f32| lut[(x.clamp(0.0, 1.0) * 4095.0 + 0.5) as usize & 4095];
        [q(c.x), q(c.y), q(c.z)]
    }
}

/// [`encode_pixel`] for `aov`, with what it needs looked up once.
pub(crate) fn pixel_encoder(aov: Aov) -> impl Fn(Vec3) -> [u8; 3] {
    let lut = srgb_table();
    move |c| if aov == Aov::Shaded { srgb_from(lut, c) } else { encode_pixel(aov, c) }
}

/// The 8-bit pixel of a colour of `aov` other than depth, as `render` writes
/// it (sRGB for the shaded picture, linear for normal and id).
pub fn encode_pixel(aov: Aov, c: Vec3) -> [u8; 3] {
    match aov {
        Aov::Shaded => encode_srgb(c),
        _ => {
            let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            [q(c.x), q(c.y), q(c.z)]
        }
    }
}

/// The depth picture: grey from each pixel's distance, scaled to the finite
/// range of the whole image (white near, black far and for no surface).
pub fn encode_depth(depth: &[f32], out: &mut [u8]) {
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for &d in depth {
        if d.is_finite() {
            lo = lo.min(d);
            hi = hi.max(d);
        }
    }
    let span = (hi - lo).max(1e-6);
    for (i, &d) in depth.iter().enumerate() {
        let g = if d.is_finite() { (255.0 * (1.0 - 0.85 * (d - lo) / span)) as u8 } else { 0 };
        out[i * 3..i * 3 + 3].copy_from_slice(&[g, g, g]);
    }
}

/// The pixels of one part before they are encoded ([`render_raw`]).
#[derive(Clone, Debug, Default)]
pub struct RawPixels {
    /// The image rows held, increasing ([`Part::rows`]).
    pub rows: Vec<usize>,
    /// The tile size (width, height) it was rendered with ([`tile_size`]):
    /// a part holds whole rows of tiles.
    pub tile: (usize, usize),
    /// Linear colour per pixel of those rows, row by row (empty for depth).
    pub rgb: Vec<Vec3>,
    /// Distance per pixel (infinite: no surface); only for the depth picture.
    pub depth: Vec<f32>,
    /// Counters.
    pub stats: RenderStats,
}

/// Counters of a render.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    /// Camera rays traced.
    pub primary_rays: u64,
    /// Shadow rays traced.
    pub shadow_rays: u64,
    /// What the tile level skipped.
    pub tiles: TileStats,
    /// What the CSG evaluation did (camera and shadow rays).
    pub eval: EvalCounts,
}

#[inline]
pub(crate) fn hash2(a: u32, b: u32) -> u32 {
    let mut h = a.wrapping_mul(0x9E37_79B1) ^ b.wrapping_mul(0x85EB_CA77);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297A_2D39);
    h ^ (h >> 15)
}

pub(crate) struct Sample {
    pub rgb: Vec3,
    pub depth: f32,
}

/// One sample of a picture that casts no shadow rays: the AOVs, and the
/// shaded picture without lights (with lights: `render_tile::shade_lit`,
/// which traces a tile's shadow rays as bundles).
pub(crate) fn shade(scene: &RenderScene, s: &RenderSettings, hit: Option<Hit>) -> Sample {
    let Some(h) = hit else {
        // AOVs keep black for "no surface" so they can be read back (leaf ids, normals).
        let bg = if s.aov == Aov::Shaded { s.background } else { Vec3::ZERO };
        return Sample { rgb: bg, depth: f32::INFINITY };
    };
    let rgb = match s.aov {
        Aov::Id => {
            let c = leaf_id_color(h.leaf);
            Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / 255.0
        }
        Aov::Normal => h.normal * 0.5 + 0.5,
        Aov::Depth => Vec3::ZERO,
        Aov::Shaded => {
            debug_assert!(s.lights.is_empty(), "lit pictures are shaded by render_tile::shade_lit");
            scene.leaf_info[h.leaf as usize].color * Vec3::splat(s.ambient)
        }
    };
    Sample { rgb, depth: h.t }
}

/// Tiles of a row that share one search of the objects' tree (see
/// `render_impl`), and the fewest objects for which they do. With groups
/// of 8 tiles, benches/scenes/capsules (300 objects) took 8.5% less time
/// flat and 3% lit, forest_objects (10 001) 3.5% (one thread, 1920x1080,
/// three alternating rounds); 4 and 16 tiles were within 1-2% of 8. Scenes
/// of a few objects (gear, polytopes) search a tree of a few nodes.
const GROUP_TILES: usize = 8;
const GROUP_OBJECTS: usize = 16;

/// Tile size in pixels (width, height): the rays of a tile share one
/// specialised program (see `crate::tile`). `ROTHRAY_TILE=WxH` overrides it
/// for measurements. Chosen by callgrind at 480x270, one thread (forest,
/// logo, a 12-tooth gear, 300 capsules, in 1e6 instructions): 8x8 1542, 205,
/// 193, 441; 16x4 1535, 207, 198, 440; 16x8 1514, 205, 197, 442; 32x16 1502,
/// 209, 215, 472; 64x32 1508, 213, 236, 512.
const TILE: (usize, usize) = (16, 8);

/// Scenes of this many leaves or more take bigger tiles ([`tile_size_for`]).
const BIG_SCENE_LEAVES: usize = 4096;

/// The tiles of a whole render of a big scene ([`tile_size_for`]).
const BIG_TILE: (usize, usize) = (32, 16);

/// The tile size in use (width, height): 16x8, or `ROTHRAY_TILE=WxH` (for measurements).
/// Split renders deal out whole rows of tiles of this height (chunks, see
/// [`Part`]); [`tile_size_for`] widens the tiles of big scenes.
pub fn tile_size() -> (usize, usize) {
    tile_override().unwrap_or(TILE)
}

/// `ROTHRAY_TILE=WxH`, when set and valid.
fn tile_override() -> Option<(usize, usize)> {
    let parse = |v: String| -> Option<(usize, usize)> {
        let (a, b) = v.split_once('x')?;
        let (w, h): (usize, usize) = (a.parse().ok()?, b.parse().ok()?);
        (w >= 4 && h >= 2 && w % 4 == 0 && h % 2 == 0).then_some((w, h))
    };
    std::env::var("ROTHRAY_TILE").ok().and_then(parse)
}

/// The tile size a render of `part` of `scene` uses: [`tile_size`], but
/// 32x16 for a whole render of a scene of 4096 leaves or more, and 32x8 for
/// a part of one (a part's chunks stay [`tile_size`]'s rows: interleaved,
/// a part's rows are not 16 in a row). `ROTHRAY_TILE` overrides both.
///
/// Why: a tile pays for finding what its region meets in the scene's trees
/// and for specialising programs to it, which grows with the scene, while
/// each of its rays saves work only where the smaller region prunes more.
/// On the forests of 10 000 and 20 000 leaves 32x16 tiles took 5-13% less
/// time flat and 3-10% lit, and 32x8 tiles 1-7% (benches/scenes/forest,
/// forest_cut, forest_objects, 1920x1080, medians of 7 in three alternating
/// rounds of `ROTHRAY_TILE=WxH rothray bench S --width 1920 --height 1080
/// --repeats 7 [--no-shadows]`); scenes of 1000 leaves or fewer (cheese,
/// capsules, gear, mesh_mold) lost up to 5% with them.
pub fn tile_size_for(scene: &RenderScene, part: Part) -> (usize, usize) {
    if let Some(t) = tile_override() {
        return t;
    }
    if scene.leaves.len() < BIG_SCENE_LEAVES {
        return TILE;
    }
    if part == Part::WHOLE {
        BIG_TILE
    } else {
        (BIG_TILE.0, TILE.1)
    }
}

impl CameraRays {
    /// The (unnormalised) direction through image point `(x, y)`, as in
    /// [`CameraRays::ray`].
    fn dir(&self, x: f32, y: f32) -> Vec3 {
        let u = 2.0 * x / self.w - 1.0;
        let v = 1.0 - 2.0 * y / self.h;
        self.fwd + self.right * u + self.up * v
    }

    /// The region of every ray through the pixels `[x0, x1) x [y0, y1)`
    /// (jittered samples included).
    pub(crate) fn tile_region(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> Frustum {
        let (x0, x1, y0, y1) = (x0 as f32, x1 as f32, y0 as f32, y1 as f32);
        Frustum::pyramid(self.eye, [self.dir(x0, y0), self.dir(x1, y0), self.dir(x1, y1), self.dir(x0, y1)])
    }
}

/// Renders into an RGB8 buffer (`width * height * 3`, rows top to bottom).
/// `progress(done_rows, total_rows)` is called as rows finish (from any thread).
/// With `s.part` other than [`Part::WHOLE`] the buffer holds only that part's
/// rows (and the depth picture is left unencoded: its scale needs the whole image).
pub fn render(scene: &RenderScene, cam: &Camera, s: &RenderSettings, progress: &(dyn Fn(usize, usize) + Sync)) -> (Vec<u8>, RenderStats) {
    let (out, _, _, stats) = render_impl(scene, cam, s, progress, false);
    (out, stats)
}

/// The rows of `s.part` before encoding: what `rothray render --tile` keeps.
/// Encoding them with [`encode_pixel`] / [`encode_depth`] gives, bit for bit,
/// the bytes of [`render`] (same chunks, packets and jitter).
pub fn render_raw(scene: &RenderScene, cam: &Camera, s: &RenderSettings, progress: &(dyn Fn(usize, usize) + Sync)) -> RawPixels {
    let (_, rgb, depth, stats) = render_impl(scene, cam, s, progress, true);
    let tile = tile_size_for(scene, s.part);
    RawPixels { rows: s.part.rows(s.height as usize, tile.1), tile, rgb, depth, stats }
}

fn render_impl(
    scene: &RenderScene,
    cam: &Camera,
    s: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
    raw: bool,
) -> (Vec<u8>, Vec<Vec3>, Vec<f32>, RenderStats) {
    let w = s.width as usize;
    let (tile_w, rows) = tile_size_for(scene, s.part);
    // Only the part's chunks (rows of tiles) are rendered, into buffers of the part's rows.
    let chunk_ids = s.part.chunks(s.height as usize, rows);
    let h = s.part.rows(s.height as usize, rows).len();
    let rays = cam.rays(s.width, s.height);
    let spp = s.spp.max(1);
    // Pixels go straight into the 8-bit image: no float frame buffer (allocating
    // and filling 33 MB of them at 1920x1080 was 17 ms of an 85 ms frame of
    // scenes/bunny, measured with a camera that sees nothing). Only the depth
    // picture keeps floats, for its range.
    let mut out = vec![0u8; w * h * 3];
    let want_depth = s.aov == Aov::Depth;
    let mut depth = if want_depth { vec![f32::INFINITY; w * h] } else { Vec::new() };
    let done = AtomicUsize::new(0);
    let shadow_total = AtomicUsize::new(0);
    let tile_total = std::sync::Mutex::new((TileStats::default(), EvalCounts::default()));
    let _ = take_eval_counts(); // this thread's earlier queries are not the render's
    let bg = if s.aov == Aov::Shaded { s.background } else { Vec3::ZERO };
    let encode = pixel_encoder(s.aov);
    let bg8 = encode(bg);
    // Raw output: linear colours, background until written (as `bg8` is).
    let mut lin = if raw && !want_depth { vec![bg; w * h] } else { Vec::new() };
    // Flat shading (no lights, one sample): a hit's pixel depends only on its
    // leaf, encoded once here exactly as `shade` and the loop below would.
    let flat: Option<Vec<[u8; 3]>> = (s.aov == Aov::Shaded && s.lights.is_empty() && spp == 1 && !raw)
        .then(|| scene.leaf_info.iter().map(|li| encode(Vec3::ZERO + li.color * Vec3::splat(s.ambient))).collect());
    // Only lights and the normal picture read a hit's normal.
    let normals = s.aov == Aov::Normal || (s.aov == Aov::Shaded && !s.lights.is_empty());
    // Each tile finds the objects its rays can meet and specialises their
    // programs (`RenderScene::prepare_tile`); a tile that meets none is
    // background, and no ray of it is traced.
    let nchunks = h.div_ceil(rows);
    let mut dchunks: Vec<Option<&mut [f32]>> =
        if want_depth { depth.chunks_mut(w * rows).map(Some).collect() } else { (0..nchunks).map(|_| None).collect() };
    let mut lchunks: Vec<Option<&mut [Vec3]>> =
        if !lin.is_empty() { lin.chunks_mut(w * rows).map(Some).collect() } else { (0..nchunks).map(|_| None).collect() };
    let frame = Frame { scene, s, rays, spp, w, flat, normals, bg8 };
    // Rayon calls the init once per job, not per thread: workers lent by the
    // scene keep their tile programs' copies of its program from render to
    // render (a sync costs them the rows it rewrote; see `crate::workers`).
    out.par_chunks_mut(w * rows * 3).zip(dchunks.par_iter_mut().zip(lchunks.par_iter_mut())).enumerate().for_each_init(
        || (scene.workers.lend(), Vec::new()),
        |(wk, blocks), (ci, (orows, (drows, lrows)))| {
            let rows_here = orows.len() / (3 * w);
            let mut part =
                Rows { y0: chunk_ids[ci] * rows, rows: rows_here, out: orows, depth: drows.as_deref_mut(), lin: lrows.as_deref_mut() };
            // Tiles in groups along the row: the group's region finds the
            // objects its tiles may meet once, and each tile keeps its own
            // among them (`RenderScene::prepare_tile_among`), in scenes of
            // enough objects for the search to cost.
            let mut among = std::mem::take(&mut wk.group);
            let grouped = scene.objects.len() >= GROUP_OBJECTS;
            for g0 in (0..w).step_by(tile_w * GROUP_TILES) {
                let g1 = (g0 + tile_w * GROUP_TILES).min(w);
                if grouped {
                    scene.objects_touched(&frame.rays.tile_region(g0, g1, part.y0, part.y0 + rows_here), &mut among);
                }
                for x0 in (g0..g1).step_by(tile_w) {
                    render_tile(&frame, wk, &mut part, (x0, (x0 + tile_w).min(w)), grouped.then_some(&among), blocks);
                }
            }
            wk.group = among;
            shadow_total.fetch_add(std::mem::take(&mut wk.shadows) as usize, Ordering::Relaxed);
            let mut tot = tile_total.lock().expect("tile counts");
            tot.0.add(&wk.ts.take_counts());
            tot.0.add(&wk.shadow_ts.take_counts());
            tot.1.add(&take_eval_counts());
            let d = done.fetch_add(rows_here, Ordering::Relaxed) + rows_here;
            progress(d, h);
        },
    );
    drop(dchunks);
    drop(lchunks);
    if want_depth && !raw && s.part.count <= 1 {
        encode_depth(&depth, &mut out);
    }
    let (tiles, eval) = tile_total.into_inner().expect("tile counts");
    let stats = RenderStats { primary_rays: (w * h) as u64 * spp as u64, shadow_rays: shadow_total.into_inner() as u64, tiles, eval };
    (out, lin, depth, stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::SmallRng, Rng, SeedableRng};

    /// The SSE2 encoding picks the table entry that the channel-by-channel
    /// formula picks, for values in and out of [0, 1], zeros of both signs,
    /// infinities, NaNs and every table step's rounding boundary.
    #[test]
    fn srgb_from_matches_the_channel_formula() {
        let lut = srgb_table();
        let q = |x: f32| lut[(x.clamp(0.0, 1.0) * 4095.0 + 0.5) as usize & 4095];
        let mut xs = vec![0.0f32, -0.0, 1.0, -1.0, 2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, 1e-40, f32::MAX];
        for i in 0..4096 {
            let b = (i as f32 - 0.5) / 4095.0;
            xs.extend([b, b.next_up(), b.next_down(), i as f32 / 4095.0]);
        }
        let seed = 0x5e6b;
        println!("seed {seed:#x}");
        let mut rng = SmallRng::seed_from_u64(seed);
        xs.extend((0..20000).map(|_| rng.gen_range(-0.5..1.5f32)));
        for w in xs.windows(3) {
            let c = Vec3::new(w[0], w[1], w[2]);
            assert_eq!(srgb_from(lut, c), [q(c.x), q(c.y), q(c.z)], "{c:?}");
        }
    }

    /// The eight-ray camera gives each ray exactly (bit for bit) what the
    /// one-ray camera gives: the renderer's packets must not change a pixel.
    #[test]
    fn ray8_matches_ray() {
        let seed = 8u64;
        println!("seed {seed}");
        let mut rng = SmallRng::seed_from_u64(seed);
        for case in 0..2000 {
            let cam = Camera {
                eye: Vec3::new(rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0)),
                target: Vec3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
                up: if case % 5 == 0 { Vec3::Z } else { Vec3::Y },
                fov_y_deg: rng.gen_range(5.0..120.0),
            };
            let (w, h) = (rng.gen_range(1..4000u32), rng.gen_range(1..3000u32));
            let rays = cam.rays(w, h);
            let x: [f32; 8] = std::array::from_fn(|_| rng.gen_range(0.0..w as f32));
            let y: [f32; 8] = std::array::from_fn(|_| rng.gen_range(0.0..h as f32));
            let r8 = rays.ray8(&x, &y);
            for k in 0..8 {
                let r1 = rays.ray(x[k], y[k]);
                assert_eq!(r8[k].origin, r1.origin);
                assert_eq!(
                    r8[k].dir.to_array().map(f32::to_bits),
                    r1.dir.to_array().map(f32::to_bits),
                    "case {case} ray {k}: {cam:?} {w}x{h} ({}, {})",
                    x[k],
                    y[k]
                );
                assert_eq!(r8[k].inv_dir.to_array().map(f32::to_bits), r1.inv_dir.to_array().map(f32::to_bits), "case {case} ray {k}");
                assert_eq!((r8[k].tmin, r8[k].tmax), (r1.tmin, r1.tmax), "case {case} ray {k}");
            }
        }
    }
}
