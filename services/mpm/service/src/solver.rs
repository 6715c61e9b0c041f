//! The MPM behind the participant loop's [`Solver`] trait, and its VTU frames of the points
//! (`frames/points.pvd`: id, velocity, pressure, plastic strain and its rate, packing fraction).

use anyhow::bail;
use grains_grid::Vector;
use grains_mpm::matrix::Matrix;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{Model, MpmParams, MpmPipeline};
use grains_mpm::points::{Points, totals};
use grains_protocol::scene::Scene;
use grains_protocol::wire::{
    BodyReach, Command, ContactPoint, Control, EpochItem, NodeVelocity, Param, PointForce, RasterNode, ViewPoint, Zone,
};
use grains_service::solver::{EpochChanges, Solver, SolverReport, StepWindow, set_component, view_stride};
use grains_service::vtu::{Field, PointFrames, Values};

pub struct MpmSolver<S: MpmSpace> {
    pub points: Points<S>,
    pub params: MpmParams<S>,
    pub pipeline: MpmPipeline<S>,
    frames: Option<(PointFrames, u64)>,
    /// The run's output directory (for a snapshot when frames are off).
    out_dir: Option<std::path::PathBuf>,
    /// Kinetic energy above which the run is declared runaway [J], and the domain's largest
    /// extent it is computed with [m].
    energy_bound: f64,
    extent: f64,
    /// The predicted grid momentum of the current step (coupled runs).
    raster: Vec<RasterNode>,
    /// New points' packing fraction (the material's) and the hybrid weight w.
    packing: f64,
    weight: f64,
    /// The step a resumed run started after (its outputs continue from there).
    resumed: Option<u64>,
    /// Whether the raster goes out empty: in a run of rigid bodies and a continuum (no grains),
    /// where nothing meets on the grid.
    no_raster: bool,
    /// Contact radius r_p of a point against a rigid body [m].
    contact_radius: f64,
    /// The points sent to the DEM this step (their indices, increasing), and the number of
    /// dead loads before the contact forces were appended to `points.loads` for the step
    /// (they are taken off after it).
    sent: Vec<u64>,
    dead_loads: Option<usize>,
    /// Energy the rigid bodies can bring [J] (for the runaway bound).
    rigid_energy: f64,
    /// The material's load on each scene wall per macro-step (`walls.csv`, `walls_mpm.csv`
    /// beside grains).
    walls_log: Option<grains_service::step_log::StepLog>,
}

/// What a checkpoint holds of the MPM (see [`Solver::save`]): the points, what commands may
/// have changed (gravity, the walls), the pipeline's time and step count, the runaway bound.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
struct Saved<S: MpmSpace> {
    points: Points<S>,
    gravity: S::V,
    walls: Vec<grains_mpm::boundary::Wall<S>>,
    pipeline: (f64, u64),
    energy_bound: f64,
}

impl<S: MpmSpace> MpmSolver<S> {
    /// The MPM of `scene` from `points`, its frames in `out_dir`; `resume`: the step a resumed
    /// run starts after (frames up to it are kept, later ones dropped; no frame of step 0).
    pub fn new(
        scene: &Scene,
        points: Points<S>,
        params: MpmParams<S>,
        out_dir: Option<&std::path::Path>,
        resume: Option<u64>,
    ) -> anyhow::Result<Self> {
        let pipeline = MpmPipeline::new(scene.threads as usize).map_err(anyhow::Error::msg)?;
        let extent = grains_service::grid::scene_extent(scene);
        let rigid_energy = rigid_energy(scene, points.mass.iter().sum(), extent);
        let energy_bound = runaway_bound(extent, &points, &params) + 100.0 * rigid_energy;
        let frames = match out_dir {
            Some(dir) if scene.output.frames_every > 0 => Some((PointFrames::open(dir, "points", resume)?, scene.output.frames_every)),
            _ => None,
        };
        let walls_log = match out_dir {
            Some(dir) if !params.walls.is_empty() => {
                // Beside grains, whose loads are the DEM's walls.csv.
                let name = if scene.has_grains() { "walls_mpm.csv" } else { "walls.csv" };
                let columns: String = params
                    .walls
                    .iter()
                    .map(|w| {
                        let k = w.id;
                        format!(",wall{k}_fx,wall{k}_fy,wall{k}_fz,wall{k}_x,wall{k}_y,wall{k}_z")
                    })
                    .collect();
                Some(grains_service::step_log::StepLog::open(&dir.join(name), &columns, resume)?)
            }
            _ => None,
        };
        let mut solver = MpmSolver {
            points,
            params,
            pipeline,
            frames,
            out_dir: out_dir.map(std::path::Path::to_path_buf),
            energy_bound,
            extent,
            raster: Vec::new(),
            packing: scene
                .materials
                .iter()
                .find_map(|m| m.mpm.as_ref().map(|m| m.packing))
                .unwrap_or(1.0),
            weight: scene.coupling.weight,
            resumed: resume,
            no_raster: scene.contact_coupling(),
            contact_radius: scene.contact_radius(),
            sent: Vec::new(),
            dead_loads: None,
            rigid_energy,
            walls_log,
        };
        if resume.is_none() {
            solver.write_frame(0)?;
        }
        Ok(solver)
    }

