//! Part files of a split render (`rothray render --tile I/N -o PART`) and
//! their merge (`rothray merge PART... -o OUT.png`).
//!
//! A part file, version 1, little-endian:
//!
//! | bytes | what |
//! |---|---|
//! | 8 | magic `ROTHPART` |
//! | 4 | format version (u32, 1) |
//! | 4 | header length L (u32) |
//! | L | header: one JSON object ([`PartHeader`]) |
//! | rest | payload: `f32` values, pixel by pixel over the part's rows (top to bottom, left to right); 3 per pixel (linear RGB) or 1 (distance, infinite for no surface) for the depth picture |
//!
//! The header says where the part came from (a hash of the scene file's
//! bytes, every setting that changes pixels and a hash of them, the rothray
//! version), which part it is (`index` of `count`, the `split`), the rows it
//! holds and a hash of the payload.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use glam::Vec3;
use rothray_engine::{encode_depth, encode_pixel, Aov, Part, RawPixels, RenderSettings, Split};
use serde::{Deserialize, Serialize};

/// The first 8 bytes of a part file.
pub const MAGIC: &[u8; 8] = b"ROTHPART";
/// The format version written (and the only one read).
pub const VERSION: u32 = 1;

/// FNV-1a, 64 bits, over bytes.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// FNV-1a, 128 bits, over bytes (the scene file's fingerprint).
pub fn fnv1a128(bytes: &[u8]) -> u128 {
    let mut h = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58du128;
    for &b in bytes {
        h ^= b as u128;
        h = h.wrapping_mul(0x0000_0000_0100_0000_0000_0000_0000_013b);
    }
    h
}

/// The payload's check: FNV-1a's step over 8-byte words (fast on large parts).
fn payload_hash(v: impl Iterator<Item = f32>) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let (mut n, mut pending) = (0u64, None::<u32>);
    let mut step = |w: u64| {
        h ^= w;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
        h ^= h >> 29;
    };
    for x in v {
        n += 1;
        match pending.take() {
            None => pending = Some(x.to_bits()),
            Some(a) => step(a as u64 | (x.to_bits() as u64) << 32),
        }
    }
    if let Some(a) = pending {
        step(a as u64);
    }
    h ^ n
}

/// The name of an AOV in part files and on the command line.
pub fn aov_name(a: Aov) -> &'static str {
    match a {
        Aov::Shaded => "shaded",
        Aov::Depth => "depth",
        Aov::Normal => "normal",
        Aov::Id => "id",
    }
}

fn aov_from_name(s: &str) -> Option<Aov> {
    Some(match s {
        "shaded" => Aov::Shaded,
        "depth" => Aov::Depth,
        "normal" => Aov::Normal,
        "id" => Aov::Id,
        _ => return None,
    })
}

/// Every setting that changes pixels, as recorded in a part.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartSettings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// `shaded`, `depth`, `normal` or `id`.
    pub aov: String,
    /// Ambient term (bits matter: compared exactly).
    pub ambient: f32,
    /// How chunks of rows are dealt out (`interleaved`, `bands`).
    pub split: String,
    /// The renderer's tile size (width, height): a chunk is one row of tiles,
    /// and the tiles' programs are the same only for the same tiles.
    pub tile: [usize; 2],
    /// The rothray version that rendered it (another build may round differently).
    pub rothray: String,
}

impl PartSettings {
    /// The settings of a render made with tiles of `tile` pixels.
    pub fn of(s: &RenderSettings, tile: (usize, usize)) -> PartSettings {
        PartSettings {
            width: s.width,
            height: s.height,
            spp: s.spp,
            aov: aov_name(s.aov).into(),
            ambient: s.ambient,
            split: s.part.split.name().into(),
            tile: [tile.0, tile.1],
            rothray: env!("CARGO_PKG_VERSION").into(),
        }
    }

    /// A hash of all of them (hex).
    pub fn hash(&self) -> String {
        format!("{:016x}", fnv1a64(serde_json::to_string(self).expect("settings serialize").as_bytes()))
    }

    /// The first setting that differs from `o`, as `name a (other b)`.
    fn differs(&self, o: &PartSettings) -> Option<String> {
        let d = |n: &str, a: &dyn std::fmt::Display, b: &dyn std::fmt::Display| Some(format!("{n} {a} (the other parts: {b})"));
        if self.width != o.width {
            return d("--width", &self.width, &o.width);
        }
        if self.height != o.height {
            return d("--height", &self.height, &o.height);
        }
        if self.spp != o.spp {
            return d("--spp", &self.spp, &o.spp);
        }
        if self.aov != o.aov {
            return d("--aov", &self.aov, &o.aov);
        }
        if self.split != o.split {
            return d("--split", &self.split, &o.split);
        }
        if self.tile != o.tile {
            let t = |t: [usize; 2]| format!("{}x{}", t[0], t[1]);
            return d("tile size (ROTHRAY_TILE)", &t(self.tile), &t(o.tile));
        }
        if self.ambient.to_bits() != o.ambient.to_bits() {
            return d("ambient", &self.ambient, &o.ambient);
        }
        if self.rothray != o.rothray {
            return d("rothray version", &self.rothray, &o.rothray);
        }
        None
    }
}

