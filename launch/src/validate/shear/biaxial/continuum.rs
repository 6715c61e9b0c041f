//! The biaxial compression as Chen's critical-state continuum on two grids (Fig. 18 right,
//! App. C) and as the hybrid that starts from it (Fig. 16–21, [`super::hybrid`]).

use super::*;

/// The continuum biaxial on two grids (Chen Fig. 18, right, and App. C): the critical-state
/// model calibrated as the planar shear's, at this test's pressure; its band against the
/// DEM's and the cell, and the oracle's detection.
pub(super) fn continuum(
    scene: &grains_protocol::scene::Scene,
    material: usize,
    dems: &[BiaxialRun],
    args: &super::super::ValidateArgs,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<()> {
    use super::super::continuum::CALIBRATION_GRAINS;
    let dem = &dems[0];
    let d = 2.0 * scene.materials[material].dem.as_ref().context("a DEM material")?.radius;
    let (model, fit, calibration_wall) = super::super::continuum::calibrated(scene, material, PRESSURE)?;
    let (bulk, shear) = (model.bulk, model.shear);
    let runs: Vec<ContinuumBiaxial> = CELLS_D
        .iter()
        .map(|&c| continuum_run(dem, &model, scene.materials[material].density, d, c, None))
        .collect::<anyhow::Result<_>>()?;
    let _ = writeln!(
        md,
        "### Continuum\n\nSeed {}'s specimen as Chen's critical-state continuum, calibrated as the planar shear's at this \
         test's {PRESSURE:.0} Pa ({CALIBRATION_GRAINS}-grain simple shear to strain 1 at I = 1e-3, small-strain probes of \
         another cell; {calibration_wall:.0} s): φ_cs = {:.2}°, Φ_cs = {:.4}, χ = {:.2}, ξ = {:.1}, K = {:.3e} Pa, G = {:.3e} \
         Pa; the points at the DEM sample's packing {:.3}, a square of {WEAK_D} D50 at the right face a quarter of the way up at \
         Φ_cs (Chen's weak elements); σ3 as a confining fluid's pressure on the free faces (the MPM's ambient pressure, `MpmParams::ambient_pressure`); the bottom nodes fixed, the top a \
         frictionless rigid plane moving down at the DEM's speed, in contact with the points (its force on their faces); the oracle with Table 6's coefficients. The band as the DEM's, on the points' \
         plastic strain grown over the window, counting the points that started {EDGE_CELLS} cells or more inside the box \
         their centres spanned (nearer, the strain is the free faces' and the platens').\n\n\
         | cell | points | t_s (App. A) | profile across the band at half peak | inclination | oracle fires at axial strain (cells flagged, their mean x, y) | peak φ (axial strain), ψ after it | φ, ψ over the window | wall |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        dem.seed, fit.friction_angle, fit.packing_critical, fit.chi, fit.xi, bulk, shear, dem.packing,
    );
    for r in &runs {
        let (peak, psi_peak) = peak_angles(&r.records);
        let (phi, psi) = window_angles(&r.records);
        let _ = writeln!(
            md,
            "| {:.0} D50 | {} | {:.1} D50 | {:.0} D50 | {:.1}° | {} | {:.2}° ({:.2}%), {:.2}° | {:.2}°, {:.2}° | {:.0} s |",
            r.cell / d,
            r.points,
            r.t_s,
            r.fwhm,
            r.angle,
            r.detected.map_or("never".into(), |(e, c, at)| format!(
                "{:.2}% ({c}, mean at {:.0}, {:.0} D50)",
                100.0 * e,
                at[0],
                at[1]
            )),
            peak.1,
            100.0 * peak.0,
            psi_peak,
            phi,
            psi,
            r.wall
        );
    }
    let _ = writeln!(md);
    let dem_fwhm = dem.fwhm;
    let (fine, coarse) = (&runs[0], &runs[1]);
    // A band through the specimen, not along the platen or the floor, and a band, not a blob:
    // App. A's box (along the band) at least half the specimen's width long. (Its top 2% may
    // cover part of the band only: on 2-D50 cells its upper half, 35 D50.)
    let through = |r: &ContinuumBiaxial| (30.0..=70.0).contains(&r.angle) && r.length >= 0.5 * dem.width / d;
    part.check(
        "biaxial (continuum): the band crosses the specimen",
        "Chen 2021 Fig. 18: an inclined band from the weak elements",
        runs.iter()
            .map(|r| format!("{:.1}°, {:.0} D50 long on {:.0}-D50 cells", r.angle, r.length, r.cell / d))
            .collect::<Vec<_>>()
            .join("; "),
        format!(
            "its line 30–70° from the horizontal and App. A's box at least half the specimen's width ({:.0} D50) long, on both grids",
            0.5 * dem.width / d
        ),
        runs.iter().all(through),
    );
    part.check(
        "biaxial (continuum): the band follows the cell, not the grain",
        format!(
            "Chen 2021 Fig. 18 and App. C: the continuum's band 7 D50, thinner than the DEM's; seed {}'s DEM {dem_fwhm:.0} D50 (half peak)",
            dem.seed
        ),
        format!(
            "{:.0} D50 on {:.0}-D50 cells, {:.0} D50 on {:.0}-D50 cells (half peak)",
            fine.fwhm,
            fine.cell / d,
            coarse.fwhm,
            coarse.cell / d
        ),
        "thinner than the DEM's on both, thicker on the coarser grid, both bands crossing the specimen",
        runs.iter().all(through) && fine.fwhm < dem_fwhm && coarse.fwhm < dem_fwhm && coarse.fwhm > fine.fwhm,
    );
    for r in &runs {
        let cells = r.cell / d;
        let inside = |y: f64| y > 2.0 * cells && y < dem.height / d - 2.0 * cells;
        part.check(
            format!("biaxial (continuum, {cells:.0}-D50 cells): the oracle finds the band"),
            "Chen 2021 Alg. 1, Table 6: detected in the specimen before the band is measured",
            r.detected.map_or("never".into(), |(e, c, at)| {
                format!(
                    "at axial strain {:.2}%, {c} cells, their mean at ({:.0}, {:.0}) D50",
                    100.0 * e,
                    at[0],
                    at[1]
                )
            }),
            format!(
                "fires before {:.1}% of axial strain, the cells' mean more than two cells from the platens",
                100.0 * WINDOW.0
            ),
            r.detected.is_some_and(|(e, _, at)| e < WINDOW.0 && inside(at[1])),
        );
    }
    for r in &runs {
        let cells = r.cell / d;
        let chart = super::super::band_chart(
            format!("Biaxial compression (continuum, {cells:.0}-D50 cells): the band's points (App. A)"),
            &r.x0,
            &r.band,
            d,
            "points",
        );
        part.chart(
            &args.out,
            &format!("shear_biaxial_band_continuum_{cells:.0}d"),
            format!("Biaxial compression (continuum, {cells:.0}-D50 cells): the points App. A counts in the band"),
            &chart,
        )?;
    }
    let hybrids = hybrid_report(dems, &model, scene.materials[material].density, d, args, part, md)?;
    for (stem, caption, y_label, f) in [
        (
            "shear_biaxial_friction_continuum",
            "Biaxial compression: the mobilised friction against the axial strain, DEM, continuum and hybrid",
            "phi = asin((s1 - s3) / (s1 + s3)) [deg]",
            (|x: &Record| x.sin_phi.asin().to_degrees()) as fn(&Record) -> f64,
        ),
        (
            "shear_biaxial_volume_continuum",
            "Biaxial compression: the volumetric strain against the axial strain, DEM, continuum and hybrid",
            "volumetric strain [%] (compression +)",
            |x: &Record| 100.0 * x.volumetric,
        ),
    ] {
        let line =
            |name: String, records: &[Record]| Series::new(name, Kind::Line, records.iter().map(|x| (100.0 * x.axial, f(x))).collect());
        let chart = Chart {
            title: caption.into(),
            x_label: "axial strain [%]".into(),
            y_label: y_label.into(),
            series: std::iter::once(line(format!("DEM, seed {}", dem.seed), &dem.records))
                .chain(
                    runs.iter()
                        .map(|r| line(format!("continuum, {:.0}-D50 cells", r.cell / d), &r.records)),
                )
                .chain(hybrids.iter().map(|h| line(h.name.clone(), &h.records)))
                .collect(),
            ..Chart::default()
        };
        part.chart(&args.out, stem, caption, &chart)?;
    }
    band_volume_report(dems, &hybrids, args, part, md)
}

/// Chen Fig. 17 (right): the volumetric strain in the band only, the DEM's on each sample and
/// the hybrids' from their enrichment on, each in App. A's box of its own band; the values at
/// the window's ends and a chart per sample.
fn band_volume_report(
    dems: &[BiaxialRun],
    hybrids: &[HybridCurves],
    args: &super::super::ValidateArgs,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<()> {
    let at = |curve: &[[f64; 2]], axial: f64| {
        curve
            .iter()
            .find(|p| p[0] >= axial)
            .or(curve.last())
            .map_or(f64::NAN, |p| 100.0 * p[1])
    };
    let _ = writeln!(
        md,
        "#### The volume in the band (Fig. 17, right)\n\nThe grains' area in App. A's box of each run's own band (the box as found \
         over the window, fixed in space; each disk clipped by its sides) over the box's area, Φ, against the sample's at the \
         start of the shortening in the same box, Φ0: ε_v = 1 − Φ0 / Φ (compression positive, dilation negative), every \
         {:.2}% of axial strain; the hybrid's from its enrichment on (before it there are no grains). Where a hybrid's box \
         reaches into continuum cells, which hold no grains, it reads the packing low.\n\n\
         | run | ε_v in the band at {:.1}% of axial strain | at the end | the specimen's at the end | the box in continuum cells |\n\
         |---|---:|---:|---:|---:|",
        100.0 * SNAPSHOT,
        100.0 * WINDOW.0
    );
    // The DEM's rows (no continuum cells) and the hybrids'.
    let rows = dems
        .iter()
        .map(|r| (format!("DEM, seed {}", r.seed), &r.band_volume, &r.records, String::new()))
        .chain(hybrids.iter().map(|h| {
            (
                h.name.clone(),
                &h.band_volume,
                &h.records,
                format!("{:.0}%", 100.0 * h.box_in_continuum),
            )
        }));
    for (name, curve, records, in_continuum) in rows {
        let _ = writeln!(
            md,
            "| {name} | {:.2}% | {:.2}% | {:.2}% | {in_continuum} |",
            at(curve, WINDOW.0),
            at(curve, f64::INFINITY),
            records.last().map_or(f64::NAN, |x| 100.0 * x.volumetric)
        );
    }
    let _ = writeln!(md);
    let line =
        |name: String, curve: &[[f64; 2]]| Series::new(name, Kind::Line, curve.iter().map(|p| (100.0 * p[0], 100.0 * p[1])).collect());
    for r in dems {
        let caption = format!(
            "Biaxial compression, seed {}: the volume in the band, DEM and hybrid (Chen Fig. 17, right)",
            r.seed
        );
        let chart = Chart {
            title: format!("Volume in the band, seed {} (Chen Fig. 17, right)", r.seed),
            x_label: "axial strain [%]".into(),
            y_label: "volumetric strain in the band [%] (compression +)".into(),
            series: std::iter::once(line("DEM".into(), &r.band_volume))
                .chain(
                    hybrids
                        .iter()
                        .filter(|h| h.seed == r.seed)
                        .map(|h| line(h.name.clone(), &h.band_volume)),
                )
                .collect(),
            ..Chart::default()
        };
        part.chart(&args.out, &format!("shear_biaxial_band_volume_s{}", r.seed), caption, &chart)?;
    }
    Ok(())
}

/// The hybrid biaxial on each DEM sample (compared with the DEM on it, as the planar shear's
/// hybrids are: one sample does not fix a band to a few D50), once per continuum cell of `--biaxial-cells` (2 D50
/// by default: on 4-D50 cells the continuum's failure starts under the platen,
/// docs/validation.md), φ0 of `--biaxial-phi0` and transfer of `--shear-transfer`: its table,
/// checks and band pictures. Returns each finished run's records, labelled.
fn hybrid_report(
    dems: &[BiaxialRun],
    model: &grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    density: f64,
    d: f64,
    args: &super::super::ValidateArgs,
    part: &mut Part,
    md: &mut String,
) -> anyhow::Result<Vec<HybridCurves>> {
    let _ = writeln!(
        md,
        "### Hybrid (Fig. 16–21)\n\nThe continuum above (on the cells named) until the oracle fires; then the cells \
         within φ0 of the flagged ones (Table 6: 1 cm, 10 D50) enriched with the DEM specimen of a sample (each of seeds {}, \
         each hybrid compared with the DEM on its sample) as it stood before its shortening (less half a cell: discrete, the points deleted; the next cell: hybrid, w = {}): \
         the grains of the cells where the material of those cells started (the points' places at the start of the \
         shortening), trained from there to the detection (§4.1.1: a ring of the sample's grains in the cells around \
         them moves with the continuum's nodal velocity and is dropped after; the inner grains move freely, the fluid's \
         pressure on the free faces, the top wall coming down with the platen; the stress is Love–Weber's over the \
         trained grains and ring), those that end in the cells that need them kept at the continuum's velocity there \
         (`band_epoch::enrich`'s cut, as the runtime's), and the two models coupled \
         every step (the DEM's substeps, the coupler's common velocity on the shared nodes, the grains' transfer back as \
         named). The fluid's pressure acts on both models' faces (the points' `ambient_pressure`, the grains' \
         `grains_dem::fluid`), the platen on the points by contact (× their weight) and on the grains as the DEM's wall, \
         both at the same plane. σ1 is the platen's force on both over the width (the outer faces' area over the \
         height) plus p, from the start; the volume the area of points and grains in slabs. The band: App. A on the grains \
         over the window, counting those cut {EDGE_CELLS} cells or more inside the box of their places in the sample.\n\n\
         | seed, cells, φ0, transfer | grains cut (points deleted) | enrichment: mass, momentum | trained [σxx, σyy] (as cut; the continuum's there) | DEM substeps | t_s (App. A) | profile at half peak | inclination | band grains at a continuum cell | strays | peak φ (axial strain) | φ, ψ over the window | shared nodes a step | coupler's momentum error | mass change | wall |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        dems.iter().map(|r| r.seed.to_string()).collect::<Vec<_>>().join(", "),
        super::super::training::WEIGHT
    );
    let mut curves = Vec::new();
    let runs = dems.iter().flat_map(|dem| {
        args.biaxial_cells.iter().flat_map(move |&cells| {
            args.biaxial_phi0
                .iter()
                .flat_map(move |&phi0| args.shear_transfers.iter().map(move |t| (dem, cells, phi0, t)))
        })
    });
    for (dem, cells, phi0, transfer) in runs {
        let name = format!("seed {}, {cells}-D50 cells, φ0 {phi0} D50, {transfer}", dem.seed);
        let stem = format!("shear_biaxial_band_hybrid_s{}_c{cells}_phi{phi0}_{transfer}", dem.seed).replace([':', '.'], "_");
        let transfer = super::super::hybrid::transfer_named(transfer)?;
        let run = match continuum_run(dem, model, density, d, cells, Some((transfer, phi0))) {
            Ok(r) => r,
            Err(e) => {
                let what = format!("biaxial (hybrid, {name})");
                super::super::unfinished_row(part, md, (&format!("`{name}`"), 14), &what, &e);
                continue;
            }
        };
        let Some(h) = run.hybrid.as_ref() else { continue };
        let (peak, _) = peak_angles(&run.records);
        let (phi, psi) = window_angles(&run.records);
        let b = &h.band;
        let _ = writeln!(
            md,
            "| `{name}` | {} ({}) | {:.1e}, {:.1e} | [{:.0}, {:.0}] Pa ([{:.0}, {:.0}]; [{:.0}, {:.0}]) | {} | {:.1} D50 ({:.0} long) | {:.0} D50 | {:.1}° | {} of {} | {} | {:.2}° ({:.2}%) | {phi:.2}°, {psi:.2}° | {:.0} | {:.1e} | {:.1e} | {:.0} s |",
            b.grains,
            b.deleted,
            b.mass,
            b.momentum,
            b.trained[0],
            b.trained[1],
            b.untrained[0],
            b.untrained[1],
            b.continuum[0],
            b.continuum[1],
            h.substeps,
            h.t_s,
            h.length,
            h.fwhm,
            h.angle,
            h.at_interface,
            h.members.len(),
            h.strays,
            peak.1,
            100.0 * peak.0,
            h.shared_per_step,
            h.momentum_error,
            h.mass_change,
            run.wall
        );
        part.check(
            format!("biaxial (hybrid, {name}): the band's thickness"),
            format!(
                "Chen 2021 Fig. 18: the hybrid's band is the DEM's (10 D50 both); here seed {}'s DEM, {:.1} D50",
                dem.seed, dem.t_s
            ),
            format!("{:.1} D50 at {:.1}°", h.t_s, h.angle),
            "within 2 D50 of the DEM's (issue 22)",
            (h.t_s - dem.t_s).abs() <= 2.0,
        );
        part.check(
            format!("biaxial (hybrid, {name}): the band forms within the grains, not at their edge"),
            "Chen 2021 §4: the enrichment holds the band",
            format!(
                "{} of App. A's {} band grains within a cell of a continuum cell",
                h.at_interface,
                h.members.len()
            ),
            "at most a quarter",
            4 * h.at_interface <= h.members.len(),
        );
        part.check(
            format!("biaxial (hybrid, {name}): the enrichment and the coupling keep mass and momentum"),
            "Yue 2018 Alg. 3 and the enrichment's rules: exchanges, not sources",
            format!(
                "enrichment: mass {:.1e}, momentum {:.1e}; coupler's largest momentum error of a step {:.1e}; mass change {:.1e}",
                b.mass, b.momentum, h.momentum_error, h.mass_change
            ),
            "round-off (1e-9; the mass over the run 1e-12)",
            b.mass < 1e-9 && b.momentum < 1e-9 && h.momentum_error < 1e-9 && h.mass_change < 1e-12,
        );
        let chart = super::super::band_chart(
            format!("Biaxial compression (hybrid, {name}): the band's grains (App. A)"),
            &h.x0,
            &h.members,
            d,
            "grains",
        );
        part.chart(
            &args.out,
            &stem,
            format!("Biaxial compression (hybrid, `{name}`): the grains App. A counts in the band"),
            &chart,
        )?;
        curves.push(HybridCurves {
            name: format!("hybrid, {name}"),
            seed: dem.seed,
            records: run.records.clone(),
            band_volume: h.band_volume.clone(),
            box_in_continuum: h.box_in_continuum,
        });
    }
    let _ = writeln!(md);
    Ok(curves)
}

/// A hybrid's name, its sample's seed, its records, its band's volume ([`band_volume`]) and
/// the share of the band's box in continuum cells.
struct HybridCurves {
    name: String,
    seed: u64,
    records: Vec<Record>,
    band_volume: Vec<[f64; 2]>,
    box_in_continuum: f64,
}

/// Side of the square of weak points at the right face [D50], the same material flaw on both
/// grids. Chen gives no size; one cell of 2 D50 left two conjugate bands, 6 D50 one band
/// (docs/validation.md).
const WEAK_D: f64 = 6.0;

/// One continuum biaxial compression (Chen Fig. 18, right).
struct ContinuumBiaxial {
    cell: f64,
    points: usize,
    /// App. A on the points' incremental plastic strain over the window: the box's thickness
    /// and length [D50]; the profile across the band's line at half peak [D50], the line's
    /// inclination [°].
    t_s: f64,
    length: f64,
    fwhm: f64,
    angle: f64,
    /// The axial strain when Alg. 1 first fired, the cells it flagged then and their mean
    /// position [D50].
    detected: Option<(f64, usize, [f64; 2])>,
    /// The points' positions at the window's start and App. A's band among them.
    x0: Vec<[f64; 2]>,
    band: Vec<usize>,
    records: Vec<Record>,
    wall: f64,
    /// A hybrid run's grains.
    hybrid: Option<HybridBiaxial>,
}

/// The hybrid's band in its grains (App. A over the window, as the DEM's), the enrichment and
/// training, and the coupling's bookkeeping.
struct HybridBiaxial {
    band: super::hybrid::BandGrains,
    /// The band's volumetric strain against the axial strain from the enrichment on
    /// ([`band_volume`]; the sample's grains at the start of the shortening its reference).
    band_volume: Vec<[f64; 2]>,
    /// The share of that band's box in continuum cells at the end.
    box_in_continuum: f64,
    substeps: usize,
    t_s: f64,
    length: f64,
    fwhm: f64,
    angle: f64,
    /// The grains' positions at the window's start and App. A's band among them, and how many
    /// of the band's grains lay within a cell of a continuum cell then.
    x0: Vec<[f64; 2]>,
    members: Vec<usize>,
    at_interface: usize,
    /// Grains in continuum cells at the end (strays: uncoupled).
    strays: usize,
    shared_per_step: f64,
    momentum_error: f64,
    mass_change: f64,
}

/// The biaxial compression of `dem`'s specimen as Chen's critical-state continuum `model`
/// on cells of `cell_d` D50 (two points per cell and axis, APIC): σ3 = p as the pressure of a
/// fluid around the specimen (`MpmParams::ambient_pressure`), the bottom nodes fixed, the top
/// a frictionless plane moving down at the DEM's speed in contact with the points
/// ([`platen`]), weak points (at Φ_cs) in a square
/// of WEAK_D at the right face a quarter of the way up (Chen: "the right lower part"), the
/// oracle (Alg. 1, Table 6) every ORACLE_EVERY steps. With `hybrid` (the grains' transfer
/// back, φ0 in D50), the hybrid of [`hybrid`] from the oracle's detection on, its stress and
/// volume from the platen's force and the outer faces of points and grains throughout.
fn continuum_run(
    dem: &BiaxialRun,
    model: &grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState,
    grain_density: f64,
    d: f64,
    cell_d: f64,
    hybrid: Option<(grains_dem::coupled::GrainTransfer, f64)>,
) -> anyhow::Result<ContinuumBiaxial> {
    use super::super::continuum::ORACLE_EVERY;
    use grains_grid::Grid;
    use grains_mpm::pipeline::{Model, MpmPipeline};
    use grains_mpm::points::Points;
    use grains_oracle::shear_band::{Coefficients, Persistence, RecentStrain};
    let t0 = std::time::Instant::now();
    let (w, height) = (dem.width, dem.height);
    let nx = (w / (cell_d * d)).round().max(4.0) as u64;
    let h = w / nx as f64;
    let spacing = 0.5 * h;
    // Room on both sides for the bulge, three wall layers under y = 0 (the fixed bottom).
    let margin = (0.25 * w / h).ceil() as u64;
    let ny = (height / h).ceil() as u64 + 4;
    let grid = Grid {
        origin: [-(margin as f64) * h, -2.0 * h, 0.0],
        h,
        nodes: [nx + 2 * margin + 1, ny + 3, 1],
        period: [0, 0, 0],
    };
    let rho = grain_density * dem.packing;
    let shear_modulus = model.shear;
    let platen_stiffness = model.wave_speed_modulus(2);
    let (params, dt) = super::super::continuum::mpm_params(grid, spacing, model, rho, (grains_mpm::pipeline::PointLoads::Face, PRESSURE));
    let packing_cs = match params.model {
        Model::CriticalState(m) => m.packing_cs,
        _ => unreachable!("built above"),
    };
    let mut pts = Points::<D2>::default();
    let (cols, rows) = ((w / spacing).round() as usize, (height / spacing).round() as usize);
    for j in 0..rows {
        for i in 0..cols {
            let x = [(i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing];
            let weak = x[0] > w - WEAK_D * d && (x[1] - 0.25 * height).abs() < 0.5 * WEAK_D * d;
            pts.push(
                D2::from_array([x[0], x[1], 0.0]),
                rho * spacing * spacing,
                spacing * spacing,
                if weak { packing_cs } else { dem.packing },
            );
        }
    }
    let n = pts.len();
    let start: HashMap<u64, [f64; 2]> = (0..n).map(|k| (pts.id[k], [pts.x[k].x, pts.x[k].y])).collect();
    if let Model::CriticalState(m) = params.model {
        super::super::continuum::consolidated(&mut pts, m.bulk, PRESSURE);
    }
    let mut pipe = MpmPipeline::<D2>::new(2).map_err(|e| anyhow::anyhow!(e))?;
    let cells = Grid {
        nodes: [grid.nodes[0] - 1, grid.nodes[1] - 1, 1],
        ..grid
    };
    let coefficients = Coefficients::BIAXIAL;
    let (mut recent, mut persistence) = (RecentStrain::default(), Persistence::default());
    let mut detected = None;
    let settle = (0.05 / dt).ceil() as usize;
    // The top comes up to speed over three shear-wave transits (the planar shear's ramp).
    let speed = SPEED_OVER_HEIGHT * height;
    let ramp = 3.0 * height / (shear_modulus / rho).sqrt();
    // The points' positions and plastic strain at the window's start, by id; their plastic
    // strain at its end.
    let mut from: Option<HashMap<u64, ([f64; 2], f64)>> = None;
    let mut to: Option<HashMap<u64, f64>> = None;
    let mut records = Vec::new();
    let (mut travel, mut v0) = (0.0, None);
    // The hybrid's: the continuum's nodal velocities up to the detection, the coupled step
    // after it, the enrichment, the grains at the window's ends, the platen's force summed
    // since the last record (points and grains) and the area at the start of the shortening.
    let mut history = super::hybrid::NodeHistory { grid, records: Vec::new() };
    // The points' positions at the start of the shortening, by id: where the material the
    // enrichment needs started (the training's packing is the DEM sample's then).
    let mut origin: Option<HashMap<u64, [f64; 2]>> = None;
    let mut coupled: Option<super::super::hybrid::Coupled> = None;
    let mut band_grains = None;
    let (mut grains_from, mut grains_to) = (None, None);
    // The hybrid's grains every SNAPSHOT of axial strain from the enrichment on (the band's
    // volume).
    let (mut snapshots, mut next_snapshot) = (Vec::new(), 0.0);
    let (mut force, mut forces, mut a0) = (0.0, 0usize, None);
    let fluid = grains_dem::fluid::Fluid {
        pressure: PRESSURE,
        cell: 2.0 * d,
        packing: dem.packing,
    };
    for step in 0.. {
        if grains_service::signals::signalled() {
            anyhow::bail!("stopped by a signal");
        }
        let axial = travel / height;
        if axial >= END {
            break;
        }
        let pressing = step >= settle;
        if pressing && hybrid.is_some() && origin.is_none() {
            origin = Some((0..pts.len()).map(|k| (pts.id[k], [pts.x[k].x, pts.x[k].y])).collect());
        }
        if pressing && from.is_none() && axial >= WINDOW.0 {
            from = Some(
                (0..pts.len())
                    .map(|k| (pts.id[k], ([pts.x[k].x, pts.x[k].y], pts.plastic_strain[k])))
                    .collect(),
            );
            grains_from = coupled.as_ref().map(free_grains);
        }
        if let Some(c) = coupled.as_ref()
            && axial >= next_snapshot
        {
            snapshots.push((axial, disks(c.dem())));
            next_snapshot = ((axial / SNAPSHOT).floor() + 1.0) * SNAPSHOT;
        }
        if pressing && to.is_none() && axial >= WINDOW.1 {
            to = Some((0..pts.len()).map(|k| (pts.id[k], pts.plastic_strain[k])).collect());
            grains_to = coupled.as_ref().map(free_grains);
        }
        // The top platen moving down, the material free to slip along it (Chen's free-slip
        // top).
        let vy = if pressing {
            -speed * ((step + 1 - settle) as f64 * dt / ramp).min(1.0)
        } else {
            0.0
        };
        force += platen(&mut pts, height - travel, vy, 0.5 * spacing, platen_stiffness);
        travel -= vy * dt;
        pipe.phase1(&pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("continuum biaxial: {e}"))?;
        if hybrid.is_some() && pressing && detected.is_none() && (step - settle).is_multiple_of(ORACLE_EVERY) {
            history.record((step + 1 - settle) as f64 * dt, &mut pipe);
        }
        let constrained = match coupled.as_mut() {
            Some(c) => {
                c.dem_mut().walls[1].velocity = D2::from_array([0.0, vy, 0.0]);
                let v = c.couple(&mut pipe, &params, dt)?;
                force += c.dem().walls[1].load[1];
                Some(v)
            }
            None => None,
        };
        forces += 1;
        pipe.phase2(&mut pts, &params, dt)
            .map_err(|e| anyhow::anyhow!("continuum biaxial: {e}"))?;
        if let (Some(c), Some(v)) = (coupled.as_mut(), constrained) {
            c.finish(&v, dt)?;
            c.track_mass(&pts);
        }
        if !pressing || !(step - settle).is_multiple_of(ORACLE_EVERY) {
            continue;
        }
        let t = step as f64 * dt;
        if detected.is_none() && super::super::continuum::oracle_fires(&cells, &pts, d, &coefficients, (&mut recent, &mut persistence), t) {
            let at: Vec<[f64; 2]> = persistence
                .flagged()
                .iter()
                .enumerate()
                .filter(|(_, f)| **f)
                .map(|(i, _)| {
                    let nx = cells.nodes[0] as usize;
                    [0, 1].map(|k| cells.origin[k] + ([i % nx, i / nx][k] as f64 + 0.5) * h)
                })
                .collect();
            let mean = [0, 1].map(|k| at.iter().map(|p| p[k]).sum::<f64>() / at.len() as f64 / d);
            detected = Some((axial, at.len(), mean));
            if let Some((transfer, phi0_d)) = hybrid {
                let detection = super::super::continuum::Detection {
                    strain: axial,
                    shear_stress: 0.0,
                    nodes: params.grid,
                    kernel: params.kernel,
                    cells,
                    flagged: persistence.flagged().to_vec(),
                    points: super::super::continuum::oracle_points(&pts),
                };
                let stress: Vec<([f64; 2], f64)> = (0..pts.len())
                    .map(|k| ([pts.tau[k].x_axis.x, pts.tau[k].y_axis.y], pts.jacobian[k] * pts.volume[k]))
                    .collect();
                let duration = (step + 1 - settle) as f64 * dt;
                let (parts, grains) = super::hybrid::enrich_and_train(
                    &dem.sample,
                    &detection,
                    origin.as_ref().context("the points' places at the start of the shortening")?,
                    &stress,
                    &history,
                    (duration, &fluid),
                    (dem.dt, GLUE_D * d, speed, travel, phi0_d * d),
                )?;
                history.records = Vec::new();
                let mut c = super::super::hybrid::Coupled::new(parts, &mut pts, &params, (cells, transfer, Some(fluid)), dt, dem.dt, None);
                // The grains' platen where the points' is.
                if let grains_dem::state::WallShape::Plane { point, .. } = &mut c.dem_mut().walls[1].shape {
                    *point = D2::from_array([0.0, height - travel, 0.0]);
                }
                tracing::info!(
                    "validate biaxial: hybrid on {cell_d}-D50 cells: {} grains cut, {} points deleted, trained in {:.0} s",
                    grains.grains,
                    grains.deleted,
                    grains.wall
                );
                band_grains = Some(grains);
                coupled = Some(c);
            }
            tracing::info!(
                "validate biaxial: continuum on {cell_d}-D50 cells: the oracle fires at axial strain {axial:.4}, {} cells, mean at ({:.1}, {:.1}) D50",
                at.len(),
                mean[0],
                mean[1]
            );
        }
        if (step - settle).is_multiple_of(5 * ORACLE_EVERY) {
            if hybrid.is_some() {
                // σ1 from the platen's force on points and grains over the width (the area
                // over the height), plus the fluid's pressure on the top (as the DEM's).
                let mut disks: Vec<([f64; 2], f64)> = (0..pts.len()).map(|k| ([pts.x[k].x, pts.x[k].y], 0.5 * spacing)).collect();
                if let Some(c) = &coupled {
                    let g = &c.dem().grains;
                    disks.extend((0..g.len()).map(|i| ([g.x[i].x, g.x[i].y], g.radius[i])));
                }
                let area = slab_area(&disks, 2.0 * d);
                let a0 = *a0.get_or_insert(area);
                let sigma1 = force / forces.max(1) as f64 / (area / (height - travel)) + PRESSURE;
                records.push(Record {
                    axial,
                    volumetric: 1.0 - area / a0,
                    sin_phi: (sigma1 - PRESSURE) / (sigma1 + PRESSURE),
                });
            } else {
                let (mut sxx, mut syy, mut vol) = (0.0, 0.0, 0.0);
                for k in 0..n {
                    sxx -= pts.tau[k].x_axis.x * pts.volume[k];
                    syy -= pts.tau[k].y_axis.y * pts.volume[k];
                    vol += pts.jacobian[k] * pts.volume[k];
                }
                let v0 = *v0.get_or_insert(vol);
                records.push(Record {
                    axial,
                    volumetric: 1.0 - vol / v0,
                    sin_phi: (syy - sxx) / (syy + sxx),
                });
            }
            (force, forces) = (0.0, 0);
        }
    }
    let (from, to) = (from.context("the window's start")?, to.context("the window's end")?);
    let mut ids: Vec<u64> = from.keys().copied().collect();
    ids.sort_unstable();
    let x0: Vec<[f64; 2]> = ids.iter().map(|id| from[id].0).collect();
    let strain: Vec<f64> = ids.iter().map(|id| to[id] - from[id].1).collect();
    let start: Vec<[f64; 2]> = ids.iter().map(|id| start[id]).collect();
    let found = inner_band(&x0, &strain, &start, EDGE_CELLS * cell_d * d, spacing, d, w.hypot(height))?;
    let hybrid = match (hybrid, coupled, band_grains) {
        (Some(_), Some(c), Some(band)) => {
            let (from, to) = (
                grains_from.with_context(|| {
                    let at = detected.map_or(f64::NAN, |d| d.0);
                    format!(
                        "the oracle fired at {:.2}% of axial strain, after the band's window starts ({:.1}%): no grains to measure the band on",
                        100.0 * at,
                        100.0 * WINDOW.0
                    )
                })?,
                grains_to.context("the hybrid's window's end")?,
            );
            let (ids, x0, strain) = super::super::best_fit(&from, &to, d);
            let start: Vec<[f64; 2]> = ids.iter().map(|id| band.start[id]).collect();
            let found = inner_band(&x0, &strain, &start, EDGE_CELLS * cell_d * d, d, d, w.hypot(height))?;
            // Within a cell of a continuum cell: any of eight points a cell away in one.
            let near_continuum = |x: [f64; 2]| {
                (0..8).any(|k| {
                    let a = k as f64 * std::f64::consts::FRAC_PI_4;
                    c.zone([x[0] + h * a.cos(), x[1] + h * a.sin(), 0.0]) == grains_oracle::Zone::Continuum
                })
            };
            let at_interface = found.members.iter().filter(|&&i| near_continuum(x0[i])).count();
            let strays = c
                .positions()
                .values()
                .filter(|p| c.zone([p[0], p[1], 0.0]) == grains_oracle::Zone::Continuum)
                .count();
            // The share of the band's box in continuum cells at the end (no grains there: the
            // box then reads the grains' packing low), on a lattice of 40 × 40 points in it.
            let b = &found.bbox;
            let normal = [-b.dir[1], b.dir[0]];
            let in_continuum = (0..1600)
                .filter(|k| {
                    let (u, v) = ((k % 40) as f64 / 39.0 * 2.0 - 1.0, (k / 40) as f64 / 39.0 * 2.0 - 1.0);
                    let (a, t) = (u * b.half[0], v * b.half[1]);
                    let x = [
                        b.centre[0] + a * b.dir[0] + t * normal[0],
                        b.centre[1] + a * b.dir[1] + t * normal[1],
                        0.0,
                    ];
                    c.zone(x) == grains_oracle::Zone::Continuum
                })
                .count() as f64
                / 1600.0;
            Some(HybridBiaxial {
                band_volume: band_volume(&found.bbox, &disks(&dem.sample), &snapshots),
                box_in_continuum: in_continuum,
                band,
                substeps: c.substeps,
                t_s: found.t_s,
                length: found.length,
                fwhm: found.fwhm,
                angle: found.angle,
                x0,
                members: found.members,
                at_interface,
                strays,
                shared_per_step: c.shared as f64 / c.steps.max(1) as f64,
                momentum_error: c.momentum_error,
                mass_change: c.mass_change,
            })
        }
        (Some(_), ..) => anyhow::bail!("the oracle never fired: nothing enriched"),
        _ => None,
    };
    Ok(ContinuumBiaxial {
        cell: h,
        points: n,
        t_s: found.t_s,
        length: found.length,
        fwhm: found.fwhm,
        angle: found.angle,
        detected,
        band: found.members,
        x0,
        records,
        wall: t0.elapsed().as_secs_f64(),
        hybrid,
    })
}

/// The free grains' positions, by id.
fn free_grains(c: &super::super::hybrid::Coupled) -> HashMap<u64, [f64; 2]> {
    let g = &c.dem().grains;
    (0..g.len())
        .filter(|&i| !g.frozen[i])
        .map(|i| (g.id[i], [g.x[i].x, g.x[i].y]))
        .collect()
}

/// The top platen as a rigid, frictionless plane at `at` moving at `vy`, in contact with the
/// points (as the DEM's platen with the grains, and Jiang 2020 §4's bodies with points), not
/// a condition on the grid's nodes: a point whose top (its GIMP half-width `reach` over its
/// centre) is above the plane carries k · overlap down, k the material's P-wave modulus (over
/// a unit thickness: as stiff as a point spacing of the material), with the damping of a
/// restitution of 0.2 on its approach. The run takes the loads on the points' faces
/// ([`PointLoads::Face`](grains_mpm::pipeline::PointLoads::Face)). A slip plane of the nodes
/// clamps the rows of nodes it has passed, a cell into the material at most, and on these
/// grids the oracle then fired where the band met the platen (docs/validation.md). A point of
/// a hybrid cell is that share of the material there (its weight): its spring and mass are
/// too. Returns the platen's force on the points (down positive).
pub(super) fn platen(pts: &mut grains_mpm::points::Points<D2>, at: f64, vy: f64, reach: f64, stiffness: f64) -> f64 {
    let e: f64 = 0.2;
    let zeta = -e.ln() / (std::f64::consts::PI.powi(2) + e.ln().powi(2)).sqrt();
    pts.loads.clear();
    let mut total = 0.0;
    for k in 0..pts.len() {
        let overlap = pts.x[k].y + reach - at;
        if overlap > 0.0 {
            let (k_n, m) = (stiffness * pts.weight[k], pts.mass[k] * pts.weight[k]);
            let approach = pts.v[k].y - vy;
            let damping = 2.0 * zeta * (k_n * m).sqrt();
            let f = (k_n * overlap + damping * approach).max(0.0);
            pts.loads.push((k, D2::from_array([0.0, -f, 0.0])));
            total += f;
        }
    }
    total
}
