//! The `rothray` command line (see README.md and docs/scene-format.md).

mod bench_knob;

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use rothray_engine::{render, render_raw, Aov, Knob, Part, RenderScene, RenderSettings, Split};
use rothray_io::{load_scene_with, SceneFile};

#[derive(Parser)]
#[command(name = "rothray", version, about = "Ray traces CSG solids by Roth's method")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum AovArg {
    Shaded,
    Depth,
    Normal,
    Id,
}

/// Largest `--spp`, and largest number of camera samples in one render: bounds
/// so that a typo or a hostile job cannot ask for a render of days (2^32
/// samples is about 7 minutes at 10 Mrays/s).
const MAX_SPP: u32 = 1024;
const MAX_SAMPLES: u64 = 1 << 32;
/// Largest `bench --repeats`.
const MAX_REPEATS: u32 = 1000;

/// Image size and sampling, shared by `render` and `bench`.
#[derive(clap::Args, Clone, Copy)]
struct ImageArgs {
    /// Image width, 1 to 65536 (default: the scene's).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    width: Option<u32>,
    /// Image height, 1 to 65536 (default: the scene's). At most 2^28 pixels.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    height: Option<u32>,
    /// Samples per pixel, 1 to 1024 (jittered when > 1); at most 2^32 samples a render.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=MAX_SPP as i64))]
    spp: u32,
}

#[derive(Clone, Copy, ValueEnum)]
enum SplitArg {
    /// Row of tiles c (8 pixel rows) goes to part c mod N.
    Interleaved,
    /// Contiguous bands of rows (worse balanced; kept for comparison).
    Bands,
}

/// `--tile I/N`: 0 <= I < N.
fn parse_tile(s: &str) -> Result<(u32, u32), String> {
    let (i, n) = s.split_once('/').ok_or_else(|| "expected I/N, such as 0/4 (part I of N, 0 <= I < N)".to_string())?;
    let i: u32 = i.trim().parse().map_err(|_| format!("I `{i}` is not a whole number (expected I/N, 0 <= I < N)"))?;
    let n: u32 = n.trim().parse().map_err(|_| format!("N `{n}` is not a whole number (expected I/N, 0 <= I < N)"))?;
    if n == 0 {
        return Err("N is 0: there must be at least one part".into());
    }
    if i >= n {
        return Err(format!("I = {i} is not below N = {n} (parts are numbered 0 to {})", n - 1));
    }
    Ok((i, n))
}

/// `--range A..B` (or `A..`, to the end).
fn parse_range(s: &str) -> Result<(usize, Option<usize>), String> {
    let (a, b) = s.split_once("..").ok_or_else(|| "expected A..B, such as 0..1000 (rays A to B-1, 0-based)".to_string())?;
    let a: usize = a.trim().parse().map_err(|_| format!("A `{a}` is not a whole number (expected A..B)"))?;
    let b: Option<usize> = if b.trim().is_empty() {
        None
    } else {
        Some(b.trim().parse().map_err(|_| format!("B `{b}` is not a whole number (expected A..B)"))?)
    };
    if let Some(b) = b {
        if a > b {
            return Err(format!("A = {a} is above B = {b}"));
        }
    }
    Ok((a, b))
}

