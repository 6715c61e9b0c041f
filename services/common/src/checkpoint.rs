//! Checkpoints of a run (`output.checkpoint_every`, `grains run --checkpoint-every N`) and
//! what `grains resume` continues from.
//!
//! After a checkpoint step, before its summary, every participant writes its whole state to
//! `<run dir>/checkpoints/<step, 10 digits>/<role>.bin` (a temporary file, synced, renamed).
//! The launcher, once it has every summary of that step and has synced `metrics.csv.part`,
//! writes `manifest.json` beside them the same way: only a directory with a manifest is a
//! complete checkpoint. A resumed participant gets that directory (`--resume DIR`), reads
//! its own file and continues with the next step as if the run had never stopped.
//!
//! Every process of a run that writes into its directory — the launcher and the participants
//! it starts — holds `run.lock` there with a shared `flock` while it runs (the kernel lets go
//! when the process ends, however it ends); `grains resume` takes it exclusive before it
//! touches anything, so it refuses a directory that any of them still writes to.
//!
//! A file: the header (little-endian), then the participant's own payload. Ours are
//! serde values in bincode's standard encoding with fixed-width integers; another program
//! taking a role may put anything in its payload: only it reads it back.

use anyhow::{Context, bail};
use grains_protocol::Role;
use grains_protocol::checksum::Checksum;
use grains_protocol::scene::Scene;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Version of the layout (header, manifest, and the built-in payloads).
/// 2: the DEM's state and pipeline carry rigid bodies and their contacts; 3: the DEM carries
/// its bodies' contacts with material points; 4: a body's contact keys name the part of the
/// outline touched (non-convex bodies).
pub const FORMAT: u32 = 4;
const MAGIC: [u8; 8] = *b"GRAINSCP";
/// magic, format, role code, scene hash, step, payload length, payload checksum.
const HEADER: usize = 8 + 4 + 4 + 8 + 8 + 8 + 8;

/// Locks `<run dir>/run.lock` (shared or exclusive) while the returned file is open; `None`
/// if another process holds it in a way that excludes this.
pub fn hold(run_dir: &Path, exclusive: bool) -> std::io::Result<Option<std::fs::File>> {
    use std::os::fd::AsRawFd;
    let f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(run_dir.join("run.lock"))?;
    let how = if exclusive { libc::LOCK_EX } else { libc::LOCK_SH };
    // SAFETY: flock(2) on a descriptor this function owns.
    if unsafe { libc::flock(f.as_raw_fd(), how | libc::LOCK_NB) } == 0 {
        return Ok(Some(f));
    }
    let err = std::io::Error::last_os_error();
    if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
        Ok(None)
    } else {
        Err(err)
    }
}

/// An exclusive [`hold`] made shared (once the resumed run may start its participants).
pub fn share(lock: &std::fs::File) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    // SAFETY: flock(2) on a descriptor the caller owns.
    if unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_SH) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Whether the participants checkpoint after `step` (never after the last: the run is done).
pub fn due(scene: &Scene, step: u64) -> bool {
    due_at(scene.output.checkpoint_every, scene.steps, step)
}

/// [`due`] of a run of `steps` steps checkpointing `every` steps (0: never).
pub fn due_at(every: u64, steps: u64, step: u64) -> bool {
    every > 0 && step.is_multiple_of(every) && step < steps
}

/// The directory of the checkpoint after `step`.
pub fn dir(run_dir: &Path, step: u64) -> PathBuf {
    run_dir.join("checkpoints").join(format!("{step:010}"))
}

/// A participant's file in checkpoint directory `dir`.
pub fn file(dir: &Path, role: Role) -> PathBuf {
    dir.join(format!("{}.bin", role.name()))
}

/// Writes `role`'s checkpoint after `step` (atomically: nothing half-written is ever there).
pub fn write(run_dir: &Path, role: Role, scene_hash: u64, step: u64, payload: &[u8]) -> anyhow::Result<PathBuf> {
    let dir = dir(run_dir, step);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = file(&dir, role);
    let mut bytes = Vec::with_capacity(HEADER + payload.len());
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&FORMAT.to_le_bytes());
    bytes.extend_from_slice(&(role as u32).to_le_bytes());
    bytes.extend_from_slice(&scene_hash.to_le_bytes());
    bytes.extend_from_slice(&step.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&payload_checksum(payload).to_le_bytes());
    bytes.extend_from_slice(payload);
    write_synced(&path, &bytes).with_context(|| format!("writing the checkpoint {}", path.display()))?;
    Ok(path)
}

