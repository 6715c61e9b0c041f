//! The DEM side of the grid-vs-grid coupling (Yue 2018 §3.5, Alg. 4–6), as plain functions:
//!
//! - [`rasterize`] (Alg. 4): the weighted mass (1 − w) m and momentum of the grains in the
//!   reconciliation zone onto the MPM grid, with the MPM's own shape functions, by node index;
//! - [`interpolate`] (Alg. 5): a grain's velocity from node velocities (the coupler's where it
//!   constrained a node, the DEM's own raster velocity elsewhere), with the same weights, and
//!   the field's [`Gradient`]: its spin ½ ∇ × v and its shear rate. Yue 2018 couples
//!   translation only; a hybrid grain whose rotation were left to its contacts would be spun up
//!   without end in a resting band, since every macro-step moves it back to where the coupling
//!   puts it while its contacts' tangential springs keep the sliding of the substeps
//!   (measured: 50 rad/s in a resting layer after 0.8 s). So where the material is
//!   quasi-static a band grain turns with it; where it flows the solver lets it roll.
//!
//! The stage that runs them through a macro-step, with the advection from the saved positions
//! (Alg. 6), is [`crate::coupled`].

use grains_grid::shape::for_each_node;
use grains_grid::{Grid, Kernel, Space};

/// Weighted mass and momentum of one grid node, with its linear index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeMomentum<S: Space> {
    pub node: u64,
    pub mass: f64,
    pub momentum: S::V,
}

/// Alg. 4: rasterizes grain `k`'s weighted mass `mass[k]` and momentum `mass[k] v[k]` for every
/// grain with `include(k)`, sorted by node index (the order the coupler merges in). Sums run
/// grain by grain in storage order, so the result does not depend on threads.
pub fn rasterize<S: Space>(
    grid: &Grid,
    kernel: Kernel,
    x: &[S::V],
    v: &[S::V],
    mass: &[f64],
    include: impl Fn(usize) -> bool,
) -> Vec<NodeMomentum<S>> {
    let items = (0..x.len()).filter(|&k| include(k)).map(|k| (x[k], v[k], mass[k], S::V::default()));
    rasterize_with_impulse::<S>(grid, kernel, items).0
}

/// Alg. 4 over `(position, velocity, weighted mass, impulse)` items: each node's weighted
/// mass Σ w m, momentum Σ w m v and impulse Σ w J, sorted by node. The contributions are
/// gathered as a list, sorted by node with a stable sort and summed in item order, so the
/// sums do not depend on threads or hashing (and no map is built per step).
pub fn rasterize_with_impulse<S: Space>(
    grid: &Grid,
    kernel: Kernel,
    items: impl Iterator<Item = (S::V, S::V, f64, S::V)>,
) -> (Vec<NodeMomentum<S>>, Vec<S::V>) {
    let mut parts: Vec<(u64, f64, S::V, S::V)> = Vec::new();
    for (x, v, m, impulse) in items {
        for_each_node::<S>(grid, kernel, x, |node, w, _| {
            if w > 0.0 {
                parts.push((node, w * m, v * (w * m), impulse * w));
            }
        });
    }
    parts.sort_by_key(|p| p.0);
    let mut nodes: Vec<NodeMomentum<S>> = Vec::new();
    let mut impulses: Vec<S::V> = Vec::new();
    for (node, m, p, j) in parts {
        match nodes.last_mut() {
            Some(last) if last.node == node => {
                last.mass += m;
                last.momentum += p;
                *impulses.last_mut().expect("one per node") += j;
            }
            _ => {
                nodes.push(NodeMomentum {
                    node,
                    mass: m,
                    momentum: p,
                });
                impulses.push(j);
            }
        }
    }
    (nodes, impulses)
}

/// The gradient L[a][b] = ∂v_a/∂x_b of an interpolated velocity field (zero rows and columns
/// beyond the space's dimension).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Gradient(pub [[f64; 3]; 3]);

impl Gradient {
    /// The spin ½ ∇ × v.
    pub fn spin<S: Space>(&self) -> S::Ang {
        let l = &self.0;
        S::ang_from_array([0.5 * (l[2][1] - l[1][2]), 0.5 * (l[0][2] - l[2][0]), 0.5 * (l[1][0] - l[0][1])])
    }

    /// The shear rate √(2 D′:D′), D′ the deviatoric part of the strain rate (of the space's
    /// `dim` dimensions): γ̇ of a simple shear v_x = γ̇ y.
    pub fn shear_rate(&self, dim: usize) -> f64 {
        let l = &self.0;
        let mean = (0..dim).map(|a| l[a][a]).sum::<f64>() / dim as f64;
        let pairs = (0..dim).flat_map(|a| (0..dim).map(move |b| (a, b)));
        let dd: f64 = pairs
            .map(|(a, b)| 0.5 * (l[a][b] + l[b][a]) - if a == b { mean } else { 0.0 })
            .map(|d| d * d)
            .sum();
        (2.0 * dd).sqrt()
    }
}

