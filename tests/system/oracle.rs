//! Issue 6: the adaptive oracle (`oracle.kind = "surface"`, Yue 2018 §4) between the real
//! solvers: conversions keep mass and momentum, new points carry the grains' stress, and an
//! oracle forced to one model reproduces that model's run.

use super::*;
use grains_protocol::wire::Zone;

const SCENE: &str = "tests/scenes/hybrid_adaptive_2d.toml";

/// Every epoch of the adaptive pile (10 epochs in 1000 steps, the first ones converting a
/// row of cells each way as the band moves to where the grains' surface is): the total mass
/// after the epoch (the solvers' summaries) within 1% of before (the oracle's), the total
/// momentum within 1% of max(|p|, m √(g d)) (the pile is nearly at rest). The epochs must
/// convert something (grains or points created or deleted), and the run is the same with the
/// participants as threads; the same checks with `oracle.kind = "layered"`.
#[test]
fn adaptive_epochs_keep_mass_and_momentum() {
    let _machine = machine();
    let out = out_dir("adaptive");
    let out_s = out.to_str().unwrap();
    let (status, err) = run_to_end(&["run", SCENE, "--out", out_s, "--quiet"]);
    assert!(status.success(), "{err}");
    let text = check_epochs(&run_dir(&err));
    let (status, err) = run_to_end(&["run", SCENE, "--out", out_s, "--quiet", "--transport", "inproc"]);
    assert!(status.success(), "{err}");
    let b = std::fs::read_to_string(run_dir(&err).join("metrics.csv")).unwrap();
    assert!(
        grains_launch::metrics::physics_columns(&text) == grains_launch::metrics::physics_columns(&b),
        "adaptive epochs differ between processes and threads"
    );
    // The layered mode (depth below the top of each column, Yue 2018 §4.3) keeps them too.
    let (status, err) = run_to_end(&["run", SCENE, "--out", out_s, "--quiet", "--set", "oracle.kind=\"layered\""]);
    assert!(status.success(), "{err}");
    check_epochs(&run_dir(&err));
    std::fs::remove_dir_all(&out).unwrap();
}

/// Every epoch of a run keeps mass within 1% and momentum within 1% of max(|p|, m √(g d));
/// 10 epochs, at least 2 converting something. Returns the run's metrics.csv.
fn check_epochs(dir: &std::path::Path) -> String {
    let t = metrics(dir);
    let col = |name: &str| t.column(name).unwrap_or_else(|e| panic!("{e:#}"));
    let (step, before, dem_mass, mpm_mass) = (col("step"), col("oracle_mass"), col("dem_mass"), col("mpm_mass"));
    let (dem_items, mpm_items) = (col("dem_items"), col("mpm_items"));
    let p = |who: &str| -> Vec<[f64; 3]> {
        let (x, y, z) = (col(&format!("{who}_px")), col(&format!("{who}_py")), col(&format!("{who}_pz")));
        (0..x.len()).map(|i| [x[i], y[i], z[i]]).collect()
    };
    let (p_before, p_dem, p_mpm) = (p("oracle"), p("dem"), p("mpm"));
    let (mut epochs, mut converting) = (0, 0);
    for i in 0..t.len() {
        if before[i] == 0.0 {
            continue;
        }
        epochs += 1;
        let after = dem_mass[i] + mpm_mass[i];
        assert!(
            (after - before[i]).abs() < 0.01 * before[i],
            "step {}: mass {} -> {after}",
            step[i],
            before[i]
        );
        let dp = (0..3)
            .map(|a| (p_dem[i][a] + p_mpm[i][a] - p_before[i][a]).powi(2))
            .sum::<f64>()
            .sqrt();
        let p = p_before[i].iter().map(|c| c * c).sum::<f64>().sqrt();
        let scale = p.max(before[i] * (9.81f64 * 1e-3).sqrt());
        assert!(dp < 0.01 * scale, "step {}: momentum changed by {dp}, 1% of {scale}", step[i]);
        if dem_items[i] != dem_items[i - 1] || mpm_items[i] != mpm_items[i - 1] {
            converting += 1;
        }
    }
    assert_eq!(epochs, 10);
    assert!(converting >= 2, "only {converting} epochs converted anything");
    std::fs::read_to_string(dir.join("metrics.csv")).unwrap()
}

