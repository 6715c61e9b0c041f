//! The launcher's side of a run once its participants are started: admission and release,
//! one metrics row per macro-step from their summaries, the acknowledgements of control
//! commands, and supervision (a participant that dies is named within a second and the others
//! are stopped; Ctrl-C stops everyone at a step boundary).

use super::admission::{Roster, admit, roster_json};
use super::bridge::Bridge;
use super::participants::Participants;
use super::progress::Progress;
use super::{RunCtx, RunOutcome, Status, TransportKind};
use crate::metrics::MetricsWriter;
use anyhow::Context;
use grains_protocol::names;
use grains_protocol::wire::{Ack, AckStatus, Command, Control, Hello, StepHeader, Summary, Verdict, Welcome};
use grains_protocol::{HELLO_MAGIC, PROTOCOL_VERSION, Role, run_id_bytes};
use grains_service::checkpoint;
use grains_service::signals::StopFlag;
use grains_transport::{Publisher, Subscriber, Transport};
use std::time::{Duration, Instant};

/// How long one pass of the loop waits for summaries.
const WAIT: Duration = Duration::from_millis(50);
/// How often the transport is asked for dead participants.
const DEAD_CHECK: Duration = Duration::from_millis(300);
/// How long the time owner has to stop at a step boundary after an interrupt.
const STOP_GRACE: Duration = Duration::from_secs(3);
/// How long the bridge has to end once the run has (it bounds its own wait on clients).
const BRIDGE_GRACE: Duration = Duration::from_secs(2);

/// The services the launcher reads or writes; they exist before any participant starts.
struct Ports<T: Transport> {
    hello: T::Subscriber<Hello, ()>,
    welcome: T::Publisher<Welcome, ()>,
    summaries: T::Subscriber<Summary, StepHeader>,
    control: T::Publisher<Control, StepHeader>,
    acks: T::Subscriber<Ack, StepHeader>,
}

impl<T: Transport> Ports<T> {
    fn open(t: &T) -> anyhow::Result<Self> {
        Ok(Ports {
            hello: t.subscriber(&names::HELLO)?,
            welcome: t.publisher(&names::WELCOME, 1)?,
            summaries: t.subscriber(&names::SUMMARY)?,
            control: t.publisher(&names::CONTROL, 1)?,
            acks: t.subscriber(&names::ACK)?,
        })
    }
}

/// Why the loop ended, when it ends for a reason of its own.
enum Stop {
    /// A participant died or reported a failure.
    Failure(String),
    /// Ctrl-C / SIGTERM before the run could stop itself.
    Forced,
}

/// A run being supervised.
pub(super) struct Supervisor<'a, T: Transport> {
    ctx: &'a RunCtx<'a>,
    transport: &'a T,
    ports: Ports<T>,
    metrics: MetricsWriter,
    parts: Box<dyn Participants>,
    bridge: Option<Bridge>,
    signals: StopFlag,
    roster: Roster,
    progress: Progress,
    /// When all participants were released into step 1.
    released: Option<Instant>,
    /// The first failure seen.
    failure: Option<String>,
    /// Ctrl-C / SIGTERM arrived; when the time owner was asked to stop (`None`: not asked).
    interrupted: Option<Option<Instant>>,
    /// Step after which a control command (from the bridge) stopped the run.
    stopped_at: Option<u64>,
    /// A control command holds the run paused.
    paused: bool,
    last_dead_check: Instant,
    /// The last peer check found fewer summary publishers than running participants.
    short_of_publishers: bool,
}

