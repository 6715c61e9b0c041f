//! `coupling.substeps = "auto"` resolved: the chosen macro-step and substeps written into the
//! scene's text (a typed edit of its TOML document), so that the run's copy of the scene says
//! what every participant runs. The launcher chooses them from the solvers' stable steps.

use super::errors::SceneError;
use super::overrides::FieldPath;
use super::{Scene, from_str, hash_bytes};

/// Cadences a new step rescaled: (field, count in the file, count now).
pub type Rescaled = Vec<(String, u64, u64)>;

/// `text` (a scene with `substeps = "auto"`, validated as `scene`) with `run.dt = dt`,
/// `coupling.substeps = substeps` and `coupling.dem_dt = dem_dt` (the DEM step they make,
/// stated). Cadences counted in macro-steps (`run.steps`,
/// `output.frames_every`, `output.checkpoint_every`, `oracle.every`, where the file gives them) are rescaled to keep
/// their length in time (at least 1); `run.duration` stays as it is. Also returns the cadences
/// that changed, as (field, count in the file, count now).
pub fn with_resolved_steps(
    text: &str,
    scene: &Scene,
    dt: f64,
    substeps: u32,
    dem_dt: f64,
) -> Result<(Scene, String, Rescaled), SceneError> {
    let plain = |message: String| SceneError {
        path: scene.path.clone(),
        line_col: None,
        field: None,
        message,
    };
    let mut doc = toml::Value::Table(text.parse::<toml::Table>().map_err(|e| plain(e.message().to_string()))?);
    let ratio = scene.dt / dt;
    let rescale = |n: i64| ((n as f64 * ratio).round() as i64).max(1);
    let counts = [
        FieldPath::root("run").key("steps"),
        FieldPath::root("output").key("frames_every"),
        FieldPath::root("output").key("checkpoint_every"),
        FieldPath::root("oracle").key("every"),
    ];
    let mut rescaled = Vec::new();
    for path in counts {
        // frames_every = 0 (no frames) stays 0.
        if let Some(n) = get_integer(&doc, &path).filter(|&n| n > 0) {
            let now = rescale(n);
            path.set(&mut doc, toml::Value::Integer(now)).map_err(plain)?;
            if now != n {
                rescaled.push((path.to_string(), n as u64, now as u64));
            }
        }
    }
    FieldPath::root("run")
        .key("dt")
        .set(&mut doc, toml::Value::Float(dt))
        .map_err(plain)?;
    FieldPath::root("coupling")
        .key("substeps")
        .set(&mut doc, toml::Value::Integer(substeps as i64))
        .map_err(plain)?;
    FieldPath::root("coupling")
        .key("dem_dt")
        .set(&mut doc, toml::Value::Float(dem_dt))
        .map_err(plain)?;
    let text = toml::to_string(&doc).map_err(|e| plain(format!("cannot write the resolved scene: {e}")))?;
    let resolved = from_str(&text, &scene.path, hash_bytes(text.as_bytes())).map_err(|mut e| {
        e.message = format!("{} (after choosing run.dt = {dt:e} s, coupling.substeps = {substeps})", e.message);
        e.line_col = None;
        e
    })?;
    Ok((resolved, text, rescaled))
}

fn get_integer(doc: &toml::Value, path: &FieldPath) -> Option<i64> {
    path.get(doc).and_then(|v| v.as_integer())
}
