//! `[coupling]`: how the DEM and the MPM meet in a hybrid body.

use super::errors::{
    Bound::{self, Closed, Open},
    Ctx, SceneError, in_range,
};
use super::raw::RawCoupling;

#[derive(Clone, Debug, PartialEq)]
pub struct Coupling {
    /// DEM substeps per macro-step k (Yue 2018 Alg. 2).
    pub substeps: u32,
    /// MPM share w of the mass in the hybrid zone (DEM takes 1 − w).
    pub weight: f64,
    /// Layered zones of a hybrid body (Yue 2018 §4.3), fixed to the material: grains only
    /// within this depth [m] of the body's free faces (those not on a wall or the domain's edge)...
    pub discrete_layer: f64,
    /// ... then a band of this thickness [m] where grains and points overlap and are coupled;
    /// points only below it.
    pub hybrid_band: f64,
    /// How a hybrid grain takes the constrained velocities back.
    pub grain_transfer: GrainTransfer,
    /// With `"flip"`: the inertial number γ̇ √(d / |g|) of the material around a band grain
    /// (γ̇ its shear rate, d the grain's diameter) below which the grain turns with the
    /// material; above it the grain keeps its own spin and rolls. GDR MiDi (2004) put the
    /// quasi-static regime of dense flows at I < 1e-3; √(d / |g|) takes the pressure under one
    /// grain layer, so deeper in the band the true inertial number is smaller and grains start
    /// rolling at a smaller one (early rather than late). 0 never turns
    /// the grains (Yue 2018 couples translation only); without gravity they always roll.
    pub quasi_static: f64,
}

/// How a hybrid grain takes the coupler's node velocities back (Yue 2018 Alg. 5–6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrainTransfer {
    /// Alg. 5–6 as written: the grain's velocity becomes the interpolated node velocity (spin:
    /// half the curl) and it moves from its saved position with it. The band's grains move
    /// affinely with the grid: they stay put at rest, but cannot rearrange, and the band holds
    /// faces a granular material would not.
    Pic,
    /// The default. The grain keeps its substepped velocity and position and adds the
    /// coupling's change of the node velocities interpolated to it (times dt / 2 for the
    /// position); where the material is quasi-static (`quasi_static`) its spin is the
    /// material's, elsewhere its own. The substeps carry the last step's coupling force of the
    /// nodes around each grain, so the coupling acts with the contacts rather than as a kick
    /// after them: a resting band stays at rest and a flowing band rolls
    /// (`docs/validate/column_collapse.md`).
    Flip,
}

/// `[coupling]`; the zones default to two cells of `cell_size` each.
pub(super) fn validate(ctx: &Ctx, raw: Option<&RawCoupling>, cell_size: f64) -> Result<Coupling, SceneError> {
    let band_default = 2.0 * cell_size;
    let Some(c) = raw else {
        return Ok(Coupling {
            substeps: 10,
            weight: 0.5,
            discrete_layer: band_default,
            hybrid_band: band_default,
            grain_transfer: GrainTransfer::Flip,
            quasi_static: 1e-3,
        });
    };
    Ok(Coupling {
        substeps: match &c.substeps {
            None => 10,
            Some(k) if (1..=10_000).contains(k.get_ref()) => *k.get_ref(),
            Some(k) => {
                return Err(ctx.err(
                    Some(k.span()),
                    Some("coupling.substeps"),
                    format!("must be between 1 and 10000, got {}", k.get_ref()),
                ));
            }
        },
        weight: match &c.weight {
            None => 0.5,
            Some(w) => in_range(ctx, w, "coupling.weight", Open(0.0), Open(1.0))?,
        },
        discrete_layer: match &c.discrete_layer {
            None => band_default,
            Some(t) => in_range(ctx, t, "coupling.discrete_layer", Closed(0.0), Bound::None)?,
        },
        hybrid_band: match &c.hybrid_band {
            None => band_default,
            Some(t) => in_range(ctx, t, "coupling.hybrid_band", Open(0.0), Bound::None)?,
        },
        grain_transfer: match c.grain_transfer.as_ref().map(|t| (t, t.get_ref().as_str())) {
            Some((_, "pic")) => GrainTransfer::Pic,
            None | Some((_, "flip")) => GrainTransfer::Flip,
            Some((t, other)) => {
                return Err(ctx.err(
                    Some(t.span()),
                    Some("coupling.grain_transfer"),
                    format!("must be \"flip\" or \"pic\", got {other:?}"),
                ));
            }
        },
        quasi_static: match &c.quasi_static {
            None => 1e-3,
            Some(i) => in_range(ctx, i, "coupling.quasi_static", Closed(0.0), Bound::None)?,
        },
    })
}
