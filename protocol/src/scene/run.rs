//! `[run]`: dimension, macro-step, length, seed, threads, name; and the top-level `gravity`.

use super::errors::{Ctx, SceneError, positive, vec3};
use super::raw::RawRun;
use toml::Spanned;

/// Spatial dimension of a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dimension {
    Two = 2,
    Three = 3,
}

/// The validated `[run]` table, but its name (see [`name`]).
pub(super) struct Run {
    pub dimension: Dimension,
    pub dt: f64,
    pub steps: u64,
    pub seed: u64,
    pub threads: u32,
}

pub(super) fn validate(ctx: &Ctx, run: &RawRun) -> Result<Run, SceneError> {
    let dimension = match *run.dimension.get_ref() {
        2 => Dimension::Two,
        3 => Dimension::Three,
        d => {
            return Err(ctx.err(
                Some(run.dimension.span()),
                Some("run.dimension"),
                format!("must be 2 or 3, got {d}"),
            ));
        }
    };
    let dt = positive(ctx, &run.dt, "run.dt")?;
    let steps = match (&run.steps, &run.duration) {
        (Some(s), None) if *s.get_ref() >= 1 => *s.get_ref(),
        (Some(s), None) => return Err(ctx.err(Some(s.span()), Some("run.steps"), "must be >= 1, got 0".into())),
        (None, Some(d)) => {
            let d = positive(ctx, d, "run.duration")?;
            (d / dt).round().max(1.0) as u64
        }
        (Some(s), Some(_)) => {
            return Err(ctx.err(
                Some(s.span()),
                Some("run.steps"),
                "give either `run.steps` or `run.duration`, not both".into(),
            ));
        }
        (None, None) => {
            return Err(ctx.err(
                Some(run.dt.span()),
                Some("run"),
                "missing `steps` or `duration`: one of them sets the length of the run".into(),
            ));
        }
    };
    let threads = match &run.threads {
        None => 1,
        Some(t) if (1..=256).contains(t.get_ref()) => *t.get_ref(),
        Some(t) => {
            return Err(ctx.err(
                Some(t.span()),
                Some("run.threads"),
                format!("must be between 1 and 256, got {}", t.get_ref()),
            ));
        }
    };
    Ok(Run {
        dimension,
        dt,
        steps,
        seed: run.seed.unwrap_or(0),
        threads,
    })
}

/// The run's name (it names the output directory): `run.name`, else the file name without
/// extension. Checked after every other section, so that another error of the scene comes first.
pub(super) fn name(ctx: &Ctx, run: &RawRun) -> Result<String, SceneError> {
    match &run.name {
        Some(n) if !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') => Ok(n.clone()),
        Some(n) => Err(ctx.err(
            None,
            Some("run.name"),
            format!("must be non-empty and use only letters, digits, '_' and '-' (it names the output directory), got {n:?}"),
        )),
        None => Ok(ctx
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into())),
    }
}

/// The top-level `gravity` [m/s²], one component per dimension; none by default.
pub(super) fn gravity(ctx: &Ctx, dim: usize, raw: Option<&Spanned<Vec<f64>>>) -> Result<[f64; 3], SceneError> {
    match raw {
        Some(g) => vec3(ctx, dim, g, "gravity"),
        None => Ok([0.0; 3]),
    }
}
