//! What the rigid-body tests share: a contact law and a DEM state of bodies alone.

use glam::DVec2;
use grains_dem::bodies::Body;
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::space::D2;
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall};

/// Spring k_n (k_t = k_n / 2), restitution e, friction μ, no cohesion.
pub fn law(kn: f64, e: f64, mu: f64) -> ContactParams {
    ContactParams {
        stiffness_normal: kn,
        stiffness_tangential: 0.5 * kn,
        damping: Damping::Restitution(e),
        friction: mu,
        cohesion_normal: 0.0,
        cohesion_tangential: 0.0,
        damping_scale: 1.0,
    }
}

/// Bodies and walls with one law, no grains, in a 2-m box.
pub fn state(law: ContactParams, gravity: DVec2, bodies: Vec<Body>, walls: Vec<Wall<D2>>) -> DemState<D2> {
    DemState {
        grains: Grains::default(),
        walls,
        bodies,
        params: DemParams {
            materials: vec![law],
            gravity,
            domain: Domain {
                min: [-1.0; 3],
                max: [1.0; 3],
                periodic: [false; 3],
            },
            skin: 1e-4,
        },
        time: 0.0,
    }
}