/// The oracle forced to one model: a band at φ0 = 1 km (every cell discrete, no points) gives
/// the DEM run of the same scene with `model = "dem"`, and at φ0 = −1 km (every cell
/// continuum, no grains) the MPM run with `model = "mpm"`: their last frames are the same
/// bytes, through 8 epochs that change nothing.
#[test]
fn an_oracle_forced_to_one_model_reproduces_that_model() {
    let _machine = machine();
    let out = out_dir("forced");
    let common = ["--set", "run.duration=0.02", "--set", "output.frames_every=400", "--quiet"];
    let last_frame = |extra: &[&str], sub: &str, name: &str| -> Vec<u8> {
        let o = out.join(sub);
        let mut args = vec!["run", SCENE, "--out", o.to_str().unwrap()];
        args.extend(common);
        args.extend(extra);
        let (status, err) = run_to_end(&args);
        assert!(status.success(), "{err}");
        let dir = run_dir(&err);
        if extra.contains(&"oracle.every=50") {
            // The epochs did run: the oracle's mass before each of the 8.
            let epochs = column(&dir, "oracle_mass")
                .iter()
                .filter(|m| m.parse::<f64>().unwrap() > 0.0)
                .count();
            assert_eq!(epochs, 8, "{sub}: epochs");
        }
        std::fs::read(dir.join("frames").join(format!("{name}_00000400.vtu"))).unwrap()
    };
    let forced = ["--set", "oracle.every=50"];
    let hybrid_discrete = last_frame(&[&forced[..], &["--set", "oracle.centre=1000"]].concat(), "hd", "grains");
    let dem = last_frame(&["--set", "body.0.model=\"dem\""], "d", "grains");
    assert!(hybrid_discrete == dem, "all-discrete hybrid and DEM frames differ");
    let hybrid_continuum = last_frame(&[&forced[..], &["--set", "oracle.centre=-1000"]].concat(), "hc", "points");
    let mpm = last_frame(&["--set", "body.0.model=\"mpm\""], "m", "points");
    assert!(hybrid_continuum == mpm, "all-continuum hybrid and MPM frames differ");
    std::fs::remove_dir_all(&out).unwrap();
}

