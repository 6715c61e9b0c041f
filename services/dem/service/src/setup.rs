//! Scene → DEM state: the only place where the scene file meets the DEM library.

use glam::DVec2;
use grains_dem::contact::{ContactParams, Damping};
use grains_dem::packing::lattice_in_box;
use grains_dem::pipeline::{SAFE_FRACTION, critical_time_step};
use grains_dem::space::{Space, Vector};
use grains_dem::state::{DemParams, DemState, Domain, Grains, Wall};
use grains_grid::rng::{Rng, radius};
use grains_protocol::scene::{Body, DemDamping, DemMaterial, Model, Scene, Shape, WallShape};
use grains_protocol::wire::Zone;
use grains_service::zones::ZoneField;

/// DEM step length of a scene: the macro-step over the substeps.
pub fn dem_dt(scene: &Scene) -> f64 {
    scene.dt / scene.coupling.substeps as f64
}

/// The DEM library's contact parameters of a scene material.
pub fn contact_params(m: &DemMaterial) -> ContactParams {
    ContactParams {
        stiffness_normal: m.stiffness_normal,
        stiffness_tangential: m.stiffness_tangential,
        damping: match m.damping {
            DemDamping::Restitution(e) => Damping::Restitution(e),
            DemDamping::Viscous(g) => Damping::Viscous(g),
        },
        friction: m.friction,
        cohesion_normal: m.cohesion_normal,
        cohesion_tangential: m.cohesion_tangential,
        damping_scale: grains_service::fault::restitution_damping_scale(),
    }
}

/// Smallest grain radius a material can produce (radii are clamped to mean ± 2σ).
fn min_radius(m: &DemMaterial) -> f64 {
    (m.radius - 2.0 * m.radius_std).max(0.05 * m.radius)
}

/// The spacing of the lattice a body without a packing file is built on: the largest grain
/// (r + 2σ, where the radius distribution is clamped) with 2% to spare.
pub fn lattice_spacing(dem: &DemMaterial) -> f64 {
    2.0 * (dem.radius + 2.0 * dem.radius_std) * 1.02
}

/// The packing fraction of that lattice ([`lattice_in_box`]: triangular rows in 2D, square
/// layers in 3D, one site per s² √3/2 or s³) for grains of the material's radius and spread.
pub fn lattice_packing(dem: &DemMaterial, dim: usize) -> f64 {
    let (s, r, var) = (lattice_spacing(dem), dem.radius, dem.radius_std.powi(2));
    match dim {
        2 => std::f64::consts::PI * (r * r + var) / (s * s * 3f64.sqrt() / 2.0),
        _ => 4.0 / 3.0 * std::f64::consts::PI * (r.powi(3) + 3.0 * r * var) / s.powi(3),
    }
}

/// A grain's mass of radius `r` [m] (2D: per metre).
pub fn grain_mass(dim: usize, r: f64, density: f64) -> f64 {
    if dim == 2 {
        density * std::f64::consts::PI * r * r
    } else {
        density * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3)
    }
}

