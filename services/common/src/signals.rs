//! SIGINT/SIGTERM: set a flag that every wait loop checks (at least every 100 ms), so that a
//! participant stops at a clean point and drops its iceoryx2 ports (which removes them).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

static SIGNALLED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    SIGNALLED.store(true, Ordering::SeqCst);
}

/// Installs the handler for SIGINT and SIGTERM (idempotent).
pub fn install() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as *const () as usize;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(sig, &action, std::ptr::null_mut());
        }
    }
}

/// Whether SIGINT or SIGTERM arrived since [`install`].
pub fn signalled() -> bool {
    SIGNALLED.load(Ordering::SeqCst)
}

/// A stop request for one participant: its own flag (set by the launcher of an in-process
/// run), and, for a participant that is a process of its own, the signals.
#[derive(Clone, Debug, Default)]
pub struct StopFlag {
    own: Arc<AtomicBool>,
    follow_signals: bool,
}

impl StopFlag {
    /// A flag that also trips on SIGINT/SIGTERM (installs the handler).
    pub fn with_signals() -> Self {
        install();
        StopFlag {
            own: Arc::default(),
            follow_signals: true,
        }
    }

    /// A flag only [`StopFlag::set`] trips (threads of an in-process run).
    pub fn manual() -> Self {
        StopFlag::default()
    }

    pub fn set(&self) {
        self.own.store(true, Ordering::SeqCst);
    }

    pub fn is_set(&self) -> bool {
        self.own.load(Ordering::SeqCst) || (self.follow_signals && signalled())
    }

    /// The flag as the iceoryx2 transport asks it while a send is blocked on a full
    /// subscriber: a stop request ends the wait.
    pub fn as_cancel(&self) -> grains_transport::ipc::Cancel {
        let flag = self.clone();
        std::sync::Arc::new(move || flag.is_set())
    }
}
