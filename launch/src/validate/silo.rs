//! `grains validate`, silo part: `scenes/silo_hybrid_2d.toml` run as DEM, hybrid (adaptive
//! zones) and MPM from one settled packing (Yue 2018 §5, issue 6):
//!
//! - the **discharge rate** W [kg/(m s)]: the mass more than [`OUT`] below the silo's bottom in
//!   every frame (grains and points, each with the mass it carries), its least-squares slope over
//!   [`WINDOW`] (after the start-up, before the silo runs low); check: the hybrid's within 15%
//!   of the DEM's at the scene's orifice (6 d), the others reported;
//! - **Beverloo's law** in 2D, W = C ρ_b √g (w − k d)^{3/2} (Beverloo 1961; the 3/2 of a slot,
//!   e.g. Mankoc et al. 2007) over w = 6, 8, 10, 12 mm: W^{2/3} is linear in w, so a
//!   straight-line fit of W^{2/3} over the flowing orifices gives k and C for each model;
//!   reported with the fit's largest residual. The MPM-only runs use 1-mm cells
//!   ([`MPM_CELL`]): on the scene's 2-mm grid orifices of 5, 6 and 8 mm opened the same three
//!   nodes and discharged at the same rate (measured);
//! - **clogging** at an orifice of 3 grain diameters (`scenes/silo_small_orifice_2d.toml`, 1-mm
//!   cells as in Yue 2018 Fig. 12): a run is clogged when its rate over the last
//!   [`CLOG_TAIL`] is under 5% of its model's rate at the 6-d orifice; check: DEM and hybrid
//!   clog, MPM does not (Yue 2018 §5: a continuum cannot arch);
//! - **bouncing**: restitution 0.5 (the scene's) and 0, DEM and hybrid at the 6-d orifice: the
//!   share of the grains in the bin that are in flight above the pile (no contact, outside the
//!   jet under the orifice), averaged over the frames of the window (reported).
//!
//! `--quick` runs the DEM and the hybrid at the 6-d orifice only (the discharge check).

use super::args::ValidateArgs;
use super::deposit::frames_of;
use super::packings;
use super::runs::{SCENE_USE_HEADER, load_with, run_scene, scene_use};
use super::scenes::silo::{BOTTOM, CENTRE, D, FILL, LATTICE, SCENE, SMALL_SCENE};
use super::stats::slope;
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use crate::run::Status;
use anyhow::{Context, bail};
use grains_protocol::Role;
use grains_service::vtu::Frame;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Window of the discharge-rate fit [s].
const WINDOW: (f64, f64) = (0.1, 0.45);
const CLOG_TAIL: f64 = 0.2;
/// How far below the bottom material counts as discharged [m]: two diameters. Points resting
/// on the bottom sink into its node-based wall, up to 1.5 mm in 0.5 s (the hybrid at 6 mm:
/// 22 points at 0.1 s, 40 at 0.45 s, which counted as discharged added 5% to its rate);
/// grains on the bottom stay above it.
const OUT: f64 = 2.0 * D;
const RATE_TOLERANCE: f64 = 0.15;
/// Orifice widths of the Beverloo fit [m]: whole cells of the MPM-only runs' grid, whose
/// node-based walls open (w / h − 1) nodes, as wide as w (the DEM clogs at 4 mm, measured);
/// and the small scene's.
const ORIFICES: [f64; 4] = [0.006, 0.008, 0.010, 0.012];
pub const REFERENCE: f64 = 0.006;
const CLOG_ORIFICE: f64 = 0.003;
/// Cell and step of the MPM-only runs [m, s] (CFL 0.4 at h / c = 2.5e-5 s).
pub const MPM_CELL: f64 = 0.001;
pub const MPM_DT: f64 = 1e-5;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Model {
    Dem,
    Hybrid,
    Mpm,
}