/// The largest DEM step the scene's DEM materials allow (the safe fraction of the smallest
/// critical step), with what it comes from: (step, critical step, smallest grain mass or a free
/// rigid body's effective mass, the material). `None` without DEM material.
pub fn stable_step(scene: &Scene) -> Option<(f64, f64, f64, &DemMaterial, &str)> {
    let mut best: Option<(f64, f64, f64, &DemMaterial, &str)> = None;
    for body in scene.bodies.iter().filter(|b| matches!(b.model, Model::Dem | Model::Hybrid)) {
        let mat = &scene.materials[body.material];
        let Some(dem) = &mat.dem else { continue };
        let m_min = grain_mass(scene.dim(), min_radius(dem), mat.density);
        let critical = critical_time_step(&contact_params(dem), m_min);
        if best.is_none_or(|b| SAFE_FRACTION * critical < b.0) {
            best = Some((SAFE_FRACTION * critical, critical, m_min, dem, &mat.name));
        }
    }
    // A grain against a rigid body takes the body's law: with the lightest grain.
    let lightest = scene
        .bodies
        .iter()
        .filter(|b| matches!(b.model, Model::Dem | Model::Hybrid))
        .filter_map(|b| {
            let mat = &scene.materials[b.material];
            mat.dem.as_ref().map(|dem| grain_mass(scene.dim(), min_radius(dem), mat.density))
        })
        .fold(f64::INFINITY, f64::min);
    for r in scene.rigids.iter().filter(|_| lightest.is_finite()) {
        let mat = &scene.materials[r.material];
        let Some(dem) = &mat.dem else { continue };
        let critical = critical_time_step(&contact_params(dem), lightest);
        if best.is_none_or(|b| SAFE_FRACTION * critical < b.0) {
            best = Some((SAFE_FRACTION * critical, critical, lightest, dem, &mat.name));
        }
    }
    // A free rigid body: its effective mass at its farthest point, 1 / (1/m + R²/I), over 4
    // (two faces flush touch with up to four vertex springs at once).
    for r in scene
        .rigids
        .iter()
        .filter(|r| r.motion == grains_protocol::scene::RigidMotion::Free)
    {
        let mat = &scene.materials[r.material];
        let Some(dem) = &mat.dem else { continue };
        let m_min = 0.25 * effective_mass(r, mat.density);
        let critical = critical_time_step(&contact_params(dem), m_min);
        if best.is_none_or(|b| SAFE_FRACTION * critical < b.0) {
            best = Some((SAFE_FRACTION * critical, critical, m_min, dem, &mat.name));
        }
    }
    best
}

/// A rigid body's effective mass at its farthest point, 1 / (1/m + R²/I): what a contact
/// there pushes (mass and inertia from its swept shape of density `rho`).
fn effective_mass(r: &grains_protocol::scene::Rigid, rho: f64) -> f64 {
    let vertices: Vec<DVec2> = r.vertices.iter().map(|&[x, y]| DVec2::new(x, y)).collect();
    let props = grains_dem::bodies::mass_properties(&vertices, r.radius);
    let reach = vertices.iter().map(|&v| (v - props.centroid).length()).fold(0.0, f64::max) + r.radius;
    1.0 / (1.0 / (rho * props.area) + reach * reach / (rho * props.second_moment))
}

/// Refuses a DEM step above the safe fraction of the critical step of any DEM material the
/// scene uses, with both numbers and what they come from.
pub fn check_time_step(scene: &Scene) -> Result<(), String> {
    let dt = dem_dt(scene);
    if let Some((safe, critical, m_min, dem, name)) = stable_step(scene)
        && dt > safe
    {
        return Err(format!(
            "the DEM step run.dt / coupling.substeps = {dt:.3e} s is above the stable limit for material `{name}`: \
             critical step {critical:.3e} s (k_n = {:.4e} N/m, smallest grain mass {m_min:.4e} kg), allowed at most {:.0}% of it = {safe:.3e} s; \
             lower run.dt or raise coupling.substeps",
            dem.stiffness_normal,
            SAFE_FRACTION * 100.0,
        ));
    }
    if let Some((limit, k, m)) = contact_step(scene)
        && scene.dt > limit
    {
        return Err(format!(
            "the macro-step run.dt = {:.3e} s is above the limit of the rigid bodies' contact with the material points \
             (Jiang 2020 eq. 51): 2π κ₂ √(m / k_n) = {limit:.3e} s with κ₂ = {CONTACT_KAPPA}, k_n = {k:.4e} N/m of the stiffest rigid \
             body and the lighter side's mass m = {m:.4e} kg (the lightest point, or a free body's effective mass); lower run.dt \
             or soften the body's stiffness_normal (fewer mpm.points_per_axis also make heavier points)",
            scene.dt
        ));
    }
    Ok(())
}

/// Jiang 2020 eq. 51's contact term: a material point meets a rigid body once per macro-step,
/// so the step must resolve the contact's vibration, Δt ≤ 2π κ₂ √(m / k_n) with κ₂ = 0.1 (the
/// paper's value) and m the lighter side of a contact: the lightest material point, or a free
/// body's effective mass at its farthest point, 1 / (1/m + R²/I), if that is lighter.
pub const CONTACT_KAPPA: f64 = 0.1;

