//! Enrichment (continuum → hybrid, Yue 2018 §4.2): the state of new grains.

/// Alg. 10: the velocity of a new grain at `x`, the Gaussian-weighted mean of the velocities of
/// the grains and material points (`sources`: position, velocity) within 12 mean radii (6 mean
/// diameters), weight exp(−|xᵢ − x|² / 2 r_mean²). (The paper's listing drops the minus sign of
/// the exponent; a weight growing with distance would let the farthest neighbour decide.)
/// `None` when nothing is in reach.
pub fn neighbour_velocity(x: [f64; 3], r_mean: f64, sources: impl IntoIterator<Item = ([f64; 3], [f64; 3])>) -> Option<[f64; 3]> {
    let reach2 = (12.0 * r_mean).powi(2);
    let (mut v, mut total) = ([0.0; 3], 0.0);
    for (xi, vi) in sources {
        let d2: f64 = (0..3).map(|k| (xi[k] - x[k]).powi(2)).sum();
        if d2 < reach2 {
            let w = (-d2 / (2.0 * r_mean * r_mean)).exp();
            for k in 0..3 {
                v[k] += w * vi[k];
            }
            total += w;
        }
    }
    (total > 0.0).then(|| v.map(|c| c / total))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform field comes back; a linear field sampled symmetrically around x gives its
    /// value at x; nothing in reach gives none.
    #[test]
    fn uniform_and_linear_fields() {
        let r = 0.5e-3;
        let u = [0.3, -1.2, 0.0];
        let ring: Vec<[f64; 3]> = (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::PI / 6.0;
                let d = (1 + k % 3) as f64 * r;
                [0.01 + d * a.cos(), 0.02 + d * a.sin(), 0.0]
            })
            .collect();
        let v = neighbour_velocity([0.01, 0.02, 0.0], r, ring.iter().map(|&p| (p, u))).unwrap();
        assert!((0..3).all(|k| (v[k] - u[k]).abs() < 1e-14), "{v:?}");
        // v = (2 (x − 0.01), 0): symmetric pairs cancel, the mean is the value at x, 0.
        let v = neighbour_velocity([0.01, 0.02, 0.0], r, ring.iter().map(|&p| (p, [2.0 * (p[0] - 0.01), 0.0, 0.0]))).unwrap();
        assert!(v[0].abs() < 1e-15 && v[1] == 0.0, "{v:?}");
        assert_eq!(neighbour_velocity([0.0; 3], r, [([0.0061, 0.0, 0.0], u)]), None, "beyond 12 r");
    }

    /// The nearer neighbour weighs more: at 1 and 3 mean radii the weights are e^-0.5 and
    /// e^-4.5, so the mean is within 2% of the near one's velocity.
    #[test]
    fn nearer_neighbours_weigh_more() {
        let r = 1.0;
        let v = neighbour_velocity(
            [0.0; 3],
            r,
            [([1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), ([0.0, 3.0, 0.0], [0.0, 0.0, 0.0])],
        )
        .unwrap();
        let (wn, wf) = ((-0.5f64).exp(), (-4.5f64).exp());
        assert!((v[0] - wn / (wn + wf)).abs() < 1e-14 && v[0] > 0.98, "{v:?}");
    }
}
