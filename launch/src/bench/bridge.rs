//! `grains bench bridge`: what remote access costs a run. The same scene runs without a
//! bridge, with a bridge and no client, with a bridge and a client that subscribes to the
//! views and never reads them (`grains_bridge::client::stalled_viewer`, a child process
//! stopped with SIGSTOP once its buffers are full), and with the live viewer's page open in
//! headless chromium (Debian's `chromium`; it draws every view), alternating, fastest of the repeats each
//! (the machine is shared: the fastest run is the least disturbed). Figures: wall time of the
//! stepping (release to last row) and of the whole run (start to end, so a bridge that holds up
//! the run's start or end shows), and their ratios to the run without a bridge; the bridge's
//! own CPU time (from `/proc`), which is what a run pays for a viewer whose browser runs on
//! another machine; the browser's CPU time (what it drew with); and the CPU time of the run's
//! child processes (the participants and the bridge).
//!
//! `--browser-idle` stands in for that other machine on this one: chromium runs under
//! SCHED_IDLE, so it draws only on a core the run leaves idle and gives it up the moment a
//! run's process wakes, while the bridge serving it still takes its share. (Holding the run to
//! one core and the browser to the other measured a one-core run instead, which waits on every
//! handshake: +1% to +20% between sessions.)

use crate::run::{RunOptions, RunOutcome, Status, run};
use anyhow::{Context, bail};
use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Clone, clap::Args)]
pub struct BridgeArgs {
    /// The scene (its views: up to 5,000 grains and points, 5 a second).
    #[arg(long, default_value = "scenes/quickstart_hybrid_2d.toml")]
    pub scene: PathBuf,
    /// Simulated time of every run [s] (`run.duration`).
    #[arg(long, default_value_t = 0.05)]
    pub duration: f64,
    /// Runs of each kind (the fastest is reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Extra `--set` overrides of the scene.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Where the runs and the result table go.
    #[arg(long, default_value = "out/bench/bridge")]
    pub out: PathBuf,
    /// Run chromium under SCHED_IDLE: it draws only on a core the run leaves idle and yields it
    /// the moment a run's process wakes (a browser on its own machine, the run on all cores).
    #[arg(long)]
    pub browser_idle: bool,
}

/// Puts the calling process under SCHED_IDLE (its children inherit it).
fn idle() -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: sched_setscheduler reads the param for the duration of the call.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The kinds of run, in the order they alternate.
const KINDS: [&str; 4] = [
    "no bridge",
    "bridge, no client",
    "bridge, a client that never reads",
    "bridge, the viewer page in headless chromium",
];

/// A loopback endpoint on a port that was free a moment ago.
fn free_endpoint() -> anyhow::Result<String> {
    let l = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(format!("tcp/127.0.0.1:{}", l.local_addr()?.port()))
}

/// Starts the stalled client against `connect` (it waits for the bridge), and stops it with
/// SIGSTOP a second after it subscribed: by then the views have filled what its socket and
/// zenoh buffer, and a stopped process takes no CPU from the run.
fn stalled_client(connect: &str) -> anyhow::Result<(std::process::Child, std::thread::JoinHandle<anyhow::Result<()>>)> {
    let mut child = std::process::Command::new(std::env::current_exe()?)
        .args(["bench", "stalled-client", "--connect", connect])
        .stdout(std::process::Stdio::piped())
        // Its zenoh warns of every try before the bridge listens; a failure shows as no
        // "subscribed" line.
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting the stalled client")?;
    let stdout = child.stdout.take().expect("piped");
    let pid = child.id() as i32;
    let stopper = std::thread::spawn(move || {
        let mut line = String::new();
        std::io::BufReader::new(stdout).read_line(&mut line)?;
        if line.trim() != "subscribed" {
            bail!("the stalled client did not subscribe: {line:?}");
        }
        std::thread::sleep(Duration::from_secs(1));
        // SAFETY: kill(2) on our own child, by pid.
        if unsafe { libc::kill(pid, libc::SIGSTOP) } != 0 {
            bail!("cannot stop the stalled client: {}", std::io::Error::last_os_error());
        }
        Ok(())
    });
    Ok((child, stopper))
}

