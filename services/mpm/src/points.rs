//! Material points (structure of arrays) and how they are seeded from shapes.

use crate::matrix::{Matrix, MpmSpace};
use grains_grid::{Space, Vector};

/// Material points. The elastic strain b^e and the Kirchhoff stress τ are kept together: the
/// constitutive update (end of phase 2) writes both, the force computation (phase 1) reads τ.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Points<S: MpmSpace> {
    /// Identity of a point (the pipeline reorders points by grid block from time to time).
    pub id: Vec<u64>,
    pub x: Vec<S::V>,
    pub v: Vec<S::V>,
    /// Mass [kg] (2D: per metre).
    pub mass: Vec<f64>,
    /// Reference volume V0 [m³] (2D: m² per metre).
    pub volume: Vec<f64>,
    /// Elastic left Cauchy–Green strain b^e.
    pub b_e: Vec<S::M>,
    /// Kirchhoff stress τ = J σ [Pa] (tension positive).
    pub tau: Vec<S::M>,
    /// Hybrid weight w of mass and stress (1 outside a hybrid zone).
    pub weight: Vec<f64>,
    /// APIC affine velocity C (zero unless the transfer is APIC).
    pub affine: Vec<S::M>,
    /// J = det F, the volume ratio V / V0.
    pub jacobian: Vec<f64>,
    /// Packing fraction Φ: the critical-state model's state variable; the initial Φ0 for the
    /// other models, whose current packing is Φ0 / J (see `Model::packing`).
    pub packing: Vec<f64>,
    /// Accumulated plastic strain Σ ‖Δε^p‖.
    pub plastic_strain: Vec<f64>,
    /// Plastic strain rate ‖Δε^p‖ / dt of the last step [1/s] (what the shear-band oracle reads).
    pub plastic_rate: Vec<f64>,
    /// Dead loads on points (traction boundaries): point index and force [N] (2D: N/m).
    pub loads: Vec<(usize, S::V)>,
}

impl<S: MpmSpace> Default for Points<S> {
    fn default() -> Self {
        Points {
            id: Vec::new(),
            x: Vec::new(),
            v: Vec::new(),
            mass: Vec::new(),
            volume: Vec::new(),
            b_e: Vec::new(),
            tau: Vec::new(),
            weight: Vec::new(),
            affine: Vec::new(),
            jacobian: Vec::new(),
            packing: Vec::new(),
            plastic_strain: Vec::new(),
            plastic_rate: Vec::new(),
            loads: Vec::new(),
        }
    }
}

impl<S: MpmSpace> Points<S> {
    /// A point at rest and unstrained, with the next id.
    pub fn push(&mut self, x: S::V, mass: f64, volume: f64, packing: f64) {
        let zero = S::M::identity() * 0.0;
        self.id.push(self.id.last().map_or(0, |&i| i + 1));
        self.x.push(x);
        self.v.push(S::V::default());
        self.mass.push(mass);
        self.volume.push(volume);
        self.b_e.push(S::M::identity());
        self.tau.push(zero);
        self.weight.push(1.0);
        self.affine.push(zero);
        self.jacobian.push(1.0);
        self.packing.push(packing);
        self.plastic_strain.push(0.0);
        self.plastic_rate.push(0.0);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Reorders the points: point k becomes the old point `order[k]` (loads follow).
    pub fn permute(&mut self, order: &[u32]) {
        fn apply<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            let old = std::mem::take(v);
            v.extend(order.iter().map(|&k| old[k as usize]));
        }
        debug_assert_eq!(order.len(), self.len());
        apply(&mut self.id, order);
        apply(&mut self.x, order);
        apply(&mut self.v, order);
        apply(&mut self.mass, order);
        apply(&mut self.volume, order);
        apply(&mut self.b_e, order);
        apply(&mut self.tau, order);
        apply(&mut self.weight, order);
        apply(&mut self.affine, order);
        apply(&mut self.jacobian, order);
        apply(&mut self.packing, order);
        apply(&mut self.plastic_strain, order);
        apply(&mut self.plastic_rate, order);
        if !self.loads.is_empty() {
            let mut new_index = vec![0usize; order.len()];
            for (k, &old) in order.iter().enumerate() {
                new_index[old as usize] = k;
            }
            for load in &mut self.loads {
                load.0 = new_index[load.0];
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Keeps the points `keep` (indices, increasing) and drops the rest; loads of dropped
    /// points go with them.
    pub fn retain_indices(&mut self, keep: &[u32]) {
        let mut new_index = vec![usize::MAX; self.len()];
        for (k, &old) in keep.iter().enumerate() {
            new_index[old as usize] = k;
        }
        let loads = std::mem::take(&mut self.loads);
        fn select<T: Copy>(v: &mut Vec<T>, keep: &[u32]) {
            let old = std::mem::take(v);
            v.extend(keep.iter().map(|&k| old[k as usize]));
        }
        select(&mut self.id, keep);
        select(&mut self.x, keep);
        select(&mut self.v, keep);
        select(&mut self.mass, keep);
        select(&mut self.volume, keep);
        select(&mut self.b_e, keep);
        select(&mut self.tau, keep);
        select(&mut self.weight, keep);
        select(&mut self.affine, keep);
        select(&mut self.jacobian, keep);
        select(&mut self.packing, keep);
        select(&mut self.plastic_strain, keep);
        select(&mut self.plastic_rate, keep);
        self.loads = loads
            .into_iter()
            .filter(|(i, _)| new_index[*i] != usize::MAX)
            .map(|(i, f)| (new_index[i], f))
            .collect();
    }
}

/// A region to fill with points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Region {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    /// A disk in 2D, a ball in 3D.
    Ball {
        center: [f64; 3],
        radius: f64,
    },
}

impl Region {
    fn contains(&self, p: [f64; 3], dim: usize) -> bool {
        match *self {
            Region::Box { min, max } => (0..dim).all(|k| p[k] >= min[k] && p[k] < max[k]),
            Region::Ball { center, radius } => (0..dim).map(|k| (p[k] - center[k]).powi(2)).sum::<f64>() < radius * radius,
        }
    }

    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Region::Box { min, max } => (min, max),
            Region::Ball { center, radius } => (center.map(|c| c - radius), center.map(|c| c + radius)),
        }
    }
}

