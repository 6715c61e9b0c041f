//! `grains bench dem`: DEM cost per grain-step on the dense beds of `shared/peers/dem`, side
//! by side with LAMMPS in the same session, on the same LAMMPS data files.
//!
//! The beds are built once by `launch/bench/dem_packings.sh` (LAMMPS settles and shears them;
//! LAMMPS is installed from Debian if missing) and cached. Every case then runs: grains with 1
//! and 2 threads (in this process), and LAMMPS `gran/hooke/history` (its fastest granular
//! style) and `granular ... damping velocity` (the same contact law as grains) on one rank,
//! each with 300 untimed warm-up steps. Figures: CPU and wall µs per grain-step of the timed
//! loop, grains counted with their frozen base as LAMMPS counts atoms.

use super::machine::cpu_seconds;
use anyhow::{Context, bail};
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, D3, Space};
use grains_dem::state::{DemParams, DemState, Domain, Grains};
use grains_dem_service::lammps_data::{self, DataFile};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

#[derive(Debug, Clone, clap::Args)]
pub struct DemArgs {
    /// The peer decks and packing generator (shared/peers/dem).
    #[arg(long, default_value = "../shared/peers/dem")]
    pub peers: PathBuf,
    /// Where the beds, logs and the result table go.
    #[arg(long, default_value = "out/bench/dem")]
    pub out: PathBuf,
    /// Cases to run (default: all): 3d-static-20k, 3d-static-100k, 3d-flow-20k, 3d-flow-100k,
    /// 2d-static-10k, 2d-static-50k, 2d-flow-10k, 2d-flow-50k.
    #[arg(long, value_delimiter = ',')]
    pub cases: Vec<String>,
    /// Multiply the timed steps of every case (e.g. 0.1 for a quick look).
    #[arg(long, default_value_t = 1.0)]
    pub steps_scale: f64,
    /// Run grains only.
    #[arg(long)]
    pub no_lammps: bool,
}

struct Case {
    name: &'static str,
    dim: usize,
    file: &'static str,
    replicate: usize,
    steps: u64,
    flow: bool,
}

const CASES: [Case; 8] = [
    Case {
        name: "3d-static-20k",
        dim: 3,
        file: "static_20k.data",
        replicate: 1,
        steps: 3000,
        flow: false,
    },
    Case {
        name: "3d-static-100k",
        dim: 3,
        file: "static_100k.data",
        replicate: 1,
        steps: 800,
        flow: false,
    },
    Case {
        name: "3d-flow-20k",
        dim: 3,
        file: "flow_20k.data",
        replicate: 1,
        steps: 3000,
        flow: true,
    },
    Case {
        name: "3d-flow-100k",
        dim: 3,
        file: "flow_100k.data",
        replicate: 1,
        steps: 800,
        flow: true,
    },
    Case {
        name: "2d-static-10k",
        dim: 2,
        file: "static_2d_10k.data",
        replicate: 1,
        steps: 5000,
        flow: false,
    },
    Case {
        name: "2d-static-50k",
        dim: 2,
        file: "static_2d_10k.data",
        replicate: 5,
        steps: 1200,
        flow: false,
    },
    Case {
        name: "2d-flow-10k",
        dim: 2,
        file: "flow_2d_10k.data",
        replicate: 1,
        steps: 5000,
        flow: true,
    },
    Case {
        name: "2d-flow-50k",
        dim: 2,
        file: "flow_2d_10k.data",
        replicate: 5,
        steps: 1200,
        flow: true,
    },
];

const WARM: u64 = 300;
const DT: f64 = 5e-7;
const SKIN: f64 = 1e-4;

/// The contact law of the peers' decks: Chen 2021 Table 1 in 2D (per metre), its 3D
/// equivalent with the same contact time and restitution in 3D; constant viscous damping.
fn params(dim: usize) -> ContactParams {
    if dim == 3 {
        ContactParams {
            stiffness_normal: 1181.40,
            stiffness_tangential: 590.70,
            damping: Damping::Viscous(4.6667e-3),
            friction: 0.5,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
            damping_scale: 1.0,
        }
    } else {
        ContactParams {
            stiffness_normal: 1772093.8,
            stiffness_tangential: 886046.9,
            damping: Damping::Viscous(7.0),
            friction: 0.5,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
            damping_scale: 1.0,
        }
    }
}

