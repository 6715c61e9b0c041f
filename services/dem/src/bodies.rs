//! Rigid spheropolygons in 2D (Jiang 2020 §3, after Alonso-Marroquín 2008): a simple polygon,
//! convex or not, swept by a disk of radius `a` (their Minkowski sum, eq. 37), moving as one
//! rigid body.
//!
//! Contacts are vertex–edge (eqs. 38–43): a vertex V of one body touches another body where its
//! distance d to the nearest point Y of the other's polygon is under a_i + a_j; the overlap is
//! ξ = a_i + a_j − d, the normal N = (V − Y)/d, and the force acts at the middle of the overlap,
//! p = V − (a_i − ξ/2) N (eq. 41), with the torques about both centres of mass (eq. 40). The law
//! is the grains' ([`contact_force`]: spring–dashpot, tangential anchor spring, Coulomb cap).
//!
//! - Against a convex polygon, one contact per vertex and body it touches: the vertex against
//!   the nearest point of the other polygon (an edge, or an end of one), so a vertex near a
//!   corner is not counted once per edge. Of the two passes of a pair (i's vertices on j, j's
//!   on i), the second leaves out touches whose nearest point is a vertex of i: a
//!   vertex–vertex touch is then counted once (V_j within reach of V_i puts V_i within reach
//!   of j, so the first pass has it).
//! - Against a non-convex polygon, one contact per part of its outline the vertex touches
//!   ([`touching`]: each edge it faces, each convex corner whose region holds it), so a vertex
//!   in a notch meets both its sides, as eq. 39's sum over vertex–edge pairs has it. A reflex
//!   vertex touches nothing itself: whatever reaches it from outside meets one of its edges
//!   first, and is counted there. The history of a contact is kept per part (a vertex
//!   sliding round a corner of a non-convex body starts a new tangential spring), and a bond
//!   to a non-convex body holds only while the two touch.
//! - A grain meets a body as a one-vertex body of its radius; so does, in the coupling with
//!   the MPM (Jiang 2020 §4), a material point of contact radius r_p.
//! - The damping takes the contact's effective mass along N, 1 / (Σ 1/m + (r × N)²/I) over
//!   both sides (infinite masses left out): for two grains that is the reduced mass the
//!   grains' law uses; for a body hit off its centre it is what makes the restitution e of the
//!   material hold for the normal impulse, as in rigid-body impact.
//! - A contact takes the law of the body's material (of the first body for two; a grain
//!   against a body takes the body's), with a wall's friction against a wall.
//!
//! Bodies move by the grains' velocity Verlet ([`kick_drift`], [`half_kick`]): free ones with
//! their mass and moment of inertia from the shape ([`mass_properties`]), fixed ones not at
//! all, scripted ones at a set velocity and spin whatever the forces (the forces on them are
//! still recorded: the load on a floor or a tool).

use crate::contact::{ContactParams, ContactState, contact_force};
use crate::space::D2;
use crate::state::{Wall, WallShape};
use glam::DVec2;
pub use grains_grid::polygon::{Near, is_convex, is_reflex, near, touching};

/// How a body moves.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Motion {
    /// By the forces on it and gravity.
    Free,
    /// Never.
    Fixed,
    /// At this velocity [m/s] and spin [rad/s] (counter-clockwise positive), whatever the
    /// forces.
    Scripted { velocity: DVec2, spin: f64 },
}

/// A rigid spheropolygon.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Body {
    pub id: u64,
    /// The polygon's vertices in the body's frame, counter-clockwise, about the centre of mass
    /// of the swept shape (one vertex: a disk; two: a rod with round ends).
    pub shape: Vec<DVec2>,
    /// Sphero-radius a [m].
    pub radius: f64,
    /// Centre of mass [m], orientation [rad], their rates.
    pub x: DVec2,
    pub angle: f64,
    pub v: DVec2,
    pub omega: f64,
    /// [kg] (2D: per metre of thickness) and [kg m²] about the centre of mass.
    pub mass: f64,
    pub inertia: f64,
    /// Index into [`crate::state::DemParams::materials`].
    pub material: u32,
    pub motion: Motion,
    /// Force [N] and torque [N m] of its contacts at the last evaluation (gravity not in it).
    pub force: DVec2,
    pub torque: f64,
    /// Force [N] and torque [N m] added at every step: the reactions of the material points
    /// in contact with it ([`point_forces`]), held over a macro-step.
    pub external: DVec2,
    pub external_torque: f64,
}

/// Area, centroid and polar second moment (about the centroid, per unit density) of a
/// spheropolygon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    pub area: f64,
    pub centroid: DVec2,
    /// ∫ |x − c|² dA [m⁴].
    pub second_moment: f64,
}

fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// ω × r in the plane.
fn spin_cross(omega: f64, r: DVec2) -> DVec2 {
    DVec2::new(-omega * r.y, omega * r.x)
}

