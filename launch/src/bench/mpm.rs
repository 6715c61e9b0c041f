//! `grains bench mpm`: MPM cost per point-step of a sand block collapsing in a unit box, side
//! by side with the Taichi program of `shared/peers/mpm` in the same session, on the same
//! grid, points per cell and transfer.
//!
//! Cases (the rows of the peer's README): 2D 90,000 and 226,576 points on 256², 3D 195,112 and
//! 1,124,864 points on 64³, 2×2 (×2) points per cell, quadratic B-splines, PIC/FLIP 0.95, f64.
//! Each case runs grains with 1 and 2 threads (in this process), then the peer (a venv with
//! `taichi` from PyPI, made once by `launch/bench/taichi_venv.sh`) with PIC/FLIP f64 on 1 and 2
//! threads and, as a reference, APIC f32 on 1 thread. Both codes do the same warm-up and
//! untimed steps before the same number of timed steps. Figures: wall and process CPU time of
//! the timed loop per point-step; where grains' time goes (P2G, grid, G2P, constitutive
//! update) and where Taichi's goes (its per-kernel shares; its P2G includes the stress).
//!
//! The scene is the peer's as far as grains allows: the same block (cell counts, placement on
//! the floor above the 3-node wall layer, centred across), the same jittered lattice (jitter
//! ±¼ spacing, another random sequence), E, ν, ρ, friction angle, gravity, dt = 0.3 h / c_p,
//! sticky walls 3 nodes thick. What differs is printed with the table.
//!
//! The machine may be shared: before each run the bench waits for builds and other load to end
//! (`--quiet-wait`), and each row reports how many cores other processes used meanwhile.

use super::machine::{children_cpu_seconds, cpu_seconds, machine_busy_seconds, other_load, wait_quiet};
use crate::run::outputs;
use anyhow::{Context, bail};
use grains_grid::{D2, D3, Grid, Kernel};
use grains_mpm::boundary::Contact;
use grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{DOMAIN_WALL_NODES, Model, MpmParams, MpmPipeline, PhaseTimes, Transfer, cfl_time_step};
use grains_mpm::points::Points;
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[derive(Debug, Clone, clap::Args)]
pub struct MpmArgs {
    /// The peer program (shared/peers/mpm).
    #[arg(long, default_value = "../shared/peers/mpm")]
    pub peers: PathBuf,
    /// Where the table, the raw results and the peer's final positions go.
    #[arg(long, default_value = "out/bench/mpm")]
    pub out: PathBuf,
    /// Cases to run (default: all): 2d-90k, 2d-230k, 3d-200k, 3d-1.1m.
    #[arg(long, value_delimiter = ',')]
    pub cases: Vec<String>,
    /// Multiply the timed steps of every case (e.g. 0.3 for a quick look).
    #[arg(long, default_value_t = 1.0)]
    pub steps_scale: f64,
    /// Untimed warm-up steps of both codes (the peer's --warmup).
    #[arg(long, default_value_t = 10)]
    pub warmup: usize,
    /// Further untimed steps after the warm-up, to let the block collapse before timing (the
    /// peer's --pre-steps).
    #[arg(long, default_value_t = 0)]
    pub pre_steps: usize,
    /// Run grains only.
    #[arg(long)]
    pub no_taichi: bool,
    /// Skip the peer's APIC f32 reference row.
    #[arg(long)]
    pub no_apic: bool,
    /// The venv with taichi (made if missing; default: the script's, ~/.cache/grains/taichi-venv).
    #[arg(long)]
    pub venv: Option<PathBuf>,
    /// Before each measurement, wait up to this many seconds while a cargo or rustc process
    /// runs or other processes keep more than a third of a core busy (0: do not wait).
    #[arg(long, default_value_t = 900)]
    pub quiet_wait: u64,
}

struct Case {
    name: &'static str,
    dim: usize,
    n_grid: usize,
    /// Block extent as a fraction of the box inside the walls, per axis (the peer's --fill).
    fill: f64,
    /// Points the peer's README lists for this case.
    points: usize,
    /// Timed steps at --steps-scale 1 (a few seconds of Taichi's loop at 1 thread).
    steps: usize,
}

const CASES: [Case; 4] = [
    Case {
        name: "2d-90k",
        dim: 2,
        n_grid: 256,
        fill: 0.6,
        points: 90_000,
        steps: 200,
    },
    Case {
        name: "2d-230k",
        dim: 2,
        n_grid: 256,
        fill: 0.952,
        points: 226_576,
        steps: 80,
    },
    Case {
        name: "3d-200k",
        dim: 3,
        n_grid: 64,
        fill: 0.5,
        points: 195_112,
        steps: 20,
    },
    Case {
        name: "3d-1.1m",
        dim: 3,
        n_grid: 64,
        fill: 0.9,
        points: 1_124_864,
        steps: 5,
    },
];

