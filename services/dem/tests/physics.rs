//! DEM against analytic answers (issue 3 "must show"). Each test names its reference.

use glam::{DVec2, DVec3};
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::pipeline::{DemPipeline, critical_time_step};
use grains_dem::space::{D2, D3, Space, Vector};
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall};

const RADIUS: f64 = 1e-3;
const DENSITY: f64 = 2500.0;
const KN: f64 = 1e4;

fn params(e: f64, mu: f64) -> ContactParams {
    ContactParams {
        stiffness_normal: KN,
        stiffness_tangential: 0.5 * KN,
        damping: Damping::Restitution(e),
        friction: mu,
        cohesion_normal: 0.0,
        cohesion_tangential: 0.0,
        damping_scale: 1.0,
    }
}

fn state<S: Space>(p: ContactParams, gravity: [f64; 3]) -> DemState<S> {
    DemState {
        grains: Grains::default(),
        walls: Vec::new(),
        bodies: Vec::new(),
        params: DemParams {
            materials: vec![p],
            gravity: S::from_array(gravity),
            domain: Domain {
                min: [-1.0; 3],
                max: [1.0; 3],
                periodic: [false; 3],
            },
            skin: 0.1 * RADIUS,
        },
        time: 0.0,
    }
}

fn mass<S: Space>() -> f64 {
    Grains::<S>::mass_of(RADIUS, DENSITY)
}

/// Contact duration of a pair of equal grains, π / ω with ω = √(k / m_red).
fn contact_time<S: Space>() -> f64 {
    std::f64::consts::PI / (KN / (0.5 * mass::<S>())).sqrt()
}

fn assert_close(actual: f64, expected: f64, rel: f64, what: &str) {
    let err = (actual - expected).abs() / expected.abs();
    assert!(err <= rel, "{what}: {actual} vs {expected} (relative error {err:.2e} > {rel:.0e})");
}

/// Two equal grains meet head-on at ±v; the rebound speed over the approach speed is the
/// restitution coefficient the damping was derived from (analytic for the linear
/// spring–dashpot: e = exp(−πζ/√(1−ζ²))). Also the gap between the grains at the end.
fn impact<S: Space>(e: f64) -> (f64, f64) {
    let mut st = state::<S>(params(e, 0.5), [0.0; 3]);
    let m = mass::<S>();
    let v0 = 0.1;
    let a = st.grains.push(0, S::from_array([-1.05 * RADIUS, 0.0, 0.0]), RADIUS, m, 0);
    let b = st.grains.push(1, S::from_array([1.05 * RADIUS, 0.0, 0.0]), RADIUS, m, 0);
    st.grains.v[a] = S::from_array([v0, 0.0, 0.0]);
    st.grains.v[b] = S::from_array([-v0, 0.0, 0.0]);
    let mut pipe = DemPipeline::<S>::new(1).unwrap();
    let dt = contact_time::<S>() / 400.0;
    let steps = (4.0 * contact_time::<S>() / dt) as usize + (0.1 * RADIUS / v0 / dt) as usize;
    pipe.run(&mut st, dt, steps);
    // Storage indices may change (grains are re-sorted by cell): find the grains by id.
    let (a, b) = (st.grains.index_of(0).unwrap(), st.grains.index_of(1).unwrap());
    let gap = (st.grains.x[b] - st.grains.x[a]).length() - 2.0 * RADIUS;
    let rebound = S::component(st.grains.v[b] - st.grains.v[a], 0);
    (rebound / (2.0 * v0), gap)
}

fn restitution<S: Space>(e: f64) -> f64 {
    let (e, gap) = impact::<S>(e);
    assert!(gap > 0.0, "the grains must have separated");
    e
}

#[test]
fn restitution_matches_target_for_head_on_impact_2d_and_3d() {
    for e in [0.1, 0.5, 0.9] {
        assert_close(restitution::<D2>(e), e, 0.01, &format!("2D restitution, e = {e}"));
        assert_close(restitution::<D3>(e), e, 0.01, &format!("3D restitution, e = {e}"));
    }
}

/// e = 0 is critical damping (ζ = 1): the pair comes to rest in contact, without rebound;
/// the overlap decays as (1 + ω t) e^{−ω t}, so it is not yet zero after the test's time.
#[test]
fn zero_restitution_stops_an_impact_without_rebound() {
    let (e2, gap2) = impact::<D2>(0.0);
    let (e3, gap3) = impact::<D3>(0.0);
    for (e, gap) in [(e2, gap2), (e3, gap3)] {
        assert!(e.abs() < 0.01, "rebound {e} of the approach speed");
        assert!(gap <= 0.0 && gap > -0.01 * RADIUS, "gap {gap} m");
    }
}

