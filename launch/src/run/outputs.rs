//! Files of a run in `out/<scene>/<run-id>/` besides `metrics.csv` ([`crate::metrics`]):
//! the scene's copy and `summary.json`, written to a temporary file and renamed, so that
//! nothing is ever half-written.

use super::{RunCtx, RunOutcome, TransportKind};
use anyhow::Context;
use grains_protocol::PROTOCOL_VERSION;
use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::time::SystemTime;

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// `summary.json`: the run, how it ended, every participant.
pub(super) fn write_summary(ctx: &RunCtx, r: &RunOutcome, participants: serde_json::Value, started: SystemTime) -> anyhow::Result<()> {
    let wall = r.stepping.as_secs_f64();
    let resumed_after = ctx.resume.map(|r| r.manifest.step);
    let steps_here = r.steps_done - resumed_after.unwrap_or(0).min(r.steps_done);
    let json = serde_json::json!({
        "run_id": r.run_id,
        "scene": ctx.scene_path.display().to_string(),
        "scene_name": ctx.scene.name,
        "scene_hash": format!("{:016x}", ctx.scene.hash),
        "protocol_version": PROTOCOL_VERSION,
        "transport": match ctx.opts.transport { TransportKind::Ipc => "ipc", TransportKind::Inproc => "inproc", TransportKind::Zenoh => "zenoh" },
        "status": r.status.as_str(),
        "message": r.message,
        "steps_planned": ctx.scene.steps,
        "steps_completed": r.steps_done,
        "simulated_time": r.steps_done as f64 * ctx.scene.dt,
        "wall_time_s": wall,
        "steps_per_second": if wall > 0.0 { steps_here as f64 / wall } else { 0.0 },
        "resumed_after_step": resumed_after,
        "checkpoint_every": ctx.scene.output.checkpoint_every,
        "started_unix_s": started.duration_since(SystemTime::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0),
        "participants": participants,
        "outputs": { "metrics": "metrics.csv" },
    });
    let text = serde_json::to_string_pretty(&json)? + "\n";
    write_atomic(&ctx.dir.join("summary.json"), text.as_bytes())
        .with_context(|| format!("writing {}", ctx.dir.join("summary.json").display()))
}
