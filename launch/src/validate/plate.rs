//! `grains validate --part plate`: plate indentation (Chen 2021 §6.3, scaled to this machine).
//! A rigid plate scripted down at 5 cm/s into the middle of a bed of grains
//! (`plate_indentation_2d.toml`, its bed cut from a poured packing) and of the same bed as the
//! continuum calibrated on a DEM biaxial test of those grains (`plate_indentation_mpm_2d.toml`):
//! the plate's force against its depth for both, the DEM on `--packings` beds (default 2). The
//! continuum's curve is a prediction (its friction angle and stiffness come from another test,
//! not from this one); the check compares it with the DEM's mean over the second half of the
//! travel. Then §6.3.1's far-field loading: the same on packing 1 with the left wall pushed in
//! at 5 cm/s, the plate's forces and the strain pictures. Last, Chen's hybrid (the continuum
//! turning discrete where the bands form, `plate_indentation_hybrid_2d.toml`: its own bed and
//! a segment wall for the plate, as a rigid plate does not meet a hybrid band) against the
//! same scene as a DEM from the same packing and as the continuum, trained and untrained.

use super::args::ValidateArgs;
use super::packings;
use super::pictures;
use super::runs::{finished, load_with};
use super::scenes::plate::{B, CENTRE, DEM, DEPTH, HALF_HEIGHT, HYBRID, MPM, TOP, WIDTH};
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use anyhow::Context as _;
use std::fmt::Write as _;
use std::path::Path;

/// The continuum's mean force over the second half of the travel within this share of the
/// DEM's: the bearing capacity of a calibrated continuum, as predicted, not fitted.
const TOLERANCE: f64 = 0.3;
/// The plate starts this far above the bed's top [m], and moves down at this speed [m/s]
/// (Chen's).
const GAP: f64 = 0.0015;
const SPEED: f64 = 0.05;
/// The DEM runs' duration: the gap and [`DEPTH`] at 5 cm/s, and a little more [s] (the
/// continuum scene's is the same).
const END: f64 = (GAP + DEPTH) / SPEED + 0.01;

/// The plate's (depth below [`TOP`], force along `axis`: "x" or "y") of a run, per
/// macro-step; `k` the plate's body index in `bodies.csv`.
fn bearing(dir: &Path, k: usize, axis: &str) -> anyhow::Result<Vec<(f64, f64)>> {
    let path = dir.join("bodies.csv");
    let t = MetricsTable::parse(&std::fs::read_to_string(&path)?, &path)?;
    let (y, f) = (t.column(&format!("body{k}_y"))?, t.column(&format!("body{k}_f{axis}"))?);
    Ok(y.iter().zip(&f).map(|(y, f)| (TOP - (y - HALF_HEIGHT), *f)).collect())
}

/// The mean force of a curve over depths [a, b].
fn mean_over(curve: &[(f64, f64)], a: f64, b: f64) -> f64 {
    let inside: Vec<f64> = curve.iter().filter(|(d, _)| *d >= a && *d <= b).map(|(_, f)| *f).collect();
    inside.iter().sum::<f64>() / inside.len().max(1) as f64
}

