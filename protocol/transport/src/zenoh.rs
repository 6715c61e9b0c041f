//! zenoh transport: the same services over TCP, so that a participant may run on another
//! host (`grains run --transport zenoh`). The launcher's session is a zenoh router listening
//! on an endpoint; every participant is a client connected to it; nothing is scouted.
//!
//! iceoryx2 0.10's own zenoh link cannot carry a run (it mirrors services with default
//! limits, adds ports of its own to every count, and shows no remote node's death), so the
//! pieces our protocol needs are built here from plain zenoh:
//!
//! - a message is one `put` of the header's bytes followed by the elements' bytes, on the key
//!   `grains-run/<run-id>/svc/<service>`, congestion control `Block` (nothing is dropped but
//!   a view, whose subscriber keeps only the latest); a subscriber queues them in order;
//! - every port declares a liveliness token `grains-run/<run-id>/port/<service>/<pub|sub>/<id>`,
//!   and every transport follows them: that gives the connection counts of the handshake;
//! - every participant declares `grains-run/<run-id>/node/<name>/<pid>`; one that leaves
//!   cleanly says so first on `grains-run/<run-id>/left`, so a token that disappears without
//!   it is a death (a killed process's link closes at once; a lost host's after zenoh's lease).

use crate::{Pod, ServiceSpec, TransportError};
use std::collections::BTreeSet;
use std::marker::PhantomData;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;
use zenoh::handlers::{FifoChannel, FifoChannelHandler, RingChannel, RingChannelHandler};
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::sample::{Sample, SampleKind};

/// Messages a subscriber queues before its zenoh session stops reading (backpressure).
const QUEUE: usize = 256;

fn open_err(service: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Open {
        service: service.into(),
        reason: e.to_string(),
    }
}

fn io_err(service: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Io {
        service: service.into(),
        reason: e.to_string(),
    }
}

/// What every transport of a run sees of the others: live ports and nodes, and who left.
#[derive(Default)]
struct Peers {
    /// Port token keys below `port/`: `<service>/<pub|sub>/<id>`.
    ports: BTreeSet<String>,
    /// Node token keys below `node/`: `<name>/<pid>`.
    nodes: BTreeSet<String>,
    left: BTreeSet<String>,
    dead: BTreeSet<String>,
}

impl Peers {
    fn count(&self, service: &str, kind: &str) -> usize {
        let head = format!("{service}/{kind}/");
        self.ports
            .iter()
            .filter(|k| k.starts_with(&head) && !k[head.len()..].contains('/'))
            .count()
    }
}

/// A participant's (or the launcher's) zenoh session in a run.
pub struct Zenoh {
    session: zenoh::Session,
    prefix: String,
    /// `<name>/<pid>` of this process.
    me: String,
    peers: Arc<Mutex<Peers>>,
    next_port: std::sync::atomic::AtomicU64,
    _node: LivelinessToken,
    _watch: zenoh::pubsub::Subscriber<()>,
    _left: zenoh::pubsub::Subscriber<()>,
    _ports: zenoh::pubsub::Subscriber<()>,
    /// The router's answer to [`Zenoh::drop`]'s sync query.
    _sync: Option<zenoh::query::Queryable<()>>,
}

impl Zenoh {
    /// The launcher's session: a router listening on `listen` (`tcp/HOST:PORT`).
    pub fn router(run_id: &str, name: &str, listen: &str) -> Result<Self, TransportError> {
        let mut c = base_config()?;
        set(&mut c, "mode", "\"router\"")?;
        set(&mut c, "listen/endpoints", &format!("[\"{listen}\"]"))?;
        let mut z = Self::open(c, run_id, name)?;
        let sync = z
            .session
            .declare_queryable(format!("{}/sync", z.prefix))
            .callback(|q| {
                let _ = q.reply(q.key_expr().clone(), Vec::<u8>::new()).wait();
            })
            .wait()
            .map_err(|e| open_err("zenoh sync", e))?;
        z._sync = Some(sync);
        Ok(z)
    }

