//! Quick cost probe: settle a dense 3D bed and time steps (not the benchmark; see `grains bench dem`).
use glam::DVec3;
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::packing::lattice_in_box;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::D3;
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall};
use grains_grid::rng::{Rng, radius};
use std::time::Instant;

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let threads: usize = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let d: f64 = 1e-3;
    let side: f64 = 30e-3;
    let p = ContactParams {
        stiffness_normal: 1181.4,
        stiffness_tangential: 590.7,
        damping: Damping::Viscous(4.6667e-3),
        friction: 0.5,
        cohesion_normal: 0.0,
        cohesion_tangential: 0.0,
        damping_scale: 1.0,
    };
    let height = n as f64 / (side / (1.05 * d)).powi(2) * 1.05 * d + 2.0 * d;
    let mut st = DemState::<D3> {
        grains: Grains::default(),
        walls: vec![Wall::plane(DVec3::ZERO, DVec3::Z, 0.5)],
        bodies: Vec::new(),
        params: DemParams {
            materials: vec![p],
            gravity: DVec3::new(0.0, 0.0, -9.81),
            domain: Domain {
                min: [0.0; 3],
                max: [side, side, 1.0],
                periodic: [true, true, false],
            },
            skin: 1e-4,
        },
        time: 0.0,
    };
    let mut rng = Rng::new(1);
    for (k, x) in lattice_in_box::<D3>([0.0; 3], [side, side, height], 1.21 * d, 0.6 * d, 0.05 * d, &mut rng)
        .into_iter()
        .take(n)
        .enumerate()
    {
        let r = radius(&mut rng, 0.5 * d, 0.04 * d);
        st.grains.push(k as u64, x, r, Grains::<D3>::mass_of(r, 2530.0), 0);
    }
    let mut pipe = DemPipeline::<D3>::new(threads).unwrap();
    let dt = 5e-7;
    let t = Instant::now();
    pipe.run(
        &mut st,
        4.0 * dt,
        std::env::args().nth(3).and_then(|s| s.parse().ok()).unwrap_or(20_000),
    );
    eprintln!(
        "settled {} grains in {:.1} s, KE {:.3e}",
        st.grains.len(),
        t.elapsed().as_secs_f64(),
        DemPipeline::<D3>::kinetic_energy(&st)
    );
    let steps = 1000;
    let builds = pipe.neighbors.builds;
    let contacts = pipe.forces.iter().map(|f| f.contacts as f64).sum::<f64>() / st.grains.len() as f64;
    let t = Instant::now();
    pipe.run(&mut st, dt, steps);
    let us = t.elapsed().as_secs_f64() * 1e6 / (steps as f64 * st.grains.len() as f64);
    println!(
        "{} grains, {threads} threads: {us:.4} µs/grain-step wall, {:.2} contacts/grain, {} pairs listed, {} rebuilds",
        st.grains.len(),
        contacts,
        pipe.neighbors.pairs.len(),
        pipe.neighbors.builds - builds
    );
}
