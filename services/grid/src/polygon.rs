//! Where a point is against a simple polygon, convex or not: the nearest point of its
//! outline and the signed distance ([`near`]: the MPM's seeding, which leaves out the points
//! a body covers), and the parts of the outline it touches ([`touching`]: the rigid bodies'
//! contacts in the DEM).

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
    nearest(poly, p).0
}

/// [`near`], and the edge the nearest point is on (None for a single vertex).
fn nearest(poly: &[DVec2], p: DVec2) -> (Near, Option<usize>) {
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
    // Left of every edge (a convex polygon's inside, its outline included), or wound around
    // (any simple polygon's inside).
    let inside = n >= 3 && ((0..n).all(|k| cross(poly[(k + 1) % n] - poly[k], p - poly[k]) >= 0.0) || winds(poly, p));
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
    let at = if inside {
        Near {
            y,
            vertex,
            gap: -d,
            normal: if d > 0.0 { -normal } else { normal },
        }
    } else {
        Near { y, vertex, gap: d, normal }
    };
    (at, edge)
}

/// Whether the closed polygon `poly` winds around `p` (the winding number is not zero).
fn winds(poly: &[DVec2], p: DVec2) -> bool {
    let n = poly.len();
    let mut winding = 0;
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let side = cross(b - a, p - a);
        if a.y <= p.y && b.y > p.y && side > 0.0 {
            winding += 1;
        } else if a.y > p.y && b.y <= p.y && side < 0.0 {
            winding -= 1;
        }
    }
    winding != 0
}

/// Whether the polygon (counter-clockwise) turns left at every vertex; one or two vertices
/// count as convex.
pub fn is_convex(poly: &[DVec2]) -> bool {
    let n = poly.len();
    n < 3 || (0..n).all(|k| !is_reflex(poly, k))
}

/// Whether vertex `k` of a counter-clockwise polygon of three vertices or more turns right
/// (its inside angle is over 180°).
pub fn is_reflex(poly: &[DVec2], k: usize) -> bool {
    let n = poly.len();
    n >= 3 && cross(poly[k] - poly[(k + n - 1) % n], poly[(k + 1) % n] - poly[k]) < 0.0
}

