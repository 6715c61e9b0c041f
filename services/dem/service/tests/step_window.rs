//! The DEM takes its substeps from the step window the time owner gives it (the coupler's step
//! begin), not from the scene it read.

use grains_dem::D2;
use grains_dem::pipeline::DemPipeline;
use grains_dem_service::{setup, solver::DemSolver};
use grains_protocol::scene;
use grains_service::solver::{Solver, StepWindow};

fn scene() -> scene::Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/dem_small_2d.toml");
    scene::load(&path).expect("test scene")
}

/// A window of 50 substeps (the scene says 100) advances the grains by 50 DEM steps of
/// dt / 50, bit for bit, alone and coupled; a window of 0 substeps is refused.
#[test]
fn the_substeps_come_from_the_step_window() {
    let s = scene();
    assert_ne!(s.coupling.substeps, 50);
    let state = || setup::build_state::<D2>(&s, &grains_service::zones::ZoneField::layered(&s)).unwrap();
    let mut expected = state();
    let mut pipeline = DemPipeline::<D2>::new(s.threads as usize).unwrap();
    let (mut alone, mut coupled) = (
        DemSolver::new(&s, state(), None, None).unwrap(),
        DemSolver::new(&s, state(), None, None).unwrap(),
    );
    let window = StepWindow {
        substeps: 50,
        ..StepWindow::of(&s, 1)
    };
    pipeline.run(&mut expected, window.dt / 50.0, 50);
    alone.step_alone(&window).unwrap();
    assert_eq!(coupled.predict(&window).unwrap(), 0);
    coupled.finish(&window, &[]).unwrap();
    assert_eq!(alone.state.grains, expected.grains);
    assert_eq!(coupled.state.grains, expected.grains);
    let none = StepWindow { substeps: 0, ..window };
    let err = alone.step_alone(&none).unwrap_err().to_string();
    assert!(err.contains("0 substeps"), "{err}");
    assert!(coupled.predict(&none).is_err());
}

/// A scene's `confining_pressure` on a DEM box (`grains_dem::fluid`): a free box of grains in
/// a fluid at 1 kPa, without gravity or walls (`tests/scenes/dem_confined_2d.toml`), closes
/// into one block whose contacts carry across its middle, both ways, what the fluid pushes on
/// each half (equilibrium, within 2%; measured to the printed digit), and that push is p over
/// the block's face within the fluid's resolution, a cell over the face (measured 0.93 and
/// 0.95 p over the grains' extent plus a diameter, 17 mm; the surface c = ½ lies within half
/// a cell of the outer grains). No grain is left behind. Without the fluid the lattice's
/// grains never touch: nothing is carried, and the test fails.
#[test]
fn a_confined_dem_box_carries_the_pressure() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/dem_confined_2d.toml");
    let s = scene::load(&path).expect("test scene");
    let pressure = s.bodies[0].confining_pressure;
    let state = setup::build_state::<D2>(&s, &grains_service::zones::ZoneField::layered(&s)).unwrap();
    let mut dem = DemSolver::new(&s, state, None, None).unwrap();
    let steps = s.steps;
    for step in 1..=steps {
        dem.step_alone(&StepWindow::of(&s, step)).unwrap();
    }
    let g = &dem.state.grains;
    let (ke, mass): (f64, f64) = (0..g.len()).fold((0.0, 0.0), |(e, m), i| {
        (e + 0.5 * g.mass[i] * g.v[i].length_squared(), m + g.mass[i])
    });
    let mean = |k: usize| g.x.iter().map(|x| x[k]).sum::<f64>() / g.len() as f64;
    let middle = [mean(0), mean(1)];
    let extent = |k: usize| {
        let (lo, hi) = g.x.iter().fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x[k]), hi.max(x[k])));
        hi - lo
    };
    // σ_kk across the cut through the middle normal to k: the contacts' k-force across it over
    // the block's extent along the other axis (its grains' centres, plus a diameter).
    let contacts = dem.pipeline.contact_forces(&dem.state);
    let across = |k: usize| {
        let f: f64 = contacts
            .iter()
            .filter(|&&(i, _, _, b)| (g.x[i][k] < middle[k]) != (g.x[i][k] - b[k] < middle[k]))
            .map(|&(i, _, f, _)| if g.x[i][k] < middle[k] { f[k] } else { -f[k] })
            .sum();
        -f / (extent(1 - k) + 2.0 * s.materials[0].dem.as_ref().unwrap().radius)
    };
    let (sxx, syy) = (across(0), across(1));
    // The fluid's push on the upper half along k (the grains' external loads of the last
    // macro-step), over the same length.
    let push = |k: usize| {
        let f: f64 = (0..g.len()).filter(|&i| g.x[i][k] > middle[k]).map(|i| -g.external[i][k]).sum();
        f / (extent(1 - k) + 2.0 * s.materials[0].dem.as_ref().unwrap().radius)
    };
    eprintln!("the fluid's push on the upper halves: {:.1}, {:.1} Pa", push(0), push(1));
    eprintln!(
        "confined DEM box: {} grains over {:.2} x {:.2} mm, σxx {sxx:.1} σyy {syy:.1} Pa across the middle, mean speed {:.2e} m/s",
        g.len(),
        1e3 * extent(0),
        1e3 * extent(1),
        (2.0 * ke / mass).sqrt()
    );
    assert!(extent(0) < 0.021 && extent(1) < 0.021, "the block came apart");
    let h = 2.0 * 2.0 * g.radius.iter().copied().fold(0.0, f64::max);
    for k in 0..2 {
        let (cut, load) = (across(k), push(k));
        assert!(
            (cut / load - 1.0).abs() < 0.02,
            "axis {k}: the cut carries {cut:.1} Pa of the fluid's {load:.1}"
        );
        let face = extent(1 - k) + 2.0 * s.materials[0].dem.as_ref().unwrap().radius;
        let bound = h / face;
        assert!(
            (load / pressure - 1.0).abs() < bound,
            "axis {k}: the fluid pushes {load:.1} Pa over the block's face, p = {pressure} Pa (within a fluid cell of {h:.4} m over {face:.4} m)"
        );
    }
}
