//! `coupling.substeps = "auto"`: the launcher chooses a hybrid scene's DEM substeps k and its
//! macro-step from the solvers' own stable steps, before anything starts, and writes them into
//! the run's copy of the scene (`grains_protocol::scene::with_resolved_steps`).
//!
//! The DEM step is `coupling.dem_dt`, or the DEM's stable step (the safe fraction of its
//! critical step, `grains_dem::pipeline::SAFE_FRACTION`); the macro-step, which is the MPM's
//! step, is the largest multiple k of it within both `run.dt` and the MPM's stable step (CFL
//! number `grains_mpm::pipeline::MAX_CFL`). Both limits are the ones `grains run` enforces on a
//! scene with fixed steps, and `grains validate --part stability` maps what lies beyond them.

use super::BadInput;
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
    /// The most substeps a scene may have (10,000).
    Cap,
}

/// The steps chosen for a scene with `substeps = "auto"`.
#[derive(Clone, Debug, PartialEq)]
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
    /// The cadences counted in macro-steps that the new step rescaled to keep their length in
    /// time, as (field, steps of `run.dt` in the file, macro-steps now). Said aloud because the
    /// file's count is in steps of `run.dt`, the upper bound: `oracle.every = 50` with `run.dt =
    /// 1e-3` is every 50 ms, however small the chosen step.
    pub cadences: scene::Rescaled,
}

impl std::fmt::Display for Chosen {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let why = match self.limit {
            Limit::Mpm => "the MPM's stable step",
            Limit::Requested => "run.dt",
            Limit::Dem => "the DEM step (k = 1)",
            Limit::Cap => "the cap of 10,000 substeps",
        };
        write!(
            f,
            "coupling.substeps = \"auto\": k = {} DEM steps of {:.3e} s per macro-step of {:.3e} s, set by {why} \
             (DEM stable step {:.3e} s, MPM stable step {:.3e} s, run.dt {:.3e} s)",
            self.substeps, self.dem_dt, self.dt, self.dem_limit, self.mpm_limit, self.requested
        )?;
        for (i, (field, from, to)) in self.cadences.iter().enumerate() {
            let lead = if i == 0 { "; kept in time: " } else { ", " };
            write!(f, "{lead}{field} {from} → {to} steps ({:.2} ms)", *to as f64 * self.dt * 1e3)?;
        }
        Ok(())
    }
}

