//! The runs of a part drawn side by side: one column per run (DEM, hybrid, MPM), one row per
//! moment, each run's frame nearest that moment, all in the same view; or each run's last
//! frame, one row per model. Grains sand, material points blue, so that the hybrid's zones
//! show.

use crate::render::{Colour, Scene2, frame, frame_times, panels};
use crate::report::Part;
use anyhow::Context as _;
use std::path::Path;

/// Pixels across one panel.
const PANEL: u32 = 420;

/// Draws `runs` (label, run directory) at `times` [s] into `<out>/<stem>.png` and lists it
/// under `part`. A run without a frame near a moment (within a quarter of the spacing of the
/// moments, or 0.05 s for one moment) leaves its panel out: it is not drawn at another time.
pub fn side_by_side(
    part: &mut Part,
    out: &Path,
    stem: &str,
    caption: &str,
    runs: &[(&str, &Path)],
    times: &[f64],
    view: Option<([f64; 2], [f64; 2])>,
) -> anyhow::Result<()> {
    let slack = match times {
        [a, b, ..] => 0.25 * (b - a).abs(),
        _ => 0.05,
    };
    let mut rows = Vec::new();
    for &t in times {
        let mut row: Vec<(String, Scene2)> = Vec::new();
        for (label, dir) in runs {
            let nearest = frame_times(dir)?
                .into_iter()
                .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
                .filter(|(ft, _)| (ft - t).abs() <= slack);
            if let Some((ft, step)) = nearest {
                row.push((format!("{label}, t = {ft:.2} s"), frame(dir, step, view)?));
            }
        }
        if !row.is_empty() {
            rows.push(row);
        }
    }
    panels(&rows, Colour::Model, PANEL, &out.join(format!("{stem}.png")))?;
    part.pictures.push((stem.to_string(), caption.to_string()));
    Ok(())
}

/// Draws the last frame of each run of `rows` (one row per model: (label, run directory))
/// into `<out>/<stem>.png`, all in `view`, and lists it under `part`. A run without frames is
/// an error: every run drawn here wrote its end.
pub fn last_frames(
    part: &mut Part,
    out: &Path,
    stem: &str,
    caption: &str,
    rows: &[Vec<(String, &Path)>],
    view: Option<([f64; 2], [f64; 2])>,
) -> anyhow::Result<()> {
    let mut drawn = Vec::new();
    for row in rows.iter().filter(|r| !r.is_empty()) {
        let mut panels_of_row = Vec::new();
        for (label, dir) in row {
            let (t, step) = frame_times(dir)?
                .into_iter()
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .ok_or_else(|| anyhow::anyhow!("{}: no frame to draw", dir.display()))?;
            panels_of_row.push((format!("{label}, t = {t:.2} s"), frame(dir, step, view)?));
        }
        drawn.push(panels_of_row);
    }
    panels(&drawn, Colour::Model, PANEL, &out.join(format!("{stem}.png")))?;
    part.pictures.push((stem.to_string(), caption.to_string()));
    Ok(())
}

/// A run's grains and points in `view` at its frame nearest `to` [s], each carrying (in the
/// place of its speed) Cundall's best-fit deviatoric strain since the frame nearest `from`
/// (`grains_oracle::band`, each centre with its neighbours within 1.5 of its size then; 0 for
/// an item the earlier frame does not have), and the two frames' times.
pub fn strain_scene(dir: &Path, from: f64, to: f64, view: Option<([f64; 2], [f64; 2])>) -> anyhow::Result<(f64, f64, Scene2)> {
    use grains_oracle::band::{best_fit_strain, neighbours};
    use grains_service::vtu::Frame;
    let nearest = |t: f64| -> anyhow::Result<(f64, u64)> {
        frame_times(dir)?
            .into_iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .ok_or_else(|| anyhow::anyhow!("{}: no frame to draw", dir.display()))
    };
    let strains = |kind: &str, steps: (u64, u64), size: f64| -> anyhow::Result<Vec<f64>> {
        let read = |step: u64| Frame::read(&dir.join("frames").join(format!("{kind}_{step:08}.vtu")));
        let (a, b) = (read(steps.0)?, read(steps.1)?);
        let ids = |f: &Frame| -> anyhow::Result<Vec<u64>> {
            Ok(f.array("id")
                .context("a frame without an id array")?
                .iter()
                .map(|&i| i as u64)
                .collect())
        };
        let before: std::collections::HashMap<u64, [f64; 3]> = ids(&a)?.into_iter().zip(a.points.iter().copied()).collect();
        let (mut x0, mut x1, mut at) = (Vec::new(), Vec::new(), Vec::new());
        for (k, (id, x)) in ids(&b)?.into_iter().zip(&b.points).enumerate() {
            if let Some(p) = before.get(&id) {
                x0.push([p[0], p[1]]);
                x1.push([x[0], x[1]]);
                at.push(k);
            }
        }
        let mut out = vec![0.0; b.points.len()];
        for (e, k) in best_fit_strain(&x0, &x1, &neighbours(&x0, 1.5 * size)).into_iter().zip(at) {
            out[k] = e;
        }
        Ok(out)
    };
    let (t0, s0) = nearest(from)?;
    let (t1, s1) = nearest(to)?;
    let mut scene = frame(dir, s1, view)?;
    if !scene.grains.is_empty() {
        let d = 2.0 * scene.grains.iter().map(|g| g.1).sum::<f64>() / scene.grains.len() as f64;
        for (g, e) in scene.grains.iter_mut().zip(strains("grains", (s0, s1), d)?) {
            g.2 = e;
        }
    }
    if let Some(&(_, half, _)) = scene.points.first() {
        for (p, e) in scene.points.iter_mut().zip(strains("points", (s0, s1), 2.0 * half)?) {
            p.2 = e;
        }
    }
    scene.bodies.iter_mut().for_each(|b| b.1 = 0.0);
    Ok((t0, t1, scene))
}

/// Incremental-strain pictures (as Chen 2021 Figs. 11, 18 and 24): one row per run of `runs`
/// (label, [`strain_scene`]'s frames' times and scene), dark blue no strain, yellow the 98th
/// percentile of all the panels' strains or more. Into `<out>/<stem>.png`, listed under `part`.
pub fn strain_rows(part: &mut Part, out: &Path, stem: &str, caption: &str, runs: Vec<(&str, (f64, f64, Scene2))>) -> anyhow::Result<()> {
    use grains_oracle::band::percentile;
    let mut rows: Vec<Vec<(String, Scene2)>> = runs
        .into_iter()
        .map(|(label, (t0, t1, scene))| vec![(format!("{label}, strain from t = {t0:.2} to {t1:.2} s"), scene)])
        .collect();
    let all: Vec<f64> = rows
        .iter()
        .flatten()
        .flat_map(|(_, s)| s.grains.iter().chain(&s.points).map(|m| m.2))
        .collect();
    let cap = percentile(&all, 0.98);
    for (_, s) in rows.iter_mut().flatten() {
        s.grains.iter_mut().chain(s.points.iter_mut()).for_each(|m| m.2 = m.2.min(cap));
    }
    panels(&rows, Colour::Speed, PANEL, &out.join(format!("{stem}.png")))?;
    part.pictures.push((stem.to_string(), caption.to_string()));
    Ok(())
}