impl Model {
    fn name(self) -> &'static str {
        match self {
            Model::Dem => "DEM",
            Model::Hybrid => "hybrid",
            Model::Mpm => "MPM",
        }
    }
}

pub struct SiloRun {
    model: Model,
    orifice: f64,
    restitution: Option<f64>,
    /// (time, mass below the bottom) per frame.
    discharged: Vec<(f64, f64)>,
    pub rate: f64,
    tail_rate: f64,
    /// Share of the bin's grains in flight, averaged over the window's frames.
    flying: f64,
    /// Mean DEM grains over the run.
    pub grains: f64,
    pub wall: f64,
    pub dir: PathBuf,
}

/// Beverloo's 2D law fitted to (orifice w, rate W): W^{2/3} = a (w − k d), so a straight line
/// through (w, W^{2/3}) gives k = −intercept / (a d) and C = a^{3/2} / (ρ_b √g). Returns
/// (C, k, largest |W_fit / W − 1|).
pub fn beverloo(points: &[(f64, f64)], bulk_density: f64, g: f64) -> (f64, f64, f64) {
    let line: Vec<(f64, f64)> = points.iter().map(|&(w, q)| (w, q.powf(2.0 / 3.0))).collect();
    let a = slope(&line);
    let n = line.len() as f64;
    let intercept = line.iter().map(|p| p.1).sum::<f64>() / n - a * line.iter().map(|p| p.0).sum::<f64>() / n;
    let k = -intercept / (a * D);
    let c = a.powf(1.5) / (bulk_density * g.sqrt());
    let worst = points
        .iter()
        .map(|&(w, q)| ((c * bulk_density * g.sqrt() * (w - k * D).max(0.0).powf(1.5)) / q - 1.0).abs())
        .fold(0.0, f64::max);
    (c, k, worst)
}

/// The share of `grains` (centre, radius) in the bin that fly: no other grain within their
/// radii + 0.1 d, outside the jet (|x − centre| > the orifice's width) and below the bottom.
pub fn flying_share(grains: &[([f64; 3], f64)], orifice: f64) -> (usize, usize) {
    let bin: Vec<&([f64; 3], f64)> = grains.iter().filter(|g| g.0[1] < BOTTOM).collect();
    let mut flying = 0;
    for (i, a) in bin.iter().enumerate() {
        if (a.0[0] - CENTRE).abs() <= orifice {
            continue;
        }
        let touching = bin
            .iter()
            .enumerate()
            .any(|(j, b)| j != i && ((a.0[0] - b.0[0]).powi(2) + (a.0[1] - b.0[1]).powi(2)).sqrt() < a.1 + b.1 + 0.1 * D);
        // Resting on the bin's floor or walls is not flying either.
        let on_wall = a.0[1] < a.1 + 0.1 * D || a.0[0] < a.1 + 0.1 * D || a.0[0] > 2.0 * CENTRE - a.1 - 0.1 * D;
        if !touching && !on_wall {
            flying += 1;
        }
    }
    (flying, bin.len())
}

/// The overrides that raise the silo's box and domain to hold the lattice poured for a fill
/// of `fill` [m] over its bottom, keeping the scene's room over it, so that the pour and the
/// runs share one grid (none at the scene's own fill: its runs stay the same).
pub fn room(fill: f64) -> Vec<String> {
    if fill == FILL {
        return Vec::new();
    }
    let lattice = BOTTOM + LATTICE * fill;
    vec![
        format!("domain.max=[0.046,{}]", lattice + 0.016),
        format!("wall.2.max=[0.04,{}]", lattice + 0.01),
    ]
}

/// [`room`] for a fill of `fill`, and the silo's body filled to it (what a run takes).
pub fn raised(fill: f64) -> Vec<String> {
    let mut overrides = room(fill);
    if fill != FILL {
        overrides.push(format!("body.0.max=[0.04,{}]", BOTTOM + fill));
    }
    overrides
}

