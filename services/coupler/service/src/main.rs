use clap::Parser;
use std::process::ExitCode;

/// The grains coupler: owns time in a coupled run and constrains the node velocities of DEM
/// and MPM every macro-step. Started by `grains run`; start it by hand to attach to a run
/// waiting for an external coupler (`grains run <scene> --external coupler`).
#[derive(Parser)]
#[command(name = "grains-coupler", version)]
struct Cli {
    #[command(flatten)]
    common: grains_service::cli::CommonArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::participant_main(
        grains_protocol::Role::Coupler,
        &cli.common,
        &grains_coupler_service::run::<grains_transport::ipc::Iceoryx2>,
        &grains_coupler_service::run::<grains_transport::zenoh::Zenoh>,
    )
}
