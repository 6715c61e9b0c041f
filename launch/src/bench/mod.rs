//! `grains bench`: figures that say how fast grains is, each measured side by side in one run
//! (two codes, two transports, two models) so that a shared machine's noise cancels in the
//! ratio: [`ipc`] (transport cost per macro-step, iceoryx2 processes against threads),
//! [`dem`] (µs per grain-step beside LAMMPS), [`mpm`] (µs per point-step beside Taichi),
//! [`hybrid`] (the hybrid column against the pure DEM one), [`chute`] (Yue 2018 §5's speed-up
//! study on the periodic chute), [`bridge`] (what remote access costs a run). [`machine`] measures the machine itself.

pub mod bridge;
pub mod chute;
pub mod dem;
pub mod hybrid;
pub mod ipc;
pub mod machine;
pub mod mpm;

/// Runs `scene` with `overrides` as a bench run: the scene as it will run (steps chosen) in a
/// file of its own under `out/scenes` named after `label`, its output under `out/runs`, one
/// frame at the end when `frame` is set. Returns the run's directory and its scene.
pub(crate) fn run_resolved(
    scene: &std::path::Path,
    label: &str,
    overrides: &[String],
    out: &std::path::Path,
    frame: bool,
) -> anyhow::Result<(std::path::PathBuf, grains_protocol::scene::Scene)> {
    use crate::run::{RunOptions, Status, run};
    let (s, text, _) = crate::run::steps::load(scene, overrides)?;
    let resolved = std::path::absolute(
        out.join("scenes")
            .join(format!("{}.toml", label.replace([' ', ',', '/', '='], "_"))),
    )?;
    std::fs::create_dir_all(resolved.parent().expect("a file in a directory"))?;
    std::fs::write(&resolved, &text)?;
    tracing::info!("bench: {label}");
    let frames = format!("output.frames_every={}", if frame { s.steps } else { 0 });
    let outcome = run(&RunOptions::quiet(resolved, out.join("runs"), vec![frames]))?;
    if outcome.status != Status::Completed {
        anyhow::bail!("{label}: the run did not complete: {}", outcome.message);
    }
    let run_scene = grains_protocol::scene::load(&outcome.dir.join("scene.toml"))?;
    Ok((outcome.dir, run_scene))
}
