//! The explicit MPM step, split in two phases at the coupling point (Yue 2018 App. C,
//! Alg. 20/21):
//!
//! - [`MpmPipeline::phase1`]: points → grid mass, momentum and internal force (P2G, from the
//!   Kirchhoff stress each point carries), gravity and point loads, grid velocities
//!   v_i = (p_i + dt f_i) / m_i, walls. The coupler may overwrite grid velocities after this.
//! - [`MpmPipeline::phase2`]: grid → points (G2P) with a PIC/FLIP blend or APIC, velocity
//!   gradient, trial elastic strain b^e ← (I + dt ∇v) b^e (I + dt ∇v)ᵀ, advection; then the
//!   constitutive update (return mapping, stress) of every point.
//!
//! The grid is sparse ([`crate::sparse`]): blocks are activated from the points' stencils at
//! the start of phase 1. With several threads, each thread scatters a contiguous share of the
//! points into its own node arrays, which are then summed node by node (the memory per thread
//! is that of the active nodes, far below that of the points).

use crate::boundary::{Contact, Wall};
use crate::constitutive::hencky_critical_state::{self as chen, HenckyCriticalState, PointState};
use crate::constitutive::plasticity_drucker_prager::{self as yue, DruckerPragerYue};
use crate::matrix::{Matrix, MpmSpace};
use crate::points::Points;
use crate::sparse::BlockMap;
use grains_grid::shape::axis_weights;
use grains_grid::{Grid, Kernel, Space, Vector};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Grid-to-point velocity transfer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transfer {
    /// PIC/FLIP blend with FLIP share β (1 = pure FLIP, 0 = PIC).
    Flip(f64),
    /// Affine particle-in-cell (Jiang et al. 2015): conserves angular momentum.
    Apic,
}

/// The constitutive model of the points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Model {
    /// Yue 2018 elasticity without yield (for elastic checks).
    Elastic(DruckerPragerYue),
    /// Yue 2018: b^e elasticity, Drucker–Prager, volume-preserving return, free flow.
    Yue(DruckerPragerYue),
    /// Chen 2021: Hencky elasticity, cohesive Drucker–Prager, critical-state softening.
    CriticalState(HenckyCriticalState),
}

impl Model {
    /// P-wave modulus M = K + 2 (1 − 1/d) G of the linearized elasticity [Pa]: the elastic
    /// wave speed is √(M / ρ).
    pub fn p_wave_modulus(&self, dim: usize) -> f64 {
        match self {
            Model::Elastic(m) | Model::Yue(m) => m.bulk + 2.0 * (1.0 - 1.0 / dim as f64) * m.shear,
            Model::CriticalState(m) => m.wave_speed_modulus(dim),
        }
    }

    /// Pressure −tr σ / d [Pa] (positive in compression) of a point with Kirchhoff stress τ and
    /// volume ratio J.
    pub fn pressure<M: Matrix>(tau: &M, jacobian: f64) -> f64 {
        -tau.trace() / (M::DIM as f64 * jacobian)
    }

    /// The packing fraction of a point: the critical-state model's state variable (eq. 8); for
    /// the others the initial one over J (they keep Φ0 in [`Points::packing`]).
    pub fn packing(&self, stored: f64, jacobian: f64) -> f64 {
        match self {
            Model::CriticalState(_) => stored,
            Model::Elastic(_) | Model::Yue(_) => stored / jacobian,
        }
    }
}

/// Parameters of a step.
#[derive(Clone, Debug)]
pub struct MpmParams<S: Space> {
    pub grid: Grid,
    pub kernel: Kernel,
    pub model: Model,
    pub gravity: S::V,
    pub transfer: Transfer,
    /// Condition on the outer layers of nodes of the domain (see [`DOMAIN_WALL_NODES`]); `None`
    /// leaves them free (then points must be kept away from the domain faces otherwise).
    pub domain_walls: Option<Contact>,
    pub walls: Vec<Wall<S>>,
}

