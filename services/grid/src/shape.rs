//! The background grid and its shape functions.
//!
//! Nodes sit at `origin + h · (i, j, k)`; their linear index is `i + nx (j + ny k)`. A point
//! touches a 3 × 3 (× 3) block of nodes starting at `floor(x/h − 1/2)` in every axis, for
//! both kernels (GIMP with a half-width of at most h/2 reaches no further).

use crate::space::Space;

/// Which shape function transfers between points and nodes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kernel {
    /// GIMP with particle half-width `half_width` [m] (h / (2 · points per cell)), ≤ h/2.
    Gimp { half_width: f64 },
    /// Quadratic B-spline.
    Bspline2,
}

/// A uniform grid of nodes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub origin: [f64; 3],
    /// Cell width h [m].
    pub h: f64,
    /// Nodes per axis (1 on unused axes).
    pub nodes: [u64; 3],
    /// Cells per period along a periodic axis (0 on open axes): node i and node i + period
    /// are one node, numbered i mod period, so the last node of the covering is never used.
    pub period: [u64; 3],
}

impl Grid {
    /// A grid covering [min, max] with cell width h (nodes on both ends).
    pub fn covering(min: [f64; 3], max: [f64; 3], h: f64, dim: usize) -> Self {
        let mut nodes = [1u64; 3];
        for k in 0..dim {
            nodes[k] = ((max[k] - min[k]) / h).ceil() as u64 + 1;
        }
        Grid {
            origin: min,
            h,
            nodes,
            period: [0; 3],
        }
    }

    /// The same grid wrapping around along the `periodic` axes (whose length must be a whole
    /// number of cells: checked by the scene).
    pub fn with_periodic(mut self, periodic: [bool; 3]) -> Self {
        for ((p, &wraps), &n) in self.period.iter_mut().zip(&periodic).zip(&self.nodes) {
            *p = if wraps && n > 1 { n - 1 } else { 0 };
        }
        self
    }

    /// Node (i, j, k) with its periodic components brought into [0, period).
    #[inline(always)]
    pub fn wrap(&self, ijk: [i64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|k| wrap_index(ijk[k], self.period[k] as i64))
    }

    /// The periodic box of the grid for [`crate::Vector::wrap`] (see [`crate::space::wrap_box`]).
    pub fn wrap_box<S: crate::Space>(&self) -> (S::V, S::V, S::V) {
        let max = [0, 1, 2].map(|k| self.origin[k] + self.h * self.period[k] as f64);
        crate::space::wrap_box::<S>(self.origin, max, self.period.map(|p| p > 0))
    }

    /// Linear index of node (i, j, k) (wrapped on periodic axes), or `None` outside the grid.
    #[inline]
    pub fn index(&self, ijk: [i64; 3]) -> Option<u64> {
        let ijk = self.wrap(ijk);
        let mut idx = 0u64;
        for k in (0..3).rev() {
            if ijk[k] < 0 || ijk[k] as u64 >= self.nodes[k] {
                return None;
            }
            idx = idx * self.nodes[k] + ijk[k] as u64;
        }
        Some(idx)
    }

    /// Node coordinates (i, j, k) of a linear index.
    pub fn ijk(&self, index: u64) -> [i64; 3] {
        let i = index % self.nodes[0];
        let j = (index / self.nodes[0]) % self.nodes[1];
        let k = index / (self.nodes[0] * self.nodes[1]);
        [i as i64, j as i64, k as i64]
    }

    /// Position of a node [m].
    pub fn position(&self, ijk: [i64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| self.origin[k] + self.h * ijk[k] as f64)
    }
}

/// Node index `i` along an axis of `period` nodes, brought into [0, period) (unchanged on an
/// open axis, period 0).
#[inline(always)]
pub fn wrap_index(i: i64, period: i64) -> i64 {
    if period > 0 { i.rem_euclid(period) } else { i }
}

/// One axis of a stencil: the first node and three weights with their derivatives d/dx [1/m].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    pub start: i64,
    pub w: [f64; 3],
    pub dw: [f64; 3],
}

/// ⌊t⌋ as an integer without a libm call (f64::floor is one on baseline x86-64).
#[inline(always)]
fn floor_i64(t: f64) -> i64 {
    let i = t as i64;
    if (i as f64) > t { i - 1 } else { i }
}

