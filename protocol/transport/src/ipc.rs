//! iceoryx2 transport: one participant per process, one iceoryx2 node per participant.
//!
//! Every data service `S` is a publish–subscribe service of `[E]` with user header `H`, paired
//! with an event service of the same name: the publisher notifies after each send, each
//! subscriber owns a listener and blocks on it. All participants of a run share the domain
//! prefix [`grains_protocol::names::domain_prefix`], which isolates runs and names every file
//! the run leaves in `/dev/shm` and iceoryx2's root directory.

use crate::{Pod, ServiceSpec, TransportError, ZeroCopy};
use iceoryx2::node::NodeView;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event as ev, publish_subscribe as ps};
use std::fmt::Debug;
use std::path::PathBuf;
use std::time::{Duration, Instant};

type Ipc = ipc::Service;

/// A participant's handle on the run's iceoryx2 domain.
pub struct Iceoryx2 {
    node: Node<Ipc>,
    /// Whether a send blocked on a full subscriber should give up (a stop was requested).
    cancel: Cancel,
}

/// Asked while a send waits for a subscriber with a full buffer: `true` makes it fail.
pub type Cancel = std::sync::Arc<dyn Fn() -> bool + Send + Sync>;

/// How long a send waits for a subscriber whose buffer stays full before it fails. In the
/// macro-step handshake a buffer fills only when its subscriber has stopped reading (died):
/// without a bound, a participant whose launcher was killed would wait for it for ever.
pub const STALLED_SUBSCRIBER: Duration = Duration::from_secs(5);

fn open_err(service: &str, e: impl Debug) -> TransportError {
    TransportError::Open {
        service: service.into(),
        reason: format!("{e:?}"),
    }
}

fn io_err(service: &str, e: impl Debug) -> TransportError {
    TransportError::Io {
        service: service.into(),
        reason: format!("{e:?}"),
    }
}

/// The iceoryx2 configuration of a run: the global defaults with the run's prefix.
pub fn run_config(run_id: &str) -> Result<Config, TransportError> {
    // iceoryx2 warns on every start that it found no config file: keep its log to errors
    // unless IOX2_LOG_LEVEL says otherwise.
    set_log_level_from_env_or(LogLevel::Error);
    let prefix = grains_protocol::names::domain_prefix(run_id);
    let mut config = Config::global_config().clone();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| open_err("domain prefix", e))?;
    // No node removes a dead one as it comes or goes: every participant must see a death
    // ([`crate::Transport::dead_peers`]). Left on, a participant stopping at its launcher's
    // death removed the launcher's node on its way out, and three others, which had not
    // seen it yet, waited on it for ever. The run's end, or the next run, removes the remains.
    config.global.node.cleanup_dead_nodes_on_creation = false;
    config.global.node.cleanup_dead_nodes_on_destruction = false;
    Ok(config)
}

impl Iceoryx2 {
    /// Joins the domain of `run_id` as the node `node_name` (`grains-dem`, …). Signal handling
    /// stays with the caller: grains processes handle SIGINT/SIGTERM themselves, and pass
    /// their stop request as `cancel`, which ends a send blocked on a dead subscriber.
    pub fn join(run_id: &str, node_name: &str, cancel: Cancel) -> Result<Self, TransportError> {
        let config = run_config(run_id)?;
        let name = NodeName::new(node_name).map_err(|e| open_err(node_name, e))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| open_err(node_name, e))?;
        Ok(Iceoryx2 { node, cancel })
    }

    fn service_name(spec: &ServiceSpec) -> Result<ServiceName, TransportError> {
        ServiceName::new(spec.name).map_err(|e| open_err(spec.name, e))
    }

    fn pubsub<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(&self, spec: &ServiceSpec) -> Result<ps::PortFactory<Ipc, [E], H>, TransportError> {
        self.node
            .service_builder(&Self::service_name(spec)?)
            .publish_subscribe::<[E]>()
            .user_header::<H>()
            .max_publishers(spec.max_publishers)
            .max_subscribers(spec.max_subscribers)
            .subscriber_max_buffer_size(spec.buffer)
            .subscriber_max_borrowed_samples(1)
            .history_size(0)
            .enable_safe_overflow(spec.overflow)
            .open_or_create()
            .map_err(|e| open_err(spec.name, e))
    }

    fn event(&self, spec: &ServiceSpec) -> Result<ev::PortFactory<Ipc>, TransportError> {
        self.node
            .service_builder(&Self::service_name(spec)?)
            .event()
            .open_or_create()
            .map_err(|e| open_err(spec.name, e))
    }
}

