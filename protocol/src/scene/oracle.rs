//! `[oracle]`: who decides where the material is discrete, hybrid or continuum.

use super::errors::{
    Bound::{self, Closed, Open},
    Ctx, SceneError, in_range,
};
use super::raw::RawOracle;
use toml::Spanned;

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
    /// Continuum until a shear band forms, then grains within `band_distance` of it (Chen
    /// 2021 Alg. 1 and §4): the run starts with every cell continuum.
    ShearBand,
}

impl OracleKind {
    /// The kind as a scene writes it.
    pub fn name(self) -> &'static str {
        match self {
            OracleKind::Fixed => "fixed",
            OracleKind::Layered => "layered",
            OracleKind::Surface => "surface",
            OracleKind::ShearBand => "shear_band",
        }
    }

    /// Whether the oracle moves the zones every `every` steps.
    pub fn adaptive(self) -> bool {
        matches!(self, OracleKind::Layered | OracleKind::Surface | OracleKind::ShearBand)
    }
}

/// `shear_band`: the oracle's coefficients (Chen 2021 Tables 4, 6, 9), the enrichment's
/// distance and the prepared packing the new grains are cut from.
#[derive(Clone, Debug, PartialEq)]
pub struct ShearBand {
    /// c0: the Laplacian threshold is min(c0 / D50², c0 / ΔX²).
    pub c0: f64,
    /// c1: the recent plastic strain a cell must exceed.
    pub c1: f64,
    /// c_l, c_g: the windows τ_l = c_l / γ̇_max (recent strain) and τ_g = c_g / γ̇_max
    /// (persistence).
    pub c_l: f64,
    pub c_g: f64,
    /// φ0 [m]: cells within it of the band's boundary become discrete (the overlap t_h, one
    /// cell, about it hybrid).
    pub band_distance: f64,
    /// A LAMMPS data file (e.g. written by `grains pack`) in the scene's coordinates: the
    /// grains cut into the band, with its box periodic along the domain's periodic axes.
    pub packing: std::path::PathBuf,
    /// Kinematic training of the new grains (§4.1.1); on by default.
    pub training: bool,
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
    /// `shear_band`'s settings (None for the other kinds).
    pub shear_band: Option<ShearBand>,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawOracle>) -> Result<Option<Oracle>, SceneError> {
    let Some(o) = raw else { return Ok(None) };
    let shear_band = shear_band(ctx, o)?;
    Ok(Some(Oracle {
        kind: match o.kind.get_ref().as_str() {
            "fixed" => OracleKind::Fixed,
            "layered" => OracleKind::Layered,
            "surface" => OracleKind::Surface,
            "shear_band" => OracleKind::ShearBand,
            other => {
                return Err(ctx.err(
                    Some(o.kind.span()),
                    Some("oracle.kind"),
                    format!("must be one of \"fixed\", \"layered\", \"surface\", \"shear_band\", got {other:?}"),
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
        shear_band,
    }))
}

/// The `shear_band` fields: only with that kind; `band_distance` and `packing` required.
fn shear_band(ctx: &Ctx, o: &RawOracle) -> Result<Option<ShearBand>, SceneError> {
    let ours = [
        ("c0", o.c0.as_ref().map(|v| v.span())),
        ("c1", o.c1.as_ref().map(|v| v.span())),
        ("c_l", o.c_l.as_ref().map(|v| v.span())),
        ("c_g", o.c_g.as_ref().map(|v| v.span())),
        ("band_distance", o.band_distance.as_ref().map(|v| v.span())),
        ("packing", o.packing.as_ref().map(|v| v.span())),
        ("training", o.training.as_ref().map(|v| v.span())),
    ];
    if o.kind.get_ref() != "shear_band" {
        return match ours.iter().find(|(_, s)| s.is_some()) {
            Some((name, span)) => Err(ctx.err(
                span.clone(),
                Some(&format!("oracle.{name}")),
                format!("`{name}` is a setting of kind = \"shear_band\", not of {:?}", o.kind.get_ref()),
            )),
            None => Ok(None),
        };
    }
    let coefficient = |v: &Option<Spanned<f64>>, name: &str, default: f64| match v {
        None => Ok(default),
        Some(v) => in_range(ctx, v, &format!("oracle.{name}"), Open(0.0), Bound::None),
    };
    // Chen 2021 Tables 6 and 9 (biaxial test, plate indentation); Table 4 (planar shear) has
    // c1 = 1e-4, c_l = 8e-4, c_g = 1.2e-3.
    let (c0, c1) = (coefficient(&o.c0, "c0", 1.0e-6)?, coefficient(&o.c1, "c1", 8.0e-3)?);
    let (c_l, c_g) = (coefficient(&o.c_l, "c_l", 2.0e-2)?, coefficient(&o.c_g, "c_g", 9.6e-3)?);
    let band_distance = match &o.band_distance {
        Some(v) => in_range(ctx, v, "oracle.band_distance", Open(0.0), Bound::None)?,
        None => {
            return Err(ctx.err(
                Some(o.kind.span()),
                Some("oracle.band_distance"),
                "kind = \"shear_band\" needs `band_distance`, φ0 [m]: how far from the band's boundary the grains reach \
                 (Chen 2021: 22 D50 in the planar shear, 1 cm in the biaxial test, 2.5 cm under a 5-cm plate)"
                    .into(),
            ));
        }
    };
    let packing = match &o.packing {
        Some(p) => ctx.existing_file(p, "oracle.packing", "packing file", "; `grains pack` writes one")?,
        None => {
            return Err(ctx.err(
                Some(o.kind.span()),
                Some("oracle.packing"),
                "kind = \"shear_band\" needs `packing`, a LAMMPS data file of grains in the scene's coordinates (`grains pack` \
                 writes one) that the band's new grains are cut from (Chen 2021 §4)"
                    .into(),
            ));
        }
    };
    Ok(Some(ShearBand {
        c0,
        c1,
        c_l,
        c_g,
        band_distance,
        packing,
        training: o.training.as_ref().is_none_or(|t| *t.get_ref()),
    }))
}
