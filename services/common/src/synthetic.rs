//! SYNTHETIC — the solver of `[synthetic]` test scenes, and nothing else.
//!
//! Issue 2 proves the runtime before the physics exists: this solver publishes rasters of a
//! chosen size whose content is a deterministic function of (seed, role, step, node), and
//! checks what the coupler sends back: the payload checksum (in the session), the node
//! ranges and order, and on every 997th shared node the exact value of the mass-weighted
//! velocity it recomputes from both sides' synthetic content. A scene with `[[body]]` tables
//! can never reach this module: the scene schema refuses to mix the two.

use crate::solver::{Solver, SolverReport, StepWindow};
use anyhow::{bail, ensure};
use grains_grid::rng::splitmix64;
use grains_protocol::Role;
use grains_protocol::scene::{Synthetic, SyntheticContent};
use grains_protocol::wire::{NodeVelocity, RasterNode};

/// Deterministic synthetic rasters for one role.
pub struct SyntheticSolver {
    role: Role,
    seed: u64,
    dim: usize,
    params: Synthetic,
    n: usize,
    report: SolverReport,
}

fn unit(x: u64) -> f64 {
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// First node and base node count of a role's raster.
fn layout(params: &Synthetic, role: Role) -> (u64, u64) {
    match role {
        Role::Dem => (0, params.dem_nodes),
        _ => {
            let shared = (params.overlap * params.dem_nodes.min(params.mpm_nodes) as f64).round() as u64;
            (params.dem_nodes - shared, params.mpm_nodes)
        }
    }
}

/// Raster length of `role` at `step`: the base count shrunk by up to `vary`.
pub fn raster_len(params: &Synthetic, seed: u64, role: Role, step: u64) -> usize {
    let (_, base) = layout(params, role);
    let shrink = (params.vary * base as f64 * unit(splitmix64(seed ^ splitmix64(step ^ ((role as u64) << 56))))) as u64;
    (base - shrink).max(1) as usize
}

/// Mass and momentum of one node of `role`'s raster at `step`.
#[inline]
pub fn node_values(content: SyntheticContent, seed: u64, role: Role, step: u64, node: u64, dim: usize) -> (f64, [f64; 3]) {
    if content == SyntheticContent::Plain {
        let mass = (1 + (node + role as u64) % 7) as f64;
        let mut p = [0.0; 3];
        p[0] = node as f64 * 1e-6;
        p[1] = step as f64 - mass;
        return (mass, p);
    }
    let h = splitmix64(seed ^ splitmix64(node ^ splitmix64(step ^ ((role as u64) << 56))));
    let mass = 1.0 + unit(h);
    let mut p = [0.0; 3];
    let mut x = h;
    for c in p.iter_mut().take(dim) {
        x = splitmix64(x);
        *c = mass * (2.0 * unit(x) - 1.0);
    }
    (mass, p)
}

impl SyntheticSolver {
    pub fn new(role: Role, seed: u64, dim: usize, params: Synthetic) -> Self {
        SyntheticSolver {
            role,
            seed,
            dim,
            params,
            n: 0,
            report: SolverReport::default(),
        }
    }

    fn peer(&self) -> Role {
        if self.role == Role::Dem { Role::Mpm } else { Role::Dem }
    }
}

impl Solver for SyntheticSolver {
    fn predict(&mut self, window: &StepWindow) -> anyhow::Result<usize> {
        self.n = raster_len(&self.params, self.seed, self.role, window.step);
        Ok(self.n)
    }

    fn write_raster(&mut self, window: &StepWindow, out: &mut [RasterNode]) {
        let (first, _) = layout(&self.params, self.role);
        let mut r = SolverReport {
            n_nodes: out.len() as u64,
            ..SolverReport::default()
        };
        for (j, slot) in out.iter_mut().enumerate() {
            let node = first + j as u64;
            let (mass, momentum) = node_values(self.params.content, self.seed, self.role, window.step, node, self.dim);
            *slot = RasterNode { node, mass, momentum };
            r.mass += mass;
            let mut p2 = 0.0;
            for (total, p) in r.momentum.iter_mut().zip(momentum) {
                *total += p;
                p2 += p * p;
            }
            r.kinetic_energy += 0.5 * p2 / mass;
        }
        self.report = r;
    }

    fn finish(&mut self, window: &StepWindow, velocities: &[NodeVelocity]) -> anyhow::Result<()> {
        let (first, _) = layout(&self.params, self.role);
        let (peer_first, _) = layout(&self.params, self.peer());
        let peer_n = raster_len(&self.params, self.seed, self.peer(), window.step) as u64;
        let lo = first.max(peer_first);
        let hi = (first + self.n as u64).min(peer_first + peer_n);
        let expected = hi.saturating_sub(lo) as usize;
        ensure!(
            velocities.len() == expected,
            "synthetic check: step {}: {} constrained velocities, expected {expected} (the nodes both rasters share)",
            window.step,
            velocities.len()
        );
        for (j, v) in velocities.iter().enumerate() {
            if v.node != lo + j as u64 {
                bail!(
                    "synthetic check: step {}: velocity {j} is for node {}, expected node {}",
                    window.step,
                    v.node,
                    lo + j as u64
                );
            }
            if j % 997 == 0 {
                let (ma, pa) = node_values(self.params.content, self.seed, Role::Dem, window.step, v.node, self.dim);
                let (mb, pb) = node_values(self.params.content, self.seed, Role::Mpm, window.step, v.node, self.dim);
                let m = ma + mb;
                for k in 0..3 {
                    let want = (pa[k] + pb[k]) / m;
                    if v.velocity[k] != want {
                        bail!(
                            "synthetic check: step {}: node {} velocity[{k}] = {}, expected {want}",
                            window.step,
                            v.node,
                            v.velocity[k]
                        );
                    }
                }
            }
        }
        self.report.n_items = velocities.len() as u64;
        Ok(())
    }

    fn step_alone(&mut self, window: &StepWindow) -> anyhow::Result<()> {
        // Alone, the synthetic solver still produces its raster content (into a scratch
        // buffer), so that a single-participant run does real work per step.
        let n = self.predict(window)?;
        let mut scratch = vec![RasterNode::default(); n];
        self.write_raster(window, &mut scratch);
        Ok(())
    }

    fn report(&self) -> SolverReport {
        self.report
    }
}
