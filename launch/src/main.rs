use clap::{Parser, Subcommand};
use grains_launch::run::{RunOptions, TransportKind};
use grains_protocol::Role;
use std::path::PathBuf;
use std::process::ExitCode;

/// grains: hybrid discrete–continuum simulation of granular media.
#[derive(Parser)]
#[command(name = "grains", version)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a scene: start its participants, show progress, write out/<scene>/<run-id>/.
    Run {
        /// Scene file (TOML, schema v1; see scenes/README.md).
        scene: PathBuf,
        /// How participants run and talk.
        #[arg(long, value_enum, default_value_t = TransportKind::Ipc)]
        transport: TransportKind,
        /// Start everything but this participant and wait for it to attach (repeatable).
        #[arg(long, value_parser = parse_role)]
        external: Vec<Role>,
        /// Root of the output directories.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// No live progress line.
        #[arg(long)]
        quiet: bool,
        /// Override a scene value before validation, e.g. `--set coupling.substeps=20` or
        /// `--set body.0.max=[0.04,0.08]` (repeatable; values in TOML syntax).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
    /// Pour and settle a DEM scene's grains; save the packing for scenes to reuse.
    Pack(grains_launch::pack::PackArgs),
    /// Check a scene file and print what a run of it would start.
    Check { scene: PathBuf },
    /// Validation against reference results: report, picture, non-zero exit on a failed check.
    Validate(grains_launch::validate::ValidateArgs),
    /// Benchmarks that print tables (ipc: transport cost per macro-step).
    Bench {
        #[command(subcommand)]
        what: BenchCmd,
    },
}

#[derive(Subcommand)]
enum BenchCmd {
    /// Per-macro-step exchange time, iceoryx2 processes vs in-process threads.
    Ipc(grains_launch::bench::IpcArgs),
    /// DEM µs per grain-step on dense beds, side by side with LAMMPS.
    Dem(grains_launch::bench_dem::DemArgs),
    /// Hybrid vs pure DEM column collapse at 100,000 grains; processes vs threads.
    Hybrid(grains_launch::bench_hybrid::HybridArgs),
    /// MPM µs per point-step of a collapsing sand block, side by side with Taichi.
    Mpm(grains_launch::bench_mpm::MpmArgs),
}

fn parse_role(s: &str) -> Result<Role, String> {
    Role::from_name(s)
        .filter(|r| Role::PARTICIPANTS.contains(r))
        .ok_or_else(|| format!("{s:?} is not a participant; one of: dem, mpm, coupler, oracle"))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Cmd::Run {
            scene,
            transport,
            external,
            out,
            quiet,
            overrides,
        } => {
            let opts = RunOptions {
                scene_path: scene,
                transport,
                external,
                out_root: out,
                progress: !quiet,
                overrides,
                announce: true,
            };
            grains_launch::run::run(&opts).map(|o| {
                eprintln!(
                    "grains: run {} {}: {} (output in {})",
                    o.run_id,
                    if o.status == grains_launch::run::Status::Completed {
                        "completed"
                    } else {
                        "ended"
                    },
                    o.message,
                    o.dir.display()
                );
                o.status.exit_code()
            })
        }
        Cmd::Pack(args) => grains_launch::pack::pack(&args).map(|()| 0),
        Cmd::Check { scene } => grains_protocol::scene::load(&scene).map_err(anyhow::Error::from).and_then(|s| {
            if s.synthetic.is_none() {
                grains_launch::run::check_physics(&s)?;
            }
            let roles: Vec<_> = s.participants().iter().map(|r| r.binary()).collect();
            println!(
                "{}: ok: scene {:?}, {}D, {} steps of {} s; starts {}",
                scene.display(),
                s.name,
                s.dim(),
                s.steps,
                s.dt,
                roles.join(", ")
            );
            Ok(0)
        }),
        Cmd::Validate(args) => grains_launch::validate::validate(&args).map(|ok| if ok { 0 } else { 1 }),
        Cmd::Bench { what: BenchCmd::Ipc(args) } => grains_launch::bench::ipc(&args).map(|()| 0),
        Cmd::Bench { what: BenchCmd::Dem(args) } => grains_launch::bench_dem::dem(&args).map(|()| 0),
        Cmd::Bench {
            what: BenchCmd::Hybrid(args),
        } => grains_launch::bench_hybrid::bench(&args).map(|()| 0),
        Cmd::Bench { what: BenchCmd::Mpm(args) } => grains_launch::bench_mpm::mpm(&args).map(|()| 0),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(err) => {
            eprintln!("grains: error: {err:#}");
            ExitCode::from(grains_launch::exit_code(&err))
        }
    }
}
