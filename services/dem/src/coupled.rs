//! The DEM half of a coupled macro-step (Yue 2018 Alg. 2, 4–6), as a stage over the state and
//! the pipeline, split at the coupling point like the MPM's `phase1` / `phase2`:
//!
//! 1. [`CoupledStep::advance`] (Alg. 2): saves the hybrid grains' positions (scale 1 − w < 1,
//!    not frozen) and runs the k substeps, hybrid grains with mass and springs scaled by 1 − w;
//! 2. [`CoupledStep::rasterize`] (Alg. 4): their predicted momentum at the saved positions
//!    onto the MPM grid, with its weights; what the coupler gets is
//!    [`CoupledStep::uncoupled_momentum`] of each node;
//! 3. the coupler constrains the shared nodes (Alg. 3, in `grains-coupler`);
//! 4. [`CoupledStep::finish`] (Alg. 5–6): the hybrid grains take the constrained velocities
//!    back, by the run's [`GrainTransfer`].
//!
//! The stage owns the scratch of one step (the saved positions by grain id, the raster, the
//! carried impulse) and, for [`GrainTransfer::Flip`], the node accelerations the coupling
//! gave the last step. Maps by grain id and node are only looked up; everything that comes
//! out runs over the grains in storage order or over the raster in node order, so the result
//! does not depend on hashing.

use crate::coupling::{self, NodeMomentum};
use crate::pipeline::DemPipeline;
use crate::space::Space;
use crate::state::DemState;
use grains_grid::{Grid, Kernel};
use std::collections::HashMap;

/// How a hybrid grain takes the coupler's node velocities back (Alg. 5–6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrainTransfer {
    /// Alg. 5–6 as written: the grain's velocity becomes the velocity interpolated from the
    /// coupler's node velocities (its own raster's elsewhere), its spin that field's, and it
    /// moves from its saved position with that velocity.
    Pic,
    /// The grain keeps its substepped velocity and position and adds the coupling's change of
    /// the node velocities interpolated to it (times dt / 2 for the position); where the
    /// material is quasi-static its spin is the material's, elsewhere its own. The substeps
    /// carry the last step's coupling force of the nodes around each grain, which the raster
    /// the coupler gets leaves out.
    Flip,
}

/// What stays fixed for a run: the MPM's grid and kernel, and the transfer back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CouplingParams {
    /// The MPM's grid and kernel: the raster uses its nodes and weights (Alg. 4).
    pub grid: Grid,
    pub kernel: Kernel,
    pub transfer: GrainTransfer,
    /// With [`GrainTransfer::Flip`]: the inertial number I_c below which a band grain turns
    /// with the material (0: never).
    pub quasi_static: f64,
    /// |g| [m/s²] of that inertial number, I² = γ̇² d / |g|.
    pub gravity: f64,
}

/// The DEM half of a coupled macro-step: its parameters and the scratch of one step.
#[derive(Clone, Debug)]
pub struct CoupledStep<S: Space> {
    pub params: CouplingParams,
    /// The step in progress: the hybrid grains by id with their positions at its start.
    hybrid: HashMap<u64, S::V>,
    /// The raster of their predicted momentum, by node index.
    raster: Vec<NodeMomentum<S>>,
    /// With [`GrainTransfer::Flip`]: per node of `raster`, the impulse of the coupling forces
    /// the grains carried through the substeps (`external`), which the coupler must not see: it
    /// is taken out of the raster it is sent.
    carried: Vec<S::V>,
    /// With [`GrainTransfer::Flip`]: each constrained node's coupling acceleration of the last
    /// step [m/s²].
    accel: HashMap<u64, S::V>,
}

impl<S: Space> CoupledStep<S> {
    pub fn new(params: CouplingParams) -> Self {
        CoupledStep {
            params,
            hybrid: HashMap::new(),
            raster: Vec::new(),
            carried: Vec::new(),
            accel: HashMap::new(),
        }
    }

