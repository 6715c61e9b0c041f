//! `[[wall]]`: boundaries that keep material in, fixed or scripted.

use super::errors::{Bound, Ctx, SceneError, box_corners, in_range, non_negative, positive, vec3};
use super::overrides::FieldPath;
use super::raw::RawWall;

#[derive(Clone, Debug, PartialEq)]
pub enum WallShape {
    /// Half-space boundary through `point` with inward `normal` (unit).
    Plane { point: [f64; 3], normal: [f64; 3] },
    /// Material kept inside the box.
    Box { min: [f64; 3], max: [f64; 3] },
    /// Material kept inside a circle (2D) or a cylinder along z (3D).
    Drum { center: [f64; 3], radius: f64 },
    /// A line segment material cannot cross (silo bottoms, hoppers; a thin rod in 3D).
    Segment { from: [f64; 3], to: [f64; 3] },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Wall {
    pub shape: WallShape,
    /// Coulomb friction between material and wall.
    pub friction: f64,
    /// Scripted translation velocity [m/s].
    pub velocity: [f64; 3],
    /// Scripted angular velocity of a drum about its axis [rad/s], counter-clockwise positive.
    pub spin: f64,
    /// Material sticks (MPM): no slip at all, whatever the friction.
    pub sticky: bool,
}

pub(super) fn validate(ctx: &Ctx, dim: usize, raw: &[RawWall]) -> Result<Vec<Wall>, SceneError> {
    raw.iter()
        .enumerate()
        .map(|(i, w)| {
            let at = FieldPath::root("wall").index(i);
            wall(ctx, dim, w, &|name| format!("{at}.{name}"))
        })
        .collect()
}

/// One `[[wall]]`; `f` names its fields.
fn wall(ctx: &Ctx, dim: usize, w: &RawWall, f: &dyn Fn(&str) -> String) -> Result<Wall, SceneError> {
    let shape = shape(ctx, dim, w, f)?;
    if let (Some(spin), false) = (&w.spin, matches!(shape, WallShape::Drum { .. })) {
        return Err(ctx.err(Some(spin.span()), Some(&f("spin")), "only a \"drum\" wall can spin".into()));
    }
    Ok(Wall {
        shape,
        friction: non_negative(ctx, &w.friction, &f("friction"))?,
        velocity: match &w.velocity {
            Some(v) => vec3(ctx, dim, v, &f("velocity"))?,
            None => [0.0; 3],
        },
        spin: match &w.spin {
            Some(sp) => in_range(ctx, sp, &f("spin"), Bound::None, Bound::None)?,
            None => 0.0,
        },
        sticky: w.sticky.unwrap_or(false),
    })
}

/// The wall's geometry by `kind`, with the fields that kind needs.
fn shape(ctx: &Ctx, dim: usize, w: &RawWall, f: &dyn Fn(&str) -> String) -> Result<WallShape, SceneError> {
    let missing = |name: &str| {
        ctx.err(
            Some(w.kind.span()),
            Some(&f(name)),
            format!("a {:?} wall needs `{name}`", w.kind.get_ref()),
        )
    };
    Ok(match w.kind.get_ref().as_str() {
        "plane" => {
            let point = vec3(ctx, dim, w.point.as_ref().ok_or_else(|| missing("point"))?, &f("point"))?;
            let n = w.normal.as_ref().ok_or_else(|| missing("normal"))?;
            let mut normal = vec3(ctx, dim, n, &f("normal"))?;
            let len = normal.iter().map(|x| x * x).sum::<f64>().sqrt();
            if len == 0.0 {
                return Err(ctx.err(Some(n.span()), Some(&f("normal")), "must not be the zero vector".into()));
            }
            normal.iter_mut().for_each(|x| *x /= len);
            WallShape::Plane { point, normal }
        }
        "box" => {
            let (min, max) = box_corners(
                ctx,
                dim,
                w.min.as_ref().ok_or_else(|| missing("min"))?,
                w.max.as_ref().ok_or_else(|| missing("max"))?,
                f,
            )?;
            WallShape::Box { min, max }
        }
        "drum" => WallShape::Drum {
            center: vec3(ctx, dim, w.center.as_ref().ok_or_else(|| missing("center"))?, &f("center"))?,
            radius: positive(ctx, w.radius.as_ref().ok_or_else(|| missing("radius"))?, &f("radius"))?,
        },
        "segment" => WallShape::Segment {
            from: vec3(ctx, dim, w.from.as_ref().ok_or_else(|| missing("from"))?, &f("from"))?,
            to: vec3(ctx, dim, w.to.as_ref().ok_or_else(|| missing("to"))?, &f("to"))?,
        },
        other => {
            return Err(ctx.err(
                Some(w.kind.span()),
                Some(&f("kind")),
                format!("must be \"plane\", \"box\", \"drum\" or \"segment\", got {other:?}"),
            ));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of};

    #[test]
    fn wall_errors_name_the_wall_by_index() {
        let text = edit(DEM, "to = [0.05, 0.05]", "to = [0.05, 0.05, 0.0]");
        check_err(&text, Some(line_of(&text, "to = ")), "wall.1.to", "expected 2 components");
        let text = edit(DEM, "normal = [0.0, 1.0]", "normal = [0.0, 0.0]");
        check_err(&text, Some(line_of(&text, "normal")), "wall.0.normal", "zero vector");
    }
}
