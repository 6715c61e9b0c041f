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
    let mut summaries = t.subscriber::<Summary, StepHeader>(&names::SUMMARY)?;
    let mut acks = t.subscriber::<Ack, StepHeader>(&names::ACK)?;
    // No control port at all unless steering is on.
    let mut control = match cfg.steering {
        true => Some(t.publisher::<Control, StepHeader>(&names::CONTROL, 1)?),
        false => None,
    };
    // Views of the solvers of this run (a DEM-only run has no MPM view).
    let roles = scene.participants();
    let mut views = Vec::new();
    for (role, spec) in [(Role::Dem, names::DEM_VIEW), (Role::Mpm, names::MPM_VIEW)] {
        if roles.contains(&role) {
            views.push((role, t.subscriber::<ViewPoint, StepHeader>(&spec)?));
        }
    }

    let effective = cfg.effective(run);
    tracing::info!("run {run}: {effective}");
    if let Some(dir) = out_dir {
        let text = serde_json::to_string_pretty(&effective)? + "\n";
        std::fs::write(dir.join("bridge.json"), text).with_context(|| format!("writing {}", dir.join("bridge.json").display()))?;
    }
    let session = zenoh::open(cfg.zenoh(run)?)
        .wait()
        .map_err(|e| anyhow::anyhow!("grains-bridge: cannot open zenoh on {:?}: {e}", cfg.listen))?;
    let (tx, rx) = mpsc::channel();
    let tx_state = tx.clone();
    let _state_q = session
        .declare_queryable(keys::state_all(run))
        .callback(move |q| {
            let _ = tx_state.send(Incoming::State(q));
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("declaring {}: {e}", keys::state_all(run)))?;
    let _control_q = session
        .declare_queryable(keys::control(run))
        .callback(move |q| {
            let _ = tx.send(Incoming::Control(q));
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("declaring {}: {e}", keys::control(run)))?;
    let view_roles: Vec<Role> = views.iter().map(|(r, _)| *r).collect();
    let outbox = Outbox::open(&session, run, &view_roles)?;
    let (out_tx, out_rx) = mpsc::channel::<Out>();

    std::thread::scope(|scope| -> anyhow::Result<()> {
        let sender = scope.spawn(move || outbox.run(out_rx));
        let out = |o: Out| {
            let _ = out_tx.send(o);
        };
        let mut alive: Vec<Role> = Vec::new();
        let mut latest_views: HashMap<Role, serde_json::Value> = HashMap::new();
        let mut gather = state::Gather::new(&roles);
        let mut paused = false;
        let mut seq = SEQ_BASE;
        let mut pending = Pending::new();
        let mut published: Option<(u64, Instant, bool)> = None;
        let mut last_dead_check = Instant::now();
        let min_interval = if cfg.rate > 0.0 {
            Duration::from_secs_f64(1.0 / cfg.rate)
        } else {
            Duration::ZERO
        };
        let doc = |gather: &state::Gather, paused: bool| gather.document(run, &scene.name, scene.steps, paused);

        while !stop.is_set() {
            // Summaries: wait up to 20 ms for one, then drain.
            let mut timeout = Duration::from_millis(20);
            while let Some(s) = summaries.receive(timeout, |_, s| s.first().copied())? {
                timeout = Duration::ZERO;
                let Some(s) = s else { continue };
                if let Some(role) = Role::from_code(s.role)
                    && !alive.contains(&role)
                {
                    alive.push(role);
                    out(Out::Alive(role, true));
                }
                gather.add(s);
            }

            // Views: the latest of each solver.
            for (role, sub) in &mut views {
                while let Some(v) = sub.receive(Duration::ZERO, |h, pts| state::view_document(run, *role, h, pts))? {
                    out(Out::View(*role, v.to_string()));
                    latest_views.insert(*role, v);
                }
            }

            // Acknowledgements of our commands (and the launcher's: they change the pause state).
            drain_acks(&mut acks, &mut pending, &mut paused, &out)?;
            let now = Instant::now();
            pending.retain(|_, (q, c, since)| {
                let expired = now.duration_since(*since) > ACK_TIMEOUT;
                if expired {
                    let why = format!(
                        "{}: not acknowledged by the time owner within {} s: it may still take effect (a long step), or the run has ended",
                        c.command.name(),
                        ACK_TIMEOUT.as_secs()
                    );
                    out(Out::Error(q.clone(), error_json(&why)));
                }
                !expired
            });

            // Queries from clients.
            while let Ok(incoming) = rx.try_recv() {
                match incoming {
                    Incoming::State(q) => {
                        let mut answers = vec![
                            (keys::summary(run), doc(&gather, paused)),
                            (keys::config(run), Some(effective.clone())),
                        ];
                        answers.extend(latest_views.iter().map(|(role, v)| (keys::view(run, role.name()), Some(v.clone()))));
                        for (key, value) in answers {
                            let Some(value) = value else { continue };
                            if let Ok(k) = zenoh::key_expr::KeyExpr::try_from(key.as_str())
                                && q.key_expr().intersects(&k)
                            {
                                out(Out::Reply(q.clone(), key, value.to_string()));
                            }
                        }
                    }
                    Incoming::Control(q) => {
                        let payload = q.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                        let Some(control) = control.as_mut() else {
                            let why = "steering is disabled for this run: every command is refused (start it with grains run --bridge --steering)";
                            out(Out::Error(q, error_json(why)));
                            continue;
                        };
                        if pending.len() >= MAX_IN_FLIGHT {
                            let why = format!("busy: {MAX_IN_FLIGHT} commands are waiting for the run's acknowledgement; retry");
                            out(Out::Error(q, error_json(&why)));
                            continue;
                        }
                        match command::parse(&payload, scene.walls.len()) {
                            Err(why) => out(Out::Error(q, error_json(&why))),
                            Ok(c) => {
                                seq += 1;
                                let header = StepHeader {
                                    protocol_version: PROTOCOL_VERSION,
                                    sender: Role::Bridge as u32,
                                    step: gather.latest_step().unwrap_or(0),
                                    run_id: run_id_bytes(run),
                                    ..StepHeader::default()
                                };
                                let msg = Control {
                                    seq,
                                    command: c.command as u32,
                                    key: c.key,
                                    value: c.value,
                                };
                                control.publish(1, |h, out| {
                                    *h = header;
                                    out[0] = msg;
                                })?;
                                pending.insert(seq, (q, c, Instant::now()));
                            }
                        }
                    }
                }
            }

            // The latest complete step, at most `rate` times a second, and at once when the
            // run pauses or resumes (no new step says so).
            if let Some(step) = gather.latest_step()
                && published.is_none_or(|(s, at, p)| (s < step && at.elapsed() >= min_interval) || p != paused)
                && let Some(d) = doc(&gather, paused)
            {
                out(Out::Summary(d.to_string()));
                published = Some((step, Instant::now(), paused));
            }

            // Participants that died lose their token; once every participant has gone, the
            // run is over and so is the bridge (one started by hand is not told).
            if last_dead_check.elapsed() > Duration::from_millis(500) {
                last_dead_check = Instant::now();
                if gather.latest_step().is_some() && summaries.publisher_count() == 0 {
                    tracing::info!("run {run} has ended");
                    break;
                }
                for dead in t.dead_peers() {
                    alive.retain(|role| {
                        let gone = dead.starts_with(&format!("{} ", role.binary()));
                        if gone {
                            out(Out::Alive(*role, false));
                        }
                        !gone
                    });
                }
            }
        }
        // A stop's acknowledgement is sent just before the run ends, which is when we are
        // told to stop: it is still queued.
        drain_acks(&mut acks, &mut pending, &mut paused, &out)?;
        for (q, c, _) in pending.into_values() {
            out(Out::Error(
                q,
                error_json(&format!("{}: the bridge is shutting down", c.command.name())),
            ));
        }
        drop(out_tx);
        sender.join().map_err(|_| anyhow::anyhow!("the bridge's outbox thread panicked"))?;
        Ok(())
    })?;
    let _ = session.close().wait();
    Ok(())
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