    /// Alg. 2 and 4 in one call: [`CoupledStep::advance`], then [`CoupledStep::rasterize`].
    pub fn predict(&mut self, state: &mut DemState<S>, pipeline: &mut DemPipeline<S>, dt: f64, substeps: usize) -> &[NodeMomentum<S>] {
        self.advance(state, pipeline, dt, substeps);
        self.rasterize(state, dt)
    }

    /// Yue 2018 Alg. 2: saves the hybrid grains' positions and runs `substeps` steps of
    /// dt / substeps (hybrid grains with mass and springs scaled by 1 − w).
    ///
    /// With [`GrainTransfer::Flip`] the substeps also push every hybrid grain with the last
    /// step's coupling acceleration of the nodes around it: the coupling force then acts on the
    /// grains while their contacts do, rather than as a kick after them (kicks a step apart
    /// shake a resting band until it creeps: 0.23 grain diameters in 0.5 s), and the coupler
    /// only corrects what changed.
    pub fn advance(&mut self, state: &mut DemState<S>, pipeline: &mut DemPipeline<S>, dt: f64, substeps: usize) {
        let (grid, kernel) = (&self.params.grid, self.params.kernel);
        let g = &state.grains;
        // Frozen grains never move: never hybrid.
        self.hybrid = (0..g.len())
            .filter(|&i| g.scale[i] < 1.0 && !g.frozen[i])
            .map(|i| (g.id[i], g.x[i]))
            .collect();
        if self.params.transfer == GrainTransfer::Flip {
            // Nodes the coupler did not constrain last step push nothing.
            let g = &mut state.grains;
            let accel = |n: u64| Some(self.accel.get(&n).copied().unwrap_or_default());
            for i in 0..g.len() {
                if self.hybrid.contains_key(&g.id[i]) {
                    let (a, _) = coupling::interpolate::<S>(grid, kernel, g.x[i], accel);
                    g.external[i] = a * (g.mass[i] * g.scale[i]);
                }
            }
        }
        pipeline.run(state, dt / substeps as f64, substeps);
    }

    /// Yue 2018 Alg. 4: the hybrid grains' weighted mass (1 − w) m and predicted momentum,
    /// at their saved positions, onto the MPM grid with its weights, by node index (call after
    /// [`CoupledStep::advance`] of the same step of length `dt`). With
    /// [`GrainTransfer::Flip`] also the impulse of the push they carried, on the same nodes
    /// with the same weights.
    pub fn rasterize(&mut self, state: &DemState<S>, dt: f64) -> &[NodeMomentum<S>] {
        let (grid, kernel) = (&self.params.grid, self.params.kernel);
        let g = &state.grains;
        let saved: Vec<S::V> = (0..g.len()).map(|i| self.hybrid.get(&g.id[i]).copied().unwrap_or(g.x[i])).collect();
        let mass: Vec<f64> = (0..g.len()).map(|i| g.mass[i] * g.scale[i]).collect();
        let hybrid = &self.hybrid;
        let include = |i: usize| hybrid.contains_key(&g.id[i]);
        self.raster = coupling::rasterize::<S>(grid, kernel, &saved, &g.v, &mass, include);
        self.carried.clear();
        if self.params.transfer == GrainTransfer::Flip {
            // The push's impulse per node, Σ w F dt, with the raster's weights and nodes.
            let impulse: Vec<S::V> = (0..g.len())
                .map(|i| g.external[i] * (dt / mass[i].max(f64::MIN_POSITIVE)))
                .collect();
            let r = coupling::rasterize::<S>(grid, kernel, &saved, &impulse, &mass, include);
            self.carried = r.into_iter().map(|n| n.momentum).collect();
        }
        &self.raster
    }

    /// The raster of the step in progress (empty before the first coupled step), by node
    /// index.
    pub fn raster(&self) -> &[NodeMomentum<S>] {
        &self.raster
    }

    /// Node `k` of the raster without the impulse of the carried coupling push: what the
    /// grains would have without any coupling, which is what the coupler's eq. 31 needs.
    pub fn uncoupled_momentum(&self, k: usize) -> S::V {
        self.raster[k].momentum - self.carried.get(k).copied().unwrap_or_default()
    }

