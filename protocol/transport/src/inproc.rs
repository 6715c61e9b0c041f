//! In-process transport: participants are threads of one process.
//!
//! A service is a list of subscriber queues. A message is a pooled buffer behind an `Arc`:
//! publishing pushes one `Arc` into every queue (no copy), the last reader's drop gives the
//! buffer back to the service's pool, so steady state allocates nothing.

use crate::{Pod, ServiceSpec, TransportError};
use std::any::Any;
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// One in-process "domain": what a run's participants share. Cheap to clone.
#[derive(Clone, Default)]
pub struct InProc {
    bus: Arc<Bus>,
}

#[derive(Default)]
struct Bus {
    services: Mutex<HashMap<&'static str, Arc<dyn Any + Send + Sync>>>,
    dead: Mutex<Vec<String>>,
}

impl InProc {
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a participant thread that failed, for [`crate::Transport::dead_peers`].
    pub fn mark_dead(&self, who: String) {
        self.bus.dead.lock().expect("bus lock").push(who);
    }

    fn channel<E: Pod, H: Pod>(&self, spec: &ServiceSpec) -> Result<Arc<Channel<E, H>>, TransportError> {
        let mut services = self.bus.services.lock().expect("bus lock");
        let any = services
            .entry(spec.name)
            .or_insert_with(|| Arc::new(Channel::<E, H>::default()) as Arc<dyn Any + Send + Sync>)
            .clone();
        any.downcast::<Channel<E, H>>().map_err(|_| TransportError::Open {
            service: spec.name.into(),
            reason: "opened with another payload or header type".into(),
        })
    }
}

struct Channel<E, H> {
    subscribers: Mutex<Vec<Arc<Queue<E, H>>>>,
    publishers: Mutex<usize>,
    pool: Arc<Mutex<Vec<Vec<E>>>>,
}

impl<E, H> Default for Channel<E, H> {
    fn default() -> Self {
        Channel {
            subscribers: Mutex::default(),
            publishers: Mutex::new(0),
            pool: Arc::default(),
        }
    }
}

struct Queue<E, H> {
    messages: Mutex<VecDeque<Arc<Message<E, H>>>>,
    ready: Condvar,
}

struct Message<E, H> {
    header: H,
    data: Vec<E>,
    pool: Arc<Mutex<Vec<Vec<E>>>>,
}

impl<E, H> Drop for Message<E, H> {
    fn drop(&mut self) {
        let data = std::mem::take(&mut self.data);
        if let Ok(mut pool) = self.pool.lock() {
            pool.push(data);
        }
    }
}

pub struct InProcPublisher<E, H> {
    channel: Arc<Channel<E, H>>,
    /// Queue length at which the oldest message is dropped (overflow services).
    cap: Option<usize>,
}

pub struct InProcSubscriber<E, H> {
    channel: Arc<Channel<E, H>>,
    queue: Arc<Queue<E, H>>,
}

impl<E, H> Drop for InProcPublisher<E, H> {
    fn drop(&mut self) {
        *self.channel.publishers.lock().expect("lock") -= 1;
    }
}

impl<E, H> Drop for InProcSubscriber<E, H> {
    fn drop(&mut self) {
        self.channel
            .subscribers
            .lock()
            .expect("lock")
            .retain(|q| !Arc::ptr_eq(q, &self.queue));
    }
}

impl crate::Transport for InProc {
    type Publisher<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy> = InProcPublisher<E, H>;
    type Subscriber<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy> = InProcSubscriber<E, H>;

    fn publisher<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy>(
        &self,
        spec: &ServiceSpec,
        _initial_len: usize,
    ) -> Result<Self::Publisher<E, H>, TransportError> {
        let channel = self.channel::<E, H>(spec)?;
        let mut n = channel.publishers.lock().expect("lock");
        if *n >= spec.max_publishers {
            return Err(TransportError::Open {
                service: spec.name.into(),
                reason: format!("already {} publishers", *n),
            });
        }
        *n += 1;
        drop(n);
        Ok(InProcPublisher {
            channel,
            cap: spec.overflow.then_some(spec.buffer),
        })
    }

    fn subscriber<E: Pod + crate::ZeroCopy, H: Pod + crate::ZeroCopy>(
        &self,
        spec: &ServiceSpec,
    ) -> Result<Self::Subscriber<E, H>, TransportError> {
        let channel = self.channel::<E, H>(spec)?;
        let queue = Arc::new(Queue {
            messages: Mutex::default(),
            ready: Condvar::new(),
        });
        let mut subs = channel.subscribers.lock().expect("lock");
        if subs.len() >= spec.max_subscribers {
            return Err(TransportError::Open {
                service: spec.name.into(),
                reason: format!("already {} subscribers", subs.len()),
            });
        }
        subs.push(queue.clone());
        drop(subs);
        Ok(InProcSubscriber { channel, queue })
    }

    fn dead_peers(&self, _remove: &dyn Fn(&str) -> bool) -> Vec<String> {
        self.bus.dead.lock().expect("bus lock").clone()
    }
}

impl<E: Pod, H: Pod> crate::Publisher<E, H> for InProcPublisher<E, H> {
    fn publish(&mut self, len: usize, fill: impl FnOnce(&mut H, &mut [E])) -> Result<(), TransportError> {
        let mut data = self.channel.pool.lock().expect("pool lock").pop().unwrap_or_default();
        data.resize(len, E::default());
        let mut header = H::default();
        fill(&mut header, &mut data);
        let message = Arc::new(Message {
            header,
            data,
            pool: self.channel.pool.clone(),
        });
        let subs = self.channel.subscribers.lock().expect("lock").clone();
        for queue in subs {
            let mut messages = queue.messages.lock().expect("queue lock");
            if self.cap.is_some_and(|cap| messages.len() >= cap) {
                messages.pop_front();
            }
            messages.push_back(message.clone());
            drop(messages);
            queue.ready.notify_all();
        }
        Ok(())
    }

    fn subscriber_count(&self) -> usize {
        self.channel.subscribers.lock().expect("lock").len()
    }
}

impl<E: Pod, H: Pod> crate::Subscriber<E, H> for InProcSubscriber<E, H> {
    fn receive<R>(&mut self, timeout: Duration, read: impl FnOnce(&H, &[E]) -> R) -> Result<Option<R>, TransportError> {
        let deadline = Instant::now() + timeout;
        let mut messages = self.queue.messages.lock().expect("queue lock");
        loop {
            if let Some(m) = messages.pop_front() {
                drop(messages);
                return Ok(Some(read(&m.header, &m.data)));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            messages = self.queue.ready.wait_timeout(messages, deadline - now).expect("queue lock").0;
        }
    }

    fn publisher_count(&self) -> usize {
        *self.channel.publishers.lock().expect("lock")
    }
}
