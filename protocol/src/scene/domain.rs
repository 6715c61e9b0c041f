//! `[domain]`: the box the simulation lives in and its background grid.

use super::errors::{Ctx, SceneError, positive, vec3};
use super::raw::RawDomain;

#[derive(Clone, Debug, PartialEq)]
pub struct Domain {
    /// Lower corner [m]; the third component is 0 in 2D.
    pub min: [f64; 3],
    /// Upper corner [m].
    pub max: [f64; 3],
    /// Background grid cell width [m] (MPM grid, rasters, oracle).
    pub cell_size: f64,
    /// Axes along which the domain wraps around.
    pub periodic: [bool; 3],
}

pub(super) fn validate(ctx: &Ctx, dim: usize, d: &RawDomain) -> Result<Domain, SceneError> {
    let min = vec3(ctx, dim, &d.min, "domain.min")?;
    let max = vec3(ctx, dim, &d.max, "domain.max")?;
    if (0..dim).any(|k| max[k] <= min[k]) {
        return Err(ctx.err(
            Some(d.max.span()),
            Some("domain.max"),
            format!(
                "must be greater than `domain.min` in every component ({:?} vs {:?})",
                &max[..dim],
                &min[..dim]
            ),
        ));
    }
    let cell_size = positive(ctx, &d.cell_size, "domain.cell_size")?;
    let mut periodic = [false; 3];
    if let Some(p) = &d.periodic {
        if p.get_ref().len() != dim {
            return Err(ctx.err(
                Some(p.span()),
                Some("domain.periodic"),
                format!("expected {dim} booleans, got {}", p.get_ref().len()),
            ));
        }
        periodic[..dim].copy_from_slice(p.get_ref());
    }
    Ok(Domain {
        min,
        max,
        cell_size,
        periodic,
    })
}
