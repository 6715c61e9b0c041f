//! `grains validate --part column`: both models start from the same random packing,
//! `scenes/column_packing_2d.toml` poured and settled by `grains pack` (once per seed
//! 1..=`--packings`, kept in `--out`) to a little above the tallest column. Each case runs
//! `column_collapse_2d.toml` and `column_collapse_hybrid_2d.toml` with the column's top moved
//! to a·L₀ (L₀ = 40 mm), its grains cut from the packing, for 6 √(a L₀ / g) (at least 0.3 s)
//! with a frame at the end, reads the final deposits from the frames and compares them:
//!
//! - the **height profile** h(x): on 1-mm bins from the wall, the highest top of the material
//!   in the bin (grains: centre + radius; material points: centre + half their spacing),
//!   leaving out the glued floor row;
//! - the **front** L∞: scanning the bins from the wall, the first bin where the deposit,
//!   averaged over it and its two neighbours, is thinner than 3.5 mm (about two grain layers
//!   above the 1.3-mm floor row), so that a few grains rolling ahead of the deposit do not
//!   count, nor one bin that catches no surface grain (a one-grain dip); the **runout** is
//!   ΔL = L∞ − L₀;
//! - the check: the hybrid runout averaged over the packings within 10% of the DEM's averaged
//!   over the same packings (issue 5; one packing moves a runout by several percent), and the
//!   L1 difference of the profiles, in grain diameters, over the bins up to the farther front
//!   (reported);
//! - in a full run, the MPM column of every ratio (`column_collapse_mpm_2d.toml`, reported),
//!   and fits of ΔL/L₀ = λ a below the crossover and c aⁿ above it ([`runout_fits`]).

use super::args::ValidateArgs;
use super::deposit::{BIN, Deposit, FRONT_HEIGHT, deposit, front, profile, profile_l1};
use super::packings;
use super::runs::{RunResult, SCENE_USE_HEADER, finished, load_with, run_scene, scene_use};
use super::scenes::column::{BOTTOM, D, DEM, HYBRID, L0, MPM};
use super::stats::slope;
use crate::metrics::MetricsTable;
use crate::report::Part;
use crate::report::chart::{Chart, Kind, Series};
use crate::run::{BadInput, Status};
use anyhow::bail;
use grains_service::vtu::Frame;
use std::fmt::Write as _;
use std::path::Path;

/// Columns of the pile's surface (the at-rest test's) [m].
const PILE_COLUMN: f64 = 0.002;
/// Issue 5: the hybrid runout within 10% of the DEM's.
const RUNOUT_TOLERANCE: f64 = 0.10;

/// One run of the substep sweep.
pub struct SweepRow {
    pub k: u32,
    /// Completed without the solvers' failure checks (NaN, runaway energy, leaving the grid)
    /// and the kinetic energy never above the potential energy gravity can release.
    pub stable: bool,
    /// Largest kinetic energy over the run / (m g H / 2) of the column.
    pub energy_ratio: f64,
    pub wall: f64,
    pub message: String,
}

