//! Logging of every grains binary: `tracing`, with one subscriber per process set up here.
//!
//! A line says who wrote it, at which macro-step when there is one, and how much it matters:
//!
//! ```text
//! grains INFO: run 20261202-010203-9f3a of scene column_collapse_hybrid_2d (2000 steps), …
//! grains-dem step 120 WARN: command 3 not carried out: …
//! grains ERROR: participant grains-mpm (pid 4242) killed by signal 9 (SIGKILL); …
//! ```
//!
//! The writer is the process's participant (or, in an in-process run, the thread's: each
//! participant thread says who it is with [`set_participant`]); the step is the one the
//! participant loop is in ([`set_step`]). `RUST_LOG` chooses what is shown (default: info for
//! grains, warnings and errors of everything else, zenoh's and iceoryx2's diagnostics
//! among them). The launcher's progress line is not a log line and stays as it is.

use std::cell::Cell;
use std::fmt;
use std::sync::OnceLock;
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
use tracing_subscriber::registry::LookupSpan;

/// The default filter: every grains crate at info, everything else (zenoh, …) at warn.
/// iceoryx2 (whose log comes through its `tracing` backend) stays at error, as its own console
/// logger was, and so does zenoh's warning that gossip is off: the bridge turns it off on
/// purpose (no scouting of any kind). `RUST_LOG` replaces all of it.
const DEFAULT_FILTER: &str = "warn,iceoryx2_bb_loggers=error,zenoh::net::routing::hat::peer=error,\
grains=info,grains_launch=info,grains_service=info,grains_bridge=info,\
grains_dem_service=info,grains_mpm_service=info,grains_coupler_service=info,grains_oracle_service=info,\
grains_transport=info,grains_protocol=info,grains_dem=info,grains_mpm=info,grains_oracle=info,grains_coupler=info";

static PROCESS: OnceLock<&'static str> = OnceLock::new();

thread_local! {
    static WHO: Cell<Option<&'static str>> = const { Cell::new(None) };
    static STEP: Cell<Option<u64>> = const { Cell::new(None) };
}

/// Installs the subscriber of this process, which writes as `who` (`grains`, `grains-dem`, …)
/// to stderr. Idempotent: a second call (tests, in-process runs) keeps the first.
pub fn init(who: &'static str) {
    let _ = PROCESS.set(who);
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_FILTER));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(false)
        .event_format(Line)
        .try_init();
}

/// This thread writes as `who` (a participant running as a thread of the launcher).
pub fn set_participant(who: &'static str) {
    WHO.with(|w| w.set(Some(who)));
}

/// The macro-step this thread is in, for its log lines (`None` between runs or before the
/// first step).
pub fn set_step(step: Option<u64>) {
    STEP.with(|s| s.set(step));
}

fn stderr_is_terminal() -> bool {
    static TTY: OnceLock<bool> = OnceLock::new();
    *TTY.get_or_init(|| std::io::IsTerminal::is_terminal(&std::io::stderr()))
}

/// One line: `<who>[ step N] <LEVEL>: <message and fields>`.
struct Line;

impl<S, N> FormatEvent<S, N> for Line
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(&self, ctx: &FmtContext<'_, S, N>, mut writer: Writer<'_>, event: &Event<'_>) -> fmt::Result {
        let who = WHO.with(Cell::get).or_else(|| PROCESS.get().copied()).unwrap_or("grains");
        if stderr_is_terminal() {
            // Clear the launcher's progress line, which is redrawn after the log line.
            write!(writer, "\r\x1b[2K")?;
        }
        write!(writer, "{who}")?;
        if let Some(step) = STEP.with(Cell::get) {
            write!(writer, " step {step}")?;
        }
        let meta = event.metadata();
        // Other crates' lines (zenoh, iceoryx2) say where they come from.
        let foreign = !meta.target().starts_with("grains");
        let level = match *meta.level() {
            Level::ERROR => "ERROR",
            Level::WARN => "WARN",
            Level::INFO => "INFO",
            Level::DEBUG => "DEBUG",
            Level::TRACE => "TRACE",
        };
        write!(writer, " {level}: ")?;
        if foreign {
            write!(writer, "[{}] ", meta.target())?;
        }
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}
