//! `grains validate --part shear`: shear bands (Chen 2021). The planar shear of §6.1 as a DEM
//! (the ground truth), as a continuum watched by the shear-band oracle (Alg. 1), and as the
//! hybrid: at the oracle's detection the band is enriched with grains of a prepared packing
//! (§4), trained through the continuum's history (§4.1.1, Fig. 13: its stress against the
//! DEM's) and coupled to the continuum (§5) to the end. The DEM planar shear of §6.1 (Table
//! 3: 6 × 12 cm, 7,640 grains of Table 1, periodic along the shear, the bottom fixed, the top
//! driven sideways under a constant normal stress), with the band measured by App. A's rule
//! ([`grains_oracle::band`]): its thickness against the paper's 22 D50, the stress against
//! strain (Fig. 10: softening as the band forms), and the incremental strain's profile across
//! the specimen; the same sample again with cohesive bonds (§6.1.1). A specimen many times as
//! tall as the hybrid, for its cost against the DEM's (§6.4, [`large`]).
//!
//! The grains are the column scenes' glass beads, which are Chen's Table 1 (k_n 1.77e6 N/m,
//! γ 7 N s/m, d 1 ± 0.08 mm, ρ 2530, μ 0.5). Chen's γ_n = 7 N s/m at e = 0.1 fixes its grain
//! mass at 2.0e-5 kg: its disks are 1 cm thick, so its 400 kPa is 4 kN/m over a unit-thick
//! disk of ours. The cell keeps App. F's k_n / (P d) with P = 4 kPa; at that pressure a
//! unit-thick grain is ten times slower to respond than Chen's, so the top moves at the
//! speed that gives the band (22 D50) Chen's quasi-static inertial number order, not at
//! its 2 cm/s (see [`BAND_INERTIAL`]). The packing is prepared as Chen's (Cundall 1989): consolidated with μ = 0.01,
//! then sheared with μ = 0.5. The cell is the one `grains calibrate --shear` uses
//! ([`crate::calibrate::shear::ShearCell`]): rough floor and plate rows of frozen grains, the
//! plate's servo holding σ_yy.

use super::args::ValidateArgs;
use crate::calibrate::shear::{SAMPLE, SERVO, ShearCell};
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use anyhow::Context;
use grains_dem::space::{D2, Space};
use grains_oracle::band;
use std::collections::HashMap;
use std::fmt::Write as _;

pub(super) mod biaxial;
mod continuum;
mod hybrid;
mod large;
mod membrane;
mod training;

/// The scene whose grains the planar shear uses (Chen's Table 1).
const SCENE: &str = "column_collapse_2d.toml";
/// Chen's Table 3: width and height in D50, grain count, and its 400 kPa over a 1-cm-thick
/// disk as a stress over a unit-thick one [Pa].
const WIDTH_D: f64 = 60.0;
const GRAINS: usize = 7640;
const PRESSURE: f64 = 4.0e3;
/// The band's inertial number the top's speed is set for, V = I √(P / ρ) / d × 22 D50: Chen's
/// 2 cm/s is I ≈ 7e-5 in its 22-D50 band; 5e-4 is still quasi-static (below 1e-3) and takes
/// 2.4 s of shear instead of 17 s at this pressure.
const BAND_INERTIAL: f64 = 5e-4;
/// The paper's band: 22 D50 for its DEM and its hybrid (Fig. 11), measured as the strain grows
/// from 37% to 57% (the top's travel over the specimen's width).
const PAPER_BAND: f64 = 22.0;
const WINDOW: (f64, f64) = (0.37, 0.57);
/// t_s within this many D50 of the paper's: App. A's rule reads a synthetic band 0.2–2 D50
/// thin (`grains_oracle::band`'s test), the packings differ, and the literature's bands span
/// 10–30 D50.
const BAND_TOLERANCE: f64 = 4.0;
/// The DEM planar shear's samples, and the thickness of the layers of grains glued to the
/// floor and to the plate [D50].
const GLUE_D: f64 = 3.0;

pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Shear bands (Chen 2021)\n\n");
    let dems = planar_shear(args, &mut part, &mut md)?;
    // The DEM's results stand if the continuum cannot run.
    if let Err(e) = continuum::continuum_planar_shear(args, &dems, &mut part, &mut md) {
        unfinished(&mut part, &mut md, "§6.1: planar shear, continuum", "planar shear (continuum)", &e);
    }
    part.md = md;
    Ok(part)
}