/// Points per cell and axis.
const PPC_1D: usize = 2;
/// Wall layers of nodes (the peer's `bound`; grains' DOMAIN_WALL_NODES).
const BOUND: usize = 3;
const _: () = assert!(DOMAIN_WALL_NODES == BOUND as i64, "grains' wall layer must match the peer's");
const YOUNG: f64 = 3.537e5;
const POISSON: f64 = 0.3;
const DENSITY: f64 = 2200.0;
const FRICTION_DEG: f64 = 30.0;
const GRAVITY: f64 = -9.81;
const FLIP: f64 = 0.95;
const CFL: f64 = 0.3;
/// Packing fraction of every point, equal to Φ_cs (with χ = 0 it changes nothing).
const PACKING: f64 = 0.6;

impl Case {
    /// Cells of the block per axis, the peer's rule round(fill · (n − 2 bound)), ≥ 1.
    fn cells(&self) -> [usize; 3] {
        let c = ((self.fill * (self.n_grid - 2 * BOUND) as f64).round() as usize).max(1);
        [0, 1, 2].map(|k| if k < self.dim { c } else { 1 })
    }

    fn point_count(&self) -> usize {
        self.cells()[..self.dim].iter().map(|c| c * PPC_1D).product()
    }

    fn h(&self) -> f64 {
        1.0 / self.n_grid as f64
    }

    /// Untimed steps before the timed loop: warm-up, pre-steps, and the peer's per-kernel
    /// breakdown (max(5, steps/10) steps), so that both codes time the same stretch of the flow.
    fn untimed(&self, args: &MpmArgs, steps: usize) -> usize {
        args.warmup.max(1) + args.pre_steps + (steps / 10).max(5)
    }
}

/// Lamé constants (λ, μ) of E, ν.
fn lame() -> (f64, f64) {
    let mu = YOUNG / (2.0 * (1.0 + POISSON));
    let lambda = YOUNG * POISSON / ((1.0 + POISSON) * (1.0 - 2.0 * POISSON));
    (lambda, mu)
}

/// The closest grains model to the peer's Drucker–Prager sand: Hencky elasticity with
/// τ = λ tr ε I + 2μ ε (K = λ + 2μ/d: the plane-strain λ + μ in 2D, E / (3(1 − 2ν)) in 3D),
/// constant friction (χ = 0, no dilation), no cohesion.
fn model(dim: usize) -> HenckyCriticalState {
    let (lambda, mu) = lame();
    let bulk = if dim == 3 {
        YOUNG / (3.0 * (1.0 - 2.0 * POISSON))
    } else {
        lambda + mu
    };
    HenckyCriticalState {
        bulk,
        shear: mu,
        tan_friction_cs: FRICTION_DEG.to_radians().tan(),
        packing_cs: PACKING,
        chi: 0.0,
        xi: 0.0,
        cohesion: 0.0,
    }
}

/// The peer's time step 0.3 h / c_p, c_p = √((λ + 2μ) / ρ).
fn peer_dt(h: f64) -> f64 {
    let (lambda, mu) = lame();
    CFL * h / ((lambda + 2.0 * mu) / DENSITY).sqrt()
}

/// The peer's block: a lattice of PPC_1D points per cell and axis, jittered by ±¼ of the
/// spacing, resting on the floor (axis 1) at the wall layer and centred on the other axes.
/// Points are in lattice order with axis 0 fastest, which is grains' node order (the peer's
/// lattice order is its own node order, last axis fastest).
fn block<S: MpmSpace>(case: &Case) -> Points<S> {
    let dim = S::DIM;
    let h = case.h();
    let cells = case.cells();
    let spacing = h / PPC_1D as f64;
    let vol = spacing.powi(dim as i32);
    let mut offset = [0.0; 3];
    let mut count = [1usize; 3];
    for k in 0..dim {
        offset[k] = BOUND as f64 * h;
        if k != 1 {
            offset[k] += 0.5 * (1.0 - 2.0 * BOUND as f64 * h) - 0.5 * cells[k] as f64 * h;
        }
        count[k] = cells[k] * PPC_1D;
    }
    // The seed as it always was: the shared generator mixes its seed with this constant.
    let mut rng = grains_grid::rng::Rng::new(0x6772_6169_6e73 ^ 0x5851_f42d_4c95_7f2d);
    let mut pts = Points::<S>::default();
    for c in 0..count[2] {
        for b in 0..count[1] {
            for a in 0..count[0] {
                let idx = [a, b, c];
                let mut x = [0.0; 3];
                for k in 0..dim {
                    x[k] = (idx[k] as f64 + 0.5 + 0.5 * (rng.uniform() - 0.5)) * spacing + offset[k];
                }
                pts.push(S::from_array(x), DENSITY * vol, vol, PACKING);
            }
        }
    }
    pts
}

