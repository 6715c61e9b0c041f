//! The DEM behind the participant loop's [`Solver`] trait.

use crate::frames::FrameWriter;
use anyhow::bail;
use grains_dem::coupled::{CoupledStep, CouplingParams};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{Space, Vector};
use grains_dem::state::{DemState, WallShape};
use grains_protocol::scene::Model;
use grains_protocol::scene::{GrainTransfer, Scene};
use grains_protocol::wire::{
    BodyReach, Command, ContactPoint, Control, EpochItem, NodeStress, NodeVelocity, Param, PointForce, RasterNode, ViewPoint, Zone,
};
use grains_service::solver::{EpochChanges, Solver, SolverReport, StepWindow, set_component, view_stride};
use grains_service::step_log::StepLog;

pub struct DemSolver<S: Space> {
    pub state: DemState<S>,
    pub pipeline: DemPipeline<S>,
    /// The DEM half of a coupled step (unused when the DEM runs alone).
    coupled: CoupledStep<S>,
    frames: Option<(FrameWriter, u64)>,
    /// The run's output directory (for a snapshot when frames are off).
    out_dir: Option<std::path::PathBuf>,
    /// `walls.csv`: per macro-step, the force of the grains on every wall and where the wall
    /// is (force–displacement curves of plates, penetrometers, drums).
    walls_log: Option<StepLog>,
    /// Kinetic energy above which the run is declared runaway [J], and the domain's largest
    /// extent it is computed with [m].
    energy_bound: f64,
    extent: f64,
    /// |g| of the scene [m/s²], for the runaway bound after new grains.
    gravity: f64,
    /// Grains the oracle creates: their material (index into the state's materials) and
    /// density, the first hybrid body's; and the hybrid weight w.
    spawn: Option<(u32, f64)>,
    weight: f64,
    /// The step a resumed run started after (its outputs continue from there).
    resumed: Option<u64>,
    /// The rigid bodies' contacts with material points (Jiang 2020 §4) and their histories.
    point_contacts: grains_dem::bodies::BodyContacts,
    /// `bodies.csv`: per macro-step, each rigid body's pose and the force and torque on it.
    bodies_log: Option<StepLog>,
}

/// The fluid of a scene whose bodies with grains are confined: its pressure, a grid of two of
/// the largest grain's diameters (the ramp needs a few grains per node) and the packing
/// fraction (a hybrid body's continuum's; else that of the grains that move in the confined
/// boxes); with the work p V the fluid can do on them (V the boxes' volume), for the runaway
/// bound.
fn fluid<S: Space>(scene: &Scene, state: &DemState<S>) -> Option<(grains_dem::fluid::Fluid, f64)> {
    use grains_protocol::scene::Shape;
    let confined: Vec<_> = scene
        .bodies
        .iter()
        .filter(|b| matches!(b.model, Model::Dem | Model::Hybrid) && b.confining_pressure > 0.0)
        .collect();
    let first = confined.first()?;
    let dim = S::DIM;
    let volume: f64 = confined
        .iter()
        .map(|b| match b.shape {
            Shape::Box { min, max } => (0..dim).map(|k| max[k] - min[k]).product::<f64>(),
            Shape::Ball { .. } => 0.0,
        })
        .sum();
    let g = &state.grains;
    let moving = (0..g.len()).filter(|&i| !g.frozen[i]);
    // A grain's volume: its mass at unit density.
    let solid: f64 = moving.clone().map(|i| crate::setup::grain_mass(dim, g.radius[i], 1.0)).sum();
    let largest = moving.map(|i| g.radius[i]).fold(0.0, f64::max);
    let continuum = scene.materials[first.material].mpm.as_ref().map(|m| m.packing);
    let fluid = grains_dem::fluid::Fluid {
        pressure: first.confining_pressure,
        cell: 4.0 * largest,
        packing: continuum.unwrap_or((solid / volume).clamp(0.1, 1.0)),
    };
    Some((fluid, fluid.pressure * volume))
}

