//! The DEM step (velocity Verlet, as LAMMPS `fix nve/sphere`), on one screen:
//!
//! 1. half kick: v += dt/2 · (F/m' + g), ω += dt/2 · τ/I'   (m', I' scaled by 1 − w)
//! 2. drift: x += dt · v, orientation turned by ω dt; periodic axes wrapped; walls moved
//! 3. neighbour list rebuilt if a grain or wall moved more than skin/2
//! 4. forces: every listed pair and grain–wall pair in parallel (each writes its own slot),
//!    then every grain gathers its slots in a fixed order (no float reduction depends on the
//!    thread count, so results are bit-identical for any number of threads)
//! 5. half kick with the new forces.
//!
//! The pipeline owns scratch only (forces, the neighbour list, the thread pool); the state is
//! passed in.

use crate::contact::{ContactParams, contact_force, reduced_mass};
use crate::neighbors::{NeighborList, periods, separation, wall_gap, wall_geometry};
use crate::space::{Space, Vector};
use crate::state::{DemState, WallShape};
use rayon::prelude::*;

/// Per-grain result of the force gather.
#[derive(Clone, Copy, Debug, Default)]
pub struct GrainForce<S: Space> {
    pub force: S::V,
    pub torque: S::Ang,
    /// Active contacts (grains and walls).
    pub contacts: u32,
}

pub struct DemPipeline<S: Space> {
    pool: std::sync::Arc<rayon::ThreadPool>,
    pub neighbors: NeighborList<S>,
    pub forces: Vec<GrainForce<S>>,
    prepared: bool,
    /// Pair loops run in chunks of this many pairs.
    chunk: usize,
}

/// Error building a pipeline (thread pool).
#[derive(Debug)]
pub struct BuildError(pub String);

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BuildError {}