/// A kernel on a cell width with its reciprocals worked out once: the per-point weights then
/// need no division (a division costs as much as the rest of an axis's weights).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    kernel: Kernel,
    h: f64,
    inv_h: f64,
    /// GIMP: lp, 1 / (4 h lp), 1 / (2 h lp), 1 / (h lp).
    lp: f64,
    c4: f64,
    c2: f64,
    c1: f64,
}

impl Weights {
    pub fn new(kernel: Kernel, h: f64) -> Self {
        let lp = match kernel {
            Kernel::Gimp { half_width } => half_width,
            Kernel::Bspline2 => 0.0,
        };
        let hl = h * lp;
        let inv = |x: f64| if x > 0.0 { 1.0 / x } else { 0.0 };
        Weights {
            kernel,
            h,
            inv_h: 1.0 / h,
            lp,
            c4: inv(4.0 * hl),
            c2: inv(2.0 * hl),
            c1: inv(hl),
        }
    }

    /// The first node of the stencil of `x` [m] (measured from the grid origin) on one axis.
    #[inline(always)]
    pub fn start(&self, x: f64) -> i64 {
        floor_i64(x * self.inv_h - 0.5)
    }

    /// Weights of the three nodes around `x` [m] (measured from the grid origin) on one axis.
    #[inline(always)]
    pub fn axis(&self, x: f64) -> Axis {
        let xh = x * self.inv_h;
        let start = floor_i64(xh - 0.5);
        let mut w = [0.0; 3];
        let mut dw = [0.0; 3];
        match self.kernel {
            Kernel::Bspline2 => {
                let f = xh - start as f64; // in [0.5, 1.5)
                w = [0.5 * (1.5 - f).powi(2), 0.75 - (f - 1.0).powi(2), 0.5 * (f - 0.5).powi(2)];
                dw = [(f - 1.5) * self.inv_h, -2.0 * (f - 1.0) * self.inv_h, (f - 0.5) * self.inv_h];
            }
            Kernel::Gimp { .. } => {
                for (a, node) in (start..start + 3).enumerate() {
                    (w[a], dw[a]) = self.gimp(x - node as f64 * self.h);
                }
            }
        }
        Axis { start, w, dw }
    }

    #[inline(always)]
    fn gimp(&self, r: f64) -> (f64, f64) {
        let (h, lp) = (self.h, self.lp);
        let a = r.abs();
        let sign = r.signum();
        if lp == 0.0 {
            // A point without width: the linear hat.
            return if a < h {
                (1.0 - a * self.inv_h, -sign * self.inv_h)
            } else {
                (0.0, 0.0)
            };
        }
        if a >= h + lp {
            (0.0, 0.0)
        } else if a > h - lp {
            let t = h + lp - a;
            (t * t * self.c4, -sign * t * self.c2)
        } else if a > lp {
            (1.0 - a * self.inv_h, -sign * self.inv_h)
        } else {
            (1.0 - (r * r + lp * lp) * self.c2, -r * self.c1)
        }
    }
}

/// Weights of the three nodes around `x` [m] (measured from the grid origin) on one axis.
#[inline]
pub fn axis_weights(kernel: Kernel, x: f64, h: f64) -> Axis {
    Weights::new(kernel, h).axis(x)
}

/// GIMP weight and its derivative for a point at offset r = x_p − x_i from a node: the
/// linear hat of half-width h averaged over the point's extent [x_p − lp, x_p + lp]
/// (Bardenhagen & Kober 2004, uGIMP), valid for lp ≤ h/2.
#[inline]
pub fn gimp(r: f64, h: f64, lp: f64) -> (f64, f64) {
    Weights::new(Kernel::Gimp { half_width: lp }, h).gimp(r)
}

