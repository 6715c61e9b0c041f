//! `mpm.initial_stress = "geostatic"`: a layer starts at rest under its own weight instead of
//! settling through its depth. The stress at seeding is the weight above each point (statics),
//! and a layer so started on a sticky floor stays at rest, where the unstressed one sags.

use grains_grid::D2;
use grains_mpm::matrix::Matrix;
use grains_mpm_service::{setup, solver::MpmSolver};
use grains_protocol::scene::{self, MpmInitialStress};
use grains_service::solver::{Solver, StepWindow};

/// A layer 0.2 m deep, periodic along x, on a sticky floor, under vertical gravity.
fn layer(initial: MpmInitialStress) -> scene::Scene {
    let text = r#"
schema = 1
gravity = [0.0, -9.81]
[run]
dimension = 2
dt = 1e-4
steps = 300
threads = 1
[domain]
min = [0.0, -0.03]
max = [0.1, 0.3]
cell_size = 0.01
periodic = [true, false]
[[material]]
name = "sand"
density = 2650.0
[material.mpm]
young = 1e6
poisson = 0.3
friction_angle = 30.0
packing = 0.6
[[body]]
material = "sand"
model = "mpm"
shape = "box"
min = [0.0, 0.0]
max = [0.1, 0.2]
[[wall]]
kind = "plane"
point = [0.0, 0.0]
normal = [0.0, 1.0]
sticky = true
"#;
    // A file of its own per call: the tests run at once.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("geostatic_layer_{n}.toml"));
    std::fs::write(&path, text).unwrap();
    let mut s = scene::load(&path).expect("test scene");
    s.mpm.initial_stress = initial;
    s
}

#[test]
fn the_geostatic_stress_is_the_weight_above_each_point() {
    let s = layer(MpmInitialStress::Geostatic);
    let (pts, params) = setup::build::<D2>(&s, &grains_service::zones::ZoneField::layered(&s)).unwrap();
    // K0: the elastic ν / (1 − ν) = 0.4286 is under the 30° cone's floor (1 − sin φ) / (1 + sin φ)
    // = 1/3, so the elastic one holds.
    let k0 = 0.3 / 0.7;
    assert!(setup::geostatic_k0_floor(30.0) < k0);
    let weight = 2650.0 * 0.6 * 9.81;
    for k in 0..pts.len() {
        let b = pts.b_e[k];
        let sigma = pts.tau[k] * (1.0 / b.det().sqrt());
        let y = pts.x[k].y;
        let want = -weight * (0.2 - y);
        let (sxx, syy, sxy) = (sigma.x_axis.x, sigma.y_axis.y, sigma.y_axis.x);
        assert!(
            (syy - want).abs() < 1e-9 * weight * 0.2,
            "point at y {y}: σ_yy {syy} against {want}"
        );
        assert!((sxx - k0 * want).abs() < 1e-9 * weight * 0.2, "point at y {y}: σ_xx {sxx}");
        assert!(sxy.abs() < 1e-9 * weight * 0.2);
    }
    // 10 × 20 cells of 2 × 2 points, no confining pressure on top.
    assert!(pts.len() == 800 && params.ambient_pressure == 0.0, "{} points", pts.len());
}

/// The mean of |v_y| over the points, largest over 300 steps (0.03 s, four transits of the
/// layer by its pressure wave, c = √(M / ρ) ≈ 29 m/s): an unstressed layer sags at about
/// g h / c ≈ 0.07 m/s at its top (the mean over the points: 0.038 measured); started geostatic
/// it stays within a hundredth of that (8e-5 measured).
#[test]
fn a_geostatic_layer_stays_at_rest_where_an_unstressed_one_sags() {
    let sag = |initial| {
        let s = layer(initial);
        let (points, params) = setup::build::<D2>(&s, &grains_service::zones::ZoneField::layered(&s)).unwrap();
        let mut solver = MpmSolver::new(&s, points, params, None, None).unwrap();
        let mut largest: f64 = 0.0;
        for step in 1..=300 {
            solver.step_alone(&StepWindow::of(&s, step)).unwrap();
            let p = &solver.points;
            let mean = p.v.iter().map(|v| v.y.abs()).sum::<f64>() / p.len() as f64;
            largest = largest.max(mean);
        }
        largest
    };
    let (unstressed, geostatic) = (sag(MpmInitialStress::None), sag(MpmInitialStress::Geostatic));
    eprintln!("largest mean |v_y|: unstressed {unstressed:.3e} m/s, geostatic {geostatic:.3e} m/s");
    assert!(unstressed > 0.02, "the unstressed layer's sag: {unstressed} m/s");
    assert!(
        geostatic < 0.01 * unstressed,
        "geostatic {geostatic} m/s against unstressed {unstressed}"
    );
}
