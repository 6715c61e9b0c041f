//! The DEM behind the participant loop's [`Solver`] trait.

use crate::frames::FrameWriter;
use anyhow::bail;
use grains_dem::coupling;
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{Space, Vector};
use grains_dem::state::{DemState, WallShape};
use grains_grid::{Grid, Kernel};
use grains_protocol::scene::Model;
use grains_protocol::scene::{GrainTransfer, Scene};
use grains_protocol::wire::{Command, Control, EpochItem, NodeStress, NodeVelocity, Param, RasterNode, ViewPoint, Zone};
use grains_service::solver::{EpochChanges, Solver, SolverReport, StepWindow, set_component, view_stride};
use std::collections::HashMap;

pub struct DemSolver<S: Space> {
    pub state: DemState<S>,
    pub pipeline: DemPipeline<S>,
    substeps: u32,
    grain_transfer: GrainTransfer,
    frames: Option<(FrameWriter, u64)>,
    /// The run's output directory (for a snapshot when frames are off).
    out_dir: Option<std::path::PathBuf>,
    /// `walls.csv`: per macro-step, the force of the grains on every wall and where the wall
    /// is (force–displacement curves of plates, penetrometers, drums).
    walls_log: Option<std::io::BufWriter<std::fs::File>>,
    /// Kinetic energy above which the run is declared runaway [J], and the domain's largest
    /// extent it is computed with [m].
    energy_bound: f64,
    extent: f64,
    /// The MPM's grid and kernel, for the raster of a coupled step.
    grid: Grid,
    kernel: Kernel,
    /// A coupled step in progress: the hybrid grains (scale < 1) by id with their positions at
    /// the start of the step, and the raster of their predicted momentum.
    hybrid: HashMap<u64, S::V>,
    raster: Vec<coupling::NodeMomentum<S>>,
    /// With `grain_transfer = "flip"`: per node of `raster`, the impulse of the coupling
    /// forces the grains carried through the substeps (`external`), which the coupler must not
    /// see: it is taken out of the raster it is sent.
    carried: Vec<S::V>,
    /// With `"flip"`: each constrained node's coupling acceleration of the last step [m/s²].
    accel: HashMap<u64, S::V>,
    /// With `"flip"`: the inertial number below which a band grain turns with the material,
    /// and |g| [m/s²].
    quasi_static: f64,
    gravity: f64,
    /// Grains the oracle creates: their material (index into the state's materials) and
    /// density, the first hybrid body's; and the hybrid weight w.
    spawn: Option<(u32, f64)>,
    weight: f64,
}

impl<S: Space> DemSolver<S> {
    pub fn new(scene: &Scene, state: DemState<S>, out_dir: Option<&std::path::Path>) -> anyhow::Result<Self> {
        let pipeline = DemPipeline::new(scene.threads as usize)?;
        let extent = grains_service::grid::scene_extent(scene);
        let energy_bound = runaway_bound(extent, S::from_array(scene.gravity).length(), &state);
        let (grid, kernel) = grains_service::grid::scene_grid(scene);
        let frames = match out_dir {
            Some(dir) if scene.output.frames_every > 0 => Some(FrameWriter::new(dir)?),
            _ => None,
        };
        let walls_log = match out_dir {
            Some(dir) if !state.walls.is_empty() => {
                use std::io::Write as _;
                let mut f = std::io::BufWriter::new(std::fs::File::create(dir.join("walls.csv"))?);
                let mut header = String::from("step,time");
                for k in 0..state.walls.len() {
                    header.push_str(&format!(",wall{k}_fx,wall{k}_fy,wall{k}_fz,wall{k}_x,wall{k}_y,wall{k}_z"));
                }
                writeln!(f, "{header}")?;
                Some(f)
            }
            _ => None,
        };
        let mut solver = DemSolver {
            state,
            pipeline,
            substeps: scene.coupling.substeps,
            grain_transfer: scene.coupling.grain_transfer,
            frames: frames.map(|f| (f, scene.output.frames_every)),
            out_dir: out_dir.map(std::path::Path::to_path_buf),
            walls_log,
            energy_bound,
            extent,
            grid,
            kernel,
            hybrid: HashMap::new(),
            raster: Vec::new(),
            carried: Vec::new(),
            accel: HashMap::new(),
            quasi_static: scene.coupling.quasi_static,
            gravity: S::from_array(scene.gravity).length(),
            spawn: scene.bodies.iter().find(|b| b.model == Model::Hybrid).map(|b| {
                let index = scene.materials[..b.material].iter().filter(|m| m.dem.is_some()).count() as u32;
                (index, scene.materials[b.material].density)
            }),
            weight: scene.coupling.weight,
        };
        if let Some((f, _)) = &mut solver.frames {
            f.write(0, &solver.state, &solver.pipeline)?;
        }
        Ok(solver)
    }

