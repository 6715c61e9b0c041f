use clap::Parser;
use std::process::ExitCode;

/// The grains MPM participant. Started by `grains run`; start it by hand to attach to a run
/// waiting for an external mpm (`grains run <scene> --external mpm`).
#[derive(Parser)]
#[command(name = "grains-mpm", version)]
struct Cli {
    #[command(flatten)]
    common: grains_service::cli::CommonArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::participant_main(
        grains_protocol::Role::Mpm,
        &cli.common,
        &grains_mpm_service::run::<grains_transport::ipc::Iceoryx2>,
        &grains_mpm_service::run::<grains_transport::zenoh::Zenoh>,
    )
}