/// Point positions filling `region` on a lattice aligned with the grid cells (origin, cell width
/// h): `per_axis` points per cell and axis at the centres of the sub-cells, so a cell inside the
/// region holds exactly per_axis^d points. Each point stands for (h / per_axis)^d of volume.
pub fn seed<S: Space>(region: Region, origin: [f64; 3], h: f64, per_axis: usize) -> Vec<S::V> {
    let d = h / per_axis as f64;
    let (lo, hi) = region.bounds();
    let mut range = [(0i64, 0i64); 3];
    for k in 0..3 {
        range[k] = if k < S::DIM {
            (((lo[k] - origin[k]) / d).floor() as i64, ((hi[k] - origin[k]) / d).ceil() as i64)
        } else {
            (0, 1)
        };
    }
    let mut out = Vec::new();
    for c in range[2].0..range[2].1 {
        for b in range[1].0..range[1].1 {
            for a in range[0].0..range[0].1 {
                let idx = [a, b, c];
                let p: [f64; 3] = [0, 1, 2].map(|k| if k < S::DIM { origin[k] + (idx[k] as f64 + 0.5) * d } else { 0.0 });
                if region.contains(p, S::DIM) {
                    out.push(S::from_array(p));
                }
            }
        }
    }
    out
}

/// Kinetic energy [J] and momentum of the points, with their masses scaled by their hybrid
/// weights (the share of the material the continuum carries, as the DEM scales its grains).
pub fn totals<S: MpmSpace>(pts: &Points<S>) -> (f64, S::V) {
    let mut ke = 0.0;
    let mut p = S::V::default();
    for k in 0..pts.len() {
        let m = pts.mass[k] * pts.weight[k];
        ke += 0.5 * m * pts.v[k].length_squared();
        p += pts.v[k] * m;
    }
    (ke, p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use grains_grid::{D2, D3};

    /// Dropping points keeps the others in order with their loads re-indexed; a dropped
    /// point's load goes with it.
    #[test]
    fn retain_keeps_order_and_loads() {
        let mut p = Points::<D2>::default();
        for k in 0..4 {
            p.push(glam::DVec2::new(k as f64, 0.0), 1.0 + k as f64, 1.0, 0.8);
        }
        p.loads = vec![(2, glam::DVec2::new(0.0, -1.0)), (1, glam::DVec2::new(1.0, 0.0))];
        p.retain_indices(&[0, 2, 3]);
        assert_eq!(p.id, [0, 2, 3]);
        assert_eq!(p.mass, [1.0, 3.0, 4.0]);
        assert_eq!(p.loads, [(1, glam::DVec2::new(0.0, -1.0))]);
    }

    #[test]
    fn seeding_fills_cells_evenly_and_respects_the_shape() {
        let h = 0.1;
        let pts = seed::<D2>(
            Region::Box {
                min: [0.2, 0.3, 0.0],
                max: [0.6, 0.5, 0.0],
            },
            [0.0; 3],
            h,
            2,
        );
        assert_eq!(pts.len(), 4 * 2 * 4);
        let pts = seed::<D3>(
            Region::Box {
                min: [0.0; 3],
                max: [0.3, 0.2, 0.1],
            },
            [0.0; 3],
            h,
            3,
        );
        assert_eq!(pts.len(), 27 * 6);
        // A disk of radius 1 seeded finely has the disk's area within 1%.
        let d = 0.01;
        let pts = seed::<D2>(
            Region::Ball {
                center: [2.0, 2.0, 0.0],
                radius: 1.0,
            },
            [0.0; 3],
            d,
            1,
        );
        let area = pts.len() as f64 * d * d;
        assert!((area - std::f64::consts::PI).abs() < 0.01 * std::f64::consts::PI, "{area}");
        assert!(pts.iter().all(|p| (*p - glam::DVec2::splat(2.0)).length() < 1.0));
    }
}