/// A section of the report that stopped with an error `e` (the results before it stand):
/// its heading `title` saying so, and a failed check that `what` ran to its end.
fn unfinished(part: &mut Part, md: &mut String, title: &str, what: &str, e: &anyhow::Error) {
    tracing::error!("validate: {what} failed: {e:#}");
    let _ = writeln!(md, "### {title}\n\nDid not finish: {e:#}\n");
    did_not_finish(part, what, e);
}

/// A run of a table that did not finish: its row (`row`, then the error and `columns` empty
/// cells) and a failed check that `what` ran to its end.
fn unfinished_row(part: &mut Part, md: &mut String, (row, columns): (&str, usize), what: &str, e: &anyhow::Error) {
    tracing::error!("validate: {what} failed: {e:#}");
    let _ = writeln!(md, "| {row} | did not finish: {e:#} |{}", " |".repeat(columns));
    did_not_finish(part, what, e);
}

/// The failed check of a run that stopped with `e`.
fn did_not_finish(part: &mut Part, what: &str, e: &anyhow::Error) {
    part.check(
        format!("{what} ran to its end"),
        "every run completes",
        format!("{e:#}"),
        "no error",
        false,
    );
}

/// What the DEM planar shear hands the continuum's: the specimen, its packing, the band.
#[derive(Clone)]
struct DemShear {
    /// The sample's seed.
    seed: u64,
    /// Period and height after consolidation [m], mean grain diameter [m].
    width: f64,
    height: f64,
    diameter: f64,
    /// Packing fraction of the consolidated sample (middle half).
    packing: f64,
    /// The top's speed [m/s].
    speed: f64,
    /// The slab profile's width at half its peak [D50], and App. A's t_s [D50].
    fwhm: f64,
    t_s: f64,
    /// The incremental strain profile (strain, height in D50).
    profile: Vec<(f64, f64)>,
    /// The consolidated sample before the shear, the DEM step [s], τ/σ_yy and the cell's
    /// stress [σxx, σyy, σxy] (compression positive) against strain.
    initial: grains_dem::DemState<D2>,
    dt: f64,
    curve: Vec<(f64, f64)>,
    stresses: Vec<(f64, [f64; 3])>,
    /// The band's centre [D50], the peak τ/σ_yy (strain, value), its mean over the window,
    /// and the run's wall time [s].
    centre: f64,
    peak: (f64, f64),
    residual: f64,
    wall: f64,
    /// The shear alone (after consolidation): its steps and wall time [s].
    shear_steps: usize,
    shear_wall: f64,
}

/// Sample grains' positions by id, x unwrapped against `reference` (the period is `width`).
fn positions(cell: &ShearCell, reference: Option<&HashMap<u64, [f64; 2]>>) -> HashMap<u64, [f64; 2]> {
    positions_of(&cell.state, cell.width, |id| id >= SAMPLE, reference)
}

/// The positions of the grains whose ids pass `take`, by id, x unwrapped against `reference`
/// (the period is `width`).
fn positions_of(
    state: &grains_dem::DemState<D2>,
    width: f64,
    take: impl Fn(u64) -> bool,
    reference: Option<&HashMap<u64, [f64; 2]>>,
) -> HashMap<u64, [f64; 2]> {
    let g = &state.grains;
    (0..g.len())
        .filter(|&i| take(g.id[i]))
        .map(|i| {
            let x = D2::to_array(g.x[i]);
            let mut p = [x[0], x[1]];
            if let Some(r) = reference.and_then(|r| r.get(&g.id[i])) {
                p[0] = r[0] + (p[0] - r[0] + 0.5 * width).rem_euclid(width) - 0.5 * width;
            }
            (g.id[i], p)
        })
        .collect()
}