/// Writes `bytes` to `path` through a synced temporary file and a rename.
pub fn write_synced(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// Reads `role`'s payload from the checkpoint `resume`, checking that it is this scene's,
/// this role's and this step's, whole and unaltered.
pub fn read(resume: &Resume, role: Role, scene_hash: u64) -> anyhow::Result<Vec<u8>> {
    let path = file(&resume.dir, role);
    let bytes = std::fs::read(&path).with_context(|| format!("reading the checkpoint {}", path.display()))?;
    let bad = |what: String| anyhow::anyhow!("{}: {what}", path.display());
    if bytes.len() < HEADER || bytes[..8] != MAGIC {
        return Err(bad("not a grains checkpoint".into()));
    }
    let u32_at = |k: usize| u32::from_le_bytes(bytes[k..k + 4].try_into().expect("4 bytes"));
    let u64_at = |k: usize| u64::from_le_bytes(bytes[k..k + 8].try_into().expect("8 bytes"));
    let (format, code, hash, step, len, sum) = (u32_at(8), u32_at(12), u64_at(16), u64_at(24), u64_at(32), u64_at(40));
    if format != FORMAT {
        return Err(bad(format!("checkpoint format {format}; this build reads {FORMAT}")));
    }
    if code != role as u32 {
        return Err(bad(format!("written by role code {code}, not by the {role}")));
    }
    if hash != scene_hash {
        return Err(bad(format!("written for scene hash {hash:016x}, this run's is {scene_hash:016x}")));
    }
    if step != resume.step {
        return Err(bad(format!("holds step {step}, the manifest says {}", resume.step)));
    }
    let payload = &bytes[HEADER..];
    if payload.len() as u64 != len || payload_checksum(payload) != sum {
        return Err(bad(format!(
            "damaged: {} payload bytes of {len}, or a wrong checksum",
            payload.len()
        )));
    }
    Ok(payload.to_vec())
}

/// The wire checksum over the payload's words, the last one padded with zeros (the wire's
/// own leaves a tail of fewer than 8 bytes out; the length is checked on its own).
fn payload_checksum(payload: &[u8]) -> u64 {
    let mut c = Checksum::default();
    let mut words = payload.chunks_exact(8);
    for w in &mut words {
        c.word(u64::from_le_bytes(w.try_into().expect("8 bytes")));
    }
    if !words.remainder().is_empty() {
        let mut last = [0u8; 8];
        last[..words.remainder().len()].copy_from_slice(words.remainder());
        c.word(u64::from_le_bytes(last));
    }
    c.finish()
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_fixed_int_encoding()
}

/// A built-in participant's state as a payload.
pub fn encode<T: Serialize>(value: &T) -> anyhow::Result<Vec<u8>> {
    bincode::serde::encode_to_vec(value, config()).context("encoding a checkpoint")
}

/// A payload of [`encode`] back; all of it must be used.
pub fn decode<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> anyhow::Result<T> {
    let (value, used) = bincode::serde::decode_from_slice(bytes, config()).context("decoding a checkpoint")?;
    if used != bytes.len() {
        bail!(
            "decoding a checkpoint: {} bytes left over (another build's checkpoint?)",
            bytes.len() - used
        );
    }
    Ok(value)
}

/// `manifest.json`: the launcher's record that a checkpoint is complete.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: u32,
    /// The last step the checkpoint holds; the run resumes with the next.
    pub step: u64,
    /// Simulated time at its end [s].
    pub time: f64,
    /// The scene's hash (hex) of the run's copy of the scene.
    pub scene_hash: String,
    /// The run that wrote it.
    pub run_id: String,
    /// One file per participant (`<role>.bin`).
    pub participants: Vec<String>,
    /// `metrics.csv` up to and including this step: its length in bytes and the `wall_s` of
    /// the step's row (the resumed run's wall clock goes on from it).
    pub metrics_bytes: u64,
    pub wall_s: f64,
}

/// Where a participant resumes from: a complete checkpoint's directory and its step.
#[derive(Clone, Debug, PartialEq)]
pub struct Resume {
    pub dir: PathBuf,
    pub step: u64,
    pub time: f64,
}

