//! The explicit MPM step, split in two phases at the coupling point (Yue 2018 App. C,
//! Alg. 20/21):
//!
//! - [`MpmPipeline::phase1`]: points → grid mass and momentum (P2G), Kirchhoff stress of
//!   every point, internal and gravity forces on the nodes, grid velocities updated
//!   (v_i = (p_i + dt f_i) / m_i), wall conditions. The coupler may overwrite grid velocities
//!   after this.
//! - [`MpmPipeline::phase2`]: grid → points (G2P) with a PIC/FLIP blend, velocity gradient,
//!   elastic strain update b^e ← (I + dt ∇v) b^e (I + dt ∇v)ᵀ with the return mapping,
//!   advection.
//!
//! The grid is dense over the domain in this first version; masses and stresses of a point
//! are scaled by its hybrid weight.

use crate::constitutive::plasticity_drucker_prager::{DruckerPragerYue, kirchhoff, return_map};
use crate::matrix::{Matrix, MpmSpace};
use grains_grid::shape::for_each_node;
use grains_grid::{Grid, Kernel, Space, Vector};

/// Material points (structure of arrays).
#[derive(Clone, Debug, Default)]
pub struct Points<S: MpmSpace> {
    pub x: Vec<S::V>,
    pub v: Vec<S::V>,
    /// Mass [kg] (2D: per metre).
    pub mass: Vec<f64>,
    /// Reference volume [m³] (2D: m² per metre).
    pub volume: Vec<f64>,
    /// Elastic left Cauchy–Green strain b^e.
    pub b_e: Vec<S::M>,
    /// Hybrid weight w of mass and stress (1 outside a hybrid zone).
    pub weight: Vec<f64>,
    /// APIC affine velocity C (zero unless the transfer is APIC).
    pub affine: Vec<S::M>,
}

impl<S: MpmSpace> Points<S> {
    pub fn push(&mut self, x: S::V, mass: f64, volume: f64) {
        self.x.push(x);
        self.v.push(S::V::default());
        self.mass.push(mass);
        self.volume.push(volume);
        self.b_e.push(S::M::identity());
        self.weight.push(1.0);
        self.affine.push(S::M::identity() * 0.0);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

/// Grid-to-point velocity transfer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transfer {
    /// PIC/FLIP blend with FLIP share β (1 = pure FLIP, 0 = PIC).
    Flip(f64),
    /// Affine particle-in-cell (Jiang et al. 2015): conserves angular momentum.
    Apic,
}

/// Parameters of a step.
#[derive(Clone, Copy, Debug)]
pub struct MpmParams<S: Space> {
    pub grid: Grid,
    pub kernel: Kernel,
    pub material: DruckerPragerYue,
    pub gravity: S::V,
    /// How velocities go back to the points.
    pub transfer: Transfer,
    /// Plastic flow on (Drucker–Prager return mapping and free flow under extension); off,
    /// the same elasticity without yield (for elastic checks).
    pub plastic: bool,
    /// Nodes within this many cells of a domain face are walls: their velocity component
    /// into the face is removed (slip).
    pub wall_cells: i64,
}

/// Grid scratch of the pipeline.
#[derive(Clone, Debug, Default)]
pub struct MpmPipeline<S: MpmSpace> {
    pub mass: Vec<f64>,
    pub momentum: Vec<S::V>,
    /// Grid velocity after phase 1 (possibly overwritten by the coupler).
    pub velocity: Vec<S::V>,
    /// Grid velocity before the force update (for FLIP).
    velocity_old: Vec<S::V>,
}

impl<S: MpmSpace> MpmPipeline<S> {
    pub fn new() -> Self {
        MpmPipeline {
            mass: Vec::new(),
            momentum: Vec::new(),
            velocity: Vec::new(),
            velocity_old: Vec::new(),
        }
    }