/// The stability sweep over k (Yue 2018 §3.7 saw instability beyond about 10): the hybrid
/// column of a = 1 for 0.2 s with MPM step k × 5e-7 s.
pub fn sweep(args: &ValidateArgs, packing: &Path, ks: &[u32], extra: &[String]) -> anyhow::Result<Vec<SweepRow>> {
    let a = 1.0;
    let mut rows = Vec::new();
    for &k in ks {
        tracing::info!("validate: substep sweep k = {k}");
        let mut overrides = vec![
            format!("body.0.max=[{L0},{}]", BOTTOM + a * L0),
            format!("body.0.packing={:?}", packing.display().to_string()),
            "run.duration=0.2".to_string(),
            format!("run.dt={:e}", k as f64 * 5e-7),
            format!("coupling.substeps={k}"),
            "output.frames_every=0".to_string(),
        ];
        overrides.extend(args.hybrid_overrides.iter().chain(extra).cloned());
        // A setting `grains run` refuses is a point of the map, with its message.
        let outcome = match run_scene(args, &args.scenes.join(HYBRID), overrides) {
            Ok(o) => o,
            Err(e) => {
                rows.push(SweepRow {
                    k,
                    stable: false,
                    energy_ratio: f64::NAN,
                    wall: 0.0,
                    message: format!("grains run refuses: {e:#}"),
                });
                continue;
            }
        };
        let t = MetricsTable::read(&outcome.dir)?;
        let e_pot = (t.first("dem_mass")? + t.first("mpm_mass")?) * 9.81 * 0.5 * a * L0;
        let ke_max = t
            .column("dem_ke")?
            .iter()
            .zip(t.column("mpm_ke")?)
            .map(|(d, m)| d + m)
            .fold(0.0, f64::max);
        let energy_ratio = if e_pot > 0.0 { ke_max / e_pot } else { f64::NAN };
        let completed = outcome.status == Status::Completed;
        rows.push(SweepRow {
            k,
            stable: completed && energy_ratio <= 1.0,
            energy_ratio,
            wall: t.last("wall_s")?,
            message: if completed { String::new() } else { outcome.message.clone() },
        });
    }
    Ok(rows)
}

/// The hybrid pile at rest with one grain transfer: the largest move of its free surface
/// (top of the grains per 2-mm column) from 0.4 s (settled) to 0.9 s, and the kinetic energy
/// at the end (the at-rest test of issue 5 runs the same scene with the default "flip").
struct PileDrift {
    transfer: &'static str,
    drift: f64,
    ke_end: f64,
}