    /// Node `k` of the raster without the impulse of the carried coupling push.
    fn uncoupled_momentum(&self, k: usize) -> S::V {
        self.raster[k].momentum - self.carried.get(k).copied().unwrap_or_default()
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
        let ke = DemPipeline::kinetic_energy(&self.state);
        if ke > self.energy_bound {
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

/// 100 × (initial kinetic energy + the work gravity can do across the domain + the kinetic
/// energy every grain would have at the fastest wall's speed): a run that exceeds it is
/// blowing up, not flowing.
fn runaway_bound<S: Space>(extent: f64, g_norm: f64, state: &DemState<S>) -> f64 {
    let g = &state.grains;
    let mass: f64 = g.mass.iter().sum();
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
        .fold(0.0, f64::max);
    let bound = DemPipeline::kinetic_energy(state) + mass * g_norm * extent + 0.5 * mass * wall_speed * wall_speed;
    100.0 * bound.max(f64::MIN_POSITIVE)
}

impl<S: Space> Solver for DemSolver<S> {
    /// Yue 2018 Alg. 2: saves the hybrid grains' positions, runs the k substeps (hybrid grains
    /// with mass and springs scaled by 1 − w), and rasterizes their predicted momentum at the
    /// saved positions onto the MPM grid with its weights (Alg. 4).
    ///
    /// With `grain_transfer = "flip"` the substeps also push every hybrid grain with the last
    /// step's coupling acceleration of the nodes around it: the coupling force then acts on the
    /// grains while their contacts do, rather than as a kick after them (kicks a step apart
    /// shake a resting band until it creeps: 0.23 grain diameters in 0.5 s), and the coupler
    /// only corrects what changed. The raster it is sent leaves that push out.
    fn predict(&mut self, window: &StepWindow) -> anyhow::Result<usize> {
        let g = &self.state.grains;
        // Frozen grains never move: never hybrid.
        self.hybrid = (0..g.len())
            .filter(|&i| g.scale[i] < 1.0 && !g.frozen[i])
            .map(|i| (g.id[i], g.x[i]))
            .collect();
        if self.grain_transfer == GrainTransfer::Flip {
            // Nodes the coupler did not constrain last step push nothing.
            let g = &mut self.state.grains;
            let accel = |n: u64| Some(self.accel.get(&n).copied().unwrap_or_default());
            for i in 0..g.len() {
                if self.hybrid.contains_key(&g.id[i]) {
                    let (a, _) = coupling::interpolate::<S>(&self.grid, self.kernel, g.x[i], accel);
                    g.external[i] = a * (g.mass[i] * g.scale[i]);
                }
            }
        }
        let dt = window.dt / self.substeps as f64;
        self.pipeline.run(&mut self.state, dt, self.substeps as usize);
        self.check(window.step, dt)?;
        let g = &self.state.grains;
        let saved: Vec<S::V> = (0..g.len()).map(|i| self.hybrid.get(&g.id[i]).copied().unwrap_or(g.x[i])).collect();
        let mass: Vec<f64> = (0..g.len()).map(|i| g.mass[i] * g.scale[i]).collect();
        let hybrid = &self.hybrid;
        let include = |i: usize| hybrid.contains_key(&g.id[i]);
        self.raster = coupling::rasterize::<S>(&self.grid, self.kernel, &saved, &g.v, &mass, include);
        self.carried.clear();
        if self.grain_transfer == GrainTransfer::Flip {
            // The push's impulse per node, Σ w F dt, with the raster's weights and nodes.
            let impulse: Vec<S::V> = (0..g.len())
                .map(|i| g.external[i] * (window.dt / mass[i].max(f64::MIN_POSITIVE)))
                .collect();
            let r = coupling::rasterize::<S>(&self.grid, self.kernel, &saved, &impulse, &mass, include);
            self.carried = r.into_iter().map(|n| n.momentum).collect();
        }
        Ok(self.raster.len())
    }

    /// The predicted momentum without the carried coupling forces: what the grains would have
    /// without any coupling, which is what the coupler's eq. 31 needs.
    fn write_raster(&mut self, _window: &StepWindow, out: &mut [RasterNode]) {
        for (k, (o, r)) in out.iter_mut().zip(&self.raster).enumerate() {
            *o = RasterNode {
                node: r.node,
                mass: r.mass,
                momentum: S::to_array(self.uncoupled_momentum(k)),
            };
        }
    }

    /// Alg. 5 and 6. With `grain_transfer = "flip"` every hybrid grain adds to its substepped
    /// velocity the coupling's change of the node velocities (constrained minus its own
    /// raster's; on nodes the coupler left alone, its uncoupled minus its own: the push is
    /// taken back) interpolated at its saved position, moves by that change times dt / 2 and
    /// takes the spin of the constrained field; each node's whole coupling acceleration
    /// (constrained velocity minus the uncoupled one, over dt) is kept for the next step's
    /// substeps. With `"pic"` (Alg. 5–6 as written) it takes the velocity interpolated from the coupler's node velocities (its own raster's elsewhere) and the spin
    /// of that field, and moves from its saved position with that velocity. The other grains
    /// keep their substepped state.
    fn finish(&mut self, window: &StepWindow, velocities: &[NodeVelocity]) -> anyhow::Result<()> {
        if !self.hybrid.is_empty() {
            let constrained: HashMap<u64, S::V> = velocities.iter().map(|v| (v.node, S::from_array(v.velocity))).collect();
            let own: HashMap<u64, S::V> = self.raster.iter().map(|r| (r.node, r.momentum * (1.0 / r.mass))).collect();
            let node_velocity = |n: u64| constrained.get(&n).or_else(|| own.get(&n)).copied();
            let flip = self.grain_transfer == GrainTransfer::Flip;
            // Each node's velocity without any coupling force (its own without the push).
            let free: HashMap<u64, S::V> = self
                .raster
                .iter()
                .enumerate()
                .map(|(k, r)| (r.node, self.uncoupled_momentum(k) * (1.0 / r.mass)))
                .collect();
            if flip {
                // The whole coupling acceleration of each node: its constrained velocity minus
                // the velocity it would have had without any coupling force.
                self.accel = free
                    .iter()
                    .filter_map(|(n, f)| constrained.get(n).map(|v| (*n, (*v - *f) * (1.0 / window.dt))))
                    .collect();
            }
            let g = &mut self.state.grains;
            // The coupling's change of each node velocity. Where the coupler did not act the
            // node goes back to its uncoupled velocity: the part of the push spread there is
            // taken back.
            let change = |n: u64| {
                let o = own.get(&n).copied().unwrap_or_default();
                Some(constrained.get(&n).or_else(|| free.get(&n)).map_or(S::V::default(), |c| *c - o))
            };
            for i in 0..g.len() {
                if let Some(&x0) = self.hybrid.get(&g.id[i]) {
                    if flip {
                        // The rest of the coupling force, spread evenly over the step, changes
                        // the velocity by dv and the position by dv dt / 2.
                        let (dv, _) = coupling::interpolate::<S>(&self.grid, self.kernel, x0, change);
                        g.v[i] += dv;
                        g.x[i] += dv * (0.5 * window.dt);
                        // Its spin is not coupled otherwise: where the material is
                        // quasi-static the grain turns with it (held up by the coupling, it
                        // would be spun up by the sliding of its contacts: 35 rad/s in a
                        // resting layer, which creeps 0.3 d in 0.5 s); where it flows the grain
                        // rolls (turning with the material there, a = 0.5 columns stop at
                        // 2/3 of the DEM's runout). I² = γ̇² d / |g| < I_c², without a division.
                        let (_, grad) = coupling::interpolate::<S>(&self.grid, self.kernel, x0, node_velocity);
                        let rate = grad.shear_rate(S::DIM);
                        let d = 2.0 * g.radius[i];
                        if rate * rate * d < self.quasi_static * self.quasi_static * self.gravity {
                            g.omega[i] = grad.spin::<S>();
                        }
                    } else {
                        let (v, grad) = coupling::interpolate::<S>(&self.grid, self.kernel, x0, node_velocity);
                        g.v[i] = v;
                        g.omega[i] = grad.spin::<S>();
                        g.x[i] = x0 + v * window.dt;
                    }
                }
            }
            self.pipeline.invalidate();
        }
        self.after_step(window)
    }

    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        let dt = window.dt / self.substeps as f64;
        self.pipeline.run(&mut self.state, dt, self.substeps as usize);
        self.check(window.step, dt)?;
        self.after_step(window)
    }

    fn view(&self, max: usize, out: &mut Vec<ViewPoint>) -> u64 {
        let g = &self.state.grains;
        for i in (0..g.len()).step_by(view_stride(g.len(), max)) {
            out.push(ViewPoint {
                id: g.id[i],
                position: S::to_array(g.x[i]),
                velocity: S::to_array(g.v[i]),
                size: g.radius[i],
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
                    let writer = FrameWriter::new(dir).map_err(|e| e.to_string())?;
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
        let stress = grains_grid::homogenize::stress::<S>(&self.grid, self.kernel, &contacts);
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
            self.energy_bound = self.energy_bound.max(runaway_bound(self.extent, self.gravity, &self.state));
        }
        Ok(())
    }

    fn report(&self) -> SolverReport {
        let g = &self.state.grains;
        let p = S::to_array(DemPipeline::momentum(&self.state));
        SolverReport {
            n_items: g.len() as u64,
            n_nodes: self.raster.len() as u64,
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
            use std::io::Write as _;
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
            writeln!(log, "{row}")?;
            if window.step.is_multiple_of(100) {
                log.flush()?;
            }
        }
        if let Some((f, every)) = &mut self.frames
            && window.step.is_multiple_of(*every)
        {
            f.write(window.step, &self.state, &self.pipeline)?;
        }
        Ok(())
    }
}
