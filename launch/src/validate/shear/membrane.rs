//! App. B of Chen 2021: the flexible membrane that holds a biaxial specimen's sides at the
//! confining pressure, as chains of mass–spring nodes among the grains.
//!
//! The nodes are grains of the sample's contact law, a fifth of a diameter in radius and half
//! a diameter apart (a grain cannot pass between two of them; they touch only if the membrane
//! shortens by a fifth), each of a grain's mass so that the DEM's step holds. Each step every
//! free node takes the pressure over half of each of its two segments along their normal (the
//! pressure integrated over the chain) and the springs' tension along the segments. The end
//! nodes are fixed to the platens.

use grains_dem::pipeline::DemPipeline;
use grains_dem::space::{D2, Space};
use grains_dem::state::{DemState, Grains};

/// App. B, Table B.1: spring [N/m] and damping [N s/m] of the membrane's segments (Chen's
/// forces per grain are ours: its k_n is ours and its pressure over 1-cm disks is ours over
/// unit-thick ones).
pub(super) const K_MS: f64 = 1.0e4;
pub(super) const GAMMA_MS: f64 = 1.0;
/// The membrane's nodes: radius and spacing [D50].
pub(super) const NODE_RADIUS_D: f64 = 0.2;
pub(super) const NODE_SPACING_D: f64 = 0.5;
/// Ids of the membrane's nodes: left chain from MEMBRANE, right chain from MEMBRANE + CHAIN,
/// bottom to top.
pub(super) const MEMBRANE: u64 = 1 << 40;
pub(super) const CHAIN: u64 = 1 << 20;

/// A membrane on both sides of a box sample: the chains' node ids, bottom to top, and the
/// pressure, spring and rest length it holds.
pub(super) struct Membrane {
    pub chains: [Vec<u64>; 2],
    pub pressure: f64,
    pub rest: f64,
}

impl Membrane {
    /// Replaces the side walls (0 and 1) of a consolidated box sample (`box_sample`'s walls)
    /// by membranes at `pressure`, their nodes touching the outermost grains' faces (the walls'
    /// planes) from the bottom wall to the top; the end nodes frozen. The walls left are the
    /// bottom (0) and the top (1).
    pub fn wrap(state: &mut DemState<D2>, pressure: f64, diameter: f64, density: f64) -> Membrane {
        let wall_x = |k: usize| D2::to_array(plane_point(state, k))[0];
        let (left, right) = (wall_x(0), wall_x(1));
        let (bottom, top) = (D2::to_array(plane_point(state, 2))[1], D2::to_array(plane_point(state, 3))[1]);
        state.walls.drain(0..2);
        let r = NODE_RADIUS_D * diameter;
        // The end nodes touch the platens (a frozen node in a wall would load it).
        let (bottom, top) = (bottom + r, top - r);
        let n = ((top - bottom) / (NODE_SPACING_D * diameter)).round() as usize + 1;
        let rest = (top - bottom) / (n - 1) as f64;
        let mass = Grains::<D2>::mass_of(0.5 * diameter, density);
        let mut chains = [Vec::new(), Vec::new()];
        for (side, x) in [(0, left - r), (1, right + r)] {
            for k in 0..n {
                let id = MEMBRANE + side as u64 * CHAIN + k as u64;
                let i = state
                    .grains
                    .push(id, D2::from_array([x, bottom + k as f64 * rest, 0.0]), r, mass, 0);
                state.grains.frozen[i] = k == 0 || k == n - 1;
                chains[side].push(id);
            }
        }
        Membrane { chains, pressure, rest }
    }

    /// Sets the external force of every free node (the pressure and the springs at the
    /// current positions and velocities) and moves the top end nodes with the top platen
    /// (wall 1), before a step of dt.
    pub fn load(&self, state: &mut DemState<D2>, dt: f64) {
        let at = self.indices(&state.grains);
        let g = &mut state.grains;
        let n = self.chains[0].len();
        let top_v = state.walls[1].velocity;
        for (side, inward) in [(0, 1.0), (1, -1.0)] {
            let idx = &at[side * n..(side + 1) * n];
            let x: Vec<DVec2> = idx.iter().map(|&i| g.x[i]).collect();
            let v: Vec<DVec2> = idx.iter().map(|&i| g.v[i]).collect();
            let mut f = self.springs(&x, &v);
            for k in 1..n - 1 {
                // The pressure over half of each segment: p (x_{k+1} − x_{k−1}) / 2 turned
                // towards the sample (the chains run bottom to top: the left's inward normal is
                // the tangent turned clockwise).
                let t = x[k + 1] - x[k - 1];
                f[k] += DVec2::new(t.y, -t.x) * (0.5 * self.pressure * inward);
            }
            for (k, &i) in idx.iter().enumerate() {
                g.external[i] = f[k];
            }
            // The top end rides with the platen and follows the node under it sideways
            // (within 100 steps): the top of the sample slides on the frictionless platen, and
            // an end held in x would stretch the membrane across the corner.
            g.v[idx[n - 1]] = DVec2::new((x[n - 2].x - x[n - 1].x) / (100.0 * dt), top_v.y);
        }
    }