/// The continuum scene in `dir`, once both plate scenes there are checked to be what the part
/// reads: the bed's top at [`TOP`], the run [`END`] long, each plate [`B`] wide and
/// 2 [`HALF_HEIGHT`] tall about [`CENTRE`], moving down at [`SPEED`], the continuum's [`GAP`]
/// above the bed (the DEM's is set by the part).
fn checked_scenes(dir: &Path) -> anyhow::Result<grains_protocol::scene::Scene> {
    let mpm_path = dir.join(MPM);
    let mpm_scene = load_with(&mpm_path, &[])?;
    let mpm_top = match mpm_scene.bodies[0].shape {
        grains_protocol::scene::Shape::Box { max, .. } => max[1],
        _ => f64::NAN,
    };
    anyhow::ensure!(
        (mpm_top - TOP).abs() < 1e-12,
        "{}: the bed's top is {mpm_top} m, the validation reads it at {TOP} m",
        mpm_path.display()
    );
    let duration = mpm_scene.steps as f64 * mpm_scene.dt;
    anyhow::ensure!(
        (duration - END).abs() <= mpm_scene.dt,
        "{}: the run lasts {duration} s, the validation reads it to {END} s",
        mpm_path.display()
    );
    // Both scenes' plates as the depths are read: B wide, 2 HALF_HEIGHT tall, centred on CENTRE,
    // down at SPEED; the continuum's starting GAP above the bed (the part sets the DEM's).
    let dem_scene = load_with(&dir.join(DEM), &[])?;
    for (scene, k, path) in [(&mpm_scene, 1, &mpm_path), (&dem_scene, 0, &dir.join(DEM))] {
        let plate = scene.rigids.get(k).context("no plate")?;
        let span = |axis: usize| {
            let v = plate.vertices.iter().map(|p| p[axis]);
            (
                v.clone().fold(f64::INFINITY, f64::min) - plate.radius,
                v.fold(f64::NEG_INFINITY, f64::max) + plate.radius,
            )
        };
        let ((left, right), (bottom, top)) = (span(0), span(1));
        let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
        let bottom_ok = k == 0 || near(bottom, TOP + GAP);
        anyhow::ensure!(
            near(right - left, B)
                && near(0.5 * (left + right), CENTRE)
                && near(top - bottom, 2.0 * HALF_HEIGHT)
                && bottom_ok
                && plate.velocity == [0.0, -SPEED],
            "{}: rigid.{k} is not the plate the validation reads ({B} m wide, {} m tall, centred at x = {CENTRE} m, moving at \
             [0, -{SPEED}] m/s, the continuum's bottom at {} m)",
            path.display(),
            2.0 * HALF_HEIGHT,
            TOP + GAP
        );
    }
    Ok(mpm_scene)
}

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Plate indentation (Chen 2021 §6.3)\n\n");
    let mpm_path = args.scenes.join(MPM);
    let mpm_scene = checked_scenes(&args.scenes)?;
    let seeds = args.packings.unwrap_or(2);
    anyhow::ensure!(seeds >= 1, crate::run::BadInput("--packings: at least 1".into()));
    // Each DEM bed cut at TOP, the plate GAP above it (outline: vertices + its 0.5-mm radius).
    let (x0, x1) = (CENTRE - 0.5 * B + 0.0005, CENTRE + 0.5 * B - 0.0005);
    let (y0, y1) = (TOP + GAP + 0.0005, TOP + GAP + 2.0 * HALF_HEIGHT - 0.0005);
    let dem_bed = |seed: u64| -> anyhow::Result<Vec<String>> {
        let packing = packings::plate(args, seed)?;
        Ok(vec![
            format!("body.0.packing={:?}", packing.display().to_string()),
            format!("body.0.max=[{WIDTH},{TOP}]"),
            format!("rigid.0.vertices=[[{x0},{y0}],[{x1},{y0}],[{x1},{y1}],[{x0},{y1}]]"),
            format!("run.duration={END:.3}"),
        ])
    };
    let mut dems = Vec::new();
    for seed in 1..=seeds {
        tracing::info!("validate: plate, DEM bed of packing {seed}");
        let run = finished(args, &args.scenes.join(DEM), dem_bed(seed)?)?;
        let curve = bearing(&run.dir, 0, "y")?;
        dems.push((run, curve));
    }
    let mpm = finished(args, &mpm_path, Vec::new())?;
    let continuum = bearing(&mpm.dir, 1, "y")?;
    let gamma = {
        let m = &mpm_scene.materials[mpm_scene.bodies[0].material];
        m.density * m.mpm.as_ref().map_or(1.0, |m| m.packing) * 9.81
    };
    let seed_columns: String = (1..=seeds).map(|s| format!(" DEM, packing {s} [N/m] |")).collect();
    let _ = writeln!(
        md,
        "A plate {B} m wide, scripted down at 5 cm/s, into a bed {WIDTH} m wide and {TOP} m deep: {} grains cut from each of \
         {seeds} poured packings (`{DEM}`), or {} material points of the continuum calibrated on a DEM biaxial test of the same \
         grains (`{MPM}`; γ = ρ g = {gamma:.0} N/m³). Depth from the bed's top at {TOP} m (the grains' tops and the points' \
         contact disks reach about 0.5 mm above it). Force per metre of plate, the mean over ±0.5 mm of each depth. Chen's \
         Fig. 23 (DEM and hybrid): a peak, then the force fluctuating about a constant.\n\n| depth [mm] |{seed_columns} DEM \
         mean [N/m] | continuum [N/m] | continuum / DEM | DEM q/(γB) |\n|---:|{}---:|---:|---:|---:|",
        dems.iter().map(|(r, _)| r.grains.to_string()).collect::<Vec<_>>().join(" / "),
        mpm.points,
        "---:|".repeat(seeds as usize)
    );
    for mm in 1..=(DEPTH * 1e3).round() as u32 {
        let d = mm as f64 * 1e-3;
        let each: Vec<f64> = dems.iter().map(|(_, c)| mean_over(c, d - 5e-4, d + 5e-4)).collect();
        let dem = each.iter().sum::<f64>() / each.len() as f64;
        let f_mpm = mean_over(&continuum, d - 5e-4, d + 5e-4);
        let cells: String = each.iter().map(|f| format!(" {f:.1} |")).collect();
        let _ = writeln!(
            md,
            "| {mm} |{cells} {dem:.1} | {f_mpm:.1} | {:.2} | {:.2} |",
            f_mpm / dem,
            dem / B / (gamma * B)
        );
    }
    let mut chart = Chart {
        title: "Plate indentation: the plate's force against its depth".into(),
        x_label: "depth [mm]".into(),
        y_label: "force [N/m]".into(),
        ..Chart::default()
    };
    let curves = dems
        .iter()
        .enumerate()
        .map(|(k, (_, c))| (format!("DEM, packing {}", k + 1), c))
        .chain(std::iter::once(("continuum (MPM)".to_string(), &continuum)));
    for (name, c) in curves {
        chart.series.push(Series::new(
            name,
            Kind::Line,
            c.iter().filter(|(d, _)| *d >= -GAP).map(|&(d, f)| (1e3 * d, f)).collect(),
        ));
    }
    part.chart(
        &args.out,
        "plate_force",
        "The plate's force against its depth, DEM and continuum",
        &chart,
    )?;
    let (a, b) = (0.5 * DEPTH, DEPTH);
    let each: Vec<f64> = dems.iter().map(|(_, c)| mean_over(c, a, b)).collect();
    let f_dem = each.iter().sum::<f64>() / each.len() as f64;
    let f_mpm = mean_over(&continuum, a, b);
    part.check(
        "plate indentation: the calibrated continuum's force within 30% of the DEM's",
        "Chen 2021 §6.3 (the DEM as ground truth); the continuum calibrated on a biaxial test",
        format!(
            "mean over {:.0}–{:.0} mm: continuum {f_mpm:.1} N/m, DEM {f_dem:.1} N/m ({:+.1}%; the packings {})",
            1e3 * a,
            1e3 * b,
            100.0 * (f_mpm / f_dem - 1.0),
            each.iter().map(|f| format!("{f:.1}")).collect::<Vec<_>>().join(", ")
        ),
        format!("within {:.0}%", 100.0 * TOLERANCE),
        ((f_mpm / f_dem) - 1.0).abs() <= TOLERANCE,
    );
    let _ = writeln!(
        md,
        "\nWall time: DEM {} s, continuum {:.0} s.\n",
        dems.iter().map(|(r, _)| format!("{:.0}", r.wall)).collect::<Vec<_>>().join(" / "),
        mpm.wall
    );
    let view = Some(([CENTRE - 2.5 * B, 0.0], [CENTRE + 2.5 * B, TOP + 0.012]));
    // The bands (Chen's Fig. 24): the strain from about 2.5 mm of depth to the end.
    let strain = |dir: &Path| pictures::strain_scene(dir, (GAP + 0.0025) / SPEED, END, view);
    pictures::strain_rows(
        &mut part,
        &args.out,
        "plate_strain",
        "Incremental strain under the plate (Cundall's best-fit strain, dark blue none, yellow the 98th percentile and more): \
         DEM of packing 1 (top), continuum (bottom)",
        vec![("DEM, packing 1", strain(&dems[0].0.dir)?), ("continuum", strain(&mpm.dir)?)],
    )?;
    // §6.3.1: far-field loading, the left wall pushed in at the plate's speed (the DEM's
    // wall.1, the continuum's grid-node wall.0), on packing 1.
    tracing::info!("validate: plate, the left wall moving (§6.3.1)");
    let push = format!("[{SPEED},0.0]");
    let mut far = dem_bed(1)?;
    far.push(format!("wall.1.velocity={push}"));
    let dem_far = finished(args, &args.scenes.join(DEM), far)?;
    let mpm_far = finished(args, &mpm_path, vec![format!("wall.0.velocity={push}")])?;
    let forces = |dir: &Path, k: usize| -> anyhow::Result<(f64, f64)> {
        Ok((mean_over(&bearing(dir, k, "x")?, a, b), mean_over(&bearing(dir, k, "y")?, a, b)))
    };
    let _ = writeln!(
        md,
        "Far-field loading (§6.3.1): the left wall moves right at 5 cm/s through the whole run (10 mm by its end), packing 1 \
         and the continuum. The plate's mean force over {:.0}–{:.0} mm (x, y) [N/m]:\n\n| run | still walls | left wall \
         moving |\n|---|---:|---:|",
        1e3 * a,
        1e3 * b
    );
    for (label, still, moving, k) in [
        ("DEM, packing 1", &dems[0].0.dir, &dem_far.dir, 0),
        ("continuum", &mpm.dir, &mpm_far.dir, 1),
    ] {
        let ((sx, sy), (mx, my)) = (forces(still, k)?, forces(moving, k)?);
        let _ = writeln!(md, "| {label} | ({sx:.1}, {sy:.1}) | ({mx:.1}, {my:.1}) |");
    }
    let _ = writeln!(md);
    pictures::strain_rows(
        &mut part,
        &args.out,
        "plate_strain_far_field",
        "Incremental strain with the left wall pushed in at 5 cm/s (§6.3.1, Chen's Fig. 25): DEM of packing 1 (top), \
         continuum (bottom)",
        vec![
            ("DEM, left wall moving", strain(&dem_far.dir)?),
            ("continuum, left wall moving", strain(&mpm_far.dir)?),
        ],
    )?;
    hybrid(args, &mut part, &mut md)?;
    part.md = md;
    Ok(part)
}

