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
    /// The points' stress at the start.
    pub initial_stress: MpmInitialStress,
}

/// The continuum's stress at the start of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpmInitialStress {
    /// Unstressed: the continuum first settles under its weight (a wave through its depth).
    None,
    /// At rest under its own weight along −y: σ_yy the weight of the body above the point,
    /// σ_xx (and σ_zz) K0 σ_yy, K0 the elastic one, ν / (1 − ν), or the least the friction
    /// holds, (1 − sin φ) / (1 + sin φ). For a bed the grains start in loaded (a poured packing).
    Geostatic,
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
        initial_stress: MpmInitialStress::None,
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
    if let Some(w) = &m.initial_stress {
        out.initial_stress = match w.get_ref().as_str() {
            "none" => MpmInitialStress::None,
            "geostatic" => MpmInitialStress::Geostatic,
            other => {
                return Err(ctx.err(
                    Some(w.span()),
                    Some("mpm.initial_stress"),
                    format!("must be \"none\" or \"geostatic\", got {other:?}"),
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

#[cfg(test)]
mod tests {
    use super::super::testing::{GOOD, check_err, line_of};
    use super::super::{Path, from_str};
    use super::MpmInitialStress;

    #[test]
    fn the_initial_stress_is_none_unless_geostatic_is_asked_and_nothing_else_is_taken() {
        let s = from_str(GOOD, Path::new("s.toml"), 0).unwrap();
        assert_eq!(s.mpm.initial_stress, MpmInitialStress::None);
        let text = format!("{GOOD}[mpm]\ninitial_stress = \"geostatic\"\n");
        let s = from_str(&text, Path::new("s.toml"), 0).unwrap();
        assert_eq!(s.mpm.initial_stress, MpmInitialStress::Geostatic);
        let text = format!("{GOOD}[mpm]\ninitial_stress = \"k0\"\n");
        check_err(
            &text,
            Some(line_of(&text, "initial_stress")),
            "mpm.initial_stress",
            "\"none\" or \"geostatic\"",
        );
    }
}
