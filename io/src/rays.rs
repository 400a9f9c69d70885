//! The ray file of `rothray trace`: one ray a line, `ox,oy,oz,dx,dy,dz[,tmin,tmax]`,
//! an optional header line starting with `ox`.

use glam::Vec3;
use rothray_engine::Ray;

/// One line of a ray file: the ray, or why it is unusable (the others go on).
#[derive(Clone, Debug, PartialEq)]
pub struct RayLine {
    /// 1-based line number in the file.
    pub line: usize,
    /// The ray or the problem.
    pub ray: Result<Ray, String>,
}

/// Parses a ray file. Blank lines are skipped; every other line is one ray.
pub fn parse_rays(text: &str) -> Vec<RayLine> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let l = raw.trim();
        if l.is_empty() {
            continue;
        }
        if out.is_empty() && l.starts_with("ox") {
            continue;
        }
        out.push(RayLine { line: i + 1, ray: parse_line(l) });
    }
    out
}

fn parse_line(l: &str) -> Result<Ray, String> {
    let f: Vec<&str> = l.split(',').map(|s| s.trim()).collect();
    if f.len() != 6 && f.len() != 8 {
        return Err(format!("expected 6 or 8 comma-separated numbers, got {}", f.len()));
    }
    let mut v = [0.0f32; 8];
    for (k, s) in f.iter().enumerate() {
        v[k] = s.parse::<f32>().map_err(|_| format!("field {} `{s}` is not a number", k + 1))?;
    }
    let o = Vec3::new(v[0], v[1], v[2]);
    let d = Vec3::new(v[3], v[4], v[5]);
    if !o.is_finite() {
        return Err("origin has a NaN or infinite component".into());
    }
    if !d.is_finite() {
        return Err("direction has a NaN or infinite component".into());
    }
    if d == Vec3::ZERO {
        return Err("direction is zero".into());
    }
    let (tmin, tmax) = if f.len() == 8 { (v[6], v[7]) } else { (0.0, f32::INFINITY) };
    if tmin.is_nan() || tmax.is_nan() {
        return Err("tmin or tmax is NaN".into());
    }
    if tmin > tmax {
        return Err(format!("tmin {tmin} is above tmax {tmax}"));
    }
    Ok(Ray::segment(o, d, tmin, tmax))
}
