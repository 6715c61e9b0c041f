//! The command line of `grains` (clap derive); `main.rs` dispatches it.

use clap::{Parser, Subcommand};
use grains_launch::remote::Remote;
use grains_launch::run::TransportKind;
use grains_protocol::Role;
use std::path::PathBuf;

/// grains: hybrid discrete–continuum simulation of granular media.
#[derive(Parser)]
#[command(name = "grains", version)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Cmd,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// Run a scene: start its participants, show progress, write out/<scene>/<run-id>/.
    Run(RunArgs),
    /// Continue a run that stopped (killed, interrupted, failed) from its last complete
    /// checkpoint, in its own directory: physics and frames as if it had never stopped.
    Resume(ResumeArgs),
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
    /// Send a command to a run through its bridge: pause, resume, stop, snapshot, checkpoint,
    /// or `set KEY VALUE`; prints the step at which it took effect, or why it was refused.
    Steer {
        /// Run id (see `grains runs`).
        #[arg(long)]
        run: String,
        /// pause | resume | stop | snapshot | checkpoint | set KEY VALUE
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
    /// The continuum's friction angle and stiffness of a hybrid scene from a DEM biaxial test
    /// of its grains; `--write` records them, with their provenance, in the scene.
    Calibrate(grains_launch::calibrate::CalibrateArgs),
    /// Draw a frame of a run to PNG (grains as disks of their radius, material points as dots).
    Render(grains_launch::render::RenderArgs),
    /// Check a scene file and print what a run of it would start.
    Check { scene: PathBuf },
    /// Validation against reference results: report, pictures, non-zero exit on a failed check.
    Validate(grains_launch::validate::ValidateArgs),
    /// Benchmarks that print tables.
    Bench {
        #[command(subcommand)]
        what: BenchCmd,
    },
}

#[derive(clap::Args)]
pub struct RunArgs {
    /// Scene file (TOML, schema v1; see scenes/README.md).
    pub scene: PathBuf,
    #[command(flatten)]
    pub launch: LaunchArgs,
    /// Root of the output directories.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Override a scene value before validation, e.g. `--set coupling.substeps=20` or
    /// `--set body.0.max=[0.04,0.08]` (repeatable; values in TOML syntax).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Checkpoint every N macro-steps into <run dir>/checkpoints/ (`grains resume` continues
    /// from the last); the same as `--set output.checkpoint_every=N`.
    #[arg(long, value_name = "N")]
    pub checkpoint_every: Option<u64>,
}

/// How a run (new or resumed) is launched: its transport, the participants left to attach,
/// progress, the bridge.
#[derive(clap::Args)]
pub struct LaunchArgs {
    /// How participants run and talk.
    #[arg(long, value_enum, default_value_t = TransportKind::Ipc)]
    pub transport: TransportKind,
    /// Start everything but this participant and wait for it to attach (repeatable).
    #[arg(long, value_parser = parse_role)]
    pub external: Vec<Role>,
    /// With `--transport zenoh`: the endpoint the launcher listens on, e.g.
    /// `tcp/192.168.1.10:7450` for a participant on another host (default: a free loopback port).
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh_listen: Option<String>,
    /// No live progress line.
    #[arg(long)]
    pub quiet: bool,
    /// Open the run to remote clients over zenoh (grains monitor, grains steer; see README).
    #[arg(long)]
    pub bridge: bool,
    #[command(flatten)]
    pub bridge_args: grains_bridge::config::BridgeArgs,
}

impl LaunchArgs {
    /// The options of a run of `scene_path` with `overrides`, or of the run in `resume`.
    fn options(
        self,
        scene_path: PathBuf,
        out_root: PathBuf,
        overrides: Vec<String>,
        resume: Option<PathBuf>,
    ) -> grains_launch::run::RunOptions {
        grains_launch::run::RunOptions {
            scene_path,
            transport: self.transport,
            external: self.external,
            out_root,
            progress: !self.quiet,
            overrides,
            announce: true,
            bridge: self.bridge.then_some(self.bridge_args),
            resume,
            zenoh_listen: self.zenoh_listen,
        }
    }
}

impl RunArgs {
    pub fn options(self) -> grains_launch::run::RunOptions {
        let mut overrides = self.overrides;
        if let Some(n) = self.checkpoint_every {
            overrides.push(format!("output.checkpoint_every={n}"));
        }
        self.launch.options(self.scene, self.out, overrides, None)
    }
}

#[derive(clap::Args)]
pub struct ResumeArgs {
    /// The run's directory (out/<scene>/<run id>).
    pub run_dir: PathBuf,
    #[command(flatten)]
    pub launch: LaunchArgs,
}

impl ResumeArgs {
    pub fn options(self) -> grains_launch::run::RunOptions {
        let scene = self.run_dir.join("scene.toml");
        self.launch.options(scene, PathBuf::new(), Vec::new(), Some(self.run_dir))
    }
}

#[derive(Subcommand)]
pub enum BenchCmd {
    /// Per-macro-step exchange time, iceoryx2 processes vs in-process threads.
    Ipc(grains_launch::bench::ipc::IpcArgs),
    /// DEM µs per grain-step on dense beds, side by side with LAMMPS.
    Dem(grains_launch::bench::dem::DemArgs),
    /// Hybrid vs pure DEM column collapse at 100,000 grains; processes vs threads.
    Hybrid(grains_launch::bench::hybrid::HybridArgs),
    /// MPM µs per point-step of a collapsing sand block, side by side with Taichi.
    Mpm(grains_launch::bench::mpm::MpmArgs),
    /// Yue 2018 §5's speed-up study: the periodic chute over grain size, DEM fraction and cell.
    Chute(grains_launch::bench::chute::ChuteArgs),
    /// What remote access costs a run: no bridge, a bridge, a client that never reads.
    Bridge(grains_launch::bench::bridge::BridgeArgs),
    /// The client that never reads, for `bench bridge` (a process of its own).
    #[command(hide = true)]
    StalledClient {
        #[command(flatten)]
        remote: grains_launch::remote::Remote,
    },
}

fn parse_role(s: &str) -> Result<Role, String> {
    Role::from_name(s)
        .filter(|r| Role::PARTICIPANTS.contains(r))
        .ok_or_else(|| format!("{s:?} is not a participant; one of: dem, mpm, coupler, oracle"))
}
