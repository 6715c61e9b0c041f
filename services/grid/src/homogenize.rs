//! Homogenization (discrete → hybrid, Yue 2018 §4.2, Alg. 11): the stress of the grains as a
//! field on the MPM grid, for the new material points. The DEM computes it from its contacts
//! and sends it to the oracle, which gives it to the points it creates; it lives here, below
//! both, because it is the grid's shape functions applied to a contact list.

use crate::shape::for_each_node;
use crate::{Grid, Kernel, Space};
use std::collections::BTreeMap;

/// One contact between two grains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Where the grains touch [m].
    pub point: [f64; 3],
    /// The force on the grain at the arm's tip from the one at its base [N].
    pub force: [f64; 3],
    /// The branch vector from the base grain's centre to the tip grain's [m].
    pub arm: [f64; 3],
}

/// Alg. 11 (the Christoffersen formula spread with the MPM's shape functions): per node,
/// σ = −Σ_c w(x_c) sym(f_c ⊗ l_c) / h^d over the contacts, tension positive like the MPM's
/// stress (a pushing contact, f along l, gives compression). A node's sum weights each contact
/// by its shape function, so the stress of a uniform assembly comes out uniform where the
/// nodes' supports are full. Nodes with no contact are left out.
pub fn stress<S: Space>(grid: &Grid, kernel: Kernel, contacts: &[Contact]) -> BTreeMap<u64, [[f64; 3]; 3]> {
    let volume = grid.h.powi(S::DIM as i32);
    let mut out: BTreeMap<u64, [[f64; 3]; 3]> = BTreeMap::new();
    for c in contacts {
        let (f, l) = (c.force, c.arm);
        for_each_node::<S>(grid, kernel, S::from_array(c.point), |node, w, _| {
            if w > 0.0 {
                let s = out.entry(node).or_default();
                for (a, row) in s.iter_mut().enumerate() {
                    for (b, e) in row.iter_mut().enumerate() {
                        *e -= w * 0.5 * (f[a] * l[b] + l[a] * f[b]) / volume;
                    }
                }
            }
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::D2;

    /// A hexagonal lattice of disks (radius r), every contact pushing with F: per grain three
    /// contacts of arm 2r at 0°, 60°, 120° (Σ n⊗n = 3/2 I) over its area 2√3 r², so
    /// σ = −(√3/2) F / r I, the same pressure on every interior node (within 1%: the lattice
    /// and the grid do not line up) and no shear.
    #[test]
    fn a_uniformly_pressed_lattice() {
        let (r, force) = (0.5e-3, 0.02);
        let grid = Grid::covering([0.0; 3], [0.04, 0.04, 0.0], 0.002, 2);
        let mut contacts = Vec::new();
        for j in 0..50 {
            for i in 0..45 {
                let x = [i as f64 * 2.0 * r + (j % 2) as f64 * r, j as f64 * 3f64.sqrt() * r, 0.0];
                for angle in [0.0f64, 60.0, 120.0] {
                    let n = [angle.to_radians().cos(), angle.to_radians().sin(), 0.0];
                    contacts.push(Contact {
                        point: [x[0] + r * n[0], x[1] + r * n[1], 0.0],
                        force: n.map(|c| force * c),
                        arm: n.map(|c| 2.0 * r * c),
                    });
                }
            }
        }
        let s = stress::<D2>(&grid, Kernel::Bspline2, &contacts);
        let exact = -(3f64.sqrt() / 2.0) * force / r;
        let interior: Vec<_> = s
            .iter()
            .filter(|(n, _)| {
                let p = grid.position(grid.ijk(**n));
                (0.01..0.03).contains(&p[0]) && (0.01..0.03).contains(&p[1])
            })
            .collect();
        assert!(interior.len() >= 100);
        for (n, t) in interior {
            assert!(
                (t[0][0] / exact - 1.0).abs() < 0.01 && (t[1][1] / exact - 1.0).abs() < 0.01,
                "node {n}: {t:?} vs {exact}"
            );
            assert!(
                t[0][1].abs() < 0.01 * exact.abs() && t[0][1] == t[1][0],
                "node {n}: shear {}",
                t[0][1]
            );
        }
    }
}
