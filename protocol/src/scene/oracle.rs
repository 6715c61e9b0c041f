//! `[oracle]`: who decides where the material is discrete, hybrid or continuum.

use super::errors::{
    Bound::{self, Closed, Open},
    Ctx, SceneError, in_range,
};
use super::raw::RawOracle;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OracleKind {
    /// Zones given by the scene, never changed.
    Fixed,
    /// Zones from the depth below the top surface of the grains' packing fraction, column by
    /// column against gravity, every `every` steps (Yue 2018 §4.3: discrete only at the
    /// visible top; walls, floors and cavities stay continuum).
    Layered,
    /// Zones from the distance to the packing-fraction isocontour (Yue 2018 §4).
    Surface,
}

impl OracleKind {
    /// Whether the oracle moves the zones every `every` steps.
    pub fn adaptive(self) -> bool {
        matches!(self, OracleKind::Layered | OracleKind::Surface)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Oracle {
    pub kind: OracleKind,
    /// Macro-steps between oracle epochs.
    pub every: u64,
    /// `surface`: the packing fraction Φρ of the isocontour the zones are measured from.
    pub critical_packing: f64,
    /// `surface`: φ0, the distance inside the isocontour of the hybrid band's centre [m]
    /// (default `coupling.discrete_layer + hybrid_band / 2`, where the layered zones put it;
    /// very large: all discrete; very negative: all continuum).
    pub centre: Option<f64>,
    /// `surface`: r_h, the band's half-width [m] (default `coupling.hybrid_band / 2`).
    pub half_width: Option<f64>,
    /// `surface` and `layered`: material whose inertial number I = γ̇ d √(ρ / p) exceeds this
    /// counts as not dense, like a free surface, so that the zones keep flowing material
    /// discrete and the band in quasi-static material (Yue 2018 §4.1 names fast shear as a
    /// reason for grains; GDR MiDi 2004 puts quasi-static flow below I ≈ 1e-3). 0: off.
    pub max_inertial: f64,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawOracle>) -> Result<Option<Oracle>, SceneError> {
    let Some(o) = raw else { return Ok(None) };
    Ok(Some(Oracle {
        kind: match o.kind.get_ref().as_str() {
            "fixed" => OracleKind::Fixed,
            "layered" => OracleKind::Layered,
            "surface" => OracleKind::Surface,
            // Chen 2021's hybrid exists as functions (grains_oracle::shear_band, band_epoch,
            // grains_dem::training) and runs in process in `grains validate --part shear`;
            // the runtime's oracle does not take it yet.
            "shear_band" => {
                return Err(ctx.err(
                    Some(o.kind.span()),
                    Some("oracle.kind"),
                    "\"shear_band\" (Chen 2021) is not built into runs yet: its oracle, enrichment and training run in process in \
                     `grains validate --part shear` only; use one of \"fixed\", \"layered\", \"surface\""
                        .into(),
                ));
            }
            other => {
                return Err(ctx.err(
                    Some(o.kind.span()),
                    Some("oracle.kind"),
                    format!("must be one of \"fixed\", \"layered\", \"surface\", got {other:?}"),
                ));
            }
        },
        every: match &o.every {
            None => 100,
            Some(e) if *e.get_ref() >= 1 => *e.get_ref(),
            Some(e) => return Err(ctx.err(Some(e.span()), Some("oracle.every"), "must be >= 1, got 0".into())),
        },
        critical_packing: match &o.critical_packing {
            None => 0.5,
            Some(c) => in_range(ctx, c, "oracle.critical_packing", Open(0.0), Open(1.0))?,
        },
        centre: match &o.centre {
            None => None,
            Some(c) => Some(in_range(ctx, c, "oracle.centre", Bound::None, Bound::None)?),
        },
        half_width: match &o.half_width {
            None => None,
            Some(c) => Some(in_range(ctx, c, "oracle.half_width", Closed(0.0), Bound::None)?),
        },
        max_inertial: match &o.max_inertial {
            None => 0.0,
            Some(i) => in_range(ctx, i, "oracle.max_inertial", Closed(0.0), Bound::None)?,
        },
    }))
}
