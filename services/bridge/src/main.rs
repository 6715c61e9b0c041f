use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;

/// The grains bridge: publishes a run's state over zenoh and forwards remote commands.
/// Started by `grains run --bridge`; start it by hand to open a running run to remote
/// clients.
#[derive(Parser)]
#[command(name = "grains-bridge", version)]
struct Cli {
    /// Scene file of the run.
    #[arg(long)]
    scene: PathBuf,
    /// Run id to serve.
    #[arg(long)]
    run_id: String,
    /// The run's output directory (`bridge.json` goes there).
    #[arg(long)]
    out_dir: Option<PathBuf>,
    /// The scene's name as the launcher knows it (the run's copy of the scene is `scene.toml`).
    #[arg(long)]
    scene_name: Option<String>,
    /// Read the run over zenoh, as a client of the launcher's router at this endpoint (a run
    /// of `grains run --transport zenoh`), instead of over iceoryx2.
    #[arg(long, value_name = "ENDPOINT")]
    zenoh: Option<String>,
    #[command(flatten)]
    bridge: grains_bridge::config::BridgeArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::telemetry::init(grains_protocol::Role::Bridge.binary());
    let run = || -> anyhow::Result<()> {
        let cfg = cli.bridge.resolve()?;
        let mut scene = grains_protocol::scene::load(&cli.scene)?;
        if let Some(name) = &cli.scene_name {
            scene.name = name.clone();
        }
        let stop = grains_service::signals::StopFlag::with_signals();
        let name = grains_protocol::Role::Bridge.binary();
        match &cli.zenoh {
            None => {
                let transport = grains_transport::ipc::Iceoryx2::join(&cli.run_id, name, stop.as_cancel())?;
                grains_bridge::serve(&transport, &cfg, &cli.run_id, &scene, cli.out_dir.as_deref(), &stop)
            }
            Some(endpoint) => {
                let transport = grains_transport::zenoh::Zenoh::client(&cli.run_id, name, endpoint)?;
                grains_bridge::serve(&transport, &cfg, &cli.run_id, &scene, cli.out_dir.as_deref(), &stop)
            }
        }
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            tracing::error!("{err:#}");
            ExitCode::FAILURE
        }
    }
}
