//! `grains validate`: the validation report (issue 8). Parts, in the order they run
//! (`--part`; `--quick` is the CI subset, under 15 minutes):
//!
//! - `contact`, `stability` ([`crate::validate_stability`]): the DEM restitution against its
//!   analytic value; stability maps of the DEM step, the MPM CFL number and, in a full run,
//!   the hybrid's substeps and cell / grain ratio.
//! - `column` (here): the hybrid and MPM column collapse against the pure DEM one (Yue 2018
//!   §5, Fig. 5), runouts against Lube et al. 2005 and Yue 2018's laws.
//! - `silo`, `drum` ([`crate::validate_silo`], [`crate::validate_drum`]).
//! - `cost` ([`crate::validate_cost`]): error against wall time, with the Pareto front.
//!
//! Everything goes to `--out` (default `out/validate/<date>`): `report.md` opens with every
//! check (reference, measured, tolerance, pass/fail), then each part's tables and charts
//! (PNG, SVG and the CSV behind each). The command exits 1 when a check fails.
//!
//! The column part: both models start from the same random packing,
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

use crate::chart::{Chart, Kind, Series};
use crate::report::Part;
use crate::run::{RunOptions, Status, TransportKind, run};
use anyhow::{Context, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub(crate) fn load_with(path: &Path, overrides: &[String]) -> anyhow::Result<grains_protocol::scene::Scene> {
    Ok(grains_protocol::scene::load_with_overrides(path, overrides)?.0)
}

/// One run of `scene` with `overrides` as processes, quietly, under `<out>/runs`.
pub(crate) fn run_scene(args: &ValidateArgs, scene: &Path, overrides: Vec<String>) -> anyhow::Result<crate::run::RunOutcome> {
    run(&RunOptions {
        bridge: None,
        scene_path: scene.to_path_buf(),
        transport: TransportKind::Ipc,
        external: Vec::new(),
        out_root: args.out.join("runs"),
        progress: false,
        overrides,
        announce: false,
    })
}

/// The rows of a run's `metrics.csv` (empty when it has none).
pub(crate) struct Table {
    header: Vec<String>,
    pub(crate) rows: Vec<Vec<f64>>,
}

impl Table {
    pub(crate) fn read(run_dir: &Path) -> Table {
        let csv = std::fs::read_to_string(run_dir.join("metrics.csv")).unwrap_or_default();
        let mut lines = csv.lines();
        let header = lines.next().unwrap_or_default().split(',').map(String::from).collect();
        let rows = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect())
            .collect();
        Table { header, rows }
    }

    /// Column `name` of `row` (0 when the column is missing).
    pub(crate) fn get(&self, row: &[f64], name: &str) -> f64 {
        self.header
            .iter()
            .position(|c| c == name)
            .and_then(|i| row.get(i).copied())
            .unwrap_or(0.0)
    }

    fn first(&self, name: &str) -> f64 {
        self.rows.first().map_or(f64::NAN, |r| self.get(r, name))
    }

    /// Mean of column `name` over the rows (NaN without rows).
    pub(crate) fn mean(&self, name: &str) -> f64 {
        self.rows.iter().map(|r| self.get(r, name)).sum::<f64>() / self.rows.len() as f64
    }

    pub(crate) fn last(&self, name: &str) -> f64 {
        self.rows.last().map_or(f64::NAN, |r| self.get(r, name))
    }
}

