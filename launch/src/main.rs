mod cli;

use clap::Parser;
use cli::{BenchCmd, Cli, Cmd};
use grains_launch::{bench, remote, run, validate};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    grains_service::telemetry::init("grains");
    let result = match cli.command {
        Cmd::Run(args) => finish_run(run::run(&args.options())),
        Cmd::Resume(args) => finish_run(run::run(&args.options())),
        Cmd::Monitor { run, rows, remote } => remote
            .endpoint()
            .and_then(|ep| grains_bridge::client::monitor(&ep, &run, rows, &mut std::io::stdout().lock()))
            .map(|()| 0),
        Cmd::Steer { run, command, remote } => remote::steer(&remote, &run, &command),
        Cmd::Runs { remote } => remote::list_runs(&remote),
        Cmd::Pack(args) => grains_launch::pack::pack(&args).map(|()| 0),
        Cmd::Calibrate(args) => grains_launch::calibrate::calibrate(&args).map(|()| 0),
        Cmd::Check { scene } => run::check(&scene).map(|()| 0),
        Cmd::Render(args) => grains_launch::render::render(&args).map(|paths| {
            for p in paths {
                println!("{}", p.display());
            }
            0
        }),
        Cmd::Validate(args) => validate::validate(&args).map(|ok| if ok { 0 } else { 1 }),
        Cmd::Bench { what: BenchCmd::Ipc(args) } => bench::ipc::ipc(&args).map(|()| 0),
        Cmd::Bench { what: BenchCmd::Dem(args) } => bench::dem::dem(&args).map(|()| 0),
        Cmd::Bench {
            what: BenchCmd::Hybrid(args),
        } => bench::hybrid::bench(&args).map(|()| 0),
        Cmd::Bench { what: BenchCmd::Mpm(args) } => bench::mpm::mpm(&args).map(|()| 0),
        Cmd::Bench {
            what: BenchCmd::Chute(args),
        } => bench::chute::bench(&args).map(|()| 0),
        Cmd::Bench {
            what: BenchCmd::Bridge(args),
        } => bench::bridge::bench(&args).map(|()| 0),
        Cmd::Bench {
            what: BenchCmd::StalledClient { remote },
        } => remote
            .endpoint()
            .and_then(|ep| grains_bridge::client::stalled_viewer(&ep, std::time::Duration::from_secs(60)))
            .map(|never| match never {}),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(err) => {
            tracing::error!("{err:#}");
            ExitCode::from(grains_launch::exit_code(&err))
        }
    }
}

/// How a run (or a resumed one) ended, said once; its exit code.
fn finish_run(outcome: anyhow::Result<run::RunOutcome>) -> anyhow::Result<u8> {
    outcome.map(|o| {
        tracing::info!(
            "run {} {}: {} (output in {})",
            o.run_id,
            o.status.as_str(),
            o.message,
            o.dir.display()
        );
        o.status.exit_code()
    })
}