/// One measured run of one code.
struct Run {
    code: String,
    /// "PIC/FLIP 0.95 f64" or "APIC f32".
    variant: &'static str,
    threads: usize,
    steps: usize,
    wall_us: f64,
    cpu_us: f64,
    /// Shares of P2G, grid, G2P, constitutive update (None: inside P2G, the peer's case).
    shares: [Option<f64>; 4],
    /// Final block extent per axis [min, max].
    extent: Option<Vec<[f64; 2]>>,
    sane: bool,
    load: f64,
    raw: Value,
    /// Why the run did not finish (then its figures are NaN).
    failed: Option<String>,
}

impl Run {
    fn is_grains(&self) -> bool {
        self.code == "grains"
    }

    /// A run that stopped with an error: kept in the table so that the other runs still count.
    fn failed(code: &str, variant: &'static str, threads: usize, steps: usize, err: &anyhow::Error) -> Run {
        let msg = format!("{err:#}");
        Run {
            code: code.into(),
            variant,
            threads,
            steps,
            wall_us: f64::NAN,
            cpu_us: f64::NAN,
            shares: [None; 4],
            extent: None,
            sane: false,
            load: f64::NAN,
            raw: json!({"code": code, "variant": variant, "threads": threads, "steps": steps, "error": msg}),
            failed: Some(msg),
        }
    }
}

fn extent_of(xs: impl Iterator<Item = [f64; 3]>, dim: usize) -> (Vec<[f64; 2]>, bool) {
    let mut e = vec![[f64::INFINITY, f64::NEG_INFINITY]; dim];
    let mut ok = true;
    for x in xs {
        for k in 0..dim {
            ok &= x[k].is_finite() && (0.0..=1.0).contains(&x[k]);
            e[k][0] = e[k][0].min(x[k]);
            e[k][1] = e[k][1].max(x[k]);
        }
    }
    (e, ok)
}

fn run_grains<S: MpmSpace>(case: &Case, threads: usize, untimed: usize, steps: usize) -> anyhow::Result<Run> {
    let dim = S::DIM;
    let h = case.h();
    let mut pts = block::<S>(case);
    let hencky = model(dim);
    let model = Model::CriticalState(hencky);
    let dt = CFL * cfl_time_step(&model, DENSITY, h, dim);
    debug_assert!((dt / peer_dt(h) - 1.0).abs() < 1e-12);
    let params = MpmParams::<S> {
        grid: Grid::covering([0.0; 3], [1.0; 3], h, dim),
        kernel: Kernel::Bspline2,
        model,
        gravity: S::from_array([0.0, GRAVITY, 0.0]),
        transfer: Transfer::Flip(FLIP),
        domain_walls: Some(Contact::Sticky),
        walls: Vec::new(),
        point_loads: grains_mpm::pipeline::PointLoads::Weights,
        ambient_pressure: 0.0,
    };
    let mut pipe = MpmPipeline::<S>::new(threads).map_err(anyhow::Error::msg)?;
    for k in 0..untimed {
        pipe.step(&mut pts, &params, dt).with_context(|| format!("untimed step {k}"))?;
    }
    pipe.times = PhaseTimes::default();
    let (b0, c0, w0) = (machine_busy_seconds(), cpu_seconds(), Instant::now());
    for k in 0..steps {
        pipe.step(&mut pts, &params, dt).with_context(|| format!("timed step {k}"))?;
    }
    let (cpu, wall) = (cpu_seconds() - c0, w0.elapsed().as_secs_f64());
    let load = other_load(b0, cpu, wall);
    let t = pipe.times;
    let phases = [t.p2g, t.grid, t.g2p, t.constitutive].map(|d| d.as_secs_f64());
    let total: f64 = phases.iter().sum();
    let (extent, sane) = extent_of(pts.x.iter().map(|&x| S::to_array(x)), dim);
    let per = 1e6 / (steps as f64 * pts.len() as f64);
    let raw = json!({
        "code": "grains", "case": case.name, "dim": dim, "grid": case.n_grid,
        "grid_nodes": params.grid.nodes[..dim].iter().product::<u64>(),
        "active_nodes": pipe.map.len(),
        "particles": pts.len(), "ppc": PPC_1D.pow(dim as u32), "threads": threads,
        "model": "hencky-critical-state chi=0", "transfer": "flip", "flip_ratio": FLIP, "fp": 64,
        "bulk": hencky.bulk, "shear": hencky.shear, "dt": dt, "untimed_steps": untimed, "steps": steps,
        "ms_per_step": wall / steps as f64 * 1e3,
        "us_per_particle_step": wall * per, "cpu_us_per_particle_step": cpu * per,
        "phase_us_per_particle_step": {"p2g": phases[0] * per, "grid": phases[1] * per, "g2p": phases[2] * per, "constitutive": phases[3] * per},
        "finite_in_box": sane, "extent": extent, "other_load_cores": load,
    });
    Ok(Run {
        code: "grains".into(),
        variant: "PIC/FLIP 0.95 f64",
        threads,
        steps,
        wall_us: wall * per,
        cpu_us: cpu * per,
        shares: phases.map(|p| Some(p / total)),
        extent: Some(extent),
        sane,
        load,
        raw,
        failed: None,
    })
}

