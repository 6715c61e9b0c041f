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
//! The stage owns the scratch of one step (the hybrid grains' storage indices and saved
//! positions, the raster sorted by node, the carried impulse) and, for
//! [`GrainTransfer::Flip`], the node accelerations the coupling gave the last step. The
//! substeps keep the grains' storage order (the pipeline re-sorts between macro-steps only),
//! so grains are addressed by index; nodes are found by binary search in node-sorted lists.
//! Everything runs over the grains in storage order or over the raster in node order, so the
//! result does not depend on threads.

use crate::coupling::{NodeMomentum, Stencils};
use crate::pipeline::DemPipeline;
use crate::space::Space;
use crate::state::DemState;
use grains_grid::{Grid, Kernel, Vector};

/// How a hybrid grain takes the coupler's node velocities back (Alg. 5–6).
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// Yue 2018 §3.7's "in the same manner as MPM points": the grain's substepped velocity
    /// plus the coupling's change (FLIP) blended with the interpolated velocity (PIC) at this
    /// FLIP share β, then it moves from its saved position with that velocity (Alg. 6); its
    /// spin is its contacts'.
    Points(f64),
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
    /// A confining fluid around the material ([`crate::fluid`]): its load on every grain is
    /// set at the start of each step and held over the substeps, the hybrid grains' at their
    /// scale (the points take the rest of a shared cell's, at their weight).
    pub fluid: Option<crate::fluid::Fluid>,
}

/// The DEM half of a coupled macro-step: its parameters and the scratch of one step.
#[derive(Clone, Debug)]
pub struct CoupledStep<S: Space> {
    pub params: CouplingParams,
    /// The step in progress: storage indices of the hybrid grains, ascending...
    hybrid: Vec<u32>,
    /// ... and their positions at its start.
    saved: Vec<S::V>,
    /// The grid nodes around the saved positions, with weights: every transfer of the step
    /// uses them (evaluated once, nodes addressed by slot).
    stencils: Stencils<S>,
    /// The raster of their predicted momentum, one entry per slot of `stencils` (node order).
    raster: Vec<NodeMomentum<S>>,
    /// With [`GrainTransfer::Flip`]: per node of `raster`, the impulse of the coupling forces
    /// the grains carried through the substeps (`external`), which the coupler must not see: it
    /// is taken out of the raster it is sent.
    carried: Vec<S::V>,
    /// With [`GrainTransfer::Flip`]: each constrained node's coupling acceleration of the last
    /// step [m/s²], sorted by node.
    accel: Vec<(u64, S::V)>,
    /// With [`GrainTransfer::Flip`]: the coupling's push on each hybrid grain this step (of
    /// their `external` load, the part the coupler must not see; the fluid's it must).
    push: Vec<S::V>,
}

/// The value of `node` in a node-sorted list.
fn lookup<T: Copy>(list: &[(u64, T)], node: u64) -> Option<T> {
    list.binary_search_by_key(&node, |e| e.0).ok().map(|k| list[k].1)
}

impl<S: Space> CoupledStep<S> {
    pub fn new(params: CouplingParams) -> Self {
        CoupledStep {
            params,
            hybrid: Vec::new(),
            saved: Vec::new(),
            stencils: Stencils::default(),
            raster: Vec::new(),
            carried: Vec::new(),
            accel: Vec::new(),
            push: Vec::new(),
        }
    }

    /// What one step hands the next (the flip transfer's node accelerations), for a
    /// checkpoint; the rest is the scratch of a step.
    pub fn carry(&self) -> &[(u64, S::V)] {
        &self.accel
    }

    pub fn restore(&mut self, accel: Vec<(u64, S::V)>) {
        self.accel = accel;
    }

    /// Alg. 2 and 4 in one call: [`CoupledStep::advance`], then [`CoupledStep::rasterize`].
    pub fn predict(&mut self, state: &mut DemState<S>, pipeline: &mut DemPipeline<S>, dt: f64, substeps: usize) -> &[NodeMomentum<S>] {
        self.advance(state, pipeline, dt, substeps);
        self.rasterize(state, dt)
    }

    /// Yue 2018 Alg. 2: saves the hybrid grains' positions and runs `substeps` steps of
    /// dt / substeps (hybrid grains with mass and springs scaled by 1 − w), keeping the
    /// grains' storage order.
    ///
    /// With [`GrainTransfer::Flip`] the substeps also push every hybrid grain with the last
    /// step's coupling acceleration of the nodes around it: the coupling force then acts on the
    /// grains while their contacts do, rather than as a kick after them (kicks a step apart
    /// shake a resting band until it creeps: 0.23 grain diameters in 0.5 s), and the coupler
    /// only corrects what changed.
    pub fn advance(&mut self, state: &mut DemState<S>, pipeline: &mut DemPipeline<S>, dt: f64, substeps: usize) {
        let (grid, kernel) = (&self.params.grid, self.params.kernel);
        // A re-sort due happens now, before the grains are taken by index.
        pipeline.settle(state);
        let g = &mut state.grains;
        // Frozen grains never move: never hybrid.
        self.hybrid.clear();
        self.hybrid
            .extend((0..g.len()).filter(|&i| g.scale[i] < 1.0 && !g.frozen[i]).map(|i| i as u32));
        self.saved.clear();
        self.saved.extend(self.hybrid.iter().map(|&i| g.x[i as usize]));
        self.stencils.build(grid, kernel, &self.saved);
        if let Some(fluid) = &self.params.fluid {
            g.external = crate::fluid::forces(g, fluid).0;
        }
        self.push.clear();
        if self.params.transfer == GrainTransfer::Flip {
            // Each slot's acceleration of the last step; nodes the coupler did not constrain
            // then push nothing.
            let accel: Vec<S::V> = self
                .stencils
                .nodes
                .iter()
                .map(|&n| lookup(&self.accel, n).unwrap_or_default())
                .collect();
            for (k, &i) in self.hybrid.iter().enumerate() {
                let i = i as usize;
                let (a, _) = self.stencils.interpolate(k, |slot| Some(accel[slot]));
                let push = a * (g.mass[i] * g.scale[i]);
                self.push.push(push);
                g.external[i] = match self.params.fluid {
                    Some(_) => g.external[i] + push,
                    None => push,
                };
            }
        }
        if self.hybrid.is_empty() {
            // Nothing is taken by index: the pure DEM's steps, re-sorts where they fall due
            // (an all-discrete hybrid is then the DEM, byte for byte).
            pipeline.run(state, dt / substeps as f64, substeps);
        } else {
            pipeline.run_in_order(state, dt / substeps as f64, substeps);
        }
    }