/// Which files a scene may read besides those in its own folder.
#[derive(clap::Args, Clone, Default)]
struct FileArgs {
    /// Also allow the files a scene (or mesh) names to lie inside DIR; repeatable.
    /// By default a scene reads only files inside its own folder (after `..` and
    /// symbolic links are resolved), like POV-Ray's file I/O restrictions.
    #[arg(long = "allow-path", value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

impl FileArgs {
    fn options(&self) -> rothray_io::LoadOptions {
        rothray_io::LoadOptions { allow_paths: self.allow_path.clone() }
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Render a scene to a PNG (or, with --tile, one part of it for `rothray merge`).
    Render {
        /// Scene file (JSON).
        scene: PathBuf,
        /// Output PNG; with --tile, the part file.
        #[arg(short = 'o', long = "output")]
        output: PathBuf,
        #[command(flatten)]
        image: ImageArgs,
        #[command(flatten)]
        files: FileArgs,
        /// What to draw.
        #[arg(long, value_enum, default_value = "shaded")]
        aov: AovArg,
        /// Render only part I of N (0 <= I < N) and write it, unencoded, as a
        /// part file; `rothray merge` makes the PNG from all N parts. Rows of
        /// tiles (8 pixel rows) are dealt out in turn (row of tiles c to part c mod N). With Slurm:
        /// --tile $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.
        #[arg(long, value_name = "I/N", value_parser = parse_tile)]
        tile: Option<(u32, u32)>,
        /// How --tile deals rows out to the parts.
        #[arg(long, value_enum, default_value = "interleaved")]
        split: SplitArg,
    },
    /// Merge the part files of `render --tile I/N` (all N of them, any order)
    /// into exactly the PNG that `render` without --tile writes.
    Merge {
        /// The part files.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output PNG (replaced only when the merge succeeds).
        #[arg(short = 'o', long = "output")]
        output: PathBuf,
    },
    /// Trace the rays of a CSV file; print nearest hits (or all intervals with --all).
    Trace {
        /// Scene file (JSON).
        scene: PathBuf,
        /// Ray file: ox,oy,oz,dx,dy,dz[,tmin,tmax] per line.
        #[arg(long)]
        rays: PathBuf,
        /// Output CSV (default: standard output).
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// Print every interval of every object (Roth diagram) instead of the nearest hit.
        #[arg(long)]
        all: bool,
        /// Trace only rays A to B-1 (0-based, the header line not counted; `A..`
        /// runs to the end), numbered as in the whole file: the outputs of
        /// consecutive ranges, without their header lines, concatenate to the
        /// whole file's output.
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        range: Option<(usize, Option<usize>)>,
        #[command(flatten)]
        files: FileArgs,
    },
    /// Bake once, render repeatedly, report times.
    Bench {
        /// Scene file (JSON).
        scene: PathBuf,
        #[command(flatten)]
        image: ImageArgs,
        #[command(flatten)]
        files: FileArgs,
        /// Number of timed renders, 1 to 1000 (the median is reported).
        #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u32).range(1..=MAX_REPEATS as i64))]
        repeats: u32,
        /// Trace camera rays only (no shadow rays), like POV-Ray at +Q0.
        #[arg(long)]
        no_shadows: bool,
        /// Trace every ray alone: no packet walks of wide unions or meshes, no
        /// leaf solved for eight rays at once (the same picture; for measuring
        /// what packets gain).
        #[arg(long)]
        ray_by_ray: bool,
        /// Print one JSON object as the last line (times, rays, and `counters`: what the
        /// tiles skipped and what the evaluation did in the last render).
        #[arg(long)]
        json: bool,
        /// Time only part I of N of the image (as `render --tile I/N`).
        #[arg(long, value_name = "I/N", value_parser = parse_tile)]
        tile: Option<(u32, u32)>,
        /// How --tile deals rows out to the parts.
        #[arg(long, value_enum, default_value = "interleaved")]
        split: SplitArg,
        /// Run time against error for one approximation: sweep, gcyl, frame,
        /// torus, winding or fuse (README, "Run time against error"); its
        /// default range unless --tolerances gives the settings.
        #[arg(long)]
        knob: Option<String>,
        /// Run time against error: a comma-separated list of settings of
        /// --knob, or without it of the solver tolerance (swept spheres,
        /// generalized cylinders); prints trace time and the max / RMS error of
        /// t against the finest setting (tolerance 1e-12), per setting.
        #[arg(long, value_delimiter = ',')]
        tolerances: Vec<f64>,
        /// With --knob or --tolerances: write the curve as an SVG plot here.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Check a mesh file (.obj, .gltf, .glb): triangles, bounds, closedness,
    /// orientation, self-intersections, volume, usable as a solid.
    Check {
        /// Mesh file.
        mesh: PathBuf,
        /// Print the report as one JSON object.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        files: FileArgs,
    },
}

/// An error that maps to exit status 2 (bad input) rather than 1.
#[derive(Debug)]
struct BadInput(String);
impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for BadInput {}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<BadInput>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}

fn load(path: &Path, files: &FileArgs) -> Result<(SceneFile, RenderScene, Duration)> {
    let sf = load_scene_with(path, &files.options()).map_err(|e| BadInput(e.to_string()))?;
    for w in &sf.warnings {
        eprintln!("warning: {w}");
    }
    let t = Instant::now();
    let scene = RenderScene::from_world(&sf.world).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    Ok((sf, scene, t.elapsed()))
}

fn settings(sf: &SceneFile, img: ImageArgs, aov: Aov) -> Result<RenderSettings> {
    let (w, h, spp) = (img.width.unwrap_or(sf.width), img.height.unwrap_or(sf.height), img.spp);
    if w == 0 || h == 0 || w > 65536 || h > 65536 {
        return Err(BadInput(format!("image size {w}x{h} is out of range (1..65536)")).into());
    }
    // About 19 bytes per pixel are held while rendering: cap the frame at 2^28
    // pixels (~5 GB) rather than fail in the allocator.
    if (w as u64) * (h as u64) > 1 << 28 {
        return Err(BadInput(format!("image size {w}x{h} has more than 2^28 pixels")).into());
    }
    if spp == 0 || spp > MAX_SPP {
        return Err(BadInput(format!("--spp {spp} is out of range (1..={MAX_SPP})")).into());
    }
    let samples = (w as u64) * (h as u64) * (spp as u64);
    if samples > MAX_SAMPLES {
        return Err(BadInput(format!("{w}x{h} at {spp} spp is {samples} samples, more than 2^32 in one render")).into());
    }
    Ok(RenderSettings {
        width: w,
        height: h,
        spp,
        aov,
        background: sf.background,
        lights: sf.lights.clone(),
        ambient: 0.1,
        part: Part::WHOLE,
    })
}

/// A progress bar on standard error, shown only once a render has run for a second.
struct Progress {
    done: Arc<AtomicUsize>,
    stop: Arc<AtomicUsize>,
    handle: Option<std::thread::JoinHandle<()>>,
}

impl Progress {
    fn start(total: usize, label: &str) -> Progress {
        let done = Arc::new(AtomicUsize::new(0));
        let stop = Arc::new(AtomicUsize::new(0));
        let (d, s) = (done.clone(), stop.clone());
        let label = label.to_string();
        let tty = std::io::stderr().is_terminal();
        let handle = std::thread::spawn(move || {
            let t0 = Instant::now();
            let mut shown = false;
            let mut last_pct = usize::MAX;
            loop {
                std::thread::sleep(Duration::from_millis(100));
                let finished = s.load(Ordering::Relaxed) != 0;
                let el = t0.elapsed();
                if el >= Duration::from_secs(1) {
                    let n = d.load(Ordering::Relaxed).min(total);
                    let pct = n * 100 / total.max(1);
                    let bar = "#".repeat(pct * 30 / 100) + &" ".repeat(30 - pct * 30 / 100);
                    let eta = if n > 0 { el.as_secs_f64() * (total - n) as f64 / n as f64 } else { 0.0 };
                    if tty {
                        eprint!("\r{label} [{bar}] {pct:3}% {:.1}s, ~{eta:.1}s left ", el.as_secs_f64());
                        shown = true;
                    } else if pct / 10 != last_pct / 10 || finished {
                        eprintln!("{label}: {pct}% after {:.1}s", el.as_secs_f64());
                    }
                    last_pct = pct;
                }
                if finished {
                    if shown {
                        eprintln!();
                    }
                    return;
                }
            }
        });
        Progress { done, stop, handle: Some(handle) }
    }
    fn finish(mut self) {
        self.stop.store(1, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Render { scene, output, image, aov, tile, split, files } => {
            let (sf, rs, _) = load(&scene, &files)?;
            let aov = match aov {
                AovArg::Shaded => Aov::Shaded,
                AovArg::Depth => Aov::Depth,
                AovArg::Normal => Aov::Normal,
                AovArg::Id => Aov::Id,
            };
            let mut s = settings(&sf, image, aov)?;
            if let Some((index, count)) = tile {
                s.part = Part { index, count, split: split_of(split) };
                // The bytes whose hash the part records (read again: the loader
                // does not keep them).
                let bytes = std::fs::read(&scene).map_err(|e| BadInput(format!("{}: cannot read: {e}", scene.display())))?;
                let prog =
                    Progress::start(s.part.rows(s.height as usize, rothray_engine::tile_size_for(&rs, s.part).1).len(), "render part");
                let done = prog.done.clone();
                let px = render_raw(&rs, &sf.camera, &s, &|d, _| {
                    done.fetch_max(d, Ordering::Relaxed);
                });
                prog.finish();
                rothray_io::part::write_part(&output, &scene, &bytes, &s, &px)
                    .with_context(|| format!("cannot write {}", output.display()))?;
                return Ok(());
            }
            let prog = Progress::start(s.height as usize, "render");
            let done = prog.done.clone();
            let (img, _) = render(&rs, &sf.camera, &s, &|d, _| {
                done.fetch_max(d, Ordering::Relaxed);
            });
            prog.finish();
            rothray_io::write_png(&output, s.width, s.height, &img).with_context(|| format!("cannot write {}", output.display()))?;
            Ok(())
        }
        Cmd::Merge { parts, output } => {
            let m = rothray_io::part::merge_parts(&parts).map_err(BadInput)?;
            rothray_io::part::write_atomic(&output, |tmp| {
                rothray_io::write_png(tmp, m.width, m.height, &m.rgb8).map_err(std::io::Error::other)
            })
            .with_context(|| format!("cannot write {}", output.display()))?;
            Ok(())
        }
        Cmd::Trace { scene, rays, output, all, range, files } => {
            // The ray file first: a bad one fails before a long load. Only a regular
            // file is read (a FIFO would block for ever).
            let text = rothray_io::files::read_user_text(&rays).map_err(|e| BadInput(e.to_string()))?;
            let (_sf, rs, _) = load(&scene, &files)?;
            let lines = rothray_io::rays::parse_rays(&text);
            let (first, end) = match range {
                None => (0, lines.len()),
                Some((a, b)) => {
                    let b = b.unwrap_or(lines.len().max(a));
                    if b > lines.len() {
                        return Err(BadInput(format!(
                            "--range {a}..{b}: {} holds {} rays (numbered 0 to {}), so B can be at most {}",
                            rays.display(),
                            lines.len(),
                            lines.len() as i64 - 1,
                            lines.len()
                        ))
                        .into());
                    }
                    (a, b)
                }
            };
            let mut out: Box<dyn Write> = match &output {
                Some(p) => {
                    Box::new(std::io::BufWriter::new(std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?))
                }
                None => Box::new(std::io::BufWriter::new(std::io::stdout().lock())),
            };
            let mut bad = 0;
            if all {
                writeln!(out, "ray,object,t_in,t_out")?;
            } else {
                writeln!(out, "ray,hit,t,nx,ny,nz,object,leaf")?;
            }
            for (i, l) in lines.iter().enumerate().take(end).skip(first) {
                let ray = match &l.ray {
                    Ok(r) => r,
                    Err(msg) => {
                        eprintln!("error: {}:{}: ray {i}: {msg}", rays.display(), l.line);
                        bad += 1;
                        continue;
                    }
                };
                if all {
                    for (oi, o) in rs.objects.iter().enumerate() {
                        for s in rs.spans(ray, oi as u32) {
                            writeln!(out, "{i},{},{:?},{:?}", csv(&o.name), s.t0, s.t1)?;
                        }
                    }
                } else {
                    match rs.intersect(ray) {
                        Some(h) => writeln!(
                            out,
                            "{i},1,{:?},{:?},{:?},{:?},{},{}",
                            h.t,
                            h.normal.x,
                            h.normal.y,
                            h.normal.z,
                            csv(&rs.objects[h.object as usize].name),
                            csv(&rs.leaf_name(h.leaf))
                        )?,
                        None => writeln!(out, "{i},0,,,,,,")?,
                    }
                }
            }
            out.flush()?;
            if bad > 0 {
                eprintln!("{bad} of {} rays were unusable and skipped", end - first);
            }
            Ok(())
        }
        Cmd::Check { mesh, json, files } => check_mesh(&mesh, json, &files),
        Cmd::Bench { scene, image, repeats, json, knob, tolerances, plot, files, .. } if knob.is_some() || !tolerances.is_empty() => {
            let knob = match knob {
                Some(k) => Some(Knob::parse(&k).ok_or_else(|| {
                    let names: Vec<&str> = Knob::ALL.iter().map(|k| k.name()).collect();
                    BadInput(format!("--knob {k}: unknown; the knobs are {}", names.join(", ")))
                })?),
                None => None,
            };
            let sf = load_scene_with(&scene, &files.options()).map_err(|e| BadInput(e.to_string()))?;
            let run = bench_knob::KnobRun { knob, values: &tolerances, image, repeats, plot: plot.as_deref(), json };
            bench_knob::bench_knob(&sf, &run)
        }
        Cmd::Bench { scene, image, repeats, json, no_shadows, ray_by_ray, tile, split, files, .. } => {
            let (sf, mut rs, bake) = load(&scene, &files)?;
            rs.set_ray_by_ray(ray_by_ray);
            let mut s = settings(&sf, image, Aov::Shaded)?;
            if let Some((index, count)) = tile {
                s.part = Part { index, count, split: split_of(split) };
            }
            if no_shadows {
                s.lights.clear();
                s.ambient = 1.0;
            }
            let mut times = Vec::new();
            let mut cpu = Vec::new();
            let mut stats = Default::default();
            // One warm-up render (page faults, thread pool start), then the timed ones.
            let _ = render(&rs, &sf.camera, &s, &|_, _| {});
            for _ in 0..repeats.max(1) {
                let (t, c) = (Instant::now(), process_cpu_s());
                let (_, st) = render(&rs, &sf.camera, &s, &|_, _| {});
                times.push(t.elapsed().as_secs_f64());
                cpu.push(process_cpu_s() - c);
                stats = st;
            }
            times.sort_by(f64::total_cmp);
            let med = times[times.len() / 2];
            let rays = stats.primary_rays + stats.shadow_rays;
            let name = sf.name.clone().unwrap_or_else(|| scene.display().to_string());
            println!("scene          {name} ({}x{}, {} spp, {} threads)", s.width, s.height, s.spp, rayon::current_num_threads());
            println!("leaves         {}", rs.leaves.len());
            println!("bake           {:.4} s", bake.as_secs_f64());
            println!("trace median   {:.4} s  (min {:.4}, max {:.4}, {} runs)", med, times[0], times[times.len() - 1], times.len());
            println!("rays           {} ({} camera + {} shadow)", rays, stats.primary_rays, stats.shadow_rays);
            println!("throughput     {:.2} Mrays/s", rays as f64 / med / 1e6);
            if json {
                let j = serde_json::json!({
                    "scene": name,
                    "width": s.width,
                    "height": s.height,
                    "spp": s.spp,
                    "threads": rayon::current_num_threads(),
                    "tile": [s.part.index, s.part.count],
                    "split": s.part.split.name(),
                    "shadows": !no_shadows,
                    "ray_by_ray": ray_by_ray,
                    "rays": rays,
                    "camera_rays": stats.primary_rays,
                    "shadow_rays": stats.shadow_rays,
                    "bake_s": bake.as_secs_f64(),
                    "trace_s_median": med,
                    "trace_s_all": times,
                    "trace_cpu_s_all": cpu,
                    "mrays_per_s": rays as f64 / med / 1e6,
                    "counters": bench_counters(&stats, rays),
                });
                println!("{j}");
            }
            Ok(())
        }
    }
}

/// CPU time of the whole process (all threads), seconds: unlike wall time it
/// does not count the time other processes hold the cores (`bench --json`'s
/// `trace_cpu_s_all`, used by scripts/split-balance.sh on shared machines).
fn process_cpu_s() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) } != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

fn split_of(s: SplitArg) -> Split {
    match s {
        SplitArg::Interleaved => Split::Interleaved,
        SplitArg::Bands => Split::Bands,
    }
}

/// What one frame skipped and did (the last timed render): tiles, the tile
/// programs, and the evaluation per ray.
fn bench_counters(st: &rothray::engine::RenderStats, rays: u64) -> serde_json::Value {
    let t = &st.tiles;
    let per = |x: u64, n: u64| if n == 0 { 0.0 } else { x as f64 / n as f64 };
    serde_json::json!({
        "tiles": t.tiles,
        "tiles_culled": t.tiles_culled,
        "shadow_bundles_split": t.bundles_split,
        "objects_per_tile": per(t.objects_kept, t.tiles),
        "leaves_pruned_per_tile": per(t.spec.leaves_pruned, t.tiles),
        "leaves_kept_per_tile": per(t.spec.leaves_kept, t.tiles),
        "wide_queries_per_tile": per(t.spec.wide_queries, t.tiles),
        "tile_nodes_written": t.spec.nodes_written,
        "tile_lists": t.spec.lists,
        "tile_listed_per_list": t.spec.listed as f64 / t.spec.lists.max(1) as f64,
        "leaves_asked_per_ray": per(st.eval.leaves, rays),
        "wide_children_visited": st.eval.wide_children,
        "early_outs": st.eval.early_outs,
        "packet_union_lanes": st.eval.packet_lanes,
        "packet_union_misses": st.eval.packet_misses,
        "packet_leaf_solves": st.eval.leaf_solves,
        "packet_leaf_lanes": st.eval.leaf_lanes,
        "packet_leaf_scalar_lanes": st.eval.leaf_scalar,
        "union_first_entry_lanes": st.eval.first_settled,
        "union_walked_lanes": st.eval.first_walked,
        "union_listed_collects": st.eval.listed_collects,
        "object_packet_lanes": st.eval.object_settled,
        "object_packet_left": st.eval.object_left,
        "masked_tries_sure": st.eval.masked_sure,
        "masked_tries_left": st.eval.masked_left,
        "deep_sweeps_sure": st.eval.deep_sure,
        "deep_sweeps_left": st.eval.deep_left,
        "full_redos": st.eval.full_redos,
        "parallel_mesh_lanes": st.eval.parallel_mesh_lanes,
        "mesh_walk_lanes": st.eval.mesh_walk_lanes,
        "mesh_walk_left": st.eval.mesh_walk_left,
        "parallel_mesh_left": st.eval.parallel_mesh_left,
    })
}

fn csv(s: &str) -> String {
    if s.contains(',') || s.contains('"') || s.contains('\n') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn check_mesh(path: &Path, json: bool, files: &FileArgs) -> Result<()> {
    use rothray_primitives::mesh::{InsideRule, MeshData};
    let bad = |e: rothray_io::MeshLoadError| BadInput(e.to_string());
    let (real, allowed) = rothray_io::user_mesh(path, &files.options()).map_err(bad)?;
    let (pos, tris, warnings) = rothray_io::load_mesh_in(&real, &allowed).map_err(bad)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let data = MeshData::new(pos, tris, InsideRule::Orientation).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    let r = data.report();
    let b = r.bounds;
    if json {
        let j = serde_json::json!({
            "file": path.display().to_string(),
            "triangles": r.triangles,
            "vertices": r.vertices,
            "bounds": {"min": b.min.to_array(), "max": b.max.to_array()},
            "boundary_edges": r.boundary_edges,
            "non_manifold_edges": r.non_manifold_edges,
            "closed": r.closed,
            "consistently_oriented": r.consistently_oriented,
            "self_intersections": r.self_intersections,
            "volume": r.volume,
            "area": r.area,
            "usable_as_solid": r.usable_as_solid,
            "inside_rule": format!("{:?}", r.rule).to_lowercase(),
            "warnings": r.warnings,
        });
        println!("{j}");
        return Ok(());
    }
    println!("file                   {}", path.display());
    println!("triangles              {}", r.triangles);
    println!("vertices               {}", r.vertices);
    println!("bounds                 {:?} .. {:?}", b.min.to_array(), b.max.to_array());
    println!("boundary edges         {}", r.boundary_edges);
    println!("non-manifold edges     {}", r.non_manifold_edges);
    println!("closed                 {}", if r.closed { "yes" } else { "no" });
    println!("consistently oriented  {}", if r.consistently_oriented { "yes" } else { "no" });
    match r.self_intersections {
        Some(n) => println!("self-intersections     {n}"),
        None => println!("self-intersections     not computed"),
    }
    println!("volume                 {:.6}", r.volume);
    println!("area                   {:.6}", r.area);
    println!(
        "usable as a solid      {}",
        if r.usable_as_solid { format!("yes (inside rule: {:?})", r.rule).to_lowercase() } else { "no".to_string() }
    );
    for w in &r.warnings {
        println!("warning                {w}");
    }
    Ok(())
}
