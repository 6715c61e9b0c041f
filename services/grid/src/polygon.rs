//! Where a point is against a convex polygon: the nearest point of its outline, and the
//! signed distance (the rigid bodies' contacts in the DEM; the MPM's seeding, which leaves
//! out the points a body covers).

use glam::DVec2;

fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Where a point is against a polygon ([`near`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Near {
    /// The nearest point of the polygon's outline...
    pub y: DVec2,
    /// ... the vertex it is, if it is one;
    pub vertex: Option<usize>,
    /// the signed distance to it (negative inside a polygon of three vertices or more)...
    pub gap: f64,
    /// ... along this unit normal, which points from the polygon to the point (outward).
    pub normal: DVec2,
}

/// Where `p` is against the polygon `poly` (world vertices; one vertex: a point, two: a
/// segment). A point inside a polygon is at a negative distance from its outline, with the
/// normal pointing out through the nearest edge, so that a contact pushes it out, never on
/// through.
pub fn near(poly: &[DVec2], p: DVec2) -> Near {
    let n = poly.len();
    let edges = match n {
        1 => 0,
        2 => 1,
        _ => n,
    };
    let (mut y, mut vertex, mut best, mut edge) = (poly[0], Some(0), (p - poly[0]).length_squared(), None);
    for k in 0..edges {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let e = b - a;
        let t = ((p - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
        let at = a + e * t;
        let d2 = (p - at).length_squared();
        if d2 < best {
            (y, best, edge) = (at, d2, Some(k));
            vertex = if t == 0.0 {
                Some(k)
            } else if t == 1.0 {
                Some((k + 1) % n)
            } else {
                None
            };
        }
    }
    let inside = n >= 3 && (0..n).all(|k| cross(poly[(k + 1) % n] - poly[k], p - poly[k]) >= 0.0);
    let d = best.sqrt();
    let normal = if d > 0.0 {
        (p - y) / d
    } else if let Some(k) = edge {
        // On the outline: the edge's outward normal (counter-clockwise polygons).
        let e = poly[(k + 1) % n] - poly[k];
        DVec2::new(e.y, -e.x).normalize()
    } else {
        DVec2::ZERO
    };
    if inside {
        Near {
            y,
            vertex,
            gap: -d,
            normal: if d > 0.0 { -normal } else { normal },
        }
    } else {
        Near { y, vertex, gap: d, normal }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nearest point and vertex, and the signed distance with its outward normal: outside
    /// off an edge and off a corner, inside (negative, out through the nearest edge), and of a
    /// point and a segment.
    #[test]
    fn near_finds_the_nearest_point_and_the_side() {
        let sq = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y];
        let at = near(&sq, DVec2::new(0.5, -0.2));
        assert_eq!((at.y, at.vertex, at.normal), (DVec2::new(0.5, 0.0), None, -DVec2::Y));
        assert!((at.gap - 0.2).abs() < 1e-15);
        let at = near(&sq, DVec2::new(1.5, 1.5));
        assert_eq!((at.y, at.vertex), (DVec2::ONE, Some(2)));
        assert!((at.gap - 0.5f64.sqrt()).abs() < 1e-15 && (at.normal - DVec2::ONE.normalize()).length() < 1e-15);
        let at = near(&sq, DVec2::new(0.5, 0.1));
        assert_eq!((at.y, at.vertex, at.normal), (DVec2::new(0.5, 0.0), None, -DVec2::Y));
        assert!((at.gap + 0.1).abs() < 1e-15, "inside: {}", at.gap);
        let at = near(&sq[..1], DVec2::new(3.0, 4.0));
        assert_eq!((at.y, at.vertex, at.gap), (DVec2::ZERO, Some(0), 5.0));
        let at = near(&sq[..2], DVec2::new(0.25, -1.0));
        assert_eq!((at.y, at.vertex, at.gap, at.normal), (DVec2::new(0.25, 0.0), None, 1.0, -DVec2::Y));
    }
}
