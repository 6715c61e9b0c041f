//! `grains bench bridge`: what remote access costs a run. The same scene runs without a
//! bridge, with a bridge and no client, with a bridge and a client that subscribes to the
//! views and never reads them (`grains_bridge::client::stalled_viewer`, a child process
//! stopped with SIGSTOP once its buffers are full), and with the live viewer's page open in
//! headless chromium (Debian's `chromium`; it draws every view), alternating, fastest of the repeats each
//! (the machine is shared: the fastest run is the least disturbed). Figures: wall time of the
//! stepping (release to last row) and of the whole run (start to end, so a bridge that holds up
//! the run's start or end shows), and their ratios to the run without a bridge; and the
//! bridge's own CPU time (from `/proc`), which is what a run pays for a viewer whose browser
//! runs on another machine.
//!
//! `--browser-core N` stands in for that other machine on this one: every run (all four kinds,
//! so that they stay comparable) is held to the other cores and chromium to core N, so the
//! browser's drawing takes nothing from the run while the bridge serving it still does.

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
    /// Hold chromium to this core and every run to the others (a browser on its own machine).
    #[arg(long, value_name = "CORE")]
    pub browser_core: Option<usize>,
}

/// Holds the calling thread, and every process it starts from now on, to `cores`.
fn pin(cores: impl IntoIterator<Item = usize>) -> std::io::Result<()> {
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET and sched_setaffinity take it by
    // pointer for the duration of the call.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for c in cores {
            libc::CPU_SET(c, &mut set);
        }
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            return Err(std::io::Error::last_os_error());
        }
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

/// Opens the viewer page at `http` in headless chromium (held to `core` if given) once the
/// bridge serves it; the browser runs until killed.
fn viewer_page(http: std::net::SocketAddr, core: Option<usize>) -> anyhow::Result<std::process::Child> {
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while std::net::TcpStream::connect(http).is_err() {
        if std::time::Instant::now() > deadline {
            bail!("the viewer page at {http} did not open in 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut chromium = std::process::Command::new("chromium");
    if let Some(c) = core {
        use std::os::unix::process::CommandExt;
        // SAFETY: between fork and exec the closure only makes one system call.
        unsafe { chromium.pre_exec(move || pin([c])) };
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

/// CPU seconds (user + system) of our child process named `name`, if there is one now.
fn child_cpu(name: &str) -> Option<f64> {
    let me = std::process::id().to_string();
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
        // pid (comm) state ppid ... utime stime: fields 14 and 15; comm may hold spaces.
        let (comm, rest) = stat.split_once(" (")?.1.rsplit_once(") ")?;
        let f: Vec<&str> = rest.split_whitespace().collect();
        if comm != name || f.get(1) != Some(&me.as_str()) {
            return None;
        }
        Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / tick)
    })
}

/// Samples the bridge's CPU time every 100 ms until `done`; the last sample (the bridge's
/// total to within 100 ms of its CPU, a few ms at its 5% of a core).
fn bridge_cpu(done: std::sync::Arc<std::sync::atomic::AtomicBool>) -> f64 {
    let mut last = 0.0;
    while !done.load(std::sync::atomic::Ordering::Relaxed) {
        if let Some(s) = child_cpu(grains_protocol::Role::Bridge.binary()) {
            last = s;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    last
}

/// One run of `kind`: stepping and whole wall time [s], and the bridge's CPU time [s].
fn one(args: &BridgeArgs, kind: usize) -> anyhow::Result<(f64, f64, f64)> {
    let connect = free_endpoint()?;
    let http = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?;
    let bridge = (kind > 0).then(|| grains_bridge::config::BridgeArgs {
        listen: vec![connect.clone()],
        view_listen: (kind == 3).then(|| http.to_string()),
        ..Default::default()
    });
    let client = if kind == 2 { Some(stalled_client(&connect)?) } else { None };
    let browser = if kind == 3 {
        let core = args.browser_core;
        Some(std::thread::spawn(move || viewer_page(http, core)))
    } else {
        None
    };
    let mut overrides = vec![format!("run.duration={}", args.duration), "output.frames_every=0".to_string()];
    overrides.extend(args.overrides.iter().cloned());
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sampler = {
        let done = done.clone();
        std::thread::spawn(move || bridge_cpu(done))
    };
    let started = std::time::Instant::now();
    let outcome: anyhow::Result<RunOutcome> = run(&RunOptions {
        bridge,
        ..RunOptions::quiet(args.scene.clone(), args.out.join("runs"), overrides)
    });
    let whole = started.elapsed().as_secs_f64();
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let cpu = sampler.join().expect("the sampler thread");
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
    Ok((outcome.stepping.as_secs_f64(), whole, cpu))
}

pub fn bench(args: &BridgeArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Some(b) = args.browser_core {
        if b >= cores || cores < 2 {
            bail!(
                "--browser-core {b}: this machine has cores 0 to {}, and the runs need one besides the browser's",
                cores - 1
            );
        }
        pin((0..cores).filter(|&c| c != b)).context("holding the runs to the other cores")?;
    }
    let mut best = [(f64::INFINITY, f64::INFINITY); KINDS.len()];
    // The bridge's CPU seconds of each run, for the median.
    let mut cpu: [Vec<f64>; KINDS.len()] = Default::default();
    for r in 0..args.repeats {
        for (k, b) in best.iter_mut().enumerate() {
            tracing::info!("bench bridge: repeat {}/{}, {} ...", r + 1, args.repeats, KINDS[k]);
            let (stepping, whole, c) = one(args, k)?;
            *b = (b.0.min(stepping), b.1.min(whole));
            cpu[k].push(c);
        }
    }
    let mut out = format!(
        "machine: {} cores{}; {} for {} s, {} runs of each kind alternating, fastest of each\n\n\
         | run | stepping s | whole run s | stepping / no bridge | whole / no bridge | bridge CPU s (median) |\n|---|---:|---:|---:|---:|---:|\n",
        cores,
        args.browser_core
            .map_or(String::new(), |b| format!(" (chromium on core {b}, the runs on the others)")),
        args.scene.display(),
        args.duration,
        args.repeats,
    );
    for (k, (s, w)) in best.iter().enumerate() {
        let mut c = cpu[k].clone();
        c.sort_by(f64::total_cmp);
        let c = if k == 0 {
            "—".to_string()
        } else {
            format!("{:.2}", c[c.len() / 2])
        };
        out.push_str(&format!(
            "| {} | {s:.3} | {w:.3} | {:.3} | {:.3} | {c} |\n",
            KINDS[k],
            s / best[0].0,
            w / best[0].1
        ));
    }
    println!("{out}");
    let table = args.out.join("bridge.md");
    std::fs::File::create(&table)?.write_all(out.as_bytes())?;
    tracing::info!("bench bridge: table written to {}", table.display());
    Ok(())
}
