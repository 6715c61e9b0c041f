//! `grains bench chute`: Yue 2018 §5's speed-up study (Fig. 18–19) on the periodic chute of
//! `scenes/chute_hybrid_2d.toml`. The geometry stays fixed (a layer 0.2 m long and 5 cm deep);
//! the sweep varies the grain radius (so the initial grain count N_i), the depth of the
//! discrete layer (so the DEM fraction F left after hybridization) and the MPM cell H. Every
//! grain size is poured once (vertical gravity, `grains pack`) and both models start from that
//! packing: the pure DEM (the layer's body made `dem`, two threads) and the hybrid (fixed
//! layered zones, two threads per solver, `coupling.substeps = "auto"`: both at their stable
//! steps), every run over the same simulated window. Printed: wall time, speed-up, the
//! measured F and the down-slope mass flux of each, the phase plots (hybrid faster or slower,
//! per H) and the cost model of `launch/src/cost.rs` fitted to these runs, with its
//! prediction at sizes this machine does not run.

use crate::cost::{Costs, Sample, fit};
use crate::report::chart::{Chart, Kind, Series};
use anyhow::Context;
use grains_protocol::Role;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, clap::Args)]
pub struct ChuteArgs {
    /// Directory of the scenes (chute_hybrid_2d.toml).
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Mean grain radii [mm] (N_i: about 3,400 at 1 mm, 28,000 at 0.35 mm).
    #[arg(long, value_delimiter = ',', default_values_t = [1.0, 0.5, 0.35])]
    pub radii: Vec<f64>,
    /// Depth of the layer [m] (the scene's is 5 cm).
    #[arg(long, default_value_t = 0.05)]
    pub depth: f64,
    /// Depths of the discrete layer, as fractions of the layer's depth (the coupled band comes
    /// under it).
    #[arg(long, value_delimiter = ',', default_values_t = [0.05, 0.15, 0.3])]
    pub depths: Vec<f64>,
    /// MPM cell sizes H [m] (whole divisors of the 0.2 m period).
    #[arg(long, value_delimiter = ',', default_values_t = [0.008, 0.004, 0.002])]
    pub cells: Vec<f64>,
    /// Thickness of the coupled band, in cells.
    #[arg(long, default_value_t = 1.0)]
    pub band: f64,
    /// Grains kept over the floor under the continuum, with a band of `--band` cells over
    /// them (`coupling.discrete_base`) [m]; 0: the continuum reaches the floor.
    #[arg(long, default_value_t = 0.0)]
    pub base: f64,
    /// Simulated time of every run [s].
    #[arg(long, default_value_t = 0.1)]
    pub window: f64,
    /// Where the packings, runs, table and charts go.
    #[arg(long, default_value = "out/bench/chute")]
    pub out: PathBuf,
    /// The hybrid's continuum: the scene's (`scene`), or Chen 2021's critical-state softening
    /// calibrated per grain size on `grains calibrate --shear`'s first shear (I = 1e-3, strain
    /// 2, `--cell-grains` grains at the scene's default pressure) and started at the poured bed's packing
    /// fraction (`critical-state`).
    #[arg(long, value_enum, default_value_t = Continuum::Scene)]
    pub continuum: Continuum,
    /// Grains of the shear cell of `--continuum critical-state` (more: less noise in its Φ).
    #[arg(long, default_value_t = 2400)]
    pub cell_grains: usize,
    /// Beds poured per grain size (`run.seed` 1 to N) for the pure DEM: its flux over this
    /// window scatters from one pour to the next (6.5% between four 15-cm beds), so the
    /// hybrid (run on the first) is compared with their mean.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub pours: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Continuum {
    Scene,
    CriticalState,
}

const SCENE: &str = "chute_hybrid_2d.toml";
/// Period of the layer [m].
const LENGTH: f64 = 0.2;
/// DEM steps per macro-step of the pure DEM runs.
const DEM_SUBSTEPS: u32 = 20;
/// Slabs of the velocity profile, parallel to the floor [m].
const SLAB: f64 = 2.5e-3;
/// The share of the layer's mass, from the top, whose mean velocity is the surface's.
const SURFACE: f64 = 0.2;

/// The grains of one size: radius and spread, and the layer between the glued row and the top.
fn grains(r: f64) -> Vec<String> {
    let bottom = 3.0 * r;
    vec![
        format!("material.0.dem.radius={r:e}"),
        format!("material.0.dem.radius_std={:e}", 0.08 * r),
        format!("body.1.max=[{LENGTH},{:e}]", 2.6 * r),
        format!("body.0.min=[0.0,{bottom:e}]"),
    ]
}