/// One run of `scene` with `model`; at `orifice` if given (else the scene's, `CLOG_ORIFICE`).
pub fn run_silo(
    args: &ValidateArgs,
    scene: &str,
    packing: &Path,
    model: Model,
    orifice: Option<f64>,
    restitution: Option<f64>,
    extra: &[String],
) -> anyhow::Result<SiloRun> {
    let path = args.scenes.join(scene);
    let mut overrides = Vec::new();
    if let Some(w) = orifice {
        overrides.push(format!("wall.0.to=[{},{BOTTOM}]", CENTRE - w / 2.0));
        overrides.push(format!("wall.1.from=[{},{BOTTOM}]", CENTRE + w / 2.0));
    }
    let orifice = orifice.unwrap_or(CLOG_ORIFICE);
    overrides.extend(raised(args.silo_fill));
    match model {
        Model::Dem => overrides.push("body.0.model=\"dem\"".into()),
        Model::Mpm if scene == SCENE => overrides.extend([
            "body.0.model=\"mpm\"".into(),
            format!("domain.cell_size={MPM_CELL}"),
            format!("run.dt={MPM_DT}"),
            "output.frames_every=1000".into(),
        ]),
        Model::Mpm => overrides.push("body.0.model=\"mpm\"".into()),
        Model::Hybrid => {}
    }
    if model != Model::Mpm {
        overrides.push(format!("body.0.packing={:?}", packing.display().to_string()));
    }
    if let Some(e) = restitution {
        overrides.push(format!("material.0.dem.restitution={e}"));
    }
    overrides.extend(extra.iter().cloned());
    let loaded = load_with(&path, &overrides)?;
    let duration = loaded.steps as f64 * loaded.dt;
    let outcome = run_scene(args, &path, overrides)?;
    if outcome.status != Status::Completed {
        bail!(
            "{scene} ({}, orifice {} mm): the run did not complete: {}",
            model.name(),
            orifice * 1e3,
            outcome.message
        );
    }
    let table = MetricsTable::read(&outcome.dir)?;
    let grains = match table.participant(Role::Dem, "items")? {
        Some(v) => v.iter().sum::<f64>() / v.len().max(1) as f64,
        None => 0.0,
    };
    let (discharged, flying) = discharge(&outcome.dir, orifice)?;
    let window: Vec<(f64, f64)> = discharged
        .iter()
        .copied()
        .filter(|p| (WINDOW.0..=WINDOW.1).contains(&p.0))
        .collect();
    let tail: Vec<(f64, f64)> = discharged.iter().copied().filter(|p| p.0 >= duration - CLOG_TAIL - 1e-9).collect();
    Ok(SiloRun {
        model,
        orifice,
        restitution,
        rate: slope(&window),
        tail_rate: slope(&tail),
        flying,
        discharged,
        grains,
        wall: table.last("wall_s")?,
        dir: outcome.dir,
    })
}

/// The mass of `points` (grains or material points) with `mass` that has left the silo: more
/// than [`OUT`] below its bottom.
fn mass_out(points: &[[f64; 3]], mass: &[f64]) -> f64 {
    points.iter().zip(mass).filter(|(x, _)| x[1] < BOTTOM - OUT).map(|(_, m)| m).sum()
}