/// The mass properties of the polygon `vertices` (simple, counter-clockwise) swept by a disk
/// of radius `a`, exactly: the polygon, a rectangle of width a outside each edge, at each
/// convex vertex a circular sector of radius a spanning the turn between its edges' normals,
/// less at each reflex vertex the kite where its two edges' rectangles overlap. Exact while
/// the rectangles meet nowhere else: no part of the polygon, and no gap between two of its
/// parts, narrower than 2a.
pub fn mass_properties(vertices: &[DVec2], a: f64) -> MassProperties {
    let n = vertices.len();
    // Accumulated about the origin: area, first moment, second moment.
    let (mut area, mut first, mut second) = (0.0, DVec2::ZERO, 0.0);
    let mut add = |m: f64, c: DVec2, own: f64| {
        area += m;
        first += c * m;
        second += own + m * c.length_squared();
    };
    if n >= 3 {
        // The polygon by its triangles from the origin (shoelace).
        for k in 0..n {
            let (p, q) = (vertices[k], vertices[(k + 1) % n]);
            let w = 0.5 * cross(p, q);
            let c = (p + q) / 3.0;
            // About the origin: w (|p|² + p·q + |q|²) / 6; recorded as its own moment about c.
            let about_origin = w * (p.length_squared() + p.dot(q) + q.length_squared()) / 6.0;
            add(w, c, about_origin - w * c.length_squared());
        }
    }
    // An edge's outward normal (counter-clockwise: the edge direction turned clockwise).
    let edges = match n {
        1 => 0,
        2 => 2,
        _ => n,
    };
    let normal = |k: usize| {
        let e = vertices[(k + 1) % n] - vertices[k];
        DVec2::new(e.y, -e.x) / e.length()
    };
    for k in 0..edges {
        let (p, q) = (vertices[k], vertices[(k + 1) % n]);
        let len = (q - p).length();
        let m = len * a;
        add(m, 0.5 * (p + q) + normal(k) * (0.5 * a), m * (len * len + a * a) / 12.0);
    }
    for (k, &vertex) in vertices.iter().enumerate() {
        // The sector between the normals of the edges before and after vertex k.
        let (turn, bisector) = if edges == 0 {
            (2.0 * std::f64::consts::PI, DVec2::X)
        } else {
            let (before, after) = (normal((k + edges - 1) % edges), normal(k % edges));
            let turn = cross(before, after).atan2(before.dot(after));
            // A rod's ends turn by π (its two normals are opposite).
            let turn = if n == 2 { std::f64::consts::PI } else { turn };
            if turn < 0.0 {
                // A reflex vertex: the rectangles outside its two edges overlap in the kite
                // V, V + a N_before, P, V + a N_after, P where the offset edges cross.
                let far = vertex + (before + after) * (a / (1.0 + before.dot(after)));
                for (p, q) in [(vertex + before * a, far), (far, vertex + after * a)] {
                    let (w, c, own) = triangle(vertex, p, q);
                    add(-w.abs(), c, -own.abs());
                }
                continue;
            }
            let b = before + after;
            (
                turn,
                if b.length() > 1e-12 {
                    b.normalize()
                } else {
                    DVec2::new(-before.y, before.x)
                },
            )
        };
        let m = 0.5 * turn * a * a;
        if m == 0.0 {
            continue;
        }
        // Centroid at 4 a sin(θ/2) / (3 θ) along the bisector; ∫ r² dA = θ a⁴ / 4 about the apex.
        let d = 4.0 * a * (0.5 * turn).sin() / (3.0 * turn);
        add(m, vertex + bisector * d, 0.25 * turn * a.powi(4) - m * d * d);
    }
    let centroid = first / area;
    MassProperties {
        area,
        centroid,
        second_moment: second - area * centroid.length_squared(),
    }
}

/// Area, centroid and second moment about the centroid of the triangle p q r (signed:
/// negative clockwise).
fn triangle(p: DVec2, q: DVec2, r: DVec2) -> (f64, DVec2, f64) {
    let w = 0.5 * cross(q - p, r - p);
    let c = (p + q + r) / 3.0;
    let about_origin = w * (p.length_squared() + q.length_squared() + r.length_squared() + p.dot(q) + q.dot(r) + r.dot(p)) / 6.0;
    (w, c, about_origin - w * c.length_squared())
}

impl Body {
    /// A body of the polygon `vertices` (scene coordinates, simple, counter-clockwise: the
    /// scene checks it) swept by `radius`, of `density` [kg/m²], at rest (or moving as
    /// scripted).
    pub fn new(id: u64, vertices: &[DVec2], radius: f64, density: f64, material: u32, motion: Motion) -> Body {
        let props = mass_properties(vertices, radius);
        let (v, omega) = match motion {
            Motion::Scripted { velocity, spin } => (velocity, spin),
            _ => (DVec2::ZERO, 0.0),
        };
        Body {
            id,
            shape: vertices.iter().map(|&p| p - props.centroid).collect(),
            radius,
            x: props.centroid,
            angle: 0.0,
            v,
            omega,
            mass: density * props.area,
            inertia: density * props.second_moment,
            material,
            motion,
            force: DVec2::ZERO,
            torque: 0.0,
            external: DVec2::ZERO,
            external_torque: 0.0,
        }
    }