/// Softening of a τ/σ_yy curve (strain, value): its peak (strain, value; running mean over 0.05
/// of strain) and its mean over the window.
fn softening(curve: &[(f64, f64)]) -> ((f64, f64), f64) {
    let per = curve.len().div_ceil(curve.last().map_or(1.0, |c| c.0 / 0.05) as usize).max(1);
    let smooth: Vec<(f64, f64)> = curve
        .chunks(per)
        .map(|c| {
            (
                c.iter().map(|p| p.0).sum::<f64>() / c.len() as f64,
                c.iter().map(|p| p.1).sum::<f64>() / c.len() as f64,
            )
        })
        .collect();
    let peak = smooth.iter().copied().fold((0.0, 0.0), |b, p| if p.1 > b.1 { p } else { b });
    let late: Vec<f64> = curve.iter().filter(|p| p.0 >= WINDOW.0).map(|p| p.1).collect();
    (peak, late.iter().sum::<f64>() / late.len().max(1) as f64)
}

/// A band in grains over the strain window, by App. A: thickness and centre [D50], the 98th
/// percentile of the best-fit strain, the grains' positions boxed into the period, the band,
/// and the incremental strain's slab profile with its half-peak width [D50].
struct Measured {
    t_s: f64,
    centre: f64,
    threshold: f64,
    x_box: Vec<[f64; 2]>,
    found: band::Band,
    profile: Vec<(f64, f64)>,
    fwhm: f64,
}

/// Cundall's best-fit strain (App. A) of the grains in both `from` (positions at a window's
/// start, by id) and `to` (at its end), over their neighbours within 1.5 diameters `d`: their
/// positions at the start and their strains, in order of id.
fn best_fit(from: &HashMap<u64, [f64; 2]>, to: &HashMap<u64, [f64; 2]>, d: f64) -> (Vec<u64>, Vec<[f64; 2]>, Vec<f64>) {
    let mut ids: Vec<u64> = from.keys().copied().filter(|id| to.contains_key(id)).collect();
    ids.sort_unstable();
    let x0: Vec<[f64; 2]> = ids.iter().map(|id| from[id]).collect();
    let x1: Vec<[f64; 2]> = ids.iter().map(|id| to[id]).collect();
    let strain = band::best_fit_strain(&x0, &x1, &band::neighbours(&x0, 1.5 * d));
    (ids, x0, strain)
}

/// App. A on the grains that are in both `from` (the window's start) and `to` (its end),
/// grains of diameter `d` in a cell `width` wide (periodic) and `height` high.
fn band_of(from: &HashMap<u64, [f64; 2]>, to: &HashMap<u64, [f64; 2]>, d: f64, width: f64, height: f64) -> anyhow::Result<Measured> {
    let (_, x0, strain) = best_fit(from, to, d);
    let threshold = band::percentile(&strain, 0.98);
    // Boxed where the grains are at the window's start, x in the period (a band along x).
    let x_box: Vec<[f64; 2]> = x0.iter().map(|p| [p[0].rem_euclid(width), p[1]]).collect();
    let found = band::measure(&x_box, &strain, threshold, d).context("no band: fewer than three grains above the 98th percentile")?;
    let centre = found.grains.iter().map(|&i| x0[i][1]).sum::<f64>() / found.grains.len() as f64 / d;
    // The incremental strain's profile, by height at the window's start.
    let profile = slab_profile(x0.iter().zip(&strain).map(|(p, &e)| (p[1], e)), height, d);
    let fwhm = half_peak_width(&profile, SLAB_D);
    Ok(Measured {
        t_s: found.thickness / d,
        centre,
        threshold,
        x_box,
        found,
        profile,
        fwhm,
    })
}

/// One DEM planar shear: everything the report and the continuum take from it.
struct DemRun {
    seed: u64,
    width: f64,
    height: f64,
    packing: f64,
    speed: f64,
    initial: grains_dem::DemState<D2>,
    dt: f64,
    curve: Vec<(f64, f64)>,
    stresses: Vec<(f64, [f64; 3])>,
    /// App. A's band: thickness [D50], the threshold, the grains' boxed positions, the band.
    t_s: f64,
    threshold: f64,
    x_box: Vec<[f64; 2]>,
    found: band::Band,
    centre: f64,
    profile: Vec<(f64, f64)>,
    fwhm: f64,
    /// Softening: the peak of τ/σ and its strain, the mean over the window.
    peak: (f64, f64),
    residual: f64,
    wall: f64,
    shear_steps: usize,
    shear_wall: f64,
}

