//! Scene → material points and step parameters: the only place where the scene file meets the
//! MPM library.

use grains_grid::polygon::near;
use grains_grid::{Grid, Space};
use grains_mpm::boundary::{Contact, Geometry, Wall};
use grains_mpm::constitutive::hencky_critical_state::HenckyCriticalState;
use grains_mpm::constitutive::plasticity_drucker_prager::{DruckerPragerYue, InertialFriction};
use grains_mpm::matrix::Matrix;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{DOMAIN_WALL_NODES, MAX_CFL, Model, MpmParams, PointLoads, Transfer, cfl_time_step};
use grains_mpm::points::{Points, Region, seed};
use grains_protocol::scene::{
    ContactForces, Material, Model as BodyModel, MpmDomainWalls, MpmInitialStress, MpmModel, Scene, Shape, WallShape,
};
use grains_protocol::wire::Zone;
use grains_service::zones::ZoneField;

/// The one MPM material of a scene (one per scene in this version) and its index.
fn mpm_material(scene: &Scene) -> Result<(usize, &Material), String> {
    let mut used = scene.bodies.iter().filter(|b| b.model != BodyModel::Dem).map(|b| b.material);
    let Some(first) = used.next() else {
        return Err("the scene has no mpm or hybrid body".into());
    };
    if let Some(other) = used.find(|&m| m != first) {
        return Err(format!(
            "mpm bodies use materials `{}` and `{}`; this version runs one MPM material per scene",
            scene.materials[first].name, scene.materials[other].name
        ));
    }
    Ok((first, &scene.materials[first]))
}

/// The constitutive model of a material in `dim` dimensions.
pub fn model(material: &Material, dim: usize) -> Model {
    let m = material.mpm.as_ref().expect("validated: mpm bodies have [material.mpm]");
    match m.model {
        MpmModel::DruckerPrager => {
            let mut dp = DruckerPragerYue::new(m.young, m.poisson, m.friction_angle, dim);
            dp.rate = m.rate.map(|r| InertialFriction {
                sin_static: m.friction_angle.to_radians().sin(),
                sin_dynamic: r.friction_angle_2.to_radians().sin(),
                i0: r.i0,
                // Checked by `check`: a rate-dependent continuum has grains to take d from.
                diameter: 2.0 * material.dem.as_ref().map_or(0.0, |d| d.radius),
                grain_density: material.density,
                dim,
            });
            Model::Yue(dp)
        }
        MpmModel::CriticalState { packing_critical, chi, xi } => {
            let elastic = DruckerPragerYue::new(m.young, m.poisson, 0.0, dim);
            Model::CriticalState(HenckyCriticalState {
                bulk: elastic.bulk,
                shear: elastic.shear,
                tan_friction_cs: m.friction_angle.to_radians().tan(),
                packing_cs: packing_critical,
                chi,
                xi,
                cohesion: m.cohesion,
            })
        }
    }
}

/// Bulk density of the continuum: packing fraction × grain material density [kg/m³].
fn bulk_density(material: &Material) -> f64 {
    material.density * material.mpm.as_ref().map_or(1.0, |m| m.packing)
}