/// The packing of grains of radius `r` poured with `run.seed` = `seed`, once per size and
/// seed (kept in `--out`).
fn packing(args: &ChuteArgs, r: f64, seed: u64) -> anyhow::Result<PathBuf> {
    let pour = if seed == 1 { String::new() } else { format!("_s{seed}") };
    let name = format!("packing_r{:.0}um_d{:.0}mm{pour}.data", r * 1e6, args.depth * 1e3);
    let path = std::path::absolute(args.out.join(name))?;
    if path.exists() {
        return Ok(path);
    }
    // A jittered lattice (spacing 2.37 r) settles to about 0.66 of its height.
    let top = 3.0 * r + args.depth / 0.62;
    let mut o = grains(r);
    o.extend([
        "gravity=[0.0,-9.81]".into(),
        "body.0.model=\"dem\"".into(),
        format!("body.0.max=[{LENGTH},{top:e}]"),
        format!("domain.max=[{LENGTH},{:e}]", top + 0.01),
        "coupling.substeps=10".into(),
        "run.threads=2".into(),
        format!("run.seed={seed}"),
    ]);
    let dt = dem_step(&args.scenes.join(SCENE), &o)?;
    o.push(format!("run.dt={:e}", 10.0 * dt));
    o.push(format!("run.duration={:.3}", (2.0 * top / 9.81).sqrt() + 0.1));
    tracing::info!(
        "bench chute: pouring grains of radius {} mm, seed {seed} (grains pack, once)",
        r * 1e3
    );
    crate::pack::pack(&crate::pack::PackArgs {
        scene: args.scenes.join(SCENE),
        out: path.clone(),
        friction: None,
        overrides: o,
    })?;
    Ok(path)
}

/// The DEM's stable step of the scene with these overrides [s] (a hair under it: the check
/// is strict, and run.dt = k dt must not round above k times the limit).
fn dem_step(scene: &Path, overrides: &[String]) -> anyhow::Result<f64> {
    let mut o = overrides.to_vec();
    o.extend(["body.0.model=\"dem\"".into(), "coupling.substeps=1".into(), "run.dt=1e-9".into()]);
    let (s, _) = grains_protocol::scene::load_with_overrides(scene, &o)?;
    let (safe, ..) = grains_dem_service::setup::stable_step(&s).context("the chute has DEM grains")?;
    Ok(safe * (1.0 - 1e-6))
}

/// The layer's continuum as Chen 2021's critical-state softening: its parameters from the
/// shear cell of these grains (not from the chute), its initial packing fraction the poured
/// bed's, read with the cell's estimator over the middle half of the layer.
fn critical_state_overrides(args: &ChuteArgs, base: &[String], packing: &Path) -> anyhow::Result<Vec<String>> {
    use crate::calibrate::{default_pressure, shear};
    let (scene, _) = grains_protocol::scene::load_with_overrides(&args.scenes.join(SCENE), base)?;
    let material = crate::calibrate::hybrid_material(&scene)?;
    let pressure = default_pressure(&scene, material);
    let (grains, strain, seed) = (args.cell_grains, 2.0, 1);
    tracing::info!("bench chute: the critical-state continuum from the shear cell ({grains} grains at {pressure:.0} Pa, I = 1e-3)");
    let cell = shear::simple_shear(&scene, material, grains, pressure, &[1e-3], strain, seed)?;
    let Some(c) = shear::critical_state(&cell.transient) else {
        anyhow::bail!("the shear cell's sample has no peak denser than its critical state: no critical-state continuum to fit");
    };
    let grains_protocol::scene::Shape::Box { min, max } = scene.bodies[0].shape else {
        anyhow::bail!("the chute's layer is a box");
    };
    let bed = grains_dem_service::lammps_data::read(packing).map_err(anyhow::Error::msg)?;
    let inside = bed
        .atoms
        .iter()
        .filter(|a| a.kind != 2 && (min[0]..=max[0]).contains(&a.x[0]))
        .map(|a| (a.x[1], 0.5 * a.diameter));
    let (lo, hi) = (min[1] + 0.25 * (max[1] - min[1]), min[1] + 0.75 * (max[1] - min[1]));
    let phi0 = shear::band_packing(inside, lo, hi, max[0] - min[0]);
    tracing::info!(
        "bench chute: critical state phi_cs {:.2} deg, packing_critical {:.4}, chi {:.2}, xi {:.2} (peak sin phi {:.4} at packing {:.4});          the bed's packing {phi0:.4}",
        c.friction_angle,
        c.packing_critical,
        c.chi,
        c.xi,
        c.peak_sin,
        c.peak_packing
    );
    Ok(vec![
        "material.0.mpm.model=\"critical_state\"".into(),
        format!("material.0.mpm.friction_angle={:.4}", c.friction_angle),
        format!("material.0.mpm.packing_critical={:.5}", c.packing_critical),
        format!("material.0.mpm.chi={:.4}", c.chi),
        format!("material.0.mpm.xi={:.4}", c.xi),
        format!("material.0.mpm.packing={phi0:.5}"),
        format!(
            "material.0.mpm.calibration=\"grains calibrate --shear --grains {grains} --seed {seed} --pressure {pressure} \
             --inertials 1e-3 --strain {strain}: first shear's critical state (bench chute); packing: the poured bed's\""
        ),
    ])
}