fn pile_drift(args: &ValidateArgs, transfer: &'static str) -> anyhow::Result<PileDrift> {
    let s = load_with(&args.pile, &[])?;
    let (settled, end) = ((0.4 / s.dt).round() as u64, (0.9 / s.dt).round() as u64);
    let overrides = vec![
        format!("coupling.grain_transfer={transfer:?}"),
        "run.duration=0.9".into(),
        format!("output.frames_every={}", gcd(settled, end)),
    ];
    let outcome = run_scene(args, &args.pile, overrides)?;
    if outcome.status != Status::Completed {
        bail!("{}: the run did not complete: {}", args.pile.display(), outcome.message);
    }
    let surface = |step: u64| -> anyhow::Result<Vec<f64>> {
        let file = outcome.dir.join("frames").join(format!("grains_{step:08}.vtu"));
        let dep = Deposit {
            grains: super::deposit::grains_of(&Frame::read(&file)?, &file)?,
            ..Deposit::default()
        };
        Ok(profile(&dep, PILE_COLUMN, 20))
    };
    let (before, after) = (surface(settled)?, surface(end)?);
    let drift = before
        .iter()
        .zip(&after)
        .filter(|(b, _)| **b > 0.0)
        .map(|(b, a)| (a - b).abs())
        .fold(0.0, f64::max);
    let t = MetricsTable::read(&outcome.dir)?;
    Ok(PileDrift {
        transfer,
        drift,
        ke_end: t.last("dem_ke")? + t.last("mpm_ke")?,
    })
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// Simulated time of the runs of a column of aspect `a` [s]: six free-fall times of its
/// height, at least 0.3 s.
fn duration(a: f64) -> f64 {
    (6.0 * (a * L0 / 9.81).sqrt()).max(0.3)
}

/// Runs a scene to the end with a frame at the last step; first-row counts and wall time.
pub fn run_case(args: &ValidateArgs, scene: &str, packing: &Path, a: f64, extra: &[String]) -> anyhow::Result<RunResult> {
    let path = args.scenes.join(scene);
    let top = BOTTOM + a * L0;
    let duration = duration(a);
    let mut overrides = vec![
        format!("body.0.max=[{L0},{top}]"),
        format!("body.0.packing={:?}", packing.display().to_string()),
        format!("run.duration={:.2}", duration),
    ];
    overrides.extend(extra.iter().cloned());
    // One frame at the start and one at the last step, whatever the overrides make of it.
    let steps = load_with(&path, &overrides)?.steps;
    overrides.push(format!("output.frames_every={steps}"));
    finished(args, &path, overrides)
}

struct Case {
    aspect: f64,
    /// Seed of the packing the column was cut from.
    packing: u64,
    dem: RunResult,
    hybrid: RunResult,
    /// The MPM run of this ratio (packing 1 of a full run only).
    mpm: Option<RunResult>,
    h_dem: Vec<f64>,
    h_hybrid: Vec<f64>,
    /// Empty without an MPM run.
    h_mpm: Vec<f64>,
    front_dem: f64,
    front_hybrid: f64,
    /// NaN without an MPM run.
    front_mpm: f64,
    l1: f64,
}

impl Case {
    fn runout_error(&self) -> f64 {
        (self.front_hybrid - L0) / (self.front_dem - L0) - 1.0
    }
}

/// The runs of one aspect ratio over all packings: one packing's runout moves by several
/// percent with the packing alone (a few grains more or less in the front bins), so the check
/// compares the mean runouts.
struct Summary {
    aspect: f64,
    runs: usize,
    runout_dem: f64,
    runout_hybrid: f64,
    /// Sample standard deviation of the DEM runout over the packings (0 for one packing).
    spread_dem: f64,
    /// The MPM runout of the ratio (NaN without a run).
    runout_mpm: f64,
    l1: f64,
}

impl Summary {
    fn of(aspect: f64, cases: &[&Case]) -> Self {
        let n = cases.len() as f64;
        let mean = |f: &dyn Fn(&Case) -> f64| cases.iter().map(|c| f(c)).sum::<f64>() / n;
        let runout_dem = mean(&|c| c.front_dem - L0);
        let var = cases.iter().map(|c| (c.front_dem - L0 - runout_dem).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        Summary {
            aspect,
            runs: cases.len(),
            runout_dem,
            runout_hybrid: mean(&|c| c.front_hybrid - L0),
            spread_dem: var.sqrt(),
            runout_mpm: cases
                .iter()
                .find(|c| c.front_mpm.is_finite())
                .map_or(f64::NAN, |c| c.front_mpm - L0),
            l1: mean(&|c| c.l1),
        }
    }
    fn runout_error(&self) -> f64 {
        self.runout_hybrid / self.runout_dem - 1.0
    }
    fn passes(&self) -> bool {
        self.runout_error().abs() <= RUNOUT_TOLERANCE
    }
}

/// ΔL/L₀ = λ a below the crossover (Lube 2005: a < 1.8) and c aⁿ above it (a > 2.8); the
/// fits split the ratios at [`CROSSOVER`].
pub const CROSSOVER: f64 = 2.5;
/// Lube et al. 2005 (λ; c, n) and Yue 2018's hybrid 2D columns (Fig. 6).
const LUBE: (f64, f64, f64) = (1.2, 1.9, 2.0 / 3.0);
const YUE: (f64, f64, f64) = (1.45, 2.05, 0.67);

/// Least-squares fits of normalized runouts (a, ΔL/L₀): λ of the line through the origin over
/// a < [`CROSSOVER`] and (c, n) of the power law over a > it (a line in log–log); `None` where
/// there are too few ratios (one for λ, two for the power law).
pub fn runout_fits(points: &[(f64, f64)]) -> (Option<f64>, Option<(f64, f64)>) {
    let low: Vec<&(f64, f64)> = points.iter().filter(|p| p.0 < CROSSOVER && p.1.is_finite()).collect();
    let lambda = (!low.is_empty()).then(|| low.iter().map(|p| p.0 * p.1).sum::<f64>() / low.iter().map(|p| p.0 * p.0).sum::<f64>());
    let high: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.0 > CROSSOVER && p.1 > 0.0)
        .map(|p| (p.0.ln(), p.1.ln()))
        .collect();
    let power = (high.len() >= 2).then(|| {
        let n = slope(&high);
        let (mx, my) = (
            high.iter().map(|p| p.0).sum::<f64>() / high.len() as f64,
            high.iter().map(|p| p.1).sum::<f64>() / high.len() as f64,
        );
        ((my - n * mx).exp(), n)
    });
    (lambda, power)
}

/// The curve of a fit (λ; c, n) over the ratios [a0, a1], the two laws joined at the crossover
/// by a gap (NaN).
fn law_curve(lambda: f64, c: f64, n: f64, a0: f64, a1: f64) -> Vec<(f64, f64)> {
    let mut v = Vec::new();
    let steps = 40;
    for i in 0..=steps {
        let a = a0 * (a1 / a0).powf(i as f64 / steps as f64);
        if a < CROSSOVER {
            v.push((a, lambda * a));
        }
    }
    v.push((f64::NAN, f64::NAN));
    for i in 0..=steps {
        let a = a0 * (a1 / a0).powf(i as f64 / steps as f64);
        if a > CROSSOVER {
            v.push((a, c * a.powf(n)));
        }
    }
    v
}

/// The column part: the hybrid against the DEM at every aspect ratio (checked), the MPM
/// beside them (reported), runouts against the published laws.
pub fn validate(args: &ValidateArgs) -> anyhow::Result<Part> {
    let aspects = match (args.aspect.is_empty(), args.quick) {
        (false, _) => args.aspect.clone(),
        (true, true) => vec![1.0],
        (true, false) => vec![0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0],
    };
    let packings = args.packings.unwrap_or(if args.quick { 1 } else { 3 });
    if packings == 0 {
        bail!(BadInput("--packings: at least 1".into()));
    }
    let hybrid_scene = load_with(&args.scenes.join(HYBRID), &args.hybrid_overrides)?;
    let point_half = 0.5 * hybrid_scene.domain.cell_size / hybrid_scene.mpm.points_per_axis as f64;
    let mpm_scene = load_with(&args.scenes.join(MPM), &[])?;
    let mpm_half = 0.5 * mpm_scene.domain.cell_size / mpm_scene.mpm.points_per_axis as f64;
    let n_bins = ((hybrid_scene.domain.max[0] / BIN) as usize).max(1);
    let a_max = aspects.iter().copied().fold(0.0, f64::max);
    let mut cases = Vec::new();
    // Packing by packing, so that the log shows every aspect ratio of one packing early.
    for seed in 1..=packings {
        let packing = packings::column(args, a_max, seed)?;
        for &a in &aspects {
            tracing::info!("validate: packing {seed}, column collapse a = {a}: DEM");
            let dem = run_case(args, DEM, &packing, a, &[])?;
            tracing::info!("validate: packing {seed}, column collapse a = {a}: hybrid");
            let hybrid = run_case(args, HYBRID, &packing, a, &args.hybrid_overrides)?;
            // The continuum does not depend on the packing: one MPM run per ratio.
            let mpm = if args.quick || seed > 1 {
                None
            } else {
                tracing::info!("validate: column collapse a = {a}: MPM");
                Some(run_mpm_case(args, a)?)
            };
            let h_dem = profile(&deposit(&dem.dir, point_half)?, BIN, n_bins);
            let h_hybrid = profile(&deposit(&hybrid.dir, point_half)?, BIN, n_bins);
            let h_mpm = match &mpm {
                Some(m) => profile(&deposit(&m.dir, mpm_half)?, BIN, n_bins),
                None => Vec::new(),
            };
            let (front_dem, front_hybrid) = (front(&h_dem, BIN, FRONT_HEIGHT), front(&h_hybrid, BIN, FRONT_HEIGHT));
            let front_mpm = if h_mpm.is_empty() {
                f64::NAN
            } else {
                front(&h_mpm, BIN, FRONT_HEIGHT)
            };
            let l1 = profile_l1(&h_dem, &h_hybrid, front_dem.max(front_hybrid));
            let case = Case {
                aspect: a,
                packing: seed,
                dem,
                hybrid,
                mpm,
                h_dem,
                h_hybrid,
                h_mpm,
                front_dem,
                front_hybrid,
                front_mpm,
                l1,
            };
            tracing::info!(
                "validate: packing {seed}, a = {a}: front DEM {:.3} m, hybrid {:.3} m, MPM {:.3} m; runout {:+.1}%; profile L1 {:.2} d",
                case.front_dem,
                case.front_hybrid,
                case.front_mpm,
                100.0 * case.runout_error(),
                case.l1
            );
            cases.push(case);
        }
    }
    let summaries: Vec<Summary> = aspects
        .iter()
        .map(|&a| Summary::of(a, &cases.iter().filter(|c| c.aspect == a).collect::<Vec<_>>()))
        .collect();
    let mut piles = Vec::new();
    if !args.quick {
        for transfer in ["pic", "flip"] {
            tracing::info!("validate: hybrid pile at rest, grain_transfer = {transfer:?}");
            piles.push(pile_drift(args, transfer)?);
        }
    }
    column_outputs(args, &cases, &summaries, &piles, n_bins)
}

/// The MPM column of aspect ratio `a` (its material from the floor up: no glued row).
fn run_mpm_case(args: &ValidateArgs, a: f64) -> anyhow::Result<RunResult> {
    let path = args.scenes.join(MPM);
    let duration = duration(a);
    let mut overrides = vec![format!("body.0.max=[{L0},{}]", a * L0), format!("run.duration={duration:.2}")];
    let steps = load_with(&path, &overrides)?.steps;
    overrides.push(format!("output.frames_every={steps}"));
    finished(args, &path, overrides)
}

/// The column part's report: tables, checks, charts and the profiles' CSV.
fn column_outputs(args: &ValidateArgs, cases: &[Case], summaries: &[Summary], piles: &[PileDrift], n_bins: usize) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Column collapse: hybrid and MPM against the pure DEM\n\n");
    summary_section(&mut md, &mut part, args, summaries);
    runs_table(&mut md, cases);
    runout_section(&mut md, &mut part, args, summaries)?;
    profile_charts(&mut part, args, summaries, cases)?;
    if let Some(c) = cases.iter().find(|c| c.aspect == 1.0).or(cases.first()) {
        let row = scene_use(
            args,
            &mut part,
            "column_use",
            &format!("column a = {}", c.aspect),
            &c.hybrid.dir,
            &c.dem.dir,
        )?;
        let _ = writeln!(md, "\n### What each run simulates\n\n{SCENE_USE_HEADER}\n{row}");
        let mut runs = vec![("DEM", c.dem.dir.as_path()), ("hybrid", c.hybrid.dir.as_path())];
        if let Some(m) = &c.mpm {
            runs.push(("MPM", m.dir.as_path()));
        }
        let reach = [c.front_dem, c.front_hybrid, c.front_mpm]
            .into_iter()
            .filter(|f| f.is_finite())
            .fold(L0, f64::max);
        let top = BOTTOM + c.aspect * L0;
        super::pictures::side_by_side(
            &mut part,
            &args.out,
            "column_pictures",
            &format!(
                "Column a = {}, packing {}: at the start and the end of the runs",
                c.aspect, c.packing
            ),
            &runs,
            &[0.0, duration(c.aspect)],
            Some(([0.0, 0.0], [1.15 * reach, 1.15 * top])),
        )?;
    }
    if !piles.is_empty() {
        let _ = write!(
            md,
            "\n### Hybrid pile at rest: grain transfer\n\n`{}` (the scene of the at-rest test): largest move of the free \
             surface from 0.4 s to 0.9 s (issue 5 asks for under 0.1 grain diameter) and the kinetic energy at 0.9 s. \
             The column collapse above uses its scene's transfer.\n\n| grain_transfer | surface move (d) | KE at 0.9 s J |\n|---|---:|---:|\n",
            args.pile.display()
        );
        for p in piles {
            let _ = writeln!(md, "| {} | {:.3} | {:.2e} |", p.transfer, p.drift / D, p.ke_end);
        }
    }
    let mut csv = String::from("aspect,packing,x_m,h_dem_m,h_hybrid_m,h_mpm_m\n");
    for c in cases {
        for i in 0..n_bins {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{}",
                c.aspect,
                c.packing,
                (i as f64 + 0.5) * BIN,
                c.h_dem[i],
                c.h_hybrid[i],
                c.h_mpm.get(i).map_or(String::new(), |v| v.to_string())
            );
        }
    }
    std::fs::write(args.out.join("column_profiles.csv"), csv)?;
    md.push_str("\nAll profiles: `column_profiles.csv`.\n");
    part.md = md;
    Ok(part)
}