/// What the MPM needs of a scene before anything runs: one material, no segment walls in 3D, and
/// the time step under [`MAX_CFL`] of the CFL limit h / c of the elastic wave speed c = √(M / ρ). Errors name
/// the scene field.
pub fn check(scene: &Scene) -> Result<(), (String, String)> {
    let (_, material) = mpm_material(scene).map_err(|e| ("body".to_string(), e))?;
    for (k, w) in scene.walls.iter().enumerate() {
        if matches!(w.shape, WallShape::Segment { .. }) && scene.dim() == 3 {
            return Err((
                format!("wall.{k}.kind"),
                "an MPM segment wall is 2D only (a thin rod holds no continuum in 3D): use a \"plane\" or \"box\"".into(),
            ));
        }
    }
    if scene.mpm.initial_stress == MpmInitialStress::Geostatic && scene.gravity[1] >= 0.0 {
        return Err((
            "mpm.initial_stress".into(),
            format!(
                "\"geostatic\" weighs the body above each point along -y: gravity needs a downward y component, got {:?}",
                scene.gravity
            ),
        ));
    }
    let dim = scene.dim();
    let h = scene.domain.cell_size;
    // The outer three node layers of every domain face are its wall (DOMAIN_WALL_NODES); a
    // periodic axis has no faces.
    let margin = (DOMAIN_WALL_NODES - 1) as f64 * h;
    for (k, b) in scene.bodies.iter().enumerate().filter(|(_, b)| b.model != BodyModel::Dem) {
        let (lo, hi) = match b.shape {
            Shape::Box { min, max } => (min, max),
            Shape::Ball { center, radius } => (center.map(|c| c - radius), center.map(|c| c + radius)),
        };
        for a in (0..dim).filter(|&a| !scene.domain.periodic[a]) {
            if lo[a] < scene.domain.min[a] + margin || hi[a] > scene.domain.max[a] - margin {
                return Err((
                    format!("body.{k}"),
                    format!(
                        "MPM material must lie {margin} m (two cells) inside the domain on every side, where the domain's own wall \
                         layers begin: axis {a} of the body spans [{}, {}], the domain [{}, {}]; widen domain.min/max",
                        lo[a], hi[a], scene.domain.min[a], scene.domain.max[a]
                    ),
                ));
            }
        }
    }
    if material.mpm.as_ref().is_some_and(|m| m.rate.is_some()) && material.dem.is_none() {
        let k = scene.materials.iter().position(|m| std::ptr::eq(m, material)).unwrap_or(0);
        return Err((
            format!("material.{k}.mpm.friction_angle_2"),
            "a rate-dependent friction needs the grain diameter of the inertial number: give the material a [material.dem] radius".into(),
        ));
    }
    let rho = bulk_density(material);
    let model = model(material, dim);
    let limit = cfl_time_step(&model, rho, h, dim);
    if scene.dt > MAX_CFL * limit {
        return Err((
            "run.dt".into(),
            format!(
                "the MPM step run.dt = {:.3e} s is CFL number {:.2}, above the {MAX_CFL} allowed (the step h / c = {limit:.3e} s has CFL number 1; \
                 explicit MPM with GIMP was seen to blow up from 0.9): cell h = {h} m, \
                 elastic wave speed c = √(M/ρ) = {:.1} m/s with P-wave modulus M = {:.4e} Pa of material `{}` and bulk density ρ = {rho:.1} kg/m³; \
                 lower run.dt to at most {:.3e} s or coarsen domain.cell_size",
                scene.dt,
                scene.dt / limit,
                h / limit,
                model.p_wave_modulus(dim),
                material.name,
                MAX_CFL * limit
            ),
        ));
    }
    Ok(())
}

/// The largest MPM step the scene allows: [`MAX_CFL`] of the CFL limit h / c of its
/// material (see [`check`]); `None` without MPM material.
pub fn stable_step(scene: &Scene) -> Option<f64> {
    let (_, material) = mpm_material(scene).ok()?;
    let dim = scene.dim();
    Some(MAX_CFL * cfl_time_step(&model(material, dim), bulk_density(material), scene.domain.cell_size, dim))
}

/// How far behind a segment, in cells, grid nodes belong to it: a GIMP point's support reaches
/// 1.5 cells, so two cells keep a point in front from weighing free nodes behind.
const SEGMENT_CELLS: f64 = 2.0;

fn vec<S: Space>(a: [f64; 3]) -> S::V {
    S::from_array(a)
}

