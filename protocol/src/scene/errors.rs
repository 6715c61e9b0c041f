//! [`SceneError`] and the checks every section shares: where a value sits in the file (line,
//! column, field) and whether it is in range.

use super::overrides::{FieldPath, PathSegment};
use crate::number;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// A scene file that cannot be used, with where and why.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    pub path: PathBuf,
    /// 1-based line and column, when the problem has a place in the file.
    pub line_col: Option<(usize, usize)>,
    /// Dotted field path (`domain.cell_size`), when known.
    pub field: Option<String>,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some((line, col)) = self.line_col {
            write!(f, ":{line}:{col}")?;
        }
        if let Some(field) = &self.field {
            write!(f, ": field `{field}`")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for SceneError {}

/// The text being validated and the file it came from: turns spans into line and column.
pub(super) struct Ctx<'a> {
    pub text: &'a str,
    pub path: &'a Path,
}

impl Ctx<'_> {
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        (line, col)
    }

    pub fn err(&self, span: Option<Range<usize>>, field: Option<&str>, message: String) -> SceneError {
        SceneError {
            path: self.path.to_path_buf(),
            line_col: span.map(|s| self.line_col(s.start)),
            field: field.map(str::to_string),
            message,
        }
    }

    /// A serde/TOML error: keep its message, add the field written on the offending line.
    pub fn toml_error(&self, e: &toml::de::Error) -> SceneError {
        let span = e.span();
        let field = span.clone().and_then(|s| self.field_on_line_of(s.start)).map(|f| f.to_string());
        let message = e.message().trim().replace('\n', " ");
        SceneError {
            path: self.path.to_path_buf(),
            line_col: span.map(|s| self.line_col(s.start)),
            field,
            message,
        }
    }

    /// The field written on the line of `offset`: its dotted key inside the table the line
    /// sits in (`wall.1.friction` for a key of the second `[[wall]]`), or that table itself
    /// when the line is its header.
    fn field_on_line_of(&self, offset: usize) -> Option<FieldPath> {
        let start = self.text[..offset.min(self.text.len())].rfind('\n').map_or(0, |i| i + 1);
        let line = self.text[start..].lines().next()?;
        if header(line).is_some() {
            let end = start + line.len();
            return Some(table_at(&self.text[..end]));
        }
        let (key, _) = line.split_once('=')?;
        let key = key.trim();
        let ok = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '-');
        if !ok {
            return None;
        }
        let mut field = table_at(&self.text[..start]);
        for k in key.split('.') {
            field.push(PathSegment::Key(k.into()));
        }
        Some(field)
    }

    /// The file a path field names: relative paths are relative to the scene file's directory.
    pub fn file(&self, written: &str) -> PathBuf {
        resolve(self.path, written)
    }

    /// The file the path field `field` names ([`Ctx::file`]), which must exist: else an error
    /// "no `what` at <path>" (with `hint` after the rule for relative paths).
    pub fn existing_file(&self, p: &toml::Spanned<String>, field: &str, what: &str, hint: &str) -> Result<PathBuf, SceneError> {
        let path = self.file(p.get_ref());
        if path.is_file() {
            return Ok(path);
        }
        Err(self.err(
            Some(p.span()),
            Some(field),
            format!("no {what} at {} (paths are relative to the scene file{hint})", path.display()),
        ))
    }
}

/// The file a path field of the scene at `scene_path` names: relative to the scene file's
/// directory unless absolute.
pub(super) fn resolve(scene_path: &Path, written: &str) -> PathBuf {
    scene_path.parent().unwrap_or(Path::new(".")).join(written)
}