/// The planar shear of seed `seed`: consolidated with μ = 0.01, glued boundaries, sheared
/// with the material's μ and, if `bond` > 0, Chen's cohesion (§2.1) e_n = e_t = `bond` [N/m]
/// from the shear's start (every contact of the consolidated sample bonds); its band by App. A
/// over the window.
fn dem_run(scene: &grains_protocol::scene::Scene, material: usize, seed: u64, bond: f64) -> anyhow::Result<DemRun> {
    let t0 = std::time::Instant::now();
    let dem = scene.materials[material].dem.as_ref().context("a DEM material")?;
    let (mu, d) = (dem.friction, 2.0 * dem.radius);
    // Columns of the cell's lattice for Chen's width.
    let cols = (WIDTH_D * d / ShearCell::spacing(dem)).round() as usize;
    let mut cell = ShearCell::new(scene, material, GRAINS, cols, PRESSURE, seed, 2)?;
    cell.state.params.materials[0].friction = 0.01;
    cell.consolidate().context("consolidating the planar shear at mu = 0.01")?;
    cell.state.params.materials[0].friction = mu;
    cell.glue(GLUE_D * d);
    for m in &mut cell.state.params.materials {
        (m.cohesion_normal, m.cohesion_tangential) = (bond, bond);
    }
    // The discrete version of the initial system, which kinematic training starts from.
    let initial = cell.state.clone();
    let packing = cell.packing();
    let height = cell.plate_y();
    let speed = cell.rate_of(BAND_INERTIAL) * PAPER_BAND * d;
    tracing::info!(
        "validate shear: seed {seed}: {GRAINS} grains, {:.1} x {:.1} D50, packing {packing:.3}, top at {:.2} mm/s",
        cell.width / d,
        height / d,
        1e3 * speed
    );
    // Shear: the top at `speed`, its height a servo on σ_yy; every SERVO steps the stress.
    let steps = (WINDOW.1 * cell.width / speed / cell.dt).ceil() as usize;
    let shear_start = std::time::Instant::now();
    let mut curve: Vec<(f64, f64)> = Vec::new();
    let mut stresses: Vec<(f64, [f64; 3])> = Vec::new();
    let mut reference = None;
    let mut s = [PRESSURE, PRESSURE, 0.0];
    let mut step = 0;
    while step < steps {
        if grains_service::signals::signalled() {
            anyhow::bail!("stopped by a signal");
        }
        let strain = speed * cell.dt * step as f64 / cell.width;
        if reference.is_none() && strain >= WINDOW.0 {
            reference = Some(positions(&cell, None));
        }
        cell.servo(s[1], speed, 0.0);
        s = cell.run(SERVO);
        if let Some(id) = grains_dem::pipeline::DemPipeline::first_non_finite(&cell.state) {
            anyhow::bail!("grain {id} is not finite: the planar shear blew up at strain {strain:.3}");
        }
        step += SERVO;
        let strain = speed * cell.dt * step as f64 / cell.width;
        curve.push((strain, s[2].abs() / s[1]));
        stresses.push((strain, s));
        if step % (50 * SERVO) == 0 {
            tracing::info!(
                "validate shear: seed {seed}: strain {strain:.3}, tau/sigma {:.3}",
                s[2].abs() / s[1]
            );
        }
    }
    let shear_wall = shear_start.elapsed().as_secs_f64();
    let from = reference.context("the shear reached the window's start")?;
    let to = positions(&cell, Some(&from));
    let Measured {
        t_s,
        centre,
        threshold,
        x_box,
        found,
        profile,
        fwhm,
    } = band_of(&from, &to, d, cell.width, height)?;

    let (peak, residual) = softening(&curve);

    Ok(DemRun {
        seed,
        width: cell.width,
        height,
        packing,
        speed,
        initial,
        dt: cell.dt,
        curve,
        stresses,
        t_s,
        threshold,
        x_box,
        found,
        centre,
        profile,
        fwhm,
        peak,
        residual,
        wall: t0.elapsed().as_secs_f64(),
        shear_steps: step,
        shear_wall,
    })
}