/// Points of every mpm body (of `hybrid` bodies, those in the hybrid and continuum cells of
/// `zones`) and the step parameters of a scene.
pub fn build<S: MpmSpace>(scene: &Scene, zones: &ZoneField) -> Result<(Points<S>, MpmParams<S>), String> {
    let dim = scene.dim();
    let (material_index, material) = mpm_material(scene)?;
    let (grid, kernel) = grains_service::grid::scene_grid(scene);
    let walls = walls::<S>(scene);
    let mut pts = seed_points::<S>(scene, zones, (material_index, material), &grid, &walls);
    let model = model(material, dim);
    if scene.mpm.initial_stress == MpmInitialStress::Geostatic {
        geostatic(scene, material, &model, &mut pts);
    }
    let params = MpmParams {
        grid,
        kernel,
        model,
        gravity: vec::<S>(scene.gravity),
        transfer: match scene.mpm.flip {
            Some(beta) => Transfer::Flip(beta),
            None => Transfer::Apic,
        },
        domain_walls: Some(match scene.mpm.domain_walls {
            MpmDomainWalls::Slip => Contact::Slip,
            MpmDomainWalls::Sticky => Contact::Sticky,
        }),
        walls,
        point_loads: match scene.coupling.contact_forces {
            ContactForces::Points => PointLoads::Weights,
            ContactForces::Nodes => PointLoads::Nearest,
            ContactForces::Faces => PointLoads::Face,
        },
        // The scene's confining pressure, the same on every continuum body (the scene checks).
        ambient_pressure: scene.bodies.iter().map(|b| b.confining_pressure).fold(0.0, f64::max),
    };
    Ok((pts, params))
}

/// `mpm.initial_stress = "geostatic"`: every point at rest under the weight of its body above
/// it along −y, σ_yy = −ρ g_y (top − y), σ_xx = σ_zz = K0 σ_yy with the elastic K0 = ν / (1 − ν)
/// or, where that would lie outside the friction cone, the least it holds, (1 − sin φ) / (1 +
/// sin φ); its elastic strain b^e is the one of that stress (as for points made from grains).
/// The top is the body's (a box's upper face, a ball's surface over the point), so a hybrid
/// body's grains above the continuum weigh on it at the continuum's density.
fn geostatic<S: MpmSpace>(scene: &Scene, material: &Material, model: &Model, pts: &mut Points<S>) {
    let mpm = material.mpm.as_ref().expect("an MPM material");
    let k0 = (mpm.poisson / (1.0 - mpm.poisson)).max(geostatic_k0_floor(mpm.friction_angle));
    let weight = bulk_density(material) * -scene.gravity[1];
    for k in 0..pts.len() {
        let [x, y, z] = S::to_array(pts.x[k]);
        let top = scene
            .bodies
            .iter()
            .filter(|b| b.model != BodyModel::Dem)
            .filter_map(|b| match b.shape {
                Shape::Box { min, max } => {
                    let inside = (0..scene.dim())
                        .filter(|&a| a != 1)
                        .all(|a| (min[a]..=max[a]).contains(&[x, y, z][a]));
                    (inside && y <= max[1]).then_some(max[1])
                }
                Shape::Ball { center, radius } => {
                    let across = (x - center[0]).powi(2) + if scene.dim() == 3 { (z - center[2]).powi(2) } else { 0.0 };
                    (across <= radius * radius).then(|| center[1] + (radius * radius - across).sqrt())
                }
            })
            .fold(y, f64::max);
        let syy = -weight * (top - y);
        let sigma = <S::M as Matrix>::from_rows3([[k0 * syy, 0.0, 0.0], [0.0, syy, 0.0], [0.0, 0.0, k0 * syy]]);
        let b_e = model.strain_of_stress(&sigma);
        pts.b_e[k] = b_e;
        pts.tau[k] = model.kirchhoff(&b_e);
    }
}

/// The least K0 = σ_xx / σ_yy that the plane Mohr–Coulomb cone of friction angle φ [deg] holds:
/// (σ_yy − σ_xx) / (σ_yy + σ_xx) = sin φ.
pub fn geostatic_k0_floor(friction_angle: f64) -> f64 {
    let s = friction_angle.to_radians().sin();
    (1.0 - s) / (1.0 + s)
}