/// A bed as the decks set it up: x (and y in 3D) periodic, type-2 grains frozen, gravity
/// vertical (static) or tilted 30° along +x (flow); 2D masses per metre (`density/disc`).
fn state_from<S: Space>(data: &DataFile, flow: bool) -> DemState<S> {
    let dim = S::DIM;
    let up = dim - 1;
    let mut g = [0.0; 3];
    if flow {
        g[0] = 0.5 * 9.81;
        g[up] = -0.866_025_4 * 9.81;
    } else {
        g[up] = -9.81;
    }
    let mut periodic = [false; 3];
    periodic[0] = true;
    if dim == 3 {
        periodic[1] = true;
    }
    let mut min = [0.0; 3];
    let mut max = [0.0; 3];
    for k in 0..3 {
        min[k] = data.bounds[k][0];
        max[k] = data.bounds[k][1];
    }
    let mut st = DemState::<S> {
        grains: Grains::default(),
        bodies: Vec::new(),
        walls: Vec::new(),
        params: DemParams {
            materials: vec![params(dim)],
            gravity: S::from_array(g),
            domain: Domain { min, max, periodic },
            skin: SKIN,
        },
        time: 0.0,
    };
    for a in &data.atoms {
        let r = 0.5 * a.diameter;
        let mass = if dim == 2 {
            2530.0 * std::f64::consts::PI * r * r
        } else {
            a.density * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3)
        };
        let i = st.grains.push(a.id, S::from_array(a.x), r, mass, 0);
        if a.kind == 2 {
            st.grains.frozen[i] = true;
        } else {
            st.grains.v[i] = S::from_array(a.v);
        }
    }
    st
}

struct Figure {
    cpu_us: f64,
    wall_us: f64,
}

fn run_grains<S: Space>(data: &DataFile, flow: bool, threads: usize, steps: u64) -> anyhow::Result<Figure> {
    let mut st = state_from::<S>(data, flow);
    let mut pipe = DemPipeline::<S>::new(threads)?;
    pipe.run(&mut st, DT, WARM as usize);
    let (c0, w0) = (cpu_seconds(), Instant::now());
    pipe.run(&mut st, DT, steps as usize);
    let (cpu, wall) = (cpu_seconds() - c0, w0.elapsed().as_secs_f64());
    if let Some(id) = DemPipeline::first_non_finite(&st) {
        bail!("grains blew up on this bed (grain {id} not finite)");
    }
    let per = 1e6 / (steps as f64 * st.grains.len() as f64);
    Ok(Figure {
        cpu_us: cpu * per,
        wall_us: wall * per,
    })
}

/// Runs one LAMMPS deck and reads "Loop time of T on 1 procs for N steps with M atoms" and
/// the "% CPU use" of the timed (last) run from its log.
fn run_lammps(peers: &Path, beds: &Path, case: &Case, pair: &str, steps: u64) -> anyhow::Result<Figure> {
    let deck = peers.join(if case.dim == 3 {
        "dem_bench3d_lammps.in"
    } else {
        "dem_bench2d_lammps.in"
    });
    let log = beds.join(format!("lammps_{}_{pair}.log", case.name));
    let (gx, gv) = if case.flow { ("0.5", "-0.8660254") } else { ("0", "-1") };
    let mut cmd = Command::new("lmp");
    cmd.current_dir(beds)
        .env("OMP_NUM_THREADS", "1")
        .arg("-in")
        .arg(&deck)
        .arg("-log")
        .arg(&log)
        .arg("-screen")
        .arg("none");
    for (k, v) in [
        ("data", case.file.to_string()),
        ("pair", pair.into()),
        ("skin", SKIN.to_string()),
        ("warm", WARM.to_string()),
        ("steps", steps.to_string()),
        ("gx", gx.into()),
    ] {
        cmd.arg("-var").arg(k).arg(v);
    }
    if case.dim == 3 {
        cmd.arg("-var").arg("gz").arg(gv);
    } else {
        cmd.arg("-var")
            .arg("gy")
            .arg(gv)
            .arg("-var")
            .arg("nrep")
            .arg(case.replicate.to_string());
    }
    let status = cmd.status().context("running lmp")?;
    if !status.success() {
        bail!("LAMMPS failed on {} ({pair}); see {}", case.name, log.display());
    }
    let text = std::fs::read_to_string(&log)?;
    let loop_line = text
        .lines()
        .rev()
        .find(|l| l.starts_with("Loop time of"))
        .context("no 'Loop time' in the LAMMPS log")?;
    let f: Vec<&str> = loop_line.split_whitespace().collect();
    let (t, n, m): (f64, f64, f64) = (f[3].parse()?, f[8].parse()?, f[11].parse()?);
    let cpu_pct: f64 = text
        .lines()
        .rev()
        .find(|l| l.contains("% CPU use"))
        .and_then(|l| l.split('%').next())
        .and_then(|p| p.trim().parse().ok())
        .unwrap_or(100.0);
    let per = 1e6 / (n * m);
    Ok(Figure {
        cpu_us: t * cpu_pct / 100.0 * per,
        wall_us: t * per,
    })
}

