//! Field paths and `--set key=value` overrides, applied to the scene's TOML document before
//! validation.

use super::SceneError;
use std::path::Path;
use std::str::FromStr;

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

    /// The value at this path in `doc`, if there is one.
    pub(super) fn get<'a>(&self, doc: &'a toml::Value) -> Option<&'a toml::Value> {
        self.segments.iter().try_fold(doc, |node, segment| match (node, segment) {
            (toml::Value::Table(t), segment) => t.get(&segment.to_string()),
            (toml::Value::Array(a), PathSegment::Index(i)) => a.get(*i),
            _ => None,
        })
    }

    /// Puts `value` at this path in `doc`. Missing tables on the way are created (a list where
    /// the next step is an index, so that `body.0.model` in a scene without bodies says the list
    /// is empty); list entries must exist. The error says which step failed and why.
    pub(super) fn set(&self, doc: &mut toml::Value, value: toml::Value) -> Result<(), String> {
        let Some((last, steps)) = self.segments.split_last() else {
            return Err("empty key".into());
        };
        let mut node = doc;
        for (k, segment) in steps.iter().enumerate() {
            let next_is_index = matches!(self.segments[k + 1], PathSegment::Index(_));
            node = match (node, segment) {
                (toml::Value::Table(t), segment) => t.entry(segment.to_string()).or_insert_with(|| {
                    if next_is_index {
                        toml::Value::Array(Vec::new())
                    } else {
                        toml::Value::Table(toml::Table::new())
                    }
                }),
                (toml::Value::Array(a), segment) => entry(a, segment)?,
                (_, segment) => return Err(format!("`{segment}` is inside a value, not a table or list")),
            };
        }
        match (node, last) {
            (toml::Value::Table(t), segment) => {
                t.insert(segment.to_string(), value);
            }
            (toml::Value::Array(a), segment) => *entry(a, segment)? = value,
            (_, segment) => return Err(format!("`{segment}` is inside a value, not a table or list")),
        }
        Ok(())
    }
}

/// The entry of list `a` that `segment` names, which must be an index in range.
fn entry<'a>(a: &'a mut [toml::Value], segment: &PathSegment) -> Result<&'a mut toml::Value, String> {
    let n = a.len();
    match segment {
        PathSegment::Index(i) => a
            .get_mut(*i)
            .ok_or_else(|| format!("index {i} is out of range: the list has {n} entries")),
        PathSegment::Key(k) => Err(format!("`{k}` must be an index into a list of {n} entries")),
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

impl FromStr for FieldPath {
    type Err = OverrideParseError;

    /// Dotted keys; a part of digits only is a list index.
    fn from_str(text: &str) -> Result<FieldPath, OverrideParseError> {
        let mut path = FieldPath::default();
        for part in text.split('.').map(str::trim) {
            if part.is_empty() {
                return Err(OverrideParseError {
                    field: text.trim().into(),
                    message: format!(
                        "`{}` has an empty key: write dotted keys and list indices, e.g. body.0.max",
                        text.trim()
                    ),
                });
            }
            path.push(match part.parse() {
                Ok(i) if part.bytes().all(|b| b.is_ascii_digit()) => PathSegment::Index(i),
                _ => PathSegment::Key(part.into()),
            });
        }
        Ok(path)
    }
}

/// A `--set key=value` override: a field and a TOML value for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    pub path: FieldPath,
    pub value: toml::Value,
}

/// A `--set` (or a field path) that cannot be read: which field, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OverrideParseError {
    /// The field as written (all of the override when it has no `=`).
    pub field: String,
    pub message: String,
}

impl std::fmt::Display for OverrideParseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for OverrideParseError {}

impl FromStr for Override {
    type Err = OverrideParseError;

    /// `key=value`: a [`FieldPath`], then a value in TOML syntax (`body.0.max=[0.04, 0.16]`,
    /// `oracle.kind="surface"`).
    fn from_str(o: &str) -> Result<Override, OverrideParseError> {
        let Some((key, value)) = o.split_once('=') else {
            return Err(OverrideParseError {
                field: o.into(),
                message: format!("--set {o:?}: expected key=value, e.g. coupling.substeps=20"),
            });
        };
        let key = key.trim();
        let err = |message: String| OverrideParseError {
            field: key.into(),
            message: format!("--set {o:?}: {message}"),
        };
        let path = key.parse::<FieldPath>().map_err(|e| err(e.message))?;
        let value = format!("v = {}", value.trim())
            .parse::<toml::Table>()
            .map_err(|e| err(format!("the value is not TOML: {}", e.message())))?
            .remove("v")
            .expect("parsed above");
        Ok(Override { path, value })
    }
}

impl std::fmt::Display for Override {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}={}", self.path, self.value)
    }
}