/// Chen 2021 §6.1 as a DEM, one run per seed of `--shear-seeds`: the band's thickness (their mean
/// against the paper's), direction and softening. Returns each seed's run: the first is the
/// one the continuum and the training take; the hybrid runs on every one.
fn planar_shear(args: &ValidateArgs, part: &mut Part, md: &mut String) -> anyhow::Result<Vec<DemShear>> {
    let path = args.scenes.join(SCENE);
    let scene = grains_protocol::scene::load(&path).with_context(|| format!("loading {}", path.display()))?;
    let material = scene.bodies[0].material;
    let dem = scene.materials[material].dem.as_ref().context("a DEM material")?;
    let (mu, d) = (dem.friction, 2.0 * dem.radius);
    // `--quick`: the first seed only, no cohesive run.
    let runs: Vec<DemRun> = args
        .shear_seeds()?
        .iter()
        .map(|&seed| dem_run(&scene, material, seed, 0.0))
        .collect::<anyhow::Result<_>>()?;
    let first = &runs[0];
    let _ = writeln!(
        md,
        "### §6.1: planar shear, DEM\n\nChen 2021 Table 3 in D50: {GRAINS} grains of `{SCENE}` (Chen's Table 1), \
         {:.1} D50 wide (periodic), {:.1} D50 high after consolidation at σ_yy = {:.0} Pa with μ = 0.01, then sheared with \
         μ = {mu}: the top row at {:.2} mm/s (I ≈ {BAND_INERTIAL:.0e} in a 22-D50 band), σ_yy held by its servo. The grains \
         within {GLUE_D} D50 of the floor row and of the plate row are glued to them: boundaries as rough as the packing \
         (with one row of grains for a wall the band formed along the floor in one of three runs, 2.6 D50 up, 6.0 D50 \
         thick). The strain is the top's travel over the width, as Chen's. Band (App. A): Cundall's best-fit strain of \
         each grain over its neighbours within 1.5 D50 from strain {} to {}, the grains above its 98th percentile, 2σ \
         outliers out, the minimum-area box. One run per seed (the samples differ in their lattice's jitter and radii).\n\n\
         | seed | packing (middle half) | t_s (App. A) | band centre | direction | slab profile at half peak | grains in the measure | peak τ/σ_yy (strain) | mean τ/σ_yy over the window | wall |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        first.width / d,
        first.height / d,
        PRESSURE,
        1e3 * first.speed,
        WINDOW.0,
        WINDOW.1,
    );
    for r in &runs {
        let _ = writeln!(
            md,
            "| {} | {:.3} | {:.1} D50 | {:.1} D50 | {:.1}° | {:.0} D50 | {} | {:.3} ({:.2}) | {:.3} | {:.0} s |",
            r.seed,
            r.packing,
            r.t_s,
            r.centre,
            r.found.angle.to_degrees(),
            r.fwhm,
            r.found.grains.len(),
            r.peak.1,
            r.peak.0,
            r.residual,
            r.wall
        );
    }
    let t_s = runs.iter().map(|r| r.t_s).sum::<f64>() / runs.len() as f64;
    let _ = writeln!(md, "\nPaper: t_s = {PAPER_BAND} D50 in the middle of the specimen (Fig. 11).\n");
    part.check(
        "planar shear (DEM): band thickness",
        format!("Chen 2021 Fig. 11: {PAPER_BAND} D50 (DEM and hybrid)"),
        format!(
            "{t_s:.1} D50, the mean of {} seeds ({})",
            runs.len(),
            runs.iter().map(|r| format!("{:.1}", r.t_s)).collect::<Vec<_>>().join(", ")
        ),
        format!("±{BAND_TOLERANCE} D50"),
        (t_s - PAPER_BAND).abs() <= BAND_TOLERANCE,
    );
    let angles: Vec<f64> = runs.iter().map(|r| r.found.angle.to_degrees()).collect();
    part.check(
        "planar shear (DEM): the band runs along the shear",
        "Chen 2021 Fig. 11: a horizontal band",
        angles.iter().map(|a| format!("{a:.1}°")).collect::<Vec<_>>().join(", "),
        "within 10° on every seed",
        angles.iter().all(|a| a.abs() <= 10.0),
    );
    part.check(
        "planar shear (DEM): softening",
        "Chen 2021 Fig. 10: the shear stress peaks, then softens as the band forms",
        runs.iter()
            .map(|r| format!("peak τ/σ {:.3} at strain {:.2}, window mean {:.3}", r.peak.1, r.peak.0, r.residual))
            .collect::<Vec<_>>()
            .join("; "),
        "peak above the window's mean on every seed",
        runs.iter().all(|r| r.peak.1 > r.residual),
    );
    let cohesive = if args.quick {
        None
    } else {
        Some(cohesion(&scene, material, &runs[0], part, md)?)
    };
    let mut curves: Vec<Series> = runs
        .iter()
        .map(|r| Series::new(format!("DEM, seed {}", r.seed), Kind::Line, r.curve.clone()))
        .collect();
    if let Some(cohesive) = &cohesive {
        curves.push(Series::new(
            format!("DEM, seed {}, cohesive", cohesive.seed),
            Kind::Line,
            cohesive.curve.clone(),
        ));
    }
    let stress = Chart {
        title: "Planar shear (DEM): shear over normal stress against strain".into(),
        x_label: "strain (top travel / width)".into(),
        y_label: "tau_xy / sigma_yy".into(),
        series: curves,
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_planar_stress",
        "Planar shear (DEM): τ/σ_yy against strain",
        &stress,
    )?;
    let mut series: Vec<Series> = runs
        .iter()
        .map(|r| Series::new(format!("DEM, seed {}", r.seed), Kind::LinePoints, r.profile.clone()))
        .collect();
    if let Some(cohesive) = &cohesive {
        series.push(Series::new(
            format!("DEM, seed {}, cohesive", cohesive.seed),
            Kind::LinePoints,
            cohesive.profile.clone(),
        ));
    }
    series.push(Series::new(
        format!("98th percentile, seed {}", first.seed),
        Kind::Dashed,
        vec![(first.threshold, 0.0), (first.threshold, first.height / d)],
    ));
    let profile_chart = Chart {
        title: format!(
            "Planar shear (DEM): incremental strain {}-{} across the specimen",
            WINDOW.0, WINDOW.1
        ),
        x_label: "mean deviatoric best-fit strain of a 2-D50 slab".into(),
        y_label: "height [D50]".into(),
        series,
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_planar_profile",
        "Planar shear (DEM): where the band is",
        &profile_chart,
    )?;
    let grains_chart = band_chart(
        format!("Planar shear (DEM, seed {}): the band's grains (App. A)", first.seed),
        &first.x_box,
        &first.found.grains,
        d,
        "grains",
    );
    part.chart(
        &args.out,
        "shear_planar_band",
        "Planar shear (DEM): the grains App. A counts in the band",
        &grains_chart,
    )?;
    Ok(runs
        .into_iter()
        .map(|r| DemShear {
            seed: r.seed,
            width: r.width,
            height: r.height,
            diameter: d,
            packing: r.packing,
            speed: r.speed,
            fwhm: r.fwhm,
            t_s: r.t_s,
            profile: r.profile,
            initial: r.initial,
            dt: r.dt,
            curve: r.curve,
            stresses: r.stresses,
            centre: r.centre,
            peak: r.peak,
            residual: r.residual,
            wall: r.wall,
            shear_steps: r.shear_steps,
            shear_wall: r.shear_wall,
        })
        .collect())
}