/// Homogenization on a static pile (Yue 2018 §4.2): the adaptive pile all discrete, settled
/// for 0.3 s, then one epoch with the band 3 ± 1 mm under the surface turns the cells deeper
/// than 2 mm hybrid and gives them points. Their stress, from the grains' homogenized stress
/// (Alg. 11 with the wall contacts) through the MPM's own strain (b^e), per row of cells:
/// - σ_yy carries the weight above them, −ρ g × (mass above per width) (vertical
///   equilibrium of a pile ten times wider than deep), within 10%;
/// - the pressure −tr σ / 2 matches the grains' own in the same row (Christoffersen over the
///   contacts there, −Σ f ⊗ l / A), within 10%.
///
/// At creation: after it the coupled band relaxes (the continuum's top is free, the grains
/// above rest on the band's grains), which is the method, not the conversion.
#[test]
fn new_points_carry_the_stress_of_the_grains() {
    let mut h = Hybrid::load_with(SCENE, |s| {
        let o = s.oracle.as_mut().unwrap();
        o.centre = Some(1000.0);
    });
    let settle = (0.3 / h.scene.dt).round() as u64;
    for step in 1..=settle {
        h.step(step);
    }
    assert!(h.kinetic_energy() < 1e-7, "not settled: {}", h.kinetic_energy());
    h.scene.oracle.as_mut().unwrap().centre = Some(0.003);
    let mut oracle = grains_oracle_service::OracleState::new(&h.scene).unwrap();
    let cells = oracle.zones.len();
    oracle.zones = vec![Zone::Discrete; cells];
    let epoch = h.epoch(&mut oracle, settle);
    assert!(epoch.spawn_points.len() > 100, "{} new points", epoch.spawn_points.len());

    // Per row of cells (2 mm): σ_yy and pressure of the points, weight above, the grains'.
    let g = &h.dem.state.grains;
    let width = 0.04;
    let top = g.x.iter().zip(&g.radius).map(|(x, r)| x.y + r).fold(0.0, f64::max);
    let p = &h.mpm.points;
    let (mut rows_checked, mut failed) = (0, Vec::new());
    for row in 0..4 {
        let (lo, hi) = (row as f64 * 0.002, (row + 1) as f64 * 0.002);
        let members: Vec<usize> = (0..p.len())
            .filter(|&k| p.x[k].y >= lo && p.x[k].y < hi && p.x[k].x > 0.004 && p.x[k].x < 0.036)
            .collect();
        if members.len() < 10 {
            continue;
        }
        let n = members.len() as f64;
        let sigma_yy = members.iter().map(|&k| p.tau[k].y_axis.y / p.jacobian[k]).sum::<f64>() / n;
        let pressure = members
            .iter()
            .map(|&k| -(p.tau[k].x_axis.x + p.tau[k].y_axis.y) / (2.0 * p.jacobian[k]))
            .sum::<f64>()
            / n;
        let y = members.iter().map(|&k| p.x[k].y).sum::<f64>() / n;
        // Mass above y per width: grains above, with the weight the DEM gives them (the
        // points in the hybrid cells carry w of it, the grains 1 − w: together all of it).
        let above: f64 = (0..g.len()).filter(|&i| g.x[i].y > y).map(|i| g.mass[i]).sum::<f64>() / width;
        let weight = 9.81 * above;
        // The grains' pressure in the same row, away from the walls.
        let contacts = h.dem.pipeline.contact_forces(&h.dem.state);
        let mut trace = 0.0;
        for (i, _, force, l) in contacts {
            let c = g.x[i] - l * 0.5;
            if c.y >= lo && c.y < hi && c.x > 0.004 && c.x < 0.036 {
                trace += force.dot(l);
            }
        }
        // A grain on the floor: its half of the branch, from the contact to its centre.
        for (i, at, force) in h.dem.pipeline.wall_contact_forces(&h.dem.state) {
            if at.y >= lo && at.y < hi && at.x > 0.004 && at.x < 0.036 {
                trace += force.dot(g.x[i] - at);
            }
        }
        let grains_pressure = trace / (2.0 * (hi - lo) * 0.032);
        eprintln!(
            "row {row}: {} points, σ_yy {sigma_yy:.2} Pa (weight above {weight:.2}), pressure {pressure:.2} Pa (grains {grains_pressure:.2})",
            members.len()
        );
        if (-sigma_yy - weight).abs() >= 0.1 * weight {
            failed.push(format!(
                "row {row} (y {y:.4}, {:.1} mm deep): σ_yy {sigma_yy:.2} Pa vs weight above {weight:.2} Pa",
                (top - y) * 1e3
            ));
        }
        if (pressure - grains_pressure).abs() >= 0.1 * grains_pressure {
            failed.push(format!(
                "row {row}: points' pressure {pressure:.2} Pa vs the grains' {grains_pressure:.2} Pa"
            ));
        }
        rows_checked += 1;
    }
    assert!(failed.is_empty(), "{failed:#?}");
    assert!(rows_checked >= 2, "only {rows_checked} rows of new points");
}

