//! `grains validate --part cost`: accuracy against cost. Each run's error against the finest
//! pure-DEM run of the same problem, against its wall time, with the Pareto front marked (the
//! runs no other run beats in both).
//!
//! - **Column collapse, a = 1**: the reference is the DEM of 1-mm grains on packing 1 (the
//!   column part's run). DEM of 1.5- and 2-mm grains (own poured packings; viscous damping
//!   scaled with √m ∝ d so that the restitution stays that of the 1-mm grains, DEM step scaled
//!   with d as the critical step), DEM of 1-mm grains with steps of 2e-6 and 7.1e-6 s (the
//!   scene's 5e-7 s is 1/72 of the critical step), MPM on 4-, 2- and 1-mm cells (step ∝ cell), hybrid with
//!   discrete layers of 2, 4 and 8 mm on 2-mm cells and 8 mm on 4-mm cells. Errors: runout
//!   |ΔL/ΔL_ref − 1| and the profile's L1 distance (in reference grain diameters).
//! - **Silo, 6-mm orifice**: the reference is the DEM silo; hybrid with discrete layers of 4
//!   and 8 mm, MPM on 1- and 2-mm cells. Error: |W/W_ref − 1| of the discharge rate. A coarser
//!   DEM is left out here: grains of 1.5 d would make the orifice 4 grains wide, another
//!   silo (Beverloo's k d term), not a cheaper model of the same one.

use super::args::ValidateArgs;
use super::column::run_case;
use super::deposit::{BIN, FRONT_HEIGHT, deposit, front, profile, profile_l1};
use super::packings;
use super::runs::{RunResult, finished, load_with};
use super::scenes::column::{BOTTOM, DEM, HYBRID, L0, MPM};
use super::scenes::silo::SCENE as SILO;
use super::silo::{self, Model};
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series, pareto_front};
use grains_protocol::Role;
use std::fmt::Write as _;

/// One run of the chart.
struct Row {
    family: &'static str,
    label: String,
    wall: f64,
    /// Relative error of the headline measure (runout or discharge rate).
    error: f64,
    /// Profile L1 in grain diameters (column only; NaN otherwise).
    l1: f64,
    grains: u64,
    points: u64,
    /// The run, for its picture.
    dir: std::path::PathBuf,
    /// The deposit's front [m] (column only; NaN otherwise).
    front: f64,
}

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Accuracy against cost\n\n");
    md.push_str(
        "Every run's error against the finest pure-DEM run of the same problem, against its wall time (one run each, \
         on this machine, beside nothing else the validation starts). Pareto front: the runs no other run beats in both \
         wall time and error.\n\n",
    );
    let column = column_rows(args)?;
    table(&mut md, "Column collapse, a = 1 (error: runout)", &column, true);
    part.chart(
        &args.out,
        "cost_column",
        "Column collapse: runout error against wall time",
        &cost_chart(
            "Column collapse a = 1: accuracy against cost",
            "|runout / DEM(1 mm) runout - 1|",
            &column,
        ),
    )?;
    let reach = column.iter().map(|r| r.front).fold(L0, f64::max);
    super::pictures::last_frames(
        &mut part,
        &args.out,
        "cost_column_pictures",
        "Column collapse a = 1: the deposit of every run of the chart, one row per model",
        &by_family(&column),
        Some(([0.0, 0.0], [1.15 * reach, 1.15 * (BOTTOM + L0)])),
    )?;
    let silo = silo_rows(args)?;
    let silo_title = format!(
        "Silo, 6-mm orifice, filled to {:.0} mm (error: discharge rate)",
        args.silo_fill * 1e3
    );
    table(&mut md, &silo_title, &silo, false);
    let labelled: Vec<(String, &std::path::Path)> = by_family(&silo).into_iter().flatten().collect();
    let runs: Vec<(&str, &std::path::Path)> = labelled.iter().map(|(l, d)| (l.as_str(), *d)).collect();
    super::pictures::side_by_side(
        &mut part,
        &args.out,
        "cost_silo_pictures",
        "Silo, 6-mm orifice: every run of the chart at 0.25 s",
        &runs,
        &[0.25],
        None,
    )?;
    part.chart(
        &args.out,
        "cost_silo",
        "Silo: discharge-rate error against wall time",
        &cost_chart("Silo, 6 mm orifice: accuracy against cost", "|W / DEM W - 1|", &silo),
    )?;
    part.md = md;
    Ok(part)
}