impl<'a, T: Transport> Supervisor<'a, T> {
    /// Opens the launcher's services, starts the bridge (if any) and the participants, and
    /// says what the run is.
    pub(super) fn start(
        transport: &'a T,
        ctx: &'a RunCtx<'a>,
        start_bridge: impl FnOnce() -> anyhow::Result<Option<Bridge>>,
        start: impl FnOnce() -> anyhow::Result<Box<dyn Participants>>,
    ) -> anyhow::Result<Self> {
        let ports = Ports::open(transport)?;
        let mut metrics = match ctx.resume {
            None => MetricsWriter::create(ctx.dir, ctx.roles),
            Some(r) => MetricsWriter::resume(ctx.dir, ctx.roles, r.manifest.step, r.manifest.time, r.manifest.wall_s),
        }
        .with_context(|| format!("opening metrics in {}", ctx.dir.display()))?;
        metrics.checkpoint_at(ctx.scene.output.checkpoint_every, ctx.scene.steps);
        let signals = StopFlag::with_signals();
        let mut bridge = start_bridge()?;
        let parts = start().inspect_err(|_| {
            if let Some(b) = &mut bridge {
                let _ = b.stop(Duration::from_secs(1));
            }
        })?;
        let s = Supervisor {
            ctx,
            transport,
            ports,
            metrics,
            parts,
            bridge,
            signals,
            roster: Roster::default(),
            progress: Progress::new(ctx.opts.progress, ctx.scene.steps),
            released: None,
            failure: None,
            interrupted: None,
            stopped_at: None,
            paused: false,
            last_dead_check: Instant::now(),
            short_of_publishers: false,
        };
        s.announce();
        Ok(s)
    }

    fn announce(&self) {
        let ctx = self.ctx;
        if ctx.opts.announce {
            tracing::info!(
                "run {} of scene {} ({} steps), output in {}",
                ctx.run_id,
                ctx.scene.name,
                ctx.scene.steps,
                ctx.dir.display()
            );
            let pids: Vec<String> = self.parts.pids().iter().map(|(r, p)| format!("{} (pid {p})", r.binary())).collect();
            let how = match ctx.opts.transport {
                TransportKind::Ipc => "processes",
                TransportKind::Inproc => "threads",
                TransportKind::Zenoh => "processes over zenoh",
            };
            if !pids.is_empty() {
                tracing::info!("started as {how}: {}", pids.join(", "));
            }
            if let Some(b) = &self.bridge {
                let pid = b.pid().map_or_else(|| "(thread)".to_string(), |p| format!("(pid {p})"));
                tracing::info!(
                    "started the bridge: {} {pid}; its settings: {}",
                    Role::Bridge.binary(),
                    ctx.dir.join("bridge.json").display()
                );
            }
        }
        for e in &ctx.opts.external {
            let bin = super::participants::bin_dir().join(e.binary());
            let dir = std::fs::canonicalize(ctx.dir).unwrap_or_else(|_| ctx.dir.to_path_buf());
            let mut words = vec![
                bin.as_os_str(),
                "--scene".as_ref(),
                ctx.scene_path.as_os_str(),
                "--run-id".as_ref(),
                ctx.run_id.as_ref(),
                "--out-dir".as_ref(),
                dir.as_os_str(),
            ];
            let resume = ctx
                .resume
                .map(|r| std::fs::canonicalize(&r.checkpoint).unwrap_or_else(|_| r.checkpoint.clone()));
            if let Some(r) = &resume {
                words.extend(["--resume".as_ref(), r.as_os_str()]);
            }
            if let Some(z) = ctx.zenoh {
                words.extend([std::ffi::OsStr::new("--zenoh"), std::ffi::OsStr::new(z)]);
            }
            tracing::info!(
                "waiting for an external {e} to attach; start it (or your own program, with the same arguments) with:\n  {}",
                shell_words(&words)
            );
        }
    }

    /// Supervises the run to its end; returns how it ended and the participants' roster.
    pub(super) fn run(mut self) -> anyhow::Result<(RunOutcome, serde_json::Value)> {
        let n_spawned = self.parts.pids().len();
        loop {
            let turn = Instant::now();
            self.admit()?;
            self.collect_summaries(WAIT)?;
            self.record_checkpoints()?;
            self.progress.show(self.metrics.last, self.released);
            self.follow_acks()?;
            self.watch_bridge()?;
            self.watch_participants()?;
            if let Some(stop) = self.check_interrupt()?.or_else(|| self.failure.clone().map(Stop::Failure)) {
                if let Stop::Failure(f) = &stop {
                    tracing::error!("{f}; stopping the other participants");
                }
                self.parts.terminate(Duration::from_secs(1));
                break;
            }
            let complete = self.metrics.last.is_some_and(|(s, _)| s == self.ctx.scene.steps);
            if self.parts.all_ended() && (n_spawned > 0 || complete) {
                // Summaries and acknowledgements sent just before the last exit are still queued.
                self.collect_summaries(WAIT)?;
                self.follow_acks()?;
                break;
            }
            std::thread::sleep(names::SUMMARY_READ_TURN.saturating_sub(turn.elapsed()));
        }
        self.finish()
    }

