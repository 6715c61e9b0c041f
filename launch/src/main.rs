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
        /// Open the run to remote clients over zenoh (grains monitor, grains steer; see README).
        #[arg(long)]
        bridge: bool,
        #[command(flatten)]
        bridge_args: grains_bridge::config::BridgeArgs,
    },
    /// Live table of a run's summaries, from its bridge (here or on another machine).
    Monitor {
        /// Run id (see `grains runs`).
        #[arg(long)]
        run: String,
        /// Stop after this many rows.
        #[arg(long)]
        rows: Option<u64>,
        #[command(flatten)]
        remote: Remote,
    },
    /// Send a command to a run through its bridge: pause, resume, stop, snapshot, or
    /// `set KEY VALUE`; prints the step at which it took effect, or why it was refused.
    Steer {
        /// Run id (see `grains runs`).
        #[arg(long)]
        run: String,
        /// pause | resume | stop | snapshot | set KEY VALUE
        #[arg(required = true, num_args = 1..=3, allow_hyphen_values = true)]
        command: Vec<String>,
        #[command(flatten)]
        remote: Remote,
    },
    /// List the runs whose bridge answers at an endpoint.
    Runs {
        #[command(flatten)]
        remote: Remote,
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

/// Where the bridge is and who asks.
#[derive(clap::Args)]
struct Remote {
    /// The bridge's zenoh endpoint.
    #[arg(long, default_value = grains_bridge::config::DEFAULT_LISTEN)]
    connect: String,
    /// User name, if the bridge requires credentials; the password is read from the
    /// environment variable GRAINS_BRIDGE_PASSWORD.
    #[arg(long)]
    user: Option<String>,
}

impl Remote {
    fn endpoint(&self) -> anyhow::Result<grains_bridge::client::Endpoint> {
        let credentials = match &self.user {
            Some(u) => {
                let p = std::env::var("GRAINS_BRIDGE_PASSWORD")
                    .map_err(|_| anyhow::anyhow!("--user {u}: set the password in the environment variable GRAINS_BRIDGE_PASSWORD"))?;
                Some((u.clone(), p))
            }
            None => None,
        };
        Ok(grains_bridge::client::Endpoint {
            connect: self.connect.clone(),
            credentials,
        })
    }
}

/// `grains steer` words as the JSON command the bridge takes.
fn command_json(words: &[String]) -> anyhow::Result<String> {
    match words {
        [c] => Ok(serde_json::json!({ "command": c }).to_string()),
        [set, key, value] if set == "set" => {
            let v: f64 = value.parse().map_err(|_| anyhow::anyhow!("set {key}: {value:?} is not a number"))?;
            Ok(serde_json::json!({ "command": "set", "key": key, "value": v }).to_string())
        }
        _ => anyhow::bail!("expected pause, resume, stop, snapshot or set KEY VALUE; got {:?}", words.join(" ")),
    }
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
            bridge,
            bridge_args,
        } => {
            let opts = RunOptions {
                scene_path: scene,
                transport,
                external,
                out_root: out,
                progress: !quiet,
                overrides,
                announce: true,
                bridge: bridge.then_some(bridge_args),
            };
            grains_launch::run::run(&opts).map(|o| {
                eprintln!(
                    "grains: run {} {}: {} (output in {})",
                    o.run_id,
                    match o.status {
                        grains_launch::run::Status::Completed => "completed",
                        grains_launch::run::Status::Stopped => "stopped",
                        _ => "ended",
                    },
                    o.message,
                    o.dir.display()
                );
                o.status.exit_code()
            })
        }
        Cmd::Monitor { run, rows, remote } => remote
            .endpoint()
            .and_then(|ep| grains_bridge::client::monitor(&ep, &run, rows, &mut std::io::stdout().lock()))
            .map(|()| 0),
        Cmd::Steer { run, command, remote } => (|| {
            let json = command_json(&command)?;
            match grains_bridge::client::steer(&remote.endpoint()?, &run, json.as_bytes())? {
                Ok(ack) => {
                    println!("{ack}");
                    Ok(0)
                }
                Err(why) => {
                    eprintln!("grains: steer: refused: {why}");
                    Ok(1)
                }
            }
        })(),
        Cmd::Runs { remote } => remote.endpoint().and_then(|ep| {
            let runs = grains_bridge::client::runs(&ep, std::time::Duration::from_secs(2))?;
            if runs.is_empty() {
                println!("no run answers at {}", ep.connect);
            }
            for (id, latest) in runs {
                match latest {
                    Some(v) => println!(
                        "{id}  scene {}  step {}/{}  t = {:.4e} s{}",
                        v["scene"].as_str().unwrap_or("?"),
                        v["step"],
                        v["steps"],
                        v["time"].as_f64().unwrap_or(0.0),
                        if v["paused"].as_bool() == Some(true) { "  (paused)" } else { "" }
                    ),
                    None => println!("{id}  (no step yet)"),
                }
            }
            Ok(0)
        }),
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