/// What a checkpoint holds of the DEM (see [`Solver::save`]).
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
struct Saved<S: Space> {
    state: DemState<S>,
    pipeline: grains_dem::pipeline::Carry<S>,
    accel: Vec<(u64, S::V)>,
    energy_bound: f64,
    point_contacts: grains_dem::bodies::BodyContacts,
}

impl<S: Space> DemSolver<S> {
    /// The DEM of `scene` from `state`, its outputs in `out_dir`; `resume`: the step a resumed
    /// run starts after (outputs up to it are kept, later ones dropped; no frame of step 0).
    pub fn new(scene: &Scene, state: DemState<S>, out_dir: Option<&std::path::Path>, resume: Option<u64>) -> anyhow::Result<Self> {
        let pipeline = DemPipeline::new(scene.threads as usize)?;
        let extent = grains_service::grid::scene_extent(scene);
        let continuum = if scene.contact_coupling() { continuum(scene) } else { (0.0, 0.0) };
        let fluid = fluid(scene, &state);
        let work = fluid.map_or(0.0, |f| f.1);
        let energy_bound = runaway_bound(
            extent,
            S::from_array(scene.gravity).length(),
            &state,
            (continuum.0, continuum.1 + work),
        );
        let (grid, kernel) = grains_service::grid::scene_grid(scene);
        let frames = match out_dir {
            Some(dir) if scene.output.frames_every > 0 => Some(FrameWriter::new(dir, resume, &state)?),
            _ => None,
        };
        let log = |name: &str, header: String| -> std::io::Result<Option<StepLog>> {
            out_dir.map(|dir| StepLog::open(&dir.join(name), &header, resume)).transpose()
        };
        // The grains' loads: none without grains (the walls' loads of a continuum are the MPM's).
        let walls_log = match state.walls.is_empty() || !scene.has_grains() {
            true => None,
            false => log(
                "walls.csv",
                (0..state.walls.len())
                    .map(|k| format!(",wall{k}_fx,wall{k}_fy,wall{k}_fz,wall{k}_x,wall{k}_y,wall{k}_z"))
                    .collect(),
            )?,
        };
        let bodies_log = match state.bodies.is_empty() {
            true => None,
            false => log(
                "bodies.csv",
                state
                    .bodies
                    .iter()
                    .map(|b| {
                        let k = b.id;
                        format!(
                            ",body{k}_x,body{k}_y,body{k}_angle,body{k}_vx,body{k}_vy,body{k}_omega,body{k}_fx,body{k}_fy,body{k}_torque"
                        )
                    })
                    .collect(),
            )?,
        };
        let mut solver = DemSolver {
            state,
            pipeline,
            coupled: CoupledStep::new(CouplingParams {
                grid,
                kernel,
                transfer: match scene.coupling.grain_transfer {
                    GrainTransfer::Pic => grains_dem::GrainTransfer::Pic,
                    GrainTransfer::Flip => grains_dem::GrainTransfer::Flip,
                    // As the MPM's points (APIC's take the grid's velocity).
                    GrainTransfer::Points => grains_dem::GrainTransfer::Points(scene.mpm.flip.unwrap_or(0.0)),
                },
                quasi_static: scene.coupling.quasi_static,
                gravity: S::from_array(scene.gravity).length(),
                fluid: fluid.map(|f| f.0),
            }),
            frames: frames.map(|f| (f, scene.output.frames_every)),
            out_dir: out_dir.map(std::path::Path::to_path_buf),
            walls_log,
            energy_bound,
            extent,
            gravity: S::from_array(scene.gravity).length(),
            spawn: scene.bodies.iter().find(|b| b.model == Model::Hybrid).map(|b| {
                let index = scene.materials[..b.material].iter().filter(|m| m.dem.is_some()).count() as u32;
                (index, scene.materials[b.material].density)
            }),
            weight: scene.coupling.weight,
            resumed: resume,
            point_contacts: Default::default(),
            bodies_log,
        };
        if let Some((f, _)) = &mut solver.frames
            && resume.is_none()
        {
            f.write(0, &solver.state, &solver.pipeline)?;
        }
        Ok(solver)
    }