/// The scene's walls as the MPM's: geometry (a segment [`SEGMENT_CELLS`] cells thick), contact
/// (sticky, else frictional, else slip) and velocity, each with the index of its scene wall.
fn walls<S: MpmSpace>(scene: &Scene) -> Vec<Wall<S>> {
    let h = scene.domain.cell_size;
    scene
        .walls
        .iter()
        .enumerate()
        .map(|(id, w)| {
            let geometry = match w.shape {
                WallShape::Plane { point, normal } => Geometry::Plane {
                    point: vec::<S>(point),
                    normal: vec::<S>(normal),
                },
                WallShape::Box { min, max } => Geometry::Box {
                    min: vec::<S>(min),
                    max: vec::<S>(max),
                },
                WallShape::Segment { from, to } => Geometry::Segment {
                    from: vec::<S>(from),
                    to: vec::<S>(to),
                    thickness: SEGMENT_CELLS * h,
                },
                WallShape::Drum { center, radius } => Geometry::Drum {
                    center: vec::<S>(center),
                    radius,
                    spin: w.spin,
                },
            };
            let contact = if w.sticky {
                Contact::Sticky
            } else if w.friction > 0.0 {
                Contact::Friction(w.friction)
            } else {
                Contact::Slip
            };
            Wall {
                geometry,
                contact,
                velocity: vec::<S>(w.velocity),
                shift: S::V::default(),
                id,
            }
        })
        .collect()
}

/// The points of every mpm and hybrid body (of `material`, index and material): seeded
/// `points_per_axis` per cell and axis of `grid` at the bulk density, none behind a wall or
/// where a rigid body is (within its swept outline and the points' contact radius: they would
/// start deep in contact), a hybrid body's only in its hybrid (weight w) and continuum cells;
/// moving at the body's velocity, and a box body under its confining pressure.
fn seed_points<S: MpmSpace>(
    scene: &Scene,
    zones: &ZoneField,
    (material_index, material): (usize, &Material),
    grid: &Grid,
    walls: &[Wall<S>],
) -> Points<S> {
    let dim = scene.dim();
    let h = scene.domain.cell_size;
    let per_axis = scene.mpm.points_per_axis as usize;
    let spacing = h / per_axis as f64;
    let volume = spacing.powi(dim as i32);
    let rho = bulk_density(material);
    let packing = material.mpm.as_ref().map_or(1.0, |m| m.packing);
    let mut pts = Points::<S>::default();
    let r_p = scene.contact_radius();
    let rigids: Vec<(Vec<glam::DVec2>, f64)> = scene
        .rigids
        .iter()
        .map(|r| (r.vertices.iter().map(|&[x, y]| glam::DVec2::new(x, y)).collect(), r.radius + r_p))
        .collect();
    let covered = |x: S::V| {
        let [x, y, _] = S::to_array(x);
        rigids.iter().any(|(poly, reach)| near(poly, glam::DVec2::new(x, y)).gap < *reach)
    };
    for body in scene.bodies.iter().filter(|b| b.model != BodyModel::Dem) {
        debug_assert_eq!(body.material, material_index);
        let region = match body.shape {
            Shape::Box { min, max } => Region::Box { min, max },
            Shape::Ball { center, radius } => Region::Ball { center, radius },
        };
        // Points behind a wall (a box body cut by a drum's circle) are not seeded.
        for x in seed::<S>(region, grid.origin, h, per_axis)
            .into_iter()
            .filter(|&x| !walls.iter().any(|w| w.behind(x, 0.0)) && !covered(x))
        {
            // Hybrid bodies: points in the hybrid band (weight w) and below it only.
            let weight = match body.model {
                BodyModel::Hybrid => match zones.zone_at(S::to_array(x)) {
                    Zone::Discrete => continue,
                    Zone::Hybrid => scene.coupling.weight,
                    Zone::Continuum => 1.0,
                },
                BodyModel::Mpm | BodyModel::Dem => 1.0,
            };
            pts.push(x, rho * volume, volume, packing);
            *pts.weight.last_mut().expect("just pushed") = weight;
            *pts.v.last_mut().expect("just pushed") = S::from_array(body.velocity);
        }
    }
    pts
}
