//! The DEM half of a coupled step (Yue 2018 Alg. 2, 4–6) against the DEM step alone.

use grains_dem::D2;
use grains_dem_service::{setup, solver::DemSolver};
use grains_protocol::scene;
use grains_protocol::wire::RasterNode;
use grains_service::solver::{Solver, StepWindow};

fn scene() -> scene::Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/dem_small_2d.toml");
    scene::load(&path).expect("test scene")
}

fn solver(s: &scene::Scene) -> DemSolver<D2> {
    DemSolver::new(
        s,
        setup::build_state::<D2>(s, &grains_service::zones::ZoneField::layered(s)).unwrap(),
        None,
    )
    .unwrap()
}

/// Without hybrid grains a coupled step is the step alone, bit for bit: nothing is rasterized
/// and every grain keeps its substepped state.
#[test]
fn without_hybrid_grains_the_coupled_step_is_the_step_alone() {
    let s = scene();
    let (mut alone, mut coupled) = (solver(&s), solver(&s));
    for step in 1..=10 {
        let w = StepWindow::of(&s, step);
        alone.step_alone(&w).unwrap();
        assert_eq!(coupled.predict(&w).unwrap(), 0);
        coupled.finish(&w, &[]).unwrap();
    }
    assert_eq!(alone.state.grains.x, coupled.state.grains.x);
    assert_eq!(alone.state.grains.v, coupled.state.grains.v);
}

/// With every grain hybrid (scale 1 − w = 0.5) and no MPM to share nodes with, the grains take
/// the velocities of their own raster (Alg. 5): the weighted momentum of the raster is the
/// grains' weighted momentum after the substeps, and after the transfer back it is unchanged
/// (Σ_g m_g Σ_i w_gi v_i = Σ_i m_i v_i: the weights are a partition of unity), to round-off.
#[test]
fn hybrid_grains_round_trip_through_their_raster_keeping_momentum() {
    let s = scene();
    let mut coupled = solver(&s);
    coupled.state.grains.scale.iter_mut().for_each(|x| *x = 0.5);
    let w = StepWindow::of(&s, 1);
    let n = coupled.predict(&w).unwrap();
    assert!(n > 0);
    let mut raster = vec![RasterNode::default(); n];
    coupled.write_raster(&w, &mut raster);
    let g = &coupled.state.grains;
    let weighted = |g: &grains_dem::Grains<D2>| (0..g.len()).fold(glam::DVec2::ZERO, |a, i| a + g.v[i] * (g.mass[i] * g.scale[i]));
    let before = weighted(g);
    let raster_p = raster
        .iter()
        .fold(glam::DVec2::ZERO, |a, r| a + glam::DVec2::new(r.momentum[0], r.momentum[1]));
    let raster_m: f64 = raster.iter().map(|r| r.mass).sum();
    let grains_m: f64 = (0..g.len()).map(|i| g.mass[i] * g.scale[i]).sum();
    assert!((raster_m - grains_m).abs() < 1e-12 * grains_m);
    assert!((raster_p - before).length() < 1e-12 * grains_m, "{raster_p:?} vs {before:?}");
    coupled.finish(&w, &[]).unwrap();
    let after = weighted(&coupled.state.grains);
    assert!((after - before).length() < 1e-12 * grains_m, "{after:?} vs {before:?}");
}
