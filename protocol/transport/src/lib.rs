//! The transports of the macro-step, behind one small trait.
//!
//! - [`ipc::Iceoryx2`]: separate processes over iceoryx2 shared memory. Payloads are loaned
//!   from the service's data segment and written in place; the subscriber reads them where
//!   they lie. Nothing is serialized or copied.
//! - [`zenoh::Zenoh`]: processes on any hosts over TCP (zenoh), for a participant elsewhere;
//!   every message is copied into one zenoh put.
//! - [`inproc::InProc`]: threads of one process. Payload buffers come from a per-service pool
//!   and are handed over by reference count; nothing is copied either.
//!
//! Every data service is a stream of messages, each one slice of elements `E` plus a user
//! header `H`. A waiting subscriber blocks on an event (iceoryx2: the paired event service;
//! in-process: a condition variable) with a deadline, never in a spin.
//!
//! This is the only crate of grains that uses iceoryx2 (and, besides the bridge, zenoh).

pub mod inproc;
pub mod ipc;
pub mod zenoh;

use grains_protocol::wire::*;
use std::time::Duration;

/// Plain data that may be handed out as initialized memory whatever its bytes.
///
/// # Safety
/// Every bit pattern must be a valid value (only integers, floats and arrays of them, no
/// padding that matters), and the type must be `#[repr(C)]` with the layout the spec gives.
pub unsafe trait Pod: Copy + Default + std::fmt::Debug + Send + Sync + 'static {}

// SAFETY: all these are #[repr(C)] structs of u32/u64/f64 and arrays of them (see
// grains_protocol::wire and its layout test), or primitive integers, or the empty tuple.
unsafe impl Pod for StepHeader {}
unsafe impl Pod for Hello {}
unsafe impl Pod for Welcome {}
unsafe impl Pod for StepBegin {}
unsafe impl Pod for RasterNode {}
unsafe impl Pod for NodeVelocity {}
unsafe impl Pod for ZoneCell {}
unsafe impl Pod for SpawnGrain {}
unsafe impl Pod for SpawnPoint {}
unsafe impl Pod for EpochItem {}
unsafe impl Pod for NodeStress {}
unsafe impl Pod for PointScale {}
unsafe impl Pod for Summary {}
unsafe impl Pod for Control {}
unsafe impl Pod for Ack {}
unsafe impl Pod for ViewPoint {}
unsafe impl Pod for BodyReach {}
unsafe impl Pod for ContactPoint {}
unsafe impl Pod for PointForce {}
unsafe impl Pod for u64 {}
unsafe impl Pod for () {}

/// What can fail in a transport.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// A service could not be created or opened (another protocol version, or limits reached).
    #[error("cannot open service {service}: {reason}")]
    Open { service: String, reason: String },
    /// Loaning, sending or receiving failed.
    #[error("service {service}: {reason}")]
    Io { service: String, reason: String },
}

pub use grains_protocol::names::ServiceSpec;

/// Opens publishers and subscribers and tells who is gone.
pub trait Transport {
    type Publisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy>: Publisher<E, H>;
    type Subscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy>: Subscriber<E, H>;

    /// Opens (creating if needed) `spec` for publishing messages of up to about
    /// `initial_len` elements; longer messages grow the buffers.
    fn publisher<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(
        &self,
        spec: &ServiceSpec,
        initial_len: usize,
    ) -> Result<Self::Publisher<E, H>, TransportError>;

    /// Opens (creating if needed) `spec` for receiving.
    fn subscriber<E: Pod + ZeroCopy, H: Pod + ZeroCopy>(&self, spec: &ServiceSpec) -> Result<Self::Subscriber<E, H>, TransportError>;

    /// Participants of the run found dead, as "name (pid N)", on every call while their
    /// remains last. Every participant must see a death, so the remains stay (the run's end
    /// or the next run removes them), except those of the dead whose node name `remove`
    /// accepts: an expendable peer (the bridge) whose dead ports would stall the run.
    fn dead_peers(&self, remove: &dyn Fn(&str) -> bool) -> Vec<String>;
}

pub trait Publisher<E, H> {
    /// Loans a message of `len` elements, lets `fill` write the header and payload in place,
    /// sends it and wakes the subscribers. The header starts as `H::default()`; the payload
    /// holds unspecified (but valid) values that `fill` must overwrite.
    fn publish(&mut self, len: usize, fill: impl FnOnce(&mut H, &mut [E])) -> Result<(), TransportError>;

    /// Subscribers currently connected (for the start-up handshake).
    fn subscriber_count(&self) -> usize;
}

pub trait Subscriber<E, H> {
    /// Waits up to `timeout` for the next message and lets `read` look at it in place.
    /// `Ok(None)` on timeout.
    fn receive<R>(&mut self, timeout: Duration, read: impl FnOnce(&H, &[E]) -> R) -> Result<Option<R>, TransportError>;

    /// Publishers currently connected (for the start-up handshake).
    fn publisher_count(&self) -> usize;
}

/// The iceoryx2 bound on payload and header types, so that both transports accept the same.
pub use iceoryx2::prelude::ZeroCopySend as ZeroCopy;

/// The bytes of a slice of plain data (for checksums).
pub fn as_bytes<E: Pod>(data: &[E]) -> &[u8] {
    // SAFETY: `E: Pod` has no padding that matters and any initialized `E` is plain bytes;
    // the length covers exactly the slice.
    unsafe { std::slice::from_raw_parts(data.as_ptr().cast::<u8>(), std::mem::size_of_val(data)) }
}