fn table(md: &mut String, title: &str, rows: &[Row], l1: bool) {
    let front = pareto_front(&rows.iter().map(|r| (r.wall, r.error)).collect::<Vec<_>>());
    let _ = writeln!(
        md,
        "### {title}\n\n| model | run | grains | points | wall s | error |{} Pareto |\n|---|---|---:|---:|---:|---:|{}---|",
        if l1 { " profile L1 (d) |" } else { "" },
        if l1 { "---:|" } else { "" }
    );
    for (i, r) in rows.iter().enumerate() {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.1} | {:.1}% |{} {} |",
            r.family,
            r.label,
            r.grains,
            r.points,
            r.wall,
            100.0 * r.error,
            if l1 { format!(" {:.2} |", r.l1) } else { String::new() },
            if front.contains(&i) { "yes" } else { "" }
        );
    }
    md.push('\n');
}

/// The rows' runs grouped by model (DEM, MPM, hybrid), each labelled by its run.
fn by_family(rows: &[Row]) -> Vec<Vec<(String, &std::path::Path)>> {
    ["DEM", "MPM", "hybrid"]
        .iter()
        .map(|family| {
            rows.iter()
                .filter(|r| r.family == *family)
                // The label without its note in brackets.
                .map(|r| (format!("{family} {}", r.label.split(" (").next().unwrap_or("")), r.dir.as_path()))
                .collect()
        })
        .collect()
}

fn cost_chart(title: &str, y: &str, rows: &[Row]) -> Chart {
    let mut chart = Chart {
        title: title.into(),
        x_label: "wall time [s]".into(),
        y_label: y.into(),
        log_x: true,
        log_y: true,
        legend_low: true,
        notes: rows.iter().map(|r| (r.wall, r.error.max(1e-3), format!("  {}", r.label))).collect(),
        ..Chart::default()
    };
    for family in ["DEM", "MPM", "hybrid"] {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.family == family)
            // The reference has no error: drawn at 0.1% so that it shows on a log axis (its
            // label says so).
            .map(|r| (r.wall, r.error.max(1e-3)))
            .collect();
        if !pts.is_empty() {
            chart.series.push(Series::new(family, Kind::Points, pts));
        }
    }
    let mut front: Vec<(f64, f64)> = pareto_front(&rows.iter().map(|r| (r.wall, r.error)).collect::<Vec<_>>())
        .into_iter()
        .map(|i| (rows[i].wall, rows[i].error.max(1e-3)))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart.series.push(Series::new("Pareto front", Kind::Dashed, front));
    chart
}

fn column_rows(args: &ValidateArgs) -> anyhow::Result<Vec<Row>> {
    let a = 1.0;
    let hybrid = load_with(&args.scenes.join(HYBRID), &[])?;
    let n_bins = ((hybrid.domain.max[0] / BIN) as usize).max(1);
    let packing = packings::column(args, a, 1)?;
    tracing::info!("validate: cost, column: DEM 1 mm (reference)");
    let reference = run_case(args, DEM, &packing, a, &[])?;
    let h_ref = profile(&deposit(&reference.dir, 0.0)?, BIN, n_bins);
    let runout_ref = front(&h_ref, BIN, FRONT_HEIGHT) - L0;
    let mut rows = Vec::new();
    let mut push = |family: &'static str, label: String, r: &RunResult, point_half: f64| -> anyhow::Result<()> {
        let h = profile(&deposit(&r.dir, point_half)?, BIN, n_bins);
        let f = front(&h, BIN, FRONT_HEIGHT);
        let error = ((f - L0) / runout_ref - 1.0).abs();
        tracing::info!(
            "validate: cost, column {family} {label}: front {f:.3} m, error {:.1}%, {:.1} s",
            100.0 * error,
            r.wall
        );
        rows.push(Row {
            family,
            label,
            wall: r.wall,
            error,
            l1: profile_l1(&h_ref, &h, (f).max(runout_ref + L0)),
            grains: r.grains,
            points: r.points,
            dir: r.dir.clone(),
            front: f,
        });
        Ok(())
    };
    push("DEM", "d = 1 mm (reference, error drawn at 0.1%)".into(), &reference, 0.0)?;
    for s in [1.5f64, 2.0] {
        let d = s * 1e-3;
        let grain = vec![
            format!("material.0.dem.radius={}", 0.5 * d),
            format!("material.0.dem.radius_std={}", 4e-5 * s),
            format!("material.0.dem.damping={}", 7.0 * s),
            format!("coupling.substeps={}", (100.0 / s).round()),
        ];
        let packing = packings::coarse_column(args, s, &grain)?;
        let mut extra = grain.clone();
        extra.extend([format!("body.0.min=[0.0,{}]", 1.5 * d), format!("body.1.max=[0.5,{}]", 1.3 * d)]);
        // run_case puts the column's top at 1.5 mm + a L0; the coarse floor row is thicker.
        extra.push(format!("body.0.max=[{L0},{}]", 1.5 * d + a * L0));
        tracing::info!("validate: cost, column: DEM d = {s} mm");
        let r = run_case(args, DEM, &packing, a, &extra)?;
        push("DEM", format!("d = {s} mm"), &r, 0.0)?;
    }
    // The scene's DEM step (Chen 2021: 5e-7 s) is 1/72 of the critical step; larger ones, up
    // to the 1/5 `grains run` allows.
    for substeps in [25, 7] {
        tracing::info!("validate: cost, column: DEM d = 1 mm, {substeps} substeps");
        let r = run_case(args, DEM, &packing, a, &[format!("coupling.substeps={substeps}")])?;
        push("DEM", format!("d = 1 mm, dt = {:.2e} s", 5e-5 / substeps as f64), &r, 0.0)?;
    }
    let mpm = args.scenes.join(MPM);
    for cell in [4.0, 2.0, 1.0] {
        let h = cell * 1e-3;
        let mut overrides = vec![
            format!("body.0.max=[{L0},{}]", a * L0),
            "run.duration=0.3".to_string(),
            format!("domain.cell_size={h}"),
            // The material stays two cells inside the domain's wall layers.
            format!("domain.min=[{},{}]", -3.0 * h, -3.0 * h),
            format!("run.dt={:e}", 1e-5 * cell / 2.0),
        ];
        let steps = load_with(&mpm, &overrides)?.steps;
        overrides.push(format!("output.frames_every={steps}"));
        tracing::info!("validate: cost, column: MPM cell {cell} mm");
        let r = finished(args, &mpm, overrides)?;
        push("MPM", format!("cell {cell} mm"), &r, 0.25 * h)?;
    }
    for (cell, layer) in [(2.0, 2.0), (2.0, 4.0), (2.0, 8.0), (4.0, 8.0)] {
        let extra = vec![
            format!("domain.cell_size={}", cell * 1e-3),
            format!("domain.min=[{},{}]", -3e-3 * cell, -3e-3 * cell),
            format!("coupling.discrete_layer={}", layer * 1e-3),
            format!("coupling.hybrid_band={}", layer * 1e-3),
        ];
        tracing::info!("validate: cost, column: hybrid cell {cell} mm, layer {layer} mm");
        let r = run_case(args, HYBRID, &packing, a, &extra)?;
        push("hybrid", format!("cell {cell} mm, layer {layer} mm"), &r, 0.25 * cell * 1e-3)?;
    }
    Ok(rows)
}