/// The mass out of the silo ([`mass_out`]) in every frame of a run, and the share of the
/// bin's grains in flight over the fit window's frames.
pub fn discharge(dir: &Path, orifice: f64) -> anyhow::Result<(Vec<(f64, f64)>, f64)> {
    let mut discharged = Vec::new();
    let (mut flown, mut counted) = (0usize, 0usize);
    let grain_frames = frames_of(dir, "grains")?;
    let point_frames = frames_of(dir, "points")?;
    let times: Vec<f64> = if grain_frames.is_empty() {
        point_frames.iter().map(|f| f.0).collect()
    } else {
        grain_frames.iter().map(|f| f.0).collect()
    };
    for (k, &t) in times.iter().enumerate() {
        let mut below = 0.0;
        for frames in [&grain_frames, &point_frames] {
            let Some((_, file)) = frames.get(k) else { continue };
            let a = Frame::read(file)?;
            let mass = a.array("mass").with_context(|| format!("{}: no mass array", file.display()))?;
            below += mass_out(&a.points, mass);
            if let Some(r) = a.array("radius")
                && (WINDOW.0..=WINDOW.1).contains(&t)
            {
                let grains: Vec<([f64; 3], f64)> = a.points.iter().copied().zip(r.iter().copied()).collect();
                let (f, n) = flying_share(&grains, orifice);
                flown += f;
                counted += n;
            }
        }
        discharged.push((t, below));
    }
    Ok((discharged, if counted > 0 { flown as f64 / counted as f64 } else { 0.0 }))
}

/// The runs of the silo part: every model at every orifice, then (full runs) the clogging
/// orifice and the restitution-0 runs.
struct Runs {
    orifices: Vec<f64>,
    models: Vec<Model>,
    /// Every model at every orifice.
    runs: Vec<SiloRun>,
    /// The clogging orifice and the bouncing runs with restitution 0.
    extra: Vec<SiloRun>,
}

impl Runs {
    fn rate(&self, m: Model, w: f64) -> Option<f64> {
        self.runs.iter().find(|r| r.model == m && r.orifice == w).map(|r| r.rate)
    }
}

fn run_all(args: &ValidateArgs, packing: &Path) -> anyhow::Result<Runs> {
    let (orifices, models): (Vec<f64>, Vec<Model>) = if args.quick {
        (vec![REFERENCE], vec![Model::Dem, Model::Hybrid])
    } else {
        (ORIFICES.to_vec(), vec![Model::Dem, Model::Hybrid, Model::Mpm])
    };
    let mut runs = Vec::new();
    for &w in &orifices {
        for &m in &models {
            tracing::info!("validate: silo, orifice {:.0} mm: {}", w * 1e3, m.name());
            let r = run_silo(args, SCENE, packing, m, Some(w), None, &[])?;
            tracing::info!("validate: silo {} w = {:.0} mm: rate {:.3} kg/(m s)", m.name(), w * 1e3, r.rate);
            runs.push(r);
        }
    }
    let mut extra = Vec::new();
    if !args.quick {
        for &m in &models {
            tracing::info!("validate: silo, orifice {:.0} mm (clogging): {}", CLOG_ORIFICE * 1e3, m.name());
            extra.push(run_silo(args, SMALL_SCENE, packing, m, None, None, &[])?);
        }
        for m in [Model::Dem, Model::Hybrid] {
            tracing::info!("validate: silo, restitution 0: {}", m.name());
            extra.push(run_silo(args, SCENE, packing, m, Some(REFERENCE), Some(0.0), &[])?);
        }
    }
    Ok(Runs {
        orifices,
        models,
        runs,
        extra,
    })
}

/// Runs the silo part and writes `silo.csv` in `--out`.
pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let packing = packings::silo(args)?;
    let scene = load_with(&args.scenes.join(SCENE), &[])?;
    let all = run_all(args, &packing)?;
    let mut md = String::new();
    rates_section(&mut md, &mut part, &scene, &all, args.silo_fill)?;
    if all.orifices.len() >= 4 {
        beverloo_section(&mut md, &mut part, args, &scene, &all)?;
    }
    clogging_section(&mut md, &mut part, &all)?;
    bouncing_section(&mut md, &scene, &all)?;
    discharge_outputs(&mut md, &mut part, args, &all)?;
    let runs: Vec<(&str, &Path)> = all
        .runs
        .iter()
        .filter(|r| r.orifice == REFERENCE)
        .map(|r| (r.model.name(), r.dir.as_path()))
        .collect();
    super::pictures::side_by_side(
        &mut part,
        &args.out,
        "silo_pictures",
        &format!("Silo, orifice {:.0} mm: each model at the same moments", REFERENCE * 1e3),
        &runs,
        &[0.0, 0.25, 0.5],
        None,
    )?;
    part.md = md;
    Ok(part)
}

