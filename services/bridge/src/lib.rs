//! The zenoh bridge of a run: the only door to a run from outside.
//!
//! Out: the participants' summaries, gathered per macro-step, on `grains/<run>/state/summary`
//! (at most `rate` per second), the solvers' decimated views on `grains/<run>/state/view/<role>`
//! (a few per second; both dropped rather than queued for slow clients), the latest of each
//! under the queryable `grains/<run>/state/**`, and liveliness tokens
//! `grains/<run>/alive/<bridge|dem|mpm|…>`. In: commands as queries on `grains/<run>/control`
//! (only with steering on), checked ([`command`]), sent to the time owner over the control
//! service and answered with its acknowledgement: the step at which the command took effect,
//! or why it was refused. A query is never dropped: every command that reaches the bridge gets
//! an answer (zenoh's access control drops a reader's command before it does).
//!
//! The bridge is expendable: it is not admitted to the run, the run does not wait for it, and
//! if it dies the run goes on. It never blocks the participants: it drains their summaries
//! every 20 ms whatever its clients do.

pub mod client;
pub mod command;
pub mod config;
pub mod state;
pub mod view;

use anyhow::Context;
use config::{BridgeConfig, keys};
use grains_protocol::wire::{Ack, AckStatus, Command, Control, StepHeader, Summary, ViewPoint};
use grains_protocol::{PROTOCOL_VERSION, Role, names, run_id_bytes, scene::Scene};
use grains_service::signals::StopFlag;
use grains_transport::{Publisher, Subscriber, Transport};
use std::collections::HashMap;
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::query::Query;

/// How long a command waits for the time owner's acknowledgement.
pub const ACK_TIMEOUT: Duration = Duration::from_secs(5);
/// Sequence numbers of the bridge's commands start here (the launcher's are small).
const SEQ_BASE: u64 = 1 << 32;
/// Commands waiting for their acknowledgement at most: with fewer than the control and ack
/// services hold (16 each), neither the bridge nor the time owner can wait on the other.
pub const MAX_IN_FLIGHT: usize = 8;

enum Incoming {
    State(Query),
    Control(Query),
}

/// Serves run `run` until `stop` trips. `out_dir`, if given, receives `bridge.json` (the
/// effective settings).
///
/// This thread only talks to the run (iceoryx2) and never waits on a client: everything that
/// goes out over zenoh is handed to an outbox thread, which sends the latest summary and view
/// of each solver (older ones are skipped if it falls behind) and every reply.
pub fn serve<T: Transport>(
    t: &T,
    cfg: &BridgeConfig,
    run: &str,
    scene: &Scene,
    out_dir: Option<&Path>,
    stop: &StopFlag,
) -> anyhow::Result<()> {
    cfg.check()?;
    let mut ports = Ports::open(t, cfg, scene)?;
    let effective = cfg.effective(run);
    tracing::info!("run {run}: {effective}");
    if let Some(dir) = out_dir {
        let text = serde_json::to_string_pretty(&effective)? + "\n";
        std::fs::write(dir.join("bridge.json"), text).with_context(|| format!("writing {}", dir.join("bridge.json").display()))?;
    }
    let session = zenoh::open(cfg.zenoh(run)?)
        .wait()
        .map_err(|e| anyhow::anyhow!("grains-bridge: cannot open zenoh on {:?}: {e}", cfg.listen))?;
    let _viewer = match &cfg.view {
        Some(v) => {
            let viewer = view::start(cfg, v, run)?;
            tracing::info!("the live viewer of run {run}: {}", viewer.url);
            Some(viewer)
        }
        None => None,
    };
    let (tx, rx) = mpsc::channel();
    let _state_q = queryable(&session, keys::state_all(run), tx.clone(), Incoming::State)?;
    let _control_q = queryable(&session, keys::control(run), tx, Incoming::Control)?;
    let view_roles: Vec<Role> = ports.views.iter().map(|(r, _)| *r).collect();
    let outbox = Outbox::open(&session, run, &view_roles)?;
    let (out_tx, out_rx) = mpsc::channel::<Out>();
    let sender = std::thread::spawn(move || outbox.run(out_rx));
    let served = (|| -> anyhow::Result<()> {
        let mut bridge = Bridge::new(&mut ports, cfg, run, scene, effective, Outgoing(out_tx));
        while !stop.is_set() {
            let turn = Instant::now();
            bridge.take_summaries()?;
            bridge.take_views()?;
            bridge.take_acks()?;
            while let Ok(incoming) = rx.try_recv() {
                match incoming {
                    Incoming::State(q) => bridge.answer_state(q),
                    Incoming::Control(q) => bridge.forward_command(q)?,
                }
            }
            bridge.publish_summary();
            if bridge.run_has_ended(t) {
                break;
            }
            std::thread::sleep(names::SUMMARY_READ_TURN.saturating_sub(turn.elapsed()));
        }
        bridge.shut_down()
    })();
    // What is left goes out, and the session closes, unless a client that does not read holds
    // them up: zenoh would wait for its socket for seconds (10 s to close), and the launcher
    // for the bridge. The process ends anyway, and the client's link with it.
    if !finished_within(&sender, SHUTDOWN_WAIT) {
        tracing::warn!(
            "replies or state left unsent after {} ms: a client does not read",
            SHUTDOWN_WAIT.as_millis()
        );
    } else if sender.join().is_err() {
        anyhow::bail!("the bridge's outbox thread panicked");
    }
    let closing = session.clone();
    let closer = std::thread::spawn(move || closing.close().wait());
    if !finished_within(&closer, SHUTDOWN_WAIT) {
        tracing::warn!(
            "zenoh session not closed within {} ms: a client does not read",
            SHUTDOWN_WAIT.as_millis()
        );
    }
    served
}