    fn write_frame(&mut self, step: u64) -> std::io::Result<()> {
        let Some((frames, _)) = &mut self.frames else { return Ok(()) };
        let p = &self.points;
        let model = &self.params.model;
        let x: Vec<[f64; 3]> = p.x.iter().map(|&x| S::to_array(x)).collect();
        let v: Vec<f64> = p.v.iter().flat_map(|&v| S::to_array(v)).collect();
        // The mass a point carries in the mixture: m w in a hybrid band.
        let mass: Vec<f64> = p.mass.iter().zip(&p.weight).map(|(m, w)| m * w).collect();
        let pressure: Vec<f64> = (0..p.len()).map(|k| Model::pressure(&p.tau[k], p.jacobian[k])).collect();
        let packing: Vec<f64> = (0..p.len()).map(|k| model.packing(p.packing[k], p.jacobian[k])).collect();
        let fields = [
            Field {
                name: "id",
                components: 1,
                values: Values::U64(&p.id),
            },
            Field {
                name: "mass",
                components: 1,
                values: Values::F64(&mass),
            },
            Field {
                name: "velocity",
                components: 3,
                values: Values::F64(&v),
            },
            Field {
                name: "pressure",
                components: 1,
                values: Values::F64(&pressure),
            },
            Field {
                name: "plastic_strain",
                components: 1,
                values: Values::F64(&p.plastic_strain),
            },
            Field {
                name: "plastic_strain_rate",
                components: 1,
                values: Values::F64(&p.plastic_rate),
            },
            Field {
                name: "packing_fraction",
                components: 1,
                values: Values::F64(&packing),
            },
        ];
        frames.write(step, self.pipeline.time, &x, &fields).map(|_| ())
    }
}

/// 100 × (initial kinetic energy + the work gravity can do across the domain + the kinetic
/// energy of all the material at the fastest wall's speed + the work of the point loads across
/// the domain and of the confining fluid squeezing the material to nothing, p V): a run that
/// exceeds it is blowing up, not flowing.
fn runaway_bound<S: MpmSpace>(extent: f64, pts: &Points<S>, params: &MpmParams<S>) -> f64 {
    let mass: f64 = pts.mass.iter().sum();
    let g = params.gravity.length();
    let wall_speed = params.walls.iter().map(|w| w.velocity.length()).fold(0.0, f64::max);
    let loads: f64 = pts.loads.iter().map(|(_, f)| f.length()).sum::<f64>() * extent;
    let fluid = params.ambient_pressure * pts.volume.iter().sum::<f64>();
    let (ke, _) = totals(pts);
    100.0 * (ke + mass * g * extent + 0.5 * mass * wall_speed * wall_speed + loads + fluid).max(f64::MIN_POSITIVE)
}