    /// The confining fluid's load on every grain (the scene's, kept with the coupled step's
    /// parameters: [`CouplingParams::fluid`]), for the macro-step about to run alone; a
    /// coupled step sets it itself, beside the coupling's push. Held over the substeps.
    fn confine(&mut self) {
        if let Some(f) = &self.coupled.params.fluid {
            self.state.grains.external = grains_dem::fluid::forces(&self.state.grains, f).0;
        }
    }

    /// NaN and runaway energy, with the step and the likely cause.
    fn check(&self, step: u64, dt: f64) -> anyhow::Result<()> {
        if let Some(id) = DemPipeline::first_non_finite(&self.state) {
            bail!(
                "DEM step {step} (t = {:.6e} s): grain {id} has a non-finite position or velocity; likely cause: a time step too large for the \
                 stiffness and the lightest grain (DEM step {dt:.3e} s), or grains created overlapping",
                self.state.time
            );
        }
        if let Some(b) = self
            .state
            .bodies
            .iter()
            .find(|b| !(b.x.is_finite() && b.v.is_finite() && b.angle.is_finite() && b.omega.is_finite()))
        {
            bail!(
                "DEM step {step} (t = {:.6e} s): rigid body {} has a non-finite position or velocity; likely cause: a time step too large for the \
                 stiffness and the body's effective mass (DEM step {dt:.3e} s), or a body created overlapping",
                self.state.time,
                b.id
            );
        }
        let ke = DemPipeline::kinetic_energy(&self.state);
        if ke.is_nan() || ke > self.energy_bound {
            bail!(
                "DEM step {step} (t = {:.6e} s): kinetic energy {ke:.4e} J exceeds {:.4e} J, far more than gravity and the walls can supply \
                 (runaway); likely cause: a time step too large for the stiffness (DEM step {dt:.3e} s), or grains created overlapping",
                self.state.time,
                self.energy_bound
            );
        }
        Ok(())
    }
}

/// The mass and kinetic energy of the scene's `mpm` bodies at the start (bulk density × the
/// shape's volume).
fn continuum(scene: &Scene) -> (f64, f64) {
    let dim = scene.dim();
    scene
        .bodies
        .iter()
        .filter(|b| b.model == Model::Mpm)
        .map(|b| {
            let volume = match b.shape {
                grains_protocol::scene::Shape::Box { min, max } => (0..dim).map(|k| max[k] - min[k]).product::<f64>(),
                grains_protocol::scene::Shape::Ball { radius, .. } if dim == 2 => std::f64::consts::PI * radius * radius,
                grains_protocol::scene::Shape::Ball { radius, .. } => 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3),
            };
            let mat = &scene.materials[b.material];
            let m = mat.density * mat.mpm.as_ref().map_or(1.0, |c| c.packing) * volume;
            (m, 0.5 * m * b.velocity.iter().map(|v| v * v).sum::<f64>())
        })
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// 100 × (initial kinetic energy + the work gravity can do across the domain + the kinetic
/// energy every grain would have at the fastest wall's speed): a run that exceeds it is
/// blowing up, not flowing. `continuum`: the mass and kinetic energy of a continuum the
/// rigid bodies meet by contact (it can give them all of it).
fn runaway_bound<S: Space>(extent: f64, g_norm: f64, state: &DemState<S>, continuum: (f64, f64)) -> f64 {
    use grains_dem::bodies::Motion;
    let g = &state.grains;
    let free = state.bodies.iter().filter(|b| b.motion == Motion::Free);
    let mass: f64 = g.mass.iter().sum::<f64>() + free.map(|b| b.mass).sum::<f64>() + continuum.0;
    // Scripted bodies drive like walls.
    let scripted = state.bodies.iter().filter_map(|b| match b.motion {
        Motion::Scripted { velocity, spin } => Some(velocity.length() + spin.abs() * b.reach()),
        _ => None,
    });
    let wall_speed = state
        .walls
        .iter()
        .map(|w| {
            let spin = match w.shape {
                WallShape::Drum { radius, .. } => w.spin.abs() * radius,
                WallShape::Plane { .. } | WallShape::Segment { .. } => 0.0,
            };
            w.velocity.length() + spin
        })
        .chain(scripted)
        .fold(0.0, f64::max);
    let bound = DemPipeline::kinetic_energy(state) + continuum.1 + mass * g_norm * extent + 0.5 * mass * wall_speed * wall_speed;
    100.0 * bound.max(f64::MIN_POSITIVE)
}

