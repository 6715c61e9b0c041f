//! `[[body]]`: the material of the scene, where it starts and how it is modelled.

use super::errors::{
    Bound::{self, Closed},
    Ctx, SceneError, box_corners, in_range, positive, vec3,
};
use super::materials::Material;
use super::overrides::FieldPath;
use super::raw::RawBody;
use std::path::PathBuf;
use toml::Spanned;

/// How a body of material is modelled at the start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    Dem,
    Mpm,
    Hybrid,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    /// A disk in 2D, a sphere in 3D.
    Ball {
        center: [f64; 3],
        radius: f64,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// Index into [`Scene::materials`](super::Scene::materials).
    pub material: usize,
    pub model: Model,
    pub shape: Shape,
    /// A packing (LAMMPS data file, e.g. written by `grains pack`) whose grains inside the
    /// shape make up the body, instead of a fresh lattice. Relative to the scene file.
    pub packing: Option<PathBuf>,
    /// Grains that never move but push (a rough base of glued grains). DEM bodies only.
    pub frozen: bool,
    /// Confining pressure on the free faces of a box body [Pa] (biaxial and triaxial tests),
    /// as a fluid's: on material points `MpmParams::ambient_pressure`, on grains
    /// `grains_dem::fluid`. The same on every body of the scene that is not frozen. MPM and
    /// DEM box bodies only.
    pub confining_pressure: f64,
    /// Initial velocity of the body's grains and points [m/s].
    pub velocity: [f64; 3],
}

pub(super) fn validate(ctx: &Ctx, dim: usize, raw: &[RawBody], materials: &[Material]) -> Result<Vec<Body>, SceneError> {
    raw.iter()
        .enumerate()
        .map(|(i, b)| {
            let at = FieldPath::root("body").index(i);
            body(ctx, dim, b, materials, &|name| format!("{at}.{name}"))
        })
        .collect()
}

/// One `[[body]]`; `f` names its fields.
fn body(ctx: &Ctx, dim: usize, b: &RawBody, materials: &[Material], f: &dyn Fn(&str) -> String) -> Result<Body, SceneError> {
    let (material, model) = material_and_model(ctx, b, materials, f)?;
    let shape = shape(ctx, dim, b, f)?;
    let packing = packing(ctx, b.packing.as_ref(), model, f)?;
    if let Some(fz) = &b.frozen
        && *fz.get_ref()
        && model != Model::Dem
    {
        return Err(ctx.err(
            Some(fz.span()),
            Some(&f("frozen")),
            "only a model = \"dem\" body can be frozen".into(),
        ));
    }
    let frozen = b.frozen.as_ref().is_some_and(|fz| *fz.get_ref());
    let confining_pressure = match &b.confining_pressure {
        None => 0.0,
        Some(p) if !matches!(model, Model::Mpm | Model::Dem) || !matches!(shape, Shape::Box { .. }) || frozen => {
            return Err(ctx.err(
                Some(p.span()),
                Some(&f("confining_pressure")),
                "only a model = \"mpm\" or \"dem\" body of shape \"box\" that is not frozen can be confined (a frozen body is a \
                 wall; a hybrid body's grains and points each take the fluid, but no scene has shown its core at p yet: \
                 docs/validation.md)"
                    .into(),
            ));
        }
        Some(p) => in_range(ctx, p, &f("confining_pressure"), Closed(0.0), Bound::None)?,
    };
    let velocity = match &b.velocity {
        None => [0.0; 3],
        Some(v) if frozen => {
            return Err(ctx.err(Some(v.span()), Some(&f("velocity")), "a frozen body cannot move".into()));
        }
        Some(v) => vec3(ctx, dim, v, &f("velocity"))?,
    };
    Ok(Body {
        material,
        model,
        shape,
        packing,
        frozen,
        confining_pressure,
        velocity,
    })
}