/// The discharge rates against the DEM's, and the check at the reference orifice.
fn rates_section(md: &mut String, part: &mut Part, scene: &grains_protocol::scene::Scene, all: &Runs, fill: f64) -> anyhow::Result<()> {
    let runs = &all.runs;
    let rate = |m: Model, w: f64| all.rate(m, w);
    writeln!(md, "## Silo discharge: DEM, hybrid (adaptive zones), MPM\n")?;
    writeln!(
        md,
        "Scene `{SCENE}` (a 40 mm silo filled to {:.0} mm from one poured packing; the hybrid's zones move every {} steps). \
         Discharge rate W = slope of the mass below the bottom over t in [{}, {}] s. Reference: the pure DEM run \
         of the same packing (issue 6: hybrid within {:.0}%).\n",
        fill * 1e3,
        scene.oracle.as_ref().map_or(0, |o| o.every),
        WINDOW.0,
        WINDOW.1,
        RATE_TOLERANCE * 100.0
    )?;
    writeln!(
        md,
        "| orifice | model | W [kg/(m s)] | vs DEM | mean DEM grains | wall [s] | speedup vs DEM | check |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|")?;
    for r in runs {
        let dem = rate(Model::Dem, r.orifice).unwrap_or(f64::NAN);
        let dem_wall = runs
            .iter()
            .find(|x| x.model == Model::Dem && x.orifice == r.orifice)
            .map_or(f64::NAN, |x| x.wall);
        let err = r.rate / dem - 1.0;
        let check = match r.model {
            Model::Hybrid if r.orifice == REFERENCE => {
                let ok = err.abs() <= RATE_TOLERANCE;
                part.check(
                    format!("silo {:.0} mm: hybrid discharge rate", r.orifice * 1e3),
                    format!("pure DEM silo, same packing ({dem:.3} kg/(m s); Yue 2018 §5, issue 6)"),
                    format!("{:.3} kg/(m s) ({:+.1}%)", r.rate, 100.0 * err),
                    format!("±{:.0}%", 100.0 * RATE_TOLERANCE),
                    ok,
                );
                if ok { "pass" } else { "**FAIL**" }
            }
            _ => "",
        };
        let versus = if r.model == Model::Dem || dem <= 0.0 {
            String::from("–")
        } else {
            format!("{:+.1}%", 100.0 * err)
        };
        writeln!(
            md,
            "| {:.0} mm | {} | {:.3} | {versus} | {:.0} | {:.1} | {:.2}x | {check} |",
            r.orifice * 1e3,
            r.model.name(),
            r.rate,
            r.grains,
            r.wall,
            dem_wall / r.wall
        )?;
    }
    Ok(())
}