/// The DEM substeps of a macro-step, as the time owner gives them (the coupler's step begin,
/// or the scene's `coupling.substeps` when the DEM runs alone): the one source of the DEM step
/// `window.dt / substeps`.
fn substeps(window: &StepWindow) -> anyhow::Result<usize> {
    if window.substeps == 0 {
        bail!("DEM step {}: the time owner asked for 0 substeps (at least 1)", window.step);
    }
    Ok(window.substeps as usize)
}

impl<S: Space> Solver for DemSolver<S> {
    /// Yue 2018 Alg. 2 (the substeps) and 4 (the raster of the hybrid grains):
    /// [`CoupledStep::advance`], the NaN and runaway checks, [`CoupledStep::rasterize`].
    fn predict(&mut self, window: &StepWindow) -> anyhow::Result<usize> {
        let substeps = substeps(window)?;
        self.coupled.advance(&mut self.state, &mut self.pipeline, window.dt, substeps);
        self.check(window.step, window.dt / substeps as f64)?;
        Ok(self.coupled.rasterize(&self.state, window.dt).len())
    }

    /// The predicted momentum without the carried coupling forces
    /// ([`CoupledStep::uncoupled_momentum`]).
    fn write_raster(&mut self, _window: &StepWindow, out: &mut [RasterNode]) {
        for (k, (o, r)) in out.iter_mut().zip(self.coupled.raster()).enumerate() {
            *o = RasterNode {
                node: r.node,
                mass: r.mass,
                momentum: S::to_array(self.coupled.uncoupled_momentum(k)),
            };
        }
    }

