//! `grains validate`: the hybrid column collapse against the pure DEM one (Yue 2018 §5,
//! Fig. 5: the hybrid reproduces the DEM's deposit), for aspect ratios a = H₀/L₀ of 0.5, 1, 2
//! and 4 (`--quick`: a = 1 only, for CI: its runout, about 75 mm, is large next to the
//! millimetre the front can be placed to; at a = 0.5, 30 mm, a 2-mm step was 7% of it).
//!
//! Both start from the same random packing: `scenes/column_packing_2d.toml` poured and settled
//! by `grains pack` (once per seed 1..=`--packings`, kept in `--out`) to a little above the
//! tallest column. Each case
//! runs `column_collapse_2d.toml` and `column_collapse_hybrid_2d.toml` with the column's top
//! moved to a·L₀ (L₀ = 40 mm), its grains cut from the packing, for 6 √(a L₀ / g) (at least
//! 0.3 s) with a frame at the end, reads the final deposits from the frames and compares them:
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
//!   (reported).
//!
//! Outputs in `--out`: `report.md` (table, checks, pass/fail), `profiles.csv` (the data of
//! the picture) and `profiles.svg` (both profiles of every case overlaid). Exits non-zero when
//! a check fails.

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
    /// Where the runs and the report go.
    #[arg(long, default_value = "out/validate")]
    pub out: PathBuf,
    /// DEM substeps per MPM step to sweep for stability (hybrid, a = 1, first 0.2 s); the
    /// default set 1, 2, 5, 10, 20, 40 runs without `--quick`.
    #[arg(long, value_delimiter = ',')]
    pub sweep_k: Vec<u32>,
    /// The hybrid pile at rest whose surface drift is measured with both grain transfers.
    #[arg(long, default_value = "tests/scenes/hybrid_pile_2d.toml")]
    pub pile: PathBuf,
    /// Extra `--set` overrides for the hybrid runs (to explore; the report lists them).
    #[arg(long = "set-hybrid", value_name = "KEY=VALUE")]
    pub hybrid_overrides: Vec<String>,
    /// Packings poured (seeds 1..=N) and run at every aspect ratio; the check compares the
    /// runouts averaged over them. Default 3, `--quick` 1.
    #[arg(long)]
    pub packings: Option<u64>,
    /// Parts to run: `column` (the collapse, `report.md`), `silo` (discharge, Beverloo,
    /// clogging, bouncing: `silo.md`), `drum` (angle of repose: `drum.md`). Default all
    /// (`--quick`: column and silo).
    #[arg(long, value_delimiter = ',')]
    pub part: Vec<String>,
}

