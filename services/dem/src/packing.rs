//! Initial placements: grains on a jittered lattice inside a box. The randomness (SplitMix64,
//! the polydisperse radius draw) is `grains_grid::rng`, shared with the oracle: everything
//! derives from the seed, so a scene builds the same grains on every machine.

use crate::space::Space;
use grains_grid::rng::Rng;

/// Centres of a lattice of spacing `spacing` filling the box [min, max] (centres at least
/// `margin` from its faces), each jittered by up to `jitter` in every direction. Hexagonal
/// rows in 2D, face-centred-like offset layers in 3D.
pub fn lattice_in_box<S: Space>(min: [f64; 3], max: [f64; 3], spacing: f64, margin: f64, jitter: f64, rng: &mut Rng) -> Vec<S::V> {
    let mut out = Vec::new();
    let dy = if S::DIM == 2 { spacing * 3f64.sqrt() / 2.0 } else { spacing };
    let lo = [min[0] + margin, min[1] + margin, min[2] + margin];
    let hi = [max[0] - margin, max[1] - margin, max[2] - margin];
    let nz = if S::DIM == 3 {
        ((hi[2] - lo[2]) / spacing).floor() as i64 + 1
    } else {
        1
    };
    for kz in 0..nz.max(1) {
        let z = if S::DIM == 3 { lo[2] + kz as f64 * spacing } else { 0.0 };
        let mut ky = 0;
        loop {
            let y = lo[1] + ky as f64 * dy;
            if y > hi[1] {
                break;
            }
            let shift = if (ky + kz) % 2 == 1 { 0.5 * spacing } else { 0.0 };
            let mut kx = 0;
            loop {
                let x = lo[0] + shift + kx as f64 * spacing;
                if x > hi[0] {
                    break;
                }
                let mut p = [x, y, z];
                for c in p.iter_mut().take(S::DIM) {
                    *c += jitter * (2.0 * rng.uniform() - 1.0);
                }
                out.push(S::from_array(p));
                kx += 1;
            }
            ky += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::space::D2;

    #[test]
    fn lattice_points_keep_their_spacing() {
        let pts = lattice_in_box::<D2>([0.0; 3], [1.0, 1.0, 0.0], 0.1, 0.05, 0.0, &mut Rng::new(1));
        assert!(pts.len() > 80);
        for (a, p) in pts.iter().enumerate() {
            for q in &pts[a + 1..] {
                assert!((*p - *q).length() > 0.0999);
            }
        }
    }
}
