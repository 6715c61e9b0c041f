//! `grains calibrate`: every shipped hybrid scene takes its continuum's friction angle and
//! Young's modulus from DEM tests of its own grains (the biaxial test; for the angle, poured
//! piles where the scene says so), and says so; the test reproduces them.

use grains_launch::calibrate::{CalibrateOptions, Calibration, Strength, run_for};
use grains_protocol::scene::{self, Model};
use grains_system_tests::*;

/// Every scene in scenes/ with a hybrid body records a `calibration` in its material's
/// `[material.mpm]`; for each distinct DEM material and calibration command among them the
/// biaxial test is run again and gives the recorded friction angle (the critical state's or,
/// with `--strength peak`, the peak's; with `--strength repose`, the piles' are poured
/// again) within 0.5 degrees and
/// Young's modulus within 5 % (the same seed and thread count give the same bits; the
/// tolerance covers another machine's rounding: another seed moves the angle by up to 0.8
/// degrees).
#[test]
fn every_hybrid_scene_takes_its_continuum_from_grains_calibrate() {
    let _machine = machine();
    let mut checked: Vec<(String, CalibrateOptions, Calibration)> = Vec::new();
    let mut scenes = 0;
    for entry in std::fs::read_dir(repo().join("scenes")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let s = scene::load(&path).unwrap();
        let Some(body) = s.bodies.iter().find(|b| b.model == Model::Hybrid) else {
            continue;
        };
        scenes += 1;
        let material = &s.materials[body.material];
        let mpm = material.mpm.as_ref().unwrap();
        let provenance = mpm
            .calibration
            .as_deref()
            .unwrap_or_else(|| panic!("{}: material `{}` has no calibration", path.display(), material.name));
        let options = CalibrateOptions::parse(provenance).unwrap_or_else(|| {
            panic!(
                "{}: the calibration does not start with grains calibrate's options: {provenance}",
                path.display()
            )
        });
        // The DEM material and the test's options decide the result; the strength picks
        // which of its angles the scene records.
        let key = format!("{:?}", material.dem);
        // (The piles of the repose strength are a test of their own.)
        let test = CalibrateOptions {
            strength: match options.strength {
                Strength::Repose => Strength::Repose,
                _ => Strength::Critical,
            },
            ..options
        };
        let k = match checked.iter().position(|c| c.0 == key && c.1 == test) {
            Some(k) => k,
            None => {
                let (_, c) = run_for(&s, &test).unwrap();
                // A consolidated 2D packing of disks of a few per cent polydispersity: 0.80–0.85
                // (the grains' area over the box's; a diameter taken for a radius is 4 times it).
                assert!(
                    (0.78..0.86).contains(&c.packing),
                    "{}: the sample's packing {}",
                    path.display(),
                    c.packing
                );
                checked.push((key, test, c));
                checked.len() - 1
            }
        };
        let (phi, young) = (checked[k].2.friction(options.strength), checked[k].2.young(mpm.poisson));
        assert!(
            (mpm.friction_angle - phi).abs() <= 0.5,
            "{}: friction_angle {} but grains calibrate gives {phi:.2}",
            path.display(),
            mpm.friction_angle
        );
        assert!(
            (mpm.young / young - 1.0).abs() <= 0.05,
            "{}: young {} but grains calibrate gives {young:.4e}",
            path.display(),
            mpm.young
        );
    }
    assert!(scenes >= 5, "the shipped hybrid scenes: {scenes}");
}