/// The JSON header of a part file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartHeader {
    /// The scene file as named on the command line (for messages only).
    pub scene: String,
    /// FNV-1a 128 of the scene file's bytes (hex).
    pub scene_hash: String,
    /// The settings that change pixels.
    pub settings: PartSettings,
    /// [`PartSettings::hash`].
    pub settings_hash: String,
    /// Which part (0-based).
    pub index: u32,
    /// Of how many.
    pub count: u32,
    /// The rows held, as half-open ranges `[y0, y1)`, increasing.
    pub rows: Vec<[usize; 2]>,
    /// Values per pixel: 3 (linear RGB) or 1 (depth).
    pub channels: u32,
    /// Number of f32 values in the payload.
    pub values: u64,
    /// Hash of the payload (hex).
    pub payload_hash: String,
}

fn row_ranges(rows: &[usize]) -> Vec<[usize; 2]> {
    let mut out: Vec<[usize; 2]> = Vec::new();
    for &r in rows {
        match out.last_mut() {
            Some(last) if last[1] == r => last[1] = r + 1,
            _ => out.push([r, r + 1]),
        }
    }
    out
}

/// Writes `path` through a temporary file in the same folder, renamed over
/// `path` only once it is complete: an existing file is replaced only on success.
pub fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> std::io::Result<()>) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let r = write(&tmp).and_then(|()| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// Writes the part of a render: `scene_bytes` is the scene file as read.
pub fn write_part(path: &Path, scene: &Path, scene_bytes: &[u8], s: &RenderSettings, px: &RawPixels) -> std::io::Result<()> {
    let settings = PartSettings::of(s, px.tile);
    // The payload, without a copy of the pixels.
    let depth = s.aov == Aov::Depth;
    let values = || -> Box<dyn Iterator<Item = f32> + '_> {
        if depth {
            Box::new(px.depth.iter().copied())
        } else {
            Box::new(px.rgb.iter().flat_map(|c| c.to_array()))
        }
    };
    let (channels, nvalues) = if depth { (1, px.depth.len()) } else { (3, px.rgb.len() * 3) };
    let header = PartHeader {
        scene: scene.display().to_string(),
        scene_hash: format!("{:032x}", fnv1a128(scene_bytes)),
        settings_hash: settings.hash(),
        settings,
        index: s.part.index,
        count: s.part.count,
        rows: row_ranges(&px.rows),
        channels,
        values: nvalues as u64,
        payload_hash: format!("{:016x}", payload_hash(values())),
    };
    let json = serde_json::to_vec(&header).expect("header serializes");
    write_atomic(path, |tmp| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        f.write_all(MAGIC)?;
        f.write_all(&VERSION.to_le_bytes())?;
        f.write_all(&(json.len() as u32).to_le_bytes())?;
        f.write_all(&json)?;
        let mut buf = Vec::with_capacity(1 << 22);
        for v in values() {
            buf.extend_from_slice(&v.to_le_bytes());
            if buf.len() >= 1 << 22 {
                f.write_all(&buf)?;
                buf.clear();
            }
        }
        f.write_all(&buf)?;
        // No fsync: a part cut short by a crash after the rename is caught by
        // the merge (length and hash of the pixels), and fsync of 25 MB cost
        // more than tracing a small scene's part.
        f.flush()
    })
}

/// An opened part file: its header, the reader positioned at the payload.
struct OpenPart {
    path: PathBuf,
    header: PartHeader,
    file: std::io::BufReader<std::fs::File>,
}

fn open_part(path: &Path) -> Result<OpenPart, String> {
    let at = |m: String| format!("{}: {m}", path.display());
    let f = std::fs::File::open(path).map_err(|e| at(format!("cannot read: {e}")))?;
    let mut f = std::io::BufReader::new(f);
    let mut head = [0u8; 16];
    f.read_exact(&mut head).map_err(|_| at("not a rothray part file (shorter than its 16-byte start)".into()))?;
    if &head[..8] != MAGIC {
        return Err(at("not a rothray part file (it does not start with ROTHPART); make parts with `rothray render --tile I/N`".into()));
    }
    let version = u32::from_le_bytes(head[8..12].try_into().unwrap());
    if version != VERSION {
        return Err(at(format!("part file format version {version}; this rothray reads version {VERSION}")));
    }
    let len = u32::from_le_bytes(head[12..16].try_into().unwrap()) as usize;
    if len > 1 << 26 {
        return Err(at(format!("header length {len} is implausible: the file is damaged")));
    }
    let mut json = vec![0u8; len];
    f.read_exact(&mut json).map_err(|_| at("truncated in its header".into()))?;
    let header: PartHeader = serde_json::from_slice(&json).map_err(|e| at(format!("damaged header: {e}")))?;
    Ok(OpenPart { path: path.to_path_buf(), header, file: f })
}

/// The image a set of parts makes.
pub struct Merged {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// RGB8, rows top to bottom: exactly what `render` writes.
    pub rgb8: Vec<u8>,
}

