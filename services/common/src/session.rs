//! Joining a run and talking within it: the participant side of the handshake of
//! `protocol/README.md` §5, and receives that notice a dead peer or a stop request.

use crate::Halt;
use crate::signals::StopFlag;
use anyhow::{Context, bail};
use grains_protocol::names::{self, ServiceSpec};
use grains_protocol::wire::{HELLO_READY, Hello, StepHeader, Verdict, Welcome};
use grains_protocol::{HELLO_MAGIC, PROTOCOL_VERSION, Role, checksum, run_id_bytes, run_id_str};
use grains_transport::{Pod, Publisher, Subscriber, Transport, ZeroCopy, as_bytes};
use std::time::{Duration, Instant};

/// How long one blocking wait lasts before the liveness checks run.
pub const POLL: Duration = Duration::from_millis(100);
/// Liveness checks look for dead peers every this many polls (iceoryx2 notices a crashed
/// process only when someone looks).
const DEAD_CHECK_EVERY: u32 = 3;

/// One participant's view of its run.
pub struct Session<'t, T: Transport> {
    pub transport: &'t T,
    pub role: Role,
    pub run_id: String,
    run_id_bytes: [u8; 32],
    pub scene_hash: u64,
    pub stop: StopFlag,
    pub connect_timeout: Option<Duration>,
    /// Protocol version announced (differs from the built-in one only in tests).
    pub protocol_version: u32,
    hello: T::Publisher<Hello, ()>,
    welcome: T::Subscriber<Welcome, ()>,
    polls: std::cell::Cell<u32>,
    /// When [`Session::watch_peers`] last looked for dead peers.
    last_dead_check: std::cell::Cell<Instant>,
}

impl<'t, T: Transport> Session<'t, T> {
    /// Asks the launcher for admission; returns once accepted. Run this before opening any
    /// data service: hello and welcome have a layout that never changes, so a participant of
    /// another protocol version is told why it is refused instead of failing on a type check.
    pub fn join(
        transport: &'t T,
        role: Role,
        run_id: &str,
        scene_hash: u64,
        stop: StopFlag,
        connect_timeout: Option<Duration>,
        protocol_version: u32,
    ) -> anyhow::Result<Self> {
        let hello = transport.publisher::<Hello, ()>(&names::HELLO, 1)?;
        let welcome = transport.subscriber::<Welcome, ()>(&names::WELCOME)?;
        let mut session = Session {
            transport,
            role,
            run_id: run_id.to_string(),
            run_id_bytes: run_id_bytes(run_id),
            scene_hash,
            stop,
            connect_timeout,
            protocol_version,
            hello,
            welcome,
            polls: std::cell::Cell::new(0),
            last_dead_check: std::cell::Cell::new(Instant::now()),
        };
        let launcher = format!("the launcher of run {run_id}");
        session.wait_until(&launcher, |s| s.welcome.publisher_count() >= 1 && s.hello.subscriber_count() >= 1)?;
        session.say_hello(0)?;
        let verdict = session.wait_welcome(false)?;
        if verdict.verdict != Verdict::Accepted as u32 {
            bail!(Halt::Refused(refusal(&verdict, role, protocol_version, scene_hash)));
        }
        Ok(session)
    }

    /// A session that skipped admission (unit tests of what happens after it).
    #[cfg(test)]
    pub(crate) fn unadmitted(transport: &'t T, role: Role, run_id: &str) -> anyhow::Result<Self> {
        Ok(Session {
            transport,
            role,
            run_id: run_id.to_string(),
            run_id_bytes: run_id_bytes(run_id),
            scene_hash: 0,
            stop: StopFlag::manual(),
            connect_timeout: None,
            protocol_version: PROTOCOL_VERSION,
            hello: transport.publisher::<Hello, ()>(&names::HELLO, 1)?,
            welcome: transport.subscriber::<Welcome, ()>(&names::WELCOME)?,
            polls: std::cell::Cell::new(0),
            last_dead_check: std::cell::Cell::new(Instant::now()),
        })
    }