/// The largest macro-step the contacts of material points with the rigid bodies allow (eq. 51),
/// with the stiffness and the mass it comes from; `None` without contact coupling.
pub fn contact_step(scene: &Scene) -> Option<(f64, f64, f64)> {
    if !scene.contact_coupling() {
        return None;
    }
    let bodies = scene
        .rigids
        .iter()
        .filter(|r| r.motion == grains_protocol::scene::RigidMotion::Free)
        .map(|r| effective_mass(r, scene.materials[r.material].density));
    let m = bodies.fold(scene.point_mass()?, f64::min);
    scene
        .rigids
        .iter()
        .filter_map(|r| scene.materials[r.material].dem.as_ref().map(|d| d.stiffness_normal))
        .map(|k| (2.0 * std::f64::consts::PI * CONTACT_KAPPA * (m / k).sqrt(), k, m))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Builds the DEM state of a scene: grains of every `dem` body on a jittered lattice (a
/// loose packing that gravity settles) or from its packing file, walls, domain; in `hybrid`
/// bodies only the grains of the discrete and hybrid cells of `zones`. Deterministic from the
/// scene's seed.
pub fn build_state<S: Space>(scene: &Scene, zones: &ZoneField) -> anyhow::Result<DemState<S>> {
    let (mut state, material_index) = bare_state::<S>(scene);
    let mut rng = Rng::new(scene.seed);
    // Per grain: whether it comes from a packing file.
    let mut from_packing = Vec::new();
    for body in scene.bodies.iter().filter(|b| matches!(b.model, Model::Dem | Model::Hybrid)) {
        let mat = &scene.materials[body.material];
        let Some(dem) = &mat.dem else { continue };
        let body_grains = BodyGrains {
            scene,
            zones,
            body,
            density: mat.density,
            material: material_index[body.material],
        };
        match &body.packing {
            Some(path) => body_grains.add_packed(&mut state, path, &mut from_packing)?,
            None => body_grains.add_lattice(&mut state, dem, &mut rng, &mut from_packing),
        }
    }
    add_walls(&mut state, scene);
    add_rigids(&mut state, scene, &material_index);
    drop_grains_cut_by_walls(&mut state, &from_packing);
    Ok(state)
}

/// A state with the scene's contact laws, gravity and domain and no grains, walls or bodies,
/// and each scene material's index among the laws (`u32::MAX`: none).
fn bare_state<S: Space>(scene: &Scene) -> (DemState<S>, Vec<u32>) {
    let (params, material_index) = dem_params::<S>(scene);
    let state = DemState::<S> {
        grains: Grains::default(),
        walls: Vec::new(),
        bodies: Vec::new(),
        params,
        time: 0.0,
    };
    (state, material_index)
}

/// The scene's DEM at time 0 with no grains (its walls and rigid bodies, its contact laws),
/// and each scene material's index among the laws (`u32::MAX`: none): what a caller fills
/// with grains of its own (the shear-band oracle's kinematic training).
pub fn grainless_state<S: Space>(scene: &Scene) -> (DemState<S>, Vec<u32>) {
    let (mut state, material_index) = bare_state::<S>(scene);
    add_walls(&mut state, scene);
    add_rigids(&mut state, scene, &material_index);
    (state, material_index)
}

/// The DEM parameters of a scene (the contact laws of its DEM materials, gravity, domain,
/// skin), and each scene material's index among those laws (`u32::MAX`: none).
fn dem_params<S: Space>(scene: &Scene) -> (DemParams<S>, Vec<u32>) {
    let mut materials = Vec::new();
    let mut material_index = vec![u32::MAX; scene.materials.len()];
    for (k, m) in scene.materials.iter().enumerate() {
        if let Some(dem) = &m.dem {
            material_index[k] = materials.len() as u32;
            materials.push(contact_params(dem));
        }
    }
    let mean_diameter = scene
        .materials
        .iter()
        .filter_map(|m| m.dem.as_ref())
        .map(|d| 2.0 * d.radius)
        .fold(0.0, f64::max);
    let params = DemParams {
        materials,
        gravity: S::from_array(scene.gravity),
        domain: Domain {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        },
        // LAMMPS-like skin of a tenth of a diameter: rebuilds every few tens of steps.
        skin: 0.1 * mean_diameter,
    };
    (params, material_index)
}

/// The grains of one `dem` or `hybrid` body, as they are added to the state (ids count up
/// from 0 in the order grains are made).
struct BodyGrains<'a> {
    scene: &'a Scene,
    zones: &'a ZoneField,
    body: &'a Body,
    /// Grain material density [kg/m³].
    density: f64,
    /// Index of the body's contact law in the state.
    material: u32,
}

impl BodyGrains<'_> {
    /// Hybrid bodies: grains in the discrete and hybrid cells only, the hybrid ones with mass
    /// and springs scaled by 1 − w; `None` for a grain in a continuum cell.
    fn zone_scale<S: Space>(&self, x: S::V) -> Option<f64> {
        match self.body.model {
            Model::Hybrid => match self.zones.zone_at(S::to_array(x)) {
                Zone::Continuum => None,
                Zone::Hybrid => Some(1.0 - self.scene.coupling.weight),
                Zone::Discrete => Some(1.0),
            },
            Model::Dem | Model::Mpm => Some(1.0),
        }
    }

    /// Grains of the packing file at `path` whose centre lies in the body's shape, at rest
    /// (moving with the body's velocity unless frozen; a grain of type 2 is frozen).
    fn add_packed<S: Space>(&self, state: &mut DemState<S>, path: &std::path::Path, from_packing: &mut Vec<bool>) -> anyhow::Result<()> {
        let (body, dim) = (self.body, self.scene.dim());
        let data = crate::lammps_data::read(path).map_err(anyhow::Error::msg)?;
        for a in &data.atoms {
            let x = S::from_array(a.x);
            let inside = match body.shape {
                Shape::Box { min, max } => (0..dim).all(|k| a.x[k] >= min[k] && a.x[k] <= max[k]),
                Shape::Ball { center, radius } => (x - S::from_array(center)).length() <= radius,
            };
            let Some(scale) = inside.then(|| self.zone_scale::<S>(x)).flatten() else {
                continue;
            };
            from_packing.push(true);
            let r = 0.5 * a.diameter;
            let id = state.grains.len() as u64;
            let i = state.grains.push(id, x, r, grain_mass(dim, r, self.density), self.material);
            state.grains.frozen[i] = a.kind == 2 || body.frozen;
            // Frozen grains are the boundary, not material: never weighed.
            state.grains.scale[i] = if state.grains.frozen[i] { 1.0 } else { scale };
            if !state.grains.frozen[i] {
                state.grains.v[i] = S::from_array(body.velocity);
            }
        }
        Ok(())
    }

    /// Grains on a jittered lattice over the body's box (for a ball, its bounding box, keeping
    /// the sites a largest grain fits inside at), radii drawn from the material's distribution.
    fn add_lattice<S: Space>(&self, state: &mut DemState<S>, dem: &DemMaterial, rng: &mut Rng, from_packing: &mut Vec<bool>) {
        let (body, dim) = (self.body, self.scene.dim());
        let r_max = dem.radius + 2.0 * dem.radius_std;
        let spacing = lattice_spacing(dem);
        let (lo, hi, ball) = match body.shape {
            Shape::Box { min, max } => (min, max, None),
            Shape::Ball { center, radius } => {
                let mut lo = center;
                let mut hi = center;
                for k in 0..dim {
                    lo[k] -= radius;
                    hi[k] += radius;
                }
                (lo, hi, Some((S::from_array(center), radius)))
            }
        };
        for x in lattice_in_box::<S>(lo, hi, spacing, r_max * 1.01, 0.01 * dem.radius, rng) {
            if let Some((c, big_r)) = ball
                && (x - c).length() > big_r - r_max
            {
                continue;
            }
            let r = radius(rng, dem.radius, dem.radius_std);
            let Some(scale) = self.zone_scale::<S>(x) else { continue };
            from_packing.push(false);
            let id = state.grains.len() as u64;
            let i = state.grains.push(id, x, r, grain_mass(dim, r, self.density), self.material);
            state.grains.frozen[i] = body.frozen;
            state.grains.scale[i] = if body.frozen { 1.0 } else { scale };
            state.grains.v[i] = S::from_array(body.velocity);
        }
    }
}