/// Opens the viewer page at `http` in headless chromium (under SCHED_IDLE if `idle_policy`)
/// once the bridge serves it; the browser runs until killed.
fn viewer_page(http: std::net::SocketAddr, idle_policy: bool) -> anyhow::Result<std::process::Child> {
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while std::net::TcpStream::connect(http).is_err() {
        if std::time::Instant::now() > deadline {
            bail!("the viewer page at {http} did not open in 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut chromium = std::process::Command::new("chromium");
    if idle_policy {
        use std::os::unix::process::CommandExt;
        // SAFETY: between fork and exec the closure only makes one system call.
        unsafe { chromium.pre_exec(idle) };
    }
    chromium
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--remote-debugging-port=0",
            "--window-size=1280,720",
        ])
        .arg(format!("http://{http}/"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting chromium (Debian's chromium) for the viewer")
}

/// (name, parent's pid, CPU seconds user + system) of every process alive now: one pass over
/// `/proc` (the sampler shares the run's machine).
fn processes_cpu() -> Vec<(String, String, f64)> {
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let Ok(dir) = std::fs::read_dir("/proc") else { return Vec::new() };
    dir.flatten()
        .filter_map(|e| {
            let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
            // pid (comm) state ppid ... utime stime: fields 14 and 15; comm may hold spaces.
            let (comm, rest) = stat.split_once(" (")?.1.rsplit_once(") ")?;
            let f: Vec<&str> = rest.split_whitespace().collect();
            let cpu = (f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / tick;
            Some((comm.to_string(), f.get(1)?.to_string(), cpu))
        })
        .collect()
}

/// Samples every 100 ms until `done` the CPU time of the bridge (our child) and of the
/// browser (chromium and the processes it starts); the last samples, each within 100 ms of
/// its total.
fn sample_cpu(done: std::sync::Arc<std::sync::atomic::AtomicBool>) -> (f64, f64) {
    let me = std::process::id().to_string();
    let bridge = grains_protocol::Role::Bridge.binary();
    let mut last = (0.0f64, 0.0f64);
    while !done.load(std::sync::atomic::Ordering::Relaxed) {
        let all = processes_cpu();
        let sum = |pick: &dyn Fn(&str, &str) -> bool| all.iter().filter(|(c, p, _)| pick(c, p)).map(|(_, _, cpu)| cpu).sum::<f64>();
        last = (
            sum(&|comm, parent| comm == bridge && parent == me).max(last.0),
            sum(&|comm, _| comm.starts_with("chrom")).max(last.1),
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    last
}

/// CPU seconds (user + system) of this process's children that have ended and been waited for.
fn children_cpu() -> f64 {
    // SAFETY: getrusage fills the zeroed struct it is given.
    let u = unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_CHILDREN, &mut u);
        u
    };
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    secs(u.ru_utime) + secs(u.ru_stime)
}

/// What one run measured [s].
struct Measured {
    stepping: f64,
    whole: f64,
    bridge_cpu: f64,
    browser_cpu: f64,
    /// Of the run's child processes (the participants and the bridge; not the launcher, which
    /// runs in this process).
    run_cpu: f64,
}

/// One run of `kind`.
fn one(args: &BridgeArgs, kind: usize) -> anyhow::Result<Measured> {
    let connect = free_endpoint()?;
    let http = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?;
    let bridge = (kind > 0).then(|| grains_bridge::config::BridgeArgs {
        listen: vec![connect.clone()],
        view_listen: (kind == 3).then(|| http.to_string()),
        ..Default::default()
    });
    let client = if kind == 2 { Some(stalled_client(&connect)?) } else { None };
    let browser = if kind == 3 {
        let idle_policy = args.browser_idle;
        Some(std::thread::spawn(move || viewer_page(http, idle_policy)))
    } else {
        None
    };
    let mut overrides = vec![format!("run.duration={}", args.duration), "output.frames_every=0".to_string()];
    overrides.extend(args.overrides.iter().cloned());
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sampler = {
        let done = done.clone();
        std::thread::spawn(move || sample_cpu(done))
    };
    let started = std::time::Instant::now();
    let cpu0 = children_cpu();
    let outcome: anyhow::Result<RunOutcome> = run(&RunOptions {
        bridge,
        ..RunOptions::quiet(args.scene.clone(), args.out.join("runs"), overrides)
    });
    let whole = started.elapsed().as_secs_f64();
    // The run's processes have all been waited for; the browser and the client are not yet.
    let run_cpu = children_cpu() - cpu0;
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let (bridge_cpu, browser_cpu) = sampler.join().expect("the sampler thread");
    if let Some(b) = browser {
        let mut chromium = b.join().expect("the browser thread")?;
        let _ = chromium.kill();
        let _ = chromium.wait();
    }
    if let Some((mut child, stopper)) = client {
        let _ = child.kill();
        let _ = child.wait();
        stopper.join().expect("the stopper thread")?;
    }
    let outcome = outcome?;
    if outcome.status != Status::Completed {
        bail!("{}: the run did not complete: {}", KINDS[kind], outcome.message);
    }
    let _ = std::fs::remove_dir_all(&outcome.dir);
    Ok(Measured {
        stepping: outcome.stepping.as_secs_f64(),
        whole,
        bridge_cpu,
        browser_cpu,
        run_cpu,
    })
}

pub fn bench(args: &BridgeArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut best = [(f64::INFINITY, f64::INFINITY); KINDS.len()];
    // Every run of each kind, for the medians.
    let mut runs: [Vec<Measured>; KINDS.len()] = Default::default();
    // Each run's stepping time over the run without a bridge of the same repeat (a pair run
    // back to back sees the same load).
    let mut paired: [Vec<f64>; KINDS.len()] = Default::default();
    for r in 0..args.repeats {
        let mut alone = f64::NAN;
        for (k, b) in best.iter_mut().enumerate() {
            tracing::info!("bench bridge: repeat {}/{}, {} ...", r + 1, args.repeats, KINDS[k]);
            let m = one(args, k)?;
            if k == 0 {
                alone = m.stepping;
            }
            paired[k].push(m.stepping / alone);
            *b = (b.0.min(m.stepping), b.1.min(m.whole));
            runs[k].push(m);
        }
    }
    // The middle value, or the mean of the two middle ones.
    let median = |v: Vec<f64>| {
        let mut v = v;
        v.sort_by(f64::total_cmp);
        let n = v.len();
        0.5 * (v[(n - 1) / 2] + v[n / 2])
    };
    let of = |k: usize, f: fn(&Measured) -> f64| median(runs[k].iter().map(f).collect());
    let mut out = format!(
        "machine: {} cores{}; {} for {} s, {} runs of each kind alternating, fastest of each; paired: the median over \
         the repeats of the stepping time over that repeat's run without a bridge; CPU: medians (the run's: its child \
         processes, the participants and the bridge)\n\n\
         | run | stepping s | whole run s | stepping / no bridge | whole / no bridge | paired | bridge CPU s | browser CPU s | run CPU s | run CPU / no bridge |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        cores,
        if args.browser_idle { " (chromium under SCHED_IDLE)" } else { "" },
        args.scene.display(),
        args.duration,
        args.repeats,
    );
    let run_cpu0 = of(0, |m| m.run_cpu);
    for (k, (s, w)) in best.iter().enumerate() {
        let dash = |on: bool, v: f64| if on { format!("{v:.2}") } else { "—".to_string() };
        let rc = of(k, |m| m.run_cpu);
        out.push_str(&format!(
            "| {} | {s:.3} | {w:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {rc:.2} | {:.3} |\n",
            KINDS[k],
            s / best[0].0,
            w / best[0].1,
            median(paired[k].clone()),
            dash(k > 0, of(k, |m| m.bridge_cpu)),
            dash(k == 3, of(k, |m| m.browser_cpu)),
            rc / run_cpu0
        ));
    }
    println!("{out}");
    let table = args.out.join("bridge.md");
    std::fs::File::create(&table)?.write_all(out.as_bytes())?;
    tracing::info!("bench bridge: table written to {}", table.display());
    Ok(())
}