    /// The springs' forces on the nodes of one chain at positions `x` and velocities `v`.
    fn springs(&self, x: &[DVec2], v: &[DVec2]) -> Vec<DVec2> {
        let mut f = vec![DVec2::ZERO; x.len()];
        for k in 0..x.len() - 1 {
            let e = x[k + 1] - x[k];
            let len = e.length();
            let u = e / len;
            // A membrane slackens when shortened: its springs pull, they do not push (a
            // chain that pushed would buckle into the sample: at 5% of axial strain its
            // compression was half the pressure's load on a node).
            let tension = K_MS * (len - self.rest).max(0.0) + GAMMA_MS * (v[k + 1] - v[k]).dot(u);
            f[k] += u * tension;
            f[k + 1] -= u * tension;
        }
        f
    }

    /// The springs' pull on the free nodes towards the sample, as a stress over the height
    /// [`Membrane::traction`] divides by [Pa]: what a taut, curved membrane adds to the
    /// pressure.
    pub fn pull(&self, state: &DemState<D2>) -> f64 {
        let g = &state.grains;
        let at = self.indices(g);
        let n = self.chains[0].len();
        let mut inward = 0.0;
        for (side, sign) in [(0, 1.0), (1, -1.0)] {
            let idx = &at[side * n..(side + 1) * n];
            let x: Vec<DVec2> = idx.iter().map(|&i| g.x[i]).collect();
            let v: Vec<DVec2> = idx.iter().map(|&i| g.v[i]).collect();
            inward += self.springs(&x, &v)[1..n - 1].iter().map(|f| sign * f.x).sum::<f64>();
        }
        let y = |k: usize| g.x[at[k]].y;
        inward / (2.0 * (0.5 * (y(n - 2) + y(n - 1)) - 0.5 * (y(0) + y(1))))
    }

    /// The lateral stress the grains take from the membrane [Pa]: the net outward force of
    /// their contacts on both chains' free nodes (the elastic part, as the contacts are after a
    /// step), over twice the height those nodes span. The end nodes are the platens'
    /// (frozen, or driven with the top), so their contacts are the platens' reactions, not the
    /// pressure: counted, they added 1.9 and 1.3 points of p on two samples. The pressure acts over that height, so it is p unless
    /// the springs or the nodes' inertia carry some of the load, or a node left the sample.
    /// Net, not each contact's |f_x|: a node in the valley between two boundary grains is
    /// touched from above and below, and those contacts push it inward; summed as magnitudes
    /// they read 0.8–2.4% over p in the biaxial (docs/validation.md).
    pub fn traction(&self, pipe: &DemPipeline<D2>, state: &DemState<D2>) -> f64 {
        let g = &state.grains;
        let n = self.chains[0].len() as u64;
        let free_node = |i: usize| g.id[i] >= MEMBRANE && !matches!((g.id[i] - MEMBRANE) % CHAIN, k if k == 0 || k == n - 1);
        let push: f64 = pipe
            .contact_forces(state)
            .into_iter()
            .filter(|&(i, j, ..)| (g.id[i] >= MEMBRANE) != (g.id[j] >= MEMBRANE) && (free_node(i) || free_node(j)))
            .map(|(i, j, f, _)| {
                // The force on the node (f acts on i), outward: −x on the left chain.
                let (node, on_node) = if g.id[i] >= MEMBRANE { (i, f) } else { (j, -f) };
                let left = (g.id[node] - MEMBRANE) / CHAIN == 0;
                if left { -on_node.x } else { on_node.x }
            })
            .sum();
        // The free nodes take the pressure from the middle of the first segment to the middle
        // of the last (the halves at the ends would load the platens' nodes).
        let at = self.indices(g);
        let y = |k: usize| g.x[at[k]].y;
        let n = n as usize;
        let height = 0.5 * (y(n - 2) + y(n - 1)) - 0.5 * (y(0) + y(1));
        push / (2.0 * height)
    }

    /// The storage index of every node, the left chain then the right, bottom to top: one
    /// pass over the grains (the DEM re-sorts them, so indices hold for one step only).
    fn indices(&self, g: &Grains<D2>) -> Vec<usize> {
        let n = self.chains[0].len();
        let mut at = vec![usize::MAX; 2 * n];
        for i in 0..g.len() {
            if g.id[i] >= MEMBRANE {
                let k = g.id[i] - MEMBRANE;
                at[(k / CHAIN) as usize * n + (k % CHAIN) as usize] = i;
            }
        }
        at
    }

    /// The area enclosed by the chains' centre lines [m²].
    pub fn area(&self, state: &DemState<D2>) -> f64 {
        let g = &state.grains;
        let (at, n) = (self.indices(g), self.chains[0].len());
        // Up the right chain, down the left.
        let ring: Vec<DVec2> = at[n..].iter().chain(at[..n].iter().rev()).map(|&i| g.x[i]).collect();
        0.5 * (0..ring.len())
            .map(|k| {
                let (p, q) = (ring[k], ring[(k + 1) % ring.len()]);
                p.x * q.y - p.y * q.x
            })
            .sum::<f64>()
            .abs()
    }
}

