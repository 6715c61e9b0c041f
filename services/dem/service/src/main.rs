use clap::Parser;
use std::process::ExitCode;

/// The grains DEM participant. Started by `grains run`; start it by hand to attach to a run
/// waiting for an external dem (`grains run <scene> --external dem`).
#[derive(Parser)]
#[command(name = "grains-dem", version)]
struct Cli {
    #[command(flatten)]
    common: grains_service::cli::CommonArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::participant_main(
        grains_protocol::Role::Dem,
        &cli.common,
        &grains_dem_service::run::<grains_transport::ipc::Iceoryx2>,
        &grains_dem_service::run::<grains_transport::zenoh::Zenoh>,
    )
}
