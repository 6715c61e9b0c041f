//! `--set key=value` overrides, applied to the scene's TOML document before validation.

use super::SceneError;
use std::path::Path;

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
