//! `[[material]]` with its `[material.dem]` (grains) and `[material.mpm]` (continuum) tables.

use super::errors::{
    Bound::{self, Closed, Open},
    Ctx, SceneError, in_range, non_negative, positive,
};
use super::overrides::FieldPath;
use super::raw::{RawDemMaterial, RawMaterial, RawMpmMaterial};

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Density of the grain material [kg/m³].
    pub density: f64,
    pub dem: Option<DemMaterial>,
    pub mpm: Option<MpmMaterial>,
}

/// How grain contacts dissipate energy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DemDamping {
    /// Restitution coefficient e of a head-on impact, in [0, 1] (0: critically damped).
    Restitution(f64),
    /// Constant damping coefficient γ_n = γ_t [N s/m] (Chen 2021 Table 1).
    Viscous(f64),
}

/// Grain parameters (Yue 2018 §3.2, Chen 2021 §2.1 and Table 1).
#[derive(Clone, Debug, PartialEq)]
pub struct DemMaterial {
    /// Mean grain radius [m].
    pub radius: f64,
    /// Standard deviation of the radius [m] (normal distribution, clamped to ±2σ).
    pub radius_std: f64,
    /// Normal stiffness k_n [N/m].
    pub stiffness_normal: f64,
    /// Tangential stiffness k_t [N/m].
    pub stiffness_tangential: f64,
    /// Normal and tangential damping.
    pub damping: DemDamping,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Normal cohesion e_n [N/m] (Chen 2021).
    pub cohesion_normal: f64,
    /// Tangential cohesion e_t [N/m].
    pub cohesion_tangential: f64,
}

/// The continuum's constitutive model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MpmModel {
    /// Yue 2018 §3.3: b^e elasticity, Drucker–Prager, volume-preserving return, free flow.
    DruckerPrager,
    /// Chen 2021 §2.2: Hencky elasticity, cohesive Drucker–Prager with critical-state
    /// softening: tan φ = tan φ_cs + χ (Φ − Φ_cs), dΦ/dt = −ξ Φ (Φ − Φ_cs) ‖ε̇^p‖.
    CriticalState {
        /// Critical packing fraction Φ_cs.
        packing_critical: f64,
        /// χ of eq. 7.
        chi: f64,
        /// ξ of eq. 8.
        xi: f64,
    },
}

/// Continuum parameters (Yue 2018 §3.3–3.4, Chen 2021 §2.2).
#[derive(Clone, Debug, PartialEq)]
pub struct MpmMaterial {
    pub model: MpmModel,
    /// Young's modulus [Pa].
    pub young: f64,
    /// Poisson's ratio, in [0, 0.5).
    pub poisson: f64,
    /// Friction angle [degrees] (the critical-state one, φ_cs, with `critical_state`).
    pub friction_angle: f64,
    /// Cohesion [Pa] (`critical_state` only).
    pub cohesion: f64,
    /// Initial packing fraction Φ0: the continuum's density is Φ0 × the material density.
    pub packing: f64,
    /// Where `friction_angle` and `young` come from (`grains calibrate --write` writes it).
    pub calibration: Option<String>,
    /// `drucker_prager` only: a friction that grows with the inertial number, sin φ(I) =
    /// sin φ + (sin φ₂ − sin φ) / (1 + I₀ / I) (the μ(I) law of GDR MiDi 2004 on the plane
    /// Mohr–Coulomb ratio); `None`: rate-independent.
    pub rate: Option<RateFriction>,
}

/// The rate dependence of `drucker_prager`'s friction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateFriction {
    /// φ₂ [degrees]: the friction angle at large inertial numbers, > `friction_angle`.
    pub friction_angle_2: f64,
    /// I₀: the inertial number half way between, > 0.
    pub i0: f64,
}

