//! Kinematic training's release (`grains_dem::training::release`) against linear elasticity.

mod common;

use glam::DVec2;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::D2;
use grains_dem::state::{DemState, Grains};
use grains_dem::training::{pressure, release};

const RADIUS: f64 = 1e-3;
const DENSITY: f64 = 2500.0;
const KN: f64 = 1e4;

/// A triangular lattice of touching disks, 16 × 16, its outer rows (centres within 1.5
/// diameters of the lattice's edge) the shell. Returns the state and the shell's ids.
fn lattice() -> (DemState<D2>, Vec<u64>) {
    let mut state = common::state(common::law(KN, 0.3, 0.5), DVec2::ZERO, Vec::new(), Vec::new());
    let (d, n) = (2.0 * RADIUS, 16);
    let row = d * 3f64.sqrt() / 2.0;
    let (width, height) = (n as f64 * d, (n - 1) as f64 * row);
    let mut shell = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let x = i as f64 * d + if j % 2 == 1 { 0.5 * d } else { 0.0 };
            let y = j as f64 * row;
            let id = (j * n + i) as u64;
            state
                .grains
                .push(id, DVec2::new(x, y), RADIUS, Grains::<D2>::mass_of(RADIUS, DENSITY), 0);
            let edge = x.min(width - 0.5 * d - x).min(y).min(height - y);
            if edge < 1.5 * d {
                shell.push(id);
            }
        }
    }
    (state, shell)
}

/// A lattice squeezed by its shell by a strain ε0 = 1% holds a pressure P0 ∝ ε0 (linear
/// springs, every contact kept). Released to P0 / 10, the shell must dilate by the strain s
/// that leaves ε0 / 10 of the squeeze: (1 − ε0)(1 + s) = 1 − ε0 / 10, s = 0.909%, within one
/// release step (0.05%) above it; the pressure ends at or under the target and above half of
/// it (one step moves it by P0 / 20); the grains keep the velocities they had. Without the
/// dilation the pressure stays at P0 and the test fails.
#[test]
fn a_squeezed_packing_gives_up_its_pressure_by_the_strain_linear_elasticity_predicts() {
    let (mut state, shell) = lattice();
    let in_shell = |id: u64| shell.binary_search(&id).is_ok();
    let centre = {
        let g = &state.grains;
        (0..g.len()).filter(|&i| in_shell(g.id[i])).map(|i| g.x[i]).sum::<DVec2>() / shell.len() as f64
    };
    let squeeze = 0.01;
    {
        let g = &mut state.grains;
        for i in 0..g.len() {
            g.x[i] = centre + (g.x[i] - centre) * (1.0 - squeeze);
            g.frozen[i] = in_shell(g.id[i]);
        }
    }
    let mass = Grains::<D2>::mass_of(RADIUS, DENSITY);
    let dt = std::f64::consts::PI / (KN / (0.5 * mass)).sqrt() / 50.0;
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    for _ in 0..2000 {
        pipe.step(&mut state, dt);
    }
    let g = &mut state.grains;
    for i in 0..g.len() {
        g.frozen[i] = false;
        g.v[i] = DVec2::new(0.01, -0.02);
    }
    // The interior and the area its grains fill at the lattice's packing fraction π / (2√3).
    let interior = |id: u64, _: DVec2| !in_shell(id);
    let count = state.grains.len() - shell.len();
    let area = count as f64 * std::f64::consts::PI * RADIUS * RADIUS / (std::f64::consts::PI / (2.0 * 3f64.sqrt()));
    let p0 = pressure(&pipe, &state, interior, area);
    assert!(p0 > 0.0, "the squeezed lattice holds a pressure");
    let target = p0 / 10.0;
    let r = release(&mut pipe, &mut state, &shell, interior, area, target, dt, 0.05);
    assert!((r.before / p0 - 1.0).abs() < 0.05, "before {} against {p0}", r.before);
    let expected = (1.0 - squeeze / 10.0) / (1.0 - squeeze) - 1.0;
    assert!(
        r.strain >= expected - 1e-4 && r.strain <= expected + 5e-4 + 1e-4,
        "dilation {:.5} against {expected:.5}",
        r.strain
    );
    assert!(
        r.after <= target && r.after > 0.5 * target,
        "pressure {} against the target {target}",
        r.after
    );
    let g = &state.grains;
    assert!((0..g.len()).all(|i| g.v[i] == DVec2::new(0.01, -0.02) && !g.frozen[i]));
}
