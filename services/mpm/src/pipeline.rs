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
use grains_grid::shape::Weights;
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

    /// Kirchhoff stress τ of an elastic strain b^e.
    pub fn kirchhoff<M: Matrix>(&self, b_e: &M) -> M {
        match self {
            Model::Elastic(m) | Model::Yue(m) => yue::kirchhoff(m, b_e),
            Model::CriticalState(m) => chen::kirchhoff(m, b_e),
        }
    }

    /// The elastic strain b^e of a Cauchy stress σ (new points made from grains, Yue 2018
    /// §4.2).
    pub fn strain_of_stress<M: Matrix>(&self, sigma: &M) -> M {
        match self {
            Model::Elastic(m) | Model::Yue(m) => yue::strain_of_stress(m, sigma),
            Model::CriticalState(m) => chen::strain_of_stress(m, sigma),
        }
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

/// How a point load ([`Points::loads`]) reaches the grid's nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointLoads {
    /// Through the point's weights (Jiang 2020 §4: the force on the point). A load on an
    /// outermost point then hands part of itself to the nodes inside the material, past the
    /// cell the point is in: that cell's stress carries only the rest (about 3/4 on GIMP with
    /// two points per cell).
    Weights,
    /// On the node nearest the point (Jiang 2020 §5.4's MPM-GRID scheme, to compare with).
    Nearest,
    /// As a traction on the point's face the load comes from: at x_p − l f/|f| (l the GIMP
    /// half-width), spread by the linear hat, as a finite element takes a surface load. The
    /// cells between that face and the nodes carry it whole: the outermost points are
    /// stressed as the rest (`validate::shear::biaxial`'s platen test).
    Face,
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
    /// How a point load reaches the nodes.
    pub point_loads: PointLoads,
    /// The pressure of a fluid around the material [Pa] (a confining cell's), for MPM-only
    /// material: it acts on every face, following the faces as they move (on a face against
    /// a wall the wall's nodes take it, so a wall's reaction includes p A), scaled like the
    /// stress by a point's hybrid weight; grains get none. By the
    /// divergence theorem its nodal forces are those of a uniform stress −p I, so the
    /// material's stress is taken as σ + p I in the internal force, and material at −p I is in
    /// equilibrium node by node. (Point loads on the outermost points, the other way, leave
    /// those points unstressed and yielding: GIMP hands part of each load to nodes the stress
    /// does not reach.) 0: no fluid.
    pub ambient_pressure: f64,
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
    /// A point is in the outer cell of the grid (its stencil would leave the grid).
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

/// What P2G accumulates on a node (one record per node: a point's scatter touches one cache
/// line per node rather than one per array).
#[derive(Clone, Copy, Debug, Default)]
struct Acc<S: Space> {
    mass: f64,
    momentum: S::V,
    force: S::V,
}

/// What a chunk of the grid update found: its first non-finite node, and the momentum each
/// wall took from its nodes.
type ChunkUpdate<S> = (Option<[i64; 3]>, Vec<<S as Space>::V>);

/// A node's velocity after phase 1 and before the force update (FLIP needs both).
#[derive(Clone, Copy, Debug, Default)]
struct Vel<S: Space> {
    v: S::V,
    old: S::V,
}

fn reset<T: Default + Clone>(v: &mut Vec<T>, n: usize) {
    v.clear();
    v.resize(n, T::default());
}

/// The pipeline: its thread pool and grid state.
pub struct MpmPipeline<S: MpmSpace> {
    pool: std::sync::Arc<rayon::ThreadPool>,
    threads: usize,
    pub map: BlockMap,
    nodes: Vec<Acc<S>>,
    /// Per-thread node arrays beyond the first thread, each over the slots from its offset.
    partial: Vec<(usize, Vec<Acc<S>>)>,
    /// Grid velocities after phase 1 (possibly overwritten by the coupler) and before forces.
    velocity: Vec<Vel<S>>,
    /// Simulated time [s] (moves walls).
    pub time: f64,
    pub times: PhaseTimes,
    steps: u64,
    /// The material's force on each of `params.walls` over the last grid update [N] (2D: N/m):
    /// minus the momentum the wall took from its nodes, over dt.
    pub wall_loads: Vec<S::V>,
}

impl<S: MpmSpace> MpmPipeline<S> {
    /// What the pipeline carries from one step to the next beside the points: the time (it
    /// moves walls) and the step count (it times the points' re-sort). The grid is rebuilt
    /// from the points every step.
    pub fn carry(&self) -> (f64, u64) {
        (self.time, self.steps)
    }

    pub fn restore(&mut self, (time, steps): (f64, u64)) {
        self.time = time;
        self.steps = steps;
    }
}

/// Points per task in the per-point passes.
const POINT_TASK: usize = 4096;

/// Sort the points by grid block every this many steps: neighbours in memory stay neighbours
/// on the grid (cache reuse in P2G and G2P), and each thread's share of the points covers a
/// compact range of nodes (its private P2G array stays small).
const SORT_EVERY: u64 = 25;

/// One point's stencil: per axis the first node and the three weights and derivatives.
#[derive(Clone, Copy)]
struct Stencil {
    start: [i64; 3],
    w: [[f64; 3]; 3],
    dw: [[f64; 3]; 3],
}

#[inline(always)]
fn stencil<S: Space>(grid: &Grid, weights: &Weights, x: S::V) -> Stencil {
    let a = S::to_array(x);
    let mut s = Stencil {
        start: [0; 3],
        w: [[1.0, 0.0, 0.0]; 3],
        dw: [[0.0; 3]; 3],
    };
    for (k, &ak) in a.iter().enumerate().take(S::DIM) {
        let axis = weights.axis(ak - grid.origin[k]);
        s.start[k] = axis.start;
        s.w[k] = axis.w;
        s.dw[k] = axis.dw;
    }
    s
}

/// The first node of a point's stencil.
#[inline(always)]
fn stencil_start<S: Space>(grid: &Grid, weights: &Weights, x: S::V) -> [i64; 3] {
    let a = S::to_array(x);
    let mut start = [0; 3];
    for (k, &ak) in a.iter().enumerate().take(S::DIM) {
        start[k] = weights.start(ak - grid.origin[k]);
    }
    start
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
    let slots = map.stencil_nodes(st.start);
    let nz = if S::DIM == 3 { 3 } else { 1 };
    for c in 0..nz {
        for b in 0..3 {
            let (wy, wz, dwy, dwz) = (st.w[1][b], st.w[2][c], st.dw[1][b], st.dw[2][c]);
            for a in 0..3 {
                let slot = slots[a + 3 * b + 9 * c];
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
            nodes: Vec::new(),
            partial: Vec::new(),
            velocity: Vec::new(),
            time: 0.0,
            times: PhaseTimes::default(),
            steps: 0,
            wall_loads: Vec::new(),
        })
    }

    /// Phase 1 (Alg. 20): P2G, forces, grid velocities.
    pub fn phase1(&mut self, pts: &Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let pool = self.pool.clone();
        pool.install(|| {
            let t0 = Instant::now();
            self.scatter(pts, params)?;
            let t1 = Instant::now();
            let r = self.update_grid(params, dt);
            self.times.p2g += t1 - t0;
            self.times.grid += t1.elapsed();
            r
        })
    }

    fn scatter(&mut self, pts: &Points<S>, params: &MpmParams<S>) -> Result<(), StepError> {
        let grid = &params.grid;
        if self.map.domain_blocks() == 0 || self.map_grid_changed(grid) {
            self.map = BlockMap::new(grid, S::DIM);
        }
        let weights = Weights::new(params.kernel, grid.h);
        if let Err(p) = self.map.rebuild(pts.x.iter().map(|&x| stencil_start::<S>(grid, &weights, x))) {
            return Err(StepError::LeftDomain {
                point: p,
                position: S::to_array(pts.x[p]),
            });
        }
        let n = self.map.len();
        let chunks = if pts.len() >= 2 * POINT_TASK { self.threads } else { 1 };
        self.partial.resize_with(chunks - 1, || (0, Vec::new()));
        let per = pts.len().div_ceil(chunks);
        let map = &self.map;
        let bn = map.block_nodes();
        // The slots a range of points writes: from the block of the lowest stencil slot to the
        // end of the block of the highest (slots follow block order).
        let slot_range = |range: std::ops::Range<usize>| {
            let (mut lo, mut hi) = (usize::MAX, 0);
            for p in range {
                let (a, b) = map.stencil_slots(stencil_start::<S>(grid, &weights, pts.x[p]));
                lo = lo.min(a);
                hi = hi.max(b);
            }
            (lo / bn * bn, (hi / bn + 1) * bn)
        };
        let zero = S::M::identity() * 0.0;
        let ambient = params.ambient_pressure;
        let scatter_range = |nodes: &mut Vec<Acc<S>>, offset: usize, len: usize, range: std::ops::Range<usize>| {
            reset(nodes, len);
            for p in range {
                let (w, xp) = (pts.weight[p], pts.x[p]);
                let m = pts.mass[p] * w;
                // Kirchhoff stress with the reference volume: f_i = −Σ V0 τ ∇w_ip; the ambient
                // pressure as the Kirchhoff stress J p I.
                let tau = if ambient == 0.0 {
                    pts.tau[p]
                } else {
                    pts.tau[p] + S::M::identity() * (ambient * pts.jacobian[p])
                };
                let tau = tau * (pts.volume[p] * w);
                let apic = params.transfer == Transfer::Apic;
                // FLIP never reads the affine matrices (a third of a 3D point's bytes).
                let (v, c) = (pts.v[p], if apic { pts.affine[p] } else { zero });
                let st = stencil::<S>(grid, &weights, xp);
                for_stencil::<S>(grid, map, &st, xp, |i, wip, grad, r| {
                    let node = &mut nodes[i - offset];
                    node.mass += m * wip;
                    let vi = if apic { v + S::mul_vec(&c, r) } else { v };
                    node.momentum += vi * (m * wip);
                    node.force -= S::mul_vec(&tau, grad);
                });
            }
        };
        let (first, rest) = (&mut self.nodes, &mut self.partial);
        rayon::join(
            || scatter_range(first, 0, n, 0..per.min(pts.len())),
            || {
                rest.par_iter_mut().enumerate().for_each(|(k, (offset, nodes))| {
                    let range = ((k + 1) * per).min(pts.len())..((k + 2) * per).min(pts.len());
                    let (lo, hi) = if range.is_empty() { (0, 0) } else { slot_range(range.clone()) };
                    *offset = lo;
                    scatter_range(nodes, lo, hi - lo, range)
                })
            },
        );
        for (offset, src) in &self.partial {
            self.nodes[*offset..*offset + src.len()]
                .par_chunks_mut(POINT_TASK)
                .zip(src.par_chunks(POINT_TASK))
                .for_each(|(dst, src)| {
                    for (d, s) in dst.iter_mut().zip(src) {
                        d.mass += s.mass;
                        d.momentum += s.momentum;
                        d.force += s.force;
                    }
                });
        }
        // Point loads (few points): serial.
        for &(p, f) in &pts.loads {
            let st = stencil::<S>(grid, &weights, pts.x[p]);
            let nodes = &mut self.nodes;
            match params.point_loads {
                PointLoads::Nearest => {
                    // The node of the largest weight (the first of equals): the nearest one.
                    let mut best = (usize::MAX, 0.0);
                    for_stencil::<S>(grid, map, &st, pts.x[p], |i, wip, _, _| {
                        if wip > best.1 {
                            best = (i, wip);
                        }
                    });
                    if best.0 != usize::MAX {
                        nodes[best.0].force += f;
                    }
                }
                PointLoads::Weights => {
                    for_stencil::<S>(grid, map, &st, pts.x[p], |i, wip, _, _| nodes[i].force += f * wip);
                }
                PointLoads::Face => {
                    let l = match params.kernel {
                        Kernel::Gimp { half_width } => half_width,
                        Kernel::Bspline2 => 0.0,
                    };
                    let len = f.length();
                    let face = if len > 0.0 { pts.x[p] - f * (l / len) } else { pts.x[p] };
                    // The face lies within l ≤ h/2 of the point, so the two nodes about it on
                    // each axis are among the point's stencil's three.
                    let linear = |x: S::V| {
                        let mut s = st;
                        for (k, &xk) in S::to_array(x).iter().enumerate().take(S::DIM) {
                            for a in 0..3 {
                                let node = grid.origin[k] + grid.h * (st.start[k] + a as i64) as f64;
                                s.w[k][a] = (1.0 - (xk - node).abs() / grid.h).max(0.0);
                            }
                        }
                        s
                    };
                    for_stencil::<S>(grid, map, &linear(face), pts.x[p], |i, wip, _, _| nodes[i].force += f * wip);
                }
            }
        }
        Ok(())
    }

    fn map_grid_changed(&self, grid: &Grid) -> bool {
        let probe = BlockMap::new(grid, S::DIM);
        probe.domain_blocks() != self.map.domain_blocks()
    }

    fn update_grid(&mut self, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        reset(&mut self.velocity, self.map.len());
        let (map, nodes, time) = (&self.map, &self.nodes, self.time);
        let walls = params.walls.len();
        // Per chunk, in chunk order: the same sums for any thread count.
        let chunks: Vec<ChunkUpdate<S>> = self
            .velocity
            .par_chunks_mut(POINT_TASK)
            .enumerate()
            .map(|(c, vel)| {
                let mut bad = None;
                let mut taken = vec![S::V::default(); walls];
                for (k, out) in vel.iter_mut().enumerate() {
                    let i = c * POINT_TASK + k;
                    let node = &nodes[i];
                    if node.mass <= 0.0 {
                        continue;
                    }
                    let inv_m = 1.0 / node.mass;
                    out.old = node.momentum * inv_m;
                    let mut v = (node.momentum + node.force * dt) * inv_m + params.gravity * dt;
                    if params.domain_walls.is_some() || walls > 0 {
                        v = apply_walls(params, map.ijk(i), v, time, node.mass, &mut taken);
                    }
                    if !v.is_finite() && bad.is_none() {
                        bad = Some(map.ijk(i));
                    }
                    out.v = v;
                }
                (bad, taken)
            })
            .collect();
        self.wall_loads.clear();
        self.wall_loads.resize(walls, S::V::default());
        for (_, taken) in &chunks {
            for (load, t) in self.wall_loads.iter_mut().zip(taken) {
                *load += *t * (1.0 / dt);
            }
        }
        match chunks.iter().find_map(|c| c.0) {
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
            self.steps += 1;
            if self.steps.is_multiple_of(SORT_EVERY) {
                let t2 = Instant::now();
                self.sort(pts, params);
                self.times.g2p += t2.elapsed();
            }
            r
        })
    }

    fn gather(&self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        let grid = &params.grid;
        let (map, vel) = (&self.map, &self.velocity);
        let weights = Weights::new(params.kernel, grid.h);
        // Points must keep one cell between them and the outer nodes (see DOMAIN_WALL_NODES);
        // along a periodic axis they wrap around instead.
        let lo = S::from_array([0, 1, 2].map(|k| grid.origin[k] + grid.h));
        let hi = S::from_array([0, 1, 2].map(|k| grid.origin[k] + grid.h * (grid.nodes[k] as f64 - 2.0)));
        let inside = |x: S::V| {
            let (x, lo, hi) = (S::to_array(x), S::to_array(lo), S::to_array(hi));
            (0..S::DIM).all(|k| grid.period[k] > 0 || (x[k] >= lo[k] && x[k] <= hi[k]))
        };
        let periodic = grid.period.iter().any(|&p| p > 0);
        let (box_lo, box_hi, period) = grid.wrap_box::<S>();
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
                    let st = stencil::<S>(grid, &weights, xp);
                    let (mut v_pic, mut dv) = (S::V::default(), S::V::default());
                    let (mut grad_v, mut b, mut d) = (zero, zero, zero);
                    for_stencil::<S>(grid, map, &st, xp, |i, wip, grad, r| {
                        let node = &vel[i];
                        v_pic += node.v * wip;
                        grad_v = grad_v + S::outer(node.v, grad);
                        match params.transfer {
                            Transfer::Flip(_) => dv += (node.v - node.old) * wip,
                            Transfer::Apic => {
                                b = b + S::outer(node.v, r) * wip;
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
                    if periodic {
                        xs[k] = xs[k].wrap(box_lo, box_hi, period);
                    }
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

    /// Sorts the points by the grid block of their stencil (a stable counting sort).
    fn sort(&self, pts: &mut Points<S>, params: &MpmParams<S>) {
        let weights = Weights::new(params.kernel, params.grid.h);
        let keys: Vec<u32> = pts
            .x
            .iter()
            .map(|&x| self.map.block_index(stencil_start::<S>(&params.grid, &weights, x)) as u32)
            .collect();
        let mut count = vec![0u32; self.map.domain_blocks() + 1];
        for &k in &keys {
            count[k as usize + 1] += 1;
        }
        for b in 1..count.len() {
            count[b] += count[b - 1];
        }
        let mut order = vec![0u32; keys.len()];
        for (p, &k) in keys.iter().enumerate() {
            order[count[k as usize] as usize] = p as u32;
            count[k as usize] += 1;
        }
        pts.permute(&order);
    }

    /// Both phases (an MPM-only step).
    pub fn step(&mut self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) -> Result<(), StepError> {
        self.phase1(pts, params, dt)?;
        self.phase2(pts, params, dt)
    }

    /// Total mass and momentum on the grid after phase 1's P2G [kg, kg m/s].
    pub fn grid_totals(&self) -> (f64, S::V) {
        (
            self.nodes.iter().map(|n| n.mass).sum(),
            self.nodes.iter().fold(S::V::default(), |a, n| a + n.momentum),
        )
    }

    /// The velocity of node (i, j, k) after phase 1, for the coupler to overwrite; `None` when
    /// the node carries no material.
    pub fn node_velocity_mut(&mut self, ijk: [i64; 3]) -> Option<&mut S::V> {
        let slot = self.map.try_slot(ijk)?;
        (self.nodes[slot].mass > 0.0).then(|| &mut self.velocity[slot].v)
    }

    /// Visits every stored node with mass after phase 1: its (i, j, k), mass and velocity
    /// (which the coupler may change before phase 2).
    pub fn for_each_node_mut(&mut self, mut f: impl FnMut([i64; 3], f64, &mut S::V)) {
        for (i, node) in self.velocity.iter_mut().enumerate() {
            let m = self.nodes[i].mass;
            if m > 0.0 {
                f(self.map.ijk(i), m, &mut node.v);
            }
        }
    }
}

/// The node's velocity after the domain's walls and the scene's; `taken[w]` gains the
/// momentum wall `w` took from it (its load on the wall over the step).
#[inline]
fn apply_walls<S: MpmSpace>(params: &MpmParams<S>, ijk: [i64; 3], v: S::V, time: f64, mass: f64, taken: &mut [S::V]) -> S::V {
    let mut v = v;
    if let Some(contact) = params.domain_walls {
        // No wall across a periodic axis.
        for k in (0..S::DIM).filter(|&k| params.grid.period[k] == 0) {
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
        for (w, taken) in params.walls.iter().zip(taken) {
            let after = w.apply(x, v, time);
            *taken += (v - after) * mass;
            v = after;
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
                        let (b, de) = m.return_map_rate(&trial, dt);
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

/// Largest CFL number dt c / h a scene may use. `grains validate`'s stability map found the
/// column collapse (GIMP, FLIP) stable at 0.8 and blowing up at 0.9 of h / c; half of it
/// leaves room for the flow's own speed and other materials.
pub const MAX_CFL: f64 = 0.5;

/// The largest stable time step h / c with c = √(M / ρ) the elastic P-wave speed [s]
/// (CFL number 1; explicit MPM is run below it, at 0.3–0.5 of it as a rule).
pub fn cfl_time_step(model: &Model, density: f64, h: f64, dim: usize) -> f64 {
    h / (model.p_wave_modulus(dim) / density).sqrt()
}