pub fn dem(args: &DemArgs) -> anyhow::Result<()> {
    let beds = args.out.join("packings");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/dem_packings.sh");
    if !args.peers.join("gen_pack.py").exists() {
        bail!("{}: no peer decks there (pass --peers <shared/peers/dem>)", args.peers.display());
    }
    tracing::info!("bench dem: building or reusing the beds in {}", beds.display());
    let status = Command::new("bash")
        .arg(&script)
        .arg(&args.peers)
        .arg(&beds)
        .status()
        .context("running dem_packings.sh")?;
    if !status.success() {
        bail!("building the benchmark beds failed");
    }
    let peers = std::fs::canonicalize(&args.peers)?;
    let beds = std::fs::canonicalize(&beds)?;
    let mut rows = Vec::new();
    for case in CASES
        .iter()
        .filter(|c| args.cases.is_empty() || args.cases.iter().any(|n| n == c.name))
    {
        let steps = ((case.steps as f64 * args.steps_scale).round() as u64).max(10);
        let data = lammps_data::read(&beds.join(case.file)).map_err(anyhow::Error::msg)?;
        let data = if case.replicate > 1 {
            lammps_data::replicate_x(&data, case.replicate)
        } else {
            data
        };
        tracing::info!("bench dem: {} ({} grains, {steps} steps)", case.name, data.atoms.len());
        let run = |threads| {
            if case.dim == 3 {
                run_grains::<D3>(&data, case.flow, threads, steps)
            } else {
                run_grains::<D2>(&data, case.flow, threads, steps)
            }
        };
        let one = run(1)?;
        let two = run(2)?;
        let (hh, gr) = if args.no_lammps {
            (None, None)
        } else {
            (
                Some(run_lammps(&peers, &beds, case, "hh", steps)?),
                Some(run_lammps(&peers, &beds, case, "gr", steps)?),
            )
        };
        rows.push((case.name, data.atoms.len(), steps, one, two, hh, gr));
    }

    let cell = |f: &Option<Figure>| f.as_ref().map_or("–".to_string(), |f| format!("{:.3}", f.cpu_us));
    let mut out = String::new();
    out.push_str("CPU µs per grain-step of the timed loop (wall in brackets); same beds, same session; dt = 5e-7 s, skin 0.1 mm.\n\n");
    out.push_str("| case | grains | steps | grains 1 thread | grains 2 threads (wall) | speed-up 2/1 (wall) | LAMMPS gran/hooke/history | LAMMPS granular (same law) | hooke/history ÷ grains (CPU) |\n");
    out.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for (name, n, steps, one, two, hh, gr) in &rows {
        let ratio = hh.as_ref().map_or("–".to_string(), |h| format!("{:.2}×", h.cpu_us / one.cpu_us));
        out.push_str(&format!(
            "| {name} | {n} | {steps} | {:.3} ({:.3}) | ({:.3}) | {:.2}× | {} | {} | {ratio} |\n",
            one.cpu_us,
            one.wall_us,
            two.wall_us,
            one.wall_us / two.wall_us,
            cell(hh),
            cell(gr)
        ));
    }
    println!("{out}");
    std::fs::create_dir_all(&args.out)?;
    let path = args.out.join("dem.md");
    std::fs::File::create(&path)?.write_all(out.as_bytes())?;
    tracing::info!("bench dem: table written to {}", path.display());
    Ok(())
}
