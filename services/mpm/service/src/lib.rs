//! The grains-mpm participant: scene → material points ([`setup`]), the MPM behind the
//! participant loop and its VTU frames ([`solver`]). Synthetic test scenes run the synthetic
//! solver of `grains_service::synthetic` instead.

pub mod setup;
pub mod solver;

use grains_grid::{D2, D3};
use grains_mpm::matrix::MpmSpace;
use grains_protocol::Role;
use grains_protocol::scene::{Dimension, Scene, SceneError};
use grains_service::solver::{self as participant, ParticipantOptions};
use grains_service::synthetic::SyntheticSolver;
use grains_transport::Transport;

/// Checks what the MPM needs of a scene before any process starts (one material, wall kinds,
/// the CFL limit); the error is a scene error (exit code 2).
pub fn check_scene(scene: &Scene) -> Result<(), SceneError> {
    setup::check(scene).map_err(|(field, message)| SceneError {
        path: scene.path.clone(),
        line_col: None,
        field: Some(field),
        message,
    })
}

/// Runs the MPM participant of `scene` over `transport` to the end of the run.
pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    if let Some(params) = &scene.synthetic {
        let synthetic = SyntheticSolver::new(Role::Mpm, scene.seed, scene.dim(), params.clone());
        return participant::run(transport, Role::Mpm, scene, opts, |_| Ok(synthetic));
    }
    check_scene(scene)?;
    match scene.dimension {
        Dimension::Two => run_physics::<T, D2>(transport, scene, opts),
        Dimension::Three => run_physics::<T, D3>(transport, scene, opts),
    }
}

fn run_physics<T: Transport, S: MpmSpace>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    participant::run(transport, Role::Mpm, scene, opts, |zones| {
        let (points, params) = setup::build::<S>(scene, zones).map_err(anyhow::Error::msg)?;
        solver::MpmSolver::new(scene, points, params, opts.out_dir.as_deref(), opts.resume.as_ref().map(|r| r.step))
    })
}