/// The plate's (depth below `top`, force along y) per macro-step of a run of the hybrid scene:
/// the segment wall `wall`'s force from the grains (walls.csv) and from the points
/// (walls_mpm.csv), summed at each time.
fn wall_bearing(dir: &Path, wall: usize, top: f64) -> anyhow::Result<Vec<(f64, f64)>> {
    let mut by_time: std::collections::BTreeMap<i64, (f64, f64)> = std::collections::BTreeMap::new();
    for file in ["walls.csv", "walls_mpm.csv"] {
        let path = dir.join(file);
        if !path.is_file() {
            continue;
        }
        let t = MetricsTable::parse(&std::fs::read_to_string(&path)?, &path)?;
        let (time, y, f) = (
            t.column("time")?,
            t.column(&format!("wall{wall}_y"))?,
            t.column(&format!("wall{wall}_fy"))?,
        );
        for k in 0..time.len() {
            let e = by_time.entry((time[k] * 1e9).round() as i64).or_insert((y[k], 0.0));
            e.1 += f[k];
        }
    }
    anyhow::ensure!(!by_time.is_empty(), "{}: no walls.csv or walls_mpm.csv", dir.display());
    Ok(by_time.into_values().map(|(y, f)| (top - y, f)).collect())
}

/// The hybrid scene's bed top and its plate (the moving segment wall): (top, wall index).
fn hybrid_plate(scene: &grains_protocol::scene::Scene) -> anyhow::Result<(f64, usize)> {
    let top = match scene.bodies.first().map(|b| &b.shape) {
        Some(grains_protocol::scene::Shape::Box { max, .. }) => max[1],
        _ => anyhow::bail!("{}: body.0 must be the bed, a box", scene.path.display()),
    };
    let wall = scene
        .walls
        .iter()
        .position(|w| matches!(w.shape, grains_protocol::scene::WallShape::Segment { .. }) && w.velocity[1] < 0.0)
        .with_context(|| format!("{}: no segment wall moving down (the plate)", scene.path.display()))?;
    Ok((top, wall))
}

