//! `rothray bench SCENE --knob K [--tolerances ...] [--plot F.svg] [--json]`:
//! run time against error for one approximation (one mechanism for every knob
//! of [`Knob`]; without `--knob`, `--tolerances` sets the shared swept-sphere
//! and generalized-cylinder tolerance, as it always did).
//!
//! Each setting is baked, its camera rays rendered `repeats` times (median
//! trace time), and the nearest hits of an error grid (every 2nd pixel each
//! way) compared with those of the knob's reference setting: errors of t
//! relative to the scene's size, and the rays that hit in one and miss in the
//! other. The `fuse` knob also counts speckles: pixels of the id picture unlike
//! all four neighbours (coincident faces that were not fused).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use rothray_engine::{bake_scene, render, Aov, Knob, Ray, RenderScene};
use rothray_io::SceneFile;

use crate::{settings, BadInput, ImageArgs};

/// What to measure: the knob (`None`: the shared tolerance), its settings, and
/// the outputs.
pub(crate) struct KnobRun<'a> {
    pub knob: Option<Knob>,
    /// Settings, coarsest first (empty: the knob's default range).
    pub values: &'a [f64],
    pub image: ImageArgs,
    pub repeats: u32,
    pub plot: Option<&'a Path>,
    pub json: bool,
}

/// One row of the curve.
struct Row {
    value: f64,
    trace_s: f64,
    max_err: f64,
    rms_err: f64,
    hit_diff: usize,
    speckles: Option<usize>,
}

fn bake_at(sf: &SceneFile, knob: Option<Knob>, v: f64) -> Result<RenderScene> {
    let mut rs = RenderScene::default();
    match knob {
        Some(k) => rs.knobs = k.set(rs.knobs, v),
        None => rs.tolerance = v as f32,
    }
    bake_scene(&sf.world, &mut rs).map_err(|e| BadInput(e.to_string()))?;
    Ok(rs)
}

/// Pixels that differ from all four neighbours (as tests/coincident.rs counts them).
fn speckles(img: &[u8], w: usize, h: usize) -> usize {
    let px = |x: usize, y: usize| &img[(y * w + x) * 3..(y * w + x) * 3 + 3];
    let mut n = 0;
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let c = px(x, y);
            n += (c != px(x - 1, y) && c != px(x + 1, y) && c != px(x, y - 1) && c != px(x, y + 1)) as usize;
        }
    }
    n
}

