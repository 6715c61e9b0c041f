//! `coupling.substeps = "auto"`: the launcher chooses a hybrid scene's DEM substeps k and its
//! macro-step from the solvers' own stable steps, before anything starts, and writes them into
//! the run's copy of the scene (`grains_protocol::scene::with_resolved_steps`).
//!
//! The DEM step is `coupling.dem_dt`, or the DEM's stable step (the safe fraction of its
//! critical step, `grains_dem::pipeline::SAFE_FRACTION`); the macro-step, which is the MPM's
//! step, is the largest multiple k of it within both `run.dt` and the MPM's stable step (CFL
//! number `grains_mpm::pipeline::MAX_CFL`). Both limits are the ones `grains run` enforces on a
//! scene with fixed steps, and `grains validate --part stability` maps what lies beyond them.

use grains_protocol::scene::{self, Scene};
use std::path::Path;

/// Which limit set the macro-step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// The MPM's stable step.
    Mpm,
    /// `run.dt`, the scene's upper bound.
    Requested,
    /// The DEM step itself (k = 1: the MPM's limit or `run.dt` is below the DEM step, which
    /// then comes down to it).
    Dem,
}

/// The steps chosen for a scene with `substeps = "auto"`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chosen {
    pub substeps: u32,
    /// The macro-step (the MPM's step) [s].
    pub dt: f64,
    /// The DEM step dt / k [s].
    pub dem_dt: f64,
    /// The DEM's and the MPM's stable steps, and the scene's `run.dt` [s].
    pub dem_limit: f64,
    pub mpm_limit: f64,
    pub requested: f64,
    pub limit: Limit,
}

impl std::fmt::Display for Chosen {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let why = match self.limit {
            Limit::Mpm => "the MPM's stable step",
            Limit::Requested => "run.dt",
            Limit::Dem => "the DEM step (k = 1)",
        };
        write!(
            f,
            "coupling.substeps = \"auto\": k = {} DEM steps of {:.3e} s per macro-step of {:.3e} s, set by {why} \
             (DEM stable step {:.3e} s, MPM stable step {:.3e} s, run.dt {:.3e} s)",
            self.substeps, self.dem_dt, self.dt, self.dem_limit, self.mpm_limit, self.requested
        )
    }
}

/// The steps for `run.dt` = `requested` and `coupling.dem_dt` = `dem_dt` (None: the DEM's stable step), given
/// the DEM's and the MPM's stable steps.
pub fn choose(requested: f64, dem_dt: Option<f64>, dem_limit: f64, mpm_limit: f64) -> Chosen {
    let dem = dem_dt.unwrap_or(dem_limit);
    let (bound, limit) = if mpm_limit <= requested {
        (mpm_limit, Limit::Mpm)
    } else {
        (requested, Limit::Requested)
    };
    // The largest k with k · dem ≤ bound (a hair of tolerance: a bound that is an exact multiple
    // in decimal should not lose a substep to rounding).
    let k = (bound / dem * (1.0 + 1e-12)).floor().min(10_000.0);
    let (substeps, dt, limit) = if k >= 1.0 {
        (k as u32, k * dem, limit)
    } else {
        (1, bound, Limit::Dem)
    };
    Chosen {
        substeps,
        dt,
        dem_dt: dt / substeps as f64,
        dem_limit,
        mpm_limit,
        requested,
        limit,
    }
}

/// Loads a scene with its overrides, as `scene::load_with_overrides`, and resolves
/// `substeps = "auto"`: the scene, its text (what the run's copy holds) and the choice made.
pub fn load(path: &Path, overrides: &[String]) -> anyhow::Result<(Scene, String, Option<Chosen>)> {
    let (scene, text) = scene::load_with_overrides(path, overrides)?;
    let Some(auto) = scene.coupling.auto else {
        return Ok((scene, text, None));
    };
    let Some((dem_limit, ..)) = grains_dem_service::setup::stable_step(&scene) else {
        anyhow::bail!("{}: coupling.substeps = \"auto\" needs DEM material", path.display());
    };
    let Some(mpm_limit) = grains_mpm_service::setup::stable_step(&scene) else {
        anyhow::bail!("{}: coupling.substeps = \"auto\" needs MPM material", path.display());
    };
    let chosen = choose(scene.dt, auto.dem_dt, dem_limit, mpm_limit);
    let (scene, text) = scene::with_resolved_steps(&text, &scene, chosen.dt, chosen.substeps)?;
    Ok((scene, text, Some(chosen)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each limit in turn sets the macro-step, which is always a whole number of DEM steps
    /// within both stable steps and run.dt.
    #[test]
    fn the_tighter_limit_sets_the_macro_step() {
        // The MPM's limit binds: 4.9e-5 / 5e-7 = 98 substeps.
        let c = choose(1e-3, Some(5e-7), 7e-6, 4.9e-5);
        assert_eq!((c.substeps, c.limit), (98, Limit::Mpm));
        assert!((c.dt - 4.9e-5).abs() < 1e-18 && c.dt <= c.mpm_limit);
        // run.dt binds.
        let c = choose(2e-5, Some(5e-7), 7e-6, 4.9e-5);
        assert_eq!((c.substeps, c.limit), (40, Limit::Requested));
        // Without dem_dt the DEM runs at its own stable step: floor(4.9e-5 / 7e-6) = 7.
        let c = choose(1e-3, None, 7e-6, 4.9e-5);
        assert_eq!((c.substeps, c.limit), (7, Limit::Mpm));
        assert!(c.dem_dt <= 7e-6 && c.dt <= 4.9e-5);
        // A DEM step above the MPM's limit comes down to it: k = 1.
        let c = choose(1e-3, Some(1e-4), 2e-4, 4.9e-5);
        assert_eq!((c.substeps, c.limit), (1, Limit::Dem));
        assert_eq!((c.dt, c.dem_dt), (4.9e-5, 4.9e-5));
    }
}