/// Node layers along each domain face that form its wall: with three layers no point can come
/// within 1.5 cells of the face, so every stencil stays inside the grid.
pub const DOMAIN_WALL_NODES: i64 = 3;

/// Which part of the step found a problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Phase 1, grid velocity update.
    GridUpdate,
    /// Phase 2, grid to points.
    G2p,
    /// Phase 2, constitutive update.
    Constitutive,
}

impl std::fmt::Display for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Phase::GridUpdate => "phase 1 (grid velocity update)",
            Phase::G2p => "phase 2 (grid to points)",
            Phase::Constitutive => "phase 2 (constitutive update)",
        })
    }
}

/// A step that cannot go on.
#[derive(Clone, Debug, PartialEq)]
pub enum StepError {
    /// A value became NaN or infinite.
    NotFinite { phase: Phase, what: String },
    /// A point reached the outer cell of the grid (its stencil would leave the grid).
    LeftDomain { point: usize, position: [f64; 3] },
}

impl std::fmt::Display for StepError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StepError::NotFinite { phase, what } => write!(f, "{what} is not finite after {phase}"),
            StepError::LeftDomain { point, position } => write!(
                f,
                "material point {point} reached the edge of the grid at {position:?} (the domain must leave room for the flow)"
            ),
        }
    }
}

impl std::error::Error for StepError {}

/// Accumulated wall time of each part of the step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseTimes {
    /// Active blocks, P2G scatter and the sum of the threads' node arrays.
    pub p2g: Duration,
    /// Grid velocity update and walls.
    pub grid: Duration,
    /// G2P, strain update, advection.
    pub g2p: Duration,
    /// Return mapping and stress.
    pub constitutive: Duration,
}

/// Node arrays of a scatter.
#[derive(Clone, Debug, Default)]
struct Nodes<S: Space> {
    mass: Vec<f64>,
    momentum: Vec<S::V>,
    force: Vec<S::V>,
}

impl<S: Space> Nodes<S> {
    fn reset(&mut self, n: usize) {
        self.mass.clear();
        self.mass.resize(n, 0.0);
        self.momentum.clear();
        self.momentum.resize(n, S::V::default());
        self.force.clear();
        self.force.resize(n, S::V::default());
    }
}

/// The pipeline: its thread pool and grid state.
pub struct MpmPipeline<S: MpmSpace> {
    pool: std::sync::Arc<rayon::ThreadPool>,
    threads: usize,
    pub map: BlockMap,
    nodes: Nodes<S>,
    /// Per-thread node arrays beyond the first thread.
    partial: Vec<Nodes<S>>,
    /// Grid velocity after phase 1 (possibly overwritten by the coupler).
    pub velocity: Vec<S::V>,
    /// Grid velocity before the force update (for FLIP).
    velocity_old: Vec<S::V>,
    /// Simulated time [s] (moves walls).
    pub time: f64,
    pub times: PhaseTimes,
}

/// Points per task in the per-point passes.
const POINT_TASK: usize = 4096;

/// One point's stencil: per axis the first node and the three weights and derivatives.
#[derive(Clone, Copy)]
struct Stencil {
    start: [i64; 3],
    w: [[f64; 3]; 3],
    dw: [[f64; 3]; 3],
}

#[inline(always)]
fn stencil<S: Space>(grid: &Grid, kernel: Kernel, x: S::V) -> Stencil {
    let a = S::to_array(x);
    let mut s = Stencil {
        start: [0; 3],
        w: [[1.0, 0.0, 0.0]; 3],
        dw: [[0.0; 3]; 3],
    };
    for (k, &ak) in a.iter().enumerate().take(S::DIM) {
        let axis = axis_weights(kernel, ak - grid.origin[k], grid.h);
        s.start[k] = axis.start;
        s.w[k] = axis.w;
        s.dw[k] = axis.dw;
    }
    s
}