    /// Tells the launcher that every port is connected, then waits until all participants
    /// are: the run starts for everyone at once.
    pub fn ready(&mut self) -> anyhow::Result<()> {
        self.say_hello(HELLO_READY)?;
        self.wait_welcome(true)?;
        Ok(())
    }

    fn say_hello(&mut self, flags: u32) -> anyhow::Result<()> {
        let hello = Hello {
            magic: HELLO_MAGIC,
            scene_hash: self.scene_hash,
            protocol_version: self.protocol_version,
            role: self.role as u32,
            pid: std::process::id(),
            flags,
            run_id: self.run_id_bytes,
        };
        self.hello.publish(1, |_, out| out[0] = hello)?;
        Ok(())
    }

    /// Waits for the answer addressed to this participant, or for the start broadcast.
    fn wait_welcome(&mut self, start: bool) -> anyhow::Result<Welcome> {
        let pid = std::process::id();
        let role = self.role as u32;
        let what = if start {
            "the start of the run (all participants connected)"
        } else {
            "admission by the launcher"
        };
        let deadline = self.connect_timeout.map(|t| Instant::now() + t);
        loop {
            let got = self.welcome.receive(POLL, |_, w| w.first().copied())?;
            if let Some(Some(w)) = got {
                let mine = w.magic == HELLO_MAGIC && w.role == role && w.pid == pid;
                let broadcast = w.magic == HELLO_MAGIC && w.role == 0 && w.verdict == Verdict::Start as u32;
                if (start && broadcast) || (!start && mine) {
                    return Ok(w);
                }
                continue;
            }
            self.check_alive(what)?;
            if deadline.is_some_and(|d| Instant::now() > d) {
                bail!(
                    "no answer from the launcher: waited {:.0} s for {what}",
                    self.connect_timeout.unwrap_or_default().as_secs_f64()
                );
            }
        }
    }

