//! `grains run`: one run from scene file to outputs.
//!
//! The launcher owns the run (STYLE §2.2 invariant 5): it creates the run id and the
//! iceoryx2 domain, opens the admission, summary and control services before any participant
//! exists, starts only the participants the scene needs, admits them (protocol version, scene,
//! role), releases them all at once, writes one metrics row per macro-step from their
//! summaries, supervises them (a participant that dies is named within a second and the
//! others are stopped), and cleans up every file of the run at the end.

use crate::bridge::Bridge;
use crate::outputs::{Metrics, write_atomic};
use crate::participants::{Participants, Processes, Threads};
use anyhow::{Context, bail};
use grains_bridge::config::BridgeArgs;
use grains_protocol::names;
use grains_protocol::scene::{self, Scene};
use grains_protocol::wire::{Ack, AckStatus, Command, Control, HELLO_READY, Hello, StepHeader, Summary, Verdict, Welcome};
use grains_protocol::{HELLO_MAGIC, PROTOCOL_VERSION, Role, run_id_bytes};
use grains_service::signals::StopFlag;
use grains_transport::{Publisher, Subscriber, Transport, inproc::InProc, ipc};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TransportKind {
    /// Separate processes exchanging over iceoryx2 shared memory.
    Ipc,
    /// Threads of the launcher's process (same participants, same protocol).
    Inproc,
}

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene_path: PathBuf,
    pub transport: TransportKind,
    /// Participants the launcher does not start: it waits for them to attach.
    pub external: Vec<Role>,
    /// Outputs go to `<out_root>/<scene name>/<run id>/`.
    pub out_root: PathBuf,
    /// Live progress on stderr.
    pub progress: bool,
    /// `--set key=value` overrides of the scene (applied before validation).
    pub overrides: Vec<String>,
    /// Say on stderr what the run is (id, output directory, participants) and how it ended.
    pub announce: bool,
    /// Start the zenoh bridge with these flags.
    pub bridge: Option<BridgeArgs>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Completed,
    Failed,
    Interrupted,
    /// Ended early by a `stop` control command (from the bridge).
    Stopped,
}

impl Status {
    pub fn exit_code(self) -> u8 {
        match self {
            Status::Completed | Status::Stopped => 0,
            Status::Failed => 1,
            Status::Interrupted => 130,
        }
    }
    fn as_str(self) -> &'static str {
        match self {
            Status::Completed => "completed",
            Status::Failed => "failed",
            Status::Interrupted => "interrupted",
            Status::Stopped => "stopped",
        }
    }
}

#[derive(Clone, Debug)]
pub struct RunOutcome {
    pub run_id: String,
    pub dir: PathBuf,
    pub status: Status,
    pub message: String,
    pub steps_done: u64,
    /// Wall time from the release of the participants to the last metrics row.
    pub stepping: Duration,
}

/// Bad input to `grains run` (exit code 2), apart from scene errors.
#[derive(Debug)]
pub struct BadInput(pub String);

/// What the solvers need of a physics scene, checked before anything starts: the participants
/// this build can run, then each solver's own checks (time steps against their limits).
pub fn check_physics(scene: &Scene) -> anyhow::Result<()> {
    let roles = scene.participants();
    match roles.as_slice() {
        [Role::Dem] => grains_dem_service::check_scene(scene)?,
        [Role::Mpm] => grains_mpm_service::check_scene(scene)?,
        [Role::Dem, Role::Mpm, Role::Coupler, Role::Oracle] => {
            grains_dem_service::check_scene(scene)?;
            grains_mpm_service::check_scene(scene)?;
            grains_oracle_service::check_scene(scene)?;
        }
        _ => {
            let list: Vec<_> = roles.iter().map(|r| r.name()).collect();
            bail!(BadInput(format!(
                "{}: this scene needs {}; this build runs DEM-only, MPM-only and hybrid scenes",
                scene.path.display(),
                list.join(", ")
            )));
        }
    }
    Ok(())
}

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

