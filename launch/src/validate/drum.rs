//! `grains validate`, drum part: `scenes/drum_hybrid_2d.toml` run as DEM and as hybrid
//! (adaptive zones) from one poured packing (Yue 2018 §5, issue 6). The measure is the
//! dynamic angle of repose: in every frame after [`STEADY`], the top of the material (grains:
//! centre + radius; points: centre + half their spacing) in 2-mm columns across the middle
//! half of the drum's width, a least-squares line through the tops, its angle to the
//! horizontal; averaged over the frames. Check: the hybrid's within 3° of the DEM's.

use super::args::ValidateArgs;
use super::deposit::frames_of;
use super::packings;
use super::runs::{SCENE_USE_HEADER, load_with, run_scene, scene_use};
use super::scenes::drum::{CENTRE, RADIUS, SCENE};
use super::stats::slope;
use crate::metrics::MetricsTable;
use crate::run::Status;
use anyhow::bail;
use grains_service::vtu::Frame;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const COLUMN: f64 = 0.002;
/// Frames from this time on are in the steady rolling regime [s].
const STEADY: f64 = 1.0;
const ANGLE_TOLERANCE: f64 = 3.0;

/// Angle [degrees] of the line through the tops of `material` (x, top) in columns of
/// [`COLUMN`] over |x − centre| < R/2.
pub fn surface_angle(material: &[(f64, f64)]) -> f64 {
    let n = (RADIUS / COLUMN).round() as usize;
    let x0 = CENTRE[0] - 0.5 * RADIUS;
    let mut top = vec![f64::NEG_INFINITY; n];
    for &(x, y) in material {
        let k = ((x - x0) / COLUMN).floor();
        if k >= 0.0 && (k as usize) < n {
            top[k as usize] = top[k as usize].max(y);
        }
    }
    let line: Vec<(f64, f64)> = top
        .iter()
        .enumerate()
        .filter(|(_, t)| t.is_finite())
        .map(|(k, &t)| (x0 + (k as f64 + 0.5) * COLUMN, t))
        .collect();
    slope(&line).atan().to_degrees()
}

struct DrumRun {
    angle: f64,
    frames: usize,
    grains: f64,
    wall: f64,
    dir: PathBuf,
}

fn run_drum(args: &ValidateArgs, packing: &Path, dem: bool, point_half: f64) -> anyhow::Result<DrumRun> {
    let path = args.scenes.join(SCENE);
    let mut overrides = vec![format!("body.0.packing={:?}", packing.display().to_string())];
    if dem {
        overrides.push("body.0.model=\"dem\"".into());
    } else {
        overrides.extend(args.hybrid_overrides.iter().cloned());
    }
    let outcome = run_scene(args, &path, overrides)?;
    if outcome.status != Status::Completed {
        bail!("{SCENE}: the run did not complete: {}", outcome.message);
    }
    let table = MetricsTable::read(&outcome.dir)?;
    let grains = table.mean("dem_items")?;
    let grain_frames = frames_of(&outcome.dir, "grains")?;
    let point_frames = frames_of(&outcome.dir, "points")?;
    let mut angles = Vec::new();
    for (k, (t, file)) in grain_frames.iter().enumerate() {
        if *t < STEADY {
            continue;
        }
        let grains = super::deposit::grains_of(&Frame::read(file)?, file)?;
        let mut tops: Vec<(f64, f64)> = grains.iter().map(|(x, r)| (x[0], x[1] + r)).collect();
        if let Some((_, pf)) = point_frames.get(k) {
            tops.extend(Frame::read(pf)?.points.iter().map(|x| (x[0], x[1] + point_half)));
        }
        angles.push(surface_angle(&tops));
    }
    if angles.is_empty() {
        bail!("{SCENE}: no frame after {STEADY} s");
    }
    Ok(DrumRun {
        angle: angles.iter().sum::<f64>() / angles.len() as f64,
        frames: angles.len(),
        grains,
        wall: table.last("wall_s")?,
        dir: outcome.dir,
    })
}

