//! The DEM step (velocity Verlet, as LAMMPS `fix nve/sphere`), on one screen:
//!
//! 1. one pass over the grains: half kick v += dt/2 · (F/m' + g), ω += dt/2 · τ/I'
//!    (m', I' scaled by 1 − w), then drift x += dt · v, orientation turned by ω dt, periodic
//!    axes wrapped, and the largest displacement since the last neighbour-list build;
//! 2. neighbour list rebuilt if a grain or wall moved more than skin/2;
//! 3. pair forces: the listed pairs are cut into one fixed range per thread; each range adds
//!    its forces into its own per-grain buffer, in list order (as a serial code would);
//! 4. one pass over the grains: the buffers summed in range order, plus the grain's wall
//!    contacts, then the second half kick.
//!
//! Results are bit-identical between runs with the same thread count (the ranges, and so the
//! order of every float sum, depend only on the number of threads and pairs).
//!
//! The pipeline owns scratch only (forces, the neighbour list, the thread pool); the state is
//! passed in.

use crate::bodies::{self, BodyContacts, GrainView};
use crate::contact::{ContactParams, Damping, contact_force, reduced_mass};
use crate::neighbors::{NeighborList, PairSlot, periods, separation, wall_gap, wall_geometry};
use crate::space::{Space, Vector};
use crate::state::{DemState, Grains, WallShape};
use rayon::prelude::*;

/// What the pair loop reads of one grain, packed in one place (the arrays of
/// [`crate::state::Grains`] spread it over seven cache lines); refreshed by the drift.
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Hot<S: Space> {
    pub x: S::V,
    pub v: S::V,
    pub omega: S::Ang,
    pub radius: f64,
    /// Mass [kg]; +∞ for a frozen grain (an immovable partner, like a wall).
    pub mass: f64,
    pub scale: f64,
    pub material: u32,
}

/// A pair range's force buffer: the first grain of its window and one entry per grain.
type Window<S> = (usize, Vec<GrainForce<S>>);

/// Per-grain result of the force gather.
#[derive(Clone, Copy, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct GrainForce<S: Space> {
    pub force: S::V,
    pub torque: S::Ang,
    /// Active contacts (grains and walls).
    pub contacts: u32,
}

pub struct DemPipeline<S: Space> {
    pool: std::sync::Arc<rayon::ThreadPool>,
    threads: usize,
    pub neighbors: NeighborList<S>,
    /// Total force, torque and contact count of every grain at the last evaluation.
    pub forces: Vec<GrainForce<S>>,
    /// One buffer per pair range, over the window of grains its pairs touch (first index,
    /// entries): grains are sorted in space, so a window is about N/threads grains.
    partial: Vec<Window<S>>,
    hot: Vec<Hot<S>>,
    /// The last pair evaluation added straight into `forces` (one range).
    direct: bool,
    prepared: bool,
    /// Grains moved outside of a step ([`DemPipeline::moved`]): forces are due again.
    resync: bool,
    /// Keep the grains' storage order ([`DemPipeline::run_in_order`]); a re-sort that fell
    /// due meanwhile waits for the next preparation out of it ([`DemPipeline::settle`] or the
    /// next step of [`DemPipeline::run`]).
    hold_order: bool,
    sort_due: bool,
    /// The rigid bodies' contact histories ([`crate::bodies`]).
    bodies: BodyContacts,
    /// Per grain, the force of the bodies on it at the last evaluation (empty without bodies).
    from_bodies: Vec<GrainForce<S>>,
}