/// Reads an (n, dim) float array of a .npy file and returns its extent per axis and whether
/// every value is finite and in [0, 1].
fn npy_extent(path: &Path, dim: usize) -> anyhow::Result<(Vec<[f64; 2]>, bool)> {
    let b = std::fs::read(path)?;
    if b.len() < 12 || &b[..6] != b"\x93NUMPY" {
        bail!("{}: not a .npy file", path.display());
    }
    let (hlen, start) = if b[6] == 1 {
        (u16::from_le_bytes([b[8], b[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(b.get(start..start + hlen).context("short .npy header")?)?;
    if header.contains("'fortran_order': True") {
        bail!("{}: Fortran order", path.display());
    }
    let data = &b[start + hlen..];
    let values: Vec<f64> = if header.contains("'<f8'") {
        data.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
    } else if header.contains("'<f4'") {
        data.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect()
    } else {
        bail!("{}: unexpected dtype in {header}", path.display());
    };
    Ok(extent_of(
        values.chunks_exact(dim).map(|c| {
            let mut x = [0.0; 3];
            x[..dim].copy_from_slice(c);
            x
        }),
        dim,
    ))
}

/// The peer's transfer and precision.
#[derive(Clone, Copy)]
enum Peer {
    Flip64,
    Apic32,
}

impl Peer {
    /// (--transfer, --fp, label).
    fn options(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Peer::Flip64 => ("flip", "64", "PIC/FLIP 0.95 f64"),
            Peer::Apic32 => ("apic", "32", "APIC f32"),
        }
    }

    fn variant(self) -> &'static str {
        self.options().2
    }
}

/// Where the peer runs: the venv's python, the program, the directory for its positions.
struct Taichi {
    python: PathBuf,
    script: PathBuf,
    out: PathBuf,
}

fn run_taichi(taichi: &Taichi, case: &Case, peer: Peer, threads: usize, args: &MpmArgs, steps: usize) -> anyhow::Result<Run> {
    let (transfer, fp, variant) = peer.options();
    let dump = taichi.out.join(format!("taichi_{}_{transfer}{fp}_{threads}t.npy", case.name));
    let mut cmd = Command::new(&taichi.python);
    cmd.arg(&taichi.script);
    for (k, v) in [
        ("--dim", case.dim.to_string()),
        ("--n-grid", case.n_grid.to_string()),
        ("--fill", case.fill.to_string()),
        ("--ppc-1d", PPC_1D.to_string()),
        ("--threads", threads.to_string()),
        ("--steps", steps.to_string()),
        ("--warmup", args.warmup.max(1).to_string()),
        ("--pre-steps", args.pre_steps.to_string()),
        ("--model", "sand".into()),
        ("--transfer", transfer.into()),
        ("--flip-ratio", FLIP.to_string()),
        ("--fp", fp.into()),
    ] {
        cmd.arg(k).arg(v);
    }
    cmd.arg("--dump").arg(&dump);
    let (b0, c0, w0) = (machine_busy_seconds(), children_cpu_seconds(), Instant::now());
    let o = cmd.output().context("running the Taichi peer")?;
    let load = other_load(b0, children_cpu_seconds() - c0, w0.elapsed().as_secs_f64());
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout.lines().rev().find(|l| l.trim_start().starts_with('{'));
    let (true, Some(line)) = (o.status.success(), line) else {
        bail!(
            "the Taichi peer failed on {} ({variant}, {threads} thread(s)): {}\n{stdout}\n{}",
            case.name,
            o.status,
            String::from_utf8_lossy(&o.stderr)
        );
    };
    let raw: Value = serde_json::from_str(line).with_context(|| format!("parsing the peer's line {line}"))?;
    let num = |k: &str| raw[k].as_f64().with_context(|| format!("no {k} in the peer's line {line}"));
    let share = |k: &str| raw["kernel_share"][k].as_f64();
    let particles = num("particles")? as usize;
    if particles != case.point_count() {
        bail!(
            "the peer made {particles} particles for {}, grains {}",
            case.name,
            case.point_count()
        );
    }
    let grid_share = match (share("clear"), share("grid")) {
        (Some(a), Some(b)) => Some(a + b),
        _ => None,
    };
    let (extent, in_box) = match npy_extent(&dump, case.dim) {
        Ok((e, ok)) => (Some(e), ok),
        Err(e) => {
            tracing::warn!("bench mpm: cannot read the peer's positions: {e:#}");
            (None, true)
        }
    };
    Ok(Run {
        code: raw["code"].as_str().unwrap_or("taichi").to_string(),
        variant,
        threads,
        steps,
        wall_us: num("us_per_particle_step")?,
        cpu_us: num("cpu_us_per_particle_step")?,
        shares: [share("p2g"), grid_share, share("g2p"), None],
        extent,
        sane: raw["finite_in_box"].as_bool().unwrap_or(false) && in_box,
        load,
        raw,
        failed: None,
    })
}

fn fmt_extent(e: &Option<Vec<[f64; 2]>>) -> String {
    e.as_ref().map_or("–".into(), |e| {
        e.iter()
            .zip(["x", "y", "z"])
            .map(|(r, a)| format!("{a} [{:.4}, {:.4}]", r[0], r[1]))
            .collect::<Vec<_>>()
            .join(" ")
    })
}

fn pct(s: Option<f64>) -> String {
    s.map_or("–".into(), |s| format!("{:.0} %", s * 100.0))
}

pub fn mpm(args: &MpmArgs) -> anyhow::Result<()> {
    for n in &args.cases {
        if !CASES.iter().any(|c| c.name == n) {
            bail!("unknown case {n:?}; one of: 2d-90k, 2d-230k, 3d-200k, 3d-1.1m");
        }
    }
    std::fs::create_dir_all(&args.out)?;
    let out = std::fs::canonicalize(&args.out)?;
    let peer = taichi(args, &out)?;
    let mut results: Vec<(&Case, Vec<Run>)> = Vec::new();
    let mut loaded = false;
    for case in CASES
        .iter()
        .filter(|c| args.cases.is_empty() || args.cases.iter().any(|n| n == c.name))
    {
        let (runs, busy) = run_case(args, case, peer.as_ref())?;
        loaded |= busy;
        results.push((case, runs));
    }
    let text = report(args, &results, loaded);
    println!("{text}");
    outputs::write_atomic(&out.join("mpm.md"), text.as_bytes())?;
    write_data(&out, &results)?;
    tracing::info!(
        "bench mpm: table, CSV and raw JSON lines written to {}/mpm.{{md,csv,jsonl}}",
        out.display()
    );
    if results.iter().flat_map(|(_, r)| r).any(|r| !r.sane) {
        bail!("a run failed or ended with points not finite or outside the box (see the table)");
    }
    Ok(())
}

/// The peer: the Taichi program in a venv made once (none with `--no-taichi`).
fn taichi(args: &MpmArgs, out: &Path) -> anyhow::Result<Option<Taichi>> {
    if args.no_taichi {
        return Ok(None);
    }
    let script = args.peers.join("taichi_mpm_bench.py");
    if !script.exists() {
        bail!(
            "{}: no peer program there (pass --peers <shared/peers/mpm> or --no-taichi)",
            script.display()
        );
    }
    let setup = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/taichi_venv.sh");
    let mut cmd = Command::new("bash");
    cmd.arg(&setup);
    if let Some(v) = &args.venv {
        cmd.arg(v);
    }
    tracing::info!("bench mpm: making or reusing the taichi venv ({})", setup.display());
    let o = cmd
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running taichi_venv.sh")?;
    let python = String::from_utf8_lossy(&o.stdout).lines().last().unwrap_or("").trim().to_string();
    if !o.status.success() || python.is_empty() {
        bail!("setting up taichi failed (see above; --no-taichi runs grains only)");
    }
    Ok(Some(Taichi {
        python: PathBuf::from(python),
        script: std::fs::canonicalize(script)?,
        out: out.to_path_buf(),
    }))
}

/// One case: grains on 1 and 2 threads, then the peer's runs; whether the machine was busy.
fn run_case(args: &MpmArgs, case: &Case, peer: Option<&Taichi>) -> anyhow::Result<(Vec<Run>, bool)> {
    let mut loaded = false;
    let n = case.point_count();
    if n != case.points {
        bail!("{}: {n} points, the peer's README has {}", case.name, case.points);
    }
    let steps = ((case.steps as f64 * args.steps_scale).round() as usize).max(3);
    let untimed = case.untimed(args, steps);
    tracing::info!("bench mpm: {} ({n} points, {untimed} untimed + {steps} timed steps)", case.name);
    let mut runs = Vec::new();
    for threads in [1, 2] {
        loaded |= wait_quiet("bench mpm", args.quiet_wait);
        let r = if case.dim == 3 {
            run_grains::<D3>(case, threads, untimed, steps)
        } else {
            run_grains::<D2>(case, threads, untimed, steps)
        }
        .unwrap_or_else(|e| Run::failed("grains", "PIC/FLIP 0.95 f64", threads, steps, &e));
        match &r.failed {
            None => tracing::info!(
                "bench mpm:   grains, {threads} thread(s): {:.4} µs/pt-step wall, {:.4} CPU",
                r.wall_us,
                r.cpu_us
            ),
            Some(e) => tracing::warn!("bench mpm:   grains, {threads} thread(s): FAILED: {e}"),
        }
        runs.push(r);
    }
    if let Some(taichi) = peer {
        let mut todo = vec![(Peer::Flip64, 1), (Peer::Flip64, 2)];
        if !args.no_apic {
            todo.push((Peer::Apic32, 1));
        }
        for (p, threads) in todo {
            loaded |= wait_quiet("bench mpm", args.quiet_wait);
            let r = run_taichi(taichi, case, p, threads, args, steps)
                .unwrap_or_else(|e| Run::failed("taichi", p.variant(), threads, steps, &e));
            match &r.failed {
                None => tracing::info!(
                    "bench mpm:   {} {}, {threads} thread(s): {:.4} µs/pt-step wall, {:.4} CPU",
                    r.code,
                    r.variant,
                    r.wall_us,
                    r.cpu_us
                ),
                Some(e) => tracing::warn!("bench mpm:   taichi {}, {threads} thread(s): FAILED: {e}", r.variant),
            }
            runs.push(r);
        }
    }
    Ok((runs, loaded))
}

/// `mpm.csv` (one row per run) and `mpm.jsonl` (each run's raw figures).
fn write_data(out: &Path, results: &[(&Case, Vec<Run>)]) -> anyhow::Result<()> {
    let mut csv = String::from(
        "case,dim,points,code,variant,threads,steps,wall_us_per_point_step,cpu_us_per_point_step,share_p2g,share_grid,share_g2p,share_constitutive,finite_in_box,other_load_cores\n",
    );
    let mut jsonl = String::new();
    for (case, runs) in results {
        for r in runs {
            let s = r.shares.map(|s| s.map_or(String::new(), |s| format!("{s:.4}")));
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{},{},{:.5},{:.5},{},{},{},{},{},{:.2}",
                case.name,
                case.dim,
                case.point_count(),
                r.code,
                r.variant,
                r.threads,
                r.steps,
                r.wall_us,
                r.cpu_us,
                s[0],
                s[1],
                s[2],
                s[3],
                r.sane,
                r.load
            );
            let mut raw = r.raw.clone();
            raw["case"] = json!(case.name);
            raw["other_load_cores"] = json!(r.load);
            let _ = writeln!(jsonl, "{raw}");
        }
    }
    outputs::write_atomic(&out.join("mpm.csv"), csv.as_bytes())?;
    outputs::write_atomic(&out.join("mpm.jsonl"), jsonl.as_bytes())?;
    Ok(())
}

fn report(args: &MpmArgs, results: &[(&Case, Vec<Run>)], loaded: bool) -> String {
    let (lambda, mu) = lame();
    let mut t = String::new();
    let _ = writeln!(
        t,
        "µs per point-step of the timed loop, wall and process CPU (all threads); sand block collapsing in the unit box, \
         quadratic B-splines, {PPC_1D}^d points per cell, dt = {CFL} h / c_p, {} warm-up + {} pre-steps + max(5, steps/10) untimed steps \
         in both codes; same session. Machine: {} cores{}. 'other load': cores other processes kept busy during the run \
         (machine busy time minus the run's own CPU time, per second; for Taichi over its whole process, JIT included).\n",
        args.warmup.max(1),
        args.pre_steps,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        if loaded {
            ", some runs started while other processes kept it busy"
        } else {
            ""
        }
    );
    t.push_str("| case | points | code | threads | steps | wall µs/pt-step | CPU µs/pt-step | Taichi PIC/FLIP f64 ÷ this, wall (CPU) | speed-up 2/1 threads, wall | P2G | grid | G2P | constitutive | other load |\n");
    t.push_str("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let mut targets = String::new();
    for (case, runs) in results {
        table_rows(&mut t, case, runs);
        target_lines(&mut targets, case, runs);
    }
    t.push_str("\nTargets (issue): 1 thread ≥ 1.5× faster than Taichi PIC/FLIP f64 (≤ 0.18 µs/pt-step in 2D, ≤ 1.1 in 3D), 2 threads ≥ 1.8× faster than 1 on the largest case.\n\n");
    t.push_str(&targets);

    t.push_str("\nWhere grains' time goes, µs per point-step (1 thread / 2 threads, wall):\n\n| case | P2G | grid | G2P | constitutive | sum of phases | loop |\n|---|---:|---:|---:|---:|---:|---:|\n");
    for (case, runs) in results {
        let g: Vec<&Run> = runs.iter().filter(|r| r.is_grains() && r.failed.is_none()).collect();
        if g.is_empty() {
            let _ = writeln!(t, "| {} | (no grains run finished) | | | | | |", case.name);
            continue;
        }
        let ph = |r: &Run, k: &str| r.raw["phase_us_per_particle_step"][k].as_f64().unwrap_or(f64::NAN);
        let cell = |k: &str| g.iter().map(|r| format!("{:.4}", ph(r, k))).collect::<Vec<_>>().join(" / ");
        let sum = g
            .iter()
            .map(|r| {
                format!(
                    "{:.4}",
                    ["p2g", "grid", "g2p", "constitutive"].iter().map(|k| ph(r, k)).sum::<f64>()
                )
            })
            .collect::<Vec<_>>()
            .join(" / ");
        let wall = g.iter().map(|r| format!("{:.4}", r.wall_us)).collect::<Vec<_>>().join(" / ");
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {sum} | {wall} |",
            case.name,
            cell("p2g"),
            cell("grid"),
            cell("g2p"),
            cell("constitutive")
        );
    }

    t.push_str("\nFinal block extent (after all steps; 1-thread runs; both codes should agree closely):\n\n| case | grains | Taichi PIC/FLIP f64 |\n|---|---|---|\n");
    for (case, runs) in results {
        let g = runs.iter().find(|r| r.is_grains() && r.threads == 1);
        let p = runs
            .iter()
            .find(|r| !r.is_grains() && r.threads == 1 && r.variant.starts_with("PIC"));
        let _ = writeln!(
            t,
            "| {} | {} | {} |",
            case.name,
            fmt_extent(&g.and_then(|r| r.extent.clone())),
            fmt_extent(&p.and_then(|r| r.extent.clone()))
        );
    }

    let (k2, k3) = (model(2).bulk, model(3).bulk);
    let _ = write!(
        t,
        "\nSetup: E = {YOUNG:e} Pa, ν = {POISSON}, ρ = {DENSITY} kg/m³ (λ = {lambda:.4e}, μ = {mu:.4e} Pa), friction angle {FRICTION_DEG}°, \
         gravity {GRAVITY} m/s² on axis 1, h = 1/n, dt = {CFL} h / √((λ + 2μ)/ρ) (2D {:.4e} s, 3D {:.4e} s), PIC/FLIP {FLIP}, f64, \
         sticky walls {BOUND} nodes thick, the peer's block and jittered lattice (own random sequence).\n\
         grains' model: Hencky critical state with χ = 0 (constant friction, no dilation), Φ = Φ_cs = {PACKING}, no cohesion, \
         G = μ; K = λ + μ = {k2:.4e} Pa in 2D (plane strain, so that τ = λ tr ε I + 2μ ε as in the peer) and \
         K = E/(3(1 − 2ν)) = {k3:.4e} Pa in 3D.\n\
         Differences that remain: (1) grains' grid `Grid::covering([0,0,0], [1,1,1], h)` has n + 1 nodes per axis (257², 65³), \
         the peer's n (256², 64³), and grains stores only the 4^d node blocks the points touch (sparse) where the peer clears \
         and updates its whole dense grid every step; (2) the yield cone: the peer's Drucker–Prager (Klar et al. 2016) uses \
         α = √(2/3) · 2 sin φ/(3 − sin φ) in 2D and 3D, grains the Mohr–Coulomb compression-corner cone in 3D and sin φ \
         (plane Mohr–Coulomb) in 2D, both non-dilatant, stress-free in extension; (3) the peer's sticky wall zeroes a \
         node's velocity only while it moves into the wall, grains' zeroes it always; (4) the peer updates F and the stress \
         at the start of P2G (so its P2G share includes the constitutive update and its 'grid' share includes clearing the \
         grid), grains at the end of the step; (5) point order: lattice order in each code's node order (grains axis 0 \
         fastest, the peer last axis fastest); (6) CPU time of 2-thread runs includes the pools' spin-waiting.\n",
        peer_dt(1.0 / 256.0),
        peer_dt(1.0 / 64.0),
    );
    t
}

/// The grains or Taichi run of a case with `variant` on `threads`, if it did not fail.
fn find<'a>(runs: &'a [Run], grains: bool, variant: &str, threads: usize) -> Option<&'a Run> {
    runs.iter()
        .find(|r| r.is_grains() == grains && r.variant == variant && r.threads == threads && r.failed.is_none())
}