    /// A participant's session: a client of the launcher's router at `connect`.
    pub fn client(run_id: &str, name: &str, connect: &str) -> Result<Self, TransportError> {
        let mut c = base_config()?;
        set(&mut c, "mode", "\"client\"")?;
        set(&mut c, "connect/endpoints", &format!("[\"{connect}\"]"))?;
        Self::open(c, run_id, name)
    }

    fn open(config: zenoh::Config, run_id: &str, name: &str) -> Result<Self, TransportError> {
        let session = zenoh::open(config).wait().map_err(|e| open_err("zenoh session", e))?;
        let prefix = format!("grains-run/{run_id}");
        let me = format!("{name}/{}", std::process::id());
        let peers = Arc::new(Mutex::new(Peers::default()));
        let follow = |sub: &str, apply: fn(&mut Peers, String, bool)| {
            let peers = peers.clone();
            let head = format!("{prefix}/{sub}/");
            session
                .liveliness()
                .declare_subscriber(format!("{prefix}/{sub}/**"))
                .history(true)
                .callback(move |s: Sample| {
                    if let Some(key) = s.key_expr().as_str().strip_prefix(&head) {
                        let mut p = peers.lock().expect("peers");
                        apply(&mut p, key.to_string(), s.kind() == SampleKind::Put);
                    }
                })
                .wait()
                .map_err(|e| open_err("zenoh liveliness", e))
        };
        let ports = follow("port", |p, key, up| {
            if up {
                p.ports.insert(key);
            } else {
                p.ports.remove(&key);
            }
        })?;
        let watch = follow("node", |p, key, up| {
            if up {
                p.nodes.insert(key);
            } else {
                p.nodes.remove(&key);
                if !p.left.contains(&key) {
                    p.dead.insert(key);
                }
            }
        })?;
        let left_peers = peers.clone();
        let left = session
            .declare_subscriber(format!("{prefix}/left"))
            .callback(move |s: Sample| {
                let who = String::from_utf8_lossy(&s.payload().to_bytes()).into_owned();
                left_peers.lock().expect("peers").left.insert(who);
            })
            .wait()
            .map_err(|e| open_err("zenoh left", e))?;
        let node = session
            .liveliness()
            .declare_token(format!("{prefix}/node/{me}"))
            .wait()
            .map_err(|e| open_err("zenoh node token", e))?;
        Ok(Zenoh {
            session,
            prefix,
            me,
            peers,
            next_port: std::sync::atomic::AtomicU64::new(0),
            _node: node,
            _watch: watch,
            _left: left,
            _ports: ports,
            _sync: None,
        })
    }

    fn data_key(&self, spec: &ServiceSpec) -> String {
        format!("{}/svc/{}", self.prefix, spec.name)
    }

    fn port_token(&self, spec: &ServiceSpec, kind: &str) -> Result<LivelinessToken, TransportError> {
        let k = self.next_port.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let id = format!("{}-{k}", self.me.replace('/', "-"));
        self.session
            .liveliness()
            .declare_token(format!("{}/port/{}/{kind}/{id}", self.prefix, spec.name))
            .wait()
            .map_err(|e| open_err(spec.name, e))
    }
}

impl Drop for Zenoh {
    /// A clean exit says so before its node token goes: it is not a death. Then it asks the
    /// router for an answer: the link is in order, so once it comes every message sent
    /// before (a last summary, the STOP) has reached the router, which a close alone does
    /// not wait for (a run lost its last summary now and then).
    fn drop(&mut self) {
        let _ = self.session.put(format!("{}/left", self.prefix), self.me.clone()).wait();
        if self._sync.is_none()
            && let Ok(replies) = self
                .session
                .get(format!("{}/sync", self.prefix))
                .timeout(Duration::from_secs(2))
                .wait()
        {
            let _ = replies.recv();
        }
        let _ = self.session.close().wait();
    }
}

fn base_config() -> Result<zenoh::Config, TransportError> {
    let mut c = zenoh::Config::default();
    set(&mut c, "scouting/multicast/enabled", "false")?;
    set(&mut c, "scouting/gossip/enabled", "false")?;
    Ok(c)
}

fn set(c: &mut zenoh::Config, key: &str, value: &str) -> Result<(), TransportError> {
    c.insert_json5(key, value)
        .map_err(|e| open_err("zenoh config", format!("{key} = {value}: {e}")))
}