/// Beverloo fits over the flowing orifices, per model, with their chart.
fn beverloo_section(
    md: &mut String,
    part: &mut Part,
    args: &ValidateArgs,
    scene: &grains_protocol::scene::Scene,
    all: &Runs,
) -> anyhow::Result<()> {
    let material = &scene.materials[0];
    let bulk = material.density * material.mpm.as_ref().map_or(1.0, |m| m.packing);
    let g = scene.gravity[1].abs();
    let (orifices, models) = (&all.orifices, &all.models);
    let rate = |m: Model, w: f64| all.rate(m, w);
    writeln!(
        md,
        "\n### Beverloo fits (2D: W = C ρ_b √g (w − k d)^{{3/2}}, ρ_b = {bulk:.0} kg/m³, d = 1 mm)\n"
    )?;
    writeln!(md, "| model | C | k | largest misfit of the fit |")?;
    writeln!(md, "|---|---|---|---|")?;
    let mut chart = Chart {
        title: "Silo: Beverloo plot".into(),
        x_label: "orifice w [mm]".into(),
        y_label: "W^(2/3) [(kg/(m s))^(2/3)]".into(),
        ..Chart::default()
    };
    for &m in models {
        // Clogged orifices are outside Beverloo's law.
        let pts: Vec<(f64, f64)> = orifices
            .iter()
            .filter_map(|&w| rate(m, w).map(|q| (w, q)))
            .filter(|p| p.1 > 0.0)
            .collect();
        if pts.len() < 3 {
            writeln!(md, "| {} | – | – | {} flowing orifices: no fit |", m.name(), pts.len())?;
            continue;
        }
        let (c, k, worst) = beverloo(&pts, bulk, g);
        // 2D Beverloo: W^(2/3) = (C ρ_b √g)^(2/3) (w − k d), a line in w.
        let slope = (c * bulk * g.sqrt()).powf(2.0 / 3.0);
        chart.series.push(Series::new(
            m.name(),
            Kind::Points,
            pts.iter().map(|p| (p.0 * 1e3, p.1.powf(2.0 / 3.0))).collect(),
        ));
        let ends = [k * D, ORIFICES[ORIFICES.len() - 1]];
        chart.series.push(Series::new(
            format!("{} fit C = {c:.2}, k = {k:.2}", m.name()),
            Kind::Dashed,
            ends.iter().map(|&w| (w * 1e3, slope * (w - k * D))).collect(),
        ));
        writeln!(
            md,
            "| {} | {c:.3} | {k:.2} | {:.1}% ({} orifices) |",
            m.name(),
            100.0 * worst,
            pts.len()
        )?;
    }
    part.chart(
        &args.out,
        "silo_beverloo",
        "Silo discharge rates in Beverloo's coordinates, with the fits",
        &chart,
    )?;
    Ok(())
}

/// Clogging at a 3-d orifice: grains clog, a continuum flows (checked).
fn clogging_section(md: &mut String, part: &mut Part, all: &Runs) -> anyhow::Result<()> {
    let rate = |m: Model, w: f64| all.rate(m, w);
    let clogs: Vec<&SiloRun> = all.extra.iter().filter(|r| r.orifice == CLOG_ORIFICE).collect();
    if !clogs.is_empty() {
        writeln!(
            md,
            "\n### Clogging at w = {:.0} mm (3 d)\n\n`{SMALL_SCENE}` (1-mm cells). Clogged: the rate over the last \
             {CLOG_TAIL} s is under 5% of the model's rate at w = {:.0} mm. Expected (Yue 2018 §5, Fig. 12): DEM and \
             hybrid clog, MPM does not.\n",
            CLOG_ORIFICE * 1e3,
            REFERENCE * 1e3,
        )?;
        writeln!(md, "| model | mass out [kg/m] | rate, last {CLOG_TAIL} s | clogged | check |")?;
        writeln!(md, "|---|---|---|---|---|")?;
        for r in clogs {
            let reference = rate(r.model, REFERENCE).unwrap_or(f64::NAN);
            let clogged = r.tail_rate < 0.05 * reference;
            let ok = clogged == (r.model != Model::Mpm);
            part.check(
                format!(
                    "silo {:.0} mm (3 d): {} {}",
                    CLOG_ORIFICE * 1e3,
                    r.model.name(),
                    if r.model == Model::Mpm { "flows" } else { "clogs" }
                ),
                "Yue 2018 §5 Fig. 12: grains clog a 3-d orifice, a continuum flows",
                format!(
                    "last {CLOG_TAIL} s: {:.4} kg/(m s), {:.1}% of its 6-mm rate",
                    r.tail_rate,
                    100.0 * r.tail_rate / reference
                ),
                if r.model == Model::Mpm {
                    "≥ 5% (flowing)"
                } else {
                    "< 5% (clogged)"
                },
                ok,
            );
            writeln!(
                md,
                "| {} | {:.4} | {:.4} | {} | {} |",
                r.model.name(),
                r.discharged.last().map_or(0.0, |p| p.1),
                r.tail_rate,
                if clogged { "yes" } else { "no" },
                if ok { "pass" } else { "**FAIL**" }
            )?;
        }
    }
    Ok(())
}

