//! Issue 25: a participant on another host. The test makes a network namespace with a veth
//! pair to this one (traffic only between the two), runs the launcher here with
//! `--transport zenoh` listening on its end, and the MPM in the namespace, joined by the
//! endpoint the launcher prints. The physics is the iceoryx2 run's, byte for byte; killing
//! the remote MPM ends the run within 2 s, naming it.

use super::{printed_command, run_to_end};
use grains_system_tests::*;
use std::process::Command;
use std::time::{Duration, Instant};

/// A network namespace joined to this one by a veth pair; removed when dropped.
struct Namespace {
    name: String,
    /// This side's address and the namespace's.
    here: String,
}

impl Namespace {
    fn new() -> Namespace {
        grains_system_tests::debian("ip", "-V", "iproute2");
        let id = std::process::id() % 100_000;
        let (name, host, peer) = (format!("grains-{id}"), format!("gv{id}h"), format!("gv{id}r"));
        let net = format!("10.231.{}", id % 250);
        let ip = |args: &[&str]| {
            let out = Command::new("ip").args(args).output().expect("ip (iproute2)");
            assert!(
                out.status.success(),
                "ip {}: {} (this test makes a network namespace: it needs root or CAP_NET_ADMIN)",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr).trim()
            );
        };
        let _ = Command::new("ip").args(["netns", "del", &name]).output();
        ip(&["netns", "add", &name]);
        let ns = Namespace {
            name: name.clone(),
            here: format!("{net}.1"),
        };
        ip(&["link", "add", &host, "type", "veth", "peer", "name", &peer]);
        ip(&["link", "set", &peer, "netns", &name]);
        ip(&["addr", "add", &format!("{net}.1/24"), "dev", &host]);
        ip(&["link", "set", &host, "up"]);
        ip(&["netns", "exec", &name, "ip", "addr", "add", &format!("{net}.2/24"), "dev", &peer]);
        ip(&["netns", "exec", &name, "ip", "link", "set", &peer, "up"]);
        ip(&["netns", "exec", &name, "ip", "link", "set", "lo", "up"]);
        ns
    }

    /// `printed` (a participant's command line as the launcher prints it) in the namespace.
    fn start(&self, printed: &str) -> Running {
        let command = format!("exec ip netns exec {} {printed}", self.name);
        Running::start(std::path::Path::new("sh"), &["-c", &command])
    }
}

impl Drop for Namespace {
    fn drop(&mut self) {
        // The namespace's end of the pair goes with it, and the pair with its end.
        let _ = Command::new("ip").args(["netns", "del", &self.name]).output();
    }
}

fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("addr").port()
}

#[test]
fn an_mpm_in_another_network_namespace_gives_the_same_physics_and_its_death_ends_the_run() {
    let _machine = machine();
    let ns = Namespace::new();
    let out = out_dir("remote");
    let out_s = out.to_str().unwrap();
    let scene = "tests/scenes/hybrid_small_2d.toml";
    let (status, err) = run_to_end(&["run", scene, "--out", out_s, "--quiet", "--set", "run.steps=200"]);
    assert!(status.success(), "{err}");
    let local = run_dir(&err);

    let listen = format!("tcp/{}:{}", ns.here, free_port());
    let zenoh_run = |steps: &str| {
        Running::grains(&[
            "run",
            scene,
            "--out",
            out_s,
            "--quiet",
            "--set",
            steps,
            "--transport",
            "zenoh",
            "--zenoh-listen",
            &listen,
            "--external",
            "mpm",
        ])
    };
    let mut launcher = zenoh_run("run.steps=200");
    let printed = printed_command(&mut launcher, "mpm");
    assert!(printed.contains(&format!("--zenoh {listen}")), "{printed}");
    let mut mpm = ns.start(&printed);
    assert!(launcher.wait_exit(Duration::from_secs(120)).success(), "{}", launcher.stderr());
    assert!(mpm.wait_exit(Duration::from_secs(30)).success(), "{}", mpm.stderr());
    let remote = run_dir(&launcher.stderr());
    let s = summary(&remote);
    assert_eq!(s["transport"], "zenoh", "{s}");
    assert_eq!(physics(&local).lines().count(), 201);
    assert_eq!(
        physics(&remote),
        physics(&local),
        "the remote MPM's run differs from the iceoryx2 run"
    );

    // The remote MPM killed mid-run: the run fails within 2 s, naming it.
    let mut launcher = zenoh_run("run.steps=1000000");
    let printed = printed_command(&mut launcher, "mpm");
    let mut mpm = ns.start(&printed);
    let dir = run_dir(&launcher.stderr());
    wait_until(&launcher, "the run did not start", Duration::from_secs(60), || {
        rows_written(&dir) >= 19
    });
    mpm.child.kill().expect("SIGKILL the remote MPM");
    let killed = Instant::now();
    let status = launcher.wait_exit(Duration::from_secs(30));
    let took = killed.elapsed();
    eprintln!("the run ended {took:?} after the remote MPM was killed");
    assert_eq!(status.code(), Some(1), "{}", launcher.stderr());
    assert!(
        took < Duration::from_secs(2),
        "the run took {took:?} to end after the remote MPM died"
    );
    assert!(launcher.stderr().contains("grains-mpm"), "{}", launcher.stderr());
    std::fs::remove_dir_all(&out).unwrap();
}
