//! VTU frames of the grains (ParaView: open `frames/grains.pvd`, glyph by `radius`), with point
//! data id, radius, mass (the grain's share in a hybrid band: m (1 − w)), velocity,
//! angular_velocity and contacts; the rigid bodies' outlines beside them (`frames/bodies.pvd`,
//! one polygon each, cell data id, velocity, angular_velocity, force, torque).

use grains_dem::pipeline::DemPipeline;
use grains_dem::space::Space;
use grains_dem::state::DemState;
use grains_service::vtu::{Field, PointFrames, Values};
use std::path::{Path, PathBuf};

pub struct FrameWriter(PointFrames, Option<PointFrames>);

impl FrameWriter {
    /// The grains' frames of a run (and the rigid bodies', `frames/bodies.pvd`, if it has
    /// any); of a run resumed after step `resume`, see [`PointFrames::open`].
    pub fn new<S: Space>(run_dir: &Path, resume: Option<u64>, state: &DemState<S>) -> std::io::Result<Self> {
        let bodies = if state.bodies.is_empty() {
            None
        } else {
            Some(PointFrames::open(run_dir, "bodies", resume)?)
        };
        Ok(FrameWriter(PointFrames::open(run_dir, "grains", resume)?, bodies))
    }

    /// The rigid bodies' outlines, with cell data id, velocity, angular_velocity (z), force
    /// and torque of their contacts (material points' included).
    fn write_bodies<S: Space>(&mut self, step: u64, state: &DemState<S>) -> std::io::Result<()> {
        let Some(frames) = &mut self.1 else { return Ok(()) };
        let b = &state.bodies;
        let outlines: Vec<Vec<[f64; 3]>> = b.iter().map(|b| b.outline(8).iter().map(|p| [p.x, p.y, 0.0]).collect()).collect();
        let id: Vec<u64> = b.iter().map(|b| b.id).collect();
        let v: Vec<f64> = b.iter().flat_map(|b| [b.v.x, b.v.y, 0.0]).collect();
        let w: Vec<f64> = b.iter().map(|b| b.omega).collect();
        // Its contacts with bodies, grains and walls, and with material points.
        let f: Vec<f64> = b
            .iter()
            .flat_map(|b| [b.force.x + b.external.x, b.force.y + b.external.y, 0.0])
            .collect();
        let t: Vec<f64> = b.iter().map(|b| b.torque + b.external_torque).collect();
        let field = |name, components, values| Field { name, components, values };
        let fields = [
            field("id", 1, Values::U64(&id)),
            field("velocity", 3, Values::F64(&v)),
            field("angular_velocity", 1, Values::F64(&w)),
            field("force", 3, Values::F64(&f)),
            field("torque", 1, Values::F64(&t)),
        ];
        frames.write_polygons(step, state.time, &outlines, &fields)?;
        Ok(())
    }

    pub fn write<S: Space>(&mut self, step: u64, state: &DemState<S>, pipeline: &DemPipeline<S>) -> std::io::Result<PathBuf> {
        let g = &state.grains;
        let x: Vec<[f64; 3]> = g.x.iter().map(|&x| S::to_array(x)).collect();
        let v: Vec<f64> = g.v.iter().flat_map(|&v| S::to_array(v)).collect();
        let w: Vec<f64> = g.omega.iter().flat_map(|&w| S::ang_array(w)).collect();
        let mass: Vec<f64> = g.mass.iter().zip(&g.scale).map(|(m, s)| m * s).collect();
        let contacts: Vec<i32> = (0..g.len())
            .map(|i| pipeline.forces.get(i).map_or(0, |f| f.contacts as i32))
            .collect();
        let fields = [
            Field {
                name: "id",
                components: 1,
                values: Values::U64(&g.id),
            },
            Field {
                name: "radius",
                components: 1,
                values: Values::F64(&g.radius),
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
                name: "angular_velocity",
                components: 3,
                values: Values::F64(&w),
            },
            Field {
                name: "contacts",
                components: 1,
                values: Values::I32(&contacts),
            },
        ];
        self.write_bodies(step, state)?;
        self.0.write(step, state.time, &x, &fields)
    }
}