pub(super) fn validate(ctx: &Ctx, raw: &[RawMaterial]) -> Result<Vec<Material>, SceneError> {
    let mut materials = Vec::new();
    for (i, m) in raw.iter().enumerate() {
        let at = FieldPath::root("material").index(i);
        let f = |name: &str| format!("{at}.{name}");
        let name = m.name.get_ref().clone();
        if materials.iter().any(|x: &Material| x.name == name) {
            return Err(ctx.err(Some(m.name.span()), Some(&f("name")), format!("material `{name}` is defined twice")));
        }
        let dem = match &m.dem {
            None => None,
            Some(g) => Some(dem(ctx, g, &|name| format!("{at}.dem.{name}"))?),
        };
        let mpm = match &m.mpm {
            None => None,
            Some(c) => Some(mpm(ctx, c, &|name| format!("{at}.mpm.{name}"))?),
        };
        materials.push(Material {
            name,
            density: positive(ctx, &m.density, &f("density"))?,
            dem,
            mpm,
        });
    }
    Ok(materials)
}

/// `[material.dem]`; `f` names its fields.
fn dem(ctx: &Ctx, g: &RawDemMaterial, f: &dyn Fn(&str) -> String) -> Result<DemMaterial, SceneError> {
    let stiffness_normal = positive(ctx, &g.stiffness_normal, &f("stiffness_normal"))?;
    Ok(DemMaterial {
        radius: positive(ctx, &g.radius, &f("radius"))?,
        radius_std: non_negative(ctx, &g.radius_std, &f("radius_std"))?,
        stiffness_normal,
        stiffness_tangential: match &g.stiffness_tangential {
            Some(k) => positive(ctx, k, &f("stiffness_tangential"))?,
            None => stiffness_normal * 2.0 / 7.0,
        },
        damping: match (&g.restitution, &g.damping) {
            (Some(e), None) => DemDamping::Restitution(in_range(ctx, e, &f("restitution"), Closed(0.0), Closed(1.0))?),
            (None, Some(gm)) => DemDamping::Viscous(in_range(ctx, gm, &f("damping"), Closed(0.0), Bound::None)?),
            (Some(e), Some(_)) => {
                return Err(ctx.err(
                    Some(e.span()),
                    Some(&f("restitution")),
                    "give either `restitution` or `damping` [N s/m], not both".into(),
                ));
            }
            (None, None) => {
                return Err(ctx.err(
                    Some(g.radius.span()),
                    Some(&f("restitution")),
                    "missing: give `restitution` (0 <= e <= 1) or `damping` [N s/m]".into(),
                ));
            }
        },
        friction: in_range(ctx, &g.friction, &f("friction"), Closed(0.0), Bound::None)?,
        cohesion_normal: non_negative(ctx, &g.cohesion_normal, &f("cohesion_normal"))?,
        cohesion_tangential: non_negative(ctx, &g.cohesion_tangential, &f("cohesion_tangential"))?,
    })
}

/// `[material.mpm]`; `f` names its fields.
fn mpm(ctx: &Ctx, c: &RawMpmMaterial, f: &dyn Fn(&str) -> String) -> Result<MpmMaterial, SceneError> {
    Ok(MpmMaterial {
        model: mpm_model(ctx, c, f)?,
        young: positive(ctx, &c.young, &f("young"))?,
        poisson: in_range(ctx, &c.poisson, &f("poisson"), Closed(0.0), Open(0.5))?,
        friction_angle: in_range(ctx, &c.friction_angle, &f("friction_angle"), Closed(0.0), Open(90.0))?,
        cohesion: non_negative(ctx, &c.cohesion, &f("cohesion"))?,
        packing: in_range(ctx, &c.packing, &f("packing"), Open(0.0), Closed(1.0))?,
        calibration: c.calibration.as_ref().map(|s| s.get_ref().clone()),
        rate: rate_friction(ctx, c, f)?,
    })
}