struct Row {
    radius: f64,
    /// Cell [m] (0 for the pure DEM) and discrete depth fraction asked for.
    cell: f64,
    depth: f64,
    /// Grains of the run at the start, and of the pure DEM of the same size.
    grains: u64,
    dem_grains: u64,
    points: u64,
    sample: Sample,
    /// Down-slope mass flux per unit width at the end of the window, Σ m v_x / L [kg/(m s)]
    /// (per metre of thickness).
    flux: f64,
    /// The pure DEM's: its flux on every pour, the first (`flux`) included; empty for a hybrid.
    pours: Vec<f64>,
    /// Wall time of every run of the row [s] (the pure DEM's pours; a hybrid's runs, one after
    /// each pour): `sample` takes their median.
    walls: Vec<f64>,
    /// Mass and down-slope momentum per `SLAB` above y = 0 at the end (grains and points; the
    /// pure DEM's summed over its pours).
    profile: Vec<(f64, f64)>,
}

impl Row {
    fn fraction(&self) -> f64 {
        self.grains as f64 / self.dem_grains as f64
    }
}

/// Mass and down-slope momentum per `SLAB` of height at the run's last frame, grains and
/// points together.
fn profile(dir: &Path) -> anyhow::Result<Vec<(f64, f64)>> {
    let mut slabs: Vec<(f64, f64)> = Vec::new();
    for name in ["grains.pvd", "points.pvd"] {
        let pvd = dir.join("frames").join(name);
        if !pvd.exists() {
            continue;
        }
        let frames = grains_service::vtu::collection(&pvd)?;
        let (_, last) = frames.last().with_context(|| format!("{}: no frame", pvd.display()))?;
        let f = grains_service::vtu::Frame::read(last)?;
        let (m, v) = (f.array("mass"), f.array("velocity"));
        let (m, v) = m.zip(v).with_context(|| format!("{}: no mass or velocity", last.display()))?;
        for (k, x) in f.points.iter().enumerate() {
            let slab = (x[1] / SLAB).floor().max(0.0) as usize;
            if slabs.len() <= slab {
                slabs.resize(slab + 1, (0.0, 0.0));
            }
            slabs[slab].0 += m[k];
            slabs[slab].1 += m[k] * v[3 * k];
        }
    }
    Ok(slabs)
}

/// The mean velocity of the top `SURFACE` of the mass, and the profile's L1 distance from
/// `reference`'s relative to its mean speed (Σ m |v − v_ref| / Σ m |v_ref|, by slab with
/// the reference's masses).
fn compare(profile: &[(f64, f64)], reference: &[(f64, f64)]) -> (f64, f64) {
    let v = |p: &[(f64, f64)], k: usize| p.get(k).filter(|s| s.0 > 0.0).map_or(0.0, |s| s.1 / s.0);
    let (mut diff, mut norm) = (0.0, 0.0);
    for (k, &(m, _)) in reference.iter().enumerate() {
        diff += m * (v(profile, k) - v(reference, k)).abs();
        norm += m * v(reference, k).abs();
    }
    (surface(profile), diff / norm)
}

/// The mean velocity of the top `SURFACE` share of the mass.
fn surface(profile: &[(f64, f64)]) -> f64 {
    let total: f64 = profile.iter().map(|s| s.0).sum();
    let (mut m, mut p) = (0.0, 0.0);
    for &(ms, ps) in profile.iter().rev() {
        let take = (SURFACE * total - m).min(ms).max(0.0);
        if take <= 0.0 {
            break;
        }
        m += take;
        p += ps * take / ms;
    }
    p / m
}

/// What one run gives: its costs, its grains and points at the start, its flux and profile.
type Outcome = (Sample, u64, u64, f64, Vec<(f64, f64)>);