    /// The polygon's vertices where the body is now.
    pub fn vertices(&self) -> Vec<DVec2> {
        let rot = DVec2::from_angle(self.angle);
        self.shape.iter().map(|&p| self.x + rot.rotate(p)).collect()
    }

    /// Whether a disk at `p` of radius `r` overlaps the body (inside its polygon, or nearer to
    /// it than r + a).
    pub fn overlaps(&self, p: DVec2, r: f64) -> bool {
        near(&self.vertices(), p).gap < r + self.radius
    }

    /// The outline of the swept shape where the body is now, counter-clockwise: each edge
    /// moved out by a, and `per_arc` segments on the arc of radius a around each convex
    /// vertex (a disk: 4 `per_arc` segments); at a reflex vertex the point where its two
    /// moved edges cross.
    pub fn outline(&self, per_arc: usize) -> Vec<DVec2> {
        let poly = self.vertices();
        let n = poly.len();
        let normal = |k: usize| {
            let e = poly[(k + 1) % n] - poly[k];
            DVec2::new(e.y, -e.x).normalize()
        };
        let mut out = Vec::new();
        for (k, &vertex) in poly.iter().enumerate() {
            let (from, turn) = match n {
                1 => (0.0, 2.0 * std::f64::consts::PI),
                // A rod: half a turn at each end, from the normal of the edge that arrives.
                2 => (normal((k + 1) % 2).to_angle(), std::f64::consts::PI),
                _ => {
                    let (a, b) = (normal((k + n - 1) % n), normal(k));
                    let turn = cross(a, b).atan2(a.dot(b));
                    if turn < 0.0 {
                        out.push(vertex + (a + b) * (self.radius / (1.0 + a.dot(b))));
                        continue;
                    }
                    (a.to_angle(), turn)
                }
            };
            let steps = if n == 1 { 4 * per_arc } else { per_arc };
            for s in 0..=steps {
                if self.radius == 0.0 && s > 0 {
                    break;
                }
                let t = from + turn * s as f64 / steps as f64;
                out.push(vertex + DVec2::from_angle(t) * self.radius);
            }
        }
        out
    }

    /// Distance from the centre of mass to the farthest point of the swept shape.
    pub fn reach(&self) -> f64 {
        self.shape.iter().map(|p| p.length()).fold(0.0, f64::max) + self.radius
    }

    fn side(&self) -> Side {
        let free = self.motion == Motion::Free;
        Side {
            x: self.x,
            v: self.v,
            omega: self.omega,
            inv_mass: if free { 1.0 / self.mass } else { 0.0 },
            inv_inertia: if free { 1.0 / self.inertia } else { 0.0 },
        }
    }

    /// Kinetic energy [J] (translation and rotation).
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self.mass * self.v.length_squared() + 0.5 * self.inertia * self.omega * self.omega
    }
}

/// One side of a contact: its centre, velocity, spin and inverse inertias (0 for a side that
/// does not yield: a wall, a fixed or scripted body, a frozen grain).
#[derive(Clone, Copy, Debug)]
pub struct Side {
    pub x: DVec2,
    pub v: DVec2,
    pub omega: f64,
    pub inv_mass: f64,
    pub inv_inertia: f64,
}

/// What a contact is between, for its history: a body's vertex and a body, a grain or a
/// material point (by id) and a body, or a body's vertex and a wall (a segment wall's ends
/// are vertices `u32::MAX` and `u32::MAX − 1`); `feature` is the part of the other body's
/// outline touched ([`touching`]: 0 on a convex body, which has one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub enum Key {
    Bodies { of: u64, vertex: u32, on: u64, feature: u32 },
    Grain { grain: u64, body: u64, feature: u32 },
    Point { point: u64, body: u64, feature: u32 },
    Wall { body: u64, vertex: u32, wall: u32, feature: u32 },
}

/// The contacts of the last evaluation with their tangential springs, sorted by key (the
/// history a body's contacts carry from step to step; carried through checkpoints).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BodyContacts {
    pub list: Vec<(Key, ContactState<DVec2>)>,
}

/// A contact's force on the first side and where it acts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Touch {
    pub force: DVec2,
    pub point: DVec2,
}