/// A frozen grain driven at V (a shear cell's plate) hits a grain at rest head-on: it is an
/// infinite mass, so the struck grain leaves at (1 + e) V (the impact in the driver's frame,
/// restitution e against an immovable partner), and the driver goes on at V, unslowed.
#[test]
fn a_driven_frozen_grain_keeps_its_velocity_and_strikes_at_one_plus_e_times_it() {
    fn strike<S: Space>(e: f64) -> (f64, f64, f64) {
        let mut st = state::<S>(params(e, 0.5), [0.0; 3]);
        let m = mass::<S>();
        let v0 = 0.1;
        let a = st.grains.push(0, S::from_array([-1.05 * RADIUS, 0.0, 0.0]), RADIUS, m, 0);
        st.grains.push(1, S::from_array([1.05 * RADIUS, 0.0, 0.0]), RADIUS, m, 0);
        st.grains.frozen[a] = true;
        st.grains.v[a] = S::from_array([v0, 0.0, 0.0]);
        let mut pipe = DemPipeline::<S>::new(1).unwrap();
        // Contact time of a grain against an immovable partner: π √(m / k).
        let t_c = std::f64::consts::PI * (m / KN).sqrt();
        let dt = t_c / 400.0;
        let steps = (3.0 * t_c / dt) as usize + (0.1 * RADIUS / v0 / dt) as usize;
        pipe.run(&mut st, dt, steps);
        let (a, b) = (st.grains.index_of(0).unwrap(), st.grains.index_of(1).unwrap());
        let travelled = S::component(st.grains.x[a], 0) + 1.05 * RADIUS;
        (
            S::component(st.grains.v[b], 0) / v0,
            S::component(st.grains.v[a], 0) / v0,
            travelled / (v0 * steps as f64 * dt),
        )
    }
    for e in [0.3, 0.9] {
        for (dim, (struck, driver, travelled)) in [("2D", strike::<D2>(e)), ("3D", strike::<D3>(e))] {
            assert_close(struck, 1.0 + e, 0.01, &format!("{dim} struck grain's speed over V, e = {e}"));
            assert_eq!(driver, 1.0, "{dim}: the driver's velocity changed");
            assert_close(travelled, 1.0, 1e-9, &format!("{dim} driver's travel over V t"));
        }
    }
}

fn floor<S: Space>(mu: f64) -> Wall<S> {
    Wall::plane(S::from_array([0.0; 3]), S::from_array([0.0, 1.0, 0.0]), mu)
}

/// A grain at rest on a floor: the floor carries its weight, k_n δ = m g (statics).
fn resting_load<S: Space>() -> f64 {
    let mut st = state::<S>(params(0.3, 0.5), [0.0, -9.81, 0.0]);
    st.walls.push(floor::<S>(0.5));
    st.grains.push(0, S::from_array([0.0, RADIUS, 0.0]), RADIUS, mass::<S>(), 0);
    let mut pipe = DemPipeline::<S>::new(1).unwrap();
    let dt = contact_time::<S>() / 100.0;
    pipe.run(&mut st, dt, 200_000);
    S::component(st.walls[0].load, 1)
}

#[test]
fn floor_carries_the_weight_of_a_resting_grain() {
    assert_close(-resting_load::<D2>(), mass::<D2>() * 9.81, 1e-3, "2D normal force");
    assert_close(-resting_load::<D3>(), mass::<D3>() * 9.81, 1e-3, "3D normal force");
}

/// Two grains stacked on a floor, at rest: each grain's Love–Weber pressure
/// −(1/(d V)) Σ l · f from statics. The top grain bears its own weight where it touches the
/// bottom one (equal radii: |l| = r − δ/2, δ = m g / k_n their overlap); the bottom one bears
/// the top's weight there and both weights at the floor (|l| = r − 2 m g / k_n).
fn stacked_pressures<S: Space>() -> (Vec<f64>, [f64; 2]) {
    let mut st = state::<S>(params(0.3, 0.5), [0.0, -9.81, 0.0]);
    st.walls.push(floor::<S>(0.5));
    st.grains.push(0, S::from_array([0.0, RADIUS, 0.0]), RADIUS, mass::<S>(), 0);
    st.grains.push(1, S::from_array([0.0, 3.0 * RADIUS, 0.0]), RADIUS, mass::<S>(), 0);
    let mut pipe = DemPipeline::<S>::new(1).unwrap();
    pipe.run(&mut st, contact_time::<S>() / 100.0, 200_000);
    let w = mass::<S>() * 9.81;
    let volume = Grains::<S>::mass_of(RADIUS, 1.0) * S::DIM as f64;
    let between = (RADIUS - 0.5 * w / KN) * w;
    let bottom = (between + (RADIUS - 2.0 * w / KN) * 2.0 * w) / volume;
    let top = between / volume;
    let p = pipe.grain_pressures(&st);
    let of = |id: u64| p[st.grains.index_of(id).unwrap()];
    (vec![of(0), of(1)], [bottom, top])
}