/// The body's material (by name) and model, and whether the material has the tables the
/// model needs.
fn material_and_model(ctx: &Ctx, b: &RawBody, materials: &[Material], f: &dyn Fn(&str) -> String) -> Result<(usize, Model), SceneError> {
    let Some(material) = materials.iter().position(|m| &m.name == b.material.get_ref()) else {
        let known: Vec<_> = materials.iter().map(|m| format!("`{}`", m.name)).collect();
        return Err(ctx.err(
            Some(b.material.span()),
            Some(&f("material")),
            format!(
                "no material named `{}`; defined: {}",
                b.material.get_ref(),
                if known.is_empty() { "none".into() } else { known.join(", ") }
            ),
        ));
    };
    let model = match b.model.get_ref().as_str() {
        "dem" => Model::Dem,
        "mpm" => Model::Mpm,
        "hybrid" => Model::Hybrid,
        other => {
            return Err(ctx.err(
                Some(b.model.span()),
                Some(&f("model")),
                format!("must be one of \"dem\", \"mpm\", \"hybrid\", got {other:?}"),
            ));
        }
    };
    let mat = &materials[material];
    let needs_dem = matches!(model, Model::Dem | Model::Hybrid);
    let needs_mpm = matches!(model, Model::Mpm | Model::Hybrid);
    if (needs_dem && mat.dem.is_none()) || (needs_mpm && mat.mpm.is_none()) {
        return Err(ctx.err(
            Some(b.model.span()),
            Some(&f("model")),
            format!(
                "model {:?} needs material `{}` to have {}",
                b.model.get_ref(),
                mat.name,
                if needs_dem && mat.dem.is_none() {
                    "a [material.dem] table"
                } else {
                    "a [material.mpm] table"
                }
            ),
        ));
    }
    Ok((material, model))
}

fn shape(ctx: &Ctx, dim: usize, b: &RawBody, f: &dyn Fn(&str) -> String) -> Result<Shape, SceneError> {
    let kind = &b.shape;
    let missing = |name: &str| {
        ctx.err(
            Some(kind.span()),
            Some(&f(name)),
            format!("a {:?} body needs `{name}`", kind.get_ref()),
        )
    };
    match kind.get_ref().as_str() {
        "box" => {
            let (min, max) = box_corners(
                ctx,
                dim,
                b.min.as_ref().ok_or_else(|| missing("min"))?,
                b.max.as_ref().ok_or_else(|| missing("max"))?,
                f,
            )?;
            Ok(Shape::Box { min, max })
        }
        "ball" => Ok(Shape::Ball {
            center: vec3(ctx, dim, b.center.as_ref().ok_or_else(|| missing("center"))?, &f("center"))?,
            radius: positive(ctx, b.radius.as_ref().ok_or_else(|| missing("radius"))?, &f("radius"))?,
        }),
        other => Err(ctx.err(
            Some(kind.span()),
            Some(&f("shape")),
            format!("must be \"box\" or \"ball\" (disk in 2D, sphere in 3D), got {other:?}"),
        )),
    }
}

/// The packing file of a grain body, which must exist.
fn packing(ctx: &Ctx, raw: Option<&Spanned<String>>, model: Model, f: &dyn Fn(&str) -> String) -> Result<Option<PathBuf>, SceneError> {
    match raw {
        None => Ok(None),
        Some(p) if model == Model::Mpm => Err(ctx.err(
            Some(p.span()),
            Some(&f("packing")),
            "a packing file makes grains: only a model = \"dem\" or \"hybrid\" body can have one".into(),
        )),
        Some(p) => Ok(Some(ctx.existing_file(p, &f("packing"), "packing file", "")?)),
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of};

    #[test]
    fn body_errors_name_the_body_by_index() {
        let text = edit(DEM, "model = \"dem\"", "model = \"sph\"");
        check_err(&text, Some(line_of(&text, "model")), "body.0.model", "\"hybrid\"");
        let text = edit(DEM, "max = [0.05, 0.05]", "max = [0.05]");
        check_err(&text, Some(line_of(&text, "max = [0.05]")), "body.0.max", "expected 2 components");
        let text = edit(DEM, "material = \"sand\"", "material = \"clay\"");
        check_err(
            &text,
            Some(line_of(&text, "material = \"clay\"")),
            "body.0.material",
            "`glass`, `sand`",
        );
    }
}
