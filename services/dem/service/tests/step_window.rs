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
