//! Fixtures of the scene tests.

use super::{SceneError, from_str};
use std::path::Path;

/// The smallest valid scene: a synthetic exchange.
pub const GOOD: &str = r#"
schema = 1
[run]
dimension = 2
dt = 1e-4
steps = 10
[domain]
min = [0.0, 0.0]
max = [1.0, 1.0]
cell_size = 0.01
[synthetic]
dem_nodes = 100
mpm_nodes = 50
"#;

/// A DEM scene with two materials, a body and two walls; every value below is written once,
/// so that a test can change one with `replace`.
pub const DEM: &str = r#"
schema = 1
gravity = [0.0, -9.81]
[run]
dimension = 2
dt = 1e-5
steps = 10
[domain]
min = [0.0, 0.0]
max = [0.1, 0.1]
cell_size = 0.002

[[material]]
name = "glass"
density = 2500.0
[material.dem]
radius = 5e-4
stiffness_normal = 1e6
restitution = 0.5
friction = 0.5

[[material]]
name = "sand"
density = 2650.0
[material.dem]
radius = 4e-4
stiffness_normal = 2e6
damping = 7.0
friction = 0.4

[[body]]                  # the column
material = "sand"
model = "dem"
shape = "box"
min = [0.0, 0.0]
max = [0.05, 0.05]

[[wall]]
kind = "plane"
point = [0.0, 0.0]
normal = [0.0, 1.0]

[[wall]]
kind = "segment"
from = [0.0, 0.05]
to = [0.05, 0.05]
friction = 0.3
"#;

/// `text` with the first `from` replaced by `to`, which must be there.
pub fn edit(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "the fixture has no {from:?}");
    text.replacen(from, to, 1)
}

/// The 1-based line of `text` that starts with `needle`.
pub fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.starts_with(needle)).expect("the line is in the text") + 1
}

/// Validates `text` and returns its error, which must be there.
pub fn refused(text: &str) -> SceneError {
    from_str(text, Path::new("s.toml"), 0).expect_err("must be refused")
}

pub fn check_err(text: &str, line: Option<usize>, field: &str, needle: &str) {
    let err = refused(text);
    assert_eq!(err.line_col.map(|l| l.0), line, "{err}");
    assert_eq!(err.field.as_deref(), Some(field), "{err}");
    assert!(err.message.contains(needle), "{err}");
}

/// A fresh directory under the system's temporary one, removed when dropped.
pub struct TempDir(pub std::path::PathBuf);

impl TempDir {
    /// `name` must differ between the tests that run at once.
    pub fn new(name: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("grains-scene-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("creating a temporary directory");
        TempDir(dir)
    }

    /// Writes `text` to `name` in the directory and returns its path.
    pub fn write(&self, name: &str, text: &str) -> std::path::PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, text).expect("writing a test file");
        path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