impl Resume {
    /// The checkpoint in `dir` (its manifest must be there: only complete ones resume).
    pub fn open(dir: &Path) -> anyhow::Result<Self> {
        let m = manifest(dir)?;
        Ok(Resume {
            dir: dir.to_path_buf(),
            step: m.step,
            time: m.time,
        })
    }
}

/// The manifest of checkpoint directory `dir`.
pub fn manifest(dir: &Path) -> anyhow::Result<Manifest> {
    let path = dir.join("manifest.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {} (a checkpoint without one is incomplete)", path.display()))?;
    let m: Manifest = serde_json::from_str(&text).with_context(|| format!("{}: not a checkpoint manifest", path.display()))?;
    if m.format != FORMAT {
        bail!("{}: checkpoint format {}; this build reads {FORMAT}", path.display(), m.format);
    }
    Ok(m)
}

/// The checkpoint directories of a run with a manifest, oldest first.
pub fn complete(run_dir: &Path) -> Vec<(PathBuf, Manifest)> {
    let Ok(entries) = std::fs::read_dir(run_dir.join("checkpoints")) else {
        return Vec::new();
    };
    let mut found: Vec<(PathBuf, Manifest)> = entries
        .flatten()
        .map(|e| e.path())
        .filter_map(|d| manifest(&d).ok().map(|m| (d, m)))
        .collect();
    found.sort_by_key(|(_, m)| m.step);
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("grains-checkpoint-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// A file reads back to its payload; one of another role, scene or step, or with a byte
    /// changed, is refused with the reason.
    #[test]
    fn a_checkpoint_file_reads_back_only_for_its_role_scene_and_step() {
        let run = scratch("file");
        let payload = encode(&(vec![1.5f64, -2.0], 7u64, true)).unwrap();
        let path = write(&run, Role::Dem, 0xabc, 40, &payload).unwrap();
        let resume = Resume {
            dir: dir(&run, 40),
            step: 40,
            time: 0.0,
        };
        let back: (Vec<f64>, u64, bool) = decode(&read(&resume, Role::Dem, 0xabc).unwrap()).unwrap();
        assert_eq!(back, (vec![1.5, -2.0], 7, true));
        let err = |e: anyhow::Error| format!("{e:#}");
        assert!(err(read(&resume, Role::Mpm, 0xabc).unwrap_err()).contains("reading"), "no MPM file");
        assert!(err(read(&resume, Role::Dem, 0xabd).unwrap_err()).contains("scene hash"));
        let later = Resume {
            step: 60,
            ..resume.clone()
        };
        assert!(err(read(&later, Role::Dem, 0xabc).unwrap_err()).contains("holds step 40"));
        let mut bytes = std::fs::read(&path).unwrap();
        *bytes.last_mut().unwrap() ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        assert!(err(read(&resume, Role::Dem, 0xabc).unwrap_err()).contains("damaged"));
        assert!(decode::<(Vec<f64>, u64)>(&payload).is_err(), "bytes left over are an error");
        std::fs::remove_dir_all(&run).unwrap();
    }

    /// Only directories with a manifest count, in step order.
    #[test]
    fn only_checkpoints_with_a_manifest_are_complete() {
        let run = scratch("manifest");
        for step in [20, 10, 30] {
            write(&run, Role::Dem, 1, step, &[]).unwrap();
            if step != 30 {
                let m = Manifest {
                    format: FORMAT,
                    step,
                    time: step as f64,
                    scene_hash: "1".into(),
                    run_id: "r".into(),
                    participants: vec!["dem".into()],
                    metrics_bytes: 0,
                    wall_s: 0.0,
                };
                write_synced(
                    &dir(&run, step).join("manifest.json"),
                    serde_json::to_string(&m).unwrap().as_bytes(),
                )
                .unwrap();
            }
        }
        let steps: Vec<u64> = complete(&run).iter().map(|(_, m)| m.step).collect();
        assert_eq!(steps, [10, 20]);
        assert!(Resume::open(&dir(&run, 30)).is_err(), "no manifest, no resume");
        assert_eq!(Resume::open(&dir(&run, 20)).unwrap().step, 20);
        std::fs::remove_dir_all(&run).unwrap();
    }
}
