//! The continuum planar shear (Chen 2021 §6.1, Fig. 11 right) watched by the shear-band oracle.

use super::hybrid::{Coupled, HYBRID_CELL_D, hybrid_report, transfer_named};
use super::training::{Training, enrich_and_train, training_report};
use super::*;

/// Continuum cells of the planar shear, in grain diameters: App. C's mesh dependence and
/// App. D's detection on a fine and a coarse grid.
const CELLS_D: [f64; 2] = [2.0, 4.0];
/// MPM steps between two looks of the oracle (about 7e-4 s on the 2-D50 cells): the recent
/// plastic strain is then over at least this many steps, where τ_l = c_l / γ̇_max is a step or
/// two at this shear rate.
pub(super) const ORACLE_EVERY: usize = 10;
/// Grains of the simple-shear cell the continuum is calibrated on (`grains calibrate --shear`'s
/// cell, a different sample and test from the planar shear).
pub(super) const CALIBRATION_GRAINS: usize = 2400;
/// The seed of the cell the continuum's elastic moduli are probed on (the calibration's is 1).
pub(super) const PROBE_SEED: u64 = 2;

/// One continuum planar shear: where its band is and when the oracle found it.
pub(super) struct ContinuumShear {
    pub(super) cell: f64,
    pub(super) points: usize,
    /// The incremental strain's slab profile (strain, height in D50) and its half-peak width.
    pub(super) profile: Vec<(f64, f64)>,
    pub(super) fwhm: f64,
    /// Strain when Alg. 1 first returned true, and the heights [D50] of the cells it flagged
    /// then (lowest, highest).
    pub(super) detected: Option<(f64, f64, f64)>,
    /// τ/σ_yy against strain.
    pub(super) curve: Vec<(f64, f64)>,
    pub(super) wall: f64,
    /// The wall time [s] from the start to the oracle's detection (before any enrichment).
    pub(super) detection_wall: Option<f64>,
    /// Up to the detection: the mean velocity [vx, vy] of the points in each cell-high slab
    /// (from y = 0) every ORACLE_EVERY steps, with the time since the shear began [s].
    pub(super) history: Vec<(f64, Vec<[f64; 2]>)>,
    /// The continuum as the oracle saw it at the detection, for the enrichment.
    pub(super) at_detection: Option<Detection>,
    /// A hybrid run's grains.
    pub(super) hybrid: Option<HybridShear>,
}

/// The hybrid's band in the grains (App. A), the grains measured and the strays, its DEM
/// substeps per step, the coupler's shared nodes summed over its steps and its largest
/// momentum error of a step, and the enrichment and training at the detection.
pub(super) struct HybridShear {
    pub(super) band: anyhow::Result<(Measured, usize, [usize; 2])>,
    pub(super) substeps: usize,
    pub(super) shared: u64,
    pub(super) steps: u64,
    pub(super) momentum_error: f64,
    pub(super) mass_change: f64,
    pub(super) training: Training,
}

/// The continuum at the oracle's detection: the strain, the mean σ_xy [Pa], its grid (nodes,
/// kernel) and cells, the cells flagged, and its points as the oracle sees them.
pub(super) struct Detection {
    pub(super) strain: f64,
    pub(super) shear_stress: f64,
    pub(super) nodes: grains_grid::Grid,
    pub(super) kernel: grains_grid::Kernel,
    pub(super) cells: grains_grid::Grid,
    pub(super) flagged: Vec<bool>,
    pub(super) points: Vec<grains_oracle::epoch::Point>,
}