/// Calls `f(slot, weight, gradient, node − x)` for the 3^d nodes of a stencil.
#[inline(always)]
fn for_stencil<S: Space>(grid: &Grid, map: &BlockMap, st: &Stencil, x: S::V, mut f: impl FnMut(usize, f64, S::V, S::V)) {
    let xa = S::to_array(x);
    let mut r = [[0.0; 3]; 3];
    for (k, rk) in r.iter_mut().enumerate().take(S::DIM) {
        for (a, ra) in rk.iter_mut().enumerate() {
            *ra = grid.origin[k] + grid.h * (st.start[k] + a as i64) as f64 - xa[k];
        }
    }
    let nz = if S::DIM == 3 { 3 } else { 1 };
    for c in 0..nz {
        for b in 0..3 {
            let (wy, wz, dwy, dwz) = (st.w[1][b], st.w[2][c], st.dw[1][b], st.dw[2][c]);
            for a in 0..3 {
                let slot = map.slot([st.start[0] + a as i64, st.start[1] + b as i64, st.start[2] + c as i64]);
                let wx = st.w[0][a];
                let w = wx * wy * wz;
                let grad = S::from_array([st.dw[0][a] * wy * wz, wx * dwy * wz, wx * wy * dwz]);
                f(slot, w, grad, S::from_array([r[0][a], r[1][b], r[2][c]]));
            }
        }
    }
}