/// The check of every aspect ratio: the mean runouts over the packings.
fn summary_section(md: &mut String, part: &mut Part, args: &ValidateArgs, summaries: &[Summary]) {
    let _ = writeln!(
        md,
        "Yue 2018 §5 (Fig. 5): the hybrid deposit reproduces the DEM's. Column L₀ = 40 mm, height a·L₀, \
         scenes `column_collapse_2d.toml` (DEM), `column_collapse_hybrid_2d.toml` (hybrid){} and `{MPM}` (MPM, \
         one run per ratio, its column from the floor up). \
         Front: first 1-mm bin from the wall where the deposit, averaged over the bin and its two \
         neighbours, is under 3.5 mm; runout ΔL = L∞ − L₀. \
         Each aspect ratio runs on {} packing{} (`grains pack` of `column_packing_2d.toml`, seeds 1..{}); \
         one packing's runout moves by several percent with the packing alone, so the check compares the runouts \
         averaged over the packings: hybrid within {:.0}% of the DEM's (issue 5). L1: mean |h_DEM − h_hybrid| over the \
         bins up to the farther front, in grain diameters (reported). DEM spread: standard deviation of \
         the DEM runout over the packings.\n",
        if args.hybrid_overrides.is_empty() {
            String::new()
        } else {
            format!(" with overrides `{}`", args.hybrid_overrides.join(" "))
        },
        summaries.first().map_or(0, |s| s.runs),
        if summaries.first().is_some_and(|s| s.runs == 1) { "" } else { "s" },
        summaries.first().map_or(0, |s| s.runs),
        100.0 * RUNOUT_TOLERANCE
    );
    md.push_str(
        "| a | packings | DEM runout mm | DEM spread mm | hybrid runout mm | runout error | MPM runout mm | mean L1 (d) | check |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---|\n",
    );
    for m in summaries {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:+.1}% | {} | {:.2} | {} |",
            m.aspect,
            m.runs,
            m.runout_dem * 1e3,
            m.spread_dem * 1e3,
            m.runout_hybrid * 1e3,
            100.0 * m.runout_error(),
            if m.runout_mpm.is_finite() {
                format!("{:.1}", m.runout_mpm * 1e3)
            } else {
                "–".into()
            },
            m.l1,
            if m.passes() { "pass" } else { "**FAIL**" }
        );
        part.check(
            format!("column a = {}: hybrid runout", m.aspect),
            format!(
                "pure DEM runout, same packing{} ({:.1} mm; Yue 2018 Fig. 5, issue 5)",
                if m.runs > 1 { "s, mean" } else { "" },
                m.runout_dem * 1e3
            ),
            format!("{:.1} mm ({:+.1}%)", m.runout_hybrid * 1e3, 100.0 * m.runout_error()),
            format!("±{:.0}%", 100.0 * RUNOUT_TOLERANCE),
            m.passes(),
        );
    }
}

