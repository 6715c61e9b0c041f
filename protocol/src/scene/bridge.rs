//! `[bridge]`: open every run of the scene to remote clients.

use super::errors::{Ctx, SceneError};
use super::raw::RawBridge;
use std::path::PathBuf;

/// `[bridge]`: open every run of this scene to remote clients (as `grains run --bridge`).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneBridge {
    /// The bridge settings file (listen, steering, rate, access control), if any.
    pub settings: Option<PathBuf>,
}

/// The bridge of an `enabled = true` table, whose settings file must exist.
pub(super) fn validate(ctx: &Ctx, raw: Option<&RawBridge>) -> Result<Option<SceneBridge>, SceneError> {
    let Some(b) = raw.filter(|b| b.enabled) else { return Ok(None) };
    let settings = match &b.settings {
        None => None,
        Some(p) => Some(ctx.existing_file(p, "bridge.settings", "bridge settings file", "")?),
    };
    Ok(Some(SceneBridge { settings }))
}