fn silo_rows(args: &ValidateArgs) -> anyhow::Result<Vec<Row>> {
    let packing = packings::silo(args)?;
    let w = Some(silo::REFERENCE);
    let mut rows = Vec::new();
    tracing::info!("validate: cost, silo: DEM (reference)");
    let reference = silo::run_silo(args, SILO, &packing, Model::Dem, w, None, &[])?;
    let mut push = |family: &'static str, label: String, r: silo::SiloRun| -> anyhow::Result<()> {
        let error = (r.rate / reference.rate - 1.0).abs();
        tracing::info!(
            "validate: cost, silo {family} {label}: W {:.3}, error {:.1}%, {:.1} s",
            r.rate,
            100.0 * error,
            r.wall
        );
        rows.push(Row {
            family,
            label,
            wall: r.wall,
            error,
            l1: f64::NAN,
            grains: r.grains.round() as u64,
            points: MetricsTable::read(&r.dir)?
                .participant(Role::Mpm, "items")?
                .map_or(0.0, |v| v.iter().sum::<f64>() / v.len().max(1) as f64)
                .round() as u64,
            dir: r.dir,
            front: f64::NAN,
        });
        Ok(())
    };
    for layer in [4.0, 8.0] {
        let extra = [
            format!("coupling.discrete_layer={}", layer * 1e-3),
            format!("coupling.hybrid_band={}", layer * 1e-3),
        ];
        tracing::info!("validate: cost, silo: hybrid layer {layer} mm");
        let r = silo::run_silo(args, SILO, &packing, Model::Hybrid, w, None, &extra)?;
        push("hybrid", format!("cell 2 mm, layer {layer} mm (mean counts)"), r)?;
    }
    for cell in [silo::MPM_CELL, 2.0 * silo::MPM_CELL] {
        let extra = [
            format!("domain.cell_size={cell}"),
            format!("run.dt={:e}", silo::MPM_DT * cell / silo::MPM_CELL),
        ];
        tracing::info!("validate: cost, silo: MPM cell {} mm", cell * 1e3);
        let r = silo::run_silo(args, SILO, &packing, Model::Mpm, w, None, &extra)?;
        push("MPM", format!("cell {} mm", cell * 1e3), r)?;
    }
    let reference_wall = reference.wall;
    let grains = reference.grains.round() as u64;
    let dir = reference.dir.clone();
    rows.insert(
        0,
        Row {
            family: "DEM",
            label: "d = 1 mm (reference, error drawn at 0.1%; mean grains)".into(),
            wall: reference_wall,
            error: 0.0,
            l1: f64::NAN,
            grains,
            points: 0,
            dir,
            front: f64::NAN,
        },
    );
    Ok(rows)
}
