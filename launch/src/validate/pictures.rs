//! The runs of a part drawn side by side: one column per run (DEM, hybrid, MPM), one row per
//! moment, each run's frame nearest that moment, all in the same view; or each run's last
//! frame, one row per model. Grains sand, material points blue, so that the hybrid's zones
//! show.

use crate::render::{Colour, Scene2, frame, frame_times, panels, panels_scaled};
use crate::report::Part;
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

/// A run's picture at its frame nearest `to` [s] with each grain's and point's strain since its
/// frame nearest `from` ([`crate::render::strain_frame`]), and the two frames' times.
pub fn strain_scene(dir: &Path, from: f64, to: f64, view: Option<([f64; 2], [f64; 2])>) -> anyhow::Result<(f64, f64, Scene2)> {
    let nearest = |t: f64| -> anyhow::Result<(f64, u64)> {
        frame_times(dir)?
            .into_iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .ok_or_else(|| anyhow::anyhow!("{}: no frame to draw", dir.display()))
    };
    let (t0, s0) = nearest(from)?;
    let (t1, s1) = nearest(to)?;
    Ok((t0, t1, crate::render::strain_frame(dir, s0, s1, view)?))
}

/// Incremental-strain pictures (as Chen 2021 Figs. 11, 18 and 24): one row per run of `runs`
/// (label, [`strain_scene`]'s frames' times and scene), dark blue no strain, yellow the 98th
/// percentile of all the panels' strains or more. Into `<out>/<stem>.png`, listed under `part`.
pub fn strain_rows(part: &mut Part, out: &Path, stem: &str, caption: &str, runs: Vec<(&str, (f64, f64, Scene2))>) -> anyhow::Result<()> {
    let (labels, scenes): (Vec<String>, Vec<Scene2>) = runs
        .into_iter()
        .map(|(label, (t0, t1, scene))| (format!("{label}, strain from t = {t0:.2} to {t1:.2} s"), scene))
        .unzip();
    let top = crate::render::strain_top(&scenes);
    let rows: Vec<Vec<(String, Scene2)>> = labels.into_iter().zip(scenes).map(|r| vec![r]).collect();
    panels_scaled(&rows, Colour::Strain, top, PANEL, &out.join(format!("{stem}.png")))?;
    part.pictures.push((stem.to_string(), caption.to_string()));
    Ok(())
}