/// Evaluates the contact of a vertex `v` (sphero-radius `a_v`, on side `s`) with the other
/// side's polygon (sphero-radius `a_y`, side `o`), `gap` from it along the outward `normal`
/// ([`near`]), advancing `state` by dt; `None` apart, or between two sides that neither
/// yields (a fixed body on a wall: no dynamics, and no damping to derive), the history
/// cleared. The force is on `s`.
#[allow(clippy::too_many_arguments)]
pub fn touch(
    law: &ContactParams,
    v: DVec2,
    a_v: f64,
    s: &Side,
    normal: DVec2,
    gap: f64,
    a_y: f64,
    o: &Side,
    scale: f64,
    dt: f64,
    state: &mut ContactState<DVec2>,
) -> Option<Touch> {
    let overlap = a_v + a_y - gap;
    let point = v - normal * (a_v - 0.5 * overlap);
    let (rs, ro) = (point - s.x, point - o.x);
    let inv = s.inv_mass + s.inv_inertia * cross(rs, normal).powi(2) + o.inv_mass + o.inv_inertia * cross(ro, normal).powi(2);
    if (overlap <= 0.0 && !state.bonded) || normal == DVec2::ZERO || inv == 0.0 {
        *state = ContactState::default();
        return None;
    }
    let v_rel = (s.v + spin_cross(s.omega, rs)) - (o.v + spin_cross(o.omega, ro));
    // A hybrid grain's mass is scaled by 1 − w already; the grains' law scales the damping of
    // the unscaled mass by it, √(s m) √s = s √m.
    let gamma = law.gamma(law.damping_factor(), 1.0 / inv) * scale.sqrt();
    let c = contact_force::<D2>(law, overlap, normal, v_rel, gamma, scale, dt, state);
    c.active.then_some(Touch { force: c.force, point })
}

/// A grain as the contacts see it: centre, velocity, spin, radius, inverse mass (0 frozen),
/// hybrid scale, id and storage index.
#[derive(Clone, Copy, Debug)]
pub struct GrainView {
    pub index: usize,
    pub x: DVec2,
    pub v: DVec2,
    pub omega: f64,
    pub radius: f64,
    pub inv_mass: f64,
    pub scale: f64,
    pub id: u64,
}

