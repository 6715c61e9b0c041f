//! `grains resume <run dir>`: which checkpoint a run continues from, and the run directory
//! made ready for it (what was written after that checkpoint goes; the participants drop
//! their own later frames and rows themselves, [`grains_service::vtu::PointFrames::open`]).

use super::BadInput;
use anyhow::{Context, bail};
use grains_protocol::scene::Scene;
use grains_service::checkpoint::{self, Manifest};
use std::path::{Path, PathBuf};

/// How many complete checkpoints a run keeps (the newest; one more in case the newest is
/// damaged on disk).
pub const KEEP: usize = 2;

/// The run directory for this launcher, exclusively: nobody else (a launcher, a participant
/// of the stopped run still exiting) holds `run.lock` ([`checkpoint::hold`]). Shared once
/// the directory is ready ([`checkpoint::share`]), for the new participants to hold it too.
pub fn lock(run_dir: &Path) -> anyhow::Result<std::fs::File> {
    let path = run_dir.join("run.lock");
    match checkpoint::hold(run_dir, true).with_context(|| format!("locking {}", path.display()))? {
        Some(f) => Ok(f),
        None => bail!(BadInput(format!(
            "{}: the run is still going (a process of it holds {}: its launcher, or a participant still exiting); stop it first",
            run_dir.display(),
            path.display()
        ))),
    }
}

/// A run being resumed.
#[derive(Clone, Debug)]
pub struct Resumed {
    pub run_dir: PathBuf,
    /// The checkpoint directory the participants resume from.
    pub checkpoint: PathBuf,
    pub manifest: Manifest,
}

/// The last complete checkpoint of the run in `run_dir` (of `scene`, its copy of the scene),
/// with everything after it removed: later (incomplete) checkpoints, and the metrics file
/// cut back to the checkpoint's step (`metrics.csv.part` again, as during a run).
pub fn prepare(run_dir: &Path, scene: &Scene) -> anyhow::Result<Resumed> {
    let summary = run_dir.join("summary.json");
    if let Ok(text) = std::fs::read_to_string(&summary)
        && let Ok(json) = serde_json::from_str::<serde_json::Value>(&text)
        && json["status"] == "completed"
    {
        bail!(BadInput(format!(
            "{}: the run completed; there is nothing to resume",
            summary.display()
        )));
    }
    let Some((checkpoint, manifest)) = checkpoint::complete(run_dir).pop() else {
        bail!(BadInput(format!(
            "{}: no complete checkpoint (a directory with a manifest.json); only a run started with \
             --checkpoint-every N (or output.checkpoint_every in its scene) can be resumed, from its last checkpoint",
            run_dir.join("checkpoints").display()
        )));
    };
    let hash = format!("{:016x}", scene.hash);
    if manifest.scene_hash != hash {
        bail!(BadInput(format!(
            "{}: written for scene hash {}, but {} hashes to {hash}: the run's scene was changed",
            checkpoint.join("manifest.json").display(),
            manifest.scene_hash,
            run_dir.join("scene.toml").display()
        )));
    }
    // Checkpoints begun after the last complete one.
    if let Ok(entries) = std::fs::read_dir(run_dir.join("checkpoints")) {
        for e in entries.flatten() {
            let later = e
                .file_name()
                .to_str()
                .and_then(|n| n.parse::<u64>().ok())
                .is_some_and(|s| s > manifest.step);
            if later {
                std::fs::remove_dir_all(e.path()).with_context(|| format!("removing {}", e.path().display()))?;
            }
        }
    }
    cut_metrics(run_dir, manifest.metrics_bytes)?;
    let _ = std::fs::remove_file(&summary);
    Ok(Resumed {
        run_dir: run_dir.to_path_buf(),
        checkpoint,
        manifest,
    })
}

/// `metrics.csv.part` (renamed back from `metrics.csv` if the launcher finished it) cut to
/// `bytes`: the rows up to the checkpoint's step.
fn cut_metrics(run_dir: &Path, bytes: u64) -> anyhow::Result<()> {
    let part = run_dir.join("metrics.csv.part");
    let done = run_dir.join("metrics.csv");
    if !part.exists() && done.exists() {
        std::fs::rename(&done, &part).with_context(|| format!("renaming {}", done.display()))?;
    }
    let f = std::fs::OpenOptions::new()
        .write(true)
        .open(&part)
        .with_context(|| format!("opening {} to resume it", part.display()))?;
    let len = f.metadata()?.len();
    if len < bytes {
        bail!(
            "{}: {len} bytes, shorter than the {bytes} the checkpoint recorded: the metrics were damaged",
            part.display()
        );
    }
    f.set_len(bytes).with_context(|| format!("cutting {}", part.display()))?;
    Ok(())
}

/// After the checkpoint `manifest` of `run_dir` is written: only the newest [`KEEP`]
/// complete checkpoints stay, and nothing older that never completed.
pub fn prune(run_dir: &Path, manifest: &Manifest) {
    let complete = checkpoint::complete(run_dir);
    let keep_from = complete.iter().rev().nth(KEEP - 1).map_or(0, |(_, m)| m.step);
    let Ok(entries) = std::fs::read_dir(run_dir.join("checkpoints")) else {
        return;
    };
    for e in entries.flatten() {
        let step = e.file_name().to_str().and_then(|n| n.parse::<u64>().ok());
        if step.is_some_and(|s| s < keep_from || (s < manifest.step && !complete.iter().any(|(_, m)| m.step == s))) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}