    /// Yue 2018 Alg. 4: the hybrid grains' weighted mass (1 − w) m and predicted momentum,
    /// at their saved positions, onto the MPM grid with its weights, sorted by node (call
    /// after [`CoupledStep::advance`] of the same step of length `dt`). With
    /// [`GrainTransfer::Flip`] also the impulse of the push they carried, on the same nodes
    /// with the same weights.
    pub fn rasterize(&mut self, state: &DemState<S>, dt: f64) -> &[NodeMomentum<S>] {
        let g = &state.grains;
        let flip = self.params.transfer == GrainTransfer::Flip;
        let items = self.hybrid.iter().enumerate().map(|(k, &i)| {
            let i = i as usize;
            // The push's impulse F dt, rasterized as Σ w F dt.
            let impulse = if flip { self.push[k] * dt } else { S::V::default() };
            (g.mass[i] * g.scale[i], g.v[i], impulse)
        });
        let (raster, carried) = self.stencils.rasterize(items);
        self.raster = raster;
        self.carried = if flip { carried } else { Vec::new() };
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
    /// their substepped state. [`GrainTransfer::Points`] blends the two velocities as the
    /// MPM's points do and moves the grain from its saved position with the blend.
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
        let flip = self.params.transfer == GrainTransfer::Flip;
        // Per slot of the raster (node order): its own velocity, its velocity without any
        // coupling force (its own without the push), and the coupler's if it constrained it.
        let mut given: Vec<(u64, S::V)> = constrained.into_iter().collect();
        given.sort_unstable_by_key(|e| e.0);
        let own: Vec<S::V> = self.raster.iter().map(|r| r.momentum * (1.0 / r.mass)).collect();
        let free: Vec<S::V> = (0..self.raster.len())
            .map(|k| self.uncoupled_momentum(k) * (1.0 / self.raster[k].mass))
            .collect();
        let fixed: Vec<Option<S::V>> = self.raster.iter().map(|r| lookup(&given, r.node)).collect();
        if flip {
            // The whole coupling acceleration of each node: its constrained velocity minus
            // the velocity it would have had without any coupling force.
            self.accel = (0..self.raster.len())
                .filter_map(|k| fixed[k].map(|v| (self.raster[k].node, (v - free[k]) * (1.0 / dt))))
                .collect();
        }
        let node_velocity = |k: usize| Some(fixed[k].unwrap_or(own[k]));
        // The coupling's change of each node velocity. Where the coupler did not act the
        // node goes back to its uncoupled velocity: the part of the push spread there is
        // taken back.
        let change = |k: usize| Some(fixed[k].unwrap_or(free[k]) - own[k]);
        let (lo, hi, period) = state.params.domain.wrap_box::<S>();
        let g = &mut state.grains;
        for (k, (&i, &x0)) in self.hybrid.iter().zip(&self.saved).enumerate() {
            let i = i as usize;
            if flip {
                // The rest of the coupling force, spread evenly over the step, changes the
                // velocity by dv and the position by dv dt / 2.
                let (dv, _) = self.stencils.interpolate(k, change);
                g.v[i] += dv;
                g.x[i] += dv * (0.5 * dt);
                // Its spin is not coupled otherwise: where the material is quasi-static the
                // grain turns with it (held up by the coupling, it would be spun up by the
                // sliding of its contacts: 35 rad/s in a resting layer, which creeps 0.3 d in
                // 0.5 s); where it flows the grain rolls (turning with the material there,
                // a = 0.5 columns stop at 2/3 of the DEM's runout). I² = γ̇² d / |g| < I_c²,
                // without a division.
                let (_, grad) = self.stencils.interpolate(k, node_velocity);
                let rate = grad.shear_rate(S::DIM);
                let d = 2.0 * g.radius[i];
                if rate * rate * d < self.params.quasi_static * self.params.quasi_static * self.params.gravity {
                    g.omega[i] = grad.spin::<S>();
                }
            } else if let GrainTransfer::Points(beta) = self.params.transfer {
                let (v_pic, _) = self.stencils.interpolate(k, node_velocity);
                let (dv, _) = self.stencils.interpolate(k, change);
                g.v[i] = (g.v[i] + dv) * beta + v_pic * (1.0 - beta);
                g.x[i] = x0 + g.v[i] * dt;
            } else {
                let (v, grad) = self.stencils.interpolate(k, node_velocity);
                g.v[i] = v;
                g.omega[i] = grad.spin::<S>();
                g.x[i] = x0 + v * dt;
            }
            g.x[i] = g.x[i].wrap(lo, hi, period);
        }
        pipeline.moved();
    }
}