/// Every contact of the bodies (with each other, with the grains and with the walls) at the
/// current positions: sets each body's `force` and `torque`, returns the force and torque on
/// each grain touched (its `index`, in order of evaluation), and advances the histories by dt
/// (0: forces only). Pairs are found by the bodies' reach ([`Body::reach`]); `grains` need
/// only hold those within some body's reach.
pub fn forces(
    bodies: &mut [Body],
    grains: &[GrainView],
    walls: &[Wall<D2>],
    materials: &[ContactParams],
    dt: f64,
    contacts: &mut BodyContacts,
) -> Vec<(usize, DVec2, f64)> {
    let old = std::mem::take(&mut contacts.list);
    let history = |key: &Key| old.binary_search_by(|e| e.0.cmp(key)).map(|k| old[k].1).unwrap_or_default();
    let mut list = Vec::new();
    let mut on_grains = Vec::new();
    let polys: Vec<Vec<DVec2>> = bodies.iter().map(Body::vertices).collect();
    let convex: Vec<bool> = polys.iter().map(|p| is_convex(p)).collect();
    let sides: Vec<Side> = bodies.iter().map(Body::side).collect();
    let candidates = near_disks(bodies, grains);
    let mut load = vec![(DVec2::ZERO, 0.0); bodies.len()];
    let apply = |load: &mut Vec<(DVec2, f64)>, b: usize, f: DVec2, p: DVec2| {
        load[b].0 += f;
        load[b].1 += cross(p - sides[b].x, f);
    };
    for i in 0..bodies.len() {
        let law = materials[bodies[i].material as usize];
        for j in i + 1..bodies.len() {
            if bodies[i].motion != Motion::Free && bodies[j].motion != Motion::Free {
                continue;
            }
            let reach = bodies[i].reach() + bodies[j].reach();
            if (bodies[i].x - bodies[j].x).length_squared() > reach * reach {
                continue;
            }
            for (s, o, first) in [(i, j, true), (j, i, false)] {
                let (a_s, a_o) = (bodies[s].radius, bodies[o].radius);
                for (k, &v) in polys[s].iter().enumerate() {
                    if is_reflex(&polys[s], k) {
                        continue;
                    }
                    touching(&polys[o], convex[o], v, a_s + a_o, |feature, at| {
                        // A vertex–vertex touch once: in the first pass, and only between two
                        // vertices each touching the other (else the other's vertex touches
                        // this body's edge, and the second pass has it).
                        if let Some(w) = at.vertex
                            && (!first || !touches_vertex(&polys[s], convex[s], k, polys[o][w], a_s + a_o))
                        {
                            return;
                        }
                        let key = Key::Bodies {
                            of: bodies[s].id,
                            vertex: k as u32,
                            on: bodies[o].id,
                            feature,
                        };
                        let mut state = history(&key);
                        if let Some(t) = touch(&law, v, a_s, &sides[s], at.normal, at.gap, a_o, &sides[o], 1.0, dt, &mut state) {
                            apply(&mut load, s, t.force, t.point);
                            apply(&mut load, o, -t.force, t.point);
                            list.push((key, state));
                        }
                    });
                }
            }
        }
        let grain_key = |grain, body, feature| Key::Grain { grain, body, feature };
        on_grains.extend(disk_contacts(
            i,
            &bodies[i],
            &polys[i],
            &sides[i],
            &law,
            grains,
            &candidates[i],
            grain_key,
            dt,
            &history,
            &mut list,
            &mut load,
        ));
        for (w, wall) in walls.iter().enumerate() {
            let mut law = law;
            law.friction = wall.friction;
            let wall_side = |x: DVec2, omega: f64| Side {
                x,
                v: wall.velocity,
                omega,
                inv_mass: 0.0,
                inv_inertia: 0.0,
            };
            let a = bodies[i].radius;
            #[allow(clippy::too_many_arguments)]
            let at = |load: &mut Vec<(DVec2, f64)>,
                      list: &mut Vec<_>,
                      k: u32,
                      feature: u32,
                      v: DVec2,
                      normal: DVec2,
                      gap: f64,
                      o: Side,
                      mine: bool| {
                let key = Key::Wall {
                    body: bodies[i].id,
                    vertex: k,
                    wall: w as u32,
                    feature,
                };
                let mut state = history(&key);
                // The body's vertex on the wall, or the wall's end (a vertex of radius 0) on
                // the body.
                let t = if mine {
                    touch(&law, v, a, &sides[i], normal, gap, 0.0, &o, 1.0, dt, &mut state).map(|t| (t.force, t.point))
                } else {
                    touch(&law, v, 0.0, &o, normal, gap, a, &sides[i], 1.0, dt, &mut state).map(|t| (-t.force, t.point))
                };
                if let Some((f, p)) = t {
                    apply(load, i, f, p);
                    list.push((key, state));
                }
            };
            // A reflex vertex is never the first to reach a wall: the convex ones around it are.
            let vertices = || polys[i].iter().enumerate().filter(|&(k, _)| !is_reflex(&polys[i], k));
            match wall.shape {
                WallShape::Plane { point, normal } => {
                    // Signed: a vertex pushed past the plane is pushed back, not through.
                    for (k, &v) in vertices() {
                        let gap = (v - point).dot(normal);
                        at(&mut load, &mut list, k as u32, 0, v, normal, gap, wall_side(point, 0.0), true);
                    }
                }
                WallShape::Drum { center, radius } => {
                    for (k, &v) in vertices() {
                        let r = v - center;
                        let len = r.length();
                        if len > 0.0 {
                            let (normal, gap) = (-r / len, radius - len);
                            at(
                                &mut load,
                                &mut list,
                                k as u32,
                                0,
                                v,
                                normal,
                                gap,
                                wall_side(center, wall.spin),
                                true,
                            );
                        }
                    }
                }
                WallShape::Segment { a: p, b: q } => {
                    let seg = [p, q];
                    for (k, &v) in vertices() {
                        let on = near(&seg, v);
                        at(&mut load, &mut list, k as u32, 0, v, on.normal, on.gap, wall_side(p, 0.0), true);
                    }
                    // The segment's ends against the body's edges (on its vertices: above).
                    for (e, &end) in seg.iter().enumerate() {
                        touching(&polys[i], convex[i], end, a, |feature, on| {
                            if on.vertex.is_none() {
                                let k = u32::MAX - e as u32;
                                at(&mut load, &mut list, k, feature, end, on.normal, on.gap, wall_side(p, 0.0), false);
                            }
                        });
                    }
                }
            }
        }
    }
    for (b, (f, t)) in bodies.iter_mut().zip(load) {
        b.force = f;
        b.torque = t;
    }
    list.sort_unstable_by_key(|e| e.0);
    contacts.list = list;
    on_grains
}

/// Whether `p`, within `reach` of the polygon `poly`, touches its vertex `k` ([`touching`]).
fn touches_vertex(poly: &[DVec2], convex: bool, k: usize, p: DVec2, reach: f64) -> bool {
    let mut found = false;
    touching(poly, convex, p, reach, |_, at| found |= at.vertex == Some(k));
    found
}

/// For each body, the disks within its reach ([`Body::reach`]), by the broad phase.
fn near_disks(bodies: &[Body], disks: &[GrainView]) -> Vec<Vec<usize>> {
    let circles: Vec<(DVec2, f64)> = bodies.iter().map(|b| (b.x, b.reach())).collect();
    grains_grid::reach::within_reach(disks.len(), |k| (disks[k].x, disks[k].radius), &circles)
}