impl crate::Transport for Zenoh {
    type Publisher<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy> = ZenohPublisher<E, H>;
    type Subscriber<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy> = ZenohSubscriber<E, H>;

    fn publisher<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy>(
        &self,
        spec: &ServiceSpec,
        _initial_len: usize,
    ) -> Result<Self::Publisher<E, H>, TransportError> {
        let publisher = self
            .session
            .declare_publisher(self.data_key(spec))
            .congestion_control(if spec.overflow {
                CongestionControl::Drop
            } else {
                CongestionControl::Block
            })
            .wait()
            .map_err(|e| open_err(spec.name, e))?;
        Ok(ZenohPublisher {
            name: spec.name,
            publisher,
            _token: self.port_token(spec, "pub")?,
            peers: self.peers.clone(),
            _types: PhantomData,
        })
    }

    fn subscriber<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy>(
        &self,
        spec: &ServiceSpec,
    ) -> Result<Self::Subscriber<E, H>, TransportError> {
        let key = self.data_key(spec);
        let rx = if spec.overflow {
            Rx::Latest(
                self.session
                    .declare_subscriber(key)
                    .with(RingChannel::new(spec.buffer.max(1)))
                    .wait()
                    .map_err(|e| open_err(spec.name, e))?,
            )
        } else {
            Rx::Queue(
                self.session
                    .declare_subscriber(key)
                    .with(FifoChannel::new(QUEUE))
                    .wait()
                    .map_err(|e| open_err(spec.name, e))?,
            )
        };
        // The token after the subscriber: a publisher that sees it is routed to it.
        Ok(ZenohSubscriber {
            name: spec.name,
            _token: self.port_token(spec, "sub")?,
            rx,
            peers: self.peers.clone(),
            _types: PhantomData,
        })
    }

    /// Participants whose node token went without their saying they left.
    fn dead_peers(&self, _remove: &dyn Fn(&str) -> bool) -> Vec<String> {
        let p = self.peers.lock().expect("peers");
        p.dead
            .iter()
            .map(|k| match k.split_once('/') {
                Some((name, pid)) => format!("{name} (pid {pid})"),
                None => k.clone(),
            })
            .collect()
    }
}

pub struct ZenohPublisher<E, H> {
    name: &'static str,
    publisher: zenoh::pubsub::Publisher<'static>,
    /// The port's liveliness token: the others count it while it lives.
    _token: LivelinessToken,
    peers: Arc<Mutex<Peers>>,
    _types: PhantomData<(E, H)>,
}

impl<E: Pod, H: Pod> crate::Publisher<E, H> for ZenohPublisher<E, H> {
    fn publish(&mut self, len: usize, fill: impl FnOnce(&mut H, &mut [E])) -> Result<(), TransportError> {
        let mut header = H::default();
        let mut elements = vec![E::default(); len];
        fill(&mut header, &mut elements);
        // One buffer handed to zenoh as it is (no further copy on this side).
        let mut buf = Vec::with_capacity(std::mem::size_of::<H>() + std::mem::size_of_val(elements.as_slice()));
        buf.extend_from_slice(crate::as_bytes(std::slice::from_ref(&header)));
        buf.extend_from_slice(crate::as_bytes(&elements));
        self.publisher.put(buf).wait().map_err(|e| io_err(self.name, e))
    }

    fn subscriber_count(&self) -> usize {
        self.peers.lock().expect("peers").count(self.name, "sub")
    }
}

enum Rx {
    Queue(zenoh::pubsub::Subscriber<FifoChannelHandler<Sample>>),
    Latest(zenoh::pubsub::Subscriber<RingChannelHandler<Sample>>),
}

pub struct ZenohSubscriber<E, H> {
    name: &'static str,
    rx: Rx,
    /// The port's liveliness token: the others count it while it lives.
    _token: LivelinessToken,
    peers: Arc<Mutex<Peers>>,
    _types: PhantomData<(E, H)>,
}