#[derive(Debug, Clone, clap::Args)]
pub struct ValidateArgs {
    /// The CI subset: aspect ratio 1 only.
    #[arg(long)]
    pub quick: bool,
    /// Aspect ratios to run instead of the default set.
    #[arg(long, value_delimiter = ',')]
    pub aspect: Vec<f64>,
    /// Directory of column_collapse_2d.toml and column_collapse_hybrid_2d.toml.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Where the runs and the report go (default `out/validate/<today>`).
    #[arg(long = "out", value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// `--out`, or its default, once `validate` has chosen it.
    #[arg(skip)]
    pub out: PathBuf,
    /// DEM substeps per MPM step to sweep for stability (hybrid, a = 1, first 0.2 s); the
    /// default set 2, 5, 10, 20, 40, 80, 160 runs without `--quick`.
    #[arg(long, value_delimiter = ',')]
    pub sweep_k: Vec<u32>,
    /// The hybrid pile at rest whose surface drift is measured with both grain transfers.
    #[arg(long, default_value = "tests/scenes/hybrid_pile_2d.toml")]
    pub pile: PathBuf,
    /// Extra `--set` overrides for the hybrid runs (to explore; the report lists them).
    #[arg(long = "set-hybrid", value_name = "KEY=VALUE")]
    pub hybrid_overrides: Vec<String>,
    /// Also copy the report and its charts (PNG, SVG, CSV), without the runs, into this
    /// directory (the repository's `docs/validate` keeps the last published one).
    #[arg(long)]
    pub publish: Option<PathBuf>,
    /// Packings poured (seeds 1..=N) and run at every aspect ratio; the check compares the
    /// runouts averaged over them. Default 3, `--quick` 1.
    #[arg(long)]
    pub packings: Option<u64>,
    /// Parts to run: `contact` (DEM restitution), `stability` (stability maps), `column`
    /// (collapse against DEM and published laws), `silo` (discharge, Beverloo, clogging,
    /// bouncing), `drum` (angle of repose), `cost` (accuracy against wall time). Default all
    /// (`--quick`: all but drum and cost, each in its CI subset).
    #[arg(long, value_delimiter = ',')]
    pub part: Vec<String>,
}

/// Column width L₀ and bottom of both scenes [m].
const L0: f64 = 0.04;
pub(crate) const L0_COLUMN: f64 = L0;
const BOTTOM: f64 = 0.0015;
/// Mean grain diameter of both scenes [m].
const D: f64 = 0.001;
/// Profile bins [m] and the thinnest deposit that counts for the front [m]. One grain wide:
/// 2-mm bins moved the front of both runs in 2-mm steps, 7% of the runout at a = 0.5.
pub(crate) const BIN: f64 = 0.001;
pub(crate) const FRONT_HEIGHT: f64 = 0.0035;
/// Columns of the pile's surface (the at-rest test's).
const PILE_COLUMN: f64 = 0.002;
/// Grains of the glued floor row have their centres below this [m].
const FLOOR_ROW: f64 = 0.0012;
/// Issue 5: the hybrid runout within 10% of the DEM's.
const RUNOUT_TOLERANCE: f64 = 0.10;

/// The final deposit of a run: grains (centre, radius) and material points (centre).
#[derive(Debug, Default)]
pub struct Deposit {
    pub grains: Vec<([f64; 3], f64)>,
    pub points: Vec<[f64; 3]>,
    /// Half the spacing of the material points [m].
    pub point_half: f64,
}

/// Heights of the deposit on `n` bins of width `bin` from x = 0 (0 where a bin is empty).
pub fn profile(dep: &Deposit, bin: f64, n: usize) -> Vec<f64> {
    let mut h = vec![0.0f64; n];
    let mut put = |x: f64, top: f64| {
        if x >= 0.0 {
            let i = (x / bin) as usize;
            if i < n {
                h[i] = h[i].max(top);
            }
        }
    };
    for &(x, r) in &dep.grains {
        if x[1] >= FLOOR_ROW {
            put(x[0], x[1] + r);
        }
    }
    for x in &dep.points {
        put(x[0], x[1] + dep.point_half);
    }
    h
}

