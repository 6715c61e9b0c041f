//! The live progress line of a run on stderr.

use std::time::{Duration, Instant};

/// Live progress on stderr: a line rewritten in place on a terminal, a line every 10 s
/// otherwise.
pub struct Progress {
    enabled: bool,
    tty: bool,
    steps: u64,
    last: Instant,
}

impl Progress {
    pub fn new(enabled: bool, steps: u64) -> Self {
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

    pub fn show(&mut self, last: Option<(u64, f64)>, release: Option<Instant>) {
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

    pub fn finish(&mut self, last: Option<(u64, f64)>, release: Option<Instant>) {
        if let Some(line) = self.line(last, release) {
            if self.tty && self.enabled {
                eprint!("\r\x1b[2K");
            }
            tracing::info!("{line}");
        }
    }
}
