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
    grains_launch::run::participants::bin_dir().join(name)
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

/// The launcher's line that announces the run ("grains INFO: run <id> of scene ...").
fn run_line(stderr: &str) -> &str {
    let at = |l: &&str| l.starts_with("grains INFO: run ") && l.contains(" of scene ");
    stderr.lines().find(at).expect("run line")
}

/// The run id from the launcher's first line.
pub fn run_id(stderr: &str) -> String {
    run_line(stderr).split_whitespace().nth(3).expect("run id").to_string()
}

/// The physics of a finished run's `metrics.csv`: its rows without the timing columns (equal
/// between two runs of the same physics, whatever the transport).
pub fn physics(run_dir: &Path) -> String {
    grains_launch::metrics::physics_columns(&std::fs::read_to_string(run_dir.join("metrics.csv")).unwrap())
}

/// The output directory of a run from the launcher's first line.
pub fn run_dir(stderr: &str) -> PathBuf {
    PathBuf::from(run_line(stderr).rsplit("output in ").next().expect("output dir").trim())
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

/// A run's `metrics.csv`, by column name (the launcher's own reader: a missing column fails).
pub fn metrics(dir: &Path) -> grains_launch::metrics::MetricsTable {
    grains_launch::metrics::MetricsTable::read(dir).unwrap_or_else(|e| panic!("{e:#}"))
}

/// Column `name` of a run's metrics, as written.
pub fn column(dir: &Path, name: &str) -> Vec<String> {
    metrics(dir).text(name).unwrap_or_else(|e| panic!("{e:#}")).to_vec()
}

/// Column `name` of a run's metrics, as numbers.
pub fn values(dir: &Path, name: &str) -> Vec<f64> {
    metrics(dir).column(name).unwrap_or_else(|e| panic!("{e:#}"))
}

/// Rows of a running run's `metrics.csv.part` (0 before it exists).
pub fn rows_written(dir: &Path) -> usize {
    std::fs::read_to_string(dir.join("metrics.csv.part")).map_or(0, |t| t.lines().count().saturating_sub(1))
}

/// Waits up to `limit` for `ready`, failing with `what` and the launcher's stderr.
pub fn wait_until(launcher: &Running, what: &str, limit: Duration, mut ready: impl FnMut() -> bool) {
    let deadline = Instant::now() + limit;
    while !ready() {
        assert!(Instant::now() < deadline, "{what} within {limit:?}: {}", launcher.stderr());
        std::thread::sleep(Duration::from_millis(5));
    }
}

pub fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary.json")).expect("json")
}

/// The Python interpreter the test clients in `tests/python/` run with: `GRAINS_PYTHON` if
/// set, else a venv the harness makes once, under the target directory, with the packages of
/// `tests/python/requirements.txt` from PyPI (a fresh machine has Python but not them) and the
/// example participants of `clients/python` (`grains_participants`; a `GRAINS_PYTHON` must
/// have both). A test that needs it fails at once, with the reason, when it cannot be had.
pub fn python() -> PathBuf {
    static PYTHON: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    PYTHON
        .get_or_init(|| match std::env::var_os("GRAINS_PYTHON") {
            Some(p) => Ok(PathBuf::from(p)),
            None => test_venv(),
        })
        .clone()
        .unwrap_or_else(|why| panic!("no Python for the test clients: {why}"))
}

/// Makes (or reuses) `<target>/test-python`; one process at a time (a lock file).
fn test_venv() -> Result<PathBuf, String> {
    let bins = grains_launch::run::participants::bin_dir();
    let target = bins.parent().unwrap_or(&bins).to_path_buf();
    let venv = target.join("test-python");
    let python = venv.join("bin/python");
    let requirements = repo().join("tests/python/requirements.txt");
    let clients = repo().join("clients/python");
    let _lock = FileLock::take(&target.join("test-python.lock"))?;
    let wanted = std::fs::read_to_string(&requirements).map_err(|e| format!("{}: {e}", requirements.display()))?;
    // The stamp names the editable install and its pyproject.toml too, so that a venv made
    // before either changed (a package added, a dependency) is remade.
    let pyproject = std::fs::read_to_string(clients.join("pyproject.toml")).map_err(|e| format!("clients/python/pyproject.toml: {e}"))?;
    let wanted = format!("{wanted}-e {}\n{pyproject}", clients.display());
    let stamp = venv.join("requirements.installed");
    if python.exists() && std::fs::read_to_string(&stamp).is_ok_and(|s| s == wanted) {
        return Ok(python);
    }
    let run = |cmd: &mut Command, what: &str| -> Result<(), String> {
        let out = cmd
            .output()
            .map_err(|e| format!("{what}: cannot start {:?}: {e}", cmd.get_program()))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "{what} failed ({}): {}",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ))
        }
    };
    eprintln!("tests: making the Python venv {} (once)", venv.display());
    run(
        Command::new("python3").args(["-m", "venv", "--clear"]).arg(&venv),
        "python3 -m venv",
    )?;
    run(
        Command::new(&python)
            .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r"])
            .arg(&requirements),
        "pip install -r tests/python/requirements.txt",
    )?;
    // Editable: the venv runs the repository's `clients/python` as it is now, so a change to
    // the example is tested without remaking the venv (the stamp follows requirements.txt
    // only); a plain install would keep testing the copy made with the venv.
    run(
        Command::new(&python)
            .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-e"])
            .arg(&clients),
        "pip install -e clients/python",
    )?;
    std::fs::write(&stamp, wanted).map_err(|e| format!("{}: {e}", stamp.display()))?;
    Ok(python)
}

/// An exclusive lock on a file (flock), released when dropped.
struct FileLock(std::fs::File);

impl FileLock {
    fn take(path: &Path) -> Result<Self, String> {
        let f = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
        use std::os::fd::AsRawFd;
        // SAFETY: flock on a file descriptor this struct owns.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(format!("cannot lock {}", path.display()));
        }
        Ok(FileLock(f))
    }
}

impl Drop for FileLock {
    fn drop(&mut self) {
        use std::os::fd::AsRawFd;
        // SAFETY: unlocks the descriptor this struct owns.
        unsafe { libc::flock(self.0.as_raw_fd(), libc::LOCK_UN) };
    }
}

/// Makes sure `program` runs (`<program> <probe>` starts), installing Debian's `package` if
/// not, as a test makes its Python venv: one installation at a time, the package lists
/// fetched first if the machine has none (a fresh one). Panics, naming both, if it cannot.
pub fn debian(program: &str, probe: &str, package: &str) {
    static APT: Mutex<()> = Mutex::new(());
    let _apt = APT.lock().unwrap_or_else(|e| e.into_inner());
    if Command::new(program).arg(probe).output().is_ok() {
        return;
    }
    let install = || Command::new("apt-get").args(["install", "-y", "-q", package]).output();
    let mut got = install();
    if !got.as_ref().is_ok_and(|o| o.status.success()) {
        let _ = Command::new("apt-get").args(["update", "-q"]).output();
        got = install();
    }
    assert!(
        got.as_ref().is_ok_and(|o| o.status.success()) && Command::new(program).arg(probe).output().is_ok(),
        "this test needs {program} (Debian's {package}), and apt-get could not install it: {got:?}"
    );
}
