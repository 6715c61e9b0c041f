//! The MPM behind the participant loop's [`Solver`] trait, and its VTU frames of the points
//! (`frames/points.pvd`: id, velocity, pressure, plastic strain and its rate, packing fraction).

use anyhow::bail;
use grains_grid::Vector;
use grains_mpm::matrix::MpmSpace;
use grains_mpm::pipeline::{Model, MpmParams, MpmPipeline};
use grains_mpm::points::{Points, totals};
use grains_protocol::scene::Scene;
use grains_protocol::wire::{NodeVelocity, RasterNode};
use grains_service::solver::{Solver, SolverReport, StepWindow};
use grains_service::vtu::{Field, PointFrames, Values};

pub struct MpmSolver<S: MpmSpace> {
    pub points: Points<S>,
    pub params: MpmParams<S>,
    pub pipeline: MpmPipeline<S>,
    frames: Option<(PointFrames, u64)>,
    /// Kinetic energy above which the run is declared runaway [J].
    energy_bound: f64,
}

impl<S: MpmSpace> MpmSolver<S> {
    pub fn new(scene: &Scene, points: Points<S>, params: MpmParams<S>, out_dir: Option<&std::path::Path>) -> anyhow::Result<Self> {
        let pipeline = MpmPipeline::new(scene.threads as usize).map_err(anyhow::Error::msg)?;
        let energy_bound = runaway_bound(scene, &points, &params);
        let frames = match out_dir {
            Some(dir) if scene.output.frames_every > 0 => Some((PointFrames::new(dir, "points")?, scene.output.frames_every)),
            _ => None,
        };
        let mut solver = MpmSolver {
            points,
            params,
            pipeline,
            frames,
            energy_bound,
        };
        solver.write_frame(0)?;
        Ok(solver)
    }

    fn write_frame(&mut self, step: u64) -> std::io::Result<()> {
        let Some((frames, _)) = &mut self.frames else { return Ok(()) };
        let p = &self.points;
        let model = &self.params.model;
        let x: Vec<[f64; 3]> = p.x.iter().map(|&x| S::to_array(x)).collect();
        let v: Vec<f64> = p.v.iter().flat_map(|&v| S::to_array(v)).collect();
        let pressure: Vec<f64> = (0..p.len()).map(|k| Model::pressure(&p.tau[k], p.jacobian[k])).collect();
        let packing: Vec<f64> = (0..p.len()).map(|k| model.packing(p.packing[k], p.jacobian[k])).collect();
        let fields = [
            Field {
                name: "id",
                components: 1,
                values: Values::U64(&p.id),
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
/// energy of all the material at the fastest wall's speed): a run that exceeds it is blowing up,
/// not flowing.
fn runaway_bound<S: MpmSpace>(scene: &Scene, pts: &Points<S>, params: &MpmParams<S>) -> f64 {
    let mass: f64 = pts.mass.iter().sum();
    let extent = (0..scene.dim())
        .map(|k| scene.domain.max[k] - scene.domain.min[k])
        .fold(0.0, f64::max);
    let g = params.gravity.length();
    let wall_speed = params.walls.iter().map(|w| w.velocity.length()).fold(0.0, f64::max);
    // Confining loads can accelerate the whole body across the domain at most.
    let loads: f64 = pts.loads.iter().map(|(_, f)| f.length()).sum::<f64>() * extent;
    let (ke, _) = totals(pts);
    100.0 * (ke + mass * g * extent + 0.5 * mass * wall_speed * wall_speed + loads).max(f64::MIN_POSITIVE)
}

impl<S: MpmSpace> Solver for MpmSolver<S> {
    fn predict(&mut self, _window: &StepWindow) -> anyhow::Result<usize> {
        bail!("the MPM side of a coupled run (grid momentum to the coupler, Yue 2018 Alg. 20/21) is not in this build")
    }

    fn write_raster(&mut self, _window: &StepWindow, _out: &mut [RasterNode]) {}

    fn finish(&mut self, _window: &StepWindow, _velocities: &[NodeVelocity]) -> anyhow::Result<()> {
        bail!("the MPM side of a coupled run is not in this build")
    }

    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        if let Err(e) = self.pipeline.step(&mut self.points, &self.params, window.dt) {
            bail!(
                "MPM step {} (t = {:.6e} s): {e}; likely cause: a time step too large for the stiffness (CFL) or the flow speed, \
                 or material driven into the domain's edge",
                window.step,
                self.pipeline.time
            );
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
        if let Some((_, every)) = &self.frames
            && window.step.is_multiple_of(*every)
        {
            self.write_frame(window.step)?;
        }
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