/// The steps for `run.dt` = `requested` and `coupling.dem_dt` = `dem_dt` (None: the DEM's
/// stable step), given the DEM's and the MPM's stable steps. The result holds the checks the
/// solvers make exactly (dt ≤ the MPM's limit and dt / k ≤ the DEM's, in floating point), so
/// that the run it makes is never refused. A `dem_dt` above the DEM's own limit is refused.
pub fn choose(requested: f64, dem_dt: Option<f64>, dem_limit: f64, mpm_limit: f64) -> anyhow::Result<Chosen> {
    if let Some(d) = dem_dt
        && d > dem_limit
    {
        anyhow::bail!(BadInput(format!(
            "coupling.dem_dt = {d:e} s is above the DEM's stable step {dem_limit:.4e} s (20% of its critical step): lower it"
        )));
    }
    let dem = dem_dt.unwrap_or(dem_limit);
    let (bound, mut limit) = if mpm_limit <= requested {
        (mpm_limit, Limit::Mpm)
    } else {
        (requested, Limit::Requested)
    };
    // The largest k with k · dem ≤ bound, at most 10,000.
    let mut k = (bound / dem).floor().clamp(0.0, 10_000.0);
    if k < 10_000.0 && (k + 1.0) * dem <= bound {
        k += 1.0;
    }
    if k == 10_000.0 {
        limit = Limit::Cap;
    }
    let (k, mut dt) = if k >= 1.0 {
        (k, k * dem)
    } else {
        limit = Limit::Dem;
        (1.0, bound)
    };
    // Rounding must not take either step over its limit.
    while dt > bound || dt / k > dem.min(dem_limit) {
        dt = dt.next_down();
    }
    Ok(Chosen {
        substeps: k as u32,
        dt,
        dem_dt: dt / k,
        dem_limit,
        mpm_limit,
        requested,
        limit,
        cadences: Vec::new(),
    })
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
    let mut chosen = choose(scene.dt, auto.dem_dt, dem_limit, mpm_limit)?;
    let (resolved, text, rescaled) = scene::with_resolved_steps(&text, &scene, chosen.dt, chosen.substeps, chosen.dem_dt)?;
    chosen.cadences = rescaled;
    Ok((resolved, text, Some(chosen)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each limit in turn sets the macro-step, which is always a whole number of DEM steps
    /// within both stable steps and run.dt, exactly (the solvers' checks are strict).
    #[test]
    fn the_tighter_limit_sets_the_macro_step() {
        let ok = |c: &Chosen| c.dt <= c.mpm_limit && c.dt <= c.requested && c.dt / c.substeps as f64 <= c.dem_limit;
        // The MPM's limit binds: 4.9e-5 / 5e-7 = 98 substeps.
        let c = choose(1e-3, Some(5e-7), 7e-6, 4.9e-5).unwrap();
        assert_eq!((c.substeps, c.limit), (98, Limit::Mpm));
        assert!(ok(&c) && (c.dt - 4.9e-5).abs() < 1e-18);
        // run.dt binds.
        let c = choose(2e-5, Some(5e-7), 7e-6, 4.9e-5).unwrap();
        assert_eq!((c.substeps, c.limit), (40, Limit::Requested));
        assert!(ok(&c));
        // Without dem_dt the DEM runs at its own stable step: floor(4.9e-5 / 7e-6) = 7.
        let c = choose(1e-3, None, 7e-6, 4.9e-5).unwrap();
        assert_eq!((c.substeps, c.limit), (7, Limit::Mpm));
        assert!(ok(&c));
        // A DEM step above the MPM's limit comes down to it: k = 1.
        let c = choose(1e-3, Some(1e-4), 2e-4, 4.9e-5).unwrap();
        assert_eq!((c.substeps, c.limit), (1, Limit::Dem));
        assert!(ok(&c) && c.dt == 4.9e-5);
        // A DEM step above the DEM's own limit is refused.
        assert!(choose(1e-3, Some(1e-5), 7e-6, 4.9e-5).is_err());
        // Awkward ratios: the product of k and the DEM step never ends above a limit.
        let mut x = 0.123_456_789;
        for _ in 0..2000 {
            x = (x * 7.31 + 0.17) % 1.0;
            let (d, m) = (1e-6 * (0.5 + x), 1e-5 * (1.0 + 9.0 * ((x * 13.7) % 1.0)));
            for c in [choose(1.0, None, d, m).unwrap(), choose(1.0, Some(0.7 * d), d, m).unwrap()] {
                assert!(ok(&c), "{c:?}");
            }
        }
    }

    /// A cadence the file counts in steps of `run.dt` keeps its length in time, and the
    /// choice says so: the silo with `run.dt = 1e-3` as the bound and the oracle every 50 of
    /// those steps runs its oracle every 641 macro-steps of 7.8e-5 s (50 ms), not every 50.
    #[test]
    fn rescaled_cadences_are_named_with_their_length_in_time() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/silo_hybrid_2d.toml");
        let overrides = [
            "coupling.substeps=\"auto\"",
            "coupling.dem_dt=2e-6",
            "run.dt=1e-3",
            "oracle.every=50",
            "output.frames_every=10",
        ];
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let (scene, _, chosen) = load(&path, &overrides).unwrap();
        let c = chosen.unwrap();
        assert_eq!((c.substeps, c.limit), (39, Limit::Mpm));
        let every = (1e-3 * 50.0 / c.dt).round() as u64;
        assert_eq!(scene.oracle.as_ref().unwrap().every, every);
        assert_eq!(
            c.cadences,
            vec![
                ("output.frames_every".to_string(), 10, (1e-2 / c.dt).round() as u64),
                ("oracle.every".to_string(), 50, every),
            ]
        );
        let said = c.to_string();
        assert!(said.contains(&format!("oracle.every 50 → {every} steps (50.00 ms)")), "{said}");
        // Without a rescale nothing more is said.
        let mut same = c.clone();
        same.cadences.clear();
        assert!(!same.to_string().contains("kept in time"));
    }
}
