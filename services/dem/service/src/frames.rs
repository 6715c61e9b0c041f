//! VTU frames of the grains (ParaView: open `frames/grains.pvd`, glyph by `radius`), with point
//! data id, radius, mass (the grain's share in a hybrid band: m (1 − w)), velocity,
//! angular_velocity and contacts.

use grains_dem::pipeline::DemPipeline;
use grains_dem::space::Space;
use grains_dem::state::DemState;
use grains_service::vtu::{Field, PointFrames, Values};
use std::path::{Path, PathBuf};

pub struct FrameWriter(PointFrames);

impl FrameWriter {
    /// The grains' frames of a run; of a run resumed after step `resume`, see [`PointFrames::open`].
    pub fn new(run_dir: &Path, resume: Option<u64>) -> std::io::Result<Self> {
        Ok(FrameWriter(PointFrames::open(run_dir, "grains", resume)?))
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
        self.0.write(step, state.time, &x, &fields)
    }
}