/// One table row per run of a case.
fn table_rows(t: &mut String, case: &Case, runs: &[Run]) {
    let find = |grains: bool, variant: &str, threads: usize| find(runs, grains, variant, threads);
    for r in runs {
        let ratio = if r.is_grains() {
            find(false, "PIC/FLIP 0.95 f64", r.threads).map_or("–".into(), |p| {
                format!("{:.2}× ({:.2}×)", p.wall_us / r.wall_us, p.cpu_us / r.cpu_us)
            })
        } else {
            "–".into()
        };
        let speedup = if r.threads == 2 {
            find(r.is_grains(), r.variant, 1).map_or("–".into(), |one| format!("{:.2}×", one.wall_us / r.wall_us))
        } else {
            "–".into()
        };
        let constitutive = if r.is_grains() { pct(r.shares[3]) } else { "(in P2G)".into() };
        let code = if r.is_grains() {
            format!("grains {}", r.variant)
        } else {
            format!("{} {}", r.code, r.variant)
        };
        if let Some(e) = &r.failed {
            let _ = writeln!(
                t,
                "| {} | {} | {code} | {} | {} | failed: {} | | | | | | | | – |",
                case.name,
                case.point_count(),
                r.threads,
                r.steps,
                e.replace('|', "/"),
            );
            continue;
        }
        let _ = writeln!(
            t,
            "| {} | {} | {code} | {} | {} | {:.4} | {:.4} | {ratio} | {speedup} | {} | {} | {} | {constitutive} | {:.2} |{}",
            case.name,
            case.point_count(),
            r.threads,
            r.steps,
            r.wall_us,
            r.cpu_us,
            pct(r.shares[0]),
            pct(r.shares[1]),
            pct(r.shares[2]),
            r.load,
            if r.sane { "" } else { " NOT FINITE / LEFT THE BOX" }
        );
    }
}