pub struct IpcPublisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy> {
    name: &'static str,
    // Field order is drop order: ports before their services.
    publisher: iceoryx2::port::publisher::Publisher<Ipc, [E], H>,
    notifier: iceoryx2::port::notifier::Notifier<Ipc>,
    service: ps::PortFactory<Ipc, [E], H>,
    _event: ev::PortFactory<Ipc>,
}

pub struct IpcSubscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy> {
    name: &'static str,
    subscriber: iceoryx2::port::subscriber::Subscriber<Ipc, [E], H>,
    listener: iceoryx2::port::listener::Listener<Ipc>,
    service: ps::PortFactory<Ipc, [E], H>,
    _event: ev::PortFactory<Ipc>,
}

impl crate::Transport for Iceoryx2 {
    type Publisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy> = IpcPublisher<E, H>;
    type Subscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy> = IpcSubscriber<E, H>;

    fn publisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(
        &self,
        spec: &ServiceSpec,
        initial_len: usize,
    ) -> Result<Self::Publisher<E, H>, TransportError> {
        let service = self.pubsub::<E, H>(spec)?;
        let event = self.event(spec)?;
        let backpressure = match spec.overflow {
            true => BackpressureStrategy::DiscardData,
            false => BackpressureStrategy::RetryUntilDelivered,
        };
        let mut builder = service
            .publisher_builder()
            .initial_max_slice_len(initial_len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .max_loaned_samples(1)
            .backpressure_strategy(backpressure);
        if !spec.overflow {
            // Asked again at every retry of a blocked send (an atomic load and a clock read).
            let cancel = self.cancel.clone();
            builder = builder.set_backpressure_handler(move |info: &BackpressureInfo| {
                if info.elapsed_time > STALLED_SUBSCRIBER || cancel() {
                    BackpressureAction::DiscardDataAndFail
                } else {
                    BackpressureAction::Retry
                }
            });
        }
        let publisher = builder.create().map_err(|e| open_err(spec.name, e))?;
        let notifier = event.notifier_builder().create().map_err(|e| open_err(spec.name, e))?;
        Ok(IpcPublisher {
            name: spec.name,
            publisher,
            notifier,
            service,
            _event: event,
        })
    }

    fn subscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(&self, spec: &ServiceSpec) -> Result<Self::Subscriber<E, H>, TransportError> {
        let service = self.pubsub::<E, H>(spec)?;
        let event = self.event(spec)?;
        // The listener exists before anyone can be told to send: a notification only reaches
        // listeners that exist when it is sent.
        let listener = event.listener_builder().create().map_err(|e| open_err(spec.name, e))?;
        let subscriber = service.subscriber_builder().create().map_err(|e| open_err(spec.name, e))?;
        Ok(IpcSubscriber {
            name: spec.name,
            subscriber,
            listener,
            service,
            _event: event,
        })
    }

    fn dead_peers(&self, remove: &dyn Fn(&str) -> bool) -> Vec<String> {
        // A node that leaves cleanly removes its details, then its monitor, and iceoryx2
        // lists a monitor being removed as dead. A look that read the details just before
        // and the monitor during that removal saw a clean exit as a death (9 in 200 exits in
        // the test `clean_exit`; it failed a run at its last step under load). So a node is
        // dead only if a second look, after the first, still finds its details: a clean exit
        // has removed them by then, a dead process never does.
        let mut suspects = Vec::new();
        let _ = Node::<Ipc>::list(self.node.config(), |state| {
            if let NodeState::Dead(view) = state
                && view.details().is_some()
            {
                suspects.push(*view.id());
            }
            CallbackProgression::Continue
        });
        let mut dead = Vec::new();
        if suspects.is_empty() {
            return dead;
        }
        let _ = Node::<Ipc>::list(self.node.config(), |state| {
            if let NodeState::Dead(view) = state
                && suspects.contains(view.id())
            {
                // A dead node whose details cannot be read is one whose remains another
                // participant is removing right now: only an expendable peer's are ever
                // removed during a run (below), so it is no participant's death. (Reported, it
                // failed a run on CI when the bridge was killed: every process removes it.)
                let Some(details) = view.details() else {
                    return CallbackProgression::Continue;
                };
                let name = details.name().as_str().to_string();
                let who = format!("{name} (pid {})", details.process_id().value());
                dead.push(who);
                // Only an expendable peer's remains go now (a dead subscriber's ports would
                // stall every publisher); any other dead node stays for every participant to
                // see (see `run_config`).
                if remove(&name) {
                    let _ = view.try_remove_stale_resources();
                }
            }
            CallbackProgression::Continue
        });
        dead
    }
}

impl<E: Pod + ZeroCopy, H: Pod + ZeroCopy> crate::Publisher<E, H> for IpcPublisher<E, H> {
    fn publish(&mut self, len: usize, fill: impl FnOnce(&mut H, &mut [E])) -> Result<(), TransportError> {
        let mut sample = self.publisher.loan_slice_uninit(len).map_err(|e| io_err(self.name, e))?;
        let payload = sample.payload_mut();
        // SAFETY: the chunk lies in a shared-memory segment that the OS handed out zero-filled
        // and that afterwards only ever holds earlier messages of this service, so its bytes
        // are initialized; `E: Pod` makes any bytes a valid `E`. `fill` overwrites them.
        let payload: &mut [E] = unsafe { &mut *(payload as *mut [std::mem::MaybeUninit<E>] as *mut [E]) };
        let mut header = H::default();
        fill(&mut header, payload);
        // SAFETY: every element was initialized, see above.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = header;
        sample.send().map_err(|e| match e {
            iceoryx2::port::SendError::UnableToDeliver => TransportError::Io {
                service: self.name.into(),
                reason: format!(
                    "a subscriber took no message for {:.0} s (it died or stopped reading), or this participant is stopping",
                    STALLED_SUBSCRIBER.as_secs_f64()
                ),
            },
            e => io_err(self.name, e),
        })?;
        self.notifier.notify().map_err(|e| io_err(self.name, e))?;
        Ok(())
    }

