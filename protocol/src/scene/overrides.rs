//! Field paths and `--set key=value` overrides, applied to the scene's TOML document before
//! validation.

use super::SceneError;
use std::path::Path;

/// A field of the scene file as `--set` and every [`SceneError`] spell it: dotted keys, list
/// entries by index (`material.0.dem.radius`, `body.1.packing`, `wall.0.to`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct FieldPath {
    segments: Vec<PathSegment>,
}

/// One step of a [`FieldPath`].
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum PathSegment {
    /// A key of a table (`domain`, `cell_size`).
    Key(String),
    /// An entry of a list (`[[body]]` tables, vector components).
    Index(usize),
}

impl FieldPath {
    /// The path of a top-level key (`FieldPath::root("wall").index(0).key("to")` is `wall.0.to`).
    pub fn root(key: impl Into<String>) -> FieldPath {
        FieldPath::default().key(key)
    }

    pub fn key(mut self, key: impl Into<String>) -> FieldPath {
        self.segments.push(PathSegment::Key(key.into()));
        self
    }

    pub fn index(mut self, index: usize) -> FieldPath {
        self.segments.push(PathSegment::Index(index));
        self
    }

    pub fn push(&mut self, segment: PathSegment) {
        self.segments.push(segment);
    }

    pub fn segments(&self) -> &[PathSegment] {
        &self.segments
    }
}

impl std::fmt::Display for PathSegment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PathSegment::Key(k) => f.write_str(k),
            PathSegment::Index(i) => write!(f, "{i}"),
        }
    }
}

impl std::fmt::Display for FieldPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (k, segment) in self.segments.iter().enumerate() {
            if k > 0 {
                f.write_str(".")?;
            }
            write!(f, "{segment}")?;
        }
        Ok(())
    }
}

/// Applies `--set key=value` overrides (dotted keys, list entries by index: `body.0.max=[0.1,
/// 0.2]`, values in TOML syntax) to the scene text and returns the edited text.
pub(super) fn apply(path: &Path, text: &str, overrides: &[String]) -> Result<String, SceneError> {
    let err = |field: &str, message: String| SceneError {
        path: path.into(),
        line_col: None,
        field: Some(field.into()),
        message,
    };
    let mut doc = toml::Value::Table(text.parse::<toml::Table>().map_err(|e| err("", e.message().to_string()))?);
    for o in overrides {
        let Some((key, value)) = o.split_once('=') else {
            return Err(err(o, format!("--set {o:?}: expected key=value, e.g. coupling.substeps=20")));
        };
        let key = key.trim();
        let value = format!("v = {}", value.trim())
            .parse::<toml::Table>()
            .map_err(|e| err(key, format!("--set {o:?}: the value is not TOML: {}", e.message())))?
            .remove("v")
            .expect("parsed above");
        let parts: Vec<&str> = key.split('.').collect();
        set_path(&mut doc, &parts, value).map_err(|m| err(key, format!("--set {o:?}: {m}")))?;
    }
    toml::to_string(&doc).map_err(|e| err("", format!("cannot write the overridden scene: {e}")))
}

fn set_path(node: &mut toml::Value, parts: &[&str], value: toml::Value) -> Result<(), String> {
    let Some((first, rest)) = parts.split_first() else {
        return Err("empty key".into());
    };
    let child = match node {
        toml::Value::Table(t) => {
            if rest.is_empty() {
                t.insert(first.to_string(), value);
                return Ok(());
            }
            t.entry(first.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()))
        }
        toml::Value::Array(a) => {
            let n = a.len();
            let idx: usize = first
                .parse()
                .map_err(|_| format!("`{first}` must be an index into a list of {n} entries"))?;
            let child = a
                .get_mut(idx)
                .ok_or_else(|| format!("index {idx} is out of range: the list has {n} entries"))?;
            if rest.is_empty() {
                *child = value;
                return Ok(());
            }
            child
        }
        _ => return Err(format!("`{first}` is inside a value, not a table or list")),
    };
    set_path(child, rest, value)
}