/// Issue 22: the shear-band oracle (`oracle.kind = "shear_band"`, Chen 2021 Alg. 1 and §4)
/// between the real solvers, on a plate pushed into a continuum bed
/// (`tests/scenes/hybrid_band_2d.toml`). The run starts with no grain; the plate reaches the
/// bed at 0.03 s; an epoch after that finds a band and cuts grains from the scene's packing
/// into the cells around it. Checked:
/// - no grain before the plate touches, grains at the end, and the first ones arrive at an
///   epoch that deletes points;
/// - every epoch keeps the total mass to round-off (the enrichment's rules, also at the
///   epochs that only reweigh what crossed a zone's edge: without them the solvers' weights
///   moved it by 6e-4, measured) and the momentum within 1% of max(|p|, m √(g d));
/// - the grains stay where the material yields: none in the bottom 2 mm or within 3 mm of a
///   side wall, the rigid zones of a punch;
/// - the participants as threads give the same physics.
#[test]
fn a_shear_band_turns_the_continuum_discrete_where_it_forms() {
    const BAND: &str = "tests/scenes/hybrid_band_2d.toml";
    let _machine = machine();
    let out = out_dir("shear-band");
    let out_s = out.to_str().unwrap();
    let (status, err) = run_to_end(&["run", BAND, "--out", out_s, "--quiet"]);
    assert!(status.success(), "{err}");
    let dir = run_dir(&err);
    let t = metrics(&dir);
    let col = |name: &str| t.column(name).unwrap_or_else(|e| panic!("{e:#}"));
    let (step, time, before) = (col("step"), col("time"), col("oracle_mass"));
    let (dem_items, mpm_items, dem_mass, mpm_mass) = (col("dem_items"), col("mpm_items"), col("dem_mass"), col("mpm_mass"));
    let first = (0..t.len())
        .find(|&i| dem_items[i] > 0.0)
        .expect("the oracle never enriched a band");
    assert!(
        time[first] > 0.03,
        "grains at t = {} s, before the plate reached the bed",
        time[first]
    );
    assert!(
        before[first] > 0.0 && mpm_items[first] < mpm_items[first - 1],
        "the grains came outside an epoch"
    );
    assert!(dem_items[t.len() - 1] > 100.0, "{} grains at the end", dem_items[t.len() - 1]);
    let mut epochs = 0;
    for i in (0..t.len()).filter(|&i| before[i] > 0.0) {
        epochs += 1;
        let after = dem_mass[i] + mpm_mass[i];
        assert!(
            (after / before[i] - 1.0).abs() < 1e-9,
            "step {}: mass {} -> {after}",
            step[i],
            before[i]
        );
        let p = |who: &str| [col(&format!("{who}_px"))[i], col(&format!("{who}_py"))[i]];
        let (pb, pd, pm) = (p("oracle"), p("dem"), p("mpm"));
        let dp = (pd[0] + pm[0] - pb[0]).hypot(pd[1] + pm[1] - pb[1]);
        let scale = pb[0].hypot(pb[1]).max(before[i] * (9.81f64 * 1e-3).sqrt());
        assert!(dp < 0.01 * scale, "step {}: momentum changed by {dp}, 1% of {scale}", step[i]);
    }
    assert_eq!(epochs, t.len() / 10, "an epoch every 10 steps");
    let last = (0..t.len()).rev().find(|&i| step[i] % 500.0 == 0.0).unwrap();
    let frame = grains_service::vtu::Frame::read(&dir.join("frames").join(format!("grains_{:08}.vtu", step[last] as u64))).unwrap();
    for x in &frame.points {
        assert!(x[1] > 0.002 && x[0] > 0.003 && x[0] < 0.037, "a grain at {x:?}: in a rigid zone");
    }
    let (status, err) = run_to_end(&["run", BAND, "--out", out_s, "--quiet", "--transport", "inproc"]);
    assert!(status.success(), "{err}");
    let threads = std::fs::read_to_string(run_dir(&err).join("metrics.csv")).unwrap();
    let processes = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    assert!(
        grains_launch::metrics::physics_columns(&processes) == grains_launch::metrics::physics_columns(&threads),
        "the shear-band run differs between processes and threads"
    );
    std::fs::remove_dir_all(&out).unwrap();
}
