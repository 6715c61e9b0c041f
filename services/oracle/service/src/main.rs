use clap::Parser;
use std::process::ExitCode;

/// The grains oracle: publishes the zone field of a hybrid run (which grid cells are discrete,
/// hybrid or continuum). Started by `grains run`; start it by hand to attach to a run waiting
/// for an external oracle (`grains run <scene> --external oracle`).
#[derive(Parser)]
#[command(name = "grains-oracle", version)]
struct Cli {
    #[command(flatten)]
    common: grains_service::cli::CommonArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::participant_main(
        grains_protocol::Role::Oracle,
        &cli.common,
        &grains_oracle_service::run::<grains_transport::ipc::Iceoryx2>,
        &grains_oracle_service::run::<grains_transport::zenoh::Zenoh>,
    )
}
