//! The DEM side of the grid-vs-grid coupling (Yue 2018 §3.5, Alg. 4–6):
//!
//! - [`Stencils`]: the MPM grid nodes around the grains of the reconciliation zone, with the
//!   MPM's own shape functions, evaluated once per macro-step;
//! - [`Stencils::rasterize`] (Alg. 4): their weighted mass (1 − w) m and momentum onto those
//!   nodes, in node order;
//! - [`Stencils::interpolate`] (Alg. 5): a grain's velocity from node velocities (the
//!   coupler's where it constrained a node, the DEM's own raster velocity elsewhere), with the
//!   same weights, and the field's [`Gradient`]: its spin ½ ∇ × v and its shear rate. Yue 2018 couples
//!   translation only; a hybrid grain whose rotation were left to its contacts would be spun up
//!   without end in a resting band, since every macro-step moves it back to where the coupling
//!   puts it while its contacts' tangential springs keep the sliding of the substeps
//!   (measured: 50 rad/s in a resting layer after 0.8 s). So where the material is
//!   quasi-static a band grain turns with it; where it flows the solver lets it roll.
//!
//! The stage that runs them through a macro-step, with the advection from the saved positions
//! (Alg. 6), is [`crate::coupled`].

pub use grains_grid::gradient::Gradient;
use grains_grid::shape::for_each_node;
use grains_grid::{Grid, Kernel, Space};

/// Weighted mass and momentum of one grid node, with its linear index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeMomentum<S: Space> {
    pub node: u64,
    pub mass: f64,
    pub momentum: S::V,
}

/// The MPM grid nodes around a set of points (the hybrid grains' saved positions) with their
/// weights and weight gradients, evaluated once and used by every transfer of a macro-step:
/// `nodes` sorted and unique (the raster's nodes), and per point its entries (slot into
/// `nodes`, weight, gradient), points in the order given.
#[derive(Clone, Debug, Default)]
pub struct Stencils<S: Space> {
    pub nodes: Vec<u64>,
    entries: Vec<(u32, f64, S::V)>,
    offsets: Vec<u32>,
}

impl<S: Space> Stencils<S> {
    /// The stencils of `points` on `grid` with `kernel` (entries of zero weight left out).
    pub fn build(&mut self, grid: &Grid, kernel: Kernel, points: &[S::V]) {
        let mut raw: Vec<(u64, f64, S::V)> = Vec::with_capacity(points.len() * 3usize.pow(S::DIM as u32));
        self.offsets.clear();
        self.offsets.push(0);
        for &x in points {
            for_each_node::<S>(grid, kernel, x, |node, w, grad| {
                if w > 0.0 {
                    raw.push((node, w, grad));
                }
            });
            self.offsets.push(raw.len() as u32);
        }
        self.nodes.clear();
        self.nodes.extend(raw.iter().map(|e| e.0));
        self.nodes.sort_unstable();
        self.nodes.dedup();
        let nodes = &self.nodes;
        self.entries.clear();
        self.entries.extend(raw.iter().map(|&(node, w, grad)| {
            let slot = nodes.binary_search(&node).expect("every node was listed");
            (slot as u32, w, grad)
        }));
    }

    /// Point `k`'s entries: (slot, weight, gradient).
    pub fn of(&self, k: usize) -> &[(u32, f64, S::V)] {
        &self.entries[self.offsets[k] as usize..self.offsets[k + 1] as usize]
    }

    /// Alg. 4 over the points (in order, with `items[k]` = (weighted mass, velocity, impulse)
    /// of point `k`): per slot Σ w m, Σ w m v and Σ w J, summed point by point in order.
    pub fn rasterize(&self, items: impl Iterator<Item = (f64, S::V, S::V)>) -> (Vec<NodeMomentum<S>>, Vec<S::V>) {
        let mut nodes: Vec<NodeMomentum<S>> = self
            .nodes
            .iter()
            .map(|&node| NodeMomentum {
                node,
                mass: 0.0,
                momentum: S::V::default(),
            })
            .collect();
        let mut impulses = vec![S::V::default(); self.nodes.len()];
        for (k, (m, v, j)) in items.enumerate() {
            for &(slot, w, _) in self.of(k) {
                let n = &mut nodes[slot as usize];
                n.mass += w * m;
                n.momentum += v * (w * m);
                impulses[slot as usize] += j * w;
            }
        }
        (nodes, impulses)
    }