    /// Answers every hello at once; releases everyone when all are ready.
    fn admit(&mut self) -> anyhow::Result<()> {
        while let Some(hello) = self.ports.hello.receive(Duration::ZERO, |_, h| h.first().copied())? {
            let Some(hello) = hello else { continue };
            if let Some(answer) = admit(&hello, self.ctx, &mut self.roster) {
                self.ports.welcome.publish(1, |_, out| out[0] = answer)?;
            }
        }
        if self.released.is_none() && self.roster.ready.len() == self.ctx.roles.len() {
            let start = Welcome {
                magic: HELLO_MAGIC,
                scene_hash: self.ctx.scene.hash,
                protocol_version: PROTOCOL_VERSION,
                role: 0,
                pid: 0,
                verdict: Verdict::Start as u32,
                run_id: run_id_bytes(self.ctx.run_id),
            };
            self.ports.welcome.publish(1, |_, out| out[0] = start)?;
            self.metrics.start_clock();
            self.released = Some(Instant::now());
        }
        Ok(())
    }

    /// Blocks on the summary event up to `wait`, then takes every summary queued.
    fn collect_summaries(&mut self, wait: Duration) -> anyhow::Result<()> {
        let mut timeout = wait;
        while let Some(s) = self.ports.summaries.receive(timeout, |_, s| s.first().copied())? {
            timeout = Duration::ZERO;
            let Some(s) = s else { continue };
            if s.status != 0 && self.failure.is_none() {
                self.failure = Some(format!(
                    "{} reported a failure at step {}",
                    Role::from_code(s.role).map_or("a participant", |r| r.binary()),
                    s.step
                ));
            }
            if let Err(e) = self.metrics.add(&s) {
                self.failure.get_or_insert(e);
            }
        }
        Ok(())
    }

    /// Every checkpoint whose step's row is written: each participant wrote its file before
    /// its summary, so once the row is synced the checkpoint is complete; its manifest says
    /// so. Older checkpoints beyond [`super::resume::KEEP`] go.
    fn record_checkpoints(&mut self) -> anyhow::Result<()> {
        if self.metrics.checkpoint_rows.is_empty() {
            return Ok(());
        }
        let ctx = self.ctx;
        self.metrics
            .sync()
            .with_context(|| format!("syncing metrics in {}", ctx.dir.display()))?;
        for (step, time, bytes, wall_s) in std::mem::take(&mut self.metrics.checkpoint_rows) {
            let dir = checkpoint::dir(ctx.dir, step);
            let missing: Vec<&str> = ctx
                .roles
                .iter()
                .filter(|r| !checkpoint::file(&dir, **r).exists())
                .map(|r| r.binary())
                .collect();
            if !missing.is_empty() {
                tracing::warn!(
                    "the checkpoint after step {step} is incomplete: no file from {} in {}; the run goes on, this checkpoint cannot be resumed",
                    missing.join(", "),
                    dir.display()
                );
                continue;
            }
            let manifest = checkpoint::Manifest {
                format: checkpoint::FORMAT,
                step,
                time,
                scene_hash: format!("{:016x}", ctx.scene.hash),
                run_id: ctx.run_id.into(),
                participants: ctx.roles.iter().map(|r| r.name().to_string()).collect(),
                metrics_bytes: bytes,
                wall_s,
            };
            let path = dir.join("manifest.json");
            checkpoint::write_synced(&path, (serde_json::to_string_pretty(&manifest)? + "\n").as_bytes())
                .with_context(|| format!("writing {}", path.display()))?;
            super::resume::prune(ctx.dir, &manifest);
        }
        Ok(())
    }

