//! `grains bench hybrid`: the hybrid column collapse against the pure DEM one, from the same
//! settled packing of about 100,000 grains, with the same grains, contact law and DEM step
//! (5e-7 s) in both: wall time per simulated second, the speed-up, and how far the front has
//! run in each at the end of the window.
//!
//! The packing is `scenes/column_packing_2d.toml` widened to `--width` and poured to 0.4 m
//! by `grains pack` (with a DEM step of 5e-6 s: only the pour, not the measured runs; kept in
//! `--out` and reused). The DEM run is `column_collapse_2d.toml` on it (two threads: the whole
//! machine); each hybrid run is `column_collapse_hybrid_2d.toml` on it with `--cells` MPM cells,
//! `coupling.substeps = "auto"` (DEM step 5e-7 s, the MPM at its stable step) and one thread
//! per solver (the DEM and the MPM share the machine's two cores), with fixed layered zones and
//! the "flip" transfer and, with `--surface`, also as the scene ships (surface oracle, "pic",
//! continuum where the inertial number is under 1e-3). Every run writes one frame at the end; the
//! front is validate's (1-mm bins, the first whose three-bin mean height is under 3.5 mm).

use crate::validate::deposit::{BIN, FRONT_HEIGHT, deposit, front, profile};
use anyhow::Context;
use grains_protocol::Role;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct HybridArgs {
    /// Directory of the column scenes.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Column width [m] (height 0.4 m): 0.3 gives about 100,000 grains.
    #[arg(long, default_value_t = 0.3)]
    pub width: f64,
    /// Simulated time of every run [s].
    #[arg(long, default_value_t = 0.1)]
    pub window: f64,
    /// MPM cell sizes of the hybrid runs [m].
    #[arg(long, value_delimiter = ',', default_values_t = [0.004])]
    pub cells: Vec<f64>,
    /// Also run the hybrid with the surface oracle (Yue 2018 §4, every 1 ms).
    #[arg(long)]
    pub surface: bool,
    /// Extra `--set` overrides of the hybrid runs.
    #[arg(long = "set-hybrid", value_name = "KEY=VALUE")]
    pub hybrid_overrides: Vec<String>,
    /// Where the packing, the runs and the result table go.
    #[arg(long, default_value = "out/bench/hybrid")]
    pub out: PathBuf,
}

/// The DEM step of every measured run [s] (the column scenes').
const DEM_DT: f64 = 5e-7;
/// Column height [m] and the bottom of the column (over the glued floor row) [m].
const HEIGHT: f64 = 0.4;
const BOTTOM: f64 = 0.0015;

struct Row {
    label: String,
    grains: u64,
    points: u64,
    /// Mean grains and points over the run.
    mean_grains: f64,
    mean_points: f64,
    substeps: u32,
    steps: u64,
    /// The macro-step [s].
    dt: f64,
    wall: f64,
    front: f64,
    /// Mean compute time of the DEM and of the MPM per macro-step [s].
    dem_step: f64,
    mpm_step: f64,
}

/// The settled packing of the bench's column, poured once.
fn packing(args: &HybridArgs) -> anyhow::Result<PathBuf> {
    let path = std::path::absolute(args.out.join(format!("packing_{:.0}mm.data", args.width * 1e3)))?;
    if path.exists() {
        return Ok(path);
    }
    // A lattice settles to about 0.78 of its height.
    let pour_top = BOTTOM + HEIGHT / 0.76;
    let settle = (2.0 * pour_top / 9.81).sqrt() + 0.25;
    tracing::info!("bench hybrid: pouring the {} m column (grains pack, once)", args.width);
    crate::pack::pack(&crate::pack::PackArgs {
        scene: args.scenes.join("column_packing_2d.toml"),
        out: path.clone(),
        friction: None,
        overrides: vec![
            format!("body.0.max=[{},{pour_top}]", args.width),
            format!("body.1.max=[{},0.0013]", args.width),
            format!("wall.2.point=[{},0.0]", args.width),
            format!("domain.max=[{},{}]", args.width, pour_top + 0.01),
            "run.dt=5e-5".into(),
            "coupling.substeps=10".into(),
            format!("run.duration={settle:.2}"),
        ],
    })?;
    Ok(path)
}

/// The overrides both models share: the column cut from the packing, the domain, the window,
/// one frame at the end.
fn common(args: &HybridArgs, packing: &Path) -> Vec<String> {
    vec![
        format!("body.0.max=[{},{}]", args.width, BOTTOM + HEIGHT),
        format!("body.0.packing={:?}", packing.display().to_string()),
        format!("body.1.max=[{},0.0013]", args.width + 0.3),
        format!("domain.max=[{},{}]", args.width + 0.3, HEIGHT + 0.05),
        format!("run.duration={}", args.window),
    ]
}

fn one(args: &HybridArgs, scene: &str, label: String, overrides: Vec<String>) -> anyhow::Result<Row> {
    let (dir, run_scene) = super::run_resolved(&args.scenes.join(scene), &label, &overrides, &args.out, true)?;
    let dir = &dir;
    let t = crate::metrics::MetricsTable::read(dir)?;
    let first = |role| -> anyhow::Result<u64> { Ok(t.participant(role, "items")?.and_then(|v| v.first().copied()).unwrap_or(0.0) as u64) };
    let mean = |role, what| -> anyhow::Result<f64> {
        let v = t.participant(role, what)?.unwrap_or_default();
        Ok(if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        })
    };
    let half = 0.5 * run_scene.domain.cell_size / run_scene.mpm.points_per_axis as f64;
    let n_bins = (run_scene.domain.max[0] / BIN) as usize;
    let front = front(&profile(&deposit(dir, half)?, BIN, n_bins), BIN, FRONT_HEIGHT);
    Ok(Row {
        label,
        grains: first(Role::Dem)?,
        points: first(Role::Mpm)?,
        mean_grains: mean(Role::Dem, "items")?,
        mean_points: mean(Role::Mpm, "items")?,
        substeps: run_scene.coupling.substeps,
        steps: run_scene.steps,
        dt: run_scene.dt,
        wall: t.last("wall_s")?,
        front,
        dem_step: 1e-3 * mean(Role::Dem, "compute_ms")?,
        mpm_step: 1e-3 * mean(Role::Mpm, "compute_ms")?,
    })
}