/// The contacts of body `i` (world polygon `poly`, side `side`, law `law`) with the disks
/// `candidates` of `disks` (grains, or material points as disks of their contact radius), keyed by
/// `key(disk id, body id)`: each one's history from `history`, pushed to `list`; the reaction
/// added to `load[i]`; returns (disk index, force on the disk, its torque about the disk's
/// centre).
#[allow(clippy::too_many_arguments)]
fn disk_contacts(
    i: usize,
    body: &Body,
    poly: &[DVec2],
    side: &Side,
    law: &ContactParams,
    disks: &[GrainView],
    candidates: &[usize],
    key: impl Fn(u64, u64, u32) -> Key,
    dt: f64,
    history: &impl Fn(&Key) -> ContactState<DVec2>,
    list: &mut Vec<(Key, ContactState<DVec2>)>,
    load: &mut [(DVec2, f64)],
) -> Vec<(usize, DVec2, f64)> {
    let mut out = Vec::new();
    // Once per body, not per disk: the hot path of a continuum against a body.
    let convex = is_convex(poly);
    for disk in candidates.iter().map(|&k| &disks[k]) {
        let s = Side {
            x: disk.x,
            v: disk.v,
            omega: disk.omega,
            inv_mass: disk.inv_mass,
            inv_inertia: 0.0,
        };
        touching(poly, convex, disk.x, disk.radius + body.radius, |feature, at| {
            let k = key(disk.id, body.id, feature);
            let mut state = history(&k);
            if let Some(t) = touch(
                law,
                disk.x,
                disk.radius,
                &s,
                at.normal,
                at.gap,
                body.radius,
                side,
                disk.scale,
                dt,
                &mut state,
            ) {
                load[i].0 -= t.force;
                load[i].1 -= cross(t.point - side.x, t.force);
                out.push((disk.index, t.force, cross(t.point - disk.x, t.force)));
                list.push((k, state));
            }
        });
    }
    out
}

/// Jiang 2020 §4 (eqs. 44–50): material points within reach of a body meet it as disks of
/// their contact radius r_p (`points`, `inv_mass` 1/m_p) by the body's law. Returns the force
/// on each point touched (its `index`), to act on the point (eq. 46–48: an external force
/// the MPM spreads to its nodes), and sets each body's `external` force and torque to the
/// reactions, which its steps then carry (eq. 49–50); advances `contacts` by dt.
pub fn point_forces(
    bodies: &mut [Body],
    points: &[GrainView],
    materials: &[ContactParams],
    dt: f64,
    contacts: &mut BodyContacts,
) -> Vec<(usize, DVec2)> {
    let old = std::mem::take(&mut contacts.list);
    let history = |key: &Key| old.binary_search_by(|e| e.0.cmp(key)).map(|k| old[k].1).unwrap_or_default();
    let mut list = Vec::new();
    let mut load = vec![(DVec2::ZERO, 0.0); bodies.len()];
    let mut out = Vec::new();
    let candidates = near_disks(bodies, points);
    for (i, body) in bodies.iter().enumerate() {
        let (poly, side) = (body.vertices(), body.side());
        let law = materials[body.material as usize];
        let key = |point, body, feature| Key::Point { point, body, feature };
        let touched = disk_contacts(
            i,
            body,
            &poly,
            &side,
            &law,
            points,
            &candidates[i],
            key,
            dt,
            &history,
            &mut list,
            &mut load,
        );
        out.extend(touched.into_iter().map(|(p, f, _)| (p, f)));
    }
    for (b, (f, t)) in bodies.iter_mut().zip(load) {
        b.external = f;
        b.external_torque = t;
    }
    list.sort_unstable_by_key(|e| e.0);
    contacts.list = list;
    out
}

/// The first half kick (forces of the last evaluation) and the drift of every body over dt.
pub fn kick_drift(bodies: &mut [Body], gravity: DVec2, dt: f64) {
    half_kick(bodies, gravity, 0.5 * dt);
    for b in bodies.iter_mut().filter(|b| b.motion != Motion::Fixed) {
        b.x += b.v * dt;
        b.angle += b.omega * dt;
    }
}