    /// Applied control commands: said once on stderr; a stop's step and pause/resume are kept.
    fn follow_acks(&mut self) -> anyhow::Result<()> {
        let announce = self.ctx.opts.announce && self.interrupted.is_none();
        while let Some(Some(a)) = self.ports.acks.receive(Duration::ZERO, |_, a| a.first().copied())? {
            let Some(c) = Command::from_code(a.command) else { continue };
            if a.status != AckStatus::Applied as u32 {
                continue;
            }
            match c {
                Command::Stop => self.stopped_at = Some(a.step),
                Command::Pause => self.paused = true,
                Command::Resume => self.paused = false,
                // The time owner flags the next step's begin: every participant checkpoints
                // after it.
                Command::Checkpoint => self.metrics.checkpoint_also(a.step + 1),
                Command::Snapshot | Command::Set => {}
            }
            if announce {
                let what = match c {
                    Command::Pause => "paused by a control command",
                    Command::Resume => "resumed by a control command",
                    Command::Stop => "stopping on a control command",
                    Command::Snapshot => "snapshot (frames) by a control command",
                    Command::Set => "a parameter set by a control command",
                    Command::Checkpoint => "a checkpoint after the next step asked by a control command",
                };
                tracing::info!("{what} after step {}", a.step);
            }
        }
        Ok(())
    }

    /// The bridge is expendable: if it ends, the run goes on (resumed, if it was paused from
    /// outside: nobody could resume it any more).
    fn watch_bridge(&mut self) -> anyhow::Result<()> {
        let Some(how) = self.bridge.as_mut().and_then(Bridge::poll) else {
            return Ok(());
        };
        tracing::warn!("the bridge {how}; the run goes on without remote access");
        self.bridge = None;
        if self.paused {
            tracing::info!("the run was paused from outside: resuming it");
            self.send_control(Command::Resume)?;
        }
        Ok(())
    }

    /// Our children's exits, then dead nodes (external participants too), then external
    /// participants that left: the first one that did not end well is the run's failure.
    fn watch_participants(&mut self) -> anyhow::Result<()> {
        let expected = self.interrupted.is_some();
        for exit in self.parts.poll_exits() {
            let pid = self.parts.pids().iter().find(|(r, _)| *r == exit.role).map_or(0, |(_, p)| *p);
            self.roster.exits.insert(exit.role, exit.how.clone());
            if !exit.ok && self.failure.is_none() && !expected {
                self.failure = Some(format!("participant {} (pid {pid}) {}", exit.role.binary(), exit.how));
            }
        }
        if self.last_dead_check.elapsed() > DEAD_CHECK {
            self.last_dead_check = Instant::now();
            // The bridge is our child: its end is seen by `watch_bridge`.
            let dead: Vec<_> = self
                .transport
                .dead_peers(&|name| name == Role::Bridge.binary())
                .into_iter()
                .filter(|d| !d.starts_with(Role::Bridge.binary()))
                .collect();
            if !dead.is_empty() && self.failure.is_none() && !expected {
                self.failure = Some(format!("participant {} died", dead.join(", ")));
            }
            if self.failure.is_none() && !expected {
                self.failure = self.external_left()?;
            }
        }
        Ok(())
    }

    /// Why the run fails if an external participant left it. A clean exit (on SIGTERM, or
    /// after an error of its own) leaves no dead node and no exit status we could read: the
    /// run would wait for it for ever. It does take its summary publisher along. So: fewer
    /// summary publishers than admitted participants still running, at two checks in a row (a
    /// child that exits in between is seen by its status), and the run neither complete nor
    /// stopped once every summary sent is read.
    fn external_left(&mut self) -> anyhow::Result<Option<String>> {
        let ctx = self.ctx;
        let externals: Vec<Role> = ctx
            .opts
            .external
            .iter()
            .copied()
            .filter(|r| self.roster.ready.contains(r))
            .collect();
        if externals.is_empty() || self.released.is_none() {
            return Ok(None);
        }
        let children = self.parts.pids().iter().filter(|(r, _)| !self.roster.exits.contains_key(r)).count();
        let short = self.ports.summaries.publisher_count() < children + externals.len();
        let before = std::mem::replace(&mut self.short_of_publishers, short);
        if !(short && before) {
            return Ok(None);
        }
        self.collect_summaries(Duration::ZERO)?;
        if self.metrics.last.is_some_and(|(s, _)| s == ctx.scene.steps) || self.stopped_at.is_some() {
            return Ok(None);
        }
        let names: Vec<&str> = externals.iter().map(|r| r.binary()).collect();
        Ok(Some(format!(
            "the external {} left the run after step {} of {}: it ended without a failure the run could see (a clean exit leaves no dead node)",
            names.join(" or "),
            self.metrics.last.map_or(0, |(s, _)| s),
            ctx.scene.steps
        )))
    }

