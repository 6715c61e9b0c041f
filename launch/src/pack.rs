//! `grains pack`: pour and settle the grains of a DEM scene and save the packing (a LAMMPS
//! data file) for scenes to reuse (`packing = "file.data"` in a `[[body]]`) and for LAMMPS.
//! `--friction` settles with another friction coefficient (Chen 2021 §4.1: μ = 0.01 gives a
//! denser packing; the scenes that reuse it set their own μ).

use anyhow::{Context, bail};
use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, D3, Space};
use grains_dem_service::lammps_data::{Atom, DataFile};
use grains_protocol::scene::{self, Dimension, Scene};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Clone, clap::Args)]
pub struct PackArgs {
    /// A DEM scene: its bodies are poured, its walls hold them, its duration settles them.
    pub scene: PathBuf,
    /// Where to write the packing (LAMMPS data file, `atom_style sphere`).
    #[arg(long)]
    pub out: PathBuf,
    /// Friction coefficient while settling (grains and walls), e.g. 0.01 for a dense packing.
    #[arg(long)]
    pub friction: Option<f64>,
    /// Scene overrides, as for `grains run`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

pub fn pack(args: &PackArgs) -> anyhow::Result<()> {
    let (scene, _) = scene::load_with_overrides(&args.scene, &args.overrides)?;
    if scene.synthetic.is_some() || scene.participants() != [grains_protocol::Role::Dem] {
        bail!(crate::run::BadInput(format!(
            "{}: grains pack needs a scene whose bodies are all model = \"dem\"",
            scene.path.display()
        )));
    }
    grains_dem_service::check_scene(&scene)?;
    match scene.dimension {
        Dimension::Two => pack_in::<D2>(&scene, args),
        Dimension::Three => pack_in::<D3>(&scene, args),
    }
}

fn pack_in<S: Space>(scene: &Scene, args: &PackArgs) -> anyhow::Result<()> {
    let mut state = grains_dem_service::setup::build_state::<S>(scene, &grains_service::zones::ZoneField::layered(scene))?;
    if let Some(mu) = args.friction {
        state.params.materials.iter_mut().for_each(|m| m.friction = mu);
        state.walls.iter_mut().for_each(|w| w.friction = mu);
    }
    let mut pipeline = DemPipeline::<S>::new(scene.threads as usize)?;
    let dt = grains_dem_service::setup::dem_dt(scene);
    let per_step = scene.coupling.substeps as usize;
    let t0 = Instant::now();
    tracing::info!(
        "pack: {} grains, {} steps of {dt:.3e} s",
        state.grains.len(),
        scene.steps * per_step as u64
    );
    for step in 1..=scene.steps {
        // Inside `grains bench` an earlier run has installed the launcher's Ctrl-C/SIGTERM
        // handler, which only raises a flag: without this a pour would not stop.
        if grains_service::signals::signalled() {
            bail!("interrupted at macro-step {step} of {}: no packing written", scene.steps);
        }
        pipeline.run(&mut state, dt, per_step);
        if let Some(id) = DemPipeline::first_non_finite(&state) {
            bail!("grain {id} is not finite at macro-step {step}: the settling blew up");
        }
        if step % (scene.steps / 20).max(1) == 0 || step == scene.steps {
            tracing::info!(
                "pack: step {step}/{} | t = {:.4} s | kinetic energy {:.3e} J | {:.0} s",
                scene.steps,
                state.time,
                DemPipeline::kinetic_energy(&state),
                t0.elapsed().as_secs_f64()
            );
        }
    }
    let g = &state.grains;
    let density: Vec<f64> = scene.materials.iter().filter(|m| m.dem.is_some()).map(|m| m.density).collect();
    let mut bounds = [[0.0, 0.0]; 3];
    for (k, b) in bounds.iter_mut().enumerate() {
        *b = [scene.domain.min[k], scene.domain.max[k]];
        if k >= S::DIM {
            *b = [-0.5e-3, 0.5e-3];
        }
    }
    let atoms = (0..g.len())
        .map(|i| Atom {
            id: i as u64 + 1,
            kind: if g.frozen[i] { 2 } else { 1 },
            diameter: 2.0 * g.radius[i],
            density: density.get(g.material[i] as usize).copied().unwrap_or(0.0),
            x: S::to_array(g.x[i]),
            v: [0.0; 3],
            omega: [0.0; 3],
        })
        .collect();
    let title = format!("grains pack of {} (settled {:.3} s)", scene.path.display(), state.time);
    grains_dem_service::lammps_data::write(&args.out, &DataFile { bounds, atoms }, &title)
        .with_context(|| format!("writing {}", args.out.display()))?;
    tracing::info!("pack: {} grains written to {}", g.len(), args.out.display());
    Ok(())
}