#[test]
fn a_grain_s_pressure_is_its_contacts_mean_stress() {
    for (dim, (p, expected)) in [(2, stacked_pressures::<D2>()), (3, stacked_pressures::<D3>())] {
        assert_close(p[0], expected[0], 1e-3, &format!("{dim}D bottom grain's pressure"));
        assert_close(p[1], expected[1], 1e-3, &format!("{dim}D top grain's pressure"));
    }
}

/// A grain launched sliding without spin ends up rolling at v0 / (1 + I/(m r²)): 2/3 v0
/// for a disk, 5/7 v0 for a solid sphere (angular momentum about the contact point is
/// conserved; classic result, e.g. Goldstein).
fn rolling_speed<S: Space>() -> (f64, f64) {
    let mut st = state::<S>(params(0.3, 0.4), [0.0, -9.81, 0.0]);
    st.walls.push(floor::<S>(0.4));
    let m = mass::<S>();
    let delta = m * 9.81 / KN;
    let i = st.grains.push(0, S::from_array([0.0, RADIUS - delta, 0.0]), RADIUS, m, 0);
    let v0 = 0.5;
    st.grains.v[i] = S::from_array([v0, 0.0, 0.0]);
    let mut pipe = DemPipeline::<S>::new(1).unwrap();
    let dt = contact_time::<S>() / 100.0;
    // Sliding lasts v0 / (μ g (1 + m r²/I)) < 0.1 s; run 0.3 s.
    pipe.run(&mut st, dt, (0.3 / dt) as usize);
    let vx = S::component(st.grains.v[i], 0);
    let spin = S::ang_array(st.grains.omega[i])[2];
    (vx / v0, -spin * RADIUS / vx)
}

#[test]
fn sliding_grain_ends_rolling_at_two_thirds_disk_five_sevenths_sphere() {
    let (ratio, rolling) = rolling_speed::<D2>();
    assert_close(ratio, 2.0 / 3.0, 0.01, "disk final speed / v0");
    assert_close(rolling, 1.0, 0.01, "disk ω r / v");
    let (ratio, rolling) = rolling_speed::<D3>();
    assert_close(ratio, 5.0 / 7.0, 0.01, "sphere final speed / v0");
    assert_close(rolling, 1.0, 0.01, "sphere ω r / v");
}

fn gas<S: Space>(n: usize, e: f64, mu: f64, seed: u64) -> DemState<S> {
    let mut st = state::<S>(params(e, mu), [0.0; 3]);
    let side = 2.6 * RADIUS * ((n as f64).powf(1.0 / S::DIM as f64).ceil() + 3.0);
    for k in 0..S::DIM {
        let mut lo = [0.0; 3];
        let mut nrm = [0.0; 3];
        nrm[k] = 1.0;
        st.walls.push(Wall::plane(S::from_array(lo), S::from_array(nrm), mu));
        lo[k] = side;
        nrm[k] = -1.0;
        st.walls.push(Wall::plane(S::from_array(lo), S::from_array(nrm), mu));
    }
    let mut rng = grains_grid::rng::Rng::new(seed);
    let pts = grains_dem::packing::lattice_in_box::<S>([0.0; 3], [side; 3], 2.6 * RADIUS, 1.3 * RADIUS, 0.2 * RADIUS, &mut rng);
    for (k, p) in pts.into_iter().take(n).enumerate() {
        let r = grains_grid::rng::radius(&mut rng, RADIUS, 0.05 * RADIUS);
        let i = st.grains.push(k as u64, p, r, Grains::<S>::mass_of(r, DENSITY), 0);
        st.grains.v[i] = S::from_array([rng.normal() * 0.05, rng.normal() * 0.05, rng.normal() * 0.05]);
    }
    assert_eq!(st.grains.len(), n);
    st
}