fn one(args: &ChuteArgs, label: &str, overrides: &[String]) -> anyhow::Result<Outcome> {
    let (dir, scene) = super::run_resolved(&args.scenes.join(SCENE), label, overrides, &args.out, true)?;
    let t = crate::metrics::MetricsTable::read(&dir)?;
    let col = |role, what| -> anyhow::Result<Vec<f64>> { Ok(t.participant(role, what)?.unwrap_or_default()) };
    let mean = |v: Vec<f64>| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let first = |v: Vec<f64>| v.first().copied().unwrap_or(0.0) as u64;
    let last = |v: Vec<f64>| v.last().copied().unwrap_or(0.0);
    let flux = (last(col(Role::Dem, "px")?) + last(col(Role::Mpm, "px")?)) / LENGTH;
    Ok((
        Sample {
            grains: mean(col(Role::Dem, "items")?),
            points: mean(col(Role::Mpm, "items")?),
            substeps: scene.coupling.substeps,
            steps: scene.steps,
            wall: t.last("wall_s")?,
            dem_step: 1e-3 * mean(col(Role::Dem, "compute_ms")?),
            mpm_step: 1e-3 * mean(col(Role::Mpm, "compute_ms")?),
        },
        first(col(Role::Dem, "items")?),
        first(col(Role::Mpm, "items")?),
        flux,
        profile(&dir)?,
    ))
}

pub fn bench(args: &ChuteArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let mut rows: Vec<Row> = Vec::new();
    for &radius_mm in &args.radii {
        let r = radius_mm * 1e-3;
        let first = packing(args, r, 1)?;
        let mut base = grains(r);
        base.extend([
            format!("body.0.max=[{LENGTH},{:e}]", 3.0 * r + args.depth),
            format!("domain.max=[{LENGTH},{:e}]", args.depth + 0.03),
            format!("run.duration={}", args.window),
        ]);
        let dt = dem_step(&args.scenes.join(SCENE), &base)?;
        let on = |packing: &Path| format!("body.0.packing={:?}", packing.display().to_string());
        let on_first: Vec<String> = base.iter().cloned().chain([on(&first)]).collect();
        let continuum = match args.continuum {
            Continuum::Scene => Vec::new(),
            Continuum::CriticalState => critical_state_overrides(args, &on_first, &first)?,
        };
        // The hybrids' overrides, each run on the first pour.
        let mut hybrids = Vec::new();
        for &h in &args.cells {
            for &f in &args.depths {
                let mut o = on_first.clone();
                o.extend(continuum.iter().cloned());
                o.extend([
                    format!("domain.cell_size={h}"),
                    format!("domain.min=[0.0,{:e}]", -3.0 * h),
                    format!("coupling.discrete_layer={:e}", f * args.depth),
                    format!("coupling.hybrid_band={:e}", args.band * h),
                    format!("coupling.discrete_base={:e}", args.base),
                    format!("coupling.dem_dt={dt:e}"),
                    "run.threads=2".into(),
                ]);
                hybrids.push((h, f, format!("hybrid r={radius_mm}mm H={}mm depth={f}", h * 1e3), o));
            }
        }
        // The pure DEM on every pour, each pour followed by every hybrid: the hybrids' times
        // are taken beside the DEM's through the whole bench (a shared machine's speed drifts
        // by 2× over minutes), and their row takes the median (the same run every time). The
        // same DEM step, 20 to a macro-step: the launcher's per-macro-step cost (summaries,
        // metrics) stays out of the DEM's figure.
        let mut dem: Option<(Sample, u64, f64)> = None;
        let mut pours = Vec::new();
        let mut dem_runs = Vec::new();
        let mut dem_profile: Vec<(f64, f64)> = Vec::new();
        let mut hybrid_rows: Vec<Row> = Vec::new();
        let mut hybrid_runs: Vec<Vec<Sample>> = vec![Vec::new(); hybrids.len()];
        for seed in 1..=args.pours {
            let mut o: Vec<String> = base.iter().cloned().chain([on(&packing(args, r, seed)?)]).collect();
            o.extend([
                "body.0.model=\"dem\"".into(),
                format!("coupling.substeps={DEM_SUBSTEPS}"),
                format!("run.dt={:e}", DEM_SUBSTEPS as f64 * dt),
                "run.threads=2".into(),
                // The seed the bed was poured with: the glued floor row is drawn from it.
                format!("run.seed={seed}"),
            ]);
            let pour = if seed == 1 { String::new() } else { format!(" seed={seed}") };
            let (sample, grains, _, flux, profile) = one(args, &format!("DEM r={radius_mm}mm{pour}"), &o)?;
            pours.push(flux);
            dem_runs.push(sample);
            if dem_profile.len() < profile.len() {
                dem_profile.resize(profile.len(), (0.0, 0.0));
            }
            for (d, p) in dem_profile.iter_mut().zip(profile) {
                d.0 += p.0;
                d.1 += p.1;
            }
            dem.get_or_insert((sample, grains, flux));
            for ((h, f, label, o), runs) in hybrids.iter().zip(&mut hybrid_runs) {
                let (sample, grains, points, flux, profile) = one(args, label, o)?;
                runs.push(sample);
                if seed == 1 {
                    hybrid_rows.push(Row {
                        radius: r,
                        cell: *h,
                        depth: *f,
                        grains,
                        dem_grains: 0,
                        points,
                        sample,
                        flux,
                        pours: Vec::new(),
                        walls: Vec::new(),
                        profile,
                    });
                }
            }
        }
        let (sample, dem_grains, flux) = dem.expect("at least one pour");
        rows.push(Row {
            radius: r,
            cell: 0.0,
            depth: 1.0,
            grains: dem_grains,
            dem_grains,
            points: 0,
            sample: median_time(sample, &dem_runs),
            flux,
            pours,
            walls: dem_runs.iter().map(|s| s.wall).collect(),
            profile: dem_profile,
        });
        for (mut row, runs) in hybrid_rows.into_iter().zip(hybrid_runs) {
            row.dem_grains = dem_grains;
            row.sample = median_time(row.sample, &runs);
            row.walls = runs.iter().map(|s| s.wall).collect();
            rows.push(row);
        }
    }
    // The costs of the finest grains' runs: the smaller ones pay fixed costs per step that
    // the model puts in no term, and the model is for extrapolating upwards.
    let costs = rows
        .iter()
        .filter(|r| r.cell == 0.0)
        .min_by(|a, b| a.radius.total_cmp(&b.radius))
        .and_then(|dem| {
            let hybrid: Vec<Sample> = rows
                .iter()
                .filter(|r| r.cell > 0.0 && r.radius == dem.radius)
                .map(|r| r.sample)
                .collect();
            fit(&dem.sample, &hybrid)
        });
    let md = table(args, &rows, costs.as_ref());
    print!("{md}");
    let path = args.out.join("chute.md");
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(md.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))?;
    for &h in &args.cells {
        phase_chart(&rows, h).write(&args.out, &format!("chute_phase_h{:.0}mm", h * 1e3))?;
    }
    tracing::info!("bench chute: table and phase plots written to {}", args.out.display());
    Ok(())
}

