//! Helpers of the system tests: start the real `grains` binary, follow its stderr, wait with
//! deadlines (a hung test fails, it never blocks CI), find a run's leftover files.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Heavy runs take the machine's two cores; tests that run them take this lock so that they
/// run one after another (the two-runs-at-once test runs its two inside one lock).
pub fn machine() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The repository root (scenes are given relative to it).
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ is in the repository")
        .to_path_buf()
}

pub fn bin(name: &str) -> PathBuf {
    grains_launch::participants::bin_dir().join(name)
}

/// A fresh output directory for one test.
pub fn out_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("grains-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A running program whose stderr is collected line by line.
pub struct Running {
    pub child: Child,
    stderr: Arc<Mutex<String>>,
}

impl Running {
    pub fn start(program: &Path, args: &[&str]) -> Running {
        Running::start_with_env(program, args, &[])
    }

    /// As [`Running::start`], with extra environment variables.
    pub fn start_with_env(program: &Path, args: &[&str], env: &[(&str, &str)]) -> Running {
        let mut child = Command::new(program)
            .args(args)
            .envs(env.iter().copied())
            .current_dir(repo())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "cannot start {}: {e} (build the binaries first: cargo build --release --workspace --bins)",
                    program.display()
                )
            });
        let stderr = Arc::new(Mutex::new(String::new()));
        let pipe = child.stderr.take().expect("piped");
        let sink = stderr.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                let mut s = sink.lock().expect("lock");
                s.push_str(&line);
                s.push('\n');
            }
        });
        Running { child, stderr }
    }

    pub fn grains(args: &[&str]) -> Running {
        Running::start(&bin("grains"), args)
    }

    pub fn stderr(&self) -> String {
        self.stderr.lock().expect("lock").clone()
    }

    /// Waits until stderr contains `needle`; panics with the stderr so far after `limit`.
    pub fn wait_for(&mut self, needle: &str, limit: Duration) -> String {
        let deadline = Instant::now() + limit;
        loop {
            let text = self.stderr();
            if text.contains(needle) {
                return text;
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                std::thread::sleep(Duration::from_millis(50));
                let text = self.stderr();
                if text.contains(needle) {
                    return text;
                }
                panic!("exited ({status}) before printing {needle:?}; stderr:\n{text}");
            }
            assert!(Instant::now() < deadline, "no {needle:?} within {limit:?}; stderr:\n{text}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the exit; kills and panics after `limit`.
    pub fn wait_exit(&mut self, limit: Duration) -> ExitStatus {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().expect("wait") {
                std::thread::sleep(Duration::from_millis(50)); // let the stderr reader catch up
                return status;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                panic!("did not exit within {limit:?}; stderr:\n{}", self.stderr());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The run id from the launcher's first line ("grains: run <id> of scene ...").
pub fn run_id(stderr: &str) -> String {
    let line = stderr.lines().find(|l| l.starts_with("grains: run ")).expect("run line");
    line.split_whitespace().nth(2).expect("run id").to_string()
}

/// The output directory of a run from the launcher's first line.
pub fn run_dir(stderr: &str) -> PathBuf {
    let line = stderr.lines().find(|l| l.starts_with("grains: run ")).expect("run line");
    PathBuf::from(line.rsplit("output in ").next().expect("output dir").trim())
}

/// pid of a participant from the launcher's "started as processes: ..." line.
pub fn pid_of(stderr: &str, binary: &str) -> i32 {
    let line = stderr.lines().find(|l| l.contains("started as processes:")).expect("started line");
    let at = line
        .find(&format!("{binary} (pid "))
        .unwrap_or_else(|| panic!("{binary} not in {line:?}"));
    let rest = &line[at + binary.len() + 6..];
    rest[..rest.find(')').expect(")")].parse().expect("pid")
}

/// Rows of a metrics file (without the header).
pub fn metrics_rows(dir: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    text.lines().skip(1).map(|l| l.split(',').map(str::to_string).collect()).collect()
}

pub fn column(dir: &Path, name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).expect("metrics");
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let k = header.iter().position(|c| *c == name).unwrap_or_else(|| panic!("no column {name}"));
    metrics_rows(dir).into_iter().map(|r| r[k].clone()).collect()
}

pub fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary.json")).expect("json")
}