/// The front: the left edge of the first bin, from the wall, where the mean height of the bin
/// and its two neighbours is below `min`. On one-grain bins a bin whose surface grains sit in
/// the next bins reads a grain lower; the mean keeps such a dip from ending the deposit.
pub fn front(profile: &[f64], bin: f64, min: f64) -> f64 {
    let n = profile.len();
    let mean = |i: usize| {
        let (lo, hi) = (i.saturating_sub(1), (i + 2).min(n));
        profile[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
    };
    (0..n).position(|i| mean(i) < min).unwrap_or(n) as f64 * bin
}

/// Positions and, if present, the `radius` array of an ASCII VTU frame of grains.
type Frame = (Vec<[f64; 3]>, Option<Vec<f64>>);

fn read_vtu(path: &Path) -> anyhow::Result<Frame> {
    let a = frame_arrays(path, &["radius"])?;
    let radius = a.get("radius").cloned();
    Ok((a.x, radius))
}

/// The named arrays of a VTU frame, with its positions.
pub(crate) struct Arrays {
    pub x: Vec<[f64; 3]>,
    named: Vec<(String, Vec<f64>)>,
}

impl Arrays {
    pub fn get(&self, name: &str) -> Option<&Vec<f64>> {
        self.named.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
}

/// Positions and the arrays `names` (those present) of an ASCII VTU frame.
pub(crate) fn frame_arrays(path: &Path, names: &[&str]) -> anyhow::Result<Arrays> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let array = |start: &str| -> Option<Vec<f64>> {
        let at = text.find(start)?;
        let body = &text[at + text[at..].find("<DataArray")?..];
        let open = body.find('>')? + 1;
        let close = body.find("</DataArray>")?;
        body[open..close].split_ascii_whitespace().map(|v| v.parse().ok()).collect()
    };
    let flat = array("<Points>").with_context(|| format!("{}: no points", path.display()))?;
    let named = names
        .iter()
        .filter_map(|n| array(&format!("<DataArray type=\"Float64\" Name=\"{n}\"")).map(|v| (n.to_string(), v)))
        .collect();
    Ok(Arrays {
        x: flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        named,
    })
}

/// Every frame listed in `frames/<name>.pvd` of a run: (time, file), in order; none without one.
pub(crate) fn frames_of(run_dir: &Path, name: &str) -> anyhow::Result<Vec<(f64, PathBuf)>> {
    let Ok(pvd) = std::fs::read_to_string(run_dir.join("frames").join(format!("{name}.pvd"))) else {
        return Ok(Vec::new());
    };
    pvd.split("<DataSet")
        .skip(1)
        .map(|d| {
            let field = |key: &str| -> Option<&str> { d.split(&format!("{key}=\"")).nth(1)?.split('"').next() };
            let t: f64 = field("timestep")
                .and_then(|t| t.parse().ok())
                .with_context(|| format!("{name}.pvd: a data set without timestep"))?;
            let file = field("file").with_context(|| format!("{name}.pvd: a data set without file"))?;
            Ok((t, run_dir.join("frames").join(file)))
        })
        .collect()
}

/// A packing poured by `grains pack` from `scene` with `overrides`, kept in `--out` as `name`
/// (poured once: later runs reuse it).
pub(crate) fn poured(args: &ValidateArgs, name: &str, scene: &str, overrides: Vec<String>) -> anyhow::Result<PathBuf> {
    let path = std::path::absolute(args.out.join(name))?;
    if !path.exists() {
        eprintln!("validate: pouring {name} with grains pack");
        crate::pack::pack(&crate::pack::PackArgs {
            scene: args.scenes.join(scene),
            out: path.clone(),
            friction: None,
            overrides,
        })?;
    }
    Ok(path)
}

/// The last frame listed in `frames/<name>.pvd` of a run, if any.
fn last_frame(run_dir: &Path, name: &str) -> Option<PathBuf> {
    let pvd = std::fs::read_to_string(run_dir.join("frames").join(format!("{name}.pvd"))).ok()?;
    let file = pvd
        .rsplit("file=\"")
        .next()
        .filter(|_| pvd.contains("file=\""))?
        .split('"')
        .next()?;
    Some(run_dir.join("frames").join(file))
}

/// The deposit at the end of a run from its last frames.
pub(crate) fn deposit(run_dir: &Path, point_half: f64) -> anyhow::Result<Deposit> {
    let mut dep = Deposit {
        point_half,
        ..Deposit::default()
    };
    if let Some(f) = last_frame(run_dir, "grains") {
        let (x, r) = read_vtu(&f)?;
        let r = r.with_context(|| format!("{}: no radius array", f.display()))?;
        dep.grains = x.into_iter().zip(r).collect();
    }
    if let Some(f) = last_frame(run_dir, "points") {
        dep.points = read_vtu(&f)?.0;
    }
    Ok(dep)
}

/// The settled packing of `seed` for columns up to `a_max`: made by `grains pack` unless
/// `--out` has it. The seed draws the radii and the lattice's jitter, so each pour settles
/// into another random packing.
pub(crate) fn ensure_packing(args: &ValidateArgs, a_max: f64, seed: u64) -> anyhow::Result<PathBuf> {
    // A lattice settles to about 0.78 of its height; pour a third more than the column needs.
    let pour_top = BOTTOM + 1.35 * a_max * L0 + 0.005;
    let name = format!("packing_column_{:.0}mm_seed{seed}.data", pour_top * 1e3);
    let path = std::path::absolute(args.out.join(name))?;
    if !path.exists() {
        let settle = ((2.0 * pour_top / 9.81).sqrt() + 0.2) * 100.0;
        eprintln!(
            "validate: pouring column packing {seed} ({:.0} mm of lattice) with grains pack",
            pour_top * 1e3
        );
        crate::pack::pack(&crate::pack::PackArgs {
            scene: args.scenes.join("column_packing_2d.toml"),
            out: path.clone(),
            friction: None,
            overrides: vec![
                format!("body.0.max=[{L0},{pour_top}]"),
                format!("run.duration={}", settle.ceil() / 100.0),
                format!("run.seed={seed}"),
            ],
        })?;
    }
    let data = grains_dem_service::lammps_data::read(&path).map_err(anyhow::Error::msg)?;
    let top = data.atoms.iter().filter(|a| a.kind == 1).map(|a| a.x[1]).fold(0.0, f64::max);
    if top < BOTTOM + a_max * L0 + D {
        bail!(
            "{}: the packing is {:.1} mm tall, too short for a column of aspect ratio {a_max}; delete it to pour a new one",
            path.display(),
            top * 1e3
        );
    }
    Ok(path)
}

/// One run of the substep sweep.
pub(crate) struct SweepRow {
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
pub(crate) fn sweep(args: &ValidateArgs, packing: &Path, ks: &[u32], extra: &[String]) -> anyhow::Result<Vec<SweepRow>> {
    let a = 1.0;
    let mut rows = Vec::new();
    for &k in ks {
        eprintln!("validate: substep sweep k = {k}");
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
        let outcome = match run_scene(args, &args.scenes.join("column_collapse_hybrid_2d.toml"), overrides) {
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
        let t = Table::read(&outcome.dir);
        let e_pot = (t.first("dem_mass") + t.first("mpm_mass")) * 9.81 * 0.5 * a * L0;
        let ke_max = t.rows.iter().map(|r| t.get(r, "dem_ke") + t.get(r, "mpm_ke")).fold(0.0, f64::max);
        let energy_ratio = if e_pot > 0.0 { ke_max / e_pot } else { f64::NAN };
        let completed = outcome.status == Status::Completed;
        rows.push(SweepRow {
            k,
            stable: completed && energy_ratio <= 1.0,
            energy_ratio,
            wall: t.last("wall_s"),
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
        let (x, r) = read_vtu(&outcome.dir.join("frames").join(format!("grains_{step:08}.vtu")))?;
        let dep = Deposit {
            grains: x.into_iter().zip(r.unwrap_or_default()).collect(),
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
    let t = Table::read(&outcome.dir);
    Ok(PileDrift {
        transfer,
        drift,
        ke_end: t.last("dem_ke") + t.last("mpm_ke"),
    })
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

pub(crate) struct RunResult {
    pub dir: PathBuf,
    pub grains: u64,
    pub points: u64,
    pub wall: f64,
}

/// Runs a scene to the end with a frame at the last step; first-row counts and wall time.
pub(crate) fn run_case(args: &ValidateArgs, scene: &str, packing: &Path, a: f64, extra: &[String]) -> anyhow::Result<RunResult> {
    let path = args.scenes.join(scene);
    let top = BOTTOM + a * L0;
    let duration = (6.0 * (a * L0 / 9.81).sqrt()).max(0.3);
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

/// Runs `scene` to its end: its counts and wall time; an error names it if it did not complete.
pub(crate) fn finished(args: &ValidateArgs, path: &Path, overrides: Vec<String>) -> anyhow::Result<RunResult> {
    let outcome = run_scene(args, path, overrides)?;
    if outcome.status != Status::Completed {
        bail!("{}: the run did not complete: {}", path.display(), outcome.message);
    }
    let t = Table::read(&outcome.dir);
    Ok(RunResult {
        grains: t.first("dem_items") as u64,
        points: t.first("mpm_items") as u64,
        wall: t.last("wall_s"),
        dir: outcome.dir,
    })
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

/// The roles of the participants a run started (from its `summary.json`).
pub(crate) fn participants_of(run_dir: &Path) -> Vec<String> {
    let summary: serde_json::Value = std::fs::read_to_string(run_dir.join("summary.json"))
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or_default();
    summary["participants"]
        .as_array()
        .map(|a| a.iter().filter_map(|p| p["role"].as_str().map(String::from)).collect())
        .unwrap_or_default()
}

/// "Model no more than a scene needs": the participants a hybrid run started, its grains and
/// points over time next to the pure-DEM run of the same scene, and both wall times. Returns
/// the section's table row and writes the chart `<stem>.*`.
pub(crate) fn scene_use(
    args: &ValidateArgs,
    part: &mut Part,
    stem: &str,
    scene: &str,
    hybrid_dir: &Path,
    dem_dir: &Path,
) -> anyhow::Result<String> {
    let (h, d) = (Table::read(hybrid_dir), Table::read(dem_dir));
    let series = |t: &Table, col: &str| -> Vec<(f64, f64)> {
        let every = (t.rows.len() / 400).max(1);
        t.rows.iter().step_by(every).map(|r| (t.get(r, "time"), t.get(r, col))).collect()
    };
    let chart = Chart {
        title: format!("{scene}: what each run simulates"),
        x_label: "time [s]".into(),
        y_label: "grains or material points".into(),
        series: vec![
            Series::new("hybrid: grains", Kind::Line, series(&h, "dem_items")),
            Series::new("hybrid: material points", Kind::Line, series(&h, "mpm_items")),
            Series::new("pure DEM: grains", Kind::Dashed, series(&d, "dem_items")),
        ],
        ..Chart::default()
    };
    part.chart(
        &args.out,
        stem,
        format!("{scene}: grains and points over time, hybrid and pure DEM"),
        &chart,
    )?;
    let (hw, dw) = (h.last("wall_s"), d.last("wall_s"));
    Ok(format!(
        "| `{scene}` | {} | {} | {:.0} → {:.0} | {:.0} → {:.0} | {:.0} | {hw:.1} | {dw:.1} | {:.2}x |",
        participants_of(hybrid_dir).join(", "),
        participants_of(dem_dir).join(", "),
        h.first("dem_items"),
        h.last("dem_items"),
        h.first("mpm_items"),
        h.last("mpm_items"),
        d.mean("dem_items"),
        dw / hw
    ))
}

/// The header of the tables [`scene_use`] fills.
pub(crate) const SCENE_USE_HEADER: &str = "| scene | hybrid run's participants | pure DEM's | hybrid grains start → end | points start → end | pure-DEM grains | hybrid wall s | pure-DEM wall s | speedup |\n|---|---|---|---:|---:|---:|---:|---:|---:|";

/// The parts of `grains validate`, in the order they run.
const PARTS: [&str; 6] = ["contact", "stability", "column", "silo", "drum", "cost"];

pub fn validate(args: &ValidateArgs) -> anyhow::Result<bool> {
    if let Some(p) = args.part.iter().find(|p| !PARTS.contains(&p.as_str())) {
        bail!(crate::run::BadInput(format!(
            "--part {p:?}: the parts are {}",
            PARTS.map(|p| format!("{p:?}")).join(", ")
        )));
    }
    let mut args = args.clone();
    args.out = args
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/validate").join(crate::report::today()));
    std::fs::create_dir_all(&args.out)?;
    let args = &args;
    // The drum and the accuracy-cost runs take longer than the quick set allows: full runs
    // only, or when asked for by name.
    let named = |p: &str| args.part.iter().any(|q| q == p);
    let wants = |p: &str| named(p) || (args.part.is_empty() && (!args.quick || !["drum", "cost"].contains(&p)));
    let t0 = std::time::Instant::now();
    let mut parts = Vec::new();
    for p in PARTS.iter().filter(|p| wants(p)) {
        let result = match *p {
            "contact" => crate::validate_stability::validate_contact(args),
            "stability" => crate::validate_stability::validate_stability(args),
            "column" => validate_column(args),
            "silo" => crate::validate_silo::validate_silo(args),
            "drum" => crate::validate_drum::validate_drum(args),
            _ => crate::validate_cost::validate_cost(args),
        };
        // A part that cannot finish (a run refused or failed) is a failed check; the other
        // parts still run and report.
        parts.push(result.unwrap_or_else(|e| {
            eprintln!("validate: part {p} failed: {e:#}");
            let mut part = Part {
                md: format!("## Part `{p}`: did not finish\n\n{e:#}\n"),
                ..Part::default()
            };
            part.check(
                format!("part {p} ran to its end"),
                "every run of the part completes",
                format!("{e:#}"),
                "no error",
                false,
            );
            part
        }));
    }
    let preamble = format!(
        "`grains validate{}` (grains {}), {} UTC, {:.0} min on {} threads. Parts: {}. Every check names what it is \
         compared with; the figures below each part hold the runs' numbers, with the data of every chart as CSV.",
        std::env::args().skip(2).map(|a| format!(" {a}")).collect::<String>(),
        env!("CARGO_PKG_VERSION"),
        crate::report::today(),
        t0.elapsed().as_secs_f64() / 60.0,
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        PARTS.iter().filter(|p| wants(p)).copied().collect::<Vec<_>>().join(", ")
    );
    let md = crate::report::markdown("grains validate", &preamble, &parts);
    let path = args.out.join("report.md");
    std::fs::write(&path, &md)?;
    if let Some(dir) = &args.publish {
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("report.md"), &md)?;
        for (stem, _) in parts.iter().flat_map(|p| &p.charts) {
            for ext in ["png", "svg", "csv"] {
                let name = format!("{stem}.{ext}");
                std::fs::copy(args.out.join(&name), dir.join(&name)).with_context(|| format!("publishing {name}"))?;
            }
        }
        eprintln!("validate: report and charts published to {}", dir.display());
    }
    let failed: Vec<&crate::report::Check> = parts.iter().flat_map(|p| &p.checks).filter(|c| !c.pass).collect();
    for c in &failed {
        eprintln!(
            "validate: FAIL {}: measured {} against {} (tolerance {})",
            c.name, c.measured, c.reference, c.tolerance
        );
    }
    eprintln!(
        "validate: {} checks, {} failed; report in {}",
        parts.iter().map(|p| p.checks.len()).sum::<usize>(),
        failed.len(),
        path.display()
    );
    Ok(failed.is_empty())
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
        let n = crate::validate_silo::slope(&high);
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
fn validate_column(args: &ValidateArgs) -> anyhow::Result<Part> {
    let aspects = match (args.aspect.is_empty(), args.quick) {
        (false, _) => args.aspect.clone(),
        (true, true) => vec![1.0],
        (true, false) => vec![0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0],
    };
    let packings = args.packings.unwrap_or(if args.quick { 1 } else { 3 });
    if packings == 0 {
        bail!(crate::run::BadInput("--packings: at least 1".into()));
    }
    let hybrid_scene = load_with(&args.scenes.join("column_collapse_hybrid_2d.toml"), &args.hybrid_overrides)?;
    let point_half = 0.5 * hybrid_scene.domain.cell_size / hybrid_scene.mpm.points_per_axis as f64;
    let mpm_scene = load_with(&args.scenes.join(MPM_SCENE), &[])?;
    let mpm_half = 0.5 * mpm_scene.domain.cell_size / mpm_scene.mpm.points_per_axis as f64;
    let n_bins = ((hybrid_scene.domain.max[0] / BIN) as usize).max(1);
    let a_max = aspects.iter().copied().fold(0.0, f64::max);
    let mut cases = Vec::new();
    // Packing by packing, so that the log shows every aspect ratio of one packing early.
    for seed in 1..=packings {
        let packing = ensure_packing(args, a_max, seed)?;
        for &a in &aspects {
            eprintln!("validate: packing {seed}, column collapse a = {a}: DEM");
            let dem = run_case(args, "column_collapse_2d.toml", &packing, a, &[])?;
            eprintln!("validate: packing {seed}, column collapse a = {a}: hybrid");
            let hybrid = run_case(args, "column_collapse_hybrid_2d.toml", &packing, a, &args.hybrid_overrides)?;
            // The continuum does not depend on the packing: one MPM run per ratio.
            let mpm = if args.quick || seed > 1 {
                None
            } else {
                eprintln!("validate: column collapse a = {a}: MPM");
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
            eprintln!(
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
            eprintln!("validate: hybrid pile at rest, grain_transfer = {transfer:?}");
            piles.push(pile_drift(args, transfer)?);
        }
    }
    column_outputs(args, &cases, &summaries, &piles, n_bins)
}

const MPM_SCENE: &str = "column_collapse_mpm_2d.toml";

/// The MPM column of aspect ratio `a` (its material from the floor up: no glued row).
fn run_mpm_case(args: &ValidateArgs, a: f64) -> anyhow::Result<RunResult> {
    let path = args.scenes.join(MPM_SCENE);
    let duration = (6.0 * (a * L0 / 9.81).sqrt()).max(0.3);
    let mut overrides = vec![format!("body.0.max=[{L0},{}]", a * L0), format!("run.duration={duration:.2}")];
    let steps = load_with(&path, &overrides)?.steps;
    overrides.push(format!("output.frames_every={steps}"));
    finished(args, &path, overrides)
}

/// Mean |h₁ − h₂| over the bins up to `upto` [m], in grain diameters.
pub(crate) fn profile_l1(h1: &[f64], h2: &[f64], upto: f64) -> f64 {
    let n = ((upto / BIN).round() as usize).clamp(1, h1.len().min(h2.len()).max(1));
    h1.iter().zip(h2).take(n).map(|(a, b)| (a - b).abs()).sum::<f64>() / n as f64 / D
}

fn column_outputs(args: &ValidateArgs, cases: &[Case], summaries: &[Summary], piles: &[PileDrift], n_bins: usize) -> anyhow::Result<Part> {
    let mut part = Part::default();
    let mut md = String::from("## Column collapse: hybrid and MPM against the pure DEM\n\n");
    let _ = writeln!(
        md,
        "Yue 2018 §5 (Fig. 5): the hybrid deposit reproduces the DEM's. Column L₀ = 40 mm, height a·L₀, \
         scenes `column_collapse_2d.toml` (DEM), `column_collapse_hybrid_2d.toml` (hybrid){} and `{MPM_SCENE}` (MPM, \
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
    // Runouts against the published laws (ΔL/L₀ against a, log–log as Lube 2005 Fig. 5).
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A deposit of known shape: a ramp of grains 10 mm high at the wall down to 0 at 30 mm.
    #[test]
    fn profile_and_front_of_a_known_deposit() {
        let mut dep = Deposit {
            point_half: 0.00025,
            ..Deposit::default()
        };
        // The floor row: never counted.
        for i in 0..100 {
            dep.grains.push(([i as f64 * 0.001, 0.0005, 0.0], 0.0005));
        }
        // A column of grains in every millimetre up to the ramp 0.010 (1 − x / 0.030).
        for i in 0..30 {
            let x = i as f64 * 0.001 + 0.0005;
            let top = 0.010 * (1.0 - x / 0.030);
            let mut y = 0.0018;
            while y + 0.0005 <= top {
                dep.grains.push(([x, y, 0.0], 0.0005));
                y += 0.001;
            }
        }
        let mut h = profile(&dep, BIN, 50);
        // Bin [0, 1) mm: the grain column at x = 0.5 mm reaches 0.0018 + 7 · 0.001 + 0.0005
        // (the next grain would top 10.3 mm, above the ramp's 9.83 mm).
        assert!((h[0] - 0.0093).abs() < 1e-12, "{}", h[0]);
        assert_eq!(h[40], 0.0, "beyond the ramp only the floor row, which does not count");
        // Columns at 15.5-16.5 mm hold three grains (tops 4.3 mm), 17.5-19.5 mm two (3.3 mm):
        // the three-bin mean first falls under 3.5 mm at bin [18, 19) mm (3.3; at 17: 3.63).
        let f = front(&h, BIN, FRONT_HEIGHT);
        assert!((f - 0.018).abs() < 1e-12, "front {f}");
        // One bin reading a grain layer low (10: 6.3 → 2.9 mm, under 3.5) does not end it.
        h[10] = 0.0029;
        let f = front(&h, BIN, FRONT_HEIGHT);
        assert!((f - 0.018).abs() < 1e-12, "front {f} after a one-bin dip");
        // Points count with half their spacing.
        dep.points.push([0.041, 0.005, 0.0]);
        assert!((profile(&dep, BIN, 50)[41] - 0.00525).abs() < 1e-12);
    }

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

    /// A frame written by the participants' VTU writer reads back as written.
    #[test]
    fn frames_read_back() {
        use grains_service::vtu::{Field, PointFrames, Values};
        let dir = std::env::temp_dir().join(format!("grains-validate-vtu-{}", std::process::id()));
        let mut frames = PointFrames::new(&dir, "grains").unwrap();
        let x = [[0.001, 0.002, 0.0], [0.25, -0.5, 1e-9]];
        let field = |name, v| Field {
            name,
            components: 1,
            values: Values::F64(v),
        };
        let fields = [field("id_like", &[7.0, 8.0][..]), field("radius", &[5e-4, 6e-4][..])];
        frames
            .write(0, 0.0, &[[9.0; 3]], &[field("id_like", &[1.0][..]), field("radius", &[1.0][..])])
            .unwrap();
        frames.write(40, 0.1, &x, &fields).unwrap();
        let last = last_frame(&dir, "grains").unwrap();
        assert!(last.ends_with("grains_00000040.vtu"), "{}", last.display());
        let (got, r) = read_vtu(&last).unwrap();
        assert_eq!(got, x);
        assert_eq!(r.unwrap(), [5e-4, 6e-4]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