    /// Alg. 5 and 6 with the coupler's velocities ([`CoupledStep::finish`]), then the walls'
    /// loads and the frames.
    fn finish(&mut self, window: &StepWindow, velocities: &[NodeVelocity]) -> anyhow::Result<()> {
        let constrained = velocities.iter().map(|v| (v.node, S::from_array(v.velocity)));
        self.coupled.finish(&mut self.state, &mut self.pipeline, constrained, window.dt);
        self.after_step(window)
    }

    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        let substeps = substeps(window)?;
        let dt = window.dt / substeps as f64;
        self.confine();
        self.pipeline.run(&mut self.state, dt, substeps);
        self.check(window.step, dt)?;
        self.after_step(window)
    }

    /// A grain's pressure needs its contacts: not right after an epoch's exchange.
    fn view_ready(&self) -> bool {
        self.pipeline.contacts_known()
    }

    fn view(&self, max: usize, out: &mut Vec<ViewPoint>) -> u64 {
        let g = &self.state.grains;
        // Every contact is summed for the few grains shown: a view is made a few times a
        // second, not every step.
        let pressure = self.pipeline.grain_pressures(&self.state);
        for i in (0..g.len()).step_by(view_stride(g.len(), max)) {
            out.push(ViewPoint {
                id: g.id[i],
                position: S::to_array(g.x[i]),
                velocity: S::to_array(g.v[i]),
                size: g.radius[i],
                pressure: pressure[i],
            });
        }
        g.len() as u64
    }

    /// `snapshot`: a frame of the grains now (`frames/`); `set gravity.*` and
    /// `set wall.K.velocity.*`.
    fn command(&mut self, done: u64, c: &Control) -> Result<(), String> {
        match (Command::from_code(c.command), Param::from_code(c.key)) {
            (Some(Command::Snapshot), _) => {
                if self.frames.is_none() {
                    let dir = self.out_dir.as_deref().ok_or("no output directory: nowhere to write a snapshot")?;
                    let writer = FrameWriter::new(dir, self.resumed, &self.state).map_err(|e| e.to_string())?;
                    self.frames = Some((writer, 0));
                }
                let (f, every) = self.frames.as_mut().expect("made above");
                if *every == 0 || !done.is_multiple_of(*every) {
                    f.write(done, &self.state, &self.pipeline).map_err(|e| e.to_string())?;
                }
                Ok(())
            }
            (Some(Command::Set), Some(p @ Param::Gravity { .. })) => {
                let g = set_component(S::to_array(self.state.params.gravity), S::DIM, p, c.value)?;
                self.state.params.gravity = S::from_array(g);
                Ok(())
            }
            (Some(Command::Set), Some(p @ Param::WallVelocity { wall, .. })) => {
                let mut found = false;
                for w in self.state.walls.iter_mut().filter(|w| w.id == wall) {
                    w.velocity = S::from_array(set_component(S::to_array(w.velocity), S::DIM, p, c.value)?);
                    found = true;
                }
                found
                    .then_some(())
                    .ok_or_else(|| format!("{}: the scene has no wall {wall}", p.name()))
            }
            _ => Err(format!("command {} (key {}) is not one the DEM takes", c.command, c.key)),
        }
    }

    /// Every grain, the frozen ones (the scene's fixed boundary) flagged.
    fn epoch_items(&mut self, out: &mut Vec<EpochItem>) {
        let g = &self.state.grains;
        out.extend((0..g.len()).map(|i| EpochItem {
            id: g.id[i],
            radius: g.radius[i],
            mass: g.mass[i],
            share: g.scale[i],
            flags: if g.frozen[i] { grains_protocol::wire::EPOCH_FIXED } else { 0 },
            position: S::to_array(g.x[i]),
            velocity: S::to_array(g.v[i]),
            ..EpochItem::default()
        }));
    }

    /// Yue 2018 Alg. 11 over the contacts of the last step, grain–grain and grain–wall (the
    /// grain's own half of the branch), at full stiffness (a hybrid grain's contacts carry
    /// 1 − w of the load; the new points need the material's).
    fn epoch_stress(&mut self, out: &mut Vec<NodeStress>) {
        let g = &self.state.grains;
        let contacts: Vec<grains_grid::homogenize::Contact> = self
            .pipeline
            .contact_forces(&self.state)
            .into_iter()
            .map(|(i, j, f, d)| {
                // Base j, tip i: the arm from j's centre to i's (the minimum image across a
                // periodic boundary), the force on i; the contact point on the arm, split by
                // the radii, on i's side.
                let (xi, arm) = (S::to_array(g.x[i]), S::to_array(d));
                let share = g.radius[i] / (g.radius[i] + g.radius[j]);
                grains_grid::homogenize::Contact {
                    point: std::array::from_fn(|k| xi[k] - share * arm[k]),
                    force: S::to_array(f),
                    arm,
                }
            })
            .collect();
        // A grain on a wall: the grain's half of the branch, from the contact to its centre.
        let walls = self.pipeline.wall_contact_forces(&self.state).into_iter().map(|(i, at, f)| {
            let (xi, xc) = (S::to_array(g.x[i]), S::to_array(at));
            grains_grid::homogenize::Contact {
                point: xc,
                force: S::to_array(f),
                arm: std::array::from_fn(|k| xi[k] - xc[k]),
            }
        });
        let contacts: Vec<_> = contacts.into_iter().chain(walls).collect();
        let CouplingParams { grid, kernel, .. } = &self.coupled.params;
        let stress = grains_grid::homogenize::stress::<S>(grid, *kernel, &contacts);
        out.extend(stress.into_iter().map(|(node, s)| NodeStress {
            node,
            stress: [s[0][0], s[1][1], s[2][2], s[1][2], s[0][2], s[0][1]],
        }));
    }

    /// Deletes the listed grains (frozen ones stay: they are the scene's fixed boundary),
    /// creates the new ones at rest spin, and weighs every grain by its cell's new zone: 1 − w
    /// in a hybrid cell, 1 elsewhere. A grain that leaves the hybrid band drops the coupling
    /// push it carried.
    fn apply_epoch(&mut self, step: u64, changes: &EpochChanges<'_>) -> anyhow::Result<()> {
        let g = &mut self.state.grains;
        let delete: std::collections::HashSet<u64> = changes.delete.iter().copied().collect();
        let keep: Vec<u32> = (0..g.len())
            .filter(|&i| g.frozen[i] || !delete.contains(&g.id[i]))
            .map(|i| i as u32)
            .collect();
        // Nothing changed, nothing rebuilt: an epoch that changes nothing leaves the run as
        // it would be without one.
        let mut changed = keep.len() != g.len() || !changes.spawn_grains.is_empty();
        if keep.len() != g.len() {
            g.permute(&keep);
        }
        if !changes.spawn_grains.is_empty() {
            let Some((material, density)) = self.spawn else {
                bail!("oracle epoch after step {step}: new grains, but the scene has no hybrid body to take their material from");
            };
            for n in changes.spawn_grains {
                let x = S::from_array(n.position);
                let i = g.push(
                    n.id,
                    x,
                    n.radius,
                    grains_dem::state::Grains::<S>::mass_of(n.radius, density),
                    material,
                );
                g.v[i] = S::from_array(n.velocity);
            }
        }
        for i in 0..g.len() {
            let scale = match changes.zones.zone_at(S::to_array(g.x[i])) {
                Zone::Hybrid if !g.frozen[i] => 1.0 - self.weight,
                _ => 1.0,
            };
            if scale != g.scale[i] {
                changed = true;
                if scale == 1.0 {
                    g.external[i] = S::V::default();
                }
                g.scale[i] = scale;
            }
        }
        if changed {
            self.pipeline.invalidate();
        }
        if !changes.spawn_grains.is_empty() {
            self.energy_bound = self
                .energy_bound
                .max(runaway_bound(self.extent, self.gravity, &self.state, (0.0, 0.0)));
        }
        Ok(())
    }

    /// The state, the pipeline's neighbour list with the contact histories, the flip
    /// transfer's node accelerations, and the runaway bound.
    fn save(&self) -> anyhow::Result<Vec<u8>> {
        grains_service::checkpoint::encode(&Saved {
            state: self.state.clone(),
            pipeline: self.pipeline.carry(),
            accel: self.coupled.carry().to_vec(),
            energy_bound: self.energy_bound,
            point_contacts: self.point_contacts.clone(),
        })
    }

    fn restore(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let saved: Saved<S> = grains_service::checkpoint::decode(bytes)?;
        self.state = saved.state;
        self.pipeline.restore(saved.pipeline);
        self.coupled.restore(saved.accel);
        self.energy_bound = saved.energy_bound;
        self.point_contacts = saved.point_contacts;
        Ok(())
    }

    fn body_reach(&self, out: &mut Vec<BodyReach>) {
        out.extend(self.state.bodies.iter().map(|b| BodyReach {
            id: b.id,
            center: [b.x.x, b.x.y, 0.0],
            reach: b.reach(),
        }));
    }

    /// Jiang 2020 eq. 44–50 ([`grains_dem::bodies::point_forces`]): the points meet the
    /// bodies as disks of their contact radius; the reactions stay on the bodies as their
    /// external load through the step's substeps.
    fn contact_forces(&mut self, window: &StepWindow, points: &[ContactPoint], out: &mut Vec<PointForce>) -> anyhow::Result<()> {
        use glam::DVec2;
        let finite = |p: &ContactPoint| p.position.iter().chain(&p.velocity).all(|c| c.is_finite());
        if let Some(p) = points.iter().find(|p| !(p.mass > 0.0 && p.radius > 0.0 && finite(p))) {
            bail!(
                "{}: step {}: point {} has mass {}, contact radius {} (both must be > 0), position {:?} and velocity {:?} (finite)",
                grains_protocol::names::CONTACT_POINTS.name,
                window.step,
                p.id,
                p.mass,
                p.radius,
                p.position,
                p.velocity
            );
        }
        if let Some(w) = points.windows(2).find(|w| w[1].index <= w[0].index) {
            bail!(
                "{}: step {}: point indices {} then {}: they must increase",
                grains_protocol::names::CONTACT_POINTS.name,
                window.step,
                w[0].index,
                w[1].index
            );
        }
        let disks: Vec<grains_dem::bodies::GrainView> = points
            .iter()
            .enumerate()
            .map(|(k, p)| grains_dem::bodies::GrainView {
                index: k,
                x: DVec2::new(p.position[0], p.position[1]),
                v: DVec2::new(p.velocity[0], p.velocity[1]),
                omega: 0.0,
                radius: p.radius,
                inv_mass: 1.0 / p.mass,
                scale: 1.0,
                id: p.id,
            })
            .collect();
        let mut forces = grains_dem::bodies::point_forces(
            &mut self.state.bodies,
            &disks,
            &self.state.params.materials,
            window.dt,
            &mut self.point_contacts,
        );
        // A point may touch two bodies: one force each, in index order.
        forces.sort_by_key(|f| f.0);
        for (k, f) in forces {
            match out.last_mut() {
                Some(last) if last.index == points[k].index => {
                    last.force[0] += f.x;
                    last.force[1] += f.y;
                }
                _ => out.push(PointForce {
                    index: points[k].index,
                    force: [f.x, f.y, 0.0],
                }),
            }
        }
        Ok(())
    }

    fn report(&self) -> SolverReport {
        let g = &self.state.grains;
        let p = S::to_array(DemPipeline::momentum(&self.state));
        SolverReport {
            n_items: g.len() as u64,
            n_nodes: self.coupled.raster().len() as u64,
            mass: g.mass.iter().zip(&g.scale).map(|(m, s)| m * s).sum(),
            momentum: p,
            kinetic_energy: DemPipeline::kinetic_energy(&self.state),
            checksum: 0,
        }
    }
}