/// An upper bound of the energy the scene's rigid bodies can give the points [J]: a moving
/// body's kinetic energy (its mass at most ρ π R², R its reach from its first vertex) and
/// the work of gravity on it across the domain; a scripted body drives like a wall, the
/// points' whole `mass` at its fastest speed.
fn rigid_energy(scene: &Scene, mass: f64, extent: f64) -> f64 {
    use grains_protocol::scene::RigidMotion;
    let g = scene.gravity.iter().map(|g| g * g).sum::<f64>().sqrt();
    scene
        .rigids
        .iter()
        .map(|r| {
            let [x0, y0] = r.vertices[0];
            let reach = r.vertices.iter().map(|&[x, y]| (x - x0).hypot(y - y0)).fold(0.0, f64::max) + 2.0 * r.radius;
            let speed = r.velocity[0].hypot(r.velocity[1]) + r.spin.abs() * reach;
            let m = scene.materials[r.material].density * std::f64::consts::PI * reach * reach;
            match r.motion {
                RigidMotion::Fixed => 0.0,
                RigidMotion::Free => 0.5 * m * speed * speed + m * g * extent,
                RigidMotion::Scripted => 0.5 * mass * speed * speed,
            }
        })
        .sum()
}

fn step_failed(step: u64, time: f64, e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!(
        "MPM step {step} (t = {time:.6e} s): {e}; likely cause: a time step too large for the stiffness (CFL) or the flow speed, \
         or material driven into the domain's edge"
    )
}

impl<S: MpmSpace> MpmSolver<S> {
    /// After a step: runaway energy and frames.
    fn after_step(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        // The contact forces acted for this step only (the step keeps the loads' order).
        if let Some(dead) = self.dead_loads.take() {
            self.points.loads.truncate(dead);
        }
        let (ke, _) = totals(&self.points);
        if ke > self.energy_bound {
            bail!(
                "MPM step {} (t = {:.6e} s): kinetic energy {ke:.4e} J exceeds {:.4e} J, far more than gravity, walls and loads can supply \
                 (runaway); likely cause: a time step too large for the stiffness and the flow speed (CFL)",
                window.step,
                self.pipeline.time,
                self.energy_bound
            );
        }
        if let Some(log) = &mut self.walls_log {
            use grains_mpm::boundary::Geometry;
            let mut row = format!("{},{}", window.step, self.pipeline.time);
            for (w, f) in self.params.walls.iter().zip(&self.pipeline.wall_loads) {
                let at = match w.geometry {
                    Geometry::Plane { point, .. } => point,
                    Geometry::Box { min, .. } => min,
                    Geometry::Segment { from, .. } => from,
                    Geometry::Drum { center, .. } => center,
                };
                let (f, at) = (S::to_array(*f), S::to_array(at + w.shift + w.velocity * self.pipeline.time));
                row.push_str(&format!(",{},{},{},{},{},{}", f[0], f[1], f[2], at[0], at[1], at[2]));
            }
            log.row(&row)?;
        }
        if let Some((_, every)) = &self.frames
            && window.step.is_multiple_of(*every)
        {
            self.write_frame(window.step)?;
        }
        Ok(())
    }
}

impl<S: MpmSpace> Solver for MpmSolver<S> {
    /// Phase 1 (Yue 2018 Alg. 20), then the raster of the predicted grid momentum: every node
    /// with material, its weighted mass and momentum m v after the force update, by node index.
    fn predict(&mut self, window: &StepWindow) -> anyhow::Result<usize> {
        let time = self.pipeline.time;
        self.pipeline
            .phase1(&self.points, &self.params, window.dt)
            .map_err(|e| step_failed(window.step, time, e))?;
        let grid = self.params.grid;
        self.raster.clear();
        if self.no_raster {
            return Ok(0);
        }
        self.pipeline.for_each_node_mut(|ijk, mass, v| {
            let node = grid.index(ijk).expect("stored nodes with mass lie inside the grid");
            self.raster.push(RasterNode {
                node,
                mass,
                momentum: S::to_array(*v * mass),
            });
        });
        self.raster.sort_unstable_by_key(|r| r.node);
        Ok(self.raster.len())
    }

    fn write_raster(&mut self, _window: &StepWindow, out: &mut [RasterNode]) {
        out.copy_from_slice(&self.raster);
    }