/// Fig. 19 for one cell size: each hybrid run at (N_i, F), marked by which model was faster,
/// with its speed-up written beside it.
fn phase_chart(rows: &[Row], h: f64) -> Chart {
    let runs: Vec<(&Row, f64)> = rows
        .iter()
        .filter(|r| r.cell == h)
        .map(|r| (r, dem_wall(rows, r.radius) / r.sample.wall))
        .collect();
    let at = |faster: bool| -> Vec<(f64, f64)> {
        runs.iter()
            .filter(|(_, s)| (*s > 1.0) == faster)
            .map(|(r, _)| (r.dem_grains as f64, r.fraction()))
            .collect()
    };
    Chart {
        title: format!("Periodic chute, H = {} mm: hybrid against pure DEM (grains bench chute)", h * 1e3),
        x_label: "N_i, grains of the pure DEM".into(),
        y_label: "F, hybrid grains / N_i".into(),
        log_x: true,
        series: vec![
            Series::new("DEM faster", Kind::Crosses, at(false)),
            Series::new("hybrid faster", Kind::Points, at(true)),
        ],
        notes: runs
            .iter()
            .map(|(r, s)| (r.dem_grains as f64, r.fraction(), format!("{s:.1}x")))
            .collect(),
        ..Chart::default()
    }
}

fn dem_wall(rows: &[Row], radius: f64) -> f64 {
    rows.iter()
        .find(|r| r.cell == 0.0 && r.radius == radius)
        .map_or(f64::NAN, |r| r.sample.wall)
}

/// The pure DEM's flux for grains of `radius`: the mean over its pours.
fn dem_flux(rows: &[Row], radius: f64) -> f64 {
    rows.iter()
        .find(|r| r.cell == 0.0 && r.radius == radius)
        .map_or(f64::NAN, |r| mean_sd(&r.pours).0)
}

/// Mean and sample standard deviation (0 for one value).
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

fn seconds(walls: &[f64]) -> String {
    walls.iter().map(|w| format!("{w:.1}")).collect::<Vec<_>>().join(", ")
}