    /// Phase 1 (Alg. 20): P2G, stress, forces, grid velocities.
    pub fn phase1(&mut self, pts: &Points<S>, params: &MpmParams<S>, dt: f64) {
        let n_nodes = (params.grid.nodes[0] * params.grid.nodes[1] * params.grid.nodes[2]) as usize;
        self.mass.clear();
        self.mass.resize(n_nodes, 0.0);
        self.momentum.clear();
        self.momentum.resize(n_nodes, S::V::default());
        let mut force = vec![S::V::default(); n_nodes];
        for p in 0..pts.len() {
            let (m, w) = (pts.mass[p] * pts.weight[p], pts.weight[p]);
            // Kirchhoff stress with the reference volume: f_i = −Σ V0 τ ∇w_ip.
            let tau = kirchhoff(&params.material, &pts.b_e[p]) * (pts.volume[p] * w);
            let (v, xp, c) = (pts.v[p], pts.x[p], pts.affine[p]);
            let apic = params.transfer == Transfer::Apic;
            for_each_node::<S>(&params.grid, params.kernel, xp, |node, wip, grad| {
                let i = node as usize;
                self.mass[i] += m * wip;
                let vi = if apic {
                    v + S::mul_vec(&c, S::from_array(params.grid.position(params.grid.ijk(node))) - xp)
                } else {
                    v
                };
                self.momentum[i] += vi * (m * wip);
                force[i] -= S::mul_vec(&tau, grad);
            });
        }
        self.velocity.clear();
        self.velocity.resize(n_nodes, S::V::default());
        self.velocity_old.clear();
        self.velocity_old.resize(n_nodes, S::V::default());
        for (i, f) in force.iter().enumerate() {
            let m = self.mass[i];
            if m > 0.0 {
                self.velocity_old[i] = self.momentum[i] * (1.0 / m);
                let v = (self.momentum[i] + *f * dt) * (1.0 / m) + params.gravity * dt;
                self.velocity[i] = self.apply_walls(params, i as u64, v);
            }
        }
    }

    fn apply_walls(&self, params: &MpmParams<S>, node: u64, v: S::V) -> S::V {
        if params.wall_cells <= 0 {
            return v;
        }
        let ijk = params.grid.ijk(node);
        let mut a = S::to_array(v);
        for k in 0..S::DIM {
            let n = params.grid.nodes[k] as i64;
            if (ijk[k] < params.wall_cells && a[k] < 0.0) || (ijk[k] >= n - params.wall_cells && a[k] > 0.0) {
                a[k] = 0.0;
            }
        }
        S::from_array(a)
    }

    /// Phase 2 (Alg. 21): G2P with the PIC/FLIP blend, strain update and return mapping,
    /// advection, from the (possibly constrained) grid velocities.
    pub fn phase2(&mut self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) {
        for p in 0..pts.len() {
            let mut v_pic = S::V::default();
            let mut dv = S::V::default();
            let zero = S::outer(S::V::default(), S::V::default());
            let (mut grad_v, mut b, mut d) = (zero, zero, zero);
            let xp = pts.x[p];
            for_each_node::<S>(&params.grid, params.kernel, xp, |node, wip, grad| {
                let i = node as usize;
                v_pic += self.velocity[i] * wip;
                dv += (self.velocity[i] - self.velocity_old[i]) * wip;
                grad_v = grad_v + S::outer(self.velocity[i], grad);
                if params.transfer == Transfer::Apic {
                    let r = S::from_array(params.grid.position(params.grid.ijk(node))) - xp;
                    b = b + S::outer(self.velocity[i], r) * wip;
                    d = d + S::outer(r, r) * wip;
                }
            });
            match params.transfer {
                Transfer::Flip(beta) => pts.v[p] = (pts.v[p] + dv) * beta + v_pic * (1.0 - beta),
                Transfer::Apic => {
                    pts.v[p] = v_pic;
                    // C = B D⁻¹ (D is h²/4 I for quadratic B-splines; computed for GIMP).
                    pts.affine[p] = S::mul(&b, &d.inverse());
                }
            }
            let step = S::M::identity() + grad_v * dt;
            let b = S::mul(&S::mul(&step, &pts.b_e[p]), &S::transpose(&step));
            pts.b_e[p] = if params.plastic { return_map(&params.material, &b) } else { b };
            pts.x[p] += v_pic * dt;
        }
    }

    /// Both phases (an MPM-only step).
    pub fn step(&mut self, pts: &mut Points<S>, params: &MpmParams<S>, dt: f64) {
        self.phase1(pts, params, dt);
        self.phase2(pts, params, dt);
    }

    /// Total mass and momentum on the grid after phase 1's P2G [kg, kg m/s].
    pub fn grid_totals(&self) -> (f64, S::V) {
        (self.mass.iter().sum(), self.momentum.iter().fold(S::V::default(), |a, &b| a + b))
    }
}

/// CFL time step: dt ≤ CFL · h / c with the elastic P-wave speed c = √((κ + 4μ/3 … ) / ρ)
/// taken as √((κ + μ) / ρ) (the uniaxial modulus of the model) [s].
pub fn cfl_time_step(material: &DruckerPragerYue, density: f64, h: f64) -> f64 {
    h / ((material.bulk + material.shear) / density).sqrt()
}

/// Kinetic energy [J] and momentum of the points.
pub fn point_totals<S: MpmSpace>(pts: &Points<S>) -> (f64, S::V) {
    let mut ke = 0.0;
    let mut p = S::V::default();
    for k in 0..pts.len() {
        ke += 0.5 * pts.mass[k] * pts.v[k].length_squared();
        p += pts.v[k] * pts.mass[k];
    }
    (ke, p)
}