/// Applies the overrides to `doc` in turn; `written` are they as the user wrote them, for
/// messages.
pub(super) fn apply(scene_path: &Path, doc: &mut toml::Value, overrides: &[Override], written: &[String]) -> Result<(), SceneError> {
    for (o, text) in overrides.iter().zip(written) {
        o.path.set(doc, o.value.clone()).map_err(|m| SceneError {
            path: scene_path.into(),
            line_col: None,
            field: Some(o.path.to_string()),
            message: format!("--set {text:?}: {m}"),
        })?;
    }
    Ok(())
}

/// Reads `--set` overrides; an error names the scene file, the field and what is wrong.
pub(super) fn parse(scene_path: &Path, written: &[String]) -> Result<Vec<Override>, SceneError> {
    written
        .iter()
        .map(|o| {
            o.parse().map_err(|e: OverrideParseError| SceneError {
                path: scene_path.into(),
                line_col: None,
                field: Some(e.field),
                message: e.message,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{FieldPath, Override, PathSegment};

    #[test]
    fn field_paths_parse_and_display_round_trip() {
        let path: FieldPath = "material.0.dem.radius".parse().unwrap();
        assert_eq!(path, FieldPath::root("material").index(0).key("dem").key("radius"));
        assert_eq!(path.segments()[1], PathSegment::Index(0));
        assert_eq!(path.to_string(), "material.0.dem.radius");
        for text in ["run.dt", "body.12.packing", "wall.0.to", "gravity"] {
            assert_eq!(text.parse::<FieldPath>().unwrap().to_string(), text);
        }
        assert_eq!(" wall . 1 ".parse::<FieldPath>().unwrap().to_string(), "wall.1");
        assert_eq!("+1".parse::<FieldPath>().unwrap().segments(), [PathSegment::Key("+1".into())]);
        let e = "run..dt".parse::<FieldPath>().unwrap_err();
        assert!(e.message.contains("empty key"), "{e}");
    }

    #[test]
    fn overrides_parse_and_display_round_trip() {
        for text in [
            "body.0.max=[0.04, 0.16]",
            "coupling.substeps=20",
            "oracle.kind=\"surface\"",
            "run.dt=0.0001",
            "bridge.enabled=true",
        ] {
            let o: Override = text.parse().unwrap();
            assert_eq!(o.to_string(), text);
            assert_eq!(o.to_string().parse::<Override>().unwrap(), o);
        }
        let o: Override = " body.1.packing = \"bed.data\" ".parse().unwrap();
        assert_eq!(o.path, FieldPath::root("body").index(1).key("packing"));
        assert_eq!(o.value, toml::Value::String("bed.data".into()));
    }

    #[test]
    fn overrides_that_cannot_be_read_say_why_as_before() {
        let e = "bogus".parse::<Override>().unwrap_err();
        assert_eq!(e.field, "bogus");
        assert_eq!(e.message, "--set \"bogus\": expected key=value, e.g. coupling.substeps=20");
        let e = "run.dt = ".parse::<Override>().unwrap_err();
        assert_eq!(e.field, "run.dt");
        assert!(e.message.starts_with("--set \"run.dt = \": the value is not TOML: "), "{e}");
    }

    #[test]
    fn typed_edits_create_tables_and_refuse_missing_entries() {
        let mut doc = toml::Value::Table("[run]\ndt = 1.0\n[[body]]\nmodel = \"dem\"\n".parse().unwrap());
        let set = |doc: &mut toml::Value, path: &str, value: toml::Value| path.parse::<FieldPath>().unwrap().set(doc, value);
        set(&mut doc, "coupling.substeps", toml::Value::Integer(20)).unwrap();
        set(&mut doc, "body.0.model", toml::Value::String("mpm".into())).unwrap();
        let get = |doc: &toml::Value, path: &str| path.parse::<FieldPath>().unwrap().get(doc).cloned();
        assert_eq!(get(&doc, "coupling.substeps"), Some(toml::Value::Integer(20)));
        assert_eq!(get(&doc, "body.0.model"), Some(toml::Value::String("mpm".into())));
        let one = toml::Value::Integer(1);
        let e = set(&mut doc, "body.1.model", one.clone()).unwrap_err();
        assert_eq!(e, "index 1 is out of range: the list has 1 entries");
        assert_eq!(
            set(&mut doc, "body.first", one.clone()).unwrap_err(),
            "`first` must be an index into a list of 1 entries"
        );
        assert_eq!(
            set(&mut doc, "run.dt.x", one.clone()).unwrap_err(),
            "`x` is inside a value, not a table or list"
        );
        assert_eq!(
            set(&mut doc, "wall.0.to", one).unwrap_err(),
            "index 0 is out of range: the list has 0 entries"
        );
    }
}