/// The table the end of `text` is in, with the index of every array-of-tables entry on the
/// way: a `[[name]]` header opens entry n of `name` after n such headers (so `[material.dem]`
/// after the third `[[material]]` is `material.2.dem`).
fn table_at(text: &str) -> FieldPath {
    // Entries so far of every array of tables, by its path (`material`, `material.2.layer`).
    let mut entries: Vec<(String, usize)> = Vec::new();
    let mut table = FieldPath::default();
    for (is_array, keys) in text.lines().filter_map(header) {
        let mut path = FieldPath::default();
        for (k, key) in keys.iter().enumerate() {
            path.push(PathSegment::Key(key.clone()));
            let name = path.to_string();
            let seen = entries.iter_mut().find(|(n, _)| *n == name);
            if is_array && k + 1 == keys.len() {
                let n = match seen {
                    Some((_, n)) => {
                        *n += 1;
                        *n
                    }
                    None => {
                        entries.push((name, 1));
                        1
                    }
                };
                path.push(PathSegment::Index(n - 1));
            } else if let Some((_, n)) = seen {
                path.push(PathSegment::Index(*n - 1));
            }
        }
        table = path;
    }
    table
}

/// The keys of a table header line (`[domain]`, `[[body]]  # the column`, `[material.dem]`)
/// and whether it opens an entry of an array of tables; `None` for any other line.
fn header(line: &str) -> Option<(bool, Vec<String>)> {
    let line = line.trim();
    let (is_array, rest) = match line.strip_prefix("[[") {
        Some(rest) => (true, rest),
        None => (false, line.strip_prefix('[')?),
    };
    let (name, after) = rest.split_once(if is_array { "]]" } else { "]" })?;
    let after = after.trim_start();
    if !(after.is_empty() || after.starts_with('#')) {
        return None;
    }
    let keys: Vec<String> = name
        .split('.')
        .map(|k| k.trim().trim_matches(|c| c == '"' || c == '\'').to_string())
        .collect();
    let bare = |k: &String| !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    keys.iter().all(bare).then_some((is_array, keys))
}

pub(super) fn vec3(ctx: &Ctx, dim: usize, v: &Spanned<Vec<f64>>, field: &str) -> Result<[f64; 3], SceneError> {
    if v.get_ref().len() != dim {
        return Err(ctx.err(
            Some(v.span()),
            Some(field),
            format!("expected {dim} components for a {dim}D scene, got {}", v.get_ref().len()),
        ));
    }
    if let Some(x) = v.get_ref().iter().find(|x| !x.is_finite()) {
        return Err(ctx.err(
            Some(v.span()),
            Some(field),
            format!("components must be finite, got {}", number(*x)),
        ));
    }
    let mut out = [0.0; 3];
    out[..dim].copy_from_slice(v.get_ref());
    Ok(out)
}

/// The corners of a box, `max` above `min` in every component; `f` names the fields.
pub(super) fn box_corners(
    ctx: &Ctx,
    dim: usize,
    min: &Spanned<Vec<f64>>,
    max: &Spanned<Vec<f64>>,
    f: &dyn Fn(&str) -> String,
) -> Result<([f64; 3], [f64; 3]), SceneError> {
    let lo = vec3(ctx, dim, min, &f("min"))?;
    let hi = vec3(ctx, dim, max, &f("max"))?;
    if (0..dim).any(|k| hi[k] <= lo[k]) {
        return Err(ctx.err(
            Some(max.span()),
            Some(&f("max")),
            "must be greater than `min` in every component".into(),
        ));
    }
    Ok((lo, hi))
}

/// Checks `lo < x < hi` (open or closed ends as given) and finiteness.
pub(super) fn in_range(ctx: &Ctx, v: &Spanned<f64>, field: &str, lo: Bound, hi: Bound) -> Result<f64, SceneError> {
    let x = *v.get_ref();
    let ok = x.is_finite() && lo.below(x) && hi.above(x);
    if ok {
        Ok(x)
    } else {
        Err(ctx.err(
            Some(v.span()),
            Some(field),
            format!("must be {}{}, got {}", lo.describe_lo(), hi.describe_hi(), number(x)),
        ))
    }
}

/// One end of an allowed range.
#[derive(Clone, Copy)]
pub(super) enum Bound {
    Open(f64),
    Closed(f64),
    None,
}