impl<S: MpmSpace> MpmPipeline<S> {
    /// A pipeline running its loops on `threads` threads (named `mpm-worker-<k>`).
    pub fn new(threads: usize) -> Result<Self, String> {
        let threads = threads.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|k| format!("mpm-worker-{k}"))
            .build()
            .map_err(|e| format!("cannot start {threads} MPM threads: {e}"))?;
        Ok(MpmPipeline {
            pool: std::sync::Arc::new(pool),
            threads,
            map: BlockMap::default(),
            nodes: Nodes::default(),
            partial: Vec::new(),
            velocity: Vec::new(),
            velocity_old: Vec::new(),
            time: 0.0,
            times: PhaseTimes::default(),
        })
    }

    /// Phase 1 (Alg. 20): P2G, forces, grid velocities.
    pub fn phase1(&mut self, pts: &Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let pool = self.pool.clone();
        pool.install(|| {
            let t0 = Instant::now();
            self.scatter(pts, params);
            let t1 = Instant::now();
            let r = self.update_grid(params, dt);
            self.times.p2g += t1 - t0;
            self.times.grid += t1.elapsed();
            r
        })
    }

    fn scatter(&mut self, pts: &Points<S>, params: &MpmParams<S>) {
        let grid = &params.grid;
        if self.map.domain_blocks() == 0 || self.map_grid_changed(grid) {
            self.map = BlockMap::new(grid, S::DIM);
        }
        self.map.rebuild(pts.x.iter().map(|&x| stencil::<S>(grid, params.kernel, x).start));
        let n = self.map.len();
        let chunks = if pts.len() >= 2 * POINT_TASK { self.threads } else { 1 };
        self.partial.resize_with(chunks - 1, Nodes::default);
        let per = pts.len().div_ceil(chunks);
        let map = &self.map;
        let scatter_range = |nodes: &mut Nodes<S>, range: std::ops::Range<usize>| {
            nodes.reset(n);
            for p in range {
                let (w, xp) = (pts.weight[p], pts.x[p]);
                let m = pts.mass[p] * w;
                // Kirchhoff stress with the reference volume: f_i = −Σ V0 τ ∇w_ip.
                let tau = pts.tau[p] * (pts.volume[p] * w);
                let (v, c) = (pts.v[p], pts.affine[p]);
                let apic = params.transfer == Transfer::Apic;
                let st = stencil::<S>(grid, params.kernel, xp);
                for_stencil::<S>(grid, map, &st, xp, |i, wip, grad, r| {
                    nodes.mass[i] += m * wip;
                    let vi = if apic { v + S::mul_vec(&c, r) } else { v };
                    nodes.momentum[i] += vi * (m * wip);
                    nodes.force[i] -= S::mul_vec(&tau, grad);
                });
            }
        };
        let (first, rest) = (&mut self.nodes, &mut self.partial);
        rayon::join(
            || scatter_range(first, 0..per.min(pts.len())),
            || {
                rest.par_iter_mut().enumerate().for_each(|(k, nodes)| {
                    let lo = ((k + 1) * per).min(pts.len());
                    scatter_range(nodes, lo..((k + 2) * per).min(pts.len()))
                })
            },
        );
        if !self.partial.is_empty() {
            let partial = &self.partial;
            let dst = &mut self.nodes;
            dst.mass
                .par_chunks_mut(POINT_TASK)
                .zip(dst.momentum.par_chunks_mut(POINT_TASK))
                .zip(dst.force.par_chunks_mut(POINT_TASK))
                .enumerate()
                .for_each(|(c, ((m, p), f))| {
                    let lo = c * POINT_TASK;
                    for src in partial {
                        for k in 0..m.len() {
                            m[k] += src.mass[lo + k];
                            p[k] += src.momentum[lo + k];
                            f[k] += src.force[lo + k];
                        }
                    }
                });
        }
        // Point loads (few points): serial.
        for &(p, f) in &pts.loads {
            let st = stencil::<S>(grid, params.kernel, pts.x[p]);
            let force = &mut self.nodes.force;
            for_stencil::<S>(grid, map, &st, pts.x[p], |i, wip, _, _| force[i] += f * wip);
        }
    }

    fn map_grid_changed(&self, grid: &Grid) -> bool {
        let probe = BlockMap::new(grid, S::DIM);
        probe.domain_blocks() != self.map.domain_blocks()
    }

    fn update_grid(&mut self, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let n = self.map.len();
        self.velocity.clear();
        self.velocity.resize(n, S::V::default());
        self.velocity_old.clear();
        self.velocity_old.resize(n, S::V::default());
        let (map, nodes, time) = (&self.map, &self.nodes, self.time);
        let bad = self
            .velocity
            .par_chunks_mut(POINT_TASK)
            .zip(self.velocity_old.par_chunks_mut(POINT_TASK))
            .enumerate()
            .map(|(c, (vel, old))| {
                let mut bad = None;
                for k in 0..vel.len() {
                    let i = c * POINT_TASK + k;
                    let m = nodes.mass[i];
                    if m <= 0.0 {
                        continue;
                    }
                    old[k] = nodes.momentum[i] * (1.0 / m);
                    let mut v = (nodes.momentum[i] + nodes.force[i] * dt) * (1.0 / m) + params.gravity * dt;
                    if params.domain_walls.is_some() || !params.walls.is_empty() {
                        v = apply_walls(params, map.ijk(i), v, time);
                    }
                    if !v.is_finite() && bad.is_none() {
                        bad = Some(map.ijk(i));
                    }
                    vel[k] = v;
                }
                bad
            })
            .find_any(|b| b.is_some())
            .flatten();
        match bad {
            Some(ijk) => Err(StepError::NotFinite {
                phase: Phase::GridUpdate,
                what: format!("the velocity of grid node {:?}", &ijk[..S::DIM]),
            }),
            None => Ok(()),
        }
    }

    /// Phase 2 (Alg. 21): G2P, strain update, advection from the (possibly constrained) grid
    /// velocities, then the constitutive update.
    pub fn phase2(&mut self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let pool = self.pool.clone();
        pool.install(|| {
            let t0 = Instant::now();
            let r = self.gather(pts, params, dt);
            let t1 = Instant::now();
            self.times.g2p += t1 - t0;
            r?;
            let r = constitutive(pts, &params.model, dt);
            self.times.constitutive += t1.elapsed();
            self.time += dt;
            r
        })
    }

    fn gather(&self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let grid = &params.grid;
        let (map, vel, old) = (&self.map, &self.velocity, &self.velocity_old);
        // Points must keep one cell between them and the outer nodes (see DOMAIN_WALL_NODES).
        let lo = S::from_array([0, 1, 2].map(|k| grid.origin[k] + grid.h));
        let hi = S::from_array([0, 1, 2].map(|k| grid.origin[k] + grid.h * (grid.nodes[k] as f64 - 2.0)));
        let inside = |x: S::V| {
            let (x, lo, hi) = (S::to_array(x), S::to_array(lo), S::to_array(hi));
            (0..S::DIM).all(|k| x[k] >= lo[k] && x[k] <= hi[k])
        };
        let gimp_d = matches!(params.kernel, Kernel::Gimp { .. });
        let d_inv_bspline = 4.0 / (grid.h * grid.h);
        let zero = S::M::identity() * 0.0;
        let bad = pts
            .x
            .par_chunks_mut(POINT_TASK)
            .zip(pts.v.par_chunks_mut(POINT_TASK))
            .zip(pts.b_e.par_chunks_mut(POINT_TASK))
            .zip(pts.affine.par_chunks_mut(POINT_TASK))
            .zip(pts.jacobian.par_chunks_mut(POINT_TASK))
            .enumerate()
            .map(|(c, ((((xs, vs), bs), cs), js))| {
                for k in 0..xs.len() {
                    let xp = xs[k];
                    if !inside(xp) {
                        return Some(StepError::LeftDomain {
                            point: c * POINT_TASK + k,
                            position: S::to_array(xp),
                        });
                    }
                    let st = stencil::<S>(grid, params.kernel, xp);
                    let (mut v_pic, mut dv) = (S::V::default(), S::V::default());
                    let (mut grad_v, mut b, mut d) = (zero, zero, zero);
                    for_stencil::<S>(grid, map, &st, xp, |i, wip, grad, r| {
                        v_pic += vel[i] * wip;
                        grad_v = grad_v + S::outer(vel[i], grad);
                        match params.transfer {
                            Transfer::Flip(_) => dv += (vel[i] - old[i]) * wip,
                            Transfer::Apic => {
                                b = b + S::outer(vel[i], r) * wip;
                                if gimp_d {
                                    d = d + S::outer(r, r) * wip;
                                }
                            }
                        }
                    });
                    match params.transfer {
                        Transfer::Flip(beta) => vs[k] = (vs[k] + dv) * beta + v_pic * (1.0 - beta),
                        Transfer::Apic => {
                            vs[k] = v_pic;
                            // C = B D⁻¹ (D = h²/4 I for quadratic B-splines; computed for GIMP).
                            cs[k] = if gimp_d { S::mul(&b, &d.inverse()) } else { b * d_inv_bspline };
                        }
                    }
                    let f = S::M::identity() + grad_v * dt;
                    bs[k] = S::mul(&S::mul(&f, &bs[k]), &S::transpose(&f));
                    js[k] *= f.det();
                    xs[k] = xp + v_pic * dt;
                    if !(vs[k].is_finite() && xs[k].is_finite()) {
                        return Some(StepError::NotFinite {
                            phase: Phase::G2p,
                            what: format!("the velocity of material point {}", c * POINT_TASK + k),
                        });
                    }
                }
                None
            })
            .find_any(|e| e.is_some())
            .flatten();
        bad.map_or(Ok(()), Err)
    }

    /// Both phases (an MPM-only step).
    pub fn step(&mut self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        self.phase1(pts, params, dt)?;
        self.phase2(pts, params, dt)
    }

    /// Total mass and momentum on the grid after phase 1's P2G [kg, kg m/s].
    pub fn grid_totals(&self) -> (f64, S::V) {
        (
            self.nodes.mass.iter().sum(),
            self.nodes.momentum.iter().fold(S::V::default(), |a, &b| a + b),
        )
    }

    /// Visits every stored node with mass after phase 1: its (i, j, k), mass and velocity
    /// (which the coupler may change before phase 2).
    pub fn for_each_node_mut(&mut self, mut f: impl FnMut([i64; 3], f64, &mut S::V)) {
        for (i, v) in self.velocity.iter_mut().enumerate() {
            let m = self.nodes.mass[i];
            if m > 0.0 {
                f(self.map.ijk(i), m, v);
            }
        }
    }
}

