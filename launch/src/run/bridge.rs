//! The bridge as the launcher sees it: optional and expendable. It is started beside the
//! participants, never admitted or waited for; if it ends early the launcher warns and the run
//! goes on; at the end of the run it is stopped.

use super::participants::{bin_dir, child_command, describe};
use grains_bridge::config::{BridgeArgs, BridgeConfig};
use grains_protocol::Role;
use grains_protocol::scene::Scene;
use grains_service::signals::StopFlag;
use grains_transport::inproc::InProc;
use std::path::Path;
use std::process::Child;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub enum Bridge {
    Process(Child),
    Thread(JoinHandle<anyhow::Result<()>>, StopFlag),
    Ended,
}

impl Bridge {
    /// `grains-bridge` as a process of its own, with the launcher's bridge flags.
    /// The bridge as a process of its own; `extra` arguments (`--zenoh ENDPOINT`) after the rest.
    pub fn spawn_process(
        args: &BridgeArgs,
        scene: &Scene,
        scene_path: &Path,
        run_id: &str,
        out_dir: &Path,
        extra: &[String],
    ) -> anyhow::Result<Self> {
        let bin = bin_dir().join(Role::Bridge.binary());
        let mut cmd = child_command(&bin);
        cmd.arg("--scene")
            .arg(scene_path)
            .arg("--run-id")
            .arg(run_id)
            .arg("--out-dir")
            .arg(out_dir)
            .arg("--scene-name")
            .arg(&scene.name)
            .args(args.to_args())
            .args(extra);
        let child = cmd.spawn().map_err(|e| anyhow::anyhow!("cannot start {}: {e}", bin.display()))?;
        Ok(Bridge::Process(child))
    }

    /// The bridge as a thread of an in-process run.
    pub fn spawn_thread(cfg: &BridgeConfig, bus: &InProc, scene: &Scene, run_id: &str, out_dir: &Path) -> anyhow::Result<Self> {
        let stop = StopFlag::manual();
        let (cfg, bus, scene, run_id, out_dir, flag) = (
            cfg.clone(),
            bus.clone(),
            scene.clone(),
            run_id.to_string(),
            out_dir.to_path_buf(),
            stop.clone(),
        );
        let handle = std::thread::Builder::new().name(Role::Bridge.binary().into()).spawn(move || {
            grains_service::telemetry::set_participant(Role::Bridge.binary());
            grains_bridge::serve(&bus, &cfg, &run_id, &scene, Some(&out_dir), &flag)
        })?;
        Ok(Bridge::Thread(handle, stop))
    }

    pub fn pid(&self) -> Option<u32> {
        match self {
            Bridge::Process(c) => Some(c.id()),
            _ => None,
        }
    }

    /// How the bridge ended, once, if it ended since the last call.
    pub fn poll(&mut self) -> Option<String> {
        let how = match self {
            Bridge::Process(c) => c.try_wait().ok().flatten().map(describe)?,
            Bridge::Thread(h, _) if h.is_finished() => {
                let Bridge::Thread(h, _) = std::mem::replace(self, Bridge::Ended) else {
                    unreachable!()
                };
                return Some(match h.join() {
                    Ok(Ok(())) => "ended".into(),
                    Ok(Err(e)) => format!("failed: {e:#}"),
                    Err(_) => "panicked".into(),
                });
            }
            _ => return None,
        };
        *self = Bridge::Ended;
        Some(how)
    }

    /// Stops the bridge (SIGTERM, then SIGKILL after `grace`). False if it had to be killed.
    pub fn stop(&mut self, grace: Duration) -> bool {
        match std::mem::replace(self, Bridge::Ended) {
            Bridge::Process(mut c) => {
                // SAFETY: plain kill(2) on our own child, not yet reaped.
                unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
                let deadline = Instant::now() + grace;
                while Instant::now() < deadline {
                    if let Ok(Some(_)) = c.try_wait() {
                        return true;
                    }
                    std::thread::sleep(Duration::from_millis(10));
                }
                let _ = c.kill();
                let _ = c.wait();
                false
            }
            Bridge::Thread(h, stop) => {
                stop.set();
                let _ = h.join();
                true
            }
            Bridge::Ended => true,
        }
    }
}
