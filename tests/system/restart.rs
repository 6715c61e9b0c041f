//! Issue 25: checkpoint and restart. A run whose launcher is killed (SIGKILL) mid-way and
//! then resumed with `grains resume` ends with the same physics columns of `metrics.csv`,
//! the same frames (byte for byte) and the same `walls.csv` as the run that never stopped.

use super::run_to_end;
use grains_system_tests::*;
use std::path::Path;
use std::time::Duration;

/// The physics of a finished run: `metrics.csv` without its timings, every frame's bytes
/// (by file name), and `walls.csv`, `walls_mpm.csv` and `bodies.csv` if there are.
pub(crate) struct Outputs {
    metrics: String,
    frames: Vec<(String, Vec<u8>)>,
    walls: Option<String>,
    walls_mpm: Option<String>,
    bodies: Option<String>,
}

pub(crate) fn outputs(dir: &Path) -> Outputs {
    let metrics = physics(dir);
    let mut frames: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir.join("frames"))
        .unwrap()
        .flatten()
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .collect();
    frames.sort();
    Outputs {
        metrics,
        frames,
        walls: std::fs::read_to_string(dir.join("walls.csv")).ok(),
        walls_mpm: std::fs::read_to_string(dir.join("walls_mpm.csv")).ok(),
        bodies: std::fs::read_to_string(dir.join("bodies.csv")).ok(),
    }
}

/// The resumed run's outputs are the uninterrupted run's (`what` names the case).
pub(crate) fn assert_same(resumed: &Outputs, whole: &Outputs, what: &str) {
    assert_eq!(resumed.metrics, whole.metrics, "{what}: metrics differ after the resume");
    let names = |o: &Outputs| o.frames.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(resumed), names(whole), "{what}: other frames");
    for ((name, a), (_, b)) in resumed.frames.iter().zip(&whole.frames) {
        assert!(a == b, "{what}: frame {name} differs after the resume");
    }
    assert_eq!(resumed.walls, whole.walls, "{what}: walls.csv differs after the resume");
    assert_eq!(resumed.walls_mpm, whole.walls_mpm, "{what}: walls_mpm.csv differs after the resume");
    assert_eq!(resumed.bodies, whole.bodies, "{what}: bodies.csv differs after the resume");
}