#[inline]
fn apply_walls<S: MpmSpace>(params: &MpmParams<S>, ijk: [i64; 3], v: S::V, time: f64) -> S::V {
    let mut v = v;
    if let Some(contact) = params.domain_walls {
        for k in 0..S::DIM {
            let n = params.grid.nodes[k] as i64;
            let mut normal = [0.0; 3];
            if ijk[k] < DOMAIN_WALL_NODES {
                normal[k] = 1.0;
            } else if ijk[k] >= n - DOMAIN_WALL_NODES {
                normal[k] = -1.0;
            } else {
                continue;
            }
            v = crate::boundary::correct::<S>(contact, v, S::V::default(), S::from_array(normal));
        }
    }
    if !params.walls.is_empty() {
        let x = S::from_array(params.grid.position(ijk));
        for w in &params.walls {
            v = w.apply(x, v, time);
        }
    }
    v
}

/// The return mapping and the stress of every point.
fn constitutive<S: MpmSpace>(pts: &mut Points<S>, model: &Model, dt: f64) -> Result<(), StepError> {
    let bad = pts
        .b_e
        .par_chunks_mut(POINT_TASK)
        .zip(pts.tau.par_chunks_mut(POINT_TASK))
        .zip(pts.plastic_strain.par_chunks_mut(POINT_TASK))
        .zip(pts.plastic_rate.par_chunks_mut(POINT_TASK))
        .zip(pts.packing.par_chunks_mut(POINT_TASK))
        .enumerate()
        .map(|(c, ((((bs, ts), eps), rate), phi))| {
            for k in 0..bs.len() {
                let trial = bs[k];
                match model {
                    Model::Elastic(m) => ts[k] = yue::kirchhoff(m, &trial),
                    Model::Yue(m) => {
                        let b = yue::return_map(m, &trial);
                        // ‖Δε^p‖ with ε = ½ ln b ≈ ½ (b − I) for the small elastic strains of sand.
                        let de = 0.5 * (trial - b).norm();
                        eps[k] += de;
                        rate[k] = de / dt;
                        bs[k] = b;
                        ts[k] = yue::kirchhoff(m, &b);
                    }
                    Model::CriticalState(m) => {
                        let mut state = PointState {
                            packing: phi[k],
                            plastic_strain: eps[k],
                            plastic_strain_rate: 0.0,
                        };
                        (bs[k], ts[k]) = chen::return_map(m, &trial, &mut state, dt);
                        (phi[k], eps[k], rate[k]) = (state.packing, state.plastic_strain, state.plastic_strain_rate);
                    }
                }
                if !ts[k].norm().is_finite() {
                    return Some(c * POINT_TASK + k);
                }
            }
            None
        })
        .find_any(|e| e.is_some())
        .flatten();
    match bad {
        Some(p) => Err(StepError::NotFinite {
            phase: Phase::Constitutive,
            what: format!("the stress of material point {p}"),
        }),
        None => Ok(()),
    }
}

/// The largest stable time step h / c with c = √(M / ρ) the elastic P-wave speed [s]
/// (CFL number 1; explicit MPM is run below it, at 0.3–0.5 of it as a rule).
pub fn cfl_time_step(model: &Model, density: f64, h: f64, dim: usize) -> f64 {
    h / (model.p_wave_modulus(dim) / density).sqrt()
}