/// Calls `f(node, weight, gradient)` for every grid node a point at `x` touches (tensor
/// product of the axes; nodes outside the grid are skipped).
#[inline]
pub fn for_each_node<S: Space>(grid: &Grid, kernel: Kernel, x: S::V, mut f: impl FnMut(u64, f64, S::V)) {
    let a = S::to_array(x);
    let axes: [Axis; 3] = [0, 1, 2].map(|k| {
        if k < S::DIM {
            axis_weights(kernel, a[k] - grid.origin[k], grid.h)
        } else {
            Axis {
                start: 0,
                w: [1.0, 0.0, 0.0],
                dw: [0.0; 3],
            }
        }
    });
    let n = |k: usize| if k < S::DIM { 3 } else { 1 };
    for c in 0..n(2) {
        for b in 0..n(1) {
            for q in 0..n(0) {
                let Some(node) = grid.index([axes[0].start + q as i64, axes[1].start + b as i64, axes[2].start + c as i64]) else {
                    continue;
                };
                let (wx, wy, wz) = (axes[0].w[q], axes[1].w[b], axes[2].w[c]);
                let w = wx * wy * wz;
                let grad = S::from_array([axes[0].dw[q] * wy * wz, wx * axes[1].dw[b] * wz, wx * wy * axes[2].dw[c]]);
                f(node, w, grad);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::space::{D2, D3, Vector};

    /// Shape functions form a partition of unity and reproduce linear fields exactly:
    /// Σ w = 1, Σ w x_i = x, Σ ∇w = 0, Σ ∇w ⊗ x_i = I (what makes MPM transfers conserve mass
    /// and momentum and see a uniform strain exactly).
    fn check<S: Space>(kernel: Kernel) {
        let grid = Grid::covering([-1.0, -2.0, 0.5], [3.0, 2.0, 4.0], 0.25, S::DIM);
        for k in 0..500 {
            let t = k as f64 * 0.618_033_988_7 % 1.0;
            let p = [0.3 + 2.4 * t, -1.4 + 2.7 * ((t * 7.3) % 1.0), 1.0 + 2.5 * ((t * 3.1) % 1.0)];
            let x = S::from_array(p);
            let (mut sw, mut swx, mut sg) = (0.0, S::V::default(), S::V::default());
            let mut sgx = [[0.0; 3]; 3];
            for_each_node::<S>(&grid, kernel, x, |node, w, g| {
                let xi = S::from_array(grid.position(grid.ijk(node)));
                sw += w;
                swx += xi * w;
                sg += g;
                let (ga, xa) = (S::to_array(g), S::to_array(xi));
                for r in 0..3 {
                    for c in 0..3 {
                        sgx[r][c] += ga[r] * xa[c];
                    }
                }
            });
            assert!((sw - 1.0).abs() < 1e-12, "{kernel:?} Σw = {sw} at {p:?}");
            assert!((swx - x).length() < 1e-12, "{kernel:?} Σ w x_i at {p:?}");
            assert!(sg.length() < 1e-9, "{kernel:?} Σ∇w = {sg:?}");
            for (r, row) in sgx.iter().enumerate().take(S::DIM) {
                for (c, value) in row.iter().enumerate().take(S::DIM) {
                    let want = if r == c { 1.0 } else { 0.0 };
                    assert!((value - want).abs() < 1e-9, "{kernel:?} Σ ∇w x_i [{r}][{c}] = {value}");
                }
            }
        }
    }

    #[test]
    fn shape_functions_are_a_partition_of_unity_and_reproduce_linear_fields() {
        for kernel in [
            Kernel::Bspline2,
            Kernel::Gimp { half_width: 0.0625 },
            Kernel::Gimp { half_width: 0.125 },
        ] {
            check::<D2>(kernel);
            check::<D3>(kernel);
        }
    }

    #[test]
    fn gimp_is_the_averaged_hat_and_continuous() {
        let (h, lp) = (1.0, 0.25);
        // Average of the hat over [r − lp, r + lp], by quadrature.
        let avg = |r: f64| {
            let n = 20_000;
            (0..n)
                .map(|k| (1.0 - (r - lp + (k as f64 + 0.5) * 2.0 * lp / n as f64).abs()).max(0.0))
                .sum::<f64>()
                / n as f64
        };
        for k in 0..=60 {
            let r = -1.5 + k as f64 * 0.05;
            assert!((gimp(r, h, lp).0 - avg(r)).abs() < 1e-7, "r = {r}");
            let d = (gimp(r + 1e-6, h, lp).0 - gimp(r - 1e-6, h, lp).0) / 2e-6;
            assert!((gimp(r, h, lp).1 - d).abs() < 1e-4, "derivative at r = {r}");
        }
    }

    #[test]
    fn node_indices_round_trip() {
        let g = Grid::covering([0.0; 3], [1.0, 2.0, 3.0], 0.5, 3);
        assert_eq!(g.nodes, [3, 5, 7]);
        for idx in 0..3 * 5 * 7 {
            assert_eq!(g.index(g.ijk(idx)), Some(idx));
        }
        assert_eq!(g.index([3, 0, 0]), None);
    }
}
