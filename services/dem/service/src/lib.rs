//! The grains-dem participant: scene → DEM state ([`setup`]), the DEM behind the participant
//! loop ([`solver`]), VTU frames ([`frames`]). Synthetic test scenes run the synthetic solver
//! of `grains_service::synthetic` instead.

pub mod frames;
pub mod lammps_data;
pub mod setup;
pub mod solver;

use grains_dem::space::{D2, D3, Space};
use grains_protocol::scene::{Dimension, Scene};
use grains_protocol::{Role, scene::SceneError};
use grains_service::solver::{self as participant, ParticipantOptions};
use grains_service::synthetic::SyntheticSolver;
use grains_transport::Transport;

/// Checks what the DEM needs of a scene before any process starts (the time step against
/// the critical one); the error is a scene error (exit code 2).
pub fn check_scene(scene: &Scene) -> Result<(), SceneError> {
    setup::check_time_step(scene).map_err(|message| SceneError {
        path: scene.path.clone(),
        line_col: None,
        field: Some("run.dt".into()),
        message,
    })
}

/// Runs the DEM participant of `scene` over `transport` to the end of the run.
pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    if let Some(params) = &scene.synthetic {
        let synthetic = SyntheticSolver::new(Role::Dem, scene.seed, scene.dim(), params.clone());
        return participant::run(transport, Role::Dem, scene, opts, |_| Ok(synthetic));
    }
    check_scene(scene)?;
    match scene.dimension {
        Dimension::Two => run_physics::<T, D2>(transport, scene, opts),
        Dimension::Three => run_physics::<T, D3>(transport, scene, opts),
    }
}

fn run_physics<T: Transport, S: Space>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    participant::run(transport, Role::Dem, scene, opts, |zones| {
        let state = setup::build_state::<S>(scene, zones)?;
        solver::DemSolver::new(scene, state, opts.out_dir.as_deref(), opts.resume.as_ref().map(|r| r.step))
    })
}