/// Runs the drum part and writes `drum.md` in `--out`; whether the check passed.
pub fn validate(args: &ValidateArgs) -> anyhow::Result<crate::report::Part> {
    let mut part = crate::report::Part::default();
    let packing = packings::drum(args)?;
    let scene = load_with(&args.scenes.join(SCENE), &[])?;
    let point_half = 0.5 * scene.domain.cell_size / scene.mpm.points_per_axis as f64;
    tracing::info!("validate: drum: DEM");
    let dem = run_drum(args, &packing, true, point_half)?;
    tracing::info!("validate: drum: hybrid");
    let hybrid = run_drum(args, &packing, false, point_half)?;
    let diff = hybrid.angle - dem.angle;
    let pass = diff.abs() <= ANGLE_TOLERANCE;
    let mut md = String::new();
    writeln!(md, "## Rotating drum: DEM and hybrid (adaptive zones)\n")?;
    writeln!(
        md,
        "Scene `{SCENE}` from one poured packing, {} s at 2 rad/s; the free surface's angle (line through the \
         tops of the material in 2-mm columns over the middle half of the drum) averaged over the frames after {STEADY} s. \
         Reference: the pure DEM run (issue 6: hybrid within {ANGLE_TOLERANCE}°).{}\n",
        scene.steps as f64 * scene.dt,
        if args.hybrid_overrides.is_empty() {
            String::new()
        } else {
            format!(" The hybrid run with overrides `{}`.", args.hybrid_overrides.join(" "))
        }
    )?;
    writeln!(md, "| model | angle [°] | frames | mean DEM grains | wall [s] | speedup vs DEM |")?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    for (name, r) in [("DEM", &dem), ("hybrid", &hybrid)] {
        writeln!(
            md,
            "| {name} | {:.1} | {} | {:.0} | {:.1} | {:.2}x |",
            r.angle,
            r.frames,
            r.grains,
            r.wall,
            dem.wall / r.wall
        )?;
    }
    writeln!(
        md,
        "\nCheck: |hybrid − DEM| = {:.1}° (limit {ANGLE_TOLERANCE}°): {}",
        diff.abs(),
        if pass { "pass" } else { "**FAIL**" }
    )?;
    part.check(
        "drum: hybrid angle of repose",
        format!("pure DEM drum, same packing ({:.1}°; issue 6)", dem.angle),
        format!("{:.1}° ({:+.1}°)", hybrid.angle, diff),
        format!("±{ANGLE_TOLERANCE}°"),
        pass,
    );
    let row = scene_use(args, &mut part, "drum_use", SCENE, &hybrid.dir, &dem.dir)?;
    writeln!(md, "\n### What each run simulates\n\n{}\n{row}", SCENE_USE_HEADER)?;
    tracing::info!("validate: drum: DEM {:.1}°, hybrid {:.1}°", dem.angle, hybrid.angle);
    let end = scene.steps as f64 * scene.dt;
    super::pictures::side_by_side(
        &mut part,
        &args.out,
        "drum_pictures",
        "Drum: DEM and hybrid at the same moments",
        &[("DEM", dem.dir.as_path()), ("hybrid", hybrid.dir.as_path())],
        &[0.0, 0.5 * end, end],
        None,
    )?;
    part.md = md;
    Ok(part)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_angle_of_a_tilted_surface_is_found() {
        // Material under a 30° line through the centre, plus grains far outside the window.
        let tan = 30f64.to_radians().tan();
        let mut m = Vec::new();
        for i in 0..200 {
            let x = 0.005 + i as f64 * 0.00045;
            let top = CENTRE[1] + (x - CENTRE[0]) * tan;
            m.push((x, top));
            m.push((x, top - 0.003));
        }
        m.push((0.006, 0.2));
        assert!((surface_angle(&m) - 30.0).abs() < 0.5, "{}", surface_angle(&m));
    }
}