/// Whether the case met the targets.
fn target_lines(targets: &mut String, case: &Case, runs: &[Run]) {
    let find = |grains: bool, variant: &str, threads: usize| find(runs, grains, variant, threads);
    // The targets: ≥ 1.5× Taichi PIC/FLIP f64 on 1 thread (≤ 0.18 µs in 2D, ≤ 1.1 µs
    // in 3D), ≥ 1.8× from 2 threads on the largest case.
    if let Some(g1) = find(true, "PIC/FLIP 0.95 f64", 1) {
        let limit = if case.dim == 2 { 0.18 } else { 1.1 };
        let peer = find(false, "PIC/FLIP 0.95 f64", 1).map_or(String::new(), |p| {
            let x = p.wall_us / g1.wall_us;
            format!(", {x:.2}× Taichi here (≥ 1.5×: {})", if x >= 1.5 { "met" } else { "not met" })
        });
        let _ = writeln!(
            targets,
            "- {}: grains 1 thread {:.3} µs/pt-step wall (≤ {limit}: {}){peer}",
            case.name,
            g1.wall_us,
            if g1.wall_us <= limit { "met" } else { "not met" }
        );
        if case.name == "3d-1.1m"
            && let Some(g2) = find(true, "PIC/FLIP 0.95 f64", 2)
        {
            let s = g1.wall_us / g2.wall_us;
            let _ = writeln!(
                targets,
                "- {}: grains 2 threads ÷ 1 thread {s:.2}× wall (≥ 1.8×: {})",
                case.name,
                if s >= 1.8 { "met" } else { "not met" }
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use grains_grid::Space;

    #[test]
    fn cases_reproduce_the_peer_point_counts_and_time_step() {
        for c in &CASES {
            assert_eq!(c.point_count(), c.points, "{}", c.name);
        }
        // The peer's fills: 150/250, 238/250, 29/58, 52/58 cells.
        assert_eq!(CASES.map(|c| c.cells()[0]), [150, 238, 29, 52]);
        for dim in [2, 3] {
            let m = Model::CriticalState(model(dim));
            let dt = CFL * cfl_time_step(&m, DENSITY, 0.01, dim);
            assert!((dt / peer_dt(0.01) - 1.0).abs() < 1e-12, "{dim}D: {dt} vs {}", peer_dt(0.01));
        }
    }

    #[test]
    fn the_block_sits_on_the_floor_centred_across() {
        let case = Case {
            name: "t",
            dim: 2,
            n_grid: 32,
            fill: 0.5,
            points: 0,
            steps: 1,
        };
        let pts = block::<D2>(&case);
        assert_eq!(pts.len(), case.point_count());
        let (e, ok) = extent_of(pts.x.iter().map(|&x| D2::to_array(x)), 2);
        let h = case.h();
        let cells = case.cells()[0] as f64;
        assert!(ok);
        // Lattice spacing h/2, jitter ±h/8: first point within [h/8, 3h/8] of the block's edge.
        assert!(e[1][0] >= 3.0 * h + h / 8.0 - 1e-12 && e[1][0] <= 3.0 * h + 3.0 * h / 8.0);
        assert!(((e[0][0] + e[0][1]) / 2.0 - 0.5).abs() < h / 4.0);
        assert!(e[0][1] - e[0][0] <= cells * h && e[0][1] - e[0][0] >= cells * h - h / 2.0);
    }
}
