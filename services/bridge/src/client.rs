//! Remote clients of a bridge: `grains runs`, `grains monitor`, `grains steer`.

use crate::config::{self, keys};
use anyhow::{Context, bail};
use serde_json::Value;
use std::io::Write;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Where a client connects and as whom.
#[derive(Clone, Debug)]
pub struct Endpoint {
    pub connect: String,
    pub credentials: Option<(String, String)>,
}

impl Endpoint {
    pub fn open(&self) -> anyhow::Result<zenoh::Session> {
        let creds = self.credentials.as_ref().map(|(u, p)| (u.as_str(), p.as_str()));
        zenoh::open(config::client(&self.connect, creds)?)
            .wait()
            .map_err(|e| anyhow::anyhow!("cannot reach a grains bridge at {}: {e}", self.connect))
    }
}

/// One query, every reply as `Ok(json)` or `Err(message)`.
fn query(session: &zenoh::Session, key: &str, payload: Option<Vec<u8>>, timeout: Duration) -> anyhow::Result<Vec<Result<Value, String>>> {
    let mut get = session.get(key).timeout(timeout);
    if let Some(p) = payload {
        get = get.payload(p);
    }
    let replies = get.wait().map_err(|e| anyhow::anyhow!("query {key}: {e}"))?;
    let mut out = Vec::new();
    while let Ok(reply) = replies.recv() {
        let (bytes, ok) = match reply.result() {
            Ok(s) => (s.payload().to_bytes().into_owned(), true),
            Err(e) => (e.payload().to_bytes().into_owned(), false),
        };
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let value = serde_json::from_str::<Value>(&text);
        out.push(match (ok, value) {
            (true, Ok(v)) => Ok(v),
            (true, Err(_)) => Err(format!("unreadable reply: {text}")),
            (false, Ok(v)) => Err(v["error"].as_str().map_or(text.clone(), str::to_string)),
            (false, Err(_)) => Err(text),
        });
    }
    Ok(out)
}

/// The runs whose bridge is reachable at the endpoint, each with its latest summary.
pub fn runs(ep: &Endpoint, timeout: Duration) -> anyhow::Result<Vec<(String, Option<Value>)>> {
    let session = ep.open()?;
    let replies = session
        .liveliness()
        .get(keys::ALL_BRIDGES)
        .timeout(timeout)
        .wait()
        .map_err(|e| anyhow::anyhow!("liveliness query: {e}"))?;
    let mut ids = Vec::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result()
            && let Some(run) = keys::run_of(s.key_expr().as_str())
        {
            ids.push(run.to_string());
        }
    }
    ids.sort();
    ids.dedup();
    let mut out = Vec::new();
    for id in ids {
        let latest = query(&session, &keys::summary(&id), None, timeout)?
            .into_iter()
            .find_map(Result::ok);
        out.push((id, latest));
    }
    let _ = session.close().wait();
    Ok(out)
}

/// Sends one command (JSON, see [`crate::command`]) to a run; the time owner's
/// acknowledgement, or why not.
pub fn steer(ep: &Endpoint, run: &str, command: &[u8]) -> anyhow::Result<Result<Value, String>> {
    let session = ep.open()?;
    let replies = query(
        &session,
        &keys::control(run),
        Some(command.to_vec()),
        crate::ACK_TIMEOUT + Duration::from_secs(2),
    )?;
    let _ = session.close().wait();
    match replies.into_iter().next() {
        Some(r) => Ok(r),
        None => bail!(
            "no answer from run {run} at {}: no such run, its bridge is not running, or steering is not allowed for this user",
            ep.connect
        ),
    }
}

/// The columns of `grains monitor`.
pub fn table_header() -> String {
    format!(
        "{:>9} {:>12} {:>9} {:>9} {:>11} {:>12} {:>9} {:>6}",
        "step", "time s", "grains", "points", "zone nodes", "KE J", "steps/s", "state"
    )
}

pub fn table_row(v: &Value) -> String {
    let count = |k: &str| v[k].as_u64().map_or("-".to_string(), |n| n.to_string());
    format!(
        "{:>9} {:>12.6e} {:>9} {:>9} {:>11} {:>12.4e} {:>9.1} {:>6}",
        v["step"].as_u64().unwrap_or(0),
        v["time"].as_f64().unwrap_or(0.0),
        count("grains"),
        count("points"),
        count("zone_nodes"),
        v["kinetic_energy"].as_f64().unwrap_or(0.0),
        v["steps_per_s"].as_f64().unwrap_or(0.0),
        if v["paused"].as_bool() == Some(true) { "paused" } else { "run" }
    )
}

/// Prints the run's summaries as a live table until `rows` rows were printed (if given), or
/// the run's bridge is gone.
pub fn monitor(ep: &Endpoint, run: &str, rows: Option<u64>, out: &mut impl Write) -> anyhow::Result<()> {
    let session = ep.open()?;
    let sub = session
        .declare_subscriber(keys::summary(run))
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to {}: {e}", keys::summary(run)))?;
    let latest = query(&session, &keys::summary(run), None, Duration::from_secs(2))?;
    let alive = |session: &zenoh::Session| -> bool {
        session
            .liveliness()
            .get(keys::alive(run, "bridge"))
            .timeout(Duration::from_secs(2))
            .wait()
            .is_ok_and(|r| r.recv().is_ok_and(|x| x.result().is_ok()))
    };
    if latest.is_empty() && !alive(&session) {
        bail!(
            "no run {run} at {}: `grains runs --connect {}` lists the runs there",
            ep.connect,
            ep.connect
        );
    }
    writeln!(out, "{}", table_header())?;
    let mut printed = 0;
    if let Some(Ok(v)) = latest.first() {
        writeln!(out, "{}", table_row(v))?;
        printed += 1;
    }
    let mut quiet_since = Instant::now();
    while rows.is_none_or(|n| printed < n) {
        match sub.recv_timeout(Duration::from_secs(1)) {
            Ok(Some(sample)) => {
                let bytes = sample.payload().to_bytes();
                let v: Value = serde_json::from_slice(&bytes).context("a summary that is not JSON")?;
                writeln!(out, "{}", table_row(&v))?;
                out.flush()?;
                printed += 1;
                quiet_since = Instant::now();
            }
            Ok(None) if quiet_since.elapsed() > Duration::from_secs(5) => {
                if !alive(&session) {
                    writeln!(out, "run {run}: its bridge is gone (the run ended)")?;
                    break;
                }
                quiet_since = Instant::now();
            }
            Ok(None) => {}
            Err(e) => bail!("receiving summaries: {e}"),
        }
    }
    let _ = session.close().wait();
    Ok(())
}

/// A client of every run at `ep` that subscribes to the views and never takes them off its
/// socket: its callback blocks on the first sample for good. It is what `grains bench bridge`
/// measures the run against. Tries to connect for up to `wait` (the bridge may not be up
/// yet), prints `subscribed` on stdout once the subscription stands, and never returns.
pub fn stalled_viewer(ep: &Endpoint, wait: Duration) -> anyhow::Result<std::convert::Infallible> {
    let deadline = Instant::now() + wait;
    let session = loop {
        match ep.open() {
            Ok(s) => break s,
            Err(e) if Instant::now() >= deadline => return Err(e),
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    };
    let _sub = session
        .declare_subscriber("grains/*/state/view/*")
        .callback(|_| {
            loop {
                std::thread::park();
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to the views: {e}"))?;
    println!("subscribed");
    std::io::stdout().flush()?;
    loop {
        std::thread::park();
    }
}
