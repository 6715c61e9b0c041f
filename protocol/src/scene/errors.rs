//! [`SceneError`] and the checks every section shares: where a value sits in the file (line,
//! column, field) and whether it is in range.

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

    /// A serde/TOML error: keep its message, add the key written on the offending line.
    pub fn toml_error(&self, e: &toml::de::Error) -> SceneError {
        let span = e.span();
        let field = span.clone().and_then(|s| self.key_on_line_of(s.start));
        let message = e.message().trim().replace('\n', " ");
        SceneError {
            path: self.path.to_path_buf(),
            line_col: span.map(|s| self.line_col(s.start)),
            field,
            message,
        }
    }

    /// The dotted key written on the line of `offset`, prefixed by the table it sits in.
    fn key_on_line_of(&self, offset: usize) -> Option<String> {
        let start = self.text[..offset.min(self.text.len())].rfind('\n').map_or(0, |i| i + 1);
        let line = self.text[start..].lines().next()?;
        let (key, _) = line.split_once('=')?;
        let key = key.trim();
        let ok = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '-');
        if !ok {
            return None;
        }
        let table = self.text[..start]
            .lines()
            .rev()
            .map(str::trim)
            .find(|l| l.starts_with('['))
            .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
        Some(match table {
            Some(t) => format!("{t}.{key}"),
            None => key.to_string(),
        })
    }

    /// The file a path field names: relative paths are relative to the scene file's directory.
    pub fn file(&self, relative: &str) -> PathBuf {
        self.path.parent().unwrap_or(Path::new(".")).join(relative)
    }
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
        return Err(ctx.err(Some(v.span()), Some(field), format!("components must be finite, got {x}")));
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
            format!("must be {}{}, got {x}", lo.describe_lo(), hi.describe_hi()),
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