/// The parts of the outline of `poly` (counter-clockwise, simple; `convex` as [`is_convex`]
/// says, which a caller knows once per polygon, not per point) that a disk of radius `reach`
/// centred at `p` touches, each as `f(feature, near)`: the point it is nearest to on that
/// part, at the signed distance `near.gap` along `near.normal`.
///
/// - A convex polygon (or a point, or a segment) has one part, the nearest point ([`near`],
///   feature 0), given whatever its distance: a bonded contact holds beyond the reach.
/// - A non-convex one, from outside: each edge `k` whose inner points the disk's centre
///   faces (in front of it and between its ends' normals; feature `k`), and each convex
///   vertex `k` whose corner region (between the normals of its two edges) holds the
///   centre (feature n + k), nearer than `reach`. A centre in a notch may face both its
///   sides: two parts, as a disk wedged in a corner has two contacts. A reflex vertex is
///   never a part: from outside, one of its edges is always as near. From inside (a deep
///   overlap): the nearest edge or vertex only, so that the contact pushes out.
pub fn touching(poly: &[DVec2], convex: bool, p: DVec2, reach: f64, mut f: impl FnMut(u32, Near)) {
    let n = poly.len();
    if convex {
        f(0, near(poly, p));
        return;
    }
    let (at, edge) = nearest(poly, p);
    if at.gap < 0.0 {
        let feature = match at.vertex {
            Some(v) => n + v,
            None => edge.unwrap_or(0),
        };
        f(feature as u32, at);
        return;
    }
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let e = b - a;
        let len2 = e.length_squared();
        let t = (p - a).dot(e) / len2;
        let outward = DVec2::new(e.y, -e.x) / len2.sqrt();
        let gap = (p - a).dot(outward);
        if t > 0.0 && t < 1.0 && gap >= 0.0 && gap < reach {
            let near = Near {
                y: a + e * t,
                vertex: None,
                gap,
                normal: outward,
            };
            f(k as u32, near);
        }
    }
    for k in 0..n {
        if is_reflex(poly, k) {
            continue;
        }
        let (before, v, after) = (poly[(k + n - 1) % n], poly[k], poly[(k + 1) % n]);
        let d = p - v;
        let gap = d.length();
        if d.dot(v - before) >= 0.0 && d.dot(after - v) <= 0.0 && gap < reach {
            // On the vertex itself: out along the bisector of its edges' normals.
            let normal = if gap > 0.0 {
                d / gap
            } else {
                let (e0, e1) = (v - before, after - v);
                (DVec2::new(e0.y, -e0.x).normalize() + DVec2::new(e1.y, -e1.x).normalize()).normalize()
            };
            let near = Near {
                y: v,
                vertex: Some(k),
                gap,
                normal,
            };
            f((n + k) as u32, near);
        }
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

    /// An L (a reflex corner at (1, 1)): inside and outside by winding, also in the arm the
    /// convex test would miss; the parts a disk touches: one edge off a face, one vertex off
    /// a convex corner, both faces in the reflex corner, nothing out of reach; from inside,
    /// the nearest edge only. A convex polygon gives its one nearest point, as `near`.
    #[test]
    fn touching_finds_each_face_a_disk_meets() {
        let l = [
            DVec2::ZERO,
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 1.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0, 2.0),
            DVec2::new(0.0, 2.0),
        ];
        assert!(!is_convex(&l) && is_reflex(&l, 3) && (0..6).filter(|&k| is_reflex(&l, k)).count() == 1);
        assert!(near(&l, DVec2::new(1.5, 0.5)).gap < 0.0 && near(&l, DVec2::new(0.5, 1.5)).gap < 0.0);
        assert!((near(&l, DVec2::new(1.5, 1.5)).gap - 0.5).abs() < 1e-15, "the notch is outside");
        let parts = |p: DVec2, reach: f64| {
            let mut out = Vec::new();
            touching(&l, false, p, reach, |k, at| out.push((k, at)));
            out
        };
        let face = parts(DVec2::new(1.5, -0.1), 0.2);
        assert_eq!(face.len(), 1);
        assert_eq!((face[0].0, face[0].1.normal), (0, -DVec2::Y));
        assert!((face[0].1.gap - 0.1).abs() < 1e-15);
        let corner = parts(DVec2::new(2.1, 1.1), 0.2);
        assert_eq!(corner.len(), 1);
        assert_eq!((corner[0].0, corner[0].1.vertex), (6 + 2, Some(2)));
        assert!((corner[0].1.normal - DVec2::ONE.normalize()).length() < 1e-12);
        let notch = parts(DVec2::new(1.1, 1.05), 0.2);
        let faces: Vec<(u32, DVec2)> = notch.iter().map(|(k, at)| (*k, at.normal)).collect();
        assert_eq!(faces, vec![(2, DVec2::Y), (3, DVec2::X)]);
        assert!(parts(DVec2::new(1.5, 1.5), 0.2).is_empty());
        let deep = parts(DVec2::new(1.5, 0.9), 0.2);
        assert_eq!(deep.len(), 1);
        assert_eq!((deep[0].0, deep[0].1.normal), (2, DVec2::Y));
        assert!((deep[0].1.gap + 0.1).abs() < 1e-12);
        let sq = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y];
        let mut one = Vec::new();
        assert!(is_convex(&sq));
        touching(&sq, true, DVec2::new(3.0, 0.5), 0.1, |k, at| one.push((k, at)));
        assert_eq!(one, vec![(0, near(&sq, DVec2::new(3.0, 0.5)))]);
    }
}