pub fn bench(args: &HybridArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let packing = packing(args)?;
    let base = common(args, &packing);
    let mut rows = Vec::new();
    rows.push(one(args, "column_collapse_2d.toml", "DEM, 2 threads".into(), {
        let mut o = base.clone();
        o.push("run.threads=2".into());
        o
    })?);
    for &h in &args.cells {
        // oracle.every counts macro-steps of run.dt's bound: 1 ms.
        // Fixed zones with "flip": with "pic" a band in yielding material holds the column up
        // (docs/validation.md).
        let fixed = ["oracle.kind=\"fixed\"", "coupling.grain_transfer=\"flip\""];
        let mut kinds = vec![("layered zones, flip", fixed.map(String::from).to_vec())];
        if args.surface {
            kinds.push((
                "surface oracle, pic, I < 1e-3",
                vec!["oracle.kind=\"surface\"".into(), "oracle.every=1".into()],
            ));
        }
        for (kind, extra) in kinds {
            let mut o = base.clone();
            o.extend([
                "run.threads=1".to_string(),
                "coupling.substeps=\"auto\"".into(),
                format!("coupling.dem_dt={DEM_DT:e}"),
                "run.dt=1e-3".into(),
                format!("domain.cell_size={h}"),
                // Two cells of room under and left of the material for the MPM's wall layers.
                format!("domain.min=[{},{}]", -3.0 * h, -3.0 * h),
            ]);
            o.extend(extra);
            o.extend(args.hybrid_overrides.iter().cloned());
            rows.push(one(
                args,
                "column_collapse_hybrid_2d.toml",
                format!("hybrid, {} mm cells, {kind}", h * 1e3),
                o,
            )?);
        }
    }
    let md = table(args, &rows);
    print!("{md}");
    let path = args.out.join("hybrid.md");
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(md.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))?;
    tracing::info!("bench hybrid: table written to {}", path.display());
    Ok(())
}

fn table(args: &HybridArgs, rows: &[Row]) -> String {
    let dem = &rows[0];
    let (dem_run, dem_wall) = (dem.front - args.width, dem.wall);
    let mut md = format!(
        "# grains bench hybrid\n\nColumn collapse {} × {HEIGHT} m from a settled packing, {} s simulated, DEM step {DEM_DT:e} s in \
         every run (`grains bench hybrid`). Speed-up: the DEM's wall time over the run's. Runout: how far the front has moved \
         past the column's foot at the end of the window.\n\n\
         | run | DEM grains | MPM points | k | wall s | wall s per simulated s | speed-up | DEM / MPM compute s per simulated s | front m | runout m | runout vs DEM |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        args.width, args.window
    );
    for r in rows {
        let runout = r.front - args.width;
        md.push_str(&format!(
            "| {} | {} | {} | {} | {:.1} | {:.0} | {:.2}× | {:.1} / {:.1} | {:.3} | {:.3} | {:+.1}% |\n",
            r.label,
            r.grains,
            r.points,
            r.substeps,
            r.wall,
            r.wall / args.window,
            dem_wall / r.wall,
            r.dem_step / r.dt,
            r.mpm_step / r.dt,
            r.front,
            runout,
            100.0 * (runout / dem_run - 1.0)
        ));
    }
    if let Some(c) = fit(rows) {
        md.push_str(&format!(
            "\nCosts fitted to these runs (`launch/src/cost.rs`): DEM alone {:.3e} s per grain-step (2 threads), the hybrid's DEM \
             {:.3e} s per grain-step (1 thread), its MPM {:.3e} s per point-step (1 thread), {:.3e} s per macro-step beside them.\n",
            c.dem_alone, c.dem_hybrid, c.mpm, c.step
        ));
        md.push_str("\n| run | wall s | model s |\n|---|---:|---:|\n");
        for r in rows {
            let n = crate::cost::Counts {
                hybrid_grains: r.mean_grains as usize,
                points: r.mean_points as usize,
                all_grains: rows[0].mean_grains as usize,
                substeps: r.substeps,
                steps: r.steps,
            };
            let (h, d) = crate::cost::predict(&c, &n);
            md.push_str(&format!(
                "| {} | {:.1} | {:.1} |\n",
                r.label,
                r.wall,
                if r.points == 0 { d } else { h }
            ));
        }
    }
    md
}

fn sample(r: &Row) -> crate::cost::Sample {
    crate::cost::Sample {
        grains: r.mean_grains,
        points: r.mean_points,
        substeps: r.substeps,
        steps: r.steps,
        wall: r.wall,
        dem_step: r.dem_step,
        mpm_step: r.mpm_step,
    }
}

fn fit(rows: &[Row]) -> Option<crate::cost::Costs> {
    let hybrid: Vec<_> = rows.iter().skip(1).map(sample).collect();
    crate::cost::fit(&sample(rows.first()?), &hybrid)
}