    /// Yue 2018 Alg. 5 and 6, with the coupler's velocities `constrained` (node, velocity) of
    /// the step of length `dt`; nothing happens without hybrid grains.
    ///
    /// With [`GrainTransfer::Flip`] every hybrid grain adds to its substepped velocity the
    /// coupling's change of the node velocities (constrained minus its own raster's; on nodes
    /// the coupler left alone, its uncoupled minus its own: the push is taken back)
    /// interpolated at its saved position, moves by that change times dt / 2 and takes the spin
    /// of the constrained field where the material is quasi-static; each node's whole coupling
    /// acceleration (constrained velocity minus the uncoupled one, over dt) is kept for the
    /// next step's substeps. With [`GrainTransfer::Pic`] it takes the velocity interpolated
    /// from the coupler's node velocities (its own raster's elsewhere) and the spin of that
    /// field, and moves from its saved position with that velocity. The other grains keep
    /// their substepped state.
    pub fn finish(
        &mut self,
        state: &mut DemState<S>,
        pipeline: &mut DemPipeline<S>,
        constrained: impl IntoIterator<Item = (u64, S::V)>,
        dt: f64,
    ) {
        if self.hybrid.is_empty() {
            return;
        }
        let (grid, kernel) = (&self.params.grid, self.params.kernel);
        let constrained: HashMap<u64, S::V> = constrained.into_iter().collect();
        let own: HashMap<u64, S::V> = self.raster.iter().map(|r| (r.node, r.momentum * (1.0 / r.mass))).collect();
        let node_velocity = |n: u64| constrained.get(&n).or_else(|| own.get(&n)).copied();
        let flip = self.params.transfer == GrainTransfer::Flip;
        // Each node's velocity without any coupling force (its own without the push).
        let free: HashMap<u64, S::V> = self
            .raster
            .iter()
            .enumerate()
            .map(|(k, r)| (r.node, self.uncoupled_momentum(k) * (1.0 / r.mass)))
            .collect();
        if flip {
            // The whole coupling acceleration of each node: its constrained velocity minus
            // the velocity it would have had without any coupling force.
            self.accel = free
                .iter()
                .filter_map(|(n, f)| constrained.get(n).map(|v| (*n, (*v - *f) * (1.0 / dt))))
                .collect();
        }
        let g = &mut state.grains;
        // The coupling's change of each node velocity. Where the coupler did not act the
        // node goes back to its uncoupled velocity: the part of the push spread there is
        // taken back.
        let change = |n: u64| {
            let o = own.get(&n).copied().unwrap_or_default();
            Some(constrained.get(&n).or_else(|| free.get(&n)).map_or(S::V::default(), |c| *c - o))
        };
        for i in 0..g.len() {
            if let Some(&x0) = self.hybrid.get(&g.id[i]) {
                if flip {
                    // The rest of the coupling force, spread evenly over the step, changes
                    // the velocity by dv and the position by dv dt / 2.
                    let (dv, _) = coupling::interpolate::<S>(grid, kernel, x0, change);
                    g.v[i] += dv;
                    g.x[i] += dv * (0.5 * dt);
                    // Its spin is not coupled otherwise: where the material is
                    // quasi-static the grain turns with it (held up by the coupling, it
                    // would be spun up by the sliding of its contacts: 35 rad/s in a
                    // resting layer, which creeps 0.3 d in 0.5 s); where it flows the grain
                    // rolls (turning with the material there, a = 0.5 columns stop at
                    // 2/3 of the DEM's runout). I² = γ̇² d / |g| < I_c², without a division.
                    let (_, grad) = coupling::interpolate::<S>(grid, kernel, x0, node_velocity);
                    let rate = grad.shear_rate(S::DIM);
                    let d = 2.0 * g.radius[i];
                    if rate * rate * d < self.params.quasi_static * self.params.quasi_static * self.params.gravity {
                        g.omega[i] = grad.spin::<S>();
                    }
                } else {
                    let (v, grad) = coupling::interpolate::<S>(grid, kernel, x0, node_velocity);
                    g.v[i] = v;
                    g.omega[i] = grad.spin::<S>();
                    g.x[i] = x0 + v * dt;
                }
            }
        }
        pipeline.invalidate();
    }
}