impl<E: Pod, H: Pod> crate::Subscriber<E, H> for ZenohSubscriber<E, H> {
    fn receive<R>(&mut self, timeout: Duration, read: impl FnOnce(&H, &[E]) -> R) -> Result<Option<R>, TransportError> {
        let got = match &self.rx {
            Rx::Queue(s) if timeout.is_zero() => s.try_recv(),
            Rx::Queue(s) => s.recv_timeout(timeout),
            Rx::Latest(s) if timeout.is_zero() => s.try_recv(),
            Rx::Latest(s) => s.recv_timeout(timeout),
        }
        .map_err(|e| io_err(self.name, e))?;
        let Some(sample) = got else { return Ok(None) };
        let bytes = sample.payload().to_bytes();
        let (hs, es) = (std::mem::size_of::<H>(), std::mem::size_of::<E>().max(1));
        if bytes.len() < hs || !(bytes.len() - hs).is_multiple_of(es) {
            return Err(io_err(
                self.name,
                format!("a message of {} bytes: not a {hs}-byte header and {es}-byte elements", bytes.len()),
            ));
        }
        let n = if std::mem::size_of::<E>() == 0 {
            0
        } else {
            (bytes.len() - hs) / es
        };
        // SAFETY: `H: Pod` takes any bytes; the length was checked above.
        let header: H = unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<H>()) };
        let at = bytes[hs..].as_ptr();
        if at.cast::<E>().is_aligned() {
            // Read where it lies (a zenoh buffer is usually aligned well enough).
            // SAFETY: `E: Pod` takes any bytes; aligned, n elements in bounds (checked above).
            let elements = unsafe { std::slice::from_raw_parts(at.cast::<E>(), n) };
            return Ok(Some(read(&header, elements)));
        }
        let mut elements = vec![E::default(); n];
        // SAFETY: as above; the destination holds exactly n elements of E.
        unsafe {
            std::ptr::copy_nonoverlapping(at, elements.as_mut_ptr().cast::<u8>(), n * std::mem::size_of::<E>());
        }
        Ok(Some(read(&header, &elements)))
    }

    fn publisher_count(&self) -> usize {
        self.peers.lock().expect("peers").count(self.name, "pub")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Publisher as _, Subscriber as _, Transport as _};
    use grains_protocol::names;
    use grains_protocol::wire::{StepHeader, Summary};

    fn free_endpoint() -> String {
        let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        format!("tcp/127.0.0.1:{}", l.local_addr().expect("addr").port())
    }

    fn wait_until(what: &str, mut ok: impl FnMut() -> bool) {
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while !ok() {
            assert!(std::time::Instant::now() < deadline, "{what} within 10 s");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// A router and a client of one run: the counts see each other's ports, messages arrive
    /// whole and in order (header and elements), a clean exit is not a death.
    #[test]
    fn messages_counts_and_clean_exits_cross_a_zenoh_link() {
        let ep = free_endpoint();
        let router = Zenoh::router("t1", "grains", &ep).unwrap();
        let client = Zenoh::client("t1", "grains-dem", &ep).unwrap();
        let mut sub = router.subscriber::<Summary, StepHeader>(&names::SUMMARY).unwrap();
        let mut publisher = client.publisher::<Summary, StepHeader>(&names::SUMMARY, 1).unwrap();
        wait_until("the counts", || sub.publisher_count() == 1 && publisher.subscriber_count() == 1);
        for step in 1..=50u64 {
            publisher
                .publish(2, |h, out| {
                    h.step = step;
                    out[0].step = step;
                    out[1].kinetic_energy = step as f64 * 0.5;
                })
                .unwrap();
        }
        for step in 1..=50u64 {
            let got = sub
                .receive(Duration::from_secs(5), |h, s| (h.step, s.len(), s[0].step, s[1].kinetic_energy))
                .unwrap();
            assert_eq!(got, Some((step, 2, step, step as f64 * 0.5)));
        }
        assert_eq!(sub.receive(Duration::from_millis(50), |_, _| ()).unwrap(), None);
        drop(publisher);
        wait_until("the publisher's port to go", || sub.publisher_count() == 0);
        drop(client);
        std::thread::sleep(Duration::from_millis(300));
        assert!(router.dead_peers(&|_| false).is_empty(), "a clean exit is no death");
    }
}
