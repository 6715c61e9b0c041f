//! Running scenes for the validation and reading what a run did: one run as processes under
//! `<out>/runs`, its counts and wall time, and "what each run simulates" (participants, grains
//! and points over time) next to the pure DEM's.

use super::args::ValidateArgs;
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use crate::run::{RunOptions, RunOutcome, Status, run};
use anyhow::bail;
use grains_protocol::Role;
use std::path::{Path, PathBuf};

/// The scene at `path` with `--set` overrides, validated.
pub fn load_with(path: &Path, overrides: &[String]) -> anyhow::Result<grains_protocol::scene::Scene> {
    Ok(grains_protocol::scene::load_with_overrides(path, overrides)?.0)
}

/// One run of `scene` with `overrides` as processes, quietly, under `<out>/runs`.
pub fn run_scene(args: &ValidateArgs, scene: &Path, overrides: Vec<String>) -> anyhow::Result<RunOutcome> {
    run(&RunOptions::quiet(scene.to_path_buf(), args.out.join("runs"), overrides))
}

/// A completed run: its directory, first-row counts and wall time.
pub struct RunResult {
    pub dir: PathBuf,
    pub grains: u64,
    pub points: u64,
    pub wall: f64,
}

/// Runs `scene` to its end: its counts and wall time; an error names it if it did not complete.
pub fn finished(args: &ValidateArgs, path: &Path, overrides: Vec<String>) -> anyhow::Result<RunResult> {
    let outcome = run_scene(args, path, overrides)?;
    if outcome.status != Status::Completed {
        bail!("{}: the run did not complete: {}", path.display(), outcome.message);
    }
    let t = MetricsTable::read(&outcome.dir)?;
    Ok(RunResult {
        grains: first_count(&t, Role::Dem)?,
        points: first_count(&t, Role::Mpm)?,
        wall: t.last("wall_s")?,
        dir: outcome.dir,
    })
}

/// A participant's items in the first row (0 when the run did not have it).
fn first_count(t: &MetricsTable, role: Role) -> anyhow::Result<u64> {
    Ok(t.participant(role, "items")?.and_then(|v| v.first().copied()).unwrap_or(0.0) as u64)
}

/// The roles of the participants a run started (from its `summary.json`).
pub fn participants_of(run_dir: &Path) -> Vec<String> {
    let summary: serde_json::Value = std::fs::read_to_string(run_dir.join("summary.json"))
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or_default();
    summary["participants"]
        .as_array()
        .map(|a| a.iter().filter_map(|p| p["role"].as_str().map(String::from)).collect())
        .unwrap_or_default()
}

/// The header of the tables [`scene_use`] fills.
pub const SCENE_USE_HEADER: &str = "| scene | hybrid run's participants | pure DEM's | hybrid grains start → end | points start → end | pure-DEM grains | hybrid wall s | pure-DEM wall s | speedup |\n|---|---|---|---:|---:|---:|---:|---:|---:|";

/// "Model no more than a scene needs": the participants a hybrid run started, its grains and
/// points over time next to the pure-DEM run of the same scene, and both wall times. Returns
/// the section's table row and writes the chart `<stem>.*`.
pub fn scene_use(
    args: &ValidateArgs,
    part: &mut Part,
    stem: &str,
    scene: &str,
    hybrid_dir: &Path,
    dem_dir: &Path,
) -> anyhow::Result<String> {
    let (h, d) = (MetricsTable::read(hybrid_dir)?, MetricsTable::read(dem_dir)?);
    let series = |t: &MetricsTable, col: &str| -> anyhow::Result<Vec<(f64, f64)>> {
        let (time, v) = (t.column("time")?, t.column(col)?);
        let every = (t.len() / 400).max(1);
        Ok(time.into_iter().zip(v).step_by(every).collect())
    };
    let chart = Chart {
        title: format!("{scene}: what each run simulates"),
        x_label: "time [s]".into(),
        y_label: "grains or material points".into(),
        series: vec![
            Series::new("hybrid: grains", Kind::Line, series(&h, "dem_items")?),
            Series::new("hybrid: material points", Kind::Line, series(&h, "mpm_items")?),
            Series::new("pure DEM: grains", Kind::Dashed, series(&d, "dem_items")?),
        ],
        ..Chart::default()
    };
    part.chart(
        &args.out,
        stem,
        format!("{scene}: grains and points over time, hybrid and pure DEM"),
        &chart,
    )?;
    let (hw, dw) = (h.last("wall_s")?, d.last("wall_s")?);
    Ok(format!(
        "| `{scene}` | {} | {} | {:.0} → {:.0} | {:.0} → {:.0} | {:.0} | {hw:.1} | {dw:.1} | {:.2}x |",
        participants_of(hybrid_dir).join(", "),
        participants_of(dem_dir).join(", "),
        h.first("dem_items")?,
        h.last("dem_items")?,
        h.first("mpm_items")?,
        h.last("mpm_items")?,
        d.mean("dem_items")?,
        dw / hw
    ))
}
