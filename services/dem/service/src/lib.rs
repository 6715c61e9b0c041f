//! The grains-dem participant.
//!
//! In this build the only DEM solver is the synthetic one of `[synthetic]` test scenes
//! (`grains_service::synthetic`); a physics scene is refused at load with exit code 2.

use anyhow::bail;
use grains_protocol::{Role, scene::Scene};
use grains_service::solver::{self, ParticipantOptions};
use grains_service::synthetic::SyntheticSolver;
use grains_transport::Transport;

/// Runs the DEM participant of `scene` over `transport` to the end of the run.
pub fn run<T: Transport>(transport: &T, scene: &Scene, opts: &ParticipantOptions) -> anyhow::Result<()> {
    match &scene.synthetic {
        Some(params) => {
            let mut synthetic = SyntheticSolver::new(Role::Dem, scene.seed, scene.dim(), params.clone());
            solver::run(transport, Role::Dem, scene, opts, &mut synthetic)
        }
        None => bail!(
            "{}: this build has no DEM physics yet; it runs [synthetic] test scenes only",
            scene.path.display()
        ),
    }
}