/// Chen 2021's continuum for these grains (the chute's glass beads, the same material): the
/// critical-state softening fitted by `grains bench chute --radii 0.5 --cells 0.004 --depths
/// 0.15 --continuum critical-state --cell-grains 9600` to the first shear of a 9,600-grain
/// simple-shear cell (docs/validate/chute/chute_critical_state_9600.md), started at the scene's
/// packing fraction. Fitted to another test, not to this one.
const CRITICAL_STATE: [&str; 5] = [
    "material.0.mpm.model=\"critical_state\"",
    "material.0.mpm.friction_angle=14.96",
    "material.0.mpm.packing_critical=0.8156",
    "material.0.mpm.chi=8.80",
    "material.0.mpm.xi=4.47",
];

/// Chen's hybrid on `plate_indentation_hybrid_2d.toml` against the same scene as a DEM from
/// its packing (same DEM step and substeps) and as the continuum; trained and untrained.
fn hybrid(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let path = args.scenes.join(HYBRID);
    let scene = load_with(&path, &[])?;
    let (top, wall) = hybrid_plate(&scene)?;
    let packing = scene
        .oracle
        .as_ref()
        .and_then(|o| o.shear_band.as_ref())
        .map(|b| b.packing.display().to_string())
        .with_context(|| format!("{}: not a shear-band scene", path.display()))?;
    let fixed = "oracle={kind=\"fixed\"}".to_string();
    let critical: Vec<String> = CRITICAL_STATE.iter().map(|s| s.to_string()).collect();
    let runs: [(&str, Vec<String>); 6] = [
        ("hybrid, trained", Vec::new()),
        ("hybrid, untrained", vec!["oracle.training=false".into()]),
        (
            "DEM",
            vec!["body.0.model=\"dem\"".into(), fixed.clone(), format!("body.0.packing={packing:?}")],
        ),
        ("continuum", vec!["body.0.model=\"mpm\"".into(), fixed.clone()]),
        ("hybrid, trained, critical state", critical.clone()),
        (
            "continuum, critical state",
            [critical, vec!["body.0.model=\"mpm\"".into(), fixed]].concat(),
        ),
    ];
    let mut done = Vec::new();
    for (label, overrides) in runs {
        tracing::info!("validate: plate, {label} ({HYBRID})");
        let run = finished(args, &path, overrides)?;
        let curve = wall_bearing(&run.dir, wall, top)?;
        done.push((label, run, curve));
    }
    let depth = (DEPTH * 1e3).round() as u32;
    let _ = writeln!(
        md,
        "### The hybrid (Chen 2021 §6.3, Fig. 22–23)\n\n`{HYBRID}`: a continuum bed {top} m deep that turns discrete where \
         the shear-band oracle finds the bands (Alg. 1), the new grains cut from the same bed poured and trained (§4.1.1); \
         the plate is a segment wall (a rigid plate does not meet a hybrid band yet). The same scene as a DEM from the \
         packing (same DEM step and substeps) and as the continuum; the hybrid also untrained (`oracle.training = false`). \
         Last, the hybrid and the continuum with Chen's own continuum, the critical-state softening, fitted to the first \
         shear of a 9,600-grain simple-shear cell of the same grains (not to this test: `{}`). Force per metre (grains' and points'), the mean over ±0.5 mm of each depth below the bed's top.\n\n| depth [mm] | \
         {} |\n|---:|{}",
        CRITICAL_STATE.join(" "),
        done.iter().map(|(l, _, _)| format!("{l} [N/m]")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(done.len())
    );
    for mm in 1..=depth {
        let d = mm as f64 * 1e-3;
        let cells: Vec<String> = done
            .iter()
            .map(|(_, _, c)| format!("{:.1}", mean_over(c, d - 5e-4, d + 5e-4)))
            .collect();
        let _ = writeln!(md, "| {mm} | {} |", cells.join(" | "));
    }
    let (a, b) = (0.5 * DEPTH, DEPTH);
    let mean = |k: usize| mean_over(&done[k].2, a, b);
    let dem_wall = done[2].1.wall;
    let _ = writeln!(
        md,
        "\n| run | wall time | speed against the DEM | grains at the end | mean force {:.0}–{:.0} mm |\n|---|---:|---:|---:|---:|",
        1e3 * a,
        1e3 * b
    );
    for (k, (label, run, _)) in done.iter().enumerate() {
        let t = MetricsTable::read(&run.dir)?;
        let _ = writeln!(
            md,
            "| {label} | {:.1} s | {:.2}× | {:.0} | {:.1} N/m |",
            run.wall,
            dem_wall / run.wall,
            t.last("dem_items").unwrap_or(0.0),
            mean(k)
        );
    }
    let _ = writeln!(md);
    let mut chart = Chart {
        title: "Plate indentation: the hybrid against the DEM of the same bed and the continuum".into(),
        x_label: "depth [mm]".into(),
        y_label: "force [N/m]".into(),
        ..Chart::default()
    };
    for (label, _, c) in &done {
        chart.series.push(Series::new(
            label.to_string(),
            Kind::Line,
            c.iter().filter(|(d, _)| *d >= -GAP).map(|&(d, f)| (1e3 * d, f)).collect(),
        ));
    }
    part.chart(
        &args.out,
        "plate_force_hybrid",
        "The plate's force against its depth: the hybrid (trained and untrained), the DEM of the same bed, the continuum; the hybrid and the continuum with Chen's critical-state continuum",
        &chart,
    )?;
    part.check(
        "plate indentation: the hybrid's force within 30% of the DEM's on the same bed",
        "Chen 2021 Fig. 23: hybrid and DEM agree",
        format!(
            "mean over {:.0}–{:.0} mm: hybrid {:.1} N/m, DEM {:.1} N/m ({:+.1}%); untrained {:.1}, continuum {:.1}",
            1e3 * a,
            1e3 * b,
            mean(0),
            mean(2),
            100.0 * (mean(0) / mean(2) - 1.0),
            mean(1),
            mean(3)
        ),
        format!("within {:.0}%", 100.0 * TOLERANCE),
        (mean(0) / mean(2) - 1.0).abs() <= TOLERANCE,
    );
    // Chen's Fig. 23–24: the hybrid follows the DEM more closely than its continuum does.
    let off = |k: usize| mean(k) / mean(2) - 1.0;
    part.check(
        "plate indentation, Chen's continuum: the trained hybrid is closer to the DEM than the continuum alone",
        "Chen 2021 Fig. 23–24: the hybrid agrees with the DEM where the continuum does not",
        format!(
            "mean over {:.0}–{:.0} mm: hybrid {:.1} N/m ({:+.1}%), continuum {:.1} N/m ({:+.1}%), DEM {:.1}",
            1e3 * a,
            1e3 * b,
            mean(4),
            100.0 * off(4),
            mean(5),
            100.0 * off(5),
            mean(2)
        ),
        "the hybrid's error under the continuum's",
        off(4).abs() < off(5).abs(),
    );
    // Every epoch of the hybrid keeps the mass (the enrichment's rules, protocol §3.10).
    let t = MetricsTable::read(&done[0].1.dir)?;
    let (before, dem, mpm) = (t.column("oracle_mass")?, t.column("dem_mass")?, t.column("mpm_mass")?);
    let worst = (0..before.len())
        .filter(|&i| before[i] > 0.0)
        .map(|i| ((dem[i] + mpm[i]) / before[i] - 1.0).abs())
        .fold(0.0, f64::max);
    let enriched = t.last("dem_items").unwrap_or(0.0) > 0.0;
    part.check(
        "plate indentation: the hybrid enriches a band and every epoch keeps the mass",
        "Chen 2021 §4: grains replace the continuum in the band, the mass conserved",
        format!("grains at the end: {enriched}; the worst epoch's mass change {worst:.1e}"),
        "grains at the end, mass to 1e-9",
        enriched && worst < 1e-9,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    /// The shipped scenes are the ones the part reads (an edited plate or bed would make it
    /// measure depths from the wrong place).
    #[test]
    fn the_shipped_plate_scenes_are_what_the_part_reads() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        super::checked_scenes(&dir).unwrap();
        // And the check can refuse: another plate speed.
        let text = std::fs::read_to_string(dir.join(super::MPM)).unwrap();
        let tmp = std::env::temp_dir().join(format!("grains-plate-check-{}", std::process::id()));
        std::fs::create_dir_all(&tmp).unwrap();
        std::fs::write(
            tmp.join(super::MPM),
            text.replace("velocity = [0.0, -0.05]", "velocity = [0.0, -0.04]"),
        )
        .unwrap();
        std::fs::copy(dir.join(super::DEM), tmp.join(super::DEM)).unwrap();
        assert!(super::checked_scenes(&tmp).is_err());
        std::fs::remove_dir_all(&tmp).unwrap();
    }

    /// The mean over a depth window takes the samples inside it only.
    #[test]
    fn the_mean_force_takes_the_window_s_samples() {
        let curve = [(0.0, 100.0), (0.001, 1.0), (0.002, 3.0), (0.003, 100.0)];
        assert_eq!(super::mean_over(&curve, 0.0005, 0.0025), 2.0);
    }
}