    fn subscriber_count(&self) -> usize {
        let _ = self.publisher.update_connections();
        self.service.dynamic_config().number_of_subscribers()
    }
}

impl<E: Pod + ZeroCopy, H: Pod + ZeroCopy> crate::Subscriber<E, H> for IpcSubscriber<E, H> {
    fn receive<R>(&mut self, timeout: Duration, read: impl FnOnce(&H, &[E]) -> R) -> Result<Option<R>, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = self.subscriber.receive().map_err(|e| io_err(self.name, e))? {
                return Ok(Some(read(sample.user_header(), sample.payload())));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            // Events are sticky: a notification sent between `receive` and here still wakes us.
            // A signal (SIGINT/SIGTERM) interrupts the wait: report a timeout, so that the
            // caller checks its stop flag and stops at a clean point.
            match self.listener.timed_wait(|_| {}, deadline - now) {
                Ok(_) => {}
                Err(ListenerWaitError::InterruptSignal) => return Ok(None),
                Err(e) => return Err(io_err(self.name, e)),
            }
        }
    }

    fn publisher_count(&self) -> usize {
        let _ = self.subscriber.update_connections();
        self.service.dynamic_config().number_of_publishers()
    }
}

/// Removes what a run left behind: dead nodes' resources, then every file of the run's
/// prefix in `/dev/shm` and under iceoryx2's root directory. Call only when no participant
/// of the run is alive. Returns the paths removed.
pub fn remove_run_files(run_id: &str) -> Vec<PathBuf> {
    if let Ok(config) = run_config(run_id) {
        let _ = Node::<Ipc>::list(&config, |state| {
            if let NodeState::Dead(view) = state {
                let _ = view.try_remove_stale_resources();
            }
            CallbackProgression::Continue
        });
    }
    let mut removed = Vec::new();
    for path in run_files(run_id) {
        let ok = if path.is_dir() {
            std::fs::remove_dir_all(&path).is_ok()
        } else {
            std::fs::remove_file(&path).is_ok()
        };
        if ok {
            removed.push(path);
        }
    }
    removed
}