/// Every run, one row each.
fn runs_table(md: &mut String, cases: &[Case]) {
    md.push_str(
        "\nEvery run:\n\n\
         | a | packing | DEM grains | hybrid grains + points | DEM L∞ m | hybrid L∞ m | MPM L∞ m | runout error | L1 (d) | DEM wall s | hybrid wall s | MPM wall s |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for c in cases {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} + {} | {:.3} | {:.3} | {} | {:+.1}% | {:.2} | {:.1} | {:.1} | {} |",
            c.aspect,
            c.packing,
            c.dem.grains,
            c.hybrid.grains,
            c.hybrid.points,
            c.front_dem,
            c.front_hybrid,
            if c.front_mpm.is_finite() {
                format!("{:.3}", c.front_mpm)
            } else {
                "–".into()
            },
            100.0 * c.runout_error(),
            c.l1,
            c.dem.wall,
            c.hybrid.wall,
            c.mpm.as_ref().map_or("–".into(), |m| format!("{:.1}", m.wall)),
        );
    }
}

/// Runouts against the published laws (ΔL/L₀ against a, log–log as Lube 2005 Fig. 5).
fn runout_section(md: &mut String, part: &mut Part, args: &ValidateArgs, summaries: &[Summary]) -> anyhow::Result<()> {
    let norm = |f: &dyn Fn(&Summary) -> f64| -> Vec<(f64, f64)> {
        summaries
            .iter()
            .map(|m| (m.aspect, f(m) / L0))
            .filter(|p| p.1.is_finite())
            .collect()
    };
    let (dem_pts, hyb_pts, mpm_pts) = (norm(&|m| m.runout_dem), norm(&|m| m.runout_hybrid), norm(&|m| m.runout_mpm));
    let _ = writeln!(
        md,
        "\n### Runout against aspect ratio\n\nFits of ΔL/L₀ = λ a (a < {CROSSOVER}) and c aⁿ (a > {CROSSOVER}) by least squares \
         (reported, no tolerance: a 2D column of 1-mm glass disks is not the experiments' 3D sand), next to the published ones.\n\n\
         | | λ | c | n |\n|---|---:|---:|---:|\n| Lube et al. 2005 (experiments) | {} | {} | 0.67 |\n\
         | Yue 2018 (hybrid, 2D) | {} | {} | {} |",
        LUBE.0, LUBE.1, YUE.0, YUE.1, YUE.2
    );
    let a_lo = summaries.iter().map(|m| m.aspect).fold(f64::INFINITY, f64::min).min(0.5);
    let a_hi = summaries.iter().map(|m| m.aspect).fold(0.0, f64::max).max(6.0);
    let mut chart = Chart {
        title: "Column collapse: runout against aspect ratio".into(),
        x_label: "aspect ratio a = H0/L0".into(),
        y_label: "runout (L - L0)/L0".into(),
        log_x: true,
        log_y: true,
        ..Chart::default()
    };
    for (name, pts) in [("DEM", &dem_pts), ("hybrid", &hyb_pts), ("MPM", &mpm_pts)] {
        let (lambda, power) = runout_fits(pts);
        let _ = writeln!(
            md,
            "| grains {name} ({} ratios) | {} | {} | {} |",
            pts.len(),
            lambda.map_or("–".into(), |l| format!("{l:.2}")),
            power.map_or("–".into(), |p| format!("{:.2}", p.0)),
            power.map_or("–".into(), |p| format!("{:.2}", p.1)),
        );
        if !pts.is_empty() {
            chart.series.push(Series::new(name, Kind::Points, pts.to_vec()));
        }
        if name == "DEM"
            && let Some(l) = lambda
        {
            // Without ratios above the crossover, the line alone (the power law's points are NaN).
            let (c, n) = power.unwrap_or((f64::NAN, f64::NAN));
            chart
                .series
                .push(Series::new("DEM fit", Kind::Line, law_curve(l, c, n, a_lo, a_hi)));
        }
    }
    for (name, (l, c, n)) in [("Lube et al. 2005", LUBE), ("Yue 2018 hybrid", YUE)] {
        chart.series.push(Series::new(name, Kind::Dashed, law_curve(l, c, n, a_lo, a_hi)));
    }
    if !dem_pts.is_empty() {
        part.chart(
            &args.out,
            "column_runout",
            "Normalized runout against aspect ratio, grains and published laws",
            &chart,
        )?;
    }
    Ok(())
}