/// The share of grains in flight in the bin, with the scene's restitution and with 0.
fn bouncing_section(md: &mut String, scene: &grains_protocol::scene::Scene, all: &Runs) -> anyhow::Result<()> {
    let material = &scene.materials[0];
    writeln!(md, "\n### Bouncing grains (w = {:.0} mm)\n", REFERENCE * 1e3)?;
    writeln!(
        md,
        "Share of the bin's grains in flight (no contact, outside the jet, off the walls), averaged over the window's frames (reported).\n"
    )?;
    writeln!(md, "| model | restitution | flying share |")?;
    writeln!(md, "|---|---|---|")?;
    let e0 = match material.dem.as_ref().map(|d| d.damping) {
        Some(grains_protocol::scene::DemDamping::Restitution(e)) => e.to_string(),
        Some(grains_protocol::scene::DemDamping::Viscous(g)) => format!("γ = {g} N s/m"),
        None => String::from("?"),
    };
    for r in all
        .runs
        .iter()
        .chain(&all.extra)
        .filter(|r| r.orifice == REFERENCE && r.model != Model::Mpm)
    {
        let e = r.restitution.map_or(e0.clone(), |e| e.to_string());
        writeln!(md, "| {} | {e} | {:.2}% |", r.model.name(), 100.0 * r.flying)?;
    }
    Ok(())
}