impl Bound {
    fn below(self, x: f64) -> bool {
        match self {
            Bound::Open(b) => x > b,
            Bound::Closed(b) => x >= b,
            Bound::None => true,
        }
    }
    fn above(self, x: f64) -> bool {
        match self {
            Bound::Open(b) => x < b,
            Bound::Closed(b) => x <= b,
            Bound::None => true,
        }
    }
    fn describe_lo(self) -> String {
        match self {
            Bound::Open(b) => format!("> {b}"),
            Bound::Closed(b) => format!(">= {b}"),
            Bound::None => "finite".into(),
        }
    }
    fn describe_hi(self) -> String {
        match self {
            Bound::Open(b) => format!(" and < {b}"),
            Bound::Closed(b) => format!(" and <= {b}"),
            Bound::None => String::new(),
        }
    }
}

pub(super) fn positive(ctx: &Ctx, v: &Spanned<f64>, field: &str) -> Result<f64, SceneError> {
    in_range(ctx, v, field, Bound::Open(0.0), Bound::None)
}

/// An optional value `>= 0`, 0 when absent.
pub(super) fn non_negative(ctx: &Ctx, v: &Option<Spanned<f64>>, field: &str) -> Result<f64, SceneError> {
    v.as_ref()
        .map_or(Ok(0.0), |v| in_range(ctx, v, field, Bound::Closed(0.0), Bound::None))
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of, refused};

    #[test]
    fn serde_errors_name_the_entry_of_a_list_of_tables() {
        let text = edit(DEM, "friction = 0.3", "friction = \"rough\"");
        check_err(
            &text,
            Some(line_of(&text, "friction = \"rough\"")),
            "wall.1.friction",
            "invalid type",
        );
        let text = edit(DEM, "normal = [0.0, 1.0]", "normal = [0.0, 1.0]\nbogus = 1");
        check_err(&text, Some(line_of(&text, "bogus")), "wall.0.bogus", "unknown field");
    }

    #[test]
    fn serde_errors_in_a_sub_table_name_the_entry_it_belongs_to() {
        let text = edit(DEM, "damping = 7.0", "damping = \"x\"");
        check_err(&text, Some(line_of(&text, "damping")), "material.1.dem.damping", "invalid type");
        let text = edit(DEM, "density = 2500.0", "density = \"heavy\"");
        check_err(
            &text,
            Some(line_of(&text, "density = \"heavy\"")),
            "material.0.density",
            "invalid type",
        );
    }

    #[test]
    fn a_comment_after_a_header_is_not_part_of_the_field() {
        let text = edit(DEM, "shape = \"box\"", "shape = 3");
        check_err(&text, Some(line_of(&text, "shape = 3")), "body.0.shape", "invalid type");
    }

    #[test]
    fn an_error_on_a_header_line_names_its_table() {
        let text = edit(DEM, "kind = \"segment\"\n", "");
        let err = refused(&text);
        assert!(err.message.contains("missing field `kind`"), "{err}");
        assert_eq!(err.field.as_deref(), Some("wall.1"), "{err}");
    }

    #[test]
    fn refused_values_are_echoed_in_short_notation() {
        let text = edit(DEM, "dt = 1e-5", "dt = -1e308");
        check_err(&text, Some(line_of(&text, "dt")), "run.dt", "must be > 0, got -1e308");
        let text = format!("{DEM}[coupling]\nweight = 1e308\n");
        let err = refused(&text);
        assert!(err.message.ends_with("must be > 0 and < 1, got 1e308"), "{err}");
        let text = edit(DEM, "radius = 5e-4", "radius = -2.5e-9");
        check_err(&text, Some(line_of(&text, "radius")), "material.0.dem.radius", "got -2.5e-9");
    }

    #[test]
    fn a_line_of_a_multiline_array_is_not_a_header() {
        assert_eq!(super::header("  [0.0, 1.0],"), None);
        assert_eq!(super::header("[[wall]]  # left"), Some((true, vec!["wall".into()])));
        assert_eq!(
            super::header("[ material . dem ]"),
            Some((false, vec!["material".into(), "dem".into()]))
        );
        assert_eq!(
            super::table_at("[[a]]\n[[a]]\n[[a.b]]\n[[a]]\n[[a.b]]\n[[a.b]]\n").to_string(),
            "a.2.b.1"
        );
    }
}