/// Removes the files of every earlier run none of whose participants is alive any more (a
/// launcher killed with SIGKILL cleans nothing up). Returns the ids of the runs cleaned, with
/// the paths removed. Runs with a live node are left alone, however old.
pub fn remove_dead_runs() -> Vec<(String, Vec<PathBuf>)> {
    let mut cleaned = Vec::new();
    for run_id in runs_with_files() {
        let Ok(config) = run_config(&run_id) else { continue };
        let mut alive = false;
        let _ = Node::<Ipc>::list(&config, |state| {
            // Only a node known to be dead lets the run go: one that cannot be read yet may be
            // starting.
            if !matches!(state, NodeState::Dead(_)) {
                alive = true;
            }
            CallbackProgression::Continue
        });
        if !alive {
            let removed = remove_run_files(&run_id);
            if !removed.is_empty() {
                cleaned.push((run_id, removed));
            }
        }
    }
    cleaned
}

/// Run ids that have files in `/dev/shm` or under iceoryx2's root directory.
fn runs_with_files() -> Vec<String> {
    let root = Config::global_config().global.root_path().to_string();
    let mut ids = std::collections::BTreeSet::new();
    fn walk(dir: &std::path::Path, ids: &mut std::collections::BTreeSet<String>, depth: usize) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(id) = run_id_of(&name) {
                ids.insert(id.to_string());
            } else if depth > 0 && entry.path().is_dir() {
                walk(&entry.path(), ids, depth - 1);
            }
        }
    }
    walk(std::path::Path::new("/dev/shm"), &mut ids, 0);
    walk(std::path::Path::new(&root), &mut ids, 4);
    ids.into_iter().collect()
}

/// The run id in a file name of a run's domain (`grains_<run-id>_…`; run ids have no `_`).
fn run_id_of(file_name: &str) -> Option<&str> {
    let rest = file_name.strip_prefix("grains_")?;
    let (id, _) = rest.split_once('_')?;
    (!id.is_empty() && grains_protocol::names::domain_prefix(id).len() < file_name.len()).then_some(id)
}

/// Every file or directory whose name carries the run's prefix, in `/dev/shm` and under
/// iceoryx2's root directory (searched recursively).
pub fn run_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = grains_protocol::names::domain_prefix(run_id);
    let mut found = Vec::new();
    let mut roots = vec![PathBuf::from("/dev/shm")];
    if let Ok(config) = run_config(run_id) {
        roots.push(PathBuf::from(config.global.root_path().to_string()));
    }
    fn walk(dir: &std::path::Path, prefix: &str, found: &mut Vec<PathBuf>, depth: usize) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            if entry.file_name().to_string_lossy().starts_with(prefix) {
                found.push(path);
            } else if depth > 0 && path.is_dir() {
                walk(&path, prefix, found, depth - 1);
            }
        }
    }
    for root in roots {
        walk(&root, &prefix, &mut found, 4);
    }
    found
}