/// The area of disks (centre, radius) as their outer faces enclose it: in horizontal slabs
/// about `cell` high, the extent of the disks whose centres lie in each, over its height.
pub(super) fn slab_area(disks: &[([f64; 2], f64)], cell: f64) -> f64 {
    let (lo, hi) = disks.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (x, r)| {
        (lo.min(x[1] - r), hi.max(x[1] + r))
    });
    let slabs = ((hi - lo) / cell).ceil().max(1.0) as usize;
    let dy = (hi - lo) / slabs as f64;
    let mut extent = vec![(f64::INFINITY, f64::NEG_INFINITY); slabs];
    for (x, r) in disks {
        let k = (((x[1] - lo) / dy) as usize).min(slabs - 1);
        extent[k].0 = extent[k].0.min(x[0] - r);
        extent[k].1 = extent[k].1.max(x[0] + r);
    }
    extent.iter().filter(|e| e.1 > e.0).map(|e| (e.1 - e.0) * dy).sum()
}

/// The plane's vectors (glam's, through the DEM's space).
type DVec2 = <D2 as Space>::V;

pub(super) fn plane_point(state: &DemState<D2>, k: usize) -> <D2 as Space>::V {
    match state.walls[k].shape {
        grains_dem::state::WallShape::Plane { point, .. } => point,
        _ => unreachable!("a box sample's walls are planes"),
    }
}

/// What holds a box sample's sides (walls 0 and 1 of `box_sample`, replaced) at the pressure:
/// App. B's membrane, or a fluid on the packing's surface ([`grains_dem::fluid`]).
pub(super) enum Sides {
    Membrane(Membrane),
    Fluid(grains_dem::fluid::Fluid),
}

impl Sides {
    /// Replaces the side walls by `kind` at `pressure`; the fluid's grid has cells of two
    /// diameters and takes the sample's `packing` fraction.
    pub fn wrap(
        kind: crate::validate::args::Confinement,
        state: &mut DemState<D2>,
        pressure: f64,
        diameter: f64,
        density: f64,
        packing: f64,
    ) -> Sides {
        match kind {
            crate::validate::args::Confinement::Membrane => Sides::Membrane(Membrane::wrap(state, pressure, diameter, density)),
            crate::validate::args::Confinement::Fluid => {
                state.walls.drain(0..2);
                Sides::Fluid(grains_dem::fluid::Fluid {
                    pressure,
                    cell: 2.0 * diameter,
                    packing,
                })
            }
        }
    }

    /// Loads the grains (the membrane's nodes, or the fluid's forces on every grain) before a
    /// step of dt.
    pub fn load(&self, state: &mut DemState<D2>, dt: f64) {
        match self {
            Sides::Membrane(m) => m.load(state, dt),
            Sides::Fluid(f) => {
                let (forces, _) = grains_dem::fluid::forces(&state.grains, f);
                state.grains.external = forces;
            }
        }
    }

    /// The area the sides enclose [m²]: the chains' polygon; under the fluid, the grains'
    /// outer faces in horizontal slabs of a fluid cell (the extent of the grains in each, over
    /// its height). Not the fluid's own ∫ c dA: that moves by ±1% of the area as the top
    /// crosses the fluid's cells (a period of 2 D50 in the first run, `/tmp/vb_fluid`).
    pub fn area(&self, state: &DemState<D2>) -> f64 {
        match self {
            Sides::Membrane(m) => m.area(state),
            Sides::Fluid(f) => {
                let g = &state.grains;
                slab_area(
                    &(0..g.len()).map(|i| ([g.x[i].x, g.x[i].y], g.radius[i])).collect::<Vec<_>>(),
                    f.cell,
                )
            }
        }
    }

    /// The part of the axial stress σ1 the top platen does not carry: the fluid pushes the
    /// top grains down as well (the MPM's fluid does the same); the membrane ends at the
    /// platens.
    pub fn on_top(&self) -> f64 {
        match self {
            Sides::Membrane(_) => 0.0,
            Sides::Fluid(f) => f.pressure,
        }
    }

    /// The lateral stress the grains take from the sides and the springs' net pull, over the
    /// pressure ([`Membrane::traction`], [`Membrane::pull`]); the fluid's is its net inward
    /// force on each half of the sample (the load [`Sides::load`] set for the last step) over
    /// twice the height between the platens (walls 0 and 1 after the wrap), and it pulls
    /// nothing.
    pub fn lateral(&self, pipe: &DemPipeline<D2>, state: &DemState<D2>) -> (f64, f64) {
        match self {
            Sides::Membrane(m) => (m.traction(pipe, state) / m.pressure, m.pull(state) / m.pressure),
            Sides::Fluid(f) => {
                let g = &state.grains;
                let forces = &g.external;
                let mid = g.x.iter().map(|x| x.x).sum::<f64>() / g.len() as f64;
                let push: f64 = (0..g.len()).map(|i| if g.x[i].x > mid { -forces[i].x } else { forces[i].x }).sum();
                let height = plane_point(state, 1).y - plane_point(state, 0).y;
                (push / (2.0 * height) / f.pressure, 0.0)
            }
        }
    }
}