    /// Alg. 5 at point `k` from slot velocities (`None` for a slot without one: its weight
    /// is left out and the others renormalized, so that a uniform field is kept exactly), and
    /// the field's [`Gradient`] there (for the spin ½ ∇ × v and the shear rate).
    pub fn interpolate(&self, k: usize, velocity: impl Fn(usize) -> Option<S::V>) -> (S::V, Gradient) {
        let (mut v, mut total) = (S::V::default(), 0.0);
        let mut l = [[0.0; 3]; 3];
        for &(slot, w, grad) in self.of(k) {
            if let Some(vn) = velocity(slot as usize) {
                v += vn * w;
                total += w;
                let (va, ga) = (S::to_array(vn), S::to_array(grad));
                for (a, row) in l.iter_mut().enumerate() {
                    for (b, e) in row.iter_mut().enumerate() {
                        *e += va[a] * ga[b];
                    }
                }
            }
        }
        (if total > 0.0 { v * (1.0 / total) } else { v }, Gradient(l))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;
    use grains_grid::D2;

    fn grains() -> (Vec<DVec2>, Vec<DVec2>, Vec<f64>) {
        let mut x = Vec::new();
        let mut v = Vec::new();
        let mut m = Vec::new();
        for k in 0..200 {
            let t = k as f64 * 0.618_033_988_7 % 1.0;
            x.push(DVec2::new(0.3 + 0.4 * t, 0.2 + 0.5 * ((7.3 * t) % 1.0)));
            v.push(DVec2::new((3.1 * t).sin(), (2.3 * t).cos()));
            m.push(1e-3 * (1.0 + t));
        }
        (x, v, m)
    }

    /// Alg. 4 conserves the rasterized mass, momentum and impulse (the weights are a partition
    /// of unity), for both kernels; every node listed carries weight.
    #[test]
    fn rasterizing_conserves_mass_momentum_and_impulse() {
        let (x, v, m) = grains();
        let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], 0.05, 2);
        for kernel in [Kernel::Bspline2, Kernel::Gimp { half_width: 0.0125 }] {
            let mut st = Stencils::<D2>::default();
            st.build(&grid, kernel, &x);
            let impulse = |k: usize| DVec2::new(1e-3 * k as f64, -2e-3);
            let (r, j) = st.rasterize((0..x.len()).map(|k| (m[k], v[k], impulse(k))));
            assert!(r.windows(2).all(|w| w[0].node < w[1].node));
            assert!(r.iter().all(|n| n.mass > 0.0) && j.len() == r.len());
            let mass: f64 = r.iter().map(|n| n.mass).sum();
            let p = r.iter().fold(DVec2::ZERO, |a, n| a + n.momentum);
            let jj = j.iter().fold(DVec2::ZERO, |a, &b| a + b);
            let (m_in, p_in, j_in) = (0..x.len()).fold((0.0, DVec2::ZERO, DVec2::ZERO), |(a, b, c), k| {
                (a + m[k], b + v[k] * m[k], c + impulse(k))
            });
            assert!((mass - m_in).abs() < 1e-14, "{kernel:?}: {mass} vs {m_in}");
            assert!((p - p_in).length() < 1e-14, "{kernel:?}");
            assert!((jj - j_in).length() < 1e-12, "{kernel:?}: {jj:?} vs {j_in:?}");
        }
    }

    /// Alg. 5 of a uniform node field gives that field back at any point, also where part of
    /// the stencil has no velocity (renormalized weights), and of a linear field the linear
    /// field (the weights reproduce linear functions).
    #[test]
    fn interpolation_keeps_uniform_and_linear_fields() {
        let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], 0.05, 2);
        let kernel = Kernel::Bspline2;
        let u = DVec2::new(0.4, -1.2);
        let at = |node: u64| {
            let p = grid.position(grid.ijk(node));
            DVec2::new(p[0], p[1])
        };
        for k in 0..100 {
            let t = k as f64 * 0.618_033_988_7 % 1.0;
            let x = DVec2::new(0.2 + 0.6 * t, 0.2 + 0.6 * ((3.7 * t) % 1.0));
            let mut st = Stencils::<D2>::default();
            st.build(&grid, kernel, &[x]);
            let node = |k: usize| st.nodes[k];
            let interpolate = |f: &dyn Fn(u64) -> Option<DVec2>| st.interpolate(0, |k| f(node(k)));
            let (v, grad) = interpolate(&|_| Some(u));
            assert!((v - u).length() < 1e-14 && grad.spin::<D2>().abs() < 1e-12 && grad.shear_rate(2) < 1e-12);
            let (half, _) = interpolate(&|n| (n % 2 == 0).then_some(u));
            assert!((half - u).length() < 1e-14);
            let (linear, grad) = interpolate(&|n| Some(at(n) * 2.0));
            assert!((linear - x * 2.0).length() < 1e-12, "{linear:?} vs {:?}", x * 2.0);
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!(
                spin.abs() < 1e-10 && rate < 1e-10,
                "an isotropic stretch has no spin ({spin}) and no shear ({rate})"
            );
            // A rigid rotation at ω about (0.5, 0.5): v = ω × r, spin ω (the weights reproduce
            // linear fields and their gradients).
            let omega = 3.0;
            let (rot, grad) = interpolate(&|n| {
                let r = at(n) - DVec2::splat(0.5);
                Some(DVec2::new(-omega * r.y, omega * r.x))
            });
            let r = x - DVec2::splat(0.5);
            assert!((rot - DVec2::new(-omega * r.y, omega * r.x)).length() < 1e-12);
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!((spin - omega).abs() < 1e-9 && rate < 1e-9, "spin {spin} vs {omega}, shear {rate}");
            // A simple shear v_x = γ̇ y: shear rate γ̇, spin −γ̇/2.
            let shear = 4.0;
            let (_, grad) = interpolate(&|n| Some(DVec2::new(shear * at(n).y, 0.0)));
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!(
                (rate - shear).abs() < 1e-9 && (spin + 0.5 * shear).abs() < 1e-9,
                "shear {rate}, spin {spin}"
            );
        }
    }
}