    /// The coupler's velocities on the shared nodes, then phase 2 (Alg. 21).
    fn finish(&mut self, window: &StepWindow, velocities: &[NodeVelocity]) -> anyhow::Result<()> {
        let grid = self.params.grid;
        for nv in velocities {
            let ijk = grid.ijk(nv.node);
            let Some(v) = self.pipeline.node_velocity_mut(ijk) else {
                bail!(
                    "MPM step {}: the coupler constrained node {} where the MPM has no material",
                    window.step,
                    nv.node
                );
            };
            *v = S::from_array(nv.velocity);
        }
        let time = self.pipeline.time;
        self.pipeline
            .phase2(&mut self.points, &self.params, window.dt)
            .map_err(|e| step_failed(window.step, time, e))?;
        self.after_step(window)
    }

    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        let time = self.pipeline.time;
        self.pipeline
            .step(&mut self.points, &self.params, window.dt)
            .map_err(|e| step_failed(window.step, time, e))?;
        self.after_step(window)
    }

    fn contact_points(&mut self, reach: &[BodyReach], out: &mut Vec<ContactPoint>) {
        let p = &self.points;
        let r_p = self.contact_radius;
        // The contact coupling is 2D (scenes refuse rigid bodies in 3D): the plane's x and y.
        let plane = |x: [f64; 3]| glam::DVec2::new(x[0], x[1]);
        let circles: Vec<(glam::DVec2, f64)> = reach.iter().map(|b| (plane(b.center), b.reach)).collect();
        let mut near = grains_grid::reach::within_reach(p.len(), |k| (plane(S::to_array(p.x[k])), r_p), &circles).concat();
        near.sort_unstable();
        near.dedup();
        self.sent.clear();
        for k in near {
            self.sent.push(k as u64);
            out.push(ContactPoint {
                index: k as u64,
                id: p.id[k],
                position: S::to_array(p.x[k]),
                velocity: S::to_array(p.v[k]),
                mass: p.mass[k],
                radius: r_p,
            });
        }
    }

    /// Jiang 2020 eq. 46–48: a body's contact force on a point is a load on it for the step,
    /// spread to its nodes with its weights.
    fn take_contact_forces(&mut self, forces: &[PointForce]) -> anyhow::Result<()> {
        // Each on a point sent this step, in increasing order, once.
        let mut sent = self.sent.iter().peekable();
        for f in forces {
            while sent.next_if(|&&k| k < f.index).is_some() {}
            if sent.next_if(|&&k| k == f.index).is_none() || !f.force.iter().all(|c| c.is_finite()) {
                bail!(
                    "{}: a force {:?} on point index {}: not a point the MPM sent this step, out of order, twice, or not finite",
                    grains_protocol::names::POINT_FORCES.name,
                    f.force,
                    f.index
                );
            }
        }
        self.dead_loads = Some(self.points.loads.len());
        self.points
            .loads
            .extend(forces.iter().map(|f| (f.index as usize, S::from_array(f.force))));
        Ok(())
    }

    fn view(&self, max: usize, out: &mut Vec<ViewPoint>) -> u64 {
        let p = &self.points;
        for k in (0..p.len()).step_by(view_stride(p.len(), max)) {
            out.push(ViewPoint {
                id: p.id[k],
                position: S::to_array(p.x[k]),
                velocity: S::to_array(p.v[k]),
                size: 0.5 * p.volume[k].powf(1.0 / S::DIM as f64),
                pressure: Model::pressure(&p.tau[k], p.jacobian[k]),
            });
        }
        p.len() as u64
    }

    /// `snapshot`: a frame of the points now (`frames/`); `set gravity.*` and
    /// `set wall.K.velocity.*`.
    fn command(&mut self, done: u64, c: &Control) -> Result<(), String> {
        match (Command::from_code(c.command), Param::from_code(c.key)) {
            (Some(Command::Snapshot), _) => {
                if self.frames.is_none() {
                    let dir = self.out_dir.as_deref().ok_or("no output directory: nowhere to write a snapshot")?;
                    self.frames = Some((PointFrames::open(dir, "points", self.resumed).map_err(|e| e.to_string())?, 0));
                }
                let every = self.frames.as_ref().map_or(0, |f| f.1);
                if every == 0 || !done.is_multiple_of(every) {
                    self.write_frame(done).map_err(|e| e.to_string())?;
                }
                Ok(())
            }
            (Some(Command::Set), Some(p @ Param::Gravity { .. })) => {
                let g = set_component(S::to_array(self.params.gravity), S::DIM, p, c.value)?;
                self.params.gravity = S::from_array(g);
                Ok(())
            }
            (Some(Command::Set), Some(p @ Param::WallVelocity { wall, .. })) => {
                let time = self.pipeline.time;
                let w = self
                    .params
                    .walls
                    .iter_mut()
                    .find(|w| w.id == wall)
                    .ok_or_else(|| format!("{}: the MPM has no wall {wall}", p.name()))?;
                let v = set_component(S::to_array(w.velocity), S::DIM, p, c.value)?;
                w.set_velocity(S::from_array(v), time);
                Ok(())
            }
            _ => Err(format!("command {} (key {}) is not one the MPM takes", c.command, c.key)),
        }
    }

    fn epoch_items(&mut self, out: &mut Vec<EpochItem>) {
        let p = &self.points;
        out.extend((0..p.len()).map(|k| EpochItem {
            id: p.id[k],
            radius: 0.0,
            mass: p.mass[k],
            share: p.weight[k],
            flags: 0,
            position: S::to_array(p.x[k]),
            velocity: S::to_array(p.v[k]),
            plastic_strain: p.plastic_strain[k],
            plastic_rate: p.plastic_rate[k],
            pressure: Model::pressure(&p.tau[k], p.jacobian[k]),
        }));
    }

    /// Deletes the listed points, scales the mass and volume of the listed ones, creates the
    /// new ones (their elastic strain from the homogenized stress, Yue 2018 §4.2), and weighs
    /// every point by its cell's new zone: w in a hybrid cell, 1 elsewhere.
    fn apply_epoch(&mut self, step: u64, changes: &EpochChanges<'_>) -> anyhow::Result<()> {
        let p = &mut self.points;
        let delete: std::collections::HashSet<u64> = changes.delete.iter().copied().collect();
        let keep: Vec<u32> = (0..p.len()).filter(|&k| !delete.contains(&p.id[k])).map(|k| k as u32).collect();
        if keep.len() != p.len() {
            if p.loads.iter().any(|(k, _)| delete.contains(&p.id[*k])) {
                bail!(
                    "oracle epoch after step {step}: a point under a confining load would be deleted (adaptive zones and confined bodies do not mix)"
                );
            }
            p.retain_indices(&keep);
        }
        if !changes.scale_points.is_empty() {
            let factor: std::collections::HashMap<u64, f64> = changes.scale_points.iter().map(|s| (s.id, s.factor)).collect();
            for k in 0..p.len() {
                if let Some(f) = factor.get(&p.id[k]) {
                    p.mass[k] *= f;
                    p.volume[k] *= f;
                }
            }
        }
        let model = self.params.model;
        for n in changes.spawn_points {
            let v = n.stress;
            let sigma = <S::M as Matrix>::from_rows3([[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]]);
            let b_e = model.strain_of_stress(&sigma);
            p.push(S::from_array(n.position), n.mass, n.volume, self.packing);
            let k = p.len() - 1;
            p.id[k] = n.id;
            p.v[k] = S::from_array(n.velocity);
            p.b_e[k] = b_e;
            p.tau[k] = model.kirchhoff(&b_e);
        }
        for k in 0..p.len() {
            p.weight[k] = match changes.zones.zone_at(S::to_array(p.x[k])) {
                Zone::Hybrid => self.weight,
                _ => 1.0,
            };
        }
        if !changes.spawn_points.is_empty() || !changes.scale_points.is_empty() {
            self.energy_bound = self
                .energy_bound
                .max(runaway_bound(self.extent, &self.points, &self.params) + 100.0 * self.rigid_energy);
        }
        Ok(())
    }

    fn save(&self) -> anyhow::Result<Vec<u8>> {
        grains_service::checkpoint::encode(&Saved {
            points: self.points.clone(),
            gravity: self.params.gravity,
            walls: self.params.walls.clone(),
            pipeline: self.pipeline.carry(),
            energy_bound: self.energy_bound,
        })
    }

    fn restore(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let saved: Saved<S> = grains_service::checkpoint::decode(bytes)?;
        self.points = saved.points;
        self.params.gravity = saved.gravity;
        self.params.walls = saved.walls;
        self.pipeline.restore(saved.pipeline);
        self.energy_bound = saved.energy_bound;
        Ok(())
    }

    fn report(&self) -> SolverReport {
        let (ke, p) = totals(&self.points);
        SolverReport {
            n_items: self.points.len() as u64,
            n_nodes: self.pipeline.map.len() as u64,
            mass: self.points.mass.iter().zip(&self.points.weight).map(|(m, w)| m * w).sum(),
            momentum: S::to_array(p),
            kinetic_energy: ke,
            checksum: 0,
        }
    }
}