/// Checks that `paths` are the N parts of one render, each exactly once (in
/// any order), and assembles the picture. Errors name the part file.
pub fn merge_parts(paths: &[PathBuf]) -> Result<Merged, String> {
    if paths.is_empty() {
        return Err("merge: no part files given".into());
    }
    let mut parts = Vec::with_capacity(paths.len());
    for p in paths {
        parts.push(open_part(p)?);
    }
    let first = &parts[0];
    let (ref_path, ref_h) = (first.path.display().to_string(), first.header.clone());
    let st = &ref_h.settings;
    let aov = aov_from_name(&st.aov).ok_or_else(|| format!("{ref_path}: unknown aov `{}`", st.aov))?;
    let split = Split::from_name(&st.split).ok_or_else(|| format!("{ref_path}: unknown split `{}`", st.split))?;
    let n = ref_h.count;
    let mut owner: Vec<Option<usize>> = vec![None; n as usize];
    for (k, p) in parts.iter().enumerate() {
        let h = &p.header;
        let name = p.path.display();
        if h.scene_hash != ref_h.scene_hash {
            return Err(format!(
                "{name}: foreign part: made from another scene file ({}, hash {}) than {ref_path} ({}, hash {})",
                h.scene, h.scene_hash, ref_h.scene, ref_h.scene_hash
            ));
        }
        if let Some(d) = h.settings.differs(st) {
            return Err(format!("{name}: foreign part: made with other settings than {ref_path}: {d}"));
        }
        if h.settings_hash != h.settings.hash() {
            return Err(format!("{name}: damaged header: its settings do not match their hash"));
        }
        if h.count != n {
            return Err(format!(
                "{name}: part {}/{} of a split into {} parts, but {ref_path} is part {}/{n}",
                h.index, h.count, h.count, ref_h.index
            ));
        }
        if h.index >= n {
            return Err(format!("{name}: damaged header: part index {} is not below {n}", h.index));
        }
        if let Some(o) = owner[h.index as usize] {
            return Err(format!("{name}: repeated part {}/{n}: {} holds it too", h.index, parts[o].path.display()));
        }
        owner[h.index as usize] = Some(k);
        let want = row_ranges(&Part { index: h.index, count: n, split }.rows(st.height as usize, st.tile[1]));
        if h.rows != want {
            return Err(format!("{name}: damaged header: its rows are not those of part {}/{n}", h.index));
        }
    }
    let missing: Vec<String> = owner.iter().enumerate().filter(|(_, o)| o.is_none()).map(|(i, _)| i.to_string()).collect();
    if !missing.is_empty() {
        let shown: Vec<String> = missing.iter().take(20).cloned().collect();
        let more = if missing.len() > 20 { format!(" and {} more", missing.len() - 20) } else { String::new() };
        return Err(format!(
            "missing part{} {}{more} of {n} (given: {} part file{}, {ref_path} first); render them with `rothray render {} --tile I/{n}`",
            if missing.len() > 1 { "s" } else { "" },
            shown.join(", "),
            parts.len(),
            if parts.len() > 1 { "s" } else { "" },
            ref_h.scene
        ));
    }
    let (w, h) = (st.width as usize, st.height as usize);
    let ch = if aov == Aov::Depth { 1 } else { 3 };
    let mut img = vec![0f32; w * h * ch];
    for p in &mut parts {
        let name = p.path.display().to_string();
        let hd = &p.header;
        let rows: usize = hd.rows.iter().map(|r| r[1] - r[0]).sum();
        let want = (rows * w * ch) as u64;
        if hd.channels as usize != ch || hd.values != want {
            return Err(format!("{name}: damaged header: {} values of {} channels, expected {want} of {ch}", hd.values, hd.channels));
        }
        let mut bytes = Vec::with_capacity(want as usize * 4);
        p.file.read_to_end(&mut bytes).map_err(|e| format!("{name}: cannot read: {e}"))?;
        if bytes.len() != want as usize * 4 {
            return Err(format!("{name}: truncated or overlong: {} payload bytes, expected {}", bytes.len(), want * 4));
        }
        let vals: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
        drop(bytes);
        if format!("{:016x}", payload_hash(vals.iter().copied())) != hd.payload_hash {
            return Err(format!("{name}: damaged: its pixels do not match their hash"));
        }
        let mut off = 0;
        for r in &hd.rows {
            let len = (r[1] - r[0]) * w * ch;
            img[r[0] * w * ch..r[1] * w * ch].copy_from_slice(&vals[off..off + len]);
            off += len;
        }
    }
    let mut rgb8 = vec![0u8; w * h * 3];
    if aov == Aov::Depth {
        encode_depth(&img, &mut rgb8);
    } else {
        for (px, c) in rgb8.chunks_exact_mut(3).zip(img.chunks_exact(3)) {
            px.copy_from_slice(&encode_pixel(aov, Vec3::new(c[0], c[1], c[2])));
        }
    }
    Ok(Merged { width: st.width, height: st.height, rgb8 })
}