/// Column width L₀ and bottom of both scenes [m].
const L0: f64 = 0.04;
const BOTTOM: f64 = 0.0015;
/// Mean grain diameter of both scenes [m].
const D: f64 = 0.001;
/// Profile bins [m] and the thinnest deposit that counts for the front [m]. One grain wide:
/// 2-mm bins moved the front of both runs in 2-mm steps, 7% of the runout at a = 0.5.
const BIN: f64 = 0.001;
const FRONT_HEIGHT: f64 = 0.0035;
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
fn deposit(run_dir: &Path, point_half: f64) -> anyhow::Result<Deposit> {
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
fn ensure_packing(args: &ValidateArgs, a_max: f64, seed: u64) -> anyhow::Result<PathBuf> {
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
struct SweepRow {
    k: u32,
    /// Completed without the solvers' failure checks (NaN, runaway energy, leaving the grid)
    /// and the kinetic energy never above the potential energy gravity can release.
    stable: bool,
    /// Largest kinetic energy over the run / (m g H / 2) of the column.
    energy_ratio: f64,
    wall: f64,
    message: String,
}

/// The stability sweep over k (Yue 2018 §3.7 saw instability beyond about 10): the hybrid
/// column of a = 1 for 0.2 s with MPM step k × 5e-7 s.
fn sweep(args: &ValidateArgs, packing: &Path, ks: &[u32]) -> anyhow::Result<Vec<SweepRow>> {
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
        overrides.extend(args.hybrid_overrides.iter().cloned());
        let outcome = run_scene(args, &args.scenes.join("column_collapse_hybrid_2d.toml"), overrides)?;
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

struct RunResult {
    dir: PathBuf,
    grains: u64,
    points: u64,
    wall: f64,
}

/// Runs a scene to the end with a frame at the last step; first-row counts and wall time.
fn run_case(args: &ValidateArgs, scene: &str, packing: &Path, a: f64, extra: &[String]) -> anyhow::Result<RunResult> {
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
    let outcome = run_scene(args, &path, overrides)?;
    if outcome.status != Status::Completed {
        bail!("{scene}: the run did not complete: {}", outcome.message);
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
    h_dem: Vec<f64>,
    h_hybrid: Vec<f64>,
    front_dem: f64,
    front_hybrid: f64,
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

pub fn validate(args: &ValidateArgs) -> anyhow::Result<bool> {
    if let Some(p) = args.part.iter().find(|p| !["column", "silo", "drum"].contains(&p.as_str())) {
        bail!(crate::run::BadInput(format!(
            "--part {p:?}: the parts are \"column\", \"silo\" and \"drum\""
        )));
    }
    let wants = |p: &str| args.part.is_empty() || args.part.iter().any(|q| q == p);
    let column = if wants("column") { validate_column(args)? } else { true };
    let silo = if wants("silo") {
        crate::validate_silo::validate_silo(args)?
    } else {
        true
    };
    // The drum takes minutes more than the quick set allows: full runs only, or when asked.
    let drum = if wants("drum") && (!args.quick || args.part.iter().any(|q| q == "drum")) {
        crate::validate_drum::validate_drum(args)?
    } else {
        true
    };
    Ok(column && silo && drum)
}

/// The column part: `report.md` and its data; whether every check passed.
fn validate_column(args: &ValidateArgs) -> anyhow::Result<bool> {
    let ks = match (args.sweep_k.is_empty(), args.quick) {
        (false, _) => args.sweep_k.clone(),
        (true, true) => Vec::new(),
        (true, false) => vec![1, 2, 5, 10, 20, 40],
    };
    let aspects = match (args.aspect.is_empty(), args.quick) {
        (false, _) => args.aspect.clone(),
        (true, true) => vec![1.0],
        (true, false) => vec![0.5, 1.0, 2.0, 4.0],
    };
    let packings = args.packings.unwrap_or(if args.quick { 1 } else { 3 });
    if packings == 0 {
        bail!(crate::run::BadInput("--packings: at least 1".into()));
    }
    std::fs::create_dir_all(&args.out)?;
    let hybrid_scene = load_with(&args.scenes.join("column_collapse_hybrid_2d.toml"), &args.hybrid_overrides)?;
    let point_half = 0.5 * hybrid_scene.domain.cell_size / hybrid_scene.mpm.points_per_axis as f64;
    let n_bins = ((hybrid_scene.domain.max[0] / BIN) as usize).max(1);
    let a_max = aspects.iter().copied().fold(if ks.is_empty() { 0.0 } else { 1.0 }, f64::max);
    let mut cases = Vec::new();
    // Packing by packing, so that the log shows every aspect ratio of one packing early.
    for seed in 1..=packings {
        let packing = ensure_packing(args, a_max, seed)?;
        for &a in &aspects {
            eprintln!("validate: packing {seed}, column collapse a = {a}: DEM");
            let dem = run_case(args, "column_collapse_2d.toml", &packing, a, &[])?;
            eprintln!("validate: packing {seed}, column collapse a = {a}: hybrid");
            let hybrid = run_case(args, "column_collapse_hybrid_2d.toml", &packing, a, &args.hybrid_overrides)?;
            let h_dem = profile(&deposit(&dem.dir, point_half)?, BIN, n_bins);
            let h_hybrid = profile(&deposit(&hybrid.dir, point_half)?, BIN, n_bins);
            let (front_dem, front_hybrid) = (front(&h_dem, BIN, FRONT_HEIGHT), front(&h_hybrid, BIN, FRONT_HEIGHT));
            let upto = ((front_dem.max(front_hybrid) / BIN).round() as usize).clamp(1, n_bins);
            let l1 = h_dem[..upto].iter().zip(&h_hybrid[..upto]).map(|(a, b)| (a - b).abs()).sum::<f64>() / upto as f64 / D;
            let case = Case {
                aspect: a,
                packing: seed,
                dem,
                hybrid,
                h_dem,
                h_hybrid,
                front_dem,
                front_hybrid,
                l1,
            };
            eprintln!(
                "validate: packing {seed}, a = {a}: front DEM {:.3} m, hybrid {:.3} m; runout {:+.1}%; profile L1 {:.2} d",
                case.front_dem,
                case.front_hybrid,
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
    // The sweep runs on the first packing.
    let sweep_rows = if ks.is_empty() {
        Vec::new()
    } else {
        sweep(args, &ensure_packing(args, a_max, 1)?, &ks)?
    };
    let mut piles = Vec::new();
    if !args.quick {
        for transfer in ["pic", "flip"] {
            eprintln!("validate: hybrid pile at rest, grain_transfer = {transfer:?}");
            piles.push(pile_drift(args, transfer)?);
        }
    }
    write_outputs(args, &cases, &summaries, &sweep_rows, &piles, n_bins)?;
    Ok(summaries.iter().all(Summary::passes))
}

fn write_outputs(
    args: &ValidateArgs,
    cases: &[Case],
    summaries: &[Summary],
    sweep_rows: &[SweepRow],
    piles: &[PileDrift],
    n_bins: usize,
) -> anyhow::Result<()> {
    let mut md = String::from("# grains validate: hybrid vs pure DEM column collapse\n\n");
    let _ = writeln!(
        md,
        "Yue 2018 §5 (Fig. 5): the hybrid deposit reproduces the DEM's. Column L₀ = 40 mm, height a·L₀, \
         scenes `column_collapse_2d.toml` (DEM) and `column_collapse_hybrid_2d.toml` (hybrid){}. \
         Front: first 1-mm bin from the wall where the deposit, averaged over the bin and its two \
         neighbours, is under 3.5 mm; runout ΔL = L∞ − L₀. \
         Each aspect ratio runs on {} packing{} (`grains pack` of `column_packing_2d.toml`, seeds 1..{}); \
         one packing's runout moves by several percent with the packing alone, so the check compares the runouts \
         averaged over the packings: hybrid within {:.0}% of the DEM's (issue 5). L1: mean |h_DEM − h_hybrid| over the \
         bins up to the farther front, in grain diameters (reported, no tolerance). DEM spread: standard deviation of \
         the DEM runout over the packings.\n",
        if args.hybrid_overrides.is_empty() {
            String::new()
        } else {
            format!(", hybrid overrides `{}`", args.hybrid_overrides.join(" "))
        },
        summaries.first().map_or(0, |s| s.runs),
        if summaries.first().is_some_and(|s| s.runs == 1) { "" } else { "s" },
        summaries.first().map_or(0, |s| s.runs),
        100.0 * RUNOUT_TOLERANCE
    );
    md.push_str(
        "| a | packings | DEM runout mm | DEM spread mm | hybrid runout mm | runout error | mean L1 (d) | check |\n\
         |---:|---:|---:|---:|---:|---:|---:|---|\n",
    );
    for m in summaries {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:+.1}% | {:.2} | {} |",
            m.aspect,
            m.runs,
            m.runout_dem * 1e3,
            m.spread_dem * 1e3,
            m.runout_hybrid * 1e3,
            100.0 * m.runout_error(),
            m.l1,
            if m.passes() { "pass" } else { "FAIL" }
        );
    }
    md.push_str(
        "\nEvery run:\n\n\
         | a | packing | DEM grains | hybrid grains + points | DEM L∞ m | hybrid L∞ m | runout error | L1 (d) | DEM wall s | hybrid wall s |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for c in cases {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} + {} | {:.3} | {:.3} | {:+.1}% | {:.2} | {:.1} | {:.1} |",
            c.aspect,
            c.packing,
            c.dem.grains,
            c.hybrid.grains,
            c.hybrid.points,
            c.front_dem,
            c.front_hybrid,
            100.0 * c.runout_error(),
            c.l1,
            c.dem.wall,
            c.hybrid.wall,
        );
    }
    md.push_str("\nProfiles: `profiles.svg` (data: `profiles.csv`).\n");
    if !piles.is_empty() {
        let _ = write!(
            md,
            "\n## Hybrid pile at rest: grain transfer\n\n`{}` (the scene of the at-rest test): largest move of the free \
             surface from 0.4 s to 0.9 s (issue 5 asks for under 0.1 grain diameter) and the kinetic energy at 0.9 s. \
             The column collapse above uses its scene's transfer.\n\n| grain_transfer | surface move (d) | KE at 0.9 s J |\n|---|---:|---:|\n",
            args.pile.display()
        );
        for p in piles {
            let _ = writeln!(md, "| {} | {:.3} | {:.2e} |", p.transfer, p.drift / D, p.ke_end);
        }
    }
    if !sweep_rows.is_empty() {
        md.push_str(
            "\n## Substeps k per MPM step: stability\n\n\
             Hybrid column a = 1, first 0.2 s, DEM step 5e-7 s, MPM step k × 5e-7 s. Stable: the run completes \
             (no NaN, no runaway energy, nothing leaves the grid) and the kinetic energy stays below m g H / 2, \
             the potential energy the collapse can release (reported, not a check: Yue 2018 §3.7 saw instability beyond about 10).\n\n\
             | k | MPM step s | max KE / (m g H / 2) | wall s | stable | message |\n|---:|---:|---:|---:|---|---|\n",
        );
        for r in sweep_rows {
            let _ = writeln!(
                md,
                "| {} | {:.1e} | {:.3} | {:.1} | {} | {} |",
                r.k,
                r.k as f64 * 5e-7,
                r.energy_ratio,
                r.wall,
                if r.stable { "yes" } else { "no" },
                r.message.replace('|', "/")
            );
        }
    }
    std::fs::write(args.out.join("report.md"), &md)?;
    print!("{md}");

    let mut csv = String::from("aspect,packing,x_m,h_dem_m,h_hybrid_m\n");
    for c in cases {
        for i in 0..n_bins {
            let _ = writeln!(
                csv,
                "{},{},{},{},{}",
                c.aspect,
                c.packing,
                (i as f64 + 0.5) * BIN,
                c.h_dem[i],
                c.h_hybrid[i]
            );
        }
    }
    std::fs::write(args.out.join("profiles.csv"), csv)?;
    std::fs::write(args.out.join("profiles.svg"), svg(cases))?;
    eprintln!("validate: report in {}", args.out.join("report.md").display());
    Ok(())
}

/// One panel per case, the DEM profile (blue) and the hybrid one (orange) overlaid.
fn svg(cases: &[Case]) -> String {
    let (w, ph, pad) = (720.0, 180.0, 40.0);
    let xmax = cases.iter().map(|c| c.front_dem.max(c.front_hybrid)).fold(0.06f64, f64::max) * 1.15;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        cases.len() as f64 * (ph + pad) + pad
    );
    for (k, c) in cases.iter().enumerate() {
        let top = pad + k as f64 * (ph + pad);
        let hmax = c.h_dem.iter().chain(&c.h_hybrid).fold(0.01f64, |a, &b| a.max(b)) * 1.1;
        let px = |x: f64| pad + (x / xmax) * (w - 2.0 * pad);
        let py = |h: f64| top + ph - (h / hmax) * ph;
        let _ = writeln!(
            s,
            "<rect x=\"{pad}\" y=\"{top}\" width=\"{}\" height=\"{ph}\" fill=\"none\" stroke=\"#999\"/>\n\
             <text x=\"{}\" y=\"{}\">a = {}, packing {}: DEM (blue) front {:.3} m, hybrid (orange) {:.3} m, L1 {:.2} d; x to {:.3} m, h to {:.3} m</text>",
            w - 2.0 * pad,
            pad,
            top - 6.0,
            c.aspect,
            c.packing,
            c.front_dem,
            c.front_hybrid,
            c.l1,
            xmax,
            hmax
        );
        for (h, colour) in [(&c.h_dem, "#1f77b4"), (&c.h_hybrid, "#ff7f0e")] {
            let pts: Vec<String> = h
                .iter()
                .enumerate()
                .take_while(|(i, _)| (*i as f64) * BIN < xmax)
                .map(|(i, &v)| format!("{:.1},{:.1}", px((i as f64 + 0.5) * BIN), py(v)))
                .collect();
            let _ = writeln!(
                s,
                "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.5\" points=\"{}\"/>",
                pts.join(" ")
            );
        }
    }
    s.push_str("</svg>\n");
    s
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
            h_dem: Vec::new(),
            h_hybrid: Vec::new(),
            front_dem,
            front_hybrid,
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