/// One deposit chart per aspect ratio (its first packing).
fn profile_charts(part: &mut Part, args: &ValidateArgs, summaries: &[Summary], cases: &[Case]) -> anyhow::Result<()> {
    for (i, m) in summaries.iter().enumerate() {
        let Some(c) = cases.iter().find(|c| c.aspect == m.aspect) else {
            continue;
        };
        let xmax = c
            .front_dem
            .max(c.front_hybrid)
            .max(if c.front_mpm.is_finite() { c.front_mpm } else { 0.0 })
            * 1.15;
        let bins = |h: &[f64]| -> Vec<(f64, f64)> {
            h.iter()
                .enumerate()
                .map(|(i, &v)| ((i as f64 + 0.5) * BIN, v))
                .take_while(|p| p.0 < xmax)
                .collect()
        };
        let mut chart = Chart {
            title: format!("Column a = {}: final deposit (packing {})", c.aspect, c.packing),
            x_label: "x [m]".into(),
            y_label: "height [m]".into(),
            ..Chart::default()
        };
        chart.series.push(Series::new("DEM", Kind::Line, bins(&c.h_dem)));
        chart.series.push(Series::new("hybrid", Kind::Line, bins(&c.h_hybrid)));
        if !c.h_mpm.is_empty() {
            chart.series.push(Series::new("MPM", Kind::Line, bins(&c.h_mpm)));
        }
        part.chart(
            &args.out,
            &format!("column_profile_{i}"),
            format!("Deposit at a = {}", c.aspect),
            &chart,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// The check compares mean runouts, not the mean of the runs' errors: with DEM runouts
    /// 60 and 80 mm and hybrid 75 and 73 mm the runs are off by +25% and -8.75% (mean +8.1%),
    /// the means by 74 / 70 - 1 = +5.7%.
    #[test]
    fn summary_compares_mean_runouts() {
        let run = || RunResult {
            dir: PathBuf::new(),
            grains: 0,
            points: 0,
            wall: 0.0,
        };
        let case = |packing, front_dem: f64, front_hybrid: f64| Case {
            aspect: 1.0,
            packing,
            dem: run(),
            hybrid: run(),
            mpm: None,
            h_dem: Vec::new(),
            h_hybrid: Vec::new(),
            h_mpm: Vec::new(),
            front_dem,
            front_hybrid,
            front_mpm: f64::NAN,
            l1: packing as f64,
        };
        let cases = [case(1, L0 + 0.060, L0 + 0.075), case(2, L0 + 0.080, L0 + 0.073)];
        assert!((cases[0].runout_error() - 0.25).abs() < 1e-12);
        let m = Summary::of(1.0, &cases.iter().collect::<Vec<_>>());
        assert!((m.runout_error() - (74.0 / 70.0 - 1.0)).abs() < 1e-12, "{}", m.runout_error());
        assert!(m.passes());
        assert!((m.spread_dem - 200f64.sqrt() * 1e-3).abs() < 1e-12, "{}", m.spread_dem);
        assert_eq!((m.runs, m.l1), (2, 1.5));
        // One packing: its own error, no spread; 11% off fails.
        let one = Summary::of(1.0, &[&case(1, L0 + 0.100, L0 + 0.111)]);
        assert_eq!(one.spread_dem, 0.0);
        assert!(!one.passes(), "{}", one.runout_error());
    }

    /// Runouts made from a law come back as its λ, c and n; one ratio below the crossover
    /// and one above give λ but no power law.
    #[test]
    fn runout_fits_recover_a_law() {
        let law = |a: f64| if a < CROSSOVER { 1.3 * a } else { 2.1 * a.powf(0.7) };
        let pts: Vec<(f64, f64)> = [0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0].iter().map(|&a| (a, law(a))).collect();
        let (l, p) = runout_fits(&pts);
        let (c, n) = p.unwrap();
        assert!(
            (l.unwrap() - 1.3).abs() < 1e-12 && (c - 2.1).abs() < 1e-9 && (n - 0.7).abs() < 1e-9,
            "{l:?} {c} {n}"
        );
        let (l, p) = runout_fits(&[(1.0, 1.5), (4.0, 5.0)]);
        assert_eq!((l, p), (Some(1.5), None));
    }
}