/// `friction_angle_2` and `inertial_i0`: both or neither, `drucker_prager` only.
fn rate_friction(ctx: &Ctx, c: &RawMpmMaterial, f: &dyn Fn(&str) -> String) -> Result<Option<RateFriction>, SceneError> {
    let (phi2, i0) = match (&c.friction_angle_2, &c.inertial_i0) {
        (None, None) => return Ok(None),
        (Some(a), Some(b)) => (a, b),
        (Some(a), None) => {
            return Err(ctx.err(
                Some(a.span()),
                Some(&f("inertial_i0")),
                "missing: `friction_angle_2` needs `inertial_i0` (I₀ > 0)".into(),
            ));
        }
        (None, Some(b)) => {
            return Err(ctx.err(
                Some(b.span()),
                Some(&f("friction_angle_2")),
                "missing: `inertial_i0` needs `friction_angle_2` (degrees, above `friction_angle`)".into(),
            ));
        }
    };
    if c.model.as_ref().is_some_and(|m| m.get_ref() != "drucker_prager") {
        return Err(ctx.err(
            Some(phi2.span()),
            Some(&f("friction_angle_2")),
            "a rate-dependent friction belongs to model = \"drucker_prager\"".into(),
        ));
    }
    let friction_angle_2 = in_range(ctx, phi2, &f("friction_angle_2"), Open(*c.friction_angle.get_ref()), Open(90.0))?;
    let i0 = positive(ctx, i0, &f("inertial_i0"))?;
    Ok(Some(RateFriction { friction_angle_2, i0 }))
}

/// `model` of `[material.mpm]` and the parameters that belong to it alone.
fn mpm_model(ctx: &Ctx, c: &RawMpmMaterial, f: &dyn Fn(&str) -> String) -> Result<MpmModel, SceneError> {
    match c.model.as_ref().map(|m| m.get_ref().as_str()) {
        None | Some("drucker_prager") => {
            for (name, v) in [("packing_critical", &c.packing_critical), ("chi", &c.chi), ("xi", &c.xi)] {
                if let Some(v) = v {
                    return Err(ctx.err(
                        Some(v.span()),
                        Some(&f(name)),
                        "belongs to model = \"critical_state\" (Chen 2021), not \"drucker_prager\"".into(),
                    ));
                }
            }
            if let Some(coh) = &c.cohesion
                && *coh.get_ref() != 0.0
            {
                return Err(ctx.err(
                    Some(coh.span()),
                    Some(&f("cohesion")),
                    "model = \"drucker_prager\" (Yue 2018) is cohesionless; use model = \"critical_state\" for cohesion".into(),
                ));
            }
            Ok(MpmModel::DruckerPrager)
        }
        Some("critical_state") => Ok(MpmModel::CriticalState {
            packing_critical: match &c.packing_critical {
                Some(v) => in_range(ctx, v, &f("packing_critical"), Open(0.0), Open(1.0))?,
                None => {
                    return Err(ctx.err(
                        c.model.as_ref().map(|m| m.span()),
                        Some(&f("packing_critical")),
                        "model = \"critical_state\" needs the critical packing fraction `packing_critical` (Chen 2021 Table 2: 0.815)"
                            .into(),
                    ));
                }
            },
            chi: match &c.chi {
                Some(v) => in_range(ctx, v, &f("chi"), Closed(0.0), Bound::None)?,
                None => 7.0,
            },
            xi: match &c.xi {
                Some(v) => in_range(ctx, v, &f("xi"), Closed(0.0), Bound::None)?,
                None => 0.01,
            },
        }),
        Some(other) => Err(ctx.err(
            c.model.as_ref().map(|m| m.span()),
            Some(&f("model")),
            format!("must be \"drucker_prager\" (Yue 2018) or \"critical_state\" (Chen 2021), got {other:?}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of};

    #[test]
    fn material_errors_name_the_material_and_its_table_by_index() {
        let text = edit(DEM, "radius = 4e-4", "radius = -4e-4");
        check_err(&text, Some(line_of(&text, "radius = -4e-4")), "material.1.dem.radius", "> 0");
        let text = edit(DEM, "name = \"sand\"", "name = \"glass\"");
        check_err(&text, Some(line_of(DEM, "name = \"sand\"")), "material.1.name", "defined twice");
    }
}