/// Chen 2021 §6.1 as a continuum (its Fig. 11, right): the critical-state model calibrated on
/// a DEM simple shear of the same grains, the planar shear's specimen and loads, weak points
/// (at Φ_cs) in the middle rows to seed the band as Chen's, and the shear-band oracle (Alg. 1,
/// Table 4) watching every step. Its band against the DEM's, on two grids.
pub(super) fn continuum_planar_shear(args: &ValidateArgs, dems: &[DemShear], part: &mut Part, md: &mut String) -> anyhow::Result<()> {
    let dem = dems.first().context("no DEM planar shear")?;
    let path = args.scenes.join(SCENE);
    let scene = grains_protocol::scene::load(&path).with_context(|| format!("loading {}", path.display()))?;
    let material = scene.bodies[0].material;
    let (model, fit, calibration_wall) = calibrated(&scene, material, PRESSURE)?;
    let runs: Vec<ContinuumShear> = CELLS_D
        .iter()
        .map(|&c| continuum_run(dem, &model, scene.materials[material].density, c, None))
        .collect::<anyhow::Result<_>>()?;

    let d = dem.diameter;
    let _ = writeln!(
        md,
        "### §6.1: planar shear, continuum, and the shear-band oracle\n\nThe same specimen, loads and top speed as a \
         continuum (Chen's critical-state model, `model = \"critical_state\"`), calibrated on `grains calibrate --shear`'s \
         cell ({CALIBRATION_GRAINS} grains of the same material at the same pressure, I = 1e-3, strain 1; {calibration_wall:.0} s): \
         φ_cs = {:.2}°, Φ_cs = {:.4}, χ = {:.2}, ξ = {:.1} (peak sin φ {:.3} at Φ {:.4}); K = {:.3e} Pa, G = {:.3e} Pa from \
         small-strain probes (1e-4, simple shear and confined compression) of another {CALIBRATION_GRAINS}-grain cell \
         prepared as the planar shear's (seed {PROBE_SEED}). The points start at the DEM sample's packing ({:.3}); those \
         in the middle cell row at Φ_cs, Chen's weak elements that seed the band (the oracle is not told where they are). \
         Two points per cell and axis, APIC, the bottom rows of nodes fixed; the top a kinematic plate as the \
         DEM cell's: the nodes above the top row of points move sideways at the top's speed and vertically by a servo on \
         the mean σ_yy (a dead load on the top row's points would be a body force within that row, which leaves it at half \
         the pressure: the band formed there). The points start at the isotropic stress σ = p, as the consolidated DEM sample. The oracle (Alg. 1, Table 4: \
         c0 = 1e-6, c1 = 1e-4, c_l = 8e-4, c_g = 1.2e-3; γ̇_max the largest plastic strain rate of the points) on the MPM \
         cells every {ORACLE_EVERY} steps.\n\n| | cell | points | band: slab profile at half peak | oracle fires at strain | cells flagged then (height) | wall |\n\
         |---|---:|---:|---:|---:|---:|---:|\n| DEM | | {GRAINS} grains | {:.0} D50 (App. A: {:.1} D50) | | | |",
        fit.friction_angle,
        fit.packing_critical,
        fit.chi,
        fit.xi,
        fit.peak_sin,
        fit.peak_packing,
        model.bulk,
        model.shear,
        dem.packing,
        dem.fwhm,
        dem.t_s
    );
    for r in &runs {
        let (at, rows) = match r.detected {
            Some((e, lo, hi)) => (format!("{e:.3}"), format!("{lo:.0}–{hi:.0} D50")),
            None => ("never".into(), "–".into()),
        };
        let _ = writeln!(
            md,
            "| continuum | {:.0} D50 | {} | {:.0} D50 | {at} | {rows} | {:.0} s |",
            r.cell / d,
            r.points,
            r.fwhm,
            r.wall
        );
    }
    let _ = writeln!(md);
    training_report(dem, &runs, part, md);
    // A hybrid on each DEM sample: its band is compared with the DEM's on the same grains, and
    // one sample does not fix a hybrid's band to better than several D50 (docs/validation.md).
    let transfers = args
        .shear_transfers
        .iter()
        .map(|n| Ok((n.as_str(), transfer_named(n)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let hybrids = dems
        .iter()
        .flat_map(|dem| transfers.iter().map(move |&(name, t)| (name, t, dem)))
        .map(|(name, t, dem)| {
            let run = continuum_run(dem, &model, scene.materials[material].density, HYBRID_CELL_D, Some(t));
            (name, dem, run)
        })
        .collect();
    let hybrid_curves = hybrid_report(args, dems, hybrids, part, md)?;
    for r in &runs {
        let cells = r.cell / d;
        part.check(
            format!("planar shear (continuum, {cells:.0}-D50 cells): the oracle finds the band"),
            "Chen 2021 Alg. 1 and App. D: detected on a fine and a coarse grid",
            match r.detected {
                Some((e, lo, hi)) => format!("at strain {e:.3}, cells {lo:.0}–{hi:.0} D50 high"),
                None => "never".into(),
            },
            "fires before the strain window (0.37), on cells within 2 cells of the band's peak",
            r.detected.is_some_and(|(e, lo, hi)| {
                let peak = r.profile.iter().fold((0.0, 0.0), |b, p| if p.0 > b.0 { *p } else { b }).1;
                e < WINDOW.0 && lo >= peak - 2.0 * cells - 0.5 * cells && hi <= peak + 2.0 * cells + 0.5 * cells
            }),
        );
    }
    for r in &runs {
        let cells = r.cell / d;
        let peak = r.profile.iter().fold((0.0, 0.0), |b, p| if p.0 > b.0 { *p } else { b }).1;
        let middle = 0.5 * dem.height / d;
        part.check(
            format!("planar shear (continuum, {cells:.0}-D50 cells): the band forms at the weak points"),
            "Chen 2021 §6.1, Fig. 9 and 11: weak elements in the middle seed the continuum's band there",
            format!("peak of the incremental strain at {peak:.0} D50 (weak row at {middle:.0} D50)"),
            "within 2 cells",
            (peak - middle).abs() <= 2.0 * cells,
        );
    }
    let (fine, coarse) = (&runs[0], &runs[1]);
    part.check(
        "planar shear (continuum): the band follows the cell, not the grain",
        format!(
            "Chen 2021 App. C and Fig. 11: a local continuum's band is about one element; the DEM's {:.0} D50 (half-peak)",
            dem.fwhm
        ),
        format!(
            "{:.0} D50 on {:.0}-D50 cells, {:.0} D50 on {:.0}-D50 cells",
            fine.fwhm,
            fine.cell / d,
            coarse.fwhm,
            coarse.cell / d
        ),
        "thinner than the DEM's on both, thicker on the coarser grid",
        fine.fwhm < dem.fwhm && coarse.fwhm < dem.fwhm && coarse.fwhm > fine.fwhm,
    );
    let mut series = vec![Series::new("DEM", Kind::LinePoints, dem.profile.clone())];
    for r in &runs {
        series.push(Series::new(
            format!("continuum, {:.0}-D50 cells", r.cell / d),
            Kind::LinePoints,
            r.profile.clone(),
        ));
    }
    let profiles = Chart {
        title: format!("Planar shear: incremental strain {}-{} across the specimen", WINDOW.0, WINDOW.1),
        x_label: "mean deviatoric strain of a slab (grains: best fit; points: their own)".into(),
        y_label: "height [D50]".into(),
        series,
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_planar_profiles",
        "Planar shear: the DEM's band and the continuum's",
        &profiles,
    )?;
    let stress = Chart {
        title: "Planar shear: shear over normal stress against strain, DEM, continuum and hybrid".into(),
        x_label: "strain (top travel / width)".into(),
        y_label: "tau_xy / sigma_yy".into(),
        series: std::iter::once(Series::new("DEM", Kind::Line, dem.curve.clone()))
            .chain(
                runs.iter()
                    .map(|r| Series::new(format!("continuum, {:.0}-D50 cells", r.cell / d), Kind::Line, r.curve.clone())),
            )
            .chain(hybrid_curves.into_iter().map(|(name, c)| Series::new(name, Kind::Line, c)))
            .collect(),
        ..Chart::default()
    };
    part.chart(
        &args.out,
        "shear_planar_stress_continuum",
        "Planar shear: τ/σ_yy against strain, the DEM, the continuum and the hybrid overlaid",
        &stress,
    )?;
    if args.quick {
        return Ok(());
    }
    if let Err(e) = super::large::large_planar_shear(args, dem, &model, scene.materials[material].density, part, md) {
        unfinished(part, md, "§6.4: a large planar shear, cost", "large planar shear", &e);
    }
    Ok(())
}

/// The points as the enrichment takes them (a continuum's own: share 1).
pub(super) fn oracle_points(pts: &grains_mpm::points::Points<D2>) -> Vec<grains_oracle::epoch::Point> {
    (0..pts.len())
        .map(|k| grains_oracle::epoch::Point {
            id: pts.id[k],
            x: D2::to_array(pts.x[k]),
            mass: pts.mass[k],
            share: 1.0,
            v: D2::to_array(pts.v[k]),
        })
        .collect()
}

/// One continuum planar shear on cells of `cell_d` grain diameters; with `hybrid` (the
/// grains' transfer back), the hybrid's: at the detection the band is enriched and trained,
/// and the grains coupled from there on ([`Coupled`]).
pub(super) fn continuum_run(
    dem: &DemShear,
    model: &grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    grain_density: f64,
    cell_d: f64,
    hybrid: Option<grains_dem::coupled::GrainTransfer>,
) -> anyhow::Result<ContinuumShear> {
    use grains_grid::{D2, Grid};
    use grains_mpm::pipeline::{Model, MpmPipeline};
    use grains_mpm::points::Points;
    use grains_oracle::shear_band::{Coefficients, Persistence, RecentStrain};
    let t0 = std::time::Instant::now();
    let d = dem.diameter;
    let (w, height) = (dem.width, dem.height);
    let nx = (w / (cell_d * d)).round().max(4.0) as u64;
    let h = w / nx as f64;
    let per_axis = 2usize;
    let spacing = h / per_axis as f64;
    // Three wall layers under y = 0 (sticky: the fixed bottom), room above for dilation.
    let ny_above = ((height / h).ceil() as u64) + 8;
    let grid = Grid {
        origin: [0.0, -2.0 * h, 0.0],
        h,
        nodes: [nx + 1, ny_above + 3, 1],
        period: [nx, 0, 0],
    };
    let rho = grain_density * dem.packing;
    let shear_modulus = model.shear;
    let (params, dt) = mpm_params(grid, spacing, model, rho, (grains_mpm::pipeline::PointLoads::Weights, 0.0));
    let mut pts = Points::<D2>::default();
    let rows = (height / spacing).round() as usize;
    let cols = (w / spacing).round() as usize;
    let middle = 0.5 * height;
    for j in 0..rows {
        for i in 0..cols {
            let x = [(i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing];
            // Chen's weak elements: the cell row at mid-height at the critical packing.
            let weak = (x[1] - middle).abs() < 0.5 * h;
            let packing = if weak { model_packing_cs(&params.model) } else { dem.packing };
            pts.push(
                D2::from_array([x[0], x[1], 0.0]),
                rho * spacing * spacing,
                spacing * spacing,
                packing,
            );
        }
    }
    let n = pts.len();
    if let Model::CriticalState(m) = params.model {
        consolidated(&mut pts, m.bulk, PRESSURE);
    }
    let mut pipe = MpmPipeline::<D2>::new(2).map_err(|e| anyhow::anyhow!(e))?;
    let cells = Grid {
        origin: [0.0, -2.0 * h, 0.0],
        h,
        nodes: [nx, ny_above + 2, 1],
        period: [nx, 0, 0],
    };
    let coefficients = Coefficients::PLANAR_SHEAR;
    let mut recent = RecentStrain::default();
    let mut persistence = Persistence::default();
    let (mut detected, mut detection_wall) = (None, None);
    let (mut history, mut at_detection) = (Vec::new(), None);
    let (mut coupled, mut training): (Option<Coupled>, Option<Training>) = (None, None);
    // Settle under the load at rest, then shear.
    let settle = (0.05 / dt).ceil() as usize;
    // The top's speed ramps up over three shear-wave transits of the specimen: started at
    // full speed, the wave it sent down yielded the cells under the plate at the same time as
    // the weak row, and the oracle fired there on the 4-D50 grid (measured; docs/validation.md).
    let ramp = 3.0 * height / (shear_modulus / rho).sqrt();
    let mut reference: Option<HashMap<u64, ([f64; 2], f64)>> = None;
    let mut curve = Vec::new();
    // The top's travel over the width.
    let mut strain = 0.0;
    for step in 0.. {
        if grains_service::signals::signalled() {
            anyhow::bail!("stopped by a signal");
        }
        let shearing = step >= settle;
        if strain >= WINDOW.1 {
            break;
        }
        if shearing && strain >= WINDOW.0 {
            coupled.iter_mut().for_each(Coupled::open_window);
        }
        if shearing && reference.is_none() && strain >= WINDOW.0 {
            reference = Some(
                (0..pts.len())
                    .map(|k| {
                        let x = D2::to_array(pts.x[k]);
                        (pts.id[k], ([x[0], x[1]], pts.plastic_strain[k]))
                    })
                    .collect(),
            );
        }
        pipe.phase1(&pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("continuum planar shear: {e}"))?;
        // The top plate, as the DEM cell's: the nodes at and above the top row of points move
        // with it, sideways at the top's speed and up or down by the servo on the sample's mean
        // σ_yy. A kinematic plate and not a dead load on the top row: a load spread through
        // that row's weights is a body force within it, which leaves the row at about half
        // the pressure, and the band formed there (docs/validation.md).
        let (mut syy, mut vol, mut top) = (0.0, 0.0, f64::NEG_INFINITY);
        for k in 0..pts.len() {
            syy += pts.tau[k].y_axis.y * pts.volume[k];
            vol += pts.jacobian[k] * pts.volume[k];
            top = top.max(D2::to_array(pts.x[k])[1]);
        }
        let error = (1.0 + syy / vol / PRESSURE).clamp(-1.0, 1.0);
        let vx = if shearing {
            dem.speed * ((step + 1 - settle) as f64 * dt / ramp).min(1.0)
        } else {
            0.0
        };
        strain += vx * dt / w;
        let plate = [vx, -error * dem.speed];
        pipe.for_each_node_mut(|ijk, _, v| {
            if params.grid.origin[1] + ijk[1] as f64 * h >= top {
                *v = D2::from_array([plate[0], plate[1], 0.0]);
            }
        });
        let constrained = coupled.as_mut().map(|c| c.couple(&mut pipe, &params, dt)).transpose()?;
        pipe.phase2(&mut pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("continuum planar shear: {e}"))?;
        if let (Some(c), Some(v)) = (coupled.as_mut(), constrained) {
            c.finish(&v, dt)?;
            c.track_mass(&pts);
        }
        if !shearing || !(step - settle).is_multiple_of(ORACLE_EVERY) {
            continue;
        }
        if (step - settle).is_multiple_of(200 * ORACLE_EVERY) {
            tracing::info!("validate shear: continuum on {cell_d}-D50 cells: strain {strain:.3}");
        }
        if detected.is_none() {
            let mut slabs = vec![([0.0; 2], 0.0); (height / h).ceil() as usize + 8];
            for k in 0..pts.len() {
                let (x, v) = (D2::to_array(pts.x[k]), D2::to_array(pts.v[k]));
                let last = slabs.len() - 1;
                let slab = &mut slabs[((x[1] / h).max(0.0) as usize).min(last)];
                slab.0[0] += pts.mass[k] * v[0];
                slab.0[1] += pts.mass[k] * v[1];
                slab.1 += pts.mass[k];
            }
            let mean = slabs
                .iter()
                .map(|(p, m)| if *m > 0.0 { [p[0] / m, p[1] / m] } else { [f64::NAN; 2] })
                .collect();
            history.push(((step + 1 - settle) as f64 * dt, mean));
        }
        // The oracle (Alg. 1) on the cells.
        let t = step as f64 * dt;
        if oracle_fires(&cells, &pts, d, &coefficients, (&mut recent, &mut persistence), t) && detected.is_none() {
            let ys: Vec<f64> = persistence
                .flagged()
                .iter()
                .enumerate()
                .filter(|(_, f)| **f)
                .map(|(i, _)| (cells.origin[1] + ((i / nx as usize) as f64 + 0.5) * h) / d)
                .collect();
            let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            detected = Some((strain, lo, hi));
            detection_wall = Some(t0.elapsed().as_secs_f64());
            let (mut sxy, mut vol) = (0.0, 0.0);
            for k in 0..pts.len() {
                sxy += pts.tau[k].x_axis.y * pts.volume[k];
                vol += pts.jacobian[k] * pts.volume[k];
            }
            let detection = Detection {
                strain,
                shear_stress: sxy / vol,
                nodes: params.grid,
                kernel: params.kernel,
                cells,
                flagged: persistence.flagged().to_vec(),
                points: oracle_points(&pts),
            };
            if let Some(transfer) = hybrid {
                let enriched = enrich_and_train(dem, &detection, &history, h)?;
                training = Some(enriched.training.clone());
                coupled = Some(Coupled::new(
                    (enriched.plan, enriched.state, enriched.pipe),
                    &mut pts,
                    &params,
                    (cells, transfer, None),
                    dt,
                    dem.dt,
                    Some(w),
                ));
            }
            at_detection = Some(detection);
            tracing::info!(
                "validate shear: continuum on {cell_d}-D50 cells: the oracle fires at strain {strain:.3}, cells {lo:.0}-{hi:.0} D50 high"
            );
        }
        if (step - settle).is_multiple_of(5 * ORACLE_EVERY) {
            let (mut sxy, mut syy, mut vol) = (0.0, 0.0, 0.0);
            for k in 0..pts.len() {
                sxy += pts.tau[k].x_axis.y * pts.volume[k];
                syy += pts.tau[k].y_axis.y * pts.volume[k];
                vol += pts.jacobian[k] * pts.volume[k];
            }
            let (sxy, syy) = (sxy / vol, syy / vol);
            curve.push((strain, if syy != 0.0 { (sxy / syy).abs() } else { 0.0 }));
        }
    }
    // The incremental strain of each point over the window: its plastic strain grown (the
    // points' own measure, as Chen colours its MPM points), by slabs 2 D50 thick.
    let from = reference.context("the continuum's shear reached the window's start")?;
    let grown = (0..pts.len()).filter_map(|k| from.get(&pts.id[k]).map(|(x0, e0)| (x0[1], pts.plastic_strain[k] - e0)));
    let profile = slab_profile(grown, height, d);
    let fwhm = half_peak_width(&profile, SLAB_D);
    Ok(ContinuumShear {
        cell: h,
        points: n,
        profile,
        fwhm,
        detected,
        curve,
        wall: t0.elapsed().as_secs_f64(),
        detection_wall,
        history,
        at_detection,
        hybrid: match coupled {
            Some(c) => Some(HybridShear {
                band: c.band(d, height),
                substeps: c.substeps,
                shared: c.shared,
                steps: c.steps,
                momentum_error: c.momentum_error,
                mass_change: c.mass_change,
                training: training.context("a hybrid run trains its band")?,
            }),
            None => None,
        },
    })
}

/// Sets the points' state to the DEM sample's, consolidated at `pressure` [Pa] (isotropic: its
/// normal stresses are close to equal, where an elastic continuum loaded from stress-free
/// would hold the K0 state σ_xx = ν/(1−ν) σ_yy, already near yield). Hencky with bulk modulus
/// `bulk`: p = K tr ε, so ε = −p/(2K) I and b^e = e^(2ε) = e^(−p/K) I; τ = −p I (tension
/// positive, J = 1).
pub(super) fn consolidated(pts: &mut grains_mpm::points::Points<grains_grid::D2>, bulk: f64, pressure: f64) {
    use grains_mpm::matrix::Matrix;
    let identity = <<grains_grid::D2 as grains_mpm::matrix::MpmSpace>::M as Matrix>::identity();
    for k in 0..pts.len() {
        pts.b_e[k] = identity * (-pressure / bulk).exp();
        pts.tau[k] = identity * -pressure;
    }
}

/// One look of the shear-band oracle (Chen 2021 Alg. 1) at the points `pts` at time `t`: the
/// windows τ_l and τ_g from the fastest plastic rate, the plastic strain grown over τ_l
/// (`recent` keeps the record), both averaged on the `cells`, the cells flagged for grains of
/// diameter `d`; true once the flagged set has held for τ_g (`persistence` then holds it).
pub(super) fn oracle_fires(
    cells: &grains_grid::Grid,
    pts: &grains_mpm::points::Points<D2>,
    d: f64,
    coefficients: &grains_oracle::shear_band::Coefficients,
    (recent, persistence): (
        &mut grains_oracle::shear_band::RecentStrain,
        &mut grains_oracle::shear_band::Persistence,
    ),
    t: f64,
) -> bool {
    use grains_oracle::shear_band as oracle;
    let max_rate = pts.plastic_rate.iter().copied().fold(0.0, f64::max);
    let (tau_l, tau_g) = (oracle::window(coefficients.cl, max_rate), oracle::window(coefficients.cg, max_rate));
    let recent_strain = recent.recent(t, tau_l, &pts.id, &pts.plastic_strain);
    recent.record(t, &pts.id, &pts.plastic_strain);
    let at = |k: usize| D2::to_array(pts.x[k]);
    let rate = oracle::cell_average(cells, 2, (0..pts.len()).map(|k| (at(k), pts.mass[k], pts.plastic_rate[k])));
    let recent_cells = oracle::cell_average(cells, 2, (0..pts.len()).map(|k| (at(k), pts.mass[k], recent_strain[k])));
    let flagged = oracle::flag(cells, 2, &rate, &recent_cells, d, coefficients);
    persistence.update(t, flagged, tau_g)
}

/// The shears' continuum on `grid`: Chen's critical-state `model`, two points per cell and
/// axis (`spacing`), GIMP, APIC, no gravity, the domain's faces sticky, no walls; point
/// loads and the ambient (confining) pressure as given. With its step: half the largest CFL
/// number for material of density `rho`.
pub(super) fn mpm_params(
    grid: grains_grid::Grid,
    spacing: f64,
    model: &grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    rho: f64,
    (point_loads, ambient_pressure): (grains_mpm::pipeline::PointLoads, f64),
) -> (grains_mpm::pipeline::MpmParams<D2>, f64) {
    use grains_mpm::pipeline::{MAX_CFL, Model, MpmParams, Transfer, cfl_time_step};
    let model = Model::CriticalState(*model);
    let dt = 0.5 * MAX_CFL * cfl_time_step(&model, rho, grid.h, 2);
    let params = MpmParams::<D2> {
        grid,
        kernel: grains_grid::Kernel::Gimp { half_width: 0.5 * spacing },
        model,
        gravity: D2::from_array([0.0; 3]),
        transfer: Transfer::Apic,
        domain_walls: Some(grains_mpm::boundary::Contact::Sticky),
        walls: Vec::new(),
        point_loads,
        ambient_pressure,
    };
    (params, dt)
}

/// Chen's critical-state continuum of `material` at `pressure` [Pa] (§2.2: from DEM element
/// tests of the same grains, not from the case it is compared with): φ_cs, Φ_cs, χ and ξ
/// fitted to `grains calibrate --shear`'s cell ([`CALIBRATION_GRAINS`], I = 1e-3, strain 1),
/// K and G from small-strain probes of another cell prepared as the planar shear's
/// ([`PROBE_SEED`]). Returns the model, the fit and the wall time [s].
pub(super) fn calibrated(
    scene: &grains_protocol::scene::Scene,
    material: usize,
    pressure: f64,
) -> anyhow::Result<(
    grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    crate::calibrate::shear::CriticalStateFit,
    f64,
)> {
    let t0 = std::time::Instant::now();
    let cal = crate::calibrate::shear::simple_shear(scene, material, CALIBRATION_GRAINS, pressure, &[1e-3], 1.0, 1)?;
    let fit = crate::calibrate::shear::critical_state(&cal.transient)
        .context("the calibration's simple shear has no peak above its critical state")?;
    let (bulk, shear) = probed_moduli(scene, material, CALIBRATION_GRAINS, 40.0, pressure, PROBE_SEED)?;
    let model = grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState {
        bulk,
        shear,
        tan_friction_cs: fit.friction_angle.to_radians().tan(),
        packing_cs: fit.packing_critical,
        chi: fit.chi,
        xi: fit.xi,
        cohesion: 0.0,
    };
    Ok((model, fit, t0.elapsed().as_secs_f64()))
}

/// The small-strain moduli (K, G) of a cell of `grains` grains `width_d` D50 wide, prepared as
/// the planar shear's (consolidated at `pressure` [Pa] with μ = 0.01, then μ restored).
pub(super) fn probed_moduli(
    scene: &grains_protocol::scene::Scene,
    material: usize,
    grains: usize,
    width_d: f64,
    pressure: f64,
    seed: u64,
) -> anyhow::Result<(f64, f64)> {
    let dem = scene.materials[material].dem.as_ref().context("a DEM material")?;
    let cols = (width_d * 2.0 * dem.radius / ShearCell::spacing(dem)).round() as usize;
    let mut cell = ShearCell::new(scene, material, grains, cols, pressure, seed, 2)?;
    cell.state.params.materials[0].friction = 0.01;
    cell.consolidate().context("consolidating the moduli's probe cell")?;
    cell.state.params.materials[0].friction = dem.friction;
    Ok(cell.moduli(1e-4))
}

fn model_packing_cs(model: &grains_mpm::pipeline::Model) -> f64 {
    match model {
        grains_mpm::pipeline::Model::CriticalState(m) => m.packing_cs,
        _ => 1.0,
    }
}