/// See [`DemPipeline::carry`]. (The per-range buffers are not in it: every evaluation
/// starts them from zero.)
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Carry<S: Space> {
    neighbors: NeighborList<S>,
    forces: Vec<GrainForce<S>>,
    hot: Vec<Hot<S>>,
    direct: bool,
    prepared: bool,
    resync: bool,
    sort_due: bool,
    bodies: BodyContacts,
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

/// Grains per task in the per-grain passes (small systems stay on one thread). A hybrid's
/// discrete part is a few thousand grains: at 4,096 (with 8,192 pairs a range) a 4,824-grain
/// bed ran no faster on two threads than on one; at 1,024 (2,048) it runs 1.4× faster.
const GRAIN_TASK: usize = 1024;

/// Fewest pairs worth a range of their own (a thread's wake-up costs tens of µs here, the
/// force of a pair tens of ns).
const PAIRS_PER_RANGE: usize = 2_048;

/// Re-sort the grains by cell at every this many neighbour-list builds.
const SORT_EVERY: u64 = 20;

impl<S: Space> DemPipeline<S> {
    /// A pipeline running its loops on `threads` threads (named `dem-worker-<k>`).
    pub fn new(threads: usize) -> Result<Self, BuildError> {
        let threads = threads.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|k| format!("dem-worker-{k}"))
            .build()
            .map_err(|e| BuildError(format!("cannot start {threads} DEM threads: {e}")))?;
        Ok(DemPipeline {
            pool: std::sync::Arc::new(pool),
            threads,
            neighbors: NeighborList::default(),
            forces: Vec::new(),
            partial: Vec::new(),
            hot: Vec::new(),
            direct: false,
            prepared: false,
            resync: false,
            hold_order: false,
            sort_due: false,
            bodies: BodyContacts::default(),
            from_bodies: Vec::new(),
        })
    }

    /// What the pipeline carries from one step to the next (the neighbour list with the
    /// contact histories, the last forces, its bookkeeping), for a checkpoint: a pipeline
    /// given it back with [`DemPipeline::restore`] continues bit for bit.
    pub fn carry(&self) -> Carry<S> {
        Carry {
            neighbors: self.neighbors.clone(),
            forces: self.forces.clone(),
            hot: self.hot.clone(),
            direct: self.direct,
            prepared: self.prepared,
            resync: self.resync,
            sort_due: self.sort_due,
            bodies: self.bodies.clone(),
        }
    }

    pub fn restore(&mut self, c: Carry<S>) {
        self.neighbors = c.neighbors;
        self.forces = c.forces;
        self.hot = c.hot;
        self.direct = c.direct;
        self.prepared = c.prepared;
        self.resync = c.resync;
        self.sort_due = c.sort_due;
        self.bodies = c.bodies;
    }

    /// Whether the contacts of the last step are known for the grains as they are now (false
    /// after [`DemPipeline::invalidate`] until the next step).
    pub fn contacts_known(&self) -> bool {
        self.prepared
    }

    /// Forgets the forces of the last step: call after adding, removing or moving grains
    /// outside of [`DemPipeline::step`].
    pub fn invalidate(&mut self) {
        self.prepared = false;
    }

    /// Some grains moved or changed velocity outside of a step, the grains themselves and
    /// their order unchanged (a coupled step's transfer back): the next step evaluates their
    /// forces at the new positions first, and rebuilds the neighbour list only if a grain
    /// moved more than skin/2 since its build (or a re-sort fell due).
    pub fn moved(&mut self) {
        self.resync = true;
    }

    /// Brings the forces up to date with the state (after [`DemPipeline::invalidate`] or
    /// [`DemPipeline::moved`]); a re-sort of the grains that is due happens here. After it,
    /// [`DemPipeline::run_in_order`] keeps every grain at its storage index.
    pub fn settle(&mut self, state: &mut DemState<S>) {
        let pool = self.pool.clone();
        pool.install(|| self.prepare(state));
    }

    /// Advances the state by `n` steps of dt keeping the grains' storage order (no re-sort),
    /// so that a caller may address grains by index across the steps (settled first, so
    /// that the indices it took after [`DemPipeline::settle`] hold).
    pub fn run_in_order(&mut self, state: &mut DemState<S>, dt: f64, n: usize) {
        self.settle(state);
        self.hold_order = true;
        self.run(state, dt, n);
        self.hold_order = false;
    }

    /// Advances the state by one step of dt.
    pub fn step(&mut self, state: &mut DemState<S>, dt: f64) {
        self.run(state, dt, 1);
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
        self.prepare(state);
        let moved = self.kick_drift(state, dt);
        if self.neighbors.needs_rebuild(state, moved) {
            if self.neighbors.builds.is_multiple_of(SORT_EVERY) {
                if self.hold_order {
                    self.sort_due = true;
                } else {
                    self.sort_grains(state);
                    self.refresh_hot(state);
                }
            }
            self.neighbors.build(state);
        }
        self.pair_forces(state, dt);
        self.body_forces(state, dt);
        self.finish_forces(state, 0.5 * dt);
        bodies::half_kick(&mut state.bodies, to_plane::<S>(state.params.gravity), 0.5 * dt);
        state.time += dt;
    }

    /// The forces of the current positions, if they are not known: everything anew after
    /// [`DemPipeline::invalidate`] (or a change in the number of grains), the hot copy and the
    /// forces after [`DemPipeline::moved`] (the neighbour list only if stale, or a re-sort if
    /// one is due and the order is not held).
    fn prepare(&mut self, state: &mut DemState<S>) {
        if !self.prepared || self.forces.len() != state.grains.len() {
            self.forces = vec![GrainForce::default(); state.grains.len()];
            self.sort_grains(state);
            self.refresh_hot(state);
            self.neighbors.build(state);
            self.pair_forces(state, 0.0);
            self.body_forces(state, 0.0);
            self.finish_forces(state, 0.0);
            self.prepared = true;
            self.resync = false;
            self.sort_due = false;
        } else if self.resync || (self.sort_due && !self.hold_order) {
            self.refresh_hot(state);
            if self.sort_due && !self.hold_order {
                self.sort_grains(state);
                self.refresh_hot(state);
                self.sort_due = false;
                self.neighbors.build(state);
            } else if self.neighbors.stale(state) {
                self.neighbors.build(state);
            }
            self.pair_forces(state, 0.0);
            self.body_forces(state, 0.0);
            self.finish_forces(state, 0.0);
            self.resync = false;
        }
    }

    /// Re-sorts the grains by cell (memory follows space, as LAMMPS' `atom_modify sort`);
    /// the forces of the last step move with them, the contact histories follow by id.
    fn sort_grains(&mut self, state: &mut DemState<S>) {
        let r_max = state.grains.radius.iter().copied().fold(0.0, f64::max);
        let order = crate::neighbors::spatial_order(state, 2.0 * r_max + state.params.skin);
        if order.iter().enumerate().all(|(k, &i)| k == i as usize) {
            return;
        }
        state.grains.permute(&order);
        let old = std::mem::take(&mut self.forces);
        self.forces = order.iter().map(|&k| old[k as usize]).collect();
    }

    fn refresh_hot(&mut self, state: &DemState<S>) {
        let g = &state.grains;
        self.hot = (0..g.len())
            .map(|i| Hot {
                x: g.x[i],
                v: g.v[i],
                omega: g.omega[i],
                radius: g.radius[i],
                mass: if g.frozen[i] { f64::INFINITY } else { g.mass[i] },
                scale: g.scale[i],
                material: g.material[i],
            })
            .collect();
    }

    /// First half kick and drift; returns the largest squared displacement of a grain since
    /// the last neighbour-list build (max is exact in any order, so this is deterministic).
    fn kick_drift(&mut self, state: &mut DemState<S>, dt: f64) -> f64 {
        let h = 0.5 * dt;
        let d = state.params.domain;
        let gravity = state.params.gravity;
        let (period, half) = periods(state);
        let any_periodic = d.periodic.iter().any(|&p| p);
        // Box bounds for the wrap; open axes never wrap (bounds ±∞, period 0).
        let (lo, hi, _) = d.wrap_box::<S>();
        let g = &mut state.grains;
        let built = self.neighbors.positions_at_build();
        let check = built.len() == g.len();
        let moved = (
            g.x.par_iter_mut(),
            g.v.par_iter_mut(),
            g.omega.par_iter_mut(),
            g.rot.par_iter_mut(),
            self.forces.par_iter(),
            self.hot.par_iter_mut(),
            g.mass.par_iter(),
            g.radius.par_iter(),
            g.scale.par_iter(),
            g.frozen.par_iter(),
            g.external.par_iter(),
        )
            .into_par_iter()
            .enumerate()
            .with_min_len(GRAIN_TASK)
            .map(|(i, (x, v, w, rot, f, hot, &m, &r, &s, &frozen, &ext))| {
                // A frozen grain takes no force: it is driven at its own velocity (zero for a
                // scene's fixed base; a shear cell's plate moves).
                if !frozen {
                    half_kick::<S>(v, w, f, ext, gravity, m * s, r, h);
                    *rot = S::rotate(*rot, *w, dt);
                }
                *x += *v * dt;
                if any_periodic {
                    *x = x.wrap(lo, hi, period);
                }
                hot.x = *x;
                hot.v = *v;
                hot.omega = *w;
                if check {
                    separation::<S>(*x, built[i], period, half).length_squared()
                } else {
                    f64::INFINITY
                }
            })
            .reduce(|| 0.0, f64::max);
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
        bodies::kick_drift(&mut state.bodies, to_plane::<S>(gravity), dt);
        moved
    }

    /// The rigid bodies' contacts ([`crate::bodies::forces`]) at the current positions: their
    /// force on each grain goes to `from_bodies`, which [`DemPipeline::finish_forces`] adds.
    fn body_forces(&mut self, state: &mut DemState<S>, dt: f64) {
        self.from_bodies.clear();
        if state.bodies.is_empty() {
            return;
        }
        assert_eq!(S::DIM, 2, "rigid bodies are 2D");
        let g = &state.grains;
        // Only the grains within some body's reach: the bodies' scratch stays small.
        let reach: Vec<(glam::DVec2, f64)> = state.bodies.iter().map(|b| (b.x, b.reach())).collect();
        let mut near: Vec<usize> = grains_grid::reach::within_reach(g.len(), |i| (to_plane::<S>(g.x[i]), g.radius[i]), &reach).concat();
        near.sort_unstable();
        near.dedup();
        let view: Vec<GrainView> = near
            .into_iter()
            .map(|i| GrainView {
                index: i,
                x: to_plane::<S>(g.x[i]),
                v: to_plane::<S>(g.v[i]),
                omega: S::ang_array(g.omega[i])[2],
                radius: g.radius[i],
                inv_mass: if g.frozen[i] { 0.0 } else { 1.0 / (g.mass[i] * g.scale[i]) },
                scale: g.scale[i],
                id: g.id[i],
            })
            .collect();
        let walls: Vec<crate::state::Wall<crate::space::D2>> = state.walls.iter().map(crate::state::Wall::in_plane::<S>).collect();
        let touched = bodies::forces(&mut state.bodies, &view, &walls, &state.params.materials, dt, &mut self.bodies);
        if !touched.is_empty() {
            self.from_bodies = vec![GrainForce::default(); g.len()];
            for (i, f, t) in touched {
                let e = &mut self.from_bodies[i];
                e.force += S::from_array([f.x, f.y, 0.0]);
                e.torque += S::ang_from_array([0.0, 0.0, t]);
                e.contacts += 1;
            }
        }
    }

    /// Grain–grain contact forces at the current positions, added range by range into the
    /// per-range buffers; advances the contact histories by dt (0 at preparation).
    fn pair_forces(&mut self, state: &DemState<S>, dt: f64) {
        let hot = &self.hot;
        let n = hot.len();
        let materials = &state.params.materials;
        let damping: Vec<f64> = materials.iter().map(ContactParams::damping_factor).collect();
        let (period, half) = periods(state);
        let pairs = &mut self.neighbors.pairs;
        // A range must carry enough pairs to pay for waking a worker (tens of µs on a VM).
        let ranges = self.threads.min(pairs.len() / PAIRS_PER_RANGE).max(1);
        let range_len = pairs.len().div_ceil(ranges).max(1);
        self.partial.resize_with(ranges, || (0, Vec::new()));
        self.partial.truncate(ranges);
        let ranges_iter = pairs.par_chunks_mut(range_len).zip(self.partial.par_iter_mut());
        let work = |(chunk, (off, acc)): (&mut [PairSlot<S>], &mut Window<S>), whole: bool| {
            // Pairs are listed by first grain, so the window runs from the first pair's i to
            // the largest j of the range (the whole set when one range adds into the totals).
            *off = if whole { 0 } else { chunk.first().map_or(0, |p| p.i as usize) };
            let end = if whole {
                n
            } else {
                chunk.iter().map(|p| p.j as usize + 1).max().unwrap_or(*off).min(n)
            };
            acc.clear();
            acc.resize(end - *off, GrainForce::default());
            let off = *off;
            for p in chunk {
                let (i, j) = (p.i as usize, p.j as usize);
                let (gi, gj) = (&hot[i], &hot[j]);
                let d = separation::<S>(gi.x, gj.x, period, half);
                let (ri, rj) = (gi.radius, gj.radius);
                let r_sum = ri + rj;
                let dist2 = d.length_squared();
                if dist2 >= r_sum * r_sum && !p.state.bonded {
                    p.state = Default::default();
                    continue;
                }
                let dist = dist2.sqrt();
                let nrm = d * (1.0 / dist);
                let v_rel = (gi.v + S::ang_cross(gi.omega, nrm * -ri)) - (gj.v + S::ang_cross(gj.omega, nrm * rj));
                let mat = gi.material as usize;
                let scale = 0.5 * (gi.scale + gj.scale);
                // The reduced mass (a division) only matters for restitution damping.
                let gamma = match materials[mat].damping {
                    Damping::Viscous(g) => g,
                    Damping::Restitution(_) => damping[mat] * reduced_mass(gi.mass, gj.mass).sqrt(),
                } * scale;
                let c = contact_force::<S>(&materials[mat], r_sum - dist, nrm, v_rel, gamma, scale, dt, &mut p.state);
                if !c.active {
                    continue;
                }
                let couple = S::torque(nrm, c.force);
                let (a, b) = (&mut acc[i - off], c.force);
                a.force += b;
                a.torque -= couple * ri;
                a.contacts += 1;
                let bj = &mut acc[j - off];
                bj.force -= b;
                bj.torque -= couple * rj;
                bj.contacts += 1;
            }
        };
        self.direct = ranges == 1;
        if self.direct {
            // One range: it adds straight into the totals (as a serial code would), and no
            // task goes through the pool.
            let mut all = (0, std::mem::take(&mut self.forces));
            work((&mut pairs[..], &mut all), true);
            self.forces = all.1;
        } else {
            ranges_iter.for_each(|r| work(r, false));
        }
    }

    /// Wall contacts, the sum of the pair ranges, and the second half kick (`h` = dt/2; 0 at
    /// preparation, where only the forces are wanted).
    fn finish_forces(&mut self, state: &mut DemState<S>, h: f64) {
        let dt = 2.0 * h;
        let materials = &state.params.materials;
        let damping: Vec<f64> = materials.iter().map(ContactParams::damping_factor).collect();
        {
            let g = &state.grains;
            let walls = &state.walls;
            self.neighbors.walls.par_chunks_mut(1024).for_each(|chunk| {
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
        }

        let nb = &self.neighbors;
        let from_bodies = &self.from_bodies;
        let (partial, direct): (&[Window<S>], bool) = if self.direct { (&[], true) } else { (&self.partial, false) };
        let gravity = state.params.gravity;
        let g = &mut state.grains;
        (
            self.forces.par_iter_mut(),
            g.v.par_iter_mut(),
            g.omega.par_iter_mut(),
            g.mass.par_iter(),
            g.radius.par_iter(),
            g.scale.par_iter(),
            g.frozen.par_iter(),
            g.external.par_iter(),
        )
            .into_par_iter()
            .enumerate()
            .with_min_len(GRAIN_TASK)
            .for_each(|(i, (out, v, w, &m, &r, &s, &frozen, &ext))| {
                let mut total = if direct { *out } else { GrainForce::<S>::default() };
                for (off, acc) in partial {
                    if let Some(a) = i.checked_sub(*off).and_then(|k| acc.get(k)) {
                        total.force += a.force;
                        total.torque += a.torque;
                        total.contacts += a.contacts;
                    }
                }
                for ws in &nb.walls[nb.wall_offsets[i] as usize..nb.wall_offsets[i + 1] as usize] {
                    if ws.active {
                        total.force += ws.force;
                        total.torque -= ws.couple * r;
                        total.contacts += 1;
                    }
                }
                if let Some(b) = from_bodies.get(i) {
                    total.force += b.force;
                    total.torque += b.torque;
                    total.contacts += b.contacts;
                }
                *out = total;
                if frozen || h == 0.0 {
                    return;
                }
                half_kick::<S>(v, w, &total, ext, gravity, m * s, r, h);
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

    /// Kinetic energy (translation + rotation) [J] with scaled masses, free bodies included.
    pub fn kinetic_energy(state: &DemState<S>) -> f64 {
        let g = &state.grains;
        (0..g.len())
            .map(|i| {
                let m = g.mass[i] * g.scale[i];
                0.5 * m * g.v[i].length_squared() + 0.5 * S::INERTIA_FACTOR * m * g.radius[i].powi(2) * g.omega[i].length_squared()
            })
            .sum::<f64>()
            + free_bodies(state).map(bodies::Body::kinetic_energy).sum::<f64>()
    }

    /// Elastic energy stored in the normal and tangential springs of active contacts [J].
    pub fn elastic_energy(&self, state: &DemState<S>) -> f64 {
        let g = &state.grains;
        let (period, half) = periods(state);
        let mut e = 0.0;
        for p in &self.neighbors.pairs {
            let (i, j) = (p.i as usize, p.j as usize);
            let m = &state.params.materials[g.material[i] as usize];
            let s = 0.5 * (g.scale[i] + g.scale[j]);
            let overlap = g.radius[i] + g.radius[j] - separation::<S>(g.x[i], g.x[j], period, half).length();
            if overlap <= 0.0 && !p.state.bonded {
                continue;
            }
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

    /// The elastic force of every grain–grain contact of the last neighbour list (normal
    /// spring and tangential anchor spring, no damping), unscaled by the hybrid weight:
    /// (i, j, force on i from j, branch x_i − x_j by the minimum image) by storage index. For
    /// the grains' homogenized stress.
    pub fn contact_forces(&self, state: &DemState<S>) -> Vec<(usize, usize, S::V, S::V)> {
        let g = &state.grains;
        let (period, half) = periods(state);
        let mut out = Vec::new();
        for p in &self.neighbors.pairs {
            let (i, j) = (p.i as usize, p.j as usize);
            if i >= g.len() || j >= g.len() {
                continue;
            }
            let d = separation::<S>(g.x[i], g.x[j], period, half);
            let dist = d.length();
            let overlap = g.radius[i] + g.radius[j] - dist;
            if (overlap <= 0.0 && !p.state.bonded) || dist == 0.0 {
                continue;
            }
            let m = &state.params.materials[g.material[i] as usize];
            let mut st = p.state;
            let c = contact_force::<S>(m, overlap, d * (1.0 / dist), S::V::default(), 0.0, 1.0, 0.0, &mut st);
            if c.active {
                out.push((i, j, c.force, d));
            }
        }
        out
    }

    /// The elastic force of every grain–wall contact of the last neighbour list, unscaled
    /// like [`DemPipeline::contact_forces`]: (grain, contact point on the wall, force on the
    /// grain) by storage index.
    pub fn wall_contact_forces(&self, state: &DemState<S>) -> Vec<(usize, S::V, S::V)> {
        let g = &state.grains;
        let mut out = Vec::new();
        for w in &self.neighbors.walls {
            let i = w.grain as usize;
            if i >= g.len() {
                continue;
            }
            let wall = &state.walls[w.wall as usize];
            let (gap, n, _) = wall_geometry(&wall.shape, g.x[i], wall.velocity, wall.spin);
            if gap >= g.radius[i] && !w.state.bonded {
                continue;
            }
            let mut params = state.params.materials[g.material[i] as usize];
            params.friction = wall.friction;
            let mut st = w.state;
            let c = contact_force::<S>(&params, g.radius[i] - gap, n, S::V::default(), 0.0, 1.0, 0.0, &mut st);
            if c.active {
                out.push((i, g.x[i] - n * gap, c.force));
            }
        }
        out
    }

    /// Each grain's pressure −tr σ / d, positive in compression: the Love–Weber mean stress
    /// σ = (1/V) Σ l ⊗ f inside the grain over its own volume V (l from its centre to the
    /// contact point, which splits the centres' distance by the radii as Yue 2018 Alg. 11's
    /// homogenization does; f the force on it), from the elastic forces of
    /// [`DemPipeline::contact_forces`] and [`DemPipeline::wall_contact_forces`]. A continuum
    /// over the same packing carries φ (the packing fraction) times the grains' mean. All NaN
    /// while [`DemPipeline::contacts_known`] is false.
    pub fn grain_pressures(&self, state: &DemState<S>) -> Vec<f64> {
        let g = &state.grains;
        if !self.prepared {
            return vec![f64::NAN; g.len()];
        }
        // Σ l · f per grain; l · f < 0 in compression.
        let mut work = vec![0.0; g.len()];
        for (i, j, f, d) in self.contact_forces(state) {
            // d = x_i − x_j: i's arm is −r_i/(r_i + r_j) d, j's +r_j/(r_i + r_j) d, and j
            // feels −f; the two add up to −d · f.
            let (sum, fd) = (g.radius[i] + g.radius[j], f.dot(d));
            work[i] -= g.radius[i] / sum * fd;
            work[j] -= g.radius[j] / sum * fd;
        }
        for (i, at, f) in self.wall_contact_forces(state) {
            work[i] += (at - g.x[i]).dot(f);
        }
        (0..g.len())
            .map(|i| -work[i] / (S::DIM as f64 * Grains::<S>::mass_of(g.radius[i], 1.0)))
            .collect()
    }

    /// Gravitational potential energy −Σ m g·x [J], free bodies included.
    pub fn potential_energy(state: &DemState<S>) -> f64 {
        let g = &state.grains;
        let gravity = to_plane::<S>(state.params.gravity);
        (0..g.len())
            .map(|i| -g.mass[i] * g.scale[i] * state.params.gravity.dot(g.x[i]))
            .sum::<f64>()
            - free_bodies(state).map(|b| b.mass * gravity.dot(b.x)).sum::<f64>()
    }

    /// Total linear momentum [kg m/s], free bodies included.
    pub fn momentum(state: &DemState<S>) -> S::V {
        let g = &state.grains;
        let p = (0..g.len()).fold(S::V::default(), |p, i| p + g.v[i] * (g.mass[i] * g.scale[i]));
        free_bodies(state).fold(p, |p, b| p + S::from_array([b.v.x * b.mass, b.v.y * b.mass, 0.0]))
    }

    /// The id of the first grain whose position or velocity is not finite.
    pub fn first_non_finite(state: &DemState<S>) -> Option<u64> {
        let g = &state.grains;
        (0..g.len())
            .find(|&i| !g.x[i].is_finite() || !g.v[i].is_finite() || !g.omega[i].is_finite())
            .map(|i| g.id[i])
    }
}

/// A vector's in-plane part (the bodies are 2D).
fn to_plane<S: Space>(v: S::V) -> glam::DVec2 {
    let a = S::to_array(v);
    glam::DVec2::new(a[0], a[1])
}

/// The bodies that move by their forces (the others are boundaries: not in the energies).
fn free_bodies<S: Space>(state: &DemState<S>) -> impl Iterator<Item = &bodies::Body> {
    state.bodies.iter().filter(|b| b.motion == bodies::Motion::Free)
}

/// v += h (F + F_ext)/m' + h g, ω += h τ / I' with I' = (I/(m r²)) m' r² (m' scaled mass).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn half_kick<S: Space>(v: &mut S::V, w: &mut S::Ang, f: &GrainForce<S>, ext: S::V, gravity: S::V, mass: f64, r: f64, h: f64) {
    let inv_m = 1.0 / mass;
    *v += (f.force + ext) * (h * inv_m) + gravity * h;
    *w += f.torque * (h * inv_m / (S::INERTIA_FACTOR * r * r));
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
