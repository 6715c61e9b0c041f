//! Boundary conditions on grid nodes: the velocity a node may keep when it lies in a wall.
//!
//! A node in a wall (on or behind its surface) moving into the wall relative to the wall's
//! velocity u is corrected:
//! - sticky: v = u (always, also when separating);
//! - slip: the normal part of v − u is removed;
//! - friction μ: the normal part is removed and the tangential part shortened by μ |v_n|
//!   (Coulomb: the impulse that stops the normal motion bounds the tangential one), to zero at most.
//!
//! Separating nodes are left free except on sticky walls.
//!
//! A segment (2D) is one-sided on the grid: material stays on its left (the side of the
//! normal from → to turned counter-clockwise), and nodes on it or up to `thickness` behind it
//! are in the wall (between its ends, the ends included). Grains
//! see both sides (the DEM); the continuum only needs the side it fills, and a wall of one
//! node row would let points leak through between the rows.
//! A drum keeps material inside its circle; its surface moves at the spin's velocity.

use grains_grid::space::segment_frame;
use grains_grid::{Space, Vector};

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Contact {
    Sticky,
    Slip,
    Friction(f64),
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub enum Geometry<S: Space> {
    /// Half-space boundary through `point` with inward unit `normal`.
    Plane { point: S::V, normal: S::V },
    /// Material kept inside the box.
    Box { min: S::V, max: S::V },
    /// 2D thin wall from `from` to `to`, material on its left; nodes up to `thickness` behind.
    Segment { from: S::V, to: S::V, thickness: f64 },
    /// Material kept inside the circle (2D) or the cylinder along z (3D), turning at `spin`
    /// [rad/s] about z, counter-clockwise positive.
    Drum { center: S::V, radius: f64, spin: f64 },
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Wall<S: Space> {
    pub geometry: Geometry<S>,
    pub contact: Contact,
    /// Translation velocity [m/s]: the wall is at its start position + shift + velocity · t.
    pub velocity: S::V,
    /// What keeps the position continuous when the velocity changes during a run [m].
    pub shift: S::V,
    /// The scene wall this one comes from.
    pub id: usize,
}

impl<S: Space> Wall<S> {
    /// A new translation velocity from time `t` on; the wall stays where it is at `t`.
    pub fn set_velocity(&mut self, velocity: S::V, t: f64) {
        self.shift += (self.velocity - velocity) * t;
        self.velocity = velocity;
    }

    /// Whether `x` lies behind the wall at time `t` (where no material is seeded): behind a
    /// plane, outside a box or a drum, within a segment's thickness behind it.
    pub fn behind(&self, x: S::V, t: f64) -> bool {
        let x = x - self.shift - self.velocity * t;
        match self.geometry {
            Geometry::Plane { point, normal } => (x - point).dot(normal) < 0.0,
            Geometry::Box { min, max } => {
                let (xa, lo, hi) = (S::to_array(x), S::to_array(min), S::to_array(max));
                (0..S::DIM).any(|k| xa[k] < lo[k] || xa[k] > hi[k])
            }
            Geometry::Segment { from, to, thickness } => {
                let f = segment_frame(S::to_array(from), S::to_array(to), S::to_array(x));
                f.between_ends(true) && f.ahead < 0.0 && f.ahead >= -thickness
            }
            Geometry::Drum { center, radius, .. } => {
                let (c, p) = (S::to_array(center), S::to_array(x));
                (p[0] - c[0]).hypot(p[1] - c[1]) > radius
            }
        }
    }

    /// The corrected velocity of a node at `x` with velocity `v` at time `t`.
    #[inline]
    pub fn apply(&self, x: S::V, v: S::V, t: f64) -> S::V {
        let x = x - self.shift - self.velocity * t;
        match self.geometry {
            Geometry::Plane { point, normal } => {
                if (x - point).dot(normal) <= 0.0 {
                    correct::<S>(self.contact, v, self.velocity, normal)
                } else {
                    v
                }
            }
            Geometry::Box { min, max } => {
                let (xa, lo, hi) = (S::to_array(x), S::to_array(min), S::to_array(max));
                let mut v = v;
                for k in 0..S::DIM {
                    let mut n = [0.0; 3];
                    if xa[k] <= lo[k] {
                        n[k] = 1.0;
                    } else if xa[k] >= hi[k] {
                        n[k] = -1.0;
                    } else {
                        continue;
                    }
                    v = correct::<S>(self.contact, v, self.velocity, S::from_array(n));
                }
                v
            }
            Geometry::Segment { from, to, thickness } => {
                let f = segment_frame(S::to_array(from), S::to_array(to), S::to_array(x));
                // Closed ends: an orifice between two segments ending on nodes opens the
                // nodes strictly between them, whose velocity falls to zero at the end nodes:
                // the opening is the orifice's width.
                if f.between_ends(true) && f.ahead <= 0.0 && f.ahead >= -thickness {
                    correct::<S>(self.contact, v, self.velocity, S::from_array([f.normal[0], f.normal[1], 0.0]))
                } else {
                    v
                }
            }
            Geometry::Drum { center, radius, spin } => {
                let (c, p) = (S::to_array(center), S::to_array(x));
                let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
                let r = dx.hypot(dy);
                if r < radius || r == 0.0 {
                    return v;
                }
                // The drum's surface at the node's angle moves at ω ẑ × (x − c).
                let u = self.velocity + S::from_array([-spin * dy * radius / r, spin * dx * radius / r, 0.0]);
                correct::<S>(self.contact, v, u, S::from_array([-dx / r, -dy / r, 0.0]))
            }
        }
    }
}

/// Velocity of a node in contact with a wall of velocity `u` and inward unit normal `n`.
#[inline]
pub fn correct<S: Space>(contact: Contact, v: S::V, u: S::V, n: S::V) -> S::V {
    if contact == Contact::Sticky {
        return u;
    }
    let rel = v - u;
    let vn = rel.dot(n);
    if vn >= 0.0 {
        return v;
    }
    let tangential = rel - n * vn;
    match contact {
        Contact::Slip => u + tangential,
        Contact::Friction(mu) => {
            let vt = tangential.length();
            if vt <= mu * -vn {
                u
            } else {
                u + tangential * (1.0 - mu * -vn / vt)
            }
        }
        Contact::Sticky => unreachable!(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;
    use grains_grid::D2;

    #[test]
    fn wall_contacts_remove_what_they_should() {
        let floor = |contact| Wall::<D2> {
            geometry: Geometry::Plane {
                point: DVec2::ZERO,
                normal: DVec2::Y,
            },
            contact,
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        };
        let (below, v) = (DVec2::new(0.0, -0.01), DVec2::new(3.0, -1.0));
        assert_eq!(floor(Contact::Sticky).apply(below, v, 0.0), DVec2::ZERO);
        assert_eq!(floor(Contact::Slip).apply(below, v, 0.0), DVec2::new(3.0, 0.0));
        // μ |v_n| = 0.5 of the 3 m/s of sliding is taken away.
        assert_eq!(floor(Contact::Friction(0.5)).apply(below, v, 0.0), DVec2::new(2.5, 0.0));
        assert_eq!(floor(Contact::Friction(5.0)).apply(below, v, 0.0), DVec2::ZERO);
        // Separating or above the wall: untouched.
        assert_eq!(floor(Contact::Slip).apply(below, DVec2::new(3.0, 1.0), 0.0), DVec2::new(3.0, 1.0));
        assert_eq!(floor(Contact::Slip).apply(DVec2::new(0.0, 0.01), v, 0.0), v);
        // A floor rising at 1 m/s: at t = 0.1 it is at y = 0.1; a node at y = 0.05 resting
        // gets the floor's normal velocity.
        let mut lift = floor(Contact::Slip);
        lift.velocity = DVec2::new(0.0, 1.0);
        assert_eq!(lift.apply(DVec2::new(0.0, 0.05), DVec2::ZERO, 0.1), DVec2::new(0.0, 1.0));
        // A box keeps material in: a node beyond the right face cannot move right.
        let b = Wall::<D2> {
            geometry: Geometry::Box {
                min: DVec2::ZERO,
                max: DVec2::ONE,
            },
            contact: Contact::Slip,
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        };
        assert_eq!(b.apply(DVec2::new(1.0, 0.5), DVec2::new(2.0, 1.0), 0.0), DVec2::new(0.0, 1.0));
    }

    #[test]
    fn a_segment_holds_material_on_its_left_and_lets_it_pass_beside() {
        // A silo bottom from x = 0 to 1 at y = 0 (left normal +y), two cells of 0.1 thick.
        let bottom = Wall::<D2> {
            geometry: Geometry::Segment {
                from: DVec2::ZERO,
                to: DVec2::X,
                thickness: 0.2,
            },
            contact: Contact::Slip,
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        };
        let down = DVec2::new(1.0, -2.0);
        // On the segment and behind it within its thickness: the fall is stopped.
        assert_eq!(bottom.apply(DVec2::new(0.5, 0.0), down, 0.0), DVec2::new(1.0, 0.0));
        assert_eq!(bottom.apply(DVec2::new(0.5, -0.15), down, 0.0), DVec2::new(1.0, 0.0));
        // In front of it, beyond its thickness, or past its end (the orifice): free.
        assert_eq!(bottom.apply(DVec2::new(0.5, 0.05), down, 0.0), down);
        assert_eq!(bottom.apply(DVec2::new(0.5, -0.25), down, 0.0), down);
        assert_eq!(bottom.apply(DVec2::new(1.05, 0.0), down, 0.0), down);
        assert_eq!(
            bottom.apply(DVec2::new(1.0, 0.0), down, 0.0),
            DVec2::new(1.0, 0.0),
            "its end is in it"
        );
        // Reversed, its left is −y: material below is held up there, material above is not.
        let mut roof = bottom;
        roof.geometry = Geometry::Segment {
            from: DVec2::X,
            to: DVec2::ZERO,
            thickness: 0.2,
        };
        assert_eq!(roof.apply(DVec2::new(0.5, 0.1), -down, 0.0), DVec2::new(-1.0, 0.0));
        assert_eq!(roof.apply(DVec2::new(0.5, 0.0), down, 0.0), down);
    }

    #[test]
    fn a_spinning_drum_drags_what_presses_on_it() {
        // Radius 1 about the origin, 2 rad/s counter-clockwise: its bottom moves at +2 m/s in x.
        let drum = |contact| Wall::<D2> {
            geometry: Geometry::Drum {
                center: DVec2::ZERO,
                radius: 1.0,
                spin: 2.0,
            },
            contact,
            velocity: DVec2::ZERO,
            shift: DVec2::ZERO,
            id: 0,
        };
        let bottom = DVec2::new(0.0, -1.0);
        // Resting on the bottom and pressing in: a rough drum takes it along at +2 m/s.
        assert_eq!(
            drum(Contact::Sticky).apply(bottom, DVec2::new(0.0, -0.1), 0.0),
            DVec2::new(2.0, 0.0)
        );
        // Frictional: 2 m/s of slip, μ |v_n| = 0.5 × 1 = 0.5 of it taken away.
        let v = drum(Contact::Friction(0.5)).apply(DVec2::new(0.0, -1.01), DVec2::new(0.0, -1.0), 0.0);
        assert!((v - DVec2::new(0.5, 0.0)).length() < 1e-12, "{v}");
        assert!(drum(Contact::Slip).behind(DVec2::new(0.8, 0.8), 0.0) && !drum(Contact::Slip).behind(bottom * 0.9, 0.0));
        // Inside: free; moving away from the surface: free.
        assert_eq!(
            drum(Contact::Slip).apply(DVec2::new(0.0, -0.9), DVec2::new(0.0, -1.0), 0.0),
            DVec2::new(0.0, -1.0)
        );
        assert_eq!(drum(Contact::Slip).apply(bottom, DVec2::new(0.0, 1.0), 0.0), DVec2::new(0.0, 1.0));
    }

    #[test]
    fn a_wall_whose_velocity_changes_stays_where_it_was() {
        // Rising at 1 m/s, then at 3 m/s from t = 0.1 s: at t = 0.2 s it is at
        // y = 0.1 + 3 × 0.1 = 0.4, so a node at rest at y = 0.35 is inside (pushed up at
        // 3 m/s) and one at y = 0.45 is not.
        let mut lift = Wall::<D2> {
            geometry: Geometry::Plane {
                point: DVec2::ZERO,
                normal: DVec2::Y,
            },
            contact: Contact::Slip,
            velocity: DVec2::new(0.0, 1.0),
            shift: DVec2::ZERO,
            id: 0,
        };
        lift.set_velocity(DVec2::new(0.0, 3.0), 0.1);
        assert_eq!(lift.apply(DVec2::new(0.0, 0.35), DVec2::ZERO, 0.2), DVec2::new(0.0, 3.0));
        assert_eq!(lift.apply(DVec2::new(0.0, 0.45), DVec2::ZERO, 0.2), DVec2::ZERO);
        assert!((lift.shift.y + 0.2).abs() < 1e-15, "{}", lift.shift);
    }
}
