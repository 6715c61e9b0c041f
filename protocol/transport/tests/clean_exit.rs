//! A participant that leaves the run cleanly is never reported dead, however its exit and a
//! look at the nodes interleave; one whose process ends without leaving is.

use grains_transport::{Transport, ipc};
use std::process::{Command, Stdio};
use std::sync::Arc;

/// Set in a child: the run it joins, and how it leaves ("clean" or "crash").
const CHILD: &str = "GRAINS_TRANSPORT_TEST_CHILD";
const TEST: &str = "a_clean_exit_is_never_seen_dead_and_a_crash_always_is";

/// The child's part: join the run as the oracle, then leave as told.
fn child(spec: &str) {
    let (run_id, how) = spec.split_once(':').expect("run:how");
    let node = ipc::Iceoryx2::join(run_id, "grains-oracle", Arc::new(|| false)).unwrap();
    if how == "crash" {
        // The process ends without the node's removal, as on a kill.
        std::mem::forget(node);
        std::process::abort();
    }
}

/// Runs this test's binary as a child that joins `run_id` and leaves as `how`, calling
/// `dead_peers` as fast as it can until the child is gone; every report seen.
fn watch_one(watcher: &ipc::Iceoryx2, run_id: &str, how: &str) -> Vec<String> {
    let exe = std::env::current_exe().unwrap();
    let mut child = Command::new(exe)
        .args(["--exact", TEST, "--test-threads=1", "--nocapture"])
        .env(CHILD, format!("{run_id}:{how}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut seen = Vec::new();
    while child.try_wait().unwrap().is_none() {
        seen.extend(watcher.dead_peers(&|_| false));
    }
    seen.extend(watcher.dead_peers(&|_| false));
    seen
}

#[test]
fn a_clean_exit_is_never_seen_dead_and_a_crash_always_is() {
    if let Ok(spec) = std::env::var(CHILD) {
        child(&spec);
        return;
    }
    let run_id = format!("test-clean-exit-{}", std::process::id());
    let watcher = ipc::Iceoryx2::join(&run_id, "grains-launch", Arc::new(|| false)).unwrap();
    let runs = 200;
    let mut false_deaths = Vec::new();
    for _ in 0..runs {
        false_deaths.extend(watch_one(&watcher, &run_id, "clean"));
    }
    let crash = watch_one(&watcher, &run_id, "crash");
    drop(watcher);
    ipc::remove_run_files(&run_id);
    assert!(
        false_deaths.is_empty(),
        "{} reports of a death among {runs} clean exits: {:?}",
        false_deaths.len(),
        &false_deaths[..false_deaths.len().min(5)]
    );
    assert!(
        crash.iter().any(|d| d.starts_with("grains-oracle")),
        "a crashed participant was not seen dead: {crash:?}"
    );
}
