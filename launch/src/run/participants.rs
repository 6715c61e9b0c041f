//! The participants of a run as the launcher sees them: child processes (iceoryx2 runs) or
//! threads (in-process runs), behind one small trait.

use grains_protocol::{Role, scene::Scene};
use grains_service::signals::StopFlag;
use grains_service::solver::ParticipantOptions;
use grains_transport::inproc::InProc;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How a participant ended.
#[derive(Clone, Debug)]
pub struct Exit {
    pub role: Role,
    pub ok: bool,
    /// "exited with code 1", "killed by signal 9 (SIGKILL)", "failed: …".
    pub how: String,
}

pub trait Participants {
    /// Participants that ended since the last call.
    fn poll_exits(&mut self) -> Vec<Exit>;
    /// Whether every participant started by the launcher has ended.
    fn all_ended(&self) -> bool;
    /// Asks every running participant to stop, then forces it after `grace`.
    fn terminate(&mut self, grace: Duration);
    /// (role, pid) of the participants started by the launcher.
    fn pids(&self) -> Vec<(Role, u32)>;
}

/// Directory of the participant binaries: `GRAINS_BIN_DIR` if set, else the directory of the
/// running executable (minus a trailing `deps/`, so that integration tests find them).
pub fn bin_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("GRAINS_BIN_DIR") {
        return PathBuf::from(dir);
    }
    let exe = std::env::current_exe().unwrap_or_default();
    let mut dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    if dir.ends_with("deps") {
        dir.pop();
    }
    dir
}

pub struct Processes {
    children: Vec<(Role, Option<Child>, u32)>,
}

pub(crate) fn describe(status: std::process::ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with code {code}"),
        (None, Some(sig)) => {
            let name = match sig {
                libc::SIGKILL => " (SIGKILL)",
                libc::SIGTERM => " (SIGTERM)",
                libc::SIGSEGV => " (SIGSEGV)",
                libc::SIGABRT => " (SIGABRT)",
                libc::SIGINT => " (SIGINT)",
                _ => "",
            };
            format!("killed by signal {sig}{name}")
        }
        _ => "ended".into(),
    }
}

/// A child of the launcher: in its own process group (a terminal's Ctrl-C reaches the
/// launcher only, which stops the run at a step boundary), with a parent-death signal so that
/// none outlives a killed launcher.
pub(crate) fn child_command(bin: &Path) -> Command {
    let mut cmd = Command::new(bin);
    cmd.process_group(0);
    // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    cmd
}

impl Processes {
    /// Starts `roles` as processes of their own ([`child_command`]).
    /// `resume`: the checkpoint directory of a resumed run.
    pub fn spawn(
        roles: &[Role],
        scene_path: &Path,
        run_id: &str,
        out_dir: &Path,
        connect_timeout: f64,
        resume: Option<&Path>,
        extra: &[String],
    ) -> anyhow::Result<Self> {
        let dir = bin_dir();
        let mut children = Vec::new();
        for &role in roles {
            let bin = dir.join(role.binary());
            let mut cmd = child_command(&bin);
            cmd.arg("--scene")
                .arg(scene_path)
                .arg("--run-id")
                .arg(run_id)
                .arg("--connect-timeout")
                .arg(connect_timeout.to_string())
                .arg("--out-dir")
                .arg(out_dir);
            if let Some(dir) = resume {
                cmd.arg("--resume").arg(dir);
            }
            cmd.args(extra);
            let child = cmd.spawn().map_err(|e| anyhow::anyhow!("cannot start {}: {e}", bin.display()))?;
            let pid = child.id();
            children.push((role, Some(child), pid));
        }
        Ok(Processes { children })
    }
}

impl Participants for Processes {
    fn poll_exits(&mut self) -> Vec<Exit> {
        let mut out = Vec::new();
        for (role, slot, _) in &mut self.children {
            if let Some(child) = slot
                && let Ok(Some(status)) = child.try_wait()
            {
                out.push(Exit {
                    role: *role,
                    ok: status.success(),
                    how: describe(status),
                });
                *slot = None;
            }
        }
        out
    }

    fn all_ended(&self) -> bool {
        self.children.iter().all(|(_, c, _)| c.is_none())
    }