/// A new run id: UTC date and time plus 16 random bits, e.g. `20261122-013502-9f3a`.
pub fn new_run_id() -> String {
    let now = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    let secs = now.as_secs();
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let noise = (now.subsec_nanos() as u64 ^ ((std::process::id() as u64) << 20)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 48;
    format!(
        "{year:04}{month:02}{day:02}-{:02}{:02}{:02}-{noise:04x}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// Runs a scene to the end (or to a failure or Ctrl-C) and writes its outputs.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunOutcome> {
    let (scene, text) = scene::load_with_overrides(&opts.scene_path, &opts.overrides)?;
    // Participants read the run's copy of the scene: packing and bridge settings files must
    // not depend on where that copy lies, so their paths become absolute there.
    let bridge_settings = scene.bridge.as_ref().and_then(|b| b.settings.as_ref());
    let (scene, text) = if scene.bodies.iter().any(|b| b.packing.is_some()) || bridge_settings.is_some() {
        let mut overrides = opts.overrides.clone();
        let absolute = |p: &Path| std::fs::canonicalize(p).with_context(|| format!("resolving {}", p.display()));
        for (k, b) in scene.bodies.iter().enumerate() {
            if let Some(p) = &b.packing {
                overrides.push(format!("body.{k}.packing={:?}", absolute(p)?.display().to_string()));
            }
        }
        if let Some(p) = bridge_settings {
            overrides.push(format!("bridge.settings={:?}", absolute(p)?.display().to_string()));
        }
        scene::load_with_overrides(&opts.scene_path, &overrides)?
    } else {
        (scene, text)
    };
    let roles = scene.participants();
    if scene.synthetic.is_none() {
        check_physics(&scene)?;
    }
    for e in &opts.external {
        if !roles.contains(e) {
            let list: Vec<_> = roles.iter().map(|r| r.name()).collect();
            bail!(BadInput(format!(
                "--external {e}: the scene has no {e} participant (it runs: {})",
                list.join(", ")
            )));
        }
    }
    if opts.transport == TransportKind::Inproc && !opts.external.is_empty() {
        bail!(BadInput(
            "--external needs --transport ipc: an external participant is another process".into()
        ));
    }
    // The bridge: asked for on the command line, or by the scene's [bridge] table.
    // The scene's settings file is the base; flags on the command line override it.
    let bridge_args = match (&opts.bridge, &scene.bridge) {
        (Some(args), b) => Some(BridgeArgs {
            config: args.config.clone().or_else(|| b.as_ref().and_then(|b| b.settings.clone())),
            ..args.clone()
        }),
        (None, Some(b)) => Some(BridgeArgs {
            config: b.settings.clone(),
            ..BridgeArgs::default()
        }),
        (None, None) => None,
    };
    let bridge_cfg = match &bridge_args {
        Some(args) => Some(args.resolve().map_err(|e| BadInput(format!("{e:#}")))?),
        None => None,
    };
    // A launcher killed outright (SIGKILL) leaves its run's files in /dev/shm.
    for (dead, files) in ipc::remove_dead_runs() {
        if opts.announce {
            eprintln!("grains: removed {} files left by run {dead}, whose processes are all gone", files.len());
        }
    }
    let run_id = new_run_id();
    let dir = opts.out_root.join(&scene.name).join(&run_id);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating the output directory {}", dir.display()))?;
    // The exact scene of the run (overrides applied) sits beside its outputs; every
    // participant reads this copy.
    let scene_copy = dir.join("scene.toml");
    write_atomic(&scene_copy, text.as_bytes()).with_context(|| format!("writing {}", scene_copy.display()))?;
    let scene_path = std::fs::canonicalize(&scene_copy).with_context(|| format!("resolving {}", scene_copy.display()))?;

    let started = SystemTime::now();
    let ctx = RunCtx {
        scene: &scene,
        scene_path: &scene_path,
        roles: &roles,
        run_id: &run_id,
        dir: &dir,
        opts,
    };
    let (report, participants) = match opts.transport {
        TransportKind::Ipc => {
            let transport = ipc::Iceoryx2::join(&run_id, Role::Launcher.binary(), StopFlag::with_signals().as_cancel())?;
            let external_timeout = if opts.external.is_empty() { 60.0 } else { 0.0 };
            let spawned: Vec<Role> = roles.iter().copied().filter(|r| !opts.external.contains(r)).collect();
            let bridge = || match &bridge_args {
                Some(args) => Bridge::spawn_process(args, &scene, &scene_path, &run_id, &dir).map(Some),
                None => Ok(None),
            };
            let result = supervise(&transport, &ctx, bridge, || {
                Ok(Box::new(Processes::spawn(&spawned, &scene_path, &run_id, &dir, external_timeout)?) as Box<dyn Participants>)
            });
            drop(transport);
            ipc::remove_run_files(&run_id);
            result?
        }
        TransportKind::Inproc => {
            let bus = InProc::new();
            let bridge = || match &bridge_cfg {
                Some(cfg) => Bridge::spawn_thread(cfg, &bus, &scene, &run_id, &dir).map(Some),
                None => Ok(None),
            };
            supervise(&bus, &ctx, bridge, || {
                Ok(Box::new(Threads::spawn(&roles, &scene, &run_id, &dir, &bus)?) as Box<dyn Participants>)
            })?
        }
    };
    write_summary(&ctx, &report, participants, started)?;
    Ok(report)
}

struct RunCtx<'a> {
    scene: &'a Scene,
    scene_path: &'a Path,
    roles: &'a [Role],
    run_id: &'a str,
    dir: &'a Path,
    opts: &'a RunOptions,
}

/// What the launcher learned about the participants, for `summary.json`.
#[derive(Default)]
struct Roster {
    admitted: BTreeMap<Role, u32>,
    ready: BTreeSet<Role>,
    exits: BTreeMap<Role, String>,
}

const WAIT: Duration = Duration::from_millis(50);

fn supervise<T: Transport>(
    t: &T,
    ctx: &RunCtx,
    start_bridge: impl FnOnce() -> anyhow::Result<Option<Bridge>>,
    start: impl FnOnce() -> anyhow::Result<Box<dyn Participants>>,
) -> anyhow::Result<(RunOutcome, serde_json::Value)> {
    let scene = ctx.scene;
    // Every service the launcher reads or writes exists before any participant starts.
    let mut hello_sub = t.subscriber::<Hello, ()>(&names::HELLO)?;
    let mut welcome_pub = t.publisher::<Welcome, ()>(&names::WELCOME, 1)?;
    let mut summary_sub = t.subscriber::<Summary, StepHeader>(&names::SUMMARY)?;
    let mut control_pub = t.publisher::<Control, StepHeader>(&names::CONTROL, 1)?;
    let mut ack_sub = t.subscriber::<Ack, StepHeader>(&names::ACK)?;
    let mut metrics = Metrics::create(ctx.dir, ctx.roles).with_context(|| format!("creating metrics in {}", ctx.dir.display()))?;
    let stop = StopFlag::with_signals();
    let mut bridge = start_bridge()?;
    let mut parts = match start() {
        Ok(p) => p,
        Err(e) => {
            if let Some(b) = &mut bridge {
                b.stop(Duration::from_secs(1));
            }
            return Err(e);
        }
    };

    let how = match ctx.opts.transport {
        TransportKind::Ipc => "processes",
        TransportKind::Inproc => "threads",
    };
    let pids: Vec<String> = parts.pids().iter().map(|(r, p)| format!("{} (pid {p})", r.binary())).collect();
    if ctx.opts.announce {
        eprintln!(
            "grains: run {} of scene {} ({} steps), output in {}",
            ctx.run_id,
            scene.name,
            scene.steps,
            ctx.dir.display()
        );
    }
    if ctx.opts.announce && !pids.is_empty() {
        eprintln!("grains: started as {how}: {}", pids.join(", "));
    }
    if ctx.opts.announce
        && let Some(b) = &bridge
    {
        let pid = b.pid().map_or_else(|| "(thread)".to_string(), |p| format!("(pid {p})"));
        eprintln!(
            "grains: started the bridge: {} {pid}; its settings: {}",
            Role::Bridge.binary(),
            ctx.dir.join("bridge.json").display()
        );
    }
    for e in &ctx.opts.external {
        eprintln!(
            "grains: waiting for an external {e} to attach; start it with:\n  {} --scene {} --run-id {}",
            e.binary(),
            ctx.scene_path.display(),
            ctx.run_id
        );
    }

    let mut roster = Roster::default();
    let mut failure: Option<String> = None;
    let mut interrupted = false;
    let mut stop_sent: Option<Instant> = None;
    let mut release: Option<Instant> = None;
    // Step after which a control command (from the bridge) stopped the run, and whether one
    // holds it paused.
    let mut stopped_at: Option<u64> = None;
    let mut paused = false;
    let mut last_dead_check = Instant::now();
    let mut progress = Progress::new(ctx.opts.progress, scene.steps);
    let n_spawned = parts.pids().len();

    loop {
        // Admission: answer every hello at once; release everyone when all are ready.
        while let Some(hello) = hello_sub.receive(Duration::ZERO, |_, h| h.first().copied())? {
            let Some(hello) = hello else { continue };
            if let Some(answer) = admit(&hello, ctx, &mut roster) {
                welcome_pub.publish(1, |_, out| out[0] = answer)?;
            }
        }
        if release.is_none() && roster.ready.len() == ctx.roles.len() {
            let start = Welcome {
                magic: HELLO_MAGIC,
                scene_hash: scene.hash,
                protocol_version: PROTOCOL_VERSION,
                role: 0,
                pid: 0,
                verdict: Verdict::Start as u32,
                run_id: run_id_bytes(ctx.run_id),
            };
            welcome_pub.publish(1, |_, out| out[0] = start)?;
            metrics.start_clock();
            release = Some(Instant::now());
        }

        // Summaries: block on the event up to WAIT, then drain.
        let mut timeout = WAIT;
        while let Some(s) = summary_sub.receive(timeout, |_, s| s.first().copied())? {
            timeout = Duration::ZERO;
            let Some(s) = s else { continue };
            if s.status != 0 && failure.is_none() {
                failure = Some(format!(
                    "{} reported a failure at step {}",
                    Role::from_code(s.role).map_or("a participant", |r| r.binary()),
                    s.step
                ));
            }
            if let Err(e) = metrics.add(&s) {
                failure.get_or_insert(e);
            }
        }
        progress.show(metrics.last, release);

        // Acknowledged commands: what the time owner did, said once on stderr.
        follow_acks(&mut ack_sub, ctx.opts.announce && !interrupted, &mut stopped_at, &mut paused)?;
        if let Some(b) = &mut bridge
            && let Some(how) = b.poll()
        {
            eprintln!("\ngrains: warning: the bridge {how}; the run goes on without remote access");
            bridge = None;
            // Nobody could resume a run paused from outside: it goes on.
            if paused {
                eprintln!("grains: the run was paused from outside: resuming it");
                send_control(&mut control_pub, ctx.run_id, Command::Resume)?;
            }
        }

        // Supervision: our children, then dead nodes (external participants too).
        for exit in parts.poll_exits() {
            let pid = parts.pids().iter().find(|(r, _)| *r == exit.role).map_or(0, |(_, p)| *p);
            roster.exits.insert(exit.role, exit.how.clone());
            if !exit.ok && failure.is_none() && !interrupted {
                failure = Some(format!("participant {} (pid {pid}) {}", exit.role.binary(), exit.how));
            }
        }
        if last_dead_check.elapsed() > Duration::from_millis(300) {
            last_dead_check = Instant::now();
            // The bridge is our child: its end is seen above.
            let dead: Vec<_> = t
                .dead_peers()
                .into_iter()
                .filter(|d| !d.starts_with(Role::Bridge.binary()))
                .collect();
            if !dead.is_empty() && failure.is_none() && !interrupted {
                failure = Some(format!("participant {} died", dead.join(", ")));
            }
        }

        // Ctrl-C / SIGTERM: stop at a step boundary; force after 3 s or before the start.
        if stop.is_set() && !interrupted {
            interrupted = true;
            eprintln!("\ngrains: stopping the run (interrupt); outputs are being written");
            if release.is_some()
                && !ctx
                    .roles
                    .iter()
                    .any(|r| ctx.opts.external.contains(r) && *r == scene.time_owner() && !roster.ready.contains(r))
            {
                send_control(&mut control_pub, ctx.run_id, Command::Stop)?;
                stop_sent = Some(Instant::now());
            } else {
                parts.terminate(Duration::from_secs(1));
                break;
            }
        }
        if stop_sent.is_some_and(|t| t.elapsed() > Duration::from_secs(3)) {
            parts.terminate(Duration::from_secs(1));
            break;
        }

        if let Some(f) = &failure {
            eprintln!("\ngrains: error: {f}; stopping the other participants");
            parts.terminate(Duration::from_secs(1));
            break;
        }
        let complete = metrics.last.is_some_and(|(s, _)| s == scene.steps);
        if parts.all_ended() && (n_spawned > 0 || complete) {
            // Summaries and acknowledgements sent just before the last exit are still queued.
            while let Some(s) = summary_sub.receive(WAIT, |_, s| s.first().copied())? {
                if let Some(s) = s
                    && let Err(e) = metrics.add(&s)
                {
                    failure.get_or_insert(e);
                }
            }
            follow_acks(&mut ack_sub, ctx.opts.announce && !interrupted, &mut stopped_at, &mut paused)?;
            break;
        }
    }
    if ctx.opts.announce {
        progress.finish(metrics.last, release);
    }
    if let Some(b) = &mut bridge {
        b.stop(Duration::from_secs(2));
    }

    let steps_done = metrics.last.map_or(0, |(s, _)| s);
    let stepping = release.map_or(Duration::ZERO, |r| r.elapsed());
    metrics
        .finish()
        .with_context(|| format!("finishing metrics in {}", ctx.dir.display()))?;
    let (status, message) = if let Some(f) = failure {
        (Status::Failed, f)
    } else if interrupted {
        (Status::Interrupted, format!("interrupted after step {steps_done}"))
    } else if let Some(at) = stopped_at {
        (Status::Stopped, format!("stopped by a control command after step {at}"))
    } else if steps_done < scene.steps {
        (
            Status::Failed,
            format!("the participants ended after step {steps_done} of {}", scene.steps),
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
    Ok((outcome, roster_json(&roster, &*parts, ctx)))
}

/// The launcher's command to the time owner (its sequence numbers are small).
fn send_control<P: Publisher<Control, StepHeader>>(control: &mut P, run_id: &str, command: Command) -> anyhow::Result<()> {
    let header = StepHeader {
        protocol_version: PROTOCOL_VERSION,
        sender: Role::Launcher as u32,
        run_id: run_id_bytes(run_id),
        ..StepHeader::default()
    };
    control.publish(1, |h, out| {
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

/// Applied control commands: said on stderr (if `announce`); a stop's step goes to
/// `stopped_at`, pause and resume to `paused`.
fn follow_acks<S: Subscriber<Ack, StepHeader>>(
    acks: &mut S,
    announce: bool,
    stopped_at: &mut Option<u64>,
    paused: &mut bool,
) -> anyhow::Result<()> {
    while let Some(Some(a)) = acks.receive(Duration::ZERO, |_, a| a.first().copied())? {
        let Some(c) = Command::from_code(a.command) else { continue };
        if a.status != AckStatus::Applied as u32 {
            continue;
        }
        match c {
            Command::Stop => *stopped_at = Some(a.step),
            Command::Pause => *paused = true,
            Command::Resume => *paused = false,
            Command::Snapshot | Command::Set => {}
        }
        if announce {
            let what = match c {
                Command::Pause => "paused by a control command",
                Command::Resume => "resumed by a control command",
                Command::Stop => "stopping on a control command",
                Command::Snapshot => "snapshot (frames) by a control command",
                Command::Set => "a parameter set by a control command",
            };
            eprintln!("\ngrains: {what} after step {}", a.step);
        }
    }
    Ok(())
}

fn roster_json(roster: &Roster, parts: &dyn Participants, ctx: &RunCtx) -> serde_json::Value {
    let spawned = parts.pids();
    let list: Vec<_> = ctx
        .roles
        .iter()
        .map(|r| {
            serde_json::json!({
                "role": r.name(),
                "binary": r.binary(),
                "pid": roster.admitted.get(r).copied().or_else(|| spawned.iter().find(|(x, _)| x == r).map(|(_, p)| *p)),
                "external": ctx.opts.external.contains(r),
                "exit": roster.exits.get(r),
            })
        })
        .collect();
    serde_json::Value::Array(list)
}

/// Decides on one hello; returns the answer to send (none for the "ready" hello).
fn admit(h: &Hello, ctx: &RunCtx, roster: &mut Roster) -> Option<Welcome> {
    if h.magic != HELLO_MAGIC {
        eprintln!("grains: ignored a hello without the grains magic (pid {})", h.pid);
        return None;
    }
    let role = Role::from_code(h.role);
    let who = role.map_or_else(|| format!("participant with role code {}", h.role), |r| r.binary().to_string());
    let verdict = if h.protocol_version != PROTOCOL_VERSION {
        eprintln!(
            "grains: refused {who} (pid {}): it speaks protocol version {}, this run speaks version {PROTOCOL_VERSION}",
            h.pid, h.protocol_version
        );
        Verdict::WrongProtocolVersion
    } else if h.scene_hash != ctx.scene.hash {
        eprintln!(
            "grains: refused {who} (pid {}): it loaded another scene file than {}",
            h.pid,
            ctx.scene_path.display()
        );
        Verdict::WrongScene
    } else if role.is_none_or(|r| !ctx.roles.contains(&r)) {
        eprintln!("grains: refused {who} (pid {}): the scene has no such participant", h.pid);
        Verdict::RoleNotInRun
    } else {
        let role = role.expect("checked above");
        match roster.admitted.get(&role) {
            Some(&pid) if pid != h.pid => {
                eprintln!("grains: refused {who} (pid {}): {who} (pid {pid}) has already joined", h.pid);
                Verdict::RoleTaken
            }
            _ if h.flags == HELLO_READY => {
                roster.ready.insert(role);
                return None;
            }
            _ => {
                if ctx.opts.external.contains(&role) {
                    eprintln!("grains: external {who} (pid {}) attached", h.pid);
                }
                roster.admitted.insert(role, h.pid);
                Verdict::Accepted
            }
        }
    };
    Some(Welcome {
        magic: HELLO_MAGIC,
        scene_hash: ctx.scene.hash,
        protocol_version: PROTOCOL_VERSION,
        role: h.role,
        pid: h.pid,
        verdict: verdict as u32,
        run_id: run_id_bytes(ctx.run_id),
    })
}

fn write_summary(ctx: &RunCtx, r: &RunOutcome, participants: serde_json::Value, started: SystemTime) -> anyhow::Result<()> {
    let wall = r.stepping.as_secs_f64();
    let json = serde_json::json!({
        "run_id": r.run_id,
        "scene": ctx.scene_path.display().to_string(),
        "scene_name": ctx.scene.name,
        "scene_hash": format!("{:016x}", ctx.scene.hash),
        "protocol_version": PROTOCOL_VERSION,
        "transport": match ctx.opts.transport { TransportKind::Ipc => "ipc", TransportKind::Inproc => "inproc" },
        "status": r.status.as_str(),
        "message": r.message,
        "steps_planned": ctx.scene.steps,
        "steps_completed": r.steps_done,
        "simulated_time": r.steps_done as f64 * ctx.scene.dt,
        "wall_time_s": wall,
        "steps_per_second": if wall > 0.0 { r.steps_done as f64 / wall } else { 0.0 },
        "started_unix_s": started.duration_since(SystemTime::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0),
        "participants": participants,
        "outputs": { "metrics": "metrics.csv" },
    });
    let text = serde_json::to_string_pretty(&json)? + "\n";
    write_atomic(&ctx.dir.join("summary.json"), text.as_bytes())
        .with_context(|| format!("writing {}", ctx.dir.join("summary.json").display()))
}

/// Live progress on stderr: a line rewritten in place on a terminal, a line every 10 s
/// otherwise.
struct Progress {
    enabled: bool,
    tty: bool,
    steps: u64,
    last: Instant,
}

impl Progress {
    fn new(enabled: bool, steps: u64) -> Self {
        // SAFETY: isatty on a standard file descriptor.
        let tty = unsafe { libc::isatty(2) } == 1;
        Progress {
            enabled,
            tty,
            steps,
            last: Instant::now(),
        }
    }

    fn line(&self, last: Option<(u64, f64)>, release: Option<Instant>) -> Option<String> {
        let (step, time) = last?;
        let elapsed = release?.elapsed().as_secs_f64();
        let rate = step as f64 / elapsed.max(1e-9);
        let eta = (self.steps - step) as f64 / rate.max(1e-9);
        Some(format!(
            "step {step}/{} ({:.0}%) | {rate:.0} steps/s | t = {time:.4e} s | elapsed {elapsed:.1} s | ETA {eta:.1} s",
            self.steps,
            100.0 * step as f64 / self.steps as f64
        ))
    }

    fn show(&mut self, last: Option<(u64, f64)>, release: Option<Instant>) {
        let every = if self.tty {
            Duration::from_millis(500)
        } else {
            Duration::from_secs(10)
        };
        if !self.enabled || self.last.elapsed() < every {
            return;
        }
        self.last = Instant::now();
        if let Some(line) = self.line(last, release) {
            if self.tty {
                eprint!("\r\x1b[2K{line}");
            } else {
                eprintln!("{line}");
            }
        }
    }

    fn finish(&mut self, last: Option<(u64, f64)>, release: Option<Instant>) {
        if let Some(line) = self.line(last, release) {
            if self.tty && self.enabled {
                eprint!("\r\x1b[2K");
            }
            eprintln!("grains: {line}");
        }
    }
}