impl<S: Space> DemPipeline<S> {
    /// A pipeline running its loops on `threads` threads (named `dem-worker-<k>`).
    pub fn new(threads: usize) -> Result<Self, BuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .thread_name(|k| format!("dem-worker-{k}"))
            .build()
            .map_err(|e| BuildError(format!("cannot start {threads} DEM threads: {e}")))?;
        Ok(DemPipeline {
            pool: std::sync::Arc::new(pool),
            neighbors: NeighborList::default(),
            forces: Vec::new(),
            prepared: false,
            chunk: 1024,
        })
    }

    /// Forgets the forces of the last step: call after adding, removing or moving grains
    /// outside of [`DemPipeline::step`].
    pub fn invalidate(&mut self) {
        self.prepared = false;
    }

    /// Advances the state by one step of dt.
    pub fn step(&mut self, state: &mut DemState<S>, dt: f64) {
        let pool = self.pool.clone();
        pool.install(|| self.step_in_pool(state, dt));
    }

    /// Advances the state by `n` steps of dt.
    pub fn run(&mut self, state: &mut DemState<S>, dt: f64, n: usize) {
        let pool = self.pool.clone();
        pool.install(|| {
            for _ in 0..n {
                self.step_in_pool(state, dt);
            }
        });
    }

    fn step_in_pool(&mut self, state: &mut DemState<S>, dt: f64) {
        if !self.prepared || self.forces.len() != state.grains.len() {
            self.neighbors.build(state);
            self.compute_forces(state, 0.0);
            self.prepared = true;
        }
        self.kick(state, 0.5 * dt);
        self.drift(state, dt);
        if self.neighbors.stale(state) {
            self.neighbors.build(state);
        }
        self.compute_forces(state, dt);
        self.kick(state, 0.5 * dt);
        state.time += dt;
    }

    fn kick(&mut self, state: &mut DemState<S>, h: f64) {
        let g = &mut state.grains;
        let gravity = state.params.gravity;
        let forces = &self.forces;
        (
            g.v.par_iter_mut(),
            g.omega.par_iter_mut(),
            forces.par_iter(),
            g.mass.par_iter(),
            g.radius.par_iter(),
            g.scale.par_iter(),
            g.frozen.par_iter(),
            g.external.par_iter(),
        )
            .into_par_iter()
            .with_min_len(2048)
            .for_each(|(v, w, f, &m, &r, &s, &frozen, &ext)| {
                if frozen {
                    return;
                }
                let inv_m = 1.0 / (m * s);
                *v += (f.force + ext) * (h * inv_m) + gravity * h;
                *w += f.torque * (h * inv_m / (S::INERTIA_FACTOR * r * r));
            });
    }

    fn drift(&mut self, state: &mut DemState<S>, dt: f64) {
        let d = state.params.domain;
        let g = &mut state.grains;
        (
            g.x.par_iter_mut(),
            g.rot.par_iter_mut(),
            g.v.par_iter(),
            g.omega.par_iter(),
            g.frozen.par_iter(),
        )
            .into_par_iter()
            .with_min_len(2048)
            .for_each(|(x, rot, &v, &w, &frozen)| {
                if frozen {
                    return;
                }
                *x += v * dt;
                *rot = S::rotate(*rot, w, dt);
                if d.periodic.iter().any(|&p| p) {
                    let mut a = S::to_array(*x);
                    for (k, c) in a.iter_mut().enumerate().take(S::DIM) {
                        // A grain moves far less than a period per step: one shift suffices.
                        if d.periodic[k] {
                            if *c < d.min[k] {
                                *c += d.length(k);
                            } else if *c >= d.max[k] {
                                *c -= d.length(k);
                            }
                        }
                    }
                    *x = S::from_array(a);
                }
            });
        for w in &mut state.walls {
            match &mut w.shape {
                WallShape::Plane { point, .. } => *point += w.velocity * dt,
                WallShape::Drum { center, .. } => *center += w.velocity * dt,
                WallShape::Segment { a, b } => {
                    *a += w.velocity * dt;
                    *b += w.velocity * dt;
                }
            }
        }
    }

    /// Forces and torques of every contact at the current positions; advances the contact
    /// histories by dt (0 at preparation: nothing is integrated then).
    fn compute_forces(&mut self, state: &mut DemState<S>, dt: f64) {
        let g = &state.grains;
        let materials = &state.params.materials;
        let damping: Vec<f64> = materials.iter().map(ContactParams::damping_factor).collect();
        let (period, half) = periods(state);

        self.neighbors.pairs.par_chunks_mut(self.chunk).for_each(|chunk| {
            for p in chunk {
                let (i, j) = (p.i as usize, p.j as usize);
                let d = separation::<S>(g.x[i], g.x[j], period, half);
                let (ri, rj) = (g.radius[i], g.radius[j]);
                let r_sum = ri + rj;
                let dist2 = d.length_squared();
                if dist2 >= r_sum * r_sum && !p.state.bonded {
                    p.state = Default::default();
                    p.active = false;
                    continue;
                }
                let dist = dist2.sqrt();
                let n = d * (1.0 / dist);
                let v_rel = (g.v[i] + S::ang_cross(g.omega[i], n * -ri)) - (g.v[j] + S::ang_cross(g.omega[j], n * rj));
                let mat = g.material[i] as usize;
                let scale = 0.5 * (g.scale[i] + g.scale[j]);
                let m_red = reduced_mass(mass_or_inf(g, i), mass_or_inf(g, j));
                let gamma = materials[mat].gamma(damping[mat], m_red) * scale;
                let c = contact_force::<S>(&materials[mat], r_sum - dist, n, v_rel, gamma, scale, dt, &mut p.state);
                p.force = c.force;
                p.couple = S::torque(n, c.force);
                p.active = c.active;
            }
        });

        let walls = &state.walls;
        self.neighbors.walls.par_chunks_mut(self.chunk).for_each(|chunk| {
            for w in chunk {
                let i = w.grain as usize;
                let wall = &walls[w.wall as usize];
                let (gap, n, v_wall) = wall_geometry(&wall.shape, g.x[i], wall.velocity, wall.spin);
                let ri = g.radius[i];
                if gap >= ri && !w.state.bonded {
                    w.state = Default::default();
                    w.active = false;
                    continue;
                }
                let v_rel = g.v[i] + S::ang_cross(g.omega[i], n * -ri) - v_wall;
                let mat = g.material[i] as usize;
                let mut params = materials[mat];
                params.friction = wall.friction;
                let scale = g.scale[i];
                let gamma = materials[mat].gamma(damping[mat], mass_or_inf(g, i)) * scale;
                let c = contact_force::<S>(&params, ri - gap, n, v_rel, gamma, scale, dt, &mut w.state);
                w.force = c.force;
                w.couple = S::torque(n, c.force);
                w.active = c.active;
            }
        });

        // Gather per grain, in the fixed order of the incident lists.
        let nb = &self.neighbors;
        self.forces.resize(g.len(), GrainForce::default());
        self.forces.par_iter_mut().enumerate().with_min_len(1024).for_each(|(i, out)| {
            let mut f = S::V::default();
            let mut t = S::Ang::default();
            let mut contacts = 0;
            let r = g.radius[i];
            for &e in &nb.incident[nb.offsets[i] as usize..nb.offsets[i + 1] as usize] {
                let p = &nb.pairs[(e >> 1) as usize];
                if !p.active {
                    continue;
                }
                contacts += 1;
                if e & 1 == 0 {
                    f += p.force;
                } else {
                    f -= p.force;
                }
                t -= p.couple * r;
            }
            for w in &nb.walls[nb.wall_offsets[i] as usize..nb.wall_offsets[i + 1] as usize] {
                if w.active {
                    contacts += 1;
                    f += w.force;
                    t -= w.couple * r;
                }
            }
            *out = GrainForce {
                force: f,
                torque: t,
                contacts,
            };
        });

        // Loads on walls: the opposite of their contact forces, summed in list order.
        for w in state.walls.iter_mut() {
            w.load = S::V::default();
        }
        for slot in &nb.walls {
            if slot.active {
                state.walls[slot.wall as usize].load -= slot.force;
            }
        }
    }

    /// Kinetic energy (translation + rotation) [J] with scaled masses.
    pub fn kinetic_energy(state: &DemState<S>) -> f64 {
        let g = &state.grains;
        (0..g.len())
            .map(|i| {
                let m = g.mass[i] * g.scale[i];
                0.5 * m * g.v[i].length_squared() + 0.5 * S::INERTIA_FACTOR * m * g.radius[i].powi(2) * g.omega[i].length_squared()
            })
            .sum()
    }

    /// Elastic energy stored in the normal and tangential springs of active contacts [J].
    pub fn elastic_energy(&self, state: &DemState<S>) -> f64 {
        let g = &state.grains;
        let (period, half) = periods(state);
        let mut e = 0.0;
        for p in self.neighbors.pairs.iter().filter(|p| p.active) {
            let (i, j) = (p.i as usize, p.j as usize);
            let m = &state.params.materials[g.material[i] as usize];
            let s = 0.5 * (g.scale[i] + g.scale[j]);
            let overlap = g.radius[i] + g.radius[j] - separation::<S>(g.x[i], g.x[j], period, half).length();
            e += 0.5 * m.stiffness_normal * s * overlap * overlap + 0.5 * m.stiffness_tangential * s * p.state.spring.length_squared();
        }
        for w in self.neighbors.walls.iter().filter(|w| w.active) {
            let i = w.grain as usize;
            let m = &state.params.materials[g.material[i] as usize];
            let overlap = g.radius[i] - wall_gap(&state.walls[w.wall as usize].shape, g.x[i]);
            e += 0.5 * m.stiffness_normal * g.scale[i] * overlap * overlap
                + 0.5 * m.stiffness_tangential * g.scale[i] * w.state.spring.length_squared();
        }
        e
    }

    /// Gravitational potential energy −Σ m g·x [J].
    pub fn potential_energy(state: &DemState<S>) -> f64 {
        let g = &state.grains;
        (0..g.len())
            .map(|i| -g.mass[i] * g.scale[i] * state.params.gravity.dot(g.x[i]))
            .sum()
    }

    /// Total linear momentum [kg m/s].
    pub fn momentum(state: &DemState<S>) -> S::V {
        let g = &state.grains;
        (0..g.len()).fold(S::V::default(), |p, i| p + g.v[i] * (g.mass[i] * g.scale[i]))
    }

    /// The id of the first grain whose position or velocity is not finite.
    pub fn first_non_finite(state: &DemState<S>) -> Option<u64> {
        let g = &state.grains;
        (0..g.len())
            .find(|&i| !g.x[i].is_finite() || !g.v[i].is_finite() || !g.omega[i].is_finite())
            .map(|i| g.id[i])
    }
}

fn mass_or_inf<S: Space>(g: &crate::state::Grains<S>, i: usize) -> f64 {
    if g.frozen[i] { f64::INFINITY } else { g.mass[i] }
}

/// Critical time step of velocity Verlet for the stiffest, lightest pair [s]:
/// (2/ω)(√(1+ζ²) − ζ) with ω = √(k_n / m_red), m_red = m_min/2 and ζ the damping ratio of
/// the restitution. A run must stay below a safe fraction of it ([`SAFE_FRACTION`]).
pub fn critical_time_step(params: &ContactParams, min_mass: f64) -> f64 {
    let m_red = 0.5 * min_mass;
    let omega = (params.stiffness_normal / m_red).sqrt();
    let gamma = params.gamma(params.damping_factor(), m_red);
    let zeta = gamma / (2.0 * (params.stiffness_normal * m_red).sqrt());
    2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta)
}

/// Largest share of the critical time step a scene may use: 1/5, i.e. at least ~15 steps
/// per contact (π/ω), so that contacts are resolved, not just stable.
pub const SAFE_FRACTION: f64 = 0.2;
