//! `[synthetic]`: a test scene whose solvers publish synthetic rasters instead of physics.

use super::errors::{Bound::Closed, Ctx, SceneError, in_range};
use super::raw::RawSynthetic;
use crate::Role;
use toml::Spanned;

/// A test scene whose solvers publish synthetic rasters instead of physics (issue 2): it
/// proves the runtime with real payloads and real checks. Never part of a physics scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Synthetic {
    pub participants: Vec<Role>,
    /// Nodes in the DEM raster before variation.
    pub dem_nodes: u64,
    /// Nodes in the MPM raster before variation.
    pub mpm_nodes: u64,
    /// Share of the smaller raster's nodes that both rasters contain, in [0, 1].
    pub overlap: f64,
    /// Raster lengths shrink by up to this share, differently every step, in [0, 0.9].
    pub vary: f64,
    /// Compute and verify payload checksums.
    pub checksum: bool,
    /// How node values are made: hashed (every bit depends on seed, step and node; the
    /// default) or plain (cheap arithmetic, for benchmarks that time the exchange itself).
    pub content: SyntheticContent,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SyntheticContent {
    Hashed,
    Plain,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawSynthetic>) -> Result<Option<Synthetic>, SceneError> {
    let Some(s) = raw else { return Ok(None) };
    let participants = participants(ctx, s.participants.as_ref())?;
    let nodes = |v: &Option<Spanned<u64>>, field: &str| match v {
        None => Ok(1000),
        Some(n) if (1..=100_000_000).contains(n.get_ref()) => Ok(*n.get_ref()),
        Some(n) => Err(ctx.err(
            Some(n.span()),
            Some(field),
            format!("must be between 1 and 100000000, got {}", n.get_ref()),
        )),
    };
    Ok(Some(Synthetic {
        participants,
        dem_nodes: nodes(&s.dem_nodes, "synthetic.dem_nodes")?,
        mpm_nodes: nodes(&s.mpm_nodes, "synthetic.mpm_nodes")?,
        overlap: match &s.overlap {
            None => 0.5,
            Some(o) => in_range(ctx, o, "synthetic.overlap", Closed(0.0), Closed(1.0))?,
        },
        vary: match &s.vary {
            None => 0.0,
            Some(v) => in_range(ctx, v, "synthetic.vary", Closed(0.0), Closed(0.9))?,
        },
        checksum: s.checksum.unwrap_or(true),
        content: match s.content.as_ref().map(|c| c.get_ref().as_str()) {
            None | Some("hashed") => SyntheticContent::Hashed,
            Some("plain") => SyntheticContent::Plain,
            Some(other) => {
                let span = s.content.as_ref().map(|c| c.span());
                return Err(ctx.err(
                    span,
                    Some("synthetic.content"),
                    format!("must be \"hashed\" or \"plain\", got {other:?}"),
                ));
            }
        },
    }))
}

/// The participants of a synthetic run: one solver alone, or both with the coupler (the
/// default).
fn participants(ctx: &Ctx, raw: Option<&Spanned<Vec<String>>>) -> Result<Vec<Role>, SceneError> {
    let mut participants = Vec::new();
    match raw {
        None => participants.extend([Role::Dem, Role::Mpm, Role::Coupler]),
        Some(list) => {
            for p in list.get_ref() {
                match Role::from_name(p).filter(|r| Role::PARTICIPANTS[..3].contains(r)) {
                    Some(r) if !participants.contains(&r) => participants.push(r),
                    _ => {
                        return Err(ctx.err(
                            Some(list.span()),
                            Some("synthetic.participants"),
                            format!("entries must be distinct and one of \"dem\", \"mpm\", \"coupler\", got {p:?}"),
                        ));
                    }
                }
            }
            participants.sort();
        }
    }
    let solvers = participants.iter().filter(|r| matches!(r, Role::Dem | Role::Mpm)).count();
    let coupled = participants.contains(&Role::Coupler);
    if (coupled && solvers != 2) || (!coupled && solvers != 1) {
        return Err(ctx.err(
            raw.map(|l| l.span()),
            Some("synthetic.participants"),
            "allowed sets: [\"dem\"], [\"mpm\"], or [\"dem\", \"mpm\", \"coupler\"]".into(),
        ));
    }
    Ok(participants)
}