/// How long the bridge, on its way out, waits for zenoh to send and to close.
const SHUTDOWN_WAIT: Duration = Duration::from_millis(300);

/// Whether thread `h` ended within `wait`.
fn finished_within<R>(h: &std::thread::JoinHandle<R>, wait: Duration) -> bool {
    let deadline = Instant::now() + wait;
    while !h.is_finished() {
        if Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    true
}

/// A queryable on `key` that hands every query to `tx`, as `incoming` makes it.
fn queryable(
    session: &zenoh::Session,
    key: String,
    tx: mpsc::Sender<Incoming>,
    incoming: fn(Query) -> Incoming,
) -> anyhow::Result<zenoh::query::Queryable<()>> {
    session
        .declare_queryable(key.clone())
        .callback(move |q| {
            let _ = tx.send(incoming(q));
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("declaring {key}: {e}"))
}

/// The bridge's ports on the run. (Fields in the reverse of the order they are opened in:
/// they close in the order they did as locals of [`serve`].)
struct Ports<T: Transport> {
    /// The views of the solvers of this run (a DEM-only run has no MPM view).
    views: Vec<(Role, T::Subscriber<ViewPoint, StepHeader>)>,
    /// No control port at all unless steering is on.
    control: Option<T::Publisher<Control, StepHeader>>,
    acks: T::Subscriber<Ack, StepHeader>,
    summaries: T::Subscriber<Summary, StepHeader>,
}

impl<T: Transport> Ports<T> {
    fn open(t: &T, cfg: &BridgeConfig, scene: &Scene) -> anyhow::Result<Self> {
        let summaries = t.subscriber::<Summary, StepHeader>(&names::SUMMARY)?;
        let acks = t.subscriber::<Ack, StepHeader>(&names::ACK)?;
        let control = match cfg.steering {
            true => Some(t.publisher::<Control, StepHeader>(&names::CONTROL, 1)?),
            false => None,
        };
        let roles = scene.participants();
        let mut views = Vec::new();
        for (role, spec) in [(Role::Dem, names::DEM_VIEW), (Role::Mpm, names::MPM_VIEW)] {
            if roles.contains(&role) {
                views.push((role, t.subscriber::<ViewPoint, StepHeader>(&spec)?));
            }
        }
        Ok(Ports {
            views,
            control,
            acks,
            summaries,
        })
    }
}

/// The bridge's end of the channel to the outbox thread.
struct Outgoing(mpsc::Sender<Out>);

impl Outgoing {
    /// Hands `o` to the outbox (gone only when the bridge stops: then nothing goes out).
    fn send(&self, o: Out) {
        let _ = self.0.send(o);
    }
}

/// What the bridge knows of the run while it serves it, and the commands it waits on.
struct Bridge<'a, T: Transport> {
    ports: &'a mut Ports<T>,
    run: &'a str,
    scene: &'a Scene,
    /// The effective settings (answered under `state/config`).
    effective: serde_json::Value,
    out: Outgoing,
    /// Participants whose liveliness token is declared.
    alive: Vec<Role>,
    latest_views: HashMap<Role, serde_json::Value>,
    gather: state::Gather,
    paused: bool,
    /// Sequence number of the last command sent.
    seq: u64,
    pending: Pending,
    /// The last summary published: its step, when, and the pause state it showed.
    published: Option<(u64, Instant, bool)>,
    last_dead_check: Instant,
    /// Between two summaries at least (from `rate`).
    min_interval: Duration,
}

impl<'a, T: Transport> Bridge<'a, T> {
    fn new(
        ports: &'a mut Ports<T>,
        cfg: &BridgeConfig,
        run: &'a str,
        scene: &'a Scene,
        effective: serde_json::Value,
        out: Outgoing,
    ) -> Self {
        Bridge {
            ports,
            run,
            scene,
            effective,
            out,
            alive: Vec::new(),
            latest_views: HashMap::new(),
            gather: state::Gather::new(&scene.participants()),
            paused: false,
            seq: SEQ_BASE,
            pending: Pending::new(),
            published: None,
            last_dead_check: Instant::now(),
            min_interval: if cfg.rate > 0.0 {
                Duration::from_secs_f64(1.0 / cfg.rate)
            } else {
                Duration::ZERO
            },
        }
    }

    /// The summary document of the latest complete step, if there is one.
    fn document(&self) -> Option<serde_json::Value> {
        self.gather.document(self.run, &self.scene.name, self.scene.steps, self.paused)
    }

    /// Summaries: waits up to 20 ms for one, then drains them. A participant's first summary
    /// declares its liveliness token.
    fn take_summaries(&mut self) -> anyhow::Result<()> {
        let mut timeout = Duration::from_millis(20);
        while let Some(s) = self.ports.summaries.receive(timeout, |_, s| s.first().copied())? {
            timeout = Duration::ZERO;
            let Some(s) = s else { continue };
            if let Some(role) = Role::from_code(s.role)
                && !self.alive.contains(&role)
            {
                self.alive.push(role);
                self.out.send(Out::Alive(role, true));
            }
            self.gather.add(s);
        }
        Ok(())
    }

    /// Views: the latest of each solver.
    fn take_views(&mut self) -> anyhow::Result<()> {
        let run = self.run;
        for (role, sub) in &mut self.ports.views {
            while let Some(v) = sub.receive(Duration::ZERO, |h, pts| state::view_document(run, *role, h, pts))? {
                self.out.send(Out::View(*role, v.to_string()));
                self.latest_views.insert(*role, v);
            }
        }
        Ok(())
    }

    /// Acknowledgements of our commands (and the launcher's: they change the pause state);
    /// the commands that waited for theirs longer than [`ACK_TIMEOUT`] are answered with an
    /// error.
    fn take_acks(&mut self) -> anyhow::Result<()> {
        let out = &self.out;
        drain_acks(&mut self.ports.acks, &mut self.pending, &mut self.paused, &|o| out.send(o))?;
        let now = Instant::now();
        self.pending.retain(|_, (q, c, since)| {
            let expired = now.duration_since(*since) > ACK_TIMEOUT;
            if expired {
                let why = format!(
                    "{}: not acknowledged by the time owner within {} s: it may still take effect (a long step), or the run has ended",
                    c.command.name(),
                    ACK_TIMEOUT.as_secs()
                );
                out.send(Out::Error(q.clone(), error_json(&why)));
            }
            !expired
        });
        Ok(())
    }

    /// A client's query of the state: the summary, the settings and the latest views, those
    /// of them its key expression covers.
    fn answer_state(&self, q: Query) {
        let run = self.run;
        let mut answers = vec![
            (keys::summary(run), self.document()),
            (keys::config(run), Some(self.effective.clone())),
        ];
        answers.extend(
            self.latest_views
                .iter()
                .map(|(role, v)| (keys::view(run, role.name()), Some(v.clone()))),
        );
        for (key, value) in answers {
            let Some(value) = value else { continue };
            if let Ok(k) = zenoh::key_expr::KeyExpr::try_from(key.as_str())
                && q.key_expr().intersects(&k)
            {
                self.out.send(Out::Reply(q.clone(), key, value.to_string()));
            }
        }
    }

    /// A client's command: refused without steering, when too many wait already, or when
    /// [`command::parse`] refuses it; else sent to the time owner, answered when it
    /// acknowledges.
    fn forward_command(&mut self, q: Query) -> anyhow::Result<()> {
        let payload = q.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
        let Some(control) = self.ports.control.as_mut() else {
            let why = "steering is disabled for this run: every command is refused (start it with grains run --bridge --steering)";
            self.out.send(Out::Error(q, error_json(why)));
            return Ok(());
        };
        if self.pending.len() >= MAX_IN_FLIGHT {
            let why = format!("busy: {MAX_IN_FLIGHT} commands are waiting for the run's acknowledgement; retry");
            self.out.send(Out::Error(q, error_json(&why)));
            return Ok(());
        }
        match command::parse(&payload, self.scene.walls.len()) {
            Err(why) => self.out.send(Out::Error(q, error_json(&why))),
            Ok(c) => {
                self.seq += 1;
                let header = StepHeader {
                    protocol_version: PROTOCOL_VERSION,
                    sender: Role::Bridge as u32,
                    step: self.gather.latest_step().unwrap_or(0),
                    run_id: run_id_bytes(self.run),
                    ..StepHeader::default()
                };
                let msg = Control {
                    seq: self.seq,
                    command: c.command as u32,
                    key: c.key,
                    value: c.value,
                };
                control.publish(1, |h, out| {
                    *h = header;
                    out[0] = msg;
                })?;
                self.pending.insert(self.seq, (q, c, Instant::now()));
            }
        }
        Ok(())
    }

    /// The latest complete step, at most `rate` times a second, and at once when the run
    /// pauses or resumes (no new step says so).
    fn publish_summary(&mut self) {
        if let Some(step) = self.gather.latest_step()
            && self
                .published
                .is_none_or(|(s, at, p)| (s < step && at.elapsed() >= self.min_interval) || p != self.paused)
            && let Some(d) = self.document()
        {
            self.out.send(Out::Summary(d.to_string()));
            self.published = Some((step, Instant::now(), self.paused));
        }
    }

    /// Every 500 ms: participants that died lose their token; once every participant has
    /// gone, the run is over and so is the bridge (one started by hand is not told).
    fn run_has_ended(&mut self, t: &T) -> bool {
        if self.last_dead_check.elapsed() > Duration::from_millis(500) {
            self.last_dead_check = Instant::now();
            if self.gather.latest_step().is_some() && self.ports.summaries.publisher_count() == 0 {
                tracing::info!("run {} has ended", self.run);
                return true;
            }
            for dead in t.dead_peers(&|_| false) {
                self.alive.retain(|role| {
                    let gone = dead.starts_with(&format!("{} ", role.binary()));
                    if gone {
                        self.out.send(Out::Alive(*role, false));
                    }
                    !gone
                });
            }
        }
        false
    }

    /// On the way out: a stop's acknowledgement is sent just before the run ends, which is
    /// when we are told to stop: it is still queued. Every command still waiting is answered;
    /// then the channel to the outbox closes.
    fn shut_down(mut self) -> anyhow::Result<()> {
        let out = &self.out;
        drain_acks(&mut self.ports.acks, &mut self.pending, &mut self.paused, &|o| out.send(o))?;
        for (q, c, _) in self.pending.into_values() {
            self.out.send(Out::Error(
                q,
                error_json(&format!("{}: the bridge is shutting down", c.command.name())),
            ));
        }
        Ok(())
    }
}

/// What goes out over zenoh.
enum Out {
    Summary(String),
    View(Role, String),
    Reply(Query, String, String),
    Error(Query, String),
    /// A participant's liveliness token: declare (true) or drop (false).
    Alive(Role, bool),
}

/// The zenoh side of the bridge: publishers and tokens, fed by [`Out`] messages.
struct Outbox {
    session: zenoh::Session,
    run: String,
    summary: zenoh::pubsub::Publisher<'static>,
    views: HashMap<Role, zenoh::pubsub::Publisher<'static>>,
    _bridge_token: zenoh::liveliness::LivelinessToken,
}

impl Outbox {
    fn open(session: &zenoh::Session, run: &str, view_roles: &[Role]) -> anyhow::Result<Self> {
        let publisher = |key: String| {
            session
                .declare_publisher(key.clone())
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .wait()
                .map_err(|e| anyhow::anyhow!("declaring {key}: {e}"))
        };
        let mut views = HashMap::new();
        for role in view_roles {
            views.insert(*role, publisher(keys::view(run, role.name()))?);
        }
        let token = session
            .liveliness()
            .declare_token(keys::alive(run, "bridge"))
            .wait()
            .map_err(|e| anyhow::anyhow!("declaring {}: {e}", keys::alive(run, "bridge")))?;
        Ok(Outbox {
            session: session.clone(),
            run: run.to_string(),
            summary: publisher(keys::summary(run))?,
            views,
            _bridge_token: token,
        })
    }

    /// Sends until the channel closes. Of the summaries and views queued meanwhile only the
    /// latest of each goes out; every reply goes out, in order.
    fn run(self, rx: mpsc::Receiver<Out>) {
        let mut tokens: HashMap<Role, zenoh::liveliness::LivelinessToken> = HashMap::new();
        while let Ok(first) = rx.recv() {
            let mut summary = None;
            let mut views: HashMap<Role, String> = HashMap::new();
            for o in std::iter::once(first).chain(rx.try_iter()) {
                match o {
                    Out::Summary(s) => summary = Some(s),
                    Out::View(role, v) => {
                        views.insert(role, v);
                    }
                    Out::Reply(q, key, body) => {
                        let _ = q.reply(key, body).wait();
                    }
                    Out::Error(q, body) => {
                        let _ = q.reply_err(body).wait();
                    }
                    Out::Alive(role, true) => {
                        if let Ok(t) = self.session.liveliness().declare_token(keys::alive(&self.run, role.name())).wait() {
                            tokens.insert(role, t);
                        }
                    }
                    Out::Alive(role, false) => {
                        tokens.remove(&role);
                    }
                }
            }
            if let Some(s) = summary {
                let _ = self.summary.put(s).wait();
            }
            for (role, v) in views {
                if let Some(p) = self.views.get(&role) {
                    let _ = p.put(v).wait();
                }
            }
        }
    }
}

type Pending = HashMap<u64, (Query, command::Checked, Instant)>;

/// Answers the pending commands whose acknowledgement arrived; follows the pause state.
fn drain_acks<S: Subscriber<Ack, StepHeader>>(
    acks: &mut S,
    pending: &mut Pending,
    paused: &mut bool,
    out: &impl Fn(Out),
) -> anyhow::Result<()> {
    while let Some(Some(a)) = acks.receive(Duration::ZERO, |_, a| a.first().copied())? {
        if a.status == AckStatus::Applied as u32 {
            match Command::from_code(a.command) {
                Some(Command::Pause) => *paused = true,
                Some(Command::Resume) => *paused = false,
                _ => {}
            }
        }
        if let Some((q, c, _)) = pending.remove(&a.seq) {
            out(answer_ack(q, &c, &a));
        }
    }
    Ok(())
}

fn error_json(why: &str) -> String {
    serde_json::json!({ "ok": false, "error": why }).to_string()
}

/// The answer to a command query from the time owner's acknowledgement.
fn answer_ack(q: Query, c: &command::Checked, a: &Ack) -> Out {
    if a.status == AckStatus::Applied as u32 {
        let body = serde_json::json!({ "ok": true, "command": c.command.name(), "step": a.step, "seq": a.seq });
        let key = q.key_expr().to_string();
        return Out::Reply(q, key, body.to_string());
    }
    let why = match AckStatus::from_code(a.status) {
        Some(AckStatus::Unsupported) => format!(
            "{}: refused by the run at step {}: its solvers cannot carry it out (a parameter of an axis the run does not have, or no output directory for a snapshot)",
            c.command.name(),
            a.step
        ),
        Some(AckStatus::Busy) => format!(
            "{}: refused at step {}: too many commands at once; retry after the next step",
            c.command.name(),
            a.step
        ),
        _ => format!(
            "{}: refused by the time owner at step {} (status {})",
            c.command.name(),
            a.step,
            a.status
        ),
    };
    Out::Error(q, error_json(&why))
}
