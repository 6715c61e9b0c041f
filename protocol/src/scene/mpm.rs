//! `[mpm]`: how the MPM discretizes the continuum.

use super::errors::{Bound::Closed, Ctx, SceneError, in_range};
use super::raw::RawMpm;

/// How the MPM discretizes (the `[mpm]` table).
#[derive(Clone, Debug, PartialEq)]
pub struct MpmSettings {
    /// Points per cell along each axis (2 → 4 per cell in 2D, 8 in 3D).
    pub points_per_axis: u32,
    /// Shape functions: GIMP (Yue 2018) or quadratic B-splines.
    pub kernel: MpmKernel,
    /// Grid-to-point transfer: PIC/FLIP with this FLIP share β, or APIC when `None`.
    pub flip: Option<f64>,
    /// Condition on the three outer node layers of the domain faces.
    pub domain_walls: MpmDomainWalls,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpmKernel {
    Gimp,
    Bspline,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpmDomainWalls {
    Slip,
    Sticky,
}

pub(super) fn validate(ctx: &Ctx, raw: Option<&RawMpm>) -> Result<MpmSettings, SceneError> {
    let mut out = MpmSettings {
        points_per_axis: 2,
        kernel: MpmKernel::Gimp,
        flip: Some(0.98),
        domain_walls: MpmDomainWalls::Slip,
    };
    let Some(m) = raw else { return Ok(out) };
    if let Some(n) = &m.points_per_axis {
        if !(1..=4).contains(n.get_ref()) {
            return Err(ctx.err(
                Some(n.span()),
                Some("mpm.points_per_axis"),
                format!("must be 1 to 4, got {}", n.get_ref()),
            ));
        }
        out.points_per_axis = *n.get_ref();
    }
    if let Some(k) = &m.kernel {
        out.kernel = match k.get_ref().as_str() {
            "gimp" => MpmKernel::Gimp,
            "bspline" => MpmKernel::Bspline,
            other => {
                return Err(ctx.err(
                    Some(k.span()),
                    Some("mpm.kernel"),
                    format!("must be \"gimp\" or \"bspline\", got {other:?}"),
                ));
            }
        };
    }
    out.flip = transfer(ctx, m)?;
    if let Some(w) = &m.domain_walls {
        out.domain_walls = match w.get_ref().as_str() {
            "slip" => MpmDomainWalls::Slip,
            "sticky" => MpmDomainWalls::Sticky,
            other => {
                return Err(ctx.err(
                    Some(w.span()),
                    Some("mpm.domain_walls"),
                    format!("must be \"slip\" or \"sticky\", got {other:?}"),
                ));
            }
        };
    }
    Ok(out)
}

/// `transfer` and its FLIP share: `Some(β)` for PIC/FLIP, `None` for APIC.
fn transfer(ctx: &Ctx, m: &RawMpm) -> Result<Option<f64>, SceneError> {
    let beta = match &m.flip {
        Some(b) => in_range(ctx, b, "mpm.flip", Closed(0.0), Closed(1.0))?,
        None => 0.98,
    };
    match m.transfer.as_ref().map(|t| (t, t.get_ref().as_str())) {
        None | Some((_, "flip")) => Ok(Some(beta)),
        Some((_, "apic")) => match &m.flip {
            Some(b) => Err(ctx.err(
                Some(b.span()),
                Some("mpm.flip"),
                "is the FLIP share of transfer = \"flip\"; APIC has none".into(),
            )),
            None => Ok(None),
        },
        Some((t, other)) => Err(ctx.err(
            Some(t.span()),
            Some("mpm.transfer"),
            format!("must be \"flip\" or \"apic\", got {other:?}"),
        )),
    }
}
