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

use grains_grid::{Space, Vector};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Contact {
    Sticky,
    Slip,
    Friction(f64),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Geometry<S: Space> {
    /// Half-space boundary through `point` with inward unit `normal`.
    Plane { point: S::V, normal: S::V },
    /// Material kept inside the box.
    Box { min: S::V, max: S::V },
}

#[derive(Clone, Copy, Debug, PartialEq)]
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