impl<S: Space> DemSolver<S> {
    /// After a step: the walls' loads and the frames.
    fn after_step(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        if let Some(log) = &mut self.walls_log {
            let mut row = format!("{},{}", window.step, self.state.time);
            for w in &self.state.walls {
                let f = S::to_array(w.load);
                let at = S::to_array(match w.shape {
                    WallShape::Plane { point, .. } => point,
                    WallShape::Drum { center, .. } => center,
                    WallShape::Segment { a, .. } => a,
                });
                row.push_str(&format!(",{},{},{},{},{},{}", f[0], f[1], f[2], at[0], at[1], at[2]));
            }
            log.row(&row)?;
        }
        if let Some(log) = &mut self.bodies_log {
            let mut row = format!("{},{}", window.step, self.state.time);
            for b in &self.state.bodies {
                let (f, t) = (b.force + b.external, b.torque + b.external_torque);
                row.push_str(&format!(
                    ",{},{},{},{},{},{},{},{},{}",
                    b.x.x, b.x.y, b.angle, b.v.x, b.v.y, b.omega, f.x, f.y, t
                ));
            }
            log.row(&row)?;
        }
        if let Some((f, every)) = &mut self.frames
            && window.step.is_multiple_of(*every)
        {
            f.write(window.step, &self.state, &self.pipeline)?;
        }
        Ok(())
    }
}
