//! What a scene will cost before it runs: a model of the wall time of a hybrid run and of the
//! pure DEM run it replaces, with costs per grain-step, per point-step and per macro-step
//! measured by `grains bench chute` on this kind of machine (Yue 2018 §5, eqs. 21–23, in
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
    /// The hybrid's DEM, two threads, per grain-step.
    pub dem_hybrid: f64,
    /// The pure DEM, two threads, per grain-step.
    pub dem_alone: f64,
    /// The hybrid's MPM, two threads, per point and macro-step.
    pub mpm: f64,
    /// Per macro-step: the coupler, the exchange and the waits that do not overlap.
    pub step: f64,
}

/// Measured on a 2-core machine of this project's kind by `grains bench chute --radii 0.5
/// --cells 0.004 --depths 0.0167,0.05 --depth 0.15 --pours 4` (2026-12-07; the periodic chute
/// 0.2 × 0.15 m from poured packings of 31,852 grains; the pure DEM on two threads, 20 DEM
/// steps per macro-step; two hybrids on 4-mm cells with 1,750 and 2,580 grains and about
/// 7,200 points of the geostatic Drucker–Prager continuum, k = 22, two threads per solver,
/// each run after every pour; the medians of the four runs of each): the costs fitted to those
/// runs, which the model then reproduces within 5% (23.2 s, 2.2 s and 3.1 s measured; 23.1,
/// 2.2 and 3.2 s modelled). The same machine ran the same DEM up to twice as slowly within the
/// hour: the ratios, not the seconds, are what carries over. A settled packing's DEM costs
/// twice or more per grain-step what a loose lattice's does (its contacts are there from the
/// start).
pub const MEASURED: Costs = Costs {
    dem_hybrid: 8.1e-8,
    dem_alone: 5.2e-8,
    mpm: 2.46e-7,
    step: 3.87e-4,
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

/// What one measured run says about its costs (from its `metrics.csv`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Mean DEM grains and MPM points over the run.
    pub grains: f64,
    pub points: f64,
    /// DEM steps per macro-step, and macro-steps.
    pub substeps: u32,
    pub steps: u64,
    /// Wall time of the run [s].
    pub wall: f64,
    /// Mean compute time of the DEM and of the MPM per macro-step [s].
    pub dem_step: f64,
    pub mpm_step: f64,
}

/// The model's costs from runs: the DEM's per grain-step alone (`dem`, a pure DEM run) and in
/// the hybrid runs, the MPM's per point-step, and what a macro-step adds beyond the slower
/// solver (means over the hybrid runs). `None` without a hybrid run.
pub fn fit(dem: &Sample, hybrid: &[Sample]) -> Option<Costs> {
    let hybrid: Vec<&Sample> = hybrid.iter().filter(|r| r.points > 0.0).collect();
    if hybrid.is_empty() {
        return None;
    }
    let n = hybrid.len() as f64;
    let mean = |f: &dyn Fn(&Sample) -> f64| hybrid.iter().map(|r| f(r)).sum::<f64>() / n;
    Some(Costs {
        dem_alone: dem.dem_step / (dem.substeps as f64 * dem.grains),
        dem_hybrid: mean(&|r| r.dem_step / (r.substeps as f64 * r.grains)),
        mpm: mean(&|r| r.mpm_step / r.points),
        step: mean(&|r| (r.wall / r.steps as f64 - r.dem_step.max(r.mpm_step)).max(0.0)),
    })
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