/// Chen's cohesive grains (§2.1, §6.1.1) as a Bond number: e_n = e_t = BOND P d, a bond holds
/// half the mean contact force at the confining pressure. The paper gives no values for e_n
/// and e_t; this is a choice, not a calibration.
const BOND: f64 = 0.5;

/// §6.1.1: the planar shear of `dry`'s sample again with cohesive bonds, against the dry run
/// (Fig. 12: the cohesive band is thinner, its yield stress higher, its softening stronger).
fn cohesion(
    scene: &grains_protocol::scene::Scene,
    material: usize,
    dry: &DemRun,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<DemRun> {
    let d = 2.0 * scene.materials[material].dem.as_ref().context("a DEM material")?.radius;
    let bond = BOND * PRESSURE * d;
    let r = dem_run(scene, material, dry.seed, bond)?;
    let _ = writeln!(
        md,
        "#### §6.1.1: cohesion\n\nThe same sample (seed {}) sheared with Chen's bonds (§2.1: a contact that has closed \
         holds tension up to e_n and adds e_t to its Coulomb cap) with e_n = e_t = {BOND} P d = {bond:.1} N/m. The paper \
         gives no values for them; a bond here holds half the mean contact force at the confining pressure. The continuum \
         and the hybrid are not run cohesive.\n\n\
         | grains | t_s (App. A) | band centre | slab profile at half peak | peak τ/σ_yy (strain) | mean τ/σ_yy over the window | peak − mean | wall |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|",
        dry.seed
    );
    for (name, x) in [("dry", dry), ("cohesive", &r)] {
        let _ = writeln!(
            md,
            "| {name} | {:.1} D50 | {:.1} D50 | {:.0} D50 | {:.3} ({:.2}) | {:.3} | {:.3} | {:.0} s |",
            x.t_s,
            x.centre,
            x.fwhm,
            x.peak.1,
            x.peak.0,
            x.residual,
            x.peak.1 - x.residual,
            x.wall
        );
    }
    let _ = writeln!(md);
    part.check(
        "planar shear (DEM): a cohesive band is thinner",
        "Chen 2021 §6.1.1, Fig. 12: the cohesive band is thinner than the dry one",
        format!("t_s {:.1} D50 cohesive, {:.1} D50 dry (seed {})", r.t_s, dry.t_s, dry.seed),
        "cohesive < dry",
        r.t_s < dry.t_s,
    );
    part.check(
        "planar shear (DEM): cohesion raises the yield stress and the softening",
        "Chen 2021 §6.1.1, Fig. 12: a higher yield stress and more intense softening",
        format!(
            "peak τ/σ {:.3} cohesive, {:.3} dry; peak − window mean {:.3} cohesive, {:.3} dry",
            r.peak.1,
            dry.peak.1,
            r.peak.1 - r.residual,
            dry.peak.1 - dry.residual
        ),
        "both larger with cohesion",
        r.peak.1 > dry.peak.1 && r.peak.1 - r.residual > dry.peak.1 - dry.residual,
    );
    Ok(r)
}

/// Slabs of the strain profiles [D50].
const SLAB_D: f64 = 2.0;

/// The mean of a value over horizontal slabs SLAB_D grains thick from the floor up to `height`
/// (and a little above, for dilation), from (height, value) samples: (mean, slab centre in
/// D50) for every slab holding a sample.
fn slab_profile(samples: impl Iterator<Item = (f64, f64)>, height: f64, d: f64) -> Vec<(f64, f64)> {
    let slab = SLAB_D * d;
    let mut bins: Vec<(f64, usize)> = vec![(0.0, 0); (height / slab).ceil() as usize + 4];
    for (y, v) in samples {
        let k = ((y / slab).floor().max(0.0) as usize).min(bins.len() - 1);
        bins[k].0 += v;
        bins[k].1 += 1;
    }
    bins.iter()
        .enumerate()
        .filter(|(_, b)| b.1 > 0)
        .map(|(k, b)| (b.0 / b.1 as f64, (k as f64 + 0.5) * SLAB_D))
        .collect()
}

/// A picture of a band by App. A: a quarter of the `what` (grains or points) at `x` [m], and
/// the band's (`band`, indices into `x`), in D50 of `d`.
fn band_chart(title: String, x: &[[f64; 2]], band: &[usize], d: f64, what: &str) -> Chart {
    let hot: Vec<(f64, f64)> = band.iter().map(|&i| (x[i][0] / d, x[i][1] / d)).collect();
    let all: Vec<(f64, f64)> = x.iter().step_by(4).map(|p| (p[0] / d, p[1] / d)).collect();
    Chart {
        title,
        x_label: "x [D50]".into(),
        y_label: "y [D50]".into(),
        series: vec![
            Series::new(format!("a quarter of the {what}"), Kind::Points, all),
            Series::new(format!("band {what}"), Kind::Points, hot),
        ],
        ..Chart::default()
    }
}

/// The width of a profile (value, height) at half its peak, in the profile's height unit: the
/// slabs (each `slab` thick) around the peak down to half of it.
fn half_peak_width(profile: &[(f64, f64)], slab: f64) -> f64 {
    if profile.is_empty() {
        return 0.0;
    }
    let top = (0..profile.len()).fold(0, |b, k| if profile[k].0 > profile[b].0 { k } else { b });
    let half = 0.5 * profile[top].0;
    let lo = (0..=top).rev().take_while(|&k| profile[k].0 >= half).last().unwrap_or(top);
    let hi = (top..profile.len()).take_while(|&k| profile[k].0 >= half).last().unwrap_or(top);
    profile[hi].1 - profile[lo].1 + slab
}