/// Half a kick of h for the free bodies: v += h ((F + F_ext)/m + g), ω += h (τ + τ_ext)/I.
pub fn half_kick(bodies: &mut [Body], gravity: DVec2, h: f64) {
    for b in bodies.iter_mut().filter(|b| b.motion == Motion::Free) {
        b.v += ((b.force + b.external) / b.mass + gravity) * h;
        b.omega += (b.torque + b.external_torque) / b.inertia * h;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::Wall;
    use std::f64::consts::PI;

    /// Exact mass properties against closed forms: a disk (one vertex), a stadium (two), a
    /// square with a = 0 and a rounded square (the square, four a-wide strips and four
    /// quarter disks), off the origin.
    #[test]
    fn mass_properties_match_closed_forms() {
        let a = 0.3;
        let c = DVec2::new(2.0, -1.0);
        let disk = mass_properties(&[c], a);
        assert!((disk.area - PI * a * a).abs() < 1e-14 && (disk.centroid - c).length() < 1e-14);
        assert!((disk.second_moment - 0.5 * PI * a.powi(4)).abs() < 1e-14);
        // A stadium of length l: the rectangle l × 2a and a disk of radius a split at its ends.
        let l = 1.5;
        let stadium = mass_properties(&[c, c + DVec2::new(l, 0.0)], a);
        let rect = l * 2.0 * a;
        let ends = PI * a * a;
        assert!((stadium.area - (rect + ends)).abs() < 1e-12);
        assert!((stadium.centroid - (c + DVec2::new(0.5 * l, 0.0))).length() < 1e-12);
        // Each half disk: ∫r² about its centre π a⁴/4, its centroid 4a/(3π) out, at l/2 ± from the middle.
        let half = 0.5 * ends;
        let d = 4.0 * a / (3.0 * PI);
        let half_moment = 0.25 * PI * a.powi(4) - half * d * d + half * (0.5 * l + d).powi(2);
        let expected = rect * (l * l + 4.0 * a * a) / 12.0 + 2.0 * half_moment;
        assert!(
            (stadium.second_moment - expected).abs() < 1e-12,
            "{} vs {expected}",
            stadium.second_moment
        );
        let s = 2.0;
        let square = [c, c + DVec2::new(s, 0.0), c + DVec2::new(s, s), c + DVec2::new(0.0, s)];
        let sq = mass_properties(&square, 0.0);
        assert!((sq.area - s * s).abs() < 1e-12 && (sq.centroid - (c + DVec2::splat(0.5 * s))).length() < 1e-12);
        assert!((sq.second_moment - s.powi(4) / 6.0).abs() < 1e-12);
        let rounded = mass_properties(&square, a);
        assert!((rounded.area - (s * s + 4.0 * s * a + PI * a * a)).abs() < 1e-12);
        assert!((rounded.centroid - sq.centroid).length() < 1e-12);
        let strip = s * a;
        let strip_moment = strip * (s * s + a * a) / 12.0 + strip * (0.5 * s + 0.5 * a).powi(2);
        let quarter = 0.25 * PI * a * a;
        let dq = 4.0 * a * (PI / 4.0).sin() / (3.0 * PI / 2.0);
        let corner = (0.5 * s) * 2f64.sqrt();
        let quarter_moment = PI / 8.0 * a.powi(4) - quarter * dq * dq + quarter * (corner + dq).powi(2);
        let expected = s.powi(4) / 6.0 + 4.0 * strip_moment + 4.0 * quarter_moment;
        assert!(
            (rounded.second_moment - expected).abs() < 1e-12,
            "{} vs {expected}",
            rounded.second_moment
        );
    }

    /// A non-convex spheropolygon (an L with a reflex corner, and a V-notched block) against
    /// the swept shape integrated on a fine grid (points within a of the polygon or inside
    /// it): area, centroid and second moment to the grid's error; with a = 0 the L against
    /// its two rectangles in closed form.
    #[test]
    fn mass_properties_of_a_non_convex_shape_match_integration() {
        let l = [
            DVec2::ZERO,
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 0.5),
            DVec2::new(0.5, 0.5),
            DVec2::new(0.5, 1.5),
            DVec2::new(0.0, 1.5),
        ];
        let bare = mass_properties(&l, 0.0);
        // The foot 2 × 0.5 and the upright 0.5 × 1 above it.
        let parts = [
            (1.0, DVec2::new(1.0, 0.25), (4.0 + 0.25) / 12.0),
            (0.5, DVec2::new(0.25, 1.0), 0.5 * (0.25 + 1.0) / 12.0),
        ];
        let area: f64 = parts.iter().map(|p| p.0).sum();
        let c = parts.iter().fold(DVec2::ZERO, |s, p| s + p.1 * p.0) / area;
        let j: f64 = parts.iter().map(|p| p.2 + p.0 * (p.1 - c).length_squared()).sum();
        assert!((bare.area - area).abs() < 1e-12 && (bare.centroid - c).length() < 1e-12 && (bare.second_moment - j).abs() < 1e-12);
        let notch = [
            DVec2::new(-2.0, -1.0),
            DVec2::new(2.0, -1.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, -0.577),
            DVec2::new(-1.0, 0.0),
            DVec2::new(-2.0, 0.0),
        ];
        for (poly, a) in [(&l[..], 0.2), (&notch[..], 0.1)] {
            let exact = mass_properties(poly, a);
            let h = 2e-3;
            let (mut m, mut first, mut second) = (0.0, DVec2::ZERO, 0.0);
            for i in -1300..1300 {
                for k in -800..1100 {
                    let p = DVec2::new((i as f64 + 0.5) * h, (k as f64 + 0.5) * h);
                    if near(poly, p).gap < a {
                        m += h * h;
                        first += p * h * h;
                        second += p.length_squared() * h * h;
                    }
                }
            }
            let centroid = first / m;
            let moment = second - m * centroid.length_squared();
            assert!((exact.area - m).abs() < 2e-4 * m, "area {} vs {m}", exact.area);
            assert!(
                (exact.centroid - centroid).length() < 1e-4,
                "centroid {} vs {centroid}",
                exact.centroid
            );
            assert!(
                (exact.second_moment - moment).abs() < 5e-4 * moment,
                "moment {} vs {moment}",
                exact.second_moment
            );
            // The outline's polygon (the miter at the reflex corner) has the same area.
            let body = Body::new(0, poly, a, 1.0, 0, Motion::Free);
            let o = body.outline(256);
            let outline: f64 = (0..o.len()).map(|k| 0.5 * cross(o[k], o[(k + 1) % o.len()])).sum();
            assert!(
                (outline - exact.area).abs() < 1e-4 * exact.area,
                "outline {outline} vs {}",
                exact.area
            );
        }
    }

    /// The outline's polygon has the swept shape's area to the arcs' chord error.
    #[test]
    fn the_outline_encloses_the_swept_shape() {
        let a = 0.25;
        for shape in [
            vec![DVec2::ZERO],
            vec![DVec2::ZERO, DVec2::X],
            vec![DVec2::ZERO, DVec2::X, DVec2::new(0.3, 0.8)],
        ] {
            let body = Body::new(0, &shape, a, 1.0, 0, Motion::Free);
            let o = body.outline(64);
            let area: f64 = (0..o.len()).map(|k| 0.5 * cross(o[k], o[(k + 1) % o.len()])).sum();
            let exact = mass_properties(&shape, a).area;
            assert!(
                area > 0.0 && (area - exact).abs() < 1e-3 * exact,
                "{} vertices: {area} vs {exact}",
                shape.len()
            );
        }
    }

    fn floor_law() -> ContactParams {
        ContactParams {
            stiffness_normal: 1e5,
            stiffness_tangential: 5e4,
            damping: crate::contact::Damping::Restitution(0.5),
            friction: 0.5,
            cohesion_normal: 0.0,
            cohesion_tangential: 0.0,
            damping_scale: 1.0,
        }
    }

    fn unit_square(c: DVec2, s: f64) -> Vec<DVec2> {
        let h = 0.5 * s;
        vec![
            c + DVec2::new(-h, -h),
            c + DVec2::new(h, -h),
            c + DVec2::new(h, h),
            c + DVec2::new(-h, h),
        ]
    }

    /// A body pushed past a plane by more than its radius, or a disk body whose centre is
    /// inside another's polygon, is pushed back out (the signed distance), never on through;
    /// a fixed body on a wall gets no force (nothing yields: no dynamics, no damping).
    #[test]
    fn deep_overlaps_push_back_out() {
        let a = 0.01;
        let floor = [Wall::<D2>::plane(DVec2::ZERO, DVec2::Y, 0.5)];
        let mut sunk = [Body::new(0, &unit_square(DVec2::new(0.0, 0.4), 1.0), a, 1.0, 0, Motion::Free)];
        forces(&mut sunk, &[], &floor, &[floor_law()], 0.0, &mut BodyContacts::default());
        assert!(sunk[0].force.y > 0.0 && sunk[0].force.x.abs() < 1e-9, "{:?}", sunk[0].force);
        // The disk's centre 0.1 inside the square's right edge: pushed out along +x.
        let mut pair = [
            Body::new(0, &unit_square(DVec2::ZERO, 1.0), a, 1.0, 0, Motion::Fixed),
            Body::new(1, &[DVec2::new(0.4, 0.0)], 0.05, 1.0, 0, Motion::Free),
        ];
        forces(&mut pair, &[], &[], &[floor_law()], 0.0, &mut BodyContacts::default());
        assert!(pair[1].force.x > 0.0 && pair[1].force.y.abs() < 1e-9, "{:?}", pair[1].force);
        let mut fixed = [Body::new(0, &unit_square(DVec2::new(0.0, 0.4), 1.0), a, 1.0, 0, Motion::Fixed)];
        let mut contacts = BodyContacts::default();
        forces(&mut fixed, &[], &floor, &[floor_law()], 0.0, &mut contacts);
        assert!(fixed[0].force == DVec2::ZERO && contacts.list.is_empty());
    }

    /// A disk body beside a square's corner (its nearest point on the square on the edge, the
    /// corner within its reach too) is one contact whichever body comes first, with the same
    /// force: the corner–disk touch is the disk's with the edge, not a second one.
    #[test]
    fn a_corner_touch_is_one_contact_in_either_order() {
        let sq = Body::new(0, &unit_square(DVec2::ZERO, 1.0), 0.01, 1.0, 0, Motion::Free);
        let disk = Body::new(1, &[DVec2::new(0.55, 0.45)], 0.1, 1.0, 0, Motion::Free);
        let mut results = Vec::new();
        for mut bodies in [vec![sq.clone(), disk.clone()], vec![disk.clone(), sq.clone()]] {
            let mut contacts = BodyContacts::default();
            forces(&mut bodies, &[], &[], &[floor_law()], 0.0, &mut contacts);
            let on_disk = bodies.iter().find(|b| b.id == 1).unwrap().force;
            results.push((contacts.list.len(), on_disk));
        }
        assert_eq!(results[0].0, 1, "one contact: {results:?}");
        assert_eq!(results[0], results[1]);
        assert!(results[0].1.x > 0.0 && results[0].1.y.abs() < 1e-12 * results[0].1.x, "{results:?}");
    }
}
