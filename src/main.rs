//! The `rothray` command line (see README.md and docs/scene-format.md).

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use rothray_engine::{render, Aov, RenderScene, RenderSettings};
use rothray_io::{load_scene, SceneFile};

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

#[derive(Subcommand)]
enum Cmd {
    /// Render a scene to a PNG.
    Render {
        /// Scene file (JSON).
        scene: PathBuf,
        /// Output PNG.
        #[arg(short = 'o', long = "output")]
        output: PathBuf,
        /// Image width (default: the scene's).
        #[arg(long)]
        width: Option<u32>,
        /// Image height (default: the scene's).
        #[arg(long)]
        height: Option<u32>,
        /// Samples per pixel (jittered when > 1).
        #[arg(long, default_value_t = 1)]
        spp: u32,
        /// What to draw.
        #[arg(long, value_enum, default_value = "shaded")]
        aov: AovArg,
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
    },
    /// Bake once, render repeatedly, report times.
    Bench {
        /// Scene file (JSON).
        scene: PathBuf,
        /// Image width (default: the scene's).
        #[arg(long)]
        width: Option<u32>,
        /// Image height (default: the scene's).
        #[arg(long)]
        height: Option<u32>,
        /// Samples per pixel.
        #[arg(long, default_value_t = 1)]
        spp: u32,
        /// Number of timed renders (the median is reported).
        #[arg(long, default_value_t = 7)]
        repeats: u32,
        /// Print one JSON object as the last line.
        #[arg(long)]
        json: bool,
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
            if e.downcast_ref::<BadInput>().is_some() { ExitCode::from(2) } else { ExitCode::from(1) }
        }
    }
}

fn load(path: &Path) -> Result<(SceneFile, RenderScene, Duration)> {
    let sf = load_scene(path).map_err(|e| BadInput(e.to_string()))?;
    for w in &sf.warnings {
        eprintln!("warning: {w}");
    }
    let t = Instant::now();
    let scene = RenderScene::from_world(&sf.world).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    Ok((sf, scene, t.elapsed()))
}

fn settings(sf: &SceneFile, width: Option<u32>, height: Option<u32>, spp: u32, aov: Aov) -> Result<RenderSettings> {
    let w = width.unwrap_or(sf.width);
    let h = height.unwrap_or(sf.height);
    if w == 0 || h == 0 || w > 65536 || h > 65536 {
        return Err(BadInput(format!("image size {w}x{h} is out of range (1..65536)")).into());
    }
    if spp == 0 || spp > 65536 {
        return Err(BadInput(format!("--spp {spp} is out of range (1..65536)")).into());
    }
    Ok(RenderSettings { width: w, height: h, spp, aov, background: sf.background, lights: sf.lights.clone(), ambient: 0.1 })
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
        Cmd::Render { scene, output, width, height, spp, aov } => {
            let (sf, rs, _) = load(&scene)?;
            let aov = match aov {
                AovArg::Shaded => Aov::Shaded,
                AovArg::Depth => Aov::Depth,
                AovArg::Normal => Aov::Normal,
                AovArg::Id => Aov::Id,
            };
            let s = settings(&sf, width, height, spp, aov)?;
            let prog = Progress::start(s.height as usize, "render");
            let done = prog.done.clone();
            let (img, _) = render(&rs, &sf.camera, &s, &|d, _| {
                done.fetch_max(d, Ordering::Relaxed);
            });
            prog.finish();
            rothray_io::write_png(&output, s.width, s.height, &img)
                .with_context(|| format!("cannot write {}", output.display()))?;
            Ok(())
        }
        Cmd::Trace { scene, rays, output, all } => {
            let (_sf, rs, _) = load(&scene)?;
            let text = std::fs::read_to_string(&rays)
                .map_err(|e| BadInput(format!("{}: cannot read: {e}", rays.display())))?;
            let lines = rothray_io::rays::parse_rays(&text);
            let mut out: Box<dyn Write> = match &output {
                Some(p) => Box::new(std::io::BufWriter::new(
                    std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
                )),
                None => Box::new(std::io::BufWriter::new(std::io::stdout().lock())),
            };
            let mut bad = 0;
            if all {
                writeln!(out, "ray,object,t_in,t_out")?;
            } else {
                writeln!(out, "ray,hit,t,nx,ny,nz,object,leaf")?;
            }
            for (i, l) in lines.iter().enumerate() {
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
                            csv(&rs.leaf_info[h.leaf as usize].name)
                        )?,
                        None => writeln!(out, "{i},0,,,,,,")?,
                    }
                }
            }
            out.flush()?;
            if bad > 0 {
                eprintln!("{bad} of {} rays were unusable and skipped", lines.len());
            }
            Ok(())
        }
        Cmd::Bench { scene, width, height, spp, repeats, json } => {
            let (sf, rs, bake) = load(&scene)?;
            let s = settings(&sf, width, height, spp, Aov::Shaded)?;
            let mut times = Vec::new();
            let mut stats = Default::default();
            // One warm-up render (page faults, thread pool start), then the timed ones.
            let _ = render(&rs, &sf.camera, &s, &|_, _| {});
            for _ in 0..repeats.max(1) {
                let t = Instant::now();
                let (_, st) = render(&rs, &sf.camera, &s, &|_, _| {});
                times.push(t.elapsed().as_secs_f64());
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
                    "rays": rays,
                    "camera_rays": stats.primary_rays,
                    "shadow_rays": stats.shadow_rays,
                    "bake_s": bake.as_secs_f64(),
                    "trace_s_median": med,
                    "trace_s_all": times,
                    "mrays_per_s": rays as f64 / med / 1e6,
                });
                println!("{j}");
            }
            Ok(())
        }
    }
}

fn csv(s: &str) -> String {
    if s.contains(',') || s.contains('"') || s.contains('\n') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
