//! What every grains participant shares, so that each service binary stays a thin loop:
//!
//! - [`session`]: joining a run (admission by the launcher, connection of every port, the
//!   start barrier), receiving with liveness checks, header checks;
//! - [`solver`]: the participant loop of a solver (DEM or MPM) behind the [`solver::Solver`]
//!   trait, which the physics services implement;
//! - [`synthetic`]: the synthetic solver of test scenes (issue 2), clearly apart from physics;
//! - [`grid`]: the scene's background grid and kernel, shared by the MPM and the DEM's rasters;
//! - [`zones`]: the layered zones of hybrid bodies (which grains and points exist, their weights);
//! - [`checkpoint`]: a participant's state written after a step, and read back to resume;
//! - [`vtu`]: VTU frames of point clouds (grains, material points) for ParaView;
//! - [`step_log`]: per-step CSV logs (walls' and bodies' loads) that a resumed run continues;
//! - [`signals`], [`cli`]: SIGINT/SIGTERM handling and the flags every binary shares;
//! - [`fault`]: fault injection from the environment (`GRAINS_FAULT`), read once, for the
//!   libraries to take as parameters.

pub mod checkpoint;
pub mod cli;
pub mod fault;
pub mod grid;
pub mod session;
pub mod signals;
pub mod solver;
pub mod step_log;
pub mod synthetic;
pub mod telemetry;
pub mod vtu;
pub mod zones;

/// Why a participant stopped without finishing; chooses the exit code.
#[derive(Debug, thiserror::Error)]
pub enum Halt {
    /// SIGINT/SIGTERM, or the launcher's stop flag (in-process runs).
    #[error("stopped by a signal or by the launcher")]
    Interrupted,
    /// The launcher refused this participant (protocol version, scene, role).
    #[error("{0}")]
    Refused(String),
    /// A peer of the run died.
    #[error("{0}")]
    PeerDied(String),
}

/// Exit code of a participant for an error: 2 bad input or refused, 130 interrupted, 1 else.
pub fn exit_code(err: &anyhow::Error) -> u8 {
    match err.downcast_ref::<Halt>() {
        Some(Halt::Interrupted) => 130,
        Some(Halt::Refused(_)) => 2,
        Some(Halt::PeerDied(_)) => 1,
        None if err.downcast_ref::<grains_protocol::scene::SceneError>().is_some() => 2,
        None => 1,
    }
}

/// The body of a participant over a transport (its service's `run::<T>`).
pub type Body<'a, T> = &'a dyn Fn(&T, &grains_protocol::scene::Scene, &solver::ParticipantOptions) -> anyhow::Result<()>;

/// The whole `main` of a participant binary: load the scene (exit 2 on bad input), join the
/// run's iceoryx2 domain (or, with `--zenoh`, its zenoh router), run the body for that
/// transport, report an error once on stderr, pick the exit code.
pub fn participant_main(
    role: grains_protocol::Role,
    args: &cli::CommonArgs,
    over_ipc: Body<grains_transport::ipc::Iceoryx2>,
    over_zenoh: Body<grains_transport::zenoh::Zenoh>,
) -> std::process::ExitCode {
    telemetry::init(role.binary());
    let run = || -> anyhow::Result<()> {
        let scene = grains_protocol::scene::load(&args.scene)?;
        // Held while this process may write into the run's directory (see `checkpoint`).
        // (On another host the directory may not exist yet: its outputs there are its own.)
        let _held = match &args.out_dir {
            Some(dir) => std::fs::create_dir_all(dir)
                .and_then(|()| checkpoint::hold(dir, false))
                .map_err(|e| anyhow::anyhow!("{}: run.lock: {e}", dir.display()))?,
            None => None,
        };
        let stop = signals::StopFlag::with_signals();
        let opts = solver::ParticipantOptions {
            run_id: args.run_id.clone(),
            stop,
            connect_timeout: args.connect_timeout(),
            protocol_version: args.claim_protocol_version.unwrap_or(grains_protocol::PROTOCOL_VERSION),
            checksums: scene.synthetic.as_ref().is_none_or(|s| s.checksum),
            out_dir: args.out_dir.clone(),
            resume: args.resume.as_deref().map(checkpoint::Resume::open).transpose()?,
        };
        match &args.zenoh {
            None => over_ipc(
                &grains_transport::ipc::Iceoryx2::join(&args.run_id, role.binary(), opts.stop.as_cancel())?,
                &scene,
                &opts,
            ),
            Some(endpoint) => over_zenoh(
                &grains_transport::zenoh::Zenoh::client(&args.run_id, role.binary(), endpoint)?,
                &scene,
                &opts,
            ),
        }
    };
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            tracing::error!("{err:#}");
            std::process::ExitCode::from(exit_code(&err))
        }
    }
}