fn refs(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

/// A DEM, an MPM, a fixed-zone hybrid (with the flip transfer's carried node accelerations),
/// an adaptive hybrid (surface oracle every 100 steps: grains and points created and
/// deleted; its zones, ids and generator carried), a shear-band hybrid and a DEM with rigid bodies, each killed after a checkpoint and rows
/// beyond it, then resumed. The launcher is killed (SIGKILL: no summary, `metrics.csv.part`
/// left as it was), except in the fixed-zone hybrid, where the MPM is (the launcher fails the
/// run and finishes its outputs).
#[test]
fn a_run_killed_mid_way_resumes_to_the_uninterrupted_runs_physics_and_frames() {
    let _machine = machine();
    let out = out_dir("restart");
    let out_s = out.to_str().unwrap();
    let scenes = [
        ("tests/scenes/dem_small_2d.toml", "run.steps=3000", 500, None),
        ("tests/scenes/mpm_small_2d.toml", "run.steps=3000", 500, None),
        ("tests/scenes/hybrid_pile_2d.toml", "run.duration=0.06", 200, Some("grains-mpm")),
        ("tests/scenes/hybrid_adaptive_2d.toml", "run.duration=0.05", 250, None),
        // The shear-band oracle: checkpointed before the band (its strain records,
        // persistence and velocity history carried), the band found and trained after the
        // resume as in the run that never stopped.
        ("tests/scenes/hybrid_band_2d.toml", "run.duration=0.06", 1500, None),
        // Rigid bodies: their state and contact histories are in the DEM's checkpoint.
        ("tests/scenes/rigid_floor_2d.toml", "run.duration=0.15", 500, None),
        // Rigid bodies and a continuum: the points' contact histories are the DEM's, their
        // loads the MPM's for one step only.
        ("tests/scenes/mpm_on_rigid_2d.toml", "run.duration=0.05", 1000, None),
    ];
    for (scene, steps, every, victim) in scenes {
        let every_s = every.to_string();
        let args = |extra: &[&'static str]| -> Vec<String> {
            let mut a: Vec<String> = [
                "run",
                scene,
                "--out",
                out_s,
                "--quiet",
                "--set",
                steps,
                "--checkpoint-every",
                &every_s,
            ]
            .iter()
            .map(|s| s.to_string())
            .collect();
            a.extend(["--set".to_string(), format!("output.frames_every={}", every / 2)]);
            a.extend(extra.iter().map(|s| s.to_string()));
            a
        };
        let (status, err) = run_to_end(&refs(&args(&[])));
        assert!(status.success(), "{scene}: {err}");
        let whole = outputs(&run_dir(&err));

        let mut launcher = Running::grains(&refs(&args(&[])));
        let err = launcher.wait_for("started as processes", Duration::from_secs(60));
        let dir = run_dir(&err);
        // Killed once the first checkpoint is complete and the run has gone on past it, so
        // that rows after the checkpoint must be dropped.
        let manifest = dir.join(format!("checkpoints/{every:010}/manifest.json"));
        wait_until(
            &launcher,
            &format!("{scene}: a checkpoint and rows past it"),
            Duration::from_secs(120),
            || manifest.exists() && rows_written(&dir) >= every + 19,
        );
        let rows = match victim {
            None => {
                launcher.child.kill().expect("SIGKILL the launcher");
                let _ = launcher.child.wait();
                let rows = std::fs::read_to_string(dir.join("metrics.csv.part")).unwrap().lines().count() - 1;
                std::thread::sleep(Duration::from_millis(500));
                assert!(!dir.join("summary.json").exists(), "{scene}: a killed launcher wrote no summary");
                rows
            }
            Some(binary) => {
                // SAFETY: kill(2) by pid on a participant this test's launcher started.
                assert_eq!(unsafe { libc::kill(pid_of(&err, binary), libc::SIGKILL) }, 0);
                assert_eq!(launcher.wait_exit(Duration::from_secs(30)).code(), Some(1), "{}", launcher.stderr());
                assert_eq!(summary(&dir)["status"], "failed", "{scene}");
                std::fs::read_to_string(dir.join("metrics.csv")).unwrap().lines().count() - 1
            }
        };

        let (status, err) = run_to_end(&["resume", dir.to_str().unwrap(), "--quiet"]);
        assert!(status.success(), "{scene}: resume: {err}");
        let s = summary(&dir);
        assert_eq!(s["status"], "completed", "{scene}: {s}");
        let after = s["resumed_after_step"].as_u64().expect("resumed_after_step");
        assert!(
            after >= every as u64 && (after as usize) < rows,
            "{scene}: resumed after step {after}, killed at row {rows}: rows after the checkpoint were there to drop"
        );
        assert_same(&outputs(&dir), &whole, scene);

        // A completed run has nothing to resume.
        let (status, err) = run_to_end(&["resume", dir.to_str().unwrap(), "--quiet"]);
        assert_eq!(status.code(), Some(2), "{scene}: {err}");
        assert!(err.contains("nothing to resume"), "{err}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}

/// A run without checkpoints cannot be resumed, nor one still going (its launcher and
/// participants hold `run.lock`); both say why (exit code 2).
#[test]
fn a_run_without_a_checkpoint_or_still_going_is_not_resumed() {
    let _machine = machine();
    let out = out_dir("restart-refused");
    let out_s = out.to_str().unwrap();
    let (status, err) = run_to_end(&["run", "tests/scenes/dem_small_2d.toml", "--out", out_s, "--quiet"]);
    assert!(status.success(), "{err}");
    let dir = run_dir(&err);
    std::fs::remove_file(dir.join("summary.json")).unwrap();
    let (status, err) = run_to_end(&["resume", dir.to_str().unwrap(), "--quiet"]);
    assert_eq!(status.code(), Some(2), "{err}");
    assert!(
        err.contains("no complete checkpoint") && err.contains("--checkpoint-every"),
        "{err}"
    );

    let mut running = Running::grains(&[
        "run",
        "tests/scenes/dem_small_2d.toml",
        "--out",
        out_s,
        "--quiet",
        "--set",
        "run.steps=400000",
        "--checkpoint-every",
        "100",
    ]);
    let dir = run_dir(&running.wait_for("started as processes", Duration::from_secs(60)));
    wait_until(&running, "no checkpoint", Duration::from_secs(60), || {
        dir.join("checkpoints/0000000100/manifest.json").exists()
    });
    let (status, err) = run_to_end(&["resume", dir.to_str().unwrap(), "--quiet"]);
    assert_eq!(status.code(), Some(2), "{err}");
    assert!(err.contains("still going"), "{err}");
    assert!(
        running.child.try_wait().unwrap().is_none(),
        "the refused resume touched the running run"
    );
    // Stopped (and its participants gone) before its directory is removed.
    drop(running);
    std::thread::sleep(Duration::from_secs(2));
    std::fs::remove_dir_all(&out).unwrap();
}