/// The scene's walls (a box as 2 planes per axis), translating and spinning as the scene
/// says, each with the index of its scene wall.
fn add_walls<S: Space>(state: &mut DemState<S>, scene: &Scene) {
    let dim = scene.dim();
    for (id, w) in scene.walls.iter().enumerate() {
        let mut add = |mut wall: Wall<S>| {
            wall.velocity = S::from_array(w.velocity);
            wall.spin = w.spin;
            wall.id = id;
            state.walls.push(wall);
        };
        match w.shape {
            WallShape::Plane { point, normal } => add(Wall::plane(S::from_array(point), S::from_array(normal), w.friction)),
            WallShape::Box { min, max } => {
                for k in 0..dim {
                    let mut n = [0.0; 3];
                    n[k] = 1.0;
                    add(Wall::plane(S::from_array(min), S::from_array(n), w.friction));
                    n[k] = -1.0;
                    add(Wall::plane(S::from_array(max), S::from_array(n), w.friction));
                }
            }
            WallShape::Drum { center, radius } => add(Wall::drum(S::from_array(center), radius, w.friction)),
            WallShape::Segment { from, to } => add(Wall::segment(S::from_array(from), S::from_array(to), w.friction)),
        }
    }
}

/// The scene's rigid bodies (ids in scene order), with their material's density.
fn add_rigids<S: Space>(state: &mut DemState<S>, scene: &Scene, material_index: &[u32]) {
    use grains_dem::bodies::{Body, Motion};
    use grains_protocol::scene::RigidMotion;
    for (id, r) in scene.rigids.iter().enumerate() {
        let vertices: Vec<DVec2> = r.vertices.iter().map(|&[x, y]| DVec2::new(x, y)).collect();
        let velocity = DVec2::from_array(r.velocity);
        let motion = match r.motion {
            RigidMotion::Free => Motion::Free,
            RigidMotion::Fixed => Motion::Fixed,
            RigidMotion::Scripted => Motion::Scripted { velocity, spin: r.spin },
        };
        let density = scene.materials[r.material].density;
        let mut body = Body::new(id as u64, &vertices, r.radius, density, material_index[r.material], motion);
        body.v = velocity;
        body.omega = r.spin;
        state.bodies.push(body);
    }
}

/// Lattice sites a wall cuts through (a drum's curve, a hopper's slope) stay empty; grains
/// of a packing (`from_packing`, per grain) keep the small overlaps they settled with. No
/// grain starts in or on a rigid body.
fn drop_grains_cut_by_walls<S: Space>(state: &mut DemState<S>, from_packing: &[bool]) {
    let keep: Vec<bool> = (0..state.grains.len())
        .map(|i| {
            let (x, r) = (state.grains.x[i], state.grains.radius[i]);
            let a = S::to_array(x);
            let on_a_body = state.bodies.iter().any(|b| b.overlaps(DVec2::new(a[0], a[1]), r));
            !on_a_body && (from_packing[i] || state.walls.iter().all(|w| grains_dem::neighbors::wall_gap(&w.shape, x) > r))
        })
        .collect();
    if keep.iter().any(|k| !k) {
        let old = std::mem::take(&mut state.grains);
        for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
            let j = state.grains.push(old.id[i], old.x[i], old.radius[i], old.mass[i], old.material[i]);
            state.grains.frozen[j] = old.frozen[i];
            state.grains.scale[j] = old.scale[i];
            state.grains.v[j] = old.v[i];
        }
    }
}
