//! Grid-vs-grid coupling (Yue 2018 §3.5, Alg. 3, Appendix B eq. 31).
//!
//! On every grid node that both the DEM and the MPM raster carry, the two velocities are made
//! equal by a perfectly inelastic collision of the two node masses: with weighted masses
//! `m_d`, `m_c` and momenta `p_d`, `p_c` already scaled by `1−w` and `w` by the solvers,
//! `v = (p_d + p_c) / (m_d + m_c)`. This conserves the total momentum of each node exactly
//! (up to the rounding of one division), and is the closed-form minimizer of eq. 31.
//!
//! Rasters are sorted by strictly increasing node index; the shared nodes are found by one
//! merge pass, so the cost is linear in the raster sizes.

use grains_protocol::wire::{NodeVelocity, RasterNode};

/// Constrained velocity of one node [m/s] from the DEM and MPM weighted mass [kg] and
/// momentum [kg m/s] (Alg. 3). `None` when the node carries no mass.
#[inline]
pub fn constrained_velocity(m_dem: f64, p_dem: [f64; 3], m_mpm: f64, p_mpm: [f64; 3]) -> Option<[f64; 3]> {
    let m = m_dem + m_mpm;
    if m.is_nan() || m <= 0.0 {
        return None;
    }
    Some([(p_dem[0] + p_mpm[0]) / m, (p_dem[1] + p_mpm[1]) / m, (p_dem[2] + p_mpm[2]) / m])
}

/// Where a raster breaks the sorting rule, as (position, node).
pub fn first_unsorted(raster: &[RasterNode]) -> Option<(usize, u64)> {
    raster
        .windows(2)
        .position(|w| w[1].node <= w[0].node)
        .map(|i| (i + 1, raster[i + 1].node))
}

/// Number of nodes both rasters carry (the length of the constrained-velocity message).
pub fn count_shared(dem: &[RasterNode], mpm: &[RasterNode]) -> usize {
    let (mut i, mut j, mut n) = (0, 0, 0);
    while i < dem.len() && j < mpm.len() {
        match dem[i].node.cmp(&mpm[j].node) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                n += 1;
                i += 1;
                j += 1;
            }
        }
    }
    n
}

/// Totals over the shared nodes, before and after the constraint.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CouplingReport {
    pub shared_nodes: u64,
    pub mass: f64,
    pub momentum_before: [f64; 3],
    pub momentum_after: [f64; 3],
    pub kinetic_energy_before: f64,
    pub kinetic_energy_after: f64,
}

/// Writes the constrained velocity of every shared node into `out` (whose length must be
/// [`count_shared`]) in node order, and returns the totals. Sums run in node order, so the
/// result is bit-identical wherever it runs.
pub fn constrain(dem: &[RasterNode], mpm: &[RasterNode], out: &mut [NodeVelocity]) -> CouplingReport {
    let mut r = CouplingReport::default();
    let (mut i, mut j, mut k) = (0, 0, 0);
    let ke = |m: f64, p: [f64; 3]| {
        if m > 0.0 {
            0.5 * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) / m
        } else {
            0.0
        }
    };
    while i < dem.len() && j < mpm.len() {
        let (a, b) = (&dem[i], &mpm[j]);
        match a.node.cmp(&b.node) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                let m = a.mass + b.mass;
                let v = constrained_velocity(a.mass, a.momentum, b.mass, b.momentum).unwrap_or([0.0; 3]);
                out[k] = NodeVelocity { node: a.node, velocity: v };
                r.mass += m;
                r.kinetic_energy_before += ke(a.mass, a.momentum) + ke(b.mass, b.momentum);
                r.kinetic_energy_after += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
                for (c, vc) in v.iter().enumerate() {
                    r.momentum_before[c] += a.momentum[c] + b.momentum[c];
                    r.momentum_after[c] += m * vc;
                }
                k += 1;
                i += 1;
                j += 1;
            }
        }
    }
    r.shared_nodes = k as u64;
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(node: u64, mass: f64, v: [f64; 3]) -> RasterNode {
        RasterNode {
            node,
            mass,
            momentum: [mass * v[0], mass * v[1], mass * v[2]],
        }
    }

    #[test]
    fn equal_masses_meet_at_the_mean_velocity() {
        // Perfectly inelastic collision of equal masses: v = (v1 + v2) / 2.
        let v = constrained_velocity(2.0, [2.0, -4.0, 0.0], 2.0, [6.0, 0.0, 0.0]).unwrap();
        assert_eq!(v, [2.0, -1.0, 0.0]);
        assert_eq!(constrained_velocity(0.0, [0.0; 3], 0.0, [0.0; 3]), None);
    }

    #[test]
    fn only_shared_nodes_are_constrained_and_momentum_is_conserved() {
        let dem = [
            node(1, 1.0, [1.0, 0.0, 0.0]),
            node(3, 2.0, [0.0, 1.0, 0.0]),
            node(4, 1.5, [0.3, 0.1, -0.2]),
        ];
        let mpm = [
            node(0, 1.0, [5.0, 5.0, 5.0]),
            node(3, 1.0, [3.0, -2.0, 0.0]),
            node(4, 0.5, [-1.0, 0.0, 0.7]),
            node(9, 1.0, [0.0; 3]),
        ];
        assert_eq!(count_shared(&dem, &mpm), 2);
        let mut out = [NodeVelocity::default(); 2];
        let r = constrain(&dem, &mpm, &mut out);
        assert_eq!((out[0].node, out[1].node), (3, 4));
        assert_eq!(out[0].velocity, [1.0, 0.0, 0.0]); // (2·(0,1) + 1·(3,−2)) / 3
        for c in 0..3 {
            assert!((r.momentum_before[c] - r.momentum_after[c]).abs() <= 1e-15 * r.mass, "{r:?}");
        }
        assert!(
            r.kinetic_energy_after <= r.kinetic_energy_before,
            "an inelastic collision loses energy: {r:?}"
        );
    }

    #[test]
    fn unsorted_rasters_are_found() {
        let ok = [node(1, 1.0, [0.0; 3]), node(2, 1.0, [0.0; 3])];
        let bad = [node(2, 1.0, [0.0; 3]), node(2, 1.0, [0.0; 3])];
        assert_eq!(first_unsorted(&ok), None);
        assert_eq!(first_unsorted(&bad), Some((1, 2)));
    }
}