/// `first` with its wall and compute times the medians over `runs` (runs of one scene, `first`
/// among them): one run slowed by the machine (a pour of the 15-cm chute took 45 s where the
/// other three took 22–23) moves a mean by a quarter of its excess, a median of four not at all.
fn median_time(first: Sample, runs: &[Sample]) -> Sample {
    if runs.is_empty() {
        return first;
    }
    let median = |f: fn(&Sample) -> f64| grains_oracle::band::percentile(&runs.iter().map(f).collect::<Vec<_>>(), 0.5);
    Sample {
        wall: median(|s| s.wall),
        dem_step: median(|s| s.dem_step),
        mpm_step: median(|s| s.mpm_step),
        ..first
    }
}

fn table(args: &ChuteArgs, rows: &[Row], costs: Option<&Costs>) -> String {
    let mut md = format!(
        "# grains bench chute\n\nYue 2018 §5: the periodic chute ({LENGTH} m × {} m layer, 22°) of `scenes/{SCENE}`, {} s simulated \
         from a poured packing per grain size; both models at their stable steps, the pure DEM on two threads, the hybrid's \
         solvers on two each. F: the hybrid's grains over the pure DEM's at the start. Speed-up: the DEM's wall time over the \
         hybrid's (with several pours, the medians of their runs: each hybrid runs after every pour). Flux: Σ m v_x / L \
         at the end of the window; the hybrids run on the first pour and are compared with the mean of the pure DEM \
         over {} pour(s) (`run.seed` 1 to N; its row: mean ± standard deviation). Coupled band: {} cell(s). \
         Discrete base over the floor: {:.1} mm. Continuum: {}.\n\n\
         Surface: the mean down-slope velocity of the top {:.0}% of the mass; profile L1: Σ m |v − v_DEM| / Σ m |v_DEM| over \
         {} mm slabs above the floor (the pure DEM's over its pours), at the end of the window: a flux can agree while the \
         profile does not.\n\n\
         | run | r mm | H mm | N_i | F | MPM points | k | wall s | speed-up | DEM / MPM compute ms per macro-step | flux kg/(m s) | flux vs DEM | surface m/s | vs DEM | profile L1 |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        args.depth,
        args.window,
        args.pours,
        args.band,
        1e3 * args.base,
        match args.continuum {
            Continuum::Scene => "the scene's",
            Continuum::CriticalState =>
                "critical-state softening (Chen 2021) fitted to the shear cell's first shear per grain size, from the poured bed's packing",
        },
        100.0 * SURFACE,
        1e3 * SLAB,
    );
    for r in rows {
        let speedup = dem_wall(rows, r.radius) / r.sample.wall;
        let flux = match mean_sd(&r.pours) {
            (mean, sd) if r.pours.len() > 1 => format!("{mean:.3} ± {sd:.3}"),
            _ => format!("{:.3}", r.flux),
        };
        let dem_profile = rows
            .iter()
            .find(|d| d.cell == 0.0 && d.radius == r.radius)
            .map_or(&[][..], |d| d.profile.as_slice());
        let (surface_v, l1) = compare(&r.profile, dem_profile);
        md.push_str(&format!(
            "| {} | {} | {} | {} | {:.3} | {} | {} | {:.1} | {:.2}× | {:.2} / {:.2} | {} | {:+.1}% | {:.4} | {:+.1}% | {:.2} |\n",
            if r.cell == 0.0 {
                "DEM".into()
            } else {
                format!("hybrid, discrete {:.0}% of the depth", 100.0 * r.depth)
            },
            r.radius * 1e3,
            if r.cell == 0.0 { "-".into() } else { format!("{}", r.cell * 1e3) },
            r.dem_grains,
            r.fraction(),
            r.points,
            r.sample.substeps,
            r.sample.wall,
            speedup,
            1e3 * r.sample.dem_step,
            1e3 * r.sample.mpm_step,
            flux,
            100.0 * (r.flux / dem_flux(rows, r.radius) - 1.0),
            surface_v,
            100.0 * (surface_v / surface(dem_profile) - 1.0),
            l1
        ));
    }
    for r in rows.iter().filter(|r| r.pours.len() > 1) {
        let each: Vec<String> = r.pours.iter().map(|f| format!("{f:.3}")).collect();
        md.push_str(&format!(
            "\nThe pure DEM's flux at r = {} mm on its {} pours: {} kg/(m s); its wall time: {} s.\n",
            r.radius * 1e3,
            r.pours.len(),
            each.join(", "),
            seconds(&r.walls)
        ));
    }
    for r in rows.iter().filter(|r| r.cell > 0.0 && r.walls.len() > 1) {
        md.push_str(&format!(
            "The hybrid at r = {} mm, H = {} mm, discrete {:.0}%, run after each pour: {} s.\n",
            r.radius * 1e3,
            r.cell * 1e3,
            100.0 * r.depth,
            seconds(&r.walls)
        ));
    }
    if rows.iter().any(|r| r.walls.len() > 1) {
        md.push_str("Each row's wall time and compute times are the medians of its runs; the speed-ups divide those medians.\n");
    }
    if let Some(best) = rows
        .iter()
        .filter(|r| r.cell > 0.0)
        .max_by(|a, b| (dem_wall(rows, a.radius) / a.sample.wall).total_cmp(&(dem_wall(rows, b.radius) / b.sample.wall)))
    {
        md.push_str(&format!(
            "\nLargest speed-up measured: {:.2}× at r = {} mm (N_i = {}), H = {} mm, F = {:.3}.\n",
            dem_wall(rows, best.radius) / best.sample.wall,
            best.radius * 1e3,
            best.dem_grains,
            best.cell * 1e3,
            best.fraction()
        ));
    }
    if let Some(c) = costs {
        md.push_str(&format!(
            "\nCost model (`launch/src/cost.rs`, eqs. 21–23 in grains' terms) fitted to the runs of the finest grains: pure DEM {:.3e} s \
             per grain-step (2 threads), the hybrid's DEM {:.3e} s per grain-step and its MPM {:.3e} s per point-step (2 threads \
             each), {:.3e} s per macro-step beside them.\n\n| run | wall s | model s |\n|---|---:|---:|\n",
            c.dem_alone, c.dem_hybrid, c.mpm, c.step
        ));
        for r in rows {
            let n = crate::cost::Counts {
                hybrid_grains: r.sample.grains as usize,
                points: r.sample.points as usize,
                all_grains: r.dem_grains as usize,
                substeps: r.sample.substeps,
                steps: r.sample.steps,
            };
            let (h, d) = crate::cost::predict(c, &n);
            md.push_str(&format!(
                "| {} r={} mm H={} mm F={:.3} | {:.1} | {:.1} |\n",
                if r.cell == 0.0 { "DEM" } else { "hybrid" },
                r.radius * 1e3,
                r.cell * 1e3,
                r.fraction(),
                r.sample.wall,
                if r.cell == 0.0 { d } else { h }
            ));
        }
        md.push_str(&extrapolate(c, rows, args.depth));
    }
    md
}