/// Alg. 5: the velocity at `x` interpolated from node velocities, and its gradient there (for
/// the spin ½ ∇ × v and the shear rate); `velocity(node)` gives a node's velocity (`None` for a
/// node that carries no grain mass, which gets no weight: the weights of the nodes that do are
/// renormalized so that a uniform field is kept exactly).
pub fn interpolate<S: Space>(grid: &Grid, kernel: Kernel, x: S::V, velocity: impl Fn(u64) -> Option<S::V>) -> (S::V, Gradient) {
    let (mut v, mut total) = (S::V::default(), 0.0);
    let mut l = [[0.0; 3]; 3];
    for_each_node::<S>(grid, kernel, x, |node, w, grad| {
        if w > 0.0
            && let Some(vn) = velocity(node)
        {
            v += vn * w;
            total += w;
            let (va, ga) = (S::to_array(vn), S::to_array(grad));
            for (a, row) in l.iter_mut().enumerate() {
                for (b, e) in row.iter_mut().enumerate() {
                    *e += va[a] * ga[b];
                }
            }
        }
    });
    (if total > 0.0 { v * (1.0 / total) } else { v }, Gradient(l))
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

    /// Alg. 4 conserves the rasterized mass and momentum (the weights are a partition of unity),
    /// for both kernels, and leaves out the grains outside the zone.
    #[test]
    fn rasterizing_conserves_mass_and_momentum() {
        let (x, v, m) = grains();
        let grid = Grid::covering([0.0; 3], [1.0, 1.0, 0.0], 0.05, 2);
        for kernel in [Kernel::Bspline2, Kernel::Gimp { half_width: 0.0125 }] {
            let r = rasterize::<D2>(&grid, kernel, &x, &v, &m, |k| k % 4 != 0);
            assert!(r.windows(2).all(|w| w[0].node < w[1].node));
            let mass: f64 = r.iter().map(|n| n.mass).sum();
            let p = r.iter().fold(DVec2::ZERO, |a, n| a + n.momentum);
            let (m_in, p_in) = (0..x.len())
                .filter(|k| k % 4 != 0)
                .fold((0.0, DVec2::ZERO), |(a, b), k| (a + m[k], b + v[k] * m[k]));
            assert!((mass - m_in).abs() < 1e-14, "{kernel:?}: {mass} vs {m_in}");
            assert!((p - p_in).length() < 1e-14, "{kernel:?}");
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
            let (v, grad) = interpolate::<D2>(&grid, kernel, x, |_| Some(u));
            assert!((v - u).length() < 1e-14 && grad.spin::<D2>().abs() < 1e-12 && grad.shear_rate(2) < 1e-12);
            let (half, _) = interpolate::<D2>(&grid, kernel, x, |n| (n % 2 == 0).then_some(u));
            assert!((half - u).length() < 1e-14);
            let (linear, grad) = interpolate::<D2>(&grid, kernel, x, |n| Some(at(n) * 2.0));
            assert!((linear - x * 2.0).length() < 1e-12, "{linear:?} vs {:?}", x * 2.0);
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!(
                spin.abs() < 1e-10 && rate < 1e-10,
                "an isotropic stretch has no spin ({spin}) and no shear ({rate})"
            );
            // A rigid rotation at ω about (0.5, 0.5): v = ω × r, spin ω (the weights reproduce
            // linear fields and their gradients).
            let omega = 3.0;
            let (rot, grad) = interpolate::<D2>(&grid, kernel, x, |n| {
                let r = at(n) - DVec2::splat(0.5);
                Some(DVec2::new(-omega * r.y, omega * r.x))
            });
            let r = x - DVec2::splat(0.5);
            assert!((rot - DVec2::new(-omega * r.y, omega * r.x)).length() < 1e-12);
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!((spin - omega).abs() < 1e-9 && rate < 1e-9, "spin {spin} vs {omega}, shear {rate}");
            // A simple shear v_x = γ̇ y: shear rate γ̇, spin −γ̇/2.
            let shear = 4.0;
            let (_, grad) = interpolate::<D2>(&grid, kernel, x, |n| Some(DVec2::new(shear * at(n).y, 0.0)));
            let (spin, rate) = (grad.spin::<D2>(), grad.shear_rate(2));
            assert!(
                (rate - shear).abs() < 1e-9 && (spin + 0.5 * shear).abs() < 1e-9,
                "shear {rate}, spin {spin}"
            );
        }
    }
}
