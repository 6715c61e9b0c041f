//! `coupling.substeps = "auto"`: the launcher's choice of the DEM substeps and the macro-step
//! stays within the DEM's and the MPM's stable steps (the limits `grains run` enforces, below
//! the first unstable points of the stability map in docs/validate: MPM CFL 0.9, DEM step
//! 1.0 × critical), whichever of the two binds, and the run it makes completes.

use super::run_to_end;
use grains_system_tests::*;

/// Runs the small hybrid block with `substeps = "auto"` and the extra overrides (its length is
/// `run.steps` of the `run.dt` given, rescaled to the chosen step); returns the run's copy of
/// the scene as loaded (resolved) and the run's directory.
fn auto_run(test: &str, extra: &[&str]) -> (grains_protocol::scene::Scene, std::path::PathBuf) {
    let out = out_dir(test);
    let mut args = vec![
        "run",
        "tests/scenes/hybrid_small_2d.toml",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
        "--set",
        "coupling.substeps=\"auto\"",
    ];
    for e in extra {
        args.extend(["--set", e]);
    }
    let (status, err) = run_to_end(&args);
    assert!(status.success(), "{err}");
    let dir = run_dir(&err);
    assert_eq!(summary(&dir)["status"], "completed");
    let scene = grains_protocol::scene::load(&dir.join("scene.toml")).expect("the run's copy loads");
    assert!(scene.coupling.auto.is_none(), "the run's copy holds the chosen numbers");
    (scene, dir)
}

#[test]
fn auto_substeps_keep_both_solvers_within_their_stable_steps() {
    let _machine = machine();
    // The MPM's stable step binds: a DEM step of 5e-7 s and run.dt far above the MPM's limit.
    let (s, dir) = auto_run("auto_mpm", &["coupling.dem_dt=5e-7", "run.dt=1e-3", "run.steps=10"]);
    let mpm = grains_mpm_service::setup::stable_step(&s).unwrap();
    let dem_dt = s.dt / s.coupling.substeps as f64;
    assert!((dem_dt / 5e-7 - 1.0).abs() < 1e-9, "the DEM step asked for: {dem_dt}");
    assert!(s.dt <= mpm, "macro-step {} above the MPM's stable step {mpm}", s.dt);
    assert!(
        s.dt + 5e-7 > mpm,
        "the largest k: {} steps of 5e-7 s, limit {mpm}",
        s.coupling.substeps
    );
    assert!(s.coupling.substeps > 10, "k = {}", s.coupling.substeps);
    // 10 steps of 1e-3 s asked for: the same 0.01 s in the chosen steps, each one a metrics row.
    assert!(
        (s.steps as f64 * s.dt / 0.01 - 1.0).abs() < s.dt / 0.01,
        "{} steps of {}",
        s.steps,
        s.dt
    );
    assert_eq!(metrics(&dir).len() as u64, s.steps);

    // The DEM's stable step binds: no dem_dt, so the DEM runs at its own stable step and the
    // macro-step is the largest multiple of it within the MPM's.
    let (s, _) = auto_run("auto_dem", &["run.dt=1e-3", "run.steps=10"]);
    let (dem_limit, ..) = grains_dem_service::setup::stable_step(&s).unwrap();
    let mpm = grains_mpm_service::setup::stable_step(&s).unwrap();
    let dem_dt = s.dt / s.coupling.substeps as f64;
    assert!(
        dem_dt <= dem_limit * (1.0 + 1e-12),
        "DEM step {dem_dt} above its stable step {dem_limit}"
    );
    assert!(
        dem_dt > 0.99 * dem_limit,
        "the DEM runs at its stable step: {dem_dt} vs {dem_limit}"
    );
    assert!(s.dt <= mpm && s.dt + dem_dt > mpm, "k = {}", s.coupling.substeps);

    // run.dt binds when it is the smallest: 2e-6 s with a DEM step of 5e-7 s is 4 substeps.
    let (s, _) = auto_run("auto_requested", &["coupling.dem_dt=5e-7", "run.dt=2e-6", "run.steps=100"]);
    assert_eq!(s.coupling.substeps, 4);

    // A DEM step above run.dt comes down to it: one substep of run.dt.
    let (s, _) = auto_run("auto_one", &["coupling.dem_dt=5e-6", "run.dt=2e-6", "run.steps=100"]);
    assert_eq!((s.coupling.substeps, s.dt), (1, 2e-6));
}
