//! `grains bench hybrid`: wall time of the hybrid column collapse against the pure DEM one at
//! the scale of 100,000 grains, and what the separate processes cost on the hybrid run.
//!
//! Both scenes of `scenes/` are enlarged by overrides to a column of `--width` × 0.4 m (about
//! 100,000 grains of 1 mm at the default 0.3 m) in a domain of 0.5 × 0.45 m and run for
//! `--duration` of simulated time without frames: the DEM (100 substeps of 5e-7 s per
//! macro-step), then the hybrid with each `--substeps` k (MPM step k × 5e-7 s), the first k
//! also in-process. The figures are whole-run wall times from `metrics.csv` (`wall_s`).

use crate::run::{RunOptions, Status, TransportKind, run};
use anyhow::bail;
use grains_protocol::Role;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct HybridArgs {
    /// Directory of column_collapse_2d.toml and column_collapse_hybrid_2d.toml.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Column width [m] (height 0.4 m): 0.3 gives about 100,000 grains.
    #[arg(long, default_value_t = 0.3)]
    pub width: f64,
    /// Simulated time of every run [s].
    #[arg(long, default_value_t = 0.005)]
    pub duration: f64,
    /// DEM substeps per MPM step of the hybrid runs.
    #[arg(long, value_delimiter = ',', default_values_t = [10u32, 20, 40])]
    pub substeps: Vec<u32>,
    /// Where the runs and the result table go.
    #[arg(long, default_value = "out/bench/hybrid")]
    pub out: PathBuf,
}

struct Row {
    label: String,
    grains: u64,
    points: u64,
    wall: f64,
}

/// (first row's grains, first row's points, last row's wall_s) of a run.
fn read(dir: &Path) -> anyhow::Result<(u64, u64, f64)> {
    let t = crate::metrics::MetricsTable::read(dir)?;
    let first = |role| -> anyhow::Result<u64> { Ok(t.participant(role, "items")?.and_then(|v| v.first().copied()).unwrap_or(0.0) as u64) };
    Ok((first(Role::Dem)?, first(Role::Mpm)?, t.last("wall_s")?))
}

fn one(args: &HybridArgs, scene: &str, transport: TransportKind, extra: &[String]) -> anyhow::Result<(u64, u64, f64)> {
    let mut overrides = vec![
        format!("body.0.max=[{},0.4015]", args.width),
        "domain.max=[0.5,0.45]".to_string(),
        format!("run.duration={}", args.duration),
        "output.frames_every=0".to_string(),
    ];
    overrides.extend(extra.iter().cloned());
    let outcome = run(&RunOptions {
        bridge: None,
        scene_path: args.scenes.join(scene),
        transport,
        external: Vec::new(),
        out_root: args.out.clone(),
        progress: false,
        overrides,
        announce: false,
    })?;
    if outcome.status != Status::Completed {
        bail!("{scene}: the run did not complete: {}", outcome.message);
    }
    read(&outcome.dir)
}

pub fn bench(args: &HybridArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let mut rows = Vec::new();
    tracing::info!("bench hybrid: DEM column {} × 0.4 m, {} s", args.width, args.duration);
    let (grains, _, wall) = one(args, "column_collapse_2d.toml", TransportKind::Ipc, &[])?;
    rows.push(Row {
        label: "DEM, 100 substeps of 5e-7 s".into(),
        grains,
        points: 0,
        wall,
    });
    for (n, &k) in args.substeps.iter().enumerate() {
        let extra = [format!("coupling.substeps={k}"), format!("run.dt={:e}", k as f64 * 5e-7)];
        let transports: &[TransportKind] = if n == 0 {
            &[TransportKind::Ipc, TransportKind::Inproc]
        } else {
            &[TransportKind::Ipc]
        };
        for &t in transports {
            tracing::info!("bench hybrid: hybrid k = {k} ({t:?})");
            let (grains, points, wall) = one(args, "column_collapse_hybrid_2d.toml", t, &extra)?;
            let how = if t == TransportKind::Ipc { "processes" } else { "threads" };
            rows.push(Row {
                label: format!("hybrid, k = {k}, {how}"),
                grains,
                points,
                wall,
            });
        }
    }
    let dem_wall = rows[0].wall;
    let mut md = format!(
        "# grains bench hybrid\n\nColumn collapse, column {} × 0.4 m, {} s simulated, no frames (`grains bench hybrid`).\n\n\
         | run | DEM grains | MPM points | wall s | speed-up over DEM |\n|---|---:|---:|---:|---:|\n",
        args.width, args.duration
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.2} | {:.2}× |\n",
            r.label,
            r.grains,
            r.points,
            r.wall,
            dem_wall / r.wall
        ));
    }
    if let (Some(p), Some(t)) = (rows.get(1), rows.get(2)) {
        md.push_str(&format!(
            "\nSeparate processes over threads on the hybrid run (k = {}): {:+.1}% (one run each).\n",
            args.substeps[0],
            100.0 * (p.wall / t.wall - 1.0)
        ));
    }
    print!("{md}");
    let path = args.out.join("hybrid.md");
    std::fs::File::create(&path)?.write_all(md.as_bytes())?;
    tracing::info!("bench hybrid: table written to {}", path.display());
    Ok(())
}
