//! `[[rigid]]`: rigid spheropolygons (Jiang 2020 §3), 2D: a simple polygon, convex or not,
//! swept by a disk of radius `radius`, of a material's density and contact law, free, fixed or scripted. They
//! run in the DEM and meet its grains, walls and each other.

use super::Material;
use super::errors::{Bound, Ctx, SceneError, in_range, vec3};
use super::overrides::FieldPath;
use super::raw::RawRigid;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RigidMotion {
    /// By its forces and gravity, from `velocity` and `spin`.
    Free,
    /// Never moves (a floor, an obstacle glued in place).
    Fixed,
    /// At `velocity` and `spin`, whatever the forces (a tool, a gate).
    Scripted,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Rigid {
    /// Index into the scene's materials (one with a `[material.dem]` table).
    pub material: usize,
    /// The polygon, counter-clockwise and simple (convex or not), in scene coordinates [m]
    /// (one vertex: a disk; two: a rod with round ends).
    pub vertices: Vec<[f64; 2]>,
    /// Sphero-radius [m], > 0: the contacts act within it.
    pub radius: f64,
    pub motion: RigidMotion,
    /// Velocity of the centre of mass [m/s] and spin [rad/s, counter-clockwise]: the start of a
    /// free body, the motion of a scripted one.
    pub velocity: [f64; 2],
    pub spin: f64,
}

pub(super) fn validate(ctx: &Ctx, dim: usize, raw: &[RawRigid], materials: &[Material]) -> Result<Vec<Rigid>, SceneError> {
    raw.iter()
        .enumerate()
        .map(|(i, r)| {
            let at = FieldPath::root("rigid").index(i);
            rigid(ctx, dim, r, materials, &|name| format!("{at}.{name}"))
        })
        .collect()
}

fn rigid(ctx: &Ctx, dim: usize, r: &RawRigid, materials: &[Material], f: &dyn Fn(&str) -> String) -> Result<Rigid, SceneError> {
    if dim != 2 {
        return Err(ctx.err(
            Some(r.vertices.span()),
            Some(&f("vertices")),
            "rigid bodies are 2D (spheropolygons); 3D spheropolyhedra are not implemented".into(),
        ));
    }
    let Some(material) = materials.iter().position(|m| &m.name == r.material.get_ref()) else {
        let known: Vec<_> = materials.iter().map(|m| format!("`{}`", m.name)).collect();
        return Err(ctx.err(
            Some(r.material.span()),
            Some(&f("material")),
            format!("no material named `{}`; defined: {}", r.material.get_ref(), known.join(", ")),
        ));
    };
    if materials[material].dem.is_none() {
        return Err(ctx.err(
            Some(r.material.span()),
            Some(&f("material")),
            format!(
                "a rigid body takes its contact law from [material.dem]; `{}` has none",
                r.material.get_ref()
            ),
        ));
    }
    let mut vertices = Vec::new();
    for (k, v) in r.vertices.get_ref().iter().enumerate() {
        if v.len() != 2 || v.iter().any(|x| !x.is_finite()) {
            return Err(ctx.err(
                Some(r.vertices.span()),
                Some(&f("vertices")),
                format!("vertex {k} must be 2 finite numbers, got {v:?}"),
            ));
        }
        vertices.push([v[0], v[1]]);
    }
    let Some(a) = &r.radius else {
        return Err(ctx.err(
            Some(r.vertices.span()),
            Some(&f("radius")),
            "a rigid body needs its sphero-radius `radius` [m] > 0 (its contacts act within it)".into(),
        ));
    };
    let radius = in_range(ctx, a, &f("radius"), Bound::Open(0.0), Bound::None)?;
    if let Err(why) = check_polygon(&vertices, radius) {
        return Err(ctx.err(Some(r.vertices.span()), Some(&f("vertices")), why));
    }
    let motion = match r.motion.as_ref().map(|m| (m, m.get_ref().as_str())) {
        None | Some((_, "free")) => RigidMotion::Free,
        Some((_, "fixed")) => RigidMotion::Fixed,
        Some((_, "scripted")) => RigidMotion::Scripted,
        Some((m, other)) => {
            return Err(ctx.err(
                Some(m.span()),
                Some(&f("motion")),
                format!("must be \"free\", \"fixed\" or \"scripted\", got {other:?}"),
            ));
        }
    };
    let velocity = match &r.velocity {
        Some(v) => {
            let v = vec3(ctx, dim, v, &f("velocity"))?;
            [v[0], v[1]]
        }
        None => [0.0; 2],
    };
    let spin = match &r.spin {
        Some(s) => in_range(ctx, s, &f("spin"), Bound::None, Bound::None)?,
        None => 0.0,
    };
    if motion == RigidMotion::Fixed && (velocity != [0.0; 2] || spin != 0.0) {
        return Err(ctx.err(
            Some(r.motion.as_ref().map_or(r.vertices.span(), |m| m.span())),
            Some(&f("motion")),
            "a fixed body does not move: give it no velocity or spin, or make it \"scripted\"".into(),
        ));
    }
    Ok(Rigid {
        material,
        vertices,
        radius,
        motion,
        velocity,
        spin,
    })
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Why `vertices` cannot be the polygon of a body of sphero-radius `radius`, if it cannot: no
/// vertex, a repeated vertex, a vertex where the outline runs straight on or doubles back,
/// wound clockwise, edges that cross, or (non-convex) two edges that are not neighbours
/// closer than 2 `radius`: an arm or a notch that thin would make the swept shape overlap
/// itself away from a corner, which neither its mass properties nor its contacts follow.
pub fn check_polygon(vertices: &[[f64; 2]], radius: f64) -> Result<(), String> {
    let n = vertices.len();
    if n == 0 {
        return Err("a rigid body needs at least one vertex".into());
    }
    let d = |k: usize| {
        let (a, b) = (vertices[k], vertices[(k + 1) % n]);
        [b[0] - a[0], b[1] - a[1]]
    };
    if n == 2 && d(0) == [0.0; 2] {
        return Err("its two vertices coincide".into());
    }
    if n < 3 {
        return Ok(());
    }
    for k in 0..n {
        if d(k) == [0.0; 2] {
            return Err(format!("vertices {k} and {} coincide", (k + 1) % n));
        }
    }
    for k in 0..n {
        if cross(d(k), d((k + 1) % n)) == 0.0 {
            return Err(format!(
                "at vertex {} the outline runs straight on or doubles back; leave that vertex out",
                (k + 1) % n
            ));
        }
    }
    let edge = |k: usize| (vertices[k], vertices[(k + 1) % n]);
    let pairs = || (0..n).flat_map(move |i| (i + 2..n).filter(move |&j| !(i == 0 && j == n - 1)).map(move |j| (i, j)));
    if let Some((i, j)) = pairs().find(|&(i, j)| segment_gap(edge(i), edge(j)) == 0.0) {
        return Err(format!(
            "edges {i} and {j} cross: the polygon must be simple (convex or not), its outline going round once"
        ));
    }
    let area2: f64 = (0..n).map(|k| cross(vertices[k], vertices[(k + 1) % n])).sum();
    if area2 <= 0.0 {
        return Err("the vertices must go counter-clockwise round the polygon; these go clockwise".into());
    }
    let convex = (0..n).all(|k| cross(d(k), d((k + 1) % n)) > 0.0);
    if !convex
        && let Some((i, j, gap)) = pairs()
            .map(|(i, j)| (i, j, segment_gap(edge(i), edge(j))))
            .find(|p| p.2 < 2.0 * radius)
    {
        return Err(format!(
            "edges {i} and {j} are {gap:e} m apart, less than twice the sphero-radius ({:e} m): \
             make that arm or notch wider, or the radius smaller",
            2.0 * radius
        ));
    }
    Ok(())
}

/// Distance between two segments (0 where they cross or touch).
fn segment_gap(p: ([f64; 2], [f64; 2]), q: ([f64; 2], [f64; 2])) -> f64 {
    let sub = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
    let side = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| cross(sub(b, a), sub(c, a)).signum();
    if side(p.0, p.1, q.0) * side(p.0, p.1, q.1) <= 0.0 && side(q.0, q.1, p.0) * side(q.0, q.1, p.1) <= 0.0 {
        return 0.0;
    }
    let to_segment = |x: [f64; 2], (a, b): ([f64; 2], [f64; 2])| {
        let (e, w) = (sub(b, a), sub(x, a));
        let t = ((w[0] * e[0] + w[1] * e[1]) / (e[0] * e[0] + e[1] * e[1])).clamp(0.0, 1.0);
        let r = [w[0] - t * e[0], w[1] - t * e[1]];
        (r[0] * r[0] + r[1] * r[1]).sqrt()
    };
    to_segment(p.0, q)
        .min(to_segment(p.1, q))
        .min(to_segment(q.0, p))
        .min(to_segment(q.1, p))
}

#[cfg(test)]
mod tests {
    use super::super::testing::{DEM, check_err, edit, line_of};
    use super::check_polygon;

    const SQUARE: &str =
        "\n[[rigid]]\nmaterial = \"glass\"\nvertices = [[0.0, 0.0], [0.01, 0.0], [0.01, 0.01], [0.0, 0.01]]\nradius = 0.0005\n";

    /// Convex and non-convex simple polygons pass; clockwise, crossing (a pentagram, a bow
    /// tie), straight-on or doubled-back vertices, and non-convex arms thinner than 2a do not.
    #[test]
    fn polygons_are_checked() {
        let a = 0.01;
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(check_polygon(&sq, a).is_ok() && check_polygon(&sq[..1], a).is_ok() && check_polygon(&sq[..2], a).is_ok());
        let clockwise: Vec<_> = sq.iter().rev().copied().collect();
        assert!(check_polygon(&clockwise, a).unwrap_err().contains("counter-clockwise"));
        let dart = [[0.0, 0.0], [2.0, 0.0], [1.0, 0.3], [1.0, 2.0]];
        assert!(check_polygon(&dart, a).is_ok());
        let star = [[0.0, 1.0], [-0.59, -0.81], [0.95, 0.31], [-0.95, 0.31], [0.59, -0.81]];
        assert!(check_polygon(&star, a).unwrap_err().contains("cross"));
        let bow_tie = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(check_polygon(&bow_tie, a).unwrap_err().contains("cross"));
        let straight = [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 1.0]];
        assert!(check_polygon(&straight, a).unwrap_err().contains("vertex 1"));
        // A U: arms 0.2 wide round a notch 0.6 wide, fine at a = 0.05, not at a = 0.15.
        let u = [
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0],
            [0.8, 1.0],
            [0.8, 0.2],
            [0.2, 0.2],
            [0.2, 1.0],
            [0.0, 1.0],
        ];
        assert!(check_polygon(&u, 0.05).is_ok());
        assert!(check_polygon(&u, 0.15).unwrap_err().contains("wider"));
        assert!(check_polygon(&[], a).is_err() && check_polygon(&[[1.0, 0.0], [1.0, 0.0]], a).is_err());
    }

    #[test]
    fn rigid_errors_name_the_body_and_the_field() {
        let ok = format!("{DEM}{SQUARE}");
        let scene = super::super::from_str(&ok, std::path::Path::new("t.toml"), 0).unwrap();
        assert_eq!(scene.rigids.len(), 1);
        assert_eq!((scene.rigids[0].radius, scene.rigids[0].motion), (0.0005, super::RigidMotion::Free));
        let text = edit(
            &ok,
            "[0.01, 0.0], [0.01, 0.01], [0.0, 0.01]",
            "[0.0, 0.01], [0.01, 0.01], [0.01, 0.0]",
        );
        check_err(
            &text,
            Some(line_of(&text, "vertices = [[0.0")),
            "rigid.0.vertices",
            "counter-clockwise",
        );
        let text = edit(&ok, "material = \"glass\"\nvertices", "material = \"granite\"\nvertices");
        check_err(
            &text,
            Some(line_of(&text, "material = \"granite\"")),
            "rigid.0.material",
            "no material named `granite`",
        );
        let text = format!("{ok}motion = \"glued\"\n");
        check_err(
            &text,
            Some(line_of(&text, "motion = ")),
            "rigid.0.motion",
            "\"free\", \"fixed\" or \"scripted\"",
        );
        let text = format!("{ok}motion = \"fixed\"\nspin = 1.0\n");
        check_err(&text, Some(line_of(&text, "motion = ")), "rigid.0.motion", "does not move");
        let text = edit(&ok, "radius = 0.0005", "radius = 0.0");
        check_err(&text, Some(line_of(&text, "radius = 0.0")), "rigid.0.radius", "must be > 0");
        let text = edit(&ok, "radius = 0.0005\n", "");
        check_err(&text, Some(line_of(&text, "vertices = [[0.0")), "rigid.0.radius", "sphero-radius");
        let text = edit(&ok, "cell_size = 0.002", "cell_size = 0.002\nperiodic = [true, false]");
        check_err(&text, None, "rigid", "periodic");
    }

    /// A rigid body and a continuum: DEM and MPM under a coupler, no oracle (no zones to
    /// publish), with the contact radius of Jiang 2020 eq. 45 (2 × 2 points in a 2-mm cell:
    /// between 1 and 2 mm, 1 by default); a hybrid body beside a rigid one is refused.
    #[test]
    fn a_rigid_body_meets_a_continuum_by_contact() {
        use crate::Role;
        let mpm = edit(
            DEM,
            "damping = 7.0\nfriction = 0.4\n",
            "damping = 7.0\nfriction = 0.4\n[material.mpm]\nyoung = 2.5e6\npoisson = 0.3\nfriction_angle = 20.0\npacking = 0.8\n",
        );
        let mpm = edit(&mpm, "model = \"dem\"", "model = \"mpm\"");
        let ok = format!("{mpm}{SQUARE}");
        let scene = super::super::from_str(&ok, std::path::Path::new("t.toml"), 0).unwrap();
        assert_eq!(scene.participants(), [Role::Dem, Role::Mpm, Role::Coupler]);
        assert!(scene.contact_coupling());
        assert!((scene.contact_radius() - 1e-3).abs() < 1e-15, "{}", scene.contact_radius());
        let given = super::super::from_str(
            &format!("{ok}[coupling]\ncontact_radius = 1.2e-3\n"),
            std::path::Path::new("t.toml"),
            0,
        )
        .unwrap();
        assert_eq!(given.contact_radius(), 1.2e-3);
        let text = format!("{ok}[coupling]\ncontact_radius = 3e-3\n");
        check_err(
            &text,
            Some(line_of(&text, "contact_radius")),
            "coupling.contact_radius",
            "must be below the cell size h = 2.0000e-3 m",
        );
        let text = edit(&ok, "model = \"mpm\"", "model = \"hybrid\"");
        check_err(&text, None, "rigid", "not a hybrid band");
        let text =
            format!("{ok}\n[[body]]\nmaterial = \"glass\"\nmodel = \"dem\"\nshape = \"box\"\nmin = [0.06, 0.0]\nmax = [0.08, 0.02]\n");
        check_err(&text, None, "rigid", "do not mix");
        let text = format!("{ok}[coupling]\ncontact_radius = 2e-3\n");
        check_err(
            &text,
            Some(line_of(&text, "contact_radius")),
            "coupling.contact_radius",
            "below the cell size",
        );
        let text = format!("{ok}[coupling]\nsubsteps = \"auto\"\n");
        check_err(&text, Some(line_of(&text, "substeps")), "coupling.substeps", "no hybrid body");
        let dem_only = super::super::from_str(&format!("{DEM}{SQUARE}"), std::path::Path::new("t.toml"), 0).unwrap();
        assert!(!dem_only.contact_coupling() && dem_only.participants() == [Role::Dem]);
    }
}
