//! The MPM half of a coupled step (Yue 2018 Alg. 20, the raster, Alg. 21) against the MPM step
//! alone: a coupler that hands every node its own predicted velocity back changes nothing, and
//! the raster carries the points' mass and, with no forces, their momentum.

use grains_grid::D2;
use grains_mpm_service::{setup, solver::MpmSolver};
use grains_protocol::scene;
use grains_protocol::wire::{NodeVelocity, RasterNode};
use grains_service::solver::{Solver, StepWindow};

fn scene() -> scene::Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/mpm_small_2d.toml");
    scene::load(&path).expect("test scene")
}

fn solver(s: &scene::Scene) -> MpmSolver<D2> {
    let (points, params) = setup::build::<D2>(s, &grains_service::zones::ZoneField::layered(s)).unwrap();
    MpmSolver::new(s, points, params, None, None).unwrap()
}

#[test]
fn predict_and_finish_with_the_predicted_velocities_is_the_step_alone() {
    let s = scene();
    let (mut alone, mut coupled) = (solver(&s), solver(&s));
    for step in 1..=30 {
        let w = StepWindow::of(&s, step);
        alone.step_alone(&w).unwrap();
        let n = coupled.predict(&w).unwrap();
        let mut raster = vec![RasterNode::default(); n];
        coupled.write_raster(&w, &mut raster);
        assert!(raster.windows(2).all(|r| r[0].node < r[1].node), "raster sorted by node");
        if step == 1 {
            // At rest before the first step: the grid carries every point's mass.
            let mass: f64 = raster.iter().map(|r| r.mass).sum();
            let points: f64 = coupled.points.mass.iter().sum();
            assert!((mass - points).abs() < 1e-12 * points, "{mass} vs {points}");
        }
        let velocities: Vec<NodeVelocity> = raster
            .iter()
            .map(|r| NodeVelocity {
                node: r.node,
                velocity: r.momentum.map(|p| p / r.mass),
            })
            .collect();
        coupled.finish(&w, &velocities).unwrap();
    }
    let (a, c) = (&alone.points, &coupled.points);
    assert_eq!(a.id, c.id);
    for k in 0..a.len() {
        // m v / m differs from v by rounding only.
        assert!((a.v[k] - c.v[k]).length() < 1e-12, "point {k}: {:?} vs {:?}", a.v[k], c.v[k]);
        assert!((a.x[k] - c.x[k]).length() < 1e-12, "point {k}");
    }
}

#[test]
fn a_velocity_on_a_node_without_material_is_refused() {
    let s = scene();
    let mut coupled = solver(&s);
    let w = StepWindow::of(&s, 1);
    coupled.predict(&w).unwrap();
    let err = coupled
        .finish(
            &w,
            &[NodeVelocity {
                node: 0,
                velocity: [1.0, 0.0, 0.0],
            }],
        )
        .unwrap_err();
    assert!(err.to_string().contains("no material"), "{err}");
}

/// Contact coupling (protocol §3.11): the MPM sends the points within a body's reach plus r_p,
/// and takes back forces only on points it sent, each once and in order; a force it takes acts
/// for one step and is gone after it (the scene's own dead loads stay).
#[test]
fn contact_forces_act_on_points_sent_for_one_step_only() {
    use grains_protocol::wire::{BodyReach, PointForce};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/mpm_on_rigid_2d.toml");
    let s = scene::load(&path).expect("test scene");
    let mut m = solver(&s);
    let dead = m.points.loads.len();
    // A reach circle around the block's lower left corner.
    let reach = [BodyReach {
        id: 0,
        center: [0.0, 0.0, 0.0],
        reach: 0.002,
    }];
    let mut sent = Vec::new();
    m.contact_points(&reach, &mut sent);
    let r_p = s.contact_radius();
    let within = |x: &<D2 as grains_grid::Space>::V| x.length() <= 0.002 + r_p;
    assert_eq!(sent.len(), m.points.x.iter().filter(|x| within(x)).count());
    assert!(!sent.is_empty() && sent.windows(2).all(|w| w[0].index < w[1].index));
    assert!(sent.iter().all(|p| p.radius == r_p && p.mass == m.points.mass[p.index as usize]));
    let force = |index| PointForce {
        index,
        force: [0.0, 1e-3, 0.0],
    };
    let unsent = (0..m.points.len() as u64).find(|k| sent.iter().all(|p| p.index != *k)).unwrap();
    for bad in [
        vec![force(unsent)],
        vec![force(sent[0].index), force(sent[0].index)],
        vec![PointForce {
            force: [f64::NAN, 0.0, 0.0],
            ..force(sent[0].index)
        }],
    ] {
        let err = m.take_contact_forces(&bad).unwrap_err().to_string();
        assert!(err.contains("not a point the MPM sent"), "{err}");
    }
    assert_eq!(m.points.loads.len(), dead, "a refused list adds nothing");
    m.take_contact_forces(&[force(sent[0].index), force(sent[1].index)]).unwrap();
    assert_eq!(m.points.loads.len(), dead + 2);
    m.step_alone(&StepWindow::of(&s, 1)).unwrap();
    assert_eq!(m.points.loads.len(), dead, "the contact forces acted for one step");
}

/// A free box in a confining fluid (`confining_pressure`, the MPM's ambient pressure), started
/// at no stress: the fluid squeezes it, which the runaway bound must allow (its work p V is in
/// the bound; without it the bound was 100 × the box's zero kinetic energy and the first step
/// stopped the run), and at rest (PIC damps the ringing) its middle carries the fluid's
/// pressure within 1% (force balance of a uniformly loaded body).
#[test]
fn a_confined_box_is_squeezed_without_a_runaway() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../tests/scenes/mpm_confined_2d.toml");
    let s = scene::load(&path).expect("test scene");
    let mut mpm = solver(&s);
    assert_eq!(mpm.params.ambient_pressure, 1000.0);
    assert!(mpm.points.loads.is_empty(), "no dead loads: the fluid");
    for step in 1..=s.steps {
        mpm.step_alone(&StepWindow::of(&s, step)).unwrap();
    }
    let p = &mpm.points;
    let middle: Vec<f64> = (0..p.len())
        .filter(|&k| (p.x[k].x - 0.01).abs() < 0.004 && (p.x[k].y - 0.01).abs() < 0.004)
        .map(|k| grains_mpm::pipeline::Model::pressure(&p.tau[k], p.jacobian[k]))
        .collect();
    let mean = middle.iter().sum::<f64>() / middle.len() as f64;
    let speed = p.v.iter().map(|v| v.length()).fold(0.0, f64::max);
    eprintln!("at the end: the middle's pressure {mean:.1} Pa, the fastest point {speed:.2e} m/s");
    assert!((mean / 1000.0 - 1.0).abs() < 0.01, "the middle's pressure {mean:.1} Pa");
}