/// The discharge chart, the table of what each run simulates and `silo.csv`.
fn discharge_outputs(md: &mut String, part: &mut Part, args: &ValidateArgs, all: &Runs) -> anyhow::Result<()> {
    let runs = &all.runs;
    let mut chart = Chart {
        title: format!("Silo, {:.0} mm orifice: mass discharged", REFERENCE * 1e3),
        x_label: "time [s]".into(),
        y_label: "mass below the bottom [kg/m]".into(),
        ..Chart::default()
    };
    for r in runs.iter().filter(|r| r.orifice == REFERENCE) {
        chart.series.push(Series::new(r.model.name(), Kind::Line, r.discharged.clone()));
    }
    part.chart(&args.out, "silo_discharge", "Mass discharged through the reference orifice", &chart)?;
    let dem = runs.iter().find(|r| r.orifice == REFERENCE && r.model == Model::Dem);
    let hybrid = runs.iter().find(|r| r.orifice == REFERENCE && r.model == Model::Hybrid);
    if let (Some(d), Some(h)) = (dem, hybrid) {
        let row = scene_use(args, part, "silo_use", SCENE, &h.dir, &d.dir)?;
        writeln!(
            md,
            "\n### What each run simulates ({:.0} mm)\n\n{}\n{row}",
            REFERENCE * 1e3,
            SCENE_USE_HEADER
        )?;
    }
    let mut csv = String::from("model,orifice_m,restitution,time_s,discharged_kg_per_m\n");
    for r in runs.iter().chain(&all.extra) {
        for (t, m) in &r.discharged {
            writeln!(
                csv,
                "{},{},{},{t},{m}",
                r.model.name(),
                r.orifice,
                r.restitution.map_or(String::new(), |e| e.to_string())
            )?;
        }
    }
    std::fs::write(args.out.join("silo.csv"), csv)?;
    writeln!(md, "\nAll discharge curves: `silo.csv`.")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raised_silo_holds_its_fill_in_both_scenes_and_the_scene_s_own_fill_is_left_alone() {
        use grains_protocol::scene::WallShape;
        assert!(raised(FILL).is_empty());
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        // The formula at the scene's fill gives the scene's box and domain: a raised silo
        // keeps the scene's room over its lattice.
        let box_top = |scene: &grains_protocol::scene::Scene| match scene.walls[2].shape {
            WallShape::Box { max, .. } => max[1],
            ref other => panic!("wall 2 is not the silo's box: {other:?}"),
        };
        for name in [SCENE, SMALL_SCENE] {
            let own = load_with(&dir.join(name), &[]).unwrap();
            let lattice = BOTTOM + LATTICE * FILL;
            assert!(
                (own.domain.max[1] - (lattice + 0.016)).abs() < 1e-12,
                "{name}: domain top {}",
                own.domain.max[1]
            );
            assert!(
                (box_top(&own) - (lattice + 0.01)).abs() < 1e-12,
                "{name}: box top {}",
                box_top(&own)
            );
            let fill = 0.25;
            let tall = load_with(&dir.join(name), &raised(fill)).unwrap();
            let lattice = BOTTOM + LATTICE * fill;
            assert!((tall.domain.max[1] - (lattice + 0.016)).abs() < 1e-12);
            assert!((box_top(&tall) - (lattice + 0.01)).abs() < 1e-12);
            match tall.bodies[0].shape {
                grains_protocol::scene::Shape::Box { max, .. } => assert!((max[1] - (BOTTOM + fill)).abs() < 1e-12),
                ref other => panic!("{name}: body 0 is not a box: {other:?}"),
            }
            // Nothing else moves: the orifice and the bin are the scene's.
            assert_eq!(tall.walls[..2], own.walls[..2]);
        }
    }

    #[test]
    fn a_beverloo_law_is_recovered_from_its_own_rates() {
        // Rates made from C = 0.9, k = 1.5 come back; a rate 20% off shows in the misfit.
        let (rho, g) = (2000.0_f64, 9.81_f64);
        let law = |w: f64| 0.9 * rho * g.sqrt() * (w - 1.5 * D).powf(1.5);
        let pts: Vec<(f64, f64)> = ORIFICES.iter().map(|&w| (w, law(w))).collect();
        let (c, k, worst) = beverloo(&pts, rho, g);
        assert!((c - 0.9).abs() < 1e-9 && (k - 1.5).abs() < 1e-9 && worst < 1e-9, "{c} {k} {worst}");
        let mut off = pts.clone();
        off[3].1 *= 1.2;
        assert!(beverloo(&off, rho, g).2 > 0.05);
    }

    #[test]
    fn only_free_grains_in_the_bin_fly() {
        let r = 0.0005;
        let grains = vec![
            ([0.005, 0.01, 0.0], r),   // alone in the bin: flying
            ([0.030, 0.0005, 0.0], r), // on the bin's floor
            ([0.010, 0.0052, 0.0], r), // two touching
            ([0.0109, 0.0052, 0.0], r),
            ([CENTRE, 0.02, 0.0], r),         // in the jet
            ([0.005, BOTTOM + 0.02, 0.0], r), // in the silo
        ];
        assert_eq!(flying_share(&grains, 0.006), (1, 5));
    }

    /// What has left the silo: a point sunk 1.5 mm into the bottom (as the hybrid's do over a
    /// run) has not, a grain 2.5 mm under it in the jet has, and so has the pile in the bin.
    #[test]
    fn material_sunk_into_the_bottom_has_not_left_the_silo() {
        let points = [
            [0.005, BOTTOM - 0.0015, 0.0],  // sunk into the bottom's wall
            [CENTRE, BOTTOM - 0.0025, 0.0], // in the jet
            [0.030, 0.0005, 0.0],           // on the bin's floor
            [0.010, BOTTOM + 0.0004, 0.0],  // on the bottom
        ];
        let mass = [1.0, 2.0, 4.0, 8.0];
        assert_eq!(mass_out(&points, &mass), 6.0);
    }
}