/// With e = 1 and μ = 0 the contact law is conservative: kinetic + elastic energy of 200
/// grains in a box stays constant (velocity Verlet is symplectic: no secular drift).
#[test]
fn elastic_frictionless_gas_conserves_energy() {
    let mut st = gas::<D2>(200, 1.0, 0.0, 3);
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    let dt = contact_time::<D2>() / 100.0;
    pipe.run(&mut st, dt, 1);
    let e0 = DemPipeline::<D2>::kinetic_energy(&st) + pipe.elastic_energy(&st);
    pipe.run(&mut st, dt, 100_000);
    let e1 = DemPipeline::<D2>::kinetic_energy(&st) + pipe.elastic_energy(&st);
    assert!(pipe.neighbors.builds > 10, "the grains must have moved and collided");
    assert_close(e1, e0, 1e-4, "total energy after 1e5 steps");
}

/// Two cohesive grains (bonded by an earlier contact) pulled apart by ±F: below the bond
/// strength e_n they stay together (k_n δ = −F), above it they separate (Chen 2021 §2.1).
fn pulled_pair_gap(force: f64, strength: f64) -> f64 {
    let mut p = params(0.3, 0.5);
    p.cohesion_normal = strength;
    let mut st = state::<D2>(p, [0.0; 3]);
    let m = mass::<D2>();
    st.grains.push(0, DVec2::new(-RADIUS * 0.999, 0.0), RADIUS, m, 0);
    st.grains.push(1, DVec2::new(RADIUS * 0.999, 0.0), RADIUS, m, 0);
    let mut pipe = DemPipeline::<D2>::new(1).unwrap();
    let dt = contact_time::<D2>() / 100.0;
    pipe.run(&mut st, dt, 2_000);
    let (a, b) = (st.grains.index_of(0).unwrap(), st.grains.index_of(1).unwrap());
    // Load slowly (a step load would overshoot the static stretch), then hold.
    let ramp = 20_000;
    for k in 1..=ramp {
        let f = force * k as f64 / ramp as f64;
        st.grains.external[a] = DVec2::new(-f, 0.0);
        st.grains.external[b] = DVec2::new(f, 0.0);
        pipe.step(&mut st, dt);
    }
    pipe.run(&mut st, dt, 30_000);
    let (a, b) = (st.grains.index_of(0).unwrap(), st.grains.index_of(1).unwrap());
    (st.grains.x[b] - st.grains.x[a]).length() - 2.0 * RADIUS
}

#[test]
fn cohesive_bond_holds_below_its_strength_and_breaks_above() {
    let strength = 0.05;
    let gap = pulled_pair_gap(0.8 * strength, strength);
    assert_close(gap, 0.8 * strength / KN, 0.01, "bonded gap k_n δ = F");
    let gap = pulled_pair_gap(1.2 * strength, strength);
    assert!(gap > 10.0 * strength / KN, "above the strength the grains separate: gap {gap}");
}

fn settle_3d(threads: usize) -> Vec<(u64, DVec3, DVec3)> {
    let mut st = gas::<D3>(1500, 0.3, 0.5, 9);
    st.params.gravity = DVec3::new(0.0, -9.81, 0.0);
    let mut pipe = DemPipeline::<D3>::new(threads).unwrap();
    pipe.run(&mut st, contact_time::<D3>() / 50.0, 3_000);
    let g = &st.grains;
    (0..g.len()).map(|i| (g.id[i], g.x[i], g.v[i])).collect()
}

/// Same seed and thread count ⇒ the same bits (the pair ranges, and so the order of every
/// float sum, depend only on the thread count and the pairs). Different thread counts may
/// differ in the last bits.
#[test]
fn runs_are_bit_identical_for_the_same_seed_and_thread_count() {
    assert_eq!(settle_3d(2), settle_3d(2));
    assert_eq!(settle_3d(1), settle_3d(1));
}

#[test]
fn critical_time_step_follows_mass_and_stiffness() {
    let p = params(1.0, 0.5);
    let m = mass::<D3>();
    // Undamped: 2/ω with ω = √(k / (m/2)).
    assert_close(
        critical_time_step(&p, m),
        2.0 / (KN / (0.5 * m)).sqrt(),
        1e-12,
        "undamped critical step",
    );
    assert!(
        critical_time_step(&params(0.1, 0.5), m) < critical_time_step(&p, m),
        "damping lowers it"
    );
}