    /// Polls `ready` (every 2 ms: start-up only, never on the step path) until it holds.
    pub fn wait_until(&self, what: &str, mut ready: impl FnMut(&Self) -> bool) -> anyhow::Result<()> {
        let start = Instant::now();
        let mut last_check = start;
        while !ready(self) {
            if self.stop.is_set() {
                bail!(Halt::Interrupted);
            }
            if last_check.elapsed() >= POLL * DEAD_CHECK_EVERY {
                last_check = Instant::now();
                self.check_dead(what)?;
            }
            if let Some(t) = self.connect_timeout
                && start.elapsed() > t
            {
                bail!("{what} did not connect within {:.0} s", t.as_secs_f64());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(())
    }

    /// Runs after every empty poll: stop requests at once, dead peers every few polls.
    pub fn check_alive(&self, waiting_for: &str) -> anyhow::Result<()> {
        if self.stop.is_set() {
            bail!(Halt::Interrupted);
        }
        self.polls.set(self.polls.get() + 1);
        if self.polls.get().is_multiple_of(DEAD_CHECK_EVERY) {
            self.check_dead(waiting_for)?;
        }
        Ok(())
    }

    /// Stop requests, and dead peers every few hundred milliseconds, whether this participant
    /// waited or not: in a coupled run each peer's message can arrive within every poll, so
    /// the empty polls of [`Session::check_alive`] may never come: a run whose launcher was
    /// killed stepped on (seen once in the system test of the launcher's death), and an
    /// external coupler took no notice of SIGTERM. Call it once per step (a solver alone in its run too: then it never outlives its run).
    pub fn watch_peers(&self) -> anyhow::Result<()> {
        if self.stop.is_set() {
            bail!(Halt::Interrupted);
        }
        if self.last_dead_check.get().elapsed() >= POLL * DEAD_CHECK_EVERY {
            self.last_dead_check.set(Instant::now());
            self.check_dead("its next step")?;
        }
        Ok(())
    }

    fn check_dead(&self, waiting_for: &str) -> anyhow::Result<()> {
        // The bridge is expendable: the run goes on without it (the launcher warns).
        let bridge = grains_protocol::Role::Bridge.binary();
        let dead: Vec<String> = self
            .transport
            .dead_peers(&|name| name == bridge)
            .into_iter()
            .filter(|d| !d.starts_with(bridge))
            .collect();
        if !dead.is_empty() {
            bail!(Halt::PeerDied(format!(
                "{} died while {} waited for {waiting_for}",
                dead.join(", "),
                self.role.binary()
            )));
        }
        Ok(())
    }

    /// Receives the next message of `sub`, waiting as long as the peers are alive, and
    /// lets `read` look at it in place.
    pub fn recv<E, H, R>(&self, sub: &mut impl Subscriber<E, H>, what: &str, read: impl FnOnce(&H, &[E]) -> R) -> anyhow::Result<R> {
        let mut read = Some(read);
        loop {
            if let Some(r) = sub.receive(POLL, |h, d| read.take().expect("called once")(h, d))? {
                return Ok(r);
            }
            self.check_alive(what)?;
        }
    }

    /// A header for a message of this participant.
    pub fn header(&self, step: u64, time: f64, dt: f64) -> StepHeader {
        StepHeader {
            protocol_version: self.protocol_version,
            sender: self.role as u32,
            step,
            time,
            dt,
            checksum: 0,
            flags: 0,
            run_id: self.run_id_bytes,
        }
    }

    /// Checks that a received message belongs to this run, this protocol and `step`, and
    /// that its payload is intact (when the sender computed a checksum).
    pub fn check_message<E: Pod>(&self, service: &ServiceSpec, h: &StepHeader, step: u64, payload: &[E]) -> anyhow::Result<()> {
        if h.protocol_version != PROTOCOL_VERSION {
            bail!(
                "{}: message speaks protocol version {}, this participant speaks {PROTOCOL_VERSION}",
                service.name,
                h.protocol_version
            );
        }
        if h.run_id != self.run_id_bytes {
            bail!(
                "{}: message of run {:?}, expected run {:?}",
                service.name,
                run_id_str(&h.run_id),
                self.run_id
            );
        }
        if h.step != step {
            bail!("{}: message of step {}, expected step {step}", service.name, h.step);
        }
        if h.checksum != 0 {
            let actual = checksum::checksum_bytes(as_bytes(payload));
            if actual != h.checksum {
                bail!(
                    "{}: step {step}: payload checksum {actual:#018x} does not match the header's {:#018x} ({} elements)",
                    service.name,
                    h.checksum,
                    payload.len()
                );
            }
        }
        Ok(())
    }

    /// Opens a publisher, with context for the error.
    pub fn publisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(
        &self,
        spec: &ServiceSpec,
        initial_len: usize,
    ) -> anyhow::Result<T::Publisher<E, H>> {
        self.transport
            .publisher(spec, initial_len)
            .with_context(|| format!("{} opening {} for publishing", self.role.binary(), spec.name))
    }

    /// Opens a subscriber, with context for the error.
    pub fn subscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(&self, spec: &ServiceSpec) -> anyhow::Result<T::Subscriber<E, H>> {
        self.transport
            .subscriber(spec)
            .with_context(|| format!("{} opening {} for receiving", self.role.binary(), spec.name))
    }
}

fn refusal(w: &Welcome, role: Role, version: u32, scene_hash: u64) -> String {
    let who = role.binary();
    match Verdict::from_code(w.verdict) {
        Some(Verdict::WrongProtocolVersion) => format!(
            "the run refused this {who}: it speaks protocol version {version}, the run speaks version {}",
            w.protocol_version
        ),
        Some(Verdict::WrongScene) => format!(
            "the run refused this {who}: its scene file (hash {scene_hash:#018x}) is not the run's (hash {:#018x}); pass the same --scene as the launcher",
            w.scene_hash
        ),
        Some(Verdict::RoleNotInRun) => format!("the run refused this {who}: the scene has no {} participant", role.name()),
        Some(Verdict::RoleTaken) => format!("the run refused this {who}: another {who} has already joined"),
        _ => format!("the run refused this {who} (verdict code {})", w.verdict),
    }
}