/// A setting as people write it: 64, 1.5, 1e-6.
fn fmt_value(v: f64) -> String {
    if v == 0.0 || (0.1..1e5).contains(&v) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Runs the curve and prints it (a table; the JSON object last with `--json`).
pub(crate) fn bench_knob(sf: &SceneFile, run: &KnobRun) -> Result<()> {
    let name = run.knob.map(|k| k.name()).unwrap_or("sweep+gcyl");
    let values: Vec<f64> = match (run.knob, run.values.is_empty()) {
        (Some(k), true) => k.range().to_vec(),
        _ => run.values.to_vec(),
    };
    for &v in &values {
        match run.knob {
            Some(k) => k.check(v).map_err(BadInput)?,
            None if !(v.is_finite() && v > 0.0) => return Err(BadInput(format!("--tolerances: {v} is not a positive number")).into()),
            None => {}
        }
    }
    let scene = sf.path.as_path();
    let s = settings(sf, ImageArgs { spp: 1, ..run.image }, Aov::Depth)?;
    let cam = sf.camera.rays(s.width, s.height);
    let rays: Vec<Ray> = (0..s.height)
        .step_by(2)
        .flat_map(|y| (0..s.width).step_by(2).map(move |x| (x, y)))
        .map(|(x, y)| cam.ray(x as f32 + 0.5, y as f32 + 0.5))
        .collect();
    let trace = |rs: &RenderScene| {
        let mut out = vec![None; rays.len()];
        rs.intersect_bundle(&rays, &mut out);
        out.iter().map(|h| h.map(|h| h.t)).collect::<Vec<Option<f32>>>()
    };
    let reference_value = run.knob.map(|k| k.reference()).unwrap_or(1e-12);
    let rs = bake_at(sf, run.knob, reference_value)?;
    let reference = trace(&rs);
    let size = rs.bounds.diagonal_length().max(1e-6) as f64;
    println!(
        "scene {} ({}x{}), knob {name} ({}), error rays {}, reference setting {}",
        scene.display(),
        s.width,
        s.height,
        run.knob.map(|k| k.unit()).unwrap_or("tolerance / size"),
        rays.len(),
        fmt_value(reference_value)
    );
    println!("{:>10} {:>12} {:>12} {:>12} {:>10} {:>9}", "setting", "trace_s", "max_err", "rms_err", "hit_diff", "speckles");
    let mut rows = Vec::new();
    for &v in &values {
        let rs = bake_at(sf, run.knob, v)?;
        let _ = render(&rs, &sf.camera, &s, &|_, _| {});
        let mut times = Vec::new();
        for _ in 0..run.repeats.max(1) {
            let t0 = Instant::now();
            let _ = render(&rs, &sf.camera, &s, &|_, _| {});
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let got = trace(&rs);
        let (mut max_err, mut sq, mut n, mut hit_diff) = (0.0f64, 0.0f64, 0usize, 0usize);
        for (a, b) in got.iter().zip(reference.iter()) {
            match (a, b) {
                (Some(a), Some(b)) => {
                    let e = (*a as f64 - *b as f64).abs() / size;
                    max_err = max_err.max(e);
                    sq += e * e;
                    n += 1;
                }
                (None, None) => {}
                _ => hit_diff += 1,
            }
        }
        let speckles = (run.knob == Some(Knob::Fuse))
            .then(|| -> Result<usize> {
                let (img, _) = render(&rs, &sf.camera, &settings(sf, ImageArgs { spp: 1, ..run.image }, Aov::Id)?, &|_, _| {});
                Ok(speckles(&img, s.width as usize, s.height as usize))
            })
            .transpose()?;
        let row = Row {
            value: v,
            trace_s: times[times.len() / 2],
            max_err,
            rms_err: if n > 0 { (sq / n as f64).sqrt() } else { 0.0 },
            hit_diff,
            speckles,
        };
        let sp = row.speckles.map(|x| x.to_string()).unwrap_or_else(|| "-".into());
        println!(
            "{:>10} {:>12.5} {:>12.3e} {:>12.3e} {:>10} {:>9}",
            fmt_value(row.value),
            row.trace_s,
            row.max_err,
            row.rms_err,
            row.hit_diff,
            sp
        );
        rows.push(row);
    }
    if let Some(p) = run.plot {
        plot_curve(p, &format!("{}: knob {name}", scene.file_name().unwrap_or_default().to_string_lossy()), &rows)
            .with_context(|| format!("cannot write {}", p.display()))?;
        println!("plot: {}", p.display());
    }
    if run.json {
        let j: Vec<serde_json::Value> = rows
            .iter()
            .map(|r| {
                let mut o = serde_json::json!({"tolerance": r.value, "trace_s_median": r.trace_s, "max_err": r.max_err, "rms_err": r.rms_err, "hit_miss_differs": r.hit_diff});
                if let Some(sp) = r.speckles {
                    o["speckles"] = sp.into();
                }
                o
            })
            .collect();
        println!("{}", serde_json::json!({"scene": scene.display().to_string(), "knob": name, "rows": j}));
    }
    Ok(())
}

/// Max and RMS error of t (log scale) against the median trace time, each
/// point labelled with its setting.
fn plot_curve(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (720, 480)).into_drawing_area();
    root.fill(&WHITE)?;
    // Errors of 0 (the reference's own setting) are drawn at the floor.
    let floor = 1e-9f64;
    let ys: Vec<f64> = rows.iter().flat_map(|r| [r.max_err.max(floor), r.rms_err.max(floor)]).collect();
    let (ylo, yhi) = (ys.iter().cloned().fold(f64::INFINITY, f64::min) / 2.0, ys.iter().cloned().fold(0.0, f64::max) * 2.0);
    let (xlo, xhi) =
        (rows.iter().map(|r| r.trace_s).fold(f64::INFINITY, f64::min) * 0.9, rows.iter().map(|r| r.trace_s).fold(0.0, f64::max) * 1.1);
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{title}: trace time vs error of t"), ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(xlo..xhi, (ylo..yhi).log_scale())?;
    chart.configure_mesh().x_desc("trace time, s (median)").y_desc("error of t / scene size").draw()?;
    let max_pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.trace_s, r.max_err.max(floor))).collect();
    let rms_pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.trace_s, r.rms_err.max(floor))).collect();
    chart
        .draw_series(LineSeries::new(max_pts.clone(), &RED))?
        .label("max")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
    chart.draw_series(max_pts.iter().map(|p| Circle::new(*p, 3, RED.filled())))?;
    chart
        .draw_series(LineSeries::new(rms_pts.clone(), &BLUE))?
        .label("rms")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
    let label = |r: &Row| match r.speckles {
        Some(s) => format!("{} ({s} sp.)", fmt_value(r.value)),
        None => fmt_value(r.value),
    };
    chart.draw_series(rows.iter().map(|r| Text::new(label(r), (r.trace_s, r.max_err.max(floor)), ("sans-serif", 12))))?;
    chart.configure_series_labels().background_style(WHITE).border_style(BLACK).draw()?;
    root.present()?;
    Ok(())
}