    /// Ctrl-C / SIGTERM: the time owner stops at a step boundary; forced after
    /// [`STOP_GRACE`], or at once before the run has started (or while an external time
    /// owner has not attached).
    fn check_interrupt(&mut self) -> anyhow::Result<Option<Stop>> {
        match self.interrupted {
            None if self.signals.is_set() => {
                tracing::info!("stopping the run (interrupt); outputs are being written");
                let ctx = self.ctx;
                let owner = ctx.scene.time_owner();
                let owner_missing = ctx.opts.external.contains(&owner) && !self.roster.ready.contains(&owner);
                if self.released.is_some() && !owner_missing {
                    self.send_control(Command::Stop)?;
                    self.interrupted = Some(Some(Instant::now()));
                    Ok(None)
                } else {
                    self.interrupted = Some(None);
                    Ok(Some(Stop::Forced))
                }
            }
            Some(Some(sent)) if sent.elapsed() > STOP_GRACE => Ok(Some(Stop::Forced)),
            _ => Ok(None),
        }
    }

    /// The launcher's command to the time owner (its sequence numbers are small).
    fn send_control(&mut self, command: Command) -> anyhow::Result<()> {
        let header = StepHeader {
            protocol_version: PROTOCOL_VERSION,
            sender: Role::Launcher as u32,
            run_id: run_id_bytes(self.ctx.run_id),
            ..StepHeader::default()
        };
        self.ports.control.publish(1, |h, out| {
            *h = header;
            out[0] = Control {
                seq: command as u64,
                command: command as u32,
                key: 0,
                value: 0.0,
            };
        })?;
        Ok(())
    }

    /// Closes the outputs and says how the run ended.
    fn finish(mut self) -> anyhow::Result<(RunOutcome, serde_json::Value)> {
        let ctx = self.ctx;
        self.record_checkpoints()?;
        if ctx.opts.announce {
            self.progress.finish(self.metrics.last, self.released);
        }
        // The run's time ends with its steps, not with its bridge.
        let stepping = self.released.map_or(Duration::ZERO, |r| r.elapsed());
        if let Some(b) = &mut self.bridge
            && !b.stop(BRIDGE_GRACE)
        {
            tracing::warn!(
                "the bridge did not end within {} s of being asked to: killed",
                BRIDGE_GRACE.as_secs()
            );
        }
        let steps_done = self.metrics.last.map_or(0, |(s, _)| s);
        self.metrics
            .finish()
            .with_context(|| format!("finishing metrics in {}", ctx.dir.display()))?;
        let (status, message) = if let Some(f) = self.failure {
            (Status::Failed, f)
        } else if self.interrupted.is_some() {
            (Status::Interrupted, format!("interrupted after step {steps_done}"))
        } else if let Some(at) = self.stopped_at {
            (Status::Stopped, format!("stopped by a control command after step {at}"))
        } else if steps_done < ctx.scene.steps {
            (
                Status::Failed,
                format!("the participants ended after step {steps_done} of {}", ctx.scene.steps),
            )
        } else {
            (Status::Completed, format!("{steps_done} steps"))
        };
        let outcome = RunOutcome {
            run_id: ctx.run_id.into(),
            dir: ctx.dir.into(),
            status,
            message,
            steps_done,
            stepping,
        };
        Ok((outcome, roster_json(&self.roster, &*self.parts, ctx)))
    }
}

/// `words` as one POSIX shell command line: every word that is not plainly safe is put in
/// single quotes, so that the line works pasted as printed whatever the paths hold.
fn shell_words(words: &[&std::ffi::OsStr]) -> String {
    let word = |w: &std::ffi::OsStr| {
        let w = w.to_string_lossy();
        let safe = !w.is_empty() && w.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
        if safe {
            w.into_owned()
        } else {
            format!("'{}'", w.replace('\'', r"'\''"))
        }
    };
    words.iter().map(|w| word(w)).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::shell_words;

    #[test]
    fn shell_words_quote_what_a_shell_would_split_or_expand() {
        let w = |s: &'static str| std::ffi::OsStr::new(s);
        assert_eq!(
            shell_words(&[w("/a/grains-dem"), w("--run-id"), w("x-1")]),
            "/a/grains-dem --run-id x-1"
        );
        assert_eq!(shell_words(&[w("/my runs/a$b"), w("it's"), w("")]), r"'/my runs/a$b' 'it'\''s' ''");
    }
}