    fn terminate(&mut self, grace: Duration) {
        for (_, child, pid) in &self.children {
            if child.is_some() {
                // SAFETY: plain kill(2) on our own child's pid, which has not been reaped.
                unsafe { libc::kill(*pid as i32, libc::SIGTERM) };
            }
        }
        let deadline = Instant::now() + grace;
        while !self.all_ended() && Instant::now() < deadline {
            self.poll_exits();
            std::thread::sleep(Duration::from_millis(10));
        }
        for (_, slot, _) in &mut self.children {
            if let Some(child) = slot {
                let _ = child.kill();
                let _ = child.wait();
                *slot = None;
            }
        }
    }

    fn pids(&self) -> Vec<(Role, u32)> {
        self.children.iter().map(|(r, _, pid)| (*r, *pid)).collect()
    }
}

type ThreadResult = anyhow::Result<()>;

pub struct Threads {
    threads: Vec<(Role, Option<JoinHandle<ThreadResult>>, StopFlag)>,
    bus: InProc,
}

impl Threads {
    /// Runs `roles` as threads of this process over the in-process transport `bus`.
    pub fn spawn(roles: &[Role], scene: &Scene, run_id: &str, out_dir: &Path, bus: &InProc, resume: Option<&Path>) -> anyhow::Result<Self> {
        let resume = resume.map(grains_service::checkpoint::Resume::open).transpose()?;
        let mut threads = Vec::new();
        for &role in roles {
            let stop = StopFlag::manual();
            let opts = ParticipantOptions {
                run_id: run_id.to_string(),
                stop: stop.clone(),
                connect_timeout: Some(Duration::from_secs(60)),
                protocol_version: grains_protocol::PROTOCOL_VERSION,
                checksums: scene.synthetic.as_ref().is_none_or(|s| s.checksum),
                out_dir: Some(out_dir.to_path_buf()),
                resume: resume.clone(),
            };
            let (scene, bus) = (scene.clone(), bus.clone());
            let handle = std::thread::Builder::new().name(role.binary().into()).spawn(move || {
                grains_service::telemetry::set_participant(role.binary());
                match role {
                    Role::Dem => grains_dem_service::run(&bus, &scene, &opts),
                    Role::Mpm => grains_mpm_service::run(&bus, &scene, &opts),
                    Role::Coupler => grains_coupler_service::run(&bus, &scene, &opts),
                    Role::Oracle => grains_oracle_service::run(&bus, &scene, &opts),
                    other => Err(anyhow::anyhow!("{} has no in-process participant in this build", other.binary())),
                }
            })?;
            threads.push((role, Some(handle), stop));
        }
        Ok(Threads { threads, bus: bus.clone() })
    }
}

impl Participants for Threads {
    fn poll_exits(&mut self) -> Vec<Exit> {
        let mut out = Vec::new();
        for (role, slot, _) in &mut self.threads {
            if slot.as_ref().is_some_and(|h| h.is_finished()) {
                let handle = slot.take().expect("checked above");
                let exit = match handle.join() {
                    Ok(Ok(())) => Exit {
                        role: *role,
                        ok: true,
                        how: "ended".into(),
                    },
                    Ok(Err(e)) => {
                        tracing::error!("{} failed: {e:#}", role.binary());
                        Exit {
                            role: *role,
                            ok: false,
                            how: format!("failed: {e:#}"),
                        }
                    }
                    Err(_) => Exit {
                        role: *role,
                        ok: false,
                        how: "panicked".into(),
                    },
                };
                if !exit.ok {
                    self.bus.mark_dead(format!("{} (thread)", role.binary()));
                }
                out.push(exit);
            }
        }
        out
    }

    fn all_ended(&self) -> bool {
        self.threads.iter().all(|(_, h, _)| h.is_none())
    }

    fn terminate(&mut self, _grace: Duration) {
        for (_, _, stop) in &self.threads {
            stop.set();
        }
        for (_, slot, _) in &mut self.threads {
            if let Some(h) = slot.take() {
                let _ = h.join();
            }
        }
    }

    fn pids(&self) -> Vec<(Role, u32)> {
        self.threads.iter().map(|(r, _, _)| (*r, std::process::id())).collect()
    }
}