/// The fitted model at sizes beyond the sweep: the same grains, cells and discrete depth in
/// a layer s times deeper (Yue 2018's A: the pure DEM's grains grow as s, the hybrid's grains
/// stay, its points grow with the continuum's depth), from the runs of the finest grains.
fn extrapolate(c: &Costs, rows: &[Row], depth: f64) -> String {
    let Some(reference) = rows.iter().filter(|r| r.cell > 0.0).min_by(|a, b| a.radius.total_cmp(&b.radius)) else {
        return String::new();
    };
    let r0 = reference.radius;
    let scales = [1.0, 2.0, 5.0, 10.0, 20.0];
    let mut md = format!(
        "\nThe model beyond this machine's runs: predicted speed-up of the same chute (r = {} mm) in a layer s times deeper \
         ({} m × s; the pure DEM's grains × s, the hybrid's grains the same, its points × (s − F) / (1 − F), k the same)\n\n\
         | H mm | F at s = 1 | {} |\n|---:|---:|{}\n",
        r0 * 1e3,
        depth,
        scales.map(|s| format!("s = {s}")).join(" | "),
        "---:|".repeat(scales.len())
    );
    for r in rows.iter().filter(|r| r.cell > 0.0 && r.radius == r0) {
        let f = r.fraction();
        let cells: Vec<String> = scales
            .iter()
            .map(|&s| {
                let n = crate::cost::Counts {
                    hybrid_grains: r.sample.grains as usize,
                    points: (r.sample.points * (s - f) / (1.0 - f)) as usize,
                    all_grains: (r.dem_grains as f64 * s) as usize,
                    substeps: r.sample.substeps,
                    steps: 1,
                };
                let (h, d) = crate::cost::predict(c, &n);
                format!("{:.1}×", d / h)
            })
            .collect();
        md.push_str(&format!("| {} | {:.3} | {} |\n", r.cell * 1e3, f, cells.join(" | ")));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(cell: f64, flux: f64, pours: Vec<f64>, walls: Vec<f64>) -> Row {
        let sample = Sample {
            grains: 100.0,
            points: 0.0,
            substeps: 20,
            steps: 10,
            wall: 1.0,
            dem_step: 1e-3,
            mpm_step: 0.0,
        };
        Row {
            radius: 5e-4,
            cell,
            depth: 1.0,
            grains: 100,
            dem_grains: 100,
            points: 0,
            sample,
            flux,
            pours,
            walls,
            profile: vec![(1.0, 0.0), (1.0, 0.1), (1.0, 0.2)],
        }
    }

    /// The hybrid is compared with the mean of the DEM's pours, not its first pour, and the
    /// table shows the pours' spread (the sample standard deviation).
    #[test]
    fn the_hybrid_is_compared_with_the_mean_of_the_pours() {
        let rows = [
            row(0.0, 36.0, vec![36.0, 30.0, 33.0], vec![1.0, 1.2, 0.8]),
            row(0.004, 36.3, Vec::new(), vec![0.1, 0.12, 0.08]),
        ];
        assert_eq!(dem_flux(&rows, 5e-4), 33.0);
        assert_eq!(mean_sd(&[36.0, 30.0, 33.0]), (33.0, 3.0));
        assert_eq!(mean_sd(&[36.0]), (36.0, 0.0));
        let args = ChuteArgs {
            scenes: "scenes".into(),
            radii: vec![0.5],
            depth: 0.05,
            depths: vec![0.05],
            cells: vec![0.004],
            band: 1.0,
            base: 0.0,
            window: 0.1,
            out: "out".into(),
            continuum: Continuum::Scene,
            cell_grains: 2400,
            pours: 3,
        };
        let md = table(&args, &rows, None);
        assert!(md.contains("| 33.000 ± 3.000 | +9.1% | 0.2000 | +0.0% | 0.00 |"), "{md}");
        assert!(md.contains("| 36.300 | +10.0% | 0.2000 | +0.0% | 0.00 |"), "{md}");
        assert!(
            md.contains("on its 3 pours: 36.000, 30.000, 33.000 kg/(m s); its wall time: 1.0, 1.2, 0.8 s"),
            "{md}"
        );
        assert!(md.contains("H = 4 mm, discrete 100%, run after each pour: 0.1, 0.1, 0.1 s"), "{md}");
    }

    /// A row's times are the medians of its runs, its counts the first run's.
    #[test]
    fn a_row_takes_the_median_times_of_its_runs() {
        let run = |wall: f64, dem: f64, mpm: f64| Sample {
            grains: 100.0,
            points: 50.0,
            substeps: 20,
            steps: 10,
            wall,
            dem_step: dem,
            mpm_step: mpm,
        };
        // One slow run of four: the median is the middle pair's mean, the outlier ignored.
        let runs = [
            run(22.7, 1e-3, 4e-3),
            run(45.1, 9e-3, 6e-3),
            run(22.2, 2e-3, 3e-3),
            run(23.2, 3e-3, 5e-3),
        ];
        let m = median_time(runs[0], &runs);
        for (got, want) in [(m.wall, 22.95), (m.dem_step, 2.5e-3), (m.mpm_step, 4.5e-3)] {
            assert!((got - want).abs() < 1e-12 * want, "{got} against {want}");
        }
        assert_eq!(median_time(runs[0], &runs[..3]).wall, 22.7);
        assert_eq!((m.grains, m.points, m.substeps, m.steps), (100.0, 50.0, 20, 10));
        assert_eq!(median_time(runs[1], &[]), runs[1]);
    }

    /// A plug riding on a slip at the floor carries a shear profile's flux with another
    /// shape: the same momentum, a slower surface and an L1 distance the flux cannot show.
    #[test]
    fn a_plug_with_the_shear_profiles_flux_is_told_apart() {
        // Unit masses in five slabs: shear 0, 0.1, 0.2, 0.3, 0.4 m/s; plug 0 then 0.25.
        let shear: Vec<(f64, f64)> = (0..5).map(|k| (1.0, 0.1 * k as f64)).collect();
        let plug: Vec<(f64, f64)> = (0..5).map(|k| (1.0, if k == 0 { 0.0 } else { 0.25 })).collect();
        let sum = |p: &[(f64, f64)]| p.iter().map(|s| s.1).sum::<f64>();
        assert!((sum(&shear) - sum(&plug)).abs() < 1e-12);
        // The top fifth of the mass is the top slab.
        assert!((surface(&shear) - 0.4).abs() < 1e-12 && (surface(&plug) - 0.25).abs() < 1e-12);
        let (v, l1) = compare(&plug, &shear);
        assert!((v - 0.25).abs() < 1e-12);
        // |0| + 0.15 + 0.05 + 0.05 + 0.15 over 0 + 0.1 + 0.2 + 0.3 + 0.4.
        assert!((l1 - 0.4).abs() < 1e-12, "{l1}");
        assert_eq!(compare(&shear, &shear).1, 0.0);
    }
}
