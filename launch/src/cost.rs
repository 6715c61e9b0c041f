//! What a scene will cost before it runs: a model of the wall time of a hybrid run and of the
//! pure DEM run it replaces, with costs per grain-step, per point-step and per macro-step
//! measured by `grains bench hybrid` on this kind of machine (Yue 2018 §5, eqs. 21–23, in
//! the terms of grains' processes).
//!
//! A hybrid macro-step runs the DEM's k substeps over its N_D grains (discrete and band) and
//! the MPM's step over its N_P points at the same time, in two processes of one thread each,
//! then the coupler: T_H = max(c_D1 k N_D, c_P N_P) + c_X. The pure DEM runs the same k steps
//! of the same step over all N grains on both threads: T_DEM = c_D2 k N. The speed-up
//! T_DEM / T_H grows with the system: N grows with the area, N_D with the free surface (the
//! layer's thickness times the perimeter), and a coarser MPM cell makes both N_P and the
//! macro-step's share of the MPM smaller (k grows with the cell: the MPM's stable step is
//! proportional to it).

use grains_dem::space::D2;
use grains_protocol::scene::{Dimension, Model, Scene};

/// Costs of this kind of machine [s].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Costs {
    /// The hybrid's DEM, one thread, per grain-step.
    pub dem_hybrid: f64,
    /// The pure DEM, two threads, per grain-step.
    pub dem_alone: f64,
    /// The hybrid's MPM, one thread, per point and macro-step.
    pub mpm: f64,
    /// Per macro-step: the coupler, the exchange and the waits that do not overlap.
    pub step: f64,
}

/// Measured on a 2-core machine of this project's kind, on the column of `grains bench hybrid`
/// (0.3 × 0.4 m, 99,092 grains; hybrid on 4-mm cells, k = 80, 5,175 grains and 29,156
/// points, from `metrics.csv`: the DEM's 15.0 ms and the MPM's 10.3 ms of compute per
/// macro-step, 15.8 ms of wall; the pure DEM's 2.1 ms per step on two threads). `grains
/// bench hybrid` prints these costs fitted anew under its table.
pub const MEASURED: Costs = Costs {
    dem_hybrid: 3.6e-8,
    dem_alone: 2.1e-8,
    mpm: 3.5e-7,
    step: 0.8e-3,
};

/// The sizes a prediction needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Counts {
    /// Grains of the hybrid run (discrete and band) at the start.
    pub hybrid_grains: usize,
    /// Material points of the hybrid run at the start.
    pub points: usize,
    /// Grains of the same scene with every hybrid body discrete.
    pub all_grains: usize,
    /// DEM substeps per macro-step, and macro-steps.
    pub substeps: u32,
    pub steps: u64,
}

/// Predicted wall times [s]: (hybrid, pure DEM).
pub fn predict(c: &Costs, n: &Counts) -> (f64, f64) {
    let k = n.substeps as f64;
    let per_step = (c.dem_hybrid * k * n.hybrid_grains as f64).max(c.mpm * n.points as f64) + c.step;
    let dem = c.dem_alone * k * n.all_grains as f64;
    (per_step * n.steps as f64, dem * n.steps as f64)
}

/// The counts of a 2D hybrid scene (resolved steps), from the solvers' own set-up: the grains
/// and points the run would start with, and the grains of the same scene with its hybrid
/// bodies all discrete. `None` for a scene that is not a 2D hybrid scene.
pub fn counts(scene: &Scene, text: &str) -> anyhow::Result<Option<Counts>> {
    if scene.dimension != Dimension::Two || !scene.bodies.iter().any(|b| b.model == Model::Hybrid) {
        return Ok(None);
    }
    let zones = grains_service::zones::ZoneField::layered(scene);
    let dem = grains_dem_service::setup::build_state::<D2>(scene, &zones)?;
    let (points, _) = grains_mpm_service::setup::build::<D2>(scene, &zones).map_err(anyhow::Error::msg)?;
    // The same scene with every hybrid body a DEM one.
    let overrides: Vec<String> = scene
        .bodies
        .iter()
        .enumerate()
        .filter(|(_, b)| b.model == Model::Hybrid)
        .map(|(k, _)| format!("body.{k}.model=\"dem\""))
        .collect();
    let hash = grains_protocol::scene::hash_bytes(text.as_bytes());
    let (all, _) = grains_protocol::scene::with_overrides(text, &scene.path, hash, &overrides)?;
    let all = grains_dem_service::setup::build_state::<D2>(&all, &grains_service::zones::ZoneField::layered(&all))?;
    Ok(Some(Counts {
        hybrid_grains: dem.grains.len(),
        points: points.len(),
        all_grains: all.grains.len(),
        substeps: scene.coupling.substeps,
        steps: scene.steps,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The model's two limits: a DEM-bound hybrid is as much faster as it has fewer grains
    /// (times the thread ratio), an MPM-bound one pays per point whatever k.
    #[test]
    fn the_prediction_follows_the_bound_side() {
        let c = Costs {
            dem_hybrid: 2e-8,
            dem_alone: 1e-8,
            mpm: 1e-7,
            step: 0.0,
        };
        let n = Counts {
            hybrid_grains: 1_000,
            points: 10,
            all_grains: 100_000,
            substeps: 50,
            steps: 10,
        };
        let (h, d) = predict(&c, &n);
        assert!((d / h - 50.0).abs() < 1e-9, "{}", d / h);
        let n = Counts { points: 1_000_000, ..n };
        let (h, _) = predict(&c, &n);
        assert!((h - 10.0 * 0.1).abs() < 1e-12, "{h}");
    }
}
