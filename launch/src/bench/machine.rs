//! Measuring on a shared machine, in one place for every benchmark: CPU time of this
//! process and of its children, the busy time of the whole machine (what else ran meanwhile),
//! and a wait for builds and other load to end before a measurement.

use std::time::{Duration, Instant};

/// Seconds of CPU time (all threads) this process has used.
pub fn cpu_seconds() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// Seconds of CPU time the children this process has waited for have used.
pub fn children_cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct it is given.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) };
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 * 1e-6;
    t(ru.ru_utime) + t(ru.ru_stime)
}

/// Busy CPU seconds of the whole machine so far (all cores, /proc/stat), NaN if unknown.
pub fn machine_busy_seconds() -> f64 {
    let Some(line) = std::fs::read_to_string("/proc/stat")
        .ok()
        .and_then(|s| s.lines().next().map(String::from))
    else {
        return f64::NAN;
    };
    // cpu  user nice system idle iowait irq softirq steal ...
    let f: Vec<f64> = line.split_whitespace().skip(1).filter_map(|w| w.parse().ok()).collect();
    if f.len() < 8 {
        return f64::NAN;
    }
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    (f[0] + f[1] + f[2] + f[5] + f[6] + f[7]) / tick
}

/// What else the machine did while one run took `wall` seconds: (machine busy − own) / wall, in
/// cores.
pub fn other_load(busy0: f64, own: f64, wall: f64) -> f64 {
    ((machine_busy_seconds() - busy0 - own) / wall).max(0.0)
}

/// Processes named cargo or rustc on the machine (a build competing for the 2 cores).
pub fn compilers_running() -> bool {
    let Ok(dir) = std::fs::read_dir("/proc") else { return false };
    dir.flatten().any(|e| {
        e.file_name().to_str().is_some_and(|n| n.bytes().all(|b| b.is_ascii_digit()))
            && std::fs::read_to_string(e.path().join("comm")).is_ok_and(|c| matches!(c.trim(), "cargo" | "rustc"))
    })
}

/// Cores kept busy by other processes over one second (this process is idle meanwhile).
pub fn busy_cores_now() -> f64 {
    let b0 = machine_busy_seconds();
    std::thread::sleep(Duration::from_secs(1));
    machine_busy_seconds() - b0
}

/// Waits (up to `limit` seconds) while a cargo or rustc process runs or other processes keep
/// more than a third of a core busy; says whether it had to give up.
pub fn wait_quiet(what: &str, limit: u64) -> bool {
    let t0 = Instant::now();
    let mut told = false;
    while limit > 0 && (compilers_running() || busy_cores_now() > 0.33) {
        if t0.elapsed().as_secs() >= limit {
            tracing::warn!("{what}: the machine is still busy after {limit} s; measuring anyway");
            return true;
        }
        if !told {
            tracing::info!("{what}: a build or other load is running; waiting for the machine to be quiet");
            told = true;
        }
        std::thread::sleep(Duration::from_secs(4));
    }
    false
}
